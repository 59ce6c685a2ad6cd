"""Kinect text formats on the real files: KIMORE, KERAAL (Kinect + Vicon), krajjat TSV."""

from __future__ import annotations

import time
from functools import cache

import numpy as np
import pytest

from conftest import data_file
from tobitkf.io import ReadError, detect_format, load
from tobitkf.io.keraal import read_keraal_kinect
from tobitkf.io.kimore import read_kimore
from tobitkf.skeleton.sequence import TrackingState

KIMORE = {  # data README §3: frames, leading blank lines, inferred samples, largest jump
    "JointPositionExercise1.csv": (505, 24, 1139, 0.22),
    "JointPositionExercise3.csv": (1031, 18, 4973, 0.72),
    "JointPositionExercise5.csv": (517, 19, 2166, 0.56),
}
KERAAL_KINECT = {"CTK": 197, "ELK": 193, "RTK": 193}
KERAAL_VICON = {"CTK": 390, "ELK": 385, "RTK": 389}


@cache
def _load(rel: str):
    return load(data_file(rel))


def _raw(path, sep=None, strip_comma=False):
    """Independent parse: plain Python, one float per token."""
    rows = []
    for line in path.read_text().splitlines():
        line = line.strip()
        if not line:
            continue
        if strip_comma:
            line = line.rstrip(",")
        rows.append([float(v) for v in line.split(sep)])
    return np.array(rows)


# ---------------------------------------------------------------------- KIMORE
@pytest.mark.parametrize("name", sorted(KIMORE))
def test_kimore_counts_match_readme(name):
    frames, blank, inferred, jump = KIMORE[name]
    path = data_file(f"kimore/{name}")
    assert detect_format(path) == "kimore"
    (s,) = _load(f"kimore/{name}")
    assert s.positions.shape == (frames, 25, 3)
    assert s.topology.name == "kinect_v2" and s.fps == 30.0 and s.timestamps is None
    assert int((s.tracking_state == TrackingState.INFERRED).sum()) == inferred
    assert not (s.tracking_state == TrackingState.NOT_TRACKED).any()
    assert s.largest_jumps()[0].max() == pytest.approx(jump, abs=0.005)
    lines = path.read_text().split("\n")
    assert all(not ln.strip() for ln in lines[:blank]) and lines[blank].strip()
    raw = _raw(path, ",", strip_comma=True).reshape(frames, 25, 4)
    np.testing.assert_array_equal(s.positions, raw[:, :, :3])
    np.testing.assert_array_equal(s.tracking_state, raw[:, :, 3])


def test_kimore_feet_inferred_throughout_ex1():
    (s,) = _load("kimore/JointPositionExercise1.csv")
    for j in ("FootLeft", "FootRight"):
        assert (s.tracking_state[:, s.topology.index(j)] == TrackingState.INFERRED).all()


def test_kimore_is_fast():
    path = data_file("kimore/JointPositionExercise3.csv")
    start = time.perf_counter()
    read_kimore(path)
    assert time.perf_counter() - start < 0.5


def test_kimore_zero_joint_becomes_missing(tmp_path):
    src = data_file("kimore/JointPositionExercise1.csv")
    lines = src.read_text().split("\n")
    k = next(i for i, ln in enumerate(lines) if ln.strip())
    fields = lines[k].split(",")
    fields[4 * 11 : 4 * 11 + 4] = ["0", "0", "0", "0"]  # HandRight of the first frame
    lines[k] = ",".join(fields)
    p = tmp_path / "k.csv"
    p.write_text("\n".join(lines))
    (s,) = read_kimore(p)
    assert np.isnan(s.positions[0, 11]).all()
    assert s.tracking_state[0, 11] == TrackingState.NOT_TRACKED
    assert not np.isnan(s.positions[1, 11]).any()
    # the largest jump ignores the missing sample instead of jumping to the origin
    assert s.largest_jumps()[0][11] < 1.0


