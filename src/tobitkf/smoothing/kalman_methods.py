"""The papers' Kalman-type methods: ``kf``, ``tkf``, ``tkfc``, ``atkf``, ``atkf2016``.

Every method models each joint as an independent 3-D random walk (A = H = I),
vectorised over joints and bodies; x0 is the joint's first valid measurement and P0 = R.
``offline=True`` runs the RTS smoother after the filter.

Time steps. The paper's constants refer to 30 fps. When the sequence has timestamps or a
frame rate other than 30 Hz, step k uses ``Q_k = Q · dt_k / (1/30)`` (a random walk's
variance grows linearly with time) and ``c_k = c · dt_k / (1/30)`` (c is a largest
displacement per frame). ``dt_0`` (no previous frame) is the nominal step (1/fps, or the
median step of the timestamps). Zero steps (duplicated timestamps) are raised to a tenth
of the nominal step so no limit collapses to zero. Without timestamps or fps, 30 fps is
assumed.

Gaps. ``c`` bounds the displacement per 1/30 s, so the ATKF limits of a joint that
reappears after missing frames widen with the time elapsed since its last measurement
(``c · elapsed / (1/30)``); otherwise a joint that moved during an occlusion would crawl
back at ``gain · c`` per frame.

Pauses. A time step so long that the random walk's variance would exceed 100 R (13.3 s
with the paper's Q and R), and at least 1 s, is a new start: every joint restarts at its
next measurement
(x0 = that measurement, P0 = R) and, offline, nothing is smoothed across the pause; live,
the stepper restarts alike. (A per-joint gap of missing frames is still predicted
through.)

Up axis. The vertical entry of ``c`` goes on the topology's ``up_axis`` (y for Kinect
camera space, z for most optical systems); ``up_axis=`` overrides it. An explicit
``c=(cx, cy, cz)`` is used as given, in the sequence's axes. The Kinect device limits of
``tkf`` / ``tkfc`` are defined in Kinect camera axes (x right, y up, z depth from the
sensor): they only make sense for Kinect camera-space data; give ``lower=`` / ``upper=``
for anything else. A sensor that clips at a limit reports the limit itself, never a
value beyond it: a sample beyond a limit (by more than 1 µm) is therefore used as an
ordinary measurement on that axis instead of a censored one (the core filters, which
follow the papers, would read it as censored at the limit and, if it stays there, pull
the estimate ever further out: KIMORE's feet at y = -1.54 m against the -1.5 m limit
drifted 1.3 m with ``tkfc``). When a joint axis lies beyond a limit persistently (at
least 10 samples and 1 % of its samples) a warning says that the limits do not describe
the recording.

Tracking states. NOT_TRACKED joints and NaN positions are predicted, not updated.
INFERRED joints get their measurement variance multiplied by ``inferred_noise_factor``.
Frames before a joint's first valid measurement stay NaN; later gaps are filled by the
filter's prediction (hold, for a random walk) or, offline, by the RTS interpolation.

Uncertainty. The output's ``std`` is the posterior standard deviation of each position:
``sqrt(mean over the axes of the filtered (or, offline, smoothed) variances)``, NaN where
the position is NaN. For the Tobit filters it is the Gaussian approximation's variance.
"""

from __future__ import annotations

import dataclasses
import itertools
import warnings
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.core.engine import sum_last
from tobitkf.core.kalman import kalman_filter, rts_smooth
from tobitkf.core.model import LinearGaussian
from tobitkf.skeleton.topology import Topology
from tobitkf.smoothing import paper
from tobitkf.smoothing.params import limit_vec, optional, positive_float, positive_vec
from tobitkf.smoothing.registry import SmoothInput, SmoothOutput, register_method
from tobitkf.smoothing.timebase import (
    elapsed_since_valid,
    inferred_r_scale,
    inferred_sample_scale,
    readonly,
)

