"""OpenSim marker trajectories (``.trc``, "Track Row Column"), read and written.

Layout (tab-separated)::

    PathFileType  4  (X/Y/Z)  walk.trc
    DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  OrigDataStartFrame  ...
    60        60          120        3           mm     60            1                   ...
    Frame#  Time  RASI        LASI        ...
                  X1  Y1  Z1  X2  Y2  Z2  ...
    1  0.0  ...
    2  0.016667  ...

Reading: the values of line 3 are taken by the names of line 2 (any order); ``Units``
``mm``, ``cm`` or ``m`` (converted to metres, ``units="m"``); ``DataRate`` is the fps;
marker names are the non-empty fields of line 4 after ``Frame#`` and ``Time`` (surrounding
spaces removed); data rows follow (blank lines skipped), ``Frame# Time`` then x, y, z per
marker; an empty field or ``NaN`` is a missing coordinate, and a row cut short (trailing
markers left out) has them missing. ``NumFrames`` may differ from the rows present (kept
in ``metadata["header"]``). OpenSim's frame is y up (the sequences read have up axis 1).

Writing (:func:`write_trc`): one sequence of 3-D positions in a length unit (``m``, ``cm``,
``mm``); ``units`` chooses the file's unit (default: the sequence's own, so nothing is
rescaled). Numbers are written with the shortest text that reads back to the same float,
missing coordinates as ``nan``, as OpenSim writes them (OpenSim drops empty fields at the
end of a row, and then refuses the row as short of columns), ``DataRate`` = fps (or the
median rate of the timestamps), ``Time`` = the frame times, ``Frame#`` and
``OrigDataStartFrame`` numbered from the capture's frame at the first time (frame 1 at
time 0: a trial cut from a longer capture keeps its numbers). A sequence whose up axis
is not y (a C3D or Qualisys lab's z) is turned a quarter turn so that it is, as OpenSim
expects: z up becomes ``(x, y, z) -> (x, z, -y)``. Marker names must be
non-empty, without tabs or line breaks (control characters) and without surrounding
spaces; anything else is refused with a ValueError. Confidence and tracking states have
no place in a TRC file.
"""

from __future__ import annotations

import os
import re
import unicodedata
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tobitkf.io._marker_writer import MARKER_UNITS, first_frame, one_3d_sequence, rotate_up
from tobitkf.io._text import (
    check_positions,
    check_rate,
    check_times,
    fmt_float,
    fmt_floats,
    nonempty,
    parse_int,
    parse_number,
    parse_rows,
    read_lines,
)
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology

__all__ = ["read_trc", "sniff_trc", "write_trc"]

_HEADER_KEYS = (
    "DataRate", "CameraRate", "NumFrames", "NumMarkers", "Units", "OrigDataRate",
    "OrigDataStartFrame", "OrigNumFrames",
)  # fmt: skip


def read_trc(path: str | os.PathLike[str], implausible: str = "error") -> list[SkeletonSequence]:
    """Read an OpenSim ``.trc`` marker file.

    Returns
    -------
    list with one SkeletonSequence: positions (T, M, 3) metres (NaN where missing), fps =
    DataRate, timestamps = the Time column, ``metadata["header"]`` (line 3 by name) and
    ``metadata["frame_numbers"]``.
    """
    lines = read_lines(path)
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise ReadError(path, 1, "expected a TRC header starting with 'PathFileType'")
    keys = [k.strip() for k in lines[1].split("\t")]
    vals = [v.strip() for v in lines[2].split("\t")]
    header = {k: v for k, v in zip(keys, vals) if k}
    for key in ("DataRate", "Units"):
        if key not in header:
            raise ReadError(path, 2, f"expected a {key} field in the TRC header line")
    rate = parse_number(path, 3, header["DataRate"], "DataRate")
    fps = check_rate(path, 3, rate, "DataRate", header["DataRate"])
    unit = header["Units"].lower()
    if unit not in MARKER_UNITS:
        raise ReadError(path, 3, f"expected Units mm, cm or m, found {header['Units'][:20]!r}")
    names_row = lines[3].split("\t")
    if [f.strip() for f in names_row[:2]] != ["Frame#", "Time"]:
        raise ReadError(path, 4, "expected the column line 'Frame#<TAB>Time<TAB><marker>...'")
    names = [f.strip() for f in names_row[2:] if f.strip()]
    if not names:
        raise ReadError(path, 4, "no marker names after Frame# and Time")
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ReadError(path, 4, f"duplicate marker names {dup[:5]}")
    if "NumMarkers" in header:
        declared = parse_int(path, 3, header["NumMarkers"], "NumMarkers", 0)
        if declared != len(names):
            raise ReadError(path, 4, f"NumMarkers says {declared}, line 4 names {len(names)}")
    m = len(names)
    ncols = 2 + 3 * m
    # the X1 Y1 Z1 line (line 5) is left out by some writers: then line 5 is data
    start = 5 if not lines[4].strip() or "X1" in lines[4].split("\t") else 4
    rows, numbers = nonempty(lines, start)
    if not rows:
        raise ReadError(path, None, "no frames after the header")
    fixed = []
    for row in rows:
        fields = row.split("\t")
        if len(fields) > ncols and not any(f.strip() for f in fields[ncols:]):
            fields = fields[:ncols]  # trailing tabs
        elif 2 <= len(fields) < ncols:
            fields = fields + [""] * (ncols - len(fields))  # trailing markers left out
        fixed.append("\t".join(fields))
    data = parse_rows(
        path,
        fixed,
        numbers,
        sep="\t",
        ncols=ncols,
        what=f"Frame#, Time and {m} markers x 3",
        allow_empty=True,
        allow_nan=True,
    )
    times = data[:, 1].copy()
    check_times(path, times, numbers, "Time value")
    positions = np.ascontiguousarray(data[:, 2:].reshape(-1, m, 3)) * MARKER_UNITS[unit]
    check_positions(path, positions, numbers, implausible, names=names)
    seq = SkeletonSequence(
        positions=positions,
        topology=Topology.from_names(names, up_axis=1, name="trc"),
        timestamps=times,
        fps=fps,
        units="m",
        metadata={
            "source": str(path),
            "format": "trc",
            "units_in_file": unit,
            "header": header,
            "frame_numbers": data[:, 0].copy(),
        },
    )
    return [seq]


