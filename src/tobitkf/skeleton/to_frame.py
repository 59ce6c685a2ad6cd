"""Skeleton sequences to pandas DataFrames (the layouts: :mod:`tobitkf.skeleton.dataframe`)."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["to_dataframe"]

_COORDS = ("x", "y", "z")
_PER_SAMPLE = ("confidence", "tracking_state", "std", "sample_state")


def _pandas() -> Any:
    try:
        import pandas as pd
    except ImportError:  # pragma: no cover - pandas is in the 'pose' and 'dev' extras
        raise ImportError(
            "DataFrames need pandas: pip install 'tobitkf[pose]' (or pip install pandas)"
        ) from None
    return pd


def _is_sequence(s: Any) -> bool:
    # duck-typed: importing the sequence module here would close an import cycle
    return hasattr(s, "positions") and hasattr(s, "topology") and hasattr(s, "times")


def _sequences(sequences: Any) -> list:
    seqs = [sequences] if _is_sequence(sequences) else list(sequences)
    if not seqs or not all(_is_sequence(s) for s in seqs):
        raise TypeError("expected a SkeletonSequence or a non-empty list of them")
    first = seqs[0]
    for s in seqs[1:]:
        if (s.joint_names, s.n_dims, s.units, s.n_frames) != (
            first.joint_names, first.n_dims, first.units, first.n_frames,
        ):  # fmt: skip
            raise ValueError(
                "sequences in one DataFrame must share joints, dimension, units and frames"
            )
    return seqs


def _fields(s: Any) -> dict[str, np.ndarray]:
    """Per-sample (T, J) arrays of a sequence by column name (absent ones left out)."""
    out = {c: s.positions[..., a] for a, c in enumerate(_COORDS[: s.n_dims])}
    for name in _PER_SAMPLE:
        v = getattr(s, name)
        if v is not None:
            out[name] = v
    return out


def _attrs(s: Any) -> dict[str, Any]:
    return {
        "fps": s.fps,
        "units": s.units,
        "topology": s.topology.name,
        "parents": list(s.topology.parents),
        "up_axis": s.topology.up_axis,
    }


def to_dataframe(sequences: Any, layout: str = "long") -> Any:
    """A DataFrame of one sequence or several (one per individual), long or wide
    (module docstring)."""
    pd = _pandas()
    seqs = _sequences(sequences)
    if layout not in ("long", "wide"):
        raise ValueError(f"layout must be 'long' or 'wide', got {layout!r}")
    first = seqs[0]
    T, J = first.n_frames, first.n_joints
    timed = first.timestamps is not None or first.fps is not None
    names = [s.body_id if s.body_id is not None else k for k, s in enumerate(seqs)]
    with_ind = len(seqs) > 1 or first.body_id is not None
    if layout == "long":
        parts = []
        for s, name in zip(seqs, names, strict=True):
            cols: dict[str, Any] = {"frame": np.repeat(np.arange(T), J)}
            if timed:
                cols["time"] = np.repeat(s.times(), J)
            if with_ind:
                cols["individual"] = [name] * (T * J)
            cols["keypoint"] = np.tile(np.array(first.joint_names, dtype=object), T)
            for c, v in _fields(s).items():
                cols[c] = v.reshape(-1)
            parts.append(pd.DataFrame(cols))
        df = pd.concat(parts, ignore_index=True) if len(parts) > 1 else parts[0]
    else:
        columns, data = [], []
        for s, name in zip(seqs, names, strict=True):
            fields = _fields(s)
            for j, joint in enumerate(first.joint_names):
                for c, v in fields.items():
                    columns.append((name, joint, c) if with_ind else (joint, c))
                    data.append(v[:, j])
        levels = ["individual", "keypoint", "coord"] if with_ind else ["keypoint", "coord"]
        index = pd.Index(first.times(), name="time") if timed else pd.RangeIndex(T, name="frame")
        df = pd.DataFrame(
            np.stack(data, axis=1) if data else np.empty((T, 0)),
            index=index,
            columns=pd.MultiIndex.from_tuples(columns, names=levels),
        )
    df.attrs.update(_attrs(first))
    return df
