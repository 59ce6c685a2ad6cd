"""NTU-like data sets: ``.skeleton`` files written with the project's own NTU writer.

For throughput benchmarks and tests of batch runs, when the real NTU RGB+D files are not
at hand: each file holds one or two bodies (the built-in motions, a second body a metre
to the side) of the same number of frames, corrupted by the Kinect-like model of
:mod:`tobitkf.evaluation.corruption` (jitter, spikes, sustained failures, inferred drift;
no dropped frames, since an NTU file has no time stamps).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["NtuLikeFile", "ntu_like_file", "write_ntu_like"]

_MOTIONS = ("walk", "arms", "squat", "mixed")


@dataclass(frozen=True)
class NtuLikeFile:
    """One written file and what it holds."""

    path: Path
    frames: int
    bodies: int


def ntu_like_file(
    path: str | os.PathLike[str],
    seed: int,
    frames: tuple[int, int] = (60, 300),
    bodies: tuple[int, int] = (1, 2),
) -> NtuLikeFile:
    """Write one NTU-like file at ``path``: frames and bodies drawn uniformly from the
    inclusive ranges, motion and corruption from ``seed``."""
    from tobitkf.evaluation.corruption import CorruptionModel, corrupt
    from tobitkf.evaluation.synthetic import generate_motion
    from tobitkf.io import save

    rng = np.random.default_rng(seed)
    T = int(rng.integers(frames[0], frames[1] + 1))
    B = int(rng.integers(bodies[0], bodies[1] + 1))
    model = CorruptionModel(drop_rate=0.0)
    seqs = []
    for b in range(B):
        kind = _MOTIONS[int(rng.integers(len(_MOTIONS)))]
        clean = generate_motion(kind, duration=T / 30.0, seed=seed * 7 + b)
        clean = clean.replace(positions=clean.positions + np.array([1.0 * b, 0.0, 0.0]))
        seqs.append(corrupt(clean, model, seed=seed * 7 + b).sequence)
    save(seqs, path, format="ntu")
    return NtuLikeFile(Path(path), T, B)


def write_ntu_like(
    folder: str | os.PathLike[str],
    n: int,
    *,
    seed: int = 0,
    frames: tuple[int, int] = (60, 300),
    bodies: tuple[int, int] = (1, 2),
    per_folder: int = 1000,
    start: int = 0,
) -> list[NtuLikeFile]:
    """Write ``n`` NTU-like files into ``folder`` (``S###/`` subfolders of ``per_folder``
    files, names in the NTU style ``S001C001P001R001A001.skeleton``); file ``i`` uses
    seed ``seed + i``. ``start``: the index of the first file (a large set can be written
    in parts, in parallel)."""
    out = []
    for i in range(start, start + n):
        sub = Path(folder) / f"S{i // per_folder + 1:03d}"
        sub.mkdir(parents=True, exist_ok=True)
        name = f"S{i // per_folder + 1:03d}C001P{i % 40 + 1:03d}R001A{i % per_folder + 1:03d}"
        out.append(ntu_like_file(sub / f"{name}.skeleton", seed + i, frames, bodies))
    return out
