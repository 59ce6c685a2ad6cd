"""Checks of one frame of a live stream, shared by :class:`~tobitkf.smoothing.live.
LiveSmoother` and :class:`~tobitkf.smoothing.delayed.DelayedSmoother` (their ``update``
takes the same arguments, so it refuses the same things with the same words).

Each returns the value as the stream keeps it, or raises ``ValueError`` naming the
argument; none changes any state, so a refused frame leaves a stream as it was. The
arrays returned may be the caller's own (a stream that keeps frames copies them).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tobitkf.skeleton.sequence import TrackingState
from tobitkf.skeleton.topology import Topology

__all__ = ["INFINITE", "check_confidence", "check_positions", "check_states", "timestamp_seconds"]

Array = NDArray[np.float64]
STATES = tuple(int(s) for s in TrackingState)
# the codes are 0 .. 2 with no gap: a range check is np.isin's answer for integers at a
# small part of its cost (np.isin sorts; it was a third of a live frame's work with
# tracking states); the error message, off the fast path, still names the bad values
assert STATES == tuple(range(min(STATES), max(STATES) + 1))


def _known(raw: Any) -> Any:
    return (raw >= STATES[0]) & (raw <= STATES[-1])


INFINITE = "positions: infinite values (use NaN for a missing joint)"


def check_positions(positions: ArrayLike, topology: Topology, dims: int | None = None) -> Array:
    """``positions`` as floats, shaped ``(J, D)`` or ``(B, J, D)`` with D = 3 or 2, ``D``
    the stream's ``dims`` when it has them and ``J`` the topology's joints. Infinite
    values are the caller's to refuse (:data:`INFINITE`): a keyed stream names the body."""
    try:
        pos = np.asarray(positions, dtype=float)
    except (TypeError, ValueError):
        raise ValueError("positions: expected numbers of shape (J, 3) or (B, J, 3)") from None
    shape = pos.shape
    if len(shape) not in (2, 3) or shape[-1] not in (2, 3):
        raise ValueError(
            f"positions: expected shape (J, D) or (B, J, D) with D = 3 or 2, found {shape}"
        )
    if dims is not None and shape[-1] != dims:
        raise ValueError(f"positions: this stream has {dims} coordinates, found {shape[-1]}")
    if shape[-2] != topology.n_joints:
        raise ValueError(
            f"positions: {shape[-2]} joints, but topology {topology.name!r} has {topology.n_joints}"
        )
    return pos


def check_states(tracking_state: ArrayLike | None, shape: tuple[int, ...]) -> Any:
    """Kinect tracking states of ``shape`` as int8 codes (a copy), or None."""
    if tracking_state is None:
        return None
    raw = np.asarray(tracking_state)
    if raw.shape != shape:
        raise ValueError(f"tracking_state: expected shape {shape}, found {raw.shape}")
    if raw.dtype.kind not in "iu" or not _known(raw).all():
        odd = raw.ravel()[~np.isin(raw.ravel(), STATES)][:3].tolist()
        raise ValueError(
            "tracking_state: expected integers 0 (not tracked), 1 (inferred) or "
            + (
                f"2 (tracked), found {odd}"
                if odd
                else f"2 (tracked), found them as {raw.dtype} (give tracking_state.astype(int))"
            )
            if raw.dtype.kind in "iuf"
            else f"tracking_state: expected integers 0, 1 or 2, found dtype {raw.dtype}"
        )
    return raw.astype(np.int8)


def check_confidence(confidence: Any, shape: tuple[int, ...]) -> Array | None:
    """A pose estimator's scores of ``shape`` in [0, 1] (NaN: none), or None."""
    if confidence is None:
        return None
    try:
        conf = np.asarray(confidence, dtype=float)
    except (TypeError, ValueError):
        raise ValueError("confidence: expected numbers in [0, 1]") from None
    if conf.shape != shape:
        raise ValueError(f"confidence: expected shape {shape}, found {conf.shape}")
    if np.any((conf < 0) | (conf > 1)):
        raise ValueError("confidence: expected scores in [0, 1] (NaN: none)")
    return conf


def timestamp_seconds(timestamp: Any) -> float | None:
    """A frame's timestamp as a finite float (None: not given)."""
    if timestamp is None:
        return None
    try:
        t = float(timestamp)
    except (TypeError, ValueError):
        raise ValueError(f"timestamp must be a number of seconds, got {timestamp!r}") from None
    if not np.isfinite(t):
        raise ValueError(f"timestamp must be finite, got {timestamp!r}")
    return t
