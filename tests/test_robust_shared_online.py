"""Shared errors of the carried samples and of the guesses in robust_online's sd (the
causal form of robust_shared.py).

The structure function read so far is checked against a joint turning about its parent
at a known rate (closed form, as offline); the guesses' error so far against the offline
estimator of the frames so far (hypothesis); the added variance against the filter's own
response to a shift of each carried sample and of each guess (linear filter,
value-independent gains: an exact identity); live against batch on a real recording;
and end to end by Monte Carlo (guesses with a known shared error) and on the built-in
benchmark, whose 95 % ball coverage must come out near 95 % (and far below without).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import tobitkf as tk
from conftest import data_file
from test_robust_shared import ORDER, PARENTS, _occluded_joints, _turning_arm
from tobitkf.evaluation.benchmark import run_benchmark
from tobitkf.evaluation.corruption import SUSTAINED
from tobitkf.evaluation.metrics import in_sd_ball
from tobitkf.io import load
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology
from tobitkf.smoothing import _robust_kernels as rk
from tobitkf.smoothing.robust import RobustStepper
from tobitkf.smoothing.robust_shared import MIN_CHANGES, MIN_PAIRS, guess_error_variance
from tobitkf.smoothing.timebase import DEFAULT_INFERRED_NOISE_FACTOR


def _arm(T: int, r: float, omega: float, h: float) -> np.ndarray:
    """The offline tests' turning arm (root, elbow, hand) as one body's frames (T, 3, 3)."""
    return _turning_arm(T, r, omega, h)[:, 0]


def _run_frames(ys: np.ndarray, final: np.ndarray, n_dims: int = 3) -> np.ndarray:
    """:func:`shared_frame` over the frames; the per-axis variance of each carried sample
    (joints not accepted are carried), 0 elsewhere."""
    T, J = final.shape
    state = rk.new_state(1, J, 0, shared=True)
    sf, o_ring, s_acc = state[3], state[15], state[16]
    out = np.zeros((T, J))
    sig2 = np.empty(J)
    for t in range(T):
        radius = np.where(final[t], np.nan, 1.0)
        radius[0] = np.nan  # the root has no parent: never carried
        rk.shared_frame(ys[t], final[t], radius, PARENTS, ORDER, t, MIN_PAIRS, n_dims, sf[0],
                        o_ring[0], s_acc[0], sig2)  # fmt: skip
        out[t] = sig2
    return out


def _tabulated(d: np.ndarray) -> np.ndarray:
    """The smallest tabulated lag at least ``d``."""
    return rk.SF_LAGS[np.searchsorted(rk.SF_LAGS, d)]


def test_carried_error_is_the_turn_so_far_at_the_tabulated_lag():
    # every pair of the elbow's offset: |o(t + d) - o(t)|^2 = 2 r^2 (1 - cos omega d);
    # the hand's offset from the elbow turns at 2 omega; a carried hand adds its carried
    # elbow's variance
    r, om, h = 0.25, 0.05, 0.1
    ys = _arm(180, r, om, h)
    final = np.ones((180, 3), dtype=bool)
    final[100:130, 1:] = False
    final[150:170, 1:] = False  # again: the frames of the first failure gave no pairs
    sig2 = _run_frames(ys, final)
    for a, b in ((100, 130), (150, 170)):
        L = _tabulated(np.arange(1, b - a + 1))
        own = 2 * r**2 * (1 - np.cos(om * L)) / 3
        hand = 2 * h**2 * (1 - np.cos(2 * om * L)) / 3
        np.testing.assert_allclose(sig2[a:b, 1], own, rtol=1e-9)
        np.testing.assert_allclose(sig2[a:b, 2], own + hand, rtol=1e-9)
    assert np.all(sig2[final] == 0)
    # the elbow's turn seen in the image plane (x, y; a 2-D stream's third axis is 0):
    # the same squared turn over two coordinates
    flat = ys.copy()
    flat[..., 2] = 0.0
    sig2 = _run_frames(flat, final, n_dims=2)
    L = _tabulated(np.arange(1, 31))
    np.testing.assert_allclose(sig2[100:130, 1], r**2 * (1 - np.cos(om * L)), rtol=1e-9)


def test_carried_error_beyond_the_lags_or_the_pairs_is_the_variance_so_far():
    r, om = 0.25, 2 * np.pi / 40
    ys = _arm(200, r, om, 0.1)
    final = np.ones((200, 3), dtype=bool)
    final[100:180, 1] = False  # lags 1 .. 80: beyond the last tabulated one, 2 Var(o)
    sig2 = _run_frames(ys, final)
    o = ys[:100, 1] - ys[:100, 0]  # the offsets known when the failure starts
    lim = 2 * o.var(axis=0, ddof=1).sum() / 3
    last = rk.SF_LAGS[-1]
    np.testing.assert_allclose(sig2[100 + last : 180, 1], lim, rtol=1e-9)
    assert np.all(sig2[100 : 100 + last, 1] != lim)
    # a short history: the lags with fewer than MIN_PAIRS pairs take the limit too
    n = MIN_PAIRS + 3  # frames before the failure: lag d has n - d pairs
    final = np.ones((n + 12, 3), dtype=bool)
    final[n:, 1:] = False
    sig2 = _run_frames(ys[: n + 12], final)
    o = ys[:n, 1] - ys[:n, 0]
    lim = 2 * o.var(axis=0, ddof=1).sum() / 3
    d = np.arange(1, 13)
    L = _tabulated(d)
    want = np.where(n - L >= MIN_PAIRS, 2 * r**2 * (1 - np.cos(om * L)) / 3, lim)
    assert (want == lim).any() and (want != lim).any()
    np.testing.assert_allclose(sig2[n:, 1], want, rtol=1e-9)


def _guess_sd_so_far(ys: np.ndarray, final: np.ndarray, inferred: np.ndarray) -> np.ndarray:
    """:func:`guess_frame` over the frames of one body (the filter's part of the state,
    the previous frame's acceptance and tracking state, written as the filter does):
    the guesses' error sd at each frame."""
    T, J = final.shape
    state = rk.new_state(1, J, 0, shared=True)
    sf, sb, g_stat = state[3][0], state[4][0], state[17][0]
    out = np.empty(T)
    for t in range(T):
        out[t] = rk.guess_frame(ys[t], ys[t - 1] if t else ys[0], t > 0, final[t], inferred[t],
                                MIN_CHANGES, 3, sf, sb, g_stat)  # fmt: skip
        sb[:, rk.B_PREV_FINAL] = final[t]
        sb[:, rk.B_PREV_INF] = inferred[t]
    return out


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), p_inf=st.floats(0.05, 0.5), p_acc=st.floats(0.5, 1))
def test_guess_error_so_far_is_the_offline_estimate_of_the_frames_so_far(seed, p_inf, p_acc):
    # causal: at every frame, the offline estimate (robust_shared) of the recording up to
    # it; 0 where that has too few changes
    rng = np.random.default_rng(seed)
    T, J = 50, 4
    ys = np.cumsum(rng.normal(scale=0.02, size=(T, J, 3)), axis=0)
    inferred = rng.random((T, J)) < p_inf
    final = rng.random((T, J)) < p_acc
    ys[rng.random((T, J)) < 0.05] = np.nan  # missing samples: no step to or from them
    online = _guess_sd_so_far(ys, final, inferred)
    for t in range(T):
        s2, n = guess_error_variance(ys[None, : t + 1].swapaxes(0, 1), final[: t + 1, None],
                                     inferred[: t + 1, None])  # fmt: skip
        want = np.sqrt(s2[0]) if n[0] >= MIN_CHANGES and np.isfinite(s2[0]) else 0.0
        assert online[t] == pytest.approx(want, rel=1e-9, abs=1e-15)


