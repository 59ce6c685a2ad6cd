"""Bivariate normal CDF (tobitkf.core._bvn): scipy agreement, exact identities, tails."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate
from scipy.special import ndtr
from scipy.stats import multivariate_normal

from tobitkf.core._bvn import bivariate_normal_cdf, bivariate_normal_upper

finite = st.floats(-8.0, 8.0, allow_nan=False)
corr = st.floats(-1.0, 1.0, allow_nan=False)


def _random_points(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    x = rng.normal(0.0, 2.0, n)
    y = rng.normal(0.0, 2.0, n)
    r = rng.uniform(-1.0, 1.0, n)
    # a third of the correlations within 1e-9 .. 1e-1 of ±1, including ±(1 - 1e-9)
    k = n // 3
    r[:k] = np.sign(r[:k]) * (1.0 - 10.0 ** rng.uniform(-9.0, -1.0, k))
    r[0], r[1] = 1.0 - 1e-9, -(1.0 - 1e-9)
    # and every branch of Genz's rule (|r| < 0.3, < 0.75, < 0.925, >= 0.925)
    r[2:6] = [0.1, -0.5, 0.9, -0.93]
    return x, y, r


def test_agrees_with_scipy_multivariate_normal_cdf():
    # scipy >= 1.10 evaluates the 2-D CDF deterministically with Genz's BVNU as
    # 1 - Φ(-x) - Φ(-y) + BVNU(x, y) (scipy.stats._qmvnt._bvn), accurate to ~1e-16 absolute;
    # it is slow (~100 µs/point), hence a modest number of points.
    x, y, r = _random_points(150, seed=11)
    ours = bivariate_normal_cdf(x, y, r)
    ref = np.array(
        [
            multivariate_normal.cdf([xi, yi], mean=[0.0, 0.0], cov=[[1.0, ri], [ri, 1.0]])
            for xi, yi, ri in zip(x, y, r)
        ]
    )
    assert np.max(np.abs(ours - ref)) <= 1e-14


def test_agrees_with_scipy_bvnu_on_many_points():
    bvnu = pytest.importorskip("scipy.stats._stats_pythran")._bvnu
    x, y, r = _random_points(3000, seed=12)
    ours = bivariate_normal_upper(x, y, r)
    ref = np.array([bvnu(xi, yi, ri) for xi, yi, ri in zip(x, y, r)])
    assert np.max(np.abs(ours - ref)) <= 1e-14


def test_sheppard_quadrant_formula():
    # Φ2(0, 0; ρ) = 1/4 + asin(ρ)/(2π) (Sheppard 1899), independent of the algorithm
    r = np.array([-1.0, -0.999999999, -0.95, -0.6, -0.2, 0.0, 0.25, 0.5, 0.8, 0.93, 1.0])
    expected = 0.25 + np.arcsin(r) / (2.0 * np.pi)
    np.testing.assert_allclose(bivariate_normal_cdf(0.0, 0.0, r), expected, rtol=0, atol=1e-15)


def test_closed_forms_at_rho_limits_and_infinite_arguments():
    x = np.array([-3.0, -0.4, 0.0, 0.7, 2.5])
    y = np.array([1.0, -1.2, 0.3, 0.7, -2.0])
    np.testing.assert_allclose(bivariate_normal_cdf(x, y, 0.0), ndtr(x) * ndtr(y), atol=1e-16)
    np.testing.assert_allclose(bivariate_normal_cdf(x, y, 1.0), ndtr(np.minimum(x, y)), atol=1e-16)
    np.testing.assert_allclose(
        bivariate_normal_cdf(x, y, -1.0), np.maximum(ndtr(x) - ndtr(-y), 0.0), atol=1e-16
    )
    np.testing.assert_array_equal(bivariate_normal_cdf(x, np.inf, 0.7), ndtr(x))
    np.testing.assert_array_equal(bivariate_normal_cdf(np.inf, y, -0.3), ndtr(y))
    np.testing.assert_array_equal(bivariate_normal_cdf(x, -np.inf, 0.7), 0.0)
    assert bivariate_normal_cdf(np.inf, np.inf, 0.5) == 1.0


def _quad_cdf(x: float, y: float, r: float) -> float:
    """P(X<=x, Y<=y) = ∫_{-inf}^{x} φ(s) Φ((y - r s)/sqrt(1-r²)) ds by adaptive quadrature."""
    sig = np.sqrt(1.0 - r * r)
    val, _ = integrate.quad(
        lambda s: np.exp(-0.5 * s * s) / np.sqrt(2 * np.pi) * ndtr((y - r * s) / sig),
        -np.inf,
        x,
        epsabs=0.0,
        epsrel=1e-13,
        limit=200,
    )
    return val


@pytest.mark.parametrize(
    ("x", "y", "r"),
    [(-7.0, -6.0, 0.5), (-8.0, -8.5, 0.2), (-6.0, -6.0, 0.95), (-5.0, -7.0, 0.99), (-9, -3, 0.6)],
)
def test_lower_tail_accuracy(x, y, r):
    # Computed as an upper orthant (no 1 - ... cancellation). Genz's short rules bound the
    # relative error in far tails: measured against 40-digit mpmath, 2e-6 at
    # (-8, -8.5, 0.2) with the 6-point rule, 2.6e-10 at (-9, -3, 0.6) with 12 points,
    # < 1e-14 with the 20-point and large-|rho| branches.
    ref = _quad_cdf(x, y, r)
    got = float(bivariate_normal_cdf(x, y, r))
    assert ref > 0
    rtol = 1e-12 if abs(r) >= 0.75 else 1e-5
    assert abs(got - ref) <= rtol * ref


@settings(max_examples=60, deadline=None)
@given(finite, finite, corr)
def test_symmetries(x, y, r):
    p = bivariate_normal_cdf(x, y, r)
    # exchangeability
    assert abs(p - bivariate_normal_cdf(y, x, r)) <= 1e-15
    # P(X<=x, Y<=y) + P(X<=x, Y>y) = Φ(x), and P(X<=x, Y>y; r) = Φ2(x, -y; -r)
    assert abs(p + bivariate_normal_cdf(x, -y, -r) - ndtr(x)) <= 2e-15
    assert 0.0 <= p <= min(ndtr(x), ndtr(y)) + 1e-16


def test_monotone_in_rho():
    # ∂Φ2/∂ρ = φ2 > 0 (Plackett), so the CDF increases with ρ
    r = np.linspace(-1.0, 1.0, 2001)
    p = bivariate_normal_cdf(0.3, -0.8, r)
    assert np.all(np.diff(p) >= -1e-16)


def test_broadcasting_shapes_and_validation():
    out = bivariate_normal_cdf(np.zeros((2, 1)), np.zeros((1, 3)), 0.5)
    assert out.shape == (2, 3)
    np.testing.assert_allclose(out, 1.0 / 3.0, atol=1e-15)
    with pytest.raises(ValueError, match="rho"):
        bivariate_normal_cdf(0.0, 0.0, 1.5)
    assert np.isnan(bivariate_normal_cdf(np.nan, 0.0, 0.5))


@settings(max_examples=80, deadline=None)
@given(finite, corr, st.floats(3.0, 308.0), st.booleans())
def test_a_limit_beyond_1e3_sd_is_an_infinite_one(h, r, log_k, swap):
    # P(X > h, Y > k) = Q(h) for k = -huge, 0 for k = +huge (to below 1e-300). Drezner's
    # expansion raised (h - k)² to the square and h k times it: NaN from |k| ~ 1e77 on
    k = 10.0**log_k
    args = [(h, -k), (h, k)]
    if swap:
        args = [(b, a) for a, b in args]
    low = bivariate_normal_upper(*args[0], r)
    assert abs(low - ndtr(-h)) <= 1e-15 * ndtr(-h)
    assert bivariate_normal_upper(*args[1], r) == 0.0
    # the CDF: P(X <= h, Y <= huge) = Φ(h), P(X <= h, Y <= -huge) = 0
    assert abs(bivariate_normal_cdf(h, k, r) - ndtr(h)) <= 1e-15 * ndtr(h)
    assert bivariate_normal_cdf(h, -k, r) == 0.0
