"""TRC (read and write) and the C3D writer.

TRC fixtures are written here as OpenSim-style tools write them (MATLAB ``fprintf`` with
``%s\\t\\t\\t`` after each marker name, a blank line after the X1 Y1 Z1 line, millimetres,
trailing tabs); written files are also parsed back with pandas (the Pose2Sim recipe), not
only with our reader. C3D output is read back with the ``c3d`` library itself and with
our reader. Values written by the C3D format are float32: expected values are
``np.float32(x)``, an exact identity.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pandas as pd
import pytest

from tobitkf.core.jsonable import to_jsonable
from tobitkf.io import ReadError, detect_format, load, save
from tobitkf.io.trc import read_trc, write_trc
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology

OPENSIM_STYLE = (
    "PathFileType\t4\t(X/Y/Z)\twalk.trc\n"
    "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames\n"
    "100.00\t100.00\t3\t3\tmm\t100.00\t1\t3\n"
    "Frame#\tTime\tR.ASIS\t\t\tL.ASIS\t\t\tV.Sacral\t\t\t\n"
    "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\tX3\tY3\tZ3\t\n"
    "\n"
    "1\t0.000\t1.5\t952.25\t120.125\t-3\t950\t-120.5\t-150.75\t960.5\t0.25\t\n"
    "2\t0.010\t\t\t\t-2\t951\t-121\t-151\t961\t1\t\n"
    "3\t0.020\t2.5\t953\t121\t-1\t952\t-122\n"
)


def test_reads_an_opensim_style_file(tmp_path):
    p = tmp_path / "walk.trc"
    p.write_text(OPENSIM_STYLE)
    assert detect_format(p) == "trc"
    (s,) = load(p)
    assert s.joint_names == ("R.ASIS", "L.ASIS", "V.Sacral")
    assert s.fps == 100.0 and s.units == "m" and s.topology.up_axis == 1
    np.testing.assert_array_equal(s.timestamps, [0.0, 0.01, 0.02])
    np.testing.assert_array_equal(s.positions[0, 0], np.array([1.5, 952.25, 120.125]) * 1e-3)
    assert np.isnan(s.positions[1, 0]).all()  # empty fields
    assert np.isnan(s.positions[2, 2]).all()  # row cut short
    np.testing.assert_array_equal(s.positions[2, 1], np.array([-1, 952, -122]) * 1e-3)
    assert s.metadata["header"]["NumFrames"] == "3"


def _seq(names, T=5, fps=50.0, units="m", seed=0):
    rng = np.random.default_rng(seed)
    pos = rng.normal(size=(T, len(names), 3))
    pos[1, 0] = np.nan
    pos[3, -1] = np.nan
    return SkeletonSequence(pos, Topology.from_names(names), fps=fps, units=units)


HOSTILE = [
    "Head,L",
    'say "hi"',
    "#hash",
    "ünïçødé",
    "名前",
    "emoji\U0001f600",
    "a b",
    "1.5",
    "Frame#",
    "X1",
    ";",
]
TRC_REFUSED = ["tab\tname", "new\nline", "cr\rname", "", " ", " lead", "trail ", "nul\x00"]


@pytest.mark.parametrize("name", HOSTILE)
def test_trc_round_trip_of_hostile_names(tmp_path, name):
    seq = _seq([name, "other", "third"])
    p = tmp_path / "h.trc"
    save(seq, p)
    (back,) = load(p)
    assert back.joint_names == seq.joint_names
    np.testing.assert_array_equal(back.positions, seq.positions)
    np.testing.assert_array_equal(back.timestamps, seq.times())
    assert back.fps == seq.fps


@pytest.mark.parametrize("name", TRC_REFUSED)
def test_trc_refuses_names_it_cannot_hold(tmp_path, name):
    p = tmp_path / "h.trc"
    with pytest.raises(ValueError, match="cannot write the marker name"):
        write_trc([_seq([name, "other"])], p)
    assert not p.exists()


def test_trc_written_file_parses_with_pandas_and_converts_units(tmp_path):
    seq = _seq(["A", "B"], units="m")
    p = tmp_path / "mm.trc"
    write_trc([seq], p, units="mm")
    head = pd.read_csv(p, sep="\t", skiprows=1, header=None, nrows=2)
    header = dict(zip(head.iloc[0], head.iloc[1]))
    assert header["Units"] == "mm" and float(header["DataRate"]) == 50.0
    assert int(header["NumFrames"]) == 5 and int(header["NumMarkers"]) == 2
    data = pd.read_csv(p, sep="\t", skiprows=5, header=None).to_numpy(dtype=float)
    np.testing.assert_array_equal(data[:, 0], np.arange(1, 6))
    np.testing.assert_array_equal(data[:, 2:], (seq.positions * 1000.0).reshape(5, 6))
    (back,) = read_trc(p)
    np.testing.assert_allclose(back.positions, seq.positions, rtol=1e-15, atol=0)


def test_trc_rows_are_whole_when_the_last_marker_is_missing(tmp_path):
    """OpenSim's TRCFileAdapter drops empty fields at the end of a row and then refuses
    the row ("Unexpected number of columns"); it writes a missing marker as nan."""
    seq = _seq(["A", "B", "C"])  # frame 3 misses C, the row's last marker
    p = tmp_path / "last.trc"
    write_trc([seq], p)
    rows = p.read_text().splitlines()[5:]
    for t, row in enumerate(rows):
        fields = row.split("\t")
        assert len(fields) == 2 + 3 * 3 and all(f.strip() for f in fields), row
        missing = np.isnan(seq.positions[t]).ravel()
        assert [f == "nan" for f in fields[2:]] == missing.tolist()
    np.testing.assert_array_equal(read_trc(p)[0].positions, seq.positions)


def test_trc_writer_rules(tmp_path):
    p = tmp_path / "x.trc"
    with pytest.raises(ValueError, match="one set of markers"):
        write_trc([_seq(["a"]), _seq(["a"])], p)
    px = SkeletonSequence(np.ones((2, 1, 2)), Topology.from_names(["a"]), units="px")
    with pytest.raises(ValueError, match="3-D"):
        write_trc([px], p)
    unknown = SkeletonSequence(np.ones((2, 1, 3)), Topology.from_names(["a"]), fps=10, units=None)
    with pytest.raises(ValueError, match="unknown"):
        write_trc([unknown], p)
    write_trc([unknown], p, units="mm")
    (back,) = read_trc(p)
    np.testing.assert_array_equal(back.positions, np.full((2, 1, 3), 1e-3))
    # no fps: the rate of the timestamps
    ts = SkeletonSequence(np.ones((3, 1, 3)), Topology.from_names(["a"]), timestamps=[0, 0.5, 1.0])
    write_trc([ts], p)
    (back,) = read_trc(p)
    assert back.fps == 2.0
    np.testing.assert_array_equal(back.timestamps, [0, 0.5, 1.0])


@pytest.mark.parametrize(
    "text, match",
    [
        ("hello\n", "PathFileType"),
        (OPENSIM_STYLE.replace("\tmm\t", "\tinch\t"), "Units"),
        (OPENSIM_STYLE.replace("100.00\t100.00\t3\t3", "100.00\t100.00\t3\t4"), "NumMarkers"),
        (OPENSIM_STYLE.replace("1\t0.000\t1.5", "1\t0.000\tx"), "field 3"),
        (OPENSIM_STYLE.replace("2\t0.010", "2\t-1.0"), "non-decreasing"),
        (OPENSIM_STYLE.replace("Frame#\tTime\tR.ASIS", "Frame#\tTime\tL.ASIS"), "duplicate"),
        (OPENSIM_STYLE.replace("100.00\t100.00", "0\t100.00"), "DataRate"),
    ],
)
def test_trc_bad_content(tmp_path, text, match):
    p = tmp_path / "bad.trc"
    p.write_text(text)
    with pytest.raises(ReadError, match=match) as err:
        read_trc(p)
    assert str(p) in str(err.value)


# ------------------------------------------------------------------------------ C3D
C3D_HOSTILE = ["Head,L", 'say "hi"', "#hash", "a b", "1.5", "LASI", "x" * 40]
C3D_REFUSED = ["ünï", "tab\tname", "", " lead", "trail ", "new\nline"]


@pytest.mark.parametrize("name", C3D_HOSTILE)
def test_c3d_round_trip_through_the_library_and_our_reader(tmp_path, name):
    c3d = pytest.importorskip("c3d")
    seq = _seq([name, "B", "C"], T=6, fps=120.0, units="mm")
    p = tmp_path / "w.c3d"
    save(seq, p)
    with open(p, "rb") as fh:
        r = c3d.Reader(fh)
        assert [lab.strip() for lab in r.point_labels] == [name, "B", "C"]
        assert r.point_rate == 120.0 and r.frame_count == 6
        assert r.get("POINT:UNITS").string_value.strip() == "mm"
        pts = np.stack([p_[:, :4] for _, p_, _ in r.read_frames()])
    present = ~np.isnan(seq.positions).any(axis=-1)
    np.testing.assert_array_equal(pts[..., :3][present], seq.positions.astype(np.float32)[present])
    assert (pts[..., 3][~present] == -1).all() and (pts[..., 3][present] >= 0).all()
    (back,) = load(p)
    assert back.joint_names == (name, "B", "C") and back.units == "m" and back.fps == 120.0
    expected = seq.positions.astype(np.float32).astype(float) * 1e-3
    np.testing.assert_array_equal(back.positions, expected)


@pytest.mark.parametrize("name", C3D_REFUSED)
def test_c3d_refuses_labels_it_cannot_hold(tmp_path, name):
    pytest.importorskip("c3d")
    p = tmp_path / "h.c3d"
    with pytest.raises(ValueError, match="cannot write the label"):
        save(_seq([name, "other"]), p)
    assert not p.exists()


def test_c3d_units_option(tmp_path):
    pytest.importorskip("c3d")
    seq = _seq(["A"], units="m")
    p = tmp_path / "m.c3d"
    save(seq, p, units="mm")
    (back,) = load(p)
    expected = (seq.positions * 1000.0).astype(np.float32).astype(float) * 1e-3
    np.testing.assert_array_equal(back.positions, expected)
    with pytest.raises(ValueError, match="one set of points"):
        save([seq, seq], tmp_path / "two.c3d")


def test_c3d_keeps_a_rate_not_times_and_refuses_frames_off_its_grid(tmp_path):
    """C3D has no times: frames within half a frame of the rate's grid are written (read
    back at the grid's times), a dropped or irregular frame is refused, nothing written."""
    pytest.importorskip("c3d")
    base = _seq(["A", "B"], T=8, fps=None)
    grid = np.arange(8) / 50.0
    jitter = np.array([0, 1, -1, 1, 0, -1, 1, 0]) * 1e-3  # a clock's, 0.05 frame at 50 Hz
    p = tmp_path / "j.c3d"
    save(base.replace(timestamps=grid + jitter), p)
    (back,) = load(p)
    assert back.fps == pytest.approx(50.0, rel=0.01)
    np.testing.assert_allclose(back.times(), grid, atol=0.1 / 50)
    dropped = np.r_[grid[:4], grid[4:] + 1 / 50]  # a frame dropped after the fourth
    late = np.r_[grid[:3], grid[3:] + 0.015]  # frame 3 on, three quarters of a frame late
    for times, frame in ((dropped, 4), (late, 3)):
        q = tmp_path / f"bad{frame}.c3d"
        with pytest.raises(ValueError, match=rf"keep a frame rate.*frame {frame},"):
            save(base.replace(timestamps=times), q)
        assert not q.exists()


