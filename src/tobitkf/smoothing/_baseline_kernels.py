"""Compiled kernels of the Kinect SDK joint filter and the 1€ filter (numba, ``cache=True``).

Imported lazily by :func:`tobitkf.smoothing.baselines.kinect_double_exponential` and
:func:`~tobitkf.smoothing.baselines.one_euro`, so that importing tobitkf does not import
numba. Each kernel takes its filter state as arguments and updates it in place: the
batch functions pass fresh state for a whole recording, the live steppers the state
they carry from frame to frame, so a stream gives exactly the batch numbers. The
arithmetic is the documented form of those functions, component by component, in the
same order of operations (the Kinect norm over the last axis summed in axis order, as
numpy does); tests/test_baselines.py checks both against independent loops.
"""

from __future__ import annotations

import math

import numpy as np

from tobitkf.smoothing._numba_cache import njit

_NOT_TRACKED = 0
_INFERRED = 1


def kinect_state(M: int, D: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fresh state of :func:`kinect_run` for ``M`` joints of ``D`` axes."""
    return np.zeros((M, D)), np.zeros((M, D)), np.zeros((M, D)), np.zeros(M, dtype=np.int64)


def one_euro_state(M: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fresh state of :func:`one_euro_run` for ``M`` components: estimate (NaN until the
    first finite sample), derivative estimate, time of the last update, started."""
    return np.full(M, np.nan), np.zeros(M), np.full(M, np.nan), np.zeros(M, dtype=np.bool_)


@njit(cache=True, nogil=True)
def one_euro_run(
    x: np.ndarray,
    t: np.ndarray,
    mincutoff: float,
    beta: float,
    dcutoff: float,
    xhat: np.ndarray,
    dxhat: np.ndarray,
    t_prev: np.ndarray,
    started: np.ndarray,
) -> np.ndarray:
    """``x (T, M)`` at times ``t (T,)`` -> filtered ``(T, M)``, the state ``(M,)`` each
    (:func:`one_euro_state`) updated in place. A missing (non-finite) sample holds: the
    output repeats the estimate and the state is left as it is."""
    T, M = x.shape
    out = np.empty((T, M))
    tau_d = 1.0 / (2.0 * np.pi * dcutoff)
    for k in range(T):
        tk = t[k]
        for m in range(M):
            xk = x[k, m]
            if math.isfinite(xk):
                if not started[m]:  # first finite sample: x̂ = x, dx̂ = 0
                    xhat[m] = xk
                    t_prev[m] = tk
                    started[m] = True
                else:
                    te = tk - t_prev[m]
                    dx = (xk - xhat[m]) / te
                    a_d = 1.0 / (1.0 + tau_d / te)
                    d = a_d * dx + (1.0 - a_d) * dxhat[m]
                    fc = mincutoff + beta * abs(d)
                    a = 1.0 / (1.0 + (1.0 / (2.0 * np.pi * fc)) / te)
                    xhat[m] = a * xk + (1.0 - a) * xhat[m]
                    dxhat[m] = d
                    t_prev[m] = tk
            out[k, m] = xhat[m]
    return out


@njit(cache=True, nogil=True)
def kinect_run(
    arr: np.ndarray,
    state: np.ndarray,
    s: float,
    c: float,
    pred: float,
    jitter0: float,
    maxdev0: float,
    f_prev: np.ndarray,
    b_prev: np.ndarray,
    r_prev: np.ndarray,
    count: np.ndarray,
) -> np.ndarray:
    """``arr (T, M, D)``, ``state (T, M)`` int8 -> filtered ``(T, M, D)``.

    Filter state, updated in place (:func:`kinect_state` makes a fresh one): the
    previous filtered position ``f_prev``, trend ``b_prev`` and raw position ``r_prev``
    ``(M, D)``, and the valid frames since each joint's (re)start ``count (M,)``."""
    T, M, D = arr.shape
    out = np.empty((T, M, D))
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
