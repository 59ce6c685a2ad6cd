"""Time steps, missing samples and measurement-noise scaling: how every smoothing method
reads a skeleton sequence's clock and tracking states, so that all treat them alike.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.skeleton.sequence import SkeletonSequence, TrackingState
from tobitkf.smoothing.paper import REFERENCE_DT

__all__ = [
    "DEFAULT_INFERRED_NOISE_FACTOR",
    "any_last",
    "elapsed_since_valid",
    "frame_steps",
    "frame_times",
    "inferred_r_scale",
    "inferred_sample_scale",
    "measurements",
    "readonly",
    "typical_step",
]

Array = NDArray[np.float64]

#: measurement-variance multiplier for INFERRED joints: twice the standard deviation, the
#: same doubling the Kinect SDK's own joint filter applies to its radii for inferred joints
DEFAULT_INFERRED_NOISE_FACTOR = 4.0
#: the tracking states as plain ints: an array compared with the enum member costs
#: microseconds per call (numpy converts the member each time), a live frame's budget
NOT_TRACKED_CODE = int(TrackingState.NOT_TRACKED)
INFERRED_CODE = int(TrackingState.INFERRED)
TRACKED_CODE = int(TrackingState.TRACKED)


def frame_steps(sequence: SkeletonSequence) -> tuple[Array, float, bool]:
    """Time step before each frame, ``(T,)`` seconds, the nominal step, and irregularity.

    ``steps[0]`` is the nominal step: the median positive timestamp difference, else
    1/fps, else 1/30 s. Zero differences (duplicated stamps) become a tenth of it.
    ``is_reference`` is True when every step equals 1/30 s (no scaling needed).
    """
    T = sequence.n_frames
    ts = sequence.timestamps
    fps = sequence.fps if sequence.fps is not None else 30.0
    nominal = 1.0 / float(fps)
    steps = np.full(T, nominal)
    if ts is not None and T > 1:
        d = np.diff(np.asarray(ts, dtype=float))
        positive = d[d > 0]
        if positive.size:  # else: all stamps equal, fall back to the frame rate
            nominal = float(np.median(positive))
            steps = np.concatenate([[nominal], np.maximum(d, 0.1 * nominal)])
    is_reference = bool(np.allclose(steps, REFERENCE_DT, rtol=1e-9, atol=0.0))
    return steps, nominal, is_reference


#: units timestamps are mistaken for seconds in (MediaPipe and Azure Kinect give
#: milliseconds or microseconds), and their size in seconds
_TIME_UNITS = (("milliseconds", 1e3), ("microseconds", 1e6), ("nanoseconds", 1e9))
#: without a frame rate, stamps further apart than this (s) that would be a usual
#: tracking rate (Hz) in a smaller unit are taken to be in it (a frame a second in
#: seconds, or a thousand a second in ms, is not told apart: it passes)
_SLOW_STEP = 2.0
_RATES = (5.0, 1000.0)


def check_time_unit(step: float, fps: float | None) -> None:
    """``ValueError`` when timestamps ``step`` apart (their median positive step) are
    not seconds: the step is a thousand (a million, a billion) times ``1/fps``, give or
    take a factor of 3, or, without a frame rate, a frame every two seconds or more
    would be a usual tracking rate in milliseconds (microseconds, nanoseconds). Every
    gate and the motion model are in seconds: such stamps stretch a frame to half a
    minute, and nothing is rejected or smoothed."""
    if not (np.isfinite(step) and step > 0):
        return
    for name, size in _TIME_UNITS:
        if fps is not None:
            hit = size / 3.0 <= step * fps <= size * 3.0
        else:
            hit = step > _SLOW_STEP and _RATES[0] <= size / step <= _RATES[1]
        if hit:
            rate = (
                f"the frame rate of {fps:g} Hz says {1.0 / fps:.4g} s"
                if fps
                else f"a frame every {step:.4g} s is no tracking rate"
            )
            raise ValueError(
                f"the timestamps are {step:.4g} apart (median step) and {rate}: they look "
                f"like {name}; give them in seconds (divide by {size:g})"
            )


def typical_step(steps: Array) -> float:
    """The typical time step of ``steps (T,)`` (:func:`frame_steps`): the median of the
    steps between frames, ``steps[0]`` (the nominal step) for a single frame."""
    return float(np.median(steps[1:])) if steps.size > 1 else float(steps[0])


def frame_times(sequence: SkeletonSequence, steps: Array | None = None) -> Array:
    """Time of each frame, ``(T,)`` seconds: the timestamps, else the cumulated steps."""
    if sequence.timestamps is not None:
        return np.asarray(sequence.timestamps, dtype=float)
    if steps is None:
        steps = frame_steps(sequence)[0]
    return np.concatenate([[0.0], np.cumsum(steps[1:])])


def measurements(positions: Any, states: Any | None) -> tuple[Array, NDArray[np.bool_]]:
    """Measurements with NaN and NOT_TRACKED joints set to NaN, and the missing mask
    ``positions.shape[:-1]``. Every method, batch or live, reads its input through this,
    so that all treat a sample as missing alike. ``positions`` itself is returned (not a
    copy) when nothing has to change: callers must not write into the result.
    """
    ys = np.asarray(positions, dtype=float)
    nan = np.isnan(ys)
    missing = any_last(nan)
    if states is not None:
        not_tracked = np.asarray(states) == NOT_TRACKED_CODE
        if not_tracked.any():
            missing |= not_tracked
            return np.where(missing[..., None], np.nan, ys), missing
    # a partly-NaN sample gets all its axes NaN; there is one when the NaN are fewer than
    # D per missing sample (a count, not a second (..., D) reduction)
    if np.count_nonzero(nan) != ys.shape[-1] * np.count_nonzero(missing):
        ys = np.where(missing[..., None], np.nan, ys)
    return ys, missing


def readonly(a: NDArray[Any]) -> NDArray[Any]:
    """A read-only view of ``a``. The compiled kernels get their input samples this way,
    whether the caller's array is writable or not: numba compiles one version of a
    function per argument type, and writability is part of an array's type."""
    view = a.view()
    view.flags.writeable = False
    return view


