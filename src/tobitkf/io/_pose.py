"""What the pose-estimator formats share: optional imports, arrays to sequences, and
sequences to the (frames, individuals, keypoints) arrays their writers need."""

from __future__ import annotations

import importlib
import os
import re
from collections.abc import Sequence
from typing import Any

import numpy as np

from tobitkf.io._text import check_positions, option_rate
from tobitkf.io.errors import ReadError
from tobitkf.skeleton.sequence import SampleState, SkeletonSequence
from tobitkf.skeleton.topology import Topology

__all__ = [
    "HDF5_MAGIC",
    "PoseArrays",
    "check_alike",
    "check_hdf5_opens",
    "check_hdf5_reads",
    "check_one_video",
    "frame_numbers",
    "hdf5_open_error",
    "hdf5_reason",
    "individual_names",
    "is_hdf5",
    "pose_arrays",
    "require",
    "sequences_from_arrays",
    "sniff_hdf5",
    "written_confidence",
]

HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"

#: module -> the pip extra that installs it
_EXTRAS = {
    "h5py": "pose",
    "pandas": "pose",
    "tables": "pose",
    "xarray": "pose",
    "h5netcdf": "pose",
    "sleap_io": "slp",
    "movement": "movement",
}
_PIP = {"sleap_io": "sleap-io", "tables": "tables"}


def require(module: str, what: str) -> Any:
    """Import an optional dependency, or an ImportError saying how to install it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        extra = _EXTRAS.get(module, "pose")
        raise ImportError(
            f"{what} needs the '{_PIP.get(module, module)}' package: "
            f"pip install 'tobitkf[{extra}]' (or pip install {_PIP.get(module, module)})"
        ) from None


def is_hdf5(path: str | os.PathLike[str]) -> bool:
    """True when the file starts with the HDF5 signature."""
    try:
        with open(path, "rb") as fh:
            return fh.read(8) == HDF5_MAGIC
    except OSError:
        return False


def sniff_hdf5(path: Any, score: int, holds: Any, without_h5py: int = 0) -> int:
    """A sniffer's score for an HDF5 file: ``score`` when ``holds(f)`` is true of the
    file opened with h5py, ``without_h5py`` when h5py is not installed (a guess from the
    name, which the reader then refuses saying what to install), else 0."""
    if not is_hdf5(path):
        return 0
    try:
        import h5py
    except ImportError:
        return without_h5py
    try:
        with h5py.File(path, "r") as f:
            return score if holds(f) else 0
    except (OSError, ValueError):
        return 0


_TRACE_END = "End of HDF5 error back trace"
_H5PY_OPEN = re.compile(r"Unable to (?:synchronously )?open file \((.*)\)", re.S)


def hdf5_reason(exc: BaseException) -> str:
    """One line for an h5py or PyTables error: the innermost message of PyTables'
    multi-line HDF5 back trace (the line above its end marker); h5py's "Unable to open
    file (...)" reduced to what is in the parentheses."""
    text = str(exc)
    if _TRACE_END in text:
        lines = [ln.strip() for ln in text.split(_TRACE_END, 1)[0].splitlines() if ln.strip()]
        text = lines[-1] if lines else "HDF5 error"
    text = " ".join(text.split())
    match = _H5PY_OPEN.fullmatch(text)
    return match.group(1) if match else text


def hdf5_open_error(path: Any, exc: BaseException) -> ReadError:
    """The ReadError for a file the HDF5 library cannot open."""
    return ReadError(path, None, f"truncated or corrupt HDF5 file ({hdf5_reason(exc)})")


def check_hdf5_opens(path: Any, what: str) -> None:
    """Raise :func:`hdf5_open_error` when h5py cannot open ``path`` (``what``: for the
    message naming the package to install)."""
    h5py = require("h5py", what)
    try:
        with h5py.File(path, "r"):
            pass
    except (OSError, ValueError) as exc:
        raise hdf5_open_error(path, exc) from None


def check_hdf5_reads(path: Any, what: str) -> None:
    """Raise :func:`hdf5_open_error` unless h5py can open ``path`` and read every object
    in it. Before PyTables: where a damaged object header makes h5py raise, PyTables
    (``pandas.read_hdf``) crashes the interpreter (a segmentation fault inside HDF5)."""
    h5py = require("h5py", what)

    def read(_name: str, obj: Any) -> None:
        if isinstance(obj, h5py.Dataset):
            obj[()]

    try:
        with h5py.File(path, "r") as f:
            f.visititems(read)
    except (OSError, ValueError, RuntimeError, KeyError, TypeError) as exc:
        raise hdf5_open_error(path, exc) from None


