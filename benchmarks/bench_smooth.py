"""Throughput of every registered smoothing method through ``tk.smooth`` (run by hand).

    .venv/bin/python benchmarks/bench_smooth.py                # all methods, both data sets
    .venv/bin/python benchmarks/bench_smooth.py -m robust -m robust_online --repeats 3

Data: (a) 12 synthetic Kinect V2 recordings x 1500 frames x 25 joints (the built-in
motions with the Kinect-like corruption: jitter, spikes, sustained failures, inferred
drift), smoothed in one ``tk.smooth`` call (a list of sequences: the bodies go to the
method together); (b) the three KIMORE recordings in ../shared/data/kimore (when present),
one call each. For each method it prints joint-frames per second and the ratio to the
package's Kalman core, ``tk.kalman_filter`` (3-D random walk per joint, A = H = I, on the
same positions, all joints of all recordings as one batch), measured in the same run.
The first call of each method is not timed (it loads, or compiles, the robust kernels).
Live: the per-frame latency of ``robust_online`` through ``LiveSmoother`` for one body.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from bench_filters import best_of  # benchmarks/ is on the path when this script runs

import tobitkf as tk

KIMORE = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "kimore"


def synthetic_recordings(n: int = 12, T: int = 1500) -> list:
    """``n`` corrupted Kinect V2 recordings of ``T`` frames on one 30 fps time base."""
    kinds = ("mixed", "walk", "arms", "squat")
    out = []
    for i in range(n):
        clean = tk.generate_motion(kinds[i % 4], duration=1.2 * T / 30.0, seed=i)
        bad = tk.corrupt(clean, seed=i).sequence  # drops frames: keep the first T, 30 fps
        out.append(
            tk.SkeletonSequence(
                positions=bad.positions[:T],
                topology=bad.topology,
                fps=30.0,
                tracking_state=bad.tracking_state[:T],
            )
        )
    return out


def core_rate(batches: list[np.ndarray], repeats: int) -> float:
    """Joint-frames/s of tk.kalman_filter over the batches (T, joints, 3), NaN -> missing."""
    jf = sum(b.shape[0] * b.shape[1] for b in batches)
    models = [tk.skeleton_model(q=0.0025, r=0.01, x0=np.nan_to_num(b[0])) for b in batches]

    def run() -> None:
        for m, b in zip(models, batches, strict=True):
            tk.kalman_filter(m, b)

    return jf / best_of(run, repeats)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-m", "--method", action="append", help="only these methods")
    ap.add_argument("--repeats", type=int, default=2, help="best of N timings (default 2)")
    ap.add_argument("--frames", type=int, default=1500, help="frames per synthetic recording")
    ap.add_argument("--live-frames", type=int, default=2000, help="frames for the live latency")
    args = ap.parse_args()
    names = args.method or sorted(tk.methods())
    sets: dict[str, list] = {
        f"12 x {args.frames} x 25 synthetic": [synthetic_recordings(12, args.frames)]
    }
    files = sorted(KIMORE.glob("*.csv")) if KIMORE.is_dir() else []
    if files:
        sets[f"KIMORE x {len(files)}"] = [[tk.load(f)[0]] for f in files]
    for label, calls in sets.items():
        seqs = [s for c in calls for s in c]
        jf = sum(s.n_frames * s.n_joints for s in seqs)
        # the core on the same positions: one (T, bodies x joints, 3) batch per call
        batches = [np.concatenate([s.positions for s in c], axis=1) for c in calls]
        # the machine may be shared: the core is timed again beside each method and its
        # best rate so far is the reference (a conservative ratio)
        base = core_rate(batches, args.repeats)
        rows = []
        for name in names:

            def run(name: str = name, calls: list = calls) -> None:
                for c in calls:
                    tk.smooth(c if len(c) > 1 else c[0], method=name)

            run()  # warm-up: kernels loaded or compiled, caches filled
            sec = best_of(run, args.repeats)
            base = max(base, core_rate(batches, args.repeats))
            rows.append((name, sec, jf / sec))
        print(f"\n{label}: {jf} joint-frames; tk.kalman_filter core {base:,.0f} joint-frames/s")
        print(f"{'method':>14} {'seconds':>9} {'joint-frames/s':>15} {'/ core':>8}")
        for name, sec, rate in rows:
            print(f"{name:>14} {sec:9.3f} {rate:15,.0f} {rate / base:8.3f}")
    live_latency(args.live_frames)


def live_latency(n: int) -> None:
    """Per-frame latency of robust_online through LiveSmoother, one 25-joint body."""
    if "robust_online" not in tk.methods() or n < 2:
        return
    seq = synthetic_recordings(1, n)[0]
    live = tk.LiveSmoother(seq.topology, "robust_online", fps=30.0)
    lat = np.empty(n)
    for k in range(n):
        t0 = time.perf_counter()
        live.update(seq.positions[k], seq.tracking_state[k])
        lat[k] = time.perf_counter() - t0
    lat = lat[1:] * 1e6  # the first frame allocates the state
    print(
        f"\nlive robust_online, 1 body x 25 joints, {n} frames: per frame median "
        f"{np.median(lat):.0f} us, p99 {np.percentile(lat, 99):.0f} us, max {lat.max():.0f} us"
    )


if __name__ == "__main__":
    main()
