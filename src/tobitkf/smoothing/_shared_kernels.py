"""Compiled kernels of :mod:`tobitkf.smoothing.robust_shared` (numba, ``cache=True``):
the carried samples' error from the structure function of each joint's offset from its
parent, and the sums the guesses' error is estimated from. Imported lazily (numba on
first use)."""

from __future__ import annotations

import math

import numpy as np

from tobitkf.smoothing._numba_cache import njit

_jit = njit(cache=True, nogil=True)


@_jit
def carried_sd(
    ys: np.ndarray,  # (T, B, J, D)
    acc: np.ndarray,  # (T, B, J) accepted
    carried: np.ndarray,  # (T, B, J) carried
    parents: np.ndarray,
    order: np.ndarray,  # the joints from the root outwards
    max_lag: int,
    min_pairs: int,
    max_starts: int,
) -> np.ndarray:
    """Per-axis standard deviation ``(T, B, J)`` of each carried sample's error, NaN at
    every other sample (:mod:`tobitkf.smoothing.robust_shared`): ``S(Δ) / D`` of the
    joint's offset from its parent at the sample's lag ``Δ`` to the offset it carries
    (the last frame both were accepted, else the next), plus its parent's variance where
    the parent is carried too. ``S(Δ)`` is the mean ``|o(t + Δ) - o(t)|²`` over pairs
    known at both ends, from at most ``max_starts`` start frames ``t`` evenly spread
    (every ``ceil(T / max_starts)``-th frame); a lag with fewer than ``min_pairs`` pairs,
    or beyond ``max_lag``, takes the long-lag limit ``2 Var(o)``. Each body on its own."""
    T, B, J, D = ys.shape
    sd = np.full((T, B, J), np.nan)
    off = np.empty((T, D))
    known = np.empty(T, dtype=np.bool_)
    lag = np.empty(T, dtype=np.int64)
    mean = np.empty(D)
    S = np.empty(max(max_lag, 0) + 2)
    stride = max(1, -(-T // max(max_starts, 1)))
    for b in range(B):
        for k in range(J):
            j = order[k]
            p = parents[j]
            if p < 0:
                continue
            need = -1
            last = -1
            for t in range(T):  # the lag to the last good offset (forwards)
                known[t] = acc[t, b, j] and acc[t, b, p]
                if known[t]:
                    last = t
                    for a in range(D):
                        off[t, a] = ys[t, b, j, a] - ys[t, b, p, a]
                lag[t] = t - last if last >= 0 else -1
            nxt = -1
            for t in range(T - 1, -1, -1):  # none before: to the next one
                if known[t]:
                    nxt = t
                if lag[t] < 0:
                    lag[t] = nxt - t if nxt >= 0 else 0
                if carried[t, b, j] and lag[t] > need:
                    need = lag[t]
            if need < 0:
                continue
            n_lags = min(need, max_lag, T - 1)
            # the long-lag limit: 2 x the sample variance, summed over the axes
            n = 0
            mean[:] = 0.0
            for t in range(T):
                if known[t]:
                    n += 1
                    for a in range(D):
                        mean[a] += off[t, a]
            for a in range(D):
                mean[a] /= max(n, 1)
            ss = 0.0
            for t in range(T):
                if known[t]:
                    for a in range(D):
                        ss += (off[t, a] - mean[a]) ** 2
            limit = 2.0 * ss / max(n - 1, 1)
            S[0] = 0.0
            for d in range(1, n_lags + 1):
                s = 0.0
                m = 0
                for t in range(0, T - d, stride):
                    if known[t] and known[t + d]:
                        m += 1
                        for a in range(D):
                            s += (off[t + d, a] - off[t, a]) ** 2
                S[d] = s / m if m >= min_pairs else limit
            for t in range(T):
                if carried[t, b, j]:
                    v = (S[lag[t]] if lag[t] <= n_lags else limit) / D
                    if carried[t, b, p]:
                        v += sd[t, b, p] ** 2
                    sd[t, b, j] = math.sqrt(v)
    return sd


@_jit
def guess_sums(
    ys: np.ndarray,  # (T, B, J, D)
    acc: np.ndarray,  # (T, B, J) accepted
    inferred: np.ndarray,  # (T, B, J)
) -> np.ndarray:
    """Per body ``(B, 4)``: the sum of the squared steps at a change of tracking state and
    their number, then the same of the steps between tracked samples of the joints with
    guesses (:func:`tobitkf.smoothing.robust_shared.guess_error_variance`); a step counts
    where both its samples were accepted and are finite."""
    T, B, J, D = ys.shape
    out = np.zeros((B, 4))
    has = np.zeros((B, J), dtype=np.bool_)  # the joints with an accepted guess
    for t in range(T):
        for b in range(B):
            for j in range(J):
                if inferred[t, b, j] and acc[t, b, j] and math.isfinite(ys[t, b, j, 0]):
                    has[b, j] = True
    for t in range(1, T):
        for b in range(B):
            for j in range(J):
                if not (acc[t, b, j] and acc[t - 1, b, j]):
                    continue
                if not (math.isfinite(ys[t, b, j, 0]) and math.isfinite(ys[t - 1, b, j, 0])):
                    continue
                change = inferred[t, b, j] != inferred[t - 1, b, j]
                if not (change or (has[b, j] and not inferred[t, b, j])):
                    continue
                d2 = 0.0
                for a in range(D):
                    d2 += (ys[t, b, j, a] - ys[t - 1, b, j, a]) ** 2
                k = 0 if change else 2
                out[b, k] += d2
                out[b, k + 1] += 1.0
    return out
