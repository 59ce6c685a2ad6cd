"""Model and result containers for the Kalman / Tobit Kalman filters.

`LinearGaussian` is the state-space model of the 2020 paper (eq. 1-3)::

    x_k  = A x_{k-1} + w_k,   w_k ~ N(0, Q)
    y*_k = H x_k + v_k,       v_k ~ N(0, R)
    y_k  = clip(y*_k, a, b)   (per component; the limits belong to the filter call)

`FilterResult` and `SmootherResult` hold time-first arrays ``(T, *batch, ...)``. When the
fast per-axis (diagonal) path was used only the variances are stored; the full covariance
matrices are built on first access of ``covs`` / ``predicted_covs``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FilterResult", "LinearGaussian", "SmootherResult", "embed_diagonal"]

Array = NDArray[np.float64]

_SYM_RTOL = 1e-9
_PSD_TOL = 1e-10


def embed_diagonal(v: NDArray[Any]) -> Array:
    """Diagonal matrices from their diagonals.

    Parameters
    ----------
    v : ndarray, shape (..., n)

    Returns
    -------
    ndarray, shape (..., n, n)
        ``out[..., i, i] = v[..., i]``, zeros elsewhere.
    """
    v = np.asarray(v, dtype=float)
    n = v.shape[-1]
    out = np.zeros((*v.shape, n))
    idx = np.arange(n)
    out[..., idx, idx] = v
    return out


def _is_diag(M: NDArray[Any]) -> bool:
    """True when every matrix in the stack ``M (..., n, n)`` is diagonal (exact zeros)."""
    n = M.shape[-1]
    off = ~np.eye(n, dtype=bool)
    return not np.any(M[..., off])


def _as_matrix(name: str, value: ArrayLike, shape: tuple[int, ...]) -> Array:
    arr = np.array(value, dtype=float)
    if arr.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, found {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or infinite entries")
    return arr


def check_covariance(name: str, M: NDArray[Any], *, definite: bool = False) -> None:
    """Validate a stack of covariance matrices ``M (..., k, k)``.

    Raises ``ValueError`` naming ``name`` when an entry is not finite, a matrix is not
    symmetric (relative tolerance 1e-9), or not positive semi-definite (positive definite
    when ``definite``).
    """
    M = np.asarray(M, dtype=float)
    if M.ndim < 2 or M.shape[-1] != M.shape[-2]:
        raise ValueError(f"{name}: expected square matrices (..., k, k), found shape {M.shape}")
    if not np.all(np.isfinite(M)):
        raise ValueError(f"{name}: contains NaN or infinite entries")
    scale = np.max(np.abs(M), axis=(-2, -1), keepdims=True)
    asym = np.abs(M - np.swapaxes(M, -1, -2))
    if np.any(asym > _SYM_RTOL * np.maximum(scale, np.finfo(float).tiny)):
        raise ValueError(f"{name}: not symmetric")
    if M.shape[-1] == 0:
        return
    eig = np.linalg.eigvalsh(0.5 * (M + np.swapaxes(M, -1, -2)))
    tol = _PSD_TOL * scale[..., 0, 0]  # one per matrix (a stack: one per entry)
    if definite:
        if np.any(eig[..., 0] <= 0.0):
            raise ValueError(
                f"{name}: not positive definite (smallest eigenvalue {eig[..., 0].min():.3g})"
            )
    elif np.any(eig[..., 0] < -tol):
        raise ValueError(
            f"{name}: not positive semi-definite (smallest eigenvalue {eig[..., 0].min():.3g})"
        )


@dataclass(frozen=True, eq=False)
class LinearGaussian:
    """Linear-Gaussian state-space model (2020 paper, eq. 1-2).

    Parameters
    ----------
    A : array_like, shape (n, n)
        State transition.
    H : array_like, shape (p, n)
        Observation matrix.
    Q : array_like, shape (n, n)
        Process-noise covariance, symmetric positive semi-definite.
    R : array_like, shape (p, p)
        Measurement-noise covariance, symmetric positive definite.
    x0 : array_like, shape (n,) or (*batch, n)
        Mean of the state before the first measurement (time index 0 of the filters is
        the first measurement: the filters predict from ``x0`` first).
    P0 : array_like, shape (n, n) or (*batch, n, n)
        Covariance of ``x0``, symmetric positive semi-definite.

    Notes
    -----
    Arrays are copied, converted to float and made read-only. Every error names the
    argument, the expected shape and what was found.
    """

    A: Array
    H: Array
    Q: Array
    R: Array
    x0: Array
    P0: Array

    def __post_init__(self) -> None:
        A = np.array(self.A, dtype=float)
        if A.ndim != 2 or A.shape[0] != A.shape[1]:
            raise ValueError(f"A: expected a square matrix (n, n), found shape {A.shape}")
        n = A.shape[0]
        H = np.array(self.H, dtype=float)
        if H.ndim != 2 or H.shape[1] != n:
            raise ValueError(f"H: expected shape (p, {n}), found {H.shape}")
        p = H.shape[0]
        A = _as_matrix("A", A, (n, n))
        H = _as_matrix("H", H, (p, n))
        Q = _as_matrix("Q", self.Q, (n, n))
        R = _as_matrix("R", self.R, (p, p))
        check_covariance("Q", Q)
        check_covariance("R", R, definite=True)
        x0 = np.array(self.x0, dtype=float)
        if x0.ndim < 1 or x0.shape[-1] != n:
            raise ValueError(f"x0: expected shape (n,) or (*batch, n) with n={n}, found {x0.shape}")
        if not np.all(np.isfinite(x0)):
            raise ValueError("x0: contains NaN or infinite entries")
        P0 = np.array(self.P0, dtype=float)
        if P0.ndim < 2 or P0.shape[-2:] != (n, n):
            raise ValueError(
                f"P0: expected shape (n, n) or (*batch, n, n) with n={n}, found {P0.shape}"
            )
        check_covariance("P0", P0)
        try:
            np.broadcast_shapes(x0.shape[:-1], P0.shape[:-2])
        except ValueError:
            raise ValueError(
                f"x0 batch shape {x0.shape[:-1]} and P0 batch shape {P0.shape[:-2]} "
                "do not broadcast"
            ) from None
        for name, arr in (("A", A), ("H", H), ("Q", Q), ("R", R), ("x0", x0), ("P0", P0)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def n(self) -> int:
        """State dimension."""
        return int(self.A.shape[0])

    @property
    def p(self) -> int:
        """Measurement dimension."""
        return int(self.H.shape[0])

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Batch shape carried by ``x0`` / ``P0`` (``()`` when unbatched)."""
        return np.broadcast_shapes(self.x0.shape[:-1], self.P0.shape[:-2])

    @cached_property
    def is_diagonal(self) -> bool:
        """True when A, H, Q, R and P0 are diagonal and n == p (per-axis fast path)."""
        return self.n == self.p and all(
            _is_diag(M) for M in (self.A, self.H, self.Q, self.R, self.P0)
        )

    def replace(self, **changes: Any) -> LinearGaussian:
        """Copy with some fields replaced (validated again)."""
        fields = {k: getattr(self, k) for k in ("A", "H", "Q", "R", "x0", "P0")}
        fields.update(changes)
        return LinearGaussian(**fields)

    @classmethod
    def random_walk(
        cls,
        q: ArrayLike,
        r: ArrayLike,
        x0: ArrayLike | None = None,
        p0: ArrayLike | None = None,
        *,
        dim: int = 3,
        ys: ArrayLike | None = None,
    ) -> LinearGaussian:
        """Independent random walk per axis, observed directly: A = H = I (``dim`` axes).

        Parameters
        ----------
        q, r : float or array_like, shape (dim,)
            Process / measurement variances, one value or one per axis.
        x0 : array_like, shape (dim,) or (*batch, dim), optional
            Initial state. Default: zeros, or taken from ``ys`` when given.
        p0 : float or array_like, shape (dim,), optional
            Initial variances per axis. Default ``r`` (the state starts at a measurement).
        dim : int
            Number of axes (default 3).
        ys : array_like, shape (T, *batch, dim), optional
            Measurements; each component of ``x0`` is set to the first non-NaN value of
            that component over time (0 when it is never observed). Ignored if ``x0`` is
            given.

        Returns
        -------
        LinearGaussian
            n = p = dim, diagonal, batch shape that of ``x0``.
        """
        qv = _per_axis("q", q, dim)
        rv = _per_axis("r", r, dim)
        pv = rv if p0 is None else _per_axis("p0", p0, dim)
        if x0 is None:
            x0 = np.zeros(dim) if ys is None else first_observed(ys)
        eye = np.eye(dim)
        return cls(A=eye, H=eye, Q=np.diag(qv), R=np.diag(rv), x0=x0, P0=np.diag(pv))


