"""Compiled kernel of the Kalman-type methods on skeletons (numba, ``cache=True``).

``kf``, ``tkf``, ``tkfc`` and ``atkf`` as :mod:`tobitkf.smoothing.kalman_methods` uses
them: each joint a 3-D random walk with A = H = I and diagonal Q, R, so every axis of
every joint is an independent scalar filter. :func:`gaussian_run` (kf, atkf) and
:func:`tobit_run` (tkf, tkfc) run them in one pass over time, joint by joint inside each
frame, with the same arithmetic as the numpy core (:mod:`tobitkf.core.engine`,
:mod:`tobitkf.core.tobit`, :func:`tobitkf.core.censored.clipped_normal_variance_diag`), in
the same order of operations, so the outputs equal the core's to rounding
(tests/test_kalman_kernels.py compares the two on random and real data, censored samples
included: 1e-12 m, up to ~1e-11 m for joints held several sd beyond a limit, where the
gain is a ratio of tail quantities). Where a limit lies more than 12 sd away its normal
functions are skipped (its terms are below 2e-33). The core stays the reference
implementation (general models, likelihoods, streaming); this is the fast path of the
skeleton methods only, and it keeps no more than the outputs: no predicted covariances,
probabilities or likelihoods.

The univariate normal functions are ports of scipy's: ``ndtr`` (cephes: erf near 0,
erfc beyond), ``log_ndtr`` (log1p(-erfc/2) above -1, log(erfc/2) below, the asymptotic
series where erfc underflows), with ``math.erf`` / ``math.erfc`` (C99 libm) for cephes'
erf / erfc; tests check them against scipy to 1e-13 relative (libm's and cephes' erfc
differ by a few ulp in the far tails).

Imported lazily (numba is imported only when a Kalman-type method runs).
``NUMBA_DISABLE_JIT=1`` runs the same code as plain Python (slow; for debugging).
"""

from __future__ import annotations

import math

import numpy as np

from tobitkf.smoothing._numba_cache import njit

_jit = njit(cache=True, nogil=True, error_model="numpy")

_SQRT_HALF = math.sqrt(0.5)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)
_BIG = 1e150  # as core.tobit._BIG
_EPS = 1e-9  # as core.tobit.EPS_CENSORED
_FAR = 3.0  # as core.censored._FAR
_UNCENSORED = 12.0  # both limits further (in sd): uncensored to 1.8e-33
_CF_TERMS = 60  # as core.censored._CF_TERMS
_MILLS_RATIO = 40.0  # as core.censored._MILLS_RATIO
_GL12_X, _GL12_W = np.polynomial.legendre.leggauss(12)
# core.tobit._SERIES: 2 ∫_0^β z² φ(z) dz = 2 φ(0) Σ_k (-1/2)^k / k! β^(2k+3) / (2k+3)
_SERIES = np.array(
    [2.0 * _INV_SQRT_2PI * (-0.5) ** k / math.factorial(k) / (2 * k + 3) for k in range(14)]
)


# ------------------------------------------------------------------ univariate normal
@_jit
def ndtr(a: float) -> float:
    """Standard normal CDF Φ(a) (scipy's cephes ``ndtr``)."""
    if math.isnan(a):
        return math.nan
    x = a * _SQRT_HALF
    z = abs(x)
    if z < _SQRT_HALF:
        return 0.5 + 0.5 * math.erf(x)
    y = 0.5 * math.erfc(z)
    return 1.0 - y if x > 0 else y


@_jit
def log_ndtr(a: float) -> float:
    """log Φ(a) (scipy's ``log_ndtr``), finite down to a = -1e150."""
    if math.isnan(a):
        return math.nan
    if a == -math.inf:
        return -math.inf
    t = a * _SQRT_HALF
    if a >= -1.0:
        return math.log1p(-0.5 * math.erfc(t))
    if a > -37.0:
        return math.log(0.5 * math.erfc(-t))
    # log Φ(a) = -a²/2 - log(-a) - log √(2π) + log(1 + Σ_k (-1)^k (2k-1)!! / a^(2k))
    z = 1.0 / (a * a)
    term = 1.0
    acc = 0.0
    for k in range(1, 16):
        term *= -(2 * k - 1) * z
        acc += term
    return -0.5 * a * a - math.log(-a) - _LOG_SQRT_2PI + math.log1p(acc)


@_jit
def _log_phi(z: float) -> float:
    return -0.5 * z * z - _LOG_SQRT_2PI


