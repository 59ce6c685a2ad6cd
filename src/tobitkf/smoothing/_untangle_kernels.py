"""The frame loops of :mod:`tobitkf.smoothing.untangle`, compiled (numba, ``cache=True``).

Each frame's choice depends on the samples assigned at the frame before, so the loops
run in time order; in NumPy their per-frame overhead was most of the smoothing of a
pose estimator's recording of several people. The arithmetic is NumPy's: distances as
``np.linalg.norm`` (squares summed in axis order), the median of the finite distances
as ``np.nanmedian`` (the middle value, or the mean of the two middle ones), so the
decisions are those of the NumPy form (``tests/test_untangle_kernels.py`` compares).
"""

from __future__ import annotations

import math

import numpy as np

from tobitkf.smoothing._numba_cache import njit
from tobitkf.smoothing._scale_kernels import insert_sorted, middle


@njit(cache=True, nogil=True)
def _distance(y: np.ndarray, x: np.ndarray) -> float:
    """``|y - x|`` over the last axis, NaN when either has a NaN."""
    s = 0.0
    for k in range(y.shape[0]):
        d = y[k] - x[k]
        s += d * d
    return math.sqrt(s)


@njit(cache=True, nogil=True)
def identity_costs(y: np.ndarray, last: np.ndarray, cost: np.ndarray, scratch: np.ndarray) -> None:
    """``cost[a, b]``: the median over joints of the distance from body ``b``'s sample in
    ``y (B, J, D)`` to identity ``a``'s last one in ``last``, joints with a NaN left out
    (NaN when none is left)."""
    B, J = y.shape[0], y.shape[1]
    for a in range(B):
        for b in range(B):
            n = 0
            for j in range(J):
                d = _distance(y[b, j], last[a, j])
                if not math.isnan(d):  # (np.sort would compile numba's quicksort:
                    insert_sorted(scratch, n, d)  # seconds of a first run)
                    n += 1
            cost[a, b] = middle(scratch, n)


@njit(cache=True, nogil=True)
def keep_last1(y: np.ndarray, last: np.ndarray) -> None:
    """``last[j] = y[j]`` where the sample has no NaN (one body, ``(J, D)``)."""
    J, D = y.shape
    for j in range(J):
        ok = True
        for k in range(D):
            if math.isnan(y[j, k]):
                ok = False
        if ok:
            for k in range(D):
                last[j, k] = y[j, k]


@njit(cache=True, nogil=True)
def keep_last(y: np.ndarray, last: np.ndarray) -> None:
    """``last[b, j] = y[b, j]`` where the sample has no NaN."""
    for b in range(y.shape[0]):
        keep_last1(y[b], last[b])


@njit(cache=True, nogil=True)
def _plausible(near: float, margin: float, age: int, factor: float) -> float:
    """The longest plausible step from a reference stored ``age`` frames before the last
    one: ``near`` (``factor`` typical steps plus the noise's ``margin``), and a typical
    step, ``(near - margin) / factor``, more for each frame since; infinite without
    statistics."""
    if not math.isfinite(near):
        return math.inf
    return near + (near - margin) / factor * age


@njit(cache=True, nogil=True)
def _predicted(last: np.ndarray, age: np.ndarray, vel: np.ndarray, j: int, k: int) -> float:
    """Where joint ``j``'s reference is expected this frame, axis ``k``: the reference
    moved on by its velocity when it was stored at the last frame and has one, else the
    reference itself (after a glitch or a gap the velocity is old)."""
    v = vel[j, k]
    if age[j] == 0 and not math.isnan(v):
        return last[j, k] + v
    return last[j, k]


