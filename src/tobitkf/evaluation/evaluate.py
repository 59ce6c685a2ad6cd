"""Score smoothing methods against motion-capture ground truth (issue 5).

Pipeline (:func:`prepare_truth`, then :func:`evaluate_methods`):

1. **Pairs** — each track joint gets a mocap point or a mean of points
   (:mod:`tobitkf.evaluation.pairs`; KERAAL and UI-PRMD tables built in, detected from the
   mocap's point names).
2. **Time** — the mocap clock is fitted to the track's from correlated inter-point
   distances (:func:`~tobitkf.evaluation.alignment.fit_time_alignment`): the offset only
   (KERAAL: verified ≈ 0, then held at the documented common time zero) or offset and rate
   (UI-PRMD: files cut separately, effective Vicon rate 80–100 Hz).  The mocap is then
   resampled to the track's frame times by linear interpolation.
3. **Space** — one robust rigid transform plus per-pair offsets
   (:func:`~tobitkf.evaluation.registration.fit_registration`), in the target's own frame
   when the mocap carries orientations (KERAAL; quaternion order chosen by fit), else in
   the world frame.  Fitted once on the RAW track, then held fixed for every method.
4. **Metrics** per method (:class:`MethodScore`), the glitch classes coming from the raw
   track's error (:func:`~tobitkf.evaluation.metrics.classify_glitches`).

Without ground truth, :func:`evaluate_without_truth` gives the paper's Table 3 (M per
method) and the largest jumps.  :func:`evaluate_paths` does either from file paths (the
``tobitkf evaluate`` command); :func:`pool_scores` pools several recordings.

Methods are given as names understood by :func:`tobitkf.smooth` (``"atkf"``, ``"kf"``,
``"sgf"``, ...), ``"raw"`` (no smoothing), ``"<name>+rts"`` (the offline RTS smoother of a
Kalman-type method, ``offline=True``), ``(label, name, params)`` tuples, or
``(label, callable)`` with ``callable(sequence) -> SkeletonSequence``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.core.jsonable import to_jsonable
from tobitkf.evaluation.alignment import (
    TimeAlignment,
    distance_signals,
    fit_time_alignment,
    mocap_times,
    resample,
)
from tobitkf.evaluation.angles import (
    AngleScore,
    angle_rmse_at_delay,
    angle_rmse_best_delay,
    joint_angles,
)
from tobitkf.evaluation.metrics import (
    GLITCH_CLASS_NAMES,
    classify_glitches,
    glitch_episodes,
    joint_errors,
    rmse,
    smoothness,
    top_jumps,
    velocity_lag,
)
from tobitkf.evaluation.pairs import (
    KERAAL_PAIRS,
    UIPRMD_PAIRS,
    PairingTable,
    ResolvedPairs,
    builtin_pairs,
    normalise_name,
    read_pairs,
)
from tobitkf.evaluation.registration import (
    RigidRegistration,
    choose_quaternion_order,
    fit_registration,
    quat_to_matrix,
)

__all__ = [
    "DEFAULT_METHODS",
    "EvaluationTable",
    "GroundTruth",
    "MethodScore",
    "NoTruthTable",
    "default_methods",
    "evaluate_methods",
    "evaluate_paths",
    "evaluate_without_truth",
    "pool_scores",
    "prepare_truth",
    "resolve_method",
    "score_estimate",
    "truth_from_array",
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


# ------------------------------------------------------------------------------ truth
@dataclass(frozen=True)
class GroundTruth:
    """Ground truth laid out like the track (same frames, same joints, track frame).

    Attributes
    ----------
    positions : (T, J, 3) metres, NaN for unpaired joints / frames outside the mocap.
    joint_names : (J,) the track's joint names.
    paired : (J,) bool, joints with a mocap counterpart.
    registration : the fitted transform (None when the truth was given directly).
    time_alignment : the fitted mocap timing (None when given directly).
    fitted_time_alignment : the fitted timing even when a fixed one was used (KERAAL).
    pairs : the resolved pairing table.
    notes : free-form facts for the report: ``pairing_table``, ``quaternion_order`` and
        ``quaternion_order_fit_rms_m`` (KERAAL), ``unresolved_pairs``, and ``warnings``
        (doubtful time alignment: correlation < 0.9, overlap < 60 %, rate at the edge of
        the searched range).
    """

    positions: NDArray[np.float64]
    joint_names: tuple[str, ...]
    paired: NDArray[np.bool_]
    registration: RigidRegistration | None = None
    time_alignment: TimeAlignment | None = None
    fitted_time_alignment: TimeAlignment | None = None
    pairs: ResolvedPairs | None = None
    notes: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict:
        """JSON-ready description of how the truth was obtained."""
        return {
            "paired_joints": [n for n, p in zip(self.joint_names, self.paired) if p],
            "registration": None if self.registration is None else self.registration.summary(),
            "time_alignment": None
            if self.time_alignment is None
            else self.time_alignment.to_dict(),
            "fitted_time_alignment": None
            if self.fitted_time_alignment is None
            else self.fitted_time_alignment.to_dict(),
            "pairs": None if self.pairs is None else [str(p) for p in self.pairs.pairs],
            "notes": to_jsonable(self.notes),
        }


def truth_from_array(truth: Any, joint_names: Sequence[str]) -> GroundTruth:
    """Wrap a (T, J, 3) truth already in the track frame and layout."""
    p = np.asarray(truth, dtype=float)
    if p.ndim != 3 or p.shape[1] != len(joint_names) or p.shape[2] != 3:
        raise ValueError(f"truth must be (T, {len(joint_names)}, 3), got {p.shape}")
    return GroundTruth(p, tuple(joint_names), np.isfinite(p).all(-1).any(0))


def _quaternions(mocap: Any) -> tuple[NDArray | None, str | None]:
    """Target quaternions (T, M, 4) from a mocap sequence's metadata, if any."""
    meta = getattr(mocap, "metadata", {}) or {}
    for key in ("target_quaternions_raw", "orientations", "quaternions", "rotations"):
        q = meta.get(key)
        if (
            isinstance(q, np.ndarray)
            and q.shape[:2] == mocap.positions.shape[:2]
            and q.shape[-1] == 4
        ):
            order = meta.get("quaternion_order") or meta.get(f"{key}_order")
            return q.astype(float), order
    return None, None