def sequences_from_arrays(
    path: Any,
    positions: np.ndarray,
    confidence: np.ndarray | None,
    keypoints: Sequence[str],
    individuals: Sequence[Any] | None,
    *,
    fmt: str,
    units: str | None = "px",
    fps: Any = None,
    timestamps: np.ndarray | None = None,
    edges: Sequence[tuple[Any, Any]] | None = None,
    symmetry: Sequence[tuple[str, str]] | None = None,
    metadata: dict[str, Any] | None = None,
    implausible: str = "error",
) -> list[SkeletonSequence]:
    """One sequence per individual from ``positions (T, I, J, D)`` and ``confidence
    (T, I, J)`` (scores outside [0, 1] are clipped into it: SLEAP's peak values can
    exceed 1). ``individuals`` None: a single unnamed individual (``I = 1``)."""
    pos = np.asarray(positions, dtype=float)
    if pos.ndim != 4 or pos.shape[-1] not in (2, 3) or pos.shape[2] != len(keypoints):
        raise ReadError(
            path,
            None,
            f"expected positions (frames, individuals, {len(keypoints)} keypoints, 2 or 3), "
            f"found shape {pos.shape}",
        )
    if implausible != "missing" and np.isinf(pos).any():
        raise ReadError(path, None, "positions hold inf; expected numbers or NaN")
    names = [str(k) for k in keypoints]
    if len(set(names)) != len(names):
        raise ReadError(path, None, f"duplicate keypoint names {names}")
    conf = None
    clipped = False
    if confidence is not None:
        conf = np.asarray(confidence, dtype=float)
        if conf.shape != pos.shape[:3]:
            raise ReadError(
                path, None, f"confidence of shape {conf.shape}; expected {pos.shape[:3]}"
            )
        if np.isinf(conf).any():
            raise ReadError(path, None, "confidence holds inf; expected numbers or NaN")
        with np.errstate(invalid="ignore"):
            clipped = bool(np.any((conf < 0) | (conf > 1)))
        conf = np.clip(conf, 0.0, 1.0)
    try:
        if edges:
            topo = Topology.from_names(names, name=fmt, edges=edges)
        else:
            topo = Topology.from_names(names, name=fmt)
        if symmetry:
            index = {n: i for i, n in enumerate(names)}
            pairs = [(index[a], index[b]) for a, b in symmetry if a in index and b in index]
            topo = Topology(topo.name, topo.joints, topo.parents, tuple(pairs), topo.up_axis)
    except ValueError as exc:
        raise ReadError(path, None, f"bad skeleton: {exc}") from None
    rate = option_rate(path, fps)
    inds = [None] if individuals is None else list(individuals)
    if len(inds) != pos.shape[1]:
        raise ReadError(path, None, f"{pos.shape[1]} individuals but {len(inds)} names")
    out = []
    for i, ind in enumerate(inds):
        p = np.ascontiguousarray(pos[:, i])
        c = None if conf is None else np.ascontiguousarray(conf[:, i])
        if c is not None and np.isnan(c).all():
            c = None
        check_positions(path, p, None, implausible, names=names, units=units)
        meta = {"source": str(path), "format": fmt, **(metadata or {})}
        if clipped:
            meta["confidence_clipped"] = True
        out.append(
            SkeletonSequence(
                p,
                topo,
                confidence=c,
                units=units,
                fps=rate,
                timestamps=timestamps,
                body_id=None if ind is None else _name(ind),
                metadata=meta,
            )
        )
    return out


def _name(ind: Any) -> Any:
    if isinstance(ind, bytes):
        return ind.decode("utf-8", errors="replace")
    if isinstance(ind, np.generic):
        return ind.item()
    return ind


def written_confidence(seq: SkeletonSequence) -> np.ndarray | None:
    """The score a pose file gets for each sample (T, J): the sequence's confidence, and
    0 where a smoother filled the sample (rejected, missing or extrapolated: no detection
    lies at the written position, and a reader that keeps samples above a score cut-off
    must not take the fill for a sure detection); NaN where there is no score; None when
    the sequence has neither scores nor filled samples."""
    conf = seq.confidence
    if seq.sample_state is None:
        return conf
    filled = SampleState.filled(seq.sample_state)
    if not filled.any():
        return conf
    out = np.full(filled.shape, np.nan) if conf is None else conf.copy()
    out[filled] = 0.0
    return out