if TYPE_CHECKING:
    from tobitkf.core.streaming import StreamingFilter

__all__ = ["atkf_c", "run_kalman", "run_kalman_core"]

Array = NDArray[np.float64]

_KF_VALIDATORS = {"q": positive_vec, "r": positive_vec}
_ATKF_VALIDATORS = {
    **_KF_VALIDATORS,
    "c": optional(positive_vec),
    "c_horizontal": positive_float,
    "c_vertical": positive_float,
}
_TKF_VALIDATORS = {**_KF_VALIDATORS, "lower": limit_vec, "upper": limit_vec}


def _diag3(v: Any) -> Array:
    return np.diag(np.broadcast_to(np.asarray(v, dtype=float), (3,)).copy())


def atkf_c(params: Mapping[str, Any], up_axis: int) -> Array:
    """The ATKF half-widths (3,) in the sequence's axes: ``c`` as given, else
    ``c_horizontal`` on the two horizontal axes and ``c_vertical`` on ``up_axis``."""
    if params.get("c") is not None:
        return np.broadcast_to(np.asarray(params["c"], dtype=float), (3,)).copy()
    c = np.full(3, float(params["c_horizontal"]))
    c[up_axis] = float(params["c_vertical"])
    return c


def _check_limits(params: dict[str, Any]) -> None:
    lo, hi = np.asarray(params["lower"]), np.asarray(params["upper"])
    if np.any(lo >= hi):
        raise ValueError(f"lower {params['lower']} must be below upper {params['upper']}")


#: a measurement further beyond a censoring limit than this (m) cannot have been clipped
#: there (a clipped sensor reports the limit itself)
BEYOND_LIMIT_TOL = 1e-6
#: a joint axis with at least this many samples beyond a limit, and this fraction of its
#: present samples, contradicts the limit persistently: a warning says so
BEYOND_WARN_COUNT = 10
BEYOND_WARN_FRACTION = 0.01


def sample_limits(
    ys: Array, valid: NDArray[np.bool_], lower: Array, upper: Array
) -> tuple[Array, Array, NDArray[np.bool_]] | None:
    """Per-sample limits for measurements ``ys (T or 1, *batch, 3)``: a limit is lifted
    (set to -inf / +inf) for a sample that lies beyond it, since a sensor that clips at a
    limit reports the limit itself, never a value beyond it; such a sample is used as
    measured instead of pulling the estimate ever further out. ``None`` when no sample
    lies beyond a limit (the constant limits apply as given). Also returns the mask of
    samples beyond a limit."""
    present = valid[..., None]
    lo_out = present & (ys < lower - BEYOND_LIMIT_TOL)
    up_out = present & (ys > upper + BEYOND_LIMIT_TOL)
    beyond = lo_out | up_out
    if not beyond.any():
        return None
    return np.where(lo_out, -np.inf, lower), np.where(up_out, np.inf, upper), beyond


def warn_contradicted_limits(
    count: NDArray[np.int64], n_valid: NDArray[np.int64], joint_names: Any, method: str
) -> None:
    """Warn when the data lie beyond a censoring limit persistently (per joint axis):
    ``count (*batch, 3)`` samples beyond a limit out of ``n_valid (*batch)`` present."""
    n = np.maximum(n_valid, 1)[..., None]
    bad = (count >= BEYOND_WARN_COUNT) & (count >= BEYOND_WARN_FRACTION * n)
    if not bad.any():
        return
    joints = sorted({int(j) for j in np.nonzero(bad.any(axis=-1))[-1]})
    names = [str(joint_names[j]) if joint_names is not None else str(j) for j in joints]
    worst = float((count / n).max())
    warnings.warn(
        f"{method}: the data lie beyond the censoring limits (up to {worst:.0%} of a joint "
        f"axis's samples; joints {', '.join(names[:6])}{' ...' if len(names) > 6 else ''}): "
        "a sensor clipped at a limit never reports beyond it, so these limits do not "
        "describe this recording; those samples are used as measured. Give lower= / "
        "upper= for this sensor (the defaults are the Kinect V2's camera-space limits).",
        UserWarning,
        stacklevel=4,
    )