@_jit
def _mills_tail(x: float) -> tuple:
    """core.censored._mills_tail: (r, s) for Z | Z > x, x >= 3."""
    t = 0.0
    for n in range(_CF_TERMS, 1, -1):
        t = n / (x + t)
    return 1.0 / (x + t), t


@_jit
def truncated(alpha: float, beta: float) -> tuple:
    """core.censored._truncated_core (logs=False) for one (α, β), α <= β:
    (P_a, P_un, P_b, μ_T, v_T, μ_T - α, β - μ_T)."""
    # A limit beyond 12 sd contributes below 1.8e-33 (Φ(-12)) to every quantity: its
    # normal functions are skipped (the full evaluation gives the same numbers to 1e-30,
    # and exactly P_un = 1, μ_T = 0, v_T = 1 when both limits are that far).
    far_lo = alpha < -_UNCENSORED
    far_up = beta > _UNCENSORED
    if far_lo and far_up:
        return 0.0, 1.0, 0.0, 0.0, 1.0, -alpha, beta
    p_lower = 0.0 if far_lo else ndtr(alpha)
    p_upper = 0.0 if far_up else ndtr(-beta)
    flip = (alpha + beta) > 0
    if flip:
        a, b, pa, qb = -beta, -alpha, p_upper, p_lower
    else:
        a, b, pa, qb = alpha, beta, p_lower, p_upper
    if a == b:  # empty interval: the point mass at a
        p_un, mu, var, d_lo, d_hi = 0.0, a, 0.0, 0.0, 0.0
    else:
        c = 0.5 * (a + b)
        h = 0.5 * (b - a)
        finite = math.isfinite(a) and math.isfinite(b)
        if finite and h * (1.0 + abs(c)) <= 1.0:  # narrow: Gauss–Legendre, tilted density
            s0 = 0.0
            s1 = 0.0
            for i in range(12):
                x = _GL12_X[i]
                e = math.exp(-(c * h) * x - 0.5 * (h * h) * x * x)
                s0 += e * _GL12_W[i]
                s1 += e * x * _GL12_W[i]
            m1 = s1 / s0
            s2 = 0.0
            for i in range(12):
                x = _GL12_X[i]
                e = math.exp(-(c * h) * x - 0.5 * (h * h) * x * x)
                dx = x - m1
                s2 += e * (dx * dx) * _GL12_W[i]
            v1 = s2 / s0
            lp = math.log(h) + _log_phi(c) + math.log(s0)
            p_un = math.exp(lp)
            mu = c + h * m1
            var = h * h * v1
            d_lo = h * (1.0 + m1)
            d_hi = h * (1.0 - m1)
        elif b <= -_FAR:  # far tail: continued fractions, reflected to (x1, x2)
            x1 = -b
            x2 = -a
            r1, s1 = _mills_tail(x1)
            fin2 = math.isfinite(x2)
            r2, s2 = _mills_tail(x2) if fin2 else (0.0, 0.0)
            lq1 = log_ndtr(-x1)
            if x1 <= _MILLS_RATIO:
                ratio = math.exp(log_ndtr(-x2) - lq1)
            elif fin2:  # Q(x2)/Q(x1) from the Mills ratios, as core.censored
                gap = x2 - x1
                ratio = math.exp(
                    -gap * (0.5 * x1 + 0.5 * x2) - math.log1p((gap + r2 - r1) / (x1 + r1))
                )
            else:
                ratio = 0.0
            p_un = math.exp(lq1 + math.log1p(-ratio))
            w2 = ratio / (1.0 - ratio)
            w1 = 1.0 + w2
            if fin2:
                gap = x2 - x1
                m_rel = w1 * r1 - w2 * (gap + r2)
                second = w1 * (r1 * (s1 - r1) + (r1 - m_rel) ** 2)
                if w2 > 0.0:  # w2 = 0 where dd² could overflow (gaps beyond 1e154)
                    dd = gap + r2 - m_rel
                    second = second - w2 * (r2 * (s2 - r2) + dd * dd)
                d_lo = gap - m_rel
            else:
                m_rel = w1 * r1 - 0.0
                second = w1 * (r1 * (s1 - r1) + (r1 - m_rel) ** 2) - 0.0
                d_lo = math.inf
            mu = -(x1 + m_rel)
            var = second
            d_hi = m_rel
        else:  # general: no cancellation, no underflow
            p_un = ndtr(b) - pa if b <= 0 else (1.0 - pa) - qb
            lp = math.log(p_un)
            ra = 0.0 if a < -_UNCENSORED else math.exp(_log_phi(a) - lp)
            rb = 0.0 if b > _UNCENSORED else math.exp(_log_phi(b) - lp)
            mu = ra - rb
            ta = a * ra if math.isfinite(a) else 0.0
            tb = b * rb if math.isfinite(b) else 0.0
            var = 1.0 + ta - tb - mu * mu
            d_lo = mu - a
            d_hi = b - mu
    var = max(var, 0.0)
    if flip:
        return p_lower, p_un, p_upper, -mu, var, d_hi, d_lo
    return p_lower, p_un, p_upper, mu, var, d_lo, d_hi


