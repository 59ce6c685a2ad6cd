"""Generic skeleton CSV: one row per frame, documented and round-trippable.

Layout (a plain table: ``pandas.read_csv(path)`` loads it with no options)::

    time,SpineBase_x,SpineBase_y,SpineBase_z,SpineBase_state,SpineBase_sd,SpineBase_sample,...
    0.0,0.1,0.2,2.5,2,0.004,0,...

    time,body,snout_x,snout_y,snout_confidence,...      (2-D keypoints with a score)
    0.0,mouse1,312.5,200.25,0.98,...

* header (first line): an optional ``time`` or ``timestamp`` column (seconds), an optional
  ``body`` column (several bodies: rows are grouped by its value, a number or a name),
  then for every joint
  ``<joint>_x``, ``<joint>_y``, ``<joint>_z`` (case-insensitive suffixes, in this order,
  joints in file order; ``_x``, ``_y`` alone for 2-D keypoints, the same for every joint)
  and, after them in any order, optionally ``<joint>_state`` (tracking state: 0 not
  tracked, 1 inferred, 2 tracked), ``<joint>_sd`` (posterior standard deviation, in the
  positions' units), ``<joint>_sample`` (sample state, ``SampleState``: 0 measured,
  1 rejected and filled, 2 missing and filled, 3 extrapolated, 4 no estimate) and
  ``<joint>_confidence`` (a pose estimator's score in [0, 1]). A ``.`` may stand for the
  ``_`` (``<joint>.x``, ``<joint>.state``: R's column names), the same within a joint's
  axes; a name ending in ``_x`` is read as joint and ``_x`` first (``a.b_x``: joint
  ``a.b``), so every header read before reads the same.
  A leading index column as ``DataFrame.to_csv`` writes it (header field empty or
  ``Unnamed: 0``) is skipped.
* values: plain decimal numbers in the sidecar's ``units`` (without a sidecar: metres for
  3-D, unknown for 2-D); an empty field, ``nan`` or ``NA`` (R's missing value; both in
  any case) is a missing value.
* separator: comma (``,``); a file whose header has tabs or semicolons and no comma uses
  that separator instead (text inside double quotes does not count).
* header fields may be double-quoted (RFC 4180: ``"Head,L_x"``, ``""`` for a quote inside);
  the writer quotes a name holding a separator, a quote or a leading ``#``, and refuses
  names it cannot write so that they read back the same (empty, surrounding white space,
  control characters or lone surrogates).

Sidecar. What a table cannot hold goes into a JSON file beside it, named like the CSV
with its last extension replaced by ``.json`` (``a.robust.csv`` -> ``a.robust.json``,
:func:`sidecar_path`): topology (with its bones), units, up axis, fps, body ids (names
too), the column meanings and the
provenance (tobitkf version, method, complete parameters, source). The reader uses it
when it exists and is a tobitkf sidecar (``"format": "tobitkf.csv-sidecar"``).

Old layout. Files written before the sidecar begin with comment lines ``# key: value``
(topology, fps, body_id, up_axis); they are still read (a comment line anywhere is
skipped), the sidecar's values taking precedence where both exist.

The topology is the named built-in when its joints match the header, else the built-in
whose joints equal the header's, else a custom one from the names.

Bodies with different joints (a multi-animal pose file's individuals and its ``single``
one of unique body parts) share one table: its columns are the union of their joints, a
body leaves the fields of joints it lacks empty, and the sidecar's entry of each body
lists its own joints (``joints``) and its topology (``topology``, ``parents``), which
the reader takes back (so too for bodies of the same joints but different bones).
"""

from __future__ import annotations

import csv
import json
import os
import re
import unicodedata
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tobitkf.core.jsonable import to_jsonable
from tobitkf.core.version import __version__
from tobitkf.io._text import (
    INTEGER,
    NUMBER,
    check_positions,
    check_rate,
    check_times,
    decode,
    fmt_floats,
    nonempty,
    parse_number,
    parse_rows,
    read_bytes,
    read_lines,
)
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format, require_frames
from tobitkf.io.unstated import UNITS_UNSTATED
from tobitkf.skeleton.sequence import KNOWN_UNITS, SampleState, SkeletonSequence
from tobitkf.skeleton.topology import Topology, available_topologies, get_topology

