"""tools/motion_gain.py: the tracker's motion amplitude against the truth's and the error
per frequency band (docs/robust.md, "Where it does not help")."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import tool_module


def _tool():
    tool_module("error_breakdown")  # what the script imports from tools/, its own folder
    return tool_module("motion_gain")


def test_a_scaled_and_shifted_track_has_exactly_its_scale_as_gain():
    mg = _tool()
    rng = np.random.default_rng(0)
    truth = rng.normal(size=(50, 3, 3))
    track = 1.1 * truth + np.array([0.3, -0.2, 1.0])  # offsets per axis do not count
    track[7, 1] = np.nan  # a missing sample is left out
    gain, motion = mg.amplitude_gain(track, truth)
    assert gain == pytest.approx(1.1, rel=1e-12)
    # the truth's RMS motion: the centred truth's 3-D length, over the samples used
    ok = np.ones((50, 3), dtype=bool)
    ok[7, 1] = False
    sq = [np.sum((truth[ok[:, j], j] - truth[ok[:, j], j].mean(0)) ** 2) for j in range(3)]
    assert motion == pytest.approx(np.sqrt(sum(sq) / ok.sum()), rel=1e-12)


def test_independent_noise_leaves_the_gain_at_one_within_its_standard_error():
    mg = _tool()
    rng = np.random.default_rng(1)
    n = 4000
    truth = rng.normal(scale=0.2, size=(n, 1, 3))
    track = truth + rng.normal(scale=0.05, size=(n, 1, 3))
    gain, _ = mg.amplitude_gain(track, truth)
    # the slope's standard error: noise sd / (truth sd * sqrt(3 n))
    se = 0.05 / (0.2 * np.sqrt(3 * n))
    assert abs(gain - 1.0) < 4 * se


def test_no_gain_without_two_common_samples():
    mg = _tool()
    track = np.full((5, 1, 3), np.nan)
    gain, motion = mg.amplitude_gain(track, np.zeros((5, 1, 3)))
    assert np.isnan(gain) and np.isnan(motion)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(2, 80), fps=st.sampled_from([15.0, 30.0, 60.0]), seed=st.integers(0, 999))
def test_the_bands_add_up_to_the_centred_errors_sum_of_squares(n, fps, seed):
    # Parseval's identity, for odd and even lengths
    mg = _tool()
    err = np.random.default_rng(seed).normal(size=(n, 3))
    power, frames = mg.band_power(err, fps)
    assert frames == n
    assert power.sum() == pytest.approx(np.sum((err - err.mean(0)) ** 2), rel=1e-9)


def test_a_sine_lands_in_its_own_band():
    mg = _tool()
    fps, n = 30.0, 300
    t = np.arange(n) / fps
    # a band holds its lower edge, not its upper one
    for f, band in ((0.5, 0), (1.0, 1), (2.0, 1), (2.5, 2), (4.0, 2), (5.0, 3), (8.0, 3)):
        err = np.zeros((n, 3))
        err[:, 1] = np.sin(2 * np.pi * f * t)  # whole periods: no leakage
        power, _ = mg.band_power(err, fps)
        assert power[band] == pytest.approx(n / 2, rel=1e-9)
        assert power.sum() == pytest.approx(n / 2, rel=1e-9)


@pytest.mark.parametrize(
    "mask, expect",
    [
        ([1, 1, 0, 1, 1, 1, 0], slice(3, 6)),
        ([0, 0], slice(0, 0)),
        ([1, 1, 1], slice(0, 3)),
        ([1, 0, 1], slice(0, 1)),  # the first of equal runs
    ],
)
def test_longest_run(mask, expect):
    assert _tool().longest_run(np.array(mask, dtype=bool)) == expect
