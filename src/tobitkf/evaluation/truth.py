"""Ground truth from optical motion capture: pairs, time alignment and registration.

:func:`prepare_truth` turns a mocap recording into a :class:`GroundTruth` on the track's
frames (steps 1–3 of :mod:`tobitkf.evaluation.evaluate`): each track joint gets a mocap
point or a mean of points, the mocap clock is fitted to the track's, and one robust rigid
transform plus per-pair offsets is fitted on the raw track and held fixed.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.core.jsonable import to_jsonable
from tobitkf.evaluation.alignment import (
    TimeAlignment,
    distance_signals,
    fit_time_alignment,
    mocap_times,
    resample,
)
from tobitkf.evaluation.pairs import (
    KERAAL_PAIRS,
    UIPRMD_PAIRS,
    Pair,
    PairingTable,
    ResolvedPairs,
    builtin_pairs,
    normalise_name,
    read_pairs,
)
from tobitkf.evaluation.registration import (
    RigidRegistration,
    choose_quaternion_order,
    fit_registration,
    quat_to_matrix,
)

__all__ = ["GroundTruth", "detect_pairs", "prepare_truth", "truth_from_array"]


# ------------------------------------------------------------------------------ truth
@dataclass(frozen=True)
class GroundTruth:
    """Ground truth laid out like the track (same frames, same joints, track frame).

    Attributes
    ----------
    positions : (T, J, 3) metres, NaN for unpaired joints / frames outside the mocap.
    joint_names : (J,) the track's joint names.
    paired : (J,) bool, joints with a mocap counterpart.
    registration : the fitted transform (None when the truth was given directly).
    time_alignment : the fitted mocap timing (None when given directly).
    fitted_time_alignment : the fitted timing even when a fixed one was used (KERAAL).
    pairs : the resolved pairing table.
    notes : free-form facts for the report: ``pairing_table``, ``quaternion_order`` and
        ``quaternion_order_fit_rms_m`` (KERAAL), ``unresolved_pairs``, and ``warnings``
        (doubtful time alignment: correlation < 0.9, overlap < 60 %, rate at the edge of
        the searched range).
    """

    positions: NDArray[np.float64]
    joint_names: tuple[str, ...]
    paired: NDArray[np.bool_]
    registration: RigidRegistration | None = None
    time_alignment: TimeAlignment | None = None
    fitted_time_alignment: TimeAlignment | None = None
    pairs: ResolvedPairs | None = None
    notes: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict:
        """JSON-ready description of how the truth was obtained."""
        return {
            "paired_joints": [n for n, p in zip(self.joint_names, self.paired) if p],
            "registration": None if self.registration is None else self.registration.summary(),
            "time_alignment": None
            if self.time_alignment is None
            else self.time_alignment.to_dict(),
            "fitted_time_alignment": None
            if self.fitted_time_alignment is None
            else self.fitted_time_alignment.to_dict(),
            "pairs": None if self.pairs is None else [str(p) for p in self.pairs.pairs],
            "notes": to_jsonable(self.notes),
        }


def truth_from_array(truth: Any, joint_names: Sequence[str]) -> GroundTruth:
    """Wrap a (T, J, 3) truth already in the track frame and layout."""
    p = np.asarray(truth, dtype=float)
    if p.ndim != 3 or p.shape[1] != len(joint_names) or p.shape[2] != 3:
        raise ValueError(f"truth must be (T, {len(joint_names)}, 3), got {p.shape}")
    return GroundTruth(p, tuple(joint_names), np.isfinite(p).all(-1).any(0))


def _quaternions(mocap: Any) -> tuple[NDArray | None, str | None]:
    """Target quaternions (T, M, 4) from a mocap sequence's metadata, if any."""
    meta = getattr(mocap, "metadata", {}) or {}
    for key in ("target_quaternions_raw", "orientations", "quaternions", "rotations"):
        q = meta.get(key)
        if (
            isinstance(q, np.ndarray)
            and q.shape[:2] == mocap.positions.shape[:2]
            and q.shape[-1] == 4
        ):
            order = meta.get("quaternion_order") or meta.get(f"{key}_order")
            return q.astype(float), order
    return None, None


