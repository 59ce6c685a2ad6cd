"""C3D motion-capture files, read through the optional ``c3d`` package.

Install with ``pip install tobitkf[c3d]`` (or ``pip install c3d``). POINT samples with a
negative residual are missing (NaN); units from ``POINT:UNITS`` are converted to metres;
the rate is ``POINT:RATE``; labels are kept (stripped; duplicates get ``_2``, ``_3``
suffixes). Up axis from ``POINT:Y_SCREEN`` (the axis up on the screen; the C3D writer
records it there), z (Vicon/Qualisys convention) when the file does not say. A file whose
first frame is not frame 1 (a trial cut from a longer capture: the force plates' and
analog channels' clock) keeps its time base: timestamps ``(first_frame - 1 + k) / rate``
and ``metadata["first_frame"]``; the C3D and TRC writers number the frames from it again.

``points`` selects which POINT entries to return:

* ``"positions"`` (default): every entry that is a position: real markers, Plug-in Gait
  segment-frame points and the model's centre-of-mass points (``CentreOfMass``,
  ``CentreOfMassFloor``: positions in the lab frame, in the POINT units); not the model
  outputs that are angles, forces, moments or powers (``…Angle(s)``, ``…Force``, ``…GRF``,
  ``…Moment``, ``…Power``: the entries C3D lists in ``POINT:ANGLES``, ``POINT:FORCES``,
  ``POINT:MOMENTS``, ``POINT:POWERS``; any entry not listed there is a position);
* ``"all"``: every entry, model outputs included (converted with the same unit factor);
* ``"markers"``: real markers only: no Plug-in Gait segment frames (``…O/…A/…L/…P``
  quadruples), no centre-of-mass points and no model outputs;
* ``"joint_centres"``: the origins (``…O``) of the Plug-in Gait segment frames (PELO,
  LFEO, LTIO, LHUO, ...), usable as joint centres.

The kept entries' labels and kinds are ``metadata["labels"]`` and
``metadata["point_kinds"]`` (named in ``metadata["per_joint"]``, so that ``select_joints``
cuts them), their residuals ``metadata["residuals"]`` (T, J).

Entries left out are counted by kind in ``metadata["reader_warnings"]`` (e.g. "left out
80 of 193 POINT entries (26 angles, 20 forces, 18 moments, 16 powers)").

A file tobitkf wrote from a smoothed sequence keeps its provenance in the parameter group
``TOBITKF`` (:mod:`tobitkf.io.c3d_write`): read back as ``metadata["provenance"]``.
"""

from __future__ import annotations

import os
import warnings
from collections import Counter
from pathlib import Path

import numpy as np

from tobitkf.io._json import attach_provenance
from tobitkf.io._text import check_positions, check_rate
from tobitkf.io.errors import OptionError, ReadError
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import PER_JOINT, SkeletonSequence
from tobitkf.skeleton.topology import Topology

__all__ = ["classify_labels", "read_c3d", "sniff_c3d"]

#: the parameter group and parameter of the provenance's JSON (:mod:`tobitkf.io.c3d_write`)
PROVENANCE_GROUP, PROVENANCE_PARAM = "TOBITKF", "PROVENANCE"

_UNITS = {"mm": 1e-3, "cm": 1e-2, "m": 1.0, "dm": 0.1, "in": 0.0254}
#: name fragments of the model outputs that are not positions, and what each is
_MODEL_OUTPUTS = {
    "angle": "angles", "force": "forces", "grf": "forces", "moment": "moments", "power": "powers",
}  # fmt: skip
#: name fragments of the model's centre-of-mass points (positions, not markers)
_MODEL_POINTS = ("centreofmass", "centerofmass")
#: how a left-out entry of each kind is counted in the reader's note
_KIND_TEXT = {
    "marker": "markers",
    "segment_origin": "segment origins",
    "segment_axis": "segment axis points",
    "model_point": "centre-of-mass points",
}


def _import_c3d(doing: str = "reading"):
    try:
        import c3d
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            f"{doing} C3D files needs the 'c3d' package: pip install 'tobitkf[c3d]' "
            "(or pip install c3d)"
        ) from exc
    return c3d


def _output_kind(label: str) -> str | None:
    """``"angles"``, ``"forces"``, ``"moments"`` or ``"powers"`` for a model output's
    label, None for a position."""
    low = label.lower()
    return next((what for k, what in _MODEL_OUTPUTS.items() if k in low), None)


