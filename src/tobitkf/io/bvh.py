"""BVH (Biovision hierarchy) motion files: hierarchy + motion → joint positions.

The ``HIERARCHY`` section is a tree of ``ROOT`` / ``JOINT`` blocks with ``OFFSET x y z``
(from the parent, in file units) and ``CHANNELS n <names>``, and ``End Site`` blocks. The
``MOTION`` section gives ``Frames: N``, ``Frame Time: dt`` and N lines of channel values
in depth-first joint order, channels in declared order (rotations in degrees).

Forward kinematics (data README §6): a joint's local rotation is the product of its
rotation channels in the order they are listed (e.g. ``Zrotation Yrotation Xrotation`` →
Rz · Ry · Rx); its local translation is its OFFSET, with the components that have position
channels replaced by the channel values (the root's position); then
``R_j = R_parent · R_local`` and ``p_j = p_parent + R_parent · t_local``.

Positions are in the file's units times ``scale`` (the CMU file here is in metres); the
up axis is y. Each joint's OFFSET (times ``scale``) is kept as ``metadata["offsets"]``
(J, 3), named in ``metadata["per_joint"]`` so that ``select_joints`` cuts it.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from tobitkf.io._kinematics import axis_rotation, forward_kinematics
from tobitkf.io._text import (
    check_output_size,
    check_positions,
    check_rate,
    nonempty,
    parse_int,
    parse_number,
    parse_rows,
    read_lines,
    text_size,
)
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import PER_JOINT, SkeletonSequence
from tobitkf.skeleton.topology import Topology

__all__ = ["BvhJoint", "parse_bvh_hierarchy", "read_bvh", "sniff_bvh"]

_CHANNELS = {
    "xposition": ("p", 0),
    "yposition": ("p", 1),
    "zposition": ("p", 2),
    "xrotation": ("r", 0),
    "yrotation": ("r", 1),
    "zrotation": ("r", 2),
}


class BvhJoint:
    """One joint (or End Site) of a BVH hierarchy."""

    __slots__ = ("channels", "end_site", "name", "offset", "parent")

    def __init__(self, name: str, parent: int, end_site: bool = False) -> None:
        self.name = name
        self.parent = parent
        self.offset = np.zeros(3)
        self.channels: list[tuple[str, int]] = []  # ("p"|"r", axis)
        self.end_site = end_site


def _tokens(lines: list[str], stop: int) -> list[tuple[str, int]]:
    out = []
    for i in range(stop):
        for t in lines[i].replace("{", " { ").replace("}", " } ").split():
            out.append((t, i + 1))
    return out


def parse_bvh_hierarchy(path, lines: list[str], stop: int) -> list[BvhJoint]:
    """Parse the HIERARCHY section (lines ``[0, stop)``) into joints in file order.

    Every parent precedes its children. End Sites are included with ``end_site=True``.
    """
    toks = _tokens(lines, stop)
    if not toks or toks[0][0].upper() != "HIERARCHY":
        found = toks[0][0] if toks else "nothing"
        raise ReadError(path, toks[0][1] if toks else None, f"expected HIERARCHY, found {found!r}")
    joints: list[BvhJoint] = []
    stack: list[int] = []  # open blocks: joint index
    i = 1
    n = len(toks)

    def need(k: int, what: str) -> None:
        if i + k > n:
            raise ReadError(
                path, toks[-1][1], f"truncated hierarchy: expected {what}, found end of section"
            )

    while i < n:
        tok, no = toks[i]
        key = tok.upper()
        if key in ("ROOT", "JOINT"):
            if key == "ROOT" and stack:
                raise ReadError(path, no, "expected '}' closing the previous joint, found ROOT")
            if key == "JOINT" and (not stack or joints[stack[-1]].end_site):
                raise ReadError(path, no, "JOINT outside of a ROOT/JOINT block")
            name_parts = []
            i += 1
            while i < n and toks[i][1] == no and toks[i][0] != "{":
                name_parts.append(toks[i][0])
                i += 1
            if not name_parts:
                raise ReadError(path, no, f"expected a joint name after {tok}")
            need(1, "'{'")
            if toks[i][0] != "{":
                raise ReadError(path, toks[i][1], f"expected '{{', found {toks[i][0]!r}")
            i += 1
            joints.append(BvhJoint(" ".join(name_parts), stack[-1] if stack else -1))
            stack.append(len(joints) - 1)
        elif key == "END":
            need(3, "'Site {'")
            if toks[i + 1][0].upper() != "SITE" or toks[i + 2][0] != "{":
                raise ReadError(path, no, "expected 'End Site {'")
            if not stack or joints[stack[-1]].end_site:
                raise ReadError(path, no, "End Site outside of a joint block")
            parent = stack[-1]
            joints.append(BvhJoint(f"{joints[parent].name}_End", parent, end_site=True))
            stack.append(len(joints) - 1)
            i += 3
        elif key == "OFFSET":
            need(4, "three OFFSET values")
            if not stack:
                raise ReadError(path, no, "OFFSET outside of a joint block")
            joints[stack[-1]].offset = np.array(
                [
                    parse_number(path, no, toks[i + k][0], "three numbers after OFFSET")
                    for k in (1, 2, 3)
                ]
            )
            i += 4
        elif key == "CHANNELS":
            need(2, "a channel count")
            if not stack or joints[stack[-1]].end_site:
                raise ReadError(path, no, "CHANNELS outside of a joint block")
            count = parse_int(path, no, toks[i + 1][0], "a channel count")
            if not 0 <= count <= 6:
                raise ReadError(path, no, f"expected 0 to 6 channels, found {count}")
            need(2 + count, f"{count} channel names")
            chans = []
            for k in range(count):
                cname = toks[i + 2 + k][0]
                if cname.lower() not in _CHANNELS:
                    raise ReadError(
                        path,
                        toks[i + 2 + k][1],
                        f"expected a channel name (X/Y/Z position/rotation), found {cname!r}",
                    )
                chans.append(_CHANNELS[cname.lower()])
            joints[stack[-1]].channels = chans
            i += 2 + count
        elif tok == "}":
            if not stack:
                raise ReadError(path, no, "unbalanced '}'")
            stack.pop()
            i += 1
        else:
            raise ReadError(
                path, no, f"expected ROOT, JOINT, End Site, OFFSET, CHANNELS or '}}', found {tok!r}"
            )
    if stack:
        raise ReadError(path, stop, "truncated hierarchy: a joint block is not closed")
    if not any(not j.end_site for j in joints):
        raise ReadError(path, stop, "expected at least one ROOT joint")
    return joints


def _header_value(path, lines: list[str], k: int, key: str) -> str:
    while k < len(lines) and not lines[k].strip():
        k += 1
    if k >= len(lines):
        raise ReadError(path, len(lines), f"truncated file: expected '{key}', found end of file")
    line = lines[k].strip()
    if not line.lower().startswith(key.lower()):
        raise ReadError(path, k + 1, f"expected '{key} ...', found {line[:40]!r}")
    return line[len(key) :].strip()


def read_bvh(
    path: str | os.PathLike[str],
    scale: float = 1.0,
    end_sites: bool = False,
    implausible: str = "error",
) -> list[SkeletonSequence]:
    """Read a BVH file and compute global joint positions.

    Parameters
    ----------
    scale : float
        Multiplies the file's units to get metres (1.0 for metre files, 0.01 for cm).
    end_sites : bool
        Also return the End Site points (named ``<parent>_End``).
    implausible : {"error", "missing"}
        What to do with an offset, root position or joint position beyond the
        plausibility bound (after ``scale``; see ``_text.check_positions``).

    Returns
    -------
    list with one SkeletonSequence: positions (T, J, 3), fps = 1 / Frame Time (snapped to
    an integer within 0.01 %), topology ``bvh`` from the hierarchy (y up).
    """
    lines = read_lines(path)
    if not any(line.strip() for line in lines):
        raise ReadError(path, None, "empty file: expected a BVH HIERARCHY")
    first = next(i for i, ln in enumerate(lines) if ln.strip())
    if lines[first].split()[0].upper() != "HIERARCHY":
        shown = lines[first].strip()[:40]
        raise ReadError(path, first + 1, f"expected HIERARCHY, found {shown!r}")
    motion = next((i for i, ln in enumerate(lines) if ln.strip().upper() == "MOTION"), -1)
    if motion < 0:
        raise ReadError(path, len(lines), "expected a MOTION section, found none")
    joints = parse_bvh_hierarchy(path, lines, motion)
    k = motion + 1
    frames_text = _header_value(path, lines, k, "Frames:")
    while not lines[k].strip():
        k += 1
    n_frames = parse_int(path, k + 1, frames_text, "an integer frame count (Frames:)", 0)
    k += 1
    dt_text = _header_value(path, lines, k, "Frame Time:")
    while not lines[k].strip():
        k += 1
    dt = parse_number(path, k + 1, dt_text, "a frame time in seconds")
    if dt <= 0:
        raise ReadError(path, k + 1, f"expected a positive frame time, found {dt_text!r}")
    check_rate(path, k + 1, 1.0 / dt, "Frame Time (s)", dt_text)
    n_channels = sum(len(j.channels) for j in joints)
    rows, numbers = nonempty(lines, k + 1)
    if len(rows) < n_frames:
        raise ReadError(
            path, len(lines), f"truncated file: expected {n_frames} frames, found {len(rows)}"
        )
    if len(rows) > n_frames:
        raise ReadError(
            path, numbers[n_frames], f"expected {n_frames} frames (Frames:), found more lines"
        )
    if n_frames == 0:
        raise ReadError(path, k + 1, "expected at least one frame, found Frames: 0")
    if n_channels == 0:
        raise ReadError(path, motion, "expected at least one channel in the hierarchy")
    T = n_frames
    J = len(joints)
    # local and global rotations and positions of every joint in every frame
    check_output_size(path, T * J * 27 * 8, text_size(lines), f"{T} frames x {J} joints")
    data = parse_rows(
        path, rows, numbers, sep=None, ncols=n_channels, what=f"{n_channels} channel values"
    )
    # local rotation (channels multiplied in the order listed) and offset of each joint
    rot_l = np.broadcast_to(np.eye(3), (T, J, 3, 3)).copy()
    pos_l = np.broadcast_to(np.array([jt.offset for jt in joints], dtype=float), (T, J, 3)).copy()
    col = 0
    for j, jt in enumerate(joints):
        for kind, axis in jt.channels:
            values = data[:, col]
            col += 1
            if kind == "p":
                pos_l[:, j, axis] = values
            else:
                rot_l[:, j] = rot_l[:, j] @ axis_rotation(axis, values)
    # forward kinematics is linear in the offsets, so it can run in metres; offsets and
    # root positions are bounded first (sums of huge values would overflow to inf - inf)
    pos_l *= scale
    check_positions(path, pos_l, numbers, implausible, names=[jt.name for jt in joints])
    _, pos_g = forward_kinematics(rot_l, pos_l, [jt.parent for jt in joints])
    keep = [j for j, jt in enumerate(joints) if end_sites or not jt.end_site]
    names = [joints[j].name for j in keep]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise ReadError(path, None, f"duplicate joint names in the hierarchy: {dup}")
    new_index = {old: new for new, old in enumerate(keep)}
    parents = [new_index.get(joints[j].parent, -1) for j in keep]
    fps = 1.0 / dt
    if abs(fps - round(fps)) <= 1e-4 * fps:
        fps = float(round(fps))
    positions = np.ascontiguousarray(pos_g[:, keep])
    check_positions(path, positions, numbers, implausible, names=names)
    seq = SkeletonSequence(
        positions=positions,
        topology=Topology.from_names(names, parents, up_axis=1, name="bvh"),
        fps=fps,
        units="m",
        metadata={
            "source": str(path),
            "format": "bvh",
            "frame_time": dt,
            "scale": scale,
            "offsets": np.array([joints[j].offset for j in keep]) * scale,
            PER_JOINT: ["offsets"],
        },
    )
    return [seq]


def sniff_bvh(path: Path, head: str) -> int:
    """Score: the file starts with ``HIERARCHY``."""
    return 95 if head.lstrip().upper().startswith("HIERARCHY") else 0


register_format(
    "bvh", read_bvh, None, (".bvh",), sniff_bvh,
    description="BVH hierarchy + motion",
)  # fmt: skip
