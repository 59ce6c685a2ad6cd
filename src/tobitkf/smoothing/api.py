"""``tobitkf.smooth``: smooth skeleton sequences with a named method.

Methods (see :data:`METHODS` and :func:`method_defaults`):

========================  ================================================================
``atkf`` (default)        adaptive Tobit KF, 2020 paper (eq. 30–35, Alg. 2): R = 0.01 I,
                          Q = 0.0025 I, c = 0.34 m horizontal / 0.18 m vertical per 1/30 s
``atkf2016``              the same filter with the 2016 paper's c = (0.31, 0.18, 0.31),
                          Q = 0.001 I
``tkf``, ``tkfc``         Tobit KF (Allik 2016 / corrected 2020) with the Kinect device
                          limits x ∈ [-3, 3], y ∈ [-1.5, 3], z ∈ [0.5, 5] m
``kf``                    plain Kalman filter (random walk per joint)
``sgf`` / ``savgol``      Savitzky–Golay (window 9, order 3)
``one_euro``              1€ filter (Casiez et al. 2012)
``kinect``                Kinect SDK double-exponential joint filter (presets)
``moving_average``        centred box filter
========================  ================================================================

Every Kalman-type method models each joint as an independent 3-D random walk
(A = H = I), vectorised over joints (and bodies). x0 is the joint's first valid
measurement and P0 = R.

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

Up axis. The vertical entry of ``c`` (0.18 m) goes on the topology's ``up_axis`` (y for
Kinect camera space, z for most optical systems); ``up_axis=`` overrides it. An explicit
``c=(cx, cy, cz)`` is used as given, in the sequence's axes. The Kinect device limits of
``tkf`` / ``tkfc`` are defined in Kinect camera axes (x right, y up, z depth from the
sensor): they only make sense for Kinect camera-space data; give ``lower=`` / ``upper=``
for anything else.

Tracking states. NOT_TRACKED joints and NaN positions are predicted, not updated (the
measurement is treated as missing). INFERRED joints (positions the sensor guessed from
the neighbouring joints) get their measurement variance multiplied by
``inferred_noise_factor`` (default 4: twice the standard deviation, the same doubling
the Kinect SDK's own joint filter applies to its jitter and deviation radii for inferred
joints). Baselines: ``kinect`` uses the states as the SDK does; the others treat
NOT_TRACKED as missing and ignore INFERRED.

Output. A new :class:`SkeletonSequence` with the smoothed positions and the input's
tracking states, timestamps, fps, topology, body id and metadata, plus
``metadata["diagnostics"]``::

    clipped_fraction  (J,)  fraction of frames whose measurement was clipped (censored)
                            by the filter's limits (0 for non-Tobit methods)
    filled_fraction   (J,)  fraction of frames with a missing measurement (NaN or
                            NOT_TRACKED) that got an estimate
    method, params          the method name and the complete parameter set used

Frames before a joint's first valid measurement stay NaN (nothing observed yet); later
gaps are filled by the filter's prediction (hold, for a random walk) or, for the offline
RTS smoother, by interpolation between the neighbouring measurements.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.skeleton.sequence import SkeletonSequence, TrackingState
from tobitkf.smoothing import baselines
from tobitkf.smoothing.fit import REFERENCE_DT  # the paper's frame step (30 fps)
from tobitkf.smoothing.robust import ROBUST_DEFAULTS, ROBUST_VALIDATORS

__all__ = [
    "COMMON_KEYWORDS",
    "DEFAULT_INFERRED_NOISE_FACTOR",
    "KINECT_DEVICE_LOWER",
    "KINECT_DEVICE_UPPER",
    "METHODS",
    "MethodSpec",
    "check_params",
    "method_defaults",
    "smooth",
]

Array = NDArray[np.float64]

#: measurement-variance multiplier for INFERRED joints (2x standard deviation, see module doc)
DEFAULT_INFERRED_NOISE_FACTOR = 4.0
#: Kinect device limits of the 2020 paper, Kinect camera axes (x, y up, z depth), metres
KINECT_DEVICE_LOWER = (-3.0, -1.5, 0.5)
KINECT_DEVICE_UPPER = (3.0, 3.0, 5.0)
#: keywords of :func:`smooth` accepted next to the method's parameters
COMMON_KEYWORDS = ("offline", "up_axis", "inferred_noise_factor")


# --------------------------------------------------------------------------- validation


def _positive_vec(name: str, value: Any, allow_none: bool = False) -> Any:
    if value is None and allow_none:
        return None
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number or 3 numbers (x, y, z), got {value!r}") from None
    if arr.ndim > 1 or (arr.ndim == 1 and arr.shape[0] != 3):
        raise ValueError(f"{name} must be a number or 3 numbers (x, y, z), got {value!r}")
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ValueError(f"{name} must be positive and finite, got {value!r}")
    return float(arr) if arr.ndim == 0 else tuple(float(v) for v in arr)


def _limit_vec(name: str, value: Any) -> tuple[float, float, float]:
    try:
        arr = np.broadcast_to(np.asarray(value, dtype=float), (3,))
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be 3 numbers (±inf allowed), got {value!r}") from None
    if np.any(np.isnan(arr)):
        raise ValueError(f"{name} must be 3 numbers (±inf allowed), got {value!r}")
    return tuple(float(v) for v in arr)  # type: ignore[return-value]


def _positive_float(name: str, value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(v) or v <= 0:
        raise ValueError(f"{name} must be positive and finite, got {value!r}")
    return v


def _nonneg_float(name: str, value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(v) or v < 0:
        raise ValueError(f"{name} must be >= 0, got {value!r}")
    return v


def _unit_float(name: str, value: Any) -> float:
    v = _nonneg_float(name, value)
    if v > 1:
        raise ValueError(f"{name} must be in [0, 1], got {value!r}")
    return v


def _opt(check: Callable[[str, Any], Any]) -> Callable[[str, Any], Any]:
    return lambda name, value: None if value is None else check(name, value)


def _int_at_least(lo: int) -> Callable[[str, Any], int]:
    def check(name: str, value: Any) -> int:
        if isinstance(value, bool) or int(value) != value or int(value) < lo:
            raise ValueError(f"{name} must be an integer >= {lo}, got {value!r}")
        return int(value)

    return check


def _odd_window(name: str, value: Any) -> int:
    v = _int_at_least(1)(name, value)
    if v % 2 == 0:
        raise ValueError(f"{name} must be odd, got {value!r}")
    return v


def _bool(name: str, value: Any) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be true or false, got {value!r}")
    return bool(value)


def _preset(name: str, value: Any) -> str:
    if value not in baselines.KINECT_PRESETS:
        raise ValueError(f"{name} must be one of {sorted(baselines.KINECT_PRESETS)}, got {value!r}")
    return str(value)


def _variant(name: str, value: Any) -> str:
    if value not in ("corrected", "standard"):
        raise ValueError(f"{name} must be 'corrected' or 'standard', got {value!r}")
    return str(value)


# --------------------------------------------------------------------------- registry


@dataclass(frozen=True)
class MethodSpec:
    """One smoothing method: defaults, validators and the kind of runner.

    Calling a spec smooths a sequence with it: ``METHODS["atkf"](seq, q=0.001)`` is
    ``smooth(seq, "atkf", q=0.001)``.
    """

    name: str
    kind: str  # "kalman", "baseline" or "robust"
    defaults: Mapping[str, Any]
    validators: Mapping[str, Callable[[str, Any], Any]]
    description: str
    options: Mapping[str, Any] = field(default_factory=dict)

    def __call__(self, sequence: Any, **kwargs: Any) -> Any:
        return smooth(sequence, self.name, **kwargs)


_KF_VALIDATORS: dict[str, Callable[[str, Any], Any]] = {
    "q": _positive_vec,
    "r": _positive_vec,
}
_ATKF_VALIDATORS = {
    **_KF_VALIDATORS,
    "c": _opt(_positive_vec),
    "c_horizontal": _positive_float,
    "c_vertical": _positive_float,
}
_TKF_VALIDATORS = {**_KF_VALIDATORS, "lower": _limit_vec, "upper": _limit_vec}
_KINECT_VALIDATORS = {
    "preset": _preset,
    "smoothing": _opt(_unit_float),
    "correction": _opt(_unit_float),
    "prediction": _opt(_nonneg_float),
    "jitter_radius": _opt(_nonneg_float),
    "max_deviation_radius": _opt(_nonneg_float),
}


def _spec(
    name: str,
    kind: str,
    defaults: dict[str, Any],
    validators: dict[str, Callable[[str, Any], Any]],
    description: str,
    **options: Any,
) -> MethodSpec:
    assert set(defaults) == set(validators), name
    return MethodSpec(name, kind, defaults, validators, description, options)


_SAVGOL_DEFAULTS = {"window": 9, "polyorder": 3, "max_gap": None}
_SAVGOL_VALIDATORS = {
    "window": _odd_window,
    "polyorder": _int_at_least(0),
    "max_gap": _opt(_int_at_least(0)),
}

_ROBUST_DEFAULTS = {k: v for k, v in ROBUST_DEFAULTS.items() if k != "inferred_noise_factor"}
_ROBUST_VALIDATORS = {k: v for k, v in ROBUST_VALIDATORS.items() if k in _ROBUST_DEFAULTS}

#: registry: method name -> :class:`MethodSpec` (callable)
METHODS: dict[str, MethodSpec] = {
    "atkf": _spec(
        "atkf",
        "kalman",
        {"q": 0.0025, "r": 0.01, "c": None, "c_horizontal": 0.34, "c_vertical": 0.18},
        _ATKF_VALIDATORS,
        "adaptive Tobit KF (2020): limits = previous estimate ± c",
        filter="atkf",
    ),
    "atkf2016": _spec(
        "atkf2016",
        "kalman",
        {"q": 0.001, "r": 0.01, "c": None, "c_horizontal": 0.31, "c_vertical": 0.18},
        _ATKF_VALIDATORS,
        "adaptive Tobit KF with the 2016 paper's limits and Q",
        filter="atkf",
    ),
    "tkf": _spec(
        "tkf",
        "kalman",
        {"q": 0.0025, "r": 0.01, "lower": KINECT_DEVICE_LOWER, "upper": KINECT_DEVICE_UPPER},
        _TKF_VALIDATORS,
        "standard Tobit KF (Allik 2016), Kinect device limits (camera axes)",
        filter="tkf",
        variant="standard",
    ),
    "tkfc": _spec(
        "tkfc",
        "kalman",
        {"q": 0.0025, "r": 0.01, "lower": KINECT_DEVICE_LOWER, "upper": KINECT_DEVICE_UPPER},
        _TKF_VALIDATORS,
        "corrected Tobit KF (2020), Kinect device limits (camera axes)",
        filter="tkf",
        variant="corrected",
    ),
    "kf": _spec(
        "kf",
        "kalman",
        {"q": 0.0025, "r": 0.01},
        _KF_VALIDATORS,
        "plain Kalman filter (random walk per joint)",
        filter="kf",
    ),
    "sgf": _spec(
        "sgf",
        "baseline",
        dict(_SAVGOL_DEFAULTS),
        dict(_SAVGOL_VALIDATORS),
        "Savitzky-Golay filter (offline)",
    ),
    "savgol": _spec(
        "savgol",
        "baseline",
        dict(_SAVGOL_DEFAULTS),
        dict(_SAVGOL_VALIDATORS),
        "Savitzky-Golay filter (offline; same as sgf)",
    ),
    "one_euro": _spec(
        "one_euro",
        "baseline",
        {"mincutoff": 1.0, "beta": 0.0, "dcutoff": 1.0},
        {"mincutoff": _positive_float, "beta": _nonneg_float, "dcutoff": _positive_float},
        "1-euro filter (Casiez et al. 2012)",
    ),
    "kinect": _spec(
        "kinect",
        "baseline",
        {
            "preset": "default",
            "smoothing": None,
            "correction": None,
            "prediction": None,
            "jitter_radius": None,
            "max_deviation_radius": None,
        },
        _KINECT_VALIDATORS,
        "Kinect SDK double-exponential joint filter",
    ),
    "moving_average": _spec(
        "moving_average",
        "baseline",
        {"window": 5, "centered": True},
        {"window": _int_at_least(1), "centered": _bool},
        "moving average (centred or trailing)",
    ),
    # ours: physically impossible samples (speed, bone length) are treated as missing
    "robust": _spec(
        "robust",
        "robust",
        dict(_ROBUST_DEFAULTS),
        dict(_ROBUST_VALIDATORS),
        "physical speed / bone-length gating, OU-velocity RTS smoother (offline)",
        offline=True,
    ),
    "robust_online": _spec(
        "robust_online",
        "robust",
        dict(_ROBUST_DEFAULTS),
        dict(_ROBUST_VALIDATORS),
        "physical speed / bone-length gating, causal OU-velocity Kalman filter",
        offline=False,
    ),
}


def method_defaults(method: str) -> dict[str, Any]:
    """Default parameters of ``method`` (a copy)."""
    return dict(_get_spec(method).defaults)


def _get_spec(method: str) -> MethodSpec:
    spec = METHODS.get(method)
    if spec is None:
        raise ValueError(f"unknown method {method!r}; valid methods: {', '.join(sorted(METHODS))}")
    return spec


def check_params(method: str, params: Mapping[str, Any]) -> dict[str, Any]:
    """Validate ``params`` for ``method`` and return the complete parameter set.

    Unknown names raise ``ValueError`` listing the valid ones; bad values raise
    ``ValueError`` naming the parameter. The keywords of :func:`smooth` itself
    (``offline``, ``up_axis``, ``inferred_noise_factor``) are accepted and checked too,
    but not returned.
    """
    spec = _get_spec(method)
    unknown = sorted(set(params) - set(spec.defaults) - set(COMMON_KEYWORDS))
    if unknown:
        raise ValueError(
            f"unknown parameter{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))} "
            f"for method {method!r}; valid parameters: "
            f"{', '.join(sorted(spec.defaults))} (and {', '.join(COMMON_KEYWORDS)})"
        )
    if "offline" in params:
        _bool("offline", params["offline"])
    if params.get("up_axis") is not None:
        _check_up_axis(params["up_axis"])
    if "inferred_noise_factor" in params:
        _inferred_factor(params["inferred_noise_factor"])
    out = dict(spec.defaults)
    for name, value in params.items():
        if name in spec.validators:
            out[name] = spec.validators[name](name, value)
    if spec.kind == "kalman" and "lower" in out:
        lo, hi = np.asarray(out["lower"]), np.asarray(out["upper"])
        if np.any(lo >= hi):
            raise ValueError(f"lower {out['lower']} must be below upper {out['upper']}")
    if method in ("sgf", "savgol") and out["polyorder"] >= out["window"]:
        raise ValueError(
            f"polyorder ({out['polyorder']}) must be less than window ({out['window']})"
        )
    if method == "moving_average" and out["centered"] and out["window"] % 2 == 0:
        raise ValueError(f"a centred moving average needs an odd window, got {out['window']}")
    return out


def _check_up_axis(value: Any) -> int:
    if isinstance(value, bool) or value not in (0, 1, 2):
        raise ValueError(f"up_axis must be 0 (x), 1 (y) or 2 (z), got {value!r}")
    return int(value)


def _inferred_factor(value: Any) -> float:
    v = _positive_float("inferred_noise_factor", value)
    if v < 1:
        raise ValueError(f"inferred_noise_factor must be >= 1, got {value!r}")
    return v


# --------------------------------------------------------------------------- time steps


def frame_steps(sequence: SkeletonSequence) -> tuple[Array, float, bool]:
    """Time step before each frame, ``(T,)`` seconds, the nominal step, and irregularity.

    ``steps[0]`` is the nominal step: the median positive timestamp difference, else
    1/fps, else 1/30 s. Zero differences (duplicated stamps) become a tenth of it.
    ``is_reference`` is True when every step equals 1/30 s (no scaling needed).
    """
    T = sequence.n_frames
    ts = sequence.timestamps
    fps = sequence.fps if sequence.fps is not None else 30.0
    nominal = 1.0 / float(fps)
    steps = np.full(T, nominal)
    if ts is not None and T > 1:
        d = np.diff(np.asarray(ts, dtype=float))
        positive = d[d > 0]
        if positive.size:  # else: all stamps equal, fall back to the frame rate
            nominal = float(np.median(positive))
            steps = np.concatenate([[nominal], np.maximum(d, 0.1 * nominal)])
    is_reference = bool(np.allclose(steps, REFERENCE_DT, rtol=1e-9, atol=0.0))
    return steps, nominal, is_reference


# --------------------------------------------------------------------------- runners


@dataclass
class _Batch:
    """Stacked inputs: positions (T, *batch, 3), states (T, *batch) or None, steps (T,).

    ``ys`` / ``missing`` are the measurements and missing mask of :func:`_measurements`.
    """

    positions: Array
    states: NDArray[np.int8] | None
    steps: Array
    is_reference: bool
    up_axis: int
    ys: Array
    missing: NDArray[np.bool_]


def _measurements(positions: Any, states: Any | None) -> tuple[Array, NDArray[np.bool_]]:
    """Measurements (a float copy) with NaN and NOT_TRACKED joints set to NaN, and the
    missing mask ``positions.shape[:-1]``. Shared by :func:`smooth`, the live smoother
    and the robust smoother so that all three treat a sample as missing alike.
    """
    ys = np.array(positions, dtype=float)
    missing = np.isnan(ys).any(axis=-1)
    if states is not None:
        missing |= np.asarray(states) == TrackingState.NOT_TRACKED
    ys[missing] = np.nan
    return ys, missing


def _inferred_r_scale(states: Any | None, valid: NDArray[np.bool_], factor: float) -> Array | None:
    """Measurement-variance multiplier ``(*valid.shape, 3)`` for valid INFERRED joints.

    ``factor`` where a valid joint is INFERRED, 1 elsewhere; None when nothing is scaled
    (no states, factor 1 or no valid inferred joint), so the filters skip the work.
    """
    if states is None or factor == 1.0:
        return None
    inferred = (np.asarray(states) == TrackingState.INFERRED) & valid
    if not inferred.any():
        return None
    return np.repeat(np.where(inferred, factor, 1.0)[..., None], 3, axis=-1)


def _diag3(v: Any) -> Array:
    return np.diag(np.broadcast_to(np.asarray(v, dtype=float), (3,)).copy())


def _atkf_c(params: Mapping[str, Any], up_axis: int) -> Array:
    if params.get("c") is not None:
        return np.broadcast_to(np.asarray(params["c"], dtype=float), (3,)).copy()
    c = np.full(3, float(params["c_horizontal"]))
    c[up_axis] = float(params["c_vertical"])
    return c


def _elapsed_since_valid(steps: Array, valid: NDArray[np.bool_]) -> Array:
    """Time from each joint's last valid frame before k to frame k, ``(T, *batch)``.

    ``steps[k]`` when frame k-1 was valid (or k is before the first valid frame); after a
    gap it is the whole time since the last measurement.
    """
    T = steps.shape[0]
    times = np.cumsum(steps)
    shape = (T,) + (1,) * (valid.ndim - 1)
    idx = np.where(valid, np.arange(T).reshape(shape), -1)
    last = np.maximum.accumulate(idx, axis=0)  # last valid index <= k
    prev = np.concatenate([np.full((1, *valid.shape[1:]), -1), last[:-1]], axis=0)
    t_k = np.broadcast_to(times.reshape(shape), valid.shape)
    st_k = np.broadcast_to(steps.reshape(shape), valid.shape)
    t_prev = times[np.maximum(prev, 0)]
    return np.where(prev >= 0, t_k - t_prev, st_k)


def _run_kalman(
    spec: MethodSpec,
    params: Mapping[str, Any],
    batch: _Batch,
    offline: bool,
    inferred_noise_factor: float,
) -> tuple[Array, NDArray[np.bool_]]:
    """Kalman-type filtering; returns estimates (T, *batch, 3) and clipped (T, *batch)."""
    from tobitkf.core.kalman import kalman_filter, rts_smooth
    from tobitkf.core.model import LinearGaussian

    ys, missing = batch.ys, batch.missing
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
    kwargs: dict[str, Any] = {}
    ratio = batch.steps / REFERENCE_DT  # (T,)
    if not batch.is_reference:
        kwargs["Q_seq"] = Q[None] * ratio[:, None, None]
    r_scale = _inferred_r_scale(batch.states, valid, inferred_noise_factor)
    if r_scale is not None:
        kwargs["R_scale"] = r_scale
    kind = spec.options["filter"]
    if kind == "atkf":
        from tobitkf.core.tobit import adaptive_tobit_filter

        c = _atkf_c(params, batch.up_axis)
        elapsed = _elapsed_since_valid(batch.steps, valid)  # (T, *batch)
        if np.all(elapsed == REFERENCE_DT):
            result = adaptive_tobit_filter(model, ys, c, **kwargs)
        else:
            c_seq = c * (elapsed / REFERENCE_DT)[..., None]  # (T, *batch, 3)
            result = adaptive_tobit_filter(model, ys, None, c_seq=c_seq, **kwargs)
    else:
        if kind == "kf":
            result = kalman_filter(model, ys, **kwargs)
        else:
            from tobitkf.core.tobit import tobit_filter

            result = tobit_filter(
                model,
                ys,
                np.asarray(params["lower"], dtype=float),
                np.asarray(params["upper"], dtype=float),
                variant=spec.options["variant"],
                **kwargs,
            )
    means = rts_smooth(model, result).means if offline else result.means
    est = np.array(means, dtype=float)
    # nothing observed yet: no estimate before a joint's first valid measurement
    before = np.arange(T).reshape((T,) + (1,) * len(bshape)) < first[None]
    before |= ~has_any[None]
    est[before] = np.nan
    clipped = np.asarray(result.clipped, dtype=bool).any(axis=-1) & valid
    return est, clipped


def _run_baseline(
    spec: MethodSpec, params: Mapping[str, Any], batch: _Batch
) -> tuple[Array, NDArray[np.bool_]]:
    ys, missing = batch.ys, batch.missing
    name = spec.name
    if name in ("sgf", "savgol"):
        out = baselines.savgol(ys, params["window"], params["polyorder"], max_gap=params["max_gap"])
    elif name == "moving_average":
        out = baselines.moving_average(ys, params["window"], params["centered"])
    elif name == "one_euro":
        times = np.cumsum(batch.steps)
        out = baselines.one_euro(
            ys,
            timestamps=times,
            mincutoff=params["mincutoff"],
            beta=params["beta"],
            dcutoff=params["dcutoff"],
        )
    elif name == "kinect":
        out = baselines.kinect_double_exponential(
            batch.positions,
            tracking_state=batch.states,
            **params,
        )
    else:  # pragma: no cover - registry and runners are kept in step
        raise AssertionError(name)
    return out, np.zeros(missing.shape, dtype=bool)


# --------------------------------------------------------------------------- public entry


def smooth(
    sequence: SkeletonSequence | Sequence[SkeletonSequence],
    method: str = "atkf",
    *,
    offline: bool = False,
    up_axis: int | None = None,
    inferred_noise_factor: float = DEFAULT_INFERRED_NOISE_FACTOR,
    **params: Any,
) -> Any:
    """Smooth every joint of a skeleton sequence (or a list of them, one per body).

    Parameters
    ----------
    sequence : SkeletonSequence or list of SkeletonSequence
        A list is smoothed body by body and a list is returned; bodies with the same
        number of frames, time base and topology are filtered together in one
        vectorised pass.
    method : str
        A name from :data:`METHODS` (default ``"atkf"``).
    offline : bool
        Kalman-type methods: run the RTS smoother after the filter (uses future frames).
        ``ValueError`` for the baselines (``sgf`` and centred ``moving_average`` are
        offline by nature) and the robust methods (``robust`` is offline,
        ``robust_online`` causal).
    up_axis : int, optional
        Vertical axis (0, 1, 2) for the ATKF limits; default: ``sequence.topology.up_axis``.
    inferred_noise_factor : float
        Measurement-variance multiplier (>= 1) for INFERRED joints (Kalman-type methods).
    **params
        Method parameters; :func:`method_defaults` lists them. Kalman-type: ``q``, ``r``
        (variance per axis: a number or 3 numbers); ``atkf``: ``c`` (3 numbers in the
        sequence's axes) or ``c_horizontal`` / ``c_vertical``; ``tkf`` / ``tkfc``:
        ``lower``, ``upper``.

    Returns
    -------
    SkeletonSequence or list of SkeletonSequence
        Same metadata, positions replaced, ``metadata["diagnostics"]`` added (see module
        docstring).
    """
    spec = _get_spec(method)
    full = check_params(method, params)
    if up_axis is not None:
        up_axis = _check_up_axis(up_axis)
    factor = _inferred_factor(inferred_noise_factor)
    offline = _bool("offline", offline)
    if offline and spec.kind != "kalman":
        # silently ignoring it would label a causal or non-causal output wrongly
        hint = (
            "use method 'robust' (offline) or 'robust_online' (causal)"
            if spec.kind == "robust"
            else "it is a baseline without an RTS pass"
        )
        raise ValueError(
            f"offline=True runs the RTS smoother of the Kalman-type methods; {method!r}: {hint}"
        )
    if spec.kind == "robust":  # the method name decides offline / online
        from tobitkf.smoothing.robust import robust_smooth

        def run(s: SkeletonSequence) -> SkeletonSequence:
            return robust_smooth(
                s, offline=spec.options["offline"], inferred_noise_factor=factor, **full
            )

        if isinstance(sequence, SkeletonSequence):
            return run(sequence)
        return [run(s) for s in sequence]
    if isinstance(sequence, SkeletonSequence):
        return _smooth_group([sequence], spec, full, offline, up_axis, factor)[0]
    seqs = list(sequence)
    for i, s in enumerate(seqs):
        if not isinstance(s, SkeletonSequence):
            raise TypeError(
                f"smooth expects a SkeletonSequence or a list of them; item {i} is "
                f"{type(s).__name__}"
            )
    # group bodies that can share one vectorised pass
    out: list[Any] = [None] * len(seqs)
    groups: dict[Any, list[int]] = {}
    for i, s in enumerate(seqs):
        key = (
            s.n_frames,
            s.n_joints,
            s.topology.up_axis,
            s.fps,
            None if s.timestamps is None else s.timestamps.tobytes(),
            s.tracking_state is None,
        )
        groups.setdefault(key, []).append(i)
    for idx in groups.values():
        res = _smooth_group([seqs[i] for i in idx], spec, full, offline, up_axis, factor)
        for i, r in zip(idx, res, strict=True):
            out[i] = r
    return out


def _smooth_group(
    seqs: list[SkeletonSequence],
    spec: MethodSpec,
    params: dict[str, Any],
    offline: bool,
    up_axis: int | None,
    factor: float,
) -> list[SkeletonSequence]:
    """Smooth bodies sharing frames, joints and time base, stacked on a body axis."""
    ref = seqs[0]
    steps, _, is_reference = frame_steps(ref)
    positions = np.stack([s.positions for s in seqs], axis=1)  # (T, B, J, 3)
    states = None
    if ref.tracking_state is not None:
        states = np.stack([s.tracking_state for s in seqs], axis=1)
    ys, missing = _measurements(positions, states)
    batch = _Batch(
        positions=positions,
        states=states,
        steps=steps,
        is_reference=is_reference,
        up_axis=ref.topology.up_axis if up_axis is None else up_axis,
        ys=ys,
        missing=missing,
    )
    if ref.n_frames == 0:
        est, clipped = positions.copy(), np.zeros(positions.shape[:-1], dtype=bool)
    elif spec.kind == "kalman":
        est, clipped = _run_kalman(spec, params, batch, offline, factor)
    else:
        est, clipped = _run_baseline(spec, params, batch)
    filled = missing & np.isfinite(est).all(axis=-1)
    T = max(ref.n_frames, 1)
    used = dict(params)
    if spec.kind == "kalman":
        used.update(
            offline=offline,
            inferred_noise_factor=factor,
            up_axis=batch.up_axis,
        )
        if spec.options["filter"] == "atkf":
            used["c"] = tuple(float(v) for v in _atkf_c(params, batch.up_axis))
    out = []
    for b, s in enumerate(seqs):
        diagnostics = {
            "clipped_fraction": clipped[:, b].sum(axis=0) / T,
            "filled_fraction": filled[:, b].sum(axis=0) / T,
            "method": spec.name,
            "params": dict(used),
        }
        meta = dict(s.metadata)
        meta["diagnostics"] = diagnostics
        out.append(s.replace(positions=est[:, b], metadata=meta))
    return out
