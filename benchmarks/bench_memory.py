"""Peak memory of ``tk.smooth`` on a large batch, per method (run by hand).

    .venv/bin/python benchmarks/bench_memory.py                 # 200 x 3000 x 25, all methods
    .venv/bin/python benchmarks/bench_memory.py -m tkf -m tkfc --recordings 50

The batch (``bench_filters.synthetic_skeletons``: random walks + noise + jumps, 2 % of the
joint-frames missing, z moved 2.5 m in front of the sensor so the Kinect device limits
apply) is written once to a temporary ``.npy``. Each method then runs in a fresh process,
which loads the file (one array), makes the recordings and, after a first call on a short
slice (JIT compilation and imports out of the measurement), resets the kernel's record of
its peak resident size (``/proc/self/clear_refs``, Linux), smooths the whole batch in one
``tk.smooth`` call and reads the peak (``VmHWM``). Printed: the peak above the resident
size just before the call (input loaded), as a multiple of the input array's size.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from bench_filters import synthetic_skeletons  # benchmarks/ is on the path here

import tobitkf as tk

CHILD = r"""
import json, sys
import numpy as np
import tobitkf as tk

def status(key):
    with open("/proc/self/status") as f:
        return next(int(ln.split()[1]) for ln in f if ln.startswith(key + ":"))

path, method = sys.argv[1], sys.argv[2]
arr = np.load(path)
topo = tk.get_topology("kinect_v2")
seqs = [tk.SkeletonSequence(positions=arr[:, b], topology=topo, fps=30.0)
        for b in range(arr.shape[1])]
tk.smooth([s.replace(positions=s.positions[:50]) for s in seqs[:2]], method=method)
with open("/proc/self/clear_refs", "w") as f:  # reset the peak (VmHWM) to the current RSS
    f.write("5")
before = status("VmRSS")
out = tk.smooth(seqs, method=method)
peak = status("VmHWM")
print(json.dumps({"before_kib": before, "peak_kib": peak, "input_bytes": arr.nbytes}))
"""


def measure(path: Path, method: str) -> dict:
    res = subprocess.run(
        [sys.executable, "-c", CHILD, str(path), method], check=True, capture_output=True, text=True
    )
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-m", "--method", action="append", help="only these methods")
    ap.add_argument("--frames", type=int, default=3000)
    ap.add_argument("--recordings", type=int, default=200)
    ap.add_argument("--markdown", action="store_true", help="end with the README's table")
    args = ap.parse_args()
    names = args.method or sorted(tk.methods())
    ys = synthetic_skeletons(args.frames, args.recordings, 25)
    ys[..., 2] += 2.5
    rng = np.random.default_rng(1)
    ys[rng.uniform(size=ys.shape[:-1]) < 0.02] = np.nan
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "batch.npy"
        np.save(path, ys)
        mib = ys.nbytes / 2**20
        del ys
        print(f"{args.recordings} x {args.frames} x 25 batch: input {mib:.0f} MiB")
        print(f"{'method':>14} {'peak above input (MiB)':>24} {'x input':>8}")
        rows = []
        for name in names:
            r = measure(path, name)
            above = (r["peak_kib"] - r["before_kib"]) * 1024
            rows.append((name, above / r["input_bytes"]))
            print(f"{name:>14} {above / 2**20:24.0f} {above / r['input_bytes']:8.2f}")
    if args.markdown:
        from bench_filters import machine

        print("\x1e")  # docs_results keeps what follows
        print(f"{args.recordings} recordings × {args.frames} frames × 25 joints ({mib:.0f} MiB), "
              f"one `tk.smooth` call, measured {machine()}:")  # fmt: skip
        print()
        print("| method | peak memory above the input, × the input |")
        print("|---|---|")
        for name, ratio in rows:
            print(f"| {name} | {ratio:.2f} |")


if __name__ == "__main__":
    main()
