"""Identity swaps between bodies and left/right swaps within one, undone before gating.

Pose estimators swap things the Kinect does not: a tracker gives person A's keypoints
to person B for a few frames (an identity switch), and a 2-D estimator labels the left
wrist as the right one (a left/right swap). Both look like large jumps of several
keypoints at once; the gates would reject them and bridge the gap, but the swapped
samples are good measurements of the *other* identity or joint. Here, frame by frame
and in time order, each frame's samples are assigned to the identities (and to the
joints of each left/right pair) that continue the previous frame best:

* identities: the cost of body ``b``'s samples continuing body ``c`` is the median over
  joints of the distance from ``b``'s sample to ``c``'s last one; a frame is an
  identity exchange when the assignment of least total cost (Hungarian) costs less than
  ``RATIO`` (0.5) times keeping every body and at least ``margin`` less;
* left/right pairs: a frame exchanges a pair when exchanging it costs less than
  ``RATIO`` times keeping it (sum of the two distances to the last samples) and at least
  ``margin`` less; a joint of the pair counts only when one of its two choices is a
  plausible step (``NEAR_FACTOR`` (3) times the recording's 95th percentile of steps):
  after a glitch both are far, and the other joint decides.

Each frame is compared with the samples assigned last (so the end of a swap is found
as its start was); when neither choice is clearly better, the previous frame's choice
stands. Most of a recording is right as detected: a stretch reassigned for longer than
``MAX_SWAP_S`` (2 s) is taken as a spurious exchange (after a gap the last samples are
stale) and left as detected.

"Where the data make it clear": when the two candidates are about as good (bodies or
paired joints close together) nothing changes. ``margin`` is ``MARGIN_SDS`` (3) standard
deviations of the distance between two noisy samples, the noise measured on the
recording (:mod:`tobitkf.smoothing.robust_scale`).

:func:`tobitkf.smooth` runs this before any method with ``untangle="auto"`` (the
default) on sequences in pixels or unknown units — pose-estimator output; Kinect and
motion-capture tracks in metres are left as they are unless ``untangle=True`` — and
reports the frames it changed in ``diagnostics["identity_swapped"]`` (T,) and
``diagnostics["lr_swapped"]`` (T, P) of each output.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.smoothing.robust_scale import _quiet

__all__ = ["MAX_SWAP_S", "NEAR_FACTOR", "RATIO", "untangle", "untangle_sequences"]

Array = NDArray[np.float64]

#: a new assignment must cost less than this times the current one
RATIO = 0.5
#: longest swap undone, s: a tracker's identity switch or a left/right confusion is
#: corrected by the estimator within a second or two; a longer "swap" is more likely a
#: spurious exchange (after a gap, the last samples are stale) than a real one
MAX_SWAP_S = 2.0
#: a plausible step: NEAR_FACTOR times the recording's 95th percentile of frame-to-frame
#: steps (over all joints), plus the margin
NEAR_FACTOR = 3.0


def _assign(cost: Array) -> NDArray[np.intp]:
    """Body index for each identity minimising the total cost (rows: identities)."""
    from scipy.optimize import linear_sum_assignment

    big = np.where(np.isfinite(cost), cost, 1e300)
    rows, cols = linear_sum_assignment(big)
    out = np.arange(cost.shape[0])
    out[rows] = cols
    return out


def _runs_to_undo(changed: NDArray[np.bool_], max_frames: int) -> NDArray[np.bool_]:
    """Frames of the runs of ``changed`` (along axis 0) no longer than ``max_frames``."""
    out = np.zeros_like(changed)
    T = changed.shape[0]
    flat = changed.reshape(T, -1)
    res = out.reshape(T, -1)
    for k in range(flat.shape[1]):
        col = flat[:, k]
        if not col.any():
            continue
        edges = np.flatnonzero(np.diff(np.concatenate([[0], col.astype(np.int8), [0]])))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            if b - a <= max_frames:
                res[a:b, k] = True
    return out


def _kernels() -> Any:
    """The compiled frame loops (imports numba on first use)."""
    from tobitkf.smoothing import _untangle_kernels

    return _untangle_kernels


def untangle(
    ys: Array,
    missing: NDArray[np.bool_],
    pairs: Any,
    margin: float,
    *,
    bodies: bool = True,
    max_frames: int = 60,
    near: float = np.inf,
) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
    """Per-frame body order and left/right exchanges that undo swaps (module docstring).


    Parameters
    ----------
    ys : (T, B, J, D) measurements, NaN where missing.
    missing : (T, B, J).
    pairs : (left, right) joint index pairs.
    margin : least cost improvement (in the data's units) that counts.
    bodies : also undo identity swaps between bodies (B >= 2).
    max_frames : longest swap undone.
    near : longest plausible frame-to-frame step of a joint: a joint of a pair is
        evidence only when one of its two choices is within it.

    Returns
    -------
    order : (T, B) — identity ``a`` takes body ``order[t, a]``'s samples at frame t.
    exchanged : (T, B, P) — pair p of identity a is exchanged at frame t.
    """
    T, B = missing.shape[:2]
    pairs = [(int(a), int(b)) for a, b in pairs]
    P = len(pairs)
    order = np.tile(np.arange(B), (T, 1))
    k = _kernels()
    ys = np.ascontiguousarray(ys, dtype=float)
    if bodies and B == 2:  # keep or exchange: all of it compiled
        k.two_identities(ys, float(margin), RATIO, order)
    elif bodies and B > 2:  # the least-cost assignment of each frame by scipy
        current = np.arange(B)
        last = np.full(ys.shape[1:], np.nan)  # per identity: its last assigned samples
        cost, scratch, ids = np.empty((B, B)), np.empty(ys.shape[2]), np.arange(B)
        for t in range(T):
            y = ys[t]
            k.identity_costs(y, last, cost, scratch)  # cost[a, b]: body b as identity a
            now = cost[ids, current]
            if np.isfinite(cost).all():
                best = _assign(cost)
                new = cost[ids, best].sum()
                if new < RATIO * now.sum() and now.sum() - new > margin:
                    current = best
            order[t] = current
            k.keep_last(np.ascontiguousarray(y[current]), last)
    if bodies and B > 1:
        moved = (order != np.arange(B)).any(axis=1)
        keep_raw = moved & ~_runs_to_undo(moved, max_frames)
        order[keep_raw] = np.arange(B)
    exchanged = np.zeros((T, B, P), dtype=bool)
    if P:
        yo = np.ascontiguousarray(ys[np.arange(T)[:, None], order])  # identity order
        left = np.array([a for a, _ in pairs], dtype=np.intp)
        right = np.array([b for _, b in pairs], dtype=np.intp)
        k.pair_exchanges(yo, left, right, float(margin), float(near), RATIO, exchanged)
        exchanged &= _runs_to_undo(exchanged, max_frames)
    return order, exchanged


def apply(a: Array, order: NDArray[np.intp], exchanged: NDArray[np.bool_], pairs: Any) -> Array:
    """``a`` (T, B, J, ...) reordered: bodies by ``order``, pairs exchanged."""
    T = order.shape[0]
    out = a[np.arange(T)[:, None], order]
    if exchanged.any():
        out = out.copy()
        for p, (left, right) in enumerate(pairs):
            m = exchanged[:, :, p]
            lv, rv = out[:, :, left][m], out[:, :, right][m]
            tmp = out[:, :, left].copy()
            tmp[m] = rv
            tmp2 = out[:, :, right].copy()
            tmp2[m] = lv
            out[:, :, left], out[:, :, right] = tmp, tmp2
    return out


def untangle_sequences(seqs: list[Any]) -> tuple[list[Any], list[dict[str, Any]]]:
    """Sequences of one group (same frames and topology) with swaps undone: positions,
    confidence and tracking states reordered together; and per sequence the frames
    changed (``identity_swapped`` (T,), ``lr_swapped`` (T, P))."""
    from tobitkf.smoothing.robust_scale import MARGIN_SDS, noise_scale

    ys = np.stack([s.positions for s in seqs], axis=1)
    missing = np.isnan(ys).any(axis=-1)
    D = ys.shape[-1]
    pairs = list(seqs[0].topology.symmetry)
    margin = MARGIN_SDS * noise_scale(ys) * np.sqrt(2.0 * D)
    steps = np.diff(seqs[0].times())
    step = float(np.median(steps)) if steps.size and np.median(steps) > 0 else 1 / 30
    max_frames = max(1, round(MAX_SWAP_S / step))
    with _quiet():
        step_q95 = np.nanpercentile(np.linalg.norm(np.diff(ys, axis=0), axis=-1), 95)
    near = NEAR_FACTOR * float(step_q95) + margin if np.isfinite(step_q95) else np.inf
    order, exch = untangle(ys, missing, pairs, margin, max_frames=max_frames, near=near)
    info = [
        {
            "identity_swapped": order[:, a] != a,
            "lr_swapped": exch[:, a],
        }
        for a in range(len(seqs))
    ]
    if (order == np.arange(len(seqs))).all() and not exch.any():
        return seqs, info
    pos = apply(ys, order, exch, pairs)
    out = []
    for a, s in enumerate(seqs):
        fields: dict[str, Any] = {"positions": pos[:, a]}
        for name in ("confidence", "tracking_state"):
            if getattr(s, name) is not None:
                stacked = np.stack([getattr(x, name) for x in seqs], axis=1)
                fields[name] = apply(stacked, order, exch, pairs)[:, a]
        out.append(s.replace(**fields))
    return out, info
