"""Tests of fit_limits: per-axis displacement limits from clean motion capture."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import data_file
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology
from tobitkf.smoothing.fit import fit_limits


def _seq(pos, up_axis=1, **kw):
    names = [f"j{i}" for i in range(pos.shape[1])]
    return SkeletonSequence(pos, Topology.from_names(names, up_axis=up_axis), **kw)


def _brute_force_max(pos, steps):
    """Largest |x_k - x_{k-1}| * (1/30) / dt_k per axis, skipping NaN pairs, by loops."""
    best = [0.0, 0.0, 0.0]
    T, J, _ = pos.shape
    for k in range(1, T):
        for j in range(J):
            a, b = pos[k - 1, j], pos[k, j]
            if np.isnan(a).any() or np.isnan(b).any():
                continue
            for d in range(3):
                v = abs(b[d] - a[d]) * (1 / 30) / steps[k - 1]
                best[d] = max(best[d], v)
    return best


def test_known_displacements_at_60_fps():
    T = 20
    pos = np.zeros((T, 2, 3))
    # joint 0 moves 1 cm/frame in x; joint 1 jumps 5 cm in z once and 2 cm in y once
    pos[:, 0, 0] = 0.01 * np.arange(T)
    pos[10:, 1, 2] = 0.05
    pos[15:, 1, 1] = -0.02
    fit = fit_limits(_seq(pos, fps=60.0))
    # at 60 fps a 1/30 s step holds two frames: limits are twice the per-frame steps
    np.testing.assert_allclose(fit.c, [0.02, 0.04, 0.10], atol=1e-12)
    np.testing.assert_allclose(fit.maxima, fit.c)
    assert fit.fps == 60.0
    assert fit.c_vertical == pytest.approx(0.04)
    assert fit.c_horizontal == pytest.approx(0.10)
    assert fit.as_params() == {"c": pytest.approx((0.02, 0.04, 0.10))}
    # an explicit fps overrides the sequence's
    np.testing.assert_allclose(fit_limits(_seq(pos, fps=60.0), fps=30.0).c, [0.01, 0.02, 0.05])


@settings(deadline=None, max_examples=30)
@given(
    seed=st.integers(0, 10_000),
    irregular=st.booleans(),
    nan_rate=st.sampled_from([0.0, 0.1, 0.3]),
)
def test_max_matches_brute_force(seed, irregular, nan_rate):
    rng = np.random.default_rng(seed)
    T, J = 15, 3
    pos = np.cumsum(rng.normal(scale=0.02, size=(T, J, 3)), axis=0)
    pos[rng.random((T, J)) < nan_rate] = np.nan
    if not np.isfinite(pos).all(axis=-1)[:-1][np.isfinite(pos).all(axis=-1)[1:]].any():
        pos[:2, 0] = 0.0  # make sure one finite pair exists
        pos[1, 0, 0] = 0.01
    if irregular:
        t = np.cumsum(rng.uniform(0.005, 0.05, size=T))
        seq = _seq(pos, timestamps=t)
        steps = np.diff(t)
    else:
        seq = _seq(pos, fps=100.0)
        steps = np.full(T - 1, 0.01)
    fit = fit_limits(seq)
    np.testing.assert_allclose(fit.maxima, _brute_force_max(pos, steps), rtol=1e-12)
    assert np.all(fit.quantiles <= fit.maxima + 1e-15)
    assert fit_limits(seq, method="quantile", q=1.0).c == pytest.approx(fit.maxima)


def test_quantile_ignores_a_rare_outlier():
    rng = np.random.default_rng(5)
    T = 2001
    pos = np.zeros((T, 1, 3))
    pos[:, 0, :] = np.cumsum(rng.uniform(-0.01, 0.01, size=(T, 3)), axis=0)
    pos[1000:, 0, 1] += 0.5  # one marker swap: a single 0.5 m step in y
    fit = fit_limits(_seq(pos, fps=30.0), method="quantile", q=0.99)
    assert fit.maxima[1] > 0.49
    # |U(-0.01, 0.01)| has 0.99 quantile 0.0099 (standard error of the estimate ~ 2e-5)
    np.testing.assert_allclose(fit.c, 0.0099, atol=3e-4)
    assert fit.method == "quantile"


def test_arrays_lists_and_up_axis():
    pos = np.zeros((5, 1, 3))
    pos[:, 0, 2] = 0.01 * np.arange(5)
    fit = fit_limits(pos, fps=30.0, up_axis=2)
    assert fit.c_vertical == pytest.approx(0.01)
    assert fit.c_horizontal == 0.0
    # topology's up axis is used by default
    assert fit_limits(_seq(pos, up_axis=2, fps=30.0)).up_axis == 2
    # a list is pooled
    pos2 = pos * 3
    pooled = fit_limits([_seq(pos, fps=30.0), _seq(pos2, fps=30.0)])
    assert pooled.c[2] == pytest.approx(0.03)
    assert pooled.n_steps == 8


def test_errors():
    pos = np.zeros((5, 1, 3))
    with pytest.raises(ValueError, match="fps"):
        fit_limits(pos)
    with pytest.raises(ValueError, match="method"):
        fit_limits(pos, fps=30, method="mean")
    with pytest.raises(ValueError, match="q"):
        fit_limits(pos, fps=30, q=0.0)
    with pytest.raises(ValueError, match="2 frames"):
        fit_limits(pos[:1], fps=30)
    with pytest.raises(ValueError, match="finite"):
        fit_limits(np.full((5, 1, 3), np.nan), fps=30)
    with pytest.raises(ValueError, match="shape"):
        fit_limits(np.zeros((5, 2, 2)), fps=30)


def test_keraal_vicon_limits_are_of_the_papers_order():
    path = data_file("keraal/G3-Vicon-ELK-P1T1-Unknown-C-0.txt")
    rows = [line.split() for line in path.read_text().splitlines() if line.strip()]
    data = np.array(rows, dtype=float).reshape(len(rows), 17, 7)
    pos = data[:, :, :3] / 1000.0  # mm -> m, z up
    fit = fit_limits(pos, fps=60.0, up_axis=2)
    np.testing.assert_allclose(fit.maxima, _brute_force_max(pos, np.full(len(pos), 1 / 60)))
    # README: steps of up to ~130 mm per 60 Hz frame -> ~0.26 m per 1/30 s; the paper's
    # Vicon limits were 0.34 m (horizontal) and 0.18 m (vertical)
    assert 0.1 < fit.c_horizontal < 0.5
    assert 0.02 < fit.c_vertical < 0.5