def test_inferred_samples_are_covered_by_the_online_sd_monte_carlo():
    # 12 joints x 9 occlusions x 3 seeds = 324 shared errors of 3 cm: the 95 % ball's
    # coverage of the inferred samples (standard error about 1.2 points)
    hits, old_hits, n = 0, 0, 0
    for seed in range(3):
        seq, truth, inf = _occluded_joints(seed, 0.03)
        out = tk.smooth(seq, method="robust_online", noise_sd=0.005)
        old = tk.smooth(seq, method="robust_online", noise_sd=0.005, shared_errors=False)
        np.testing.assert_array_equal(old.positions, out.positions)  # the estimate stays
        err2 = np.sum((out.positions - truth) ** 2, axis=-1)
        ok = inf & np.isfinite(err2)
        hits += np.sum(err2[ok] <= 7.8147 * out.std[ok] ** 2)
        old_hits += np.sum(err2[ok] <= 7.8147 * old.std[ok] ** 2)
        n += ok.sum()
    assert 0.90 < hits / n < 0.99
    assert old_hits / n < 0.6


def test_added_variance_of_the_guesses_is_the_square_of_the_weighted_sd():
    # as for the carried samples: moving a guess by delta moves the estimate at t by
    # delta w(t, i); the variance added at t is (sum_i w(t, i) s_i)^2 with s_i the
    # guesses' sd from the frames up to i (the offline estimate of that prefix)
    seq, _, _ = _occluded_joints(0, 0.03)
    seq = seq.replace(positions=seq.positions[:330], tracking_state=seq.tracking_state[:330])
    base = tk.smooth(seq, method="robust_online", noise_sd=0.005)
    plain = tk.smooth(seq, method="robust_online", noise_sd=0.005, shared_errors=False)
    rej = base.metadata["diagnostics"]["rejected"]
    final = ~rej & np.isfinite(seq.positions[..., 0])
    inf = seq.tracking_state == 1
    j = 0
    guesses = np.flatnonzero(inf[:, j] & final[:, j])
    assert guesses.size > 60
    s = np.array([np.sqrt(guess_error_variance(seq.positions[None, : i + 1].swapaxes(0, 1),
                                               final[: i + 1, None], inf[: i + 1, None])[0][0])
                  for i in guesses])  # fmt: skip
    s = np.nan_to_num(s)  # too few changes yet: nothing
    delta = 1e-5
    w = np.zeros((seq.n_frames, guesses.size))
    for k, i in enumerate(guesses):
        pos = seq.positions.copy()
        pos[i, j, 0] += delta
        moved = tk.smooth(seq.replace(positions=pos), method="robust_online", noise_sd=0.005)
        w[:, k] = (moved.positions[:, j, 0] - base.positions[:, j, 0]) / delta
    added = base.std[:, j] ** 2 - plain.std[:, j] ** 2
    np.testing.assert_allclose(added, (w @ s) ** 2, rtol=1e-4, atol=1e-12)
    assert np.all(added[:40] == 0) and np.all(added[45:70] > 0)


