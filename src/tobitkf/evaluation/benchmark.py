"""Synthetic benchmark with known truth: RMSE by glitch type per method.

:func:`run_benchmark` takes clean motion (the built-in generator,
:func:`~tobitkf.evaluation.synthetic.generate_motion`, or the CMU BVH file through
:func:`~tobitkf.evaluation.synthetic.bvh_to_kinect`), corrupts it with the Kinect-like
model (:func:`~tobitkf.evaluation.corruption.corrupt`), runs every method on the
corrupted sequence and scores it against the truth, split by the label of each sample
(clean = jitter only, spike, sustained failure, inferred drift).  No registration or time
alignment is needed: the truth is known in the track's frame and clock.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tobitkf.core.jsonable import to_jsonable
from tobitkf.evaluation.corruption import LABEL_NAMES, CorruptedTrack, CorruptionModel, corrupt
from tobitkf.evaluation.evaluate import DEFAULT_METHODS, MethodLike, resolve_method
from tobitkf.evaluation.metrics import (
    in_sd_ball,
    joint_errors,
    pool_shares,
    rmse,
    sample_share,
    smoothness,
    velocity_lag,
)

__all__ = [
    "BenchmarkRow",
    "BenchmarkTable",
    "benchmark_track",
    "run_benchmark",
    "seed_ball",
    "seed_spread",
]


@dataclass(frozen=True)
class BenchmarkRow:
    """One method's RMSE (m) overall and per label, its M (m²) and its hand lag (frames).

    in_sd_ball, in_sd_ball_by_label : methods with a posterior sd: the share (0..1) of the
        samples whose error lies in the 95 % ball of that sd
        (:func:`~tobitkf.evaluation.metrics.in_sd_ball`), overall and per label; None and
        empty without an sd.  ``sd_counts``: their numbers of samples (``"all"``, labels).
    """

    method: str
    rmse: float
    rmse_by_label: dict[str, float]
    p95: float
    smoothness_M: float
    lag_frames: int | None
    in_sd_ball: float | None = None
    in_sd_ball_by_label: dict[str, float] = field(default_factory=dict)
    sd_counts: dict[str, int] = field(default_factory=dict)

    def row(self) -> dict[str, Any]:
        """Flat dict in centimetres."""
        return {
            "method": self.method,
            "rmse_cm": 100 * self.rmse,
            **{f"{k}_cm": 100 * v for k, v in self.rmse_by_label.items()},
            "p95_cm": 100 * self.p95,
            "M": self.smoothness_M,
            "lag_frames": self.lag_frames,
            "in_95_ball_pct": None if self.in_sd_ball is None else 100 * self.in_sd_ball,
            **{f"{k}_in_95_ball_pct": 100 * v for k, v in self.in_sd_ball_by_label.items()},
        }


@dataclass(frozen=True)
class BenchmarkTable:
    """Result of :func:`run_benchmark`: rows per method, label counts, what was run."""

    rows: tuple[BenchmarkRow, ...]
    label_counts: dict[str, int]
    truth_M: float
    settings: dict[str, Any]

    def row(self, method: str) -> BenchmarkRow:
        for r in self.rows:
            if r.method == method:
                return r
        raise KeyError(f"no method {method!r}; have {[r.method for r in self.rows]}")

    def to_dict(self) -> dict[str, Any]:
        return to_jsonable(
            {
                "rows": [r.row() for r in self.rows],
                "label_counts": self.label_counts,
                "truth_M": self.truth_M,
                "settings": self.settings,
            }
        )

    def to_text(self) -> str:
        labels = list(LABEL_NAMES.values())
        head = ["method", "rmse", *labels, "p95", "M e-3", "lag", "95% ball"]
        w = max(10, *(len(r.method) for r in self.rows))  # whole names: robust_online
        lines = ["  ".join([f"{head[0]:>{w}}", *(f"{h:>10}" for h in head[1:])])]
        for r in self.rows:
            cells = [r.rmse, *[r.rmse_by_label[k] for k in labels], r.p95]
            txt = [f"{r.method:>{w}}"] + [
                f"{100 * c:10.2f}" if np.isfinite(c) else f"{'-':>10}" for c in cells
            ]
            txt.append(f"{r.smoothness_M * 1e3:10.3f}")
            txt.append(f"{'-' if r.lag_frames is None else r.lag_frames:>10}")
            ball = r.in_sd_ball
            txt.append(f"{'-' if ball is None else f'{100 * ball:.1f}':>10}")
            lines.append("  ".join(txt))
        lines.append(
            "(cm; samples per label: "
            + ", ".join(f"{k} {v}" for k, v in self.label_counts.items())
            + f"; truth M = {self.truth_M * 1e3:.3f} e-3 m²; 95% ball: % of samples within"
            " the 95 % ball of the method's sd)"
        )
        return "\n".join(lines)


def benchmark_track(
    corrupted: CorruptedTrack,
    methods: Sequence[MethodLike] = DEFAULT_METHODS,
    *,
    outputs: dict[str, Any] | None = None,
    settings: dict[str, Any] | None = None,
) -> BenchmarkTable:
    """Score methods on an already corrupted track (see :func:`run_benchmark`)."""
    seq = corrupted.sequence
    truth = corrupted.truth
    labels = corrupted.labels
    groups = seq.topology.joint_groups()
    hands = list(groups.get("hands", []))
    rows = []
    for spec in methods:
        label, fn = resolve_method(spec)
        out = fn(seq)
        if outputs is not None:
            outputs[label] = out
        est = np.asarray(out.positions, dtype=float)
        err = joint_errors(est, truth)
        by = {name: rmse(err, labels == code) for code, name in LABEL_NAMES.items()}
        fin = err[np.isfinite(err)]
        lag = None
        if hands and len(est) > 30:
            try:
                lag = velocity_lag(est, truth, hands, max_lag=10)[0]
            except ValueError:
                lag = None
        ball, ball_by, sd_counts = None, {}, {}
        if getattr(out, "std", None) is not None:
            hits = in_sd_ball(est, truth, out.std)
            ball, sd_counts["all"] = sample_share(hits)
            for code, name in LABEL_NAMES.items():
                ball_by[name], sd_counts[name] = sample_share(hits, labels == code)
        rows.append(
            BenchmarkRow(
                method=label,
                rmse=rmse(err),
                rmse_by_label=by,
                p95=float(np.percentile(fin, 95)) if fin.size else float("nan"),
                smoothness_M=smoothness(est),
                lag_frames=lag,
                in_sd_ball=ball,
                in_sd_ball_by_label=ball_by,
                sd_counts=sd_counts,
            )
        )
    return BenchmarkTable(
        rows=tuple(rows),
        label_counts=corrupted.counts(),
        truth_M=smoothness(truth),
        settings=dict(settings or {}),
    )


def run_benchmark(
    seed: int = 0,
    methods: Sequence[MethodLike] = DEFAULT_METHODS,
    *,
    motion: str = "mixed",
    source: str | Path = "generator",
    duration: float = 10.0,
    model: CorruptionModel | None = None,
    outputs: dict[str, Any] | None = None,
    fps: float = 30.0,
) -> BenchmarkTable:
    """Run every method on a corrupted synthetic recording and score it by glitch type.

    Parameters
    ----------
    seed : seeds both the motion generator and the corruption.
    methods : method specs (see :mod:`tobitkf.evaluation.evaluate`), default the issue's
        comparison (raw, kf, atkf, atkf2016, sgf, kf+rts, one_euro, kinect).
    motion : ``"walk"``, ``"arms"``, ``"squat"`` or ``"mixed"`` (generator only).
    source : ``"generator"`` (built in, no files needed) or the path of a CMU BVH file.
    duration : seconds of generated motion.
    model : corruption parameters (defaults calibrated on KERAAL / KIMORE).
    outputs : optional dict filled with ``label -> smoothed sequence``, plus ``"truth"``
        (the clean sequence) and ``"corrupted"`` (the :class:`CorruptedTrack`).
    fps : frame rate of the recording (default 30, the Kinect's): the motion is generated
        or the BVH resampled at it, and the corruption's episodes keep their duration
        (:mod:`~tobitkf.evaluation.corruption`).

    Returns
    -------
    BenchmarkTable
    """
    from tobitkf.evaluation.synthetic import bvh_to_kinect, generate_motion

    if str(source) == "generator":
        clean = generate_motion(motion, duration=duration, seed=seed, fps=fps)
    else:
        clean = bvh_to_kinect(source, fps=fps)
    corrupted = corrupt(clean, model, seed=seed)
    if outputs is not None:
        outputs["truth"] = clean
        outputs["corrupted"] = corrupted
    return benchmark_track(
        corrupted,
        methods,
        outputs=outputs,
        settings={
            "seed": seed,
            "motion": motion if str(source) == "generator" else None,
            "source": str(source),
            "duration_s": duration,
            "fps": fps,
            "n_frames": corrupted.sequence.n_frames,
            "model": corrupted.model.to_dict(),
        },
    )


def seed_spread(tables: Sequence[BenchmarkTable]) -> list[dict[str, Any]]:
    """Mean and standard deviation over seeds of each method's RMSE (``tobitkf benchmark
    --seeds K``).

    Parameters
    ----------
    tables : one :class:`BenchmarkTable` per seed, with the same methods.

    Returns
    -------
    list of dicts, one per method in the first table's order: ``method`` and, for
    ``rmse`` and every label of ``rmse_by_label``, a ``(mean, sd)`` pair in metres (NaN
    where no seed had samples of that label).
    """
    if not tables:
        raise ValueError("seed_spread: no tables")
    out = []
    for r0 in tables[0].rows:
        rows = [t.row(r0.method) for t in tables]
        entry: dict[str, Any] = {"method": r0.method}
        for key in ("rmse", *r0.rmse_by_label):
            v = np.array([r.rmse if key == "rmse" else r.rmse_by_label[key] for r in rows])
            v = v[np.isfinite(v)]
            entry[key] = (float(v.mean()), float(v.std())) if v.size else (np.nan, np.nan)
        out.append(entry)
    return out


def seed_ball(tables: Sequence[BenchmarkTable]) -> list[dict[str, Any]]:
    """The share of samples in each method's 95 % sd ball, pooled over seeds (all the
    seeds' hits over all their samples, so a seed weighs by its samples).

    Returns
    -------
    list of dicts, one per method in the first table's order: ``method``,
    ``in_95_ball_pct`` and ``<label>_in_95_ball_pct`` in percent (NaN where no seed had
    samples of that label); None for a method without an sd.
    """
    out = []
    for r0 in tables[0].rows:
        rows = [t.row(r0.method) for t in tables]
        entry: dict[str, Any] = {"method": r0.method}
        for key in ("all", *LABEL_NAMES.values()):
            share = pool_shares(
                [r.in_sd_ball if key == "all" else r.in_sd_ball_by_label.get(key) for r in rows],
                [r.sd_counts.get(key, 0) for r in rows],
            )
            col = "in_95_ball_pct" if key == "all" else f"{key}_in_95_ball_pct"
            entry[col] = None if share is None else 100 * share
        out.append(entry)
    return out
