"""KERAAL Kinect V2 and Vicon text files (data README §1).

Both are ASCII, one frame per line, space-separated, CRLF line endings, a trailing space.

* Kinect: 25 joints (SDK order) × (x, y, z, qw, qx, qy, qz); metres, camera space, y up,
  30 Hz. **The quaternion order is w, x, y, z** (the dataset docs say x, y, z, w; the data
  say otherwise: read as (w, x, y, z) the local Y axis lies along the bone from the
  parent). Kept as ``metadata["orientations"]`` (T, 25, 4) in (w, x, y, z) order; end
  joints have the quaternion 0 0 0 0. Joints at (0, 0, 0) become NaN / NOT_TRACKED.
* Vicon: 17 ART rigid-body targets × (x, y, z, q1, q2, q3, q4); millimetres (converted to
  metres), z up, about 60 Hz. The quaternion is kept **raw, as in the file**, in
  ``metadata["target_quaternions_raw"]`` (T, 17, 4); the dataset documentation gives the
  order x, y, z, w, which could not be verified (``metadata["quaternion_order"]``).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from tobitkf.io._text import (
    check_positions,
    missing_state,
    nonempty,
    parse_rows,
    read_lines,
    zeros_to_nan,
)
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import get_topology

__all__ = ["read_keraal_kinect", "read_keraal_vicon", "sniff_keraal_kinect", "sniff_keraal_vicon"]

KINECT_JOINTS = 25
VICON_TARGETS = 17
KINECT_FPS = 30.0
VICON_FPS = 60.0


def _read_groups(path: str | os.PathLike[str], n_groups: int, what: str) -> tuple:
    rows, numbers = nonempty(read_lines(path))
    if not rows:
        raise ReadError(path, None, f"empty file: expected lines of {n_groups * 7} values")
    data = parse_rows(path, rows, numbers, sep=None, ncols=n_groups * 7, what=what)
    return data.reshape(-1, n_groups, 7), numbers


def read_keraal_kinect(
    path: str | os.PathLike[str], fps: float = KINECT_FPS, implausible: str = "error"
) -> list[SkeletonSequence]:
    """Read a KERAAL ``G*-Kinect-*.txt`` file.

    ``implausible`` (``"error"`` or ``"missing"``): what to do with a position beyond the
    plausibility bound (``_text.check_positions``).

    Returns
    -------
    list with one SkeletonSequence: positions (T, 25, 3) m, topology ``kinect_v2``,
    fps 30, ``metadata["orientations"]`` (T, 25, 4) quaternions (w, x, y, z).
    Tracking state is None unless some joint is reported at the origin (then those
    samples are NOT_TRACKED and the rest TRACKED).
    """
    data, numbers = _read_groups(path, KINECT_JOINTS, "25 Kinect joints x (x, y, z, w, x, y, z)")
    positions = np.ascontiguousarray(data[:, :, :3])
    orientations = np.ascontiguousarray(data[:, :, 3:])
    topo = get_topology("kinect_v2")
    check_positions(path, positions, numbers, implausible, names=topo.joints)
    zeros_to_nan(positions)
    seq = SkeletonSequence(
        positions=positions,
        topology=topo,
        tracking_state=missing_state(positions),
        fps=fps,
        units="m",
        metadata={
            "source": str(path),
            "format": "keraal_kinect",
            "orientations": orientations,
            "quaternion_order": "wxyz",
        },
    )
    return [seq]


def read_keraal_vicon(
    path: str | os.PathLike[str], fps: float = VICON_FPS, implausible: str = "error"
) -> list[SkeletonSequence]:
    """Read a KERAAL ``G*-Vicon-*.txt`` file (``implausible`` as for the Kinect file).

    Returns
    -------
    list with one SkeletonSequence: positions (T, 17, 3) in metres (file: mm), topology
    ``keraal_vicon_17`` (z up), fps 60, ``metadata["target_quaternions_raw"]`` (T, 17, 4)
    exactly as in the file (documented order x, y, z, w; unverified).
    """
    data, numbers = _read_groups(path, VICON_TARGETS, "17 Vicon targets x (x, y, z, q1..q4)")
    positions = np.ascontiguousarray(data[:, :, :3]) / 1000.0
    topo = get_topology("keraal_vicon_17")
    check_positions(path, positions, numbers, implausible, names=topo.joints)
    seq = SkeletonSequence(
        positions=positions,
        topology=topo,
        fps=fps,
        units="m",
        metadata={
            "source": str(path),
            "format": "keraal_vicon",
            "units_in_file": "mm",
            "target_quaternions_raw": np.ascontiguousarray(data[:, :, 3:]),
            "quaternion_order": "xyzw (dataset documentation; not verified)",
        },
    )
    return [seq]


def _first_count(head: str) -> int:
    for line in head.split("\n")[:50]:
        if line.strip():
            if "," in line or "\t" in line:
                return -1
            return len(line.split())
    return -1


def sniff_keraal_kinect(path: Path, head: str) -> int:
    """Score: 175 space-separated values per line."""
    return 60 if _first_count(head) == KINECT_JOINTS * 7 else 0


def sniff_keraal_vicon(path: Path, head: str) -> int:
    """Score: 119 space-separated values per line."""
    return 60 if _first_count(head) == VICON_TARGETS * 7 else 0


register_format(
    "keraal_kinect", read_keraal_kinect, None, (".txt",), sniff_keraal_kinect,
    description="KERAAL Kinect V2 text (positions + quaternions w,x,y,z)",
)  # fmt: skip

register_format(
    "keraal_vicon", read_keraal_vicon, None, (".txt",), sniff_keraal_vicon,
    description="KERAAL Vicon text (17 ART targets, mm)",
)  # fmt: skip
