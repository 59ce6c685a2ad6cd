"""LiveSmoother: frame by frame, the same numbers as smooth() on the whole recording."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import data_file
from tobitkf.io import load
from tobitkf.skeleton.sequence import SkeletonSequence, TrackingState
from tobitkf.skeleton.topology import get_topology
from tobitkf.smoothing.api import smooth
from tobitkf.smoothing.live import LiveSmoother, live_methods

LIVE_METHODS = live_methods()


def _stream(seq: SkeletonSequence, method: str, fps: float | None = None, **params) -> np.ndarray:
    live = LiveSmoother(seq.topology, method, fps=fps or seq.fps or 30.0, **params)
    ts = seq.timestamps
    out = [
        live.update(
            seq.positions[k],
            None if seq.tracking_state is None else seq.tracking_state[k],
            None if ts is None else float(ts[k]),
        )
        for k in range(seq.n_frames)
    ]
    return np.stack(out)


def _synthetic(seed: int = 0, T: int = 80) -> SkeletonSequence:
    """Moving joints with late starts, gaps, inferred and not-tracked samples, and spikes."""
    rng = np.random.default_rng(seed)
    topo = get_topology("kinect_v2")
    J = topo.n_joints
    t = np.arange(T) / 30
    pos = rng.uniform(-0.5, 0.5, (J, 3)) + 0.3 * np.sin(2 * t)[:, None, None] + [0, 0, 2.5]
    pos = pos + rng.normal(scale=0.01, size=pos.shape)
    pos[rng.random((T, J)) < 0.02] += 0.5  # one-frame jumps
    pos[:7, 3] = np.nan  # Head appears late
    pos[20:31, 7] = np.nan  # a gap in HandLeft
    states = np.full((T, J), int(TrackingState.TRACKED), dtype=np.int8)
    states[rng.random((T, J)) < 0.1] = TrackingState.INFERRED
    states[40:44, 11] = TrackingState.NOT_TRACKED
    return SkeletonSequence(positions=pos, topology=topo, tracking_state=states, fps=30.0)


@pytest.mark.parametrize("method", LIVE_METHODS)
def test_live_equals_batch_on_synthetic_stream(method):
    seq = _synthetic()
    batch = smooth(seq, method=method).positions
    live = _stream(seq, method)
    np.testing.assert_array_equal(np.isnan(live), np.isnan(batch))
    np.testing.assert_allclose(live, batch, rtol=0, atol=1e-12, equal_nan=True)


def test_live_equals_batch_with_irregular_timestamps():
    seq = load(data_file("krajjat/sequence_ainhoa_trimmed.tsv"))[0]
    seq = seq.replace(positions=seq.positions[:300], timestamps=seq.timestamps[:300])
    batch = smooth(seq, method="atkf").positions
    # batch smoothing takes the first step from the median interval of the recording; a
    # live stream cannot look ahead, so it is given that nominal rate
    live = _stream(seq, "atkf", fps=1.0 / np.median(np.diff(seq.timestamps)))
    np.testing.assert_allclose(live, batch, rtol=0, atol=1e-12, equal_nan=True)


def test_live_equals_batch_on_kimore_with_tracking_states():
    seq = load(data_file("kimore/JointPositionExercise3.csv"))[0]
    assert seq.tracking_state is not None
    batch = smooth(seq, method="atkf", c=(0.3, 0.2, 0.3), q=0.001).positions
    live = _stream(seq, "atkf", c=(0.3, 0.2, 0.3), q=0.001)
    np.testing.assert_allclose(live, batch, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "path",
    ["kimore/JointPositionExercise3.csv", "keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt"],
)
def test_robust_online_live_equals_batch_on_real_recordings(path):
    # constant work per frame: the registered stepper, not a re-run on the history
    from tobitkf.smoothing.api import get_method

    assert get_method("robust_online").live is not None
    seq = load(data_file(path))[0]
    out = smooth(seq, method="robust_online")
    assert out.metadata["diagnostics"]["rejected"].any()  # the gates have work to do
    live = _stream(seq, "robust_online")
    np.testing.assert_array_equal(np.isnan(live), np.isnan(out.positions))
    np.testing.assert_allclose(live, out.positions, rtol=0, atol=1e-12, equal_nan=True)


def test_live_rejects_offline_methods_and_bad_frames():
    with pytest.raises(ValueError, match="cannot run live"):
        LiveSmoother("kinect_v2", "sgf")
    with pytest.raises(ValueError, match="bogus"):
        LiveSmoother("kinect_v2", "atkf", bogus=1)
    live = LiveSmoother("kinect_v2", "kf")
    with pytest.raises(ValueError, match="25"):
        live.update(np.zeros((20, 3)))
    live.update(np.zeros((25, 3)), timestamp=1.0)
    with pytest.raises(ValueError, match="must not decrease"):
        live.update(np.zeros((25, 3)), timestamp=0.5)


@pytest.mark.parametrize("method", ["atkf", "robust_online"])
def test_live_handles_several_bodies_independently(method):
    a, b = _synthetic(1), _synthetic(2)
    live = LiveSmoother("kinect_v2", method)
    both = np.stack(
        [
            live.update(
                np.stack([a.positions[k], b.positions[k]]),
                np.stack([a.tracking_state[k], b.tracking_state[k]]),
            )
            for k in range(a.n_frames)
        ]
    )
    np.testing.assert_allclose(both[:, 0], _stream(a, method), atol=1e-12, equal_nan=True)
    np.testing.assert_allclose(both[:, 1], _stream(b, method), atol=1e-12, equal_nan=True)


def test_rejected_frame_leaves_the_stream_unchanged():
    # a frame refused for its batch shape must not advance the clock: the next good frame
    # gives the same result as in a stream that never saw the bad one
    seq = _synthetic(3, T=12)
    ts = np.arange(12) / 30.0
    clean = LiveSmoother("kinect_v2", "atkf")
    noisy = LiveSmoother("kinect_v2", "atkf")
    for k in range(6):
        a = clean.update(seq.positions[k], seq.tracking_state[k], ts[k])
        b = noisy.update(seq.positions[k], seq.tracking_state[k], ts[k])
        np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="batch shape"):
        noisy.update(np.stack([seq.positions[6]] * 2), None, ts[6] + 0.5)
    for k in range(6, 12):
        a = clean.update(seq.positions[k], seq.tracking_state[k], ts[k])
        b = noisy.update(seq.positions[k], seq.tracking_state[k], ts[k])
        np.testing.assert_array_equal(a, b)


# --------------------------------------------------------------------------- baselines live
# the causal baselines run through live steppers that carry the filter state from frame to
# frame and compute as the batch does: exactly the batch numbers, constant work per frame

BASELINES = [
    ("one_euro", {"beta": 0.7}),
    ("kinect", {}),
    ("kinect", {"preset": "v2_sample"}),
    ("moving_average", {"centered": False, "window": 7}),
]
_ids = [f"{m}-{'-'.join(map(str, p.values()))}" for m, p in BASELINES]


def _exact(live: np.ndarray, batch: np.ndarray) -> None:
    assert np.array_equal(live, batch, equal_nan=True), np.nanmax(np.abs(live - batch))


@pytest.mark.parametrize(("method", "params"), BASELINES, ids=_ids)
def test_baseline_live_equals_batch_exactly(method, params):
    # one body (gaps, late start, INFERRED and NOT_TRACKED), then two in one array
    a, b = _synthetic(1), _synthetic(2)
    batch_a = smooth(a, method=method, **params).positions
    _exact(_stream(a, method, **params), batch_a)
    live = LiveSmoother("kinect_v2", method, **params)
    both = np.stack([
        live.update(np.stack([a.positions[k], b.positions[k]]),
                    np.stack([a.tracking_state[k], b.tracking_state[k]]))
        for k in range(a.n_frames)
    ])  # fmt: skip
    _exact(both[:, 0], batch_a)
    _exact(both[:, 1], smooth(b, method=method, **params).positions)


@pytest.mark.parametrize(("method", "params"), BASELINES, ids=_ids)
def test_baseline_keyed_bodies_coming_and_going_equal_batch_exactly(method, params):
    """Ids arriving, leaving for less than max_missing (predicted), leaving for good
    (dropped) and arriving after that: each body's outputs, from its arrival to its last
    output, equal smooth() of its recording over those frames (NaN where it was absent)."""
    T = 90
    bodies = {i: _synthetic(10 + i, T) for i in range(4)}
    present = {0: range(T), 1: [*range(10, 40), *range(50, T)], 2: range(20, 30),
               3: range(60, T)}  # fmt: skip
    live = LiveSmoother("kinect_v2", method, max_missing=0.5, **params)
    got: dict[int, dict[int, np.ndarray]] = {i: {} for i in bodies}
    for k in range(T):
        ids = [i for i in bodies if k in present[i]]
        frame = {i: bodies[i].positions[k] for i in ids}
        states = {i: bodies[i].tracking_state[k] for i in ids if i == 1}
        for i, pos in live.update(frame, tracking_state=states).items():
            got[i][k] = pos
    assert 40 < max(got[2]) < 50  # body 2: predicted for 0.5 s, then dropped
    for i, seq in bodies.items():
        frames = sorted(got[i])
        span = slice(frames[0], frames[-1] + 1)
        absent = [k for k in range(span.start, span.stop) if k not in present[i]]
        pos = seq.positions.copy()
        pos[absent] = np.nan
        st = seq.tracking_state.copy() if i == 1 else np.full_like(seq.tracking_state, 2)
        st[absent] = TrackingState.TRACKED
        own = SkeletonSequence(positions=pos[span], topology=seq.topology, fps=30.0,
                               tracking_state=st[span])  # fmt: skip
        _exact(
            np.stack([got[i][k] for k in frames]), smooth(own, method=method, **params).positions
        )


def _fps_of(step: float) -> float:
    """A frame rate whose 1/fps is ``step`` exactly (the batch's nominal step is the
    median interval; the live stream takes its first step from fps)."""
    fps = 1.0 / step
    for _ in range(8):
        if 1.0 / fps == step:
            return fps
        fps = np.nextafter(fps, np.inf if 1.0 / fps > step else 0.0)
    raise AssertionError(f"no fps gives a step of {step!r}")


@pytest.mark.parametrize(("method", "params"), BASELINES, ids=_ids)
def test_baseline_live_equals_batch_exactly_with_irregular_timestamps(method, params):
    # jittered stamps, a repeated one (a tenth of the step) and a pause; the 1€ filter
    # uses the elapsed times: the stream's clock is the batch's cumulated steps
    seq = _synthetic(4, T=120)
    rng = np.random.default_rng(4)
    steps = rng.uniform(0.02, 0.05, seq.n_frames)
    steps[30] = 0.0
    steps[70] = 0.8
    seq = seq.replace(timestamps=100.0 + np.cumsum(steps))
    batch = smooth(seq, method=method, **params).positions
    d = np.diff(seq.timestamps)
    _exact(_stream(seq, method, fps=_fps_of(float(np.median(d[d > 0]))), **params), batch)


@pytest.mark.parametrize("method", ["one_euro", "kinect", "moving_average"])
def test_baseline_live_keeps_no_history(method):
    # a registered stepper (not a re-run of the whole history every frame), whose state
    # does not grow with the stream: per-frame work independent of the stream's length
    from tobitkf.smoothing.live import _HistoryStepper

    params = {"centered": False} if method == "moving_average" else {}
    live = LiveSmoother("kinect_v2", method, **params)
    assert not isinstance(live._new_stepper(), _HistoryStepper)
    seq = _synthetic(5, T=200)
    sizes = []
    for k in range(seq.n_frames):
        live.update(seq.positions[k], seq.tracking_state[k])
        if k in (20, 199):
            sizes.append(_state_bytes(live._stepper))
    assert sizes[0] == sizes[1] > 0


def _state_bytes(obj, seen=None) -> int:
    """Bytes of the arrays an object holds (in its attributes, lists, tuples, dicts)."""
    seen = set() if seen is None else seen
    if id(obj) in seen:
        return 0
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        return obj.nbytes
    if isinstance(obj, list | tuple):
        return sum(_state_bytes(o, seen) for o in obj) + len(obj)
    if isinstance(obj, dict):
        return sum(_state_bytes(o, seen) for o in obj.values())
    if hasattr(obj, "__dict__") and type(obj).__module__.startswith("tobitkf."):
        return _state_bytes(vars(obj), seen)
    return 0


def test_history_rerun_equals_the_baseline_steppers(monkeypatch):
    # without its stepper a causal method re-runs on the history: the same numbers, also
    # for keyed bodies whose tracking states come in some frames only
    from dataclasses import replace

    params = {"centered": False, "window": 3}
    a, b = _synthetic(6, T=40), _synthetic(7, T=40)
    step, hist = (LiveSmoother("kinect_v2", "moving_average", **params) for _ in range(2))
    hist.spec = replace(hist.spec, live=None)
    for k in range(a.n_frames):
        frame = {"a": a.positions[k]} | ({"b": b.positions[k]} if k >= 5 else {})
        states = {"b": b.tracking_state[k]} if k % 3 and k >= 5 else None
        got, ref = hist.update(frame, states), step.update(frame, states)
        assert got.keys() == ref.keys()
        for key in ref:
            _exact(got[key], ref[key])
