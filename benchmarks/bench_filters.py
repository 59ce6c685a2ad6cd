"""Throughput of the batch filters against filterpy (run by hand, not a test).

    .venv/bin/python benchmarks/bench_filters.py            # full: T=3000, 200 x 25 joints
    .venv/bin/python benchmarks/bench_filters.py --small    # quick run

A synthetic skeleton batch (random-walk joints plus Kinect-like noise and occasional
jumps), model A = H = I, Q = 0.0025 I, R = 0.01 I, 3-D per joint. Prints joint-frames per
second for tobitkf's KF and ATKF (whole batch, vectorised) and for filterpy's
``KalmanFilter`` predict/update loop (one 3-D filter per joint, on a subset of joints),
measured in the same run, and the ratios. filterpy is a benchmark-only extra
(``pip install tobitkf[bench]``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import tobitkf as tk


def synthetic_skeletons(T: int, recordings: int, joints: int, seed: int = 0) -> np.ndarray:
    """(T, recordings, joints, 3) positions in metres: random walks + noise + jumps."""
    rng = np.random.default_rng(seed)
    shape = (T, recordings, joints, 3)
    steps = rng.normal(scale=0.01, size=shape)
    steps[0] = rng.uniform(-1.0, 1.0, size=shape[1:])
    truth = np.cumsum(steps, axis=0)
    ys = truth + rng.normal(scale=0.02, size=shape)
    jumps = rng.uniform(size=shape[:-1]) < 0.01  # 1 % of joint-frames jump up to 1 m
    ys[jumps] += rng.uniform(-1.0, 1.0, size=(int(jumps.sum()), 3))
    return ys


def bench_filterpy(ys: np.ndarray, q: float, r: float) -> float:
    """Seconds filterpy needs to filter ys (T, J, 3), one KalmanFilter per joint."""
    from filterpy.kalman import KalmanFilter

    T, J, _ = ys.shape
    filters = []
    for j in range(J):
        kf = KalmanFilter(dim_x=3, dim_z=3)
        kf.F = np.eye(3)
        kf.H = np.eye(3)
        kf.Q = q * np.eye(3)
        kf.R = r * np.eye(3)
        kf.x = ys[0, j].copy()
        kf.P = r * np.eye(3)
        filters.append(kf)
    t0 = time.perf_counter()
    for j, kf in enumerate(filters):
        col = ys[:, j]
        for t in range(T):
            kf.predict()
            kf.update(col[t])
    return time.perf_counter() - t0


def best_of(fn, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--small", action="store_true", help="quick run (T=1000, 20 x 25 joints)")
    ap.add_argument("--repeats", type=int, default=2, help="best of N timings (default 2)")
    ap.add_argument("--markdown", action="store_true", help="print a Markdown table (README)")
    args = ap.parse_args()
    if args.small:
        T, recs, joints, fp_joints = 1000, 20, 25, 5
    else:
        T, recs, joints, fp_joints = 3000, 200, 25, 20
    q, r = 0.0025, 0.01
    c = np.array([0.34, 0.18, 0.34])
    ys = synthetic_skeletons(T, recs, joints)
    model = tk.skeleton_model(q=q, r=r, x0=ys[0])
    jf = T * recs * joints
    print(f"batch: T={T} frames x {recs} recordings x {joints} joints (3-D), {jf:.3g} joint-frames")

    t_kf = best_of(lambda: tk.kalman_filter(model, ys), args.repeats)
    t_atkf = best_of(lambda: tk.adaptive_tobit_filter(model, ys, c=c), args.repeats)
    try:  # best of the same number of runs as ours (the machine may be shared)
        t_fp = min(bench_filterpy(ys[:, 0, :fp_joints], q, r) for _ in range(args.repeats))
    except ImportError:
        t_fp = None
    rate_kf = jf / t_kf
    rate_atkf = jf / t_atkf
    print(f"tobitkf KF    : {t_kf:8.3f} s  {rate_kf:12.4g} joint-frames/s")
    print(f"tobitkf ATKF  : {t_atkf:8.3f} s  {rate_atkf:12.4g} joint-frames/s")
    if t_fp is None:
        print("filterpy not installed: no comparison (pip install tobitkf[bench])")
        return
    rate_fp = T * fp_joints / t_fp
    print(
        f"filterpy KF   : {t_fp:8.3f} s  {rate_fp:12.4g} joint-frames/s "
        f"({fp_joints} joints x {T} frames, predict+update loop)"
    )
    print(f"ratio KF   / filterpy: {rate_kf / rate_fp:8.0f}x   (target >= 500x)")
    print(f"ratio ATKF / filterpy: {rate_atkf / rate_fp:8.0f}x   (target >= 50x)")
    if args.markdown:
        print_markdown(
            T,
            recs,
            joints,
            [
                ("tobitkf KF (`kalman_filter`)", rate_kf),
                ("tobitkf ATKF (`adaptive_tobit_filter`)", rate_atkf),
                ("filterpy `KalmanFilter`, one 3-D filter per joint", rate_fp),
            ],
            rate_fp,
        )


def machine() -> str:
    """What the numbers were measured on: date, cores, processor, Python, numpy."""
    import datetime
    import os
    import platform

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            names = [ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")]
        cpu = names[0] if names else cpu
    except OSError:
        pass
    return (
        f"{datetime.date.today().isoformat()}, {os.cpu_count()} cores ({cpu}), "
        f"Python {platform.python_version()}, numpy {np.__version__}"
    )


def print_markdown(T, recs, joints, rows, reference) -> None:
    """The README's speed table (the text above is kept for the log)."""
    print("\x1e")  # separator: docs_results keeps what follows the last one
    print(f"{T} frames × {recs} recordings × {joints} joints (3-D), measured {machine()}:")
    print()
    print("| | joint-frames / s | vs filterpy |")
    print("|---|---|---|")
    for name, rate in rows:
        print(f"| {name} | {rate:.2g} | {rate / reference:.0f}× |")


if __name__ == "__main__":
    main()
