"""Tobit Kalman filters: standard TKF (Allik 2016), corrected TKF^c and adaptive ATKF (2020).

All three use the generic update of Algorithm 1 (2020 paper)::

    K = Pxy Pyy⁻¹,   x = x⁻ + K (y - E[y]),   P = P⁻ - K Pxyᵀ

with the moments of MATH.md §3 (m = H x⁻, S = H P⁻ Hᵀ + R):

=========  ==========================  ==========================================  ============
filter     probabilities from          E[y], Pyy                                   Pxy
=========  ==========================  ==========================================  ============
TKF        α = (a - m)/√R_ii           P_un (m + √R_ii μ_T) + P_a a + P_b b;        P⁻ Hᵀ P_un
                                       P_un H P⁻ Hᵀ P_un + R*, R*_ii = R_ii v_T
TKF^c      α = (a - m)/√S_ii           exact clipped mean / covariance of N(m, S)   P⁻ Hᵀ P_un
                                       (eq. 20, 21)                                 (eq. 12)
ATKF       TKF^c with a = H x̂_{k-1} - c, b = H x̂_{k-1} + c (eq. 31-34), y clipped to them,
           first step a plain KF (Algorithm 2)
=========  ==========================  ==========================================  ============

Safeguard for almost surely censored components
-----------------------------------------------
For TKF^c with the exact clipped covariance, when α = (a - m)/s → +∞ both Pxy ~ Q(α) and
Var[y_i] ~ 2 Q(α)/α² vanish but their ratio grows like α²/2, so the gain does *not* go to
zero by itself (and is 0/0 once Q(α) underflows). We therefore add

    Pyy += diag(ε s_i² (P_a,i + P_b,i)),   ε = 1e-9,

with s_i² = S_ii (TKF^c, ATKF) or R_ii (TKF). The term is exactly zero for infinite limits
(so TKF^c equals the KF), negligible whenever the censoring probability is ordinary
(relative change ≤ 1e-9 / Var f), and makes K ~ P_un / ε → 0 smoothly as a component
becomes certainly censored. ``P_a + P_b`` is used instead of ``1 - P_un`` so that it is
exactly 0, not a rounding residue, when the limits are infinite.

Measured for one limit α standard deviations beyond the predicted mean, gain relative to
the KF gain: 1.5 (α = 0), 6.6 (3), 14.1 (5.0, the maximum), 0.94 (6), 1e-3 (7), 8e-15
(10). Up to ~4 sd this is exact TKF^c: the ε term changes Pyy by 5e-6 relative at 3 sd,
3e-4 at 4 sd, 5 % at 5 sd. The peak depends only logarithmically on ε (≈ 8× for
ε = 1e-6, which already moves the 3 sd gain by 0.5 %; ≈ 20× for 1e-12). When P_un is
small because the interval is very narrow (width ≲ 1e-4 sd) rather than far away, the
term also dominates and the gain goes to 0, where exact TKF^c would keep a gain
~ s/width (the reading still carries the sign of y* - m).

Measurements beyond a limit are treated as censored at that limit: y := clip(y, a, b).

Log-likelihood (MATH.md §4, eq. 27 / 29): per observed component, log Φ(α) if y ≤ a,
log Φ(-β) if y ≥ b, log φ((y - m)/s) - log s otherwise, summed over the components (eq. 28,
independence), with s² = R_ii for the standard TKF (eq. 29) and s² = S_ii for TKF^c and
ATKF (eq. 27). The first ATKF step (a KF step) uses the KF's Gaussian log density.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special

from tobitkf.core.censored import (
    censored_logpdf,
    clipped_moments_unchecked,
    clipped_normal_variance_diag,
    truncated_standard_normal,
)
from tobitkf.core.engine import (
    KF,
    Method,
    StepModel,
    UpdateOut,
    gain_update_diag,
    gain_update_general,
    observed_mask,
    prepare_inputs,
    run_filter,
    sum_last,
)
from tobitkf.core.model import FilterResult, LinearGaussian

__all__ = [
    "ATKF",
    "EPS_CENSORED",
    "TKF",
    "TKFC",
    "adaptive_tobit_filter",
    "atkf_update",
    "tkf_update",
    "tkfc_update",
    "tobit_filter",
]

Array = NDArray[np.float64]

#: relative variance floor added to Pyy for censored mass (see the module docstring)
EPS_CENSORED = 1e-9

_LOG_2PI = math.log(2.0 * math.pi)
_SQRT_HALF = math.sqrt(0.5)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
_BIG = 1e150  # stands in for an infinite standardised limit (0 * BIG = 0, BIG**2 finite)


def _clipped_flag(y: Array, lower: Any, upper: Any) -> NDArray[np.bool_]:
    return (y <= lower) | (y >= upper)


# --------------------------------------------------------------------------------------
# standard TKF (Allik 2016)
# --------------------------------------------------------------------------------------
def tkf_update(
    xp: Array,
    Pp: Array,
    y: Array,
    sm: StepModel,
    lower: Any,
    upper: Any,
    c: Any = None,
    full: bool | None = None,
    out_x: Array | None = None,
) -> UpdateOut:
    """Standard Tobit update (MATH.md §3 row TKF; 2020 paper eq. 18-19, 22).

    Parameters
    ----------
    xp : (*batch, n) predicted mean; Pp : (*batch, n, n) predicted covariance (variances
    on the diagonal path); y : (*batch, p) measurement, NaN unobserved (clipped to the
    limits here); sm : StepModel; lower, upper : broadcastable to (*batch, p); full : hint
    that y has no NaN; out_x : optional output buffer for the new mean.
    """
    y = np.minimum(np.maximum(y, lower), upper)  # NaN stays NaN
    if sm.diagonal:
        h, r = sm.H, sm.R
        m = h * xp
        Pxy0 = h * Pp
        HPH = h * Pxy0  # rounded as (H P⁻) Hᵀ on the general path
    else:
        H = sm.H
        m = xp @ H.T
        HP = H @ Pp
        HPH = HP @ H.T
        Pxy0 = np.swapaxes(HP, -1, -2)
        r = np.diagonal(sm.R, axis1=-2, axis2=-1)
    sr = np.sqrt(r)
    alpha = (lower - m) / sr
    beta = (upper - m) / sr
    ts = truncated_standard_normal(alpha, beta)
    Pa, Pu, Pb = ts.p_lower, ts.p_uncensored, ts.p_upper
    lo = np.clip(lower, -_BIG, _BIG)
    up = np.clip(upper, -_BIG, _BIG)
    Ey = Pu * (m + sr * ts.mu_t) + Pa * lo + Pb * up
    e = y - Ey
    obs, full = observed_mask(y, full)
    floor = r * (ts.v_t + EPS_CENSORED * (Pa + Pb))
    if sm.diagonal:
        Pxy = Pxy0 * Pu
        Pyy = Pu * Pu * HPH + floor
        # P_un = 0 (so Pxy = 0) and R ε below the smallest subnormal: Pyy = 0. No
        # cross-covariance, no gain (not 0/0); elsewhere K = 0 / Pyy = 0 as before.
        Pyy = np.where(Pxy == 0.0, 1.0, Pyy)
        x, P, K = gain_update_diag(xp, Pp, Pxy, Pyy, e, obs, full, out_x)
        # v = v⁻ - Pxy²/Pyy = v⁻ floor / Pyy exactly; the second form has no cancellation
        # (the first went negative once v⁻ exceeded about 1e16 floor: Q/R >= 1e16)
        P = np.where(K != 0.0, Pp * (floor / Pyy), Pp)
    else:
        Pxy = Pxy0 * Pu[..., None, :]
        Pyy = HPH * Pu[..., :, None] * Pu[..., None, :]
        idx = np.arange(Pyy.shape[-1])
        Pyy[..., idx, idx] += floor
        Pyy, e = _certainly_censored(Pyy, e, Pu)
        x, P, K, _ = gain_update_general(xp, Pp, Pxy, Pyy, e, obs, full)
    ll = sum_last(censored_logpdf(y, m, r, lower, upper))
    return UpdateOut(x, P, ll, Pa, Pu, Pb, _clipped_flag(y, lower, upper), K)


def _certainly_censored(Pyy: Array, e: Array, Pu: Array) -> tuple[Array, Array]:
    """General path: a component certainly censored (P_un = 0) is its limit, a constant:
    no covariance with the state (its Pxy column is 0) nor with the other components,
    and no innovation. Its row and column of Pyy are those of the identity and its
    innovation 0, the exact limit; left as computed, a variance that underflowed to 0 or
    a subnormal made Pyy singular, or its inverse infinite times a zero innovation (NaN)."""
    dead = Pu == 0.0
    if not np.any(dead):
        return Pyy, e
    Pyy = np.where(dead[..., :, None] | dead[..., None, :], 0.0, Pyy)
    idx = np.arange(Pyy.shape[-1])
    Pyy[..., idx, idx] = np.where(dead, 1.0, Pyy[..., idx, idx])
    return Pyy, np.where(dead, 0.0, e)


# --------------------------------------------------------------------------------------
# corrected TKF^c (2020)
# --------------------------------------------------------------------------------------
def tkfc_update(
    xp: Array,
    Pp: Array,
    y: Array,
    sm: StepModel,
    lower: Any,
    upper: Any,
    c: Any = None,
    full: bool | None = None,
    out_x: Array | None = None,
) -> UpdateOut:
    """Corrected Tobit update TKF^c (2020 paper eq. 12-17, 20-21; MATH.md §3).

    Probabilities from S = H P⁻ Hᵀ + R; E[y] and Pyy the exact mean and covariance of
    clip(N(m, S), a, b) (off-diagonal terms from the bivariate normal CDF, via
    :func:`tobitkf.core.censored.clipped_normal_moments`); Pxy = P⁻ Hᵀ P_un (eq. 12, exact by
    Stein's lemma); plus the safeguard ε S_ii (P_a + P_b) on the diagonal of Pyy.
    Shapes as in :func:`tkf_update`.
    """
    y = np.minimum(np.maximum(y, lower), upper)  # NaN stays NaN
    obs, full = observed_mask(y, full)
    if sm.diagonal:
        h = sm.H
        m = h * xp
        Pxy0 = h * Pp
        S = h * Pxy0 + sm.R
        Ey, Vy, Pa, Pu, Pb = clipped_normal_variance_diag(m, S, lower, upper)
        Pxy = Pxy0 * Pu
        Pyy = Vy + EPS_CENSORED * S * (Pa + Pb)
        Pyy = np.where(Pxy == 0.0, 1.0, Pyy)  # as in tkf_update: S ε can underflow
        x, P, K = gain_update_diag(xp, Pp, Pxy, Pyy, y - Ey, obs, full, out_x)
        s2 = S
    else:
        H = sm.H
        m = xp @ H.T
        HP = H @ Pp
        S = HP @ H.T + sm.R
        S = 0.5 * (S + np.swapaxes(S, -1, -2))
        s2 = np.diagonal(S, axis1=-2, axis2=-1)
        cm = clipped_moments_unchecked(m, S, lower, upper)  # S symmetric PSD by construction
        Pa, Pu, Pb = cm.p_lower, cm.p_uncensored, cm.p_upper
        Pxy = np.swapaxes(HP, -1, -2) * Pu[..., None, :]
        Pyy = np.array(cm.cov, dtype=float, copy=True)
        idx = np.arange(Pyy.shape[-1])
        Pyy[..., idx, idx] += EPS_CENSORED * s2 * (Pa + Pb)
        e = y - cm.mean
        Pyy, e = _certainly_censored(Pyy, e, Pu)
        x, P, K, _ = gain_update_general(xp, Pp, Pxy, Pyy, e, obs, full)
    ll = sum_last(censored_logpdf(y, m, s2, lower, upper))
    return UpdateOut(x, P, ll, Pa, Pu, Pb, _clipped_flag(y, lower, upper), K)


# --------------------------------------------------------------------------------------
# adaptive ATKF (2020, Algorithm 2)
# --------------------------------------------------------------------------------------
# series of 2 ∫_0^β z² φ(z) dz = 2 φ(0) Σ_k (-1/2)^k / k! β^(2k+3) / (2k+3), for small β
_SERIES = np.array(
    [2.0 * _INV_SQRT_2PI * (-0.5) ** k / math.factorial(k) / (2 * k + 3) for k in range(14)]
)


def _pu_vt_symmetric(beta: Array, Pu: Array, phi: Array) -> Array:
    """P_un v_T = 2 ∫_0^β z² φ(z) dz for the symmetric interval (-β, β), β ≥ 0.

    Direct form P_un - 2 β φ(β) for β ≥ 0.5, power series below (no cancellation).
    """
    out = Pu - 2.0 * beta * phi
    small = beta < 0.5
    if np.any(small):
        b2 = beta * beta
        acc = np.full_like(beta, _SERIES[-1])
        for coef in _SERIES[-2::-1]:
            acc = acc * b2 + coef
        out = np.where(small, acc * b2 * beta, out)
    return out


class _LastCall:
    """One-entry memo of an elementwise function of a frame's standardised limits.

    In the adaptive filter β = c / s depends on the variances only, and those converge:
    from frame to frame most elements repeat the previous frame's β exactly, so only the
    changed elements are evaluated (the same numbers: the function is elementwise and
    evaluated element by element). The memo keeps private copies (callers may write into
    what they get) and is replaced as one tuple, so concurrent filters stay correct.
    """

    def __init__(self, f: Callable[[Array], Array]) -> None:
        self.f = f
        self.last: tuple[Array, Array] | None = None

    def __call__(self, x: Array) -> Array:
        last = self.last
        if last is not None and last[0].shape == x.shape:
            old_x, old_y = last
            changed = x != old_x
            n = int(np.count_nonzero(changed))
            if n == 0:
                return old_y.copy()
            if 4 * n < x.size:
                y = old_y.copy()
                y[changed] = self.f(x[changed])
                self.last = (x.copy(), y.copy())
                return y
        y = self.f(x)
        self.last = (x.copy(), y.copy())
        return y


_log_ndtr_memo = _LastCall(special.log_ndtr)
_erf_memo = _LastCall(special.erf)


def _atkf_update_symmetric(
    xp: Array,
    vp: Array,
    y: Array,
    sm: StepModel,
    lower: Any,
    upper: Any,
    c: Any,
    full: bool | None = None,
    out_x: Array | None = None,
) -> UpdateOut:
    """ATKF update on the diagonal path with A = I.

    Then m = H x⁻ = H x̂_{k-1} is the centre of the limits, so α = -c/s, β = c/s and
    P_a = P_b = Φ(-β), P_un = erf(β/√2), μ_T = 0, E[y] = m, and (using P_un + 2 P_a = 1)
    Var f = P_un v_T + 2 P_a β². All of these depend on the variances only, which carry
    no batch axes until the data make them differ: per frame, the work over the whole
    batch is a handful of elementwise operations on the innovation.
    The innovation of the clipped measurement is clip(y - m, -c, c) and a component is
    censored when |y - m| >= c. Equals :func:`tkfc_update` with the limits m ± c up to
    round-off.
    """
    r = sm.R
    if sm.h_identity:
        m, Pxy0 = xp, vp
        S = vp + r
    else:
        m = sm.H * xp
        Pxy0 = sm.H * vp
        S = sm.H * Pxy0 + r
    s = np.sqrt(S)
    beta = np.minimum(c / s, _BIG)
    log_pa = _log_ndtr_memo(-beta)
    Pa = np.exp(log_pa)
    Pu = _erf_memo(beta * _SQRT_HALF)
    phi = np.exp(-0.5 * beta * beta) * _INV_SQRT_2PI
    Vf = _pu_vt_symmetric(beta, Pu, phi) + 2.0 * Pa * beta * beta
    Pxy = Pxy0 * Pu
    K = Pxy / (S * (Vf + (2.0 * EPS_CENSORED) * Pa))
    d = y - m
    e = np.minimum(np.maximum(d, -c), c)  # np.clip, without its wrapper's cost per frame
    clipped = np.abs(d) >= c
    # log-likelihood terms: log Φ(-β) when censored, log N(e; 0, S) otherwise
    inv_S = -0.5 / S
    k0 = -0.5 * (np.log(S) + _LOG_2PI)
    ee = e * e
    ee *= inv_S
    ee += k0
    obs, full = observed_mask(y, full)
    if not full:
        K = np.where(obs, K, 0.0)
        e = np.where(obs, e, 0.0)
        # unobserved components: d is NaN, so clipped is False there already and their
        # term comes from ee
        ee = np.where(obs, ee, 0.0)
    terms = np.where(clipped, log_pa, ee)
    x = np.add(xp, K * e, out=out_x)
    v = vp - K * Pxy
    return UpdateOut(x, v, sum_last(terms), Pa, Pu, Pa, clipped, K)


def atkf_update(
    xp: Array,
    Pp: Array,
    y: Array,
    sm: StepModel,
    lower: Any,
    upper: Any,
    c: Any,
    full: bool | None = None,
    out_x: Array | None = None,
) -> UpdateOut:
    """ATKF update (after the first step): the TKF^c update with the adaptive limits.

    On the diagonal path with A = I the symmetric closed form
    (:func:`_atkf_update_symmetric`) is used; it equals :func:`tkfc_update` up to round-off.
    """
    if sm.diagonal and sm.a_identity:
        return _atkf_update_symmetric(xp, Pp, y, sm, lower, upper, c, full, out_x)
    return tkfc_update(xp, Pp, y, sm, lower, upper, c, full, out_x)


TKF = Method("tkf", tkf_update)
TKFC = Method("tkfc", tkfc_update)
ATKF = Method("atkf", atkf_update, adaptive=True)

FILTER_METHODS: dict[str, Method] = {"kf": KF, "tkf": TKF, "tkfc": TKFC, "atkf": ATKF}


def tobit_filter(
    model: LinearGaussian,
    ys: ArrayLike,
    lower: ArrayLike | None = None,
    upper: ArrayLike | None = None,
    *,
    variant: str = "corrected",
    lower_seq: ArrayLike | None = None,
    upper_seq: ArrayLike | None = None,
    A_seq: ArrayLike | None = None,
    Q_seq: ArrayLike | None = None,
    R_seq: ArrayLike | None = None,
    R_scale: ArrayLike | None = None,
    diagonal: bool | None = None,
    keep_probabilities: bool = True,
    keep_predicted: bool = True,
) -> FilterResult:
    """Tobit Kalman filter with fixed censoring limits (Algorithm 1, 2020 paper).

    Parameters
    ----------
    model : LinearGaussian
    ys : array_like, shape (T, *batch, p)
        Reported (censored) measurements; NaN components are unobserved. Values beyond a
        limit are treated as censored at that limit.
    lower, upper : array_like, broadcastable to (*batch, p), optional
        Constant limits a, b (default -inf / +inf: no censoring on that side).
    variant : {"corrected", "standard"}
        "corrected": TKF^c (eq. 12-17, 20-21); "standard": Allik's TKF (eq. 18-19, 22).
    lower_seq, upper_seq : array_like, broadcastable to (T, *batch, p), optional
        Time-varying limits (instead of ``lower`` / ``upper``).
    A_seq, Q_seq, R_seq, R_scale, diagonal
        As in :func:`tobitkf.core.kalman.kalman_filter`.
    keep_probabilities : bool
        False: the censoring probabilities ``p_lower``, ``p_uncensored``, ``p_upper``
        are not kept (read-only NaN views), which saves three arrays the size of ``ys``.
    keep_predicted : bool
        False: the predicted covariances are not kept (a read-only NaN view; only
        :func:`~tobitkf.core.kalman.rts_smooth` needs them).

    Returns
    -------
    FilterResult
        ``loglik`` per step: eq. 27 (corrected, s² = S_ii) or eq. 29 (standard, s² = R_ii)
        summed over the observed components.
    """
    if variant not in ("corrected", "standard"):
        raise ValueError(f"variant: expected 'corrected' or 'standard', found {variant!r}")
    inp = prepare_inputs(
        model,
        ys,
        A_seq=A_seq,
        Q_seq=Q_seq,
        R_seq=R_seq,
        R_scale=R_scale,
        lower=lower,
        upper=upper,
        lower_seq=lower_seq,
        upper_seq=upper_seq,
        diagonal=diagonal,
    )
    method = TKFC if variant == "corrected" else TKF
    return run_filter(
        model, method, inp, keep_probabilities=keep_probabilities, keep_predicted=keep_predicted
    )


def adaptive_tobit_filter(
    model: LinearGaussian,
    ys: ArrayLike,
    c: ArrayLike | None = None,
    *,
    c_seq: ArrayLike | None = None,
    A_seq: ArrayLike | None = None,
    Q_seq: ArrayLike | None = None,
    R_seq: ArrayLike | None = None,
    R_scale: ArrayLike | None = None,
    diagonal: bool | None = None,
    keep_probabilities: bool = True,
    keep_predicted: bool = True,
) -> FilterResult:
    """Adaptive Tobit Kalman filter ATKF (2020 paper, Algorithm 2, eq. 31-34).

    Step 0 is a plain KF update. At every later step k the limits are
    a_k = H x̂_{k-1} - c, b_k = H x̂_{k-1} + c (x̂_{k-1} the previous *filtered* mean),
    the measurement is clipped to them and the TKF^c update is applied.

    Parameters
    ----------
    model : LinearGaussian
    ys : array_like, shape (T, *batch, p)
        Raw (latent) measurements; NaN components are unobserved.
    c : array_like, broadcastable to (*batch, p)
        Half-widths (> 0; inf disables the limit for that component, so c = inf gives
        the KF). Skeleton default (eq. 33): (0.34, 0.18, 0.34) m per frame at 30 fps.
    c_seq : array_like, broadcastable to (T, *batch, p), optional
        Time-varying half-widths (instead of ``c``), e.g. scaled by the frame interval.
    A_seq, Q_seq, R_seq, R_scale, diagonal
        As in :func:`tobitkf.core.kalman.kalman_filter`.
    keep_probabilities, keep_predicted : bool
        As in :func:`tobit_filter`.

    Returns
    -------
    FilterResult
        ``lower`` / ``upper`` hold the adaptive limits (±inf at step 0); ``loglik`` is
        eq. 27 with s² = S_ii (step 0: the KF's Gaussian log density).
    """
    if c is None and c_seq is None:
        raise ValueError("adaptive_tobit_filter: give c (or c_seq)")
    inp = prepare_inputs(
        model,
        ys,
        A_seq=A_seq,
        Q_seq=Q_seq,
        R_seq=R_seq,
        R_scale=R_scale,
        c=c,
        c_seq=c_seq,
        diagonal=diagonal,
    )
    return run_filter(
        model, ATKF, inp, keep_probabilities=keep_probabilities, keep_predicted=keep_predicted
    )