def classify_labels(labels: list[str]) -> list[str]:
    """Kind of each POINT label: ``"marker"``, ``"segment_origin"``, ``"segment_axis"``,
    ``"model_point"`` (a centre-of-mass position) or ``"model_output"`` (not a
    position)."""
    kinds = []
    upper = {lab.upper() for lab in labels}
    for lab in labels:
        u = lab.upper()
        low = u.lower()
        if _output_kind(lab) is not None:
            kinds.append("model_output")
            continue
        if any(k in low for k in _MODEL_POINTS):
            kinds.append("model_point")
            continue
        if len(u) >= 2 and u[-1] in "OALP":
            stem = u[:-1]
            if all(stem + s in upper for s in "OALP"):
                kinds.append("segment_origin" if u[-1] == "O" else "segment_axis")
                continue
        kinds.append("marker")
    return kinds


def _unique(labels: list[str]) -> list[str]:
    """Labels made unique: the first of each keeps its name; an empty one becomes
    ``P<i>`` and a repeat ``<label>_2``, ``_3``..., skipping names already in use (a real
    ``A_2`` or ``P1`` label keeps its name)."""
    taken = {lab for lab in labels if lab}
    kept: set[str] = set()
    out = []
    for i, lab in enumerate(labels):
        if lab and lab not in kept:
            kept.add(lab)
            out.append(lab)
            continue
        base = lab or f"P{i + 1}"
        new, n = base, 1
        while new in taken:
            n += 1
            new = f"{base}_{n}"
        taken.add(new)
        out.append(new)
    return out


def _left_out_note(labels: list[str], kinds: list[str], keep: list[int], points: str) -> str:
    """What ``points`` left out, counted by kind ("" when nothing)."""
    kept = set(keep)
    counts = Counter(
        _KIND_TEXT.get(kind) or _output_kind(lab)
        for i, (lab, kind) in enumerate(zip(labels, kinds, strict=True))
        if i not in kept
    )
    if not counts:
        return ""
    parts = ", ".join(f"{n} {what}" for what, n in counts.items())
    return (
        f"points={points!r} left out {len(labels) - len(kept)} of {len(labels)} POINT "
        f"entries ({parts}); points='all' reads every entry"
    )


