"""Kinect TSV with timestamps, as written by krajjat (data README §4).

Tab-separated. Optional ``key<TAB>value`` metadata lines, then a header line
``Timestamp  <Joint>_X  <Joint>_Y  <Joint>_Z ...``, then one line per frame. Timestamps are
seconds and may be irregular. Positions are metres, camera space, y up.

The file's joint order is kept. When the joints are the 21 of the krajjat Kinect export in
its order, the topology is ``kinect_v2_21``; other Kinect V2 joint sets get the matching
subset of ``kinect_v2``; unknown names give a plain custom topology. Joints at (0, 0, 0)
become NaN (NOT_TRACKED).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from tobitkf.io._text import (
    check_positions,
    check_rate,
    check_times,
    missing_state,
    nonempty,
    parse_rows,
    read_lines,
    zeros_to_nan,
)
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import KINECT_V2_JOINTS, Topology, get_topology

__all__ = ["read_krajjat", "sniff_krajjat"]


def _header_index(lines: list[str]) -> int:
    for i, line in enumerate(lines):
        first = line.split("\t", 1)[0].strip().lower()
        if first in ("timestamp", "time"):
            return i
    return -1


def _joint_columns(path, header: list[str], line_no: int) -> list[str]:
    cols = [c.strip() for c in header[1:]]
    while cols and not cols[-1]:
        cols.pop()
    if not cols or len(cols) % 3:
        raise ReadError(
            path,
            line_no,
            f"expected 'Timestamp' then <Joint>_X, <Joint>_Y, <Joint>_Z columns, found "
            f"{len(cols)} joint columns (not a multiple of 3)",
        )
    names = []
    for k in range(0, len(cols), 3):
        triple = cols[k : k + 3]
        base = triple[0][:-2]
        expected = [f"{base}_X", f"{base}_Y", f"{base}_Z"]
        if [c.upper() for c in triple] != [e.upper() for e in expected] or not base:
            raise ReadError(
                path,
                line_no,
                f"expected columns {expected} at positions {k + 2}-{k + 4}, found {triple}",
            )
        names.append(base)
    if len(set(names)) != len(names):
        raise ReadError(path, line_no, f"duplicate joint names in the header: {names}")
    return names


def _topology_for(names: list[str]) -> Topology:
    k21 = get_topology("kinect_v2_21")
    if tuple(names) == k21.joints:
        return k21
    if set(names) <= set(KINECT_V2_JOINTS):
        return get_topology("kinect_v2").subset(names, name=f"kinect_v2_{len(names)}")
    return Topology.from_names(names, up_axis=1, name="kinect_tsv")


def read_krajjat(
    path: str | os.PathLike[str], implausible: str = "error"
) -> list[SkeletonSequence]:
    """Read a krajjat Kinect TSV file.

    ``implausible`` (``"error"`` or ``"missing"``): what to do with a position beyond the
    plausibility bound (``_text.check_positions``).

    Returns
    -------
    list with one SkeletonSequence: positions (T, J, 3) metres, timestamps (T,) seconds,
    fps = 1 / median time step, ``metadata["header"]`` the key/value lines.
    """
    lines = read_lines(path)
    if not any(line.strip() for line in lines):
        raise ReadError(path, None, "empty file: expected a 'Timestamp' header and frames")
    h = _header_index(lines)
    if h < 0:
        raise ReadError(path, None, "expected a header line starting with 'Timestamp'")
    header_meta: dict[str, str] = {}
    for line in lines[:h]:
        if line.strip():
            key, _, value = line.partition("\t")
            header_meta[key.strip()] = value.strip()
    names = _joint_columns(path, lines[h].split("\t"), h + 1)
    rows, numbers = nonempty(lines, h + 1)
    if not rows:
        raise ReadError(path, None, "no frames after the header line")
    rows = [r.rstrip("\t ") for r in rows]
    ncols = 1 + 3 * len(names)
    data = parse_rows(
        path, rows, numbers, sep="\t", ncols=ncols, what=f"a timestamp and {len(names)} joints x 3"
    )
    times = data[:, 0].copy()
    check_times(path, times, numbers, "timestamp")
    positions = np.ascontiguousarray(data[:, 1:].reshape(-1, len(names), 3))
    check_positions(path, positions, numbers, implausible, names=names)
    zeros_to_nan(positions)
    state = missing_state(positions)
    fps = None
    if len(times) > 1:
        med = float(np.median(np.diff(times)))
        if med > 0:
            fps = check_rate(path, None, 1.0 / med, "median time step (s)", repr(med))
    seq = SkeletonSequence(
        positions=positions,
        topology=_topology_for(names),
        tracking_state=state,
        timestamps=times,
        fps=fps,
        units="m",
        metadata={"source": str(path), "format": "krajjat", "header": header_meta},
    )
    return [seq]


def sniff_krajjat(path: Path, head: str) -> int:
    """Score: a tab-separated ``Timestamp`` header with ``_X`` joint columns."""
    for line in head.split("\n")[:100]:
        fields = line.split("\t")
        if fields[0].strip().lower() in ("timestamp", "time") and len(fields) > 3:
            if fields[1].strip().upper().endswith("_X"):
                return 70
    return 0


register_format(
    "krajjat", read_krajjat, None, (".tsv",), sniff_krajjat,
    description="Kinect TSV with timestamps (krajjat)", aliases=("kinect_tsv",),
)  # fmt: skip
