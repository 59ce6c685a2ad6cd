"""Synthetic benchmark for pose estimators: 2-D keypoints in pixels with confidence.

Two people move (the built-in motions, :func:`~tobitkf.evaluation.synthetic.generate_motion`,
one of them 1.2 m to the side of the other) in front of a pinhole camera
(:class:`Pose2DModel`: focal length 1000 px, 1920 × 1080 image, the Kinect's camera
frame: x right, y up, z depth); their 25 joints are projected to pixels, which is the
truth. :func:`corrupt_pose2d` then does what a 2-D pose estimator does, with a label per
sample (:data:`POSE2D_LABELS`):

``clean``
    jitter: white Gaussian noise of ``jitter_px`` (2 px; hands × 1.5) per axis;
    confidence drawn from U(0.7, 1).
``glitch``
    the keypoint is put somewhere else for 1–4 frames — on another keypoint of the body
    (part confusion) or 30–200 px away in a random direction — with a low confidence
    U(0.05, 0.5) (``glitch_rate`` per keypoint and frame);
``confident``
    the same, but the estimator is sure of it: confidence U(0.6, 0.95)
    (``confident_share`` of the glitches);
``missing``
    no detection for 3–15 frames (NaN position and confidence);
``lr_swap``
    a left/right pair (wrists, elbows, knees, ...) exchanged for 3–20 frames, with the
    estimator's usual confidence;
``id_swap``
    the two people's keypoints exchanged for 5–30 frames (a tracker's identity switch).

Rates are per frame and lengths in frames at 30 fps, a video's usual rate; a recording at
another rate (``fps`` of :func:`run_pose2d_benchmark`, ``tobitkf benchmark --kind pose2d
--fps``) gets the same episodes per second, each as many seconds long
(``round(length · fps / 30)`` frames, at least 1); jitter stays per sample. At 30 fps the
draws are exactly those of a model without this scaling.

:func:`run_pose2d_benchmark` smooths both people with every method and scores each
against its truth: RMSE in pixels by label. ``tobitkf benchmark --kind pose2d`` prints
it (docs/pose.md). The corruption rates are set from the failure modes the pose-
estimation literature reports (jitter of a few pixels, part confusions and identity
switches as the main error types); they are not fitted to any recording.

The baselines whose parameters are lengths or speeds (``one_euro``'s ``beta``, the
Kinect filter's radii) run on the pixels converted to metres with the camera's known
scale at the people's mean depth, so that their tuned defaults apply (a favour: a user
of real 2-D data does not know that scale), after the swaps are undone as
:func:`tobitkf.smooth` undoes them for every method on pixel data
(:mod:`tobitkf.smoothing.untangle`). ``kf`` and ``savgol`` are linear and need
none; ``robust`` and ``robust_online`` get the pixels as they are and take their gates
from the recording (docs/robust.md).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.core.jsonable import to_jsonable
from tobitkf.skeleton.sequence import SkeletonSequence

__all__ = [
    "POSE2D_LABELS",
    "POSE2D_METHODS",
    "Pose2DModel",
    "Pose2DTable",
    "corrupt_pose2d",
    "pose2d_markdown",
    "pose2d_spread",
    "project",
    "run_pose2d_benchmark",
]

Array = NDArray[np.float64]

#: sample labels of :func:`corrupt_pose2d` (code -> name), in the order they are applied
POSE2D_LABELS = {
    0: "clean",
    1: "glitch",
    2: "confident",
    3: "missing",
    4: "lr_swap",
    5: "id_swap",
}
#: the methods ``tobitkf benchmark --kind pose2d`` compares by default
POSE2D_METHODS = (
    "raw", "kf", "kf+rts", "savgol", "one_euro", "kinect", "robust", "robust_online",
)  # fmt: skip
#: baselines whose parameters are lengths: run in metres (module docstring)
_METRIC = ("one_euro", "kinect", "atkf", "atkf2016", "tkf", "tkfc")


@dataclass(frozen=True)
class Pose2DModel:
    """Camera and corruption parameters of the 2-D benchmark (module docstring)."""

    focal_px: float = 1000.0
    width_px: int = 1920
    height_px: int = 1080
    separation_m: float = 1.2
    jitter_px: float = 2.0
    hand_jitter_factor: float = 1.5
    clean_confidence: tuple[float, float] = (0.7, 1.0)
    glitch_rate: float = 0.004
    glitch_length: tuple[int, int] = (1, 4)
    glitch_offset_px: tuple[float, float] = (30.0, 200.0)
    glitch_confidence: tuple[float, float] = (0.05, 0.5)
    confident_share: float = 0.25
    confident_confidence: tuple[float, float] = (0.6, 0.95)
    missing_rate: float = 0.002
    missing_length: tuple[int, int] = (3, 15)
    lr_swap_rate: float = 0.003
    lr_swap_length: tuple[int, int] = (3, 20)
    id_swap_rate: float = 0.002
    id_swap_length: tuple[int, int] = (5, 30)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def project(positions: Array, model: Pose2DModel) -> Array:
    """Pinhole projection of camera-frame points (…, 3) in metres to pixels (…, 2)
    (image y pointing down)."""
    p = np.asarray(positions, dtype=float)
    z = p[..., 2]
    u = model.width_px / 2 + model.focal_px * p[..., 0] / z
    v = model.height_px / 2 - model.focal_px * p[..., 1] / z
    return np.stack([u, v], axis=-1)


def _runs(
    rng: np.random.Generator, T: int, rate: float, length: tuple[int, int], per30: float = 1.0
) -> list:
    """Episode (start, stop) pairs: starts with probability ``rate`` per frame at 30 fps,
    ``length`` frames at 30 fps; ``per30`` the recording's frames per frame at 30 fps."""
    out = []
    for t in np.flatnonzero(rng.random(T) < rate / per30):
        n = int(rng.integers(length[0], length[1] + 1))
        if per30 != 1.0:  # the same duration at the recording's rate (30 fps: as drawn)
            n = max(1, round(n * per30))
        out.append((int(t), min(T, int(t) + n)))
    return out