def _failing_elbow(shift_root_at: int | None = None, delta: float = 0.0) -> SkeletonSequence:
    """A root and an elbow turning about it, 30 fps; the elbow fails (1 m off, INFERRED)
    for 40 frames and for 10 more soon after, carried with the root. A third, still
    joint has four accepted INFERRED episodes 3 cm off before that, so the body's guesses
    have an error (which the carried guesses must not get). ``shift_root_at``: the root
    moved by ``delta`` in that frame only (every gate still accepts it)."""
    T = 170
    ys = np.zeros((T, 3, 3))
    ys[:, :2] = _arm(T, 0.25, 0.05, 0.1)[:, :2]
    ys[:, 2] = [0.5, 0.0, 0.0]
    ys += np.array([0.0, 1.0, 2.5])
    states = np.full((T, 3), 2, dtype=np.int8)
    for a in (10, 25, 40, 55):
        ys[a : a + 5, 2, 0] += 0.03
        states[a : a + 5, 2] = 1
    for a, b in ((90, 130), (140, 150)):  # the second soon after the filter recovered
        ys[a:b, 1] += np.array([0.0, 1.0, 0.0])
        states[a:b, 1] = 1
    if shift_root_at is not None:
        ys[shift_root_at, 0] += delta
    topo = Topology("arm", ("root", "elbow", "other"), (-1, 0, -1))
    return SkeletonSequence(positions=ys, topology=topo, fps=30.0, tracking_state=states)