def _check_device_limits(name: str) -> Any:
    """``check_data``: the default limits are the Kinect V2's, in metres, camera space,
    3-D: refuse them for anything else (a 2-D or pixel recording would be clipped
    everywhere)."""
    return lambda params, n_dims, units: _device_limits_fit(name, params, n_dims, units)


def _device_limits_fit(name: str, params: Mapping[str, Any], n_dims: int, units: Any) -> None:
    default = (
        tuple(np.ravel(params["lower"])) == paper.KINECT_DEVICE_LOWER
        and tuple(np.ravel(params["upper"])) == paper.KINECT_DEVICE_UPPER
    )
    if default and (n_dims != 3 or units != "m"):
        what = f"{n_dims}-D" if n_dims != 3 else f"in {units or 'unknown units'}"
        raise ValueError(
            f"{name}: the default censoring limits are the Kinect V2's camera-space limits "
            f"in metres (lower={paper.KINECT_DEVICE_LOWER}, upper={paper.KINECT_DEVICE_UPPER})"
            f"; this recording is {what}: give lower= and upper= in its own units"
        )


def _check_metre_widths(name: str, defaults: Mapping[str, Any]) -> Any:
    """``check_data``: the ATKF's default half-widths are metres; refuse them for data in
    pixels or unknown units (every sample would be clipped to the last estimate)."""

    def check(params: Mapping[str, Any], n_dims: int, units: Any) -> None:
        default = params.get("c") is None and all(
            params[k] == defaults[k] for k in ("c_horizontal", "c_vertical")
        )
        if default and units != "m":
            raise ValueError(
                f"{name}: the default half-widths c_horizontal={defaults['c_horizontal']}, "
                f"c_vertical={defaults['c_vertical']} are metres; this recording is in "
                f"{units or 'unknown units'}: give c= (or c_horizontal= and c_vertical=) "
                "in its own units"
            )

    return check


def _limits_3d(inp: SmoothInput, params: dict[str, Any]) -> dict[str, tuple[float, ...]]:
    """Limits for the three axes the method sees: 2 limits (a 2-D recording) get no
    censoring on the padded third axis; 2 limits for a 3-D recording are an error."""
    out = {}
    for key, pad in (("lower", -np.inf), ("upper", np.inf)):
        v = tuple(np.ravel(params[key]))
        if len(v) == 2:
            if inp.n_dims != 2:
                raise ValueError(f"{key}: 2 numbers given for a {inp.n_dims}-D recording")
            v = (*v, pad)
        out[key] = v
    return out


def _vec3(v: Any) -> Array:
    return np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=float), (3,)))


#: a pause (one time step) after which the random walk's variance exceeds this many R
#: restarts every joint at its next measurement, as at its first (13.3 s with the paper's
#: Q and R): the Tobit updates are linear in y, and extrapolated from a prior wider than
#: the device they threw a joint 79 m away after a 10^5 s pause (issue 14 point 5)
RESTART_VARIANCE_RATIO = 100.0
#: ... but never a pause shorter than this (s): with Q >= 100 R one frame's step passed
#: the variance rule, every frame restarted, and a joint's gaps were no longer filled
MIN_PAUSE_SECONDS = 1.0


def pause_seconds(params: Mapping[str, Any]) -> float:
    """The pause after which :func:`run_across_pauses` restarts the filters."""
    ratio = np.min(np.asarray(params["r"], dtype=float) / np.asarray(params["q"], dtype=float))
    return max(float(RESTART_VARIANCE_RATIO * ratio * paper.REFERENCE_DT), MIN_PAUSE_SECONDS)


