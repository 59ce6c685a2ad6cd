"""Hypothesis fuzzing: arbitrary bytes / text / mutations of real files give a ReadError
(or a valid result), never another exception type."""

from __future__ import annotations

import gzip

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import DATA_DIR
from fuzzing import SETTINGS, check_reader, reader_fuzz_tests
from tobitkf.io import ReadError, load
from tobitkf.io.bvh import read_bvh
from tobitkf.io.c3d import read_c3d
from tobitkf.io.generic_csv import read_csv
from tobitkf.io.keraal import read_keraal_kinect, read_keraal_vicon
from tobitkf.io.kimore import read_kimore
from tobitkf.io.krajjat import read_krajjat
from tobitkf.io.npz import read_npz
from tobitkf.io.ntu import read_ntu
from tobitkf.io.qualisys import read_qualisys
from tobitkf.io.uiprmd import read_uiprmd_kinect, read_uiprmd_vicon

READERS = {
    "ntu": (read_ntu, ".skeleton"),
    "kimore": (read_kimore, ".csv"),
    "keraal_kinect": (read_keraal_kinect, ".txt"),
    "keraal_vicon": (read_keraal_vicon, ".txt"),
    "uiprmd_vicon": (read_uiprmd_vicon, ".txt.gz"),
    # the same file serves as positions and angles: exercises the parser and reconstruction
    "uiprmd_kinect": (lambda p: read_uiprmd_kinect(p, angles_path=p), "_positions.txt"),
    "krajjat": (read_krajjat, ".tsv"),
    "qualisys": (read_qualisys, ".tsv"),
    "bvh": (read_bvh, ".bvh"),
    "csv": (read_csv, ".csv"),
    "npz": (read_npz, ".npz"),
}

# text built from the tokens these formats use, so the fuzzer gets past the first checks
TOKENS = st.sampled_from(
    [
        "0",
        "1",
        "2",
        "25",
        "-1.5",
        "nan",
        "inf",
        "1e400",
        "x",
        "",
        ",",
        "\t",
        " ",
        "\n",
        "\r\n",
        "HIERARCHY",
        "ROOT",
        "JOINT",
        "End",
        "Site",
        "{",
        "}",
        "OFFSET",
        "CHANNELS",
        "3",
        "6",
        "Xrotation",
        "Yposition",
        "MOTION",
        "Frames:",
        "Frame Time:",
        "Timestamp",
        "Head_X",
        "Head_Y",
        "Head_Z",
        "MARKER_NAMES",
        "FREQUENCY",
        "NO_OF_FRAMES",
        "a_x",
        "a_y",
        "a_z",
        "a_state",
        "time",
        "body",
        "# fps: 3",
        "72057594037931101",
        "\x00",
        "é",
    ]
)
TEXTISH = st.lists(TOKENS, max_size=80).map("".join)


test_arbitrary_bytes, test_token_soup = reader_fuzz_tests(READERS, TEXTISH)


@SETTINGS
@given(text=TEXTISH, gz=st.booleans())
def test_load_auto_never_crashes(tmp_path, text, gz):
    p = tmp_path / ("f.txt.gz" if gz else "f.txt")
    raw = text.encode("utf-8")
    p.write_bytes(gzip.compress(raw) if gz else raw)
    try:
        load(p)
    except ReadError:
        pass


REAL = [
    ("kimore/JointPositionExercise1.csv", read_kimore),
    ("keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt", read_keraal_kinect),
    ("krajjat/test_sequence_qtm_2.tsv", read_qualisys),
    ("cmu-mocap/scaled_131_01.bvh", read_bvh),
    ("btkdata/PiG_Motion-FlatFoot-Full.c3d", read_c3d),
]


@pytest.mark.parametrize(("rel", "reader"), REAL)
@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])  # fmt: skip
@given(data=st.data())
def test_mutated_real_files(tmp_path, rel, reader, data):
    """Truncate, delete or overwrite a few bytes of a real file: ReadError or valid."""
    src = DATA_DIR / rel
    if not src.exists():
        pytest.skip(f"missing {src}")
    if src.suffix == ".c3d":
        pytest.importorskip("c3d")
    raw = bytearray(src.read_bytes()[:6000] if src.suffix != ".c3d" else src.read_bytes())
    n = len(raw)
    cut = data.draw(st.integers(0, n))
    raw = raw[:cut]
    for _ in range(data.draw(st.integers(0, 3))):
        if not raw:
            break
        k = data.draw(st.integers(0, min(len(raw), 12000) - 1))
        raw[k] = data.draw(st.sampled_from(b"0x,\t \n.-e\x00\xff9"))
    p = tmp_path / f"m{src.suffix}"
    p.write_bytes(bytes(raw))
    check_reader(reader, p)


GRIDS = {  # reader name -> (values per row, separator, trailing text)
    "kimore": (100, ",", ","),
    "keraal_kinect": (175, " ", " \r"),
    "keraal_vicon": (119, " ", " \r"),
    "uiprmd_vicon": (117, ",", ""),
    "uiprmd_kinect": (66, ",", ""),
}
CELL = st.one_of(
    st.sampled_from(["0", "1", "2", "0.5", "-3.25", "1e3"]),
    st.sampled_from(["nan", "inf", "-inf", "1e400", "x", "", "1,5", "0x1", "--1", "١"]),
)


@pytest.mark.parametrize("name", sorted(GRIDS))
@SETTINGS
@given(data=st.data())
def test_numeric_grids_with_bad_cells(tmp_path, name, data):
    """Well-shaped grids with a few bad cells / short rows: ReadError or a clean result."""
    reader, ext = READERS[name]
    n, sep, tail = GRIDS[name]
    n_rows = data.draw(st.integers(1, 4))
    rows = []
    for _ in range(n_rows):
        cells = ["0.5"] * n
        for _ in range(data.draw(st.integers(0, 3))):
            cells[data.draw(st.integers(0, n - 1))] = data.draw(CELL)
        if data.draw(st.integers(0, 9)) == 0:
            cells = cells[: data.draw(st.integers(0, n))]
        rows.append(sep.join(cells) + tail)
    p = tmp_path / f"g{ext}"
    p.write_text("\n".join(rows), encoding="utf-8")
    check_reader(reader, p)
