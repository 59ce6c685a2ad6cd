"""Compiled kernel of the Kinect SDK joint filter (numba, ``cache=True``).

Imported lazily by :func:`tobitkf.smoothing.baselines.kinect_double_exponential`, so that
importing tobitkf does not import numba. The kernel is the same arithmetic as the
documented numpy form of that function, joint by joint, in the same order of operations
(the norm over the last axis summed in axis order, as numpy does), so the outputs are
the same numbers; tests/test_baselines.py checks it against an independent loop.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_NOT_TRACKED = 0
_INFERRED = 1


@njit(cache=True, nogil=True)
def kinect_run(
    arr: np.ndarray,
    state: np.ndarray,
    s: float,
    c: float,
    pred: float,
    jitter0: float,
    maxdev0: float,
) -> np.ndarray:
    """``arr (T, M, D)``, ``state (T, M)`` int8 -> filtered ``(T, M, D)``."""
    T, M, D = arr.shape
    out = np.empty_like(arr)
    f_prev = np.zeros((M, D))
    b_prev = np.zeros((M, D))
    r_prev = np.zeros((M, D))
    count = np.zeros(M, dtype=np.int64)
    rr = np.empty(D)
    f = np.empty(D)
    b = np.empty(D)
    pk = np.empty(D)
    for k in range(T):
        for j in range(M):
            st = state[k, j]
            valid = st != _NOT_TRACKED
            for a in range(D):
                if not math.isfinite(arr[k, j, a]):
                    valid = False
            if not valid:
                for a in range(D):
                    out[k, j, a] = arr[k, j, a]
                count[j] = 0
                continue
            jit = 2.0 * jitter0 if st == _INFERRED else jitter0
            mdev = 2.0 * maxdev0 if st == _INFERRED else maxdev0
            for a in range(D):
                rr[a] = arr[k, j, a]
            n = count[j]
            if n == 0:
                for a in range(D):
                    f[a] = rr[a]
                    b[a] = 0.0
            elif n == 1:
                for a in range(D):
                    f[a] = 0.5 * (rr[a] + r_prev[j, a])
                    b[a] = c * (f[a] - f_prev[j, a]) + (1.0 - c) * b_prev[j, a]
            else:
                ss = 0.0
                for a in range(D):
                    q = rr[a] - f_prev[j, a]
                    ss = q * q if a == 0 else ss + q * q
                d = math.sqrt(ss)
                w = d / jit
                for a in range(D):
                    fj = w * rr[a] + (1.0 - w) * f_prev[j, a] if d <= jit else rr[a]
                    f[a] = (1.0 - s) * fj + s * (f_prev[j, a] + b_prev[j, a])
                    b[a] = c * (f[a] - f_prev[j, a]) + (1.0 - c) * b_prev[j, a]
            ss = 0.0
            for a in range(D):
                pk[a] = f[a] + pred * b[a]
                q = pk[a] - rr[a]
                ss = q * q if a == 0 else ss + q * q
            e = math.sqrt(ss)
            ratio = 1.0
            if e > mdev:
                ratio = mdev / (e if e > 0 else 1.0)
            for a in range(D):
                if ratio < 1.0:
                    out[k, j, a] = ratio * pk[a] + (1.0 - ratio) * rr[a]
                else:
                    out[k, j, a] = pk[a]
                r_prev[j, a] = rr[a]
                f_prev[j, a] = f[a]
                b_prev[j, a] = b[a]
            count[j] = n + 1
    return out
