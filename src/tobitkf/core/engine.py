"""The filter engine: step containers, prediction, the Kalman gain updates, one filter
step and the run loop shared by every filter.

Every filter (KF, TKF, TKF^c, ATKF) is one *update function* used by :func:`filter_step`
frame by frame: predict, (adaptive limits), update. The batch functions loop over time
(:func:`run_filter`) and call exactly the same step function as
:class:`tobitkf.core.streaming.StreamingFilter`, so the two cannot diverge.

Two numerical paths
-------------------
*General*: states ``x (*batch, n)``, covariances ``P (*batch, n, n)``, updates solved with
``np.linalg.solve`` on stacked matrices (no explicit inverse), covariances symmetrised after
every update (no Joseph form: the update ``P = P⁻ - K Pxyᵀ`` is the Schur complement of a
valid joint covariance, and symmetrising removes the round-off asymmetry).

*Diagonal (per axis)*: when A, H, Q, R, P0 (and every A_seq, Q_seq, R_seq) are diagonal and
n == p, each axis is an independent scalar filter: everything is elementwise over
``(*batch, p)`` and only the variances ``(*batch, n)`` are carried. Both paths give the same
numbers (to round-off); pass ``diagonal=False`` to force the general one.

Missing data: a NaN measurement component is unobserved. In the general path its row and
column of Pyy are replaced by those of the identity and its innovation and cross-covariance
column by zeros, which is exactly the update with that component removed; the other
components of the step are still used. A fully missing step is a pure prediction.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tobitkf.core.model import FilterResult, LinearGaussian, _is_diag, check_covariance

__all__ = [
    "KF",
    "Method",
    "RunInputs",
    "StepModel",
    "StepOutput",
    "UpdateOut",
    "broadcast_param",
    "diagonal_of",
    "filter_step",
    "gain_update_diag",
    "gain_update_general",
    "initial_state",
    "kf_update",
    "make_step_model",
    "observed_mask",
    "predict",
    "prepare_inputs",
    "run_filter",
    "sum_last",
]

Array = NDArray[np.float64]
_LOG_2PI = math.log(2.0 * math.pi)


# --------------------------------------------------------------------------------------
# per-step containers
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class StepModel:
    """Model matrices used in one step.

    Diagonal path: ``A, Q, H`` have shape (n,) (the diagonals) and ``R`` (p,) or
    (*batch, p) (R_scale applied). General path: ``A (n, n)``, ``Q (n, n)``, ``H (p, n)``,
    ``R (p, p)`` or ``(*batch, p, p)``. ``a_identity``: A is exactly the identity (enables
    the symmetric fast path of the adaptive filter); ``h_identity``: H is exactly the
    identity.
    """

    A: Array
    Q: Array
    H: Array
    R: Array
    diagonal: bool
    a_identity: bool
    h_identity: bool = False


@dataclass(frozen=True)
class UpdateOut:
    """Result of a measurement update (one step).

    ``x (*batch, n)``, ``P`` (*batch, n, n) or variances (*batch, n) on the diagonal
    path; ``loglik (*batch)``; ``p_lower, p_uncensored, p_upper (*batch, p)`` or None
    (plain KF: 0, 1, 0); ``clipped (*batch, p)`` bool or None; ``gain`` K, (*batch, n, p)
    or (*batch, p) on the diagonal path (missing components have zero gain).
    """

    x: Array
    P: Array
    loglik: Array
    p_lower: Array | None
    p_uncensored: Array | None
    p_upper: Array | None
    clipped: NDArray[np.bool_] | None
    gain: Array


UpdateFn = Callable[..., UpdateOut]


@dataclass(frozen=True)
class Method:
    """A filter: its update function and whether its limits are adaptive (ATKF).

    ``update(xp, Pp, y, sm, lower, upper, c, full=None, out_x=None) -> UpdateOut``
    (the Tobit updates clip y to the limits themselves); ``full``: optional hint that y has
    no NaN (None: checked); ``out_x``: optional buffer for the new mean. ``adaptive``:
    limits H x̂_{k-1} ± c and a plain KF update at the first step (Algorithm 2, 2020).
    """

    name: str
    update: UpdateFn
    adaptive: bool = False


@dataclass(frozen=True)
class StepOutput:
    """Everything one :func:`filter_step` produces (shapes as in :class:`FilterResult`)."""

    x_pred: Array
    P_pred: Array
    lower: Array | None
    upper: Array | None
    update: UpdateOut


# --------------------------------------------------------------------------------------
# predict / KF update
# --------------------------------------------------------------------------------------
def predict(x: Array, P: Array, sm: StepModel) -> tuple[Array, Array]:
    """Prediction x⁻ = A x, P⁻ = A P Aᵀ + Q (Algorithm 1, lines 6-7).

    Diagonal path: elementwise, P holds variances (*batch, n).
    """
    if sm.diagonal:
        if sm.a_identity:
            return x, P + sm.Q
        return sm.A * x, sm.A * sm.A * P + sm.Q
    if sm.a_identity:
        return x, P + sm.Q
    xp = x @ sm.A.T
    Pp = sm.A @ P @ sm.A.T + sm.Q
    return xp, 0.5 * (Pp + np.swapaxes(Pp, -1, -2))


def sum_last(a: Array) -> Array:
    """``a.sum(axis=-1)`` with the same numbers: for 3 components numpy adds them in
    order, ``(a0 + a1) + a2``, which written out is several times faster than the
    reduction over a short last axis (a per-frame cost in every filter)."""
    if a.shape[-1] == 3:
        out = a[..., 0] + a[..., 1]
        out += a[..., 2]
        return out
    return a.sum(axis=-1)


def observed_mask(y: Array, full: bool | None = None) -> tuple[NDArray[np.bool_] | None, bool]:
    """``(obs, all_observed)`` with obs = ~isnan(y); ``full=True`` (a caller's hint that y
    has no NaN) skips the check and returns ``(None, True)``."""
    if full:
        return None, True
    obs = ~np.isnan(y)
    return obs, bool(obs.all())


def _mask_unobserved(Pyy: Array, obs: NDArray[np.bool_]) -> Array:
    """Pyy (*batch, p, p) with the rows and columns of unobserved components replaced by
    those of the identity (a new array): solving with it ignores those components, and
    its log-determinant is that of the observed block."""
    both = obs[..., :, None] & obs[..., None, :]
    Pyy = np.where(both, Pyy, 0.0)
    idx = np.arange(Pyy.shape[-1])
    Pyy[..., idx, idx] += ~obs
    return Pyy


def gain_update_diag(
    xp: Array,
    vp: Array,
    Pxy: Array,
    Pyy: Array,
    e: Array,
    obs: NDArray[np.bool_] | None,
    full: bool,
    out_x: Array | None = None,
) -> tuple[Array, Array, Array]:
    """Per-axis update x = x⁻ + K e, v = v⁻ - K Pxy with K = Pxy / Pyy (diagonal path).

    All arguments elementwise over (*batch, p) (variances may carry fewer batch axes);
    unobserved components (``~obs``, ignored when ``full``) get zero gain. ``out_x``:
    optional buffer for the new mean. Returns x, v and K.
    """
    K = Pxy / Pyy
    if not full:
        K = np.where(obs, K, 0.0)
        e = np.where(obs, e, 0.0)
    x = np.add(xp, K * e, out=out_x)
    return x, vp - K * Pxy, K


def gain_update_general(
    xp: Array, Pp: Array, Pxy: Array, Pyy: Array, e: Array, obs: NDArray[np.bool_], full: bool
) -> tuple[Array, Array, Array, Array]:
    """Generic linear update x = x⁻ + K e, P = P⁻ - K Pxyᵀ with K = Pxy Pyy⁻¹.

    Parameters
    ----------
    xp : (*batch, n); Pp : (*batch, n, n); Pxy : (*batch, n, p); Pyy : (*batch, p, p);
    e : (*batch, p) innovation (NaN where unobserved); obs : (*batch, p) observed mask;
    full : all components observed (skips the masking).

    Returns
    -------
    x (*batch, n), P (*batch, n, n) symmetrised, K (*batch, n, p), w = Pyy⁻¹ e (*batch, p).
    Unobserved components: their row/column of Pyy is replaced by the identity's and their
    Pxy column and innovation by zeros (exactly the update without them).
    """
    n = xp.shape[-1]
    p = e.shape[-1]
    if not full:
        Pyy = _mask_unobserved(Pyy, obs)
        Pxy = Pxy * obs[..., None, :]
        e = np.where(obs, e, 0.0)
    batch = np.broadcast_shapes(Pyy.shape[:-2], Pxy.shape[:-2], e.shape[:-1])
    Pyy = np.broadcast_to(Pyy, (*batch, p, p))
    rhs = np.concatenate(
        [
            np.broadcast_to(np.swapaxes(Pxy, -1, -2), (*batch, p, n)),
            np.broadcast_to(e[..., None], (*batch, p, 1)),
        ],
        axis=-1,
    )
    sol = np.linalg.solve(Pyy, rhs)
    Kt = sol[..., :n]
    w = sol[..., n]
    x = xp + np.einsum("...np,...p->...n", Pxy, w)
    P = Pp - Pxy @ Kt
    P = 0.5 * (P + np.swapaxes(P, -1, -2))
    return x, P, np.swapaxes(Kt, -1, -2), w


def _kf_update_diag(
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
    # variances may carry fewer batch axes than the means (they do not depend on the data
    # until a component goes missing): every operation on them is then cheap
    r = sm.R
    if sm.h_identity:
        m, Pxy = xp, vp
        S = vp + r
    else:
        m = sm.H * xp
        Pxy = sm.H * vp
        S = sm.H * Pxy + r
    e = y - m
    obs, full = observed_mask(y, full)
    x, v, K = gain_update_diag(xp, vp, Pxy, S, e, obs, full, out_x)
    inv_S = 1.0 / S
    if not full:
        terms = np.where(obs, np.log(S) + e * e * inv_S + _LOG_2PI, 0.0)
        ll = -0.5 * sum_last(terms)
    elif S.ndim == 1:
        ll = -0.5 * ((e * e) @ inv_S + (np.sum(np.log(S)) + S.shape[0] * _LOG_2PI))
    else:
        ll = -0.5 * (sum_last(e * e * inv_S) + sum_last(np.log(S)) + S.shape[-1] * _LOG_2PI)
    return UpdateOut(x, v, ll, None, None, None, None, K)


def _kf_update_general(
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
    H = sm.H
    m = xp @ H.T
    HP = H @ Pp
    S = HP @ H.T + sm.R
    S = 0.5 * (S + np.swapaxes(S, -1, -2))
    Pxy = np.swapaxes(HP, -1, -2)
    obs, full = observed_mask(y, full)
    e = y - m
    x, P, K, w = gain_update_general(xp, Pp, Pxy, S, e, obs, full)
    # log N(y_obs; m_obs, S_obs): logdet of the masked Pyy equals logdet S_obs
    if not full:
        S = _mask_unobserved(S, obs)
        e = np.where(obs, e, 0.0)
    _, logdet = np.linalg.slogdet(S)
    k = S.shape[-1] if full else obs.sum(axis=-1)
    ll = -0.5 * (k * _LOG_2PI + logdet + np.sum(e * w, axis=-1))
    return UpdateOut(x, P, ll, None, None, None, None, K)


def kf_update(
    xp: Array,
    Pp: Array,
    y: Array,
    sm: StepModel,
    lower: Any = None,
    upper: Any = None,
    c: Any = None,
    full: bool | None = None,
    out_x: Array | None = None,
) -> UpdateOut:
    """Kalman-filter measurement update (MATH.md §3, row KF).

    Pyy = S = H P⁻ Hᵀ + R, Pxy = P⁻ Hᵀ, E[y] = H x⁻. Log-likelihood: the Gaussian
    log density of the observed components of the innovation, log N(y_o; m_o, S_oo)
    (0 when nothing is observed). Limits are ignored.
    """
    if sm.diagonal:
        return _kf_update_diag(xp, Pp, y, sm, lower, upper, c, full, out_x)
    return _kf_update_general(xp, Pp, y, sm, lower, upper, c, full, out_x)


KF = Method("kf", kf_update)


# --------------------------------------------------------------------------------------
# one step of any filter
# --------------------------------------------------------------------------------------
def filter_step(
    method: Method,
    first: bool,
    x: Array,
    P: Array,
    y: Array,
    sm: StepModel,
    lower: Any,
    upper: Any,
    c: Any = None,
    *,
    full: bool | None = None,
    out_x: Array | None = None,
    need_limits: bool = True,
) -> StepOutput:
    """One frame of a filter: (adaptive limits), predict, update.

    Parameters
    ----------
    method : Method
    first : bool
        First frame (the adaptive filter then does a plain KF update, Algorithm 2 line 6).
    x, P : previous filtered mean (*batch, n) and covariance (*batch, n, n) (variances,
        possibly with fewer batch axes, on the diagonal path).
    y : (*batch, p) reported measurement, NaN = unobserved.
    sm : StepModel for this frame.
    lower, upper : limits broadcastable to (*batch, p) (ignored by the adaptive filter).
    c : half-widths of the adaptive filter, broadcastable to (*batch, p).
    full : optional hint that y has no NaN (None: checked).
    out_x : optional buffer (*batch, n) the new mean is written to.
    need_limits : False lets the adaptive filter skip forming its limits when its update
        does not use them (diagonal path, A = I); ``StepOutput.lower/upper`` are then
        None (the batch loop computes them afterwards from the means).
    """
    update = method.update
    if method.adaptive:
        if first:
            lower, upper = -np.inf, np.inf
            update = kf_update
        else:
            if not need_limits and sm.diagonal and sm.a_identity:
                lower = upper = None
            else:
                if sm.diagonal:
                    centre = x if sm.h_identity else sm.H * x
                else:
                    centre = x @ sm.H.T
                lower = centre - c
                upper = centre + c
    xp, Pp = predict(x, P, sm)
    out = update(xp, Pp, y, sm, lower, upper, c, full, out_x)
    return StepOutput(xp, Pp, lower, upper, out)


# --------------------------------------------------------------------------------------
# validation and per-step model construction
# --------------------------------------------------------------------------------------
def diagonal_of(M: Array) -> Array:
    return np.ascontiguousarray(np.diagonal(M, axis1=-2, axis2=-1))


def make_step_model(
    model: LinearGaussian,
    diagonal: bool,
    *,
    A: Array | None = None,
    Q: Array | None = None,
    R: Array | None = None,
    R_scale: Array | None = None,
) -> StepModel:
    """StepModel from the model with optional per-step A, Q, R and R_scale.

    R_scale (*batch, p) scales the variances of the measurement noise: R_eff = D R D with
    D = diag(sqrt(R_scale)) (correlations kept; for a diagonal R, R_ii * R_scale_i).
    """
    A = model.A if A is None else A
    Q = model.Q if Q is None else Q
    R = model.R if R is None else R
    H = model.H
    a_identity = bool(np.array_equal(A, np.eye(A.shape[0])))
    h_identity = bool(H.shape[0] == H.shape[1] and np.array_equal(H, np.eye(H.shape[0])))
    if diagonal:
        r = diagonal_of(R)
        if R_scale is not None:
            r = r * R_scale
        return StepModel(
            diagonal_of(A), diagonal_of(Q), diagonal_of(H), r, True, a_identity, h_identity
        )
    if R_scale is not None:
        d = np.sqrt(R_scale)
        r = diagonal_of(R) * R_scale
        R = R * d[..., :, None] * d[..., None, :]
        # the variances exactly as on the per-axis path (d² rounds differently from R_scale)
        idx = np.arange(R.shape[-1])
        R[..., idx, idx] = r
    return StepModel(A, Q, H, R, False, a_identity, h_identity)


def _check_seq(name: str, M: ArrayLike | None, T: int, shape: tuple[int, ...]) -> Array | None:
    if M is None:
        return None
    arr = np.asarray(M, dtype=float)
    if arr.shape != (T, *shape):
        raise ValueError(f"{name}: expected shape {(T, *shape)} (time first), found {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or infinite entries")
    return arr


def broadcast_param(
    name: str, value: ArrayLike | None, shape: tuple[int, ...], fill: float
) -> Array:
    """``value`` as a float array that broadcasts to ``shape`` (kept at its own shape, so
    that per-axis quantities stay small); ``fill`` when None."""
    if value is None:
        return np.asarray(fill, dtype=float)
    arr = np.asarray(value, dtype=float)
    try:
        ok = np.broadcast_shapes(arr.shape, shape) == shape
    except ValueError:
        ok = False
    if not ok:
        raise ValueError(f"{name}: shape {arr.shape} does not broadcast to {shape}")
    return arr


@dataclass
class RunInputs:
    """Validated inputs of a batch run (internal)."""

    ys: Array
    T: int
    batch: tuple[int, ...]
    diagonal: bool
    A_seq: Array | None
    Q_seq: Array | None
    R_seq: Array | None
    R_scale: Array | None
    lower: Array  # broadcastable to (*batch, p), or to (T, *batch, p) when limits_seq
    upper: Array
    limits_seq: bool
    c: Array | None
    c_seq: bool
    finite_steps: NDArray[np.bool_]  # (T,) the frame has no NaN


def prepare_inputs(
    model: LinearGaussian,
    ys: ArrayLike,
    *,
    A_seq: ArrayLike | None = None,
    Q_seq: ArrayLike | None = None,
    R_seq: ArrayLike | None = None,
    R_scale: ArrayLike | None = None,
    lower: ArrayLike | None = None,
    upper: ArrayLike | None = None,
    lower_seq: ArrayLike | None = None,
    upper_seq: ArrayLike | None = None,
    c: ArrayLike | None = None,
    c_seq: ArrayLike | None = None,
    diagonal: bool | None = None,
) -> RunInputs:
    """Validate a batch call; errors name the argument, the expected and the found shape."""
    if not isinstance(model, LinearGaussian):
        raise TypeError(f"model: expected LinearGaussian, found {type(model).__name__}")
    y = np.asarray(ys, dtype=float)
    n, p = model.n, model.p
    if y.ndim < 2 or y.shape[-1] != p:
        raise ValueError(f"ys: expected shape (T, *batch, p) with p={p}, found {y.shape}")
    T = y.shape[0]
    batch = tuple(y.shape[1:-1])
    finite_steps = np.isfinite(y).all(axis=tuple(range(1, y.ndim)))
    if not finite_steps.all() and np.any(np.isinf(y[~finite_steps])):
        raise ValueError("ys: contains infinite values (use NaN for missing components)")
    try:
        ok = np.broadcast_shapes(model.batch_shape, batch) == batch
    except ValueError:
        ok = False
    if not ok:
        raise ValueError(
            f"model batch shape {model.batch_shape} (x0/P0) does not broadcast to the batch "
            f"shape {batch} of ys"
        )
    A_s = _check_seq("A_seq", A_seq, T, (n, n))
    Q_s = _check_seq("Q_seq", Q_seq, T, (n, n))
    R_s = _check_seq("R_seq", R_seq, T, (p, p))
    if Q_s is not None:
        check_covariance("Q_seq", Q_s)
    if R_s is not None:
        check_covariance("R_seq", R_s, definite=True)
    full = (*batch, p)
    Rsc = None
    if R_scale is not None:
        Rsc = np.broadcast_to(broadcast_param("R_scale", R_scale, (T, *full), 1.0), (T, *full))
        if not np.all(np.isfinite(Rsc)) or np.any(Rsc <= 0):
            raise ValueError("R_scale: entries must be finite and > 0")
    if lower is not None and lower_seq is not None:
        raise ValueError("give either lower or lower_seq, not both")
    if upper is not None and upper_seq is not None:
        raise ValueError("give either upper or upper_seq, not both")
    limits_seq = lower_seq is not None or upper_seq is not None
    if limits_seq:
        lo = np.broadcast_to(
            broadcast_param(
                "lower_seq", lower_seq if lower_seq is not None else lower, (T, *full), -np.inf
            ),
            (T, *full),
        )
        up = np.broadcast_to(
            broadcast_param(
                "upper_seq", upper_seq if upper_seq is not None else upper, (T, *full), np.inf
            ),
            (T, *full),
        )
    else:
        lo = broadcast_param("lower", lower, full, -np.inf)
        up = broadcast_param("upper", upper, full, np.inf)
    if np.any(np.isnan(lo)) or np.any(np.isnan(up)):
        raise ValueError("lower/upper: NaN limits (use -inf / inf for no limit)")
    if np.any(lo >= up):  # also rules out lower = +inf and upper = -inf
        raise ValueError("lower/upper: every lower limit must be < the upper limit")
    cc = None
    if c is not None and c_seq is not None:
        raise ValueError("give either c or c_seq, not both")
    if c_seq is not None:
        cc = np.broadcast_to(broadcast_param("c_seq", c_seq, (T, *full), np.inf), (T, *full))
    elif c is not None:
        cc = broadcast_param("c", c, full, np.inf)
    if cc is not None and (np.any(np.isnan(cc)) or np.any(cc <= 0)):
        raise ValueError("c: half-widths must be > 0 (inf allowed)")
    can_diag = (
        model.is_diagonal
        and (A_s is None or _is_diag(A_s))
        and (Q_s is None or _is_diag(Q_s))
        and (R_s is None or _is_diag(R_s))
    )
    if diagonal is None:
        diagonal = can_diag
    elif diagonal and not can_diag:
        raise ValueError("diagonal=True needs diagonal A, H, Q, R, P0 (and A/Q/R_seq) and n == p")
    return RunInputs(
        y, T, batch, bool(diagonal), A_s, Q_s, R_s, Rsc, lo, up, limits_seq, cc,
        c_seq is not None, finite_steps,
    )  # fmt: skip


def initial_state(
    model: LinearGaussian, batch: tuple[int, ...], diagonal: bool
) -> tuple[Array, Array]:
    """x0 (*batch, n) and P0 (*batch, n, n), writable copies.

    On the diagonal path P holds the variances with the batch axes of P0 only (often
    ``(n,)``): they broadcast against the means and grow to (*batch, n) only when the
    data make them differ (missing components, R_scale).
    """
    n = model.n
    x = np.broadcast_to(model.x0, (*batch, n)).copy()
    if diagonal:
        P = diagonal_of(model.P0).copy()
    else:
        P = np.broadcast_to(model.P0, (*batch, n, n)).copy()
    return x, P


class _Store:
    """Per-step outputs of shape ``full`` that stay small while the values broadcast.

    ``put(t, v)`` in time order; ``get()`` returns (T, *full): a read-only broadcast view
    when no step ever had the full shape, else a dense array.
    """

    def __init__(self, T: int, full: tuple[int, ...], dtype: Any = float) -> None:
        self.T, self.full, self.dtype = T, full, dtype
        self.small: list[Any] = []
        self.arr: NDArray[Any] | None = None

    def put(self, t: int, v: Any) -> None:
        if self.arr is None:
            if np.shape(v) != self.full:
                self.small.append(v)
                return
            self.arr = np.empty((self.T, *self.full), dtype=self.dtype)
            for i, s in enumerate(self.small):
                self.arr[i] = s
            self.small = []
        self.arr[t] = v

    def get(self) -> NDArray[Any]:
        if self.arr is not None:
            return self.arr
        shape = np.broadcast_shapes(*(np.shape(s) for s in self.small))
        stacked = np.empty((self.T, *shape), dtype=self.dtype)
        for i, s in enumerate(self.small):
            stacked[i] = s
        pad = (1,) * (len(self.full) - len(shape))
        return np.broadcast_to(stacked.reshape((self.T, *pad, *shape)), (self.T, *self.full))


# --------------------------------------------------------------------------------------
# the batch run loop
# --------------------------------------------------------------------------------------
def run_filter(
    model: LinearGaussian,
    method: Method,
    inp: RunInputs,
    *,
    keep_probabilities: bool = True,
    keep_predicted: bool = True,
) -> FilterResult:
    """Run ``method`` over all frames of validated inputs; returns a FilterResult.

    Every frame goes through :func:`filter_step`, exactly as in the streaming filter.
    ``keep_probabilities=False`` leaves the censoring probabilities out of the result
    (NaN views): three arrays the size of ``ys`` less. ``keep_predicted=False`` does the
    same for the predicted covariances (which only the RTS smoother reads).
    """
    T, batch, diagonal = inp.T, inp.batch, inp.diagonal
    n, p = model.n, model.p
    ys = inp.ys
    full = (*batch, p)
    cov_full = (*batch, n) if diagonal else (*batch, n, n)
    covs = _Store(T, cov_full)
    pcovs = _Store(T, cov_full)
    loglik = np.empty((T, *batch))
    censoring = method.name != "kf"
    keep = censoring and keep_probabilities
    if censoring:
        clipped = _Store(T, full, bool)
    if keep:
        p_lo, p_un, p_up = _Store(T, full), _Store(T, full), _Store(T, full)
    constant_model = inp.A_seq is None and inp.Q_seq is None and inp.R_seq is None
    constant_model = constant_model and inp.R_scale is None
    sm = make_step_model(model, diagonal) if constant_model else None
    step_model = None if constant_model else _step_models(model, inp)
    x, P = initial_state(model, batch, diagonal)
    # with A = I throughout, x⁻_t = x_{t-1}: one buffer holds both means
    shared = (sm is not None and sm.a_identity) or (
        inp.A_seq is None and bool(np.array_equal(model.A, np.eye(n)))
    )
    # adaptive limits of the diagonal A = I path: computed from the means when asked for
    deferred = method.adaptive and shared and diagonal
    if method.adaptive and not deferred:
        lo_out, up_out = _Store(T, full), _Store(T, full)
    if shared:
        buf = np.empty((T + 1, *batch, n))
        buf[0] = x
        x = buf[0]
        means, pmeans = buf[1:], buf[:-1]
    else:
        means = np.empty((T, *batch, n))
        pmeans = np.empty((T, *batch, n))
    for t in range(T):
        if step_model is not None:
            sm = step_model(t)
        lo = inp.lower[t] if inp.limits_seq else inp.lower
        up = inp.upper[t] if inp.limits_seq else inp.upper
        c = None if inp.c is None else (inp.c[t] if inp.c_seq else inp.c)
        out_x = means[t]
        st = filter_step(
            method, t == 0, x, P, ys[t], sm, lo, up, c,  # type: ignore[arg-type]
            full=True if inp.finite_steps[t] else None, out_x=out_x, need_limits=not deferred,
        )  # fmt: skip
        u = st.update
        if u.x is not out_x:
            means[t] = u.x
        x, P = out_x, u.P
        if not shared:
            pmeans[t] = st.x_pred
        if keep_predicted:
            pcovs.put(t, st.P_pred)
        covs.put(t, P)
        loglik[t] = u.loglik
        if censoring:
            clipped.put(t, False if u.p_uncensored is None else u.clipped)
        if keep:
            if u.p_uncensored is None:
                p_lo.put(t, 0.0)
                p_un.put(t, 1.0)
                p_up.put(t, 0.0)
            else:
                p_lo.put(t, u.p_lower)
                p_un.put(t, u.p_uncensored)
                p_up.put(t, u.p_upper)
        if method.adaptive and not deferred:
            lo_out.put(t, st.lower)
            up_out.put(t, st.upper)
    if censoring:
        clipped_arr = clipped.get()
        if keep:
            p_lower, p_uncensored, p_upper = p_lo.get(), p_un.get(), p_up.get()
        else:
            p_lower = p_uncensored = p_upper = np.broadcast_to(np.nan, (T, *full))
    else:
        p_lower = np.broadcast_to(0.0, (T, *full))
        p_uncensored = np.broadcast_to(1.0, (T, *full))
        p_upper = np.broadcast_to(0.0, (T, *full))
        clipped_arr = np.broadcast_to(False, (T, *full))
    limits: Any
    if deferred:
        limits = _deferred_limits(means, inp, full, sm)  # type: ignore[arg-type]
    elif method.adaptive:
        limits = (lo_out.get(), up_out.get())
    elif inp.limits_seq:
        limits = (inp.lower, inp.upper)
    else:
        limits = (np.broadcast_to(inp.lower, (T, *full)), np.broadcast_to(inp.upper, (T, *full)))
    return FilterResult(
        means=means,
        predicted_means=pmeans,
        cov_data=covs.get(),
        predicted_cov_data=pcovs.get()
        if keep_predicted
        else np.broadcast_to(np.nan, (T, *cov_full)),
        diagonal=diagonal,
        loglik=loglik,
        p_lower=p_lower,
        p_uncensored=p_uncensored,
        p_upper=p_upper,
        clipped=clipped_arr,
        limits=limits,
        A_seq=inp.A_seq,
        method=method.name,
    )


def _step_models(model: LinearGaussian, inp: RunInputs) -> Callable[[int], StepModel]:
    """The StepModel of frame t for per-step A, Q, R or R_scale: what
    :func:`make_step_model` gives, with the per-run work (diagonals, identity checks)
    done once on the diagonal path without A_seq / R_seq (the same numbers)."""
    if not (inp.diagonal and inp.A_seq is None and inp.R_seq is None):

        def general(t: int) -> StepModel:
            return make_step_model(
                model,
                inp.diagonal,
                A=None if inp.A_seq is None else inp.A_seq[t],
                Q=None if inp.Q_seq is None else inp.Q_seq[t],
                R=None if inp.R_seq is None else inp.R_seq[t],
                R_scale=None if inp.R_scale is None else inp.R_scale[t],
            )

        return general
    base = make_step_model(model, True)
    q_all = None if inp.Q_seq is None else diagonal_of(inp.Q_seq)
    r_scale = inp.R_scale

    def diag(t: int) -> StepModel:
        q = base.Q if q_all is None else q_all[t]
        r = base.R if r_scale is None else base.R * r_scale[t]
        return StepModel(base.A, q, base.H, r, True, base.a_identity, base.h_identity)

    return diag


def _deferred_limits(
    means: Array, inp: RunInputs, full: tuple[int, ...], sm: StepModel
) -> Callable[[], tuple[Array, Array]]:
    """Adaptive limits H x̂_{t-1} ± c_t of the diagonal A = I path (±inf at t = 0), formed
    with the same elementwise operations as :func:`filter_step` (identical numbers)."""

    def limits() -> tuple[Array, Array]:
        T = inp.T
        lo = np.empty((T, *full))
        up = np.empty((T, *full))
        lo[:1], up[:1] = -np.inf, np.inf
        if T > 1:
            centre = means[:-1] if sm.h_identity else sm.H * means[:-1]
            c = inp.c[1:] if inp.c_seq else inp.c
            np.subtract(centre, c, out=lo[1:])
            np.add(centre, c, out=up[1:])
        return lo, up

    return limits