def test_new_formats_are_registered():
    from tobitkf.io import formats, writable_formats

    assert {"openpose", "mediapipe", "azure_kinect", "trc", "c3d"} <= set(formats())
    assert {"trc", "c3d"} <= set(writable_formats())


def test_trc_without_the_coordinate_line(tmp_path):
    lines = OPENSIM_STYLE.split("\n")
    del lines[4:6]  # no "X1 Y1 Z1" line, no blank line
    p = tmp_path / "short.trc"
    p.write_text("\n".join(lines))
    (s,) = read_trc(p)
    assert s.n_frames == 3
    np.testing.assert_array_equal(s.positions[0, 0], np.array([1.5, 952.25, 120.125]) * 1e-3)


def test_a_trial_cut_from_a_longer_capture_keeps_its_clock(tmp_path):
    """A C3D trial whose first frame is 148 (1.47 s at 100 Hz: the force plates' and
    analog channels' clock) is read at its times, and C3D and TRC outputs number their
    frames from 148 again (checked with the c3d library's own reader)."""
    c3d = pytest.importorskip("c3d")
    seq = _seq(["A", "B"], T=6, fps=100.0)
    seq = seq.replace(timestamps=(147 + np.arange(6)) / 100.0)
    p = tmp_path / "trial.c3d"
    save(seq, p)
    with open(p, "rb") as fh:
        reader = c3d.Reader(fh)
        assert (reader.first_frame, reader.last_frame) == (148, 153)
    (back,) = load(p)
    np.testing.assert_allclose(back.times(), seq.timestamps, rtol=0, atol=1e-12)
    assert back.metadata["first_frame"] == 148
    t = tmp_path / "trial.trc"
    save(back, t)
    lines = t.read_text().splitlines()
    header = dict(zip(lines[1].split("\t"), lines[2].split("\t")))
    assert header["OrigDataStartFrame"] == "148"
    assert [ln.split("\t")[0] for ln in lines[5:]] == [str(148 + k) for k in range(6)]
    np.testing.assert_allclose(read_trc(t)[0].times(), seq.timestamps, rtol=0, atol=1e-12)
    # a capture from its first frame stays plain: frame 1, no timestamps
    save(_seq(["A"], fps=100.0), p)
    (plain,) = load(p)
    assert plain.timestamps is None and plain.metadata["first_frame"] == 1


