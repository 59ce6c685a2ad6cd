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

from tobitkf.smoothing._numba_cache import njit
from tobitkf.smoothing._robust_kernels import ou_table

_jit = njit(cache=True, nogil=True)
# the block loops of smooth_run: a division by zero gives inf or NaN instead of raising
# (the lanes where it can happen are selected away), so that the loops have no early
# exit and the compiler can run them in SIMD lanes
_simd = njit(cache=True, nogil=True, error_model="numpy")
_inline = njit(inline="always", error_model="numpy")  # inlined into the SIMD loops

#: SIMD lanes of a block of :func:`smooth_run` (joints of all bodies): each quantity of
#: a block is a row of L lanes in one array. The row length is a compile-time constant,
#: so the compiler proves the rows apart without run-time checks.
L = 32
_P00, _P01, _P02, _P11, _P12, _P22 = (k * L for k in range(9, 15))  # covariance rows
#: rows of a block's state (smooth_run): without, and with the two shared-error axes
_NZ0, _NZ = 15, 21
_S0, _S1 = 15 * L, 18 * L  # the shared-error axes' (x, v, c) rows, after the covariance
#: rows of a block's inputs: the samples' three axes, then their variance, q, phi and
#: the two shared-error signals (read only with shared errors)
_NU = 8
_UR, _UQ, _UPHI, _US0, _US1 = 3 * L, 4 * L, 5 * L, 6 * L, 7 * L


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
    last_step = math.nan
    phi = om2 = 1.0
    for m in range(M):
        t = frames[m]
        if restart[m]:
            started[:] = False
        if steps[t] != last_step:  # else the frame before's phi (most steps repeat)
            last_step = steps[t]
            phi = math.exp(-last_step / tau_c)  # tau_c >= one frame: 1 - phi² is exact
            om2 = 1.0 - phi * phi
        a, rr = ou[t, 0], ou[t, 1]
        qa, qb, qc = q * ou[t, 2], q * ou[t, 3], q * ou[t, 4]
        frame_S = frame_log = math.nan  # the last S of this frame and its 3 log S
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
                # tracks seen at the same frames share S: the log of the track before
                lastlog[j] = frame_log if S == frame_S else 3 * math.log(S)
            frame_S, frame_log = S, lastlog[j]
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


