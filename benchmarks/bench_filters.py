"""Throughput of the batch filters against filterpy, pykalman and a compiled KF (by hand).

    .venv/bin/python benchmarks/bench_filters.py            # full: T=3000, 200 x 25 joints
    .venv/bin/python benchmarks/bench_filters.py --small    # quick run

A synthetic skeleton batch (random-walk joints plus Kinect-like noise and occasional
jumps), model A = H = I, Q = 0.0025 I, R = 0.01 I, 3-D per joint. Prints joint-frames per
second for tobitkf's KF and ATKF (whole batch, vectorised), for filterpy's
``KalmanFilter`` predict/update loop and pykalman's ``KalmanFilter.filter`` (one 3-D filter
per joint, on a subset of joints), and for a minimal compiled per-axis KF (numba, the
whole batch: the ceiling of a diagonal random-walk filter on this machine), measured in
the same run, and the ratios. filterpy and pykalman are benchmark-only extras
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


def bench_pykalman(ys: np.ndarray, q: float, r: float) -> float:
    """Seconds pykalman needs to filter ys (T, J, 3), one ``KalmanFilter.filter`` per joint."""
    from pykalman import KalmanFilter

    eye = np.eye(3)
    t0 = time.perf_counter()
    for j in range(ys.shape[1]):
        kf = KalmanFilter(
            transition_matrices=eye,
            observation_matrices=eye,
            transition_covariance=q * eye,
            observation_covariance=r * eye,
            initial_state_mean=ys[0, j],
            initial_state_covariance=r * eye,
        )
        kf.filter(ys[:, j])
    return time.perf_counter() - t0


def numba_kf():
    """A minimal compiled KF, A = H = I, scalar Q and R, every axis of every joint a scalar
    filter (no missing data, no likelihood): ``f(ys (T, N, 3), q, r) -> means``."""
    from numba import njit

    @njit(cache=True)
    def run(ys, q, r):
        T, N, D = ys.shape
        out = np.empty_like(ys)
        x = ys[0].copy()
        v = np.full((N, D), r)
        for t in range(T):
            for n in range(N):
                for d in range(D):
                    vp = v[n, d] + q
                    k = vp / (vp + r)
                    x[n, d] += k * (ys[t, n, d] - x[n, d])
                    v[n, d] = vp - k * vp
                    out[t, n, d] = x[n, d]
        return out

    return run


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
    flat = np.ascontiguousarray(ys.reshape(T, -1, 3))
    compiled = numba_kf()
    compiled(flat[:2], q, r)  # compiled (or loaded from the cache) outside the timing
    t_nb = best_of(lambda: compiled(flat, q, r), args.repeats)
    rate_kf = jf / t_kf
    rate_atkf = jf / t_atkf
    rate_nb = jf / t_nb
    print(f"tobitkf KF    : {t_kf:8.3f} s  {rate_kf:12.4g} joint-frames/s")
    print(f"tobitkf ATKF  : {t_atkf:8.3f} s  {rate_atkf:12.4g} joint-frames/s")
    print(f"numba KF      : {t_nb:8.3f} s  {rate_nb:12.4g} joint-frames/s (compiled ceiling)")
    rows = [
        ("tobitkf KF (`kalman_filter`)", rate_kf),
        ("tobitkf ATKF (`adaptive_tobit_filter`)", rate_atkf),
        ("minimal compiled per-axis KF (numba), the ceiling", rate_nb),
    ]
    sub = ys[:, 0, :fp_joints]
    rate_fp = None
    for name, bench in (("filterpy `KalmanFilter`", bench_filterpy),
                        ("pykalman `KalmanFilter.filter`", bench_pykalman)):  # fmt: skip
        try:  # best of the same number of runs as ours (the machine may be shared)
            sec = min(bench(sub, q, r) for _ in range(args.repeats))
        except ImportError:
            print(f"{name} not installed: no comparison (pip install tobitkf[bench])")
            continue
        rate = T * fp_joints / sec
        print(f"{name:30s}: {sec:8.3f} s  {rate:12.4g} joint-frames/s ({fp_joints} joints)")
        rows.append((f"{name}, one 3-D filter per joint", rate))
        rate_fp = rate if rate_fp is None else rate_fp
    print(f"ratio KF / compiled ceiling: {rate_kf / rate_nb:8.2f}")
    if rate_fp is None:
        return
    print(f"ratio KF   / filterpy: {rate_kf / rate_fp:8.0f}x   (target >= 500x)")
    print(f"ratio ATKF / filterpy: {rate_atkf / rate_fp:8.0f}x   (target >= 50x)")
    if args.markdown:
        print_markdown(T, recs, joints, rows, rate_fp)


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
    print("| | joint-frames / s | vs filterpy | vs the compiled ceiling |")
    print("|---|---|---|---|")
    ceiling = rows[2][1]
    for name, rate in rows:
        vs = rate / reference
        vs_txt = f"{vs:,.0f}" if vs >= 10 else f"{vs:.2g}"
        print(f"| {name} | {rate:.2g} | {vs_txt}× | {rate / ceiling:.2g} |")


if __name__ == "__main__":
    main()
