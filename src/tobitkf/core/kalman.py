"""The plain Kalman filter and the Rauch–Tung–Striebel smoother.

Both run on the engine (:mod:`tobitkf.core.engine`) shared with the Tobit filters; the
smoother works on the output of any of them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tobitkf.core.engine import KF, diagonal_of, prepare_inputs, run_filter
from tobitkf.core.model import FilterResult, LinearGaussian, SmootherResult

__all__ = ["kalman_filter", "rts_smooth"]

Array = NDArray[np.float64]


def kalman_filter(
    model: LinearGaussian,
    ys: ArrayLike,
    *,
    A_seq: ArrayLike | None = None,
    Q_seq: ArrayLike | None = None,
    R_seq: ArrayLike | None = None,
    R_scale: ArrayLike | None = None,
    diagonal: bool | None = None,
    keep_predicted: bool = True,
) -> FilterResult:
    """Plain Kalman filter over a time-first batch (Algorithm 1 with the KF moments).

    Parameters
    ----------
    model : LinearGaussian
    ys : array_like, shape (T, *batch, p)
        Measurements; NaN components are unobserved (only they are skipped).
    A_seq, Q_seq : array_like, shape (T, n, n), optional
        Time-varying transition / process noise: step t predicts with A_seq[t], Q_seq[t].
    R_seq : array_like, shape (T, p, p), optional
        Time-varying measurement noise.
    R_scale : array_like, broadcastable to (T, *batch, p), optional
        Per-component multiplier of the measurement variances (R_eff = D R D,
        D = diag(sqrt(R_scale))), e.g. > 1 for Kinect "inferred" joints.
    diagonal : bool, optional
        Force (True) or forbid (False) the per-axis path; default: used when possible.
    keep_predicted : bool
        False: the predicted covariances are not kept (a read-only NaN view), which saves
        an array the size of ``ys`` when the variances vary over the batch; only
        :func:`rts_smooth` needs them.

    Returns
    -------
    FilterResult
        ``loglik[t]`` = log N(y_t,obs; H x⁻_t, S_t,obs) with S = H P⁻ Hᵀ + R over the
        observed components (0 for a fully missing step). Censoring probabilities are
        0 / 1 / 0, limits ±inf.
    """
    inp = prepare_inputs(
        model, ys, A_seq=A_seq, Q_seq=Q_seq, R_seq=R_seq, R_scale=R_scale, diagonal=diagonal
    )
    return run_filter(model, KF, inp, keep_predicted=keep_predicted)


# --------------------------------------------------------------------------------------
# RTS smoother
# --------------------------------------------------------------------------------------
def rts_smooth(model: LinearGaussian, result: FilterResult) -> SmootherResult:
    """Rauch–Tung–Striebel smoother on the output of any of the filters.

    For t = T-2, ..., 0 with A = A_{t+1} (the transition used to predict step t+1)::

        G_t   = P_t Aᵀ (P⁻_{t+1})⁻¹      (pseudo-inverse when P⁻_{t+1} is singular)
        x^s_t = x_t + G_t (x^s_{t+1} - x⁻_{t+1})
        P^s_t = P_t + G_t (P^s_{t+1} - P⁻_{t+1}) G_tᵀ

    For the Tobit filters this smooths their Gaussian approximation of the posterior.

    Parameters
    ----------
    model : LinearGaussian
        The model the filter ran with (its A is used unless ``result.A_seq`` is set).
    result : FilterResult

    Returns
    -------
    SmootherResult
        Means (T, *batch, n), covariances (T, *batch, n, n) (variances on the diagonal
        path) and gains.

    Raises
    ------
    ValueError
        When ``result`` holds no predicted covariances (a filter run with
        ``keep_predicted=False``): the smoother needs them.
    """
    T = result.n_steps
    if T > 1 and np.isnan(result.predicted_cov_data[1:]).all():
        raise ValueError(
            "the filter result holds no predicted covariances (the filter ran with "
            "keep_predicted=False); run it with keep_predicted=True to smooth"
        )
    xs = np.array(result.means, dtype=float)
    Ps = np.array(result.cov_data, dtype=float)
    xf, xp = result.means, result.predicted_means
    Pf, Pp = result.cov_data, result.predicted_cov_data
    gains = np.zeros_like(Ps)
    A_seq = result.A_seq
    if result.diagonal:
        a_const = diagonal_of(model.A)
        for t in range(T - 2, -1, -1):
            a = a_const if A_seq is None else diagonal_of(A_seq[t + 1])
            ppt = Pp[t + 1]
            with np.errstate(divide="ignore", invalid="ignore"):
                G = np.where(ppt > 0, Pf[t] * a / ppt, 0.0)
            xs[t] = xf[t] + G * (xs[t + 1] - xp[t + 1])
            Ps[t] = Pf[t] + G * G * (Ps[t + 1] - ppt)
            gains[t] = G
        return SmootherResult(xs, Ps, diagonal=True, gains=gains)
    for t in range(T - 2, -1, -1):
        A = model.A if A_seq is None else A_seq[t + 1]
        # Gᵀ = (P⁻)⁻¹ A P  (P⁻, P symmetric)
        APf = A @ Pf[t]
        try:
            Gt = np.linalg.solve(Pp[t + 1], APf)
        except np.linalg.LinAlgError:
            # singular P⁻ (a singular Q with a singular P0): the pseudo-inverse gives the
            # minimum-norm gain, as the per-axis path does with G = 0 where P⁻ = 0
            Gt = np.linalg.pinv(Pp[t + 1], hermitian=True) @ APf
        G = np.swapaxes(Gt, -1, -2)
        xs[t] = xf[t] + np.einsum("...ij,...j->...i", G, xs[t + 1] - xp[t + 1])
        Pn = Pf[t] + G @ (Ps[t + 1] - Pp[t + 1]) @ Gt
        Ps[t] = 0.5 * (Pn + np.swapaxes(Pn, -1, -2))
        gains[t] = G
    return SmootherResult(xs, Ps, diagonal=False, gains=gains)
