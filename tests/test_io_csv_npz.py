"""Generic CSV and NPZ: documented layout, exact round trips, multi-body."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import tobitkf as tk
from conftest import data_file
from tobitkf.io import ReadError, detect_format, load, save
from tobitkf.io._text import NUMBER, fmt_floats
from tobitkf.io.generic_csv import read_csv
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology, get_topology


def _assert_same(a: SkeletonSequence, b: SkeletonSequence, *, metadata: bool = False):
    np.testing.assert_array_equal(a.positions, b.positions)
    if a.tracking_state is None:
        assert b.tracking_state is None
    else:
        np.testing.assert_array_equal(a.tracking_state, b.tracking_state)
    if a.timestamps is None:
        assert b.timestamps is None
    else:
        np.testing.assert_array_equal(a.timestamps, b.timestamps)
    assert a.fps == b.fps
    assert a.body_id == b.body_id
    assert a.topology == b.topology


def test_handwritten_csv(tmp_path):
    p = tmp_path / "walk.csv"
    p.write_text(
        "timestamp,Pelvis_x,Pelvis_y,Pelvis_z,Pelvis_state,LeftKnee_X,LeftKnee_Y,LeftKnee_Z\n"
        "0.0,1,2,3,2,4,5,6\n"
        "0.04,1.5,,3,1,4,5,nan\n"
    )
    assert detect_format(p) == "csv"
    (s,) = load(p)
    assert s.joint_names == ("Pelvis", "LeftKnee")
    np.testing.assert_array_equal(s.timestamps, [0.0, 0.04])
    np.testing.assert_array_equal(s.positions[0], [[1, 2, 3], [4, 5, 6]])
    assert np.isnan(s.positions[1, 0, 1]) and np.isnan(s.positions[1, 1, 2])
    np.testing.assert_array_equal(s.tracking_state[:, 0], [2, 1])
    assert (s.tracking_state[:, 1] == 2).all()  # no state column: tracked


def test_csv_na_is_a_missing_value_like_an_empty_field(tmp_path):
    """R's write.csv writes NA for a missing value; read as the empty field is."""
    rows = ["0.1,0.2,2,5,6,7", "{m},{m},{m},5,{m},7", "0.3,0.4,2,{m},6,{m}"]
    read = {}
    for m in ("", "NA", "na", " NA ", "NaN", "nan"):
        p = tmp_path / f"m{len(read)}.csv"
        p.write_text("a_x,a_y,a_z,b_x,b_y,b_z\n" + "".join(r.format(m=m) + "\n" for r in rows))
        assert detect_format(p) == "csv"
        (read[m],) = load(p)
    for m, seq in read.items():
        np.testing.assert_array_equal(seq.positions, read[""].positions, err_msg=repr(m))
    np.testing.assert_array_equal(read["NA"].positions[0], [[0.1, 0.2, 2], [5, 6, 7]])
    assert np.isnan(read["NA"].positions[1, 0]).all() and read["NA"].positions[1, 1, 0] == 5
    assert np.isnan(read["NA"].positions[1, 1, 1])
    p.write_text("a_x,a_y,a_z\n1,NAN1,3\n")  # a word starting with NA is no number
    with pytest.raises(ReadError, match="field 2") as e:
        read_csv(p)
    assert e.value.line == 2


def test_csv_dot_joined_column_names_read_like_underscored_ones(tmp_path):
    """R's data.frame names (a.x, a.y, a.z) are the documented layout with '.' for '_'."""
    body = "0.1,0.2,2,0.9,5,6,7,2\n0.3,,2.5,0.8,NA,6,7,1\n"
    under, dot = tmp_path / "under.csv", tmp_path / "dot.csv"
    under.write_text("a_x,a_y,a_z,a_sd,b_X,b_Y,b_Z,b_state\n" + body)
    dot.write_text("a.x,a.y,a.z,a.sd,b.X,b.Y,b.Z,b.state\n" + body)
    assert detect_format(dot) == "csv"
    (u,), (d,) = load(under), load(dot)
    assert d.joint_names == ("a", "b")
    _assert_same(u, d)
    np.testing.assert_array_equal(d.std, u.std)
    np.testing.assert_array_equal(d.tracking_state[:, 1], [2, 1])
    np.testing.assert_array_equal(d.positions[0], [[0.1, 0.2, 2], [5, 6, 7]])
    # round trip: written back with '_', read the same
    save(d, tmp_path / "back.csv")
    _assert_same(d, load(tmp_path / "back.csv")[0])


