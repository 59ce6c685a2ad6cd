"""UI-PRMD Kinect (hierarchy reconstruction) and Vicon marker files on the real data."""

from __future__ import annotations

import gzip
import shutil
from functools import cache

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from conftest import data_file
from tobitkf.io import ReadError, detect_format, is_companion_file, load
from tobitkf.io.uiprmd import angles_path_for, euler_zxy, reconstruct_uiprmd

KINECT = "ui-prmd/Segmented Movements/Kinect/Positions/{}_positions.txt.gz"
VICON = "ui-prmd/Segmented Movements/Vicon/Positions/{}_positions.txt.gz"
FRAMES = {  # data README §2: Kinect / Vicon frame counts
    "m01_s01_e01": (73, 191), "m01_s01_e02": (70, 219), "m01_s01_e03": (73, 227),
    "m02_s01_e01": (62, 105), "m02_s01_e02": (56, 179), "m02_s01_e03": (58, 185),
    "m07_s01_e01": (63, 229), "m07_s01_e02": (66, 283), "m07_s01_e03": (64, 292),
}  # fmt: skip


@cache
def _load(rel):
    return load(data_file(rel))[0]


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-180, 180), min_size=3, max_size=3))
def test_euler_matches_scipy_intrinsic_zxy(angles):
    ax, ay, az = angles
    expected = Rotation.from_euler("ZXY", [az, ax, ay], degrees=True).as_matrix()
    np.testing.assert_allclose(euler_zxy(np.array(angles)), expected, atol=1e-12)


def test_reconstruction_chain_by_hand():
    # root at (1,2,3) rotated 90 deg about z; child offset (1,0,0) -> (1,2,3) + (0,1,0);
    # grandchild: child rotated 90 deg about x, offset (0,1,0) -> child pos + Rz Rx (0,1,0)
    rel = np.array([[[1.0, 2, 3], [1, 0, 0], [0, 1, 0]]])
    ang = np.array([[[0.0, 0, 90], [90, 0, 0], [0, 0, 0]]])
    pos = reconstruct_uiprmd(rel, ang, parents=(-1, 0, 1))
    np.testing.assert_allclose(pos[0, 0], [1, 2, 3])
    np.testing.assert_allclose(pos[0, 1], [1, 3, 3], atol=1e-12)
    # Rz(90) Rx(90) (0,1,0) = Rz(90) (0,0,1) = (0,0,1)
    np.testing.assert_allclose(pos[0, 2], [1, 3, 4], atol=1e-12)


@pytest.mark.parametrize("code", sorted(FRAMES))
def test_kinect_and_vicon_frame_counts(code):
    kpath, vpath = data_file(KINECT.format(code)), data_file(VICON.format(code))
    assert detect_format(kpath) == "uiprmd_kinect"
    assert detect_format(vpath) == "uiprmd_vicon"
    k, v = _load(KINECT.format(code)), _load(VICON.format(code))
    assert k.positions.shape == (FRAMES[code][0], 22, 3) and k.fps == 30.0
    assert v.positions.shape == (FRAMES[code][1], 39, 3) and v.fps == 100.0
    assert k.topology.name == "ui_prmd" and k.topology.up_axis == 1
    assert v.topology.name == "plug_in_gait_39" and v.topology.up_axis == 2
    assert not np.isnan(k.positions).any() and not np.isnan(v.positions).any()


def test_kinect_root_is_file_value_in_metres():
    rel = KINECT.format("m01_s01_e01")
    raw = np.loadtxt(gzip.open(data_file(rel), "rt"), delimiter=",")
    s = _load(rel)
    np.testing.assert_allclose(s.positions[:, 0], raw[:, :3] / 100.0)
    # "floor near y = 0": the feet are a few cm above it, the head ~1.6-1.9 m
    t = s.topology
    assert abs(s.positions[0, t.index("LeftFoot"), 1]) < 0.25
    assert 1.4 < s.positions[0, t.index("Head"), 1] < 2.0


