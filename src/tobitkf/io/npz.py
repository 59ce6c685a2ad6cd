"""Lossless NumPy ``.npz`` archive of skeleton sequences (several bodies per file).

Layout (all entries plain arrays; read with ``allow_pickle=False``):

* ``format_version`` = 1, ``n_bodies`` = B;
* per body ``b``: ``b{b}/positions`` (T, J, D), optional ``b{b}/tracking_state`` (T, J),
  optional ``b{b}/confidence`` (T, J) float,
  optional ``b{b}/timestamps`` (T,), optional ``b{b}/std`` (T, J) float and
  ``b{b}/sample_state`` (T, J) int8 (smoothed output), ``b{b}/topology_joints`` (J,) str,
  ``b{b}/topology_parents`` (J,), ``b{b}/topology_symmetry`` (S, 2), and
  ``b{b}/header`` = a JSON string with fps, body_id, units, topology name, up axis and the
  metadata; arrays inside the metadata (at any depth of dicts and lists) are stored as
  separate entries ``b{b}/meta/<n>`` and referenced from the JSON. A smoothed sequence's
  provenance (tobitkf version, method, complete parameters, source) is
  ``metadata["provenance"]``, so it sits in the header.

The reader trusts nothing in the archive: the members may hold at most
``_text.MAX_INPUT_BYTES`` together, each array's declared shape and dtype must match the
bytes its member holds before anything is allocated, object arrays are refused, and every
failure (corrupt deflate data, deep JSON, bad shapes) is a :class:`ReadError`.
"""

from __future__ import annotations

import json
import lzma
import math
import os
import struct
import tokenize
import zipfile
import zlib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tobitkf.io._text import MAX_INPUT_BYTES, check_positions, check_rate, size_text
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format
from tobitkf.io.unstated import UNITS_UNSTATED
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology

__all__ = ["read_npz", "sniff_npz", "write_npz"]

FORMAT_VERSION = 1
#: what a corrupt or hostile zip member can raise while it is opened, decompressed or parsed
_ARCHIVE_ERRORS = (
    ValueError,
    OSError,
    EOFError,
    zipfile.BadZipFile,
    zlib.error,
    lzma.LZMAError,
    NotImplementedError,  # unsupported compression method
    RuntimeError,  # encrypted member; RecursionError
    struct.error,
    OverflowError,
    TypeError,  # an unusable dtype
    SyntaxError,
    tokenize.TokenError,  # NumPy's parser of a malformed .npy header
)
_HEADER_READERS = {
    (1, 0): np.lib.format.read_array_header_1_0,
    (2, 0): np.lib.format.read_array_header_2_0,
}


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
    """Write sequences to a compressed ``.npz`` archive (see module docstring).

    Raises ValueError for a joint name ending in a NUL character (NumPy string arrays
    drop trailing NULs, so it would not read back the same).
    """
    seqs = list(sequences)
    for s in seqs:
        bad = [j for j in s.topology.joints if j.endswith("\x00")]
        if bad:
            raise ValueError(
                f"cannot write the joint name {bad[0]!r} to NPZ: NumPy string arrays drop "
                "trailing NUL characters"
            )
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
        if s.std is not None:
            arrays[f"{p}/std"] = s.std
        if s.confidence is not None:
            arrays[f"{p}/confidence"] = s.confidence
        if s.sample_state is not None:
            arrays[f"{p}/sample_state"] = s.sample_state
        topo = s.topology
        arrays[f"{p}/topology_joints"] = np.array(topo.joints, dtype=str)
        arrays[f"{p}/topology_parents"] = np.array(topo.parents, dtype=np.int64)
        arrays[f"{p}/topology_symmetry"] = np.array(topo.symmetry, dtype=np.int64).reshape(-1, 2)
        meta_arrays: dict[str, np.ndarray] = {}
        header = {
            "fps": s.fps,
            "body_id": _encode(s.body_id, meta_arrays, p),
            "units": s.units,
            "topology_name": topo.name,
            "up_axis": topo.up_axis,
            # the file states the units: whether the reader of the source had to assume
            # them does not go with it
            "metadata": _encode(
                {k: v for k, v in s.metadata.items() if k != UNITS_UNSTATED}, meta_arrays, p
            ),
        }
        for key, arr in meta_arrays.items():
            if arr.dtype == object:
                raise ValueError(f"metadata array {key} has dtype object; cannot store it in NPZ")
        arrays.update(meta_arrays)
        arrays[f"{p}/header"] = np.array(json.dumps(header))
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **arrays)