def detect_pairs(track_names: Sequence[str], mocap_names: Sequence[str]) -> PairingTable:
    """The built-in table whose names match best (KERAAL or UI-PRMD); else, when the two
    name at least four of the same joints (a truth in the track's own skeleton: a
    simulation, a 3-D lifter's joints against mocap reduced to them), each such joint
    with its namesake."""
    best, score = None, 0
    mset = {normalise_name(n) for n in mocap_names}
    tset = {normalise_name(n) for n in track_names}
    for table in (KERAAL_PAIRS, UIPRMD_PAIRS):
        s = sum(
            normalise_name(p.track_joint) in tset
            and all(normalise_name(m) in mset for m in p.mocap_points)
            for p in table.pairs
        )
        if s > score:
            best, score = table, s
    if best is not None and score >= 4:
        return best
    by_key = {normalise_name(n): n for n in mocap_names}
    same = [
        Pair(t, (by_key[normalise_name(t)],)) for t in track_names if normalise_name(t) in by_key
    ]
    if len(same) >= 4:
        return PairingTable("same names", tuple(same))
    raise ValueError(
        "cannot pair the track with the mocap automatically (neither the KERAAL nor the "
        "UI-PRMD names match, nor four joint names of their own); give a pairing table "
        "with --pairs (CSV: track_joint,mocap_point)"
    )


def metric(seq: Any, name: str) -> Any:
    """``seq`` in metres, for the comparison with motion capture: a recording in another
    length unit converted (:meth:`SkeletonSequence.to_metres`), one in 2-D, pixels or
    unknown units refused with a ValueError that says why. Anything without units (an
    array-like of the caller's) is taken as it is."""
    units = getattr(seq, "units", "m")
    dims = np.shape(getattr(seq, "positions", seq))[-1]
    if dims != 3:
        raise ValueError(
            f"the {name} is {dims}-D: scores against motion capture need 3-D positions in a "
            "length unit (without a truth, tobitkf evaluate scores smoothness and jumps)"
        )
    if units == "m" or not hasattr(seq, "to_metres"):
        return seq
    if getattr(seq, "metres_per_unit", None) is None:
        raise ValueError(
            f"the {name} is in {units or 'unknown units'}: scores against motion capture "
            "need a length unit (give it: --units m, cm or mm)"
        )
    return seq.to_metres()


def _own_clock(seq: Any) -> NDArray | None:
    """A sequence's frame times from its first when it has timestamps, else None."""
    stamps = getattr(seq, "timestamps", None)
    if stamps is None:
        return None
    t = np.asarray(stamps, dtype=float)
    return t - t[0] if t.size else None


def _nearest(times: NDArray, at: NDArray) -> NDArray:
    """Index of the element of increasing ``times`` nearest each of ``at``."""
    k = np.clip(np.searchsorted(times, at), 1, max(len(times) - 1, 1))
    if len(times) < 2:
        return np.zeros(len(at), dtype=int)
    left = times[k - 1]
    return np.where(np.abs(at - left) <= np.abs(times[k] - at), k - 1, k)


def _check_metres(name: str, positions: NDArray) -> None:
    spread = np.nanmedian(np.linalg.norm(positions - np.nanmedian(positions, axis=(0, 1)), axis=-1))
    if np.isfinite(spread) and spread > 10:
        raise ValueError(
            f"{name} positions look like they are not in metres (median distance to the centre "
            f"{spread:.1f}); readers must return metres"
        )


