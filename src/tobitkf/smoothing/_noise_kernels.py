"""Compiled kernels of the robust smoother's fitted-noise model (numba, ``cache=True``).

The model is the robust smoother's (:mod:`tobitkf.smoothing._robust_kernels`): per axis
of each joint an integrated Ornstein–Uhlenbeck velocity ``(x, v)``,
``dv = -v/tau dt + sqrt(q) dW``, ``dx = v dt``, discretised exactly per step
(:func:`~tobitkf.smoothing._robust_kernels.ou_coeffs`), plus a *coloured* measurement
error ``c``, an OU process of stationary variance ``sc2`` and correlation time
``tau_c``: ``c' = phi c + n``, ``phi = exp(-dt/tau_c)``, ``var n = sc2 (1 - phi²)``. The
measurement is ``y = x + c + w``, ``w ~ N(0, r * rscale)``: ``H = [1, 0, 1]``. With
``sc2 = 0`` it is exactly the smoother's two-state model.

Each track starts at its first sample with a diffuse prior on the position, so the first
sample only initialises the state: ``E x0 = y0``, ``v0 ~ N(0, q tau / 2)`` (the stationary
velocity variance; 1 for ``tau = inf``), ``c0 ~ N(0, sc2)``, ``var x0 = r + sc2``,
``cov(x0, c0) = -sc2`` (the posterior of ``x0 = y0 - c0 - w0``).

:func:`filter_sums` gives the pieces of the exact Gaussian log-likelihood of the other
samples (prediction-error decomposition); :func:`smooth_run` is the Kalman filter + RTS
smoother of the same model and returns the estimate of ``x`` (the coloured error is
removed with the white one). The three axes share one covariance (same variances, same
missing samples). Imported lazily (numba on first use).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from tobitkf.smoothing._robust_kernels import ou_table

_jit = njit(cache=True, nogil=True)


@_jit
def filter_sums(
    yk: np.ndarray,  # (T, N, 3) samples of N tracks, NaN = not used
    rscale: np.ndarray,  # (T, N) measurement-variance multiplier of each sample
    steps: np.ndarray,  # (T,) seconds before each frame
    ou: np.ndarray,  # (T, 5) ou_table(steps, tau)
    frames: np.ndarray,  # (M,) int64 frame indices to run over, increasing
    restart: np.ndarray,  # (M,) bool: every track starts afresh at this frame
    q: float,
    r: float,
    sc2: float,
    v0: float,  # initial velocity variance (q tau / 2)
    tau_c: float,
) -> tuple:
    """``(sum e²/S, sum log S, n)`` over the samples after each track's first one in every
    stretch between restarts, ``n`` scalar samples (three axes per joint-frame, sharing
    ``S``). The log-likelihood is ``-(n log 2π + sum log S + sum e²/S) / 2``
    (:func:`loglik`); scaling ``q, r, sc2, v0`` by ``s`` scales ``S`` by ``s``."""
    N = yk.shape[1]
    M = frames.shape[0]
    se = 0.0
    sl = 0.0
    n = 0
    # time outside, tracks inside: the tracks' recursions are independent, so the CPU
    # overlaps them (one track's recursion is a chain of divisions)
    X = np.zeros((N, 9))  # (x, v, c) of the three axes
    P = np.zeros((N, 6))  # p00, p01, p02, p11, p12, p22
    started = np.zeros(N, dtype=np.bool_)
    lastS = np.full(N, np.nan)
    lastlog = np.zeros(N)
    for m in range(M):
        t = frames[m]
        if restart[m]:
            started[:] = False
        phi = math.exp(-steps[t] / tau_c)  # tau_c >= one frame: 1 - phi² is exact
        om2 = 1.0 - phi * phi
        a, rr = ou[t, 0], ou[t, 1]
        qa, qb, qc = q * ou[t, 2], q * ou[t, 3], q * ou[t, 4]
        for j in range(N):
            y0, y1, y2 = yk[t, j, 0], yk[t, j, 1], yk[t, j, 2]
            ok = math.isfinite(y0)
            if not started[j]:
                if ok:
                    rv = r * rscale[t, j]
                    P[j, 0], P[j, 1], P[j, 2] = rv + sc2, 0.0, -sc2
                    P[j, 3], P[j, 4], P[j, 5] = v0, 0.0, sc2
                    X[j, 0], X[j, 1], X[j, 2] = y0, 0.0, 0.0
                    X[j, 3], X[j, 4], X[j, 5] = y1, 0.0, 0.0
                    X[j, 6], X[j, 7], X[j, 8] = y2, 0.0, 0.0
                    started[j] = True
                continue
            p00, p01, p02, p11, p12, p22 = P[j, 0], P[j, 1], P[j, 2], P[j, 3], P[j, 4], P[j, 5]
            n00 = p00 + 2 * a * p01 + a * a * p11 + qa
            n01 = rr * (p01 + a * p11) + qb
            n11 = rr * rr * p11 + qc
            n02 = phi * (p02 + a * p12)
            n12 = phi * rr * p12
            n22 = phi * phi * p22 + sc2 * om2
            for i in range(3):
                X[j, 3 * i] += a * X[j, 3 * i + 1]
                X[j, 3 * i + 1] *= rr
                X[j, 3 * i + 2] *= phi
            if not ok:
                P[j, 0], P[j, 1], P[j, 2], P[j, 3], P[j, 4], P[j, 5] = n00, n01, n02, n11, n12, \
                    n22  # fmt: skip
                continue
            h0 = n00 + n02
            h1 = n01 + n12
            h2 = n02 + n22
            S = h0 + h2 + r * rscale[t, j]
            iS = 1.0 / S
            k0, k1, k2 = h0 * iS, h1 * iS, h2 * iS
            e = y0 - X[j, 0] - X[j, 2]
            f = y1 - X[j, 3] - X[j, 5]
            g = y2 - X[j, 6] - X[j, 8]
            se += (e * e + f * f + g * g) * iS
            if S != lastS[j]:  # the covariance settles: most steps repeat the last S
                lastS[j] = S
                lastlog[j] = 3 * math.log(S)
            sl += lastlog[j]
            n += 3
            X[j, 0] += k0 * e
            X[j, 1] += k1 * e
            X[j, 2] += k2 * e
            X[j, 3] += k0 * f
            X[j, 4] += k1 * f
            X[j, 5] += k2 * f
            X[j, 6] += k0 * g
            X[j, 7] += k1 * g
            X[j, 8] += k2 * g
            P[j, 0], P[j, 1], P[j, 2] = n00 - k0 * h0, n01 - k0 * h1, n02 - k0 * h2
            P[j, 3], P[j, 4], P[j, 5] = n11 - k1 * h1, n12 - k1 * h2, n22 - k2 * h2
    return se, sl, n


@_jit
def loglik(
    yk: np.ndarray,
    rscale: np.ndarray,
    steps: np.ndarray,
    frames: np.ndarray,
    restart: np.ndarray,
    q: float,
    r: float,
    sc2: float,
    tau: float,
    tau_c: float,
) -> tuple:
    """``(log-likelihood, n)`` of the model with these parameters (:func:`filter_sums`)."""
    v0 = q * tau / 2 if math.isfinite(tau) else 1.0
    ou = ou_table(steps, tau)
    se, sl, n = filter_sums(yk, rscale, steps, ou, frames, restart, q, r, sc2, v0, tau_c)
    return -0.5 * (n * math.log(2 * math.pi) + sl + se), n


#: columns (joints of all bodies) a block of :func:`smooth_run` runs together: time is
#: the outer loop inside a block, so each frame reads a contiguous row of the block
#: instead of one joint's samples at a stride of the whole batch
SMOOTH_BLOCK = 16


@_jit
def smooth_run(
    yk: np.ndarray,  # (T, B, J, 3) samples, NaN = none
    rvar: np.ndarray,  # (T, B, J) measurement variance of each sample
    steps: np.ndarray,  # (T,)
    q: np.ndarray,  # (T, B, J) OU velocity noise density of the step before each frame
    sc2: np.ndarray,  # (B, J) coloured-error variance
    tau: float,
    tau_c: np.ndarray,  # (B, J) coloured-error correlation time
    est: np.ndarray,  # out (T, B0, J, 3): the estimate of x
    var: np.ndarray,  # out (T, B0, J): its smoothed variance
    b0: int,  # body b is written at b0 + b (a chunk of the bodies of est and var)
) -> None:
    """Kalman filter + RTS smoother of the three-state model per joint: the estimate of
    ``x`` and its variance (NaN for a joint without samples). As
    :func:`~tobitkf.smoothing._robust_kernels.ou_smooth_run`, the filter starts at frame
    0 from the joint's first sample (velocity 0, the prior of :func:`filter_sums` with
    the ``q`` of that sample's frame) and is then updated with every sample, the first
    one included: with ``sc2 = 0`` it is exactly that two-state smoother.

    The joints run in blocks of :data:`SMOOTH_BLOCK`, time outside, the block's joints
    inside (each joint's arithmetic is that of its own recursion: the blocks change
    the memory order, not the numbers). The RTS pass recomputes each prediction from
    the stored filtered moments with the forward pass's expressions (same values)
    instead of storing it."""
    T, B, J = yk.shape[0], yk.shape[1], yk.shape[2]
    N = B * J
    W = min(SMOOTH_BLOCK, N)
    X = np.empty((T, W, 9))  # filtered (x, v, c) of each axis
    Pf = np.empty((T, W, 6))  # filtered p00, p01, p02, p11, p12, p22
    S = np.empty((W, 6))  # smoothed covariance of the frame after
    first = np.empty(W, dtype=np.int64)
    cb = np.empty(W, dtype=np.int64)  # each column's body, joint, tau_c index and sc2
    cj = np.empty(W, dtype=np.int64)
    cu = np.empty(W, dtype=np.int64)
    cs = np.empty(W)
    ou = ou_table(steps, tau)
    # exp(-dt / tau_c) per frame for each distinct tau_c (a few per body: one per region)
    # (found by hand: np.unique would add seconds to the compilation)
    tcs = np.empty(N)
    ui = np.empty(N, dtype=np.int64)
    nu = 0
    for n in range(N):
        v = tau_c[n // J, n % J]
        u = 0
        while u < nu and tcs[u] != v:
            u += 1
        if u == nu:
            tcs[nu] = v
            nu += 1
        ui[n] = u
    phis = np.empty((T, nu))
    for u in range(nu):
        for t in range(T):
            phis[t, u] = math.exp(-steps[t] / tcs[u])
    for n0 in range(0, N, W):
        w_n = min(W, N - n0)
        for w in range(w_n):
            b, j = (n0 + w) // J, (n0 + w) % J
            cb[w], cj[w], cu[w], cs[w] = b, j, ui[n0 + w], sc2[b, j]
            first[w] = -1
        for t in range(T):  # each column's first sample
            for w in range(w_n):
                if first[w] < 0 and math.isfinite(yk[t, cb[w], cj[w], 0]):
                    first[w] = t
        for w in range(w_n):
            if first[w] < 0:  # no sample: no estimate
                for t in range(T):
                    var[t, b0 + cb[w], cj[w]] = math.nan
                    for i in range(3):
                        est[t, b0 + cb[w], cj[w], i] = math.nan
        for t in range(T):
            a, rr = ou[t, 0], ou[t, 1]
            for w in range(w_n):
                fw = first[w]
                if fw < 0:
                    continue
                b, j, sj = cb[w], cj[w], cs[w]
                if t > 0:
                    phi, qq = phis[t, cu[w]], q[t, b, j]
                    for i in range(3):
                        X[t, w, 3 * i] = X[t - 1, w, 3 * i] + a * X[t - 1, w, 3 * i + 1]
                        X[t, w, 3 * i + 1] = rr * X[t - 1, w, 3 * i + 1]
                        X[t, w, 3 * i + 2] = phi * X[t - 1, w, 3 * i + 2]
                    p00, p01, p02 = Pf[t - 1, w, 0], Pf[t - 1, w, 1], Pf[t - 1, w, 2]
                    p11, p12, p22 = Pf[t - 1, w, 3], Pf[t - 1, w, 4], Pf[t - 1, w, 5]
                    n00 = p00 + 2 * a * p01 + a * a * p11 + qq * ou[t, 2]
                    n01 = rr * (p01 + a * p11) + qq * ou[t, 3]
                    n11 = rr * rr * p11 + qq * ou[t, 4]
                    n02 = phi * (p02 + a * p12)
                    n12 = phi * rr * p12
                    n22 = phi * phi * p22 + sj * (1.0 - phi * phi)
                    p00, p01, p11, p02, p12, p22 = n00, n01, n11, n02, n12, n22
                else:  # frame 0 starts at the first sample, as ou_smooth_run
                    v0 = q[fw, b, j] * tau / 2 if math.isfinite(tau) else 1.0
                    rf = rvar[fw, b, j]
                    p00, p01, p02, p11, p12, p22 = rf + sj, 0.0, -sj, v0, 0.0, sj
                    for i in range(3):
                        X[t, w, 3 * i] = yk[fw, b, j, i]
                        X[t, w, 3 * i + 1] = 0.0
                        X[t, w, 3 * i + 2] = 0.0
                if math.isfinite(yk[t, b, j, 0]):
                    h0 = p00 + p02
                    h1 = p01 + p12
                    h2 = p02 + p22
                    Sv = h0 + h2 + rvar[t, b, j]
                    iS = 1.0 / Sv
                    k0, k1, k2 = h0 * iS, h1 * iS, h2 * iS
                    for i in range(3):
                        e = yk[t, b, j, i] - X[t, w, 3 * i] - X[t, w, 3 * i + 2]
                        X[t, w, 3 * i] += k0 * e
                        X[t, w, 3 * i + 1] += k1 * e
                        X[t, w, 3 * i + 2] += k2 * e
                    p00, p01, p02 = p00 - k0 * h0, p01 - k0 * h1, p02 - k0 * h2
                    p11, p12, p22 = p11 - k1 * h1, p12 - k1 * h2, p22 - k2 * h2
                Pf[t, w, 0], Pf[t, w, 1], Pf[t, w, 2] = p00, p01, p02
                Pf[t, w, 3], Pf[t, w, 4], Pf[t, w, 5] = p11, p12, p22
        # RTS: G = P_t Aᵀ (P⁻_{t+1})⁻¹, x^s_t = x_t + G (x^s_{t+1} - x⁻_{t+1}),
        # S_t = P_t + G (S_{t+1} - P⁻_{t+1}) Gᵀ; X becomes the smoothed state
        for w in range(w_n):
            if first[w] < 0:
                continue
            b, j = cb[w], cj[w]
            for k in range(6):
                S[w, k] = Pf[T - 1, w, k]
            for i in range(3):
                est[T - 1, b0 + b, j, i] = X[T - 1, w, 3 * i]
            var[T - 1, b0 + b, j] = S[w, 0]
        for t in range(T - 2, -1, -1):
            a, rr = ou[t + 1, 0], ou[t + 1, 1]
            for w in range(w_n):
                if first[w] < 0:
                    continue
                b, j, sj = cb[w], cj[w], cs[w]
                phi, qq = phis[t + 1, cu[w]], q[t + 1, b, j]
                f00, f01, f02 = Pf[t, w, 0], Pf[t, w, 1], Pf[t, w, 2]
                f11, f12, f22 = Pf[t, w, 3], Pf[t, w, 4], Pf[t, w, 5]
                # the prediction of frame t + 1, as the forward pass computed it
                n00 = f00 + 2 * a * f01 + a * a * f11 + qq * ou[t + 1, 2]
                n01 = rr * (f01 + a * f11) + qq * ou[t + 1, 3]
                n11 = rr * rr * f11 + qq * ou[t + 1, 4]
                n02 = phi * (f02 + a * f12)
                n12 = phi * rr * f12
                n22 = phi * phi * f22 + sj * (1.0 - phi * phi)
                # M = P_t Aᵀ (rows i, columns k)
                m00, m01, m02 = f00 + a * f01, rr * f01, phi * f02
                m10, m11, m12 = f01 + a * f11, rr * f11, phi * f12
                m20, m21, m22 = f02 + a * f12, rr * f12, phi * f22
                i00, i01, i02, i11, i12, i22 = _inv3s(n00, n01, n02, n11, n12, n22)
                g00 = m00 * i00 + m01 * i01 + m02 * i02
                g01 = m00 * i01 + m01 * i11 + m02 * i12
                g02 = m00 * i02 + m01 * i12 + m02 * i22
                g10 = m10 * i00 + m11 * i01 + m12 * i02
                g11 = m10 * i01 + m11 * i11 + m12 * i12
                g12 = m10 * i02 + m11 * i12 + m12 * i22
                g20 = m20 * i00 + m21 * i01 + m22 * i02
                g21 = m20 * i01 + m21 * i11 + m22 * i12
                g22 = m20 * i02 + m21 * i12 + m22 * i22
                d00, d01, d02 = S[w, 0] - n00, S[w, 1] - n01, S[w, 2] - n02
                d11, d12, d22 = S[w, 3] - n11, S[w, 4] - n12, S[w, 5] - n22
                # E = G D
                e00 = g00 * d00 + g01 * d01 + g02 * d02
                e01 = g00 * d01 + g01 * d11 + g02 * d12
                e02 = g00 * d02 + g01 * d12 + g02 * d22
                e10 = g10 * d00 + g11 * d01 + g12 * d02
                e11 = g10 * d01 + g11 * d11 + g12 * d12
                e12 = g10 * d02 + g11 * d12 + g12 * d22
                e20 = g20 * d00 + g21 * d01 + g22 * d02
                e21 = g20 * d01 + g21 * d11 + g22 * d12
                e22 = g20 * d02 + g21 * d12 + g22 * d22
                S[w, 0] = f00 + e00 * g00 + e01 * g01 + e02 * g02
                S[w, 1] = f01 + e00 * g10 + e01 * g11 + e02 * g12
                S[w, 2] = f02 + e00 * g20 + e01 * g21 + e02 * g22
                S[w, 3] = f11 + e10 * g10 + e11 * g11 + e12 * g12
                S[w, 4] = f12 + e10 * g20 + e11 * g21 + e12 * g22
                S[w, 5] = f22 + e20 * g20 + e21 * g21 + e22 * g22
                var[t, b0 + b, j] = S[w, 0]
                for i in range(3):
                    x0, x1, x2 = X[t, w, 3 * i], X[t, w, 3 * i + 1], X[t, w, 3 * i + 2]
                    u0 = X[t + 1, w, 3 * i] - (x0 + a * x1)
                    u1 = X[t + 1, w, 3 * i + 1] - rr * x1
                    u2 = X[t + 1, w, 3 * i + 2] - phi * x2
                    X[t, w, 3 * i] = x0 + (g00 * u0 + g01 * u1 + g02 * u2)
                    X[t, w, 3 * i + 1] = x1 + (g10 * u0 + g11 * u1 + g12 * u2)
                    X[t, w, 3 * i + 2] = x2 + (g20 * u0 + g21 * u1 + g22 * u2)
                    est[t, b0 + b, j, i] = X[t, w, 3 * i]


@_jit
def _inv3s(a: float, b: float, c: float, d: float, e: float, f: float) -> tuple:
    """Inverse ``(i00, i01, i02, i11, i12, i22)`` of the symmetric matrix
    ``[[a, b, c], [b, d, e], [c, e, f]]``; singular (a state without variance: no
    coloured error, or a rank-deficient start): the (x, v) block is inverted and the
    rest set to zero, or, rank one, ``P / trace²`` (the minimum-norm gain)."""
    c00 = d * f - e * e
    c01 = c * e - b * f
    c02 = b * e - c * d
    det = a * c00 + b * c01 + c * c02
    scale = a * a + d * d + f * f
    if abs(det) > 1e-14 * scale * math.sqrt(scale):
        idet = 1.0 / det
        return (c00 * idet, c01 * idet, c02 * idet, (a * f - c * c) * idet,
                (b * c - a * e) * idet, (a * d - b * b) * idet)  # fmt: skip
    dd = a * d - b * b
    if f <= 0.0 and dd != 0.0:
        return d / dd, -b / dd, 0.0, a / dd, 0.0, 0.0
    tr = a + d + f
    w = 0.0 if tr == 0.0 else 1.0 / (tr * tr)
    return a * w, b * w, c * w, d * w, e * w, f * w


@_jit
def _profile_nll(
    th: np.ndarray,
    yk: np.ndarray,
    rscale: np.ndarray,
    steps: np.ndarray,
    ou: np.ndarray,
    frames: np.ndarray,
    restart: np.ndarray,
    tau: float,
    tau_q: float,
) -> float:
    """Negative profile log-likelihood per sample of :func:`profile_sums`' parameters."""
    se, sl, n = profile_sums(th, yk, rscale, steps, ou, frames, restart, tau, tau_q)
    if not (se > 0.0 and n > 0 and math.isfinite(sl)):
        return 1e30
    return 0.5 * (math.log(2 * math.pi * se / n) + sl / n + 1.0)