__all__ = [
    "SIDECAR_FORMAT",
    "read_csv",
    "sidecar_path",
    "sidecar_provenance",
    "sniff_csv",
    "write_csv",
]

_TIME = ("time", "timestamp", "t")
_AXES = ("_x", "_y", "_z")
#: per-joint columns after x, y, z: suffix -> what they hold
_EXTRA = ("_state", "_sd", "_sample", "_confidence")
#: what may join a joint's name to its column suffix: ``a_x``, or ``a.x`` (R's names)
_JOINERS = ("_", ".")
#: R's missing value (``NA``, any case), read as an empty field
_NA_FIELD = re.compile(r"[ \t]*na[ \t]*", re.IGNORECASE)
_INDEX = ("", "unnamed: 0")  # DataFrame.to_csv's index column
#: the ``format`` entry that marks a JSON file as a tobitkf CSV sidecar
SIDECAR_FORMAT = "tobitkf.csv-sidecar"
SIDECAR_VERSION = 1
_COLUMNS = {
    "time": "seconds",
    "body": "body id (several bodies: rows grouped by it)",
    "<joint>_x, <joint>_y, <joint>_z": "position, in `units`; empty or nan = missing; "
    "no _z column for 2-D keypoints",
    "<joint>_state": "tracking state: 0 not tracked, 1 inferred (filled or guessed), 2 tracked",
    "<joint>_sd": "posterior standard deviation of the position, in `units` (rms over the axes)",
    "<joint>_confidence": "the pose estimator's score in [0, 1]; empty = none",
    "<joint>_sample": {
        str(int(SampleState.MEASURED)): "measured: a measurement was used",
        str(int(SampleState.REJECTED)): "rejected: judged impossible, position filled in",
        str(int(SampleState.MISSING)): "missing: no measurement, interpolated",
        str(int(SampleState.EXTRAPOLATED)): "extrapolated: no measurement, predicted",
        str(int(SampleState.NONE)): "none: no estimate (position empty)",
    },
}
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
    extra: dict[str, dict[int, int]] = {suffix: {} for suffix in _EXTRA}
    k = 0
    while k < len(cols):
        c = cols[k]
        low = c.lower()
        if k == 0 and low in _INDEX:
            k += 1  # a pandas index column: skipped
            continue
        if low in _TIME and time_col is None and not joints:
            time_col = k
            k += 1
            continue
        if low in ("body", "body_id") and body_col is None:
            body_col = k
            k += 1
            continue
        joiner = next((j for j in _JOINERS if low.endswith(j + "x")), None)
        if joiner is not None:
            base = c[:-2]
            n = _axis_count(cols[k : k + 3], base, joiner)
            if not base or not n or (xyz and n != len(xyz[0])):
                expect = [joiner + a for a in "xyz"[: len(xyz[0]) if xyz else 3]]
                raise ReadError(
                    path,
                    line_no,
                    f"expected columns {[base + a for a in expect]} at positions {k + 1}-"
                    f"{k + len(expect)}, found {cols[k : k + len(expect)]}",
                )
            if base in joints:
                raise ReadError(path, line_no, f"joint {base!r} appears twice in the header")
            joints.append(base)
            xyz.append(tuple(range(k, k + n)))
            k += n
            continue
        suffix = next(
            (
                x
                for x in _EXTRA
                for j in _JOINERS
                if joints and low.endswith(j + x[1:]) and c[: -len(x)] == joints[-1]
            ),
            None,
        )
        if suffix is not None and len(joints) - 1 not in extra[suffix]:
            extra[suffix][len(joints) - 1] = k
            k += 1
            continue
        raise ReadError(
            path,
            line_no,
            f"unexpected column {c!r} (position {k + 1}); expected time, body, "
            "<joint>_x/_y(/_z), <joint>_state, <joint>_sd, <joint>_sample or "
            "<joint>_confidence ('.' in place of '_' too)",
        )
    if not joints:
        raise ReadError(path, line_no, "expected <joint>_x, <joint>_y(, <joint>_z) columns")
    return len(cols), time_col, body_col, joints, xyz, extra


