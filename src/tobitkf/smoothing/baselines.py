"""Baseline smoothers people use on skeleton tracks today.

Pure array functions over time-first arrays ``x`` of shape ``(T, *batch, d)`` (a 1-D
``(T,)`` series is accepted too and returned with the same shape). NaN marks a missing
sample. Each is registered as a method of :func:`tobitkf.smooth` at the end of this
module. Baselines treat NOT_TRACKED as missing and ignore INFERRED, except ``kinect``,
which uses the states as the SDK does.

- :func:`savgol`: Savitzky–Golay filter along time (``scipy.signal.savgol_filter``).
- :func:`one_euro`: the 1€ filter (Casiez, Roussel, Vogel, CHI 2012).
- :func:`kinect_double_exponential`: the Kinect SDK joint filter (Holt double
  exponential smoothing with jitter radius and maximum-deviation clamping), as in the
  SDK sample ``KinectJointFilter`` and the "Skeletal Joint Smoothing" white paper.
- :func:`moving_average`: centred or trailing box filter.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tobitkf.smoothing.chunks import chunks
from tobitkf.smoothing.params import (
    as_bool,
    at_least_int,
    nonneg_float,
    odd_window,
    one_of,
    optional,
    positive_float,
    unit_float,
)
from tobitkf.smoothing.registry import SmoothInput, register_method
from tobitkf.smoothing.timebase import readonly

__all__ = [
    "KINECT_PRESETS",
    "kinect_double_exponential",
    "moving_average",
    "one_euro",
    "savgol",
]

#: Kinect SDK smoothing presets: (smoothing, correction, prediction, jitter_radius,
#: max_deviation_radius). "default" is the SDK v1 default (``NUI_TRANSFORM_SMOOTH_PARAMETERS``
#: defaults); "v2_sample" the values used by the Kinect v2 ``KinectJointFilter`` sample.
KINECT_PRESETS: dict[str, dict[str, float]] = {
    "default": {
        "smoothing": 0.5,
        "correction": 0.5,
        "prediction": 0.5,
        "jitter_radius": 0.05,
        "max_deviation_radius": 0.04,
    },
    "v2_sample": {
        "smoothing": 0.25,
        "correction": 0.25,
        "prediction": 0.25,
        "jitter_radius": 0.03,
        "max_deviation_radius": 0.05,
    },
}
_KINECT_PARAMS = ("smoothing", "correction", "prediction", "jitter_radius", "max_deviation_radius")


# --------------------------------------------------------------------------- helpers


def _as_series(x: ArrayLike, name: str = "x") -> tuple[NDArray[np.float64], tuple[int, ...]]:
    """Return ``x`` as float ``(T, *batch, d)`` (1-D input becomes ``(T, 1)``) and its shape."""
    arr = np.asarray(x, dtype=float)
    if arr.ndim == 0:
        raise ValueError(f"{name} must have a leading time axis, got a scalar")
    shape = arr.shape
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.shape[0] == 0:
        raise ValueError(f"{name} has no frames (shape {shape})")
    return arr, shape


def _positive_int(window: int, name: str = "window") -> int:
    if int(window) != window or window < 1:
        raise ValueError(f"{name} must be a positive integer, got {window!r}")
    return int(window)


def _time_steps(
    n_frames: int, fps: float | None, timestamps: ArrayLike | None
) -> NDArray[np.float64]:
    """Return the time of each frame ``(T,)`` in seconds from ``timestamps`` or ``fps``."""
    if timestamps is not None:
        t = np.asarray(timestamps, dtype=float)
        if t.shape != (n_frames,):
            raise ValueError(f"timestamps must have shape ({n_frames},), got {t.shape}")
        if not np.all(np.isfinite(t)):
            raise ValueError("timestamps must be finite")
        if n_frames > 1 and np.any(np.diff(t) <= 0):
            k = int(np.argmax(np.diff(t) <= 0))
            raise ValueError(
                f"timestamps must be strictly increasing; frame {k + 1} ({t[k + 1]!r} s) "
                f"is not after frame {k} ({t[k]!r} s)"
            )
        return t
    if fps is None:
        raise ValueError("give fps or timestamps")
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be a positive number, got {fps!r}")
    return np.arange(n_frames, dtype=float) / float(fps)


# --------------------------------------------------------------------------- Savitzky–Golay


def savgol(
    x: ArrayLike,
    window: int = 9,
    polyorder: int = 3,
    *,
    max_gap: int | None = None,
) -> NDArray[np.float64]:
    """Savitzky–Golay smoothing along time, NaN-aware.

    Each series (one column of the flattened batch) is filtered over the span between
    its first and last finite sample. Interior gaps are linearly interpolated before
    filtering, so their output is an estimate; NaN is restored where nothing could be
    estimated: before the first and after the last finite sample, and in gaps longer
    than ``max_gap`` frames (when given). When a span is shorter than ``window`` the
    window shrinks to the largest odd length that fits and the order to at most
    ``window - 1`` (a span of 1 or 2 frames is returned unchanged).

    The filter works on sample index: it assumes (approximately) uniform sampling.
    Edges use ``mode="interp"`` (polynomial fit to the first / last window), so a
    polynomial of degree ``<= polyorder`` passes through unchanged.

    Parameters
    ----------
    x : array_like, shape (T, *batch, d) or (T,)
    window : int
        Odd window length in frames (``> polyorder``).
    polyorder : int
        Degree of the local polynomial.
    max_gap : int, optional
        Gaps (runs of NaN) longer than this many frames stay NaN in the output.

    Returns
    -------
    ndarray, same shape as ``x``
    """
    arr, shape = _as_series(x)
    window = _positive_int(window)
    if window % 2 == 0:
        raise ValueError(f"window must be odd, got {window}")
    if int(polyorder) != polyorder or polyorder < 0:
        raise ValueError(f"polyorder must be a non-negative integer, got {polyorder!r}")
    if polyorder >= window:
        raise ValueError(f"polyorder ({polyorder}) must be less than window ({window})")
    T = arr.shape[0]
    flat = arr.reshape(T, -1)
    # the columns are independent: a large batch goes a chunk of columns at a time, so
    # the working arrays (interpolated copies, scipy's output) stay small
    parts = chunks(flat.shape[1], T * flat.itemsize)
    if len(parts) == 1:
        return _savgol_columns(flat, window, polyorder, max_gap).reshape(shape)
    out = np.empty(flat.shape)
    for c in parts:
        out[:, c] = _savgol_columns(flat[:, c], window, polyorder, max_gap)
    return out.reshape(shape)


def _savgol_columns(
    flat: NDArray[np.float64], window: int, polyorder: int, max_gap: int | None
) -> NDArray[np.float64]:
    """:func:`savgol` of the columns of ``flat`` (T, m), arguments checked."""
    T = flat.shape[0]
    finite = np.isfinite(flat)
    if T > 2 and finite.all():  # no gap anywhere: one scipy call, no copies
        w = min(window, T if T % 2 == 1 else T - 1)
        return _savgol_span(flat, w, min(polyorder, w - 1))
    out = np.full_like(flat, np.nan)
    idx = np.arange(T)
    # group columns by their finite span so that columns sharing it go through one call
    has = finite.any(axis=0)
    firsts = np.argmax(finite, axis=0)
    lasts = T - 1 - np.argmax(finite[::-1], axis=0)
    spans, inverse = np.unique(np.stack([firsts, lasts], axis=1)[has], axis=0, return_inverse=True)
    columns = np.flatnonzero(has)
    for g, (first, last) in enumerate(spans):
        # every column in one span (the usual case): slices, no fancy-index copies
        cols = slice(None) if len(spans) == 1 and has.all() else columns[inverse.ravel() == g]
        seg = flat[first : last + 1, cols]
        seg_finite = finite[first : last + 1, cols]
        gaps = np.flatnonzero(~seg_finite.all(axis=0))
        if gaps.size:
            if isinstance(cols, slice):  # a view (fancy indexing copied already)
                seg = seg.copy()
            seg_idx = idx[first : last + 1]
            for c in gaps:
                ok = seg_finite[:, c]
                seg[~ok, c] = np.interp(seg_idx[~ok], seg_idx[ok], seg[ok, c])
        n = last - first + 1
        w = min(window, n if n % 2 == 1 else n - 1)
        order = min(polyorder, w - 1)
        out[first : last + 1, cols] = _savgol_span(seg, w, order)
    if max_gap is not None:
        long_gap = _long_gaps(finite, int(max_gap))
        out[long_gap] = np.nan
    return out


def _savgol_span(seg: NDArray[np.float64], w: int, order: int) -> NDArray[np.float64]:
    """``savgol_filter(seg, w, order, axis=0, mode="interp")`` of gap-free columns, the
    edges fitted column by column: scipy fits the polynomial of the first and last ``w``
    frames to all columns in one least-squares call, whose last bits depend on the other
    columns of the call; here each edge value is the fit's value there, a fixed weighted
    sum of the window (:func:`_edge_weights`) added up term by term, so a column's output
    is the same whichever columns, and how many, are smoothed with it (chunks)."""
    from scipy.signal import savgol_filter  # 1 s to import: only when used

    # the interior as scipy's; the edges (where the modes differ) are replaced below
    out = savgol_filter(seg, w, order, axis=0, mode="nearest")
    half, n = w // 2, seg.shape[0]
    if half:
        hat = _edge_weights(w, order)
        for rows, window, weights in (
            (slice(0, half), seg[:w], hat[:half]),
            (slice(n - half, n), seg[n - w :], hat[w - half :]),
        ):
            acc = weights[:, :1] * window[0]
            for k in range(1, w):
                acc += weights[:, k : k + 1] * window[k]
            out[rows] = acc
    return out


def _edge_weights(w: int, order: int) -> NDArray[np.float64]:
    """(w, w) least-squares fit of a polynomial of degree ``order`` to ``w`` equally spaced
    samples, as weights: row i gives the fitted value at sample i. Legendre basis on
    [-1, 1] and a QR factorisation: accurate to rounding for any window and order."""
    u = np.linspace(-1.0, 1.0, w)
    q = np.linalg.qr(np.polynomial.legendre.legvander(u, order))[0]
    return q @ q.T


def _long_gaps(finite: NDArray[np.bool_], max_gap: int) -> NDArray[np.bool_]:
    """Mask of missing samples ``(T, m)`` that belong to runs longer than ``max_gap``."""
    T, m = finite.shape
    mask = np.zeros((T, m), dtype=bool)
    for c in range(m):
        miss = ~finite[:, c]
        if not miss.any():
            continue
        edges = np.diff(np.concatenate([[0], miss.astype(np.int8), [0]]))
        starts = np.flatnonzero(edges == 1)
        ends = np.flatnonzero(edges == -1)
        for s, e in zip(starts, ends, strict=True):
            if e - s > max_gap:
                mask[s:e, c] = True
    return mask


# --------------------------------------------------------------------------- moving average


def moving_average(x: ArrayLike, window: int = 5, centered: bool = True) -> NDArray[np.float64]:
    """Box-filter moving average along time, NaN-aware.

    Each output sample is the mean of the finite samples inside its window: frames
    ``k - h .. k + h`` (``h = window // 2``) when ``centered`` (use an odd window), or
    ``k - window + 1 .. k`` (causal, trailing) otherwise. The window is truncated at the
    ends of the series. The output is NaN only where the window holds no finite sample.

    Parameters
    ----------
    x : array_like, shape (T, *batch, d) or (T,)
    window : int
        Window length in frames.
    centered : bool
        Centred (offline) or trailing (causal) window.

    Returns
    -------
    ndarray, same shape as ``x``
    """
    arr, shape = _as_series(x)
    window = _positive_int(window)
    if centered and window % 2 == 0:
        raise ValueError(f"a centred moving average needs an odd window, got {window}")
    T = arr.shape[0]
    back = window // 2 if centered else window - 1  # frames before k in its window
    flat = arr.reshape(T, -1)
    # the columns are independent: a large batch goes a chunk of columns at a time, so
    # the working arrays stay small
    parts = chunks(flat.shape[1], T * flat.itemsize)
    if len(parts) == 1:
        return _window_means(flat, window, back).reshape(shape)
    out = np.empty(flat.shape)
    for c in parts:
        out[:, c] = _window_means(flat[:, c], window, back)
    return out.reshape(shape)


def _window_means(x: NDArray[np.float64], window: int, back: int) -> NDArray[np.float64]:
    """:func:`moving_average` of the columns of ``x (T, m)``: frame k's window is frames
    ``k - back .. k - back + window - 1`` (those inside the series).

    Each window's finite samples are added up from its oldest frame to its newest,
    starting from 0 (a missing sample adds 0), then divided by their count: the
    arithmetic of the live stepper (:class:`MovingAverageStepper`), which adds its ring
    of the last frames in the same order, so a stream gives exactly these numbers. (A
    difference of cumulated sums would make each output depend, in its last bits, on
    the whole history before its window.)"""
    T = x.shape[0]
    finite = np.isfinite(x)
    vals = np.where(finite, x, 0.0)
    total = np.zeros(x.shape)
    count = np.zeros(x.shape)
    for offset in range(-back, window - back):  # oldest first: frame k + offset
        lo, hi = max(0, -offset), min(T, T - offset)  # the frames k it reaches
        if lo < hi:
            total[lo:hi] += vals[lo + offset : hi + offset]
            count[lo:hi] += finite[lo + offset : hi + offset]
    return _means(total, count)


def _means(total: NDArray[np.float64], count: NDArray[np.float64]) -> NDArray[np.float64]:
    """``total / count`` in place, NaN where the count is 0."""
    empty = count <= 0
    np.maximum(count, 1.0, out=count)
    np.divide(total, count, out=total)
    total[empty] = np.nan
    return total


class MovingAverageStepper:
    """Live form of the trailing ``moving_average`` (``centered=False``): a ring of the
    last ``window`` frames (finite samples, and which were finite), added up oldest
    first as :func:`_window_means` does. Work per frame: ``window`` additions."""

    def __init__(self, topology: Any, up_axis: int, inferred_noise_factor: float, *,
                 window: int, centered: bool) -> None:  # fmt: skip
        if centered:
            raise ValueError("a centred moving average looks ahead: it cannot run live")
        self.window = int(window)
        self._vals: NDArray[np.float64] | None = None
        self._finite: NDArray[np.bool_] | None = None
        self._n = 0  # frames seen

    def step(self, ys: Any, missing: Any, states: Any, dt: float) -> NDArray[np.float64]:
        """Smooth one frame: ys (B, J, 3) NaN where missing; returns (B, J, 3)."""
        if self._vals is None:
            self._vals = np.empty((self.window, *ys.shape))
            self._finite = np.empty((self.window, *ys.shape), dtype=bool)
        vals, finite, w = self._vals, self._finite, self.window
        slot = self._n % w
        np.isfinite(ys, out=finite[slot])
        vals[slot] = np.where(finite[slot], ys, 0.0)
        self._n += 1
        n = min(self._n, w)
        total = np.zeros(ys.shape)
        count = np.zeros(ys.shape)
        for i in range(self._n - n, self._n):  # oldest first
            total += vals[i % w]
            count += finite[i % w]
        return _means(total, count)


# --------------------------------------------------------------------------- 1€ filter


def one_euro(
    x: ArrayLike,
    fps: float = 30.0,
    *,
    timestamps: ArrayLike | None = None,
    mincutoff: float = 1.0,
    beta: float = 0.0,
    dcutoff: float = 1.0,
) -> NDArray[np.float64]:
    """The 1€ filter (Casiez, Roussel, Vogel 2012), vectorised over the batch.

    Each scalar component is filtered independently, exactly as in the paper's
    pseudo-code. With ``Te`` the time since the previous (filtered) sample::

        alpha(fc) = 1 / (1 + tau / Te),  tau = 1 / (2 pi fc)
        dx_k      = (x_k - x̂_{k-1}) / Te             (0 at the first sample)
        dx̂_k      = alpha(dcutoff) dx_k + (1 - alpha(dcutoff)) dx̂_{k-1}
        fc        = mincutoff + beta |dx̂_k|
        x̂_k       = alpha(fc) x_k + (1 - alpha(fc)) x̂_{k-1}

    The first finite sample of each component initialises ``x̂ = x`` and ``dx̂ = 0``.

    Missing samples (NaN) hold: the output repeats the last estimate and the filter
    state is left untouched, so at the next finite sample ``Te`` is the whole time
    elapsed since the last finite one (the 1€ filter has no motion model to predict
    with beyond its derivative estimate; holding is its standard behaviour). Output
    before a component's first finite sample is NaN.

    Parameters
    ----------
    x : array_like, shape (T, *batch, d) or (T,)
    fps : float
        Frame rate in Hz, used when ``timestamps`` is not given (``Te = 1 / fps``).
    timestamps : array_like, shape (T,), optional
        Frame times in seconds (strictly increasing); per-step ``Te`` is their difference.
    mincutoff : float
        Minimum cutoff frequency in Hz (> 0).
    beta : float
        Speed coefficient (>= 0).
    dcutoff : float
        Cutoff frequency in Hz of the derivative filter (> 0).

    Returns
    -------
    ndarray, same shape as ``x``
    """
    arr, shape = _as_series(x)
    for name, value in (("mincutoff", mincutoff), ("dcutoff", dcutoff)):
        if not np.isfinite(value) or value <= 0:
            raise ValueError(f"{name} must be a positive number of Hz, got {value!r}")
    if not np.isfinite(beta) or beta < 0:
        raise ValueError(f"beta must be >= 0, got {beta!r}")
    T = arr.shape[0]
    t = _time_steps(T, fps, timestamps)
    params = (float(mincutoff), float(beta), float(dcutoff))
    return _one_euro_call(arr.reshape(T, -1), t, params, None).reshape(shape)


def _one_euro_call(
    x: NDArray[np.float64], t: NDArray[np.float64], params: tuple[float, float, float],
    state: tuple[NDArray[Any], ...] | None,
) -> NDArray[np.float64]:  # fmt: skip
    """``one_euro_run`` (compiled, component by component) of ``x (T, M)`` from ``state``
    (None: a fresh one), its inputs as one type (read-only, C-ordered) in the batch and
    in the live stepper alike, so that numba compiles one version."""
    # numba, imported here: not at import tobitkf
    from tobitkf.smoothing._baseline_kernels import one_euro_run, one_euro_state

    if state is None:
        state = one_euro_state(x.shape[1])
    xs = readonly(np.ascontiguousarray(x, dtype=float))
    ts = readonly(np.ascontiguousarray(t, dtype=float))
    return one_euro_run(xs, ts, *params, *state)


# --------------------------------------------------------------------------- Kinect SDK filter


def kinect_double_exponential(
    x: ArrayLike,
    smoothing: float | None = None,
    correction: float | None = None,
    prediction: float | None = None,
    jitter_radius: float | None = None,
    max_deviation_radius: float | None = None,
    tracking_state: ArrayLike | None = None,
    *,
    preset: str = "default",
) -> NDArray[np.float64]:
    """Kinect SDK joint filter: Holt double exponential smoothing with jitter removal.

    A transcription of the SDK sample ``FilterDoubleExponential`` (``KinectJointFilter``),
    vectorised over joints. Per joint, with ``r`` the raw 3-D position, ``f`` the filtered
    position, ``b`` the trend and ``‖·‖`` the Euclidean norm over the last axis:

    - frame 1 after a (re)start: ``f = r``, ``b = 0``;
    - frame 2: ``f = (r + r_prev) / 2``, ``b = c (f - f_prev) + (1 - c) b_prev``;
    - later: jitter filter ``f' = r`` if ``‖r - f_prev‖ > J`` else
      ``f' = (d/J) r + (1 - d/J) f_prev`` with ``d = ‖r - f_prev‖``; then
      ``f = (1 - s) f' + s (f_prev + b_prev)`` and ``b = c (f - f_prev) + (1 - c) b_prev``;
    - output ``p = f + P b``, pulled back towards ``r`` so that ``‖p - r‖ <= M``:
      if ``e = ‖p - r‖ > M``, ``p = (M/e) p + (1 - M/e) r``.

    ``s, c, P, J, M`` = smoothing, correction, prediction, jitter radius (clamped to at
    least 0.1 mm as in the SDK), maximum deviation radius. The filter counts frames, not
    seconds: like the SDK it assumes the sensor's native rate.

    Tracking state (as in the SDK): INFERRED joints use ``2 J`` and ``2 M``. The SDK
    resets a joint's filter when its position is invalid (the sensor reports zeros);
    here a joint whose position has a NaN, or whose state is NOT_TRACKED, is invalid:
    its filter is reset and the output for that frame is the raw input (NaN stays NaN),
    as the SDK passes the invalid position through. One deliberate deviation: the SDK
    stores the invalid (zero) position as the "previous raw" sample, so its next valid
    frame is averaged with the origin (``f = (r + 0) / 2``), a jump halfway to the
    sensor. Here the next valid frame simply restarts the filter (``f = r``).

    Parameters
    ----------
    x : array_like, shape (T, *batch, 3)
        Joint positions in metres (any last-axis size works; the norm is over it).
    smoothing, correction, prediction, jitter_radius, max_deviation_radius : float, optional
        Override the preset's values.
    tracking_state : array_like of int, shape (T, *batch), optional
        0 = NOT_TRACKED, 1 = INFERRED, 2 = TRACKED (None: all tracked).
    preset : {"default", "v2_sample"}
        "default" = (0.5, 0.5, 0.5, 0.05, 0.04), "v2_sample" = (0.25, 0.25, 0.25, 0.03, 0.05).

    Returns
    -------
    ndarray, same shape as ``x``
    """
    consts = _kinect_constants(
        preset, smoothing, correction, prediction, jitter_radius, max_deviation_radius
    )
    arr = np.asarray(x, dtype=float)
    if arr.ndim < 2:
        raise ValueError(f"x must have shape (T, *batch, 3), got {arr.shape}")
    T = arr.shape[0]
    batch = arr.shape[1:-1]
    if tracking_state is None:
        state = np.full((T, *batch), 2, dtype=np.int8)
    else:
        state = np.asarray(tracking_state)
        if state.shape != (T, *batch):
            raise ValueError(
                f"tracking_state must have shape {(T, *batch)} to match x {arr.shape}, "
                f"got {state.shape}"
            )
    if not arr.size:  # nothing to filter
        return arr.copy()
    D = arr.shape[-1]
    out = _kinect_call(arr.reshape(T, -1, D), state.reshape(T, -1), consts, None)
    return out.reshape(arr.shape)


def _kinect_constants(preset: str, *values: float | None) -> tuple[float, ...]:
    """``(s, c, P, J, M)`` of :func:`kinect_double_exponential`: the preset's values
    overridden by ``values`` (smoothing, correction, prediction, jitter radius, maximum
    deviation radius; None keeps the preset's), checked; J at least 0.1 mm."""
    if preset not in KINECT_PRESETS:
        raise ValueError(f"unknown preset {preset!r}; valid presets: {sorted(KINECT_PRESETS)}")
    p = dict(KINECT_PRESETS[preset])
    for name, value in zip(_KINECT_PARAMS, values, strict=True):
        if value is not None:
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
            p[name] = float(value)
    for name in ("smoothing", "correction"):
        if p[name] > 1:
            raise ValueError(f"{name} must be in [0, 1], got {p[name]!r}")
    jitter0 = max(1e-4, p["jitter_radius"])
    return (p["smoothing"], p["correction"], p["prediction"], jitter0, p["max_deviation_radius"])


def _kinect_call(
    x: NDArray[np.float64], states: NDArray[Any], consts: tuple[float, ...],
    state: tuple[NDArray[Any], ...] | None,
) -> NDArray[np.float64]:  # fmt: skip
    """``kinect_run`` (compiled, joint by joint) of ``x (T, M, D)`` with tracking states
    ``(T, M)`` from filter ``state`` (None: a fresh one), its inputs as one type
    (read-only, C-ordered) in the batch and in the live stepper alike."""
    # numba, imported here: not at import tobitkf
    from tobitkf.smoothing._baseline_kernels import kinect_run, kinect_state

    if state is None:
        state = kinect_state(*x.shape[1:])
    xs = readonly(np.ascontiguousarray(x, dtype=float))
    st = readonly(np.ascontiguousarray(states, dtype=np.int8))
    return kinect_run(xs, st, *(float(v) for v in consts), *state)


# --------------------------------------------------------------------------- live steppers


class OneEuroStepper:
    """Live form of :func:`one_euro`: the compiled filter run on one frame from the state
    (estimate, derivative estimate, time of the last update, started) of the last one.

    The frame times are the cumulated steps, summed as the batch runner's
    ``np.cumsum(steps)`` does, so a stream gives exactly the batch numbers.
    """

    def __init__(self, topology: Any, up_axis: int, inferred_noise_factor: float, *,
                 mincutoff: float, beta: float, dcutoff: float) -> None:  # fmt: skip
        self.params = (float(mincutoff), float(beta), float(dcutoff))
        self._state: tuple[NDArray[Any], ...] | None = None
        self._time = 0.0

    def step(self, ys: Any, missing: Any, states: Any, dt: float) -> NDArray[np.float64]:
        """Smooth one frame: ys (B, J, 3) NaN where missing; returns (B, J, 3)."""
        if self._state is None:
            from tobitkf.smoothing._baseline_kernels import one_euro_state

            self._state = one_euro_state(ys.size)
        self._time = self._time + float(dt)
        out = _one_euro_call(ys.reshape(1, -1), np.array([self._time]), self.params, self._state)
        return out.reshape(ys.shape)


class KinectStepper:
    """Live form of ``kinect``: the compiled SDK filter run on one frame from the state
    (previous filtered, trend and raw positions, frames since the restart) of the last
    one. It reads the positions as given (``uses_positions``): a NOT_TRACKED joint
    passes its raw position through, as in the batch."""

    uses_positions = True

    def __init__(self, topology: Any, up_axis: int, inferred_noise_factor: float,
                 **params: Any) -> None:  # fmt: skip
        self.consts = _kinect_constants(params["preset"], *(params[n] for n in _KINECT_PARAMS))
        self._state: tuple[NDArray[Any], ...] | None = None

    def step(self, ys: Any, missing: Any, states: Any, dt: float,
             positions: Any = None) -> NDArray[np.float64]:  # fmt: skip
        """Smooth one frame of ``positions`` (B, J, 3) (default ``ys``) with their tracking
        ``states`` (B, J) or None (all tracked); returns (B, J, 3)."""
        pos = ys if positions is None else positions
        B, J, D = pos.shape
        if self._state is None:
            from tobitkf.smoothing._baseline_kernels import kinect_state

            self._state = kinect_state(B * J, D)
        st = np.full((1, B * J), 2, np.int8) if states is None else states.reshape(1, B * J)
        return _kinect_call(pos.reshape(1, B * J, D), st, self.consts, self._state).reshape(
            pos.shape
        )


# --------------------------------------------------------------------------- registration


def _check_savgol(params: dict[str, Any]) -> None:
    if params["polyorder"] >= params["window"]:
        raise ValueError(
            f"polyorder ({params['polyorder']}) must be less than window ({params['window']})"
        )


def _check_moving_average(params: dict[str, Any]) -> None:
    if params["centered"] and params["window"] % 2 == 0:
        raise ValueError(f"a centred moving average needs an odd window, got {params['window']}")


_MOVING_AVERAGE_WINDOW = 5  # frames, the default


def _fits(window: int, inp: SmoothInput, default: int) -> None:
    """A window longer than the recording does not smooth it, it replaces it (a window of
    1001 frames on 193 changed the data by 15 cm RMS): refused, with the numbers. A
    recording shorter than even the default window keeps the documented shrinking."""
    if window > inp.n_frames >= default:
        raise ValueError(
            f"window {window} frames is longer than the recording ({inp.n_frames} frames); "
            f"give window <= {inp.n_frames}"
        )


def _run_savgol(inp: SmoothInput, window: int, polyorder: int, max_gap: int | None) -> Any:
    _fits(window, inp, _SAVGOL["params"]["window"])
    return savgol(inp.ys, window, polyorder, max_gap=max_gap)


def _run_moving_average(inp: SmoothInput, window: int, centered: bool) -> Any:
    _fits(window, inp, _MOVING_AVERAGE_WINDOW)
    return moving_average(inp.ys, window, centered)


def _run_one_euro(inp: SmoothInput, **params: Any) -> Any:
    return one_euro(inp.ys, timestamps=np.cumsum(inp.steps), **params)


def _run_kinect(inp: SmoothInput, **params: Any) -> Any:
    return kinect_double_exponential(inp.positions, tracking_state=inp.tracking_state, **params)


_SAVGOL = {
    "params": {"window": 9, "polyorder": 3, "max_gap": None},
    "validators": {
        "window": odd_window,
        "polyorder": at_least_int(0),
        "max_gap": optional(at_least_int(0)),
    },
    "check": _check_savgol,
}
register_method("sgf", _run_savgol, description="Savitzky-Golay filter (offline)", **_SAVGOL)
register_method(
    "savgol", _run_savgol, description="Savitzky-Golay filter (offline; same as sgf)", **_SAVGOL
)
register_method(
    "one_euro",
    _run_one_euro,
    params={"mincutoff": 1.0, "beta": 0.0, "dcutoff": 1.0},
    validators={"mincutoff": positive_float, "beta": nonneg_float, "dcutoff": positive_float},
    description="1-euro filter (Casiez et al. 2012)",
    causal=True,
    live=OneEuroStepper,
)
register_method(
    "kinect",
    _run_kinect,
    params={
        "preset": "default",
        "smoothing": None,
        "correction": None,
        "prediction": None,
        "jitter_radius": None,
        "max_deviation_radius": None,
    },
    validators={
        "preset": one_of(*KINECT_PRESETS),
        "smoothing": optional(unit_float),
        "correction": optional(unit_float),
        "prediction": optional(nonneg_float),
        "jitter_radius": optional(nonneg_float),
        "max_deviation_radius": optional(nonneg_float),
    },
    description="Kinect SDK double-exponential joint filter",
    causal=True,
    live=KinectStepper,
)
register_method(
    "moving_average",
    _run_moving_average,
    params={"window": _MOVING_AVERAGE_WINDOW, "centered": True},
    validators={"window": at_least_int(1), "centered": as_bool},
    description="moving average (centred, or trailing: centered=False)",
    check=_check_moving_average,
    causal=lambda params: not params["centered"],
    live=MovingAverageStepper,
)
