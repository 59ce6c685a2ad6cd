"""Joint angles and the paper's angle evaluation (2020, Section 4.3, Table 4).

The angle at a joint is the angle between the two bones meeting there, in degrees:
elbow = angle(shoulder − elbow, wrist − elbow), knee = angle(hip − knee, ankle − knee).
180° is a straight limb.

The paper compares Kinect and Vicon angles at the delay that minimises each angle's
RMSE (:func:`angle_rmse_best_delay`).  Picking the best delay per method hides the lag a
filter adds, so :func:`angle_rmse_at_delay` scores every method at one common delay.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tobitkf.evaluation.pairs import normalise_name

__all__ = [
    "ANGLE_DEFINITIONS",
    "UIPRMD_ANGLE_DEFINITIONS",
    "AngleScore",
    "angle_rmse_at_delay",
    "angle_rmse_best_delay",
    "joint_angle",
    "joint_angles",
]

# angle name -> (proximal joint, vertex joint, distal joint); Kinect V2 names
ANGLE_DEFINITIONS: dict[str, tuple[str, str, str]] = {
    "right_elbow": ("ShoulderRight", "ElbowRight", "WristRight"),
    "left_elbow": ("ShoulderLeft", "ElbowLeft", "WristLeft"),
    "right_knee": ("HipRight", "KneeRight", "AnkleRight"),
    "left_knee": ("HipLeft", "KneeLeft", "AnkleLeft"),
}

# the same angles on the UI-PRMD hierarchy (each point is the proximal end of its segment)
UIPRMD_ANGLE_DEFINITIONS: dict[str, tuple[str, str, str]] = {
    "right_elbow": ("Right upper arm", "Right forearm", "Right hand"),
    "left_elbow": ("Left upper arm", "Left forearm", "Left hand"),
    "right_knee": ("Right upper leg", "Right lower leg", "Right foot"),
    "left_knee": ("Left upper leg", "Left lower leg", "Left foot"),
}


def joint_angle(a: ArrayLike, b: ArrayLike, c: ArrayLike) -> NDArray[np.float64]:
    """Angle ABC at vertex ``b`` in degrees, for points of shape (..., 3).

    Uses ``atan2(|u × v|, u · v)``, accurate near 0° and 180°; NaN where a point is
    missing or a bone has zero length.
    """
    u = np.asarray(a, dtype=float) - np.asarray(b, dtype=float)
    v = np.asarray(c, dtype=float) - np.asarray(b, dtype=float)
    cr = np.linalg.norm(np.cross(u, v), axis=-1)
    dot = np.sum(u * v, axis=-1)
    ang = np.degrees(np.arctan2(cr, dot))
    degenerate = (np.linalg.norm(u, axis=-1) == 0) | (np.linalg.norm(v, axis=-1) == 0)
    return np.where(degenerate, np.nan, ang)


def joint_angles(
    positions: ArrayLike,
    joint_names: Sequence[str],
    definitions: Mapping[str, tuple[str, str, str]] | None = None,
) -> dict[str, NDArray[np.float64]]:
    """Angles over time for every definition whose three joints exist.

    Parameters
    ----------
    positions : (T, J, 3).
    joint_names : (J,) names (matched case/space-insensitively).
    definitions : name -> (proximal, vertex, distal); default :data:`ANGLE_DEFINITIONS`
        and, when those joints are absent, :data:`UIPRMD_ANGLE_DEFINITIONS`.

    Returns
    -------
    dict angle name -> (T,) degrees.
    """
    p = np.asarray(positions, dtype=float)
    idx = {normalise_name(n): i for i, n in enumerate(joint_names)}
    defs_list = (
        [definitions]
        if definitions is not None
        else [
            ANGLE_DEFINITIONS,
            UIPRMD_ANGLE_DEFINITIONS,
        ]
    )
    out: dict[str, NDArray[np.float64]] = {}
    for defs in defs_list:
        for name, (a, b, c) in defs.items():
            if name in out:
                continue
            ks = [idx.get(normalise_name(x)) for x in (a, b, c)]
            if any(k is None for k in ks):
                continue
            out[name] = joint_angle(p[:, ks[0]], p[:, ks[1]], p[:, ks[2]])
    return out


def angle_rmse_at_delay(estimate: ArrayLike, truth: ArrayLike, delay: int) -> float:
    """RMSE (degrees) between ``estimate[t]`` and ``truth[t - delay]`` on the overlap.

    A positive delay compares the estimate with earlier truth (the estimate is late).
    """
    e = np.asarray(estimate, dtype=float)
    t = np.asarray(truth, dtype=float)
    if e.shape != t.shape or e.ndim != 1:
        raise ValueError(f"angle series must be equal-length 1-D, got {e.shape}, {t.shape}")
    n = len(e)
    if abs(delay) >= n:
        return float("nan")
    if delay >= 0:
        d = e[delay:] - t[: n - delay]
    else:
        d = e[: n + delay] - t[-delay:]
    d = d[np.isfinite(d)]
    return float(np.sqrt(np.mean(d**2))) if len(d) else float("nan")


def _pairs(e: np.ndarray, t: np.ndarray, delay: int) -> int:
    """How many finite (estimate, truth) pairs :func:`angle_rmse_at_delay` compares."""
    n = len(e)
    if e.shape != t.shape or abs(delay) >= n:
        return 0
    a, b = (e[delay:], t[: n - delay]) if delay >= 0 else (e[: n + delay], t[-delay:])
    return int(np.sum(np.isfinite(a) & np.isfinite(b)))


@dataclass(frozen=True)
class AngleScore:
    """Angle RMSE of one method for one angle.

    rmse_best : RMSE (deg) at the best delay in the searched range; best_delay its delay.
    rmse_fixed : RMSE (deg) at the common fixed delay ``fixed_delay``.
    """

    angle: str
    rmse_best: float
    best_delay: int
    rmse_fixed: float
    fixed_delay: int

    def to_dict(self) -> dict:
        return asdict(self)


def angle_rmse_best_delay(
    estimate: ArrayLike, truth: ArrayLike, max_delay: int = 10
) -> tuple[float, int]:
    """The smallest :func:`angle_rmse_at_delay` over ``-max_delay..max_delay`` and its delay,
    among the delays that keep at least half the samples compared at delay 0 (on a short
    track a long delay would compare a handful of samples)."""
    best = (float("inf"), 0)
    e, t = np.asarray(estimate, dtype=float), np.asarray(truth, dtype=float)
    need = 0.5 * _pairs(e, t, 0)
    for d in range(-max_delay, max_delay + 1):
        if _pairs(e, t, d) < need or _pairs(e, t, d) == 0:
            continue
        r = angle_rmse_at_delay(estimate, truth, d)
        if np.isfinite(r) and (
            r < best[0] - 1e-12 or (abs(r - best[0]) <= 1e-12 and abs(d) < abs(best[1]))
        ):
            best = (r, d)
    return best if np.isfinite(best[0]) else (float("nan"), 0)
