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