def _blank_na(row: str, sep: str) -> str:
    """``row`` with its ``NA`` fields (R's missing value) empty, as missing as ``""``."""
    return sep.join("" if _NA_FIELD.fullmatch(f) else f for f in row.split(sep))


def _axis_count(fields: list[str], base: str, joiner: str) -> int:
    """3 when ``fields`` start with ``<base>x, y, z`` columns (case-insensitive, joined by
    ``joiner``), 2 for ``x, y`` alone (2-D), 0 when they do not."""
    triple = [t.lower() for t in fields]
    want = [(base + joiner + a).lower() for a in "xyz"]
    n = 3 if triple == want else 2 if triple[:2] == want[:2] else 0
    if n == 2 and len(triple) == 3 and triple[2].startswith(base.lower() + joiner):
        if "_" + triple[2][len(base) + 1 :] not in _EXTRA:
            n = 0  # <joint>_x, <joint>_y, <joint>_<typo>: a third axis was meant
    return n


def _topology(
    names: list[str], hint: str | None, up_axis: int | None, parents: list[int] | None = None
) -> Topology:
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
        names, parents, up_axis=1 if up_axis is None else up_axis, name=hint or "custom"
    )


def _body_id(text: str) -> int | float:
    """A body-id field as an exact int when it is integral (else the float)."""
    text = text.strip()
    try:
        return int(text)
    except ValueError:
        v = float(text)  # parse_rows accepted the field, so it is a number
        return int(v) if v.is_integer() else v


def _body_keys(rows: list[str], sep: str, col: int) -> list[int | float | str | None]:
    """Each row's body: its number (:func:`_body_id`), or its name when the field is text
    (a track's or an animal's name); None for a row too short to have the field, or an
    empty one (the numbers' parser reports both)."""
    keys: list[int | float | str | None] = []
    for r in rows:
        fields = r.split(sep)
        text = fields[col].strip() if col < len(fields) else ""
        if not text:
            keys.append(None)
        elif NUMBER.fullmatch(text):
            keys.append(_body_id(text))
        else:
            keys.append(text)
    return keys


def _set_field(row: str, sep: str, col: int, value: str) -> str:
    fields = row.split(sep)
    fields[col] = value
    return sep.join(fields)