def any_last(a: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """``a.any(axis=-1)``, written out for 3 axes (a reduction over a short last axis is
    slow in numpy)."""
    if a.shape[-1] == 3:
        return (a[..., 0] | a[..., 1]) | a[..., 2]
    return a.any(axis=-1)


def first_true(mask: NDArray[np.bool_]) -> NDArray[np.int64]:
    """Index along axis 0 of each column's first True, ``mask.shape[0]`` where it has none
    (``mask (T, ...)`` gives ``(...)``)."""
    return np.where(mask.any(axis=0), mask.argmax(axis=0), mask.shape[0])


def inferred_sample_scale(
    states: Any | None, valid: NDArray[np.bool_], factor: float
) -> Array | None:
    """Measurement-variance multiplier ``valid.shape`` for valid INFERRED joints.

    ``factor`` where a valid joint is INFERRED, 1 elsewhere; None when nothing is scaled
    (no states, factor 1 or no valid inferred joint), so the filters skip the work.
    """
    if states is None or factor == 1.0:
        return None
    inferred = (np.asarray(states) == INFERRED_CODE) & valid
    if not inferred.any():
        return None
    return np.where(inferred, factor, 1.0)


def inferred_r_scale(states: Any | None, valid: NDArray[np.bool_], factor: float) -> Array | None:
    """:func:`inferred_sample_scale` repeated on the 3 axes, ``(*valid.shape, 3)``."""
    scale = inferred_sample_scale(states, valid, factor)
    return None if scale is None else np.repeat(scale[..., None], 3, axis=-1)


def elapsed_since_valid(steps: Array, valid: NDArray[np.bool_]) -> Array:
    """Time from each joint's last valid frame before k to frame k, ``(T, *batch)``.

    ``steps[k]`` when frame k-1 was valid (or k is before the first valid frame); after a
    gap it is the whole time since the last measurement.
    """
    T = steps.shape[0]
    shape = (T,) + (1,) * (valid.ndim - 1)
    if valid.all():  # no gap anywhere: the frame steps, without (T, *batch) work arrays
        return np.broadcast_to(steps.reshape(shape), valid.shape)
    times = np.cumsum(steps)
    index_type = np.int32 if T < 2**31 - 1 else np.int64
    idx = np.where(valid, np.arange(T, dtype=index_type).reshape(shape), index_type(-1))
    last = np.maximum.accumulate(idx, axis=0)  # last valid index <= k
    prev = np.concatenate([np.full((1, *valid.shape[1:]), -1, dtype=index_type), last[:-1]])
    t_k = np.broadcast_to(times.reshape(shape), valid.shape)
    st_k = np.broadcast_to(steps.reshape(shape), valid.shape)
    t_prev = times[np.maximum(prev, 0)]
    # frame k-1 valid (or nothing valid yet): exactly steps[k], not the difference of the
    # cumulated times, which differs from it by round-off (and made every joint's limits
    # differ from the per-frame ones, a full (T, *batch, 3) array of c in the filter)
    one_step = (prev < 0) | (prev == np.arange(T).reshape(shape) - 1)
    return np.where(one_step, st_k, t_k - t_prev)
