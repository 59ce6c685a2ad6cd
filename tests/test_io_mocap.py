"""Optical motion-capture formats: Qualisys TSV, C3D and BVH (real files + hand-made)."""

from __future__ import annotations

import re
from functools import cache

import numpy as np
import pytest

from conftest import data_file
from tobitkf.io import OptionError, ReadError, detect_format, load
from tobitkf.io.bvh import read_bvh
from tobitkf.io.qualisys import read_qualisys

QTM = "krajjat/test_sequence_qtm_2.tsv"
C3D = "btkdata/PiG_Motion-FlatFoot-Full.c3d"
BVH = "cmu-mocap/scaled_131_01.bvh"


@cache
def _load(rel, **kw):
    return load(data_file(rel), **kw)[0]


# ---------------------------------------------------------------------- Qualisys
def test_qualisys_real_file():
    path = data_file(QTM)
    assert detect_format(path) == "qualisys"
    s = _load(QTM)
    assert s.positions.shape == (50, 44, 3)
    assert s.fps == 200.0 and s.topology.up_axis == 2
    assert s.joint_names[0] == "HeadL" and s.joint_names[-1] == "RForefootIn"
    assert s.metadata["declared_frames"] == 15756
    np.testing.assert_allclose(s.timestamps[:3], [0.0, 0.005, 0.01])
    np.testing.assert_allclose(s.dt(), 0.005, atol=1e-9)
    # independent parse of the first data line (line 13): frame, time, then mm values
    row = path.read_text().split("\n")[12].rstrip("\t").split("\t")
    values = np.array([float(v) for v in row[2:]]).reshape(44, 3) / 1000.0
    present = ~np.all(values == 0, axis=-1)
    np.testing.assert_allclose(s.positions[0][present], values[present])
    # QTM writes a gap as 0 0 0: RWristIn is missing in the first frames
    j = s.topology.index("RWristIn")
    assert not present[j] and np.isnan(s.positions[0, j]).all()
    assert s.missing().sum() == 4


def test_qualisys_without_frame_time_columns(tmp_path):
    text = (
        "NO_OF_FRAMES\t2\nNO_OF_MARKERS\t2\nFREQUENCY\t100\nMARKER_NAMES\tA\tB\n"
        "1.0\t2.0\t3.0\t\t5.0\t6.0\n7\t8\t9\t10\t11\t12\n"
    )
    p = tmp_path / "q.tsv"
    p.write_text(text)
    assert detect_format(p) == "qualisys"
    (s,) = read_qualisys(p)
    assert s.timestamps is None and s.fps == 100.0
    np.testing.assert_allclose(s.positions[0, 0], [0.001, 0.002, 0.003])
    assert np.isnan(s.positions[0, 1, 0]) and s.positions[0, 1, 1] == 0.005
    np.testing.assert_allclose(s.positions[1, 1], [0.010, 0.011, 0.012])


def test_qualisys_errors(tmp_path):
    p = tmp_path / "q.tsv"
    p.write_text("NO_OF_FRAMES\t2\nFREQUENCY\t100\n1\t2\t3\n")
    with pytest.raises(ReadError, match="MARKER_NAMES"):
        read_qualisys(p)
    p.write_text("NO_OF_MARKERS\t3\nMARKER_NAMES\tA\tB\n1\t2\t3\t4\t5\t6\n")
    with pytest.raises(ReadError, match="NO_OF_MARKERS says 3"):
        read_qualisys(p)
    p.write_text("MARKER_NAMES\tA\n1\t2\t3\n1\t2\n")
    with pytest.raises(ReadError, match="expected 3 values") as e:
        read_qualisys(p)
    assert e.value.line == 3
    p.write_text("MARKER_NAMES\tA\n1\t2\tx\n")
    with pytest.raises(ReadError, match="field 3") as e:
        read_qualisys(p)
    assert e.value.line == 2
    p.write_text("MARKER_NAMES\tA\nFrame\tTime\tA X\tA Y\tA Z\n1\t0.01\t1\t2\t3\n2\t0\t1\t2\t3\n")
    with pytest.raises(ReadError, match=r"non-decreasing Time values, found 0\.0 after 0\.01") as e:
        read_qualisys(p)
    assert e.value.line == 4
    p.write_text("MARKER_NAMES\tA\nFrame\tTime\tA X\tA Y\tA Z\n1\t\t1\t2\t3\n")
    with pytest.raises(ReadError, match="expected a Time value, found an empty field") as e:
        read_qualisys(p)
    assert e.value.line == 3