def read_csv(path: str | os.PathLike[str], implausible: str = "error") -> list[SkeletonSequence]:
    """Read a generic skeleton CSV (see the module docstring for the layout).

    ``implausible`` (``"error"`` or ``"missing"``): what to do with a position beyond the
    plausibility bound (``_text.check_positions``).

    Returns
    -------
    list of SkeletonSequence (one per ``body`` value, or one), positions (T, J, 3) or
    (T, J, 2).
    """
    lines = read_lines(path)
    side = _read_sidecar(path)
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
    ncols, time_col, body_col, joints, xyz, extra = _parse_header(
        path, _split_header(path, header, sep, start + 1), start + 1
    )
    rows, numbers = nonempty(lines, start + 1)
    rows = [r for r in rows if not r.lstrip().startswith("#")]
    numbers = [n for n in numbers if not lines[n - 1].lstrip().startswith("#")]
    if not rows:
        raise ReadError(path, None, "no frames after the header line")
    rows = [r.rstrip() for r in rows]
    rows = [r[: -len(sep)] if r.endswith(sep) and r.count(sep) == ncols else r for r in rows]
    rows = [_blank_na(r, sep) if "a" in r or "A" in r else r for r in rows]
    keys = None if body_col is None else _body_keys(rows, sep, body_col)
    if keys is not None:  # names parse as 0: the numbers' parser sees only numbers
        rows = [
            _set_field(r, sep, body_col, "0") if isinstance(key, str) else r
            for r, key in zip(rows, keys, strict=True)
        ]
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
    if "fps" in side:
        fps = side["fps"]
    elif "fps" in comments:
        text, no = comments["fps"], comment_line["fps"]
        fps = check_rate(path, no, parse_number(path, no, text, "'# fps:'"), "fps", text)
    up_axis = side.get("up_axis")
    if up_axis is None and comments.get("up_axis") in ("0", "1", "2"):
        up_axis = int(comments["up_axis"])
    parents = side.get("parents")
    if parents is not None and len(parents) != len(joints):
        parents = None
    try:
        topo = _topology(joints, side.get("topology", comments.get("topology")), up_axis, parents)
    except ValueError as exc:  # the sidecar's parents do not form a tree
        raise ReadError(sidecar_path(path), None, f"tobitkf CSV sidecar: {exc}") from None
    n_dims = len(xyz[0])
    units = side.get("units", "m" if n_dims == 3 else None)
    if body_col is not None:
        ids = data[:, body_col]
        if np.isnan(ids).any():
            k = int(np.flatnonzero(np.isnan(ids))[0])
            raise ReadError(path, numbers[k], "expected a body id, found an empty field")
        # from the text, not the float: 64-bit Kinect body ids (NTU: 72057594037931101)
        # do not fit a double, and neighbouring ids would merge into one body
        groups: dict[int | float | str | None, list[int]] = {}  # in order of first appearance
        for k, key in enumerate(keys or ()):
            groups.setdefault(key, []).append(k)
    else:
        groups = {None: list(range(len(rows)))}
    out = []
    for group_id, members in groups.items():
        d = data[members]
        nos = [numbers[k] for k in members]
        entry = side.get("bodies", {}).get(group_id, {})
        g_joints, g_xyz, g_extra, g_topo = joints, xyz, extra, topo
        if "joints" in entry:  # this body's own joints, of the header's union
            absent = [n for n in entry["joints"] if n not in joints]
            if absent:
                raise ReadError(
                    sidecar_path(path), None,
                    f"tobitkf CSV sidecar: body {group_id}'s joint {absent[0]!r} has no "
                    "columns in the table",
                )  # fmt: skip
            sel = [joints.index(n) for n in entry["joints"]]
            g_joints = [joints[j] for j in sel]
            g_xyz = [xyz[j] for j in sel]
            g_extra = {
                k: {new: cols[j] for new, j in enumerate(sel) if j in cols}
                for k, cols in extra.items()
            }
            try:
                g_topo = _topology(g_joints, entry.get("topology"), up_axis, entry.get("parents"))
            except ValueError as exc:
                raise ReadError(sidecar_path(path), None, f"tobitkf CSV sidecar: {exc}") from None
        idx = np.array(g_xyz, dtype=int)
        positions = d[:, idx]  # (T, J, 3); parse_rows has rejected inf
        state = None
        if g_extra["_state"]:
            state = np.full((len(d), len(g_joints)), 2, dtype=np.int8)
            for j, c in g_extra["_state"].items():
                col = d[:, c]
                col = np.where(np.isnan(col), 0, col)
                bad = ~np.isin(col, (0, 1, 2))
                if bad.any():
                    k = int(np.flatnonzero(bad)[0])
                    raise ReadError(
                        path,
                        nos[k],
                        f"expected a state 0, 1 or 2 for {g_joints[j]}, found {col[k]}",
                    )
                state[:, j] = col
        std = _float_columns(
            path, d, nos, g_extra["_sd"], g_joints, "a standard deviation >= 0", 0.0
        )
        sample = _sample_columns(path, d, nos, g_extra["_sample"], g_joints)
        confidence = _float_columns(
            path, d, nos, g_extra["_confidence"], g_joints, "a confidence in [0, 1]", 0.0, 1.0
        )
        check_positions(path, positions, nos, implausible, names=g_joints, state=state, units=units)
        timestamps = None
        if time_col is not None:
            timestamps = d[:, time_col]
            check_times(path, timestamps, nos)
        body_id = group_id
        if "body_id" in entry:
            body_id = entry["body_id"]
        elif body_col is None and "body_id" in comments:
            body_id = comments["body_id"]
            if INTEGER.fullmatch(body_id):
                body_id = int(body_id)
        metadata: dict[str, Any] = {"source": str(path), "format": "csv"}
        if "units" not in side:  # assumed (metres in 3-D): --units may say otherwise
            metadata[UNITS_UNSTATED] = True
        if "video" in entry:
            metadata["video"] = entry["video"]
        provenance = entry.get("provenance", side.get("provenance"))
        if provenance is not None:
            metadata["provenance"] = provenance
        out.append(
            SkeletonSequence(
                positions=positions,
                topology=g_topo,
                tracking_state=state,
                timestamps=timestamps,
                fps=fps,
                body_id=body_id,
                metadata=metadata,
                std=std,
                sample_state=sample,
                confidence=confidence,
                units=units,
            )
        )
    return out


