"""First call of ``tk.smooth`` in a fresh process, with an empty and a filled numba cache.

    .venv/bin/python benchmarks/bench_startup.py                  # every registered method
    .venv/bin/python benchmarks/bench_startup.py -m robust -m atkf --repeats 3

For each method, ``repeats`` times: a new, empty ``NUMBA_CACHE_DIR``, then two fresh
processes that import tobitkf and time their first ``tk.smooth`` call (a 10 s synthetic
recording): the first compiles the method's kernels (cold), the second loads them from
the cache (warm). Printed: the best cold and warm wall times (the machine is shared), the
cold one also in CPU seconds (which other work on the machine inflates less).
``import tobitkf`` is not included. Then (every method only) the wall time of
``tobitkf.warmup(jobs=2)`` in an empty cache: what ``make install`` and ``tobitkf
warmup`` pay once.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

import tobitkf as tk

CHILD = """
import sys, time
import tobitkf as tk
seq = tk.generate_motion("mixed", duration=10, seed=0)
t0, c0 = time.perf_counter(), time.process_time()
tk.smooth(seq, method=sys.argv[1])
print(time.perf_counter() - t0, time.process_time() - c0)
"""


def first_call(method: str, cache: str) -> tuple[float, float]:
    """Wall and CPU seconds of the first ``tk.smooth`` call in a new process (after
    ``import tobitkf``)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=cache)
    res = subprocess.run([sys.executable, "-c", CHILD, method], check=True, env=env,
                         capture_output=True, text=True)  # fmt: skip
    wall, cpu = res.stdout.split()[-2:]
    return float(wall), float(cpu)


WARMUP = """
import time
import tobitkf as tk
t0 = time.perf_counter()
tk.warmup(jobs=2)
print(time.perf_counter() - t0)
"""


def warmup_seconds() -> float:
    """Wall seconds of ``tobitkf.warmup(jobs=2)`` (every method) in an empty cache."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        res = subprocess.run([sys.executable, "-c", WARMUP], check=True, env=env,
                             capture_output=True, text=True)  # fmt: skip
    return float(res.stdout.split()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-m", "--method", action="append", help="only these methods")
    ap.add_argument("--repeats", type=int, default=2, help="cold runs, each with a new cache")
    ap.add_argument("--markdown", action="store_true", help="end with the README's table")
    args = ap.parse_args()
    names = args.method or sorted(tk.methods())
    rows = []
    print(f"{'method':>14} {'cold (s)':>9} {'cold CPU':>9} {'warm (s)':>9}")
    for name in names:
        cold, warm = [], []
        for _ in range(args.repeats):
            with tempfile.TemporaryDirectory() as cache:
                cold.append(first_call(name, cache))
                warm.append(first_call(name, cache))
        c, w = min(cold), min(warm)  # best wall time (with its CPU time)
        rows.append((name, c, w))
        print(f"{name:>14} {c[0]:9.2f} {c[1]:9.2f} {w[0]:9.2f}")
    warm_all = None if args.method else warmup_seconds()
    if warm_all is not None:
        print(f"tobitkf warmup --jobs 2, every method, empty cache: {warm_all:.1f} s")
    if args.markdown:
        from bench_filters import machine  # benchmarks/ is on the path here

        print("\x1e")  # docs_results keeps what follows
        print(f"Measured {machine()}: the first `tk.smooth` call of a new process.")
        print()
        print("| method | empty numba cache: wall s (CPU s) | cache filled: wall s |")
        print("|---|---|---|")
        for name, c, w in rows:
            print(f"| {name} | {c[0]:.1f} ({c[1]:.1f}) | {w[0]:.2f} |")
        if warm_all is not None:
            print()
            print(
                f"`tobitkf warmup --jobs 2` (every method's kernels into an empty cache; "
                f"`make install` runs it): {warm_all:.0f} s."
            )


if __name__ == "__main__":
    main()
