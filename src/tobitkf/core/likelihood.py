"""Censored log-likelihood and maximum-likelihood noise fitting (MATH.md §4; 2020 paper
eq. 26–29).

Per measurement component, with the filter's one-step predictive ``N(m_k,i, s²_k,i)`` of
the latent measurement ``y*_k,i``, a sample censored at ``a`` contributes ``Φ(α)``, one
censored at ``b`` contributes ``Φ(-β)`` and an uncensored one ``φ((y - m)/s)/s``
(eq. 26–27); components are multiplied (eq. 28). The forms differ in ``s²``:

- ``"corrected"``: ``s² = S_ii``, ``S = H P⁻ H' + R`` (eq. 27, TKF^c; with ``c`` the
  adaptive ATKF limits ``H x̂_{k-1} ± c``),
- ``"standard"``: ``s² = R_ii`` (eq. 29, the standard TKF),
- ``"gaussian"``: the plain Kalman-filter likelihood that ignores censoring (shown to be
  biased on censored data: a clipped sample is treated as an exact one).

The per-step values come from the filters' ``FilterResult.loglik``; this module sums them
and maximises the sum over the noise covariances with :mod:`scipy.optimize`, in an
unconstrained parameterisation (log variances, or log-Cholesky for a full ``Q``). Many
sequences (a batch axis of ``ys``) share one parameter set.

Only numpy and scipy are imported: no file access and no skeleton knowledge (the
skeleton front end, ``fit_skeleton_noise``, lives in :mod:`tobitkf.smoothing.fit`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

__all__ = [
    "FORMS",
    "NoiseFit",
    "censored_loglik",
    "fit_noise",
]

Form = Literal["corrected", "standard", "gaussian"]
FORMS: tuple[str, ...] = ("corrected", "standard", "gaussian")
_Q_STRUCTURES = ("scalar", "diagonal", "full")
_R_STRUCTURES = ("scalar", "diagonal")


def _check_form(form: str, c: Any, lower: Any, upper: Any) -> None:
    if form not in FORMS:
        raise ValueError(f"form must be one of {FORMS}, got {form!r}")
    if c is not None and form == "standard":
        raise ValueError(
            "the adaptive filter (c given) has only the corrected likelihood; use "
            "form='corrected' or form='gaussian'"
        )
    if c is not None and (lower is not None or upper is not None):
        raise ValueError("give either fixed limits (lower/upper) or adaptive half-widths c")


def _run_filter(
    model: Any,
    ys: np.ndarray,
    lower: Any,
    upper: Any,
    form: str,
    c: Any,
    filter_kwargs: dict[str, Any],
) -> Any:
    if form == "gaussian":
        from tobitkf.core.kalman import kalman_filter

        return kalman_filter(model, ys, **filter_kwargs)
    if c is not None:
        from tobitkf.core.tobit import adaptive_tobit_filter

        return adaptive_tobit_filter(model, ys, c, **filter_kwargs)
    from tobitkf.core.tobit import tobit_filter

    return tobit_filter(model, ys, lower, upper, variant=form, **filter_kwargs)


def censored_loglik(
    model: Any,
    ys: np.ndarray,
    lower: Any = None,
    upper: Any = None,
    *,
    form: Form = "corrected",
    c: Any = None,
    per_sequence: bool = False,
    **filter_kwargs: Any,
) -> float | np.ndarray:
    """Log-likelihood of censored measurements (MATH.md §4; 2020 paper eq. 27–29).

    Parameters
    ----------
    model : :class:`tobitkf.core.model.LinearGaussian`.
    ys : (T, *batch, p) reported (already censored) measurements; NaN = unobserved
        (contributes 0).
    lower, upper : censoring limits broadcastable to (p,) or (*batch, p); ``None`` = ±inf.
        Ignored for ``form="gaussian"``.
    form : ``"corrected"`` (s² = S_ii, eq. 27), ``"standard"`` (s² = R_ii, eq. 29) or
        ``"gaussian"`` (plain KF likelihood, censoring ignored).
    c : (p,) or (*batch, p) half-widths of the adaptive ATKF limits ``H x̂_{k-1} ± c``; when
        given, ``lower``/``upper`` must be None and the adaptive filter is used.
    per_sequence : return the sum over time for each batch element, shape ``batch``,
        instead of the grand total.
    **filter_kwargs : passed to the filter (``A_seq``, ``Q_seq``, ``R_seq``, ...).

    Returns
    -------
    float, or ndarray of shape ``batch`` when ``per_sequence``.
    """
    _check_form(form, c, lower, upper)
    ys = np.asarray(ys, dtype=float)
    res = _run_filter(model, ys, lower, upper, form, c, filter_kwargs)
    ll = np.asarray(res.loglik, dtype=float)
    if per_sequence:
        return ll.sum(axis=0)
    return float(ll.sum())


# ---------------------------------------------------------------------------------------
# parameterisation


def _n_q_params(structure: str, n: int) -> int:
    return {"scalar": 1, "diagonal": n, "full": n * (n + 1) // 2}[structure]


def _q_from_params(theta: np.ndarray, structure: str, n: int) -> np.ndarray:
    if structure == "scalar":
        return np.exp(theta[0]) * np.eye(n)
    if structure == "diagonal":
        return np.diag(np.exp(theta))
    L = np.zeros((n, n))
    rows, cols = np.tril_indices(n)
    L[rows, cols] = theta
    d = np.arange(n)
    L[d, d] = np.exp(L[d, d])
    return L @ L.T


def _q_to_params(Q: np.ndarray, structure: str) -> np.ndarray:
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    n = Q.shape[0]
    if structure == "scalar":
        return np.array([np.log(np.mean(np.diag(Q)))])
    if structure == "diagonal":
        return np.log(np.diag(Q))
    L = np.linalg.cholesky(Q)
    d = np.arange(n)
    L[d, d] = np.log(L[d, d])
    rows, cols = np.tril_indices(n)
    return L[rows, cols].copy()


def _r_from_params(theta: np.ndarray, structure: str, p: int) -> np.ndarray:
    if structure == "scalar":
        return np.exp(theta[0]) * np.eye(p)
    return np.diag(np.exp(theta))


def _r_to_params(R: np.ndarray, structure: str) -> np.ndarray:
    d = np.diag(np.atleast_2d(np.asarray(R, dtype=float)))
    if structure == "scalar":
        return np.array([np.log(np.mean(d))])
    return np.log(d)


def _param_names(q_structure: str, n: int, fit_r: bool, r_structure: str, p: int) -> list[str]:
    if q_structure == "scalar":
        names = ["log q"]
    elif q_structure == "diagonal":
        names = [f"log Q[{i},{i}]" for i in range(n)]
    else:
        names = [
            f"log L[{i},{j}]" if i == j else f"L[{i},{j}]" for i, j in zip(*np.tril_indices(n))
        ]
    if fit_r:
        names += ["log r"] if r_structure == "scalar" else [f"log R[{i},{i}]" for i in range(p)]
    return names


# ---------------------------------------------------------------------------------------
# numerical derivatives


def _central_gradient(f: Callable[[np.ndarray], float], x: np.ndarray, h: float) -> np.ndarray:
    g = np.empty_like(x)
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = h
        g[i] = (f(x + e) - f(x - e)) / (2.0 * h)
    return g


def _central_hessian(
    f: Callable[[np.ndarray], float], x: np.ndarray, h: float, f0: float
) -> np.ndarray:
    k = x.size
    Hm = np.empty((k, k))
    for i in range(k):
        ei = np.zeros(k)
        ei[i] = h
        Hm[i, i] = (f(x + ei) - 2.0 * f0 + f(x - ei)) / h**2
        for j in range(i):
            ej = np.zeros(k)
            ej[j] = h
            v = (f(x + ei + ej) - f(x + ei - ej) - f(x - ei + ej) + f(x - ei - ej)) / (4 * h * h)
            Hm[i, j] = Hm[j, i] = v
    return Hm


# ---------------------------------------------------------------------------------------
# result


@dataclass(frozen=True)
class NoiseFit:
    """Result of :func:`fit_noise`.

    Attributes
    ----------
    Q : (n, n) estimated process-noise covariance.
    R : (p, p) measurement-noise covariance (estimated when ``fit_r``, else the given one).
    loglik : maximised log-likelihood (sum over time and batch).
    success : optimiser convergence flag (False also when every measurement is censored:
        the noise is not identified).
    message : optimiser message (plus a note when the standard errors are unavailable).
    n_iter : optimiser iterations.
    stderr : ``{"Q": (n, n), "R": (p, p) or None}`` approximate standard errors of the
        entries of Q and R: inverse numerical Hessian of the negative log-likelihood in the
        unconstrained parameters, mapped by the delta method (NaN when the Hessian is not
        positive definite, or when ``compute_stderr=False``). Exact-likelihood errors
        without censoring; with censored samples the likelihood is the Tobit filter's
        approximation and these can understate the spread (docs/reproduction.md).
    params : unconstrained parameters at the optimum (log variances / log-Cholesky).
    param_names : names of ``params``.
    params_cov : (k, k) approximate covariance of ``params`` (inverse Hessian).
    form, q_structure, fit_r : the settings used.
    n_obs : number of observed (finite) measurement components.
    n_evals : log-likelihood evaluations (filter runs) used by the optimiser.
    """

    Q: np.ndarray
    R: np.ndarray
    loglik: float
    success: bool
    message: str
    n_iter: int
    stderr: dict[str, np.ndarray | None]
    params: np.ndarray
    param_names: tuple[str, ...] = ()
    params_cov: np.ndarray | None = field(default=None, repr=False)
    form: str = "corrected"
    q_structure: str = "scalar"
    fit_r: bool = False
    n_obs: int = 0
    n_evals: int = 0

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form."""
        return {
            "Q": np.asarray(self.Q).tolist(),
            "R": np.asarray(self.R).tolist(),
            "loglik": self.loglik,
            "success": bool(self.success),
            "message": self.message,
            "n_iter": int(self.n_iter),
            "stderr": {
                k: (None if v is None else np.asarray(v).tolist()) for k, v in self.stderr.items()
            },
            "params": np.asarray(self.params).tolist(),
            "param_names": list(self.param_names),
            "form": self.form,
            "q_structure": self.q_structure,
            "fit_r": self.fit_r,
            "n_obs": self.n_obs,
            "n_evals": self.n_evals,
        }

    def format_text(self) -> str:
        """Human-readable summary for the terminal."""

        def mat(M: np.ndarray, S: np.ndarray | None) -> list[str]:
            rows = []
            for i in range(M.shape[0]):
                cells = []
                for j in range(M.shape[1]):
                    se = "" if S is None else f" ± {S[i, j]:.2e}"
                    cells.append(f"{M[i, j]: .4e}{se}")
                rows.append("    " + "   ".join(cells))
            return rows

        status = "converged" if self.success else "NOT converged"
        lines = [
            f"Maximum-likelihood noise fit ({self.form} likelihood, Q {self.q_structure}"
            f"{', R fitted' if self.fit_r else ', R fixed'})",
            f"  {status} after {self.n_iter} iterations: {self.message}",
            f"  log-likelihood {self.loglik:.4f} over {self.n_obs} observed components",
            "  Q (± approximate standard error):",
            *mat(np.asarray(self.Q), self.stderr.get("Q")),
            "  R" + (" (± approximate standard error):" if self.fit_r else " (fixed):"),
            *mat(np.asarray(self.R), self.stderr.get("R") if self.fit_r else None),
        ]
        return "\n".join(lines)


