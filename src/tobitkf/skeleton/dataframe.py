"""pandas DataFrames of skeleton sequences, long or wide (pandas is an optional extra).

Long layout (:func:`to_dataframe`, ``layout="long"``, the default): one row per frame,
individual and keypoint::

    frame  time   individual  keypoint  x      y      [z]  [confidence] [tracking_state]
    0      0.000  mouse1      snout     312.5  200.2       0.98
    ...

``individual`` is the body id (a column only when some body has one or there are
several bodies); ``time`` (seconds) when the sequence has timestamps or an fps;
``std`` and ``sample_state`` after smoothing; any other column is an error (a
pandas index column ``Unnamed: 0`` is passed over). Wide layout (``layout="wide"``): one row
per frame (index ``time`` when there are timestamps or an fps, else ``frame``) and
columns ``(individual, keypoint, coord)`` with coord ``x``, ``y``, ``z``, ``confidence``,
``tracking_state``, ``std``, ``sample_state`` — the layout of a DeepLabCut table, whose
``scorer`` level and ``likelihood`` coordinate :func:`from_dataframe` reads too.

Flat layout (what ``pandas.read_csv`` gives of tobitkf's own CSV, and of many pose
tools' exports): one row per frame, an optional ``time`` (or ``timestamp``) column, an
optional ``body`` column (rows grouped by its value), and columns ``<keypoint>_x``,
``<keypoint>_y`` [``_z``] with optionally ``<keypoint>_confidence`` (or ``_likelihood``),
``_state`` (tracking state; a keypoint without one is tracked), ``_sd`` and ``_sample``
(sample state); ``.`` may stand for the ``_`` (R's ``<keypoint>.x``); a ``frame`` column
is passed over. Each body's frames are its rows; any other column is an error.

``DataFrame.attrs`` carries ``fps``, ``units``, ``topology`` (name), ``parents`` and
``up_axis``, so a round trip through :func:`from_dataframe` gives back the sequences;
without them, units are metres for 3-D and unknown for 2-D and the keypoints have no
bones. :func:`from_dataframe` returns a list of sequences, one per individual, on the
frames of the whole table (NaN where an individual has no row).
"""

from __future__ import annotations

import difflib
from collections.abc import Sequence
from typing import Any

import numpy as np

from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.to_frame import _COORDS, _PER_SAMPLE, _pandas, to_dataframe
from tobitkf.skeleton.topology import Topology, available_topologies, get_topology

__all__ = ["from_dataframe", "to_dataframe"]

_ALIASES = {
    "keypoint": ("keypoint", "keypoints", "bodypart", "bodyparts", "joint", "marker"),
    "individual": ("individual", "individuals", "body", "body_id", "track", "animal"),
    "confidence": ("confidence", "likelihood", "score", "visibility"),
}


def _pick(columns: Sequence[str], role: str) -> str | None:
    low = {str(c).lower(): c for c in columns}
    return next((low[a] for a in _ALIASES[role] if a in low), None)


def _topology(names: list[str], attrs: dict[str, Any]) -> Topology:
    hint = attrs.get("topology")
    parents = attrs.get("parents")
    up = attrs.get("up_axis", 1)
    for name in ([hint] if isinstance(hint, str) else []) + available_topologies():
        try:
            t = get_topology(name)
        except KeyError:
            continue
        if t.joints == tuple(names):
            return t
    if parents is not None and len(parents) != len(names):
        parents = None
    return Topology.from_names(
        names, parents, up_axis=up, name=hint if isinstance(hint, str) else "custom"
    )


