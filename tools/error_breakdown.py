"""Where a robust smoother's remaining error sits, against ground truth (docs/robust.md).

For each recording (Kinect track + simultaneous mocap, paired as ``tobitkf evaluate``
does) the samples are split by what the raw measurement was (a *glitch*: more than
``--threshold`` from the truth, else *good*) and by what the method did with it
(*accepted* or *rejected* by its gates); the table gives each class's share of the
method's squared error and its RMSE before and after. A last column counts samples that
look like a left/right swap (the raw joint is closer to the truth of its mirror joint
than to its own by more than the threshold).

    python tools/error_breakdown.py TRACK... --truth-replace OLD NEW [--method robust]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

import tobitkf as tk
from tobitkf.evaluation.evaluate import evaluate_paths

CLASSES = (
    ("glitch, accepted", False, True),
    ("glitch, rejected", True, True),
    ("good, accepted", False, False),
    ("good, rejected", True, False),
)


def breakdown(track: str, truth: str, method: str, threshold: float) -> dict:
    outputs: dict = {}
    gt, _ = evaluate_paths(track, truth, [method], outputs=outputs)
    seq = tk.load(track)[0]
    est = outputs[method]
    t = gt.positions
    e_raw = np.linalg.norm(seq.positions - t, axis=-1)
    e_est = np.linalg.norm(est.positions - t, axis=-1)
    ok = np.isfinite(e_raw) & np.isfinite(e_est)
    rejected = np.asarray(est.metadata["diagnostics"].get("rejected", np.zeros_like(ok)))
    glitch = e_raw > threshold
    rows = {}
    for name, rej, gl in CLASSES:
        m = ok & (rejected == rej) & (glitch == gl)
        rows[name] = (int(m.sum()), float((e_raw[m] ** 2).sum()), float((e_est[m] ** 2).sum()))
    swaps = 0
    for a, b in seq.topology.symmetry:
        for j, k in ((a, b), (b, a)):
            mirror = np.linalg.norm(seq.positions[:, j] - t[:, k], axis=-1)
            swaps += int(np.sum(ok[:, j] & (mirror + threshold < e_raw[:, j])))
    return {"rows": rows, "swaps": swaps, "n": int(ok.sum())}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tracks", nargs="+")
    ap.add_argument("--method", default=tk.DEFAULT_METHOD)
    ap.add_argument("--threshold", type=float, default=0.10, help="glitch threshold, m")
    ap.epilog = "--truth-replace OLD NEW (required): truth = track path with OLD replaced by NEW"
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--truth-replace" not in argv or len(argv) < argv.index("--truth-replace") + 3:
        ap.error("--truth-replace OLD NEW is required")
    i = argv.index("--truth-replace")  # OLD / NEW may look like options ("-Kinect-")
    old, new = argv[i + 1], argv[i + 2]
    args = ap.parse_args(argv[:i] + argv[i + 3 :])
    print(f"| recording | class | samples | raw RMSE cm | {args.method} RMSE cm "
          f"| share of {args.method}'s squared error | swap-like samples |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    total = {name: [0, 0.0, 0.0] for name, _, _ in CLASSES}
    all_sse = 0.0
    for track in args.tracks:
        res = breakdown(track, track.replace(old, new), args.method, args.threshold)
        sse = sum(r[2] for r in res["rows"].values())
        all_sse += sse
        label = track.rsplit("/", 1)[-1]
        for i, (name, (n, raw, est)) in enumerate(res["rows"].items()):
            for k, v in enumerate((n, raw, est)):
                total[name][k] += v
            swaps = str(res["swaps"]) if i == 0 else ""
            print(f"| {label if i == 0 else ''} | {name} | {n} | {_rms(raw, n)} | "
                  f"{_rms(est, n)} | {est / sse:.0%} | {swaps} |")  # fmt: skip
    for name, (n, raw, est) in total.items():
        print(f"| all | {name} | {n} | {_rms(raw, n)} | {_rms(est, n)} | {est / all_sse:.0%} | |")
    print()
    print(f"Glitch: raw sample more than {100 * args.threshold:.0f} cm from the truth; "
          "accepted / rejected: by the method's gates.")  # fmt: skip
    return 0


def _rms(sse: float, n: int) -> str:
    return f"{100 * np.sqrt(sse / n):.1f}" if n else "–"


if __name__ == "__main__":
    sys.exit(main())
