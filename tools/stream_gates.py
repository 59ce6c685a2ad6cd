"""How well gates measured on the stream itself do against gates from the whole recording
(docs/robust.md, ``gates="stream"``).

The built-in 2-D benchmark (``tobitkf benchmark --kind pose2d``: two people, a pose
estimator's jitter, glitches and swaps, in pixels) is smoothed by ``robust_online`` with
its gates from the whole recording (the batch default for pixels, which a live stream
cannot have), from the frames so far (``gates="stream"``, what a live stream does with
``gates_from="stream"``), and by the offline ``robust`` for reference. Printed: the RMSE
in pixels against the truth from frame ``STREAM_FIRST`` on (before it, the stream's
frames are returned as measured), mean ± sd over the seeds, as a Markdown table.

    python tools/stream_gates.py [--seeds 5]
"""

from __future__ import annotations

import argparse

import numpy as np

from tobitkf.evaluation.pose2d import run_pose2d_benchmark
from tobitkf.smoothing.robust_scale import STREAM_FIRST

STREAM = ("stream", "robust_online", {"gates": "stream"})
METHODS = (
    ("raw", "raw"),
    ("robust_online, gates from the whole recording", "robust_online"),
    ("robust_online, gates and untangling from the stream so far", STREAM),
    ("robust (offline)", "robust"),
)


def rmse_from(outputs: dict, label: str, start: int) -> float:
    true = np.stack([s.positions for s in outputs["truth"]], axis=1)[start:]
    est = np.stack([s.positions for s in outputs[label]], axis=1)[start:]
    err = np.linalg.norm(est - true, axis=-1)
    return float(np.sqrt(np.nanmean(err**2)))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args(argv)
    specs = [spec for _, spec in METHODS]
    labels = [spec if isinstance(spec, str) else spec[0] for spec in specs]
    scores = np.empty((args.seeds, len(METHODS)))
    for seed in range(args.seeds):
        outputs: dict = {}
        run_pose2d_benchmark(seed, specs, outputs=outputs)
        scores[seed] = [rmse_from(outputs, label, STREAM_FIRST) for label in labels]
    mean, sd = scores.mean(axis=0), scores.std(axis=0, ddof=1) if args.seeds > 1 else 0 * scores[0]
    print(f"RMSE against the truth from frame {STREAM_FIRST} on, pixels (built-in 2-D "
          f"benchmark, mean ± sd over seeds 0–{args.seeds - 1}):\n")  # fmt: skip
    print("| method | RMSE | vs raw |")
    print("|---|---|---|")
    for (name, _), m, s in zip(METHODS, mean, sd, strict=True):
        vs = "" if name == "raw" else f"{100 * (m / mean[0] - 1):+.0f} %"
        print(f"| {name} | {m:.2f} ± {s:.2f} | {vs} |")


if __name__ == "__main__":
    main()
