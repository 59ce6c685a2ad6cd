"""LiveSmoother with bodies keyed by id: they come, go, are predicted for max_missing
seconds and dropped; each body's numbers are those of a LiveSmoother fed it alone."""

from __future__ import annotations

import numpy as np
import pytest

import tobitkf as tk

FPS = 30.0


def _body(seed: int, T: int = 120) -> np.ndarray:
    rng = np.random.default_rng(seed)
    J = tk.get_topology("kinect_v2").n_joints
    t = np.arange(T) / FPS
    pos = rng.uniform(-0.5, 0.5, (J, 3)) + 0.2 * np.sin(2 * t + seed)[:, None, None] + [0, 0, 2.5]
    pos = pos + rng.normal(scale=0.01, size=pos.shape)
    pos[rng.random((T, J)) < 0.03] += 0.4  # spikes
    return pos


@pytest.mark.parametrize("method", ["atkf", "kf", "one_euro", "tkfc"])
def test_each_body_equals_a_smoother_fed_it_alone(method):
    a, b = _body(1), _body(2)
    present_b = np.zeros(len(a), bool)
    present_b[10:40] = True  # appears at 10, leaves at 40 ...
    present_b[50:90] = True  # ... back after 10 frames (< max_missing): same filter
    live = tk.LiveSmoother("kinect_v2", method, fps=FPS, max_missing=1.0)
    got_a, got_b = [], {}
    for k in range(len(a)):
        frame = {"a": a[k]} | ({"b": b[k]} if present_b[k] else {})
        out = live.update(frame, timestamp=k / FPS)
        got_a.append(out["a"])
        if present_b[k]:
            got_b[k] = out["b"]
        elif k >= 10:
            assert "b" in out  # predicted while missing, for at most max_missing
    alone_a = tk.LiveSmoother("kinect_v2", method, fps=FPS)
    ref_a = [alone_a.update(a[k], timestamp=k / FPS) for k in range(len(a))]
    np.testing.assert_allclose(np.stack(got_a), np.stack(ref_a), rtol=0, atol=1e-9)
    alone_b = tk.LiveSmoother("kinect_v2", method, fps=FPS)
    for k in sorted(got_b):
        ref = alone_b.update(b[k], timestamp=k / FPS)
        np.testing.assert_allclose(got_b[k], ref, rtol=0, atol=1e-9, equal_nan=True)


@pytest.mark.parametrize("method", ["robust_online", "atkf", "tkf"])
def test_bodies_that_arrive_together_share_a_stepper_and_stay_independent(method):
    """Three ids in the first frame (one stepper inside), one with tracking states
    (INFERRED and NOT_TRACKED joints), one that leaves and is dropped, a fourth arriving
    later: each equals a LiveSmoother fed it alone, states and all."""
    T = 90
    a, b, c, d = _body(5, T), _body(6, T), _body(7, T), _body(8, T)
    rng = np.random.default_rng(0)
    st_b = rng.choice(np.array([0, 1, 2], dtype=np.int8), size=(T, a.shape[1]), p=[0.1, 0.2, 0.7])
    live = tk.LiveSmoother("kinect_v2", method, fps=FPS, max_missing=0.2)
    got: dict[str, list] = {"a": [], "b": [], "c": [], "d": []}
    for k in range(T):
        frame = {"a": a[k], "b": b[k]} | ({"c": c[k]} if k < 30 else {})
        frame |= {"d": d[k]} if k >= 20 else {}
        out = live.update(frame, tracking_state={"b": st_b[k]}, timestamp=k / FPS)
        for key in frame:
            got[key].append(out[key])
        assert ("c" in out) == (k < 30 + 0.2 * FPS)  # predicted 0.2 s, then dropped
    spans = (("a", a, None, 0, T), ("b", b, st_b, 0, T), ("c", c, None, 0, 30),
             ("d", d, None, 20, T))  # fmt: skip
    for key, pos, states, start, stop in spans:
        alone = tk.LiveSmoother("kinect_v2", method, fps=FPS)
        ref = [alone.update(pos[k], None if states is None else states[k], timestamp=k / FPS)
               for k in range(start, stop)]  # fmt: skip
        np.testing.assert_array_equal(np.stack(got[key]), np.stack(ref))