def test_squat_ankles_still_waist_drops():
    """m01 deep squat: the waist drops > 40 cm while the ankles stay put (README §2)."""
    s = _load(KINECT.format("m01_s01_e01"))
    t = s.topology
    waist = s.positions[:, t.index("Waist"), 1]
    assert waist.max() - waist.min() > 0.40
    for ankle in ("LeftFoot", "RightFoot"):
        p = s.positions[:, t.index(ankle)]
        assert np.all(p.std(axis=0) < 0.035)  # ~2-3 cm per axis
        assert np.linalg.norm(p - np.median(p, axis=0), axis=-1).max() < 0.08
    # the third-party convention Rz·Ry·Rx makes the ankles drift by ~20 cm (README)
    raw = np.loadtxt(gzip.open(data_file(KINECT.format("m01_s01_e01")), "rt"), delimiter=",")
    ang = s.metadata["euler_angles_deg"]
    rel = raw.reshape(-1, 22, 3)
    R = Rotation.from_euler("ZYX", ang[..., ::-1].reshape(-1, 3), degrees=True)
    local = R.as_matrix().reshape(*ang.shape[:2], 3, 3)
    rot = np.empty_like(local)
    pos = np.empty_like(rel)
    for j, p in enumerate(t.parents):
        if p < 0:
            rot[:, j], pos[:, j] = local[:, j], rel[:, j]
        else:
            rot[:, j] = rot[:, p] @ local[:, j]
            pos[:, j] = pos[:, p] + np.einsum("tab,tb->ta", rot[:, p], rel[:, j])
    wrong = pos[:, t.index("LeftFoot")] / 100.0
    assert np.linalg.norm(wrong - np.median(wrong, axis=0), axis=-1).max() > 0.15


def test_bone_lengths_equal_offset_norms():
    """Rotations preserve length: |p_child - p_parent| = |offset_child| in every frame."""
    rel = KINECT.format("m02_s01_e01")
    raw = np.loadtxt(gzip.open(data_file(rel), "rt"), delimiter=",").reshape(-1, 22, 3)
    s = _load(rel)
    for p, c in s.topology.bones:
        length = np.linalg.norm(s.positions[:, c] - s.positions[:, p], axis=-1)
        np.testing.assert_allclose(length, np.linalg.norm(raw[:, c], axis=-1) / 100, atol=1e-9)


def test_vicon_units_and_orientation():
    rel = VICON.format("m01_s01_e01")
    raw = np.loadtxt(gzip.open(data_file(rel), "rt"), delimiter=",")
    s = _load(rel)
    np.testing.assert_allclose(s.positions.reshape(len(raw), -1), raw / 1000.0)
    t = s.topology
    p = s.positions
    # left at +y, ASIS in front of PSIS (+x), heel behind toe, head above ankle
    assert np.mean(p[:, t.index("LASI"), 1]) > np.mean(p[:, t.index("RASI"), 1])
    assert np.mean(p[:, t.index("LASI"), 0]) > np.mean(p[:, t.index("LPSI"), 0])
    assert np.mean(p[:, t.index("LTOE"), 0]) > np.mean(p[:, t.index("LHEE"), 0])
    assert np.all(p[:, t.index("LFHD"), 2] - p[:, t.index("LANK"), 2] > 0.5)  # squat


def test_angles_file_location_and_missing_angles(tmp_path):
    kpath = data_file(KINECT.format("m01_s01_e01"))
    a = angles_path_for(kpath)
    assert a.parent.name == "Angles" and a.name == "m01_s01_e01_angles.txt.gz"
    assert a.exists()
    lone = tmp_path / "Kinect" / "Positions"
    lone.mkdir(parents=True)
    shutil.copy(kpath, lone / kpath.name)
    with pytest.raises(ReadError, match="angles file") as e:
        load(lone / kpath.name)
    assert "Angles" in str(e.value)
    # an angles file with a different frame count
    (tmp_path / "Kinect" / "Angles").mkdir()
    with gzip.open(tmp_path / "Kinect" / "Angles" / a.name, "wt") as fh:
        fh.write(",".join(["0"] * 66) + "\n")
    with pytest.raises(ReadError, match="expected 73 frames"):
        load(lone / kpath.name)
    # an angles file on its own has no positions: clear error
    lone_angles = tmp_path / "solo" / "Angles"
    lone_angles.mkdir(parents=True)
    shutil.copy(a, lone_angles / a.name)
    with pytest.raises(ReadError, match="positions file was expected"):
        load(lone_angles / a.name, format="uiprmd_kinect")


def test_angles_file_is_a_companion_that_loads_the_pair():
    kpath = data_file(KINECT.format("m07_s01_e01"))
    a = angles_path_for(kpath)
    assert is_companion_file(a) and not is_companion_file(kpath)
    assert detect_format(a) == "uiprmd_kinect"
    (via_angles,) = load(a)
    np.testing.assert_array_equal(
        via_angles.positions, _load(KINECT.format("m07_s01_e01")).positions
    )


def test_corrupt_gzip(tmp_path):
    p = tmp_path / "Positions" / "m01_s01_e01_positions.txt.gz"
    p.parent.mkdir()
    p.write_bytes(data_file(VICON.format("m01_s01_e01")).read_bytes()[:300])
    with pytest.raises(ReadError, match="gzip"):
        load(p, format="uiprmd_vicon")
