"""SkeletonSequence: validation, time axis, joint selection, largest jumps."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tobitkf.skeleton.sequence import SkeletonSequence, TrackingState
from tobitkf.skeleton.topology import Topology, get_topology

V2 = get_topology("kinect_v2")


def _seq(T=5, **kw):
    rng = np.random.default_rng(0)
    return SkeletonSequence(positions=rng.normal(size=(T, 25, 3)), topology=V2, **kw)


def test_tracking_state_codes_match_kinect_sdk():
    assert int(TrackingState.NOT_TRACKED) == 0
    assert int(TrackingState.INFERRED) == 1
    assert int(TrackingState.TRACKED) == 2


def test_basic_properties_and_topology_by_name():
    s = SkeletonSequence(np.zeros((4, 25, 3)), "kinect_v2", fps=30)
    assert s.topology is V2
    assert (s.n_frames, s.n_joints) == (4, 25)
    assert s.joint_names[0] == "SpineBase"
    np.testing.assert_allclose(s.times(), [0, 1 / 30, 2 / 30, 3 / 30])
    np.testing.assert_allclose(s.dt(), np.full(3, 1 / 30))
    assert s.metadata == {}


def test_timestamps_take_precedence():
    ts = np.array([0.0, 0.05, 0.2, 0.21, 0.3])
    s = _seq(timestamps=ts, fps=30)
    np.testing.assert_array_equal(s.times(), ts)
    np.testing.assert_allclose(s.dt(), [0.05, 0.15, 0.01, 0.09])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"positions": np.zeros((4, 25))}, "shape"),
        ({"positions": np.zeros((4, 24, 3))}, "24 joints"),
        ({"positions": np.full((2, 25, 3), np.inf)}, "inf"),
        ({"tracking_state": np.zeros((3, 25))}, "tracking_state"),
        ({"tracking_state": np.full((4, 25), 3)}, "0, 1 or 2"),
        ({"timestamps": np.arange(3.0)}, "timestamps"),
        ({"timestamps": np.array([0.0, 0.2, 0.1, 0.3])}, "non-decreasing"),
        ({"fps": 0.0}, "fps"),
        ({"fps": -30}, "fps"),
        ({"fps": float("nan")}, "fps"),
        ({"std": np.zeros((4, 24))}, "std must have shape"),
        ({"std": np.full((4, 25), -0.1)}, "std values"),
        ({"std": np.full((4, 25), np.inf)}, "std values"),
        ({"sample_state": np.full((4, 25), 5)}, "0 to 4"),
        ({"sample_state": np.full((4, 25), 1.5)}, "0 to 4"),
        ({"sample_state": np.zeros((3, 25))}, "sample_state must have shape"),
    ],
)
def test_validation(kwargs, match):
    base = {"positions": np.zeros((4, 25, 3)), "topology": V2}
    base.update(kwargs)
    with pytest.raises(ValueError, match=match):
        SkeletonSequence(**base)


def test_frozen_and_replace_revalidates():
    s = _seq(fps=30)
    with pytest.raises(AttributeError):
        s.fps = 10  # type: ignore[misc]
    r = s.replace(fps=60.0)
    assert r.fps == 60.0 and s.fps == 30.0
    np.testing.assert_array_equal(r.positions, s.positions)
    with pytest.raises(ValueError):
        s.replace(fps=-1)


def test_std_and_sample_state_kept_by_replace_and_sliced_by_select_joints():
    std = np.tile(np.arange(25.0) / 100, (5, 1))
    sample = np.tile(np.arange(25) % 5, (5, 1))
    s = _seq(std=std, sample_state=sample)
    assert s.sample_state.dtype == np.int8
    r = s.replace(fps=10.0)
    np.testing.assert_array_equal(r.std, std)
    np.testing.assert_array_equal(r.sample_state, sample)
    sub = s.select_joints(["HandRight", "SpineBase"])
    j = V2.index("HandRight")
    np.testing.assert_array_equal(sub.std[:, 0], std[:, j])
    np.testing.assert_array_equal(sub.sample_state[:, 0], sample[:, j])
    np.testing.assert_array_equal(sub.std[:, 1], std[:, 0])


def test_state_cast_to_int8():
    s = _seq(tracking_state=np.full((5, 25), 2, dtype=np.int64))
    assert s.tracking_state.dtype == np.int8


def test_select_joints_slices_everything():
    T = 6
    rng = np.random.default_rng(1)
    pos = rng.normal(size=(T, 25, 3))
    state = rng.integers(0, 3, size=(T, 25))
    orient = rng.normal(size=(T, 25, 4))
    s = SkeletonSequence(pos, V2, tracking_state=state, metadata={"orientations": orient, "k": 1})
    sub = s.select_joints(["HandRight", "ElbowRight", "SpineBase"])
    assert sub.joint_names == ("HandRight", "ElbowRight", "SpineBase")
    np.testing.assert_array_equal(sub.positions, pos[:, [11, 9, 0]])
    np.testing.assert_array_equal(sub.tracking_state, state[:, [11, 9, 0]])
    np.testing.assert_array_equal(sub.metadata["orientations"], orient[:, [11, 9, 0]])
    assert sub.metadata["k"] == 1
    # dropped parents: HandRight -> ElbowRight, ElbowRight -> SpineBase (nearest kept)
    assert sub.topology.parents == (1, 2, -1)


def test_largest_jumps_brute_force_with_nan():
    T = 7
    rng = np.random.default_rng(2)
    pos = rng.normal(size=(T, 25, 3))
    pos[3, 4] = np.nan
    pos[:, 7] = np.nan
    pos[1:, 8] = np.nan  # only one sample: no pair
    s = SkeletonSequence(pos, V2)
    jumps, frames = s.largest_jumps()
    for j in range(25):
        best, at = np.nan, -1
        for t in range(1, T):
            d = pos[t, j] - pos[t - 1, j]
            if np.isnan(d).any():
                continue
            n = float(np.sqrt(np.sum(d**2)))
            if np.isnan(best) or n > best:
                best, at = n, t
        if at < 0:
            assert np.isnan(jumps[j]) and frames[j] == -1
        else:
            assert jumps[j] == pytest.approx(best) and frames[j] == at


@settings(max_examples=40, deadline=None)
@given(
    hnp.arrays(
        np.float64,
        st.tuples(st.integers(1, 8), st.just(3), st.just(3)),
        elements=st.floats(-10, 10),
    ),
    st.floats(1.0, 500.0),
)
def test_times_uniform_property(pos, fps):
    s = SkeletonSequence(pos, Topology.from_names(["a", "b", "c"]), fps=fps)
    t = s.times()
    assert t.shape == (pos.shape[0],)
    np.testing.assert_allclose(np.diff(t), 1 / fps, rtol=1e-12)
    assert s.dt().shape == (pos.shape[0] - 1,)
    assert s.missing().shape == pos.shape[:2]


def _full(T=9, **kw):
    """A sequence with every per-frame field set, from independent random draws."""
    rng = np.random.default_rng(5)
    return SkeletonSequence(
        positions=rng.normal(size=(T, 25, 3)),
        topology=V2,
        tracking_state=rng.integers(0, 3, size=(T, 25)),
        std=rng.random((T, 25)),
        sample_state=rng.integers(0, 5, size=(T, 25)),
        confidence=rng.random((T, 25)),
        metadata={
            "orientations": rng.normal(size=(T, 25, 4)),
            "frame_numbers": np.arange(T) + 7,
            "offsets": rng.normal(size=(25, 3)),
            "source": "x.txt",
        },
        **kw,
    )


@pytest.mark.parametrize(
    "frames, idx",
    [
        (slice(2, 7), [2, 3, 4, 5, 6]),
        (slice(None, None, 3), [0, 3, 6]),
        ([1, 4, -1], [1, 4, 8]),
        (np.arange(9) % 4 == 1, [1, 5]),
        ([], []),
    ],
)
def test_select_frames_cuts_every_per_frame_field_alike(frames, idx):
    s = _full(fps=30.0)
    sub = s.select_frames(frames)
    for name in ("positions", "tracking_state", "std", "sample_state", "confidence"):
        np.testing.assert_array_equal(getattr(sub, name), getattr(s, name)[idx])
    for key in ("orientations", "frame_numbers"):
        np.testing.assert_array_equal(sub.metadata[key], s.metadata[key][idx])
    assert sub.metadata["offsets"] is s.metadata["offsets"]  # not per frame: as it was
    assert sub.metadata["source"] == "x.txt"
    assert sub.metadata["source_frames"].dtype == np.int64
    np.testing.assert_array_equal(sub.metadata["source_frames"], idx)
    assert "source_frames" not in s.metadata  # the original is left alone


def test_select_frames_keeps_each_frames_time():
    s = _full(fps=30.0)
    run = s.select_frames(slice(2, 7))  # evenly spaced: fps kept, times from 0 again
    assert run.timestamps is None and run.fps == 30.0
    np.testing.assert_allclose(run.times(), np.arange(5) / 30)
    gaps = s.select_frames([0, 1, 5])  # no longer evenly spaced: timestamps
    np.testing.assert_allclose(gaps.times(), np.array([0, 1, 5]) / 30)
    stamped = s.replace(timestamps=np.arange(9) ** 2 / 10.0).select_frames(slice(3, None, 2))
    np.testing.assert_allclose(stamped.timestamps, np.array([9, 25, 49]) / 10.0)
    untimed = _full().select_frames([0, 4, 5])  # no timing to keep: the indices tell
    assert untimed.timestamps is None and untimed.fps is None
    np.testing.assert_array_equal(untimed.metadata["source_frames"], [0, 4, 5])


def test_select_frames_of_a_selection_keeps_the_first_indices():
    sub = _full(fps=30.0).select_frames(slice(3, 9)).select_frames([1, 4])
    np.testing.assert_array_equal(sub.metadata["source_frames"], [4, 7])
    np.testing.assert_array_equal(sub.metadata["frame_numbers"], [11, 14])


@pytest.mark.parametrize(
    "frames, error, words",
    [
        ([3, 2], ValueError, "increasing"),
        ([2, 2], ValueError, "increasing"),
        (slice(None, None, -1), ValueError, "increasing"),
        ([9], IndexError, "out of range"),
        ([-10], IndexError, "out of range"),
        (np.ones(8, dtype=bool), ValueError, "mask"),
        ([0.5, 1.0], TypeError, "indices"),
        (np.zeros((2, 2), dtype=int), TypeError, "indices"),
    ],
)
def test_select_frames_refuses_what_is_not_a_selection(frames, error, words):
    with pytest.raises(error, match=words):
        _full(fps=30.0).select_frames(frames)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.booleans(), min_size=1, max_size=12), st.booleans())
def test_select_frames_matches_numpy_and_times(mask, stamped):
    """Any mask: the positions and times of the selection are the original's at the
    selected frames (timestamps, or fps-spaced times shifted to start at 0 for a run)."""
    T = len(mask)
    s = _full(T=T, fps=25.0)
    if stamped:
        s = s.replace(timestamps=np.cumsum(np.arange(1, T + 1)) / 100.0)
    sub = s.select_frames(np.array(mask))
    idx = np.flatnonzero(mask)
    np.testing.assert_array_equal(sub.positions, s.positions[idx])
    if idx.size:
        shift = 0.0 if (stamped or sub.timestamps is not None) else s.times()[idx[0]]
        np.testing.assert_allclose(sub.times() + shift, s.times()[idx])


def test_declared_per_joint_entries_follow_the_joints_not_the_frames(tmp_path):
    """With T == J a per-joint array looks per-frame: ``metadata["per_joint"]`` says which
    entries are indexed by joint, and they follow select_joints, not select_frames."""
    import tobitkf as tk

    s = _full(T=25, fps=30.0)
    offsets = s.metadata["offsets"]
    names = [f"n{j}" for j in range(25)]
    s = s.replace(metadata={**s.metadata, "names": names, "per_joint": ["offsets", "names"]})
    sub = s.select_frames([2, 3, 20])
    assert sub.metadata["offsets"] is offsets and sub.metadata["names"] is names
    np.testing.assert_array_equal(
        sub.metadata["orientations"], s.metadata["orientations"][[2, 3, 20]]
    )
    # undeclared, an array of first axis T is taken for a per-frame one
    bare = _full(T=25, fps=30.0).select_frames([2, 3, 20])
    np.testing.assert_array_equal(bare.metadata["offsets"], offsets[[2, 3, 20]])
    kept = ["HandRight", "ElbowRight", "SpineBase"]
    j = s.topology.indices(kept)
    part = s.select_joints(kept)
    np.testing.assert_array_equal(part.metadata["offsets"], offsets[j])
    assert part.metadata["names"] == [names[i] for i in j]
    np.testing.assert_array_equal(part.metadata["orientations"], s.metadata["orientations"][:, j])
    # NPZ keeps the declaration: the loaded sequence cuts alike
    tk.save([s], tmp_path / "s.npz")
    back = tk.load(tmp_path / "s.npz")[0].select_joints(kept)
    np.testing.assert_array_equal(back.metadata["offsets"], offsets[j])
    assert list(back.metadata["names"]) == [names[i] for i in j]


def test_a_declared_per_joint_entry_of_the_wrong_length_is_refused():
    s = _full()
    s = s.replace(metadata={**s.metadata, "offsets": np.zeros((24, 3)), "per_joint": ["offsets"]})
    with pytest.raises(ValueError, match=r"offsets.*length J = 25"):
        s.select_joints(["HandRight"])


def test_arrays_inside_metadata_dicts_are_cut_too():
    """An NTU file's per-body fields are a dict of (T,) arrays: a frame selection cuts
    them, a joint selection cuts the (T, J, ...) arrays inside dicts."""
    T = 9
    body = {"lean": np.arange(T) * 0.5, "id": 3, "grid": np.arange(T * 25.0).reshape(T, 25)}
    s = _full(T=T, fps=30.0)
    s = s.replace(metadata={**s.metadata, "ntu_body": body})
    sub = s.select_frames([1, 4, 8])
    np.testing.assert_array_equal(sub.metadata["ntu_body"]["lean"], [0.5, 2.0, 4.0])
    assert sub.metadata["ntu_body"]["id"] == 3
    part = s.select_joints(["SpineMid", "SpineBase"])
    np.testing.assert_array_equal(part.metadata["ntu_body"]["grid"], body["grid"][:, [1, 0]])
    np.testing.assert_array_equal(part.metadata["ntu_body"]["lean"], body["lean"])


def test_a_selection_round_trips_through_npz(tmp_path):
    """NPZ keeps the metadata arrays: the selection's source frames and times come back."""
    import tobitkf as tk

    sub = _full(T=20, fps=30.0).select_frames(slice(4, 20, 5))
    tk.save([sub], tmp_path / "sub.npz")
    back = tk.load(tmp_path / "sub.npz")[0]
    np.testing.assert_array_equal(back.metadata["source_frames"], [4, 9, 14, 19])
    np.testing.assert_allclose(back.times(), np.array([4, 9, 14, 19]) / 30)
    np.testing.assert_array_equal(back.positions, sub.positions)
