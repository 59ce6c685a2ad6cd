"""Methods and their scores against ground truth: which smoother a name means
(:func:`resolve_method`), and the metrics of one estimate (:func:`score_estimate`,
:class:`MethodScore`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.core.jsonable import to_jsonable
from tobitkf.evaluation.angles import (
    AngleScore,
    angle_rmse_at_delay,
    angle_rmse_best_delay,
    joint_angles,
)
from tobitkf.evaluation.metrics import (
    GLITCH_CLASS_NAMES,
    in_sd_ball,
    joint_errors,
    rmse,
    sample_share,
    smoothness,
    velocity_lag,
)
from tobitkf.evaluation.truth import GroundTruth

__all__ = [
    "DEFAULT_METHODS",
    "MethodLike",
    "MethodScore",
    "default_methods",
    "resolve_method",
    "score_estimate",
]

#: the comparison of issue 5 (raw, filters, smoother and baselines)
DEFAULT_METHODS = ("raw", "kf", "atkf", "atkf2016", "sgf", "kf+rts", "one_euro", "kinect")

MethodLike = str | tuple


def default_methods() -> list[str]:
    """:data:`DEFAULT_METHODS` plus our robust smoothers when registered.

    What ``tobitkf evaluate``, ``report``, ``benchmark`` and the demo run when no method
    is named.
    """
    from tobitkf.smoothing.api import method_names

    known = method_names()
    return [*DEFAULT_METHODS, *(m for m in ("robust", "robust_online") if m in known)]


# ---------------------------------------------------------------------------- methods
def resolve_method(spec: MethodLike) -> tuple[str, Callable[[Any], Any]]:
    """``(label, callable(sequence) -> SkeletonSequence)`` for a method spec (module doc)."""
    if isinstance(spec, tuple):
        if len(spec) == 2 and callable(spec[1]):
            return str(spec[0]), spec[1]
        if len(spec) == 3 and isinstance(spec[1], str) and isinstance(spec[2], Mapping):
            label, name, params = spec
            params = dict(params)
            return str(label), lambda s, _n=name, _p=params: _smooth(_n, _p)(s)
        raise ValueError(
            f"method spec {spec!r}: expected (label, callable) or (label, name, params)"
        )
    if not isinstance(spec, str):
        raise TypeError(f"method spec must be a str or tuple, got {type(spec).__name__}")
    if spec == "raw":
        return "raw", lambda s: s
    name, params = _split_params(spec)
    return spec, _smooth(name, params)


def _split_params(spec: str) -> tuple[str, dict[str, Any]]:
    """``"robust[noise=fixed;tau=0.2]"`` -> ``("robust", {"noise": "fixed", "tau": 0.2})``
    (the command line's way to score one method with other parameters; the label stays
    the text). Values: true / false, numbers, else text."""
    if not spec.endswith("]") or "[" not in spec:
        return spec, {}
    name, _, body = spec[:-1].partition("[")
    params: dict[str, Any] = {}
    for item in filter(None, (i.strip() for i in body.split(";"))):
        key, eq, raw = item.partition("=")
        if not eq or not key.strip():
            raise ValueError(f"method {spec!r}: {item!r} is not key=value")
        value: Any = raw.strip()
        if value.lower() in ("true", "false"):
            value = value.lower() == "true"
        else:
            try:
                value = float(value) if any(c in value for c in ".eEn") else int(value)
            except ValueError:
                pass
        params[key.strip()] = value
    return name.strip(), params


def _smooth(name: str, params: Mapping[str, Any]) -> Callable[[Any], Any]:
    from tobitkf.smoothing.api import get_method, method_names, smooth

    base, offline = name, False
    low = name.lower()
    for suffix in ("+rts", "_rts", ":offline"):
        if low.endswith(suffix):
            base, offline = name[: -len(suffix)], True
    if base not in method_names():
        raise ValueError(f"unknown method {name!r}; known: raw, {', '.join(method_names())}")
    if offline and not get_method(base).offline_ok:
        # checked here too so that a bad method list fails before any recording is loaded
        raise ValueError(f"{name!r}: method {base!r} has no RTS pass")
    return lambda s: smooth(s, method=base, offline=offline, **params)


# ---------------------------------------------------------------------------- scores
@dataclass(frozen=True)
class MethodScore:
    """Accuracy of one method against the registered ground truth (lengths in metres).

    rmse : pooled over all paired joints and frames.
    rmse_groups : per joint group (``hands``, ``arms``, ``torso``, ``legs``).
    p95, max : 95th percentile and maximum of the per-sample error.
    frames_over : number of frames with any paired joint more than ``over_threshold`` off.
    rmse_by_class : RMSE on samples where RAW is ``fine`` / ``short_glitch`` / ``sustained``.
    smoothness_M : the paper's M (eq. 41) of this method's output on the paired joints.
    lag_frames, lag_refined, lag_correlation : hand-velocity cross-correlation lag.
    angles : per angle (elbows, knees) the RMSE in degrees at the best and at a fixed delay.
    counts : number of scored samples: ``"all"``, per group and per raw class (for pooling
        several recordings with :func:`pool_scores`).
    clipped_fraction : Tobit methods: mean over paired joints of the fraction of frames whose
        measurement the filter's limits clipped (``metadata["diagnostics"]``); else None.
    in_sd_ball : methods with a posterior sd (``SkeletonSequence.std``): the share (0..1) of
        the scored samples with an sd whose error lies in the 95 % ball of that sd
        (:func:`~tobitkf.evaluation.metrics.in_sd_ball`; 0.95 when the sd is honest);
        None for methods without one. ``in_sd_ball_by_class``: the same per raw class.
        Their sample numbers are ``counts["sd"]`` and ``counts["sd:<class>"]``.
    """

    method: str
    rmse: float
    rmse_groups: dict[str, float]
    p95: float
    max: float
    frames_over: int
    rmse_by_class: dict[str, float]
    smoothness_M: float
    lag_frames: int | None
    lag_refined: float | None
    lag_correlation: float | None
    angles: dict[str, AngleScore]
    counts: dict[str, int] = field(default_factory=dict)
    clipped_fraction: float | None = None
    in_sd_ball: float | None = None
    in_sd_ball_by_class: dict[str, float] = field(default_factory=dict)

    def row(self) -> dict[str, Any]:
        """Flat dict for a table (centimetres, degrees)."""
        r: dict[str, Any] = {
            "method": self.method,
            "rmse_cm": 100 * self.rmse,
            **{f"{g}_cm": 100 * v for g, v in self.rmse_groups.items()},
            "p95_cm": 100 * self.p95,
            "max_cm": 100 * self.max,
            "frames_over": self.frames_over,
            **{f"{k}_cm": 100 * v for k, v in self.rmse_by_class.items()},
            "M": self.smoothness_M,
            "lag_frames": self.lag_frames,
            "in_95_ball_pct": None if self.in_sd_ball is None else 100 * self.in_sd_ball,
            "clipped_fraction": self.clipped_fraction,
        }
        for name, a in self.angles.items():
            r[f"{name}_best_deg"] = a.rmse_best
            r[f"{name}_delay"] = a.best_delay
            r[f"{name}_fixed_deg"] = a.rmse_fixed
        return r

    def to_dict(self) -> dict:
        """The JSON form (``tobitkf evaluate --json``): the fields above, lengths in
        metres, except the 95 % ball share, which is in percent as in the pooled rows
        (:func:`~tobitkf.evaluation.evaluate.pool_scores`) and named so:
        ``in_95_ball_pct`` and ``in_95_ball_pct_by_class`` instead of the 0..1
        ``in_sd_ball`` and ``in_sd_ball_by_class``."""
        d = asdict(self)
        d["angles"] = {k: v.to_dict() for k, v in self.angles.items()}
        share, by_class = d.pop("in_sd_ball"), d.pop("in_sd_ball_by_class")
        d["in_95_ball_pct"] = None if share is None else 100 * share
        d["in_95_ball_pct_by_class"] = {k: 100 * v for k, v in by_class.items()}
        return to_jsonable(d)


def score_estimate(
    label: str,
    estimate: Any,
    truth: GroundTruth,
    raw_classes: NDArray[np.int8],
    *,
    groups: Mapping[str, Sequence[int]],
    hand_joints: Sequence[int],
    over_threshold: float = 0.10,
    max_lag: int = 10,
    fixed_delay: int = 0,
    max_delay: int = 10,
    truth_angles: Mapping[str, NDArray] | None = None,
    clipped_fraction: float | None = None,
    std: Any = None,
) -> MethodScore:
    """Score one (T, J, 3) estimate against ``truth`` (see :class:`MethodScore`).

    ``raw_classes`` is (T, J) from :func:`~tobitkf.evaluation.metrics.classify_glitches`;
    samples labelled with no class code (e.g. -1 where the raw track is missing) count in
    the overall and group RMSEs but in no per-class RMSE.  ``std`` is the estimate's (T, J)
    posterior sd (same units), or None for a method without one.
    """
    est = np.asarray(estimate, dtype=float)
    tp = truth.positions
    err = joint_errors(est, tp)
    err[:, ~truth.paired] = np.nan
    finite = err[np.isfinite(err)]
    p95 = float(np.percentile(finite, 95)) if finite.size else float("nan")
    mx = float(finite.max()) if finite.size else float("nan")
    over = int(np.sum(np.nan_to_num(err, nan=0.0).max(axis=1) > over_threshold))
    ok = np.isfinite(err)
    counts = {"all": int(ok.sum())}
    g_rmse = {}
    for g, idx in groups.items():
        idx = [i for i in idx if truth.paired[i]]
        if idx:
            g_rmse[g] = rmse(err[:, idx])
            counts[g] = int(ok[:, idx].sum())
    by_class = {name: rmse(err, raw_classes == code) for code, name in GLITCH_CLASS_NAMES.items()}
    for code, name in GLITCH_CLASS_NAMES.items():
        counts[name] = int((ok & (raw_classes == code)).sum())
    ball = None
    ball_by_class: dict[str, float] = {}
    if std is not None:
        hits = in_sd_ball(est, tp, std)
        hits[:, ~truth.paired] = np.nan
        ball, counts["sd"] = sample_share(hits)
        for code, name in GLITCH_CLASS_NAMES.items():
            ball_by_class[name], counts[f"sd:{name}"] = sample_share(hits, raw_classes == code)
    paired_idx = np.flatnonzero(truth.paired)
    M = smoothness(est, paired_idx)
    lag = lagr = lagc = None
    if hand_joints and len(est) > 2 * max_lag + 5:
        try:
            lag, lagr, lagc = velocity_lag(est, tp, hand_joints, max_lag=max_lag)
        except ValueError:
            pass
    angles: dict[str, AngleScore] = {}
    if truth_angles:
        est_angles = joint_angles(est, truth.joint_names)
        for name, ta in truth_angles.items():
            if name not in est_angles or not np.isfinite(ta).any():
                continue
            best, d = angle_rmse_best_delay(est_angles[name], ta, max_delay)
            fixed = angle_rmse_at_delay(est_angles[name], ta, fixed_delay)
            angles[name] = AngleScore(name, best, d, fixed, fixed_delay)
    return MethodScore(
        method=label,
        rmse=rmse(err),
        rmse_groups=g_rmse,
        p95=p95,
        max=mx,
        frames_over=over,
        rmse_by_class=by_class,
        smoothness_M=M,
        lag_frames=lag,
        lag_refined=lagr,
        lag_correlation=lagc,
        angles=angles,
        counts=counts,
        clipped_fraction=clipped_fraction,
        in_sd_ball=ball,
        in_sd_ball_by_class=ball_by_class,
    )
