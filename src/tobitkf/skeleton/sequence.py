"""The skeleton sequence type: joint positions over time with tracking states.

Arrays are time-first: ``positions`` is ``(T, J, D)`` with ``D = 3`` (3-D) or ``D = 2``
(image keypoints), in ``units`` (``"m"``, ``"mm"``, ``"px"``, ... or None = unknown), with
NaN marking a missing sample; ``tracking_state`` is ``(T, J)`` (Kinect
:class:`TrackingState` codes), ``confidence`` ``(T, J)`` a pose estimator's score in
[0, 1] (NaN where missing) and ``timestamps`` ``(T,)`` seconds. A smoothed sequence also
carries ``std`` ``(T, J)`` (posterior standard deviation, in ``units``) and
``sample_state`` ``(T, J)`` (:class:`SampleState` codes: how each estimate came about).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np

from tobitkf.skeleton.topology import Topology, get_topology

__all__ = ["KNOWN_UNITS", "SampleState", "SkeletonSequence", "TrackingState"]

#: units a sequence may declare (None = unknown); lengths in metres per unit, None when the
#: unit is not a length in the world (pixels)
KNOWN_UNITS: dict[str, float | None] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "px": None}


class _Default:
    """Marker of an argument left out (``units``: metres for 3-D, unknown for 2-D)."""

    def __repr__(self) -> str:
        return "<default>"


_DEFAULT: Any = _Default()


class TrackingState(IntEnum):
    """Per-joint tracking state, as reported by the Kinect SDK (``TrackingState``)."""

    NOT_TRACKED = 0
    INFERRED = 1
    TRACKED = 2


class SampleState(IntEnum):
    """How a smoothed sample came about (``SkeletonSequence.sample_state``).

    A measurement is *used* when it was present (not NaN, not NOT_TRACKED) and the method
    did not reject it.
    """

    #: a measurement was used
    MEASURED = 0
    #: a measurement was judged impossible (rejected) and the position filled in; this
    #: wins over MISSING / EXTRAPOLATED, whichever way the fill was made
    REJECTED = 1
    #: no measurement; filled by interpolation between used measurements (offline)
    MISSING = 2
    #: no measurement; filled by prediction only: every fill of a causal method, and
    #: offline a fill before the first or after the last used measurement of the joint
    EXTRAPOLATED = 3
    #: no estimate: the position is NaN
    NONE = 4

    @classmethod
    def filled(cls, states: np.ndarray) -> np.ndarray:
        """Boolean mask of filled samples (REJECTED, MISSING or EXTRAPOLATED)."""
        s = np.asarray(states)
        return (s >= cls.REJECTED) & (s <= cls.EXTRAPOLATED)


#: ``metadata`` key of :meth:`SkeletonSequence.select_frames`: each frame's index in the
#: recording the frames were first selected from, int64 (T,)
SOURCE_FRAMES = "source_frames"

#: ``metadata`` key listing the names of the metadata entries indexed by joint along
#: their first axis (arrays or lists of length J, e.g. a BVH file's ``offsets`` (J, 3), a
#: C3D file's ``labels``): :meth:`SkeletonSequence.select_joints` cuts them, and
#: :meth:`SkeletonSequence.select_frames` leaves them whole even when T == J
PER_JOINT = "per_joint"


def _per_joint_keys(metadata: dict[str, Any]) -> frozenset[str]:
    keys = metadata.get(PER_JOINT)
    if isinstance(keys, (list, tuple)):
        return frozenset(k for k in keys if isinstance(k, str))
    return frozenset()


def _cut_frames(v: Any, T: int, idx: np.ndarray) -> Any:
    """``v`` at the frames ``idx`` if it is an array with first axis T (inside dicts too)."""
    if isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == T:
        return v[idx]
    if isinstance(v, dict):
        return {k: _cut_frames(x, T, idx) for k, x in v.items()}
    return v


def _cut_joints(v: Any, T: int, J: int, idx: np.ndarray) -> Any:
    """``v`` at the joints ``idx`` if it is an array of shape (T, J, ...) (inside dicts too)."""
    if isinstance(v, np.ndarray) and v.ndim >= 2 and v.shape[:2] == (T, J):
        return v[:, idx]
    if isinstance(v, dict):
        return {k: _cut_joints(x, T, J, idx) for k, x in v.items()}
    return v


@dataclass(frozen=True, eq=False)
class SkeletonSequence:
    """One body's joint tracks.

    Parameters
    ----------
    positions : ndarray, shape (T, J, D), D = 2 or 3
        Joint positions in ``units``; NaN where a joint is missing.
    topology : Topology or str
        Joint names and tree; a string is resolved with :func:`get_topology`.
        ``topology.n_joints`` must equal J.
    tracking_state : ndarray, shape (T, J), optional
        :class:`TrackingState` codes (stored as int8).
    timestamps : ndarray, shape (T,), optional
        Seconds, non-decreasing (strictly increasing is not required: duplicated stamps are
        kept as read, but a step backwards is an error).
    fps : float, optional
        Nominal frame rate, > 0.
    body_id : int, str or None
        Identifier of the body (the Kinect body ID, or the individual's name of a
        multi-animal / multi-person pose file).
    metadata : dict
        Source path, format and extra per-frame fields (e.g. ``orientations`` (T, J, 4));
        a smoothed sequence adds ``diagnostics`` and ``provenance`` (tobitkf version,
        method, complete parameters, source).
    std : ndarray, shape (T, J), optional
        Posterior standard deviation of each position in ``units``: the root-mean-square
        over the axes of the per-axis posterior standard deviations, NaN where there is
        no estimate. Set by :func:`tobitkf.smooth` for methods that give one.
    sample_state : ndarray, shape (T, J), optional
        :class:`SampleState` codes (stored as int8); set by :func:`tobitkf.smooth`.
    confidence : ndarray, shape (T, J), optional
        A pose estimator's per-sample score in [0, 1] (DeepLabCut likelihood, SLEAP point
        score, OpenPose / MediaPipe confidence); NaN where there is none for a sample;
        None when the source gives none.
    units : str or None
        Unit of ``positions``: ``"m"``, ``"cm"``, ``"mm"``, ``"px"`` (image pixels) or None
        (unknown). Left out: ``"m"`` for 3-D positions (the convention of every 3-D
        reader), None for 2-D ones. Metric gates of the smoothers apply to length units;
        for ``"px"`` and None they are taken from the recording itself (docs/robust.md).
    """

    positions: np.ndarray
    topology: Topology
    tracking_state: np.ndarray | None = None
    timestamps: np.ndarray | None = None
    fps: float | None = None
    body_id: int | str | None = None
    metadata: dict[str, Any] = field(default_factory=dict)
    std: np.ndarray | None = None
    sample_state: np.ndarray | None = None
    confidence: np.ndarray | None = None
    units: str | None = _DEFAULT

    def __post_init__(self) -> None:
        topo = self.topology
        if isinstance(topo, str):
            topo = get_topology(topo)
            object.__setattr__(self, "topology", topo)
        if not isinstance(topo, Topology):
            raise TypeError(f"topology must be a Topology or a name, found {type(topo).__name__}")
        try:
            pos = np.asarray(self.positions, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"positions must be numeric, found {exc}") from None
        if pos.ndim != 3 or pos.shape[2] not in (2, 3):
            raise ValueError(f"positions must have shape (T, J, 3) or (T, J, 2), found {pos.shape}")
        T, J = pos.shape[:2]
        if J != topo.n_joints:
            raise ValueError(
                f"positions have {J} joints but topology {topo.name!r} has {topo.n_joints}"
            )
        if np.isinf(pos).any():
            raise ValueError("positions must be finite or NaN, found inf")
        object.__setattr__(self, "positions", pos)
        self._set_codes("tracking_state", TrackingState, "0, 1 or 2")
        if self.timestamps is not None:
            ts = np.asarray(self.timestamps, dtype=float)
            if ts.shape != (T,):
                raise ValueError(f"timestamps must have shape (T,) = {(T,)}, found {ts.shape}")
            if not np.all(np.isfinite(ts)):
                raise ValueError("timestamps must be finite")
            if T > 1 and np.any(np.diff(ts) < 0):
                k = int(np.argmax(np.diff(ts) < 0))
                raise ValueError(
                    f"timestamps must be non-decreasing; frame {k + 1} ({ts[k + 1]}) comes "
                    f"before frame {k} ({ts[k]})"
                )
            object.__setattr__(self, "timestamps", ts)
        if self.fps is not None:
            fps = float(self.fps)
            if not np.isfinite(fps) or fps <= 0:
                raise ValueError(f"fps must be a positive number, found {self.fps!r}")
            object.__setattr__(self, "fps", fps)
        self._set_floats("std", np.inf, ">= 0 and finite, or NaN (no estimate)", copy=False)
        self._set_codes("sample_state", SampleState, "0 to 4")
        self._set_floats("confidence", 1.0, "in [0, 1] or NaN", copy=True)
        units = self.units
        if units is _DEFAULT:
            units = "m" if pos.shape[2] == 3 else None
        if units is not None:
            if not isinstance(units, str) or units.strip().lower() not in KNOWN_UNITS:
                raise ValueError(
                    f"units must be one of {sorted(KNOWN_UNITS)} or None (unknown), found {units!r}"
                )
            units = units.strip().lower()
        object.__setattr__(self, "units", units)
        if self.metadata is None:
            object.__setattr__(self, "metadata", {})
        elif not isinstance(self.metadata, dict):
            raise TypeError(f"metadata must be a dict, found {type(self.metadata).__name__}")

    def _set_floats(self, name: str, hi: float, allowed: str, *, copy: bool) -> None:
        """Check a (T, J) float field (values in [0, hi], finite, or NaN) or None, and
        store it as float (a copy with ``copy``)."""
        value = getattr(self, name)
        if value is None:
            return
        try:
            a = (np.array if copy else np.asarray)(value, dtype=float)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{name} must be numeric, found {exc}") from None
        shape = self.positions.shape[:2]
        if a.shape != shape:
            raise ValueError(f"{name} must have shape (T, J) = {shape}, found {a.shape}")
        if np.isinf(a).any() or (a < 0).any() or (a > hi).any():
            raise ValueError(f"{name} values must be {allowed}")
        object.__setattr__(self, name, a)

    def _set_codes(self, name: str, codes: type[IntEnum], allowed: str) -> None:
        """Check a (T, J) field of ``codes`` values (or None) and store it as int8."""
        value = getattr(self, name)
        if value is None:
            return
        a = np.asarray(value)
        shape = self.positions.shape[:2]
        if a.shape != shape:
            raise ValueError(f"{name} must have shape (T, J) = {shape}, found {a.shape}")
        if a.size and (
            not np.issubdtype(a.dtype, np.number)
            or np.any(a != np.round(a))
            or a.min() < min(codes)
            or a.max() > max(codes)
        ):
            raise ValueError(f"{name} values must be {allowed} ({codes.__name__})")
        object.__setattr__(self, name, a.astype(np.int8))

    # ------------------------------------------------------------------ properties
    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.positions.shape[0])

    @property
    def n_joints(self) -> int:
        """Number of joints J."""
        return int(self.positions.shape[1])

    @property
    def n_dims(self) -> int:
        """Number of coordinates D per joint (2 or 3)."""
        return int(self.positions.shape[2])

    @property
    def metres_per_unit(self) -> float | None:
        """Length of one unit of ``positions`` in metres (None for pixels / unknown)."""
        return None if self.units is None else KNOWN_UNITS[self.units]

    def to_metres(self) -> SkeletonSequence:
        """This sequence with positions and standard deviations in metres (itself when
        they are). A ValueError for pixels or unknown units: no length to convert."""
        k = self.metres_per_unit
        if k is None:
            raise ValueError(
                f"positions in {self.units or 'unknown units'} have no length in metres "
                "(give the recording's length unit: units='mm', --units mm, ...)"
            )
        if self.units == "m":
            return self
        std = None if self.std is None else self.std * k
        return self.replace(positions=self.positions * k, std=std, units="m")

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Joint names, length J."""
        return self.topology.joints

    def __len__(self) -> int:
        return self.n_frames

    def __repr__(self) -> str:
        return (
            f"SkeletonSequence(T={self.n_frames}, J={self.n_joints}, D={self.n_dims}, "
            f"units={self.units!r}, "
            f"topology={self.topology.name!r}, fps={self.fps}, body_id={self.body_id!r}, "
            f"tracking_state={'yes' if self.tracking_state is not None else 'no'}, "
            f"timestamps={'yes' if self.timestamps is not None else 'no'}"
            + (", std=yes" if self.std is not None else "")
            + (", sample_state=yes" if self.sample_state is not None else "")
            + (", confidence=yes" if self.confidence is not None else "")
            + ")"
        )

    # ------------------------------------------------------------------ time
    def times(self) -> np.ndarray:
        """Frame times in seconds, shape (T,).

        ``timestamps`` when present, else ``arange(T) / fps``; without either, frame
        indices (``fps`` taken as 1) are returned.
        """
        if self.timestamps is not None:
            return self.timestamps.copy()
        fps = self.fps if self.fps is not None else 1.0
        return np.arange(self.n_frames, dtype=float) / fps

    def dt(self) -> np.ndarray:
        """Time steps in seconds between consecutive frames, shape (T-1,)."""
        return np.diff(self.times())

    # ------------------------------------------------------------------ derived
    def replace(self, **changes: Any) -> SkeletonSequence:
        """Copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    def _replace_valid(self, **changes: Any) -> SkeletonSequence:
        """Copy with some fields changed, not validated: each value must be one that
        :meth:`__post_init__` accepts and stores as it is (float64 / int8 arrays of the
        right shapes, no inf, codes in range). For :func:`tobitkf.smooth`, which checks
        its output once for a whole batch; users go through :meth:`replace`."""
        names = [f.name for f in dataclasses.fields(self)]
        unknown = set(changes) - set(names)
        if unknown:
            raise TypeError(f"not fields of SkeletonSequence: {sorted(unknown)}")
        new = object.__new__(SkeletonSequence)
        for name in names:
            object.__setattr__(new, name, changes[name] if name in changes else getattr(self, name))
        return new

    def missing(self) -> np.ndarray:
        """Boolean ``(T, J)``: joint position missing (any coordinate NaN)."""
        return np.isnan(self.positions).any(axis=-1)

    def select_joints(self, names: Sequence[str]) -> SkeletonSequence:
        """Sequence restricted to the given joints (in the given order).

        Metadata arrays of shape ``(T, J, ...)`` (e.g. ``orientations``) are cut on their
        second axis, also inside dicts; the entries that ``metadata["per_joint"]`` names
        (indexed by joint on their first axis: arrays or lists of length J, e.g. a BVH
        file's ``offsets``) on their first.
        """
        idx = self.topology.indices(names)
        topo = self.topology.subset(names)
        T, J = self.n_frames, self.n_joints
        per_joint = _per_joint_keys(self.metadata)
        meta = {}
        for k, v in self.metadata.items():
            if k in per_joint:
                if not (
                    (isinstance(v, (list, tuple)) and len(v) == J)
                    or (isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == J)
                ):
                    raise ValueError(
                        f"metadata[{k!r}] is listed in metadata[{PER_JOINT!r}] but is not "
                        f"an array or list of length J = {J}"
                    )
                meta[k] = v[idx] if isinstance(v, np.ndarray) else type(v)(v[i] for i in idx)
            else:
                meta[k] = _cut_joints(v, T, J, idx)
        return self.replace(
            positions=self.positions[:, idx],
            topology=topo,
            tracking_state=None if self.tracking_state is None else self.tracking_state[:, idx],
            metadata=meta,
            std=None if self.std is None else self.std[:, idx],
            sample_state=None if self.sample_state is None else self.sample_state[:, idx],
            confidence=None if self.confidence is None else self.confidence[:, idx],
        )

    def select_frames(self, frames: slice | Sequence[int] | np.ndarray) -> SkeletonSequence:
        """Sequence restricted to some frames, in increasing order: a slice
        (``seq.select_frames(slice(300, 900))``), frame indices (negative ones count from
        the end) or a boolean mask of length T.

        Every per-frame field is cut alike: positions, tracking states, timestamps,
        standard deviations, sample states, confidences, and the metadata arrays whose
        first axis has length T (orientations, frame numbers, ...; also inside dicts),
        except the per-joint entries that ``metadata["per_joint"]`` names.
        ``metadata["source_frames"]`` holds each frame's index in the recording first
        selected from (a selection of a selection keeps the first one's indices). Each
        frame keeps its time: with ``timestamps``, its own; a sequence timed by ``fps``
        alone keeps ``fps`` for a run of frames (step 1; its times then start at 0 again)
        and gets ``timestamps`` from :meth:`times` otherwise, since its frames are no
        longer evenly spaced; without either, ``source_frames`` tells the gaps.
        """
        T = self.n_frames
        if isinstance(frames, slice):
            idx = np.arange(T)[frames]
        else:
            a = np.asarray(frames)
            if a.dtype == np.bool_:
                if a.shape != (T,):
                    raise ValueError(f"a frame mask must have shape (T,) = {(T,)}, found {a.shape}")
                idx = np.flatnonzero(a)
            elif a.ndim == 1 and (a.size == 0 or np.issubdtype(a.dtype, np.integer)):
                idx = a.astype(np.intp)
                bad = idx[(idx < -T) | (idx >= T)]
                if bad.size:
                    raise IndexError(f"frame {int(bad[0])} is out of range for {T} frames")
                idx = np.where(idx < 0, idx + T, idx)
            else:
                raise TypeError(
                    "frames must be a slice, integer frame indices or a boolean mask, "
                    f"found {a.dtype} of shape {a.shape}"
                )
        steps = np.diff(idx)
        if (steps <= 0).any():
            k = int(np.argmax(steps <= 0))
            raise ValueError(
                f"frames must be increasing, each at most once; frame {int(idx[k + 1])} "
                f"comes after frame {int(idx[k])}"
            )
        run = bool((steps == 1).all())
        per_joint = _per_joint_keys(self.metadata)
        meta = {
            k: v if k in per_joint else _cut_frames(v, T, idx) for k, v in self.metadata.items()
        }
        if not isinstance(self.metadata.get(SOURCE_FRAMES), np.ndarray):
            meta[SOURCE_FRAMES] = idx.astype(np.int64)  # (a selection's are sliced above)
        timestamps = self.timestamps
        if timestamps is not None:
            timestamps = timestamps[idx]
        elif self.fps is not None and not run:  # gaps: the frames are no longer evenly spaced
            timestamps = self.times()[idx]

        def cut(x: np.ndarray | None) -> np.ndarray | None:
            return None if x is None else x[idx]

        return self.replace(
            positions=self.positions[idx],
            tracking_state=cut(self.tracking_state),
            timestamps=timestamps,
            metadata=meta,
            std=cut(self.std),
            sample_state=cut(self.sample_state),
            confidence=cut(self.confidence),
        )

    def to_dataframe(self, layout: str = "long") -> Any:
        """A pandas DataFrame of the sequence, ``layout`` ``"long"`` (a row per frame and
        keypoint) or ``"wide"`` (a row per frame); see :mod:`tobitkf.skeleton.dataframe`,
        and :func:`tobitkf.from_dataframe` for the way back."""
        from tobitkf.skeleton.to_frame import to_dataframe

        return to_dataframe(self, layout)

    def largest_jumps(self) -> tuple[np.ndarray, np.ndarray]:
        """Largest frame-to-frame displacement of each joint.

        Returns
        -------
        jumps : ndarray, shape (J,)
            ``max_t ||p_t - p_{t-1}||`` in ``units`` over consecutive frames where both samples
            are present; NaN if a joint has no such pair.
        frames : ndarray of int, shape (J,)
            Frame ``t`` at which the largest jump lands (``-1`` when ``jumps`` is NaN).
        """
        return largest_jumps(self.positions)


def largest_jumps(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Largest frame-to-frame displacement of each joint, and the frame where it ends.

    Parameters
    ----------
    positions : (T, J, D)

    Returns
    -------
    jump : (J,) in the positions' units (NaN where a joint never has two consecutive valid frames)
    frame : (J,) index of the later frame of the largest jump (-1 if none)
    """
    p = np.asarray(positions, dtype=float)
    if p.shape[0] < 2:
        j = p.shape[1]
        return np.full(j, np.nan), np.full(j, -1)
    step = np.linalg.norm(np.diff(p, axis=0), axis=-1)  # (T-1, J)
    valid = np.isfinite(step)
    filled = np.where(valid, step, -np.inf)
    arg = np.argmax(filled, axis=0)
    jump = filled[arg, np.arange(p.shape[1])]
    has = valid.any(axis=0)
    return np.where(has, jump, np.nan), np.where(has, arg + 1, -1)
