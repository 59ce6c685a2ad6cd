"""Lossless NumPy ``.npz`` archive of skeleton sequences (several bodies per file).

Layout (all entries plain arrays; read with ``allow_pickle=False``):

* ``format_version`` = 1, ``n_bodies`` = B;
* per body ``b``: ``b{b}/positions`` (T, J, 3), optional ``b{b}/tracking_state`` (T, J),
  optional ``b{b}/timestamps`` (T,), ``b{b}/topology_joints`` (J,) str,
  ``b{b}/topology_parents`` (J,), ``b{b}/topology_symmetry`` (S, 2), and
  ``b{b}/header`` = a JSON string with fps, body_id, topology name, up axis and the
  metadata; arrays inside the metadata (at any depth of dicts and lists) are stored as
  separate entries ``b{b}/meta/<n>`` and referenced from the JSON.
"""

from __future__ import annotations

import json
import os
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology

__all__ = ["read_npz", "sniff_npz", "write_npz"]

FORMAT_VERSION = 1


def _encode(obj: Any, arrays: dict[str, np.ndarray], prefix: str) -> Any:
    if isinstance(obj, np.ndarray):
        key = f"{prefix}/meta/{len(arrays)}"
        arrays[key] = obj
        return {"__ndarray__": key}
    if isinstance(obj, dict):
        return {"__dict__": [[str(k), _encode(v, arrays, prefix)] for k, v in obj.items()]}
    if isinstance(obj, (list, tuple)):
        return {
            "__list__" if isinstance(obj, list) else "__tuple__": [
                _encode(v, arrays, prefix) for v in obj
            ]
        }
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return {"__float__": repr(obj)}
    if obj is None or isinstance(obj, (bool, int, float, str)):
        return obj
    return {"__repr__": repr(obj)}


def _decode(obj: Any, archive: Any) -> Any:
    if isinstance(obj, dict):
        if "__ndarray__" in obj:
            return archive[obj["__ndarray__"]]
        if "__dict__" in obj:
            return {k: _decode(v, archive) for k, v in obj["__dict__"]}
        if "__list__" in obj:
            return [_decode(v, archive) for v in obj["__list__"]]
        if "__tuple__" in obj:
            return tuple(_decode(v, archive) for v in obj["__tuple__"])
        if "__float__" in obj:
            return float(obj["__float__"])
        if "__repr__" in obj:
            return obj["__repr__"]
        return {k: _decode(v, archive) for k, v in obj.items()}
    return obj


def write_npz(sequences: Sequence[SkeletonSequence], path: str | os.PathLike[str]) -> None:
    """Write sequences to a compressed ``.npz`` archive (see module docstring)."""
    seqs = list(sequences)
    arrays: dict[str, np.ndarray] = {
        "format_version": np.array(FORMAT_VERSION),
        "n_bodies": np.array(len(seqs)),
    }
    for b, s in enumerate(seqs):
        p = f"b{b}"
        arrays[f"{p}/positions"] = s.positions
        if s.tracking_state is not None:
            arrays[f"{p}/tracking_state"] = s.tracking_state
        if s.timestamps is not None:
            arrays[f"{p}/timestamps"] = s.timestamps
        topo = s.topology
        arrays[f"{p}/topology_joints"] = np.array(topo.joints, dtype=str)
        arrays[f"{p}/topology_parents"] = np.array(topo.parents, dtype=np.int64)
        arrays[f"{p}/topology_symmetry"] = np.array(topo.symmetry, dtype=np.int64).reshape(-1, 2)
        meta_arrays: dict[str, np.ndarray] = {}
        header = {
            "fps": s.fps,
            "body_id": _encode(s.body_id, meta_arrays, p),
            "topology_name": topo.name,
            "up_axis": topo.up_axis,
            "metadata": _encode(s.metadata, meta_arrays, p),
        }
        for key, arr in meta_arrays.items():
            if arr.dtype == object:
                raise ValueError(f"metadata array {key} has dtype object; cannot store it in NPZ")
        arrays.update(meta_arrays)
        arrays[f"{p}/header"] = np.array(json.dumps(header))
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **arrays)


def read_npz(path: str | os.PathLike[str]) -> list[SkeletonSequence]:
    """Read an archive written by :func:`write_npz`."""
    try:
        archive = np.load(path, allow_pickle=False)
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as exc:
        raise ReadError(path, None, f"expected a NumPy .npz archive ({exc})") from None
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise ReadError(path, None, "expected a .npz archive, found a single .npy array")
    with archive:
        try:
            data = {k: archive[k] for k in archive.files}
        except (ValueError, OSError, zipfile.BadZipFile, EOFError, KeyError) as exc:
            raise ReadError(path, None, f"corrupt .npz archive ({exc})") from None
    if "n_bodies" not in data or "format_version" not in data:
        raise ReadError(path, None, "expected a tobitkf .npz archive (n_bodies, format_version)")
    out = []
    try:
        n = int(data["n_bodies"])
        for b in range(n):
            p = f"b{b}"
            header = json.loads(str(data[f"{p}/header"]))
            topo = Topology(
                name=header["topology_name"],
                joints=tuple(str(j) for j in data[f"{p}/topology_joints"]),
                parents=tuple(int(i) for i in data[f"{p}/topology_parents"]),
                symmetry=tuple(
                    (int(a), int(c)) for a, c in data[f"{p}/topology_symmetry"].reshape(-1, 2)
                ),
                up_axis=int(header["up_axis"]),
            )
            out.append(
                SkeletonSequence(
                    positions=data[f"{p}/positions"],
                    topology=topo,
                    tracking_state=data.get(f"{p}/tracking_state"),
                    timestamps=data.get(f"{p}/timestamps"),
                    fps=header["fps"],
                    body_id=_decode(header["body_id"], data),
                    metadata=_decode(header["metadata"], data),
                )
            )
    except (KeyError, ValueError, TypeError, json.JSONDecodeError) as exc:
        raise ReadError(path, None, f"inconsistent tobitkf .npz archive ({exc})") from None
    return out


def sniff_npz(path: Path, head: str) -> int:
    """Score: a zip archive with a ``.npz`` name."""
    return 80 if head.startswith("PK") and path.name.lower().endswith(".npz") else 0


register_format(
    "npz", read_npz, write_npz, (".npz",), sniff_npz,
    description="lossless NumPy archive",
)  # fmt: skip
