"""Hostile input (issue 14): resource limits, number syntax, plausibility, fuzzing of every
reader with mutated valid files, and writer round trips with hostile joint names.

Every hostile file is built here; each expectation is the documented rule (the limit, the
number syntax, the plausibility bound), not a number taken from the reader's output.
"""

from __future__ import annotations

import gzip
import io
import os
import struct
import subprocess
import sys
import textwrap
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tobitkf.io import ReadError, load, save
from tobitkf.io._text import MAX_ABS_POSITION_M
from tobitkf.io.bvh import read_bvh
from tobitkf.io.generic_csv import read_csv, write_csv
from tobitkf.io.keraal import read_keraal_kinect, read_keraal_vicon
from tobitkf.io.kimore import read_kimore
from tobitkf.io.krajjat import read_krajjat
from tobitkf.io.npz import read_npz, write_npz
from tobitkf.io.ntu import read_ntu, write_ntu
from tobitkf.io.qualisys import read_qualisys
from tobitkf.io.uiprmd import read_uiprmd_kinect, read_uiprmd_vicon
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology, get_topology

# ---------------------------------------------------------------------------------------
# small valid files, one per text format, with a marked cell "{v}" (x of the first joint)
# ---------------------------------------------------------------------------------------

_NTU_JOINT = "0.5 0.25 2.5 1 2 3 4 1 0 0 0 2"
_BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 3 Xposition Yposition Zposition
  JOINT Chest
  {
    OFFSET 0 0.5 0
    CHANNELS 0
    End Site
    {
      OFFSET 0 0.25 0
    }
  }
}
MOTION
Frames: 2
Frame Time: {dt}
{v} 0.5 0.25
0.5 0.5 0.25
"""


def _grid(n: int, sep: str, tail: str, v: str, state_every: int = 0) -> str:
    """Two rows of n values 0.5, the first value v; every ``state_every``-th value 2."""
    cells = ["0.5"] * n
    if state_every:
        cells[state_every - 1 :: state_every] = ["2"] * (n // state_every)
    first = [v, *cells[1:]]
    return sep.join(first) + tail + "\n" + sep.join(cells) + tail + "\n"


# name -> (reader, file name, text with "{v}", line of the marked cell, metres per unit)
TEXT_FORMATS = {
    "ntu": (
        read_ntu,
        "f.skeleton",
        "2\n1\n7 0 0 0 0 0 0 0.1 0.1 2\n25\n{v} 0.25 2.5 1 2 3 4 1 0 0 0 2\n"
        + "\n".join([_NTU_JOINT] * 24)
        + "\n1\n7 0 0 0 0 0 0 0.1 0.1 2\n25\n"
        + "\n".join([_NTU_JOINT] * 25)
        + "\n",
        5,
        1.0,
    ),
    "kimore": (read_kimore, "k.csv", _grid(100, ",", ",", "{v}", state_every=4), 1, 1.0),
    "keraal_kinect": (read_keraal_kinect, "k.txt", _grid(175, " ", " \r", "{v}"), 1, 1.0),
    "keraal_vicon": (read_keraal_vicon, "v.txt", _grid(119, " ", " \r", "{v}"), 1, 1e-3),
    "uiprmd_vicon": (read_uiprmd_vicon, "v.txt", _grid(117, ",", "", "{v}"), 1, 1e-3),
    "uiprmd_kinect": (
        lambda p, **kw: read_uiprmd_kinect(p, angles_path=p, **kw),
        "x_positions.txt",
        _grid(66, ",", "", "{v}"),
        1,
        1e-2,
    ),
    "krajjat": (
        read_krajjat,
        "k.tsv",
        "Timestamp\tHead_X\tHead_Y\tHead_Z\n0.0\t{v}\t0.5\t2.5\n0.05\t0.5\t0.5\t2.5\n",
        2,
        1.0,
    ),
    "qualisys": (
        read_qualisys,
        "q.tsv",
        "NO_OF_FRAMES\t2\nNO_OF_MARKERS\t1\nFREQUENCY\t100\nMARKER_NAMES\tA\n"
        "{v}\t500\t250\n500\t500\t250\n",
        5,
        1e-3,
    ),
    "bvh": (read_bvh, "s.bvh", _BVH.replace("{dt}", "0.04"), 19, 1.0),
    "csv": (read_csv, "s.csv", "a_x,a_y,a_z\n{v},0.5,0.25\n0.5,0.5,0.25\n", 2, 1.0),
}


def _write(tmp_path, name: str, v: str):
    reader, fname, text, line, unit = TEXT_FORMATS[name]
    p = tmp_path / fname
    p.write_bytes(text.replace("{v}", v).encode("utf-8"))
    return reader, p, line, unit


@pytest.mark.parametrize("name", sorted(TEXT_FORMATS))
def test_template_reads(tmp_path, name):
    """The templates are valid: the marked cell holds a plausible value read as written."""
    reader, p, _, unit = _write(tmp_path, name, "0.5")
    (s,) = reader(p)
    if name != "uiprmd_kinect":  # rebuilt through forward kinematics
        assert s.positions[0, 0, 0] == pytest.approx(0.5 * unit)


# plain ASCII decimal numbers only: each of these is a number to Python's float()
NOT_PLAIN = ["1_000", "\uff11\uff12", "\u0661\u0662", "0x10", "inf", "-Infinity", "1e400"]


@pytest.mark.parametrize("token", NOT_PLAIN)
@pytest.mark.parametrize("name", sorted(TEXT_FORMATS))
def test_only_plain_decimal_numbers(tmp_path, name, token):
    reader, p, line, _ = _write(tmp_path, name, token)
    with pytest.raises(ReadError) as e:
        reader(p)
    assert e.value.line == line and str(p) in str(e.value)
    assert repr(token) in str(e.value)


@pytest.mark.parametrize("name", sorted(set(TEXT_FORMATS) - {"csv"}))
def test_nan_token_is_an_error_where_undocumented(tmp_path, name):
    reader, p, line, _ = _write(tmp_path, name, "nan")
    with pytest.raises(ReadError, match="'nan'") as e:
        reader(p)
    assert e.value.line == line


def test_nan_is_missing_in_the_generic_csv(tmp_path):
    reader, p, _, _ = _write(tmp_path, "csv", "NaN")
    (s,) = reader(p)
    assert np.isnan(s.positions[0, 0, 0]) and s.positions[1, 0, 0] == 0.5


@pytest.mark.parametrize("name", sorted(TEXT_FORMATS))
def test_implausible_position(tmp_path, name):
    """1e308 (in the file's units) is far beyond the bound of 1e4 m."""
    reader, p, line, _ = _write(tmp_path, name, "1e308")
    with pytest.raises(ReadError, match=r"implausible position .*\|value\| <= 10000 m") as e:
        reader(p)
    assert e.value.line == line and str(p) in str(e.value)
    assert "frame 0, counted from 0" in str(e.value)  # as info and select_frames count
    with pytest.raises(ValueError, match="implausible must be one of"):
        reader(p, implausible="drop")
    (s,) = reader(p, implausible="missing")
    assert np.isnan(s.positions[0, 0]).all()
    assert np.isfinite(s.positions[1]).all()
    assert np.nanmax(np.abs(s.positions)) <= MAX_ABS_POSITION_M


@pytest.mark.parametrize("name", ["keraal_vicon", "qualisys", "uiprmd_vicon"])
def test_bound_applies_after_unit_conversion(tmp_path, name):
    """9e6 mm = 9 km is plausible; the same number in metres would not be."""
    reader, p, _, _ = _write(tmp_path, name, "9e6")
    (s,) = reader(p)
    assert s.positions[0, 0, 0] == 9000.0
    p.write_text(p.read_text().replace("9e6", "2e7"))  # 20 km
    with pytest.raises(ReadError, match="implausible position"):
        reader(p)


@pytest.mark.parametrize(
    ("name", "old", "new", "match"),
    [
        ("qualisys", "NO_OF_MARKERS\t1", "NO_OF_MARKERS\tone", "NO_OF_MARKERS.*'one'"),
        ("qualisys", "NO_OF_FRAMES\t2", "NO_OF_FRAMES\t\uff12", "NO_OF_FRAMES"),
        ("qualisys", "FREQUENCY\t100", "FREQUENCY\t1e308", "implausible FREQUENCY '1e308'"),
        ("qualisys", "FREQUENCY\t100", "FREQUENCY\t0", "implausible FREQUENCY '0'"),
        ("bvh", "Frame Time: 0.04", "Frame Time: 1e308", "implausible Frame Time.*'1e308'"),
        ("bvh", "Frame Time: 0.04", "Frame Time: 1e-9", "implausible Frame Time"),
        ("bvh", "Frames: 2", "Frames: 2_0", "frame count.*'2_0'"),
        ("bvh", "OFFSET 0 0.5 0", "OFFSET 0 \u0665 0", "OFFSET"),
        ("bvh", "CHANNELS 0", "CHANNELS \uff10", "channel count"),
        ("ntu", "2\n1\n7 0", "\uff12\n1\n7 0", "number of frames"),
        ("ntu", "7 0 0 0 0 0 0 0.1 0.1 2", "7 0 0 0 0 0 0 0.1 nan 2", "leanY.*'nan'"),
        ("ntu", "7 0 0 0 0 0 0", "7_0 0 0 0 0 0 0", "bodyID"),
        ("csv", "a_x,", "# fps: 1e308\na_x,", "implausible fps '1e308'"),
        ("csv", "a_x,", "# fps: -30\na_x,", "implausible fps '-30'"),
    ],
)
def test_header_numbers_and_rates(tmp_path, name, old, new, match):
    reader, p, _, _ = _write(tmp_path, name, "0.5")
    text = p.read_text()
    assert old in text
    p.write_text(text.replace(old, new, 1))
    with pytest.raises(ReadError, match=match) as e:
        reader(p)
    assert e.value.line is not None


def test_krajjat_implausible_rate(tmp_path):
    p = tmp_path / "k.tsv"
    p.write_text("Timestamp\tHead_X\tHead_Y\tHead_Z\n0\t0.5\t0.5\t2.5\n1e-9\t0.5\t0.5\t2.5\n")
    with pytest.raises(ReadError, match="implausible median time step"):
        read_krajjat(p)


# ---------------------------------------------------------------------------------------
# small files with a huge cost: a ReadError naming the limit, under a memory cap
# ---------------------------------------------------------------------------------------

CAP = 512 * 2**20  # address space of the reading process (the import alone takes ~100 MB)


def _load_capped(path, fmt: str, timeout: float = 20) -> str:
    """Load ``path`` in a subprocess limited to CAP bytes of address space and ``timeout``
    seconds."""
    script = textwrap.dedent(
        f"""
        import resource, sys
        resource.setrlimit(resource.RLIMIT_AS, ({CAP}, {CAP}))
        from tobitkf.io import ReadError, load
        try:
            load(sys.argv[1], format=sys.argv[2])
        except ReadError as exc:
            print("ReadError:", exc)
        except BaseException as exc:
            print("OTHER:", type(exc).__name__, exc)
        else:
            print("OK")
        """
    )
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    run = subprocess.run(
        [sys.executable, "-c", script, str(path), fmt],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
    )
    return run.stdout.strip() or f"no output, exit {run.returncode}: {run.stderr[-500:]}"


def test_gzip_bomb_is_refused_in_a_stream(tmp_path):
    member = gzip.compress(b"0" * 2**23, 9)  # 8 MiB of one long number
    p = tmp_path / "bomb.csv"
    p.write_bytes(gzip.compress(b"a_x,a_y,a_z\n") + member * 525)  # 4.4 GB decompressed
    assert p.stat().st_size < 5 * 2**20
    out = _load_capped(p, "csv")
    assert out.startswith("ReadError:") and "limit of 256 MiB" in out, out


def test_oversized_plain_file_is_refused_before_reading(tmp_path):
    p = tmp_path / "big.csv"
    with open(p, "wb") as fh:
        fh.write(b"a_x,a_y,a_z\n")
        fh.truncate(2**30)  # 1 GiB, sparse: costs no disk
    out = _load_capped(p, "csv")
    assert out.startswith("ReadError:") and "limit of 256 MiB" in out, out


def test_ntu_many_bodies_over_many_declared_frames(tmp_path):
    """20,000 frames x 100 body IDs: 114 KiB of text, gigabytes of per-body arrays."""
    lines = ["20000"]
    for b in range(100):
        lines += ["1", f"{b} 0 0 0 0 0 0 0 0 2", "25"] + ["0 0 1 0 0 0 0 0 0 0 0 2"] * 25
    lines += ["0"] * (20000 - 100)
    p = tmp_path / "many.skeleton"
    p.write_text("\n".join(lines) + "\n")
    out = _load_capped(p, "ntu")
    assert out.startswith("ReadError:") and "20000 frames x 100 body IDs" in out, out
    assert "the limit is" in out


def test_ntu_frame_count_beyond_the_lines_present(tmp_path):
    p = tmp_path / "f.skeleton"
    p.write_text("1000000000000\n0\n0\n")
    with pytest.raises(ReadError, match="declares 1000000000000 frames but has only 2"):
        read_ntu(p)


def test_bvh_many_joints_many_frames(tmp_path):
    """4,000 channel-less joints x 4,000 frames: 200 KiB of text, gigabytes of FK arrays."""
    joints = "\n".join(f"JOINT j{k} {{ OFFSET 0 0 0 CHANNELS 0 }}" for k in range(3999))
    text = (
        "HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 1 Xposition\n"
        + joints
        + "\n}\nMOTION\nFrames: 4000\nFrame Time: 0.01\n"
        + "0\n" * 4000
    )
    p = tmp_path / "wide.bvh"
    p.write_text(text)
    out = _load_capped(p, "bvh")
    assert out.startswith("ReadError:") and "4000 frames x 4000 joints" in out, out


def _npy(shape: tuple[int, ...], dtype: str = "<f8", data: bytes = b"") -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buf, {"descr": dtype, "fortran_order": False, "shape": shape}
    )
    return buf.getvalue() + data