def _check_name(name: str) -> str:
    bad = next((c for c in name if unicodedata.category(c) in ("Cc", "Cs", "Zl", "Zp")), None)
    if bad is not None:
        raise ValueError(
            f"cannot write the marker name {name!r} to TRC: it holds the control character "
            f"U+{ord(bad):04X} (fields are tab-separated, one line per header); rename it"
        )
    if not name.strip() or name != name.strip():
        raise ValueError(
            f"cannot write the marker name {name!r} to TRC: names are read with surrounding "
            "white space removed and must not be empty; rename it"
        )
    return name


def _label(name: str) -> str:
    """The file name shown on line 1 (information only): a batch run's temporary name
    ``.NAME.RANDOM.partEXT`` shows as NAME; a name with control characters as
    ``tobitkf.trc``."""
    m = re.fullmatch(r"\.(.+)\.[^.]+\.part(\.trc)?", name, flags=re.IGNORECASE)
    if m:
        name = m.group(1)
    if any(unicodedata.category(c) in ("Cc", "Cs", "Zl", "Zp") for c in name):
        return "tobitkf.trc"
    return name


def _rate(seq: SkeletonSequence) -> float:
    if seq.fps is not None:
        return float(seq.fps)
    dt = seq.dt()
    dt = dt[dt > 0]
    if dt.size:
        return float(1.0 / np.median(dt))
    raise ValueError("cannot write a TRC DataRate: the sequence has no fps and no time steps")


def write_trc(
    sequences: Sequence[SkeletonSequence],
    path: str | os.PathLike[str],
    *,
    units: str | None = None,
) -> None:
    """Write one sequence of 3-D marker positions as an OpenSim ``.trc`` file.

    Parameters
    ----------
    units : {"m", "cm", "mm"}, optional
        Unit of the file; positions are converted from the sequence's units. By default
        the sequence's own units. A sequence in unknown units (None) is written as they
        are, labelled ``units`` (which is then required).
    """
    seq, units, scale = one_3d_sequence(sequences, "TRC", "markers", units)
    names = [_check_name(n) for n in seq.joint_names]
    rate = _rate(seq)
    T, M = seq.n_frames, seq.n_joints
    pos = seq.positions * scale if scale != 1.0 else seq.positions
    # OpenSim's frame is y up (and the reader says so): a z-up lab (C3D, Qualisys) turned
    pos = rotate_up(pos, seq.topology.up_axis, 1)
    times = seq.times()
    label = _label(Path(path).name)
    start = first_frame(seq, rate)  # a trial cut from a longer capture keeps its numbers
    r = fmt_float(rate)
    out = [
        f"PathFileType\t4\t(X/Y/Z)\t{label}",
        "\t".join(_HEADER_KEYS),
        "\t".join([r, r, str(T), str(M), units, r, str(start), str(T)]),
        "\t".join(["Frame#", "Time", *(f"{n}\t\t" for n in names)]).rstrip("\t"),
        "\t\t" + "\t".join(f"X{i}\tY{i}\tZ{i}" for i in range(1, M + 1)),
    ]
    vals = fmt_floats(pos, nan="nan")  # OpenSim's own spelling; never an empty field
    stamps = fmt_floats(times)
    W = M * 3
    for t in range(T):
        out.append("\t".join([str(start + t), stamps[t], *vals[t * W : (t + 1) * W]]))
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write("\n".join(out) + "\n")


def sniff_trc(path: Path, head: str) -> int:
    """Score: the first line starts with ``PathFileType``."""
    return 95 if head.lstrip("\ufeff").startswith("PathFileType") else 0


register_format(
    "trc", read_trc, write_trc, (".trc",), sniff_trc,
    description="OpenSim marker trajectories (TRC)",
)  # fmt: skip
