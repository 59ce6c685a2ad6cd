"""Generic skeleton CSV: one row per frame, documented and round-trippable.

Layout::

    # topology: kinect_v2          optional comment lines "# key: value" (topology, fps,
    # fps: 30.0                    body_id, up_axis); other comment lines are ignored
    time,SpineBase_x,SpineBase_y,SpineBase_z,SpineBase_state,...
    0.0,0.1,0.2,2.5,2,...

* header (first non-comment line): an optional ``time`` or ``timestamp`` column (seconds),
  an optional ``body`` column (several bodies: rows are grouped by its value), then for
  every joint ``<joint>_x``, ``<joint>_y``, ``<joint>_z`` (case-insensitive suffixes, in
  this order, joints in file order) and optionally ``<joint>_state`` (0 not tracked,
  1 inferred, 2 tracked).
* values: metres, plain decimal numbers; an empty field or ``nan`` is a missing value.
* separator: comma (``,``); a file whose header has tabs or semicolons and no comma uses
  that separator instead (text inside double quotes does not count).
* header fields may be double-quoted (RFC 4180: ``"Head,L_x"``, ``""`` for a quote inside);
  the writer quotes a name holding a separator, a quote or a leading ``#``, and refuses
  names it cannot write so that they read back the same (empty, surrounding white space,
  control characters or lone surrogates).

The topology is the ``# topology:`` built-in when its joints match the header, else the
built-in whose joints equal the header's, else a custom one from the names.
"""

from __future__ import annotations

import csv
import os
import re
import unicodedata
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tobitkf.io._text import (
    INTEGER,
    check_positions,
    check_rate,
    check_times,
    fmt_float,
    nonempty,
    parse_number,
    parse_rows,
    read_lines,
)
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology, available_topologies, get_topology

__all__ = ["read_csv", "sniff_csv", "write_csv"]

_TIME = ("time", "timestamp", "t")
_AXES = ("_x", "_y", "_z")
_SEPARATORS = (",", "\t", ";")
_QUOTED = re.compile(r'"(?:[^"]|"")*"')


def _separator(header: str) -> str:
    """The header's separator: comma, else tab, else semicolon, outside quoted fields."""
    bare = _QUOTED.sub("", header)
    return next((c for c in _SEPARATORS if c in bare), ",")


def _split_header(path, header: str, sep: str, line_no: int) -> list[str]:
    """Header fields, double quotes resolved (RFC 4180)."""
    try:
        return next(csv.reader([header], delimiter=sep, skipinitialspace=True, strict=True))
    except csv.Error as exc:
        raise ReadError(path, line_no, f"malformed quoted header field ({exc})") from None


def _parse_header(path, fields: list[str], line_no: int):
    cols = [c.strip() for c in fields]
    while cols and not cols[-1]:
        cols.pop()
    time_col = body_col = None
    joints: list[str] = []
    xyz: list[tuple[int, int, int]] = []
    state_cols: dict[int, int] = {}
    k = 0
    while k < len(cols):
        c = cols[k]
        low = c.lower()
        if low in _TIME and time_col is None and not joints:
            time_col = k
            k += 1
            continue
        if low in ("body", "body_id") and body_col is None:
            body_col = k
            k += 1
            continue
        if low.endswith("_x"):
            base = c[:-2]
            triple = [t.lower() for t in cols[k : k + 3]]
            want = [(base + a).lower() for a in _AXES]
            if triple != want or not base:
                raise ReadError(
                    path,
                    line_no,
                    f"expected columns {[base + a for a in _AXES]} at positions {k + 1}-{k + 3}, "
                    f"found {cols[k : k + 3]}",
                )
            if base in joints:
                raise ReadError(path, line_no, f"joint {base!r} appears twice in the header")
            joints.append(base)
            xyz.append((k, k + 1, k + 2))
            k += 3
            continue
        if low.endswith("_state") and joints and c[:-6] == joints[-1]:
            state_cols[len(joints) - 1] = k
            k += 1
            continue
        raise ReadError(
            path,
            line_no,
            f"unexpected column {c!r} (position {k + 1}); expected time, body, "
            "<joint>_x/_y/_z or <joint>_state",
        )
    if not joints:
        raise ReadError(path, line_no, "expected <joint>_x, <joint>_y, <joint>_z columns")
    return len(cols), time_col, body_col, joints, xyz, state_cols


def _topology(names: list[str], hint: str | None, up_axis: int | None) -> Topology:
    candidates = [hint] if hint else []
    candidates += available_topologies()
    for name in candidates:
        try:
            t = get_topology(name)
        except KeyError:
            continue
        if t.joints == tuple(names):
            if up_axis is not None and up_axis != t.up_axis:
                return Topology(t.name, t.joints, t.parents, t.symmetry, up_axis)
            return t
    return Topology.from_names(
        names, up_axis=1 if up_axis is None else up_axis, name=hint or "custom"
    )


