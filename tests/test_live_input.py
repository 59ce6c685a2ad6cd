"""Issue 14 point 8: LiveSmoother refuses bad frames before anything moves."""

from __future__ import annotations

import numpy as np
import pytest

import tobitkf as tk

TOPO = tk.get_topology("kinect_v2")


def _frames(n=6, seed=0):
    rng = np.random.default_rng(seed)
    base = rng.normal(size=(TOPO.n_joints, 3))
    return [base + 0.01 * k + rng.normal(scale=0.003, size=base.shape) for k in range(n)]


@pytest.mark.parametrize("method", ["robust_online", "kf", "atkf", "one_euro"])
def test_an_infinite_first_frame_is_reported_in_the_users_terms(method):
    live = tk.LiveSmoother(TOPO, method=method, fps=30.0)
    bad = _frames()[0].copy()
    bad[3, 1] = np.inf
    with pytest.raises(ValueError, match="positions: infinite") as err:
        live.update(bad)
    assert "x0" not in str(err.value)


@pytest.mark.parametrize("method", ["robust_online", "kf", "one_euro"])
@pytest.mark.parametrize("bad_state", [5, -1, 1.5, np.nan, "2"])
def test_a_refused_frame_does_not_move_the_stream(method, bad_state):
    # the same stream with a refused frame (inf, or a tracking state that is not 0/1/2)
    # in the middle gives exactly the outputs of the stream without it
    frames = _frames()
    clean = tk.LiveSmoother(TOPO, method=method, fps=30.0)
    expected = [clean.update(f) for f in frames]
    live = tk.LiveSmoother(TOPO, method=method, fps=30.0)
    got = [live.update(f) for f in frames[:3]]
    inf_frame = frames[3].copy()
    inf_frame[0, 0] = np.inf
    with pytest.raises(ValueError, match="infinite"):
        live.update(inf_frame)
    states = np.full(TOPO.n_joints, bad_state, dtype=object if isinstance(bad_state, str) else None)
    with pytest.raises(ValueError, match="tracking_state"):
        live.update(frames[3], tracking_state=states)
    got += [live.update(f) for f in frames[3:]]
    for g, e in zip(got, expected, strict=True):
        np.testing.assert_array_equal(g, e)


@pytest.mark.parametrize("bad_state", [5, -1, 1.5])
def test_a_bad_tracking_state_is_named(bad_state):
    # the message names the value that is not 0, 1 or 2 (a float inside [0, 2] too)
    live = tk.LiveSmoother(TOPO, fps=30.0)
    states = np.full(TOPO.n_joints, 2, dtype=type(bad_state))
    states[3] = bad_state
    with pytest.raises(ValueError, match=rf"found \[{bad_state}\]"):
        live.update(_frames()[0], tracking_state=states)


@pytest.mark.parametrize("first", [None, 5.0])
def test_a_stream_is_timed_by_stamps_at_every_frame_or_at_none(first):
    """As DelayedSmoother: a stamp given on some frames only is refused, and the refused
    frame leaves the stream as it was."""
    rng = np.random.default_rng(3)
    frames = 0.01 * rng.normal(size=(3, 25, 3)) + [0.0, 0.0, 2.5]
    live = tk.LiveSmoother("kinect_v2", fps=30.0)
    live.update(frames[0], timestamp=first)
    other = 5.1 if first is None else None
    with pytest.raises(ValueError, match="every frame of a stream or with none"):
        live.update(frames[1], timestamp=other)
    assert live.n_frames == 1
    live.update(frames[1], timestamp=None if first is None else 5.1)
    assert live.n_frames == 2


def test_messages_say_what_to_give():
    # float tracking states said "found []"; centimetres did not name LiveSmoother's units
    live = tk.LiveSmoother("kinect_v2", fps=30)
    frame = np.random.default_rng(0).normal(scale=0.3, size=(25, 3))
    with pytest.raises(ValueError, match=r"found them as float64 \(give tracking_state.astype"):
        live.update(frame, tracking_state=np.full(25, 2.0))
    with pytest.raises(ValueError, match=r"LiveSmoother\(\.\.\., units='mm'\) for a stream"):
        live.update(frame * 100.0)