def _build(
    values: dict[str, np.ndarray], names: list[str], times: Any, ident: Any, attrs: dict
) -> SkeletonSequence:
    n_dims = 3 if "z" in values else 2
    pos = np.stack([values[c] for c in _COORDS[:n_dims]], axis=-1)
    kw: dict[str, Any] = {}
    for name in _PER_SAMPLE:
        if name in values and not np.isnan(values[name]).all():
            v = values[name]
            if name in ("tracking_state", "sample_state"):
                if np.isnan(v).any():
                    raise ValueError(f"{name} has empty values")
                if np.any(v != np.round(v)):  # a code, not a measure: 2.7 is no state
                    bad = v[v != np.round(v)][0]
                    raise ValueError(f"{name} holds codes (whole numbers); found {float(bad)!r}")
                v = v.astype(np.int8)
            kw[name] = v
    units = attrs.get("units", "m" if n_dims == 3 else None)
    fps = attrs.get("fps")
    if times is not None and fps is not None:
        if np.array_equal(times, np.arange(len(times), dtype=float) / float(fps)):
            times = None  # the frame clock of the fps, not timestamps of their own
    return SkeletonSequence(
        pos,
        _topology(names, attrs),
        timestamps=times,
        fps=fps,
        body_id=ident.item() if isinstance(ident, np.generic) else ident,  # int, not int64
        units=units,
        **kw,
    )


def _from_wide(df: Any, attrs: dict[str, Any]) -> list[SkeletonSequence]:
    cols = df.columns
    if cols.nlevels == 4:  # DeepLabCut: scorer, individuals, bodyparts, coords
        cols = cols.droplevel(0)
    if cols.nlevels == 2:
        cols = [(None, k, c) for k, c in cols]
    elif cols.nlevels == 3:
        cols = list(cols)
        if df.columns.nlevels == 3 and df.columns.names[0] == "scorer":  # single-animal DLC
            cols = [(None, k, c) for _, k, c in cols]
    else:
        raise ValueError(
            "expected wide columns (keypoint, coord), (individual, keypoint, coord) or "
            f"DeepLabCut's (scorer, individuals, bodyparts, coords); got {cols.nlevels} levels"
        )
    data = df.to_numpy(dtype=float)
    order: dict[Any, dict[str, dict[str, np.ndarray]]] = {}
    for k, (ind, kp, coord) in enumerate(cols):
        role = str(coord).lower()
        role = "confidence" if role in _ALIASES["confidence"] else role
        if role not in _COORDS + _PER_SAMPLE:
            raise ValueError(f"unknown coordinate {coord!r} of keypoint {kp!r}")
        order.setdefault(ind, {}).setdefault(str(kp), {})[role] = data[:, k]
    index = df.index
    times = None
    if index.name == "time" or (index.name is None and attrs.get("time_index")):
        times = np.asarray(index, dtype=float)
    out = []
    for ind, per_kp in order.items():
        names = list(per_kp)
        T = len(df)
        values = {}
        for role in _COORDS + _PER_SAMPLE:
            if any(role in per_kp[n] for n in names):
                values[role] = np.stack(
                    [per_kp[n].get(role, np.full(T, np.nan)) for n in names], axis=1
                )
        if "x" not in values or "y" not in values:
            raise ValueError(f"{_who(ind)}: expected x and y coordinates")
        out.append(_build(values, names, times, ind, attrs))
    return out


def _who(ind: Any) -> str:
    """How a message names an individual (a table of one, without ids: "the table")."""
    return "the table" if ind is None else f"individual {ind!r}"