def run_across_pauses(
    inp: SmoothInput, kind: str, variant: str | None, params: dict[str, Any]
) -> SmoothOutput:
    """:func:`run_kalman` on each stretch between pauses longer than
    :func:`pause_seconds`: nothing is carried across a pause (a new start, x0 = the
    first measurement after it and P0 = R; offline, no smoothing across it)."""
    T = inp.ys.shape[0]
    cuts = [0, *(int(k) for k in np.nonzero(inp.steps[1:] > pause_seconds(params))[0] + 1), T]
    if len(cuts) == 2:
        return run_kalman(inp, kind, variant, **params)
    parts = []
    for a, b in itertools.pairwise(cuts):
        steps = np.array(inp.steps[a:b], dtype=float)
        steps[0] = inp.steps[0]  # the nominal step, as for a recording's first frame
        part = dataclasses.replace(
            inp,
            positions=inp.positions[a:b],
            ys=inp.ys[a:b],
            missing=inp.missing[a:b],
            tracking_state=None if inp.tracking_state is None else inp.tracking_state[a:b],
            steps=steps,
            times=inp.times[a:b],
            is_reference=bool(inp.is_reference or np.all(steps == paper.REFERENCE_DT)),
            confidence=None if inp.confidence is None else inp.confidence[a:b],
        )
        parts.append(run_kalman(part, kind, variant, **params))
    cat = np.concatenate
    clipped = None if parts[0].clipped is None else cat([p.clipped for p in parts])
    std = None if parts[0].std is None else cat([p.std for p in parts])
    return SmoothOutput(
        cat([p.positions for p in parts]), clipped=clipped, params=parts[0].params, std=std
    )


def run_kalman(inp: SmoothInput, kind: str, variant: str | None, **params: Any) -> SmoothOutput:
    """Kalman-type filtering (+ RTS when ``inp.offline``) of ``inp.ys`` (T, *batch, 3).

    Runs the compiled per-axis kernel (:mod:`tobitkf.smoothing._kalman_kernels`), the same
    numbers as :func:`run_kalman_core` (the numpy core) to rounding, without its per-frame
    numpy calls and with no array kept beyond the outputs (and, offline, the variances).
    """
    from tobitkf.smoothing import _kalman_kernels as k  # numba: only when a method runs

    ys = inp.ys
    T = ys.shape[0]
    bshape = ys.shape[1:-1]
    flat = readonly(np.ascontiguousarray(ys).reshape(T, -1, 3))  # one compiled version
    N = flat.shape[1]
    q = _vec3(params["q"])
    if inp.is_reference:
        qs = np.ascontiguousarray(np.broadcast_to(q, (T, 3)))
    else:
        qs = q[None] * (inp.steps / paper.REFERENCE_DT)[:, None]
    scale = inferred_sample_scale(inp.tracking_state, ~inp.missing, inp.inferred_noise_factor)
    rs = np.empty((0, 0)) if scale is None else scale.reshape(T, -1)
    used: dict[str, Any] = {}
    r = _vec3(params["r"])
    est, std = np.empty((T, N, 3)), np.empty((T, N))
    clipped = np.zeros((T, N), dtype=bool)
    var = np.empty((T, N, 3) if inp.offline else (0, 0, 3))
    work = (var, np.empty((N, 3, 6)), np.empty((N, 2), dtype=np.int64))
    if kind == "tkf":
        lower, upper = _vec3(params["lower"]), _vec3(params["upper"])
        beyond = np.zeros((N, 3), dtype=np.int64)  # samples beyond a limit: used as measured
        k.tobit_run(variant == "corrected", flat, qs, r, rs, lower, upper, BEYOND_LIMIT_TOL,
                    bool(inp.offline), est, std, clipped, *work, beyond)  # fmt: skip
        if beyond.any():
            warn_contradicted_limits(
                beyond.reshape((*bshape, 3)), (~inp.missing).sum(axis=0), inp.topology.joints,
                "tkf" if variant == "standard" else "tkfc",
            )  # fmt: skip
    else:
        c = atkf_c(params, inp.up_axis) if kind == "atkf" else np.full(3, np.inf)
        if kind == "atkf":
            used["c"] = tuple(float(v) for v in c)
        steps = np.ascontiguousarray(inp.steps, dtype=float)
        k.gaussian_run(kind == "atkf", flat, qs, r, rs, c, steps, np.cumsum(steps),
                       bool(inp.is_reference), paper.REFERENCE_DT, bool(inp.offline),
                       est, std, clipped, *work)  # fmt: skip
    if inp.offline:
        k.rts_run(est, var, qs, std)
    k.blank_before_first(est, std, work[2])
    est = est.reshape(ys.shape)
    std = std.reshape((T, *bshape))
    # the plain Kalman filter has no limits: it clips nothing (None, not zeros)
    clipped = None if kind == "kf" else clipped.reshape((T, *bshape))
    return SmoothOutput(est, clipped=clipped, params=used, std=std)


