"""``tobitkf info``: what the reader found in a file."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tobitkf.io import detect_format, load
from tobitkf.io.unstated import states_no_units
from tobitkf.skeleton.describe import describe_sequence

__all__ = ["describe"]


def describe(path: str | Path, format: str = "auto") -> dict[str, Any]:
    """Read ``path`` and describe every body in it (the data behind ``tobitkf info``)."""

    fmt = detect_format(path) if format == "auto" else format
    sequences = load(path, format=fmt)
    return {
        "path": str(path),
        "format": fmt,
        "bodies": len(sequences),
        "sequences": [
            # units_stated: False where the reader assumed the unit (a CSV without its
            # sidecar) or has none (an array)
            {**describe_sequence(s), "units_stated": not states_no_units(s), **_size(s)}
            for s in sequences
        ],
    }


def _size(seq: Any) -> dict[str, Any]:
    """``size_problem``: why the smoothers would refuse the body's size (a track in
    millimetres read as metres, :mod:`tobitkf.smoothing.body_scale`); ``size_note``: for
    a 3-D track in unknown units, the unit its size looks like (what smoothing it warns,
    :func:`~tobitkf.smoothing.body_scale.unstated_unit_note`); else nothing."""
    from tobitkf.smoothing.body_scale import check_body_scale, unstated_unit_note

    scale = seq.metres_per_unit
    pos = seq.positions[:, None] * (1.0 if scale is None else scale)
    try:
        radius = check_body_scale(pos, metres=scale is not None)
    except ValueError as exc:
        return {"size_problem": str(exc)}
    note = unstated_unit_note(radius, seq.units, seq.n_dims)
    return {} if note is None else {"size_note": note}