# ---------------------------------------------------------------------- C3D
def test_c3d_real_file():
    pytest.importorskip("c3d")
    path = data_file(C3D)
    assert detect_format(path) == "c3d"
    s = _load(C3D, points="all")
    assert s.positions.shape == (315, 193, 3)
    assert s.fps == 100.0 and s.topology.up_axis == 2
    assert s.metadata["units_in_file"] == "mm"
    t = s.topology
    gaps = s.missing()
    assert gaps[:, t.index("LFHD")].sum() == 30
    for lab in ("HEDO", "HEDA", "HEDL", "HEDP", "CentreOfMass"):
        assert gaps[:, t.index(lab)].sum() == 30
    # NaN exactly where the stored residual is negative
    np.testing.assert_array_equal(gaps, s.metadata["residuals"] < 0)
    # metres: shank (knee marker to ankle marker) is 0.3-0.5 m long, constant-ish
    shank = np.linalg.norm(
        s.positions[:, t.index("LKNE")] - s.positions[:, t.index("LANK")], axis=-1
    )
    assert 0.3 < np.nanmedian(shank) < 0.5
    assert np.nanstd(shank) < 0.02
    # z up: head above the ankles; walking: the pelvis travels > 1 m
    assert np.nanmin(s.positions[:, t.index("RFHD"), 2] - s.positions[:, t.index("RANK"), 2]) > 1.2
    pelo = s.positions[:, t.index("PELO")]
    assert np.linalg.norm(pelo[-1, :2] - pelo[0, :2]) > 1.0
    # labels, kinds and residuals follow a joint selection
    kept = ["PELO", "LFHD", "CentreOfMass"]
    sub = s.select_joints(kept)
    assert sub.metadata["labels"] == kept
    assert sub.metadata["point_kinds"] == [s.metadata["point_kinds"][t.index(k)] for k in kept]
    assert sub.metadata["point_kinds"][0] != sub.metadata["point_kinds"][1]  # the test can fail
    np.testing.assert_array_equal(sub.missing(), sub.metadata["residuals"] < 0)


def test_c3d_point_selection():
    pytest.importorskip("c3d")
    path = data_file(C3D)
    everything = _load(C3D, points="all").joint_names
    default = load(path)[0]
    outputs = [
        n for n in everything if any(k in n for k in ("Angle", "Force", "Moment", "Power", "GRF"))
    ]
    assert set(default.joint_names) == set(everything) - set(outputs)
    assert len(outputs) > 50 and "LFHD" in default.joint_names and "PELO" in default.joint_names
    assert {"CentreOfMass", "CentreOfMassFloor"} <= set(default.joint_names)
    markers = load(path, points="markers")[0]
    expected = set(
        "RFHD LBHD RBHD C7 T10 CLAV STRN RBAK LSHO LELB LWRA LWRB LFIN RSHO RELB RWRA RWRB "
        "RFIN LASI RASI LPSI RPSI LTHI LKNE LTIB LANK LHEE LTOE RTHI RKNE RTIB RANK RHEE RTOE "
        "LFHD".split()
    )
    assert set(markers.joint_names) == expected and markers.n_joints == 35
    centres = load(path, points="joint_centres")[0]
    for lab in ("PELO", "LFEO", "RFEO", "LTIO", "RTIO", "LHUO", "RHUO", "LRAO", "RRAO",
                "LHNO", "RHNO", "LCLO", "RCLO", "TRXO", "HEDO"):  # fmt: skip
        assert lab in centres.joint_names
    assert all(n.endswith("O") for n in centres.joint_names)
    with pytest.raises(ValueError, match="points"):
        load(path, points="bones")
    # a bad units= is the caller's mistake, not the file's
    with pytest.raises(OptionError, match="units"):
        load(path, units="furlong")
    in_cm = load(path, units="cm")[0]
    np.testing.assert_allclose(in_cm.positions, 10 * default.positions, equal_nan=True)