def run_kalman_core(
    inp: SmoothInput, kind: str, variant: str | None, **params: Any
) -> SmoothOutput:
    """:func:`run_kalman` through the numpy core (``kalman_filter``, ``tobit_filter``,
    ``adaptive_tobit_filter``, ``rts_smooth``): the reference the compiled kernel is
    tested against (tests/test_kalman_kernels.py)."""
    # the numpy Tobit core imports scipy.special (0.25 s): only when this path runs
    from tobitkf.core.tobit import adaptive_tobit_filter, tobit_filter

    ys, missing = inp.ys, inp.missing
    T = ys.shape[0]
    bshape = ys.shape[1:-1]
    valid = ~missing
    has_any = valid.any(axis=0)  # (*batch,)
    first = np.argmax(valid, axis=0)  # (*batch,)
    x0 = np.take_along_axis(ys, first[None, ..., None], axis=0)[0]
    x0 = np.where(has_any[..., None], x0, 0.0)
    Q = _diag3(params["q"])
    R = _diag3(params["r"])
    model = LinearGaussian(A=np.eye(3), H=np.eye(3), Q=Q, R=R, x0=x0, P0=R)
    # the predicted covariances are read by the RTS pass only
    kwargs: dict[str, Any] = {"keep_predicted": inp.offline}
    ratio = inp.steps / paper.REFERENCE_DT  # (T,)
    if not inp.is_reference:
        kwargs["Q_seq"] = Q[None] * ratio[:, None, None]
    r_scale = inferred_r_scale(inp.tracking_state, valid, inp.inferred_noise_factor)
    if r_scale is not None:
        kwargs["R_scale"] = r_scale
    used: dict[str, Any] = {}
    if kind == "atkf":
        c = atkf_c(params, inp.up_axis)
        used["c"] = tuple(float(v) for v in c)
        elapsed = elapsed_since_valid(inp.steps, valid)  # (T, *batch)
        per_frame = inp.steps.reshape((T,) + (1,) * len(bshape))
        if inp.is_reference and np.all(elapsed == per_frame):
            result = adaptive_tobit_filter(model, ys, c, keep_probabilities=False, **kwargs)
        else:
            if np.all(elapsed == per_frame):  # no gap: one step per frame, (T, 1.., 3)
                elapsed = per_frame
            c_seq = c * (elapsed / paper.REFERENCE_DT)[..., None]
            result = adaptive_tobit_filter(
                model, ys, None, c_seq=c_seq, keep_probabilities=False, **kwargs
            )
    elif kind == "kf":
        result = kalman_filter(model, ys, **kwargs)
    else:
        lower = np.asarray(params["lower"], dtype=float)
        upper = np.asarray(params["upper"], dtype=float)
        lifted = sample_limits(ys, valid, lower, upper)
        if lifted is not None:
            kwargs["lower_seq"], kwargs["upper_seq"], beyond = lifted
            lower = upper = None
            warn_contradicted_limits(
                beyond.sum(axis=0), valid.sum(axis=0), inp.topology.joints,
                "tkf" if variant == "standard" else "tkfc",
            )  # fmt: skip
            del beyond
        result = tobit_filter(
            model, ys, lower, upper, variant=variant, keep_probabilities=False, **kwargs
        )
    final = rts_smooth(model, result) if inp.offline else result
    est = final.means
    try:  # the run's own buffer, read-only in the result, which is dropped here: no copy
        est.flags.writeable = True
    except ValueError:
        est = np.array(est, dtype=float)
    # position sd: root-mean-square over the axes of the per-axis posterior sd
    std = sum_last(final.variances)  # np.mean(..., axis=-1), faster and in place
    std /= 3
    np.sqrt(std, out=std)
    # nothing observed yet: no estimate before a joint's first valid measurement
    before = np.arange(T).reshape((T,) + (1,) * len(bshape)) < first[None]
    before |= ~has_any[None]
    est[before] = np.nan
    std[before] = np.nan
    clipped = None
    if kind != "kf":  # the plain Kalman filter has no limits: it clips nothing
        clipped = np.asarray(result.clipped, dtype=bool).any(axis=-1) & valid
    return SmoothOutput(est, clipped=clipped, params=used, std=std)