def test_npz_declaring_a_54_tib_array(tmp_path):
    p = tmp_path / "huge.npz"
    with zipfile.ZipFile(p, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("format_version.npy", _npy((), "<i8", np.int64(1).tobytes()))
        zf.writestr("n_bodies.npy", _npy((), "<i8", np.int64(1).tobytes()))
        zf.writestr("b0/positions.npy", _npy((10**11 * 25 * 3,)))  # 6e13 bytes
    assert p.stat().st_size < 1024
    out = _load_capped(p, "npz")
    assert out.startswith("ReadError:") and "b0/positions.npy declares shape" in out, out


def test_npz_members_beyond_the_size_limit(tmp_path):
    p = tmp_path / "bomb.npz"
    with zipfile.ZipFile(p, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as zf:
        with zf.open("b0/positions.npy", "w", force_zip64=True) as fh:
            fh.write(_npy((65 * 2**19,)))  # 260 MiB, just past the documented 256 MiB
            for _ in range(65):
                fh.write(bytes(2**22))
    out = _load_capped(p, "npz")
    assert out.startswith("ReadError:") and "limit of 256 MiB" in out, out


def test_csv_grouping_by_body_is_linear(tmp_path):
    """20,000 rows of 20,000 bodies (quadratic grouping took minutes)."""
    rows = "".join(f"{b},0.5,0.5,0.5\n" for b in range(20000))
    p = tmp_path / "bodies.csv"
    p.write_text("body,a_x,a_y,a_z\n" + rows)
    assert _load_capped(p, "csv", timeout=8) == "OK"  # linear: ~1 s; quadratic: minutes
    seqs = read_csv(p)
    assert [s.body_id for s in seqs[:3]] == [0, 1, 2] and len(seqs) == 20000


# ---------------------------------------------------------------------------------------
# fuzzing: mutated valid files give a ReadError naming the file, or sane data
# ---------------------------------------------------------------------------------------


def _valid_npz(tmp_path_factory) -> bytes:
    rng = np.random.default_rng(1)
    seqs = [
        SkeletonSequence(
            rng.normal(size=(3, 25, 3)),
            "kinect_v2",
            np.full((3, 25), 2, dtype=np.int8),
            np.array([0.0, 0.5, 1.0]),
            30.0,
            b,
            {"nested": [{"a": np.arange(3)}]},
        )
        for b in (4, 5)
    ]
    p = tmp_path_factory.mktemp("npz") / "v.npz"
    write_npz(seqs, p)
    return p.read_bytes()


FUZZ_READERS = {name: (spec[0], spec[1]) for name, spec in TEXT_FORMATS.items()}
FUZZ_READERS["npz"] = (read_npz, "f.npz")
FUZZ_SETTINGS = settings(
    max_examples=200,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
# bytes that number parsers, separators and UTF-8 decoding react to
HOSTILE_BYTES = st.sampled_from(
    [
        *(b"0", b"9", b"-", b".", b"e", b"_", b"n", b"a", b",", b" ", b"\t", b"\n", b"\r"),
        *(b"\x00", b"\xff", b"\xef\xbc\x91", b"\xd9\xa1", b"1e308", b"nan", b"{", b"}"),
    ]
)


def _mutate(data, raw: bytes) -> bytes:
    raw = bytearray(raw[: data.draw(st.integers(len(raw) // 2, len(raw)))])
    for _ in range(data.draw(st.integers(1, 4))):
        k = data.draw(st.integers(0, max(len(raw) - 1, 0)))
        if data.draw(st.booleans()):
            raw[k : k + 1] = data.draw(HOSTILE_BYTES)
        else:
            raw[k : k + 1] = bytes([data.draw(st.integers(0, 255))])
    return bytes(raw)


def _remutated_member(data, raw: bytes) -> bytes:
    """The archive with one member's content mutated and the zip rebuilt (valid CRCs),
    so that the fuzzing reaches the .npy headers, the arrays and the JSON."""
    with zipfile.ZipFile(io.BytesIO(raw)) as zf:
        members = {i.filename: zf.read(i) for i in zf.infolist()}
    key = data.draw(st.sampled_from(sorted(members)))
    members[key] = _mutate(data, members[key])
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zf:
        for k, v in members.items():
            zf.writestr(k, v)
    return out.getvalue()


def _check_result(p, reader) -> None:
    """A ReadError naming the file, or sequences within the documented bounds."""
    try:
        result = reader(p)
    except ReadError as exc:
        assert str(p) in str(exc)
        return
    for s in result:
        assert isinstance(s, SkeletonSequence)
        finite = s.positions[~np.isnan(s.positions)]
        assert np.all(np.abs(finite) <= MAX_ABS_POSITION_M)
        assert s.fps is None or 1e-3 <= s.fps <= 1e5


@pytest.mark.parametrize("name", sorted(FUZZ_READERS))
@FUZZ_SETTINGS
@given(data=st.data())
def test_mutated_valid_files(tmp_path_factory, name, data):
    reader, fname = FUZZ_READERS[name]
    if name == "npz":
        raw = _valid_npz(tmp_path_factory)
        raw = _remutated_member(data, raw) if data.draw(st.booleans()) else _mutate(data, raw)
    else:
        raw = _mutate(data, TEXT_FORMATS[name][2].replace("{v}", "0.5").encode("utf-8"))
    p = tmp_path_factory.mktemp("fuzz") / fname
    p.write_bytes(raw)
    _check_result(p, reader)


def test_npz_corrupt_deflate_stream(tmp_path_factory):
    """Bytes changed inside a member's deflate data: zlib.error became a ReadError."""
    raw = bytearray(_valid_npz(tmp_path_factory))
    with zipfile.ZipFile(io.BytesIO(bytes(raw))) as zf:
        info = zf.getinfo("b0/positions.npy")
    name_len, extra_len = struct.unpack(
        "<HH", raw[info.header_offset + 26 : info.header_offset + 30]
    )
    start = info.header_offset + 30 + name_len + extra_len  # the deflate data
    raw[start : start + 16] = b"\xff" * 16  # an invalid block type
    p = tmp_path_factory.mktemp("z") / "z.npz"
    p.write_bytes(bytes(raw))
    with pytest.raises(ReadError, match="error") as e:
        read_npz(p)
    assert str(p) in str(e.value)


@pytest.mark.parametrize(
    "header",
    [
        b"{'descr': '<f8', 'fortran_order': False, 'shape': (3, }",  # tokenize.TokenError
        b"{'descr': '<f8', 'fortran_order': False, 'shape': ('''3,), }",
        b"{'descr': [1], 'fortran_order': False, 'shape': (3,), }",
        b"{'descr': '<f8', 'fortran_order': False, 'shape': (-3,), }",
    ],
)
def test_npz_malformed_npy_header(tmp_path, header):
    header = header + b" " * (118 - len(header)) + b"\n"
    member = b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header
    p = tmp_path / "h.npz"
    with zipfile.ZipFile(p, "w") as zf:
        zf.writestr("n_bodies.npy", member)
    with pytest.raises(ReadError, match=r"expected a NumPy \.npz archive|n_bodies\.npy") as e:
        read_npz(p)
    assert str(p) in str(e.value)


def test_npz_deeply_nested_header(tmp_path_factory):
    """A header JSON nested 100,000 deep: RecursionError became a ReadError."""
    raw = _valid_npz(tmp_path_factory)
    with zipfile.ZipFile(io.BytesIO(raw)) as zf:
        members = {i.filename: zf.read(i) for i in zf.infolist()}
    header = np.array('{"fps": ' + "[" * 100000 + "]" * 100000 + "}")
    buf = io.BytesIO()
    np.save(buf, header)
    members["b0/header.npy"] = buf.getvalue()
    p = tmp_path_factory.mktemp("r") / "r.npz"
    with zipfile.ZipFile(p, "w") as zf:
        for k, v in members.items():
            zf.writestr(k, v)
    with pytest.raises(ReadError, match=r"inconsistent tobitkf \.npz archive"):
        read_npz(p)


# ---------------------------------------------------------------------------------------
# writers: what is written reads back equal, or the writer refuses with a clear error
# ---------------------------------------------------------------------------------------

# names the CSV can hold (quoted where needed) and names it cannot
CSV_NAMES = [
    "Head,L",
    'say "hi"',
    "semi;colon",
    "tab\tname",
    "#hash",
    "\u00fcn\u00ef\u00e7\u00f8d\u00e9",
    "\u540d\u524d",
    "emoji\U0001f600",
    "a_x",
    "time",
    "body",
    "x_state",
    '"',
    ",",
]
CSV_REFUSED = ["new\nline", "cr\rname", "", " ", " lead", "trail ", "nul\x00", "\u2028"]


def _sequence(names, body_id=None):
    T, J = 3, len(names)
    pos = np.arange(T * J * 3, dtype=float).reshape(T, J, 3) / 7.0
    pos[1, 0] = np.nan
    state = np.full((T, J), 2, dtype=np.int8)
    state[1, 0] = 0
    topo = Topology.from_names(names, up_axis=2, name="hostile")
    return SkeletonSequence(pos, topo, state, np.array([0.0, 0.25, 0.5]), 4.0, body_id)


def _assert_equal(a: SkeletonSequence, b: SkeletonSequence) -> None:
    assert a.joint_names == b.joint_names
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(a.tracking_state, b.tracking_state)
    np.testing.assert_array_equal(a.timestamps, b.timestamps)
    assert (a.fps, a.body_id) == (b.fps, b.body_id)


@pytest.mark.parametrize("sep", [",", "\t", ";"])
@pytest.mark.parametrize("name", CSV_NAMES)
def test_csv_round_trip_of_hostile_names(tmp_path, name, sep):
    seq = _sequence([name, "other"], body_id=3)
    p = tmp_path / "h.csv"
    write_csv([seq], p, sep=sep)
    (back,) = load(p)
    _assert_equal(seq, back)


@pytest.mark.parametrize("name", CSV_REFUSED)
def test_csv_refuses_names_it_cannot_hold(tmp_path, name):
    p = tmp_path / "h.csv"
    with pytest.raises(ValueError, match="cannot write the joint name"):
        write_csv([_sequence([name, "other"])], p)
    assert not p.exists()


@pytest.mark.parametrize("body_id", ["12", 1.5, "two\nlines"])
def test_csv_refuses_body_ids_that_read_back_different(tmp_path, body_id):
    with pytest.raises(ValueError, match="cannot write the body id"):
        write_csv([_sequence(["a"], body_id=body_id)], tmp_path / "b.csv")


def test_qualisys_marker_with_a_comma_survives_csv(tmp_path):
    q = tmp_path / "q.tsv"
    q.write_text("NO_OF_FRAMES\t1\nMARKER_NAMES\tHead,L\tB\n1\t2\t3\t4\t5\t6\n")
    (s,) = read_qualisys(q)
    assert s.joint_names == ("Head,L", "B")
    save(s, tmp_path / "out.csv")
    (back,) = load(tmp_path / "out.csv")
    assert back.joint_names == ("Head,L", "B")
    np.testing.assert_array_equal(back.positions, s.positions)


@pytest.mark.parametrize("name", [*CSV_NAMES, *CSV_REFUSED[:-2], "\u2028", "nul\x00mid"])
def test_npz_round_trip_of_hostile_names(tmp_path, name):
    seq = _sequence([name, "other"], body_id=name)
    p = tmp_path / "h.npz"
    write_npz([seq], p)
    (back,) = read_npz(p)
    _assert_equal(seq, back)


def test_npz_refuses_a_trailing_nul(tmp_path):
    with pytest.raises(ValueError, match="trailing NUL"):
        write_npz([_sequence(["nul\x00", "b"])], tmp_path / "h.npz")


def test_ntu_refuses_joint_names_it_cannot_hold(tmp_path):
    names = list(get_topology("kinect_v2").joints)
    names[3] = "Head,L"
    T = 2
    seq = SkeletonSequence(np.ones((T, 25, 3)), Topology.from_names(names), body_id=1)
    with pytest.raises(ValueError, match=r"no joint names.*'Head,L'"):
        write_ntu([seq], tmp_path / "h.skeleton")
    kinect = SkeletonSequence(np.ones((T, 25, 3)), "kinect_v2", body_id=1)
    write_ntu([kinect], tmp_path / "k.skeleton")
    (back,) = read_ntu(tmp_path / "k.skeleton")
    assert back.joint_names == kinect.joint_names and back.body_id == 1
    np.testing.assert_array_equal(back.positions, kinect.positions)