def test_added_variance_is_the_square_of_the_weighted_shared_sd():
    # the filter is linear with gains that do not depend on the values: moving the root
    # by delta in frame i moves the carried sample of frame i, and the elbow's estimate
    # at t by delta w(t, i). So the variance added at t must be (sum_i w(t, i) sd_i)^2,
    # sd_i the carried sample's own (from the frames before it, closed form as above)
    # (the failed guesses are not put back at their bone's length: they stay rejected)
    base = tk.smooth(_failing_elbow(), method="robust_online", inferred_bones=False)
    plain = tk.smooth(_failing_elbow(), method="robust_online", inferred_bones=False,
                      shared_errors=False)  # fmt: skip
    np.testing.assert_array_equal(base.positions, plain.positions)  # the estimate stays
    rej = base.metadata["diagnostics"]["rejected"][:, 1]
    carried = np.flatnonzero(rej)
    assert carried[0] == 90
    delta = 1e-4
    w = np.zeros((base.positions.shape[0], carried.size))
    for k, i in enumerate(carried):
        moved = tk.smooth(_failing_elbow(i, delta), method="robust_online",
                          inferred_bones=False)  # fmt: skip
        np.testing.assert_array_equal(moved.metadata["diagnostics"]["rejected"],
                                      base.metadata["diagnostics"]["rejected"])  # fmt: skip
        w[:, k] = (moved.positions[:, 1, 0] - base.positions[:, 1, 0]) / delta
    # the carried offset is the last accepted one: lag = frames since it, read at the
    # smallest tabulated lag at least that (all have enough pairs after 90 frames)
    accepted = np.flatnonzero(~rej)
    lag = carried - accepted[np.searchsorted(accepted, carried) - 1]
    assert lag.max() > 40 and carried[-1] > 140  # both failures
    L = _tabulated(np.minimum(lag, rk.SF_LAGS[-1]))
    sd = np.sqrt(2 * 0.25**2 * (1 - np.cos(0.05 * L)) / 3)
    added = base.std[:, 1] ** 2 - plain.std[:, 1] ** 2
    np.testing.assert_allclose(added, (w @ sd) ** 2, rtol=1e-5, atol=1e-12)
    assert np.all(added[:90] == 0) and np.all(added[95:130] > 0)
    other = base.std[:, 2] ** 2 - plain.std[:, 2] ** 2  # the accepted guesses' error
    assert np.all(other[:10] == 0) and other[60] > 1e-5


@pytest.mark.parametrize("n_dims", [3, 2])
def test_live_std_equals_batch_on_a_real_recording(n_dims):
    seq = load(data_file("keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt"))[0]
    if n_dims == 2:  # seen in the x-y plane (a 2-D stream: the third axis is zeros)
        seq = seq.replace(positions=seq.positions[..., :2])
    out = tk.smooth(seq, method="robust_online")
    plain = tk.smooth(seq, method="robust_online", shared_errors=False)
    assert np.nanmax(out.std / plain.std) > 2  # carried stretches with a shared error
    stepper = RobustStepper(seq.topology, seq.topology.up_axis, DEFAULT_INFERRED_NOISE_FACTOR)
    std = []
    for t in range(seq.n_frames):
        y = np.zeros((1, seq.n_joints, 3))
        y[..., :n_dims] = seq.positions[t]
        y[np.isnan(y[..., 0])] = np.nan
        stepper.step(y, np.isnan(y[..., 0]),
                     None if seq.tracking_state is None else seq.tracking_state[t][None],
                     1.0 / seq.fps, n_dims)  # fmt: skip
        std.append(stepper.std[0].copy())
    np.testing.assert_allclose(np.stack(std), out.std, rtol=0, atol=1e-12, equal_nan=True)


@pytest.mark.parametrize("seeds", [range(3)])
def test_sustained_failures_are_covered_by_the_online_sd_on_the_benchmark(seeds):
    # the built-in benchmark's sustained failures, rejected and bridged online by
    # carrying: the share within the 95 % ball of the filtered sd
    hits, old_hits = [], []
    for seed in seeds:
        out = {}
        run_benchmark(seed, ["robust_online", "robust_online[shared_errors=false]"],
                      outputs=out)  # fmt: skip
        cor = out["corrupted"]
        new = out["robust_online"]
        m = (cor.labels == SUSTAINED) & new.metadata["diagnostics"]["rejected"]
        old = out["robust_online[shared_errors=false]"]
        np.testing.assert_array_equal(old.positions, new.positions)
        hits.append(in_sd_ball(new.positions, cor.truth, new.std)[m])
        old_hits.append(in_sd_ball(old.positions, cor.truth, old.std)[m])
    cover, old = np.nanmean(np.concatenate(hits)), np.nanmean(np.concatenate(old_hits))
    assert cover > 0.85 and old < 0.8
