"""Cut-short and damaged binary or compressed files: one line saying what is wrong.

A truncated HDF5 file (DeepLabCut, SLEAP, movement) is reported as such, without the
HDF5 library's back trace; a gzip file that cannot be decompressed is reported as such
by format detection too, not as an unrecognised format.
"""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from tobitkf.io import ReadError, detect_format, load, save
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology

KP = ["snout", "left_ear", "right_ear", "tail_base"]


def _pixels(T: int = 40) -> SkeletonSequence:
    rng = np.random.default_rng(3)
    return SkeletonSequence(
        rng.uniform(0, 640, (T, len(KP), 2)), Topology.from_names(KP), units="px", fps=30.0
    )


def _deeplabcut(path):
    pytest.importorskip("pandas")
    pytest.importorskip("tables")
    save(_pixels(), path, format="deeplabcut")


def _movement(path):
    pytest.importorskip("xarray")
    pytest.importorskip("h5netcdf")
    save(_pixels(), path, format="movement")


def _sleap_analysis(path):
    h5py = pytest.importorskip("h5py")
    with h5py.File(path, "w") as f:  # SLEAP's layout: tracks (tracks, xy, nodes, frames)
        f["tracks"] = np.random.default_rng(0).uniform(0, 500, (1, 2, len(KP), 400))
        f["node_names"] = np.array([k.encode() for k in KP])


def _slp(path):
    sio = pytest.importorskip("sleap_io")
    nodes = [sio.Node(n) for n in KP]
    skel = sio.Skeleton(nodes=nodes)
    video = sio.Video(filename="fake.mp4")
    pts = np.arange(len(KP) * 2, dtype=float).reshape(len(KP), 2)
    frames = [
        sio.LabeledFrame(video=video, frame_idx=t, instances=[sio.Instance.from_numpy(pts, skel)])
        for t in range(20)
    ]
    sio.save_slp(sio.Labels(labeled_frames=frames, videos=[video], skeletons=[skel]), path)


@pytest.mark.parametrize(
    ("name", "fmt", "write"),
    [
        ("video1DLC.h5", "deeplabcut", _deeplabcut),
        ("poses.nc", "movement", _movement),
        ("pred.analysis.h5", "sleap_analysis", _sleap_analysis),
        ("labels.slp", "slp", _slp),
    ],
)
def test_truncated_hdf5_is_one_line_naming_the_truncation(tmp_path, name, fmt, write):
    path = tmp_path / name
    write(path)
    assert load(path)  # the whole file reads
    raw = path.read_bytes()
    half = len(raw) // 2
    path.write_bytes(raw[:half])
    for how in ("auto", fmt):
        with pytest.raises(ReadError) as info:
            load(path, format=how)
        text = str(info.value)
        # HDF5's own words for a file shorter than its superblock says, with the sizes
        assert text.startswith(
            f"{path}: truncated or corrupt HDF5 file (truncated file: eof = {half},"
        ), text
        assert f"stored_eof = {len(raw)})" in text
        assert "\n" not in text and "back trace" not in text


def test_hdf5_signature_with_garbage_is_a_corrupt_hdf5_file(tmp_path):
    pytest.importorskip("h5py")
    path = tmp_path / "x.analysis.h5"
    path.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 100)
    with pytest.raises(ReadError, match=r"x\.analysis\.h5: truncated or corrupt HDF5 file \("):
        load(path)


def _kinect_text(frames: int = 60) -> bytes:
    """UI-PRMD Kinect layout: 66 comma-separated values per line (60 frames: 40 kB, less
    than the 64 kB that format detection reads)."""
    rng = np.random.default_rng(1)
    rows = rng.uniform(-50, 50, (frames, 66))
    return "".join(",".join(f"{v:.6f}" for v in r) + "\n" for r in rows).encode()


def test_truncated_gzip_is_reported_by_format_detection(tmp_path):
    path = tmp_path / "m01_s01_e01_positions.txt.gz"
    # the reader needs the angles file beside the positions
    (tmp_path / "m01_s01_e01_angles.txt.gz").write_bytes(gzip.compress(_kinect_text()))
    packed = gzip.compress(_kinect_text())
    path.write_bytes(packed)
    assert detect_format(path) == "uiprmd_kinect"  # the whole file is recognised
    path.write_bytes(packed[: len(packed) // 2])
    for call in (detect_format, load):
        with pytest.raises(ReadError, match="corrupt or truncated gzip data") as info:
            call(path)
        assert "unrecognised" not in str(info.value)
    # the same words as the reader itself, given the format
    with pytest.raises(ReadError, match="corrupt or truncated gzip data"):
        load(path, format="uiprmd_kinect")


def test_gzip_magic_then_garbage_is_reported_as_corrupt_gzip(tmp_path):
    path = tmp_path / "walk.csv"
    path.write_bytes(b"\x1f\x8b" + b"not deflate data at all" * 4)
    with pytest.raises(ReadError, match=r"walk\.csv: corrupt or truncated gzip data \("):
        detect_format(path)


def test_a_damaged_object_header_is_an_error_not_a_crash(tmp_path):
    """200 bytes overwritten in a DeepLabCut .h5's object headers: PyTables
    (``pandas.read_hdf``) dies of a segmentation fault inside HDF5, which no Python code
    can catch; the reader reads the file with h5py first, which raises. Run in a child
    process, so that a crash fails this test instead of killing the test run."""
    import subprocess
    import sys

    path = tmp_path / "video1DLC.h5"
    _deeplabcut(path)
    raw = bytearray(path.read_bytes())
    raw[1000:1200] = b"\xff" * 200  # found by scanning offsets: PyTables crashes here
    path.write_bytes(bytes(raw))
    code = (
        "import sys\nfrom tobitkf.io import ReadError, load\n"
        f"try:\n    load({str(path)!r})\nexcept ReadError as exc:\n    print(exc)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-500:]
    assert "corrupt HDF5 file" in done.stdout and len(done.stdout.strip().splitlines()) == 1


def test_a_file_named_h5_that_is_not_hdf5_says_so(tmp_path):
    """Detection falls back to the .h5 extension (DeepLabCut): the reader said its CSV
    header row was missing, quoting binary noise."""
    path = tmp_path / "video1DLC.h5"
    path.write_bytes(np.random.default_rng(0).bytes(3000))
    with pytest.raises(ReadError, match="not an HDF5 file"):
        load(path)