def test_a_body_missing_longer_than_max_missing_is_dropped_and_restarts_fresh():
    a = _body(3)
    live = tk.LiveSmoother("kinect_v2", "atkf", fps=FPS, max_missing=0.5)  # 15 frames
    for k in range(20):
        live.update({7: a[k]}, timestamp=k / FPS)
    seen = []
    for k in range(20, 40):  # body 7 gone
        seen.append(7 in live.update({}, timestamp=k / FPS))
        assert live.bodies == ([7] if seen[-1] else [])
    # predicted while the gap is at most 0.5 s (frames 20..34), dropped after
    assert seen == [k - 19 <= 15 for k in range(20, 40)]
    fresh = tk.LiveSmoother("kinect_v2", "atkf", fps=FPS)
    for k in range(40, 60):  # comes back: a new filter, as if never seen
        got = live.update({7: a[k]}, timestamp=k / FPS)[7]
        ref = fresh.update(a[k], timestamp=k / FPS)
        np.testing.assert_array_equal(got, ref)


def test_keyed_stream_errors_leave_it_unchanged():
    a = _body(4)
    live = tk.LiveSmoother("kinect_v2", "kf", fps=FPS)
    first = live.update({1: a[0]}, timestamp=0.0)[1]
    with pytest.raises(ValueError, match="body 2: positions: infinite"):
        live.update({1: a[1], 2: np.full_like(a[1], np.inf)}, timestamp=1 / FPS)
    with pytest.raises(ValueError, match="keyed by body id"):
        live.update(a[1])
    with pytest.raises(ValueError, match="not in the frame"):
        live.update({1: a[1]}, tracking_state={3: np.full(25, 2)}, timestamp=1 / FPS)
    assert live.bodies == [1] and live.n_frames == 1
    again = tk.LiveSmoother("kinect_v2", "kf", fps=FPS)
    np.testing.assert_array_equal(again.update({1: a[0]}, timestamp=0.0)[1], first)
    with pytest.raises(ValueError, match="max_missing"):
        tk.LiveSmoother("kinect_v2", "kf", max_missing=-1)
    plain = tk.LiveSmoother("kinect_v2", "kf")
    plain.update(a[0])
    with pytest.raises(ValueError, match="not keyed by body id"):
        plain.update({1: a[1]})


def test_a_keyed_stream_says_which_joints_were_clipped_per_body():
    """``clipped`` was None on a stream keyed by id (an array stream gave (J,)): now
    ``{body_id: (J,)}``, each body's flags those of a stream of it alone."""
    rng = np.random.default_rng(0)
    y = np.clip(np.cumsum(rng.normal(scale=0.05, size=(40, 25, 3)), axis=0), -0.3, 0.3)
    kw = {"fps": 30, "lower": -0.3, "upper": 0.3}  # a sensor clipped there
    keyed = tk.LiveSmoother("kinect_v2", "tkf", **kw)
    alone = [tk.LiveSmoother("kinect_v2", "tkf", **kw) for _ in range(2)]
    seen = 0
    for frame in y:
        keyed.update({4: frame, 9: -frame})
        for s, sign in zip(alone, (1.0, -1.0), strict=True):
            s.update(sign * frame)
        assert set(keyed.clipped) == {4, 9}
        np.testing.assert_array_equal(keyed.clipped[4], alone[0].clipped)
        np.testing.assert_array_equal(keyed.clipped[9], alone[1].clipped)
        seen += int(alone[0].clipped.sum())
    assert seen > 0  # the limits clip some samples
    assert tk.LiveSmoother("kinect_v2", fps=30).clipped is None