def test_csv_dot_keeps_every_underscored_layout_as_it_was(tmp_path):
    p = tmp_path / "names.csv"
    # '_x' wins: a.b_x is the joint 'a.b'; p_q.x is the joint 'p_q'
    p.write_text("a.b_x,a.b_y,a.b_z,p_q.x,p_q.y,p_q.z\n1,2,3,4,5,6\n")
    (s,) = load(p)
    assert s.joint_names == ("a.b", "p_q")
    np.testing.assert_array_equal(s.positions[0], [[1, 2, 3], [4, 5, 6]])
    p.write_text("u.x,u.y,u.confidence\n1,2,0.5\n")  # 2-D keypoint with a score
    (s,) = load(p)
    assert s.n_dims == 2 and s.confidence[0, 0] == 0.5


@pytest.mark.parametrize(
    ("text", "line", "match"),
    [
        ("a.x,a_y,a.z\n1,2,3\n", 1, r"expected columns \['a\.x', 'a\.y', 'a\.z'\]"),
        ("a.x,a.y,a.w\n1,2,3\n", 1, "expected columns"),  # a third axis was meant
        # NA is a missing value, so not a body id
        ("body,a_x,a_y,a_z\n1,0,0,0\nNA,0,0,0\n", 3, "expected a body id, found an empty"),
        ("time,a_x,a_z\n", 1, "expected columns"),
        ("a_x,a_y,a_z,b_x,b_y\n", 1, "expected columns"),  # 3-D and 2-D joints mixed
        ("a_x,a_y,a_z\n1,2\n", 2, "expected 3 values"),
        ("a_x,a_y,a_z\n1,2,x\n", 2, "field 3"),
        ("a_x,a_y,a_z,foo\n1,2,3,4\n", 1, "unexpected column 'foo'"),
        ("time,a_x,a_y,a_z\n1,0,0,0\n0.5,0,0,0\n", 3, r"non-decreasing .*found 0\.5 after 1\.0"),
        ("time,a_x,a_y,a_z\n0,0,0,0\n,1,1,1\n", 3, "expected a time value, found an empty"),
        ("a_x,a_y,a_z,a_state\n1,2,3,7\n", 2, "state 0, 1 or 2"),
    ],
)
def test_csv_errors(tmp_path, text, line, match):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(ReadError, match=match) as e:
        read_csv(p)
    assert e.value.line == line


def test_csv_empty(tmp_path):
    p = tmp_path / "e.csv"
    p.write_text("\n\n# topology: kinect_v2\n")
    with pytest.raises(ReadError, match="empty"):
        read_csv(p)


def _random_sequence(rng, T, topo, *, state=True, times=True, fps=30.0, body_id=None):
    pos = rng.normal(size=(T, topo.n_joints, 3))
    pos[rng.random(pos.shape[:2]) < 0.1] = np.nan
    st_ = rng.integers(0, 3, size=(T, topo.n_joints)) if state else None
    ts = np.cumsum(rng.uniform(0.01, 0.1, size=T)) if times else None
    return SkeletonSequence(pos, topo, st_, ts, fps, body_id, {"source": "x"})


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 12), st.booleans(), st.booleans(), st.integers(0, 2**32),
       st.sampled_from(["kinect_v2", "kinect_v2_21", "ui_prmd", "custom"]))  # fmt: skip
def test_csv_round_trip_property(tmp_path_factory, T, state, times, seed, topo_name):
    rng = np.random.default_rng(seed)
    topo = (
        Topology.from_names(["a", "b"], up_axis=2, name="custom")
        if topo_name == "custom"
        else get_topology(topo_name)
    )
    s = _random_sequence(rng, T, topo, state=state, times=times)
    p = tmp_path_factory.mktemp("csv") / "r.csv"
    save(s, p)
    (r,) = load(p)
    _assert_same(s, r)


