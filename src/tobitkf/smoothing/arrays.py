"""NumPy arrays in, NumPy arrays out: ``tobitkf.smooth(array, fps=...)``.

Like :func:`scipy.signal.savgol_filter`, :func:`tobitkf.smooth` takes a plain array and
returns one of the same shape: ``(T, J, D)`` keypoint tracks (frames, keypoints,
coordinates; D = 2 or 3) or ``(T, D)`` for a single point, NaN where a keypoint is
missing. This module turns the array and its keywords into a
:class:`~tobitkf.skeleton.sequence.SkeletonSequence`, checking every one of them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology, get_topology

__all__ = ["sequence_from_array"]


def sequence_from_array(
    array: Any,
    *,
    fps: float | None = None,
    confidence: Any = None,
    units: str | None = None,
    topology: Topology | str | None = None,
    timestamps: Any = None,
) -> tuple[SkeletonSequence, bool]:
    """The sequence of an array, and whether the array was a single point ``(T, D)``.

    Parameters
    ----------
    array : ndarray (T, J, D) or (T, D), D = 2 or 3; NaN = missing
    fps : frame rate (Hz); None: 30 (the smoothers' convention for sequences without one)
    confidence : (T, J) (or (T,) for a single point) scores in [0, 1], NaN = none
    units : ``"m"``, ``"cm"``, ``"mm"``, ``"px"`` or None (unknown, the default for
        arrays: the robust methods then take their gates from the recording; pass
        ``units="m"`` for the physical gates of 3-D tracks in metres; a 3-D body of a
        person's size in metres, centimetres or millimetres is smoothed with a warning
        that names that unit, :func:`~tobitkf.smoothing.body_scale.unstated_unit_note`)
    topology : a :class:`Topology` or built-in name with J joints (bones for the bone
        gate); None: J keypoints without bones (gated by speed and confidence alone)
    timestamps : (T,) seconds, increasing (irregular frames), or datetimes (counted from
        the first); None: the frames are ``1 / fps`` apart. Not with ``fps``.
    """
    if not isinstance(array, np.ndarray):
        raise TypeError(f"expected a NumPy array, got {type(array).__name__}")
    if not (np.issubdtype(array.dtype, np.number) or array.dtype == bool):
        raise TypeError(f"expected a numeric array, got dtype {array.dtype}")
    if np.iscomplexobj(array):
        raise TypeError("expected a real array, got complex values")
    single = array.ndim == 2
    if array.ndim not in (2, 3) or array.shape[-1] not in (2, 3):
        raise ValueError(
            "expected an array of shape (T, J, D) (frames, keypoints, coordinates) or "
            f"(T, D) for one point, with D = 2 or 3; got shape {array.shape}"
        )
    pos = np.asarray(array, dtype=float)
    if single:
        pos = pos[:, None, :]
    if np.isinf(pos).any():
        raise ValueError("the array holds inf; use NaN for a missing keypoint")
    T, J = pos.shape[:2]
    conf = None
    if confidence is not None:
        conf = np.asarray(confidence, dtype=float)
        want = (T,) if single else (T, J)
        if conf.shape != want:
            raise ValueError(f"confidence must have shape {want}, got {conf.shape}")
        conf = conf.reshape(T, J)
    if topology is None:
        topo = Topology.from_names([f"k{j}" for j in range(J)], name="keypoints")
    else:
        topo = get_topology(topology) if isinstance(topology, str) else topology
    if fps is not None and (isinstance(fps, bool) or not isinstance(fps, (int, float, np.number))):
        raise TypeError(f"fps must be a number, got {fps!r}")
    if timestamps is not None:
        if fps is not None:
            raise ValueError("give fps or timestamps, not both (timestamps set every step)")
        timestamps = _seconds(timestamps)
    return (
        SkeletonSequence(pos, topo, fps=fps, confidence=conf, units=units, timestamps=timestamps),
        single,
    )


def _seconds(timestamps: Any) -> Any:
    """Timestamps as seconds: datetimes (numpy ``datetime64``, a pandas ``DatetimeIndex``)
    counted from the first; numbers as they are (seconds)."""
    ts = np.asarray(timestamps)
    if np.issubdtype(ts.dtype, np.datetime64):
        return (ts - ts.flat[0]) / np.timedelta64(1, "s") if ts.size else ts.astype(float)
    if np.issubdtype(ts.dtype, np.timedelta64):
        return ts / np.timedelta64(1, "s")
    return timestamps
