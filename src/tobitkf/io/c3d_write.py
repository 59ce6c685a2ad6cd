"""C3D writer, through the optional ``c3d`` package (``pip install tobitkf[c3d]``).

Writes one sequence of 3-D positions as the POINT data of a C3D file: floating-point
samples (``POINT:SCALE`` -1; C3D stores float32, so values are rounded to float32),
``POINT:RATE`` = fps (or the timestamps' rate: the least-squares step on the median
step's frame grid; C3D keeps no times, so a
sequence with frames more than half a frame off that rate's grid, irregular or dropped,
is refused with a ValueError), ``POINT:UNITS`` = the
sequence's length unit (``m``, ``cm`` or ``mm``; ``units`` converts), ``POINT:LABELS`` = the
joint names, a missing sample written with residual -1 (the C3D convention that
:func:`tobitkf.io.c3d.read_c3d` and every C3D reader read as "no data"), no analog
channels. Labels must be printable ASCII without surrounding spaces (C3D labels are
space-padded ASCII); anything else is refused with a ValueError.

This module attaches the writer to the ``c3d`` format registered by
:mod:`tobitkf.io.c3d`.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence

import numpy as np

from tobitkf.io._marker_writer import first_frame, one_3d_sequence
from tobitkf.io.c3d import _import_c3d
from tobitkf.io.registry import get_format, register_format, require_rate_grid
from tobitkf.skeleton.sequence import SkeletonSequence

__all__ = ["write_c3d"]


def _check_label(name: str) -> str:
    if not (name.isascii() and name.isprintable()) or not name.strip() or name != name.strip():
        raise ValueError(
            f"cannot write the label {name!r} to C3D: labels are printable ASCII, non-empty, "
            "without surrounding spaces; rename it or use format='npz'"
        )
    if len(name) > 255:
        raise ValueError(f"cannot write the label {name[:20]!r}... to C3D: longer than 255")
    return name


def write_c3d(
    sequences: Sequence[SkeletonSequence],
    path: str | os.PathLike[str],
    *,
    units: str | None = None,
) -> None:
    """Write one sequence of 3-D positions as a C3D file.

    Parameters
    ----------
    units : {"m", "cm", "mm"}, optional
        ``POINT:UNITS`` of the file; positions are converted from the sequence's units
        (default: the sequence's own). A sequence in unknown units (None) needs
        ``units``, which labels them without conversion.
    """
    seq, units, scale = one_3d_sequence(sequences, "C3D", "points", units)
    labels = [_check_label(n) for n in seq.joint_names]
    if seq.fps is not None:
        rate = float(seq.fps)
    else:
        dt = seq.dt()
        dt = dt[dt > 0]
        if not dt.size:
            raise ValueError("cannot write POINT:RATE: the sequence has no fps and no time steps")
        rate = float(1.0 / np.median(dt))
        # refined over the whole recording: the frame numbers on the median step's grid,
        # then the least-squares step (jitter of single steps evens out)
        t = seq.times()
        k = np.round((t - t[0]) * rate)
        if k[-1] > 0:
            rate = float(1.0 / np.polyfit(k, t, 1)[0])
    require_rate_grid(seq, rate, "C3D")
    c3d = _import_c3d()
    pos = seq.positions * scale
    missing = np.isnan(pos).any(axis=-1)
    writer = c3d.Writer(point_rate=rate, point_scale=-1.0, point_units=units)
    no_analog = np.zeros((0, 0), dtype=np.float32)
    frames = []
    for t in range(seq.n_frames):
        pts = np.zeros((seq.n_joints, 5), dtype=np.float32)
        pts[:, :3] = np.where(missing[t][:, None], 0.0, pos[t])
        pts[:, 3] = np.where(missing[t], -1.0, 0.0)
        frames.append((pts, no_analog))
    writer.add_frames(frames)
    writer.set_point_labels(labels)
    start = first_frame(seq, rate)
    if start != 1:
        writer.set_start_frame(start)
    # the up axis, where C3D keeps it (POINT:Y_SCREEN, the axis up on the screen)
    up = seq.topology.up_axis
    writer.set_screen_axis("+Y" if up == 0 else "+X", "+" + "XYZ"[up])
    with open(path, "wb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the library's notes on the empty analog group
        writer.write(fh)


_spec = get_format("c3d")
register_format(
    _spec.name, _spec.reader, write_c3d, _spec.extensions, _spec.sniff,
    description="C3D (needs the optional 'c3d' package)",
)  # fmt: skip
