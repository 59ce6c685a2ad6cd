"""Time alignment: resampling, lag search, mocap offset and rate recovery."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tobitkf.evaluation.alignment import (
    distance_signals,
    find_lag,
    fit_time_alignment,
    mocap_times,
    resample,
)
from tobitkf.evaluation.synthetic import generate_motion


@settings(deadline=None, max_examples=40)
@given(
    a=st.floats(-5, 5),
    b=st.floats(-5, 5),
    n=st.integers(2, 40),
    seed=st.integers(0, 1000),
)
def test_resample_reproduces_linear_functions(a: float, b: float, n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    ts = np.sort(rng.uniform(0, 10, n))
    ts = ts[np.concatenate([[True], np.diff(ts) > 1e-6])]
    if len(ts) < 2:
        return
    td = rng.uniform(ts[0], ts[-1], 25)
    vals = np.stack([a * ts + b, -b * ts + a], axis=1)
    out = resample(ts, vals, td)
    np.testing.assert_allclose(out, np.stack([a * td + b, -b * td + a], axis=1), atol=1e-9)


def test_resample_outside_range_is_nan_and_exact_hits_ignore_nan_neighbours() -> None:
    ts = np.array([0.0, 1.0, 2.0, 3.0])
    v = np.array([[0.0], [np.nan], [2.0], [3.0]])
    out = resample(ts, v, np.array([-0.5, 0.0, 0.5, 2.0, 2.5, 3.0, 3.5]))
    assert np.isnan(out[0, 0]) and np.isnan(out[-1, 0])
    assert out[1, 0] == 0.0 and out[3, 0] == 2.0 and out[5, 0] == 3.0
    assert np.isnan(out[2, 0])  # interpolates with a missing sample
    assert out[4, 0] == pytest.approx(2.5)


def test_resample_validates() -> None:
    with pytest.raises(ValueError, match="increasing"):
        resample([0.0, 0.0, 1.0], np.zeros(3), [0.5])
    with pytest.raises(ValueError, match="do not match"):
        resample([0.0, 1.0], np.zeros(3), [0.5])


def test_mocap_times() -> None:
    np.testing.assert_allclose(mocap_times(4, 100.0, 0.5), [0.5, 0.51, 0.52, 0.53])
    with pytest.raises(ValueError):
        mocap_times(3, 0.0)


def test_distance_signals_are_rigid_invariant() -> None:
    rng = np.random.default_rng(0)
    p = rng.normal(size=(20, 5, 3))
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    d1 = distance_signals(p)
    d2 = distance_signals(p @ q.T + rng.normal(size=3))
    assert d1.shape == (20, 10)
    np.testing.assert_allclose(d1, d2, atol=1e-12)


@settings(deadline=None, max_examples=25)
@given(lag=st.integers(-8, 8), seed=st.integers(0, 1000))
def test_find_lag_recovers_a_shift(lag: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    base = np.cumsum(rng.normal(size=(140, 3)), axis=0)
    ref = base[20:120]
    sig = base[20 - lag : 120 - lag]  # sig[t] = base[t + 20 - lag] = ref[t - lag]
    res = find_lag(ref, sig, max_lag=10)
    assert res.lag == lag
    assert abs(res.lag_refined - lag) < 0.5
    assert res.correlation == pytest.approx(1.0)


def _signals(seq, rate: float, offset: float, dur_frac=(0.1, 0.9)):
    """Track-side and mocap-side distance signals of one clean sequence."""
    p = seq.positions
    tt = seq.times()
    # the mocap samples the same motion at its own clock: frame k at offset + k / rate
    n = int((tt[-1] - offset) * rate)
    mt = mocap_times(n, rate, offset)
    keep = (mt >= tt[0]) & (mt <= tt[-1])
    mp = resample(tt, p, mt[keep])
    first = int(np.argmax(keep))
    pairs = [(0, 7), (0, 11), (7, 11), (3, 14), (3, 18), (11, 18)]
    return tt, distance_signals(p, pairs), distance_signals(mp, pairs), first


def test_fit_offset_and_rate_recovers_uiprmd_like_timing() -> None:
    seq = generate_motion("mixed", duration=6.0, seed=5)
    true_rate, true_offset = 88.0, 0.4
    tt, st_, sm, first = _signals(seq, true_rate, true_offset)
    # the mocap file starts `first` frames after the generated clock's zero
    offset_of_file = true_offset + first / true_rate
    res = fit_time_alignment(tt, st_, sm, rate=100.0, fit_rate=True, rate_range=(70.0, 110.0))
    assert res.rate_fitted
    assert res.rate_hz == pytest.approx(true_rate, abs=1.0)
    assert res.offset_s == pytest.approx(offset_of_file, abs=0.015)
    assert res.correlation > 0.99


def test_fit_offset_only_finds_zero_lag_at_known_rate() -> None:
    seq = generate_motion("mixed", duration=8.0, seed=6)  # not periodic: one answer
    tt, st_, sm, first = _signals(seq, 60.0, 0.0)
    res = fit_time_alignment(tt, st_, sm, rate=60.0)
    assert not res.rate_fitted and res.rate_hz == 60.0
    assert res.offset_s == pytest.approx(first / 60.0, abs=0.01)


def _periodic(t: np.ndarray) -> np.ndarray:
    """Two signals of a 1.02 s cycle (a stride) and a slow drift: the next cycle
    correlates almost as well as the right one (0.99 and more)."""
    w = 2 * np.pi / 1.02
    drift = 0.1 * np.sin(0.41 * t)
    return np.stack(
        [np.sin(w * t) + 0.3 * np.sin(2 * w * t + 1) + drift, np.cos(w * t + 0.2) - drift], axis=1
    )


@pytest.mark.parametrize("offset", [0.0, 0.37, -0.211])
def test_a_periodic_movement_aligns_to_its_own_cycle(offset: float) -> None:
    """The grid's best point may sit on the next cycle (its step is a few hundredths of
    the range): each grid maximum is refined, the true one wins."""
    tt = np.arange(300) / 30.0
    t_mocap = np.arange(1000) / 100.0  # mocap frame k at track time offset + k / 100
    res = fit_time_alignment(tt, _periodic(tt), _periodic(offset + t_mocap), rate=100.0)
    assert res.offset_s == pytest.approx(offset, abs=1e-4)
    assert res.correlation == pytest.approx(1.0, abs=1e-6)


def test_mocap_with_its_own_clock_aligns_on_its_timestamps() -> None:
    """Irregular mocap frames: their own times, not k / rate, place them."""
    rng = np.random.default_rng(3)
    tt = np.arange(300) / 30.0
    clock = np.cumsum(np.r_[0.0, rng.uniform(0.005, 0.02, 999)])  # about 80 Hz, jittered
    res = fit_time_alignment(
        tt, _periodic(tt), _periodic(0.5 + clock), rate=80.0, mocap_clock=clock
    )
    assert res.offset_s == pytest.approx(0.5, abs=1e-4)
    np.testing.assert_allclose(mocap_times(3, 80.0, 1.0, clock[:3], 80.0), 1.0 + clock[:3])
    # at another rate the clock stretches by nominal / rate
    np.testing.assert_allclose(mocap_times(3, 40.0, 0.0, clock[:3], 80.0), 2 * clock[:3])


def test_too_little_overlap_says_what_it_needs() -> None:
    tt = np.arange(300) / 30.0
    short = np.arange(100) / 100.0
    with pytest.raises(ValueError, match=r"at least 50 % of the track's 9.97 s; it lasts 1.00 s"):
        fit_time_alignment(tt, _periodic(tt), _periodic(short), rate=100.0)