def corrupt_pose2d(
    truth: Sequence[SkeletonSequence], model: Pose2DModel | None = None, seed: int = 0
) -> tuple[list[SkeletonSequence], NDArray[np.int8]]:
    """What a pose estimator reports for the true pixel tracks of two people, and a
    label per sample ``(T, B, J)`` (:data:`POSE2D_LABELS`)."""
    m = model or Pose2DModel()
    rng = np.random.default_rng(seed)
    true = np.stack([s.positions for s in truth], axis=1)  # (T, B, J, 2)
    T, B, J, _ = true.shape
    per30 = float(truth[0].fps or 30.0) / 30.0
    topo = truth[0].topology
    hands = np.zeros(J, bool)
    hands[topo.joint_groups()["hands"]] = True
    sd = m.jitter_px * np.where(hands, m.hand_jitter_factor, 1.0)
    pos = true + rng.normal(size=true.shape) * sd[None, None, :, None]
    conf = rng.uniform(*m.clean_confidence, size=(T, B, J))
    labels = np.zeros((T, B, J), dtype=np.int8)
    for b in range(B):
        for j in range(J):
            for t0, t1 in _runs(rng, T, m.glitch_rate, m.glitch_length, per30):
                confident = rng.random() < m.confident_share
                if rng.random() < 0.5:  # part confusion: on another keypoint
                    k = int(rng.choice([i for i in range(J) if i != j]))
                    pos[t0:t1, b, j] = true[t0:t1, b, k] + rng.normal(size=2) * m.jitter_px
                else:
                    angle = rng.uniform(0, 2 * np.pi)
                    r = rng.uniform(*m.glitch_offset_px)
                    pos[t0:t1, b, j] = true[t0:t1, b, j] + r * np.array(
                        [np.cos(angle), np.sin(angle)]
                    )
                lo_hi = m.confident_confidence if confident else m.glitch_confidence
                conf[t0:t1, b, j] = rng.uniform(*lo_hi, size=t1 - t0)
                labels[t0:t1, b, j] = 2 if confident else 1
            for t0, t1 in _runs(rng, T, m.missing_rate, m.missing_length, per30):
                pos[t0:t1, b, j] = np.nan
                conf[t0:t1, b, j] = np.nan
                labels[t0:t1, b, j] = 3
        for left, right in topo.symmetry:
            for t0, t1 in _runs(rng, T, m.lr_swap_rate, m.lr_swap_length, per30):
                a = pos[t0:t1, b, left].copy()
                pos[t0:t1, b, left] = pos[t0:t1, b, right]
                pos[t0:t1, b, right] = a
                labels[t0:t1, b, [left, right]] = 4
    if B == 2:
        for t0, t1 in _runs(rng, T, m.id_swap_rate, m.id_swap_length, per30):
            pos[t0:t1] = pos[t0:t1, ::-1].copy()
            conf[t0:t1] = conf[t0:t1, ::-1].copy()
            labels[t0:t1] = 5
    seqs = [
        s.replace(
            positions=pos[:, b],
            confidence=conf[:, b],
            units="px",
            metadata={**s.metadata, "format": "synthetic_pose2d"},
        )
        for b, s in enumerate(truth)
    ]
    return seqs, labels


def _truth(
    motion: str, duration: float, seed: int, model: Pose2DModel, fps: float = 30.0
) -> list[SkeletonSequence]:
    """Two people's true pixel tracks at ``fps``."""
    from tobitkf.evaluation.synthetic import generate_motion

    people = []
    for k, shift in enumerate((-model.separation_m / 2, model.separation_m / 2)):
        s = generate_motion(motion, duration=duration, seed=seed * 1000 + k, fps=fps)
        p = s.positions.copy()
        p[..., 0] += shift - np.nanmean(p[..., 0])
        people.append(s.replace(positions=project(p, model), units="px", body_id=f"person{k}",
                                tracking_state=None, metadata={"motion": motion}))  # fmt: skip
    return people