def test_the_pig_trial_is_read_at_its_capture_times(shared_data):
    c3d = pytest.importorskip("c3d")
    path = shared_data("btkdata/PiG_Motion-FlatFoot-Full.c3d")
    with open(path, "rb") as fh:
        reader = c3d.Reader(fh)
        first, rate = reader.first_frame, reader.point_rate
    (seq,) = load(path)
    assert first > 1
    np.testing.assert_allclose(seq.times()[:3], (first - 1 + np.arange(3)) / rate)


def test_quarter_turns_between_up_axes_are_proper_rotations():
    from tobitkf.io._marker_writer import rotate_up

    eye = np.eye(3)
    for up in range(3):
        for to in range(3):
            rot = rotate_up(eye, up, to)  # rows: the images of e_x, e_y, e_z
            np.testing.assert_allclose(rot @ rot.T, eye, atol=1e-15)
            assert np.linalg.det(rot) == pytest.approx(1.0)
            np.testing.assert_array_equal(rot[up], eye[to])
    # z up to y up: OpenSim's usual turn of lab data
    np.testing.assert_array_equal(rotate_up(np.array([1.0, 2.0, 3.0]), 2, 1), [1.0, 3.0, -2.0])


def test_trc_is_y_up_and_c3d_keeps_the_up_axis(tmp_path):
    """A z-up lab recording written as TRC has its heights in OpenSim's Y column; C3D
    records the up axis in POINT:Y_SCREEN (read by the c3d library) and reads it back."""
    c3d = pytest.importorskip("c3d")
    seq = _seq(["A", "B"], T=4, fps=100.0)
    zup = seq.replace(topology=Topology.from_names(["A", "B"], up_axis=2))
    t = tmp_path / "lab.trc"
    save(zup, t)
    data = pd.read_csv(t, sep="\t", skiprows=5, header=None).to_numpy(dtype=float)[:, 2:]
    heights = data.reshape(4, 2, 3)[:, :, 1]
    np.testing.assert_array_equal(heights, zup.positions[:, :, 2])  # nan where missing
    (back,) = read_trc(t)
    assert back.topology.up_axis == 1
    for up in (1, 2):
        s = seq.replace(topology=Topology.from_names(["A", "B"], up_axis=up))
        p = tmp_path / f"up{up}.c3d"
        save(s, p)
        with open(p, "rb") as fh:
            assert c3d.Reader(fh).get_screen_axis()[1].strip() == "+" + "XYZ"[up]
        (b,) = load(p)
        assert b.topology.up_axis == up
        np.testing.assert_allclose(b.positions, s.positions, rtol=1e-6, atol=1e-6)


