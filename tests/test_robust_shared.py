"""Shared errors in the offline robust smoother's sd (robust_shared.py).

The guesses' error variance is checked on tracks built so that its value is known by
hand (steps at a change of state perpendicular to the motion) and by its invariances
(hypothesis); the carried samples' error against a joint turning about its parent at a
known rate (the structure function in closed form); the added variance against the
smoother's own response to a shift of the samples; and end to end by Monte Carlo:
guesses with a known shared error per occlusion, and the built-in benchmark's sustained
failures, whose 95 % ball coverage must come out near 95 % (and far below without).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import tobitkf as tk
from tobitkf.evaluation.benchmark import run_benchmark
from tobitkf.evaluation.corruption import SUSTAINED
from tobitkf.evaluation.metrics import in_sd_ball
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology
from tobitkf.smoothing import _noise_kernels as nk
from tobitkf.smoothing.robust import _smooth_run as smooth_run
from tobitkf.smoothing.robust_shared import (
    MAX_LAG_FRAMES,
    MIN_CHANGES,
    MIN_PAIRS,
    carried_error_sd,
    guess_error_variance,
    max_lag_frames,
    shared_signal,
)

INFERRED = 1  # TrackingState.INFERRED


def _episodes_track(offsets: list[tuple[float, float, float]], speed: float = 0.3):
    """One joint moving along x at ``speed`` (m per frame), with a 10-frame inferred
    episode per offset (the guesses shifted by it, perpendicular to the motion)."""
    T = 20 * len(offsets) + 10
    ys = np.zeros((T, 1, 1, 3))
    ys[:, 0, 0, 0] = speed * np.arange(T)
    inferred = np.zeros((T, 1, 1), dtype=bool)
    for k, d in enumerate(offsets):
        a = 10 + 20 * k
        ys[a : a + 10, 0, 0] += d
        inferred[a : a + 10, 0, 0] = True
    return ys, inferred


def test_variance_is_the_guesses_offset_per_axis():
    # each episode has two changes of state (entry, exit), each step |u|^2 + |d|^2 with
    # the tracked steps |u|^2: s2 = mean |d|^2 / 3; a faster joint without guesses in
    # the same body is not the guessed joints' motion and does not count
    offsets = [(0.0, 0.03, 0.0), (0.0, 0.0, 0.06), (0.0, 0.03, 0.04)]
    ys, inferred = _episodes_track(offsets)
    fast = np.zeros(ys.shape)
    fast[:, 0, 0, 0] = 0.5 * np.arange(ys.shape[0])
    ys = np.concatenate([ys, fast], axis=2)
    inferred = np.concatenate([inferred, np.zeros_like(inferred)], axis=2)
    acc = np.ones(inferred.shape, dtype=bool)
    s2, n = guess_error_variance(ys, acc, inferred)
    assert n[0] == 6
    assert s2[0] == pytest.approx((0.03**2 + 0.06**2 + 0.05**2) / 3 / 3, rel=1e-9)


def test_rejected_samples_and_too_few_changes():
    offsets = [(0.0, 0.03, 0.0), (0.0, 0.0, 0.06), (0.0, 0.03, 0.04), (0.0, 0.5, 0.0)]
    ys, inferred = _episodes_track(offsets)
    acc = np.ones(inferred.shape, dtype=bool)
    acc[70, 0, 0] = False  # the last episode's entry: its step is not counted
    acc[79, 0, 0] = False  # nor its exit
    s2, n = guess_error_variance(ys, acc, inferred)
    assert n[0] == 6
    assert s2[0] == pytest.approx((0.03**2 + 0.06**2 + 0.05**2) / 9, rel=1e-9)
    s2, n = guess_error_variance(ys[:50], acc[:50], inferred[:50])  # two episodes
    assert n[0] == 4 < MIN_CHANGES and np.isnan(s2[0])


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    shift=st.floats(-5, 5),
    scale=st.floats(0.1, 10),
)
def test_variance_moves_with_the_coordinates(seed, shift, scale):
    rng = np.random.default_rng(seed)
    T, B, J = 60, 2, 3
    ys = np.cumsum(rng.normal(scale=0.02, size=(T, B, J, 3)), axis=0)
    inferred = rng.random((T, B, J)) < 0.3
    acc = rng.random((T, B, J)) < 0.9
    s2, n = guess_error_variance(ys, acc, inferred)
    s2b, nb = guess_error_variance(ys * scale + shift, acc, inferred)
    assert np.array_equal(n, nb)
    assert np.array_equal(np.isnan(s2), np.isnan(s2b))
    np.testing.assert_allclose(s2b, s2 * scale**2, rtol=1e-6, atol=1e-12)
    assert np.all(np.isnan(s2) | (s2 >= 0))


def test_added_variance_is_the_square_of_the_weighted_shared_sd():
    # the smoother is linear: shifting each sample i of a kind by delta sd_i moves its
    # estimate by delta sum w_i sd_i; the squares of the two kinds' sums are added (two
    # independent errors), nothing where no sample shares one, the estimate unchanged.
    # Two blocks of SIMD lanes; one column has both kinds, near enough to overlap
    rng = np.random.default_rng(3)
    T, B, J = 80, 2, nk.L // 2 + 4
    yk = np.cumsum(rng.normal(scale=0.01, size=(T, B, J, 3)), axis=0)
    yk[rng.random((T, B, J)) < 0.1] = np.nan
    guess, carried = np.full((T, B, J), np.nan), np.full((T, B, J), np.nan)
    guess[20:45, 0, 1] = rng.uniform(0.01, 0.03, size=25)
    carried[46:60, 0, 1] = rng.uniform(0.02, 0.05, size=14)
    carried[50:60, 1, J - 2] = 0.02
    present = np.isfinite(yk[..., 0])
    guess[~present], carried[~present] = np.nan, np.nan
    rvar = np.full((T, B, J), 1e-4)
    steps = np.full(T, 1 / 30)
    q = np.full((T, B, J), 2.0)
    sc2, tau_c = np.full((B, J), 1e-5), np.full((B, J), 0.05)

    def smooth(y, shared=None):
        est, var = np.empty((T, B, J, 3)), np.empty((T, B, J))
        smooth_run(np.ascontiguousarray(y), rvar, steps, q, sc2, 0.15, tau_c, est, var, 0,
                   shared)  # fmt: skip
        return est, var

    delta = 0.5
    e0, v0 = smooth(yk)
    w_g = (smooth(yk + delta * np.nan_to_num(guess)[..., None])[0] - e0)[..., 0] / delta
    w_c = (smooth(yk + delta * np.nan_to_num(carried)[..., None])[0] - e0)[..., 0] / delta
    e, var = smooth(yk, shared_signal(guess, carried, (T, B, J)))
    assert np.array_equal(e, e0, equal_nan=True)  # the estimate is not changed
    np.testing.assert_allclose(var - v0, w_g**2 + w_c**2, rtol=1e-6, atol=1e-12)
    assert np.array_equal(var[:, 0, 0], v0[:, 0, 0])  # no shared error: untouched
    # between the two stretches both kinds weigh: added apart, not as one error
    both = (np.abs(w_g[:, 0, 1]) > 1e-4) & (np.abs(w_c[:, 0, 1]) > 1e-4)
    assert both.sum() >= 3
    # inside a long stretch the shared samples decide: an average of their own sds
    assert np.all((w_g[30:35, 0, 1] > 0.009) & (w_g[30:35, 0, 1] < 0.031))
    # none at all: nothing added
    none = shared_signal(np.full((T, B, J), np.nan), None, (T, B, J))
    assert np.array_equal(smooth(yk, none)[1], v0, equal_nan=True)
    assert shared_signal(None, None, (T, B, J)) is None


def _turning_arm(T: int = 200, r: float = 0.25, omega: float = 0.05, h: float = 0.1):
    """A still root, an elbow turning about it on a circle of radius ``r`` (``omega`` rad
    per frame) and a hand turning about the elbow on a circle of radius ``h`` in another
    plane, twice as fast; (T, 1, 3, 3)."""
    t = np.arange(T)
    ys = np.zeros((T, 1, 3, 3))
    ys[:, 0, 1, 0] = r * np.cos(omega * t)
    ys[:, 0, 1, 1] = r * np.sin(omega * t)
    ys[:, 0, 2, 0] = ys[:, 0, 1, 0] + h * np.cos(2 * omega * t)
    ys[:, 0, 2, 1] = ys[:, 0, 1, 1]
    ys[:, 0, 2, 2] = h * np.sin(2 * omega * t)
    return ys


PARENTS, ORDER = np.array([-1, 0, 1]), np.array([0, 1, 2])


def test_carried_error_is_the_turn_since_the_offset_seen():
    # the elbow's offset turns at omega per frame: |o(t + d) - o(t)|^2 = 2 r^2 (1 - cos
    # omega d) for every pair; the hand's offset from the elbow likewise at 2 omega
    r, om, h = 0.25, 0.05, 0.1
    ys = _turning_arm(r=r, omega=om, h=h)
    acc = np.ones(ys.shape[:3], dtype=bool)
    acc[100:130, 0, 1:] = False  # elbow and hand rejected, carried
    acc[:5, 0, 1] = False  # a stretch with no offset before it: carried back from frame 5
    ys[50:60, 0, 1] += 1.0  # a failed elbow under a good hand: no offset of the hand
    acc[50:60, 0, 1] = False
    carried = ~acc
    sd = carried_error_sd(ys, acc, carried, PARENTS, ORDER, max_lag=60)
    d = np.arange(1, 31)
    own = 2 * r**2 * (1 - np.cos(om * d)) / 3
    np.testing.assert_allclose(sd[100:130, 0, 1], np.sqrt(own), rtol=1e-9)
    # the hand's own turn and its carried parent's, independent
    hand = 2 * h**2 * (1 - np.cos(2 * om * d)) / 3
    np.testing.assert_allclose(sd[100:130, 0, 2], np.sqrt(own + hand), rtol=1e-9)
    back = 2 * r**2 * (1 - np.cos(om * np.arange(5, 0, -1))) / 3
    np.testing.assert_allclose(sd[:5, 0, 1], np.sqrt(back), rtol=1e-9)
    assert np.all(np.isnan(sd[~carried]))


def test_carried_error_beyond_the_data_is_the_stationary_limit():
    # lags beyond max_lag, or with fewer than MIN_PAIRS pairs, take 2 Var(o): for the
    # elbow's offset on its circle, sampled evenly over whole turns, 2 Var = 2 r^2
    r, om = 0.25, 2 * np.pi / 40
    ys = _turning_arm(T=400, r=r, omega=om)
    acc = np.ones(ys.shape[:3], dtype=bool)
    acc[200:240, 0, 1] = False  # 40 frames: whole turns left evenly on both sides
    sd = carried_error_sd(ys, acc, ~acc, PARENTS, ORDER, max_lag=10)
    lim = np.sqrt(2 * r**2 / 3)
    np.testing.assert_allclose(sd[211:240, 0, 1], lim, rtol=0.01)  # lags 12 .. 40 > 10
    own = np.sqrt(2 * r**2 * (1 - np.cos(om * np.arange(1, 11))) / 3)
    np.testing.assert_allclose(sd[200:210, 0, 1], own, rtol=1e-9)
    # two good frames only: no lag has MIN_PAIRS pairs, every lag is the limit
    few = np.zeros(ys.shape[:3], dtype=bool)
    few[:, 0, 0] = True
    few[[10, 10 + MIN_PAIRS], 0, 1] = True
    c = ~few
    c[:, 0, 2] = False
    sd = carried_error_sd(ys, few, c, PARENTS, ORDER, max_lag=50)
    o = ys[[10, 10 + MIN_PAIRS], 0, 1]
    np.testing.assert_allclose(sd[11:20, 0, 1], np.sqrt(2 * o.var(axis=0, ddof=1).sum() / 3))


def test_longest_lag_is_max_reject_in_frames_within_bounds():
    # 2 s at 30 fps: 60 frames; a fraction of a frame rounds up; bounded both ways
    assert max_lag_frames(2.0, np.full(100, 1 / 30)) == 60
    assert max_lag_frames(2.01, np.full(100, 1 / 30)) == 61
    assert max_lag_frames(1e-6, np.full(100, 1 / 30)) == 1
    assert max_lag_frames(np.inf, np.full(100, 1 / 30)) == MAX_LAG_FRAMES
    assert max_lag_frames(60.0, np.full(100, 1 / 120)) == MAX_LAG_FRAMES  # 7,200 frames
    assert max_lag_frames(2.0, np.zeros(5)) == MAX_LAG_FRAMES  # no step to measure by


def _occluded_joints(seed: int, sd_guess: float):
    """Independent joints (no bones) moving slowly, white noise 5 mm, 30-frame
    occlusions whose guesses share one N(0, sd_guess² I) error."""
    rng = np.random.default_rng(seed)
    T, J, fps = 900, 12, 30.0
    t = np.arange(T) / fps
    phase = rng.uniform(0, 2 * np.pi, size=(J, 3))
    truth = 0.1 * np.sin(2 * np.pi * 0.3 * t[:, None, None] + phase[None])
    y = truth + rng.normal(scale=0.005, size=truth.shape)
    states = np.full((T, J), 2, dtype=np.int8)
    for j in range(J):
        for a in range(40, T - 60, 90):
            y[a : a + 30, j] += rng.normal(scale=sd_guess, size=3)
            states[a : a + 30, j] = INFERRED
    topo = Topology("independent", tuple(f"j{i}" for i in range(J)), (-1,) * J)
    seq = SkeletonSequence(positions=y, topology=topo, fps=fps, tracking_state=states)
    return seq, truth, states == INFERRED


def test_inferred_samples_are_covered_by_their_sd_monte_carlo():
    # 12 joints x 9 occlusions x 3 seeds = 324 shared errors: the coverage of the 95 %
    # ball over the inferred samples has a standard error of about 1.2 points
    hits, old_hits, n = 0, 0, 0
    for seed in range(3):
        seq, truth, inf = _occluded_joints(seed, 0.03)
        out = tk.smooth(seq, method="robust", noise="fixed", noise_sd=0.005)
        sd = out.metadata["diagnostics"]["guess_error_sd"]
        assert 0.02 < sd < 0.04  # the estimate of 0.03 from 216 changes
        err2 = np.sum((out.positions - truth) ** 2, axis=-1)
        ok = inf & np.isfinite(err2)
        hits += np.sum(err2[ok] <= 7.8147 * out.std[ok] ** 2)
        n += ok.sum()
        old = tk.smooth(seq, method="robust", noise="fixed", noise_sd=0.005,
                        shared_errors=False)  # fmt: skip
        np.testing.assert_array_equal(old.positions, out.positions)  # the estimate stays
        assert np.isnan(old.metadata["diagnostics"]["guess_error_sd"])
        old_hits += np.sum(err2[ok] <= 7.8147 * old.std[ok] ** 2)
    assert 0.90 < hits / n < 0.99
    assert old_hits / n < 0.6  # each guess independent: far too confident


def test_image_keypoints_have_two_coordinates_to_share_the_error():
    # a 2-D sequence reaches the smoother with a third axis of zeros: the guesses' error
    # is spread over its two real coordinates, s = 0.03 per axis as in 3-D (3 seeds x
    # 12 joints x 9 occlusions: the standard error of the pooled estimate is about 3 %;
    # over three axes it would come out 0.03 sqrt(2 / 3) = 0.0245)
    sds = []
    for seed in range(3):
        seq, _, _ = _occluded_joints(seed, 0.03)
        flat = seq.replace(positions=seq.positions[..., :2], units="m")
        out = tk.smooth(flat, method="robust", noise="fixed", noise_sd=0.005)
        sds.append(out.metadata["diagnostics"]["guess_error_sd"])
    assert np.mean(sds) == pytest.approx(0.03, rel=0.1)


def test_sustained_failures_are_covered_by_their_sd_on_the_benchmark():
    # the built-in benchmark's sustained failures (truth known; bridged by carrying):
    # the share of their rejected samples within the 95 % ball of the sd
    hits, old_hits = [], []
    for seed in range(3):
        out = {}
        run_benchmark(seed, ["robust", "robust[shared_errors=false]"], outputs=out)
        cor = out["corrupted"]
        rej = out["robust"].metadata["diagnostics"]["rejected"]
        m = (cor.labels == SUSTAINED) & rej
        for name, acc in (("robust", hits), ("robust[shared_errors=false]", old_hits)):
            o = out[name]
            np.testing.assert_array_equal(o.positions, out["robust"].positions)
            acc.append(in_sd_ball(o.positions, cor.truth, o.std)[m])
    cover, old = np.nanmean(np.concatenate(hits)), np.nanmean(np.concatenate(old_hits))
    assert cover > 0.85 and old < 0.8
