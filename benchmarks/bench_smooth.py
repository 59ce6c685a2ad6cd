"""Throughput of every registered smoothing method through ``tk.smooth`` (run by hand).

    .venv/bin/python benchmarks/bench_smooth.py                # all methods, both data sets
    .venv/bin/python benchmarks/bench_smooth.py -m robust -m robust_online --repeats 3
    .venv/bin/python benchmarks/bench_smooth.py --live-only      # the live latency alone

Data: (a) 12 synthetic Kinect V2 recordings x 1500 frames x 25 joints (the built-in
motions with the Kinect-like corruption: jitter, spikes, sustained failures, inferred
drift), smoothed in one ``tk.smooth`` call (a list of sequences: the bodies go to the
method together); (b) the three KIMORE recordings in ../shared/data/kimore (when present),
one call each; (c) for the default offline and causal methods only, 200 recordings x
3000 frames x 25 joints in one call (``--big``). For each method it prints joint-frames
per second and the ratio to the
package's Kalman core, ``tk.kalman_filter`` (3-D random walk per joint, A = H = I, on the
same positions, all joints of all recordings as one batch), measured in the same run.
The first call of each method is not timed (it loads, or compiles, the robust kernels).
Live: the per-frame latency of the live default (``robust_online``) and of ``atkf``
through ``LiveSmoother`` for one body (without and with the Kinect's tracking states), six
bodies in one array, and one and six bodies keyed by id (the keyed stream's own one-body
cost beside the array's), next to a minimal numpy per-frame Kalman update of one body.
Files: ``tobitkf smooth`` (default method) over a folder of small recordings, start-up
included, with 1 and 2 processes, and over the KIMORE folder (best of 3 runs).
``--markdown`` ends with the README's table (``make bench``).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from unittest import mock

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


#: methods that run their chunks of bodies in threads (tobitkf.smoothing.chunks): also
#: timed in one thread, beside the core (which runs in one)
THREADED = ("robust", "robust_online")


def _variants(name: str) -> list[tuple[str, contextlib.AbstractContextManager]]:
    """(row name, context) of each timing of ``name``: threaded methods twice, the
    second time with TOBITKF_THREADS=1."""
    if name not in THREADED:
        return [(name, contextlib.nullcontext())]
    one = mock.patch.dict(os.environ, {"TOBITKF_THREADS": "1"})
    return [(name, contextlib.nullcontext()), (f"{name}, 1 thread", one)]


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
    ap.add_argument("--files", type=int, default=1000, help="small recordings for files/s")
    ap.add_argument("--markdown", action="store_true", help="end with the README's tables")
    ap.add_argument("--live-only", action="store_true", help="only the live latency")
    ap.add_argument(
        "--big", type=int, default=200,
        help="recordings of the large batch (x 3000 frames) for the default pair (0: none)",
    )  # fmt: skip
    args = ap.parse_args()
    if args.live_only:
        show_live(live_latency(args.live_frames), args.live_frames, LIVE_ROUNDS)
        return
    # the live latency is taken a round at a time at points spread over the run (the
    # start, after each data set, after the large batch): a quiet spell of the shared
    # machine then shows in some round, whatever the length of a noisy one
    live_rounds = [live_latency(args.live_frames, rounds=1)]
    table: list[tuple[str, str, float, float]] = []
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
            for row, context in _variants(name):
                with context:
                    sec = best_of(run, args.repeats)
                base = max(base, core_rate(batches, args.repeats))
                rows.append((row, sec, jf / sec))
        print(f"\n{label}: {jf} joint-frames; tk.kalman_filter core {base:,.0f} joint-frames/s")
        print(f"{'method':>14} {'seconds':>9} {'joint-frames/s':>15} {'/ core':>8}")
        for name, sec, rate in rows:
            print(f"{name:>14} {sec:9.3f} {rate:15,.0f} {rate / base:8.3f}")
            table.append((label, name, rate, rate / base))
        live_rounds.append(live_latency(args.live_frames, rounds=1))
    if args.big > 0:
        table += big_batch(args.big, args.repeats, names)
        live_rounds.append(live_latency(args.live_frames, rounds=1))
    live = best_rounds(live_rounds)
    show_live(live, args.live_frames, len(live_rounds))
    files = files_per_second(args.files) if args.files > 0 else {}
    kimore = kimore_command()
    if args.markdown:
        print_markdown(table, live, files, args.files, kimore, len(live_rounds))


def big_batch(n: int, repeats: int, names: list[str]) -> list[tuple[str, str, float, float]]:
    """The default offline and causal methods on ``n`` recordings x 3000 frames x 25
    joints in one ``tk.smooth`` call (the 12 synthetic recordings repeated), against the
    core on the same positions as one (3000, n x 25, 3) batch. Both are the best of
    ``repeats`` runs (the first call in a process also pays the system for its fresh
    gigabytes of pages); the core's best rate of the runs before and after each is the
    reference."""
    from tobitkf.smoothing.api import DEFAULT_LIVE_METHOD, DEFAULT_METHOD

    base = synthetic_recordings(12, 3000)
    seqs = [base[i % 12] for i in range(n)]
    batch = np.concatenate([s.positions for s in seqs], axis=1)
    jf = batch.shape[0] * batch.shape[1]
    label = f"{n} x 3000 x 25 synthetic"
    rows = []
    core = core_rate([batch], repeats)
    for name in (m for m in (DEFAULT_METHOD, DEFAULT_LIVE_METHOD) if m in names):
        tk.smooth(seqs[:2], method=name)  # kernels loaded
        for row, context in _variants(name):
            with context:
                sec = best_of(lambda name=name: tk.smooth(seqs, method=name), repeats)
            core = max(core, core_rate([batch], repeats))
            rate = jf / sec
            rows.append((label, row, rate, rate / core))
            print(f"{label}: {row} {rate:,.0f} joint-frames/s, {rate / core:.3f} of the core")
    return rows


def _latencies(live: tk.LiveSmoother, frames: list, states: list | None) -> np.ndarray:
    lat = np.empty(len(frames))
    for k, frame in enumerate(frames):
        t0 = time.perf_counter()
        live.update(frame, None if states is None else states[k])
        lat[k] = time.perf_counter() - t0
    return lat[1:] * 1e6  # microseconds; the first frame allocates the state


def minimal_kf_latency(n: int) -> np.ndarray:
    """A minimal numpy per-frame Kalman update of one 25-joint body (random walk per axis)."""
    rng = np.random.default_rng(0)
    ys = rng.normal(size=(n, 25, 3))
    x, P, q, r = ys[0].copy(), np.full((25, 3), 0.01), 0.0025, 0.01
    lat = np.empty(n)
    for k in range(n):
        t0 = time.perf_counter()
        P = P + q
        K = P / (P + r)
        x = x + K * (ys[k] - x)
        P = (1 - K) * P
        lat[k] = time.perf_counter() - t0
    return lat[1:] * 1e6


#: rounds of the live latency (each configuration streamed this many times, in turns)
LIVE_ROUNDS = 3


def live_latency(
    n: int, methods: tuple[str, ...] = ("robust_online", "atkf"), rounds: int = LIVE_ROUNDS
) -> dict:
    """Per-frame latency (us) of live methods (the live default first): one body (also with
    tracking states), six in an array, one and six keyed by id. Each is streamed
    ``rounds`` times, the rounds of all of them taking turns, and the round with the
    lowest median is kept: a burst of the shared machine's noise then spoils one round,
    not one configuration."""
    if n < 2:
        return {}
    seqs = synthetic_recordings(6, n)
    topo = seqs[0].topology
    one = seqs[0].positions
    six = np.stack([s.positions for s in seqs], axis=1)  # (n, 6, J, 3)
    keyed = [{b: six[k, b] for b in range(6)} for k in range(n)]
    one_keyed = [{0: frame} for frame in one]
    runs: dict[str, list] = {"minimal numpy KF update, 1 body": []}
    for _ in range(rounds):
        runs["minimal numpy KF update, 1 body"].append(minimal_kf_latency(n))
        for method in methods:
            for label, frames, states in (
                ("1 body", list(one), None),
                ("1 body with tracking states", list(one), list(seqs[0].tracking_state)),
                ("6 bodies in one array", list(six), None),
                ("1 body keyed by id", one_keyed, None),
                ("6 bodies keyed by id", keyed, None),
            ):
                live = tk.LiveSmoother(topo, method, fps=30.0)
                lat = _latencies(live, frames, states)
                runs.setdefault(f"LiveSmoother ({method}), {label}", []).append(lat)
    return best_rounds([{name: lat} for name, lats in runs.items() for lat in lats])


def best_rounds(rounds: list[dict]) -> dict:
    """Per configuration, the round with the lowest median latency (in the order the
    configurations first appear)."""
    out: dict = {}
    for r in rounds:
        for name, lat in r.items():
            if name not in out or np.median(lat) < np.median(out[name]):
                out[name] = lat
    return out


def show_live(live: dict, n: int, rounds: int) -> None:
    """Print the live latencies of :func:`live_latency` (``n`` frames streamed)."""
    if not live:
        return
    print(f"\nlive, 25 joints, {n} frames, best of {rounds} rounds (us per frame):")
    for name, lat in live.items():
        print(f"  {name:55s} median {np.median(lat):7.1f}  p99 {np.percentile(lat, 99):7.1f}")


def kimore_command(repeats: int = 3) -> float | None:
    """Wall seconds of ``tobitkf smooth`` (default method) on the KIMORE folder, a new
    process each time, start-up included, into a new output folder: the best of
    ``repeats`` (None without the data)."""
    if not (KIMORE.is_dir() and any(KIMORE.glob("*.csv"))):
        return None
    best = float("inf")
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(repeats):
            cmd = [sys.executable, "-m", "tobitkf", "smooth", str(KIMORE), "-o",
                   str(Path(tmp) / f"out{i}")]  # fmt: skip
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True)
            best = min(best, time.perf_counter() - t0)
    print(f"tobitkf smooth on the KIMORE folder: {best:.2f} s (best of {repeats})")
    return best


def files_per_second(n: int) -> dict[int, float]:
    """``tobitkf smooth`` (default method) over ``n`` small recordings: files/s by --jobs."""
    topo = tk.get_topology("kinect_v2")
    rng = np.random.default_rng(0)
    out: dict[int, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "in"
        src.mkdir()
        for i in range(n):
            T = int(rng.integers(60, 300))
            pos = rng.normal(scale=0.01, size=(T, topo.n_joints, 3)).cumsum(0)
            pos[..., 2] += 2.5
            seq = tk.SkeletonSequence(positions=pos, topology=topo, fps=30.0)
            tk.save([seq], src / f"r{i:05d}.skeleton", format="ntu")
        for jobs in (1, 2):
            dst = Path(tmp) / f"out{jobs}"
            cmd = [sys.executable, "-m", "tobitkf", "smooth", str(src), "-o", str(dst),
                   "-j", str(jobs), "--json"]  # fmt: skip
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True)
            out[jobs] = n / (time.perf_counter() - t0)
            print(f"tobitkf smooth, {n} NTU files, -j {jobs}: {out[jobs]:.1f} files/s")
    return out


def print_markdown(
    table: list, live: dict, files: dict, n_files: int, kimore: float | None = None,
    live_rounds: int = LIVE_ROUNDS,
) -> None:  # fmt: skip
    from bench_filters import machine

    print("\x1e")  # docs_results keeps what follows
    print(f"Measured {machine()}.")
    print()
    from tobitkf.smoothing.chunks import threads

    n = threads()
    print(
        f"{' and '.join(THREADED)} run their chunks of bodies in {n} thread"
        f"{'s' if n > 1 else ''} (the CPUs here; `TOBITKF_THREADS` sets it), the core and "
        "the other methods in one; the rows `, 1 thread` time them with "
        "`TOBITKF_THREADS=1`. A single recording of one body is one chunk."
    )
    print()
    print("| data | method | joint-frames / s | / `kalman_filter` core |")
    print("|---|---|---|---|")
    for label, name, rate, ratio in table:
        print(f"| {label} | {name} | {rate:.2g} | {ratio:.2f} |")
    if live:
        print()
        print(
            f"Live: each configuration streamed {live_rounds} times, at points spread over the "
            "run (its start, after each data set, after the large batch), the configurations "
            "taking turns; the round with the lowest median is shown."
        )
        print()
        print("| live, 25 joints | median µs / frame | p99 µs / frame |")
        print("|---|---|---|")
        for name, lat in live.items():
            print(f"| {name} | {np.median(lat):.0f} | {np.percentile(lat, 99):.0f} |")
        ratios, states = [], []
        methods = dict.fromkeys(n.split("(")[1].split(")")[0] for n in live if "(" in n)
        for method in methods:
            one, arr, one_keyed, keyed, with_states = (
                float(np.median(live[f"LiveSmoother ({method}), {label}"]))
                for label in ("1 body", "6 bodies in one array", "1 body keyed by id",
                              "6 bodies keyed by id", "1 body with tracking states")
            )  # fmt: skip
            ratios.append(f"{method} {arr / one:.1f}× in one array, {keyed / one:.1f}× keyed by "
                          f"id ({keyed / one_keyed:.1f}× one body keyed by id)")  # fmt: skip
            states.append(f"{method} {with_states / one:.1f}×")
        print()
        print("Median per frame, six bodies / one body: " + "; ".join(ratios) + ". One body "
              "with tracking states / without: " + "; ".join(states) + ".")  # fmt: skip
    if files:
        print()
        rates = ", ".join(f"{v:.0f} files/s with -j {k}" for k, v in files.items())
        print(
            f"`tobitkf smooth` (default method) over {n_files} NTU files of 60–300 frames, "
            f"start-up included: {rates}."
        )
    if kimore is not None:
        print()
        print(
            "`tobitkf smooth ../shared/data/kimore -o OUT` (default method, three recordings, "
            f"a new process, start-up included): {kimore:.2f} s, the best of 3."
        )


if __name__ == "__main__":
    main()
