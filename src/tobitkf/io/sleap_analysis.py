"""SLEAP analysis HDF5 files (``*.analysis.h5``), read with h5py.

SLEAP's ``Export Analysis HDF5`` (and ``sleap-convert --format analysis``, sleap-io's
``save_analysis_h5``, movement's ``to_sleap_analysis_file``) write the datasets

* ``tracks`` — positions, stored column-major for MATLAB: ``(n_tracks, 2, n_nodes,
  n_frames)`` as h5py reads it; NaN where a node is missing;
* ``point_scores`` ``(n_tracks, n_nodes, n_frames)``, ``track_occupancy``
  ``(n_frames, n_tracks)``, ``instance_scores``, ``tracking_scores``;
* ``node_names``, ``track_names`` (bytes; empty for untracked single-instance
  predictions), ``edge_inds`` ``(n_edges, 2)`` (source, destination node) and
  ``edge_names``.

Files written by sleap-io carry a ``dims`` attribute on each array naming its axes
(``frame``, ``track``, ``node``, ``xy``); those orders are followed (its ``standard``
preset too). Files written by SLEAP with ``transpose=False`` (the attribute
``transpose`` false) are ``(n_frames, n_nodes, 2, n_tracks)``.

Read: one sequence per track (``body_id`` = the track's name), positions in pixels,
``confidence`` = point score (clipped into [0, 1]: a peak value can exceed 1; the
sequence's metadata says so), bones from ``edge_inds``, left/right pairs from sleap-io's
``skeleton_symmetries`` when present. Frame k of the arrays is frame k of the video;
``fps=`` gives the time base.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from tobitkf.io._pose import (
    check_hdf5_opens,
    hdf5_reason,
    require,
    sequences_from_arrays,
    sniff_hdf5,
)
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import SkeletonSequence

__all__ = ["read_sleap_analysis", "sniff_sleap_analysis"]

#: the stored axis order of each array without a ``dims`` attribute (SLEAP's MATLAB layout)
_MATLAB = {
    "tracks": ("track", "xy", "node", "frame"),
    "point_scores": ("track", "node", "frame"),
}
_UNTRANSPOSED = {
    "tracks": ("frame", "node", "xy", "track"),
    "point_scores": ("frame", "node", "track"),
}


def _order(f: Any, name: str) -> tuple[str, ...]:
    ds = f[name]
    if "dims" in ds.attrs:
        dims = ds.attrs["dims"]
        dims = dims.decode() if isinstance(dims, bytes) else str(dims)
        return tuple(json.loads(dims))
    return (_UNTRANSPOSED if f.attrs.get("transpose", True) is False else _MATLAB)[name]


def _canonical(path: Path, f: Any, name: str, want: tuple[str, ...]) -> np.ndarray:
    order = _order(f, name)
    data = np.asarray(f[name][()], dtype=float)
    if sorted(order) != sorted(want) or data.ndim != len(want):
        raise ReadError(path, None, f"dataset {name!r}: axes {order} for shape {data.shape}")
    return np.transpose(data, [order.index(d) for d in want])


def _strings(f: Any, name: str) -> list[str]:
    if name not in f:
        return []
    raw = f[name][()]
    if isinstance(raw, (bytes, str)):
        raw = [raw]
    return [r.decode("utf-8", errors="replace") if isinstance(r, bytes) else str(r)
            for r in np.asarray(raw).ravel()]  # fmt: skip


def read_sleap_analysis(
    path: str | os.PathLike[str], fps: float | None = None, implausible: str = "error"
) -> list[SkeletonSequence]:
    """Read a SLEAP analysis HDF5 file (module docstring)."""
    p = Path(path)
    h5py = require("h5py", "reading SLEAP analysis files")
    check_hdf5_opens(p, "reading SLEAP analysis files")
    try:
        with h5py.File(p, "r") as f:
            for key in ("tracks", "node_names"):
                if key not in f:
                    raise ReadError(p, None, f"expected a SLEAP analysis file with {key!r}")
            tracks = _canonical(p, f, "tracks", ("frame", "track", "node", "xy"))
            scores = None
            if "point_scores" in f:
                scores = _canonical(p, f, "point_scores", ("frame", "track", "node"))
            nodes = _strings(f, "node_names")
            names: list[Any] = _strings(f, "track_names")
            edges = []
            if "edge_inds" in f and f["edge_inds"].size:
                edges = [tuple(int(v) for v in e) for e in np.asarray(f["edge_inds"][()])]
            sym = f.attrs.get("skeleton_symmetries")
            symmetry = json.loads(sym) if isinstance(sym, (str, bytes)) else None
    except ReadError:
        raise
    except (OSError, ValueError, TypeError, KeyError) as exc:
        reason = hdf5_reason(exc)
        raise ReadError(p, None, f"not a readable SLEAP analysis file ({reason})") from None
    n_tracks = tracks.shape[1]
    if len(nodes) != tracks.shape[2]:
        raise ReadError(p, None, f"{len(nodes)} node names for {tracks.shape[2]} nodes")
    if not names:
        names = [None] if n_tracks == 1 else [f"track_{k}" for k in range(n_tracks)]
    if len(names) != n_tracks:
        raise ReadError(p, None, f"{len(names)} track names for {n_tracks} tracks")
    if scores is not None and scores.shape != tracks.shape[:3]:
        raise ReadError(p, None, f"point_scores of shape {scores.shape} for tracks {tracks.shape}")
    edge_names = [(nodes[a], nodes[b]) for a, b in edges if a < len(nodes) and b < len(nodes)]
    return sequences_from_arrays(
        p, tracks, scores, nodes, None if names == [None] else names, fmt="sleap_analysis",
        fps=fps, edges=edge_names, symmetry=symmetry, implausible=implausible,
    )  # fmt: skip


def sniff_sleap_analysis(path: Path, head: str) -> int:
    """Score: an HDF5 file with ``tracks`` and ``track_occupancy`` (or ``node_names``)."""
    return sniff_hdf5(
        path, 90, lambda f: "tracks" in f and ("track_occupancy" in f or "node_names" in f),
        without_h5py=4 if path.name.lower().endswith(".analysis.h5") else 0,
    )  # fmt: skip


register_format(
    "sleap_analysis", read_sleap_analysis, None, (".analysis.h5",), sniff_sleap_analysis,
    description="SLEAP analysis HDF5 (tracks, point scores, skeleton)", aliases=("sleap_h5",),
)  # fmt: skip