# ------------------------------------------------------------------ C3D provenance
def _smoothed():
    from test_cli import _recording
    from tobitkf import smooth

    return smooth(_recording(), method="robust")


def test_c3d_keeps_the_provenance_in_a_group_of_its_own(tmp_path):
    """A smoothed sequence's provenance (robust's, thousands of characters) is ASCII JSON
    in the char array TOBITKF:PROVENANCE, rows of at most 255 characters (a C3D
    dimension is one byte), read back equal; the c3d library reads the file as before."""
    c3d = pytest.importorskip("c3d")
    out = _smoothed()
    prov = to_jsonable(out.metadata["provenance"])  # JSON: NaN is null
    p = tmp_path / "s.robust.c3d"
    save(out, p)
    with open(p, "rb") as fh:
        r = c3d.Reader(fh)
        rows = list(r.get("TOBITKF:PROVENANCE").string_array)
        assert [lab.strip() for lab in r.point_labels] == list(out.joint_names)
        pts = np.stack([p_[:, :3] for _, p_, _ in r.read_frames()])
    np.testing.assert_array_equal(pts, out.positions.astype(np.float32))
    text = "".join(rows)
    assert len(text.strip()) > 255 and len(rows) > 1 and {len(row) for row in rows} == {255}
    assert json.loads(text) == prov
    (back,) = load(p)
    assert back.metadata["provenance"] == prov
    # a sequence without provenance gets no group
    save(_seq(["A", "B"]), p)
    with open(p, "rb") as fh:
        assert c3d.Reader(fh).get("TOBITKF") is None
    assert "provenance" not in load(p)[0].metadata