@_jit
def smooth_run(
    y2: np.ndarray,  # (T, B J 3) samples, NaN = none: (T, B, J, 3) as rows of frames
    r2: np.ndarray,  # (T, B J) measurement variance of each sample
    steps: np.ndarray,  # (T,)
    q2: np.ndarray,  # (T, B J) OU velocity noise density of the step before each frame
    sc2: np.ndarray,  # (B, J) coloured-error variance
    tau: float,
    tau_c: np.ndarray,  # (B, J) coloured-error correlation time
    e2: np.ndarray,  # out (T, B0 J 3): the estimate of x
    v2: np.ndarray,  # out (T, B0 J): its smoothed variance
    b0: int,  # body b is written at b0 + b (a chunk of the bodies of est and var)
    J: int,  # joints per body
    shared: np.ndarray | None,  # (T, B, J) the samples' shared errors (below), or None
) -> None:
    """Kalman filter + RTS smoother of the three-state model per joint: the estimate of
    ``x`` and its variance (NaN for a joint without samples). The filter starts at frame
    0 from the joint's first sample (velocity 0, the prior of :func:`filter_sums` with
    the ``q`` of that sample's frame) and is then updated with every sample, the first
    one included. With ``sc2 = 0`` it is the two-state OU smoother: the robust smoother
    with fixed noise runs through it too.

    The joints run in blocks of :data:`L` columns, time outside, the block's
    columns inside, without branches (a missing sample selects the prediction; the
    inverse selects its singular fall-backs), so that the inner loops are SIMD loops.
    Each column's arithmetic is that of its own recursion, operation for operation: the
    blocks change the memory order, not the numbers. The RTS pass recomputes each
    prediction from the stored filtered moments with the forward pass's expressions
    (same values) instead of storing it. Every array is C-contiguous.

    ``shared``: errors that samples share (:mod:`tobitkf.smoothing.robust_shared`), two
    kinds, independent of each other: ``s > 0`` at a sample whose error of standard
    deviation ``s`` it shares with the other samples of the first kind (the guesses),
    ``s < 0`` likewise of the second kind with ``-s`` (the carried samples), 0 at a
    sample that shares none (its value where there is no sample is not read). Two more
    axes of the filter, updated with the same gains on ``s`` (0 at the other kind's
    samples), give ``Σ w_i s_i`` of each kind, the weights ``w_i`` being those the
    estimate puts on the samples; the squares of the two are added to ``var``."""
    T, N = r2.shape[0], r2.shape[1]
    # columns n = b J + j; the caller flattens the arrays (a reshape here would compile
    # numba's error path for a wrong shape: seconds of the first run)
    # The block's columns are the SIMD lanes, each quantity a row of L lanes. Rows of a
    # state: (x, v, c) of axis i at 3i..3i+2, then the covariance p00, p01, p02, p11,
    # p12, p22 (_P..). Rows of an input: the samples of the three axes, their variance
    # (_UR), q (_UQ) and exp(-dt / tau_c) (_UPHI) of the step before the frame. With
    # shared errors, their two axes' (x, v, c) after the covariance (_S0, _S1) and their
    # inputs after the others (_US0, _US1).
    # with and without shared errors are two compilations: ``shared is not None`` is
    # decided when compiling (numba prunes the branches on an argument's None), so the
    # SIMD loops without them carry no test
    nz = _NZ0 if shared is None else _NZ  # rows in use (the shared-error axes come last)
    Z = np.empty((T, nz * L))  # filtered states
    U = np.empty((T, _NU * L))  # inputs
    cur = np.empty(_NZ * L)  # the state being filtered, then smoothed
    first = np.empty(L, dtype=np.int64)
    cu = np.empty(L, dtype=np.int64)  # each column's tau_c index and sc2
    cs = np.empty(L)
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
    for n0 in range(0, N, L):
        w_n = min(L, N - n0)
        for w in range(w_n):
            cu[w], cs[w] = ui[n0 + w], sc2[(n0 + w) // J, (n0 + w) % J]
            first[w] = -1
        for t in range(T):  # the block's inputs, one row per quantity
            for w in range(w_n):
                n = n0 + w
                y0 = y2[t, 3 * n]
                U[t, w], U[t, L + w], U[t, 2 * L + w] = y0, y2[t, 3 * n + 1], y2[t, 3 * n + 2]
                U[t, _UR + w], U[t, _UQ + w] = r2[t, n], q2[t, n]
                U[t, _UPHI + w] = phis[t, cu[w]]
                if shared is not None:  # the kinds apart: each its own axis
                    sv = shared[t, n // J, n % J]
                    U[t, _US0 + w], U[t, _US1 + w] = max(sv, 0.0), max(-sv, 0.0)
                if first[w] < 0 and math.isfinite(y0):
                    first[w] = t
        for w in range(w_n):  # frame 0 starts at the column's first sample
            fw, sj = first[w], cs[w]
            if fw < 0:  # no sample: NaN throughout, written as such below
                for k in range(nz):
                    cur[k * L + w] = math.nan
                continue
            v0 = U[fw, _UQ + w] * tau / 2 if math.isfinite(tau) else 1.0
            for i in range(3):
                cur[3 * i * L + w] = U[fw, i * L + w]
                cur[(3 * i + 1) * L + w] = 0.0
                cur[(3 * i + 2) * L + w] = 0.0
            cur[_P00 + w], cur[_P01 + w], cur[_P02 + w] = U[fw, _UR + w] + sj, 0.0, -sj
            cur[_P11 + w], cur[_P12 + w], cur[_P22 + w] = v0, 0.0, sj
            if shared is not None:
                for r, i in ((_S0, _US0), (_S1, _US1)):
                    cur[r + w], cur[r + L + w], cur[r + 2 * L + w] = U[fw, i + w], 0.0, 0.0
        for t in range(T):
            if t > 0:
                _predict_block(cur, U[t], ou[t, 0], ou[t, 1], ou[t, 2], ou[t, 3], ou[t, 4],
                               cs, w_n, shared)  # fmt: skip
            _update_block(cur, U[t], w_n, shared)
            for k in range(nz * L):
                Z[t, k] = cur[k]
        # RTS: G = P_t Aᵀ (P⁻_{t+1})⁻¹, x^s_t = x_t + G (x^s_{t+1} - x⁻_{t+1}),
        # S_t = P_t + G (S_{t+1} - P⁻_{t+1}) Gᵀ; cur holds the smoothed state of the frame
        # after (the last frame's is its filtered one)
        _write_block(cur, e2[T - 1], v2[T - 1], b0 * J + n0, w_n, shared)
        for t in range(T - 2, -1, -1):
            o = ou[t + 1]
            _rts_block(cur, Z[t], U[t + 1], o[0], o[1], o[2], o[3], o[4], cs, w_n, shared)
            _write_block(cur, e2[t], v2[t], b0 * J + n0, w_n, shared)
        for w in range(w_n):
            if first[w] < 0:  # no sample: no estimate
                n = b0 * J + n0 + w
                for t in range(T):
                    v2[t, n] = math.nan
                    for i in range(3):
                        e2[t, 3 * n + i] = math.nan


@_simd
def _predict_block(
    z: np.ndarray,  # (_NZ * L,) a block's filtered state of the frame before, predicted
    u: np.ndarray,  # (_NU * L,) this frame's inputs
    a: float,  # this step's ou_table row
    rr: float,
    o2: float,
    o3: float,
    o4: float,
    sc2: np.ndarray,  # (L,)
    w_n: int,
    ind: np.ndarray | None,  # the shared-error axes too (not None: compiled apart)
) -> None:
    """The prediction step of :func:`smooth_run`'s block, in place (a SIMD loop)."""
    for w in range(w_n):
        ph = u[_UPHI + w]
        n00, n01, n02, n11, n12, n22 = _predicted_cov(z, w, a, rr, o2, o3, o4, ph,
                                                      u[_UQ + w], sc2[w])  # fmt: skip
        z[_P00 + w], z[_P01 + w], z[_P02 + w] = n00, n01, n02
        z[_P11 + w], z[_P12 + w], z[_P22 + w] = n11, n12, n22
        _predict_axis(z, w, a, rr, ph)  # the axes, unrolled (the SIMD loop is w's)
        _predict_axis(z, 3 * L + w, a, rr, ph)
        _predict_axis(z, 6 * L + w, a, rr, ph)
        if ind is not None:  # decided when compiling
            _predict_axis(z, _S0 + w, a, rr, ph)
            _predict_axis(z, _S1 + w, a, rr, ph)


@_simd
def _update_block(z: np.ndarray, u: np.ndarray, w_n: int, ind: np.ndarray | None) -> None:
    """The measurement update of :func:`smooth_run`'s block, in place; a column without
    a sample keeps its prediction (selected, not branched: a SIMD loop)."""
    for w in range(w_n):
        m = abs(u[w]) < math.inf  # finite
        p00, p01, p02 = z[_P00 + w], z[_P01 + w], z[_P02 + w]
        p11, p12, p22 = z[_P11 + w], z[_P12 + w], z[_P22 + w]
        h0 = p00 + p02
        h1 = p01 + p12
        h2 = p02 + p22
        iS = 1.0 / (h0 + h2 + u[_UR + w])
        k0, k1, k2 = h0 * iS, h1 * iS, h2 * iS
        _update_axis(z, u, w, 0, 0, k0, k1, k2, m)  # the axes, unrolled (SIMD over w)
        _update_axis(z, u, w, 3 * L, L, k0, k1, k2, m)
        _update_axis(z, u, w, 6 * L, 2 * L, k0, k1, k2, m)
        if ind is not None:
            _update_axis(z, u, w, _S0, _US0, k0, k1, k2, m)
            _update_axis(z, u, w, _S1, _US1, k0, k1, k2, m)
        z[_P00 + w] = p00 - k0 * h0 if m else p00
        z[_P01 + w] = p01 - k0 * h1 if m else p01
        z[_P02 + w] = p02 - k0 * h2 if m else p02
        z[_P11 + w] = p11 - k1 * h1 if m else p11
        z[_P12 + w] = p12 - k1 * h2 if m else p12
        z[_P22 + w] = p22 - k2 * h2 if m else p22


@_simd
def _rts_block(
    s: np.ndarray,  # (_NZ * L,) smoothed state of frame t + 1 in, of frame t out
    f: np.ndarray,  # (_NZ * L,) filtered state of frame t
    u: np.ndarray,  # (_NU * L,) inputs of frame t + 1
    a: float,  # ou_table row of frame t + 1
    rr: float,
    o2: float,
    o3: float,
    o4: float,
    sc2: np.ndarray,  # (L,)
    w_n: int,
    ind: np.ndarray | None,  # the shared-error axes too (not None: compiled apart)
) -> None:
    """One RTS step of :func:`smooth_run`'s block, in place (a SIMD loop over columns).

    The prediction's covariance ``[[a, b, c], [b, d, e], [c, e, f]]`` is inverted by
    cofactors; when it is singular (a state without variance: no coloured error, or a
    rank-deficient start) the (x, v) block is inverted and the rest set to zero, or, rank
    one, ``P / trace²`` is used (the minimum-norm gain). The three cases are selects."""
    for w in range(w_n):
        ph = u[_UPHI + w]
        f00, f01, f02 = f[_P00 + w], f[_P01 + w], f[_P02 + w]
        f11, f12, f22 = f[_P11 + w], f[_P12 + w], f[_P22 + w]
        # the prediction of frame t + 1, as the forward pass computed it
        n00, n01, n02, n11, n12, n22 = _predicted_cov(f, w, a, rr, o2, o3, o4, ph,
                                                      u[_UQ + w], sc2[w])  # fmt: skip
        # M = P_t Aᵀ (rows i, columns k)
        m00, m01, m02 = f00 + a * f01, rr * f01, ph * f02
        m10, m11, m12 = f01 + a * f11, rr * f11, ph * f12
        m20, m21, m22 = f02 + a * f12, rr * f12, ph * f22
        # the inverse of the prediction's covariance (docstring)
        c00 = n11 * n22 - n12 * n12
        c01 = n02 * n12 - n01 * n22
        c02 = n01 * n12 - n02 * n11
        det = n00 * c00 + n01 * c01 + n02 * c02
        scale = n00 * n00 + n11 * n11 + n22 * n22
        reg = abs(det) > 1e-14 * scale * math.sqrt(scale)
        idet = 1.0 / det
        dd = n00 * n11 - n01 * n01
        two = (n22 <= 0.0) & (dd != 0.0)
        tr = n00 + n11 + n22
        wr = 0.0 if tr == 0.0 else 1.0 / (tr * tr)
        i00 = c00 * idet if reg else (n11 / dd if two else n00 * wr)
        i01 = c01 * idet if reg else (-n01 / dd if two else n01 * wr)
        i02 = c02 * idet if reg else (0.0 if two else n02 * wr)
        i11 = (n00 * n22 - n02 * n02) * idet if reg else (n00 / dd if two else n11 * wr)
        i12 = (n01 * n02 - n00 * n12) * idet if reg else (0.0 if two else n12 * wr)
        i22 = (n00 * n11 - n01 * n01) * idet if reg else (0.0 if two else n22 * wr)
        g00 = m00 * i00 + m01 * i01 + m02 * i02
        g01 = m00 * i01 + m01 * i11 + m02 * i12
        g02 = m00 * i02 + m01 * i12 + m02 * i22
        g10 = m10 * i00 + m11 * i01 + m12 * i02
        g11 = m10 * i01 + m11 * i11 + m12 * i12
        g12 = m10 * i02 + m11 * i12 + m12 * i22
        g20 = m20 * i00 + m21 * i01 + m22 * i02
        g21 = m20 * i01 + m21 * i11 + m22 * i12
        g22 = m20 * i02 + m21 * i12 + m22 * i22
        d00, d01, d02 = s[_P00 + w] - n00, s[_P01 + w] - n01, s[_P02 + w] - n02
        d11, d12, d22 = s[_P11 + w] - n11, s[_P12 + w] - n12, s[_P22 + w] - n22
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
        s[_P00 + w] = f00 + e00 * g00 + e01 * g01 + e02 * g02
        s[_P01 + w] = f01 + e00 * g10 + e01 * g11 + e02 * g12
        s[_P02 + w] = f02 + e00 * g20 + e01 * g21 + e02 * g22
        s[_P11 + w] = f11 + e10 * g10 + e11 * g11 + e12 * g12
        s[_P12 + w] = f12 + e10 * g20 + e11 * g21 + e12 * g22
        s[_P22 + w] = f22 + e20 * g20 + e21 * g21 + e22 * g22
        g = (g00, g01, g02, g10, g11, g12, g20, g21, g22)
        _rts_axis(s, f, w, a, rr, ph, g)  # the axes, unrolled (the SIMD loop is w's)
        _rts_axis(s, f, 3 * L + w, a, rr, ph, g)
        _rts_axis(s, f, 6 * L + w, a, rr, ph, g)
        if ind is not None:
            _rts_axis(s, f, _S0 + w, a, rr, ph, g)
            _rts_axis(s, f, _S1 + w, a, rr, ph, g)


@_inline
def _predicted_cov(p: np.ndarray, w: int, a: float, rr: float, o2: float, o3: float,
                   o4: float, ph: float, qq: float, sj: float) -> tuple:  # fmt: skip
    """The predicted covariance ``(n00, n01, n02, n11, n12, n22)`` of lane ``w`` of the
    block state ``p`` (the forward pass and the RTS pass share these expressions)."""
    p00, p01, p02 = p[_P00 + w], p[_P01 + w], p[_P02 + w]
    p11, p12, p22 = p[_P11 + w], p[_P12 + w], p[_P22 + w]
    return (p00 + 2 * a * p01 + a * a * p11 + qq * o2, rr * (p01 + a * p11) + qq * o3,
            ph * (p02 + a * p12), rr * rr * p11 + qq * o4, ph * rr * p12,
            ph * ph * p22 + sj * (1.0 - ph * ph))  # fmt: skip


@_inline
def _predict_axis(z: np.ndarray, k: int, a: float, rr: float, ph: float) -> None:
    """(x, v, c) of one axis at ``z[k], z[k + L], z[k + 2L]`` predicted, in place."""
    x, v, c = z[k], z[k + L], z[k + 2 * L]
    z[k] = x + a * v
    z[k + L] = rr * v
    z[k + 2 * L] = ph * c


@_inline
def _update_axis(z: np.ndarray, u: np.ndarray, w: int, zr: int, ur: int, k0: float,
                 k1: float, k2: float, m: bool) -> None:  # fmt: skip
    """(x, v, c) of an axis (state rows from ``zr``, its sample's row ``ur``) of lane
    ``w`` updated with its sample (kept without)."""
    r = zr + w
    x, v, c = z[r], z[r + L], z[r + 2 * L]
    e = u[ur + w] - x - c
    z[r] = x + k0 * e if m else x
    z[r + L] = v + k1 * e if m else v
    z[r + 2 * L] = c + k2 * e if m else c


@_inline
def _rts_axis(s: np.ndarray, f: np.ndarray, k: int, a: float, rr: float, ph: float,
              g: tuple) -> None:  # fmt: skip
    """(x, v, c) of one axis at ``k, k + L, k + 2L`` smoothed: ``s`` the frame after's
    smoothed in, this frame's out, ``f`` this frame's filtered, ``g`` the gain G."""
    x0, x1, x2 = f[k], f[k + L], f[k + 2 * L]
    u0 = s[k] - (x0 + a * x1)
    u1 = s[k + L] - rr * x1
    u2 = s[k + 2 * L] - ph * x2
    s[k] = x0 + (g[0] * u0 + g[1] * u1 + g[2] * u2)
    s[k + L] = x1 + (g[3] * u0 + g[4] * u1 + g[5] * u2)
    s[k + 2 * L] = x2 + (g[6] * u0 + g[7] * u1 + g[8] * u2)


@_jit
def _write_block(
    s: np.ndarray,  # (_NZ * L,) a block's smoothed state of one frame
    est: np.ndarray,  # out (B0 * J * 3,) that frame's estimates
    var: np.ndarray,  # out (B0 * J,)
    n0: int,  # the block's first column in them
    w_n: int,
    ind: np.ndarray | None,  # with the shared errors' variance (not None)
) -> None:
    """The block's smoothed positions and variances of one frame into the outputs."""
    for w in range(w_n):
        n = n0 + w
        v = s[_P00 + w]
        if ind is not None:
            g, c = s[_S0 + w], s[_S1 + w]
            v = v + (g * g + c * c)
        var[n] = v
        est[3 * n] = s[w]
        est[3 * n + 1] = s[3 * L + w]
        est[3 * n + 2] = s[6 * L + w]


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