def _float_columns(
    path, d: np.ndarray, nos: list[int], cols: dict[int, int], joints: list[str],
    what: str, lo: float, hi: float = np.inf,
):  # fmt: skip
    """(T, J) values in [lo, hi] from one kind of per-joint column (NaN where none); None
    when the file has none or this body's are all empty (a body written without them)."""
    if not cols:
        return None
    v = np.full((len(d), len(joints)), np.nan)
    for j, c in cols.items():
        v[:, j] = d[:, c]
    if np.isnan(v).all():
        return None
    bad = (v < lo) | (v > hi)
    if bad.any():
        k, j = (int(x[0]) for x in np.nonzero(bad))
        raise ReadError(path, nos[k], f"expected {what} for {joints[j]}, found {v[k, j]}")
    return v


def _sample_columns(path, d: np.ndarray, nos: list[int], cols: dict[int, int], joints: list[str]):
    """(T, J) sample states from the ``_sample`` columns; None when the file has none or
    this body's are all empty. A joint without a column has no estimate (NONE)."""
    if not cols:
        return None
    values = np.stack([d[:, c] for c in cols.values()], axis=1)
    if np.isnan(values).all():
        return None
    codes = [int(v) for v in SampleState]
    sample = np.full((len(d), len(joints)), int(SampleState.NONE), dtype=np.int8)
    for j, c in cols.items():
        col = d[:, c]
        bad = ~np.isin(col, codes)  # NaN too: a body has states for all its samples or none
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise ReadError(
                path,
                nos[k],
                f"expected a sample state {', '.join(map(str, codes))} for {joints[j]}, "
                f"found {col[k]}",
            )
        sample[:, j] = col
    return sample


def sidecar_path(path: str | os.PathLike[str]) -> Path:
    """The JSON sidecar of a CSV: its last extension replaced by ``.json``
    (``a.robust.csv`` -> ``a.robust.json``)."""
    return Path(path).with_suffix(".json")


#: the sidecar is small; anything larger is not one of ours
_MAX_SIDECAR_BYTES = 16 * 2**20


