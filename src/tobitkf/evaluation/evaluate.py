"""Score smoothing methods against motion-capture ground truth (issue 5).

Pipeline (:func:`prepare_truth`, then :func:`evaluate_methods`):

1. **Pairs** — each track joint gets a mocap point or a mean of points
   (:mod:`tobitkf.evaluation.pairs`; KERAAL and UI-PRMD tables built in, detected from the
   mocap's point names; else joints of the same name).
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
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tobitkf.core.jsonable import to_jsonable
from tobitkf.evaluation.angles import (
    joint_angles,
)
from tobitkf.evaluation.metrics import (
    GLITCH_CLASS_NAMES,
    classify_glitches,
    glitch_episodes,
    joint_errors,
    pool_shares,
    smoothness,
    top_jumps,
)
from tobitkf.evaluation.pairs import (
    PairingTable,
)
from tobitkf.evaluation.scores import (
    DEFAULT_METHODS,
    MethodLike,
    MethodScore,
    default_methods,
    resolve_method,
    score_estimate,
)
from tobitkf.evaluation.truth import GroundTruth, metric, prepare_truth, truth_from_array

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


def pool_scores(tables: Sequence[EvaluationTable]) -> list[dict[str, Any]]:
    """Pool several recordings' scores per method (sample-weighted RMSE, cm).

    RMSEs are combined as ``sqrt(Σ n_i rmse_i² / Σ n_i)`` over recordings, overall, per joint
    group and per raw glitch class, so the result equals the RMSE over all samples of all
    recordings.  Max is the largest max; frames over the threshold are summed.

    Returns
    -------
    list of dicts, one per method (in the first table's order): ``method``, ``rmse_cm``,
    ``<group>_cm``, ``<class>_cm``, ``M`` (sample-weighted mean of the recordings' M),
    ``max_cm``, ``frames_over``, ``n_samples``, and ``in_95_ball_pct`` and
    ``<class>_in_95_ball_pct``: the percentage of all the recordings' samples (with an sd)
    inside the method's 95 % sd ball (:attr:`MethodScore.in_sd_ball`), None for a method
    without an sd.
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
        # share in the 95 % sd ball: pooled hits over pooled samples; None without an sd
        for key in ("all", *GLITCH_CLASS_NAMES.values()):
            share = pool_shares(
                [p.in_sd_ball if key == "all" else p.in_sd_ball_by_class.get(key) for p in parts],
                [p.counts.get("sd" if key == "all" else f"sd:{key}", 0) for p in parts],
            )
            col = "in_95_ball_pct" if key == "all" else f"{key}_in_95_ball_pct"
            row[col] = None if share is None else 100 * share
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
            "95% ball",
        ]
        w = max(8, *(len(s.method) for s in self.scores))  # whole names: robust_online
        lines = ["  ".join([f"{cols[0]:>{w}}", *(f"{c:>8}" for c in cols[1:])])]
        for s in self.scores:
            g = s.rmse_groups
            cells = [
                f"{s.method:>{w}}",
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
                "-" if s.in_sd_ball is None else 100 * s.in_sd_ball,
            ]
            lines.append("  ".join(_fmt(c) for c in cells))
        lines.append(
            f"{'truth':>{w}}  M = {self.truth_M * 1e3:.3f} e-3 m²; samples per raw class: "
            + ", ".join(f"{k} {v}" for k, v in self.class_counts.items())
            + "; 95% ball: % of samples within the 95 % ball of the method's sd"
        )
        if any(s.angles for s in self.scores):
            names = sorted({n for s in self.scores for n in s.angles})
            lines.append("")
            lines.append(
                f"{'angles':>{w}}  " + "  ".join(f"{n + ' best/d/fixed':>26}" for n in names)
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
                lines.append(f"{s.method:>{w}}  " + "  ".join(cells))
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
    if abs(int(fixed_delay)) >= track.n_frames:
        raise ValueError(
            f"fixed_delay {fixed_delay} frames is not shorter than the track "
            f"({track.n_frames} frames): no angle could be compared"
        )
    if isinstance(truth, GroundTruth):  # prepared in metres (prepare_truth converts)
        track = metric(track, "track")
    else:
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
        # None for a method that clips nothing (not 0 %: it has no limits to clip at)
        if cf is not None and diag.get("censoring", True) and np.size(cf) == len(truth.paired):
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
                std=getattr(out, "std", None),
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
    #: the track's units: rows in metres (``"m"``, the keys' ``_m``) or, for pixels and
    #: unknown units, in the track's own units
    units: str | None = "m"

    def to_dict(self) -> dict:
        return to_jsonable(
            {"rows": list(self.rows), "n_frames": self.n_frames, "units": self.units}
        )

    def to_text(self) -> str:
        metric = self.units == "m"
        unit = "px" if self.units == "px" else "units"
        head_m = "M (1e-3 m²)" if metric else f"M ({unit}²)"
        head_j = "max jump cm" if metric else f"max jump {unit}"
        lines = [f"{'method':>14}  {head_m:>12}  {head_j:>11}  largest jump at"]
        for r in self.rows:
            j = r["jumps"][0] if r["jumps"] else None
            where = f"{j['joint']} frame {j['frame']}" if j else "-"
            m, jump = (r["M"] * 1e3, r["max_jump_m"] * 100) if metric else (r["M"], r["max_jump_m"])
            lines.append(f"{r['method']:>14}  {m:12.3f}  {jump:11.1f}  {where}")
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
    # lengths in metres when the track has a length unit (converted), else its own units
    scale = track.metres_per_unit
    if scale not in (None, 1.0):
        for r in rows:
            r["M"] *= scale**2
            r["max_jump_m"] *= scale
            for j in r["jumps"]:
                j["jump_m"] *= scale
    return NoTruthTable(tuple(rows), track.n_frames, "m" if scale is not None else track.units)


def evaluate_paths(
    track_path: str | Path,
    truth_path: str | Path | None = None,
    methods: Sequence[MethodLike] = DEFAULT_METHODS,
    *,
    pairs: PairingTable | str | Path | None = None,
    outputs: dict[str, Any] | None = None,
    fps: float | None = None,
    topology: str | None = None,
    **truth_options: Any,
) -> tuple[GroundTruth | None, EvaluationTable | NoTruthTable]:
    """``tobitkf evaluate TRACK [--truth MOCAP]`` as a function (for the CLI).

    Loads both files with :func:`tobitkf.io.load` (first body of each), then runs
    :func:`prepare_truth` and :func:`evaluate_methods`, or, without ``truth_path``,
    :func:`evaluate_without_truth`.  ``fps`` and ``topology`` are the track's frame rate
    and skeleton where its file states none (:func:`tobitkf.io.unstated.with_unstated`:
    a ``.npy`` array, a keypoint table).  ``truth_options`` go to :func:`prepare_truth`
    (``offset_mode``, ``time``, ``mocap_rate``, ``fit_rate``, ``rate_range``).

    Returns
    -------
    (GroundTruth or None, EvaluationTable or NoTruthTable)
    """
    from tobitkf.io import load
    from tobitkf.io.unstated import with_unstated

    tracks = with_unstated(load(track_path), fps=fps, topology=topology)
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
