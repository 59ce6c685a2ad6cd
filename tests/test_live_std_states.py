"""A live stream's standard deviation and sample states (``LiveSmoother.std``,
``LiveSmoother.sample_state``): those of ``smooth()`` on the same recording, frame by
frame, for the robust, Kalman and baseline methods, in any units, keyed or not."""

from __future__ import annotations

import numpy as np
import pytest

import tobitkf as tk
from conftest import data_file
from tobitkf.io import load
from tobitkf.skeleton.sequence import SampleState

FILES = ("keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt", "kimore/JointPositionExercise3.csv")


def _stream(seq, method, units=None, scale=1.0, **kw):
    live = tk.LiveSmoother(seq.topology, method=method, fps=seq.fps or 30.0, units=units, **kw)
    pos, std, state = [], [], []
    for t in range(seq.n_frames):
        pos.append(live.update(
            seq.positions[t] * scale,
            tracking_state=None if seq.tracking_state is None else seq.tracking_state[t],
            timestamp=None if seq.timestamps is None else seq.timestamps[t],
        ))  # fmt: skip
        std.append(live.std)
        state.append(live.sample_state)
    return np.array(pos), std, np.array(state)


@pytest.mark.realdata
@pytest.mark.parametrize("path", FILES)
@pytest.mark.parametrize("method", ["robust_online", "kf", "atkf", "one_euro"])
def test_live_std_and_states_are_batch(path, method):
    seq = load(data_file(path))[0]
    batch = tk.smooth(seq, method)
    pos, std, state = _stream(seq, method)
    np.testing.assert_allclose(pos, batch.positions, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(state, batch.sample_state)
    if batch.std is None:
        assert all(s is None for s in std)
    else:
        np.testing.assert_allclose(np.array(std), batch.std, rtol=1e-12, atol=1e-15)
    if method == "robust_online":  # the states a user reads: something was rejected
        assert (state == SampleState.REJECTED).any() and (state == SampleState.MEASURED).any()


@pytest.mark.realdata
def test_the_std_is_in_the_streams_units():
    """A stream in mm: its sd in mm, what smooth() gives of the mm recording (the method
    runs in metres)."""
    seq = load(data_file(FILES[0]))[0]
    mm = seq.replace(positions=seq.positions * 1000, units="mm")
    _, std, _ = _stream(seq, "robust_online", units="mm", scale=1000.0)
    np.testing.assert_allclose(np.array(std), tk.smooth(mm, "robust_online").std, rtol=1e-9)


def test_keyed_streams_give_each_bodys_own():
    """Bodies 1 and 2 share a stepper (slots 0 and 1), body 3 arrives later: each one's
    sd and states are those of a stream of it alone."""
    rng = np.random.default_rng(0)
    tracks = {k: np.cumsum(rng.normal(0, 0.005, (60, 25, 3)), axis=0) + 1 for k in (1, 2, 3)}
    tracks[2][20:23, 7] += 0.5  # a glitch: rejected
    keyed = tk.LiveSmoother("kinect_v2", fps=30)
    alone = {k: tk.LiveSmoother("kinect_v2", fps=30) for k in tracks}
    for t in range(60):
        frame = {k: y[t] for k, y in tracks.items() if k != 3 or t >= 10}
        keyed.update(frame)
        for body in frame:
            alone[body].update(tracks[body][t])
            np.testing.assert_array_equal(keyed.std[body], alone[body].std)
            np.testing.assert_array_equal(keyed.sample_state[body], alone[body].sample_state)
        if t == 21:
            assert keyed.sample_state[2][7] == SampleState.REJECTED
    assert set(keyed.std) == {1, 2, 3}


def test_before_the_first_frame_and_without_an_sd():
    live = tk.LiveSmoother("kinect_v2", fps=30, method="one_euro")
    assert live.std is None and live.sample_state is None
    frame = np.ones((25, 3))
    frame[3] = np.nan
    live.update(frame)
    assert live.std is None  # the 1€ filter gives none
    state = live.sample_state
    assert state[3] == SampleState.NONE and (np.delete(state, 3) == SampleState.MEASURED).all()


def test_stream_gates_first_frames_have_no_sd():
    rng = np.random.default_rng(1)
    y = 300 + np.cumsum(rng.normal(0, 2, (40, 25, 2)), axis=0)
    live = tk.LiveSmoother("kinect_v2", fps=30, gates_from="stream")
    for t in range(40):
        live.update(y[t])
        if t < 16:
            assert np.isnan(live.std).all()
            assert (live.sample_state == SampleState.MEASURED).all()
    assert np.isfinite(live.std).all()


def test_a_method_without_a_stepper_gives_its_own_sd_and_rejections():
    """A causal method re-run on the history each frame: the sd and the rejections of
    its batch result's last frame (robust_online made to run so, against its stepper)."""
    from dataclasses import replace

    rng = np.random.default_rng(3)
    y = np.cumsum(rng.normal(0, 0.005, (50, 25, 3)), axis=0) + 1
    y[30:33, 7] += 0.5  # rejected
    step, hist = (tk.LiveSmoother("kinect_v2", fps=30) for _ in range(2))
    hist.spec = replace(hist.spec, live=None)
    rejected = 0
    for t in range(50):
        np.testing.assert_allclose(hist.update(y[t]), step.update(y[t]), rtol=0, atol=1e-12)
        np.testing.assert_allclose(hist.std, step.std, rtol=1e-9, atol=1e-15)
        np.testing.assert_array_equal(hist.sample_state, step.sample_state)
        rejected += int((step.sample_state == SampleState.REJECTED).sum())
    assert rejected > 0  # the rejections' path is taken
