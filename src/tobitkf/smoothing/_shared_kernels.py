"""Compiled kernel of :mod:`tobitkf.smoothing.robust_shared` (numba, ``cache=True``):
the structure function of a joint's offset from its parent. Imported lazily (numba on
first use)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_jit = njit(cache=True, nogil=True)


@_jit
def offset_structure(off: np.ndarray, n_lags: int, min_pairs: int) -> np.ndarray:
    """``S (n_lags + 2, B)`` of ``off (T, B, D)`` (NaN where not known): per body, the
    mean of ``|o(t + d) - o(t)|²`` over the pairs known at both ends for ``d = 0 ..
    n_lags``, and last the stationary limit ``2 Var(o)`` (the sum over the axes of the
    sample variances), which also stands for a lag with fewer than ``min_pairs`` pairs.
    Each body on its own, in a fixed order."""
    T, B, D = off.shape
    S = np.empty((n_lags + 2, B))
    mean = np.empty(D)
    for b in range(B):
        n = 0
        mean[:] = 0.0
        for t in range(T):
            if math.isfinite(off[t, b, 0]):
                n += 1
                for a in range(D):
                    mean[a] += off[t, b, a]
        for a in range(D):
            mean[a] /= max(n, 1)
        ss = 0.0
        for t in range(T):
            if math.isfinite(off[t, b, 0]):
                for a in range(D):
                    ss += (off[t, b, a] - mean[a]) ** 2
        limit = 2.0 * ss / max(n - 1, 1)
        S[0, b] = 0.0
        S[n_lags + 1, b] = limit
        for d in range(1, n_lags + 1):
            s = 0.0
            m = 0
            for t in range(T - d):
                if math.isfinite(off[t, b, 0]) and math.isfinite(off[t + d, b, 0]):
                    m += 1
                    for a in range(D):
                        s += (off[t + d, b, a] - off[t, b, a]) ** 2
            S[d, b] = s / m if m >= min_pairs else limit
    return S
