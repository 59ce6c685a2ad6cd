"""The offline smoother's down-weighting of the accepted samples it does not explain
(``robust``'s ``reweight``; :mod:`tobitkf.smoothing.robust_reweight`)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import tobitkf as tk
from tobitkf.smoothing.robust_reweight import huber_cut, huber_inflation


def test_the_cut_is_the_chi_99_percent_point():
    """Tabulated values of the chi distribution's 99 % point: sqrt(11.345) in 3-D,
    sqrt(9.210) in 2-D, 2.576 in 1-D (the normal's two-sided 99 %)."""
    assert huber_cut(3) == pytest.approx(np.sqrt(11.345), abs=1e-3)
    assert huber_cut(2) == pytest.approx(np.sqrt(9.210), abs=1e-3)
    assert huber_cut(1) == pytest.approx(2.5758, abs=1e-4)


def _gauss(T=4000, B=1, J=2, D=3, seed=0, sd=0.01):
    """A slow smooth track (the estimate) and samples of it with white noise ``sd``."""
    rng = np.random.default_rng(seed)
    t = np.arange(T)[:, None, None, None] / 30.0
    est = 0.3 * np.sin(0.5 * t + rng.uniform(0, 6, (1, B, J, D)))
    return est + rng.normal(0, sd, est.shape), est


def _white(y):
    """1.4826 · median |second difference| / sqrt(6), over time and axes."""
    dd = np.abs(y[2:] - 2 * y[1:-1] + y[:-2])
    return 1.4826 * np.median(dd) / np.sqrt(6.0)


@pytest.mark.parametrize("D", [2, 3])
def test_gaussian_residuals_one_in_a_hundred_is_inflated(D):
    """Monte Carlo: with Gaussian residuals, the share beyond the cut is 1 % (each of the
    two scale estimates, the residuals' median and the second differences' white noise,
    is exact to about 2 % on 8,000 samples, and the larger is taken, which moves the share
    by a few tenths of a point at most; binomial standard error of the share 0.11
    point)."""
    ys, est = _gauss(J=2, D=D)
    infl = huber_inflation(ys, est, np.ones(ys.shape[:3], bool), np.ones(ys.shape[:3]))
    share = float(np.mean(infl > 1.0))
    assert share == pytest.approx(0.01, abs=0.004)


def test_one_outlier_gets_its_distance_over_the_cut():
    """A residual of 12 cm on each axis (21 cm), where the noise is 1 cm per axis: the
    inflation is the standardised distance over the cut, the scale being the median of
    the squared distances over the chi-square median, or the samples' white noise from
    their second differences if larger (computed here from the definitions)."""
    ys, est = _gauss(T=2000, J=1)
    ys[100, 0, 0] = est[100, 0, 0] + 0.12
    use, rinf = np.ones(ys.shape[:3], bool), np.ones(ys.shape[:3])
    d2 = np.sum((ys - est) ** 2, axis=-1)[:, 0, 0]
    # chi-square median for 3 degrees of freedom; never below the white noise
    scale = max(np.median(d2) / 2.3659739, _white(ys[:, 0, 0]) ** 2)
    expected = np.sqrt(d2[100] / scale) / huber_cut(3)
    infl = huber_inflation(ys, est, use, rinf)
    assert infl[100, 0, 0] == pytest.approx(expected, rel=1e-7)
    assert expected > 6  # 20.8 noise units over a cut of 3.37


def test_only_accepted_samples_and_joints_with_enough_of_them_are_weighed():
    ys, est = _gauss(T=200, J=2)
    ys[50] += 1.0  # far off, both joints
    use = np.ones(ys.shape[:3], bool)
    use[50, 0, 0] = False  # not accepted: not weighed
    use[8:, 0, 1] = False
    use[50, 0, 1] = True  # 9 accepted samples: too few for a scale
    infl = huber_inflation(ys, est, use, np.ones(ys.shape[:3]))
    assert infl[50, 0, 0] == 1.0
    np.testing.assert_array_equal(infl[:, 0, 1], 1.0)


def test_a_sample_with_a_larger_variance_factor_is_judged_against_it():
    """An INFERRED sample (variance factor 4) with twice the residual of a plain one
    standardises to the same distance."""
    ys, est = _gauss(T=2000, J=1)
    ys[10, 0, 0] = est[10, 0, 0] + 0.1
    ys[20, 0, 0] = est[20, 0, 0] + 0.2
    rinf = np.ones(ys.shape[:3])
    rinf[20] = 4.0
    infl = huber_inflation(ys, est, np.ones(ys.shape[:3], bool), rinf)
    assert infl[20, 0, 0] == pytest.approx(infl[10, 0, 0], rel=1e-12)
    assert infl[10, 0, 0] > 1


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    scale=st.floats(1e-3, 1e3),
    n_dims=st.sampled_from([2, 3]),
    spikes=st.integers(0, 30),
)
def test_inflation_is_at_least_one_and_does_not_depend_on_the_unit(seed, scale, n_dims, spikes):
    ys, est = _gauss(T=120, J=3, seed=seed)
    ys[..., n_dims:] = est[..., n_dims:] = 0.0
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, 120, spikes)
    ys[idx] += rng.normal(0, 0.5, (spikes, 1, 3, 3)) * (np.arange(3) < n_dims)
    use = rng.random(ys.shape[:3]) < 0.9
    rinf = rng.choice([1.0, 4.0], ys.shape[:3])
    a = huber_inflation(ys, est, use, rinf)
    b = huber_inflation(ys * scale, est * scale, use, rinf)
    assert np.all(a >= 1.0)
    np.testing.assert_array_equal(a[~use], 1.0)
    np.testing.assert_allclose(a, b, rtol=1e-9)


