"""LightningPose predictions (.csv): the single-animal DeepLabCut CSV layout.

LightningPose writes its predictions as a DeepLabCut-style CSV (header rows ``scorer``
— ``heatmap_tracker`` and the like —, ``bodyparts``, ``coords`` with ``x``, ``y``,
``likelihood``; a row per frame). They are read by the DeepLabCut reader and labelled
``lightningpose``; written back with ``format="lightningpose"`` (one individual, the
DeepLabCut single-animal layout).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from tobitkf.io.deeplabcut import (
    _is_lightningpose,
    _read_frame,
    dlc_frame,
    sequences_from_dlc_frame,
)
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import SkeletonSequence

__all__ = ["read_lightningpose", "sniff_lightningpose", "write_lightningpose"]


def read_lightningpose(
    path: str | os.PathLike[str],
    fps: float | None = None,
    skeleton: Sequence[tuple[str, str]] | None = None,
    implausible: str = "error",
) -> list[SkeletonSequence]:
    """Read a LightningPose predictions CSV (positions in pixels, confidence =
    likelihood)."""
    p = Path(path)
    return sequences_from_dlc_frame(
        p, _read_frame(p)[0], fmt="lightningpose", fps=fps, skeleton=skeleton,
        implausible=implausible,
    )  # fmt: skip


def write_lightningpose(
    sequences: Sequence[SkeletonSequence], path: str | os.PathLike[str]
) -> None:
    """Write one individual as a LightningPose / single-animal DeepLabCut CSV."""
    seqs = list(sequences)
    if len(seqs) != 1:
        raise ValueError(f"a LightningPose CSV holds one individual, got {len(seqs)}")
    scorer = str(seqs[0].metadata.get("scorer", "heatmap_tracker"))
    dlc_frame([seqs[0].replace(body_id=None)], scorer).to_csv(Path(path))


def sniff_lightningpose(path: Path, head: str) -> int:
    """Score: a DeepLabCut-style CSV whose scorer names a LightningPose model."""
    if head.startswith("scorer,") and _is_lightningpose(head):
        second = head.split("\n", 2)[1].lower() if "\n" in head else ""
        return 85 if second.startswith("bodyparts,") else 0
    return 0


register_format(
    "lightningpose", read_lightningpose, write_lightningpose, (), sniff_lightningpose,
    description="LightningPose predictions CSV (DeepLabCut layout)", aliases=("lp",),
    output_ext=".csv",  # a .csv, told from a generic CSV by its content
)  # fmt: skip