def _body_id(text: str) -> int | float:
    """A body-id field as an exact int when it is integral (else the float)."""
    text = text.strip()
    try:
        return int(text)
    except ValueError:
        v = float(text)  # parse_rows accepted the field, so it is a number
        return int(v) if v.is_integer() else v


def read_csv(path: str | os.PathLike[str], implausible: str = "error") -> list[SkeletonSequence]:
    """Read a generic skeleton CSV (see the module docstring for the layout).

    ``implausible`` (``"error"`` or ``"missing"``): what to do with a position beyond the
    plausibility bound (``_text.check_positions``).

    Returns
    -------
    list of SkeletonSequence (one per ``body`` value, or one), positions (T, J, 3).
    """
    lines = read_lines(path)
    comments: dict[str, str] = {}
    comment_line: dict[str, int] = {}
    start = None
    for i, line in enumerate(lines):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            key, sep_, value = s[1:].partition(":")
            if sep_:
                comments[key.strip().lower()] = value.strip()
                comment_line[key.strip().lower()] = i + 1
            continue
        start = i
        break
    if start is None:
        raise ReadError(path, None, "empty file: expected a header line with <joint>_x columns")
    header = lines[start]
    sep = _separator(header)
    ncols, time_col, body_col, joints, xyz, state_cols = _parse_header(
        path, _split_header(path, header, sep, start + 1), start + 1
    )
    rows, numbers = nonempty(lines, start + 1)
    rows = [r for r in rows if not r.lstrip().startswith("#")]
    numbers = [n for n in numbers if not lines[n - 1].lstrip().startswith("#")]
    if not rows:
        raise ReadError(path, None, "no frames after the header line")
    rows = [r.rstrip() for r in rows]
    rows = [r[: -len(sep)] if r.endswith(sep) and r.count(sep) == ncols else r for r in rows]
    data = parse_rows(
        path,
        rows,
        numbers,
        sep=sep,
        ncols=ncols,
        what="one value per header column",
        allow_empty=True,
        allow_nan=True,
    )
    fps = None
    if "fps" in comments:
        text, no = comments["fps"], comment_line["fps"]
        fps = check_rate(path, no, parse_number(path, no, text, "'# fps:'"), "fps", text)
    up_axis = None
    if comments.get("up_axis") in ("0", "1", "2"):
        up_axis = int(comments["up_axis"])
    topo = _topology(joints, comments.get("topology"), up_axis)
    if body_col is not None:
        ids = data[:, body_col]
        if np.isnan(ids).any():
            k = int(np.flatnonzero(np.isnan(ids))[0])
            raise ReadError(path, numbers[k], "expected a body id, found an empty field")
        # from the text, not the float: 64-bit Kinect body ids (NTU: 72057594037931101)
        # do not fit a double, and neighbouring ids would merge into one body
        groups: dict[int | float | None, list[int]] = {}  # in order of first appearance
        for k, r in enumerate(rows):
            groups.setdefault(_body_id(r.split(sep)[body_col]), []).append(k)
    else:
        groups = {None: list(range(len(rows)))}
    out = []
    for group_id, members in groups.items():
        d = data[members]
        nos = [numbers[k] for k in members]
        idx = np.array(xyz, dtype=int)
        positions = d[:, idx]  # (T, J, 3); parse_rows has rejected inf
        state = None
        if state_cols:
            state = np.full((len(d), len(joints)), 2, dtype=np.int8)
            for j, c in state_cols.items():
                col = d[:, c]
                col = np.where(np.isnan(col), 0, col)
                bad = ~np.isin(col, (0, 1, 2))
                if bad.any():
                    k = int(np.flatnonzero(bad)[0])
                    raise ReadError(
                        path, nos[k], f"expected a state 0, 1 or 2 for {joints[j]}, found {col[k]}"
                    )
                state[:, j] = col
        check_positions(path, positions, nos, implausible, names=joints, state=state)
        timestamps = None
        if time_col is not None:
            timestamps = d[:, time_col]
            check_times(path, timestamps, nos)
        body_id = group_id
        if body_col is None and "body_id" in comments:
            body_id = comments["body_id"]
            if INTEGER.fullmatch(body_id):
                body_id = int(body_id)
        out.append(
            SkeletonSequence(
                positions=positions,
                topology=topo,
                tracking_state=state,
                timestamps=timestamps,
                fps=fps,
                body_id=body_id,
                metadata={"source": str(path), "format": "csv"},
            )
        )
    return out


