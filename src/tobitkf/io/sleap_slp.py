"""SLEAP project and prediction files (``.slp``), read through the optional sleap-io.

``sleap_io.load_slp`` gives the labels; every video's predictions become one sequence
per track (``body_id`` = the track's name; untracked single-instance predictions: one
sequence), from ``Labels.numpy(video=..., return_confidence=True)`` (frame k = video
frame k), positions in pixels, ``confidence`` = point score (clipped into [0, 1]),
bones from the skeleton's edges, left/right pairs from its symmetries.
Install with ``pip install 'tobitkf[slp]'`` (or ``pip install sleap-io``).
"""

from __future__ import annotations

import os
from pathlib import Path

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

__all__ = ["read_slp", "sniff_slp"]


def read_slp(
    path: str | os.PathLike[str], fps: float | None = None, implausible: str = "error"
) -> list[SkeletonSequence]:
    """Read a SLEAP ``.slp`` file (module docstring)."""
    p = Path(path)
    sio = require("sleap_io", "reading SLEAP .slp files")
    check_hdf5_opens(p, "reading SLEAP .slp files")  # h5py: a dependency of sleap-io
    try:
        labels = sio.load_slp(str(p))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ReadError(p, None, f"not a readable SLEAP file ({hdf5_reason(exc)})") from None
    if not labels.skeletons:
        raise ReadError(p, None, "the file has no skeleton")
    skel = labels.skeletons[0]
    nodes = [n.name for n in skel.nodes]
    edges = [(e.source.name, e.destination.name) for e in skel.edges]
    symmetry = [tuple(n.name for n in s.nodes) for s in skel.symmetries]
    out: list[SkeletonSequence] = []
    for v, video in enumerate(labels.videos):
        arr = labels.numpy(video=video, return_confidence=True)  # (T, tracks, nodes, 3)
        if arr.size == 0:
            continue
        names = [t.name for t in labels.tracks] if labels.tracks else None
        if names is not None and len(names) != arr.shape[1]:
            names = [f"track_{k}" for k in range(arr.shape[1])]
        if names is None and arr.shape[1] > 1:
            names = [f"instance_{k}" for k in range(arr.shape[1])]
        out += sequences_from_arrays(
            p, arr[..., :2], arr[..., 2], nodes, names, fmt="slp", fps=fps, edges=edges,
            symmetry=symmetry, metadata={"video": str(getattr(video, "filename", v))},
            implausible=implausible,
        )  # fmt: skip
    if not out:
        raise ReadError(p, None, "the file has no predicted or labelled instances")
    return out


def sniff_slp(path: Path, head: str) -> int:
    """Score: an HDF5 file holding SLEAP's labels (``videos_json``, or ``metadata`` and
    ``frames``), whatever its name; without h5py, an HDF5 file named ``.slp``."""
    return sniff_hdf5(
        path, 95, lambda f: "videos_json" in f or ("metadata" in f and "frames" in f),
        without_h5py=90 if path.suffix.lower() == ".slp" else 0,
    )  # fmt: skip


register_format(
    "slp", read_slp, None, (".slp",), sniff_slp,
    description="SLEAP .slp labels / predictions (optional sleap-io)", aliases=("sleap",),
)  # fmt: skip
