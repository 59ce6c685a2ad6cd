"""KIMORE raw Kinect V2 joint-position CSV (data README §3).

Leading (and any) blank lines are skipped. Each frame is one line of 100 comma-separated
numbers followed by a trailing comma: 25 joints (Kinect SDK order) × (x, y, z, state),
camera space in metres with y up; state is the Kinect ``TrackingState`` (2 tracked,
1 inferred, 0 not tracked). No timestamps: the nominal rate is 30 Hz.
Joints reported at (0, 0, 0) become NaN and ``NOT_TRACKED``.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from tobitkf.io._text import check_positions, nonempty, parse_rows, read_lines, zeros_to_nan
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import get_topology

__all__ = ["read_kimore", "sniff_kimore"]

N_JOINTS = 25
FPS = 30.0


def _strip(row: str) -> str:
    row = row.strip()
    return row[:-1] if row.endswith(",") else row


def read_kimore(
    path: str | os.PathLike[str], fps: float = FPS, implausible: str = "error"
) -> list[SkeletonSequence]:
    """Read a KIMORE ``JointPosition*.csv`` file.

    ``implausible`` (``"error"`` or ``"missing"``): what to do with a position beyond the
    plausibility bound (``_text.check_positions``).

    Returns
    -------
    list with one SkeletonSequence: positions (T, 25, 3) m, tracking_state (T, 25),
    fps = 30 (nominal), topology ``kinect_v2``.
    """
    rows, numbers = nonempty(read_lines(path))
    if not rows:
        raise ReadError(path, None, "empty file: expected lines of 100 comma-separated values")
    rows = [_strip(r) for r in rows]
    data = parse_rows(
        path, rows, numbers, sep=",", ncols=N_JOINTS * 4, what="25 joints x (x, y, z, state)"
    )
    data = data.reshape(-1, N_JOINTS, 4)
    positions = np.ascontiguousarray(data[:, :, :3])
    raw_state = data[:, :, 3]
    bad = ~np.isin(raw_state, (0.0, 1.0, 2.0))
    if bad.any():
        t, j = np.argwhere(bad)[0]
        raise ReadError(
            path,
            numbers[t],
            f"expected a tracking state 0, 1 or 2 for joint {j} (field {4 * j + 4}), "
            f"found {raw_state[t, j]!r}",
        )
    state = raw_state.astype(np.int8)
    topo = get_topology("kinect_v2")
    check_positions(path, positions, numbers, implausible, names=topo.joints, state=state)
    zeros_to_nan(positions, state)
    seq = SkeletonSequence(
        positions=positions,
        topology=topo,
        tracking_state=state,
        timestamps=None,
        fps=fps,
        body_id=None,
        units="m",
        metadata={"source": str(path), "format": "kimore", "fps_nominal": True},
    )
    return [seq]


_KIMORE_ROW = re.compile(r"^\s*(?:[^,\s]+,){100}\s*$")


def sniff_kimore(path: Path, head: str) -> int:
    """Score: the first non-blank line holds 100 comma-separated values + trailing comma."""
    for line in head.split("\n")[:200]:
        line = line.strip()
        if not line:
            continue
        n = line.count(",")
        if n == 100 and line.endswith(","):
            return 60
        if n == 99 and not line.endswith(","):
            return 30
        return 0
    return 0


register_format(
    "kimore", read_kimore, None, (".csv",), sniff_kimore,
    description="KIMORE JointPosition CSV with tracking states",
)  # fmt: skip
