"""The size of a body: a unit that cannot be right, a magnitude no arithmetic holds.

**A recording said to be in metres whose size says otherwise.** The methods' constants
in a length unit are physical (the robust gates: a hand moves at most 8 m/s, a bone
keeps its length to 3 cm + 15 %; the Kalman methods' noise; the Kinect's limits). A 3-D
file that states no unit is read as metres (a CSV without its sidecar, an array given to
:class:`~tobitkf.SkeletonSequence`), so a track in millimetres would be gated as if its
person were a thousand times larger and faster: every sample rejected, the output the
input, and nothing said. The size of the body tells the unit apart without any threshold
tuned to a data set: a person's joints lie some decimetres from their centre (an
animal's from millimetres to a metre or two), and no tracked body's lie
:data:`MAX_BODY_RADIUS_M` (10 m) from it, while a person's in centimetres lie some tens
of "metres" from it, in millimetres some hundreds.

**A magnitude the arithmetic cannot hold.** In any unit, the smoothers square the
coordinates' differences (variances) and multiply variances (likelihoods, gains): a track
whose size is near the floating-point range's ends (``1e-150`` or ``1e200`` units)
underflows to zero or overflows, and the output is NaN or an error deep inside. A body
whose samples spread (:func:`body_extent`: over its joints and frames together, so a
single moving point has one too) less than :data:`MIN_BODY_RADIUS` but more than
nothing, or any of whose coordinates exceeds :data:`MAX_BODY_RADIUS` in magnitude
(``1e-50`` and ``1e50`` units: their fourth powers are still ordinary doubles), is
refused with the reason. Both are read on :data:`MAX_FRAMES` frames spread over the
recording, as the size in metres is: a body that size is so in every frame, and a lone
sample beyond the bound elsewhere is a glitch (the robust gates reject it, and every
method's output stays finite). A body that
does not move and has one point (all its samples equal) is left alone: there is nothing
to square.

:func:`check_body_scale` raises a :class:`ValueError` that says which and how to fix it
(every method's batch run and the live smoother call it); :func:`body_radius` is the
statistic. Pure numpy, no I/O.
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import NDArray

from tobitkf.smoothing.robust_scale import nanmedian_last

__all__ = [
    "MAX_BODY_RADIUS",
    "MAX_BODY_RADIUS_M",
    "MIN_BODY_RADIUS",
    "PERSON_UNITS",
    "TYPICAL_BODY_RADIUS_M",
    "body_extent",
    "body_radius",
    "check_body_scale",
    "person_unit",
    "unstated_unit_note",
]

#: no tracked body's joints lie this far (m) from their centre, on average
MAX_BODY_RADIUS_M = 10.0
#: the spreads and magnitudes (any unit) whose fourth powers are ordinary doubles, with
#: a margin
MIN_BODY_RADIUS = 1e-50
MAX_BODY_RADIUS = 1e50
#: about where a person's joints lie (m) from their centre, on average (the message's
#: comparison): a standing adult's 25 Kinect joints, head and feet included
TYPICAL_BODY_RADIUS_M = 0.4
#: frames read per body at most, evenly spread (a body's size is in every frame)
MAX_FRAMES = 16


def _frames(ys: NDArray[np.floating]) -> NDArray[np.floating]:
    """At most :data:`MAX_FRAMES` frames of ``ys``, evenly spread: a sample of the frames
    tells the size as the whole recording does, at a cost that does not grow with it."""
    T = ys.shape[0]
    if T <= MAX_FRAMES:
        return ys
    return ys[np.linspace(0, T - 1, MAX_FRAMES).round().astype(int)]


def body_radius(ys: NDArray[np.floating]) -> NDArray[np.floating]:
    """Per body, the median over frames of the mean distance of the joints from their
    mean point: ``ys (T, B, J, D)``, NaN where a joint is missing; ``(B,)``, NaN for a
    body with no frame of two joints or more."""
    y = _frames(ys)
    present = np.isfinite(y).all(axis=-1)  # (T, B, J)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN slices: NaN
        centre = np.nanmean(y, axis=2, keepdims=True)
        per_frame = np.nanmean(np.linalg.norm(y - centre, axis=-1), axis=2)  # (T, B)
        per_frame[present.sum(axis=2) < 2] = np.nan  # one joint: no size
        return nanmedian_last(per_frame.T)


def body_extent(ys: NDArray[np.floating]) -> NDArray[np.floating]:
    """Per body, the mean distance of all its samples (every joint, every frame) from
    their mean point: ``ys (T, B, J, D)``, NaN where missing; ``(B,)``, NaN for a body
    with no sample."""
    y = _frames(ys)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN slices: NaN
        centre = np.nanmean(y, axis=(0, 2), keepdims=True)
        return np.nanmean(np.linalg.norm(y - centre, axis=-1), axis=(0, 2))


#: the length units a person's size is told apart in: name, symbol, units per metre
PERSON_UNITS = (("metres", "m", 1.0), ("centimetres", "cm", 100.0), ("millimetres", "mm", 1000.0))


def person_unit(radius: float) -> tuple[str, str] | None:
    """The unit (name, symbol) in which a person's body has this radius (the mean
    distance of its joints from their centre, :func:`body_radius`): the one of
    :data:`PERSON_UNITS` whose :data:`TYPICAL_BODY_RADIUS_M` it is within half a decade
    of (nearer it than any other); None for a radius near none of them (or NaN)."""
    if not radius > 0:
        return None
    ratio = radius / TYPICAL_BODY_RADIUS_M
    for name, symbol, factor in PERSON_UNITS:
        if abs(np.log10(ratio / factor)) <= 0.5:
            return name, symbol
    return None


def _looks_like(radius: float) -> str:
    """The unit a body of this radius in "metres" most likely is in."""
    unit = person_unit(radius)
    if unit is not None and unit[1] != "m":
        return f"they look like {unit[0]}"
    return "they are not metres"


def unstated_unit_note(radius: NDArray[np.floating], units: str | None, n_dims: int) -> str | None:
    """What to tell about a track whose bodies have ``radius`` (:func:`body_radius`,
    per body): when it is 3-D, states no length unit (``units`` None) and its median
    size is a person's in metres, centimetres or millimetres (:func:`person_unit`),
    that this unit declared would let the methods' physical constants apply; else None
    (2-D keypoints are image positions, and a size like no person's in any of them says
    nothing about the unit)."""
    if units is not None or n_dims != 3:
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # every body NaN
        r = float(np.nanmedian(radius)) if np.size(radius) else float("nan")
    unit = person_unit(r)
    if unit is None:
        return None
    name, symbol = unit
    return (
        f"the positions state no length unit, and their joints lie {r:.3g} units from "
        f"their centre on average, as a person's do in {name} "
        f"(about {TYPICAL_BODY_RADIUS_M} m): if they are {name}, declare it "
        f"(units='{symbol}'; --units {symbol} of tobitkf smooth / evaluate / report) so "
        "that the methods' physical constants apply. Without a unit the robust methods "
        "measure their gates on the recording itself and the Kalman methods take their "
        "constants in the data's unit"
    )


def check_body_scale(ys: NDArray[np.floating], metres: bool) -> NDArray[np.floating]:
    """Raise ``ValueError`` when a body of ``ys (T, B, J, D)`` has a size no arithmetic
    holds, or, in metres (``metres``: as declared or converted), its joints lie more than
    :data:`MAX_BODY_RADIUS_M` from their centre on average; else return
    :func:`body_radius`.

    The message names the body, its size and how to fix it (the unit it looks like).
    """
    if ys.size == 0:  # no frame (or no joint): no size to judge
        return np.full(ys.shape[1], np.nan)
    y = _frames(ys)  # what follows reads these frames only: its cost does not grow with T
    # (a lone huge sample elsewhere is a glitch, for the gates; a body is huge everywhere)
    peak = np.fmax(np.fmax.reduce(y, axis=(0, 2, 3)), -np.fmin.reduce(y, axis=(0, 2, 3)))
    peak = np.nan_to_num(peak, nan=0.0)  # a body with no sample
    huge = peak > MAX_BODY_RADIUS
    # the spread of the bodies within bounds (beyond them the norms would overflow)
    extent = body_extent(np.where(huge[None, :, None, None], 0.0, y))
    small = (extent > 0) & (extent < MIN_BODY_RADIUS)
    beyond = np.flatnonzero(small | huge)
    if len(beyond):
        b = int(beyond[0])
        which = f"body {b}" if len(extent) > 1 else "the body"
        what = f"reaches {peak[b]:.3g}" if huge[b] else f"spreads {extent[b]:.3g}"
        raise ValueError(
            f"{which} {what} {'m' if metres else 'units'}: beyond what the smoothers' "
            f"arithmetic holds (their variances under- or overflow); give the positions in "
            f"a unit in which a body spreads more than {MIN_BODY_RADIUS:g} and no "
            f"coordinate exceeds {MAX_BODY_RADIUS:g}"
        )
    radius = body_radius(y)
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero(metres & (radius > MAX_BODY_RADIUS_M))
    if not len(bad):
        return radius
    b = int(bad[0])
    r = float(radius[b])
    body = f"body {b}'s joints lie" if len(radius) > 1 else "the joints lie"
    raise ValueError(
        f"the positions are taken as metres, but {body} {r:.3g} m from their centre on "
        f"average, where a person's lie about {TYPICAL_BODY_RADIUS_M} m: {_looks_like(r)}. "
        "The methods' speeds, noise and limits are physical, so declare the unit the data "
        "are in: SkeletonSequence(..., units='mm') or seq.replace(units='mm'); "
        "LiveSmoother(..., units='mm') for a stream; --units mm of "
        "tobitkf smooth / evaluate / report for a file that states none (a CSV without its "
        "sidecar, an array); units=None (unknown) takes the gates from the recording itself"
    )