# ---------------------------------------------------------------------------------------
# fitting


def _default_q_init(ys: np.ndarray, H: np.ndarray, n: int, r_diag: np.ndarray) -> float:
    """A rough start: per-step variance of the measurement increments minus the noise."""
    with np.errstate(all="ignore"):
        d = np.diff(ys, axis=0)
        v = np.nanmean(np.nanvar(d.reshape(d.shape[0], -1, d.shape[-1]), axis=0), axis=0)
    h2 = np.maximum(np.sum(H**2, axis=1), 1e-12)
    q = np.nanmean((v - 2.0 * r_diag) / h2) if np.all(np.isfinite(v)) else np.nan
    if not np.isfinite(q) or q <= 0:
        q = 0.1 * float(np.nanmean(v / h2)) if np.any(np.isfinite(v)) else 1.0
    if not np.isfinite(q) or q <= 0:
        q = 1.0
    return float(q)


def _all_censored(ys: np.ndarray, lower: Any, upper: Any) -> bool:
    """Whether every finite measurement lies at or beyond one of its limits."""
    if lower is None and upper is None:
        return False
    try:
        lo = np.broadcast_to(np.asarray(-np.inf if lower is None else lower, float), ys.shape)
        up = np.broadcast_to(np.asarray(np.inf if upper is None else upper, float), ys.shape)
    except ValueError:  # limits of another shape (per axis only): the filter checks them
        return False
    seen = np.isfinite(ys)
    with np.errstate(invalid="ignore"):
        return bool(np.all((ys[seen] <= lo[seen]) | (ys[seen] >= up[seen])))


