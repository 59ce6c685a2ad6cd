"""UI-PRMD Kinect (22-joint hierarchy) and Vicon (39 Plug-in Gait markers) files.

Both are gzip-compressed (or plain) comma-separated text without a header, one frame per
line (data README §2).

* Kinect ``.../Kinect/Positions/X_positions.txt.gz``: 66 columns, 22 joints × 3. Joint 0
  (Waist) is absolute (cm); every other joint is the offset from its parent in the
  parent's local frame (cm). The sibling ``.../Kinect/Angles/X_angles.txt.gz`` holds one
  Euler triple (degrees, columns about x, y, z) per joint. Absolute positions are rebuilt
  with E(a) = Rz(a_z) · Rx(a_x) · Ry(a_y), R_0 = E(angle_0), p_0 = position_0 and, for a
  joint j with parent p: p_j = p_p + R_p · offset_j, R_j = R_p · E(angle_j).
  Output in metres, y up, 30 Hz, topology ``ui_prmd``.
* Vicon ``.../Vicon/Positions/X_positions.txt.gz``: 117 columns, 39 markers × 3 in mm
  (converted to metres), z up, 100 Hz, topology ``plug_in_gait_39``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from tobitkf.io._kinematics import axis_rotation, forward_kinematics
from tobitkf.io._text import check_positions, nonempty, parse_rows, read_lines
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import UI_PRMD_PARENTS, get_topology

__all__ = [
    "angles_path_for",
    "euler_zxy",
    "is_angles_file",
    "positions_path_for",
    "read_uiprmd_kinect",
    "read_uiprmd_vicon",
    "reconstruct_uiprmd",
]

KINECT_JOINTS = 22
VICON_MARKERS = 39
KINECT_FPS = 30.0
VICON_FPS = 100.0


def _read_block(
    path: str | os.PathLike[str], ncols: int, what: str
) -> tuple[np.ndarray, list[int]]:
    """The (T, ncols) values of a file and the line number of each frame."""
    rows, numbers = nonempty(read_lines(path))
    if not rows:
        raise ReadError(path, None, f"empty file: expected lines of {ncols} comma-separated values")
    rows = [r.strip().rstrip(",") for r in rows]
    return parse_rows(path, rows, numbers, sep=",", ncols=ncols, what=what), numbers


def angles_path_for(positions_path: str | os.PathLike[str]) -> Path:
    """The angles file that goes with a Kinect positions file.

    ``.../Kinect/Positions/X_positions.txt.gz`` → ``.../Kinect/Angles/X_angles.txt.gz``;
    a file in any other folder looks for ``X_angles...`` next to itself.
    """
    p = Path(positions_path)
    name = p.name
    if "_positions" not in name:
        raise ReadError(p, None, "expected a UI-PRMD Kinect file named '<code>_positions.txt[.gz]'")
    angles_name = name.replace("_positions", "_angles")
    folder = p.parent
    if folder.name.lower() == "positions":
        sibling = folder.parent / ("Angles" if folder.name == "Positions" else "angles")
        return sibling / angles_name
    return folder / angles_name


def is_angles_file(path: str | os.PathLike[str]) -> bool:
    """True for a UI-PRMD Kinect angles file (``..._angles.txt[.gz]``), the companion of a
    positions file; batch tools should skip it (loading it reads the pair anyway)."""
    return "_angles" in Path(path).name


def positions_path_for(angles_path: str | os.PathLike[str]) -> Path:
    """Inverse of :func:`angles_path_for`: ``.../Angles/X_angles...`` →
    ``.../Positions/X_positions...``."""
    p = Path(angles_path)
    name = p.name.replace("_angles", "_positions")
    folder = p.parent
    if folder.name.lower() == "angles":
        return folder.parent / ("Positions" if folder.name == "Angles" else "positions") / name
    return folder / name


def euler_zxy(angles_deg: np.ndarray) -> np.ndarray:
    """E(a) = Rz(a_z) · Rx(a_x) · Ry(a_y) for angles (..., 3) = (a_x, a_y, a_z) in degrees.

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    a = np.asarray(angles_deg, dtype=float)
    return axis_rotation(2, a[..., 2]) @ axis_rotation(0, a[..., 0]) @ axis_rotation(1, a[..., 1])


def reconstruct_uiprmd(
    relative: np.ndarray, angles_deg: np.ndarray, parents: tuple[int, ...] = UI_PRMD_PARENTS
) -> np.ndarray:
    """Absolute joint positions from UI-PRMD relative positions and Euler angles.

    Parameters
    ----------
    relative : ndarray, shape (T, J, 3)
        Root absolute position and per-joint offsets in the parent frame.
    angles_deg : ndarray, shape (T, J, 3)
        Euler angles (a_x, a_y, a_z) in degrees per joint.
    parents : tuple of int, length J
        Parent indices; every parent must precede its child.

    Returns
    -------
    ndarray, shape (T, J, 3), same units as ``relative``.
    """
    return forward_kinematics(euler_zxy(angles_deg), relative, parents)[1]