@_jit
def profile_sums(
    th: np.ndarray,
    yk: np.ndarray,
    rscale: np.ndarray,
    steps: np.ndarray,
    ou: np.ndarray,
    frames: np.ndarray,
    restart: np.ndarray,
    tau: float,
    tau_q: float,
) -> tuple:
    """:func:`filter_sums` at ``theta = (log speed_sd / m, logit error_sd² / m²,
    log error_tau)`` with the total measurement variance ``m² = 1`` (the likelihood is
    maximised over ``m²`` in closed form: ``m² = sum e²/S / n``)."""
    ratio = math.exp(th[0])
    phi = 1.0 / (1.0 + math.exp(-th[1]))
    q = 2 * ratio * ratio / tau_q
    v0 = q * tau / 2 if math.isfinite(tau) else 1.0
    return filter_sums(yk, rscale, steps, ou, frames, restart, q, 1.0 - phi, phi, v0,
                       math.exp(th[2]))  # fmt: skip


@_jit
def profile_nll_grad(
    th: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    yk: np.ndarray,
    rscale: np.ndarray,
    steps: np.ndarray,
    ou: np.ndarray,
    frames: np.ndarray,
    restart: np.ndarray,
    tau: float,
    tau_q: float,
) -> tuple:
    """``(f, gradient)`` of :func:`_profile_nll` (forward differences of step 1e-6, taken
    backwards at an upper bound): one compiled call per optimiser iteration."""
    f = _profile_nll(th, yk, rscale, steps, ou, frames, restart, tau, tau_q)
    g = np.empty(th.shape[0])
    tt = th.copy()
    for i in range(th.shape[0]):
        h = 1e-6 if th[i] + 1e-6 <= hi[i] else -1e-6
        tt[i] = th[i] + h
        g[i] = (_profile_nll(tt, yk, rscale, steps, ou, frames, restart, tau, tau_q) - f) / h
        tt[i] = th[i]
    return f, g