def test_kimore_errors(tmp_path):
    src = data_file("kimore/JointPositionExercise1.csv").read_text().split("\n")
    k = next(i for i, ln in enumerate(src) if ln.strip())
    bad = list(src)
    bad[k + 2] = bad[k + 2].replace(",2,", ",2.5,", 1)
    p = tmp_path / "state.csv"
    p.write_text("\n".join(bad))
    with pytest.raises(ReadError, match="tracking state") as e:
        read_kimore(p)
    assert e.value.line == k + 3
    short = list(src)
    short[k + 4] = ",".join(short[k + 4].split(",")[:60])
    p.write_text("\n".join(short))
    with pytest.raises(ReadError, match="expected 100 values") as e:
        read_kimore(p)
    assert e.value.line == k + 5


# ---------------------------------------------------------------------- KERAAL Kinect
def _quat_wxyz_local_y(q):
    """Second column of the rotation matrix of unit quaternion (w, x, y, z)."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([2 * (x * y - w * z), 1 - 2 * (x * x + z * z), 2 * (y * z + w * x)], -1)


@pytest.mark.parametrize("ex", sorted(KERAAL_KINECT))
def test_keraal_kinect_shapes_and_values(ex):
    rel = f"keraal/G3-Kinect-{ex}-P1T1-Unknown-C-0.txt"
    path = data_file(rel)
    assert detect_format(path) == "keraal_kinect"
    (s,) = _load(rel)
    T = KERAAL_KINECT[ex]
    assert s.positions.shape == (T, 25, 3) and s.fps == 30.0
    assert s.metadata["orientations"].shape == (T, 25, 4)
    raw = _raw(path).reshape(T, 25, 7)
    np.testing.assert_array_equal(s.positions, raw[:, :, :3])
    np.testing.assert_array_equal(s.metadata["orientations"], raw[:, :, 3:])
    assert not np.isnan(s.positions).any()  # README: no missing values
    # depth is 2-3.6 m, y up
    z = s.positions[:, :, 2]
    assert 1.5 < z.min() and z.max() < 4.0


@pytest.mark.parametrize("ex", sorted(KERAAL_KINECT))
def test_keraal_kinect_quaternion_local_y_along_bone(ex):
    (s,) = _load(f"keraal/G3-Kinect-{ex}-P1T1-Unknown-C-0.txt")
    q = s.metadata["orientations"]
    cosines = []
    for parent, child in s.topology.bones:
        qc = q[:, child]
        if np.all(qc == 0):  # end joints: no orientation
            continue
        bone = s.positions[:, child] - s.positions[:, parent]
        bone /= np.linalg.norm(bone, axis=-1, keepdims=True)
        cosines.append(np.mean(np.sum(bone * _quat_wxyz_local_y(qc), axis=-1)))
    assert len(cosines) >= 15
    assert np.mean(cosines) > 0.99
    # read as (x, y, z, w) instead, the agreement disappears (README: about -0.5)
    wrong = []
    for parent, child in s.topology.bones:
        qc = q[:, child]
        if np.all(qc == 0):
            continue
        bone = s.positions[:, child] - s.positions[:, parent]
        bone /= np.linalg.norm(bone, axis=-1, keepdims=True)
        y = _quat_wxyz_local_y(np.roll(qc, 1, axis=-1))  # (x,y,z,w) -> (w,x,y,z)
        wrong.append(np.mean(np.sum(bone * y, axis=-1)))
    assert np.mean(wrong) < 0.5


def test_keraal_kinect_end_joints_have_zero_quaternion():
    (s,) = _load("keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt")
    q = s.metadata["orientations"]
    for j in ("Head", "FootLeft", "FootRight", "HandTipLeft", "ThumbLeft", "HandTipRight",
              "ThumbRight"):  # fmt: skip
        assert np.all(q[:, s.topology.index(j)] == 0)


def test_keraal_elk_hand_glitches_as_documented():
    (s,) = _load("keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt")
    step = np.linalg.norm(np.diff(s.positions, axis=0), axis=-1)
    assert int((step[:, s.topology.index("HandRight")] > 0.2).sum()) == 6
    assert int((step[:, s.topology.index("WristRight")] > 0.2).sum()) == 5


def test_keraal_kinect_zero_joint(tmp_path):
    lines = data_file("keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt").read_bytes().split(b"\r\n")
    vals = lines[3].split(b" ")
    vals[7 * 7 : 7 * 7 + 3] = [b"0", b"0", b"0"]  # HandLeft position of frame 3
    lines[3] = b" ".join(vals)
    p = tmp_path / "k.txt"
    p.write_bytes(b"\r\n".join(lines))
    (s,) = read_keraal_kinect(p)
    assert np.isnan(s.positions[3, 7]).all()
    assert s.tracking_state[3, 7] == TrackingState.NOT_TRACKED
    assert s.tracking_state[4, 7] == TrackingState.TRACKED


def test_keraal_kinect_wrong_group_count(tmp_path):
    lines = data_file("keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt").read_text().splitlines()
    lines[10] = " ".join(lines[10].split()[:168])
    p = tmp_path / "k.txt"
    p.write_text("\n".join(lines))
    with pytest.raises(ReadError, match=r"expected 175 values.*found 168") as e:
        read_keraal_kinect(p)
    assert e.value.line == 11


# ---------------------------------------------------------------------- KERAAL Vicon
@pytest.mark.parametrize("ex", sorted(KERAAL_VICON))
def test_keraal_vicon(ex):
    rel = f"keraal/G3-Vicon-{ex}-P1T1-Unknown-C-0.txt"
    path = data_file(rel)
    assert detect_format(path) == "keraal_vicon"
    (s,) = _load(rel)
    T = KERAAL_VICON[ex]
    assert s.positions.shape == (T, 17, 3) and s.fps == 60.0
    assert s.topology.up_axis == 2
    raw = _raw(path).reshape(T, 17, 7)
    np.testing.assert_allclose(s.positions, raw[:, :, :3] / 1000.0, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(s.metadata["target_quaternions_raw"], raw[:, :, 3:])
    assert "xyzw" in s.metadata["quaternion_order"]
    # same recording as the Kinect file: same duration within 2 Kinect frames
    assert abs(T / 60.0 - KERAAL_KINECT[ex] / 30.0) < 2 / 30
    # z up: the head is above the feet in every frame
    t = s.topology
    assert np.all(s.positions[:, t.index("Head"), 2] > s.positions[:, t.index("LeftFoot"), 2])


# ---------------------------------------------------------------------- krajjat
def test_krajjat_tsv():
    rel = "krajjat/sequence_ainhoa_trimmed.tsv"
    path = data_file(rel)
    assert detect_format(path) == "krajjat"
    (s,) = _load(rel)
    assert s.positions.shape == (1100, 21, 3)
    assert s.topology.name == "kinect_v2_21"
    assert s.joint_names[:5] == ("Head", "Neck", "SpineShoulder", "SpineMid", "SpineBase")
    dt = s.dt()
    assert s.times()[-1] - s.times()[0] == pytest.approx(67.9, abs=0.1)
    assert np.median(dt) == pytest.approx(0.060, abs=0.001)
    assert dt.min() == pytest.approx(0.047, abs=0.001)
    assert dt.max() == pytest.approx(0.153, abs=0.001)
    assert s.fps == pytest.approx(1 / np.median(dt))
    assert "Floor" in s.metadata["header"]
    # independent parse of one frame
    lines = path.read_text().split("\n")
    row = [float(v) for v in lines[12].split("\t") if v.strip()]
    assert s.timestamps[0] == row[0]
    np.testing.assert_array_equal(s.positions[0].ravel(), row[1:])
    # y up: head above the feet
    assert np.all(s.positions[:, 0, 1] > s.positions[:, s.topology.index("FootLeft"), 1])


def test_krajjat_backwards_time_is_an_error(tmp_path):
    lines = data_file("krajjat/sequence_ainhoa_trimmed.tsv").read_text().split("\n")
    f = lines[20].split("\t")
    f[0] = "0.0"
    lines[20] = "\t".join(f)
    p = tmp_path / "k.tsv"
    p.write_text("\n".join(lines))
    with pytest.raises(ReadError, match=r"non-decreasing timestamps, found 0\.0 after") as e:
        load(p)
    assert e.value.line == 21


def test_infinite_value_is_a_read_error(tmp_path):
    lines = data_file("keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt").read_text().splitlines()
    fields = lines[5].split()
    fields[2] = "inf"
    lines[5] = " ".join(fields)
    p = tmp_path / "k.txt"
    p.write_text("\n".join(lines))
    with pytest.raises(ReadError, match="finite number in field 3, found 'inf'") as e:
        read_keraal_kinect(p)
    assert e.value.line == 6