def _point_groups(path) -> dict[str, list[str]]:
    """The labels the file lists in POINT:ANGLES, FORCES, MOMENTS and POWERS (C3D's
    non-position point types), read with the c3d library."""
    import c3d

    with open(path, "rb") as fh:
        reader = c3d.Reader(fh)
        return {
            g: [lab.strip() for lab in reader.get(f"POINT:{g}").string_array]
            for g in ("ANGLES", "FORCES", "MOMENTS", "POWERS")
        }


def test_c3d_centre_of_mass_is_kept_and_what_is_left_out_is_counted():
    pytest.importorskip("c3d")
    path = data_file(C3D)
    groups = _point_groups(path)
    typed = {lab for labels in groups.values() for lab in labels}
    assert "CentreOfMass" not in typed  # C3D lists it as none of the non-position types
    s = load(path)[0]
    t = s.topology
    # positions: the floor point is the centre of mass dropped onto the floor (z = 0)
    com, floor = (
        s.positions[:, t.index("CentreOfMass")],
        s.positions[:, t.index("CentreOfMassFloor")],
    )
    np.testing.assert_array_equal(floor[:, :2], com[:, :2])
    assert np.nanmax(np.abs(floor[:, 2])) == 0.0
    assert 0.5 < np.nanmedian(com[:, 2]) < 1.2  # about pelvis height, in metres
    # left out: exactly the typed entries, counted by kind in the reader's note
    assert set(s.joint_names).isdisjoint(typed)
    assert s.n_joints == 193 - len(typed)
    (note,) = [w for w in s.metadata["reader_warnings"] if "left out" in w]
    assert f"left out {len(typed)} of 193 POINT entries (" in note
    for g, labels in groups.items():
        assert f"{len(labels)} {g.lower()}" in note
    # markers only: the centre-of-mass points are among what is left out
    markers = load(path, points="markers")[0]
    assert "CentreOfMass" not in markers.joint_names
    (note,) = markers.metadata["reader_warnings"]
    assert "2 centre-of-mass points" in note and f"left out {193 - 35} of 193" in note
    assert load(path, points="all")[0].metadata["reader_warnings"] == []


def test_c3d_garbage_and_truncation_are_read_errors(tmp_path):
    pytest.importorskip("c3d")
    p = tmp_path / "x.c3d"
    p.write_bytes(b"\x02\x50" + b"\x00" * 100)
    with pytest.raises(ReadError):
        load(p)
    raw = data_file(C3D).read_bytes()
    p.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(ReadError, match="truncated C3D file: expected 315 frames"):
        load(p)


# ---------------------------------------------------------------------- BVH
def test_bvh_real_file():
    path = data_file(BVH)
    assert detect_format(path) == "bvh"
    s = _load(BVH)
    assert s.positions.shape == (995, 31, 3)
    assert s.fps == 120.0
    assert s.topology.up_axis == 1
    names = (
        "Hips LHipJoint LeftHip LeftKnee LeftAnkle LeftToe RHipJoint RightHip RightKnee "
        "RightAnkle RightToe lowerback Chest Chest2 lowerneck Neck Head LeftCollar "
        "LeftShoulder LeftElbow LeftWrist lhand LFingers LThumb RightCollar RightShoulder "
        "RightElbow RightWrist rhand RFingers RThumb"
    ).split()
    assert s.joint_names == tuple(names)
    text = path.read_text().split("\n")
    # independent: OFFSET lines in order, skipping the End Site ones
    offsets, end_next = [], False
    for line in text:
        w = line.split()
        if not w:
            continue
        if w[0] == "End":
            end_next = True
        elif w[0] == "OFFSET":
            if not end_next:
                offsets.append([float(v) for v in w[1:4]])
            end_next = False
        elif w[0] == "MOTION":
            break
    offsets = np.array(offsets)
    assert len(offsets) == 31
    for p, c in s.topology.bones:
        length = np.linalg.norm(s.positions[:, c] - s.positions[:, p], axis=-1)
        np.testing.assert_allclose(length, np.linalg.norm(offsets[c]), atol=1e-9)
    # the root position is the first three channel values of each frame
    m = text.index("MOTION")
    first = [float(v) for v in text[m + 3].split()]
    np.testing.assert_allclose(s.positions[0, 0], first[:3])
    # y up: the head is above the toes
    assert np.all(
        s.positions[:, names.index("Head"), 1] > s.positions[:, names.index("LeftToe"), 1]
    )
    # the offsets are per joint: a joint selection keeps each kept joint's OFFSET line
    np.testing.assert_allclose(s.metadata["offsets"], offsets * s.metadata["scale"])
    kept = ["LeftKnee", "Hips", "RThumb"]
    sub = s.select_joints(kept)
    np.testing.assert_allclose(
        sub.metadata["offsets"], offsets[[names.index(n) for n in kept]] * s.metadata["scale"]
    )