@_jit
def clipped_diag(m: float, v: float, lo: float, up: float) -> tuple:
    """core.censored._diag_parts for one component, v > 0: (E[y], Var[y], P_a, P_un, P_b)."""
    s = math.sqrt(v)
    alpha = (lo - m) / s
    beta = (up - m) / s
    p_lo, p_un, p_up, mu_t, v_t, d_lo, d_hi = truncated(alpha, beta)
    if lo == -math.inf and up == math.inf:
        return m, v, p_lo, p_un, p_up
    fa = math.isfinite(alpha)
    fb = math.isfinite(beta)
    pos = p_un > 0
    ef = (alpha * p_lo if fa else 0.0) + (beta * p_up if fb else 0.0)
    ef = ef + (mu_t * p_un if pos else 0.0)
    # terms with a zero probability are skipped: their squared distances overflow for
    # limits beyond ~1e154 sd (0 * inf), as in core.censored._diag_parts
    lo_in = fa and p_lo > 0.0
    up_in = fb and p_up > 0.0
    vf = (p_un * v_t if pos else 0.0) + (p_lo * p_un * d_lo**2 if lo_in and pos else 0.0)
    vf = vf + (p_up * p_un * d_hi**2 if up_in and pos else 0.0)
    vf = vf + (p_lo * p_up * (beta - alpha) ** 2 if lo_in and up_in else 0.0)
    mean = min(max(m + s * ef, lo), up)
    return mean, v * vf, p_lo, p_un, p_up


@_jit
def _pu_vt_symmetric(beta: float, pu: float, phi: float) -> float:
    """core.tobit._pu_vt_symmetric for one β >= 0."""
    if beta < 0.5:
        b2 = beta * beta
        acc = _SERIES[13]
        for k in range(12, -1, -1):
            acc = acc * b2 + _SERIES[k]
        return acc * b2 * beta
    return pu - 2.0 * beta * phi


# ------------------------------------------------------------------ the filters
# Two kernels, so that a method compiles only its own update (numba compiles every
# function a kernel calls): ``gaussian_run`` (kf, atkf) and ``tobit_run`` (tkf, tkfc);
# ``rts_run`` only when offline. Their per-joint bookkeeping is written out in both: as
# helper calls or array views per joint (reference counting in numba) it cost 3-9x the
# time (kf 43 against 5 ms, atkf 58 against 11 ms on 12 x 1500 x 25).
#
# Arguments common to both: ys (T, N, 3) NaN = missing; qs (T, 3) process-noise variance
# of each step; r (3,) measurement-noise variance; rs (T, N) multiplier of r (INFERRED
# samples) or (0, 0) for none; outputs est (T, N, 3), std (T, N) (unless offline: the
# filtered variances go to var (T, N, 3) and rts_run writes std), clipped (T, N) bool;
# work state (N, 3, 6) (x, v, then the ATKF memo) and index (N, 2) int64 (first and last
# valid frame). The caller allocates everything: no allocation code to compile here.
# A joint's filter starts at its first measurement with variance r, predicted from frame 0
# on (x0 = first measurement, P0 = R, as in kalman_methods.run_kalman_core).


@_jit
def _init(state: np.ndarray, index: np.ndarray, r: np.ndarray) -> None:
    for n in range(state.shape[0]):
        index[n, 0] = -1
        index[n, 1] = -1
        for a in range(3):
            state[n, a, 0] = 0.0
            state[n, a, 1] = r[a]
            state[n, a, 2] = math.nan


@_jit
def blank_before_first(est: np.ndarray, std: np.ndarray, index: np.ndarray) -> None:
    """NaN before each joint's first measurement (everywhere for a joint never seen)."""
    T = est.shape[0]
    for n in range(est.shape[1]):
        stop = T if index[n, 0] < 0 else index[n, 0]
        for t in range(stop):
            std[t, n] = math.nan
            for a in range(3):
                est[t, n, a] = math.nan


@_jit
def _any_gap(ys: np.ndarray) -> bool:
    """Some joint misses a frame after its first measurement (before its last frame)."""
    T, N, _ = ys.shape
    for n in range(N):
        prev = -1  # last valid frame before t
        for t in range(T):
            if prev >= 0 and prev != t - 1:
                return True
            if not math.isnan(ys[t, n, 0]):
                prev = t
    return False