def _per_axis(name: str, value: ArrayLike, dim: int) -> Array:
    """One value or one per axis as a (dim,) array; the error names the argument."""
    arr = np.asarray(value, dtype=float)
    if arr.shape not in ((), (1,), (dim,)):
        raise ValueError(
            f"{name}: expected one value or one per axis, shape ({dim},); found {arr.shape}"
        )
    return np.broadcast_to(arr, (dim,))


def first_observed(ys: ArrayLike) -> Array:
    """First non-NaN value of every component over time.

    Parameters
    ----------
    ys : array_like, shape (T, *batch, p)

    Returns
    -------
    ndarray, shape (*batch, p)
        0 where a component is never observed.
    """
    ys = np.asarray(ys, dtype=float)
    if ys.ndim < 2:
        raise ValueError(f"ys: expected shape (T, *batch, p), found {ys.shape}")
    ok = ~np.isnan(ys)
    first = np.argmax(ok, axis=0)
    out = np.take_along_axis(ys, first[None], axis=0)[0]
    return np.where(ok.any(axis=0), out, 0.0)


def _readonly(a: NDArray[Any] | None) -> None:
    if a is not None and a.flags.writeable:
        a.setflags(write=False)


@dataclass(frozen=True, eq=False)
class FilterResult:
    """Output of a batch filter, time-first.

    Attributes
    ----------
    means : ndarray, shape (T, *batch, n)
        Filtered means x̂_k.
    predicted_means : ndarray, shape (T, *batch, n)
        Predicted means x̂_k⁻.
    cov_data, predicted_cov_data : ndarray
        Storage of the (predicted) covariances: (T, *batch, n, n), or the variances
        (T, *batch, n) when ``diagonal``. Use ``covs`` / ``variances`` instead.
    diagonal : bool
        True when the per-axis fast path was used (all covariances diagonal).
    loglik : ndarray, shape (T, *batch)
        Per-step log-likelihood (MATH.md §4, see the filter functions for the variant).
    p_lower, p_uncensored, p_upper : ndarray, shape (T, *batch, p)
        Censoring probabilities used in the update (0, 1, 0 for the plain KF).
    clipped : ndarray of bool, shape (T, *batch, p)
        The (observed) measurement component was at or beyond a limit.
    limits : (lower, upper) or a callable returning them
        Storage of the limits; a callable is evaluated on first access of ``lower`` /
        ``upper`` (the adaptive filter's limits are then computed from the means, in one
        vectorised pass, only if asked for).
    lower, upper : ndarray, shape (T, *batch, p)
        Properties: the limits used (adaptive filter: the adaptive ones, ±inf at the
        first step; ±inf for the KF).
    A_seq : ndarray, shape (T, n, n), or None
        Transition used in the prediction of every step (None: ``model.A`` throughout).
    method : str
        "kf", "tkf", "tkfc" or "atkf".

    Notes
    -----
    All arrays are read-only. Quantities that do not vary over the batch (e.g. the
    variances of a diagonal model without missing data, the KF's censoring
    probabilities, constant limits) are stored once and exposed as broadcast views of the
    documented shape; ``np.array(x)`` gives a dense copy. With A = I the predicted means
    share memory with the filtered ones (x̂⁻_t = x̂_{t-1}).
    """

    means: Array
    predicted_means: Array
    cov_data: Array
    predicted_cov_data: Array
    diagonal: bool
    loglik: Array
    p_lower: Array
    p_uncensored: Array
    p_upper: Array
    clipped: NDArray[np.bool_]
    limits: tuple[Array, Array] | Callable[[], tuple[Array, Array]]
    A_seq: Array | None = None
    method: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for a in (
            self.means, self.predicted_means, self.cov_data, self.predicted_cov_data,
            self.loglik, self.p_lower, self.p_uncensored, self.p_upper, self.clipped,
        ):  # fmt: skip
            _readonly(a)

    @cached_property
    def _limits(self) -> tuple[Array, Array]:
        lo, up = self.limits() if callable(self.limits) else self.limits
        _readonly(lo)
        _readonly(up)
        return lo, up

    @property
    def lower(self) -> Array:
        """Lower limits used, shape (T, *batch, p)."""
        return self._limits[0]

    @property
    def upper(self) -> Array:
        """Upper limits used, shape (T, *batch, p)."""
        return self._limits[1]

    @cached_property
    def covs(self) -> Array:
        """Filtered covariances P_k, shape (T, *batch, n, n)."""
        return embed_diagonal(self.cov_data) if self.diagonal else self.cov_data

    @cached_property
    def predicted_covs(self) -> Array:
        """Predicted covariances P_k⁻, shape (T, *batch, n, n)."""
        return embed_diagonal(self.predicted_cov_data) if self.diagonal else self.predicted_cov_data

    @property
    def variances(self) -> Array:
        """Diagonals of ``covs``, shape (T, *batch, n)."""
        if self.diagonal:
            return self.cov_data
        return np.diagonal(self.cov_data, axis1=-2, axis2=-1)

    @property
    def predicted_variances(self) -> Array:
        """Diagonals of ``predicted_covs``, shape (T, *batch, n)."""
        if self.diagonal:
            return self.predicted_cov_data
        return np.diagonal(self.predicted_cov_data, axis1=-2, axis2=-1)

    @property
    def n_steps(self) -> int:
        """T."""
        return int(self.means.shape[0])

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Batch shape."""
        return tuple(self.means.shape[1:-1])


@dataclass(frozen=True, eq=False)
class SmootherResult:
    """Output of the RTS smoother, time-first.

    Attributes
    ----------
    means : ndarray, shape (T, *batch, n)
        Smoothed means E[x_k | y_1..y_T] (under the filter's Gaussian approximation).
    cov_data : ndarray
        (T, *batch, n, n), or the variances (T, *batch, n) when ``diagonal``.
    diagonal : bool
    gains : ndarray or None
        Smoother gains G_k (diagonal path: (T, *batch, n); else (T, *batch, n, n)); the
        last one is zero.
    """

    means: Array
    cov_data: Array
    diagonal: bool = False
    gains: Array | None = None

    def __post_init__(self) -> None:
        _readonly(self.means)
        _readonly(self.cov_data)

    @cached_property
    def covs(self) -> Array:
        """Smoothed covariances, shape (T, *batch, n, n)."""
        return embed_diagonal(self.cov_data) if self.diagonal else self.cov_data

    @property
    def variances(self) -> Array:
        """Diagonals of ``covs``, shape (T, *batch, n)."""
        if self.diagonal:
            return self.cov_data
        return np.diagonal(self.cov_data, axis1=-2, axis2=-1)