BVH_SMALL = """HIERARCHY
ROOT root
{{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition {root_order}
  JOINT child
  {{
    OFFSET 1 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {{
      OFFSET 0 2 0
    }}
  }}
}}
MOTION
Frames: 2
Frame Time: 0.04
1 2 3 {r0}  0 0 0
0 0 0 {r1}  90 0 0
"""


def test_bvh_forward_kinematics_by_hand(tmp_path):
    p = tmp_path / "s.bvh"
    # frame 0: root rotated 90 deg about z -> child at (1,2,3) + (0,1,0)
    # frame 1: root 90 deg about x; child 90 deg about z; end site (0,2,0):
    #   child = Rx(90)(1,0,0) = (1,0,0); end = child + Rx(90) Rz(90) (0,2,0)
    #   Rz(90)(0,2,0) = (-2,0,0); Rx(90)(-2,0,0) = (-2,0,0) -> end (-1,0,0)
    p.write_text(
        BVH_SMALL.format(root_order="Zrotation Yrotation Xrotation", r0="90 0 0", r1="0 0 90")
    )
    (s,) = read_bvh(p, end_sites=True)
    assert s.joint_names == ("root", "child", "child_End")
    assert s.fps == 25.0
    np.testing.assert_allclose(s.positions[0], [[1, 2, 3], [1, 3, 3], [-1, 3, 3]], atol=1e-12)
    np.testing.assert_allclose(s.positions[1], [[0, 0, 0], [1, 0, 0], [-1, 0, 0]], atol=1e-12)
    # channel order matters: Xrotation Yrotation Zrotation = Rx·Ry·Rz
    p.write_text(
        BVH_SMALL.format(root_order="Xrotation Yrotation Zrotation", r0="90 0 90", r1="0 0 0")
    )
    (s,) = read_bvh(p, end_sites=True, scale=0.5)
    # root R = Rx(90) Rz(90): child offset (1,0,0) -> Rx(90)(0,1,0) = (0,0,1)
    np.testing.assert_allclose(s.positions[0, 1], 0.5 * np.array([1, 2, 4]), atol=1e-12)


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda t: t.replace("Frames: 2", "Frames: 3"), "truncated file: expected 3 frames"),
        (
            lambda t: t.replace("0 0 0 0 0 90  90 0 0", "0 0 0 0 0 90  90 0"),
            "expected 9 values.*found 8",
        ),
        (lambda t: t.replace("Frame Time: 0.04", "Frame Time: 0"), "positive frame time"),
        (lambda t: t.replace("Zrotation Xrotation", "Zrotation Wrotation"), "channel name"),
        (lambda t: t.replace("OFFSET 1 0 0", "OFFSET 1 0"), "three numbers after OFFSET"),
        (lambda t: t.replace("MOTION", "MOTON"), "MOTION"),
        (lambda t: t.replace("HIERARCHY", "HIERARCH"), "HIERARCHY"),
        (lambda t: re.sub(r"\}\s*\}\s*\}", "} }", t), "not closed"),
    ],
)
def test_bvh_errors(tmp_path, edit, match):
    p = tmp_path / "s.bvh"
    p.write_text(edit(BVH_SMALL.format(root_order="Zrotation Yrotation Xrotation", r0="0 0 0",
                                       r1="0 0 90")))  # fmt: skip
    with pytest.raises(ReadError, match=match):
        read_bvh(p)


def test_c3d_labels_made_unique_without_collisions():
    from tobitkf.io.c3d import _unique

    for labels in (["A", "A", "A_2"], ["A", "", "A", "A"], ["", "P1"], ["B_2", "B", "B"]):
        out = _unique(labels)
        assert len(set(out)) == len(out) == len(labels)
        # the first occurrence of a non-empty label keeps its name
        for k, lab in enumerate(labels):
            if lab and lab not in labels[:k]:
                assert out[k] == lab
