"""The running median of :mod:`tobitkf.smoothing.robust_scale`, compiled (numba,
``cache=True``): per series, the median of the values present in a centred window, as
``np.nanmedian`` gives it (the middle value, or the mean of the two middle ones; NaN
when the window holds none). In NumPy it sorted a copy of every window."""

from __future__ import annotations

import numpy as np

from tobitkf.smoothing._numba_cache import njit


@njit(cache=True, nogil=True)
def middle(w: np.ndarray, n: int) -> float:
    """The median of the first ``n`` values of ``w``, sorted, as ``np.nanmedian`` gives it:
    the middle value, or the mean of the two middle ones; NaN for none."""
    if n == 0:
        return np.nan
    if n % 2 == 1:
        return w[n // 2]
    return (w[n // 2 - 1] + w[n // 2]) / 2


@njit(cache=True, nogil=True)
def insert_sorted(buf: np.ndarray, n: int, v: float) -> None:
    """Insert ``v`` into the sorted ``buf[:n]``, so that ``buf[:n + 1]`` is sorted (for
    the few values of a window: cheaper than a sort, and no sort to compile)."""
    i = n
    while i > 0 and buf[i - 1] > v:
        buf[i] = buf[i - 1]
        i -= 1
    buf[i] = v


@njit(cache=True, nogil=True)
def running_median(y: np.ndarray, window: int, out: np.ndarray) -> None:
    """``out[t, k]``: the median of the non-NaN ``y[t - h .. t + h, k]`` (``h = window //
    2``, an odd ``window`` centred on ``t``, cut at both ends), for ``y (T, N)``."""
    T, N = y.shape
    h = window // 2
    buf = np.empty(window)
    for k in range(N):
        for t in range(T):
            n = 0
            for s in range(max(0, t - h), min(T, t + h + 1)):
                v = y[s, k]
                if not np.isnan(v):
                    insert_sorted(buf, n, v)
                    n += 1
            out[t, k] = middle(buf, n)
