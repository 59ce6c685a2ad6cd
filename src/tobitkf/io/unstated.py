"""What a file does not state, given by its user: the frame rate, the skeleton, the unit.

A ``.npy`` array, a keypoint table or an MMPose file of an unknown model may name no
skeleton (joints ``0``, ``1``, ...; or one the reader guessed from the keypoint count)
and state no frame rate; a ``.npy`` array or a CSV without its sidecar states no length
unit (the reader's ``metadata["units_unstated"]``: unknown for the array, metres assumed
for a 3-D CSV). :func:`with_unstated` gives them the ones the user names (``tobitkf
smooth / evaluate / report --topology NAME --fps HZ --units mm``) and leaves a file
that states its own as it is.
"""

from __future__ import annotations

from collections.abc import Sequence

from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import UNNAMED, get_topology

__all__ = [
    "UNITS_UNSTATED",
    "names_no_skeleton",
    "states_no_rate",
    "states_no_units",
    "with_unstated",
]

#: metadata key a reader sets when the file states no length unit
UNITS_UNSTATED = "units_unstated"


def names_no_skeleton(seq: SkeletonSequence) -> bool:
    """The reader found no skeleton in the file (joints ``0``, ``1``, ...), or only
    guessed one from the keypoint count (``metadata["topology_guessed"]``)."""
    return seq.topology.name == UNNAMED or bool(seq.metadata.get("topology_guessed"))


def states_no_rate(seq: SkeletonSequence) -> bool:
    """The file states neither a frame rate nor timestamps."""
    return seq.fps is None and seq.timestamps is None


def states_no_units(seq: SkeletonSequence) -> bool:
    """The file states no length unit (its reader assumed one, or none)."""
    return bool(seq.metadata.get(UNITS_UNSTATED))


def with_unstated(
    sequences: Sequence[SkeletonSequence],
    *,
    fps: float | None = None,
    topology: str | None = None,
    option: str = "topology",
    units: str | None = None,
) -> list[SkeletonSequence]:
    """The sequences with frame rate ``fps`` where they state none (nor timestamps) and
    skeleton ``topology`` (a name, :func:`~tobitkf.skeleton.topology.get_topology`) where
    they name none, and length unit ``units`` (``"mm"``, ``"px"``, ...) where they state
    none; what a file states itself is kept. ``option``: how an error names
    the skeleton's setting (``"--topology"`` on the command line).

    Raises
    ------
    KeyError
        An unknown topology name (the message lists the known ones).
    ValueError
        The skeleton has another number of joints than the file.
    """
    topo = None if topology is None else get_topology(topology)
    out = []
    for s in sequences:
        if topo is not None and names_no_skeleton(s):
            if s.n_joints != topo.n_joints:
                raise ValueError(
                    f"the file has {s.n_joints} keypoints, {option} {topo.name} {topo.n_joints}"
                )
            notes = [n for n in s.metadata.get("reader_warnings") or () if "0..J-1" not in n]
            meta = {k: v for k, v in s.metadata.items() if k != "topology_guessed"}
            s = s.replace(topology=topo, metadata={**meta, "reader_warnings": notes})
        if fps is not None and states_no_rate(s):
            s = s.replace(fps=fps)
        if units is not None and states_no_units(s):
            meta = {k: v for k, v in s.metadata.items() if k != UNITS_UNSTATED}
            s = s.replace(units=units, metadata=meta)
        out.append(s)
    return out
