"""What a delay buys: ``robust`` run live on a sliding window, each frame returned late
(:class:`tobitkf.DelayedSmoother`; docs/robust.md, "Live with a delay").

Each track is smoothed by :func:`tobitkf.smooth_delayed` (what a stream of it returns
frame by frame: ``robust`` on the last ``--window`` seconds, the frame ``delay`` back) at
several delays, next to the causal default ``robust_online`` and the offline ``robust``
on the whole recording. With tracks: scored against their motion capture as ``tobitkf
evaluate`` does, pooled over the recordings. With ``--benchmark SEEDS``: on the built-in
synthetic benchmark (``tobitkf benchmark``'s recordings, seeds 0 .. SEEDS - 1), the
RMSE against the truth, mean ± sd over the seeds.

    python tools/delayed.py TRACKS... --truth-replace OLD NEW [--delays 0,0.1,...]
    python tools/delayed.py --benchmark 5
"""

from __future__ import annotations

import argparse
import glob
import sys

import numpy as np
from error_breakdown import parse_with_truth_replace  # tools/ is on the script's path

from tobitkf.evaluation.benchmark import run_benchmark
from tobitkf.evaluation.evaluate import evaluate_paths, pool_scores
from tobitkf.smoothing.delayed import delay_frames, smooth_delayed


def specs(delays: list[float], window: float, **params: float) -> list:
    def late(d: float) -> tuple:
        return (f"delayed {d:g} s", lambda s: smooth_delayed(s, delay=d, window=window, **params))

    return ["raw", "robust_online", *(late(d) for d in delays), "robust"]


def late_frames(name: str, window: float) -> str:
    if name.startswith("delayed "):
        return str(delay_frames(float(name.split()[1]), window, 30.0)[0])
    return {"robust_online": "0 (causal)", "robust": "whole recording"}.get(name, "")


def given(params: dict) -> str:
    """The delayed rows' settings other than the defaults, for a table's caption."""
    return "".join(f", delayed rows with {k} {v:g}" for k, v in params.items())


def vs_raw(value: float, raw: float, name: str) -> str:
    return "" if name == "raw" else f"{100 * (value / raw - 1):+.0f} %"


def real(tracks: list[str], replace: tuple[str, str], delays: list[float], window: float,
         **params: float) -> None:  # fmt: skip
    methods = specs(delays, window, **params)
    tables = [evaluate_paths(p, p.replace(*replace), methods)[1] for p in tracks]
    pooled = pool_scores(tables)
    n = sum(t.scores[0].counts["all"] for t in tables)
    print(f"RMSE against motion capture, cm ({len(tables)} recordings, {n:,} samples; "
          f"pooled; window {window:g} s{given(params)}):\n")  # fmt: skip
    print("| method | frames late at 30 fps | RMSE | vs raw | sustained | in 95% ball |")
    print("|---|---|---|---|---|---|")
    raw = pooled[0]["rmse_cm"]
    for row in pooled:
        name, ball = row["method"], row.get("in_95_ball_pct")
        print(f"| {name} | {late_frames(name, window)} | {row['rmse_cm']:.2f} | "
              f"{vs_raw(row['rmse_cm'], raw, name)} | {row['sustained_cm']:.2f} | "
              f"{'–' if ball is None else f'{ball:.1f}'} |")  # fmt: skip


def benchmark(seeds: int, delays: list[float], window: float, **params: float) -> None:
    methods = specs(delays, window, **params)
    rmse = np.array([[r.rmse for r in run_benchmark(seed, methods).rows]
                     for seed in range(seeds)]) * 100  # fmt: skip
    names = [m if isinstance(m, str) else m[0] for m in methods]
    mean, sd = rmse.mean(axis=0), rmse.std(axis=0, ddof=1)
    print(f"RMSE against the truth, cm (built-in synthetic benchmark, mean ± sd over seeds "
          f"0–{seeds - 1}; window {window:g} s{given(params)}):\n")  # fmt: skip
    print("| method | frames late at 30 fps | RMSE | vs raw |")
    print("|---|---|---|---|")
    for name, m, s in zip(names, mean, sd, strict=True):
        print(f"| {name} | {late_frames(name, window)} | {m:.2f} ± {s:.2f} | "
              f"{vs_raw(m, mean[0], name)} |")  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("tracks", nargs="*")
    parser.add_argument("--benchmark", type=int, metavar="SEEDS")
    parser.add_argument("--delays", default="0,0.1,0.2,0.33,0.5,1,2")
    parser.add_argument("--window", type=float, default=10.0)
    parser.add_argument("--fit-seconds", type=float, help="robust's fit_seconds, delayed rows")
    parser.add_argument("--refit", type=float, help="seconds between noise fits, delayed rows")
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--benchmark" in argv:
        args = parser.parse_args(argv)
    else:
        args, replace = parse_with_truth_replace(parser, argv)
    delays = [float(d) for d in args.delays.split(",")]
    extra = {k: v for k, v in (("fit_seconds", args.fit_seconds), ("refit", args.refit))
             if v is not None}  # fmt: skip
    if args.benchmark:
        benchmark(args.benchmark, delays, args.window, **extra)
    else:
        tracks = sorted(p for pattern in args.tracks for p in glob.glob(pattern) or [pattern])
        real(tracks, replace, delays, args.window, **extra)


if __name__ == "__main__":
    main()
