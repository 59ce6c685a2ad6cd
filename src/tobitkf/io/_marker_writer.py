"""What the marker-trajectory writers (TRC, C3D) ask of their input, said once."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

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


def first_frame(seq: SkeletonSequence, rate: float) -> int:
    """The capture's number of the sequence's first frame, for the formats that number
    frames (C3D, TRC): frame 1 at time 0, so ``round(t0 * rate) + 1`` when the first
    frame's time ``t0`` is at least 0; 1 otherwise (a time before the capture's zero has
    no frame number)."""
    t0 = float(seq.times()[0]) if seq.n_frames else 0.0
    k = round(t0 * rate)
    return int(k) + 1 if k >= 0 else 1


def rotate_up(positions: np.ndarray, up: int, to: int) -> np.ndarray:
    """``positions`` (..., 3) turned by a quarter turn about the third axis so that axis
    ``up`` becomes axis ``to`` (a proper rotation: lengths, angles and handedness kept;
    Z up to Y up is ``(x, y, z) -> (x, z, -y)``, OpenSim's usual turn of lab data)."""
    if up == to:
        return positions
    rot = np.zeros((3, 3))
    a = 3 - up - to  # the axis turned about
    rot[a, a] = 1.0
    rot[to, up] = 1.0  # e_up -> e_to
    rot[up, to] = -1.0  # e_to -> -e_up
    return positions @ rot.T
