"""A plain NumPy ``.npy`` array of keypoints: what 3-D lifters and many pose pipelines save.

Layout: ``(T, J, D)`` (one body) or ``(T, B, J, D)`` (B bodies), D = 2 (image keypoints)
or 3 (points), any real dtype, NaN where a keypoint is missing. An array does not say
which joint is which, how fast it was sampled nor in which units, so:

* ``topology=`` names the skeleton (``"h36m17"`` for VideoPose3D / MotionBERT output,
  ``"coco17"`` for COCO keypoints, any name of :func:`~tobitkf.available_topologies`, or a
  :class:`~tobitkf.Topology`); without it the joints are ``0``, ``1``, ... without bones
  (the robust methods then gate by speed only), and ``metadata["reader_warnings"]`` says
  so;
* ``fps=`` the frame rate (otherwise none: ``tobitkf smooth --fps`` or ``smooth(fps=)``);
* ``units=`` the length unit (``"m"``, ``"cm"``, ``"mm"``, ``"px"``); otherwise unknown,
  so the robust gates are measured on the recording itself, as for pixels (smoothing a
  3-D body of a person's size in metres, centimetres or millimetres warns and names
  that unit).

The same three may sit in a JSON file beside the array (``poses.json`` for
``poses.npy``: ``{"topology": "h36m17", "fps": 50, "units": "m"}``), which is how
``tobitkf smooth`` learns them; arguments given to the reader win. A score column
(``(T, J, 3)`` holding x, y and a confidence) is not guessed: it is read as 3-D; split it
and pass the scores as ``confidence=`` to :func:`tobitkf.smooth`.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from tobitkf.io._text import MAX_INPUT_BYTES, check_positions, option_rate, size_text
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format
from tobitkf.io.unstated import UNITS_UNSTATED
from tobitkf.skeleton.sequence import KNOWN_UNITS, SkeletonSequence
from tobitkf.skeleton.topology import UNNAMED, Topology, available_topologies, get_topology

__all__ = ["read_npy", "sidecar_path", "sniff_npy"]

#: NumPy's magic as the sniffers see it (the first byte, 0x93, is not UTF-8 on its own)
NPY_MAGIC = ("\x93NUMPY", "\ufffdNUMPY")
#: the keys a sidecar may hold
SIDECAR_KEYS = ("topology", "fps", "units")


def sidecar_path(path: str | os.PathLike[str]) -> Path:
    """The JSON file that describes the array at ``path`` (``poses.npy`` -> ``poses.json``)."""
    p = Path(path)
    return p.with_suffix(".json")


def _parse(side: Path) -> Any:
    """The JSON document of ``side`` (at most 1 MiB: a description is small)."""
    if side.stat().st_size > 2**20:
        raise ValueError("larger than 1 MiB")
    return json.loads(side.read_text(encoding="utf-8"))


def _is_description(data: Any) -> bool:
    """A sidecar is an object naming at least one of :data:`SIDECAR_KEYS`; any other JSON
    file of the same name (an MMPose prediction file of the same clip, say) is not one."""
    return isinstance(data, dict) and any(k in data for k in SIDECAR_KEYS)


def _sidecar(path: Path) -> dict[str, Any]:
    side = sidecar_path(path)
    if not side.is_file():
        return {}
    try:
        data = _parse(side)
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise ReadError(side, None, f"unreadable sidecar of {path.name} ({exc})") from None
    if not _is_description(data):
        return {}  # another file of the same name, not a description of the array
    fps = data.get("fps")
    if fps is not None and (isinstance(fps, bool) or not isinstance(fps, (int, float))):
        raise ReadError(side, None, f"fps must be a number of frames per second, found {fps!r}")
    unknown = sorted(set(data) - set(SIDECAR_KEYS))
    if unknown:
        raise ReadError(
            side, None, f"unknown keys {unknown} in the sidecar of {path.name}; expected "
            f"some of {list(SIDECAR_KEYS)}"
        )  # fmt: skip
    return data


def _topology(path: Path, topology: Any, n_joints: int) -> Topology:
    if topology is None:
        return Topology.from_names([str(j) for j in range(n_joints)], name=UNNAMED)
    if isinstance(topology, Topology):
        topo = topology
    else:
        try:
            topo = get_topology(str(topology))
        except KeyError:
            raise ReadError(
                path, None, f"unknown topology {topology!r}; expected one of "
                f"{available_topologies()}"
            ) from None  # fmt: skip
    if topo.n_joints != n_joints:
        raise ReadError(
            path, None, f"the array has {n_joints} joints, topology {topo.name!r} "
            f"{topo.n_joints}"
        )  # fmt: skip
    return topo


def read_npy(
    path: str | os.PathLike[str],
    *,
    topology: Topology | str | None = None,
    fps: float | None = None,
    units: str | None = None,
    implausible: str = "error",
) -> list[SkeletonSequence]:
    """Read a ``.npy`` array of keypoints (module docstring): one sequence per body.
    ``implausible`` (``"error"`` or ``"missing"``): what to do with a coordinate beyond
    the plausibility bound."""
    p = Path(path)
    try:
        size = p.stat().st_size
    except OSError as exc:
        raise ReadError(p, None, f"cannot read the file ({exc.strerror or exc})") from None
    if size > MAX_INPUT_BYTES:
        raise ReadError(
            p, None, f"the file ({size_text(size)}) is larger than the limit of "
            f"{size_text(MAX_INPUT_BYTES)}"
        )  # fmt: skip
    side = _sidecar(p)
    topology = side.get("topology") if topology is None else topology
    fps = side.get("fps") if fps is None else fps
    units = side.get("units") if units is None else units
    unstated = units is None  # unknown: --units may say what it is
    try:
        arr = np.load(p, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise ReadError(p, None, f"not a readable NumPy array ({exc})") from None
    if not isinstance(arr, np.ndarray):  # an .npz archive under an .npy name
        raise ReadError(p, None, "a NumPy archive (.npz), not one array: name it .npz")
    if arr.dtype.kind not in "fiu":
        raise ReadError(p, None, f"expected real numbers, found dtype {arr.dtype}")
    if arr.ndim not in (3, 4) or arr.shape[-1] not in (2, 3) or 0 in arr.shape[:-1]:
        raise ReadError(
            p, None, f"expected an array (T, J, D) or (T, B, J, D) with D = 2 or 3 and no "
            f"empty axis, found shape {arr.shape}"
        )  # fmt: skip
    arr = np.asarray(arr, dtype=float)
    if np.isinf(arr).any():
        raise ReadError(p, None, "infinite values (use NaN for a missing keypoint)")
    if units is not None and (not isinstance(units, str) or units not in KNOWN_UNITS):
        raise ReadError(p, None, f"units must be one of {sorted(KNOWN_UNITS)}, got {units!r}")
    fps = option_rate(p, fps)
    bodies = arr[:, None] if arr.ndim == 3 else arr
    topo = _topology(p, topology, bodies.shape[2])
    notes = []
    if topo.name == UNNAMED:
        notes.append(
            "the array names no skeleton: joints 0..J-1 without bones (the robust methods "
            f"gate by speed only); give topology= (tobitkf smooth --topology) or write "
            f'{sidecar_path(p).name} with {{"topology": ...}}'
        )
    sequences = []
    for b in range(bodies.shape[1]):
        pos = np.ascontiguousarray(bodies[:, b])
        check_positions(p, pos, None, implausible, names=topo.joints, units=units)
        sequences.append(
            SkeletonSequence(
                positions=pos,
                topology=topo,
                fps=fps,
                body_id=b if bodies.shape[1] > 1 else None,
                units=units,
                metadata={
                    **({"reader_warnings": list(notes)} if notes else {}),
                    **({UNITS_UNSTATED: True} if unstated else {}),
                },
            )
        )
    return sequences


def sniff_npy(path: Path, head: str) -> int:
    """Score: NumPy's ``.npy`` magic."""
    return 90 if head.startswith(NPY_MAGIC) and path.suffix.lower() != ".npz" else 0


def _is_sidecar(path: Path) -> bool:
    """True for ``poses.json`` beside ``poses.npy`` when it describes the array (read with
    it, not alone); a JSON file of the same name that is no description is a recording."""
    if path.suffix.lower() != ".json" or not path.with_suffix(".npy").is_file():
        return False
    try:
        return _is_description(_parse(path))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        return True  # a broken description: reading the array reports it


register_format(
    "npy", read_npy, None, (".npy",), sniff_npy,
    description="NumPy .npy keypoint array (T, J, D) or (T, B, J, D)",
    companion=_is_sidecar,
    read_with=lambda p: [sidecar_path(p)] if p.suffix.lower() == ".npy" else [],
)  # fmt: skip
