"""NTU RGB+D .skeleton: layout from the data README (§7), multi-body, exact round trips."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tobitkf.io import ReadError, detect_format, load, save
from tobitkf.io.ntu import read_ntu, write_ntu
from tobitkf.skeleton.sequence import SkeletonSequence, TrackingState
from tobitkf.skeleton.topology import get_topology

ID_A = 72057594037931101
ID_B = 72057594037931102


def _joint_line(t: int, body: int, j: int) -> str:
    x, y, z = 0.1 * j + t, -0.2 + 0.01 * j + body, 2.5 + 0.001 * j
    dx, dy = 200.5 + j, 180.25 - j
    cx, cy = 900.125 + j, 500.75 + t
    w, qx, qy, qz = 0.5, -0.5, 0.5, 0.25 * body
    state = 2 if j % 5 else 1
    return f"{x} {y} {z} {dx} {dy} {cx} {cy} {w} {qx} {qy} {qz} {state}"


def _body_block(t: int, body: int, body_id: int, zero_joint: int | None = None) -> list[str]:
    lines = [f"{body_id} 0 1 2 {body} 1 0 {0.125 * body} -0.0625 2", "25"]
    for j in range(25):
        if j == zero_joint:
            lines.append("0 0 0 0 0 0 0 0 0 0 0 0")
        else:
            lines.append(_joint_line(t, body, j))
    return lines


def _handwritten() -> str:
    """3 frames: A and B, then only B (A absent, B has HandRight at 0 0 0), then none."""
    lines = ["3"]
    lines += ["2", *_body_block(0, 0, ID_A), *_body_block(0, 1, ID_B)]
    lines += ["1", *_body_block(1, 1, ID_B, zero_joint=11)]
    lines += ["0"]
    return "\n".join(lines) + "\n"


@pytest.fixture
def ntu_file(tmp_path):
    p = tmp_path / "S001C001P001R001A001.skeleton"
    p.write_text(_handwritten())
    return p


def test_layout_values(ntu_file):
    assert detect_format(ntu_file) == "ntu"
    seqs = load(ntu_file)
    assert [s.body_id for s in seqs] == [ID_A, ID_B]
    a, b = seqs
    assert a.topology is get_topology("kinect_v2")
    assert a.n_frames == b.n_frames == 3
    assert a.fps == 30.0
    # body A: frame 0 only
    for j in range(25):
        expected = [float(v) for v in _joint_line(0, 0, j).split()]
        np.testing.assert_array_equal(a.positions[0, j], expected[:3])
        np.testing.assert_array_equal(a.metadata["depth_xy"][0, j], expected[3:5])
        np.testing.assert_array_equal(a.metadata["color_xy"][0, j], expected[5:7])
        np.testing.assert_array_equal(a.metadata["orientations"][0, j], expected[7:11])
        assert a.tracking_state[0, j] == expected[11]
    assert np.isnan(a.positions[1:]).all()
    assert (a.tracking_state[1:] == TrackingState.NOT_TRACKED).all()
    np.testing.assert_array_equal(a.metadata["ntu_present"], [True, False, False])
    assert a.metadata["ntu_body"]["handLeftState"][0] == 2
    assert a.metadata["ntu_body"]["leanX"][0] == 0.0
    assert b.metadata["ntu_body"]["leanX"][0] == 0.125
    assert b.metadata["ntu_body"]["leanY"][1] == -0.0625
    assert b.metadata["ntu_body"]["trackingState"][1] == 2
    # body B: the zero joint is missing, not at the origin
    assert np.isnan(b.positions[1, 11]).all()
    assert b.tracking_state[1, 11] == TrackingState.NOT_TRACKED
    assert not np.isnan(b.positions[1, 10]).any()
    assert np.isnan(b.positions[2]).all()


def test_round_trip_exact(ntu_file, tmp_path):
    first = load(ntu_file)
    out = tmp_path / "copy.skeleton"
    save(first, out, format="ntu")
    second = load(out)
    assert len(second) == len(first)
    for s1, s2 in zip(first, second, strict=True):
        assert s1.body_id == s2.body_id
        np.testing.assert_array_equal(s1.positions, s2.positions)
        np.testing.assert_array_equal(s1.tracking_state, s2.tracking_state)
        for key in ("depth_xy", "color_xy", "orientations", "ntu_joint_state", "ntu_present"):
            np.testing.assert_array_equal(s1.metadata[key], s2.metadata[key])
        for k, v in s1.metadata["ntu_body"].items():
            np.testing.assert_array_equal(v, s2.metadata["ntu_body"][k])
    # writing again gives the same bytes; and the original numbers are all preserved
    out2 = tmp_path / "copy2.skeleton"
    write_ntu(second, out2)
    assert out.read_text() == out2.read_text()
    orig = [float(v) for v in ntu_file.read_text().split()]
    back = [float(v) for v in out.read_text().split()]
    assert orig == back


def test_a_frame_selection_keeps_the_body_fields(ntu_file, tmp_path):
    """The per-body fields (a dict of per-frame arrays) follow a frame selection into
    the written file: body B's frame 1 reads back with the file's values, not zeros."""
    b = load(ntu_file)[1].select_frames([1])
    save([b], tmp_path / "one.skeleton", format="ntu")
    (back,) = load(tmp_path / "one.skeleton")
    fields = "clippedEdges handLeftConfidence handLeftState handRightConfidence "
    fields += "handRightState isRestricted leanX leanY trackingState"
    written = dict(zip(fields.split(), [0, 1, 2, 1, 1, 0, 0.125, -0.0625, 2], strict=True))
    for name, value in written.items():
        np.testing.assert_array_equal(back.metadata["ntu_body"][name], [value])
    np.testing.assert_array_equal(back.positions[0, 10], b.positions[0, 10])


def test_writer_refuses_frames_it_would_read_at_other_times(tmp_path):
    """An NTU file has no times and is read at 30 fps: a 15 fps sequence, or one with a
    dropped frame, is refused; 30 fps with jitter is written."""
    rng = np.random.default_rng(4)
    pos = rng.normal(size=(6, 25, 3))
    p = tmp_path / "x.skeleton"
    for seq, frame in (
        (SkeletonSequence(pos, "kinect_v2", fps=15.0), 1),
        (SkeletonSequence(pos, "kinect_v2", timestamps=np.r_[0, 1, 2, 4, 5, 6] / 30), 3),
    ):
        with pytest.raises(ValueError, match=rf"30 Hz.*frame {frame},"):
            write_ntu([seq], p)
        assert not p.exists()
    jitter = np.array([0, 4, -3, 5, 0, 2]) * 1e-3
    write_ntu([SkeletonSequence(pos, "kinect_v2", timestamps=np.arange(6) / 30 + jitter)], p)
    assert load(p)[0].n_frames == 6


def test_writer_from_plain_sequence(tmp_path):
    rng = np.random.default_rng(3)
    pos = rng.normal(size=(4, 25, 3))
    pos[2, 5] = np.nan
    pos[3] = np.nan  # absent body in the last frame
    state = np.full((4, 25), 2)
    state[1, 7] = 1
    s = SkeletonSequence(pos, "kinect_v2", tracking_state=state, body_id=7)
    p = tmp_path / "x.skeleton"
    save(s, p)
    (r,) = load(p)
    assert r.body_id == 7
    np.testing.assert_array_equal(r.positions, pos)
    assert r.tracking_state[1, 7] == 1 and r.tracking_state[2, 5] == 0
    lines = p.read_text().split("\n")
    assert lines[0] == "4" and lines[1] == "1" and lines[3] == "25"
    assert len(lines[2].split()) == 10 and len(lines[4].split()) == 12
    assert p.read_text().split("\n")[-2] == "0"  # last frame: no body


@pytest.mark.parametrize(("units", "per_metre"), [("m", 1.0), ("cm", 100.0), ("mm", 1000.0)])
def test_writer_converts_lengths_to_metres(tmp_path, units, per_metre):
    """The file holds metres (NTU RGB+D's camera space): a sequence in centimetres or
    millimetres is written converted (it was written as its numbers, read back as
    metres 100 or 1000 times too large), and read back as the metres it stands for."""
    rng = np.random.default_rng(5)
    metres = rng.normal(scale=0.5, size=(3, 25, 3))
    s = SkeletonSequence(metres * per_metre, "kinect_v2", units=units)
    p = tmp_path / f"x_{units}.skeleton"
    save(s, p)
    (r,) = load(p)
    assert r.units == "m"
    np.testing.assert_allclose(r.positions, metres, rtol=0, atol=1e-6)  # (the text's digits)


def test_writer_refuses_what_is_not_metres_in_3d(tmp_path):
    """2-D keypoints and 3-D positions in unknown units have no NTU form: a clear error,
    not numpy's reshape message nor numbers labelled as metres."""
    pos = np.zeros((2, 25, 3))
    with pytest.raises(ValueError, match="positions are 2-D"):
        save(SkeletonSequence(pos[..., :2], "kinect_v2", units="px"), tmp_path / "a.skeleton")
    with pytest.raises(ValueError, match="units are None"):
        save(SkeletonSequence(pos, "kinect_v2", units=None), tmp_path / "b.skeleton")
    assert not (tmp_path / "a.skeleton").exists() and not (tmp_path / "b.skeleton").exists()


def test_writer_rejects_non_kinect_v2(tmp_path):
    s = SkeletonSequence(np.zeros((2, 21, 3)), "kinect_v2_21")
    with pytest.raises(ValueError, match="25 Kinect V2 joints"):
        save(s, tmp_path / "x.skeleton")


@pytest.mark.parametrize(
    ("mutate", "line", "match"),
    [
        (lambda ls: ls[:40], 40, "truncated"),
        (lambda ls: [*ls[:3], "24", *ls[4:]], 4, "expected 25 joints, found 24"),
        (lambda ls: [*ls[:6], "0.1 0.2 abc" + " 0" * 9, *ls[7:]], 7, "field 3"),
        (lambda ls: [*ls[:6], "0.1 0.2", *ls[7:]], 7, "expected 12 values"),
        (lambda ls: ["x", *ls[1:]], 1, "number of frames"),
        (lambda ls: [*ls, "5"], 86, "end of file"),
        (lambda ls: [*ls[:2], "1 2 3", *ls[3:]], 3, "10 body values"),
        (lambda ls: [*ls[:6], " ".join(["0.5"] * 11 + ["7"]), *ls[7:]], 7, "tracking state"),
    ],
)
def test_errors_name_the_line(tmp_path, mutate, line, match):
    lines = _handwritten().rstrip("\n").split("\n")
    p = tmp_path / "bad.skeleton"
    p.write_text("\n".join(mutate(lines)) + "\n")
    with pytest.raises(ReadError, match=match) as info:
        read_ntu(p)
    assert info.value.line == line
    assert str(p) in str(info.value)


def test_empty_file(tmp_path):
    p = tmp_path / "e.skeleton"
    p.write_text("")
    with pytest.raises(ReadError, match="empty"):
        read_ntu(p)
    with pytest.raises(ReadError):
        load(p)


@settings(max_examples=25, deadline=None)
@given(
    st.lists(
        st.lists(st.sampled_from([0, 1, 2]), min_size=0, max_size=3, unique=True),
        min_size=1,
        max_size=5,
    ),
    st.integers(0, 2**32),
)
def test_multibody_round_trip_property(tmp_path_factory, presence, seed):
    """Random presence patterns: every body keeps its frames, absent frames are NaN."""
    rng = np.random.default_rng(seed)
    F = len(presence)
    ids = [ID_A, 5, 123456789]
    lines = [str(F)]
    truth = {i: np.full((F, 25, 3), np.nan) for i in ids}
    for t, bodies in enumerate(presence):
        lines.append(str(len(bodies)))
        for b in bodies:
            lines.append(f"{ids[b]} 0 0 0 0 0 0 0.5 0.25 2")
            lines.append("25")
            xyz = np.round(rng.normal(size=(25, 3)), 6)
            truth[ids[b]][t] = xyz
            for j in range(25):
                lines.append(" ".join(repr(float(v)) for v in xyz[j]) + " 1 2 3 4 1 0 0 0 2")
    d = tmp_path_factory.mktemp("ntu")
    p = d / "r.skeleton"
    p.write_text("\n".join(lines) + "\n")
    seqs = read_ntu(p)
    present_ids = [ids[b] for b in dict.fromkeys(b for fr in presence for b in fr)]
    assert [s.body_id for s in seqs] == present_ids
    for s in seqs:
        np.testing.assert_array_equal(s.positions, truth[s.body_id])
    if not seqs:
        return
    q = d / "w.skeleton"
    write_ntu(seqs, q)
    assert [float(v) for v in q.read_text().split()] == [float(v) for v in p.read_text().split()]


def test_keraal_kinect_to_ntu_keeps_quaternions(tmp_path):
    from conftest import data_file

    (k,) = load(data_file("keraal/G3-Kinect-CTK-P1T1-Unknown-C-0.txt"))
    p = tmp_path / "keraal.skeleton"
    save(k, p)
    (r,) = load(p)
    np.testing.assert_array_equal(r.positions, k.positions)
    np.testing.assert_array_equal(r.metadata["orientations"], k.metadata["orientations"])
    # orientation columns 8-11 of a joint line are w, x, y, z (README layout)
    line = p.read_text().split("\n")[4].split()
    np.testing.assert_array_equal([float(v) for v in line[7:11]], k.metadata["orientations"][0, 0])