def fit_noise(
    ys: np.ndarray,
    lower: Any = None,
    upper: Any = None,
    *,
    A: np.ndarray,
    H: np.ndarray,
    x0: np.ndarray,
    P0: np.ndarray,
    q_structure: Literal["scalar", "diagonal", "full"] = "scalar",
    fit_r: bool = False,
    R: np.ndarray | float | None = None,
    r_structure: Literal["scalar", "diagonal"] = "diagonal",
    form: Form = "corrected",
    c: Any = None,
    Q_init: np.ndarray | float | None = None,
    R_init: np.ndarray | float | None = None,
    method: Literal["L-BFGS-B", "Nelder-Mead"] = "L-BFGS-B",
    maxiter: int = 200,
    bounds_log: tuple[float, float] = (-30.0, 15.0),
    compute_stderr: bool = True,
    filter_kwargs: dict[str, Any] | None = None,
) -> NoiseFit:
    """Maximum-likelihood estimate of Q (and optionally R) from censored measurements.

    Maximises :func:`censored_loglik` (MATH.md §4; 2020 paper eq. 27–29) with
    :func:`scipy.optimize.minimize` over unconstrained parameters: log variances for a
    scalar or diagonal Q (and for R), log-Cholesky (log of the diagonal, raw off-diagonal
    entries) for a full Q. All sequences of the batch share one parameter set.

    Parameters
    ----------
    ys : (T, *batch, p) reported measurements (clipped at the limits; NaN = unobserved).
    lower, upper : fixed censoring limits, broadcastable to (p,) or (*batch, p); None = ±inf.
    A : (n, n); H : (p, n); x0 : (n,) or (*batch, n); P0 : (n, n) or (*batch, n, n).
    q_structure : ``"scalar"`` (q I), ``"diagonal"`` or ``"full"``.
    fit_r : estimate R as well (diagonal or scalar, ``r_structure``).
    R : (p, p) or scalar measurement-noise covariance; required when ``fit_r`` is False.
    form : ``"corrected"``, ``"standard"`` or ``"gaussian"`` (see the module docstring).
    c : adaptive ATKF half-widths (then ``lower``/``upper`` must be None).
    Q_init, R_init : starting values (default: a moment-based guess for Q; R, or 0.1 × the
        measurement variance, for R).
    method : scipy optimiser: ``"L-BFGS-B"`` (central-difference gradients) or
        ``"Nelder-Mead"``.
    maxiter : iteration limit.
    bounds_log : box on the log-variance parameters (keeps the search finite).
    compute_stderr : compute the numerical Hessian for standard errors.
    filter_kwargs : extra keyword arguments for the filter.

    Returns
    -------
    NoiseFit
    """
    from scipy.optimize import minimize

    from tobitkf.core.model import LinearGaussian, check_covariance

    _check_form(form, c, lower, upper)
    if q_structure not in _Q_STRUCTURES:
        raise ValueError(f"q_structure must be one of {_Q_STRUCTURES}, got {q_structure!r}")
    if r_structure not in _R_STRUCTURES:
        raise ValueError(f"r_structure must be one of {_R_STRUCTURES}, got {r_structure!r}")
    A = np.atleast_2d(np.asarray(A, dtype=float))
    H = np.atleast_2d(np.asarray(H, dtype=float))
    n, p = A.shape[0], H.shape[0]
    if A.shape != (n, n) or H.shape[1] != n:
        raise ValueError(f"A must be (n, n) and H (p, n); got A {A.shape}, H {H.shape}")
    ys = np.asarray(ys, dtype=float)
    if ys.ndim < 2 or ys.shape[-1] != p:
        raise ValueError(f"ys must be (T, *batch, {p}), got shape {ys.shape}")
    n_obs = int(np.isfinite(ys).sum())
    if n_obs == 0:
        raise ValueError("ys has no finite measurement")
    fk = dict(filter_kwargs or {})

    def as_cov(M: Any, dim: int, name: str) -> np.ndarray:
        M = np.asarray(M, dtype=float)
        if M.ndim == 0:
            return float(M) * np.eye(dim)
        if M.shape != (dim, dim):
            raise ValueError(f"{name} must be a scalar or ({dim}, {dim}), got {M.shape}")
        return M

    if not fit_r and R is None:
        raise ValueError("R is required when fit_r is False")
    if fit_r:
        if R_init is None:
            R_init = R
        if R_init is None:
            with np.errstate(all="ignore"):
                v = np.nanvar(ys.reshape(ys.shape[0], -1, p), axis=(0, 1))
            v = np.where(np.isfinite(v) & (v > 0), v, 1.0)
            R_init = np.diag(0.1 * v)
        R0 = as_cov(R_init, p, "R_init")
    else:
        R0 = as_cov(R, p, "R")
    if Q_init is None:
        Q0 = _default_q_init(ys, H, n, np.diag(R0)) * np.eye(n)
    else:
        Q0 = as_cov(Q_init, n, "Q_init")
    # a start the parametrisation cannot take (log variances): said here, not 17 calls deep
    check_covariance("Q_init", Q0, definite=True)
    check_covariance("R_init" if fit_r else "R", R0, definite=fit_r)

    nq = _n_q_params(q_structure, n)
    theta0 = _q_to_params(Q0, q_structure)
    if fit_r:
        theta0 = np.concatenate([theta0, _r_to_params(R0, r_structure)])
    k = theta0.size
    names = tuple(_param_names(q_structure, n, fit_r, r_structure, p))

    def unpack(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Qm = _q_from_params(theta[:nq], q_structure, n)
        Rm = _r_from_params(theta[nq:], r_structure, p) if fit_r else R0
        return Qm, Rm

    def total_loglik(theta: np.ndarray) -> float:
        Qm, Rm = unpack(theta)
        model = LinearGaussian(A=A, H=H, Q=Qm, R=Rm, x0=x0, P0=P0)
        return censored_loglik(model, ys, lower, upper, form=form, c=c, **fk)

    n_evals = [0]

    def objective(theta: np.ndarray) -> float:
        n_evals[0] += 1
        with np.errstate(all="ignore"):
            val = -total_loglik(theta) / n_obs
        return float(val) if np.isfinite(val) else 1e10

    lo_b, hi_b = bounds_log
    bounds = []
    for name in names:
        bounds.append((lo_b, hi_b) if name.startswith("log") else (None, None))

    if method == "L-BFGS-B":

        def value_and_gradient(t: np.ndarray) -> tuple[float, np.ndarray]:
            return objective(t), _central_gradient(objective, t, 1e-4)

        res = minimize(
            value_and_gradient,
            theta0,
            jac=True,
            method="L-BFGS-B",
            bounds=bounds,
            options={"maxiter": maxiter, "ftol": 1e-11, "gtol": 1e-6},
        )
    elif method == "Nelder-Mead":
        res = minimize(
            objective,
            theta0,
            method="Nelder-Mead",
            bounds=bounds,
            options={"maxiter": maxiter * k, "xatol": 1e-6, "fatol": 1e-10},
        )
    else:
        raise ValueError(f"method must be 'L-BFGS-B' or 'Nelder-Mead', got {method!r}")
    theta = np.asarray(res.x, dtype=float)
    Q_hat, R_hat = unpack(theta)
    ll = total_loglik(theta)
    message = str(res.message)
    at_bound = [
        name
        for name, t in zip(names, theta)
        if name.startswith("log") and (t <= lo_b + 1e-6 or t >= hi_b - 1e-6)
    ]
    if at_bound:
        message += (
            f"; {', '.join(at_bound)} at the search bound {bounds_log}: the variance is not "
            "identified by these data (standard errors are not meaningful)"
        )
    success = bool(res.success)
    if _all_censored(ys, lower, upper):
        success = False  # a flat, bumpy likelihood: any optimum it reports is arbitrary
        message += (
            "; every measurement lies at or beyond a censoring limit: the noise is not "
            "identified by these data"
        )

    se_q = np.full((n, n), np.nan)
    se_r = np.full((p, p), np.nan) if fit_r else None
    params_cov = None
    if compute_stderr:

        def nll(t: np.ndarray) -> float:
            with np.errstate(all="ignore"):
                return -total_loglik(t)

        hess = _central_hessian(nll, theta, 1e-3, -ll)
        try:
            np.linalg.cholesky(hess)
            params_cov = np.linalg.inv(hess)
        except np.linalg.LinAlgError:
            message += "; Hessian not positive definite: standard errors unavailable"
        if params_cov is not None:

            def vec(t: np.ndarray) -> np.ndarray:
                Qm, Rm = unpack(t)
                return np.concatenate([Qm.ravel(), np.diag(Rm)])

            J = np.empty((n * n + p, k))
            for i in range(k):
                e = np.zeros(k)
                e[i] = 1e-6
                J[:, i] = (vec(theta + e) - vec(theta - e)) / 2e-6
            var = np.einsum("ai,ij,aj->a", J, params_cov, J)
            sd = np.sqrt(np.maximum(var, 0.0))
            se_q = sd[: n * n].reshape(n, n)
            if fit_r:
                se_r = np.diag(sd[n * n :])  # R is diagonal: its off-diagonal entries are 0
    return NoiseFit(
        Q=Q_hat,
        R=R_hat,
        loglik=float(ll),
        success=success,
        message=message,
        n_iter=int(getattr(res, "nit", 0)),
        stderr={"Q": se_q, "R": se_r},
        params=theta,
        param_names=names,
        params_cov=params_cov,
        form=form,
        q_structure=q_structure,
        fit_r=fit_r,
        n_obs=n_obs,
        n_evals=n_evals[0],
    )