def frame_numbers(seq: SkeletonSequence) -> np.ndarray | None:
    """The frame numbers a pose file gave its rows (``metadata["frames"]``, kept by the
    DeepLabCut and movement readers when they are not 0, 1, ...), or None."""
    frames = seq.metadata.get("frames")
    if isinstance(frames, np.ndarray) and frames.shape == (seq.n_frames,):
        if np.issubdtype(frames.dtype, np.integer):
            return frames
    return None


def check_one_video(seqs: Sequence[SkeletonSequence]) -> None:
    """ValueError when the sequences come from several videos (a SLEAP project's: one
    sequence per video and track), which one pose file cannot hold."""
    videos = list(dict.fromkeys(str(s.metadata["video"]) for s in seqs if "video" in s.metadata))
    if len(videos) > 1:
        raise ValueError(
            f"the sequences come from {len(videos)} videos ({', '.join(videos[:3])}"
            f"{', ...' if len(videos) > 3 else ''}), and a pose file holds one: write each "
            "video's sequences to its own file (select them by metadata['video']), or "
            "write csv or npz"
        )


def check_alike(seqs: list[SkeletonSequence]) -> None:
    """ValueError unless the individuals of one pose file share dimension and frame count."""
    first = seqs[0]
    check_one_video(seqs)
    for s in seqs[1:]:
        if (s.n_dims, s.n_frames) != (first.n_dims, first.n_frames):
            raise ValueError(
                "all individuals written to one pose file must share dimension and frame "
                f"count; found {first.n_dims}-D x {first.n_frames} frames and "
                f"{s.n_dims}-D x {s.n_frames} frames"
            )


def _keypoint_sets(seqs: list[SkeletonSequence]) -> str:
    """The distinct keypoint lists of ``seqs`` by body, for an error message."""
    seen: dict[tuple[str, ...], list[str]] = {}
    for k, s in enumerate(seqs):
        seen.setdefault(s.joint_names, []).append(str(k if s.body_id is None else s.body_id))
    return "; ".join(f"{', '.join(b)}: {', '.join(j)}" for j, b in seen.items())


class PoseArrays:
    """Sequences laid out for a pose writer: ``positions (T, I, J, D)``, ``confidence
    (T, I, J)`` (:func:`written_confidence`; NaN where none), ``keypoints``,
    ``individuals`` (names), ``fps``."""

    def __init__(self, seqs: list[SkeletonSequence]) -> None:
        first = seqs[0]
        if any(s.joint_names != first.joint_names for s in seqs):
            raise ValueError(
                "the individuals of this file have different keypoints, which this format "
                f"cannot hold in one array ({_keypoint_sets(seqs)}); write it as deeplabcut, "
                "csv or npz"
            )
        check_alike(seqs)
        self.positions = np.stack([s.positions for s in seqs], axis=1)
        scores = [written_confidence(s) for s in seqs]
        self.confidence = np.stack(
            [
                np.full(s.positions.shape[:2], np.nan) if c is None else c
                for s, c in zip(seqs, scores, strict=True)
            ],
            axis=1,
        )
        self.keypoints = list(first.joint_names)
        self.individuals = individual_names(seqs)
        self.fps = first.fps
        self.n_dims = first.n_dims
        self.topology = first.topology


def individual_names(seqs: list[SkeletonSequence]) -> list[str]:
    """Distinct text names: the body ids when they are distinct, else ``individual_<k>``."""
    ids = [s.body_id for s in seqs]
    names = [str(b) for b in ids]
    if any(b is None for b in ids) or len(set(names)) != len(names):
        names = [f"individual_{k}" if b is None else f"{b}_{k}" for k, b in enumerate(ids)]
        if len(seqs) == 1:
            names = [str(ids[0]) if ids[0] is not None else "individual_0"]
    return names


def pose_arrays(sequences: Sequence[SkeletonSequence]) -> PoseArrays:
    """The writer's arrays of ``sequences`` (ValueError when they do not fit one file)."""
    seqs = list(sequences)
    if not seqs:
        raise ValueError("nothing to write: no sequences")
    return PoseArrays(seqs)
