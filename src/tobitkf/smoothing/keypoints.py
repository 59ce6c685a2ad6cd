"""How a method sees any sequence: lengths in metres, three axes, confidence applied.

Every method was written for Kinect-like 3-D tracks in metres. :func:`tobitkf.smooth`
hands it any sequence through this module:

* **units** — positions in a length unit (``"mm"``, ``"cm"``) are converted to metres
  before the method runs and its output (positions, std) converted back, so the methods'
  metric parameters (m, m/s) keep their meaning. Pixels and unknown units are passed as
  they are: the robust methods then take their gates from the recording itself
  (:mod:`tobitkf.smoothing.robust_scale`), the other methods read their parameters in
  the data's units.
* **2-D** — a (T, J, 2) sequence gets a third axis of zeros (NaN where the sample is
  missing): distances, gates and per-axis filters are unchanged by an axis that is
  always 0, and the axis is dropped from the output.
* **confidence** — a sample whose confidence is below ``min_confidence`` is missing
  (:data:`DEFAULT_MIN_CONFIDENCE`); the others keep their confidence for the methods
  that weigh samples by it (``robust``, ``robust_online``: docs/robust.md).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.skeleton.sequence import KNOWN_UNITS
from tobitkf.smoothing.params import nonneg_float
from tobitkf.smoothing.timebase import measurements

__all__ = [
    "DEFAULT_MIN_CONFIDENCE",
    "check_min_confidence",
    "drop_third_axis",
    "length_scale",
    "low_confidence",
    "pad_third_axis",
]

Array = NDArray[np.float64]

#: samples whose confidence is below this are missing. A pose estimator's score under
#: 0.1 says the part was, by the estimator's own account, almost certainly not found
#: there (DeepLabCut's likelihood, SLEAP's point score and OpenPose's part confidence are
#: peak heights of a part's score map); between 0.1 and 1 the score weighs the sample.
DEFAULT_MIN_CONFIDENCE = 0.1


def check_min_confidence(value: Any) -> float:
    """``min_confidence`` in [0, 1]."""
    v = nonneg_float("min_confidence", value)
    if v > 1:
        raise ValueError(f"min_confidence must be in [0, 1], got {value!r}")
    return v


def length_scale(units: str | None) -> float | None:
    """Metres per unit for a length unit other than metres, 1.0 for metres, None for
    pixels and unknown units (nothing to convert)."""
    return None if units is None else KNOWN_UNITS.get(units)


def low_confidence(confidence: Array | None, threshold: float) -> NDArray[np.bool_] | None:
    """Samples whose confidence is below ``threshold`` (NaN = no confidence: kept)."""
    if confidence is None or threshold <= 0:
        return None
    with np.errstate(invalid="ignore"):
        return np.asarray(confidence) < threshold


def method_view(
    positions: Array,
    units: str | None,
    states: Any,
    confidence: Array | None,
    min_conf: float,
    *,
    owned: bool = False,
) -> tuple[float | None, Array, Array, NDArray[np.bool_]]:
    """What a method sees of ``positions (T, ..., D)``: lengths in metres, three axes,
    samples below ``min_conf`` missing. Returns the metres per unit (None: pixels or
    unknown units, left as they are), the converted positions, the measurements (NaN where
    missing, NOT_TRACKED or below ``min_conf``) and the missing mask. ``owned``:
    ``positions`` is the caller's own copy, converted in place (no second copy)."""
    scale = length_scale(units)
    if scale is not None and scale != 1.0:
        if owned:
            positions *= scale
        else:
            positions = positions * scale
    positions = pad_third_axis(positions)
    ys, missing = measurements(positions, states)
    low = low_confidence(confidence, min_conf)
    if low is not None and (low & ~missing).any():
        missing = missing | low
        ys = np.where(missing[..., None], np.nan, ys)
    return scale, positions, ys, missing


def pad_third_axis(positions: Array) -> Array:
    """(..., 2) -> (..., 3) with a third coordinate 0 (NaN where the sample is missing);
    3-D positions are returned as they are."""
    if positions.shape[-1] == 3:
        return positions
    zero = np.where(np.isnan(positions).any(axis=-1), np.nan, 0.0)
    return np.concatenate([positions, zero[..., None]], axis=-1)


def drop_third_axis(positions: Array, n_dims: int) -> Array:
    """The first ``n_dims`` coordinates of a method's (..., 3) output."""
    return positions if n_dims == 3 else np.ascontiguousarray(positions[..., :n_dims])