@settings(max_examples=200, deadline=None)
@given(hnp.arrays(np.float64, hnp.array_shapes(max_dims=3, max_side=6), elements=st.floats()))
def test_fmt_floats_reads_back_bit_for_bit(a):
    texts = fmt_floats(a, nan="gone")
    flat = a.reshape(-1)
    assert len(texts) == flat.size
    for v, text in zip(flat.tolist(), texts, strict=True):
        if v != v:
            assert text == "gone"
        elif np.isinf(v):
            assert text == repr(v)
        else:  # the reader's number syntax, and the same bits (sign of zero included)
            assert NUMBER.fullmatch(text), text
            assert np.float64(float(text)).tobytes() == np.float64(v).tobytes()
            assert len(text.lstrip("-").replace(".", "").lstrip("0")) <= 24  # not %.40g


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32))
def test_csv_round_trip_of_tiny_huge_and_subnormal_values_and_sd(tmp_path_factory, seed):
    rng = np.random.default_rng(seed)
    topo = get_topology("kinect_v2")
    T = 5
    mag = 10.0 ** rng.uniform(-320, 3, size=(T, topo.n_joints, 3))  # subnormals to 1 km
    pos = np.where(rng.random(mag.shape) < 0.5, -mag, mag)
    pos[0, 0] = [0.0, -0.0, 5e-324]
    sd = 10.0 ** rng.uniform(-12, 0, size=(T, topo.n_joints))
    sd[1, 1] = np.nan
    s = SkeletonSequence(pos, topo, None, None, 30.0, None, {}, std=sd)
    p = tmp_path_factory.mktemp("csv") / "r.csv"
    save(s, p)
    (r,) = load(p)
    np.testing.assert_array_equal(np.signbit(r.positions), np.signbit(pos))
    _assert_same(s, r)
    np.testing.assert_array_equal(r.std, sd)


def test_csv_multibody_round_trip(tmp_path):
    rng = np.random.default_rng(5)
    topo = get_topology("kinect_v2")
    seqs = [_random_sequence(rng, 4, topo, body_id=b) for b in (11, 12)]
    p = tmp_path / "m.csv"
    save(seqs, p, format="csv")
    back = load(p)
    assert len(back) == 2
    for a, b in zip(seqs, back, strict=True):
        _assert_same(a, b)


def test_csv_multibody_keeps_64_bit_ids_and_never_merges_bodies(tmp_path):
    rng = np.random.default_rng(6)
    topo = get_topology("kinect_v2")
    p = tmp_path / "m.csv"
    # NTU body ids exceed 2**53: as floats these two would be one body
    ntu = [
        _random_sequence(rng, 4, topo, body_id=b) for b in (72057594037931101, 72057594037931102)
    ]
    save(ntu, p, format="csv")
    back = load(p)
    assert [s.body_id for s in back] == [72057594037931101, 72057594037931102]
    for a, b in zip(ntu, back, strict=True):
        _assert_same(a, b)
    # ids that are neither all integers nor all names that read back as they are, or
    # that repeat: numbered in the body column, the ids themselves in the sidecar
    for ids in ((1, None), ("a", 2), (3, 3), ("x", "x"), ("1", "2"), ("a,b", "c"), ("NA", "b")):
        seqs = [_random_sequence(rng, 4, topo, body_id=b) for b in ids]
        save(seqs, p, format="csv")
        back = load(p)
        assert [s.body_id for s in back] == list(ids)
        lines = p.read_text().splitlines()
        k = lines[0].split(",").index("body")
        body_column = [ln.split(",")[k] for ln in lines[1:]]
        assert sorted(set(body_column)) == ["0", "1"]
        for a, b in zip(seqs, back, strict=True):
            np.testing.assert_array_equal(a.positions, b.positions)


NAMES = st.text(st.characters(codec="utf-8", exclude_categories=("Cs",)), min_size=1, max_size=8)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.one_of(NAMES, st.integers(-5, 5), st.none()), min_size=2, max_size=4))
def test_csv_body_names_are_in_the_column_and_every_id_comes_back(tmp_path_factory, ids):
    """Whatever the ids (names of any text, numbers, None, repeats), the bodies come back
    apart with their ids, and pandas sees as many bodies in the column as there are."""
    pd = pytest.importorskip("pandas")
    rng = np.random.default_rng(0)
    seqs = [
        _random_sequence(rng, 3, get_topology("kinect_v2"), body_id=b, times=False) for b in ids
    ]
    p = tmp_path_factory.mktemp("csv") / "ids.csv"
    try:
        save(seqs, p, format="csv")
    except ValueError as exc:  # an id the sidecar's JSON cannot hold is refused, not lost
        assert "body id" in str(exc)
        return
    back = load(p)
    assert [s.body_id for s in back] == list(ids)
    column = pd.read_csv(p, keep_default_na=False, dtype={"body": str})["body"]
    assert column.nunique() == len(ids)
    for a, b in zip(seqs, back, strict=True):
        np.testing.assert_array_equal(a.positions, b.positions)


