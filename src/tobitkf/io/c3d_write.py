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

A smoothed sequence's provenance (``metadata["provenance"]``) goes into a parameter
group of its own, ``TOBITKF``, which other C3D readers pass by: ``TOBITKF:PROVENANCE``
is a char array holding the provenance's ASCII JSON in rows of at most 255 characters
(a C3D dimension is one byte), joined in order to read it (the last row padded with
spaces); JSON too long for one parameter (at most 32 KB) goes on in ``PROVENANCE2``,
``PROVENANCE3``, ... :func:`tobitkf.io.c3d.read_c3d` reads it back.

This module attaches the writer to the ``c3d`` format registered by
:mod:`tobitkf.io.c3d`.
"""

from __future__ import annotations

import io
import os
import struct
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tobitkf.io._json import provenance_text
from tobitkf.io._marker_writer import first_frame, one_3d_sequence
from tobitkf.io.c3d import PROVENANCE_GROUP, PROVENANCE_PARAM, _import_c3d
from tobitkf.io.registry import get_format, register_format, require_rate_grid
from tobitkf.skeleton.sequence import SkeletonSequence

__all__ = ["write_c3d"]

#: the longest row of a C3D char array (its dimensions are one byte each)
_ROW = 255
#: rows per provenance parameter: a parameter's size is a 16-bit offset (< 32767 bytes)
_ROWS = 120
#: a C3D file's parameter section has at most 255 blocks of 512 bytes (the c3d package
#: counts each group twice, so about 64 KB of parameters fit)
_MAX_PARAMETER_BLOCKS = 255


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
    c3d = _import_c3d("writing")
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
    provenance = _add_provenance(writer, seq)
    buf = io.BytesIO()  # written whole or not at all
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the library's notes on the empty analog group
        try:
            writer.write(buf)
        except struct.error:  # the parameter section's block count is one byte
            if not provenance or writer.parameter_blocks() <= _MAX_PARAMETER_BLOCKS:
                raise
            raise ValueError(
                f"cannot write the provenance ({provenance} characters of JSON) to C3D: "
                f"with the labels the parameters need {writer.parameter_blocks()} blocks, "
                f"the c3d package writes at most {_MAX_PARAMETER_BLOCKS}; use format='npz' "
                "or 'csv'"
            ) from None
    Path(path).write_bytes(buf.getvalue())


def _add_provenance(writer, seq: SkeletonSequence) -> int:
    """The group ``TOBITKF`` with the provenance's JSON (module docstring), when the
    sequence has a provenance; the JSON's length (0 without)."""
    text = provenance_text([seq])
    if text is None:
        return 0
    group = writer.add_group(
        writer.numeric_key_next, PROVENANCE_GROUP, "tobitkf: how this file was smoothed"
    )
    width = min(_ROW, len(text))
    step = width * _ROWS
    for k, start in enumerate(range(0, len(text), step)):
        part = text[start : start + step]
        rows = -(-len(part) // width)
        name = PROVENANCE_PARAM + (str(k + 1) if k else "")
        desc = "tobitkf provenance: JSON, rows joined (then PROVENANCE2, 3, ...)"
        group.add_str(name, desc, part.ljust(rows * width), width, rows)
    return len(text)


_spec = get_format("c3d")
register_format(
    _spec.name, _spec.reader, write_c3d, _spec.extensions, _spec.sniff,
    description="C3D (needs the optional 'c3d' package)",
)  # fmt: skip
