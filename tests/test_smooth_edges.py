"""Edge cases of the smoothing API found by fuzzing (hypothesis), each kept as a small
deterministic test: short recordings with long pauses, parameters that would make the
filters' numbers meaningless, and duplicated timestamps live and in batch."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import tobitkf as tk
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.smoothing.robust_fit import fit_blocks
from tobitkf.smoothing.timebase import frame_steps


def _motion(frames: int, seed: int = 4) -> SkeletonSequence:
    clean = tk.generate_motion("arms", duration=max(frames / 30, 2.0), seed=seed)
    return SkeletonSequence(clean.positions[:frames], clean.topology, fps=30.0)


def _assert_finite_where_measured(seq: SkeletonSequence, out: SkeletonSequence) -> None:
    assert np.isfinite(out.positions).all()
    assert np.isfinite(out.std).all() and (out.std >= 0).all()


@pytest.mark.parametrize(("frames", "pause"), [(8, 10.0), (40, 3600.0), (100, 3600.0)])
def test_fit_blocks_stay_inside_a_short_recording_with_a_pause(frames, pause):
    # fewer frames than one 2 s block (or than the blocks the budget asks for), but
    # longer than fit_seconds because of a pause: the blocks started before frame 0
    steps = np.full(frames, 1 / 30)
    steps[frames // 2] = pause
    idx, _ = fit_blocks(steps, 5.0)
    assert idx.size and idx.min() >= 0 and idx.max() < frames
    assert np.all(np.diff(idx) > 0)  # each frame once, in order


@pytest.mark.parametrize("frames", [8, 40])
def test_robust_smooths_a_short_recording_with_a_long_pause(frames):
    seq = _motion(frames)
    ts = np.arange(frames) / 30
    ts[frames // 2 :] += 10.0  # a 10 s pause: longer than fit_seconds (5 s)
    seq = seq.replace(timestamps=ts)
    _assert_finite_where_measured(seq, tk.smooth(seq, "robust"))


@pytest.mark.parametrize("name", ["v_max", "speed_sd", "noise_sd"])
@pytest.mark.parametrize(
    "value",
    [
        np.inf,
        {"hands": np.inf, "arms": 1.0, "torso": 1.0, "legs": 1.0},
        np.full(25, np.inf),
    ],
    ids=["number", "region", "per-joint"],
)
def test_region_parameters_refuse_infinity_in_every_form(name, value):
    # a region's speed or noise of inf made its joints' output NaN (or raised a bare
    # "math domain error"); a scalar inf was refused only when the method ran
    with pytest.raises(ValueError, match=name):
        tk.LiveSmoother("kinect_v2", **{name: value})
    for method in ("robust", "robust_online"):
        with pytest.raises(ValueError, match=name):
            tk.smooth(_motion(30), method, **{name: value})


def test_per_joint_parameters_that_are_not_numbers_are_named():
    with pytest.raises(ValueError, match="noise_sd must be positive finite numbers"):
        tk.smooth(_motion(30), "robust", noise_sd=["a"] * 25)


@pytest.mark.parametrize("apart", [0.0, 1e-9])
@pytest.mark.parametrize("keyed", [False, True])
def test_live_equals_batch_at_duplicated_timestamps(apart, keyed):
    # batch gates on the timestamps as they are (a duplicate is 0 s after the frame
    # before), while the live stream gated on its cumulated steps, in which a duplicate
    # lasts a tenth of the nominal step: a hand step of 6.5 cm at the duplicate was
    # within the live speed gate and outside the batch one
    seq = _motion(60)
    ts = np.arange(60) / 30
    ts[30:] -= 1 / 30 - apart  # frame 30 has (nearly) frame 29's stamp
    pos = seq.positions.copy()
    pos[30:, seq.topology.joints.index("HandLeft"), 0] += 0.065
    seq = seq.replace(positions=pos, timestamps=ts)
    batch = tk.smooth(seq, "robust_online")
    live = tk.LiveSmoother(seq.topology, "robust_online", fps=30.0)
    if keyed:
        frames = [live.update({7: p}, timestamp=t)[7] for p, t in zip(pos, ts, strict=True)]
    else:
        frames = [live.update(p, timestamp=t) for p, t in zip(pos, ts, strict=True)]
    np.testing.assert_array_equal(np.stack(frames), batch.positions)


@settings(max_examples=8, deadline=None, derandomize=True)
@given(
    gaps=st.lists(
        st.sampled_from([0.0, 1e-9, 0.5, 1.0, 1.0, 1.0, 2.0, 300.0]), min_size=39, max_size=39
    ),
    missing=st.integers(0, 2**20),
)
def test_live_equals_batch_on_any_timestamps(gaps, missing):
    # steps of 0, 1e-9, half, one and two frames and 10 s pauses (in frames of 1/30 s)
    assume(any(g > 0 for g in gaps))
    seq = _motion(40)
    ts = np.concatenate([[0.0], np.cumsum(gaps)]) / 30
    pos = seq.positions.copy()
    rng = np.random.default_rng(missing)
    pos[rng.random(pos.shape[:2]) < 0.1] = np.nan
    pos[rng.random(pos.shape[:2]) < 0.05] += 0.3  # glitches for the gates
    seq = seq.replace(positions=pos, timestamps=ts)
    batch = tk.smooth(seq, "robust_online").positions
    # batch takes its nominal step from the timestamps (the median positive step); a
    # stream cannot look ahead, so it is given that rate (all stamps equal: batch uses
    # fps, which a stream cannot know is the case until its end: assumed above)
    live = tk.LiveSmoother(seq.topology, "robust_online", fps=1 / frame_steps(seq)[1])
    frames = np.stack([live.update(p, timestamp=t) for p, t in zip(pos, ts, strict=True)])
    np.testing.assert_array_equal(frames, batch)


def test_an_absurd_lookback_is_a_clear_error_not_a_huge_allocation():
    """Each frame of lookback is a copy of every joint's filter state: 10**9 of them asked
    numpy for terabytes (a MemoryError) instead of saying what is wrong."""
    walk = np.cumsum(np.full((6, 25, 3), 0.001), axis=0)
    with pytest.raises(ValueError, match="lookback must be an integer from 0 to 300"):
        tk.smooth(walk, "robust_online", lookback=10**9)
    with pytest.raises(ValueError, match="lookback"):
        tk.LiveSmoother(method="robust_online", lookback=301)
    assert np.isfinite(tk.smooth(walk, "robust_online", lookback=300)).all()
