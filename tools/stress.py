"""The methods on real recordings made harder: lower rate, added noise, dropped frames.

Recordings with ground truth (a skeleton track and its simultaneous mocap, paired as
``tobitkf evaluate`` pairs them) are smoothed as recorded and then changed in three ways a
user's recordings may differ from ours, and the pooled RMSE against the truth is printed
for each (docs/robust.md, "Stress tests on the real recordings"):

* ``--every N``: only every N-th frame is kept (a sensor at 1/N of the rate, as a Kinect
  V2 drops to 15 fps in low light). Each of the N phases (frames 0, N, 2N, ...; 1, N+1,
  ...) is smoothed as a recording of its own and scored against the truth at its frames;
  the phases are pooled, so the raw row scores exactly the samples of the full rate;
* ``--noise SD ...``: white noise of SD per axis (in the track's units: metres for a
  Kinect) is added to every present sample before smoothing (a noisier sensor or a
  person further from it), once per seed (``--seeds``: 0, 1, ...); mean ± standard
  deviation over the seeds. The truth is not changed;
* ``--drop FRACTION``: that fraction of the frames is dropped at random (the first and
  the last kept), the others keep their timestamps (a sensor or a computer too busy to
  deliver every frame: irregular steps of one, two or more frames); scored at the
  frames kept, once per seed.

The truth is registered once, on the recording as it is; a changed recording is scored
against it at the same frames.

    python tools/stress.py TRACK... --truth-replace OLD NEW [--every 2] [--noise 0.005 0.01]
                           [--drop 0.2] [--seeds 3] [--methods raw,kf+rts,robust,robust_online]
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

import tobitkf as tk
from tobitkf.evaluation.scores import resolve_method

METHODS = ("raw", "kf+rts", "robust", "robust_online")
#: the methods given a "vs raw" percentage
DEFAULTS = (tk.DEFAULT_METHOD, tk.DEFAULT_LIVE_METHOD)


def _frames(
    track: tk.SkeletonSequence, index: slice | np.ndarray, **changes
) -> tk.SkeletonSequence:
    """The frames ``index`` of ``track`` as a recording of its own: every per-frame array
    taken at them, then ``changes``."""

    def cut(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else a[index]

    arrays = {
        "positions": track.positions[index],
        "timestamps": cut(track.timestamps),
        "tracking_state": cut(track.tracking_state),
        "confidence": cut(track.confidence),
    }
    return track.replace(**{**arrays, **changes})


def every_nth(track: tk.SkeletonSequence, every: int, phase: int) -> tk.SkeletonSequence:
    """Frames ``phase, phase + every, ...`` of ``track`` as a recording of its own (the
    nominal rate divided by ``every``)."""
    if every < 1 or not 0 <= phase < every:
        raise ValueError(f"every_nth: need every >= 1 and 0 <= phase < every, got {every}, {phase}")
    fps = None if track.fps is None else track.fps / every
    return _frames(track, slice(phase, None, every), fps=fps)


def with_noise(track: tk.SkeletonSequence, sd: float, seed: int) -> tk.SkeletonSequence:
    """``track`` with independent N(0, sd²) added to every axis of every sample."""
    if not sd >= 0:
        raise ValueError(f"with_noise: the noise's sd must be >= 0, got {sd}")
    rng = np.random.default_rng(seed)
    return track.replace(positions=track.positions + rng.normal(0.0, sd, track.positions.shape))


def drop_frames(track: tk.SkeletonSequence, fraction: float, seed: int) -> np.ndarray:
    """The frames kept when ``fraction`` of them are dropped at random (each with that
    probability; the first and the last always kept), as a boolean mask (T,)."""
    if not 0 <= fraction < 1:
        raise ValueError(f"drop_frames: the fraction must be in [0, 1), got {fraction}")
    keep = np.random.default_rng(seed).random(track.n_frames) >= fraction
    keep[0] = keep[-1] = True
    return keep


def _sse(method: str, track: tk.SkeletonSequence, truth: np.ndarray) -> tuple[float, int]:
    """Sum of squared position errors and the number of samples scored (both finite);
    ``method`` is a method spec of ``tobitkf evaluate`` ("raw", "kf+rts", "robust", ...)."""
    est = resolve_method(method)[1](track)
    err = np.linalg.norm(est.positions - truth, axis=-1)
    ok = np.isfinite(err)
    return float(np.sum(err[ok] ** 2)), int(ok.sum())


def pooled_rmse(
    pairs: Sequence[tuple[tk.SkeletonSequence, np.ndarray]],
    methods: Sequence[str],
    *,
    every: int = 1,
    noise: float = 0.0,
    drop: float = 0.0,
    seed: int = 0,
) -> dict[str, float]:
    """Pooled RMSE (the track's units) of each method over ``(track, truth (T, J, D))``
    pairs, each track cut to every ``every``-th frame (all phases pooled), given white
    noise of ``noise`` per axis, and with ``drop`` of its frames dropped (``seed``; one
    generator per recording and phase, seeded ``seed``)."""
    tot = {m: [0.0, 0] for m in methods}
    for track, truth in pairs:
        if drop > 0:
            keep = drop_frames(track, drop, seed)
            # the frames kept keep their times (from the nominal rate when none are stated)
            track = _frames(track, keep, timestamps=track.times()[keep])
            truth = truth[keep]
        for phase in range(every):
            t = every_nth(track, every, phase) if every > 1 else track
            if noise > 0:
                t = with_noise(t, noise, seed)
            gt = truth[phase::every]
            for m in methods:
                s, n = _sse(m, t, gt)
                tot[m][0] += s
                tot[m][1] += n
    return {m: float(np.sqrt(s / n)) if n else float("nan") for m, (s, n) in tot.items()}


def _ordinal(n: int) -> str:
    return f"{n}" + ("th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th"))


def _cell(values: Sequence[float], raw: float | None, scale: float) -> str:
    v = np.asarray(values) * scale
    txt = f"{v.mean():.2f}" if v.size == 1 else f"{v.mean():.2f} ± {v.std(ddof=1):.2f}"
    if raw is not None:
        txt += f" ({100 * (np.mean(values) / raw - 1):+.0f} %)"
    return txt


def table(
    pairs: Sequence[tuple[tk.SkeletonSequence, np.ndarray]],
    methods: Sequence[str],
    every: int,
    noises: Sequence[float],
    seeds: int,
    scale: float,
    unit: str,
    drops: Sequence[float] = (),
) -> list[str]:
    """The markdown table's lines: one row per condition, one column per method."""
    fps = pairs[0][0].fps
    rate = f" ({fps:g} fps)" if fps else ""
    rows: list[tuple[str, list[dict[str, float]]]] = [
        (f"as recorded{rate}", [pooled_rmse(pairs, methods)])
    ]
    if every > 1:
        low = f" ({fps / every:g} fps)" if fps else ""
        rows.append((f"every {_ordinal(every)} frame{low}, {every} phases pooled",
                     [pooled_rmse(pairs, methods, every=every)]))  # fmt: skip
    for sd in noises:
        rows.append((
            f"+ {sd * scale:g} {unit} white noise per axis, {seeds} seeds",
            [pooled_rmse(pairs, methods, noise=sd, seed=s) for s in range(seeds)],
        ))  # fmt: skip
    for fr in drops:
        rows.append((
            f"{100 * fr:g} % of frames dropped at random, {seeds} seeds",
            [pooled_rmse(pairs, methods, drop=fr, seed=s) for s in range(seeds)],
        ))  # fmt: skip
    out = [
        f"| condition | {' | '.join(methods)} |",
        "|---|" + "---|" * len(methods),
    ]
    for label, runs in rows:
        raw = float(np.mean([r["raw"] for r in runs])) if "raw" in methods else None
        cells = [
            _cell([r[m] for r in runs], raw if m in DEFAULTS else None, scale) for m in methods
        ]
        out.append(f"| {label} | {' | '.join(cells)} |")
    return out


def main(argv: list[str] | None = None) -> int:
    from tobitkf.evaluation.truth import prepare_truth
    from tobitkf.io import load

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from error_breakdown import parse_with_truth_replace

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tracks", nargs="+")
    ap.add_argument("--every", type=int, default=2, help="keep every N-th frame (1: off)")
    ap.add_argument("--noise", type=float, nargs="*", default=[0.005, 0.01],
                    help="white noise per axis, the track's units (m for a Kinect)")  # fmt: skip
    ap.add_argument("--drop", type=float, nargs="*", default=[0.2],
                    help="fractions of the frames dropped at random")  # fmt: skip
    ap.add_argument("--seeds", type=int, default=3, help="draws per noise level and drop")
    ap.add_argument("--methods", default=",".join(METHODS))
    args, (old, new) = parse_with_truth_replace(ap, argv)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    if args.every < 1:
        ap.error(f"--every must be at least 1, got {args.every}")
    if any(not sd > 0 for sd in args.noise):
        ap.error(f"--noise levels must be > 0, got {args.noise}")
    if any(not 0 < fr < 1 for fr in args.drop):
        ap.error(f"--drop fractions must be in (0, 1), got {args.drop}")
    if (args.noise or args.drop) and args.seeds < 2:
        ap.error(f"--seeds must be at least 2 (a mean ± sd), got {args.seeds}")
    pairs = []
    for path in args.tracks:
        track = load(path)[0]
        truth = prepare_truth(track, load(path.replace(old, new))[0])
        pairs.append((track, truth.positions))
    units = pairs[0][0].units
    scale, unit = (100.0, "cm") if units == "m" else (1.0, units or "units")
    print(f"Pooled RMSE against the truth, {unit} ({len(pairs)} recordings); "
          f"`{tk.DEFAULT_METHOD}` and `{tk.DEFAULT_LIVE_METHOD}` with their change "
          "against raw in the same condition:\n")  # fmt: skip
    print("\n".join(table(pairs, methods, args.every, args.noise, args.seeds, scale, unit,
                          args.drop)))  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