def write_csv(
    sequences: Sequence[SkeletonSequence], path: str | os.PathLike[str], *, sep: str = ","
) -> None:
    """Write sequences as a generic CSV (exact round trip through :func:`read_csv`).

    All sequences must share the same joints. Columns: ``time`` (when any sequence has
    timestamps), ``body`` (when more than one sequence: the body ids when they are
    distinct integers, else 0, 1, ...), then per joint
    ``_x, _y, _z`` and ``_state`` (when tracking states are present).
    """
    seqs = list(sequences)
    if not seqs:
        raise ValueError("write_csv needs at least one sequence")
    if sep not in _SEPARATORS:
        raise ValueError(f"sep must be one of {_SEPARATORS}, found {sep!r}")
    names = seqs[0].joint_names
    for n in names:
        _check_writable(n, "joint name")
    for s in seqs[1:]:
        if s.joint_names != names:
            raise ValueError("all sequences written to one CSV must have the same joints")
    multi = len(seqs) > 1
    # the body column holds the sequences' own ids when they are distinct integers, else
    # their index: a mix (ids 1 and None -> 1 and 1) would merge two bodies on reading
    ids = [s.body_id for s in seqs]
    if not (
        all(isinstance(b, (int, np.integer)) and not isinstance(b, bool) for b in ids)
        and len(set(ids)) == len(ids)
    ):
        ids = list(range(len(seqs)))
    with_state = any(s.tracking_state is not None for s in seqs)
    with_time = any(s.timestamps is not None for s in seqs)
    header = []
    if with_time:
        header.append("time")
    if multi:
        header.append("body")
    for n in names:
        header += [_quoted(f"{n}{a}") for a in _AXES]
        if with_state:
            header.append(_quoted(f"{n}_state"))
    lines = [f"# topology: {_check_writable(seqs[0].topology.name, 'topology name')}"]
    fps = seqs[0].fps
    if fps is not None:
        lines.append(f"# fps: {fmt_float(fps)}")
    lines.append(f"# up_axis: {seqs[0].topology.up_axis}")
    if not multi and seqs[0].body_id is not None:
        lines.append(f"# body_id: {_writable_body_id(seqs[0].body_id)}")
    lines.append(sep.join(header))
    for k, s in enumerate(seqs):
        times = s.times() if with_time else None
        body = int(ids[k])
        for t in range(s.n_frames):
            vals = []
            if times is not None:
                vals.append(fmt_float(times[t]))
            if multi:
                vals.append(str(body))
            for j in range(s.n_joints):
                vals += [fmt_float(v) for v in s.positions[t, j]]
                if with_state:
                    st = 2 if s.tracking_state is None else int(s.tracking_state[t, j])
                    vals.append(str(st))
            lines.append(sep.join(vals))
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")


def _check_writable(text: str, what: str) -> str:
    """``text`` if it reads back the same from a header field or ``# key:`` line, else a
    ValueError saying why the CSV format cannot hold it."""
    bad = next(  # a tab is quoted; other control characters break lines or the encoding
        (c for c in text if c != "\t" and unicodedata.category(c) in ("Cc", "Cs", "Zl", "Zp")),
        None,
    )
    if bad is not None:
        raise ValueError(
            f"cannot write the {what} {text!r} to CSV: it holds the control character "
            f"U+{ord(bad):04X} (one line per header); rename it or use format='npz'"
        )
    if not text.strip() or text != text.strip():
        raise ValueError(
            f"cannot write the {what} {text!r} to CSV: names are read with surrounding "
            "white space removed and must not be empty; rename it or use format='npz'"
        )
    return text


def _writable_body_id(body_id: object) -> str:
    """Text of a single body's id for ``# body_id:``, which reads back as int or str."""
    if isinstance(body_id, (int, np.integer)) and not isinstance(body_id, bool):
        return str(int(body_id))
    if isinstance(body_id, str) and not INTEGER.fullmatch(body_id):
        return _check_writable(body_id, "body id")
    raise ValueError(
        f"cannot write the body id {body_id!r} to CSV (it would read back as "
        f"{'an int' if isinstance(body_id, str) else 'a str'}); use an int, a non-numeric "
        "str or format='npz'"
    )


def _quoted(field: str) -> str:
    """A header field, double-quoted (RFC 4180) when it holds a separator, a quote or
    starts with the comment mark."""
    if field.startswith("#") or any(c in field for c in '",;\t'):
        return '"' + field.replace('"', '""') + '"'
    return field


def sniff_csv(path: Path, head: str) -> int:
    """Score: a header line with ``<joint>_x,<joint>_y,<joint>_z`` columns (more sure
    after the ``# topology:`` line that :func:`write_csv` writes first)."""
    written = False
    for line in head.split("\n")[:50]:
        s = line.strip()
        written = written or s.startswith("# topology:")
        if not s or s.startswith("#"):
            continue
        low = s.lower()
        if "_x" in low and "_y" in low and "_z" in low and ("," in s or ";" in s or "\t" in s):
            if written:
                return 90
            if low.split("\t")[0].split(",")[0].strip() in ("timestamp",) and "\t" in s:
                return 0  # krajjat TSV
            return 40
        return 0
    return 0


register_format(
    "csv", read_csv, write_csv, (".csv",), sniff_csv,
    description="generic skeleton CSV", aliases=("generic_csv",),
)  # fmt: skip
