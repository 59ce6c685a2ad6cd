"""The floor of the robust smoother's standard deviation: the samples' own white noise,
read from their second differences, where the fitted noise is smaller
(:func:`tobitkf.smoothing.robust_fit.sd_floor`)."""

from __future__ import annotations

import numpy as np
import pytest

import tobitkf as tk
from conftest import data_file
from tobitkf.evaluation.benchmark import run_benchmark
from tobitkf.smoothing import robust_fit


def _tracks(sigma, T=600, J=4, seed=0):
    """Slow smooth motion (a few cm/s) plus white noise of ``sigma`` per axis."""
    rng = np.random.default_rng(seed)
    t = np.arange(T)[:, None, None, None] / 30.0
    motion = 0.05 * np.sin(0.5 * t + rng.uniform(0, 6, (1, 1, J, 3)))
    return motion + rng.normal(0, sigma, (T, 1, J, 3))


@pytest.mark.parametrize(("fitted", "n_dims"), [(0.005, 3), (0.02, 3), (0.005, 2)])
def test_the_scale_is_the_noise_over_the_fitted_error(fitted, n_dims):
    """1 cm of white noise: a fit that found 0.5 cm gets its variance scaled by (1/0.5)²
    = 4 (the second-difference estimate of 10,000 samples is within a few per cent);
    one that found 2 cm keeps it (scale 1). In 2-D, the third axis of zeros the
    smoother carries is not read."""
    ys = _tracks(0.01, T=900)
    ys[..., n_dims:] = 0.0
    J = ys.shape[2]
    use = np.ones(ys.shape[:3], bool)
    fits = {"noise_sd": np.full((1, J), fitted * 0.8), "error_sd": np.full((1, J), fitted * 0.6)}
    reports = [{"arms": {"fitted": True}}]
    scale = robust_fit.sd_floor(ys, use, {"arms": list(range(J))}, fits, reports, n_dims)
    expected = max(1.0, (0.01 / fitted) ** 2)  # m = fitted (0.8² + 0.6² = 1)
    np.testing.assert_allclose(scale, expected, rtol=0.1)
    assert reports[0]["arms"]["sd_scale"] == pytest.approx(np.sqrt(scale[0, 0]))
    np.testing.assert_allclose(reports[0]["arms"]["noise_floor"], 0.01, rtol=0.05)


def test_regions_not_fitted_or_with_few_samples_keep_their_sd():
    ys = _tracks(0.01, T=20)
    use = np.ones(ys.shape[:3], bool)
    fits = {"noise_sd": np.full((1, 4), 1e-4), "error_sd": np.zeros((1, 4))}
    groups = {"arms": [0, 1], "legs": [2, 3]}
    reports = [{"arms": {"fitted": False}, "legs": {"fitted": True}}]
    use[:, :, 2:] = False
    use[:5, :, 2:] = True  # 3 frames of second differences: too few
    np.testing.assert_array_equal(robust_fit.sd_floor(ys, use, groups, fits, reports, 3), 1.0)


def _cmu(seed):
    out = {}
    table = run_benchmark(seed, ["raw", "robust"], source=data_file(
        "cmu-mocap/scaled_131_01.bvh"), outputs=out)  # fmt: skip
    return table, out


@pytest.mark.realdata
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_sd_covers_the_truth_on_a_motion_the_fit_follows_too_closely(seed):
    """The synthetic corruption of the CMU run (the feet at up to 9 m/s): the fit
    explains half of the legs' noise as motion. With the floor, the clean samples' error
    is within the 95 % ball of the sd about 95 % of the time (without: 76-84 %)."""
    table, _ = _cmu(seed)
    row = next(r for r in table.to_dict()["rows"] if r["method"] == "robust")
    assert 90.0 <= row["clean_in_95_ball_pct"] <= 99.5


@pytest.mark.realdata
def test_the_floor_changes_the_sd_not_the_estimate(monkeypatch):
    _, out = _cmu(1)
    seq = out["corrupted"].sequence
    floored = tk.smooth(seq, "robust")
    monkeypatch.setattr(robust_fit, "sd_floor", lambda ys, *a: np.ones(ys.shape[1:3]))
    plain = tk.smooth(seq, "robust")
    np.testing.assert_array_equal(floored.positions, plain.positions)
    legs = seq.topology.joint_groups()["legs"]
    assert np.nanmedian(floored.std[:, legs] / plain.std[:, legs]) > 1.5
    fits = floored.metadata["diagnostics"]["noise_fit"]
    assert fits["legs"]["sd_scale"] > 1.5 and fits["hands"]["sd_scale"] == 1.0  # m > floor
