"""Describe a skeleton sequence as plain data: rates, tracking states, largest jumps.

No file access (``tobitkf info`` reads the file in :mod:`tobitkf.app.info`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from tobitkf.skeleton.sequence import SkeletonSequence, TrackingState


def describe_sequence(seq: SkeletonSequence) -> dict[str, Any]:
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
        # without a rate or timestamps the frames have no times (None: unknown)
        "duration_s": (
            None
            if seq.fps is None and seq.timestamps is None
            else float(times[-1] - times[0])
            if times.size > 1
            else 0.0
        ),
        "missing_percent": 100.0 * float(missing.mean()) if missing.size else 0.0,
        "has_timestamps": seq.timestamps is not None,
        "units": seq.units,
        # what the reader said about the file (e.g. C3D entries it left out)
        "reader_warnings": [str(w) for w in seq.metadata.get("reader_warnings") or ()],
    }
    if seq.timestamps is not None and seq.n_frames > 1:
        dt = np.diff(np.asarray(seq.timestamps, dtype=float))
        out["dt_range"] = [float(dt.min()), float(np.median(dt)), float(dt.max())]
    if seq.tracking_state is not None:
        states = np.asarray(seq.tracking_state)
        out["tracking_states"] = {
            s.name.lower(): int((states == int(s)).sum()) for s in TrackingState
        }
    order = np.argsort(-np.nan_to_num(jump, nan=-1.0))
    out["jumps"] = [
        {
            "joint": seq.joint_names[j],
            # in the sequence's units (``units``; pixels for a pose estimator's keypoints)
            "largest_jump": None if not np.isfinite(jump[j]) else float(jump[j]),
            "frame": int(frame[j]),
            "missing": int(missing[:, j].sum()),
        }
        for j in order
    ]
    return out
