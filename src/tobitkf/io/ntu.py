"""NTU RGB+D ``.skeleton`` files (Kinect V2, several bodies per frame): reader and writer.

Layout (data README §7, after ``shahroudy/NTURGB-D`` ``read_skeleton_file.m``), values
separated by whitespace::

    F                                   number of frames
    B                                   per frame: number of bodies (may be 0)
    bodyID clippedEdges handLeftConfidence handLeftState handRightConfidence
        handRightState isRestricted leanX leanY trackingState          per body: 10 values
    25                                  number of joints
    x y z depthX depthY colorX colorY orientationW orientationX orientationY
        orientationZ trackingState                                    per joint: 12 values

Each body ID becomes one :class:`SkeletonSequence` of F frames (order of first
appearance). Frames where a body is absent are NaN with tracking state NOT_TRACKED.
Joints at (0, 0, 0) become NaN / NOT_TRACKED. Every field other than x, y, z is kept as
read in ``metadata`` so that :func:`write_ntu` reproduces it exactly:

* ``metadata["ntu_present"]`` (F,) bool, ``metadata["ntu_order"]`` (F,) int (position of
  the body within its frame, -1 absent);
* ``metadata["ntu_body"]``: dict of (F,) arrays for the 9 per-body fields after bodyID
  (ints: 0 where absent; ``leanX``/``leanY`` floats: NaN where absent);
* ``metadata["depth_xy"]``, ``metadata["color_xy"]`` (F, 25, 2),
  ``metadata["orientations"]`` (F, 25, 4) in (w, x, y, z) order,
  ``metadata["ntu_joint_state"]`` (F, 25) int8: the tracking state as written in the file.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tobitkf.io._text import (
    check_output_size,
    check_positions,
    fmt_float,
    fmt_floats,
    nonempty,
    parse_int,
    parse_number,
    parse_rows,
    read_lines,
    text_size,
    zeros_to_nan,
)
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format, require_rate_grid
from tobitkf.skeleton.sequence import SampleState, SkeletonSequence, TrackingState
from tobitkf.skeleton.topology import get_topology

__all__ = ["BODY_FIELDS", "read_ntu", "sniff_ntu", "write_ntu"]

N_JOINTS = 25
FPS = 30.0
#: per-body fields after bodyID, in file order, with their type
BODY_FIELDS: tuple[tuple[str, type], ...] = (
    ("clippedEdges", int),
    ("handLeftConfidence", int),
    ("handLeftState", int),
    ("handRightConfidence", int),
    ("handRightState", int),
    ("isRestricted", int),
    ("leanX", float),
    ("leanY", float),
    ("trackingState", int),
)


class _Cursor:
    """Walks the non-blank lines of a file, reporting truncation with a line number."""

    def __init__(self, path: str | os.PathLike[str], lines: list[str]) -> None:
        self.path = path
        self.rows, self.numbers = nonempty(lines)
        self.pos = 0
        self.last_line = self.numbers[-1] if self.numbers else len(lines)

    def take(self, what: str) -> tuple[str, int]:
        if self.pos >= len(self.rows):
            raise ReadError(
                self.path, self.last_line, f"truncated file: expected {what}, found end of file"
            )
        row, no = self.rows[self.pos], self.numbers[self.pos]
        self.pos += 1
        return row, no

    def take_block(self, n: int, what: str) -> tuple[list[str], list[int]]:
        if self.pos + n > len(self.rows):
            raise ReadError(
                self.path,
                self.last_line,
                f"truncated file: expected {n} lines of {what}, found {len(self.rows) - self.pos}",
            )
        sl = slice(self.pos, self.pos + n)
        self.pos += n
        return self.rows[sl], self.numbers[sl]

    def take_int(self, what: str, minimum: int = 0) -> int:
        row, no = self.take(what)
        fields = row.split()
        if len(fields) != 1:
            raise ReadError(
                self.path, no, f"expected {what} (one integer), found {len(fields)} values"
            )
        return parse_int(self.path, no, fields[0], what, minimum)

    def remaining(self) -> int:
        return len(self.rows) - self.pos


def read_ntu(
    path: str | os.PathLike[str], fps: float = FPS, implausible: str = "error"
) -> list[SkeletonSequence]:
    """Read an NTU RGB+D ``.skeleton`` file: one sequence per body ID.

    Parameters
    ----------
    implausible : {"error", "missing"}
        What to do with a position beyond the plausibility bound (``_text.check_positions``).

    Returns
    -------
    list of SkeletonSequence, each with positions (F, 25, 3) metres, tracking_state
    (F, 25), fps 30, topology ``kinect_v2``, body_id = the file's bodyID (int).
    """
    lines = read_lines(path)
    cur = _Cursor(path, lines)
    if not cur.rows:
        raise ReadError(path, None, "empty file: expected the number of frames")
    n_frames = cur.take_int("the number of frames")
    if n_frames > cur.remaining():  # every frame takes at least its body-count line
        raise ReadError(
            path,
            cur.numbers[0],
            f"the file declares {n_frames} frames but has only {cur.remaining()} more lines",
        )
    bodies: dict[int, list[tuple[int, int, list, int]]] = {}
    block_rows: list[str] = []  # joint lines of every body, parsed in one go below
    block_numbers: list[int] = []
    n_blocks = 0
    for f in range(n_frames):
        n_bodies = cur.take_int(f"the number of bodies of frame {f + 1}")
        seen: set[int] = set()
        for b in range(n_bodies):
            row, no = cur.take(f"the 10 body values of body {b + 1} in frame {f + 1}")
            fields = row.split()
            if len(fields) != 10:
                raise ReadError(
                    path,
                    no,
                    f"expected 10 body values (bodyID ... trackingState), found {len(fields)}",
                )
            body_id = parse_int(path, no, fields[0], "bodyID")
            if body_id in seen:
                raise ReadError(path, no, f"bodyID {body_id} appears twice in frame {f + 1}")
            seen.add(body_id)
            values = [
                (parse_int if typ is int else parse_number)(path, no, t, name)
                for t, (name, typ) in zip(fields[1:], BODY_FIELDS, strict=True)
            ]
            n_joints = cur.take_int(f"the number of joints of body {b + 1} in frame {f + 1}")
            if n_joints != N_JOINTS:
                _, jno = cur.rows[cur.pos - 1], cur.numbers[cur.pos - 1]
                raise ReadError(path, jno, f"expected {N_JOINTS} joints, found {n_joints}")
            rows, numbers = cur.take_block(N_JOINTS, "12 joint values")
            block_rows.extend(rows)
            block_numbers.extend(numbers)
            bodies.setdefault(body_id, []).append((f, b, values, n_blocks))
            n_blocks += 1
    if cur.pos < len(cur.rows):
        raise ReadError(
            path,
            cur.numbers[cur.pos],
            f"expected end of file after {n_frames} frames, found more data",
        )
    all_joints = np.zeros((0, N_JOINTS, 12))
    if block_rows:
        all_joints = parse_rows(
            path,
            block_rows,
            block_numbers,
            sep=None,
            ncols=12,
            what="x y z depthX depthY colorX colorY orientationW..Z trackingState",
        ).reshape(-1, N_JOINTS, 12)
        state = all_joints[:, :, 11].ravel()
        bad = ~np.isin(state, (0.0, 1.0, 2.0))
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise ReadError(
                path,
                block_numbers[k],
                f"expected a joint tracking state 0, 1 or 2, found {state[k]!r}",
            )
    # each body ID gets arrays over all frames: refuse many short-lived IDs over many
    # declared frames (a small file that would need gigabytes)
    check_output_size(
        path,
        len(bodies) * n_frames * N_JOINTS * 12 * 8,
        text_size(lines),
        f"{n_frames} frames x {len(bodies)} body IDs",
    )
    topo = get_topology("kinect_v2")
    out = []
    for body_id, entries in bodies.items():
        F = n_frames
        positions = np.full((F, N_JOINTS, 3), np.nan)
        depth = np.full((F, N_JOINTS, 2), np.nan)
        color = np.full((F, N_JOINTS, 2), np.nan)
        orient = np.full((F, N_JOINTS, 4), np.nan)
        raw_state = np.zeros((F, N_JOINTS), dtype=np.int8)
        present = np.zeros(F, dtype=bool)
        order = np.full(F, -1, dtype=np.int64)
        body_meta = {
            name: (np.zeros(F, dtype=np.int64) if typ is int else np.full(F, np.nan))
            for name, typ in BODY_FIELDS
        }
        for f, b, values, k in entries:
            joints = all_joints[k]
            present[f] = True
            order[f] = b
            positions[f] = joints[:, 0:3]
            depth[f] = joints[:, 3:5]
            color[f] = joints[:, 5:7]
            orient[f] = joints[:, 7:11]
            raw_state[f] = joints[:, 11].astype(np.int8)
            for (name, _), v in zip(BODY_FIELDS, values, strict=True):
                body_meta[name][f] = v
        state = raw_state.copy()
        frame_lines = np.zeros(F, dtype=np.int64)  # first joint line of the body per frame
        for f, _, _, k in entries:
            frame_lines[f] = block_numbers[k * N_JOINTS]
        check_positions(path, positions, frame_lines, implausible, names=topo.joints, state=state)
        zeros_to_nan(positions, state)
        state[~present] = TrackingState.NOT_TRACKED
        out.append(
            SkeletonSequence(
                positions=positions,
                topology=topo,
                tracking_state=state,
                fps=fps,
                body_id=body_id,
                units="m",
                metadata={
                    "source": str(path),
                    "format": "ntu",
                    "ntu_present": present,
                    "ntu_order": order,
                    "ntu_body": body_meta,
                    "depth_xy": depth,
                    "color_xy": color,
                    "orientations": orient,
                    "quaternion_order": "wxyz",
                    "ntu_joint_state": raw_state,
                },
            )
        )
    return out


def _frames_array(meta: dict, key: str, shape: tuple[int, ...]) -> np.ndarray | None:
    value = meta.get(key)
    if isinstance(value, np.ndarray) and value.shape == shape:
        return value
    return None


def write_ntu(sequences: Sequence[SkeletonSequence], path: str | os.PathLike[str]) -> None:
    """Write sequences (one per body, all with the same number of frames and 25 Kinect V2
    joints, 3-D in a length unit) as an NTU ``.skeleton`` file, whose positions are
    metres: a sequence in centimetres or millimetres is converted, one in pixels or
    unknown units refused.

    Fields other than x, y, z come from the metadata written by :func:`read_ntu` when
    present (so a read file is written back exactly), otherwise: depth/colour pixels 0,
    orientations from ``metadata["orientations"]`` if (w, x, y, z) else 0, body fields 0,
    joint tracking state from ``tracking_state`` (TRACKED if absent). A NaN joint is
    written as ``0 0 0`` with state NOT_TRACKED; a body whose frame is entirely NaN (or
    marked absent in ``metadata["ntu_present"]``) is left out of that frame.

    The file has no times and is read at 30 fps: a sequence whose frames are not 30 fps
    apart (another rate, dropped or irregular frames; jitter within half a frame aside)
    is refused with a ValueError rather than written at the wrong times.

    A smoothed sequence (``sample_state`` set) has its filled joints (rejected, missing or
    extrapolated, :class:`~tobitkf.skeleton.sequence.SampleState`) written as INFERRED,
    not as the state read from the input, and joints without an estimate as NOT_TRACKED.
    """
    seqs = list(sequences)
    if not seqs:
        raise ValueError("write_ntu needs at least one sequence")
    F = seqs[0].n_frames
    kinect = get_topology("kinect_v2").joints
    for s in seqs:
        if s.n_joints != N_JOINTS:
            raise ValueError(
                f"NTU files hold 25 Kinect V2 joints; sequence has {s.n_joints} ({s.topology.name})"
            )
        if s.topology.joints != kinect:
            # the file has no joint names: they are read back as the Kinect V2 ones
            other = next(a for a, b in zip(s.topology.joints, kinect, strict=True) if a != b)
            raise ValueError(
                "NTU files hold the 25 Kinect V2 joints in SDK order and no joint names; "
                f"the sequence has the joint {other!r} ({s.topology.name}); use format='csv' "
                "or 'npz'"
            )
        if s.n_frames != F:
            raise ValueError(
                f"all bodies must have the same number of frames; found {F} and {s.n_frames}"
            )
        if s.n_dims != 3:
            raise ValueError(
                f"NTU files hold 3-D camera-space joints in metres; the positions are "
                f"{s.n_dims}-D; use format='csv' or 'npz'"
            )
        if s.metres_per_unit is None:
            raise ValueError(
                f"NTU files hold metres; the sequence's units are {s.units!r}: give its "
                "length unit (seq.replace(units='m'), 'cm' or 'mm'), or use format='csv' or 'npz'"
            )
    for s in seqs:  # the file has no times: its frames are read at 30 fps
        require_rate_grid(s, FPS, "NTU")
    # the file holds metres: a sequence in centimetres or millimetres is converted
    seqs = [s.to_metres() for s in seqs]
    prepared = []
    used_ids: set[int] = set()
    for k, s in enumerate(seqs):
        m = s.metadata
        present = _frames_array(m, "ntu_present", (F,))
        if present is None:
            present = ~np.all(np.isnan(s.positions), axis=(1, 2))
        order = _frames_array(m, "ntu_order", (F,))
        if order is None:
            order = np.full(F, k)
        try:
            body_id = int(s.body_id) if s.body_id is not None else k
        except (TypeError, ValueError):
            body_id = k
        while body_id in used_ids:
            body_id += 1
        used_ids.add(body_id)
        body_meta = m.get("ntu_body") if isinstance(m.get("ntu_body"), dict) else {}
        body_cols = []
        for name, typ in BODY_FIELDS:
            col = body_meta.get(name)
            if not (isinstance(col, np.ndarray) and col.shape == (F,)):
                col = np.zeros(F, dtype=np.int64 if typ is int else float)
            body_cols.append((typ, col))
        depth = _frames_array(m, "depth_xy", (F, N_JOINTS, 2))
        color = _frames_array(m, "color_xy", (F, N_JOINTS, 2))
        orient = _frames_array(m, "orientations", (F, N_JOINTS, 4))
        if orient is not None and m.get("quaternion_order", "wxyz") != "wxyz":
            orient = None
        raw_state = _frames_array(m, "ntu_joint_state", (F, N_JOINTS))
        if raw_state is None:
            if s.tracking_state is not None:
                raw_state = s.tracking_state
            else:
                raw_state = np.full((F, N_JOINTS), int(TrackingState.TRACKED), dtype=np.int8)
            raw_state = np.where(np.isnan(s.positions).any(axis=-1), 0, raw_state)
        if s.sample_state is not None:
            raw_state = np.where(
                SampleState.filled(s.sample_state), int(TrackingState.INFERRED), raw_state
            )
            raw_state = np.where(
                s.sample_state == SampleState.NONE, int(TrackingState.NOT_TRACKED), raw_state
            )
        prepared.append((s, present, order, body_id, body_cols, depth, color, orient, raw_state))

    # one joint line per (frame, joint), built from Python lists: formatting numpy
    # scalars one at a time made this writer most of a whole smoothing run
    def _texts(arr: np.ndarray | None, width: int) -> list[list[str]]:
        """(F, 25) lists of the space-joined fields of ``arr`` (F, 25, width)."""
        if arr is None:
            return [[" ".join(["0"] * width)] * N_JOINTS] * F
        vals = fmt_floats(arr, nan="0")
        flat = [" ".join(vals[i * width : (i + 1) * width]) for i in range(F * N_JOINTS)]
        return [flat[f * N_JOINTS : (f + 1) * N_JOINTS] for f in range(F)]

    lines_of = []
    for s, _, _, _, _, depth, color, orient, raw_state in prepared:
        txt = fmt_floats(s.positions)
        gone = np.isnan(s.positions.reshape(F * N_JOINTS, 3)).any(axis=1).tolist()
        xyz = ["0 0 0" if g else " ".join(txt[3 * i : 3 * i + 3]) for i, g in enumerate(gone)]
        extra = [_texts(depth, 2), _texts(color, 2), _texts(orient, 4)]
        states = raw_state.astype(np.int64).tolist()
        lines_of.append(
            [
                [
                    f"{xyz[f * N_JOINTS + j]} {extra[0][f][j]} {extra[1][f][j]} "
                    f"{extra[2][f][j]} {states[f][j]}"
                    for j in range(N_JOINTS)
                ]
                for f in range(F)
            ]
        )

    def _num(x: float) -> str:
        return "0" if np.isnan(x) else fmt_float(x)

    out = [str(F)]
    for t in range(F):
        here = [(p, lines) for p, lines in zip(prepared, lines_of, strict=True) if p[1][t]]
        here.sort(key=lambda pl: pl[0][2][t])
        out.append(str(len(here)))
        for (_s, _, _, body_id, body_cols, *_), lines in here:
            vals = [str(body_id)]
            for typ, col in body_cols:
                vals.append(str(int(col[t])) if typ is int else _num(col[t]))
            out.append(" ".join(vals))
            out.append(str(N_JOINTS))
            out.extend(lines[t])
    Path(path).write_text("\n".join(out) + "\n", encoding="ascii")


def sniff_ntu(path: Path, head: str) -> int:
    """Score: frame count, body count, then (if any body) 10 body values, 25, 12 values."""
    rows = [ln.split() for ln in head.split("\n")[:6] if ln.strip()]
    if len(rows) < 2 or len(rows[0]) != 1 or len(rows[1]) != 1:
        return 0
    if not (rows[0][0].isascii() and rows[0][0].isdigit()):
        return 0
    if not (rows[1][0].isascii() and rows[1][0].isdigit()):
        return 0
    if rows[1][0] == "0":
        return 50
    if len(rows) >= 5 and len(rows[2]) == 10 and rows[3] == ["25"] and len(rows[4]) == 12:
        return 95
    return 0


register_format(
    "ntu", read_ntu, write_ntu, (".skeleton",), sniff_ntu,
    description="NTU RGB+D .skeleton (Kinect V2, multi-body)",
)  # fmt: skip
