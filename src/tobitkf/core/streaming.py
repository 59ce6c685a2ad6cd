"""One frame at a time: the batch filters for live use.

:class:`StreamingFilter` calls the very same step function
(:func:`tobitkf.core.kalman.filter_step`) as the batch functions, so feeding the frames of a
batch one by one reproduces the batch result exactly (bit for bit when the same arguments
are given).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tobitkf.core.engine import (
    StepOutput,
    broadcast_param,
    filter_step,
    initial_state,
    make_step_model,
)
from tobitkf.core.model import LinearGaussian, check_covariance, embed_diagonal
from tobitkf.core.tobit import FILTER_METHODS

__all__ = ["StreamingFilter"]

Array = NDArray[np.float64]


def _opt_array(name: str, value: ArrayLike | None) -> Array | None:
    if value is None:
        return None
    arr = np.asarray(value, dtype=float)
    if np.any(np.isnan(arr)):
        raise ValueError(f"{name}: contains NaN")
    return arr


class StreamingFilter:
    """Online KF / TKF / TKF^c / ATKF, identical to the batch functions frame by frame.

    Parameters
    ----------
    model : LinearGaussian
    method : {"kf", "tkf", "tkfc", "atkf"}
        Plain KF, standard Tobit (Allik), corrected Tobit (2020), adaptive Tobit (2020).
    lower, upper : array_like, broadcastable to (*batch, p), optional
        Fixed limits of "tkf" / "tkfc" (default ±inf); can be overridden per step.
    c : array_like, broadcastable to (*batch, p)
        Half-widths of "atkf" (required for it); can be overridden per step.
    diagonal : bool, optional
        Force / forbid the per-axis path (default: when the model is diagonal).

    Examples
    --------
    >>> f = StreamingFilter(LinearGaussian.random_walk(0.0025, 0.01), "atkf", c=[0.34, 0.18, 0.34])
    >>> mean, cov = f.step(frame)          # frame (*batch, 3), NaN = missing   # doctest: +SKIP
    """

    def __init__(
        self,
        model: LinearGaussian,
        method: str = "atkf",
        *,
        lower: ArrayLike | None = None,
        upper: ArrayLike | None = None,
        c: ArrayLike | None = None,
        diagonal: bool | None = None,
    ) -> None:
        if not isinstance(model, LinearGaussian):
            raise TypeError(f"model: expected LinearGaussian, found {type(model).__name__}")
        if method not in FILTER_METHODS:
            raise ValueError(f"method: expected one of {sorted(FILTER_METHODS)}, found {method!r}")
        self.model = model
        self.method = method
        self._method = FILTER_METHODS[method]
        if method == "atkf" and c is None:
            raise ValueError("method 'atkf' needs c (half-widths of the adaptive limits)")
        self.lower = _opt_array("lower", lower)
        self.upper = _opt_array("upper", upper)
        self.c = _opt_array("c", c)
        if diagonal and not model.is_diagonal:
            raise ValueError("diagonal=True needs a diagonal model (A, H, Q, R, P0) and n == p")
        self.diagonal = model.is_diagonal if diagonal is None else bool(diagonal)
        self.reset()

    def reset(self) -> None:
        """Forget all frames: the next step starts again from (x0, P0)."""
        self.t = 0
        self._x: Array | None = None
        self._P: Array | None = None
        self.last: StepOutput | None = None

    # ------------------------------------------------------------------ state exposure
    @property
    def mean(self) -> Array | None:
        """Current filtered mean (*batch, n) (None before the first step)."""
        return self._x

    @property
    def cov(self) -> Array | None:
        """Current filtered covariance (*batch, n, n) (None before the first step)."""
        if self._P is None or self._x is None:
            return None
        if not self.diagonal:
            return self._P
        n = self._x.shape[-1]
        return np.broadcast_to(embed_diagonal(self._P), (*self._x.shape[:-1], n, n))

    @property
    def variances(self) -> Array | None:
        """Diagonal of ``cov``, (*batch, n)."""
        if self._P is None or self._x is None:
            return None
        if self.diagonal:
            return np.broadcast_to(self._P, self._x.shape)
        return np.diagonal(self._P, axis1=-2, axis2=-1)

    @property
    def loglik(self) -> Array | None:
        """Log-likelihood of the last step (*batch) (see the batch functions)."""
        return None if self.last is None else self.last.update.loglik

    def seed(self, mask: ArrayLike, mean: ArrayLike) -> None:
        """Overwrite the current mean of some batch elements before the next step.

        Used to start a track when it is first observed (e.g. a joint that was missing
        in the first frames): with A = I this is exactly what the batch functions do with
        ``x0`` set to each element's first measurement. Covariances are left as they are.

        Parameters
        ----------
        mask : array_like of bool, shape (*batch,)
            Elements to overwrite.
        mean : array_like, broadcastable to (*batch, n)
            New means (only the masked elements are used).
        """
        if self._x is None:
            raise RuntimeError("seed() needs a state: call it after the first step")
        m = np.asarray(mask, dtype=bool)
        if m.shape != self._x.shape[:-1]:
            raise ValueError(f"mask: expected shape {self._x.shape[:-1]}, found {m.shape}")
        values = np.broadcast_to(np.asarray(mean, dtype=float), self._x.shape)
        x = np.array(self._x, dtype=float)  # the state may be a read-only view
        x[m] = values[m]
        self._x = x

    # ------------------------------------------------------------------ stepping
    def step(
        self,
        y: ArrayLike,
        *,
        A: ArrayLike | None = None,
        Q: ArrayLike | None = None,
        R: ArrayLike | None = None,
        R_scale: ArrayLike | None = None,
        lower: ArrayLike | None = None,
        upper: ArrayLike | None = None,
        c: ArrayLike | None = None,
    ) -> tuple[Array, Array]:
        """Filter one frame.

        Parameters
        ----------
        y : array_like, shape (*batch, p)
            The frame; NaN components are unobserved.
        A, Q : array_like, shape (n, n), optional
            Transition / process noise for this step only (e.g. Q scaled by the frame
            interval dt).
        R : array_like, shape (p, p), optional
            Measurement noise for this step only.
        R_scale : array_like, broadcastable to (*batch, p), optional
            Per-component variance multiplier for this step.
        lower, upper, c : array_like, optional
            Limits (tkf / tkfc) or half-widths (atkf) for this step only.

        Returns
        -------
        mean : ndarray, shape (*batch, n)
        cov : ndarray, shape (*batch, n, n)
        """
        model = self.model
        yv = np.asarray(y, dtype=float)
        if yv.ndim < 1 or yv.shape[-1] != model.p:
            raise ValueError(f"y: expected shape (*batch, {model.p}), found {yv.shape}")
        if np.any(np.isinf(yv)):
            raise ValueError("y: contains infinite values (use NaN for missing components)")
        n, p = model.n, model.p
        A_ = None if A is None else np.asarray(A, dtype=float)
        Q_ = None if Q is None else np.asarray(Q, dtype=float)
        R_ = None if R is None else np.asarray(R, dtype=float)
        for name, M, shape in (("A", A_, (n, n)), ("Q", Q_, (n, n)), ("R", R_, (p, p))):
            if M is not None and M.shape != shape:
                raise ValueError(f"{name}: expected shape {shape}, found {M.shape}")
        if Q_ is not None:
            check_covariance("Q", Q_)
        if R_ is not None:
            check_covariance("R", R_, definite=True)
        if A_ is not None and not np.all(np.isfinite(A_)):
            raise ValueError("A: contains NaN or infinite entries")
        full = yv.shape
        Rs = None
        if R_scale is not None:
            Rs = broadcast_param("R_scale", R_scale, full, 1.0)
            if not np.all(np.isfinite(Rs)) or np.any(Rs <= 0):
                raise ValueError("R_scale: entries must be finite and > 0")
        if self.diagonal and any(
            M is not None and np.any(M[~np.eye(M.shape[0], dtype=bool)]) for M in (A_, Q_, R_)
        ):
            self._to_general()
        if self._x is None:
            batch = np.broadcast_shapes(model.batch_shape, yv.shape[:-1])
            if batch != yv.shape[:-1]:
                raise ValueError(
                    f"model batch shape {model.batch_shape} does not broadcast to the frame's "
                    f"batch shape {yv.shape[:-1]}"
                )
            self._x, self._P = initial_state(model, batch, self.diagonal)
        elif yv.shape[:-1] != self._x.shape[:-1]:
            raise ValueError(
                f"y: batch shape {yv.shape[:-1]} differs from the filter's {self._x.shape[:-1]}"
            )
        lo = _opt_array("lower", lower)
        up = _opt_array("upper", upper)
        lo_b = broadcast_param("lower", self.lower if lo is None else lo, full, -np.inf)
        up_b = broadcast_param("upper", self.upper if up is None else up, full, np.inf)
        if np.any(lo_b >= up_b):
            raise ValueError("lower/upper: every lower limit must be < the upper limit")
        cc = _opt_array("c", c)
        cc = self.c if cc is None else cc
        if cc is not None:
            cc = broadcast_param("c", cc, full, np.inf)
            if np.any(cc <= 0):
                raise ValueError("c: half-widths must be > 0 (inf allowed)")
        sm = make_step_model(model, self.diagonal, A=A_, Q=Q_, R=R_, R_scale=Rs)
        st = filter_step(self._method, self.t == 0, self._x, self._P, yv, sm, lo_b, up_b, cc)
        self.last = st
        self._x, self._P = st.update.x, st.update.P
        self.t += 1
        return self._x, self.cov  # type: ignore[return-value]

    def _to_general(self) -> None:
        """Switch from the per-axis path to full covariances (a non-diagonal override)."""
        if self._P is not None and self._x is not None:
            n = self._x.shape[-1]
            self._P = np.broadcast_to(embed_diagonal(self._P), (*self._x.shape[:-1], n, n)).copy()
        self.diagonal = False