def _read_sidecar(path) -> dict[str, Any]:
    """The sidecar's values, checked: ``topology``, ``up_axis``, ``fps``, ``provenance``
    and ``bodies`` (value of the body column, None for a single body -> its ``body_id``
    and ``provenance``); {} when there is no sidecar or the JSON file is not one."""
    side = sidecar_path(path)
    if side == Path(path) or not side.is_file():
        return {}
    if side.stat().st_size > _MAX_SIDECAR_BYTES:
        return {}
    try:
        doc = json.loads(decode(side, read_bytes(side)))
    except (ValueError, RecursionError):
        return {}  # not JSON: not a sidecar of ours
    if not isinstance(doc, dict) or doc.get("format") != SIDECAR_FORMAT:
        return {}

    def bad(what: str) -> ReadError:
        return ReadError(side, None, f"tobitkf CSV sidecar: {what}")

    out: dict[str, Any] = {}
    if isinstance(doc.get("topology"), str):
        out["topology"] = doc["topology"]
    if doc.get("up_axis") is not None:
        if doc["up_axis"] not in (0, 1, 2) or isinstance(doc["up_axis"], bool):
            raise bad(f"expected up_axis 0, 1 or 2, found {doc['up_axis']!r}")
        out["up_axis"] = int(doc["up_axis"])
    if doc.get("fps") is not None:
        fps = doc["fps"]
        if isinstance(fps, bool) or not isinstance(fps, (int, float)):
            raise bad(f"expected a number for fps, found {fps!r}")
        out["fps"] = check_rate(side, None, float(fps), "fps", repr(fps))
    if isinstance(doc.get("provenance"), dict):
        out["provenance"] = doc["provenance"]
    if "units" in doc:
        units = doc["units"]
        if units is not None and units not in KNOWN_UNITS:
            raise bad(f"expected units {sorted(KNOWN_UNITS)} or null, found {units!r}")
        out["units"] = units
    parents = doc.get("parents")
    if parents is not None:
        if not isinstance(parents, list) or not all(
            isinstance(p, int) and not isinstance(p, bool) for p in parents
        ):
            raise bad(f"expected a list of parent indices, found {parents!r}")
        out["parents"] = parents
    bodies: dict[Any, dict[str, Any]] = {}
    entries = doc.get("bodies", [])
    if not isinstance(entries, list):
        raise bad("expected a list of bodies")
    for e in entries:
        if not isinstance(e, dict):
            raise bad(f"expected a body entry (an object), found {e!r}")
        body_id = e.get("body_id")
        if body_id is not None and (
            isinstance(body_id, bool) or not isinstance(body_id, (int, str))
        ):
            raise bad(f"expected an int or str body id, found {body_id!r}")
        entry = {k: e[k] for k in ("body_id", "provenance") if k in e}
        if isinstance(e.get("video"), str):
            entry["video"] = e["video"]
        if e.get("joints") is not None:
            joints = e["joints"]
            if not (
                isinstance(joints, list) and joints and all(isinstance(n, str) for n in joints)
            ):
                raise bad(f"expected a body's joints as a list of names, found {joints!r}")
            if len(set(joints)) != len(joints):
                raise bad(f"a body's joints repeat a name: {joints!r}")
            entry["joints"] = joints
            parents = e.get("parents")
            if parents is not None:
                if not (
                    isinstance(parents, list)
                    and len(parents) == len(joints)
                    and all(isinstance(q, int) and not isinstance(q, bool) for q in parents)
                ):
                    raise bad(
                        f"expected a parent index for each of the body's joints, found {parents!r}"
                    )
                entry["parents"] = parents
            if isinstance(e.get("topology"), str):
                entry["topology"] = e["topology"]
        key = e.get("body")
        if key is not None and (isinstance(key, bool) or not isinstance(key, (int, str))):
            raise bad(f"expected an int or str body column value, found {key!r}")
        bodies[key] = entry
    out["bodies"] = bodies
    return out