def read_uiprmd_kinect(
    path: str | os.PathLike[str],
    angles_path: str | os.PathLike[str] | None = None,
    fps: float = KINECT_FPS,
    implausible: str = "error",
) -> list[SkeletonSequence]:
    """Read a UI-PRMD Kinect positions file and rebuild absolute joint positions.

    Parameters
    ----------
    path : positions file (66 columns, cm)
    angles_path : angles file; by default located with :func:`angles_path_for`.
    implausible : {"error", "missing"}
        What to do with a position (file offset or rebuilt joint) beyond the plausibility
        bound (``_text.check_positions``).

    Returns
    -------
    list with one SkeletonSequence: positions (T, 22, 3) metres, topology ``ui_prmd``,
    fps 30, ``metadata["euler_angles_deg"]`` (T, 22, 3).
    """
    if angles_path is None and is_angles_file(path):
        # the angles half of a pair: read the pair through its positions file
        ppath = positions_path_for(path)
        if not ppath.exists():
            raise ReadError(
                path,
                None,
                f"this is a UI-PRMD angles file; its positions file was expected at {ppath} "
                "(not found)",
            )
        seqs = read_uiprmd_kinect(ppath, path, fps=fps, implausible=implausible)
        seqs[0].metadata["opened_as"] = str(path)
        return seqs
    apath = Path(angles_path) if angles_path is not None else angles_path_for(path)
    if not apath.exists():
        raise ReadError(
            path,
            None,
            f"the UI-PRMD Kinect positions need the matching angles file, expected at "
            f"{apath} (not found)",
        )
    what = "22 joints x 3"
    rel, numbers = _read_block(path, KINECT_JOINTS * 3, what)
    rel = rel.reshape(-1, KINECT_JOINTS, 3) / 100.0
    ang = _read_block(apath, KINECT_JOINTS * 3, what)[0].reshape(-1, KINECT_JOINTS, 3)
    if rel.shape[0] != ang.shape[0]:
        raise ReadError(
            apath,
            None,
            f"expected {rel.shape[0]} frames (as in {Path(path).name}), found {ang.shape[0]}",
        )
    topo = get_topology("ui_prmd")
    # offsets bounded before the sums of forward kinematics (which could reach inf - inf)
    check_positions(path, rel, numbers, implausible, names=topo.joints)
    positions = reconstruct_uiprmd(rel, ang)
    check_positions(path, positions, numbers, implausible, names=topo.joints)
    seq = SkeletonSequence(
        positions=positions,
        topology=topo,
        fps=fps,
        units="m",
        metadata={
            "source": str(path),
            "format": "uiprmd_kinect",
            "angles_path": str(apath),
            "units_in_file": "cm",
            "euler_angles_deg": ang,
        },
    )
    return [seq]


def read_uiprmd_vicon(
    path: str | os.PathLike[str], fps: float = VICON_FPS, implausible: str = "error"
) -> list[SkeletonSequence]:
    """Read a UI-PRMD Vicon positions file (39 Plug-in Gait markers, mm → m, 100 Hz);
    ``implausible`` as for :func:`read_uiprmd_kinect`."""
    data, numbers = _read_block(path, VICON_MARKERS * 3, "39 Plug-in Gait markers x 3")
    positions = data.reshape(-1, VICON_MARKERS, 3) / 1000.0
    topo = get_topology("plug_in_gait_39")
    check_positions(path, positions, numbers, implausible, names=topo.joints)
    seq = SkeletonSequence(
        positions=positions,
        topology=topo,
        fps=fps,
        units="m",
        metadata={"source": str(path), "format": "uiprmd_vicon", "units_in_file": "mm"},
    )
    return [seq]


def _first_comma_count(head: str) -> int:
    for line in head.split("\n")[:50]:
        line = line.strip()
        if line:
            return len(line.rstrip(",").split(",")) if "," in line else -1
    return -1


def sniff_uiprmd_kinect(path: Path, head: str) -> int:
    """Score: 66 comma-separated values per line."""
    return 60 if _first_comma_count(head) == KINECT_JOINTS * 3 else 0


def sniff_uiprmd_vicon(path: Path, head: str) -> int:
    """Score: 117 comma-separated values per line."""
    return 60 if _first_comma_count(head) == VICON_MARKERS * 3 else 0


register_format(
    "uiprmd_kinect", read_uiprmd_kinect, None, (".txt.gz",),
    sniff_uiprmd_kinect, description="UI-PRMD Kinect positions + angles",
    companion=lambda p: is_angles_file(p) and positions_path_for(p).exists(),
    read_with=lambda p: [angles_path_for(p)] if "_positions" in p.name else [],
)  # fmt: skip

register_format(
    "uiprmd_vicon", read_uiprmd_vicon, None, (".txt.gz",), sniff_uiprmd_vicon,
    description="UI-PRMD Vicon (39 Plug-in Gait markers, mm)",
)  # fmt: skip
