"""Compiled kernels of a smoothed output's states (numba, ``cache=True``).

What :mod:`tobitkf.smoothing.output_states` works out of every method's output, in one
pass over each array instead of numpy's temporaries: which estimates are finite, whether
the posterior standard deviations need the NaN rule or break a sequence's checks, and
the :class:`~tobitkf.skeleton.sequence.SampleState` of every sample. Arrays are time
first with the bodies and joints flattened into one axis ``N``; the wrappers in
:mod:`~tobitkf.smoothing.output_states` pass them C-ordered and read-only (one compiled
version). tests/test_output_states.py checks each against its numpy definition.

Imported lazily (numba is imported only when a method runs).
"""

from __future__ import annotations

import math

import numpy as np

from tobitkf.skeleton.sequence import SampleState, TrackingState
from tobitkf.smoothing._numba_cache import njit

# the codes as plain ints (frozen into the kernels), from the enums themselves
_MEASURED = int(SampleState.MEASURED)
_REJECTED = int(SampleState.REJECTED)
_MISSING = int(SampleState.MISSING)
_EXTRAPOLATED = int(SampleState.EXTRAPOLATED)
_NONE = int(SampleState.NONE)
_NOT_TRACKED = int(TrackingState.NOT_TRACKED)
_INFERRED = int(TrackingState.INFERRED)
_TRACKED = int(TrackingState.TRACKED)


@njit(cache=True, nogil=True)
def finite_samples(est: np.ndarray) -> tuple[np.ndarray, bool]:
    """``est (T, N, D)`` -> ``(T, N)`` True where every coordinate is finite, and
    whether any coordinate is infinite (``np.isfinite(est).all(-1)``,
    ``np.isinf(est).any()``)."""
    T, N, D = est.shape
    finite = np.empty((T, N), dtype=np.bool_)
    has_inf = False
    for t in range(T):
        for n in range(N):
            ok = True
            for d in range(D):
                x = est[t, n, d]
                if not math.isfinite(x):
                    ok = False
                    if not math.isnan(x):
                        has_inf = True
            finite[t, n] = ok
    return finite, has_inf


@njit(cache=True, nogil=True)
def std_flags(std: np.ndarray, finite: np.ndarray) -> tuple[bool, bool]:
    """``std (T, N)`` of estimates ``finite (T, N)``: whether a sample without an
    estimate has a std other than NaN (``(~finite & ~isnan(std)).any()``), and whether a
    sample with one has an infinite or negative std
    (``(finite & (isinf(std) | (std < 0))).any()``)."""
    T, N = std.shape
    stray = 0
    bad = 0
    for t in range(T):
        for n in range(N):  # without branches: vectorised
            s = std[t, n]
            f = finite[t, n]
            stray += (not f) & (s == s)  # not NaN
            bad += f & ((s < 0.0) | (s == math.inf))  # -inf < 0
    return stray > 0, bad > 0


@njit(cache=True, nogil=True)
def sample_states(
    missing: np.ndarray, rejected: np.ndarray, finite: np.ndarray, causal: bool
) -> np.ndarray:
    """SampleState codes ``(T, N)`` int8 of :func:`tobitkf.smoothing.output_states.
    sample_states` (same arguments, ``(T, N)`` each)."""
    T, N = missing.shape
    first = np.full(N, T, dtype=np.int64)  # first used sample of each column (none: T)
    last = np.full(N, -1, dtype=np.int64)  # last one (none: -1)
    if not causal:
        for t in range(T):
            for n in range(N):
                if not missing[t, n] and not rejected[t, n]:
                    if first[n] == T:
                        first[n] = t
                    last[n] = t
    out = np.empty((T, N), dtype=np.int8)
    for t in range(T):
        for n in range(N):
            if not finite[t, n]:
                s = _NONE
            elif not missing[t, n]:
                s = _REJECTED if rejected[t, n] else _MEASURED
            elif first[n] <= t <= last[n]:
                s = _MISSING
            else:
                s = _EXTRAPOLATED
            out[t, n] = s
    return out


@njit(cache=True, nogil=True)
def tracking_states(
    states: np.ndarray, sample: np.ndarray, has_states: bool
) -> tuple[np.ndarray, np.ndarray]:
    """The output's tracking states ``(T, N)`` int8 of
    :func:`tobitkf.smoothing.output_states.output_tracking` (``states`` is read only
    with ``has_states``), and the number of filled samples of each column ``(N,)``."""
    T, N = sample.shape
    out = np.empty((T, N), dtype=np.int8)
    filled = np.zeros(N, dtype=np.int64)
    for t in range(T):
        for n in range(N):
            s = sample[t, n]
            if _REJECTED <= s <= _EXTRAPOLATED:  # filled
                out[t, n] = _INFERRED
                filled[n] += 1
            elif s == _NONE:
                out[t, n] = _NOT_TRACKED
            else:
                out[t, n] = states[t, n] if has_states else _TRACKED
    return out, filled
