"""The error of the sensor's guesses in the offline robust smoother's standard deviation.

A joint the sensor only guessed (Kinect's ``INFERRED``: an occluded hand or foot) is not
a noisy measurement of the joint: it is a guess whose error stays for as long as the
occlusion lasts. The smoother gives each such sample ``inferred_noise_factor`` times the
measurement variance and treats the samples as independent, so after twenty of them its
posterior variance says the joint is known to a few millimetres while the guess may be
centimetres off. The estimate is left as it is; its reported standard deviation gets the
guesses' error that averaging does not remove.

**How far off the guesses are, from the recording.** When a joint's state changes
between tracked and inferred, the step between the two samples carries the guess's
error on top of the joint's motion and noise. Per body, over the joints that have
inferred samples and over the steps where both samples were accepted by the gates,

    s² = (mean |step|² at a change of state − mean |step|² between tracked samples) / D

is the per-axis variance of the guesses' error (``D`` = 2 or 3 coordinates; 0 when the
changes are no larger than ordinary steps). Fewer than :data:`MIN_CHANGES` such steps:
no estimate (the standard deviation is left as it was), and the diagnostics say so.

**How much the estimate rests on the guesses.** The smoother is linear in its samples
with gains that do not depend on their values, so running it on a signal that is 1 at
the inferred samples it used and 0 at every other sample gives, at each frame, ``w``:
the total weight the estimate puts on the guesses (0 far from them, about 1 in the
middle of a long occlusion). The guesses of one occlusion share one error, so it is
not averaged away: the per-axis variance added is ``w² s²``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["MIN_CHANGES", "add_guess_error", "guess_error_variance"]

Array = NDArray[np.float64]

#: a body needs this many accepted steps at a change of tracking state for an estimate
MIN_CHANGES = 6


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
    """Per body, the sum of ``x (T, B, J)``, each body's in the same order whatever the
    other bodies (a chunk of bodies gives the bits of the whole batch)."""
    B = x.shape[1]
    return np.ascontiguousarray(np.moveaxis(x, 1, 0)).reshape(B, -1).sum(axis=1)


def add_guess_error(
    smooth: Any,
    yk: Array,
    rvar: Array,
    steps: Array,
    q: Array,
    sc2: Array,
    tau: float,
    tau_c: Array,
    used: NDArray[np.bool_],
    s2: Array,
    var: Array,
    b0: int,
) -> None:
    """Add ``w² s²`` to ``var (T, B0, J)`` (bodies from ``b0``): ``smooth`` the smoother
    (``smooth_run`` of the noise kernels), ``yk``, ``rvar``, ``steps``, ``q``, ``sc2``,
    ``tau``, ``tau_c`` its inputs, ``used (T, B, J)`` the inferred samples it used,
    ``s2 (B,)`` the per-axis variance of their error (NaN: nothing added)."""
    cols = used.any(axis=0) & np.isfinite(s2)[:, None]
    if not cols.any():
        return
    bb, jj = np.nonzero(cols)
    T, K = yk.shape[0], bb.size
    present = np.isfinite(yk[:, bb, jj, 0])
    ind = np.where(used[:, bb, jj], 1.0, np.where(present, 0.0, np.nan))
    sig = np.ascontiguousarray(np.broadcast_to(ind[:, None, :, None], (T, 1, K, 3)))
    w = np.empty((T, 1, K, 3))
    wv = np.empty((T, 1, K))
    smooth(sig, np.ascontiguousarray(rvar[:, bb, jj][:, None]), steps,
           np.ascontiguousarray(q[:, bb, jj][:, None]), np.ascontiguousarray(sc2[bb, jj][None]),
           tau, np.ascontiguousarray(tau_c[bb, jj][None]), w, wv, 0)  # fmt: skip
    var[:, b0 + bb, jj] += w[:, 0, :, 0] ** 2 * s2[bb][None]