def detect_pairs(track_names: Sequence[str], mocap_names: Sequence[str]) -> PairingTable:
    """The built-in table whose names match best (KERAAL or UI-PRMD)."""
    best, score = None, 0
    mset = {normalise_name(n) for n in mocap_names}
    tset = {normalise_name(n) for n in track_names}
    for table in (KERAAL_PAIRS, UIPRMD_PAIRS):
        s = sum(
            normalise_name(p.track_joint) in tset
            and all(normalise_name(m) in mset for m in p.mocap_points)
            for p in table.pairs
        )
        if s > score:
            best, score = table, s
    if best is None or score < 4:
        raise ValueError(
            "cannot pair the track with the mocap automatically (neither the KERAAL nor the "
            "UI-PRMD names match); give a pairing table (CSV: track_joint,mocap_point)"
        )
    return best


def _check_metres(name: str, positions: NDArray) -> None:
    spread = np.nanmedian(np.linalg.norm(positions - np.nanmedian(positions, axis=(0, 1)), axis=-1))
    if np.isfinite(spread) and spread > 10:
        raise ValueError(
            f"{name} positions look like they are not in metres (median distance to the centre "
            f"{spread:.1f}); readers must return metres"
        )


def prepare_truth(
    track: Any,
    mocap: Any,
    *,
    pairs: PairingTable | str | Path | None = None,
    offset_mode: str = "auto",
    time: str = "auto",
    mocap_rate: float | None = None,
    fit_rate: bool | None = None,
    rate_range: tuple[float, float] | None = None,
    n_signals: int = 20,
) -> GroundTruth:
    """Pair, time-align and register a mocap recording onto a raw track.

    Parameters
    ----------
    track : SkeletonSequence, the RAW track (the registration is fitted on it).
    mocap : SkeletonSequence of mocap points (names in ``joint_names``; KERAAL targets may
        carry quaternions in ``metadata["orientations"]`` (T, M, 4)).
    pairs : a :class:`PairingTable`, ``"keraal"`` / ``"ui_prmd"``, a CSV path, or None
        (detected from the names).
    offset_mode : ``"auto"`` (body-frame offsets when quaternions exist, else world),
        ``"body"``, ``"world"`` or ``"none"``.
    time : ``"auto"``, ``"fit"`` (fit offset, and rate if ``fit_rate``), or ``"fixed"``
        (offset 0 at ``mocap_rate``; the fitted timing is still reported).  ``"auto"`` is
        ``"fixed"`` for KERAAL (documented common time zero), ``"fit"`` otherwise.
    mocap_rate : nominal mocap rate (Hz); default ``mocap.fps``.
    fit_rate : fit the mocap rate too; default True for UI-PRMD, else False.
    rate_range : (lo, hi) Hz searched when fitting the rate; default ``(0.6, 1.6)`` times the
        nominal rate for UI-PRMD (its m07 episodes fit 130–160 Hz against a nominal 100 Hz,
        i.e. the two files' clocks disagree by more than the documented 80–100 Hz), else
        ``(0.75, 1.1)`` times it.
    n_signals : number of most-varying inter-point distances used for the time fit.

    Returns
    -------
    GroundTruth
    """
    table: PairingTable
    if pairs is None:
        table = detect_pairs(track.joint_names, mocap.joint_names)
    elif isinstance(pairs, PairingTable):
        table = pairs
    elif isinstance(pairs, str) and normalise_name(pairs) in ("keraal", "uiprmd"):
        table = builtin_pairs(pairs)
    else:
        table = read_pairs(pairs)
    resolved = table.resolve(track.joint_names, mocap.joint_names)
    J = track.n_joints
    y = np.asarray(track.positions, dtype=float)
    mp = np.asarray(mocap.positions, dtype=float)
    _check_metres("track", y)
    _check_metres("mocap", mp)
    m_full = resolved.mocap_positions(mp, J)  # (N, J, 3)
    quats, q_order = _quaternions(mocap)
    q_full = resolved.mocap_quaternions(quats, J) if quats is not None else None

    # ---- time
    rate = float(mocap_rate or getattr(mocap, "fps", None) or 0)
    if rate <= 0:
        raise ValueError("mocap rate unknown: give mocap_rate= or a mocap with fps")
    is_keraal = table.name == "keraal"
    is_uiprmd = table.name == "ui_prmd"
    if fit_rate is None:
        fit_rate = is_uiprmd
    if time == "auto":
        time = "fixed" if is_keraal else "fit"
    if time not in ("fit", "fixed"):
        raise ValueError(f"time must be 'auto', 'fit' or 'fixed', got {time!r}")
    tt = track.times() if hasattr(track, "times") else np.arange(len(y)) / 30.0
    ji = list(resolved.track_index)
    jp = [(a, b) for n, a in enumerate(sorted(set(ji))) for b in sorted(set(ji))[n + 1 :]]
    sig_t = distance_signals(y, jp)
    sig_m = distance_signals(m_full, jp)
    sel = np.argsort(-np.nan_to_num(np.nanstd(sig_m, axis=0)))[:n_signals]
    if fit_rate and rate_range is None:
        rate_range = (0.6 * rate, 1.6 * rate) if is_uiprmd else (0.75 * rate, 1.1 * rate)
    fitted = fit_time_alignment(
        tt, sig_t[:, sel], sig_m[:, sel], rate=rate, fit_rate=fit_rate, rate_range=rate_range
    )
    if time == "fixed":
        used = TimeAlignment(0.0, rate, float("nan"), float("nan"), False)
    else:
        used = fitted
    mt = mocap_times(len(mp), used.rate_hz, used.offset_s)
    m_res = resample(mt, m_full, tt)
    rots = None
    if q_full is not None:
        # orientation of the nearest mocap frame (quaternions do not interpolate linearly)
        k = np.clip(np.round((tt - used.offset_s) * used.rate_hz).astype(int), 0, len(mp) - 1)
        q_res = q_full[k]
    # ---- space
    notes: dict[str, Any] = {"pairing_table": table.name}
    warnings_: list[str] = []
    if not fitted.correlation >= 0.9:
        warnings_.append(
            f"time alignment is doubtful: signal correlation {fitted.correlation:.2f} < 0.9"
        )
    if fitted.overlap < 0.6:
        warnings_.append(f"mocap covers only {100 * fitted.overlap:.0f} % of the track frames")
    if fit_rate and rate_range is not None:
        lo, hi = rate_range
        if min(fitted.rate_hz - lo, hi - fitted.rate_hz) < 0.01 * (hi - lo):
            warnings_.append(
                f"fitted mocap rate {fitted.rate_hz:.1f} Hz is at the edge of the searched "
                f"range {lo:.0f}-{hi:.0f} Hz"
            )
    if resolved.missing:
        notes["unresolved_pairs"] = [r for _, r in resolved.missing]
    if warnings_:
        notes["warnings"] = warnings_
    mode = offset_mode
    if mode == "auto":
        mode = "body" if q_full is not None else "world"
    if mode == "body":
        if q_full is None:
            raise ValueError("offset_mode='body' needs mocap orientations (quaternions)")
        if q_order in ("xyzw", "wxyz"):
            rots = quat_to_matrix(q_res, q_order)
            reg = fit_registration(
                y, m_res, offset_mode="body", target_rotations=rots, quaternion_order=q_order
            )
        else:
            reg, scores = choose_quaternion_order(y, m_res, q_res)
            rots = quat_to_matrix(q_res, reg.quaternion_order)
            notes["quaternion_order_fit_rms_m"] = scores
        notes["quaternion_order"] = reg.quaternion_order
    else:
        reg = fit_registration(y, m_res, offset_mode=mode)  # type: ignore[arg-type]
    truth = reg.truth_in_track_frame(m_res, rots)
    paired = np.zeros(J, dtype=bool)
    paired[ji] = True
    truth[:, ~paired] = np.nan
    return GroundTruth(
        positions=truth,
        joint_names=tuple(track.joint_names),
        paired=paired,
        registration=reg,
        time_alignment=used,
        fitted_time_alignment=fitted,
        pairs=resolved,
        notes=notes,
    )


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
    return spec, _smooth(spec, {})


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
            "clipped_fraction": self.clipped_fraction,
        }
        for name, a in self.angles.items():
            r[f"{name}_best_deg"] = a.rmse_best
            r[f"{name}_delay"] = a.best_delay
            r[f"{name}_fixed_deg"] = a.rmse_fixed
        return r

    def to_dict(self) -> dict:
        d = asdict(self)
        d["angles"] = {k: v.to_dict() for k, v in self.angles.items()}
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
) -> MethodScore:
    """Score one (T, J, 3) estimate against ``truth`` (see :class:`MethodScore`).

    ``raw_classes`` is (T, J) from :func:`~tobitkf.evaluation.metrics.classify_glitches`;
    samples labelled with no class code (e.g. -1 where the raw track is missing) count in
    the overall and group RMSEs but in no per-class RMSE.
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
    )


def pool_scores(tables: Sequence[EvaluationTable]) -> list[dict[str, Any]]:
    """Pool several recordings' scores per method (sample-weighted RMSE, cm).

    RMSEs are combined as ``sqrt(Σ n_i rmse_i² / Σ n_i)`` over recordings, overall, per joint
    group and per raw glitch class, so the result equals the RMSE over all samples of all
    recordings.  Max is the largest max; frames over the threshold are summed.

    Returns
    -------
    list of dicts, one per method (in the first table's order): ``method``, ``rmse_cm``,
    ``<group>_cm``, ``<class>_cm``, ``M`` (sample-weighted mean of the recordings' M),
    ``max_cm``, ``frames_over``, ``n_samples``.
    """
    if not tables:
        raise ValueError("pool_scores: no tables")
    out = []
    for s0 in tables[0].scores:
        parts = [t.score(s0.method) for t in tables]
        row: dict[str, Any] = {"method": s0.method}
        keys = ["all", *s0.rmse_groups, *GLITCH_CLASS_NAMES.values()]
        for key in keys:
            num = den = 0.0
            for p in parts:
                v = (
                    p.rmse
                    if key == "all"
                    else p.rmse_groups.get(key, p.rmse_by_class.get(key, float("nan")))
                )
                n = p.counts.get(key, 0)
                if n and np.isfinite(v):
                    num += n * v * v
                    den += n
            row["rmse_cm" if key == "all" else f"{key}_cm"] = (
                100 * math.sqrt(num / den) if den else float("nan")
            )
        # recordings with no scored sample (NaN M and max) must not turn the pool into NaN
        scored = [p for p in parts if p.counts.get("all", 0)]
        n_all = [p.counts["all"] for p in scored]
        row["M"] = (
            sum(n * p.smoothness_M for n, p in zip(n_all, scored, strict=True)) / sum(n_all)
            if scored
            else float("nan")
        )
        row["max_cm"] = 100 * max((p.max for p in scored), default=float("nan"))
        row["frames_over"] = sum(p.frames_over for p in parts)
        row["n_samples"] = sum(p.counts.get("all", 0) for p in parts)
        out.append(row)
    return out


@dataclass(frozen=True)
class EvaluationTable:
    """Per-method scores against ground truth, plus how the truth was obtained.

    scores : one :class:`MethodScore` per method, in the order given.
    truth_M : the ground truth's own smoothness M (eq. 41) on the paired joints.
    n_frames, paired_joints : what was scored.
    class_counts : number of samples per raw glitch class.
    episodes : raw glitch episodes ``(joint name, start, stop)``, longest first (≤ 20).
    settings : thresholds and delays used.
    truth : the :class:`GroundTruth` summary (registration, timing, pairs).
    """

    scores: tuple[MethodScore, ...]
    truth_M: float
    n_frames: int
    paired_joints: tuple[str, ...]
    class_counts: dict[str, int]
    episodes: tuple[tuple[str, int, int], ...]
    settings: dict[str, Any]
    truth: dict[str, Any]

    def rows(self) -> list[dict[str, Any]]:
        """One flat dict per method (cm, degrees), ready for a table or CSV."""
        return [s.row() for s in self.scores]

    def score(self, method: str) -> MethodScore:
        for s in self.scores:
            if s.method == method:
                return s
        raise KeyError(f"no method {method!r}; have {[s.method for s in self.scores]}")

    def to_dict(self) -> dict:
        return to_jsonable(
            {
                "scores": [s.to_dict() for s in self.scores],
                "truth_M": self.truth_M,
                "n_frames": self.n_frames,
                "paired_joints": list(self.paired_joints),
                "class_counts": self.class_counts,
                "episodes": [list(e) for e in self.episodes],
                "settings": self.settings,
                "truth": self.truth,
            }
        )

    def to_text(self) -> str:
        """Plain-text table (cm; M in 1e-3 m²)."""
        cols = [
            "method",
            "rmse",
            "hands",
            "arms",
            "torso",
            "legs",
            "p95",
            "max",
            ">10cm",
            "fine",
            "short",
            "sust.",
            "M e-3",
            "lag",
        ]
        lines = ["  ".join(f"{c:>8}" for c in cols)]
        for s in self.scores:
            g = s.rmse_groups
            cells = [
                s.method[:8],
                s.rmse * 100,
                g.get("hands", np.nan) * 100,
                g.get("arms", np.nan) * 100,
                g.get("torso", np.nan) * 100,
                g.get("legs", np.nan) * 100,
                s.p95 * 100,
                s.max * 100,
                s.frames_over,
                s.rmse_by_class["fine"] * 100,
                s.rmse_by_class["short_glitch"] * 100,
                s.rmse_by_class["sustained"] * 100,
                s.smoothness_M * 1e3,
                "-" if s.lag_frames is None else s.lag_frames,
            ]
            lines.append("  ".join(_fmt(c) for c in cells))
        lines.append(
            f"{'truth':>8}  M = {self.truth_M * 1e3:.3f} e-3 m²; samples per raw class: "
            + ", ".join(f"{k} {v}" for k, v in self.class_counts.items())
        )
        if any(s.angles for s in self.scores):
            names = sorted({n for s in self.scores for n in s.angles})
            lines.append("")
            lines.append(
                f"{'angles':>8}  " + "  ".join(f"{n + ' best/d/fixed':>26}" for n in names)
            )
            for s in self.scores:
                cells = []
                for n in names:
                    a = s.angles.get(n)
                    cells.append(
                        f"{a.rmse_best:7.2f} @{a.best_delay:+3d} {a.rmse_fixed:7.2f}".rjust(26)
                        if a
                        else " " * 26
                    )
                lines.append(f"{s.method[:8]:>8}  " + "  ".join(cells))
        return "\n".join(lines)


def _fmt(c: Any) -> str:
    if isinstance(c, str):
        return f"{c:>8}"
    if isinstance(c, (int, np.integer)):
        return f"{int(c):>8d}"
    return f"{c:>8.2f}" if np.isfinite(c) else f"{'-':>8}"


def evaluate_methods(
    track: Any,
    truth: GroundTruth | Any,
    methods: Sequence[MethodLike] = DEFAULT_METHODS,
    *,
    glitch_threshold: float = 0.10,
    short_max: int = 4,
    over_threshold: float = 0.10,
    max_lag: int = 10,
    fixed_delay: int = 0,
    max_delay: int = 10,
    outputs: dict[str, Any] | None = None,
) -> EvaluationTable:
    """Run each method on the raw track and score it against the registered truth.

    Parameters
    ----------
    track : SkeletonSequence, the RAW track (the one the registration was fitted on).
    truth : :class:`GroundTruth` from :func:`prepare_truth`, or a (T, J, 3) array already
        in the track frame and layout.
    methods : method specs (module docstring); default :data:`DEFAULT_METHODS`.
    glitch_threshold, short_max : raw-error glitch definition (m, frames), see
        :func:`~tobitkf.evaluation.metrics.classify_glitches`.
    over_threshold : per-frame "any joint off by more than" threshold (m).
    max_lag : hand-velocity lag search range (frames).
    fixed_delay, max_delay : angle RMSE at one common delay, and best delay in ±max_delay.
    outputs : optional dict filled with ``label -> smoothed SkeletonSequence`` (for plots).

    Returns
    -------
    EvaluationTable
    """
    if not isinstance(truth, GroundTruth):
        truth = truth_from_array(truth, track.joint_names)
    if truth.positions.shape != track.positions.shape:
        raise ValueError(
            f"truth {truth.positions.shape} does not match the track {track.positions.shape}"
        )
    raw_err = joint_errors(track.positions, truth.positions)
    raw_err[:, ~truth.paired] = np.nan
    classes = classify_glitches(raw_err, glitch_threshold, short_max)
    # a sample the raw track misses has no raw class: a method that fills it is scored on
    # it overall, but the per-class RMSEs stay on the samples raw is scored on
    classes[~np.isfinite(raw_err)] = -1
    groups = track.topology.joint_groups()
    hands = [i for i in groups.get("hands", []) if truth.paired[i]]
    truth_angles = joint_angles(truth.positions, truth.joint_names)
    scores = []
    for spec in methods:
        label, fn = resolve_method(spec)
        out = fn(track)
        if outputs is not None:
            outputs[label] = out
        est = out.positions if hasattr(out, "positions") else np.asarray(out, dtype=float)
        diag = (getattr(out, "metadata", None) or {}).get("diagnostics") or {}
        clipped = None
        cf = diag.get("clipped_fraction")
        if cf is not None and np.size(cf) == len(truth.paired):
            clipped = float(np.mean(np.asarray(cf, dtype=float)[truth.paired]))
        scores.append(
            score_estimate(
                label,
                est,
                truth,
                classes,
                groups=groups,
                hand_joints=hands,
                over_threshold=over_threshold,
                max_lag=max_lag,
                fixed_delay=fixed_delay,
                max_delay=max_delay,
                truth_angles=truth_angles,
                clipped_fraction=clipped,
            )
        )
    ok = np.isfinite(raw_err)
    counts = {
        name: int(np.sum((classes == code) & ok)) for code, name in GLITCH_CLASS_NAMES.items()
    }
    eps = glitch_episodes(np.nan_to_num(raw_err, nan=0.0) > glitch_threshold)
    eps = sorted(eps, key=lambda e: -(e[2] - e[1]))[:20]
    names = truth.joint_names
    return EvaluationTable(
        scores=tuple(scores),
        truth_M=smoothness(truth.positions, np.flatnonzero(truth.paired)),
        n_frames=track.n_frames,
        paired_joints=tuple(n for n, p in zip(names, truth.paired) if p),
        class_counts=counts,
        episodes=tuple((names[j], a, b) for j, a, b in eps),
        settings={
            "glitch_threshold_m": glitch_threshold,
            "short_max_frames": short_max,
            "over_threshold_m": over_threshold,
            "max_lag_frames": max_lag,
            "fixed_delay_frames": fixed_delay,
            "max_delay_frames": max_delay,
        },
        truth=truth.summary(),
    )


# ------------------------------------------------------------------------- no truth
@dataclass(frozen=True)
class NoTruthTable:
    """Paper Table 3 on one recording: M per method and each method's largest jumps.

    rows : list of ``{"method", "M", "max_jump_m", "jumps": [{"frame", "joint", "jump_m"}]}``.
    """

    rows: tuple[dict[str, Any], ...]
    n_frames: int

    def to_dict(self) -> dict:
        return to_jsonable({"rows": list(self.rows), "n_frames": self.n_frames})

    def to_text(self) -> str:
        lines = [f"{'method':>14}  {'M (1e-3 m²)':>12}  {'max jump cm':>11}  largest jump at"]
        for r in self.rows:
            j = r["jumps"][0] if r["jumps"] else None
            where = f"{j['joint']} frame {j['frame']}" if j else "-"
            lines.append(
                f"{r['method']:>14}  {r['M'] * 1e3:12.3f}  {r['max_jump_m'] * 100:11.1f}  {where}"
            )
        return "\n".join(lines)


def evaluate_without_truth(
    track: Any,
    methods: Sequence[MethodLike] = DEFAULT_METHODS,
    *,
    n_jumps: int = 5,
    joints: Sequence[int] | None = None,
    outputs: dict[str, Any] | None = None,
) -> NoTruthTable:
    """Smoothness M (2020, eq. 41) and largest one-frame jumps per method, no truth needed.

    Parameters
    ----------
    track : SkeletonSequence (raw).
    methods : method specs; ``"raw"`` gives the sensor's own M (paper: "Kinect V2").
    n_jumps : number of largest jumps listed per method.
    joints : restrict M to these joint indices (default all).
    outputs : optional dict filled with ``label -> smoothed SkeletonSequence``.
    """
    rows = []
    for spec in methods:
        label, fn = resolve_method(spec)
        out = fn(track)
        if outputs is not None:
            outputs[label] = out
        p = out.positions
        jumps = top_jumps(p, track.joint_names, n_jumps)
        rows.append(
            {
                "method": label,
                "M": smoothness(p, joints),
                "max_jump_m": jumps[0]["jump_m"] if jumps else float("nan"),
                "jumps": jumps,
            }
        )
    return NoTruthTable(tuple(rows), track.n_frames)


def evaluate_paths(
    track_path: str | Path,
    truth_path: str | Path | None = None,
    methods: Sequence[MethodLike] = DEFAULT_METHODS,
    *,
    pairs: PairingTable | str | Path | None = None,
    outputs: dict[str, Any] | None = None,
    **truth_options: Any,
) -> tuple[GroundTruth | None, EvaluationTable | NoTruthTable]:
    """``tobitkf evaluate TRACK [--truth MOCAP]`` as a function (for the CLI).

    Loads both files with :func:`tobitkf.io.load` (first body of each), then runs
    :func:`prepare_truth` and :func:`evaluate_methods`, or, without ``truth_path``,
    :func:`evaluate_without_truth`.  ``truth_options`` go to :func:`prepare_truth`
    (``offset_mode``, ``time``, ``mocap_rate``, ``fit_rate``, ``rate_range``).

    Returns
    -------
    (GroundTruth or None, EvaluationTable or NoTruthTable)
    """
    from tobitkf.io import load

    tracks = load(track_path)
    if not tracks:
        raise ValueError(f"{track_path}: no skeleton in the file")
    track = tracks[0]
    if truth_path is None:
        return None, evaluate_without_truth(track, methods, outputs=outputs)
    mocaps = load(truth_path)
    if not mocaps:
        raise ValueError(f"{truth_path}: no motion-capture points in the file")
    gt = prepare_truth(track, mocaps[0], pairs=pairs, **truth_options)
    return gt, evaluate_methods(track, gt, methods, outputs=outputs)