def read_c3d(
    path: str | os.PathLike[str],
    points: str = "positions",
    units: str | None = None,
    implausible: str = "error",
) -> list[SkeletonSequence]:
    """Read the POINT data of a C3D file.

    Parameters
    ----------
    points : {"positions", "all", "markers", "joint_centres"}
        Which POINT entries to return (see module docstring).
    units : str, optional
        Override ``POINT:UNITS`` (``"mm"``, ``"cm"``, ``"m"``, ``"dm"``, ``"in"``).
    implausible : {"error", "missing"}
        What to do with a returned position beyond the plausibility bound
        (``_text.check_positions``).

    Returns
    -------
    list with one SkeletonSequence: positions (T, P, 3) metres (NaN where the residual is
    negative), fps = POINT:RATE, ``metadata["labels"]``, ``metadata["residuals"]`` (T, P).
    """
    if points not in ("positions", "all", "markers", "joint_centres"):
        raise OptionError(
            f"points must be 'positions', 'all', 'markers' or 'joint_centres', found {points!r}"
        )
    if units is not None and units.lower() not in _UNITS:
        raise OptionError(f"units must be one of {sorted(_UNITS)}, found {units!r}")
    c3d = _import_c3d()
    caught: list[warnings.WarningMessage] = []
    try:
        with open(path, "rb") as fh, warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")  # kept in metadata["reader_warnings"]
            reader = c3d.Reader(fh)
            labels = [str(lab).strip() for lab in reader.point_labels]
            rate = float(reader.point_rate)
            unit_param = reader.get("POINT:UNITS")
            file_units = unit_param.string_value.strip() if unit_param is not None else "mm"
            expected = int(reader.frame_count)
            first_frame = int(reader.first_frame)
            screen = reader.get_screen_axis()
            provenance = _provenance_json(reader)
            frames = [np.array(pts[:, :4], dtype=float) for _, pts, _an in reader.read_frames()]
    except FileNotFoundError:
        raise
    except Exception as exc:  # the third-party binary parser fails in many ways on bad input
        raise ReadError(
            path, None, f"not a readable C3D file ({type(exc).__name__}: {exc})"
        ) from None
    if not frames:
        raise ReadError(path, None, "C3D file holds no frames")
    if len(frames) != expected:
        raise ReadError(
            path, None, f"truncated C3D file: expected {expected} frames, found {len(frames)}"
        )
    data = np.stack(frames)  # (T, P, 4)
    unit = (units or file_units or "mm").lower()
    if unit not in _UNITS:
        raise ReadError(
            path, None, f"unknown POINT:UNITS {unit!r}; expected one of {sorted(_UNITS)}"
        )
    check_rate(path, None, rate, "POINT:RATE", repr(rate))
    if len(labels) < data.shape[1]:
        labels = labels + [""] * (data.shape[1] - len(labels))
    labels = labels[: data.shape[1]]
    positions = data[:, :, :3] * _UNITS[unit]
    residual = data[:, :, 3]
    positions[residual < 0] = np.nan
    kinds = classify_labels(labels)
    if points == "markers":
        keep = [i for i, k in enumerate(kinds) if k == "marker"]
    elif points == "joint_centres":
        keep = [i for i, k in enumerate(kinds) if k == "segment_origin"]
    elif points == "positions":
        keep = [i for i, k in enumerate(kinds) if k != "model_output"]
    else:
        keep = list(range(len(labels)))
    if not keep:
        raise ReadError(path, None, f"no POINT entries of the kind {points!r}")
    notes = [str(w.message) for w in caught]
    if left_out := _left_out_note(labels, kinds, keep, points):
        notes.append(left_out)
    names = _unique([labels[i] for i in keep])
    positions = np.ascontiguousarray(positions[:, keep])
    real = [k for k, i in enumerate(keep) if kinds[i] != "model_output"]  # not positions
    view = positions[:, real]
    check_positions(path, view, None, implausible, names=[names[k] for k in real])
    positions[:, real] = view
    # the capture's clock: frame 1 at time 0 (a trial cut from a longer capture starts later)
    stamps = None if first_frame == 1 else (first_frame - 1 + np.arange(len(data))) / rate
    seq = SkeletonSequence(
        positions=positions,
        topology=Topology.from_names(names, up_axis=_up_axis(screen), name="c3d"),
        timestamps=stamps,
        fps=rate,
        units="m",
        metadata={
            "first_frame": first_frame,
            "source": str(path),
            "format": "c3d",
            "labels": [labels[i] for i in keep],
            "point_kinds": [kinds[i] for i in keep],
            "units_in_file": unit,
            "residuals": np.ascontiguousarray(residual[:, keep]),
            "reader_warnings": notes,
            PER_JOINT: ["labels", "point_kinds"],
        },
    )
    where = f"the parameter {PROVENANCE_GROUP}:{PROVENANCE_PARAM}"
    attach_provenance(path, [seq], provenance, where)
    return [seq]


def _provenance_json(reader) -> bytes | None:
    """The provenance's JSON that tobitkf's writer put in ``TOBITKF:PROVENANCE`` (the
    char array's rows joined, then those of ``PROVENANCE2``, ...), None without it."""
    group = reader.get(PROVENANCE_GROUP)
    if group is None or group.get(PROVENANCE_PARAM) is None:
        return None
    parts, k = [], 1
    while (param := group.get(PROVENANCE_PARAM + (str(k) if k > 1 else ""))) is not None:
        parts.append(param.bytes)
        k += 1
    return b"".join(parts)


def _up_axis(screen: tuple[str, str] | None) -> int:
    """The up axis from ``POINT:Y_SCREEN`` (``+Z``: 2), z (Vicon's and Qualisys's) when
    the file does not say."""
    try:
        return "XYZ".index(str(screen[1]).strip().upper()[-1])  # type: ignore[index]
    except (TypeError, IndexError, ValueError):
        return 2


def sniff_c3d(path: Path, head: str) -> int:
    """Score: byte 2 of the file is 0x50 (the C3D parameter-section key)."""
    try:
        with open(path, "rb") as fh:
            first = fh.read(2)
    except OSError:
        return 0
    if len(first) == 2 and first[1] == 0x50:
        return 90 if path.name.lower().endswith(".c3d") else 30
    return 0


register_format(
    "c3d", read_c3d, None, (".c3d",), sniff_c3d,
    description="C3D (needs the optional 'c3d' package)",
)  # fmt: skip