@njit(cache=True, nogil=True)
def pair_step(
    yo: np.ndarray,
    last: np.ndarray,
    age: np.ndarray,
    vel: np.ndarray,
    state: np.ndarray,
    run: np.ndarray,
    left: np.ndarray,
    right: np.ndarray,
    margin: float,
    near: float,
    near_factor: float,
    ratio: float,
    max_frames: int,
    yc: np.ndarray,
    pred: np.ndarray,
) -> None:
    """One frame of the left/right loop for one identity: its samples ``yo (J, D)``
    against ``last (J, D)``, its last samples with the pairs corrected that were a
    plausible step (updated; ``age (J,)``: frames since each was stored, updated;
    ``vel (J, D)``: the pair joints' velocity per frame when they were stored, NaN
    unknown, updated; ``near_factor``: the typical steps ``near`` allows beyond the
    margin), into ``state (P,)``, whether each pair is exchanged (updated). ``run (P,)``
    counts the frames each pair has been exchanged; one exchanged for more than
    ``max_frames`` is taken as detected again (the causal form; offline, ``max_frames``
    is never reached). ``yc (J, D)``: work; ``pred (J, D)``: work, where each pair joint
    is expected (:func:`_predicted`), which the samples are compared with."""
    D = yo.shape[1]
    for p in range(left.shape[0]):
        for j in (left[p], right[p]):
            for k in range(D):
                pred[j, k] = _predicted(last, age, vel, j, k)
    for p in range(left.shape[0]):
        lj, rj = left[p], right[p]
        nl = _plausible(near, margin, age[lj], near_factor)
        nr = _plausible(near, margin, age[rj], near_factor)
        kl = _distance(yo[lj], pred[lj])
        sl = _distance(yo[lj], pred[rj])
        kr = _distance(yo[rj], pred[rj])
        sr = _distance(yo[rj], pred[lj])
        # a joint counts when both choices are measured and one is a plausible step
        okl = math.isfinite(kl) and math.isfinite(sl) and (kl <= nl or sl <= nr)
        okr = math.isfinite(kr) and math.isfinite(sr) and (kr <= nr or sr <= nl)
        # (with neither joint counting, both are 0 and nothing is clear)
        keep = (kl if okl else 0.0) + (kr if okr else 0.0)
        swap = (sl if okl else 0.0) + (sr if okr else 0.0)
        if swap < ratio * keep and keep - swap > margin:
            state[p] = True
        elif keep < ratio * swap and swap - keep > margin:
            state[p] = False
        run[p] = run[p] + 1 if state[p] else 0
        if run[p] > max_frames:  # taken as detected: the loop goes on from these samples
            state[p] = False
            run[p] = -1
    for j in range(yo.shape[0]):  # (loops, not slice assignments: those compile numba's
        for k in range(D):  # error message for a shape mismatch, seconds of a first run)
            yc[j, k] = yo[j, k]
    for p in range(left.shape[0]):
        if state[p]:
            for k in range(yo.shape[1]):
                yc[left[p], k] = yo[right[p], k]
                yc[right[p], k] = yo[left[p], k]
    # a pair's joint keeps its reference where its corrected sample is not a plausible
    # step from where it was expected (a glitch is no reference: the next frames are
    # compared with the sample before it), except where an exchange was just taken as
    # detected; every other sample is stored as it comes, and a pair joint stored anew
    # gets the velocity of its step from the reference it replaces (per frame since)
    for p in range(left.shape[0]):
        rebase = run[p] < 0
        run[p] = max(run[p], 0)
        for j in (left[p], right[p]):
            d = _distance(yc[j], pred[j])
            if rebase and not math.isnan(yc[j, 0]):
                age[j] = 0
                for k in range(D):  # the step from the reference crosses sides
                    vel[j, k] = math.nan
            elif math.isnan(d):  # no sample, or no reference yet
                if math.isnan(last[j, 0]):
                    age[j] = 0
                else:
                    age[j] += 1
                    for k in range(D):
                        yc[j, k] = last[j, k]
            elif d > _plausible(near, margin, age[j], near_factor):
                age[j] += 1
                for k in range(D):
                    yc[j, k] = last[j, k]
            else:
                for k in range(D):
                    vel[j, k] = (yc[j, k] - last[j, k]) / (age[j] + 1)
                age[j] = 0
    keep_last1(yc, last)


@njit(cache=True, nogil=True)
def pair_exchanges(
    yo: np.ndarray,
    left: np.ndarray,
    right: np.ndarray,
    margin: float,
    near: float,
    near_factor: float,
    ratio: float,
    exchanged: np.ndarray,
) -> None:
    """The left/right loop of :func:`~tobitkf.smoothing.untangle.untangle`: for each
    frame of ``yo (T, B, J, D)`` (bodies in identity order), each body and pair, whether
    the pair is exchanged (written into ``exchanged (T, B, P)``), against the samples as
    corrected at the frames before."""
    T, B, J, D = yo.shape
    P = left.shape[0]
    state = np.zeros((B, P), dtype=np.bool_)
    run = np.zeros((B, P), dtype=np.int64)
    last = np.full((B, J, D), np.nan)
    age = np.zeros((B, J), dtype=np.int64)
    vel = np.full((B, J, D), np.nan)
    yc = np.empty((J, D))
    pred = np.empty((J, D))
    never = T + 1  # offline, long exchanges are taken back afterwards (untangle())
    for t in range(T):
        for b in range(B):
            pair_step(yo[t, b], last[b], age[b], vel[b], state[b], run[b], left, right,
                      margin, near, near_factor, ratio, never, yc, pred)  # fmt: skip
            for p in range(P):
                exchanged[t, b, p] = state[b, p]


@njit(cache=True, nogil=True)
def two_choice(cost: np.ndarray, c0: int, c1: int, margin: float, ratio: float) -> tuple:
    """One frame's decision of the two-body identity loop: keep the current order
    ``(c0, c1)`` or take the cheaper of keeping and exchanging the bodies, when it costs
    less than ``ratio`` times the current one and at least ``margin`` less (an exact tie
    changes nothing, whichever is taken: the new cost is then the current one). A NaN
    cost, a body or identity without samples, fails every comparison: the current order
    stays, as where scipy is not asked."""
    keep = cost[0, 0] + cost[1, 1]
    swap = cost[0, 1] + cost[1, 0]
    b0, b1 = (0, 1) if keep <= swap else (1, 0)
    new = cost[0, b0] + cost[1, b1]
    now = cost[0, c0] + cost[1, c1]
    if new < ratio * now and now - new > margin:
        return b0, b1
    return c0, c1


@njit(cache=True, nogil=True)
def two_identities(ys: np.ndarray, margin: float, ratio: float, order: np.ndarray) -> None:
    """The identity loop of :func:`~tobitkf.smoothing.untangle.untangle` for two bodies,
    whose least-cost assignment is one of two: keep them, or exchange them
    (:func:`two_choice`). Writes ``order (T, 2)``."""
    T, _, J, D = ys.shape
    last = np.full((2, J, D), np.nan)
    cost = np.empty((2, 2))
    scratch = np.empty(J)
    y = np.empty((2, J, D))
    c0, c1 = 0, 1
    for t in range(T):
        identity_costs(ys[t], last, cost, scratch)
        c0, c1 = two_choice(cost, c0, c1, margin, ratio)
        order[t, 0], order[t, 1] = c0, c1
        for j in range(J):  # (loops: a slice assignment compiles an error message)
            for k in range(D):
                y[0, j, k], y[1, j, k] = ys[t, c0, j, k], ys[t, c1, j, k]
        keep_last(y, last)