@dataclass(frozen=True)
class Pose2DTable:
    """RMSE (px) per method, overall and by label; label counts; settings."""

    rows: tuple[dict[str, Any], ...]
    label_counts: dict[str, int]
    settings: dict[str, Any]

    def row(self, method: str) -> dict[str, Any]:
        for r in self.rows:
            if r["method"] == method:
                return r
        raise KeyError(f"no method {method!r}; have {[r['method'] for r in self.rows]}")

    def to_dict(self) -> dict[str, Any]:
        return to_jsonable(
            {"rows": list(self.rows), "label_counts": self.label_counts, "settings": self.settings}
        )


def _method(spec: Any, metres_per_px: float) -> tuple[str, Callable[[Any], Any]]:
    from tobitkf.evaluation.scores import resolve_method

    label, fn = resolve_method(spec)
    base = label.split("+")[0]
    if isinstance(spec, str) and base in _METRIC:

        def in_metres(seqs: Any, _fn: Callable[[Any], Any] = fn) -> Any:
            from tobitkf.smoothing.untangle import untangle_sequences

            seqs = untangle_sequences(list(seqs))[0]  # as tobitkf.smooth does for pixels
            scaled = [s.replace(positions=s.positions * metres_per_px, units="m") for s in seqs]
            out = _fn(scaled)
            return [
                o.replace(
                    positions=o.positions / metres_per_px,
                    std=None if o.std is None else o.std / metres_per_px,
                    units="px",
                )
                for o in out
            ]

        return label, in_metres
    return label, fn


def _rmse(err: Array, mask: NDArray[np.bool_]) -> float:
    ok = mask & np.isfinite(err)
    return float(np.sqrt(np.mean(err[ok] ** 2))) if ok.any() else float("nan")


def run_pose2d_benchmark(
    seed: int = 0,
    methods: Sequence[Any] = POSE2D_METHODS,
    *,
    motion: str = "mixed",
    duration: float = 10.0,
    model: Pose2DModel | None = None,
    outputs: dict[str, Any] | None = None,
    fps: float = 30.0,
) -> Pose2DTable:
    """Corrupt two people's projected motion (:func:`corrupt_pose2d`), smooth them with
    every method (a method is a name or an :mod:`~tobitkf.evaluation.scores` spec), and
    score every estimate against the truth: RMSE in pixels, overall and by label. ``fps``:
    the video's frame rate (the episodes keep their duration; module docstring)."""
    if not fps > 0:
        raise ValueError(f"the frame rate must be > 0, got {fps}")
    m = model or Pose2DModel()
    truth = _truth(motion, duration, seed, m, fps)
    noisy, labels = corrupt_pose2d(truth, m, seed=seed)
    from tobitkf.evaluation.synthetic import generate_motion

    depth = float(np.nanmean(generate_motion(motion, duration=duration, seed=seed * 1000,
                                             fps=fps).positions[..., 2]))  # fmt: skip
    metres_per_px = depth / m.focal_px
    true = np.stack([s.positions for s in truth], axis=1)
    rows = []
    for spec in methods:
        label, fn = _method(spec, metres_per_px)
        out = noisy if label == "raw" else list(fn(noisy))  # both people in one call
        if outputs is not None:
            outputs[label] = out
        est = np.stack([s.positions for s in out], axis=1)
        err = np.linalg.norm(est - true, axis=-1)
        row: dict[str, Any] = {"method": label, "rmse_px": _rmse(err, np.ones(err.shape, bool))}
        for code, name in POSE2D_LABELS.items():
            row[f"{name}_px"] = _rmse(err, labels == code)
        rows.append(row)
    if outputs is not None:
        outputs["truth"], outputs["corrupted"], outputs["labels"] = truth, noisy, labels
    counts = {name: int((labels == code).sum()) for code, name in POSE2D_LABELS.items()}
    return Pose2DTable(
        tuple(rows),
        counts,
        {
            "seed": seed,
            "motion": motion,
            "duration_s": duration,
            "fps": fps,
            "n_frames": truth[0].n_frames,
            "metres_per_px": metres_per_px,
            "model": m.to_dict(),
        },
    )


def pose2d_spread(tables: Sequence[Pose2DTable]) -> list[dict[str, Any]]:
    """Mean and standard deviation over seeds of every RMSE column, per method."""
    if not tables:
        raise ValueError("pose2d_spread: no tables")
    out = []
    for r0 in tables[0].rows:
        entry: dict[str, Any] = {"method": r0["method"]}
        for key in (k for k in r0 if k != "method"):
            v = np.array([t.row(r0["method"])[key] for t in tables], dtype=float)
            v = v[np.isfinite(v)]
            entry[key] = (float(v.mean()), float(v.std())) if v.size else (np.nan, np.nan)
        out.append(entry)
    return out


def pose2d_markdown(spread: Sequence[dict[str, Any]], seeds: Sequence[int]) -> str:
    """Markdown of :func:`pose2d_spread`: RMSE in px, mean ± sd over the seeds, overall
    and by label (mean)."""
    from tobitkf.evaluation.markdown import spread_markdown

    return spread_markdown(spread, seeds, total="rmse_px", unit="pixels", suffix="_px")
