"""The compiled frame loops of the untangling (``_untangle_kernels``) against the NumPy
form they replaced, kept here as the reference: the same body orders and left/right
exchanges, frame for frame, on two and three people in 2-D and 3-D with identity
switches, left/right swaps, glitches and missing samples."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import tobitkf as tk
from tobitkf.smoothing.untangle import (
    NEAR_FACTOR,
    RATIO,
    _assign,
    _runs_to_undo,
    settle,
    untangle,
)


def _nanmedian(d):
    with warnings.catch_warnings(), np.errstate(invalid="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(d, axis=-1)


def _last_valid(y, last):
    ok = ~np.isnan(y).any(axis=-1)
    last[ok] = y[ok]


def _reference(
    ys,
    missing,
    pairs,
    margin,
    *,
    bodies=True,
    max_frames=60,
    near=np.inf,
    undo=True,
):
    T, B = missing.shape[:2]
    pairs = [(int(a), int(b)) for a, b in pairs]
    P = len(pairs)
    order = np.tile(np.arange(B), (T, 1))
    if bodies and B > 1:
        current = np.arange(B)
        last = np.full(ys.shape[1:], np.nan)  # per identity: its last assigned samples
        for t in range(T):
            y = ys[t]
            d = np.linalg.norm(y[None, :] - last[:, None], axis=-1)  # (B, B, J)
            cost = _nanmedian(d)  # cost[a, b]: body b as identity a
            now = cost[np.arange(B), current]
            if np.isfinite(now).all() and np.isfinite(cost).all():
                best = _assign(cost)
                new = cost[np.arange(B), best].sum()
                if new < RATIO * now.sum() and now.sum() - new > margin:
                    current = best
            order[t] = current
            _last_valid(y[current], last)
        moved = (order != np.arange(B)).any(axis=1)
        keep_raw = moved & ~_runs_to_undo(moved, max_frames)
        order[keep_raw] = np.arange(B)
    exchanged = np.zeros((T, B, P), dtype=bool)
    if P:
        yo = ys[np.arange(T)[:, None], order]  # identity order
        left = np.array([a for a, _ in pairs], dtype=np.intp)
        right = np.array([b for _, b in pairs], dtype=np.intp)
        state = np.zeros((B, P), dtype=bool)
        last = np.full(ys.shape[1:], np.nan)  # corrected, plausible steps only
        age = np.zeros(ys.shape[1:3], dtype=int)  # frames since each was stored
        vel = np.full(ys.shape[1:], np.nan)  # per frame, when stored after a reference
        bi, pi = np.nonzero(np.ones((B, P), dtype=bool))
        step = (near - margin) / NEAR_FACTOR if np.isfinite(near) else 0.0
        js = np.concatenate([left, right])
        for t in range(T):
            y = yo[t]
            # where each joint is expected: its reference moved on by the velocity it was
            # stored with at the last frame (none after a hold or without one)
            moving = (age == 0)[..., None] & ~np.isnan(vel)
            pred = np.where(moving, last + np.where(moving, vel, 0.0), last)
            yl, yr = y[:, left], y[:, right]
            ll, lr_ = pred[:, left], pred[:, right]
            # the plausible step from a reference grows with the frames since it was stored
            nl, nr = near + step * age[:, left], near + step * age[:, right]
            # a joint of the pair counts when it and both last samples are there (a pair
            # with one joint missing is still decided by the other)
            kl, sl = np.linalg.norm(yl - ll, axis=-1), np.linalg.norm(yl - lr_, axis=-1)
            kr, sr = np.linalg.norm(yr - lr_, axis=-1), np.linalg.norm(yr - ll, axis=-1)
            # ... and its evidence is plausible: one of the two choices is a step that
            # happens (a glitch in the last sample makes both choices far: no evidence)
            with np.errstate(invalid="ignore"):
                okl = np.isfinite(kl) & np.isfinite(sl) & ((kl <= nl) | (sl <= nr))
                okr = np.isfinite(kr) & np.isfinite(sr) & ((kr <= nr) | (sr <= nl))
            keep = np.where(okl, kl, 0.0) + np.where(okr, kr, 0.0)
            swap = np.where(okl, sl, 0.0) + np.where(okr, sr, 0.0)
            keep[~okl & ~okr] = np.nan
            clear_swap = (swap < RATIO * keep) & (keep - swap > margin)
            clear_keep = (keep < RATIO * swap) & (swap - keep > margin)
            state = np.where(clear_swap, True, np.where(clear_keep, False, state))
            exchanged[t] = state
            yc = y.copy()
            m = state[bi, pi]
            yc[bi[m], left[pi[m]]] = y[bi[m], right[pi[m]]]
            yc[bi[m], right[pi[m]]] = y[bi[m], left[pi[m]]]
            # a pair's joint whose corrected sample is no plausible step from where it
            # was expected (a glitch) keeps the reference, one frame older; one stored
            # anew after a reference gets the velocity of its step (per frame since)
            d = np.linalg.norm(yc[:, js] - pred[:, js], axis=-1)
            with np.errstate(invalid="ignore"):
                far = d > near + step * age[:, js]
            had = ~np.isnan(last[:, js, 0])
            hold = far | (np.isnan(d) & had)
            fresh = ~np.isnan(d) & ~far
            gap = (age[:, js] + 1)[..., None]
            vel[:, js] = np.where(fresh[..., None], (yc[:, js] - last[:, js]) / gap, vel[:, js])
            age[:, js] = np.where(hold, age[:, js] + 1, 0)
            yc[:, js] = np.where(hold[..., None], last[:, js], yc[:, js])
            _last_valid(yc, last)
        if undo:
            exchanged &= _runs_to_undo(exchanged, max_frames)
    return order, exchanged


def _people(seed, B, dims, apart=True):
    """``B`` people in pixels (or metres, 3-D), with identity switches, left/right swaps,
    one-frame glitches and missing samples."""
    rng = np.random.default_rng(seed)
    kinds = ["mixed", "walk", "arms"]
    seqs = [tk.generate_motion(kinds[b % 3], duration=4.0, seed=seed + b) for b in range(B)]
    T = min(s.n_frames for s in seqs)
    ys = np.stack([s.positions[:T, :, :dims] for s in seqs], 1) * (500 if dims == 2 else 1)
    # apart, or close (the same motion a few noise sds apart: where the margin decides)
    if not apart:
        ys = np.repeat(ys[:, :1], B, 1)
    spread = (120 if dims == 2 else 0.3) if apart else (8 if dims == 2 else 0.02)
    ys += np.arange(B)[None, :, None, None] * spread
    ys += rng.normal(0, 2 if dims == 2 else 0.005, ys.shape)
    for _ in range(3):  # identity switches
        a, n = rng.integers(0, T - 20), rng.integers(3, 20)
        ys[a : a + n] = ys[a : a + n][:, ::-1]
    pairs = list(seqs[0].topology.symmetry)
    if not apart:  # and one pair's joints a few noise sds apart
        lj, rj = pairs[0]
        ys[:, :, rj] = ys[:, :, lj] + (6 if dims == 2 else 0.015)
    for _ in range(6):  # left/right swaps of one pair of one body
        a, b = rng.integers(0, T - 10), rng.integers(0, B)
        lj, rj = pairs[rng.integers(0, len(pairs))]
        n = rng.integers(1, 10)
        ys[a : a + n, b, [lj, rj]] = ys[a : a + n, b, [rj, lj]]
    glitch = rng.random(ys.shape[:3]) < 0.01
    ys[glitch] += rng.normal(0, 200 if dims == 2 else 0.5, (glitch.sum(), dims))
    ys[rng.random(ys.shape[:3]) < 0.05] = np.nan
    return ys, np.isnan(ys).any(axis=-1), pairs


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("B", [1, 2, 3])
@pytest.mark.parametrize("dims", [2, 3])
@pytest.mark.parametrize("apart", [True, False])
def test_the_compiled_loops_decide_as_numpy(seed, B, dims, apart):
    ys, missing, pairs = _people(seed, B, dims, apart)
    unit = 1.0 if dims == 2 else 0.0025
    cases = ((6, np.inf), (6, 16), (20, np.inf), (60, np.inf))
    for margin, near in ((m * unit, n * unit) for m, n in cases):
        want = _reference(ys, missing, pairs, margin, max_frames=45, near=near)
        got = untangle(ys, missing, pairs, margin, max_frames=45, near=near, both_ways=False)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
    if B > 1 and apart:  # the data do exercise both loops
        assert (want[0] != np.arange(B)).any() and want[1].any()


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("B", [1, 2])
@pytest.mark.parametrize("dims", [2, 3])
def test_offline_settles_the_forward_and_the_backward_pass(seed, B, dims):
    """Offline (``both_ways``), the left/right exchanges are the NumPy loop's forwards
    and its backwards in time (the loop run on the frames reversed), settled by
    :func:`settle`, and then the runs longer than ``max_frames`` undone."""
    ys, missing, pairs = _people(seed, B, dims, True)
    unit = 1.0 if dims == 2 else 0.0025
    margin, near = 6 * unit, 16 * unit
    T = len(ys)
    order, _ = _reference(ys, missing, pairs, margin, max_frames=45, near=near)
    yo = ys[np.arange(T)[:, None], order]
    mo = np.isnan(yo).any(axis=-1)
    kw = {"bodies": False, "max_frames": 45, "near": near, "undo": False}
    _, fwd = _reference(yo, mo, pairs, margin, **kw)
    _, bwd = _reference(yo[::-1].copy(), mo[::-1].copy(), pairs, margin, **kw)
    left = np.array([a for a, _ in pairs])
    right = np.array([b for _, b in pairs])
    want = settle(yo, fwd, bwd[::-1], left, right, margin)
    want &= _runs_to_undo(want, 45)
    got = untangle(ys, missing, pairs, margin, max_frames=45, near=near)
    np.testing.assert_array_equal(got[0], order)
    np.testing.assert_array_equal(got[1], want)
    assert (fwd != bwd[::-1]).any()  # the passes differ somewhere: settle decides


def test_identity_costs_are_the_median_distances():
    """``cost[a, b]`` is ``np.nanmedian`` over joints of ``|y[b] - last[a]|``, bit for
    bit, with odd and even counts of joints measured at both and none at all."""
    from tobitkf.smoothing._untangle_kernels import identity_costs

    rng = np.random.default_rng(5)
    for J in (1, 4, 7):
        y, last = rng.normal(size=(3, J, 2)), rng.normal(size=(3, J, 2))
        y[rng.random((3, J)) < 0.3] = np.nan
        last[2] = np.nan  # identity 2 never seen: NaN costs
        cost = np.empty((3, 3))
        identity_costs(y, last, cost, np.empty(J))
        want = _nanmedian(np.linalg.norm(y[None, :] - last[:, None], axis=-1))
        np.testing.assert_array_equal(cost, want)


def _pair_frames(frames, max_frames=1000, margin=1.0, near=np.inf):
    """``pair_step`` over ``frames (T, J, D)`` of one identity whose joints 0 and 1 are
    a pair: the state after each frame (velocities, ages, exchanged)."""
    from tobitkf.smoothing._untangle_kernels import pair_step

    _, J, D = frames.shape
    last, age = np.full((J, D), np.nan), np.zeros(J, dtype=np.int64)
    vel = np.full((J, D), np.nan)
    state, run = np.zeros(1, dtype=np.bool_), np.zeros(1, dtype=np.int64)
    left, right = np.array([0]), np.array([1])
    out = []
    yc, pred = np.empty((J, D)), np.empty((J, D))
    for y in frames:
        pair_step(np.ascontiguousarray(y), last, age, vel, state, run, left, right, margin,
                  near, NEAR_FACTOR, RATIO, max_frames, yc, pred)  # fmt: skip
        out.append((vel.copy(), age.copy(), bool(state[0])))
    return out


def test_a_pair_joint_velocity_is_its_step_per_frame():
    """Stored after a reference ``n`` frames old, a joint's velocity is its step over
    ``n`` (a gap of two missing frames: the step over three); it is unknown at the
    first sample, and held (not used) while the joint is missing."""
    f = np.zeros((6, 2, 2))
    f[:, 0, 0] = [0.0, 10.0, np.nan, np.nan, 40.0, 50.0]
    f[2:4, 0, 1] = np.nan
    f[:, 1] = [500.0, 0.0]
    states = _pair_frames(f)
    assert np.isnan(states[0][0][0]).all()
    np.testing.assert_array_equal(states[1][0][0], [10.0, 0.0])
    assert states[3][1][0] == 2  # missing twice: its reference is two frames old
    np.testing.assert_array_equal(states[4][0][0], [10.0, 0.0])  # (40 - 10) / 3
    np.testing.assert_array_equal(states[4][0][1], [0.0, 0.0])
    assert not any(s[2] for s in states)


def test_a_rebased_pair_has_no_velocity():
    """An exchange held longer than ``max_frames`` is taken as detected: the references
    jump to the samples as they come, and a step across sides is no velocity."""
    T = 12
    f = np.zeros((T, 2, 2))
    f[:, 0, 0] = 100.0 + 2.0 * np.arange(T)  # left moves right slowly
    f[:, 1, 0] = 300.0 - 2.0 * np.arange(T)  # right moves left slowly
    f[4:, [0, 1]] = f[4:, [1, 0]]  # exchanged from frame 4 on
    states = _pair_frames(f, max_frames=3)
    exchanged = [s[2] for s in states]
    assert exchanged[4:7] == [True, True, True] and not exchanged[7]  # taken as detected
    assert np.isnan(states[7][0][:2]).all()
    np.testing.assert_array_equal(states[8][0][0], [-2.0, 0.0])  # its own step again
