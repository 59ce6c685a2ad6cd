"""DeepLabCut pose files (.h5 and .csv; single- and multi-animal), read and written.

DeepLabCut stores a pandas DataFrame whose columns are a MultiIndex with the levels
``scorer``, ``individuals`` (multi-animal projects only), ``bodyparts`` and ``coords``
(``x``, ``y``, ``likelihood``; ``x``, ``y``, ``z`` for 3-D). The row index is the frame
number (``range(n_frames)`` for video predictions; ``labeled-data/<video>/<image>``
paths for labelled frames, read as frames 0, 1, ...). The ``.h5`` holds it under the key
``df_with_missing`` (``DataFrame.to_hdf(path, key="df_with_missing", format="table")``,
PyTables); the ``.csv`` is ``DataFrame.to_csv(path)``: one header row per column level,
its first field the level's name, then a row per frame starting with the index.

Read: one sequence per individual (``body_id`` = the individual's name; a single-animal
file gives one sequence with ``body_id`` None), positions in pixels (``units="px"``;
3-D files: unknown units), ``confidence`` = ``likelihood``. In a multi-animal file the
``single`` individual of DeepLabCut's unique body parts has its own keypoints. The
file declares no skeleton (it lives in the project's ``config.yaml``): pass
``skeleton=[("snout", "tailbase"), ...]`` for bones, and ``fps=`` for the time base.

Write (:func:`write_deeplabcut`): the same layout, so the output goes back into
DeepLabCut (or movement, or any tool reading its files): ``.h5`` or ``.csv`` by the
path's suffix, ``likelihood`` = the confidence (1 where a position is given without
one, 0 where a smoother filled it: no detection lies there, so DeepLabCut's ``pcutoff``
and movement's confidence filter do not take it for a sure one; NaN where the position
is missing), scorer ``tobitkf`` unless the input's is kept; each individual with its own
body parts (the ``single`` individual of unique body parts keeps them). In the ``.h5``
a smoothed output's provenance (``metadata["provenance"]``; the individuals' shared one,
else a list with each one's) is JSON text in HDF5 attributes of the table's group,
``tobitkf_provenance`` (then ``tobitkf_provenance_2``, ... for JSON beyond 32,000
characters: one HDF5 attribute holds at most 64 KB), which ``pandas.read_hdf`` passes
by and :func:`read_deeplabcut` reads back; the ``.csv`` has no place for it.
Needs pandas (and PyTables for ``.h5``): ``pip install 'tobitkf[pose]'``.
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tobitkf.io._json import attach_provenance, provenance_text
from tobitkf.io._pose import (
    check_alike,
    check_hdf5_reads,
    frame_numbers,
    hdf5_open_error,
    hdf5_reason,
    individual_names,
    is_hdf5,
    require,
    sequences_from_arrays,
    written_confidence,
)
from tobitkf.io._text import read_bytes
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format, require_frames
from tobitkf.skeleton.sequence import SkeletonSequence

__all__ = [
    "DLC_KEY",
    "read_deeplabcut",
    "sequences_from_dlc_frame",
    "sniff_deeplabcut",
    "write_deeplabcut",
]

#: the HDF5 key DeepLabCut writes its table under
DLC_KEY = "df_with_missing"
_LEVELS = ("scorer", "individuals", "bodyparts", "coords")
#: the HDF5 attribute (of the table's group) holding the provenance's JSON
PROVENANCE_ATTR = "tobitkf_provenance"
#: characters of the JSON per attribute (an HDF5 attribute holds at most 64 KB)
_ATTR_CHARS = 32000


def _header_rows(path: Path) -> tuple[int, bool]:
    """Number of header rows of a DeepLabCut CSV (3 or 4) and whether its index is the
    three ``labeled-data`` columns."""
    with open(path, encoding="utf-8", errors="replace") as fh:
        first = [fh.readline() for _ in range(5)]
    keys = [ln.split(",", 1)[0].strip().lower() for ln in first]
    if keys[0] != "scorer":
        raise ReadError(
            path, 1, f"expected a DeepLabCut header row 'scorer,...', found {keys[0]!r}"
        )
    n = 4 if keys[1] == "individuals" else 3
    if keys[n - 1] != "coords" and not (keys[n - 1] == "" and first[n - 1].startswith(",")):
        raise ReadError(path, n, f"expected the header row 'coords,...', found {keys[n - 1]!r}")
    labelled = keys[n] == "labeled-data"
    if not labelled and n < len(keys) and keys[n] in ("frame", "frames"):
        n += 1  # an index-name row pandas writes for a named index
    return n, labelled


def _read_table(path: Path, pd: Any) -> tuple[Any, str | None]:
    """The DataFrame of a DeepLabCut ``.h5`` and the provenance's JSON tobitkf wrote
    beside it (None without; PyTables' HDF5 errors in one line)."""
    require("tables", "reading DeepLabCut .h5 files (pandas.read_hdf)")
    check_hdf5_reads(path, "reading DeepLabCut .h5 files")
    try:
        store = pd.HDFStore(path, mode="r")
    except (OSError, ValueError, RuntimeError) as exc:  # PyTables' HDF5ExtError: RuntimeError
        raise hdf5_open_error(path, exc) from None
    try:
        with store:
            keys = store.keys()
            key = "/" + DLC_KEY if "/" + DLC_KEY in keys else (keys[0] if keys else None)
            if key is None:
                raise ReadError(path, None, "no table in the HDF5 file")
            return store[key], _provenance_json(store.get_storer(key).attrs)
    except ReadError:
        raise
    except (OSError, ValueError, TypeError, KeyError, RuntimeError, AttributeError) as exc:
        raise ReadError(path, None, f"not a DeepLabCut table ({hdf5_reason(exc)})") from None


def _check_row_widths(path: Path, data: bytes, n_header: int) -> None:
    """A ReadError at the first row of ``data`` (the file's bytes) with another number of
    fields than the first header row (pandas would fill a short row, a file cut mid-row,
    with NaN and take the cut number for a value)."""
    lines = data.split(b"\n")
    width = lines[0].count(b",")
    for k in range(n_header, len(lines)):
        row = lines[k].rstrip(b"\r")
        if row and row.count(b",") != width:
            cut = k == len(lines) - 1  # no newline after it: the file ends mid-row
            raise ReadError(
                path, k + 1,
                f"expected {width + 1} fields as in the header, found {row.count(b',') + 1}"
                + (" (the file ends within this row: cut short?)" if cut else ""),
            )  # fmt: skip


def _provenance_json(attrs: Any) -> str | None:
    """The JSON of ``tobitkf_provenance``, ``tobitkf_provenance_2``, ... joined (None
    without them)."""
    parts, k = [], 1
    while (part := getattr(attrs, PROVENANCE_ATTR + (f"_{k}" if k > 1 else ""), None)) is not None:
        parts.append(part.decode("utf-8", "replace") if isinstance(part, bytes) else str(part))
        k += 1
    return "".join(parts) if parts else None


def _read_frame(path: Path) -> tuple[Any, str | None]:
    """The file's DataFrame and, for an ``.h5`` tobitkf wrote, its provenance's JSON."""
    pd = require("pandas", "reading DeepLabCut files")
    provenance = None
    if is_hdf5(path):
        df, provenance = _read_table(path, pd)
    elif path.suffix.lower() in (".h5", ".hdf5"):  # named HDF5, is not: say so, not "CSV"
        raise ReadError(path, None, "not an HDF5 file (it lacks the HDF5 signature)")
    else:
        n, labelled = _header_rows(path)
        data = read_bytes(path)  # read once: checked, then parsed by pandas
        _check_row_widths(path, data, n)
        try:
            df = pd.read_csv(
                io.BytesIO(data), header=list(range(n)), index_col=[0, 1, 2] if labelled else 0
            )
        except (ValueError, pd.errors.ParserError, UnicodeDecodeError) as exc:
            raise ReadError(path, None, f"not a DeepLabCut CSV ({exc})") from None
    if not isinstance(df, pd.DataFrame):
        raise ReadError(path, None, "expected a DataFrame in the file")
    return df, provenance


def sequences_from_dlc_frame(
    path: Any,
    df: Any,
    *,
    fmt: str = "deeplabcut",
    fps: Any = None,
    skeleton: Sequence[tuple[str, str]] | None = None,
    implausible: str = "error",
) -> list[SkeletonSequence]:
    """Sequences from a DeepLabCut DataFrame (the module's layout)."""
    pd = require("pandas", "reading DeepLabCut files")
    cols = df.columns
    if not isinstance(cols, pd.MultiIndex) or cols.nlevels not in (3, 4):
        raise ReadError(
            path, None, "expected column levels scorer, [individuals,] bodyparts, coords"
        )
    names = [str(n).lower() if n is not None else "" for n in cols.names]
    multi = cols.nlevels == 4
    scorer = str(cols.get_level_values(0)[0])
    inds = list(dict.fromkeys(cols.get_level_values(1))) if multi else [None]
    coords_all = [str(c).lower() for c in cols.get_level_values(-1)]
    bad = sorted(set(coords_all) - {"x", "y", "z", "likelihood"})
    if bad:
        raise ReadError(path, None, f"unknown coords {bad}; expected x, y, [z,] likelihood")
    D = 3 if "z" in coords_all else 2
    data = df.to_numpy(dtype=float)
    T = data.shape[0]
    index = df.index
    frames = None
    if not isinstance(index, pd.MultiIndex) and pd.api.types.is_integer_dtype(index):
        frames = np.asarray(index, dtype=np.int64)
    out: list[SkeletonSequence] = []
    by_ind: dict[Any, dict[str, dict[str, int]]] = {}
    for k, col in enumerate(cols):
        ind = col[1] if multi else None
        by_ind.setdefault(ind, {}).setdefault(str(col[-2]), {})[str(col[-1]).lower()] = k
    for ind in inds:
        parts = by_ind[ind]
        kps = list(parts)
        pos = np.full((T, 1, len(kps), D), np.nan)
        conf = np.full((T, 1, len(kps)), np.nan)
        for j, kp in enumerate(kps):
            for a, c in enumerate("xyz"[:D]):
                if c not in parts[kp]:
                    raise ReadError(path, None, f"keypoint {kp!r} has no {c} column")
                pos[:, 0, j, a] = data[:, parts[kp][c]]
            if "likelihood" in parts[kp]:
                conf[:, 0, j] = data[:, parts[kp]["likelihood"]]
        edges = None
        if skeleton:
            edges = [(a, b) for a, b in skeleton if a in kps and b in kps]
        meta: dict[str, Any] = {"scorer": scorer}
        if frames is not None and not np.array_equal(frames, np.arange(T)):
            meta["frames"] = frames
        out += sequences_from_arrays(
            path, pos, None if np.isnan(conf).all() else conf, kps,
            None if ind is None else [ind], fmt=fmt, units="px" if D == 2 else None, fps=fps,
            edges=edges, metadata=meta, implausible=implausible,
        )  # fmt: skip
    del names
    return out


def read_deeplabcut(
    path: str | os.PathLike[str],
    fps: float | None = None,
    skeleton: Sequence[tuple[str, str]] | None = None,
    implausible: str = "error",
) -> list[SkeletonSequence]:
    """Read a DeepLabCut ``.h5`` or ``.csv`` pose file (module docstring)."""
    p = Path(path)
    df, provenance = _read_frame(p)
    seqs = sequences_from_dlc_frame(p, df, fps=fps, skeleton=skeleton, implausible=implausible)
    attach_provenance(p, seqs, provenance, f"the HDF5 attribute {PROVENANCE_ATTR}")
    return seqs


def dlc_frame(sequences: Sequence[SkeletonSequence], scorer: str | None = None) -> Any:
    """The DeepLabCut DataFrame of sequences (one individual each, each with its own
    body parts: a multi-animal project's ``single`` individual has the unique ones)."""
    pd = require("pandas", "writing DeepLabCut files")
    seqs = list(sequences)
    if not seqs:
        raise ValueError("nothing to write: no sequences")
    check_alike(seqs)
    first = seqs[0]
    if scorer is None:
        scorer = str(first.metadata.get("scorer", "tobitkf"))
    multi = len(seqs) > 1 or first.body_id is not None
    n_dims, T = first.n_dims, first.n_frames
    coords = ["x", "y", "z"] if n_dims == 3 else ["x", "y", "likelihood"]
    blocks, columns = [], []
    for name, s in zip(individual_names(seqs), seqs, strict=True):
        score = written_confidence(s)
        for j, part in enumerate(s.joint_names):
            p = s.positions[:, j]
            blocks += [p[:, a] for a in range(n_dims)]
            if n_dims == 2:
                c = np.full(T, np.nan) if score is None else score[:, j]
                present = ~np.isnan(p).any(axis=-1)
                blocks.append(np.where(present, np.where(np.isnan(c), 1.0, c), np.nan))
            columns += [(scorer, *([name] if multi else []), part, c) for c in coords]
    level_names = _LEVELS if multi else ("scorer", "bodyparts", "coords")
    index = pd.MultiIndex.from_tuples(columns, names=list(level_names))
    data = np.stack(blocks, axis=1) if blocks else np.empty((T, 0))
    frames = frame_numbers(first)  # the input's row numbers, else 0, 1, ...
    return pd.DataFrame(data, columns=index, index=range(T) if frames is None else frames)


def write_deeplabcut(
    sequences: Sequence[SkeletonSequence], path: str | os.PathLike[str], scorer: str | None = None
) -> None:
    """Write sequences (one per individual) as a DeepLabCut ``.h5`` or ``.csv`` (by the
    suffix; module docstring)."""
    p = Path(path)
    sequences = list(sequences)
    require_frames(sequences, "DeepLabCut")
    df = dlc_frame(sequences, scorer)
    if p.suffix.lower() == ".csv":
        df.to_csv(p)
    elif p.suffix.lower() in (".h5", ".hdf5"):
        require("tables", "writing DeepLabCut .h5 files (pandas.to_hdf)")
        df.to_hdf(p, key=DLC_KEY, format="table", mode="w")
        provenance = provenance_text(sequences)
        if provenance is not None:
            pd = require("pandas", "writing DeepLabCut files")
            with pd.HDFStore(p, mode="a") as store:
                attrs = store.get_storer(DLC_KEY).attrs
                for k, start in enumerate(range(0, len(provenance), _ATTR_CHARS)):
                    name = PROVENANCE_ATTR + (f"_{k + 1}" if k else "")
                    setattr(attrs, name, provenance[start : start + _ATTR_CHARS])
    else:
        raise ValueError(f"a DeepLabCut file ends in .h5 or .csv, not {p.name!r}")


def _is_lightningpose(head: str) -> bool:
    first = head.split("\n", 1)[0].lower()
    return "heatmap" in first or "lightning" in first


def sniff_deeplabcut(path: Path, head: str) -> int:
    """Score: a CSV starting ``scorer,`` then ``bodyparts,`` / ``individuals,`` rows, or
    an HDF5 file holding a pandas table (the key ``df_with_missing``)."""
    if head.startswith("scorer,"):
        second = head.split("\n", 2)[1].lower() if "\n" in head else ""
        if second.startswith(("bodyparts,", "individuals,")):
            return 40 if _is_lightningpose(head) else 85
        return 0
    if head.startswith("\ufffdHDF\r\n\x1a\n") or is_hdf5(path):
        try:
            import h5py
        except ImportError:
            # the reader says what to install; SLEAP's analysis files are its (by name)
            name = path.name.lower()
            return 5 if name.endswith(".h5") and not name.endswith(".analysis.h5") else 0
        try:
            with h5py.File(path, "r") as f:
                if DLC_KEY in f:
                    return 85
                if "tracks" in f or "position" in f:
                    return 0
                # another key of a pandas table (PyTables marks its groups)
                return 30 if any("pandas_type" in f[k].attrs for k in f) else 0
        except (OSError, ValueError, KeyError):
            return 0
    return 0


register_format(
    "deeplabcut", read_deeplabcut, write_deeplabcut, (".h5",), sniff_deeplabcut,
    description="DeepLabCut pose table (.h5 / .csv; x, y, likelihood per bodypart)",
    aliases=("dlc",),
)  # fmt: skip