def test_csv_body_names_for_pandas_and_from_a_table_alone(tmp_path):
    """Animals named by the tracker: their names in the body column, so that pandas
    users select them by name; a third-party table with names reads by them."""
    pd = pytest.importorskip("pandas")
    rng = np.random.default_rng(3)
    topo = get_topology("kinect_v2")
    seqs = [_random_sequence(rng, 4, topo, body_id=b) for b in ("mouse1", "mouse 2")]
    p = tmp_path / "two.csv"
    save(seqs, p, format="csv")
    table = pd.read_csv(p)
    assert list(dict.fromkeys(table["body"])) == ["mouse1", "mouse 2"]
    np.testing.assert_array_equal(
        table.loc[table["body"] == "mouse 2", "SpineBase_x"], seqs[1].positions[:, 0, 0]
    )
    back = tk.from_dataframe(table)
    assert [s.body_id for s in back] == ["mouse1", "mouse 2"]
    third = tmp_path / "third.csv"
    third.write_text("time,body,a_x,a_y\n0,left,1,2\n0,7,3,4\n0.1,left,5,6\n0.1,7,7,8\n")
    left, seven = load(third)
    assert (left.body_id, seven.body_id) == ("left", 7)
    np.testing.assert_array_equal(left.positions[:, 0], [[1, 2], [5, 6]])
    np.testing.assert_array_equal(seven.positions[:, 0], [[3, 4], [7, 8]])
    # without a time column the body's field starts the row: a name starting with the
    # comment mark would hide the row
    hashed = [_random_sequence(rng, 4, topo, body_id=b, times=False) for b in ("#a", "b")]
    save(hashed, p, format="csv")
    assert p.read_text().splitlines()[0].startswith("body,")
    assert [s.body_id for s in load(p)] == ["#a", "b"]


POOL = ("snout", "ear_left", "ear_right", "tail", "corner_a", "corner_b")


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.permutations(POOL).flatmap(lambda p: st.integers(1, 6).map(lambda k: p[:k])),
             min_size=2, max_size=4),
    st.integers(1, 5),
    st.booleans(),
    st.integers(0, 2**31),
)  # fmt: skip
def test_csv_bodies_with_different_joints_round_trip(tmp_path_factory, joint_sets, T, extra, seed):
    """Bodies of different joints (in any order) share one table: the union's columns,
    each body's own joints, order, bones and values back from the sidecar."""
    rng = np.random.default_rng(seed)
    seqs = []
    for k, names in enumerate(joint_sets):
        J = len(names)
        parents = [-1] + [int(rng.integers(0, j)) for j in range(1, J)]
        pos = rng.normal(size=(T, J, 2)) * 100
        pos[rng.random((T, J)) < 0.2] = np.nan
        seqs.append(
            SkeletonSequence(
                pos, Topology.from_names(list(names), parents, name=f"t{k}"), fps=30.0,
                body_id=f"animal{k}", units="px",
                confidence=rng.random((T, J)) if extra else None,
                std=rng.random((T, J)) if extra else None,
            )
        )  # fmt: skip
    p = tmp_path_factory.mktemp("csv") / "ma.csv"
    save(seqs, p, format="csv")
    pd = pytest.importorskip("pandas")
    union = list(dict.fromkeys(n for names in joint_sets for n in names))
    table = pd.read_csv(p)
    assert [c[: -len("_x")] for c in table.columns if c.endswith("_x")] == union
    assert len(table) == T * len(seqs)
    back = load(p)
    assert [s.body_id for s in back] == [s.body_id for s in seqs]
    for a, b in zip(seqs, back, strict=True):
        assert b.joint_names == a.joint_names
        assert b.topology.parents == a.topology.parents
        np.testing.assert_array_equal(b.positions, a.positions)
        for name in ("confidence", "std"):
            np.testing.assert_array_equal(getattr(b, name), getattr(a, name))
    # the table alone (no sidecar): every body gets the union, NaN where it had no joint;
    # the names are in the body column
    save(seqs, p, format="csv", sidecar=False)
    p.with_suffix(".json").unlink()
    assert list(dict.fromkeys(table["body"])) == [s.body_id for s in seqs]
    for a, b in zip(seqs, load(p), strict=True):
        assert b.body_id == a.body_id
        assert list(b.joint_names) == union
        np.testing.assert_array_equal(b.select_joints(a.joint_names).positions, a.positions)