def sidecar_provenance(path: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The provenance recorded in a CSV's sidecar (method, parameters, version), or None
    when there is no tobitkf sidecar or it cannot be read."""
    try:
        prov = _read_sidecar(path).get("provenance")
    except (ReadError, OSError):
        return None
    return prov if isinstance(prov, dict) else None


def write_csv(
    sequences: Sequence[SkeletonSequence],
    path: str | os.PathLike[str],
    *,
    sep: str = ",",
    sidecar: bool = True,
) -> None:
    """Write sequences as a generic CSV plus its JSON sidecar (exact round trip through
    :func:`read_csv`).

    Columns: ``time`` (when any sequence has
    timestamps), ``body`` (when more than one sequence: the body ids when they are
    distinct integers, or distinct names that read back as they are (not numbers nor
    ``NA``, no separator, quote, surrounding white space or leading ``#``), else
    0, 1, ...; the sidecar has the ids either way), then per joint (the union of the sequences'
    joints, in order of first appearance; a body leaves the fields of joints it lacks
    empty) ``_x, _y[, _z]``, ``_state`` (when
    tracking states are present), ``_sd`` (when a posterior standard deviation is),
    ``_sample`` (when sample states are) and ``_confidence`` (when confidences are); a
    body without one of them leaves those fields empty. The sidecar
    (:func:`sidecar_path`) holds topology (name and parents), units, up axis, fps, body
    ids, the columns' meanings and provenance; ``sidecar=False`` writes the table alone.
    An existing JSON file at the sidecar's path that is not a tobitkf sidecar is never
    overwritten (ValueError).
    """
    seqs = list(sequences)
    if not seqs:
        raise ValueError("write_csv needs at least one sequence")
    require_frames(seqs, "CSV")
    if sep not in _SEPARATORS:
        raise ValueError(f"sep must be one of {_SEPARATORS}, found {sep!r}")
    names = list(dict.fromkeys(n for s in seqs for n in s.joint_names))  # the union, in order
    for n in names:
        _check_writable(n, "joint name")
    multi = len(seqs) > 1
    ids = _column_ids(seqs)
    with_state = any(s.tracking_state is not None for s in seqs)
    with_std = any(s.std is not None for s in seqs)
    with_sample = any(s.sample_state is not None for s in seqs)
    with_time = any(s.timestamps is not None for s in seqs)
    with_conf = any(s.confidence is not None for s in seqs)
    n_dims = seqs[0].n_dims
    units = seqs[0].units
    for s in seqs[1:]:
        if (s.n_dims, s.units) != (n_dims, units):
            raise ValueError(
                "all sequences written to one CSV must have the same dimension and units"
            )
    axes = _AXES[:n_dims]
    if not multi and seqs[0].body_id is not None:
        _writable_body_id(seqs[0].body_id)
    side = sidecar_path(path)
    doc = None
    if sidecar:
        if side == Path(path):
            raise ValueError(f"cannot write a CSV named {Path(path).name!r}: its sidecar is itself")
        if side.exists() and not _is_sidecar(side):
            raise ValueError(
                f"will not overwrite {side}: it is not a tobitkf CSV sidecar (move it, or "
                "pass sidecar=False)"
            )
        doc = _sidecar(seqs, ids if multi else None)
    header = []
    if with_time:
        header.append("time")
    if multi:
        header.append("body")
    for n in names:
        header += [_quoted(f"{n}{a}") for a in axes]
        for suffix, present in (
            ("_state", with_state),
            ("_sd", with_std),
            ("_sample", with_sample),
            ("_confidence", with_conf),
        ):
            if present:
                header.append(_quoted(f"{n}{suffix}"))
    lines = [sep.join(header)]
    for k, s in enumerate(seqs):
        T = s.n_frames
        # column by column, from Python numbers (tolist): no numpy scalar per field
        cols: list[list[str]] = []
        if with_time:
            cols.append(fmt_floats(s.times()))
        if multi:
            cols.append([str(ids[k])] * T)
        # each array formatted in one call, its columns then taken as strided slices
        J = s.n_joints
        pos = fmt_floats(s.positions)
        std = None if s.std is None else fmt_floats(s.std)
        conf = None if s.confidence is None else fmt_floats(s.confidence)
        own = {n: j for j, n in enumerate(s.joint_names)}
        for name in names:
            j = own.get(name)
            if j is None:  # a joint of another body: empty fields
                width = n_dims + with_state + with_std + with_sample + with_conf
                cols += [[""] * T] * width
                continue
            cols += [pos[j * n_dims + a :: J * n_dims] for a in range(n_dims)]
            if with_state:
                st = s.tracking_state
                cols.append(["2"] * T if st is None else _ints(st[:, j]))
            if with_std:
                cols.append([""] * T if std is None else std[j::J])
            if with_sample:
                ss = s.sample_state
                cols.append([""] * T if ss is None else _ints(ss[:, j]))
            if with_conf:
                cols.append([""] * T if conf is None else conf[j::J])
        lines += map(sep.join, zip(*cols, strict=True))
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")
    if doc is not None:
        side.write_text(doc, encoding="utf-8")


def _is_sidecar(path: Path) -> bool:
    """True when ``path`` is a JSON file marked as a tobitkf CSV sidecar."""
    try:
        if path.stat().st_size > _MAX_SIDECAR_BYTES:
            return False
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return False
    return isinstance(doc, dict) and doc.get("format") == SIDECAR_FORMAT


def _sidecar(seqs: list[SkeletonSequence], ids: list[Any] | None) -> str:
    """The sidecar's JSON text (see the module docstring); ``ids``: the body column's
    values, None for a single body (no body column)."""
    first = seqs[0]
    union = list(dict.fromkeys(n for s in seqs for n in s.joint_names))
    own_joints = any(  # each body's own joints and bones when they are not all alike
        list(s.joint_names) != union
        or (s.topology.name, s.topology.parents) != (first.topology.name, first.topology.parents)
        for s in seqs
    )
    provs = [s.metadata.get("provenance") for s in seqs]
    texts = [json.dumps(to_jsonable(p), sort_keys=True) for p in provs]
    shared = provs[0] if len(set(texts)) == 1 else None
    bodies = []
    for k, s in enumerate(seqs):
        # one body: its id lives here; several: the body column holds the ids
        entry: dict[str, Any] = (
            {"body": None, "body_id": s.body_id}
            if ids is None
            else {"body": ids[k], "body_id": s.body_id}
        )
        if shared is None and provs[k] is not None:
            entry["provenance"] = provs[k]
        if isinstance(s.metadata.get("video"), str):  # a SLEAP project's video of the body
            entry["video"] = s.metadata["video"]
        if own_joints:
            entry["joints"] = list(s.joint_names)
            entry["topology"] = s.topology.name
            entry["parents"] = list(s.topology.parents)
        bodies.append(entry)
    doc = {
        "format": SIDECAR_FORMAT,
        "format_version": SIDECAR_VERSION,
        "written_by": f"tobitkf {__version__}",
        "topology": first.topology.name,
        "parents": list(first.topology.parents),
        "units": first.units,
        "up_axis": first.topology.up_axis,
        "fps": first.fps,
        "bodies": bodies,
        "columns": _COLUMNS,
        "provenance": shared,
    }
    return json.dumps(to_jsonable(doc), indent=2) + "\n"  # ASCII: any name survives


def _column_ids(seqs: list[SkeletonSequence]) -> list[int | str]:
    """The body column's values: the sequences' own ids when they are distinct integers
    or distinct names that read back as they are (:func:`_plain_name`), else their
    index. A mix (ids 1 and None -> 1 and 1; 1 and "1") would merge bodies on reading."""
    ids = [s.body_id for s in seqs]
    if len(set(map(str, ids))) == len(ids):
        if all(isinstance(b, (int, np.integer)) and not isinstance(b, bool) for b in ids):
            return [int(b) for b in ids]
        if all(_plain_name(b) for b in ids):
            return list(ids)
    return list(range(len(seqs)))


def _plain_name(body_id: object) -> bool:
    """True for a body id the body column holds as text and reads back the same: a str
    that is not a number nor a missing value, without white space around it, a
    separator, a quote, a control character or a leading comment mark."""
    if not isinstance(body_id, str):
        return False
    try:  # control characters, surrounding white space, empty: as for a header name
        _check_writable(body_id, "body id")
    except ValueError:
        return False
    if NUMBER.fullmatch(body_id) or _NA_FIELD.fullmatch(body_id) or body_id.lower() == "nan":
        return False
    return not body_id.startswith("#") and not any(c in body_id for c in "\",;\t'")


def _ints(a: np.ndarray) -> list[str]:
    return list(map(str, np.asarray(a).astype(int).tolist()))


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
    """Score: a header line with ``<joint>_x,<joint>_y(,<joint>_z)`` columns (or ``.x``,
    ``.y``, ``.z``; more sure with the sidecar :func:`write_csv` writes beside it, or, in
    the old layout, after its ``# topology:`` line)."""
    side = sidecar_path(path)
    written = side != path and side.is_file() and _is_sidecar(side)  # not any JSON beside it
    for line in head.split("\n")[:50]:
        s = line.strip()
        written = written or s.startswith("# topology:")
        if not s or s.startswith("#"):
            continue
        low = s.lower()
        fields = [f.strip().strip('"') for f in re.split(r"[,;\t]", low)]
        has = {a: any(f.endswith(("_" + a, "." + a)) for f in fields) for a in "xyz"}
        if has["x"] and has["y"] and ("," in s or ";" in s or "\t" in s):
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
    side_outputs=lambda p: [sidecar_path(p)],
    companion=lambda p: p.suffix.lower() == ".json" and p.with_suffix(".csv").is_file()
    and _is_sidecar(p),
)  # fmt: skip