class KalmanStepper:
    """Live form of :func:`run_kalman` (causal): one :class:`StreamingFilter` step per frame,
    with the same time scaling, adaptive-limit widening and INFERRED noise."""

    def __init__(
        self,
        kind: str,
        variant: str | None,
        topology: Topology,
        up_axis: int,
        inferred_noise_factor: float,
        **params: Any,
    ) -> None:
        self.kind, self.variant, self.params = kind, variant, params
        self.factor = inferred_noise_factor
        self._Q = _diag3(params["q"])
        self._R = _diag3(params["r"])
        self._c = atkf_c(params, up_axis) if kind == "atkf" else None
        self._filter: StreamingFilter | None = None
        self._started: NDArray[np.bool_] | None = None
        self._last_valid_time: Array | None = None
        self._time = 0.0
        self.clipped: NDArray[np.bool_] | None = None
        self.std: Array | None = None  # the last frame's posterior sd (B, J)

    def _make_filter(self, ys: Array, valid: NDArray[np.bool_]) -> StreamingFilter:
        from tobitkf.core.streaming import StreamingFilter

        x0 = np.where(valid[..., None], ys, 0.0)
        model = LinearGaussian(A=np.eye(3), H=np.eye(3), Q=self._Q, R=self._R, x0=x0, P0=self._R)
        if self.kind == "atkf":
            return StreamingFilter(model, "atkf", c=self._c)
        if self.kind == "kf":
            return StreamingFilter(model, "kf")
        return StreamingFilter(
            model,
            "tkf" if self.variant == "standard" else "tkfc",
            lower=np.asarray(self.params["lower"], dtype=float),
            upper=np.asarray(self.params["upper"], dtype=float),
        )

    def step(self, ys: Array, missing: NDArray[np.bool_], states: Any, dt: float) -> Array:
        valid = ~missing
        self._time += dt
        if self._filter is not None and dt > pause_seconds(self.params):
            self._filter = None  # a pause: a new start, as run_across_pauses does
            dt = self._first_dt
        if self._filter is None:
            self._first_dt = dt
            self._filter = self._make_filter(ys, valid)
            self._started = valid.copy()
            self._last_valid_time = np.full(valid.shape, np.nan)
        else:
            new = valid & ~self._started
            if new.any():
                self._filter.seed(new, ys)
                self._started |= new
        kwargs: dict[str, Any] = {"Q": self._Q * (dt / paper.REFERENCE_DT)}
        r_scale = inferred_r_scale(states, valid, self.factor)
        if r_scale is not None:
            kwargs["R_scale"] = r_scale
        if self.kind == "tkf":
            lifted = sample_limits(ys, valid, self._filter.lower, self._filter.upper)
            if lifted is not None:
                kwargs["lower"], kwargs["upper"] = lifted[:2]
        if self._c is not None:
            last = self._last_valid_time
            elapsed = np.where(np.isfinite(last), self._time - last, dt)
            kwargs["c"] = self._c * (elapsed / paper.REFERENCE_DT)[..., None]
        mean, _ = self._filter.step(ys, **kwargs)
        last_out = self._filter.last
        clipped = None if last_out is None else last_out.update.clipped
        self.clipped = None if clipped is None else np.asarray(clipped).any(axis=-1) & valid
        self._last_valid_time = np.where(valid, self._time, self._last_valid_time)
        out = np.array(mean, dtype=float)
        out[~self._started] = np.nan
        # position sd as batch gives it: the rms over the axes of the per-axis sd
        var = self._filter.variances
        self.std = None if var is None else np.sqrt(np.mean(var, axis=-1))
        if self.std is not None:
            self.std[~self._started] = np.nan
        return out