@_jit
def gaussian_run(
    adaptive: bool,  # atkf (else kf)
    ys: np.ndarray,
    qs: np.ndarray,
    r: np.ndarray,
    rs: np.ndarray,
    c: np.ndarray,  # (3,) ATKF half-widths per 1/30 s
    steps: np.ndarray,  # (T,) seconds before each frame
    times: np.ndarray,  # (T,) cumulated steps
    reference: bool,  # every step is 1/30 s: c unscaled unless some joint has a gap
    ref_dt: float,
    offline: bool,
    est: np.ndarray,
    std: np.ndarray,
    clipped: np.ndarray,
    var: np.ndarray,
    state: np.ndarray,
    index: np.ndarray,
) -> None:
    """kf, or atkf: limits x̂_{t-1} ± c (scaled by the time since the joint's last
    measurement, c per 1/30 s), a plain KF update at frame 0 (Algorithm 2, 2020)."""
    T, N, _ = ys.shape
    has_rs = rs.shape[0] > 0
    _init(state, index, r)
    # c is scaled on every joint as soon as one has a gap (as run_kalman_core does)
    scale_c = adaptive and (not reference or _any_gap(ys))
    for t in range(T):
        q = qs[t]
        kalman = not adaptive or t == 0
        for n in range(N):
            last = index[n, 1]
            valid = not math.isnan(ys[t, n, 0])
            if valid and index[n, 0] < 0:  # the first measurement starts the filter
                index[n, 0] = t
                for a in range(3):
                    state[n, a, 0] = ys[t, n, a]
            cfac = 1.0
            if scale_c:
                if last < 0 or last == t - 1:
                    cfac = steps[t] / ref_dt
                else:
                    cfac = (times[t] - times[last]) / ref_dt
            rsc = rs[t, n] if has_rs else 1.0
            any_clip = False
            for a in range(3):
                xp = state[n, a, 0]
                vp = state[n, a, 1] + q[a]
                y = ys[t, n, a]
                if math.isnan(y):  # unobserved: zero gain, the prediction
                    state[n, a, 1] = vp
                    continue
                rr = r[a] * rsc if has_rs else r[a]
                if kalman:
                    K = vp / (vp + rr)
                    e = y - xp
                    pxy = vp
                else:  # core.tobit._atkf_update_symmetric
                    ca = c[a] * cfac if scale_c else c[a]
                    S = vp + rr
                    beta = min(ca / math.sqrt(S), _BIG)
                    # β depends on the variances only, which converge: a one-entry memo
                    # per component of (β, P_a, P_un, Var f) skips the normal functions
                    if beta == state[n, a, 2]:
                        pa, pu, vf = state[n, a, 3], state[n, a, 4], state[n, a, 5]
                    else:
                        pa = math.exp(log_ndtr(-beta))
                        pu = math.erf(beta * _SQRT_HALF)
                        phi = math.exp(-0.5 * beta * beta) * _INV_SQRT_2PI
                        vf = _pu_vt_symmetric(beta, pu, phi) + 2.0 * pa * beta * beta
                        state[n, a, 2], state[n, a, 3], state[n, a, 4], state[n, a, 5] = (
                            beta,
                            pa,
                            pu,
                            vf,
                        )
                    pxy = vp * pu
                    K = pxy / (S * (vf + (2.0 * _EPS) * pa))
                    d = y - xp
                    e = min(max(d, -ca), ca)
                    if abs(d) >= ca:
                        any_clip = True
                state[n, a, 0] = xp + K * e
                state[n, a, 1] = vp - K * pxy
            if valid:
                index[n, 1] = t
                clipped[t, n] = any_clip
            for a in range(3):
                est[t, n, a] = state[n, a, 0]
            if offline:
                for a in range(3):
                    var[t, n, a] = state[n, a, 1]
            else:  # the root-mean-square of the axes' posterior sd (np.mean, then sqrt)
                std[t, n] = math.sqrt(((state[n, 0, 1] + state[n, 1, 1]) + state[n, 2, 1]) / 3)