def test_csv_sidecar_body_joints_are_checked(tmp_path):
    import json

    a = SkeletonSequence(np.zeros((2, 2, 2)), Topology.from_names(["a", "b"]), body_id="x")
    c = SkeletonSequence(np.ones((2, 1, 2)), Topology.from_names(["c"]), body_id="y")
    p = tmp_path / "m.csv"
    save([a, c], p, format="csv")
    side = p.with_suffix(".json")
    doc = json.loads(side.read_text())
    assert [b["joints"] for b in doc["bodies"]] == [["a", "b"], ["c"]]
    for joints, words in ((["a", "zz"], "'zz' has no columns"), (["a", "a"], "repeat"),
                          ("a", "list of names"), ([], "list of names")):  # fmt: skip
        doc["bodies"][0]["joints"] = joints
        doc["bodies"][0].pop("parents", None)
        side.write_text(json.dumps(doc))
        with pytest.raises(ReadError, match=words):
            load(p)
    doc["bodies"][0]["joints"], doc["bodies"][0]["parents"] = ["a", "b"], [-1]
    side.write_text(json.dumps(doc))
    with pytest.raises(ReadError, match="parent index for each"):
        load(p)


@settings(max_examples=20, deadline=None)
@given(
    hnp.arrays(
        np.float64,
        st.tuples(st.integers(1, 6), st.just(25), st.just(3)),
        elements=st.floats(-5, 5) | st.just(np.nan),
    ),
    st.one_of(st.none(), st.integers(-(2**62), 2**62), st.text(max_size=5)),
)
def test_npz_round_trip_property(tmp_path_factory, pos, body_id):
    T = pos.shape[0]
    meta = {
        "source": "s",
        "orientations": np.arange(T * 25 * 4, dtype=float).reshape(T, 25, 4),
        "nested": {"a": [1, 2.5, None, "x", (3, 4)], "arr": np.array([1, 2], dtype=np.int8)},
        "nan": float("nan"),
    }
    s = SkeletonSequence(pos, "kinect_v2", np.full((T, 25), 1), None, 15.0, body_id, meta)
    p = tmp_path_factory.mktemp("npz") / "r.npz"
    save(s, p)
    assert detect_format(p) == "npz"
    (r,) = load(p)
    _assert_same(s, r)
    np.testing.assert_array_equal(r.metadata["orientations"], meta["orientations"])
    assert r.metadata["nested"]["a"] == [1, 2.5, None, "x", (3, 4)]
    assert r.metadata["nested"]["arr"].dtype == np.int8
    assert np.isnan(r.metadata["nan"])


def test_npz_real_multibody_kimore_and_keraal(tmp_path):
    kim = load(data_file("kimore/JointPositionExercise1.csv"))[0]
    ker = load(data_file("keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt"))[0].replace(body_id="b")
    p = tmp_path / "two.npz"
    save([kim, ker], p)
    a, b = load(p)
    _assert_same(kim, a)
    _assert_same(ker, b)
    np.testing.assert_array_equal(b.metadata["orientations"], ker.metadata["orientations"])


def test_npz_garbage(tmp_path):
    p = tmp_path / "x.npz"
    p.write_bytes(b"PK\x03\x04garbage")
    with pytest.raises(ReadError):
        load(p)
    np.savez(p, a=np.zeros(3))
    with pytest.raises(ReadError, match="tobitkf"):
        load(p)


def test_csv_from_real_krajjat(tmp_path):
    (s,) = load(data_file("krajjat/sequence_ainhoa_trimmed.tsv"))
    p = tmp_path / "k.csv"
    save(s, p)
    (r,) = load(p)
    _assert_same(s, r)
    assert r.topology.name == "kinect_v2_21"


def test_an_unrelated_json_beside_a_csv_does_not_make_it_ours(tmp_path):
    from tobitkf.io.generic_csv import sniff_csv

    head = "a_x,a_y,a_z\n0,0,0\n"
    (tmp_path / "x.csv").write_text(head)
    alone = sniff_csv(tmp_path / "x.csv", head)
    (tmp_path / "x.json").write_text('{"landmarks": []}')  # e.g. another tool's output
    assert sniff_csv(tmp_path / "x.csv", head) == alone
