"""Which methods make a step their input never made (issue 10, point 4; docs/robust.md).

For every recording under the data folder (every file ``tobitkf.load`` reads, every body
of at least three frames), each method's output is compared with its input, joint by
joint: a *new jump* is an output step between two frames where the input is present at
both (finite and not NOT_TRACKED) that is larger than the largest step the input made
between two such frames, by more than a millimetre (rounding). The table counts, per
method, the recordings with one, the new jumps, and the largest excess over the input's
largest step; with ``step_guard=True`` (the guard every method may have, which the
robust methods always run) next to it.

    python tools/new_jumps.py DATA_DIR [--methods kf,atkf,...]
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np

import tobitkf as tk
from tobitkf.evaluation.scores import resolve_method

TOLERANCE = 1e-3  # m
METHODS = ("kf", "kf+rts", "atkf", "atkf2016", "tkfc", "sgf", "one_euro", "kinect",
           "robust", "robust_online")  # fmt: skip


def recordings(folder: Path) -> list[tuple[str, tk.SkeletonSequence]]:
    """Every body of at least three frames in the files under ``folder`` that tobitkf
    reads (the others, and documentation, are passed over)."""
    out = []
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        if path.suffix.lower() in (".md", ".json"):  # the folder's notes, sidecars
            continue
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                seqs = tk.load(path)
        except (ValueError, OSError, ImportError):
            continue
        out += [(path.name, s) for s in seqs if s.n_frames >= 3]
    return out


def new_jumps(seq: tk.SkeletonSequence, out: np.ndarray) -> np.ndarray:
    """Per new jump of ``out`` ``(T, J, D)`` against ``seq``: its excess (m) over the
    input's largest step of that joint (module docstring)."""
    present = np.all(np.isfinite(seq.positions), axis=-1)
    if seq.tracking_state is not None:
        present &= seq.tracking_state != tk.TrackingState.NOT_TRACKED
    pairs = present[1:] & present[:-1]  # (T-1, J): the input present at both frames
    step_in = np.linalg.norm(seq.positions[1:] - seq.positions[:-1], axis=-1)
    largest = np.max(np.where(pairs, step_in, -np.inf), axis=0)  # -inf: no step
    step_out = np.linalg.norm(out[1:] - out[:-1], axis=-1)
    excess = np.where(pairs, step_out - largest[None], -np.inf)
    return excess[excess > TOLERANCE]


def runner(spec: str, guard: bool):
    """``spec`` (``tobitkf evaluate``'s method names: ``kf+rts`` is ``kf`` offline) as a
    callable, with ``step_guard=guard`` (:func:`tobitkf.evaluation.scores.resolve_method`)."""
    return resolve_method((spec, spec, {"step_guard": guard}))[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("--methods", default=",".join(METHODS))
    args = ap.parse_args(argv)
    recs = recordings(args.folder)
    print(f"New jumps on {len(recs)} recordings (every body of every file read under the "
          "data folder; an output step larger than the input's largest by more than 1 mm, "
          "where the input is present at both frames):")  # fmt: skip
    print()
    print("| method | recordings with one | new jumps | largest excess, cm "
          "| with step_guard=True: recordings | new jumps |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for spec in (m.strip() for m in args.methods.split(",") if m.strip()):
        cells = []
        for guard in (False, True):
            smooth = runner(spec, guard)
            n_rec = n_jumps = 0
            worst = 0.0
            for _, seq in recs:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")  # the methods' notes on odd data
                    out = smooth(seq)
                ex = new_jumps(seq, out.positions)
                if ex.size:
                    n_rec += 1
                    n_jumps += ex.size
                    worst = max(worst, float(ex.max()))
            cells.append((n_rec, n_jumps, worst))
        (r0, j0, w0), (r1, j1, _) = cells
        print(f"| {spec} | {r0} | {j0} | {100 * w0:.1f} | {r1} | {j1} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
