"""Format registry: detection by content and extension, load/save dispatch, errors."""

from __future__ import annotations

import numpy as np
import pytest

import tobitkf
from conftest import data_file
from tobitkf.io import (
    ReadError,
    detect_format,
    formats,
    get_format,
    load,
    register_format,
    save,
    unregister_format,
)
from tobitkf.skeleton.sequence import SkeletonSequence

EXPECTED = {
    "kimore/JointPositionExercise1.csv": "kimore",
    "keraal/G3-Kinect-CTK-P1T1-Unknown-C-0.txt": "keraal_kinect",
    "keraal/G3-Vicon-CTK-P1T1-Unknown-C-0.txt": "keraal_vicon",
    "ui-prmd/Segmented Movements/Kinect/Positions/m07_s01_e02_positions.txt.gz": "uiprmd_kinect",
    "ui-prmd/Segmented Movements/Vicon/Positions/m07_s01_e02_positions.txt.gz": "uiprmd_vicon",
    "krajjat/sequence_ainhoa_trimmed.tsv": "krajjat",
    "krajjat/test_sequence_qtm_2.tsv": "qualisys",
    "btkdata/PiG_Motion-FlatFoot-Full.c3d": "c3d",
    "cmu-mocap/scaled_131_01.bvh": "bvh",
}


@pytest.mark.parametrize("rel", sorted(EXPECTED))
def test_detect_real_files(rel):
    assert detect_format(data_file(rel)) == EXPECTED[rel]


@pytest.mark.parametrize("rel", ["kimore/JointPositionExercise1.csv",
                                 "keraal/G3-Vicon-CTK-P1T1-Unknown-C-0.txt"])  # fmt: skip
def test_detection_by_content_not_name(tmp_path, rel):
    """The same bytes under a misleading name are still recognised."""
    p = tmp_path / "recording.dat"
    p.write_bytes(data_file(rel).read_bytes())
    assert detect_format(p) == EXPECTED[rel]


def test_extension_fallback_and_unknown(tmp_path):
    p = tmp_path / "x.bvh"
    p.write_text("garbage\n")
    assert detect_format(p) == "bvh"  # no content match: the extension decides
    with pytest.raises(ReadError, match="HIERARCHY"):
        load(p)
    q = tmp_path / "x.weird"
    q.write_text("1 2 3\n")
    with pytest.raises(ReadError, match="unrecognised content"):
        detect_format(q)
    e = tmp_path / "empty.csv"
    e.write_text("")
    with pytest.raises(ReadError, match="empty file"):
        load(e)
    with pytest.raises(ReadError, match="not found"):
        load(tmp_path / "missing.csv")
    with pytest.raises(ReadError, match="directory"):
        load(tmp_path)


def test_public_api_and_error_type():
    assert tobitkf.load is load and tobitkf.save is save
    assert issubclass(ReadError, ValueError)
    err = ReadError("/a/b.csv", 12, "expected 3 values, found 2")
    assert str(err) == "/a/b.csv, line 12: expected 3 values, found 2"
    assert err.line == 12 and err.path == "/a/b.csv"
    import pickle

    again = pickle.loads(pickle.dumps(err))
    assert str(again) == str(err)
    assert set(formats()) >= {"ntu", "kimore", "keraal_kinect", "keraal_vicon",
                              "uiprmd_kinect", "uiprmd_vicon", "krajjat", "qualisys", "c3d",
                              "bvh", "csv", "npz"}  # fmt: skip
    assert get_format("generic_csv").name == "csv"
    with pytest.raises(ValueError, match="unknown format"):
        get_format("xyz")


def test_save_dispatch(tmp_path):
    s = SkeletonSequence(np.zeros((2, 25, 3)) + 1.0, "kinect_v2", fps=30.0)
    for name, fmt in (("a.csv", "csv"), ("a.npz", "npz"), ("a.skeleton", "ntu")):
        save(s, tmp_path / name)
        assert detect_format(tmp_path / name) == fmt
        np.testing.assert_array_equal(load(tmp_path / name)[0].positions, s.positions)
    save([s], tmp_path / "b.out", format="csv")
    assert detect_format(tmp_path / "b.out") == "csv"
    with pytest.raises(ValueError, match="cannot choose"):
        save(s, tmp_path / "a.txt")
    with pytest.raises(ValueError, match="cannot be written"):
        save(s, tmp_path / "a.tsv", format="qualisys")
    with pytest.raises(TypeError):
        save([np.zeros(3)], tmp_path / "a.csv")


NO_FRAME_REFUSED = [
    ("csv", "e.csv"),
    ("deeplabcut", "e.h5"),
    ("mmpose", "e.json"),
    ("trc", "e.trc"),
    ("c3d", "e.c3d"),
]


@pytest.mark.parametrize(("fmt", "name"), NO_FRAME_REFUSED)
def test_no_frame_is_refused_where_it_cannot_be_read_back(tmp_path, fmt, name):
    """A recording with no frame written as CSV, DeepLabCut, MMPose, TRC or C3D gave a
    file its own reader refuses (or, for C3D, ezc3d's error); the writer now refuses it,
    writes nothing, and says which format keeps it: NPZ, whose empty recording reads
    back."""
    empty = SkeletonSequence(np.zeros((0, 25, 3)), "kinect_v2", fps=30.0, units="m")
    with pytest.raises(ValueError, match=r"no frame.*format='npz'"):
        save(empty, tmp_path / name, format=fmt)
    assert not (tmp_path / name).exists()
    save(empty, tmp_path / "e.npz")
    (back,) = load(tmp_path / "e.npz")
    assert back.positions.shape == (0, 25, 3)


def test_register_custom_format(tmp_path):
    def reader(path):
        v = np.loadtxt(path).reshape(-1, 1, 3)
        return [SkeletonSequence(v, tobitkf.Topology.from_names(["p"]))]

    def sniff(path, head):
        return 99 if head.startswith("1 2 3") else 0

    register_format("point3_test", reader, extensions=(".p3",))
    try:
        p = tmp_path / "x.p3"
        p.write_text("1 2 3\n4 5 6\n")
        assert detect_format(p) == "point3_test"  # by extension
        q = tmp_path / "x.dat"
        q.write_text("1 2 3\n4 5 6\n")
        with pytest.raises(ReadError):
            detect_format(q)
        register_format("point3_test", reader, extensions=(".p3",), sniff=sniff)
        assert detect_format(q) == "point3_test"  # by content
        assert load(q)[0].positions.shape == (2, 1, 3)
    finally:
        unregister_format("point3_test")
    assert "point3_test" not in formats()


def test_reader_options_pass_through():
    (s,) = load(data_file("cmu-mocap/scaled_131_01.bvh"), scale=100.0)
    (m,) = load(data_file("cmu-mocap/scaled_131_01.bvh"))
    np.testing.assert_allclose(s.positions, 100.0 * m.positions)
