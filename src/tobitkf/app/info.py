"""``tobitkf info``: what the reader found in a file."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tobitkf.io import detect_format, load
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
        "sequences": [describe_sequence(s) for s in sequences],
    }
