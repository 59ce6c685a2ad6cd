"""Qualisys Track Manager (QTM) 3-D TSV export (data README §4).

Header: ``KEY<TAB>values`` lines with upper-case keys (``NO_OF_FRAMES``, ``NO_OF_MARKERS``,
``FREQUENCY``, ``MARKER_NAMES`` ...), optionally a column-name line
(``Frame  Time  <Marker> X ...``), then one line per frame: either ``frame time x y z ...``
or only the 3 × markers values.
Positions are millimetres (converted to metres), z up. Empty fields and markers at exactly
(0, 0, 0) (QTM's gap value) become NaN. ``NO_OF_FRAMES`` may exceed the rows present (a
cut export); the rows present are read.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from tobitkf.io._text import (
    check_positions,
    check_rate,
    check_times,
    nonempty,
    parse_int,
    parse_number,
    parse_rows,
    read_lines,
    zeros_to_nan,
)
from tobitkf.io.errors import OptionError, ReadError
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology

__all__ = ["read_qualisys", "sniff_qualisys"]

_UNIT_SCALE = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}
_HEADER_KEY = re.compile(r"[A-Z][A-Z0-9_]*")  # QTM keys: NO_OF_FRAMES, MARKER_NAMES, ...


def read_qualisys(
    path: str | os.PathLike[str], units: str = "mm", implausible: str = "error"
) -> list[SkeletonSequence]:
    """Read a QTM TSV file.

    Parameters
    ----------
    units : {"mm", "cm", "m"}
        Units of the file (QTM exports millimetres).
    implausible : {"error", "missing"}
        What to do with a position beyond the plausibility bound, in metres
        (``_text.check_positions``).

    Returns
    -------
    list with one SkeletonSequence: positions (T, M, 3) metres, topology of the marker
    names (z up), fps = FREQUENCY, timestamps from the ``Time`` column when present.
    """
    if units not in _UNIT_SCALE:
        raise OptionError(f"units must be one of {sorted(_UNIT_SCALE)}, found {units!r}")
    lines = read_lines(path)
    if not any(line.strip() for line in lines):
        raise ReadError(path, None, "empty file: expected a QTM TSV header")
    header: dict[str, list[str]] = {}
    header_line: dict[str, int] = {}
    i = 0
    while i < len(lines):
        line = lines[i]
        if not line.strip():
            i += 1
            continue
        fields = line.rstrip("\t").split("\t")
        key = fields[0].strip()
        if key.lower() == "frame":  # column-name line
            i += 1
            break
        if not _HEADER_KEY.fullmatch(key):  # the first frame (a bad number is its error)
            break
        header[key.upper()] = [f.strip() for f in fields[1:]]
        header_line[key.upper()] = i + 1
        i += 1
    names = header.get("MARKER_NAMES")
    if not names:
        raise ReadError(path, None, "expected a MARKER_NAMES header line (QTM TSV)")
    if len(set(names)) != len(names) or any(not n for n in names):
        raise ReadError(path, None, f"marker names must be unique and non-empty, found {names}")
    n_markers = len(names)
    counts = {
        key: parse_int(path, header_line[key], (header[key] or [""])[0], key, 0)
        for key in ("NO_OF_FRAMES", "NO_OF_MARKERS")
        if key in header
    }
    declared = counts.get("NO_OF_MARKERS")
    if declared is not None and declared != n_markers:
        raise ReadError(
            path,
            header_line["NO_OF_MARKERS"],
            f"NO_OF_MARKERS says {declared} but MARKER_NAMES lists {n_markers} names",
        )
    fps = None
    if "FREQUENCY" in header:
        line, text = header_line["FREQUENCY"], (header["FREQUENCY"] or [""])[0]
        fps = check_rate(path, line, parse_number(path, line, text, "FREQUENCY"), "FREQUENCY", text)
    rows, numbers = nonempty(lines, i)
    if not rows:
        raise ReadError(path, None, "no frames after the header")
    rows = [r.rstrip("\t\r ") for r in rows]
    first = len(rows[0].split("\t"))
    with_time = first == 3 * n_markers + 2
    ncols = 3 * n_markers + (2 if with_time else 0)
    data = parse_rows(
        path,
        rows,
        numbers,
        sep="\t",
        ncols=ncols,
        what=f"{'frame, time and ' if with_time else ''}{n_markers} markers x 3",
        allow_empty=True,
    )
    timestamps = None
    if with_time:
        timestamps = data[:, 1].copy()
        check_times(path, timestamps, numbers, "Time value")
        data = data[:, 2:]
    positions = np.ascontiguousarray(data.reshape(-1, n_markers, 3)) * _UNIT_SCALE[units]
    check_positions(path, positions, numbers, implausible, names=names)
    zeros_to_nan(positions)
    seq = SkeletonSequence(
        positions=positions,
        topology=Topology.from_names(names, up_axis=2, name="qualisys"),
        timestamps=timestamps,
        fps=fps,
        units="m",
        metadata={
            "source": str(path),
            "format": "qualisys",
            "units_in_file": units,
            "header": {k: v for k, v in header.items() if k != "MARKER_NAMES"},
            "declared_frames": counts.get("NO_OF_FRAMES"),
        },
    )
    return [seq]


def sniff_qualisys(path: Path, head: str) -> int:
    """Score: the first line is ``NO_OF_FRAMES<TAB>n`` (QTM TSV header)."""
    for line in head.split("\n")[:5]:
        if line.strip():
            return 90 if line.split("\t")[0].strip().upper() == "NO_OF_FRAMES" else 0
    return 0


register_format(
    "qualisys", read_qualisys, None, (".tsv",), sniff_qualisys,
    description="Qualisys Track Manager TSV (mm)", aliases=("qtm",),
)  # fmt: skip
