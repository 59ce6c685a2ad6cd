"""What the marker-trajectory writers (TRC, C3D) ask of their input, said once."""

from __future__ import annotations

from collections.abc import Sequence

from tobitkf.io.errors import OptionError
from tobitkf.io.registry import require_frames
from tobitkf.skeleton.sequence import KNOWN_UNITS, SkeletonSequence

#: the length units a marker file can declare, in metres
MARKER_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}


def one_3d_sequence(
    sequences: Sequence[SkeletonSequence], fmt: str, points: str, units: str | None
) -> tuple[SkeletonSequence, str, float]:
    """The single 3-D sequence a ``fmt`` file holds, the file's units and the factor from
    the sequence's units to them. A sequence in unknown units needs ``units``, which then
    labels the numbers without converting them; one with no frame is refused (the
    readers refuse such a file)."""
    seqs = list(sequences)
    if len(seqs) != 1:
        raise ValueError(
            f"a {fmt} file holds one set of {points}; found {len(seqs)} sequences (write each "
            "body to its own file)"
        )
    (seq,) = seqs
    if seq.positions.shape[2] != 3:
        raise ValueError(f"{fmt} holds 3-D {points}; the positions are {seq.positions.shape[2]}-D")
    if units is not None and units not in MARKER_UNITS:
        raise OptionError(f"units must be one of {sorted(MARKER_UNITS)}, found {units!r}")
    if seq.units is None:
        if units is None:
            raise ValueError(
                "the sequence's units are unknown: pass units='m', 'cm' or 'mm' to label them"
            )
        factor = 1.0
    else:
        if seq.units not in MARKER_UNITS:
            raise ValueError(f"{fmt} holds lengths; the sequence's units are {seq.units!r}")
        units = units or seq.units
        factor = KNOWN_UNITS[seq.units] / MARKER_UNITS[units]
    require_frames(seqs, fmt)
    return seq, units, factor
