"""Live smoothing: one skeleton frame at a time, the same numbers as :func:`smooth`.

:class:`LiveSmoother` wraps :class:`tobitkf.StreamingFilter` with what
:func:`tobitkf.smooth` does for a whole recording: the process noise scales with the
time step, the adaptive limits with the time since a joint was last measured, inferred
joints get a larger measurement noise, not-tracked or missing joints are predicted, and
a joint starts at its first measurement. Fed the frames of a recording one by one, it
returns what ``smooth(recording, method)`` returns (tested), without looking ahead.

Example
-------
>>> live = LiveSmoother("kinect_v2", method="atkf", fps=30)        # doctest: +SKIP
>>> for frame, states, t in sensor:                                # doctest: +SKIP
...     clean = live.update(frame, tracking_state=states, timestamp=t)
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tobitkf.skeleton.topology import Topology, get_topology

__all__ = ["LIVE_METHODS", "LiveSmoother"]

#: causal Kalman-type methods that can run live (the offline smoother cannot)
LIVE_METHODS = ("atkf", "atkf2016", "kf", "tkf", "tkfc")


class LiveSmoother:
    """Smooth a live skeleton stream frame by frame.

    Parameters
    ----------
    topology : Topology or name
        Skeleton of the stream (its up axis places the vertical limit of ``atkf``).
    method : {"atkf", "atkf2016", "kf", "tkf", "tkfc"}
        Causal Kalman-type method; parameters as for :func:`tobitkf.smooth`.
    fps : float
        Nominal frame rate, used when no timestamps are given (and for the first step).
    up_axis : int, optional
        Overrides the topology's up axis.
    inferred_noise_factor : float
        Measurement-noise variance multiplier for INFERRED joints (as in ``smooth``).
    **params
        Method parameters (``q``, ``r``, ``c``, ``c_horizontal``, ``c_vertical``, ``lower``,
        ``upper``); unknown names raise ``ValueError`` listing the valid ones.
    """

    def __init__(
        self,
        topology: Topology | str = "kinect_v2",
        method: str = "atkf",
        *,
        fps: float = 30.0,
        up_axis: int | None = None,
        inferred_noise_factor: float | None = None,
        **params: Any,
    ) -> None:
        from tobitkf.smoothing import api as sm

        if method not in LIVE_METHODS:
            raise ValueError(
                f"method {method!r} cannot run live; choose one of {', '.join(LIVE_METHODS)} "
                "(offline smoothing and the non-causal baselines need the whole recording)"
            )
        if not (fps > 0 and np.isfinite(fps)):
            raise ValueError(f"fps must be a positive number, got {fps!r}")
        self.topology = get_topology(topology) if isinstance(topology, str) else topology
        self.method = method
        self.spec = sm.METHODS[method]
        self.params = sm.check_params(method, params)
        self.up_axis = int(self.topology.up_axis) if up_axis is None else sm._check_up_axis(up_axis)
        self.inferred_noise_factor = (
            sm.DEFAULT_INFERRED_NOISE_FACTOR
            if inferred_noise_factor is None
            else sm._inferred_factor(inferred_noise_factor)
        )
        self.fps = float(fps)
        self._ref = sm.REFERENCE_DT
        self._Q = sm._diag3(self.params["q"])
        self._R = sm._diag3(self.params["r"])
        kind = self.spec.options["filter"]
        self._c = sm._atkf_c(self.params, self.up_axis) if kind == "atkf" else None
        self.reset()

    def reset(self) -> None:
        """Forget the stream; the next frame starts new tracks."""
        self._filter = None
        self._started: NDArray[np.bool_] | None = None
        self._last_valid_time: NDArray[np.float64] | None = None
        self._time = 0.0
        self._last_timestamp: float | None = None
        self.n_frames = 0
        self.clipped: NDArray[np.bool_] | None = None

    def _make_filter(self, ys: NDArray[np.float64], valid: NDArray[np.bool_]):
        from tobitkf.core.model import LinearGaussian
        from tobitkf.core.streaming import StreamingFilter

        x0 = np.where(valid[..., None], ys, 0.0)
        model = LinearGaussian(A=np.eye(3), H=np.eye(3), Q=self._Q, R=self._R, x0=x0, P0=self._R)
        kind = self.spec.options["filter"]
        if kind == "atkf":
            return StreamingFilter(model, "atkf", c=self._c)
        if kind == "kf":
            return StreamingFilter(model, "kf")
        method = "tkf" if self.spec.options["variant"] == "standard" else "tkfc"
        return StreamingFilter(
            model,
            method,
            lower=np.asarray(self.params["lower"], dtype=float),
            upper=np.asarray(self.params["upper"], dtype=float),
        )

    def _step_seconds(self, timestamp: float | None) -> float:
        nominal = 1.0 / self.fps
        if timestamp is None:
            return nominal
        t = float(timestamp)
        if not np.isfinite(t):
            raise ValueError(f"timestamp must be finite, got {timestamp!r}")
        if self._last_timestamp is None:
            dt = nominal
        elif t < self._last_timestamp:
            raise ValueError(f"timestamps must not decrease: {t} after {self._last_timestamp}")
        else:
            dt = max(t - self._last_timestamp, 0.1 * nominal)
        self._last_timestamp = t
        return dt

    def update(
        self,
        positions: ArrayLike,
        tracking_state: ArrayLike | None = None,
        timestamp: float | None = None,
    ) -> NDArray[np.float64]:
        """Filter one frame.

        Parameters
        ----------
        positions : array_like, shape (J, 3) or (B, J, 3) for B bodies
            Metres; NaN for a missing joint.
        tracking_state : array_like of int, shape (J,) or (B, J), optional
            0 not tracked (treated as missing), 1 inferred (noisier), 2 tracked.
        timestamp : float, optional
            Seconds; without it frames are 1/fps apart.

        Returns
        -------
        ndarray, shape like ``positions``
            Smoothed positions; NaN for a joint not measured yet.
        """
        from tobitkf.smoothing import api as sm

        shape = np.shape(positions)
        if len(shape) not in (2, 3) or shape[-1] != 3:
            raise ValueError(f"positions: expected shape (J, 3) or (B, J, 3), found {shape}")
        if shape[-2] != self.topology.n_joints:
            raise ValueError(
                f"positions: {shape[-2]} joints, but topology {self.topology.name!r} has "
                f"{self.topology.n_joints}"
            )
        if self._started is not None and shape[:-1] != self._started.shape:
            # checked before the clock moves: a rejected frame leaves the stream unchanged
            raise ValueError(
                f"positions: batch shape {shape[:-1]} differs from the stream's "
                f"{self._started.shape}"
            )
        states = None if tracking_state is None else np.asarray(tracking_state)
        if states is not None and states.shape != shape[:-1]:
            raise ValueError(f"tracking_state: expected shape {shape[:-1]}, found {states.shape}")
        ys, missing = sm._measurements(positions, states)
        valid = ~missing
        dt = self._step_seconds(timestamp)
        self._time += dt
        if self._filter is None:
            self._filter = self._make_filter(ys, valid)
            self._started = valid.copy()
            self._last_valid_time = np.full(valid.shape, np.nan)
        else:
            new = valid & ~self._started
            if new.any():
                self._filter.seed(new, ys)
                self._started |= new
        kwargs: dict[str, Any] = {}
        ratio = dt / self._ref
        kwargs["Q"] = self._Q * ratio
        r_scale = sm._inferred_r_scale(states, valid, self.inferred_noise_factor)
        if r_scale is not None:
            kwargs["R_scale"] = r_scale
        if self._c is not None:
            last = self._last_valid_time
            elapsed = np.where(np.isfinite(last), self._time - last, dt)
            kwargs["c"] = self._c * (elapsed / self._ref)[..., None]
        mean, _ = self._filter.step(ys, **kwargs)
        last_out = self._filter.last
        clipped = None if last_out is None else last_out.update.clipped
        self.clipped = None if clipped is None else np.asarray(clipped).any(axis=-1) & valid
        self._last_valid_time = np.where(valid, self._time, self._last_valid_time)
        self.n_frames += 1
        out = np.array(mean, dtype=float)
        out[~self._started] = np.nan
        return out
