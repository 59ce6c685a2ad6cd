"""Describe a recording: what the reader found, rates, tracking states, largest jumps."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np


def largest_jumps(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Largest frame-to-frame displacement of each joint, and the frame where it ends.

    Parameters
    ----------
    positions : (T, J, 3)

    Returns
    -------
    jump : (J,) metres (NaN where a joint never has two consecutive valid frames)
    frame : (J,) index of the later frame of the largest jump (-1 if none)
    """
    p = np.asarray(positions, dtype=float)
    if p.shape[0] < 2:
        j = p.shape[1]
        return np.full(j, np.nan), np.full(j, -1)
    step = np.linalg.norm(np.diff(p, axis=0), axis=-1)  # (T-1, J)
    valid = np.isfinite(step)
    filled = np.where(valid, step, -np.inf)
    arg = np.argmax(filled, axis=0)
    jump = filled[arg, np.arange(p.shape[1])]
    has = valid.any(axis=0)
    return np.where(has, jump, np.nan), np.where(has, arg + 1, -1)


def describe_sequence(seq) -> dict[str, Any]:
    """Summary of one :class:`~tobitkf.skeleton.sequence.SkeletonSequence` as plain data."""
    pos = np.asarray(seq.positions, dtype=float)
    missing = ~np.isfinite(pos).all(axis=-1)
    jump, frame = seq.largest_jumps()
    times = np.asarray(seq.times(), dtype=float) if seq.n_frames else np.zeros(0)
    out: dict[str, Any] = {
        "body_id": seq.body_id,
        "topology": seq.topology.name,
        "frames": int(seq.n_frames),
        "joints": int(seq.n_joints),
        "fps": None if seq.fps is None else float(seq.fps),
        "duration_s": float(times[-1] - times[0]) if times.size > 1 else 0.0,
        "missing_percent": 100.0 * float(missing.mean()) if missing.size else 0.0,
        "has_timestamps": seq.timestamps is not None,
    }
    if seq.timestamps is not None and seq.n_frames > 1:
        dt = np.diff(np.asarray(seq.timestamps, dtype=float))
        out["dt_range"] = [float(dt.min()), float(np.median(dt)), float(dt.max())]
    if seq.tracking_state is not None:
        from tobitkf.skeleton.sequence import TrackingState

        states = np.asarray(seq.tracking_state)
        out["tracking_states"] = {
            s.name.lower(): int((states == int(s)).sum()) for s in TrackingState
        }
    order = np.argsort(-np.nan_to_num(jump, nan=-1.0))
    out["jumps"] = [
        {
            "joint": seq.joint_names[j],
            "largest_jump_m": None if not np.isfinite(jump[j]) else float(jump[j]),
            "frame": int(frame[j]),
            "missing": int(missing[:, j].sum()),
        }
        for j in order
    ]
    return out


def describe(path: str | Path, format: str = "auto") -> dict[str, Any]:
    """Read ``path`` and describe every body in it (the data behind ``tobitkf info``)."""
    from tobitkf.io import detect_format, load

    fmt = detect_format(path) if format == "auto" else format
    sequences = load(path, format=fmt)
    return {
        "path": str(path),
        "format": fmt,
        "bodies": len(sequences),
        "sequences": [describe_sequence(s) for s in sequences],
    }
