"""Errors that samples share, in the offline robust smoother's standard deviation.

(Online, ``robust_online`` adds both the causal way, from the frames so far:
``shared_frame``, ``guess_frame`` and the indicator filters in
:mod:`tobitkf.smoothing._robust_kernels`, docs/robust.md.)

Two kinds of samples the smoother uses are not independent measurements of the joint:

* a joint the sensor only **guessed** (Kinect's ``INFERRED``: an occluded hand or foot):
  the guess's error stays for as long as the occlusion lasts;
* a **carried** sample (a rejected joint placed at its parent plus its last good offset,
  :func:`~tobitkf.smoothing.robust_gating.carry_with_parent`): its error is how far the
  joint has turned about its parent since that offset was seen, the same turn for the
  whole stretch.

The smoother treats them as independent (a guess with ``inferred_noise_factor`` times the
measurement variance, a carried sample with its bone's length counted once per ``tau``),
so after a stretch of them its posterior variance claims a precision they do not have.
The estimate is left as it is; its reported standard deviation gets the errors that
averaging does not remove.

**How much the estimate rests on them.** The smoother is linear in its samples, with
gains that do not depend on their values. Run on a signal that is ``σ_i`` at each such
sample (the standard deviation of its error) and 0 at every other sample, it gives at
each frame ``Σ w_i σ_i``, the weights being those its estimate puts on the samples: 0 far
from them, the samples' own σ in the middle of a long stretch. The samples of a stretch
share one error, so the per-axis variance added is ``(Σ w_i σ_i)²``; guesses and carried
samples are added as two independent errors. The two signals are two more axes of the
smoother's own run (:func:`shared_signal` gives its input), which share its gains.

**How far off the guesses are, from the recording.** Where a joint's state changes
between tracked and inferred, the step between the two samples carries the guess's
error on top of the joint's motion and noise. Per body, over the steps whose two samples
the gates accepted,

    s² = (mean |step|² at a change of state − mean |step|² between tracked samples) / D

(the tracked steps of the joints that have guesses) is the per-axis variance of the
guesses' error (``D`` = 2 or 3 coordinates; 0 when the changes are no larger than
ordinary steps). Fewer than :data:`MIN_CHANGES` such steps: no estimate, nothing added.

**How far a carried joint may have turned, from the recording.** The joint's offset
from its parent, ``o(t)``, is known where both were accepted. Its structure function
``S(Δ) = mean |o(t + Δ) − o(t)|²`` over those pairs is what carrying an offset for ``Δ``
frames gets wrong, on average, in this recording. A carried sample ``Δ`` frames from the
offset it carries (the last good one, or the next for a stretch with none before) has
per-axis ``σ² = S(Δ) / D``; where its parent is carried too, the parent's ``σ²`` is added
(the two turns are independent). Each lag is read from at most :data:`MAX_STARTS`
start frames spread evenly over the recording, so the cost per joint is bounded; lags
with fewer than :data:`MIN_PAIRS` pairs, and lags beyond ``max_lag``, take the
stationary limit ``2 Var(o)``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.smoothing.timebase import readonly, typical_step

__all__ = [
    "MAX_LAG_FRAMES",
    "MAX_STARTS",
    "MIN_CHANGES",
    "MIN_PAIRS",
    "carried_error_sd",
    "guess_error_variance",
    "max_lag_frames",
    "shared_signal",
]

Array = NDArray[np.float64]

#: a body needs this many accepted steps at a change of tracking state for an estimate
MIN_CHANGES = 6
#: a lag of the offset's structure function needs this many pairs
MIN_PAIRS = 10
#: the structure function is read up to this many frames at most (20 s at 30 fps; its
#: cost grows with the lags), beyond it the stationary limit
MAX_LAG_FRAMES = 600
#: each lag of the structure function is read from at most this many start frames,
#: evenly spread (its cost per joint stays bounded however long the recording)
MAX_STARTS = 300


def guess_error_variance(
    ys: Array, acc: NDArray[np.bool_], inferred: NDArray[np.bool_]
) -> tuple[Array, NDArray[np.int64]]:
    """Per body, the per-axis variance of the guesses' error (module docstring) and the
    number of steps at a change of state it rests on: ``ys (T, B, J, D)`` the samples
    the smoother saw, ``acc (T, B, J)`` accepted by the gates, ``inferred (T, B, J)``.
    NaN where fewer than :data:`MIN_CHANGES` steps."""
    sums = _kernels().guess_sums(np.ascontiguousarray(ys, dtype=float),
                                 np.ascontiguousarray(acc, dtype=bool),
                                 np.ascontiguousarray(inferred, dtype=bool))  # fmt: skip
    n_c, n_t = sums[:, 1].astype(np.int64), sums[:, 3].astype(np.int64)
    mc = sums[:, 0] / np.maximum(n_c, 1)
    mt = sums[:, 2] / np.maximum(n_t, 1)
    s2 = np.maximum(mc - mt, 0.0) / ys.shape[-1]
    return np.where((n_c >= MIN_CHANGES) & (n_t > 0), s2, np.nan), n_c


def _kernels() -> Any:
    """The compiled kernels (imports numba on first use)."""
    from tobitkf.smoothing import _shared_kernels

    return _shared_kernels


def max_lag_frames(max_seconds: float, steps: Array) -> int:
    """The longest lag of the structure function read from the data, in frames: the
    longest believable failure ``max_seconds`` (``max_reject``) at the recording's typical
    step, at least 1 and at most :data:`MAX_LAG_FRAMES`; beyond it the stationary limit."""
    dt = typical_step(steps)
    lags = max_seconds / dt if dt > 0 else math.inf
    return max(1, math.ceil(min(lags, MAX_LAG_FRAMES)))


def carried_error_sd(
    ys: Array,
    acc: NDArray[np.bool_],
    carried: NDArray[np.bool_],
    parents: NDArray[np.int64],
    order: NDArray[np.int64],
    max_lag: int,
) -> Array:
    """The per-axis standard deviation of each carried sample's error (module docstring),
    NaN at every other sample: ``ys (T, B, J, D)``, ``acc`` the accepted samples,
    ``carried (T, B, J)`` the carried ones; ``order`` the joints from the root outwards;
    ``max_lag`` frames (at least 1) the longest lag of the structure function read from
    the data."""
    return _kernels().carried_sd(  # ys read-only whatever the caller's: one compiled version
        readonly(np.ascontiguousarray(ys, dtype=float)), np.ascontiguousarray(acc, dtype=bool),
        np.ascontiguousarray(carried, dtype=bool), np.ascontiguousarray(parents, dtype=np.int64),
        np.ascontiguousarray(order, dtype=np.int64), int(max_lag), MIN_PAIRS, MAX_STARTS,
    )  # fmt: skip


def shared_signal(guess_sd: Array | None, carried_sd: Array | None,
                  shape: tuple[int, ...]) -> Array | None:  # fmt: skip
    """The smoother's ``shared`` input (``smooth_run`` of the noise kernels): the guesses'
    ``σ_i`` positive, the carried samples' negative, 0 elsewhere (the two kinds are never
    at one sample: a guess was accepted, a carried sample was not); ``guess_sd`` and
    ``carried_sd`` ``(T, B, J)`` NaN except at their samples, or None. None when both
    are None: nothing to add."""
    if guess_sd is None and carried_sd is None:
        return None
    out = np.zeros(shape)
    if guess_sd is not None:
        np.copyto(out, guess_sd, where=np.isfinite(guess_sd))
    if carried_sd is not None:
        np.copyto(out, -carried_sd, where=np.isfinite(carried_sd))
    return out