@_jit
def tobit_run(
    corrected: bool,  # tkfc (else the standard tkf)
    ys: np.ndarray,
    qs: np.ndarray,
    r: np.ndarray,
    rs: np.ndarray,
    lower: np.ndarray,  # (3,) limits
    upper: np.ndarray,
    tol: float,  # a sample beyond a limit by more than this is used as measured
    offline: bool,
    est: np.ndarray,
    std: np.ndarray,
    clipped: np.ndarray,
    var: np.ndarray,
    state: np.ndarray,
    index: np.ndarray,
    beyond: np.ndarray,  # out (N, 3) int64, zeros: samples beyond a limit, per joint axis
) -> None:
    """tkf (core.tobit.tkf_update) or tkfc (core.tobit.tkfc_update), fixed limits. A
    sensor clipped at a limit reports the limit itself: for a sample beyond a limit (by
    more than ``tol``) that limit is lifted (±inf), as kalman_methods.sample_limits does
    for the core."""
    T, N, _ = ys.shape
    has_rs = rs.shape[0] > 0
    _init(state, index, r)
    for t in range(T):
        q = qs[t]
        for n in range(N):
            valid = not math.isnan(ys[t, n, 0])
            if valid and index[n, 0] < 0:  # the first measurement starts the filter
                index[n, 0] = t
                for a in range(3):
                    state[n, a, 0] = ys[t, n, a]
            rsc = rs[t, n] if has_rs else 1.0
            any_clip = False
            for a in range(3):
                xp = state[n, a, 0]
                vp = state[n, a, 1] + q[a]
                y = ys[t, n, a]
                if math.isnan(y):  # unobserved: zero gain, the prediction
                    state[n, a, 1] = vp
                    continue
                rr = r[a] * rsc if has_rs else r[a]
                lo, up = lower[a], upper[a]
                if y < lo - tol:
                    lo = -math.inf
                    beyond[n, a] += 1
                elif y > up + tol:
                    up = math.inf
                    beyond[n, a] += 1
                yc = min(max(y, lo), up)
                if yc <= lo or yc >= up:
                    any_clip = True
                if corrected:
                    S = vp + rr
                    ey, vy, p_lo, pu, p_up = clipped_diag(xp, S, lo, up)
                    pxy = vp * pu
                    # pxy = 0: no gain, also where S ε underflowed (0/0; core.tobit)
                    K = pxy / (vy + _EPS * S * (p_lo + p_up)) if pxy != 0.0 else 0.0
                else:
                    sr = math.sqrt(rr)
                    p_lo, pu, p_up, mu_t, v_t, _, _ = truncated((lo - xp) / sr, (up - xp) / sr)
                    ey = pu * (xp + sr * mu_t) + p_lo * min(max(lo, -_BIG), _BIG)
                    ey = ey + p_up * min(max(up, -_BIG), _BIG)
                    floor = rr * (v_t + _EPS * (p_lo + p_up))
                    pxy = vp * pu
                    pyy = pu * pu * vp + floor
                    K = pxy / pyy if pxy != 0.0 else 0.0
                    state[n, a, 0] = xp + K * (yc - ey)
                    # v⁻ - Pxy²/Pyy written as v⁻ floor/Pyy: no cancellation (core.tobit)
                    state[n, a, 1] = vp * (floor / pyy) if K != 0.0 else vp
                    continue
                state[n, a, 0] = xp + K * (yc - ey)
                state[n, a, 1] = vp - K * pxy
            if valid:
                index[n, 1] = t
                clipped[t, n] = any_clip
            for a in range(3):
                est[t, n, a] = state[n, a, 0]
            if offline:
                for a in range(3):
                    var[t, n, a] = state[n, a, 1]
            else:  # the root-mean-square of the axes' posterior sd (np.mean, then sqrt)
                std[t, n] = math.sqrt(((state[n, 0, 1] + state[n, 1, 1]) + state[n, 2, 1]) / 3)


@_jit
def rts_run(est: np.ndarray, var: np.ndarray, qs: np.ndarray, std: np.ndarray) -> None:
    """RTS with A = I over the filtered est, var (in place): x⁻_{t+1} = x_t,
    P⁻_{t+1} = P_t + Q_{t+1} (core.kalman.rts_smooth, diagonal path); std from the
    smoothed variances."""
    T, N, _ = est.shape
    for t in range(T - 2, -1, -1):
        q = qs[t + 1]
        for n in range(N):
            for a in range(3):
                pf = var[t, n, a]
                ppt = pf + q[a]
                G = pf * 1.0 / ppt if ppt > 0 else 0.0
                xf = est[t, n, a]
                est[t, n, a] = xf + G * (est[t + 1, n, a] - xf)
                var[t, n, a] = pf + G * G * (var[t + 1, n, a] - ppt)
    for t in range(T):
        for n in range(N):
            std[t, n] = math.sqrt(((var[t, n, 0] + var[t, n, 1]) + var[t, n, 2]) / 3)
