"""NumPy arrays and pandas DataFrames in and out; CSV files pandas reads as they are."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import savgol_filter

import tobitkf as tk
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology

TOPO = Topology.from_names(["snout", "leftear", "rightear"], edges=[(0, 1), (0, 2)])


def _walk(T=120, J=3, D=2, seed=0):
    return np.random.default_rng(seed).normal(size=(T, J, D)).cumsum(axis=0) + 100


# ------------------------------------------------------------------------------ numpy
def test_array_in_array_out_like_savgol_filter():
    a = _walk()
    out = tk.smooth(a, fps=30, method="savgol", window=9, polyorder=3)
    assert isinstance(out, np.ndarray) and out.shape == a.shape
    np.testing.assert_allclose(out, savgol_filter(a, 9, 3, axis=0, mode="interp"), atol=1e-9)
    one = tk.smooth(a[:, 0], fps=30, method="savgol", window=9, polyorder=3)
    np.testing.assert_allclose(one, out[:, 0], atol=1e-12)


@pytest.mark.parametrize("method", ["robust", "robust_online", "kf", "one_euro"])
def test_array_equals_the_sequence(method):
    a = _walk(D=3)
    a[10:14, 1] = np.nan
    conf = np.random.default_rng(1).uniform(0, 1, a.shape[:2])
    seq = SkeletonSequence(a, TOPO, fps=25.0, confidence=conf, units="px")
    want = tk.smooth(seq, method).positions
    got = tk.smooth(a, method, fps=25, confidence=conf, units="px", topology=TOPO)
    np.testing.assert_array_equal(got, want)
    assert not np.shares_memory(got, a)


@pytest.mark.parametrize(
    ("bad", "kw", "err", "match"),
    [
        (np.zeros((10, 3, 4)), {}, ValueError, r"shape \(T, J, D\).*got shape \(10, 3, 4\)"),
        (np.zeros((10,)), {}, ValueError, "got shape"),
        (np.zeros((10, 2, 2, 2)), {}, ValueError, "got shape"),
        (np.full((10, 2, 2), np.inf), {}, ValueError, "inf"),
        (np.array([["a", "b"]] * 10), {}, TypeError, "numeric"),
        (np.zeros((10, 2, 2), complex), {}, TypeError, "complex"),
        (np.zeros((10, 2, 2)), {"confidence": np.ones((10, 3))}, ValueError, "confidence"),
        (np.zeros((10, 2, 2)), {"confidence": np.full((10, 2), 2.0)}, ValueError, r"\[0, 1\]"),
        (np.zeros((10, 2, 2)), {"fps": -1}, ValueError, "fps"),
        (np.zeros((10, 2, 2)), {"fps": "30"}, TypeError, "fps"),
        (np.zeros((10, 2, 2)), {"units": "inch"}, ValueError, "units"),
        (np.zeros((10, 2, 2)), {"topology": "kinect_v2"}, ValueError, "joints"),
    ],
)
def test_array_errors(bad, kw, err, match):
    with pytest.raises(err, match=match):
        tk.smooth(bad, "kf", **kw)


def test_array_keywords_refused_for_sequences():
    seq = SkeletonSequence(_walk(), TOPO, fps=30.0)
    with pytest.raises(TypeError, match="fps, units: only for an array"):
        tk.smooth(seq, fps=30, units="px")
    with pytest.raises(TypeError, match="NumPy array"):
        tk.smooth(_walk().tolist())


def test_array_with_timestamps_equals_the_sequence():
    a = _walk(D=3)
    ts = np.cumsum(np.random.default_rng(5).uniform(0.02, 0.05, len(a)))
    seq = SkeletonSequence(a, Topology.from_names([f"k{j}" for j in range(3)]), timestamps=ts,
                           units=None)  # fmt: skip
    np.testing.assert_array_equal(tk.smooth(a, timestamps=ts), tk.smooth(seq).positions)
    assert not np.array_equal(tk.smooth(a, timestamps=ts), tk.smooth(a))
    with pytest.raises(ValueError, match="timestamps"):
        tk.smooth(a, timestamps=ts[:-1])
    with pytest.raises(ValueError, match="not both"):
        tk.smooth(a, timestamps=ts, fps=60)
    # datetimes count from the first, in seconds (not nanoseconds taken for seconds)
    clock = pd.Timestamp("2020-01-01") + pd.to_timedelta(ts - ts[0], unit="s")
    np.testing.assert_allclose(tk.smooth(a, timestamps=clock),
                               tk.smooth(a, timestamps=ts - ts[0]), atol=1e-9)  # fmt: skip
    np.testing.assert_allclose(tk.smooth(a, timestamps=clock.to_numpy()),
                               tk.smooth(a, timestamps=ts - ts[0]), atol=1e-9)  # fmt: skip


def test_containers_passed_by_habit_name_the_way_in():
    xr = pytest.importorskip("xarray")
    with pytest.raises(TypeError, match=r"tobitkf\.from_dataframe\(df\)"):
        tk.smooth(pd.DataFrame({"a_x": [1.0], "a_y": [2.0]}))
    with pytest.raises(TypeError, match=r"tobitkf\.from_movement\(ds\)"):
        tk.smooth(xr.Dataset({"position": (("time",), [1.0])}))
    with pytest.raises(TypeError, match=r"np\.asarray"):
        tk.smooth(_walk().tolist(), fps=30)


# ------------------------------------------------------------------------------ pandas
def _assert_same_samples(a: SkeletonSequence, b: SkeletonSequence) -> None:
    """The per-sample arrays and the body id (what a table holds without its sidecar)."""
    np.testing.assert_array_equal(a.positions, b.positions)
    for name in ("confidence", "tracking_state", "std", "sample_state", "timestamps"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            np.testing.assert_array_equal(x, y, err_msg=name)
    assert (a.body_id, a.joint_names) == (b.body_id, b.joint_names)


def _assert_same(a: SkeletonSequence, b: SkeletonSequence) -> None:
    _assert_same_samples(a, b)
    assert (a.fps, a.units) == (b.fps, b.units)
    assert a.topology.parents == b.topology.parents


@pytest.mark.parametrize("layout", ["long", "wide"])
def test_dataframe_round_trip(layout):
    rng = np.random.default_rng(2)
    conf = rng.uniform(0, 1, (40, 3))
    conf[3, 1] = np.nan
    pos = _walk(T=40)
    pos[5, 2] = np.nan
    a = SkeletonSequence(pos, TOPO, fps=30.0, confidence=conf, units="px", body_id="mouse1")
    b = a.replace(positions=_walk(T=40, seed=3), body_id="mouse2")
    back = tk.from_dataframe(tk.to_dataframe([a, b], layout))
    assert len(back) == 2
    _assert_same(a, back[0])
    _assert_same(b, back[1])
    # 3-D metres with tracking states, timestamps, and a smoothed output's std / states
    k = tk.SkeletonSequence(_walk(T=30, J=25, D=3) / 100, "kinect_v2",
                            tracking_state=rng.integers(0, 3, (30, 25)),
                            timestamps=np.cumsum(rng.uniform(0.02, 0.04, 30)))  # fmt: skip
    sm = tk.smooth(k)
    (r,) = tk.from_dataframe(sm.to_dataframe(layout))
    _assert_same(sm, r)
    assert r.topology.name == "kinect_v2"


def test_dataframe_long_layout_columns():
    a = SkeletonSequence(_walk(T=2), TOPO, confidence=np.ones((2, 3)))
    df = a.to_dataframe()
    assert list(df.columns) == ["frame", "keypoint", "x", "y", "confidence"]
    assert df["keypoint"].tolist() == ["snout", "leftear", "rightear"] * 2
    assert df["frame"].tolist() == [0, 0, 0, 1, 1, 1]
    np.testing.assert_array_equal(df["x"].to_numpy(), a.positions[..., 0].ravel())


def test_dataframe_written_by_hand_and_deeplabcut_style():
    long = pd.DataFrame({
        "frame": [1, 0, 0, 1], "bodypart": ["nose", "nose", "tail", "tail"],
        "x": [1.0, 2.0, 3.0, 4.0], "y": [5.0, 6.0, 7.0, 8.0], "likelihood": [0.5, 1, 1, 0.25],
    })  # fmt: skip
    (s,) = tk.from_dataframe(long)
    assert s.joint_names == ("nose", "tail") and s.units is None and s.n_dims == 2
    np.testing.assert_array_equal(s.positions[:, 0], [[2, 6], [1, 5]])
    np.testing.assert_array_equal(s.confidence, [[1, 1], [0.5, 0.25]])
    # DeepLabCut's multi-animal table: scorer / individuals / bodyparts / coords
    cols = pd.MultiIndex.from_product(
        [["DLC_resnet50"], ["m1", "m2"], ["nose", "tail"], ["x", "y", "likelihood"]],
        names=["scorer", "individuals", "bodyparts", "coords"],
    )
    df = pd.DataFrame(np.arange(24.0).reshape(2, 12) / 24, columns=cols)
    m1, m2 = tk.from_dataframe(df)
    assert (m1.body_id, m2.body_id) == ("m1", "m2")
    np.testing.assert_array_equal(m2.confidence, df["DLC_resnet50", "m2"].xs(
        "likelihood", axis=1, level="coords").to_numpy())  # fmt: skip
    with pytest.raises(ValueError, match="keypoint"):
        tk.from_dataframe(pd.DataFrame({"a": [1]}))
    with pytest.raises(ValueError, match="twice"):
        tk.from_dataframe(pd.concat([long, long]))
    with pytest.raises(TypeError, match="DataFrame"):
        tk.from_dataframe(np.zeros(3))


@settings(max_examples=25, deadline=None)
@given(
    T=st.integers(1, 6),
    J=st.integers(1, 4),
    D=st.sampled_from([2, 3]),
    layout=st.sampled_from(["long", "wide"]),
    seed=st.integers(0, 2**16),
)
def test_dataframe_round_trip_property(T, J, D, layout, seed):
    rng = np.random.default_rng(seed)
    pos = rng.normal(size=(T, J, D))
    pos[rng.uniform(size=(T, J)) < 0.2] = np.nan
    conf = np.where(rng.uniform(size=(T, J)) < 0.2, np.nan, rng.uniform(size=(T, J)))
    s = SkeletonSequence(pos, Topology.from_names([f"p{j}" for j in range(J)]), confidence=conf)
    (r,) = tk.from_dataframe(s.to_dataframe(layout))
    if np.isnan(conf).all():
        s = s.replace(confidence=None)
    _assert_same(s, r)


def test_read_csv_of_a_tobitkf_csv_is_a_dataframe_from_dataframe_reads(tmp_path):
    """``pandas.read_csv`` of tobitkf's own CSV (the flat layout) gives, through
    ``from_dataframe``, the samples ``tk.load`` reads from the file (another reader)."""
    rng = np.random.default_rng(6)
    conf = rng.uniform(0, 1, (25, 3))
    ts = np.cumsum(rng.uniform(0.02, 0.05, 25))
    a = SkeletonSequence(_walk(T=25), TOPO, timestamps=ts, confidence=conf, units="px",
                         body_id=3)  # fmt: skip
    b = a.replace(positions=_walk(T=25, seed=7), body_id=8)
    k = tk.SkeletonSequence(_walk(T=30, J=25, D=3) / 100, "kinect_v2", fps=30.0,
                            tracking_state=rng.integers(0, 3, (30, 25)))  # fmt: skip
    for seqs, name in [([a, b], "two.csv"), ([tk.smooth(k)], "smoothed.csv")]:
        path = tmp_path / name
        tk.save(seqs, path)
        via_pandas = tk.from_dataframe(pd.read_csv(path))
        from_file = tk.load(path)
        assert len(via_pandas) == len(from_file) == len(seqs)
        for x, y in zip(via_pandas, from_file, strict=True):
            _assert_same_samples(x, y)
    with pytest.raises(ValueError, match="flat columns"):
        tk.from_dataframe(pd.DataFrame({"a_x": [1.0], "a_q": [2.0]}))
    # R's names, <keypoint>.x: the same sequence
    df = pd.read_csv(tmp_path / "two.csv")
    dotted = df.rename(columns=lambda c: c[::-1].replace("_", ".", 1)[::-1] if "_" in c else c)
    assert "snout.x" in dotted.columns
    for x, y in zip(tk.from_dataframe(dotted), tk.from_dataframe(df), strict=True):
        _assert_same_samples(x, y)


@pytest.mark.parametrize(
    ("columns", "match"),
    [
        ({"a_x": [1.0], "a_y": [2.0], "a_z": [3.0], "b_x": [1.0], "b_y": [2.0]}, "_z column"),
        ({"a_x": [1.0], "a_y": [2.0], "subject": [7.0]}, "subject"),
        ({"a_x": [1.0], "a_y": [2.0], "a.x": [1.5]}, "x twice"),
        ({"a_x": [1.0], "a_y": [2.0], "a_state": [1.5]}, "whole numbers"),
        ({"a_x": [1.0], "b_y": [2.0]}, r"without a _x column: \[.b.\]"),
    ],
)
def test_a_flat_table_the_csv_reader_would_refuse_is_refused(columns, match):
    """As strict as ``tk.load`` of the same CSV: nothing read silently wrong (a missing
    _z as NaN, a state truncated, a column dropped or one of two taken)."""
    with pytest.raises(ValueError, match=match):
        tk.from_dataframe(pd.DataFrame(columns))


def test_a_flat_table_with_states_for_some_keypoints_and_a_frame_column():
    df = pd.DataFrame({"frame": [0, 1], "a_x": [1.0, 2.0], "a_y": [0.0, 0.0],
                       "a_state": [1, 2], "b_x": [3.0, 4.0], "b_y": [0.0, 0.0]})  # fmt: skip
    (seq,) = tk.from_dataframe(df)
    np.testing.assert_array_equal(seq.tracking_state, [[1, 2], [2, 2]])  # b: tracked
    assert seq.positions.shape == (2, 2, 2)


# ------------------------------------------------------------------------------ CSV
def test_csv_reads_in_pandas_without_options_and_back(tmp_path):
    conf = np.random.default_rng(4).uniform(0, 1, (20, 3))
    s = SkeletonSequence(_walk(T=20), TOPO, fps=30.0, confidence=conf, units="px",
                         body_id="mouse1")  # fmt: skip
    path = tmp_path / "kp.csv"
    tk.save(s, path)
    df = pd.read_csv(path)
    assert list(df.columns[:4]) == ["snout_x", "snout_y", "snout_confidence", "leftear_x"]
    np.testing.assert_array_equal(df["snout_x"].to_numpy(), s.positions[:, 0, 0])
    np.testing.assert_array_equal(df["rightear_confidence"].to_numpy(), conf[:, 2])
    (r,) = tk.load(path)
    _assert_same(s, r)
    # pandas writes it back with its index column: still readable
    df.to_csv(tmp_path / "again.csv")
    assert pd.read_csv(tmp_path / "again.csv").columns[0] == "Unnamed: 0"
    (r2,) = tk.load(tmp_path / "again.csv", format="csv")
    np.testing.assert_array_equal(r2.positions, s.positions)
    np.testing.assert_array_equal(r2.confidence, conf)
    assert r2.units is None  # no sidecar: 2-D positions in unknown units


def test_dataframe_ids_are_python_values_and_messages_name_the_table():
    """A body id read from a table is an int (not numpy's int64: json, equality with
    ids elsewhere); a table without individuals is 'the table' in messages."""
    df = pd.DataFrame(
        {"individual": [3, 3, 7, 7], "keypoint": ["a", "b", "a", "b"], "frame": [0, 0, 0, 0],
         "x": [1.0, 2.0, 3.0, 4.0], "y": [0.0, 0.0, 0.0, 0.0]}
    )  # fmt: skip
    ids = [s.body_id for s in tk.from_dataframe(df)]
    assert ids == [3, 7] and all(type(i) is int for i in ids)
    with pytest.raises(ValueError, match=r"^the table: a keypoint appears twice"):
        tk.from_dataframe(df.drop(columns="individual"))


def test_a_tracking_state_that_is_no_code_is_refused():
    """2.7 used to be read as state 2 without a word."""
    df = pd.DataFrame({"keypoint": ["a", "b"], "frame": [0, 0], "x": [1.0, 2.0],
                       "y": [0.0, 0.0], "tracking_state": [2.0, 2.7]})  # fmt: skip
    with pytest.raises(
        ValueError, match=r"tracking_state holds codes \(whole numbers\); found 2\.7"
    ):
        tk.from_dataframe(df)
    assert tk.from_dataframe(df.assign(tracking_state=[2.0, 1.0]))[0].tracking_state.tolist() == [
        [2, 1]
    ]


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        ({"confidance": [0.5, 0.9]}, r"'confidance': did you mean 'confidence'\?"),
        ({"subject": [7, 7]}, r"unexpected column\(s\) \['subject'\]"),
        ({"confidence": [1.0, 1.0], "likelihood": [0.5, 0.9]}, "a second confidence column"),
    ],
)
def test_a_long_table_with_a_column_it_does_not_know_is_refused(extra, match):
    """A misspelt confidence was dropped without a word (every sample read as certain);
    the long layout refuses a column it has no role for, as the wide and flat ones do,
    and says how to go on."""
    df = pd.DataFrame({"frame": [0, 0], "keypoint": ["a", "b"], "x": [1.0, 2.0],
                       "y": [0.0, 0.0]})  # fmt: skip
    with pytest.raises(ValueError, match=match) as err:
        tk.from_dataframe(df.assign(**extra))
    assert "df.drop(columns=" in str(err.value)
    # the same table without the column reads, as does pandas' index column from a CSV
    (seq,) = tk.from_dataframe(df.assign(**{"Unnamed: 0": [0, 1], "likelihood": [0.5, 0.9]}))
    np.testing.assert_array_equal(seq.confidence, [[0.5, 0.9]])