def prepare_truth(
    track: Any,
    mocap: Any,
    *,
    pairs: PairingTable | str | Path | None = None,
    offset_mode: str = "auto",
    time: str = "auto",
    mocap_rate: float | None = None,
    fit_rate: bool | None = None,
    rate_range: tuple[float, float] | None = None,
    n_signals: int = 20,
) -> GroundTruth:
    """Pair, time-align and register a mocap recording onto a raw track.

    Parameters
    ----------
    track : SkeletonSequence, the RAW track (the registration is fitted on it).
    mocap : SkeletonSequence of mocap points (names in ``joint_names``; KERAAL targets may
        carry quaternions in ``metadata["orientations"]`` (T, M, 4)).
    pairs : a :class:`PairingTable`, ``"keraal"`` / ``"ui_prmd"``, a CSV path, or None
        (detected from the names).
    offset_mode : ``"auto"`` (body-frame offsets when quaternions exist, else world),
        ``"body"``, ``"world"`` or ``"none"``.
    time : ``"auto"``, ``"fit"`` (fit offset, and rate if ``fit_rate``), or ``"fixed"``
        (offset 0 at ``mocap_rate``; the fitted timing is still reported).  ``"auto"`` is
        ``"fixed"`` for KERAAL (documented common time zero), ``"fit"`` otherwise.
    mocap_rate : nominal mocap rate (Hz); default ``mocap.fps``.
    fit_rate : fit the mocap rate too; default True for UI-PRMD, else False.
    rate_range : (lo, hi) Hz searched when fitting the rate; default ``(0.6, 1.6)`` times the
        nominal rate for UI-PRMD (its m07 episodes fit 130–160 Hz against a nominal 100 Hz,
        i.e. the two files' clocks disagree by more than the documented 80–100 Hz), else
        ``(0.75, 1.1)`` times it.
    n_signals : number of most-varying inter-point distances used for the time fit.

    Returns
    -------
    GroundTruth, in metres (a track or mocap in another length unit is converted first)
    """
    track = metric(track, "track")
    mocap = metric(mocap, "motion capture")
    table: PairingTable
    if pairs is None:
        table = detect_pairs(track.joint_names, mocap.joint_names)
    elif isinstance(pairs, PairingTable):
        table = pairs
    elif isinstance(pairs, str) and normalise_name(pairs) in ("keraal", "uiprmd"):
        table = builtin_pairs(pairs)
    else:
        table = read_pairs(pairs)
    resolved = table.resolve(track.joint_names, mocap.joint_names)
    J = track.n_joints
    y = np.asarray(track.positions, dtype=float)
    mp = np.asarray(mocap.positions, dtype=float)
    _check_metres("track", y)
    _check_metres("mocap", mp)
    m_full = resolved.mocap_positions(mp, J)  # (N, J, 3)
    quats, q_order = _quaternions(mocap)
    q_full = resolved.mocap_quaternions(quats, J) if quats is not None else None

    # ---- time
    if getattr(track, "fps", None) is None and getattr(track, "timestamps", None) is None:
        raise ValueError(
            "the track states no frame rate (no timestamps, no fps): the time alignment "
            "with the motion capture needs it (give --fps, or fps= when reading)"
        )
    clock = _own_clock(mocap)  # a mocap with timestamps: its frames' own times
    rate = float(mocap_rate or getattr(mocap, "fps", None) or 0)
    if rate <= 0 and clock is not None and len(clock) > 1:
        rate = 1.0 / float(np.median(np.diff(clock)))  # its nominal rate, from its clock
    if rate <= 0:
        raise ValueError(
            "the motion capture states no frame rate (no fps, no timestamps): give it "
            "(mocap_rate=, or fps= when reading it)"
        )
    is_keraal = table.name == "keraal"
    is_uiprmd = table.name == "ui_prmd"
    if fit_rate is None:
        fit_rate = is_uiprmd
    if time == "auto":
        time = "fixed" if is_keraal else "fit"
    if time not in ("fit", "fixed"):
        raise ValueError(f"time must be 'auto', 'fit' or 'fixed', got {time!r}")
    tt = track.times() if hasattr(track, "times") else np.arange(len(y)) / 30.0
    ji = list(resolved.track_index)
    jp = [(a, b) for n, a in enumerate(sorted(set(ji))) for b in sorted(set(ji))[n + 1 :]]
    sig_t = distance_signals(y, jp)
    sig_m = distance_signals(m_full, jp)
    if not (np.isfinite(sig_t).any(axis=0) & np.isfinite(sig_m).any(axis=0)).any():
        raise ValueError(
            "no two paired joints are measured together in both the track and the motion "
            "capture: the time alignment (and the registration) needs the distances between "
            "joints; check the pairing (--pairs) and that the mocap file holds the markers"
        )
    with warnings.catch_warnings():  # a pair the truth never measures has no spread
        warnings.simplefilter("ignore", RuntimeWarning)
        spread = np.nan_to_num(np.nanstd(sig_m, axis=0))
    sel = np.argsort(-spread)[:n_signals]
    if fit_rate and rate_range is None:
        rate_range = (0.6 * rate, 1.6 * rate) if is_uiprmd else (0.75 * rate, 1.1 * rate)
    unfitted = None
    try:
        fitted = fit_time_alignment(
            tt,
            sig_t[:, sel],
            sig_m[:, sel],
            rate=rate,
            fit_rate=fit_rate,
            rate_range=rate_range,
            mocap_clock=clock,
        )
    except ValueError as exc:
        if time != "fixed":
            raise
        # the offset is held anyway (KERAAL): the fit could only have checked it
        unfitted = str(exc).removeprefix("fit_time_alignment: ")
        fitted = TimeAlignment(float("nan"), rate, float("nan"), float("nan"), False)
    if time == "fixed":
        used = TimeAlignment(0.0, rate, float("nan"), float("nan"), False)
    else:
        used = fitted
    mt = mocap_times(len(mp), used.rate_hz, used.offset_s, clock, rate)
    m_res = resample(mt, m_full, tt)
    rots = None
    if q_full is not None:
        # orientation of the nearest mocap frame (quaternions do not interpolate linearly)
        q_res = q_full[_nearest(mt, tt)]
    # ---- space
    notes: dict[str, Any] = {"pairing_table": table.name}
    warnings_: list[str] = []
    frame = float(np.median(np.diff(tt))) if len(tt) > 1 else 0.0
    if unfitted is not None:
        warnings_.append(
            f"the time fit could not check the fixed offset {used.offset_s:g} s "
            f"({unfitted}): the motion capture is scored where it covers the track"
        )
    elif time == "fixed" and abs(fitted.offset_s - used.offset_s) > 2 * frame:
        warnings_.append(
            f"the fitted time offset {fitted.offset_s:+.3f} s is more than two frames from "
            f"the fixed {used.offset_s:g} s (KERAAL's common start): the motion capture may "
            "be cut or shifted; the scores hold the offset fixed"
        )
    if unfitted is None and not fitted.correlation >= 0.9:
        warnings_.append(
            f"time alignment is doubtful: signal correlation {fitted.correlation:.2f} < 0.9"
        )
    if unfitted is None and fitted.overlap < 0.6:
        warnings_.append(f"mocap covers only {100 * fitted.overlap:.0f} % of the track frames")
    if fit_rate and rate_range is not None:
        lo, hi = rate_range
        if min(fitted.rate_hz - lo, hi - fitted.rate_hz) < 0.01 * (hi - lo):
            warnings_.append(
                f"fitted mocap rate {fitted.rate_hz:.1f} Hz is at the edge of the searched "
                f"range {lo:.0f}-{hi:.0f} Hz"
            )
    if resolved.missing:
        notes["unresolved_pairs"] = [r for _, r in resolved.missing]
    if warnings_:
        notes["warnings"] = warnings_
    mode = offset_mode
    if mode == "auto":
        mode = "body" if q_full is not None else "world"
    if mode == "body":
        if q_full is None:
            raise ValueError("offset_mode='body' needs mocap orientations (quaternions)")
        if q_order in ("xyzw", "wxyz"):
            rots = quat_to_matrix(q_res, q_order)
            reg = fit_registration(
                y, m_res, offset_mode="body", target_rotations=rots, quaternion_order=q_order
            )
        else:
            reg, scores = choose_quaternion_order(y, m_res, q_res)
            rots = quat_to_matrix(q_res, reg.quaternion_order)
            notes["quaternion_order_fit_rms_m"] = scores
        notes["quaternion_order"] = reg.quaternion_order
    else:
        reg = fit_registration(y, m_res, offset_mode=mode)  # type: ignore[arg-type]
    truth = reg.truth_in_track_frame(m_res, rots)
    paired = np.zeros(J, dtype=bool)
    paired[ji] = True
    truth[:, ~paired] = np.nan
    return GroundTruth(
        positions=truth,
        joint_names=tuple(track.joint_names),
        paired=paired,
        registration=reg,
        time_alignment=used,
        fitted_time_alignment=fitted,
        pairs=resolved,
        notes=notes,
    )