def _register(
    name: str,
    kind: str,
    defaults: dict[str, Any],
    validators: dict[str, Any],
    description: str,
    variant: str | None = None,
) -> None:
    def run(inp: SmoothInput, **params: Any) -> SmoothOutput:
        if kind == "tkf":
            params = {**params, **_limits_3d(inp, params)}
        return run_across_pauses(inp, kind, variant, params)

    def live(topology: Topology, up_axis: int, inferred_noise_factor: float, **params: Any):
        return KalmanStepper(kind, variant, topology, up_axis, inferred_noise_factor, **params)

    register_method(
        name,
        run,
        params=defaults,
        validators=validators,
        description=description,
        causal=True,
        offline_ok=True,
        check=_check_limits if "lower" in defaults else None,
        live=live,
        check_data=(
            _check_device_limits(name)
            if kind == "tkf"
            else _check_metre_widths(name, defaults)
            if kind == "atkf"
            else None
        ),
    )


_ATKF_DEFAULTS = {
    "q": paper.PAPER_Q,
    "r": paper.PAPER_R,
    "c": None,
    "c_horizontal": paper.ATKF_C_HORIZONTAL,
    "c_vertical": paper.ATKF_C_VERTICAL,
}
_TKF_DEFAULTS = {
    "q": paper.PAPER_Q,
    "r": paper.PAPER_R,
    "lower": paper.KINECT_DEVICE_LOWER,
    "upper": paper.KINECT_DEVICE_UPPER,
}
_register(
    "atkf",
    "atkf",
    _ATKF_DEFAULTS,
    _ATKF_VALIDATORS,
    "adaptive Tobit KF (2020): limits = previous estimate ± c",
)
_register(
    "atkf2016",
    "atkf",
    {
        **_ATKF_DEFAULTS,
        "q": paper.ATKF2016_Q,
        "c_horizontal": paper.ATKF2016_C_HORIZONTAL,
        "c_vertical": paper.ATKF2016_C_VERTICAL,
    },
    _ATKF_VALIDATORS,
    "adaptive Tobit KF with the 2016 paper's limits and Q",
)
_register(
    "tkf",
    "tkf",
    _TKF_DEFAULTS,
    _TKF_VALIDATORS,
    "standard Tobit KF (Allik 2016), Kinect device limits (camera axes)",
    variant="standard",
)
_register(
    "tkfc",
    "tkf",
    _TKF_DEFAULTS,
    _TKF_VALIDATORS,
    "corrected Tobit KF (2020), Kinect device limits (camera axes)",
    variant="corrected",
)
_register(
    "kf",
    "kf",
    {"q": paper.PAPER_Q, "r": paper.PAPER_R},
    _KF_VALIDATORS,
    "plain Kalman filter (random walk per joint)",
)