def _from_long(df: Any, attrs: dict[str, Any]) -> list[SkeletonSequence]:
    pd = _pandas()
    kp_col = _pick(df.columns, "keypoint")
    if kp_col is None or "x" not in df.columns or "y" not in df.columns:
        raise ValueError(
            "expected a long table with columns keypoint (or bodypart, joint), x, y[, z] "
            "and optionally frame, time, individual, confidence; or flat columns "
            "<keypoint>_x, <keypoint>_y[, _z] (tobitkf's CSV); or wide MultiIndex "
            f"columns; got columns {list(df.columns)[:8]}"
        )
    ind_col = _pick(df.columns, "individual")
    conf_col = _pick(df.columns, "confidence")
    _check_long_columns(
        df.columns, {"keypoint": kp_col, "individual": ind_col, "confidence": conf_col}
    )
    key = "frame" if "frame" in df.columns else "time" if "time" in df.columns else None
    if key is None:
        raise ValueError("expected a frame or time column")
    frames = np.sort(pd.unique(df[key]))
    names = list(pd.unique(df[kp_col].astype(str)))
    inds = list(pd.unique(df[ind_col])) if ind_col is not None else [None]
    T, J = len(frames), len(names)
    f_idx = np.searchsorted(frames, df[key].to_numpy())
    k_idx = pd.Index(names).get_indexer(df[kp_col].astype(str))
    times = None
    if "time" in df.columns:
        times = np.full(T, np.nan)
        times[f_idx] = df["time"].to_numpy(dtype=float)
        if np.isnan(times).any():
            raise ValueError("empty time values")
    out = []
    for ind in inds:
        rows = np.ones(len(df), bool) if ind_col is None else (df[ind_col] == ind).to_numpy()
        fi, ki = f_idx[rows], k_idx[rows]
        if len(set(zip(fi.tolist(), ki.tolist(), strict=True))) != rows.sum():
            raise ValueError(f"{_who(ind)}: a keypoint appears twice in one frame")
        values = {}
        for role, col in [(c, c) for c in _COORDS + _PER_SAMPLE if c in df.columns] + (
            [("confidence", conf_col)] if conf_col not in (None, "confidence") else []
        ):
            v = np.full((T, J), np.nan)
            v[fi, ki] = df.loc[rows, col].to_numpy(dtype=float)
            values[role] = v
        out.append(_build(values, names, times, ind, attrs))
    return out


#: the long layout's columns besides those named by an alias (:data:`_ALIASES`)
_LONG = ("frame", "time", *_COORDS, *_PER_SAMPLE)


def _check_long_columns(columns: Sequence[Any], picked: dict[str, Any]) -> None:
    """``ValueError`` naming the columns of a long table that no role takes (a typo such
    as ``confidance``, a second confidence column, an extra), as the wide and flat
    layouts refuse theirs: a column is not dropped without a word. ``picked``: the
    column taken for each role of :data:`_ALIASES` (None if none)."""
    taken = {c for c in picked.values() if c is not None}
    odd = [c for c in columns if c not in taken and c not in _LONG]
    odd = [c for c in odd if str(c) and not str(c).lower().startswith("unnamed:")]
    if not odd:
        return
    role_of = {a: role for role, names in _ALIASES.items() for a in names}
    known = [*_LONG, *role_of]
    notes = []
    for c in odd:
        low = str(c).lower()
        if low in role_of:  # e.g. likelihood next to confidence: which one?
            notes.append(f"{c!r}: a second {role_of[low]} column, besides {picked[role_of[low]]!r}")
        elif close := difflib.get_close_matches(low, known, n=1, cutoff=0.75):
            notes.append(f"{c!r}: did you mean {close[0]!r}?")
    raise ValueError(
        f"long table: unexpected column(s) {[str(c) for c in odd[:5]]}"
        + (f" ({'; '.join(notes[:5])})" if notes else "")
        + ". Its columns are keypoint (or bodypart, joint, marker), x, y[, z] and "
        "optionally frame, time, individual (or body, track, animal), one confidence (or "
        "likelihood, score, visibility), tracking_state, std, sample_state: rename a "
        "misspelt column, or drop the others (df.drop(columns=[...]))"
    )


#: the flat layout's column suffixes and the roles they give
_FLAT = {"x": "x", "y": "y", "z": "z", "confidence": "confidence", "likelihood": "confidence",
         "state": "tracking_state", "sd": "std", "sample": "sample_state"}  # fmt: skip


def _flat_role(name: str) -> tuple[str, str] | None:
    """``(keypoint, role)`` of a flat column ``<keypoint>_<suffix>`` (or ``.<suffix>``)."""
    for sep in ("_", "."):
        base, found, suffix = name.rpartition(sep)
        if found and base and suffix.lower() in _FLAT:
            return base, _FLAT[suffix.lower()]
    return None


