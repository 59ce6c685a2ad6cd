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
samples are added as two independent errors.

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
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.smoothing.timebase import typical_step

__all__ = [
    "MAX_LAG_FRAMES",
    "MAX_STARTS",
    "MIN_CHANGES",
    "MIN_PAIRS",
    "add_shared_errors",
    "carried_error_sd",
    "guess_error_variance",
    "max_lag_frames",
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
    D = ys.shape[-1]
    ok = acc & np.isfinite(ys[..., 0])
    both = ok[1:] & ok[:-1]
    d2 = np.sum(np.diff(ys, axis=0) ** 2, axis=-1)
    d2 = np.where(both, d2, 0.0)
    change = both & (inferred[1:] != inferred[:-1])
    # the tracked steps of the joints with guesses (their motion, not the other joints')
    tracked = both & ~inferred[1:] & ~inferred[:-1] & (inferred & ok).any(axis=0)[None]
    n_c = change.sum(axis=(0, 2))
    n_t = tracked.sum(axis=(0, 2))
    mc = _body_sums(d2 * change) / np.maximum(n_c, 1)
    mt = _body_sums(d2 * tracked) / np.maximum(n_t, 1)
    s2 = np.maximum(mc - mt, 0.0) / D
    return np.where((n_c >= MIN_CHANGES) & (n_t > 0), s2, np.nan), n_c


def _body_sums(x: Array) -> Array:
    """Per body, the sum of ``x (T, B, ...)``, each body's in the same order whatever the
    other bodies (a chunk of bodies gives the bits of the whole batch)."""
    B = x.shape[1]
    return np.ascontiguousarray(np.moveaxis(x, 1, 0)).reshape(B, -1).sum(axis=1)


def _kernels() -> Any:
    """The compiled carried-sample kernel (imports numba on first use)."""
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
    return _kernels().carried_sd(
        np.ascontiguousarray(ys, dtype=float), np.ascontiguousarray(acc, dtype=bool),
        np.ascontiguousarray(carried, dtype=bool), np.ascontiguousarray(parents, dtype=np.int64),
        np.ascontiguousarray(order, dtype=np.int64), int(max_lag), MIN_PAIRS, MAX_STARTS,
    )  # fmt: skip


def add_shared_errors(
    smooth: Any,
    yk: Array,
    rvar: Array,
    steps: Array,
    q: Array,
    sc2: Array,
    tau: float,
    tau_c: Array,
    sds: Sequence[Array],
    var: Array,
    b0: int,
) -> None:
    """Add ``Σ_k (Σ_i w_i σ_ki)²`` to ``var (T, B0, J)`` (bodies from ``b0``): ``smooth``
    the smoother (``smooth_run`` of the noise kernels), ``yk`` .. ``tau_c`` its inputs,
    ``sds`` up to three ``(T, B, J)`` arrays, each the ``σ_i`` of the samples that share
    one kind of error (NaN elsewhere: they count as 0 where ``yk`` has a sample), the
    kinds independent of each other. One smoother run: the kinds are its three axes,
    which share the gains. Columns without such a sample are untouched."""
    if not 1 <= len(sds) <= 3:
        raise ValueError(f"one to three kinds of shared error, got {len(sds)}")
    cols = np.isfinite(sds[0]).any(axis=0)
    for sd in sds[1:]:
        cols |= np.isfinite(sd).any(axis=0)
    if not cols.any():
        return
    bb, jj = np.nonzero(cols)
    T, K, (B, J) = yk.shape[0], bb.size, cols.shape
    n = bb * J + jj  # flat columns: one gather per array
    present = np.isfinite(yk.reshape(T, B * J, -1)[:, n, 0])
    sig = np.zeros((T, 1, K, 3))
    for k, sd in enumerate(sds):
        sig[:, 0, :, k] = np.nan_to_num(sd.reshape(T, B * J)[:, n], nan=0.0)
    sig[:, 0][~present] = np.nan  # no sample: the smoother predicts
    w = np.empty((T, 1, K, 3))
    wv = np.empty((T, 1, K))

    def gather(a: Array) -> Array:  # (T, B, J) -> (T, 1, K), C-contiguous
        return np.ascontiguousarray(a.reshape(T, B * J)[:, n].reshape(T, 1, K))

    smooth(sig, gather(rvar), steps, gather(q), np.reshape(sc2, B * J)[n].reshape(1, K), tau,
           np.reshape(tau_c, B * J)[n].reshape(1, K), w, wv, 0)  # fmt: skip
    wk = w[:, 0, :, : len(sds)]
    var[:, b0 + bb, jj] += np.einsum("tkc,tkc->tk", wk, wk)