def _spiky(seed=0, T=300):
    """A slow joint chain with Kinect-like noise and short flicks that stay inside the
    gates (6 cm for a frame: a hand's gate for one frame is 8 m/s · 1/30 s + 5 cm)."""
    rng = np.random.default_rng(seed)
    topo = tk.get_topology("kinect_v2")
    J = len(topo.joints)
    t = np.arange(T) / 30.0
    truth = np.zeros((T, J, 3))
    truth[:] = rng.uniform(-0.3, 0.3, (1, J, 3)) + np.array([0.0, 0.0, 2.5])
    truth += 0.05 * np.sin(0.8 * t)[:, None, None]
    ys = truth + rng.normal(0, 0.005, truth.shape)
    flicks = rng.choice(T - 2, 12, replace=False)
    for f in flicks:
        ys[f, rng.integers(0, J)] += rng.choice([-1, 1], 3) * 0.035
    return tk.SkeletonSequence(ys, topology=topo, fps=30.0), truth


def test_reweighting_brings_the_flicks_closer_without_moving_the_rest():
    """Against the known truth: the passes that down-weight the samples the track does
    not explain cut the error at one-frame flicks by more than 30 % (about half on
    seeds 0-3), and elsewhere do not make it worse by more than a tenth of the noise
    (0.5 mm)."""
    seq, truth = _spiky()
    kw = {"bones": False, "noise": "fixed"}  # the flicks are not to be rejected here
    one = tk.smooth(seq, method="robust", reweight=0, **kw)
    three = tk.smooth(seq, method="robust", **kw)
    assert not np.asarray(one.metadata["diagnostics"]["rejected"]).any()
    e1 = np.linalg.norm(one.positions - truth, axis=-1)
    e3 = np.linalg.norm(three.positions - truth, axis=-1)
    flick = np.linalg.norm(seq.positions - truth, axis=-1) > 0.04
    assert flick.sum() >= 10
    assert np.sqrt(np.mean(e3[flick] ** 2)) < 0.7 * np.sqrt(np.mean(e1[flick] ** 2))
    assert np.sqrt(np.mean(e3[~flick] ** 2)) < np.sqrt(np.mean(e1[~flick] ** 2)) + 0.0005
    assert three.metadata["provenance"]["params"]["reweight"] == 2


def test_robust_online_refuses_reweighting_with_the_reason():
    seq, _ = _spiky(T=40)
    tk.smooth(seq, method="robust_online", reweight=0)
    with pytest.raises(ValueError, match="robust_online weighs each sample once"):
        tk.smooth(seq, method="robust_online", reweight=2)
    with pytest.raises(ValueError, match="reweight must be an integer"):
        tk.smooth(seq, method="robust", reweight=1.5)


def test_held_samples_and_axes_without_coordinates_do_not_set_the_scale():
    """A joint held still for most frames (the sample repeats to the last bit) has a
    residual median near zero; the held samples are not read, so a sample 3 noise units
    off is not an outlier. And a 2-D track stored with a third axis of zeros is weighed as
    the 2-D track (2 degrees of freedom)."""
    ys, est = _gauss(T=1000, J=1)
    ys[200:900] = ys[199]
    est[200:900] = ys[199] + 1e-6  # the smoother a micrometre off the held sample
    ys[100, 0, 0] = est[100, 0, 0] + 0.03 / np.sqrt(3)
    infl = huber_inflation(ys, est, np.ones(ys.shape[:3], bool), np.ones(ys.shape[:3]))
    assert infl[100, 0, 0] == 1.0
    flat = ys.copy()
    flat[..., 2] = 0.0
    e2 = est.copy()
    e2[..., 2] = 0.0
    use, rinf = np.ones(ys.shape[:3], bool), np.ones(ys.shape[:3])
    np.testing.assert_array_equal(
        huber_inflation(flat, e2, use, rinf), huber_inflation(flat[..., :2], e2[..., :2], use, rinf)
    )


def test_a_track_without_noise_is_not_reweighted():
    """Noise-free samples of smooth motion: the residuals are rounding, far inside the
    white noise their second differences show (the motion's own curvature)."""
    _, est = _gauss(T=300, J=3, sd=0.0)
    ys = est + np.random.default_rng(1).normal(0, 1e-12, est.shape)
    infl = huber_inflation(ys, est, np.ones(ys.shape[:3], bool), np.ones(ys.shape[:3]))
    np.testing.assert_array_equal(infl, 1.0)