def _flat_columns(columns: Sequence[Any]) -> dict[Any, tuple[str, str] | None] | None:
    """Column -> ``(keypoint, role)`` (None for the time, body, frame and index columns)
    when ``columns`` have at least one ``<k>_x`` and no ``keypoint`` column (the flat
    layout, module docstring); else None. ``ValueError`` naming a column that fits no
    role, or a keypoint's role given twice."""
    out: dict[Any, tuple[str, str] | None] = {}
    for c in columns:
        low = str(c).lower()
        skipped = low in ("time", "timestamp", "body", "body_id", "frame") or not low
        out[c] = None if skipped or low.startswith("unnamed:") else _flat_role(str(c))
    if not any(v is not None and v[1] == "x" for v in out.values()):
        return None
    odd = [c for c, v in out.items() if v is None and str(c).lower() not in _FLAT_SKIP]
    odd = [c for c in odd if not str(c).lower().startswith("unnamed:") and str(c)]
    if odd:
        raise ValueError(
            f"flat columns <keypoint>_x, _y[, _z], _confidence, _state, _sd, _sample (and "
            f"time, body, frame): unexpected column(s) {odd[:5]}"
        )
    seen: dict[tuple[str, str], Any] = {}
    for c, v in out.items():
        if v is not None:
            if v in seen:
                raise ValueError(f"keypoint {v[0]!r}: {v[1]} twice ({seen[v]!r}, {c!r})")
            seen[v] = c
    keypoints = {v[0] for v in seen}
    has = {role: {k for k, r in seen if r == role} for role in ("x", "y", "z")}
    for role in ("x", "y"):
        if has[role] != keypoints:
            raise ValueError(f"keypoints without a _{role} column: {sorted(keypoints - has[role])}")
    if has["z"] and has["z"] != keypoints:
        raise ValueError(f"keypoints without a _z column: {sorted(keypoints - has['z'])}")
    return out


_FLAT_SKIP = ("time", "timestamp", "body", "body_id", "frame")


def _from_flat(df: Any, attrs: dict[str, Any], layout: dict[Any, Any]) -> list[SkeletonSequence]:
    """The flat layout's sequences; a body's frames are its rows (in table order)."""
    pd = _pandas()
    low = {str(c).lower(): c for c, v in layout.items() if v is None}
    time_col = low.get("time", low.get("timestamp"))
    body_col = low.get("body", low.get("body_id"))
    keys = [c for c, v in layout.items() if v is not None]
    wide = df[keys].copy()
    wide.columns = pd.MultiIndex.from_tuples([layout[c] for c in keys])
    for role in ("tracking_state", "sample_state"):
        values = (
            wide.xs(role, axis=1, level=1) if role in wide.columns.get_level_values(1) else None
        )
        if values is not None:
            v = values.to_numpy(dtype=float)
            if np.any(np.isfinite(v) & (v != np.round(v))):
                raise ValueError(f"{role}: expected whole numbers, found {v[v != np.round(v)][:3]}")
    states = [k for k, r in wide.columns if r == "tracking_state"]
    if states:  # a keypoint without a _state column is TRACKED, as the CSV reader reads it
        for k in dict.fromkeys(k for k, _ in wide.columns):
            if k not in states:
                wide[(k, "tracking_state")] = 2.0
    if time_col is not None:
        wide.index = pd.Index(df[time_col].to_numpy(dtype=float), name="time")
    if body_col is None:
        return _from_wide(wide, attrs)
    ids = df[body_col].to_numpy()
    out = []
    for ident in pd.unique(ids):
        (seq,) = _from_wide(wide[ids == ident], attrs)
        out.append(seq.replace(body_id=ident.item() if hasattr(ident, "item") else ident))
    return out


def from_dataframe(df: Any) -> list[SkeletonSequence]:
    """Sequences (one per individual) from a long, wide or flat DataFrame (module
    docstring); ``ValueError`` naming what is missing otherwise."""
    pd = _pandas()
    if not isinstance(df, pd.DataFrame):
        raise TypeError(f"expected a pandas DataFrame, got {type(df).__name__}")
    attrs = dict(df.attrs)
    if isinstance(df.columns, pd.MultiIndex):
        return _from_wide(df, attrs)
    if _pick(df.columns, "keypoint") is None and "x" not in df.columns:
        layout = _flat_columns(list(df.columns))
        if layout is not None:
            return _from_flat(df, attrs, layout)
    return _from_long(df, attrs)