def _read_member(path, zf: zipfile.ZipFile, info: zipfile.ZipInfo) -> np.ndarray:
    """One ``.npy`` member, its declared size checked against the member's size first."""
    name = info.filename
    with zf.open(info) as fh:
        version = np.lib.format.read_magic(fh)
        if version not in _HEADER_READERS:
            raise ReadError(path, None, f"member {name}: unsupported .npy version {version}")
        shape, fortran, dtype = _HEADER_READERS[version](fh)
        if dtype.hasobject:
            raise ReadError(path, None, f"member {name}: object arrays are not read")
        nbytes = math.prod(shape) * dtype.itemsize
        held = info.file_size - fh.tell()
        if nbytes != held:
            raise ReadError(
                path,
                None,
                f"member {name} declares shape {shape} of {dtype} ({size_text(nbytes)}) "
                f"but holds {size_text(max(held, 0))}",
            )
        raw = fh.read(nbytes)
    if len(raw) != nbytes:
        raise ReadError(path, None, f"member {name} is truncated")
    if nbytes == 0:
        return np.zeros(shape, dtype=dtype)
    return np.frombuffer(raw, dtype=dtype).reshape(shape, order="F" if fortran else "C").copy()


def _read_arrays(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """The arrays of an ``.npz`` archive by name, within :data:`MAX_INPUT_BYTES`."""
    try:
        with zipfile.ZipFile(path) as zf:
            infos = [i for i in zf.infolist() if i.filename.endswith(".npy")]
            total = sum(i.file_size for i in infos)
            if total > MAX_INPUT_BYTES:
                raise ReadError(
                    path,
                    None,
                    f"the archive's arrays hold {size_text(total)}, more than the limit of "
                    f"{size_text(MAX_INPUT_BYTES)} (tobitkf.io._text.MAX_INPUT_BYTES)",
                )
            return {i.filename[:-4]: _read_member(path, zf, i) for i in infos}
    except ReadError:
        raise
    except FileNotFoundError:
        raise
    except _ARCHIVE_ERRORS as exc:
        raise ReadError(
            path, None, f"expected a NumPy .npz archive ({type(exc).__name__}: {exc})"
        ) from None


def read_npz(path: str | os.PathLike[str], implausible: str = "error") -> list[SkeletonSequence]:
    """Read an archive written by :func:`write_npz`.

    ``implausible`` (``"error"`` or ``"missing"``): what to do with a position beyond the
    plausibility bound (``_text.check_positions``).
    """
    data = _read_arrays(path)
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
            positions = np.array(data[f"{p}/positions"], dtype=float)
            if positions.ndim != 3 or positions.shape[1:] not in (
                (len(topo.joints), 3),
                (len(topo.joints), 2),
            ):
                raise ValueError(
                    f"positions of shape {positions.shape} for {len(topo.joints)} joints"
                )
            state = data.get(f"{p}/tracking_state")
            if state is not None:
                state = np.array(state)
            # archives written before units existed are 3-D metres
            units = header.get("units", "m" if positions.shape[2] == 3 else None)
            check_positions(
                path, positions, None, implausible, names=topo.joints, state=state, units=units
            )
            fps = header["fps"]
            if fps is not None:
                fps = check_rate(path, None, float(fps), "fps", repr(fps))
            out.append(
                SkeletonSequence(
                    positions=positions,
                    topology=topo,
                    tracking_state=state,
                    timestamps=data.get(f"{p}/timestamps"),
                    fps=fps,
                    body_id=_decode(header["body_id"], data),
                    metadata=_decode(header["metadata"], data),
                    std=data.get(f"{p}/std"),
                    sample_state=data.get(f"{p}/sample_state"),
                    confidence=data.get(f"{p}/confidence"),
                    units=units,
                )
            )
    except ReadError:
        raise
    except (KeyError, ValueError, TypeError, IndexError, RecursionError) as exc:
        raise ReadError(path, None, f"inconsistent tobitkf .npz archive ({exc})") from None
    return out


def sniff_npz(path: Path, head: str) -> int:
    """Score: a zip archive with a ``.npz`` name."""
    return 80 if head.startswith("PK") and path.name.lower().endswith(".npz") else 0


register_format(
    "npz", read_npz, write_npz, (".npz",), sniff_npz,
    description="lossless NumPy archive",
)  # fmt: skip