def test_c3d_provenance_beyond_one_parameter_and_beyond_the_file(tmp_path):
    """JSON longer than one parameter holds (a 16-bit size) goes on in PROVENANCE2, ...;
    longer than the parameter section holds is refused, nothing written."""
    c3d = pytest.importorskip("c3d")
    out = _smoothed()
    long = to_jsonable({**out.metadata["provenance"], "note": "x" * 40000})
    p = tmp_path / "long.c3d"
    save(out.replace(metadata={**out.metadata, "provenance": long}), p)
    with open(p, "rb") as fh:
        assert sorted(c3d.Reader(fh).get("TOBITKF").param_keys()) == [
            "PROVENANCE",
            "PROVENANCE2",
        ]
    assert load(p)[0].metadata["provenance"] == long
    huge = {**long, "note": "x" * 70000}
    q = tmp_path / "huge.c3d"
    with pytest.raises(ValueError, match=r"cannot write the provenance \(\d+ characters"):
        save(out.replace(metadata={**out.metadata, "provenance": huge}), q)
    assert not q.exists()


def test_c3d_provenance_that_is_not_json_is_a_read_error(tmp_path):
    c3d = pytest.importorskip("c3d")
    w = c3d.Writer(point_rate=50.0, point_scale=-1.0, point_units="m")
    w.add_frames([(np.zeros((1, 5), dtype=np.float32), np.zeros((0, 0), dtype=np.float32))] * 3)
    w.set_point_labels(["A"])
    w.add_group(w.numeric_key_next, "TOBITKF", "x").add_str("PROVENANCE", "x", "{oops", 5, 1)
    p = tmp_path / "bad.c3d"
    with open(p, "wb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the library's note on the empty analog group
        w.write(fh)
    with pytest.raises(ReadError, match="TOBITKF:PROVENANCE is not the provenance's JSON"):
        load(p)
