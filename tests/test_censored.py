"""Clipped-normal moments (tobitkf.core.censored): reference file, high-precision values,
Monte Carlo, properties, tails, likelihood."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import norm, truncnorm

from tobitkf.core.censored import (
    ClippedMoments,
    TruncatedStats,
    censored_logpdf,
    clipped_normal_moments,
    clipped_normal_moments_diag,
    clipped_normal_variance_diag,
    truncated_standard_normal,
)

INF = np.inf
REFERENCE = (
    Path(__file__).resolve().parents[1]
    / ".."
    / "shared"
    / "reference"
    / "clipped_normal_cases.json"
).resolve()


def _reference_cases() -> list:
    """Cases of ../shared/reference/clipped_normal_cases.json ([None] when missing)."""
    if not REFERENCE.exists():
        return [None]
    return json.loads(REFERENCE.read_text())["cases"]


def _arr(x) -> np.ndarray:
    return np.array(x, dtype=float)  # the file writes infinities as "inf" / "-inf"


# ---------------------------------------------------------------------------------------
# Reference file
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "case", _reference_cases(), ids=lambda c: "missing" if c is None else c["name"]
)
def test_reference_cases(case):
    if case is None:
        msg = f"reference file not found: {REFERENCE}"
        if os.environ.get("TOBITKF_REQUIRE_DATA") == "1":
            pytest.fail(msg + " (TOBITKF_REQUIRE_DATA=1)")
        pytest.skip(msg)
    S = _arr(case["cov_latent"])
    res = clipped_normal_moments(
        _arr(case["mean_latent"]), S, _arr(case["lower"]), _arr(case["upper"])
    )
    var_scale = float(np.max(np.diag(S)))
    sd_scale = np.sqrt(var_scale)
    # means: relative 1e-9, absolute floor 1e-12 x the latent standard-deviation scale
    np.testing.assert_allclose(res.mean, _arr(case["mean"]), rtol=1e-9, atol=1e-12 * sd_scale)
    # probabilities: relative 1e-9 only (tail probabilities down to 1e-300 must match)
    for key in ("p_uncensored", "p_lower", "p_upper"):
        np.testing.assert_allclose(getattr(res, key), _arr(case[key]), rtol=1e-9, atol=0.0)
    # (co)variances: relative 1e-7, absolute floor 1e-12 x the latent variance scale. The
    # floor matters for one case only: far_lower_tail's variance in the file
    # (8.334216631886e-303) is 1.2e-7 relative below the exact 8.334217629428e-303 (80-digit
    # mpmath, by the closed form and by quadrature; see test_univariate_high_precision).
    np.testing.assert_allclose(res.cov, _arr(case["cov"]), rtol=1e-7, atol=1e-12 * var_scale)
    assert isinstance(res, ClippedMoments)


# ---------------------------------------------------------------------------------------
# Independent high-precision values (mpmath, computed once offline)
# ---------------------------------------------------------------------------------------

# (alpha, beta, log P_un, mu_T, v_T) from the closed forms of MATH.md §2 evaluated in
# 80-digit mpmath at the exact binary values of alpha and beta (cancellation is harmless
# at that precision). They cover the far-tail branch, both sides of its 3-sd switch, both
# sides of the narrow-interval switch, P_un far below the float range, width 1e-6.
TRUNCATED_MP = [
    (-INF, -37, -689.03058557689059, -37.02698768612699, 0.00072727809887751334),
    (9, INF, -43.628149113332115, 9.1085231050028688, 0.011514790654717133),
    (40, 41, -804.60844201375379, 40.024968847207264, 0.00062266837859138626),
    (40, INF, -804.60844201375379, 40.024968847207264, 0.00062266837859138877),
    (-1000, -999, -499008.32569431385, -999.001000998995, 1.0019969799951863e-6),
    (36, 36.000001, -662.73446709363983, 36.000000499996999, 8.3333332907137674e-14),
    (-9, -8.000000000001, -35.013618593445272, -8.1211889929807816, 0.014148542782743739),
    (-9, -7.999999999999, -35.013618593429025, -8.1211889929788126, 0.014148542782752483),
    (-1.5, -0.500000000001, -1.4199324821580827, -0.92064460522264795, 0.076942097942303552),
    (-1.5, -0.499999999999, -1.4199324821551699, -0.92064460522142269, 0.076942097942594832),
    (0.1, 0.100001, -14.739449141168113, 0.10000049999999167, 8.3333333333497195e-14),
    (-3e-7, 5e-7, -14.957592642483188, 9.9999999999994662e-8, 5.3333333333332191e-14),
    (-2, 3, -0.024395187554887346, 0.050782989674878974, 0.87314863997540568),
    (-0.5, INF, -0.36894641528865639, 0.50916043383703349, 0.4861754356963671),
    (8.2, 10.2, -36.657428609686717, 8.3185675145129114, 0.013687955648491003),
    (-20, -19.99, -205.42246011261057, -19.994833486476576, 8.3166737711185236e-6),
    (-3.0, -2.9, -7.5695680138074889, -2.9475460408656944, 0.00082944546438804041),
]


@pytest.mark.parametrize(("a", "b", "logp", "mu", "v"), TRUNCATED_MP)
def test_truncated_standard_normal_high_precision(a, b, logp, mu, v):
    t = truncated_standard_normal(a, b)
    assert abs(t.log_p_uncensored - logp) <= 1e-13 * max(1.0, abs(logp))
    assert abs(t.mu_t - mu) <= 1e-13 * max(1.0, abs(mu))
    assert abs(t.v_t - v) <= 1e-11 * v
    assert np.isclose(t.p_uncensored, np.exp(logp), rtol=1e-11, atol=0)


# (m, s, a, b, E clip, Var clip): the reference file's tail cases, exact values from
# 80-digit mpmath (closed form; far_lower_tail also by quadrature).
UNIVARIATE_MP = [
    (0.0, 1.0, -INF, -37.0, -37.0, 8.3342176294277234e-303),
    (0.0, 1.0, 9.0, INF, 9.0, 2.6287143194699957e-21),
    (-4.6, 0.5, -0.5, 0.5, -0.5, 8.3372964885058043e-19),
    (0.2, 1.0, 0.3, 0.30000099999999996, 0.30000046017196422, 2.4841366139598671e-13),
]


@pytest.mark.parametrize(("m", "s", "a", "b", "mean", "var"), UNIVARIATE_MP)
def test_univariate_high_precision(m, s, a, b, mean, var):
    for res in (
        clipped_normal_moments([m], [[s * s]], [a], [b]),
        clipped_normal_moments_diag([m], [s * s], [a], [b]),
    ):
        assert abs(res.mean[0] - mean) <= 1e-15 * max(1.0, abs(mean))
        assert abs(res.cov[0, 0] - var) <= 1e-12 * var


# (rho, a1, b1, a2, b2, Cov) for standardised components: exact covariance from 40/60-digit
# mpmath as E[f1 f2] - E f1 E f2 with E[f1 f2] = ∫ φ(z) clip(z) E[clip(Z2) | Z1 = z] dz
# (1-D quadrature of the closed-form conditional clipped mean), independent of the
# Hoeffding/Plackett route used by the library. Tails, high correlation, narrow intervals.
# (*) narrow intervals, where that quadrature is only good to ~1e-10: instead 40-digit
# Cov = ∫_{a1}^{b1} φ(s) ∫_0^ρ P(a2 < r s + sqrt(1-r²) W < b2) dr ds (nested mpmath quad).
BIVARIATE_MP = [
    (0.5, 7.0, INF, -1.0, 1.0, 1.7597949132046438e-13),
    (0.95, 7.0, INF, -1.0, 1.0, 1.7603260116374831e-13),
    (0.95, 7.0, INF, 6.0, INF, 1.5970077012428723e-13),
    (0.99, 8.0, 9.0, 8.0, INF, 1.3682633182318784e-17),
    (-0.95, 7.0, INF, -INF, -6.5, -7.5304846599967242e-14),
    (0.5, -1.0, 1.0, -0.5, 2.0, 0.23122577740983613),
    (0.999, -1.0, 0.7, -0.8, 1.2, 0.44352900756652421),
    (0.3, 7.0, INF, 7.0, INF, 7.1889389125350547e-21),
    (0.93, 3.0, INF, 3.0, INF, 0.00013881610915796377),
    (0.999999, 3.0, INF, 3.0, INF, 0.00020328769033378837),
    (0.6, 0.1, 0.100001, -0.3, 0.5, 7.8854929600939329e-8),  # (*)
    (0.97, 0.1, 0.100001, 0.1, 0.100002, 4.1905333348159879e-13),  # (*)
    (-0.7, -2.0, -1.999999, 1.0, 1.000001, -1.4825985316002892e-14),  # (*)
    (-0.98, 2.0, 2.000001, -1.0, 3.0, -2.4636846554237819e-8),  # (*)
    (0.95, 5.0, 5.000005, 3.0, INF, 2.7615638765452821e-12),  # (*)
    (0.995, 0.1, 0.100001, -0.3, 0.5, 1.6543560517388131e-7),  # (*)
    (0.9999, 0.1, 0.100001, -0.3, 0.5, 1.6738066054604522e-7),  # (*)
    (0.994, -0.644, -0.643999999, 5.19, 5.69, 4.6556440626813798e-18),  # (*)
    (0.999999, 0.1, 0.100000001, -0.3, 0.5, 1.6741996491165072e-10),  # (*)
    (-0.999999999, -0.5, 0.3, -1.0, 0.2, -0.14803624541659347),
    (0.9, 8.0, INF, 8.0, INF, 1.7531562714407615e-18),
    (0.8, 6.0, INF, 7.0, INF, 2.9172316643205014e-14),
    (0.9, 10.0, INF, 10.0, INF, 4.800142983075209e-27),
    (0.7, -INF, -9.0, -INF, -8.0, 5.0718924726584243e-23),
    (0.85, 6.0, 8.0, 6.0, 8.0, 5.6268517112176699e-12),
    (0.92, 12.0, INF, 12.0, INF, 5.4030022333201884e-37),
    (0.5, 4.0, INF, -INF, -4.0, 5.1054717578451693e-11),
    (0.2, 8.0, INF, 8.5, INF, 1.4121146402224732e-29),
]


@pytest.mark.parametrize(("rho", "a1", "b1", "a2", "b2", "cov"), BIVARIATE_MP)
def test_bivariate_covariance_high_precision(rho, a1, b1, a2, b2, cov):
    # measured worst relative error 1.9e-11 (rho = 0.99, far tail, closed-form K route);
    # narrow-interval cases (*) agree to 1e-13 or better
    S = np.array([[1.0, rho], [rho, 1.0]])
    res = clipped_normal_moments([0.0, 0.0], S, [a1, a2], [b1, b2])
    assert abs(res.cov[0, 1] - cov) <= 1e-9 * abs(cov)
    assert res.cov[0, 1] == res.cov[1, 0]
    width = min(b1 - a1, b2 - a2)
    if width > 1e-7:
        # the same problem scaled and shifted (s1 = 2, s2 = 0.5): rounding the limits
        # perturbs a width w by ~1e-16/w relative, harmless above 1e-7
        m = np.array([1.0, -3.0])
        s = np.array([2.0, 0.5])
        S = np.array([[4.0, rho * 1.0], [rho * 1.0, 0.25]])
        lo = m + s * np.array([a1, a2])
        up = m + s * np.array([b1, b2])
        res = clipped_normal_moments(m, S, lo, up)
        assert abs(res.cov[0, 1] - cov * s[0] * s[1]) <= 1e-9 * abs(cov * s[0] * s[1])


def test_stein_identity_for_unbounded_partner():
    # Cov(clip(Y1), Y2) = S12 P(a1 < Y1 < b1) (Stein's lemma); here P = Q(37) ~ 5.7e-300
    res = clipped_normal_moments([0.0, 0.0], [[1.0, 0.8], [0.8, 1.0]], [37.0, -INF], [INF, INF])
    assert abs(res.cov[0, 1] - 0.8 * norm.sf(37.0)) <= 1e-12 * 0.8 * norm.sf(37.0)
    assert res.cov[1, 1] == 1.0 and res.mean[1] == 0.0


# ---------------------------------------------------------------------------------------
# Monte Carlo
# ---------------------------------------------------------------------------------------


def _mc_case(seed: int, p: int):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(p, p))
    S = A @ A.T + 0.3 * np.eye(p)
    m = rng.normal(0.0, 1.0, p)
    sd = np.sqrt(np.diag(S))
    lo = m + sd * rng.uniform(-1.5, 0.3, p)
    up = lo + sd * rng.uniform(0.4, 2.5, p)
    lo[rng.uniform(size=p) < 0.2] = -INF
    up[rng.uniform(size=p) < 0.2] = INF
    return m, S, lo, up


@pytest.mark.parametrize(("seed", "p"), [(1, 2), (2, 2), (3, 2), (4, 3), (5, 3), (6, 3)])
def test_monte_carlo(seed, p):
    """Exact moments vs 400 000 samples, within 4 standard errors.

    SE of a mean: sd(y_i)/sqrt(N); of a covariance: sd of (y_i - ȳ_i)(y_j - ȳ_j) over
    sqrt(N) (the delta-method SE of the sample covariance); of a probability:
    sqrt(p (1 - p)/N).
    """
    m, S, lo, up = _mc_case(seed, p)
    n = 400_000
    rng = np.random.default_rng(1000 + seed)
    Y = rng.multivariate_normal(m, S, size=n)
    y = np.clip(Y, lo, up)
    res = clipped_normal_moments(m, S, lo, up)
    ybar = y.mean(axis=0)
    se_mean = y.std(axis=0) / np.sqrt(n)
    assert np.all(np.abs(res.mean - ybar) <= 4 * se_mean + 1e-12)
    d = y - ybar
    prod = d[:, :, None] * d[:, None, :]
    cov_mc = prod.mean(axis=0)
    se_cov = prod.std(axis=0) / np.sqrt(n)
    assert np.all(np.abs(res.cov - cov_mc) <= 4 * se_cov + 1e-12)
    for key, frac in (
        ("p_lower", (Y <= lo).mean(axis=0)),
        ("p_upper", (Y >= up).mean(axis=0)),
        ("p_uncensored", ((Y > lo) & (Y < up)).mean(axis=0)),
    ):
        exact = getattr(res, key)
        se = np.sqrt(exact * (1 - exact) / n)
        assert np.all(np.abs(exact - frac) <= 4 * se + 1e-12), key


# ---------------------------------------------------------------------------------------
# Properties (hypothesis)
# ---------------------------------------------------------------------------------------


@st.composite
def problems(draw, max_p: int = 3):
    """A latent N(m, S) with 1..max_p components and limits (some infinite)."""
    p = draw(st.integers(1, max_p))
    fl = st.floats(-3.0, 3.0, allow_nan=False)
    L = np.array([[draw(fl) for _ in range(p)] for _ in range(p)])
    S = L @ L.T + np.diag([draw(st.floats(0.01, 2.0)) for _ in range(p)])
    m = np.array([draw(st.floats(-5.0, 5.0)) for _ in range(p)])
    lo = np.empty(p)
    up = np.empty(p)
    for i in range(p):
        kind = draw(st.sampled_from(["both", "lower", "upper", "none"]))
        a = draw(st.floats(-6.0, 6.0))
        w = draw(st.sampled_from([1e-6, 1e-3, 0.1, 0.5, 1.0, 3.0, 10.0]))
        lo[i] = a if kind in ("both", "lower") else -INF
        up[i] = a + w if kind in ("both", "upper") else INF
    return m, S, lo, up


def _scale(S: np.ndarray) -> float:
    return float(np.max(np.diag(S)))


@settings(max_examples=40, deadline=None)
@given(problems())
def test_reflection_symmetry(prob):
    m, S, lo, up = prob
    r = clipped_normal_moments(m, S, lo, up)
    f = clipped_normal_moments(-m, S, -up, -lo)
    sc = _scale(S)
    np.testing.assert_allclose(f.mean, -r.mean, rtol=1e-12, atol=1e-12 * np.sqrt(sc))
    np.testing.assert_allclose(f.cov, r.cov, rtol=1e-9, atol=1e-13 * sc)
    np.testing.assert_allclose(f.p_lower, r.p_upper, rtol=1e-12, atol=0)
    np.testing.assert_allclose(f.p_uncensored, r.p_uncensored, rtol=1e-12, atol=0)


@settings(max_examples=40, deadline=None)
@given(problems())
def test_symmetric_psd_and_bounds(prob):
    m, S, lo, up = prob
    r = clipped_normal_moments(m, S, lo, up)
    C = r.cov
    assert np.all(np.isfinite(C)) and np.all(np.isfinite(r.mean))
    np.testing.assert_array_equal(C, C.T)
    assert np.linalg.eigvalsh(C).min() >= -1e-14 * _scale(S)
    var = np.diag(C)
    assert np.all(var >= 0)
    # clipping is a 1-Lipschitz contraction, so Var(clip Y) <= Var(Y); Popoviciu's
    # inequality bounds the variance of a variable in [a, b] by (b - a)^2 / 4
    assert np.all(var <= np.diag(S) * (1 + 1e-12))
    assert np.all(var <= (up - lo) ** 2 / 4 * (1 + 1e-12) + 1e-300)
    assert np.all((r.mean >= lo) & (r.mean <= up))
    total = r.p_lower + r.p_uncensored + r.p_upper
    np.testing.assert_allclose(total, 1.0, rtol=0, atol=4e-16)


@settings(max_examples=40, deadline=None)
@given(problems(), st.lists(st.booleans(), min_size=3, max_size=3))
def test_infinite_limits_return_latent_moments_exactly(prob, free):
    m, S, lo, up = prob
    free = np.array(free[: len(m)])
    lo = np.where(free, -INF, lo)
    up = np.where(free, INF, up)
    r = clipped_normal_moments(m, S, lo, up)
    # bit for bit: the mean of every unbounded component and the block among them
    np.testing.assert_array_equal(r.mean[free], m[free])
    np.testing.assert_array_equal(r.cov[np.ix_(free, free)], S[np.ix_(free, free)])
    np.testing.assert_array_equal(r.p_uncensored[free], 1.0)
    if free.all():
        np.testing.assert_array_equal(r.cov, S)


@settings(max_examples=40, deadline=None)
@given(problems(), st.floats(-5.0, 5.0))
def test_shift_equivariance(prob, delta):
    m, S, lo, up = prob
    r = clipped_normal_moments(m, S, lo, up)
    s = clipped_normal_moments(m + delta, S, lo + delta, up + delta)
    sc = _scale(S)
    tol_mean = 1e-12 * (np.sqrt(sc) + np.abs(m).max() + np.abs(delta) + 10)
    np.testing.assert_allclose(s.mean, r.mean + delta, rtol=0, atol=tol_mean)
    np.testing.assert_allclose(s.cov, r.cov, rtol=1e-8, atol=1e-12 * sc)
    np.testing.assert_allclose(s.p_uncensored, r.p_uncensored, rtol=1e-8, atol=1e-15)


@settings(max_examples=30, deadline=None)
@given(problems(), st.floats(0.01, 100.0))
def test_scale_equivariance(prob, c):
    m, S, lo, up = prob
    r = clipped_normal_moments(m, S, lo, up)
    s = clipped_normal_moments(c * m, c * c * S, c * lo, c * up)
    sc = _scale(S)
    np.testing.assert_allclose(s.mean, c * r.mean, rtol=1e-9, atol=1e-12 * c * np.sqrt(sc))
    np.testing.assert_allclose(s.cov, c * c * r.cov, rtol=1e-8, atol=1e-12 * c * c * sc)


@settings(max_examples=30, deadline=None)
@given(problems(), st.randoms(use_true_random=False))
def test_permutation_equivariance(prob, rnd):
    m, S, lo, up = prob
    perm = list(range(len(m)))
    rnd.shuffle(perm)
    perm = np.array(perm)
    r = clipped_normal_moments(m, S, lo, up)
    q = clipped_normal_moments(m[perm], S[np.ix_(perm, perm)], lo[perm], up[perm])
    sc = _scale(S)
    np.testing.assert_allclose(q.mean, r.mean[perm], rtol=1e-14, atol=0)
    np.testing.assert_allclose(q.cov, r.cov[np.ix_(perm, perm)], rtol=1e-12, atol=1e-15 * sc)


@settings(max_examples=30, deadline=None)
@given(problems())
def test_diagonal_path_matches_general_path(prob):
    m, S, lo, up = prob
    v = np.diag(S).copy()
    g = clipped_normal_moments(m, np.diag(v), lo, up)
    d = clipped_normal_moments_diag(m, v, lo, up)
    np.testing.assert_array_equal(d.mean, g.mean)
    np.testing.assert_array_equal(d.cov, g.cov)
    np.testing.assert_array_equal(d.p_uncensored, g.p_uncensored)
    mean, var, _, pu, _ = clipped_normal_variance_diag(m, v, lo, up)
    np.testing.assert_array_equal(var, np.diag(d.cov))
    np.testing.assert_array_equal(mean, d.mean)
    np.testing.assert_array_equal(pu, d.p_uncensored)


def test_batch_equals_elementwise():
    cases = [_mc_case(seed, 3) for seed in range(10, 22)]
    m = np.stack([c[0] for c in cases]).reshape(3, 4, 3)
    S = np.stack([c[1] for c in cases]).reshape(3, 4, 3, 3)
    lo = np.stack([c[2] for c in cases]).reshape(3, 4, 3)
    up = np.stack([c[3] for c in cases]).reshape(3, 4, 3)
    res = clipped_normal_moments(m, S, lo, up)
    assert res.mean.shape == (3, 4, 3) and res.cov.shape == (3, 4, 3, 3)
    for k, (mi, Si, li, ui) in enumerate(cases):
        one = clipped_normal_moments(mi, Si, li, ui)
        i, j = divmod(k, 4)
        np.testing.assert_allclose(res.mean[i, j], one.mean, rtol=1e-15, atol=0)
        np.testing.assert_allclose(res.cov[i, j], one.cov, rtol=1e-14, atol=1e-300)
    # limits broadcast from (p,) and a shared covariance broadcast over the batch
    shared = clipped_normal_moments(m, S[0, 0], [-1.0, -INF, 0.0], [1.0, 2.0, INF])
    assert shared.cov.shape == (3, 4, 3, 3)


# ---------------------------------------------------------------------------------------
# Tails
# ---------------------------------------------------------------------------------------


def test_tail_sweep_is_finite_and_consistent():
    # means from 60 sd below to 60 sd above, widths 1e-8 .. 100 sd, one- and two-sided
    mean = np.linspace(-60.0, 60.0, 241)[:, None]
    width = np.logspace(-8, 2, 41)[None, :]
    for lo, up in ((0.0 * width, width), (-width, 0.0 * width + INF), (-INF + 0 * width, width)):
        lo_b, up_b, _ = np.broadcast_arrays(lo, up, mean)
        res = clipped_normal_moments_diag(mean, 1.0, lo_b, up_b)
        var = np.diagonal(res.cov, axis1=-2, axis2=-1)
        assert np.all(np.isfinite(res.mean)) and np.all(np.isfinite(var))
        assert np.all(var >= 0) and np.all(var <= 1.0)
        assert np.all((res.mean >= lo_b) & (res.mean <= up_b))
        fin = np.isfinite(lo_b) & np.isfinite(up_b)
        assert np.all(var[fin] <= (up_b - lo_b)[fin] ** 2 / 4 * (1 + 1e-12))
        total = res.p_lower + res.p_uncensored + res.p_upper
        np.testing.assert_allclose(total, 1.0, rtol=0, atol=4e-16)


def test_uncensored_probability_1e_300():
    # P(Y > 37) = 5.7e-300: probability, mean and variance keep full relative precision
    r = clipped_normal_moments([0.0, 0.0], [[1.0, 0.6], [0.6, 1.0]], [-INF, -1.0], [-37.0, 1.0])
    assert abs(r.p_uncensored[0] / 5.7255712225245768e-300 - 1) < 1e-12
    assert abs(r.cov[0, 0] / 8.3342176294277234e-303 - 1) < 1e-12
    assert np.all(np.isfinite(r.cov)) and np.linalg.eigvalsh(r.cov).min() >= 0


def test_mean_40_sd_outside_the_interval():
    # P_un = Phi(-40) - Phi(-41) ~ 4e-350 underflows: log P stays exact, moments are finite
    for m, edge in ((-40.0, 0.0), (41.0, 1.0)):
        r = clipped_normal_moments([m, 0.0], [[1.0, 0.9], [0.9, 1.0]], [0.0, -1.0], [1.0, 1.0])
        assert r.mean[0] == edge and r.cov[0, 0] >= 0 and r.cov[0, 0] < 1e-300
        assert np.all(np.isfinite(r.cov)) and np.linalg.eigvalsh(r.cov).min() >= -1e-300
        t = truncated_standard_normal(0.0 - m, 1.0 - m)
        assert abs(t.log_p_uncensored - (-804.60844201375379)) < 1e-12 * 804.6
        assert np.isfinite(t.mu_t) and edge - 1 <= t.mu_t + m <= edge + 1 and t.v_t > 0


def test_interval_width_1e_6_sd_both_components():
    # both components in intervals of width 1e-6 sd, correlation 0.97 (exact: mpmath)
    m = np.zeros(2)
    S = np.array([[1.0, 0.97], [0.97, 1.0]])
    r = clipped_normal_moments(m, S, [0.1, 0.1], [0.100001, 0.100002])
    assert abs(r.cov[0, 1] / 4.1905333348366841e-13 - 1) < 1e-9
    assert np.linalg.eigvalsh(r.cov).min() >= 0


def test_zero_variance_and_degenerate_intervals():
    r = clipped_normal_moments(
        [0.5, 2.0, 0.3], [[0.0, 0, 0], [0, 0.0, 0], [0, 0, 1.0]], [0.0, 0.0, 0.2], [1.0, 1.0, 0.2]
    )
    np.testing.assert_array_equal(r.mean, [0.5, 1.0, 0.2])
    np.testing.assert_array_equal(r.cov, np.zeros((3, 3)))
    np.testing.assert_array_equal(r.p_uncensored, [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(r.p_upper[:2], [0.0, 1.0])


def test_truncated_matches_scipy_truncnorm_in_the_bulk():
    rng = np.random.default_rng(3)
    a = rng.uniform(-3, 2, 50)
    b = a + rng.uniform(0.05, 4, 50)
    t = truncated_standard_normal(a, b)
    mu, v = truncnorm.stats(a, b, moments="mv")
    np.testing.assert_allclose(t.mu_t, mu, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(t.v_t, v, rtol=1e-10)
    np.testing.assert_allclose(t.p_uncensored, norm.cdf(b) - norm.cdf(a), rtol=1e-12)
    np.testing.assert_allclose(t.log_p_lower, norm.logcdf(a), rtol=1e-14)
    np.testing.assert_allclose(t.log_p_upper, norm.logsf(b), rtol=1e-14)
    assert isinstance(t, TruncatedStats) and t.mu_t.shape == (50,)


def test_input_validation():
    with pytest.raises(ValueError, match="lower <= upper"):
        clipped_normal_moments([0.0], [[1.0]], [1.0], [0.0])
    with pytest.raises(ValueError, match=">= 0"):
        clipped_normal_moments_diag([0.0], [-1.0], [0.0], [1.0])
    with pytest.raises(ValueError, match="cov must have shape"):
        clipped_normal_moments([0.0, 1.0], np.eye(3), 0.0, 1.0)
    with pytest.raises(ValueError, match="alpha <= beta"):
        truncated_standard_normal(1.0, 0.0)


# ---------------------------------------------------------------------------------------
# Censored log-likelihood
# ---------------------------------------------------------------------------------------


def test_censored_logpdf_against_scipy():
    rng = np.random.default_rng(8)
    n = 200
    m = rng.normal(0, 2, n)
    s2 = rng.uniform(0.1, 3, n)
    lo = rng.uniform(-3, 0, n)
    up = lo + rng.uniform(0.5, 4, n)
    y = np.clip(rng.normal(m, np.sqrt(s2)), lo, up)
    y[:5] = np.nan
    out = censored_logpdf(y, m, s2, lo, up)
    s = np.sqrt(s2)
    expected = np.where(
        y <= lo,
        norm.logcdf((lo - m) / s),
        np.where(y >= up, norm.logcdf((m - up) / s), norm.logpdf(y, m, s)),
    )
    expected[:5] = 0.0
    assert np.sum(y[5:] <= lo[5:]) > 5 and np.sum(y[5:] >= up[5:]) > 5
    np.testing.assert_allclose(out, expected, rtol=1e-13, atol=1e-14)
    # far tail: still finite, equal to log Phi(-50)
    v = censored_logpdf(-50.0, 0.0, 1.0, -50.0, 1.0)
    assert np.isfinite(v) and abs(v - norm.logcdf(-50.0)) < 1e-12 * abs(v)


@st.composite
def extreme_problems(draw):
    """Standardised latent pairs/triples with far tails, near-singular correlations and
    very narrow intervals."""
    p = draw(st.integers(2, 3))
    rho_abs = draw(st.sampled_from([0.0, 0.3, 0.8, 0.93, 0.999, 1 - 1e-6, 1 - 1e-12, 1.0]))
    sign = draw(st.sampled_from([-1.0, 1.0]))
    base = rho_abs * sign if p == 2 else abs(rho_abs) * 0.999  # keep 3x3 equicorrelation PSD
    S = np.full((p, p), base)
    np.fill_diagonal(S, 1.0)
    lo = np.empty(p)
    up = np.empty(p)
    for i in range(p):
        a = draw(st.floats(-60.0, 60.0))
        w = draw(st.sampled_from([1e-8, 1e-6, 1e-3, 0.5, 5.0, INF]))
        lo[i] = draw(st.sampled_from([a, -INF]))
        up[i] = a + w
    return np.zeros(p), S, lo, up


@settings(max_examples=60, deadline=None)
@given(extreme_problems())
def test_extreme_inputs_finite_psd_cauchy_schwarz(prob):
    m, S, lo, up = prob
    r = clipped_normal_moments(m, S, lo, up)
    C = r.cov
    assert np.all(np.isfinite(C)) and np.all(np.isfinite(r.mean))
    np.testing.assert_array_equal(C, C.T)
    var = np.diag(C)
    assert np.all(var >= 0)
    assert np.all((r.mean >= lo) & (r.mean <= up))
    # |Cov_ij| <= sqrt(Var_i Var_j): the clipped correlation is a correlation
    bound = np.outer(np.sqrt(var), np.sqrt(var))
    assert np.all(np.abs(C) <= bound * (1 + 1e-9) + 1e-300)
    # PSD relative to each entry's own scale (diagonal scaling)
    d = np.where(var > 0, np.sqrt(var), 1.0)
    assert np.linalg.eigvalsh(C / np.outer(d, d)).min() >= -1e-9


def test_unit_correlation_is_continuous():
    # rho = ±1 exactly (singular latent pair) agrees with rho = ±(1 - 1e-12)
    for r in (1.0, -1.0):
        exact = clipped_normal_moments([0.1, 0.2], [[1, r], [r, 1]], [-1, -0.5], [0.5, 1.5])
        near = clipped_normal_moments(
            [0.1, 0.2], [[1, r * (1 - 1e-12)], [r * (1 - 1e-12), 1]], [-1, -0.5], [0.5, 1.5]
        )
        np.testing.assert_allclose(exact.cov, near.cov, rtol=1e-10, atol=1e-12)
        assert np.linalg.eigvalsh(exact.cov).min() >= 0


def test_nan_inputs_propagate_without_error():
    r = clipped_normal_moments([np.nan, 0.2, 0.0], np.eye(3) + 0.5, [-1, -0.5, 0], [0.5, 1.5, 1])
    assert np.isnan(r.mean[0]) and np.all(np.isnan(r.cov[0])) and np.isnan(r.p_uncensored[0])
    assert np.all(np.isfinite(r.cov[1:, 1:])) and np.all(np.isfinite(r.mean[1:]))


# (h, k, rho, J) with J(h, k; ρ) = ∫_0^ρ (ρ - r) φ₂(h, k; r) dr from 40-digit mpmath
# (quadrature in θ = asin r on 32 uniform + 40 geometrically graded panels). For
# one-sided limits Cov(max(Z1, h), max(Z2, k)) = ρ Q(h) Q(k) + J exactly.
FAR_TAIL_J = [
    (25.0, 25.0, 0.9, 1.5722868122329255e-148),
    (20.0, 20.0, 0.5, 8.7078890103774798e-122),
    (20.0, 20.0, 0.95, 3.187843079712517e-94),
    (20.0, 20.0, 0.999, 1.1489347199576746e-91),
    (20.0, 20.5, 0.995, 2.5812561462805937e-95),
    (10.0, 10.2, 0.999, 3.6291456869598825e-26),
    (15.0, 15.3, 0.9995, 1.044037005517667e-54),
    (-2.0, -2.5, 0.9999, 0.0020424968897509604),
    (0.0, 0.1, 0.9999, 0.09006013144910843),
]


@pytest.mark.parametrize(("h", "k", "rho", "J"), FAR_TAIL_J)
def test_far_tail_and_near_singular_covariance(h, k, rho, J):
    res = clipped_normal_moments([0.0, 0.0], [[1.0, rho], [rho, 1.0]], [h, k], [INF, INF])
    expected = rho * norm.sf(h) * norm.sf(k) + J
    # measured worst 4e-11 (mpmath reference itself ~1e-11)
    assert abs(res.cov[0, 1] - expected) <= 1e-9 * abs(expected)
    assert np.linalg.eigvalsh(res.cov).min() >= 0


@pytest.mark.parametrize(
    ("cov", "match"),
    [
        ([[1.0, 2.0], [2.0, 1.0]], "not positive semi-definite"),  # correlation 2
        ([[1.0, 0.9], [-0.9, 1.0]], "not symmetric"),
        ([[1.0, np.nan], [np.nan, 1.0]], "NaN"),
    ],
)
def test_a_covariance_that_is_not_one_is_refused(cov, match):
    """It used to be taken as if its correlation were clipped to 1, or its off-diagonal
    pair averaged (a correlation of 0.9 and -0.9: none)."""
    with pytest.raises(ValueError, match=match):
        clipped_normal_moments([0.0, 0.0], cov, [-1.0, -1.0], [1.0, 1.0])


# ---------------------------------------------------------------------------------------
# Far limits: two-sided intervals far out, limits beyond 1e154 sd (where z² overflows)
# ---------------------------------------------------------------------------------------

# (α, β, μ_T, v_T): two-sided intervals 50 .. 1e8 sd out with (β² - α²)/2 = 2.5 .. 3, from
# the closed form in 120-digit decimal arithmetic (Q(x) = φ(x)/λ(x), λ by Laplace's
# continued fraction with 2000 terms), at the exact binary values of α and β
FAR_TWO_SIDED = [
    (50.0, 50.05, 50.01552547470628, 0.0001563963821802101),
    (-50.05, -50.0, -50.01552547470628, 0.0001563963821802101),
    (1000.0, 1000.003, 1000.0008428123084, 5.037303694566891e-07),
    (-1000.003, -1000.0, -1000.0008428123084, 5.037303694566891e-07),
    (100000.0, 100000.000025, 100000.00000776436, 3.911099769501335e-11),
    (-100000.000025, -100000.0, -100000.00000776436, 3.911099769501335e-11),
    (30000000.0, 30000000.0000001, 30000000.00000003, 5.639184400989245e-16),
    (-30000000.0000001, -30000000.0, -30000000.00000003, 5.639184400989245e-16),
    (100000000.0, 100000000.00000003, 100000000.00000001, 4.9942518996816045e-17),
    (-100000000.00000003, -100000000.0, -100000000.00000001, 4.9942518996816045e-17),
]


@pytest.mark.parametrize(("a", "b", "mu", "v"), FAR_TWO_SIDED)
def test_far_two_sided_interval_high_precision(a, b, mu, v):
    # Q(β)/Q(α) from log Φ differences kept a rounding of ~α² 1e-16: v_T off by 8e-13 at
    # 50 sd, 2 % at 3e7 sd, NaN or 100 % at 1e8 sd (both logs rounded to one number)
    t = truncated_standard_normal(a, b)
    assert abs(t.mu_t - mu) <= 1e-15 * abs(mu)
    assert abs(t.v_t / v - 1) <= 1e-13


@st.composite
def far_instead_of_infinite(draw):
    """A problem of :func:`problems` and the same one with each infinite limit replaced by
    a finite one 40 .. 1e300 sd beyond the mean (and the other limit)."""
    m, S, lo, up = draw(problems())
    s = np.sqrt(np.diag(S))
    lo_f, up_f = lo.copy(), up.copy()
    for i in range(len(m)):
        if np.isinf(lo[i]):
            lo_f[i] = min(m[i], up[i]) - 10.0 ** draw(st.floats(np.log10(40.0), 300.0)) * s[i]
        if np.isinf(up[i]):
            up_f[i] = max(m[i], lo[i]) + 10.0 ** draw(st.floats(np.log10(40.0), 300.0)) * s[i]
    return m, S, lo, up, lo_f, up_f


@settings(max_examples=60, deadline=None)
@given(far_instead_of_infinite())
def test_a_limit_40_to_1e300_sd_out_is_an_infinite_one(prob):
    # P(Z < -40) ~ 4e-350 underflows: the moments are those with the infinite limit (they
    # were NaN beyond 1e154 sd, and the cross-covariance off by O(1) at 1e100 sd, |ρ| > 0.99)
    m, S, lo, up, lo_f, up_f = prob
    ref = clipped_normal_moments(m, S, lo, up)
    far = clipped_normal_moments(m, S, lo_f, up_f)
    sc = _scale(S)
    np.testing.assert_allclose(far.mean, ref.mean, rtol=1e-13, atol=1e-14 * np.sqrt(sc))
    np.testing.assert_allclose(far.cov, ref.cov, rtol=1e-12, atol=1e-14 * sc)
    for got, exp in ((far.p_lower, ref.p_lower), (far.p_upper, ref.p_upper)):
        np.testing.assert_array_equal(got, exp)
    np.testing.assert_allclose(far.p_uncensored, ref.p_uncensored, rtol=1e-15, atol=0)


@pytest.mark.parametrize("z", [1e3, 1e100, 1e160, 1e300])
@pytest.mark.parametrize("rho", [0.3, 0.995, -0.995])
def test_a_far_limit_at_high_correlation_is_an_infinite_one(z, rho):
    # |ρ| >= 0.99: the corners use K - ρQQ, whose terms grow like z and cancel: at 1e100
    # sd the covariance came out 0.53 for 0.49 (NaN before that from the bivariate CDF)
    S = [[1.0, rho], [rho, 1.0]]
    ref = clipped_normal_moments([0.0, 0.0], S, [-INF, -1.0], [0.5, 1.0])
    far = clipped_normal_moments([0.0, 0.0], S, [-z, -1.0], [0.5, 1.0])
    np.testing.assert_allclose(far.mean, ref.mean, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(far.cov, ref.cov, rtol=1e-12, atol=0)


@st.composite
def beyond_1e154(draw):
    """A latent N(m, s²), s <= 1e-140, whose limits lie 2e154 .. 1e300 s from m (z² is
    infinite): both outside ("inside": the mean is between them), or the whole interval
    below or above the mean. Returns (m, s, lower, upper, kind)."""
    m = draw(st.floats(-5.0, 5.0))
    s = 10.0 ** draw(st.floats(-150.0, -140.0))
    d1, d2 = (10.0 ** draw(st.floats(154.3, 300.0)) * s for _ in range(2))
    kind = draw(st.sampled_from(["inside", "below", "above"]))
    if kind == "inside":
        lo, up = m - d1, m + d2
    elif kind == "below":
        up = m - d1
        lo = draw(st.sampled_from([-INF, up - d2]))
    else:
        lo = m + d1
        up = draw(st.sampled_from([INF, lo + d2]))
    return m, s, lo, up, kind


def _check_exact_far_limits(mean, var, p_lo, p_un, p_up, m, s, lo, up, kind):
    """Limits many sd beyond the mean: the uncensored moments; the whole interval beyond
    it: the point mass at the nearer limit."""
    if kind == "inside":
        assert (p_lo, p_un, p_up) == (0.0, 1.0, 0.0)
        assert mean == m and var == s * s
    else:
        edge = up if kind == "below" else lo
        assert (p_lo, p_un, p_up) == ((0.0, 0.0, 1.0) if kind == "below" else (1.0, 0.0, 0.0))
        assert abs(mean - edge) <= 4e-16 * abs(edge - m) and var == 0.0


@settings(max_examples=60, deadline=None)
@given(beyond_1e154(), st.floats(-0.999, 0.999))
def test_limits_beyond_1e154_sd_give_the_exact_limits(prob, rho):
    m, s, lo, up, kind = prob
    d = clipped_normal_moments_diag(m, s * s, lo, up)
    got = (d.mean[0], d.cov[0, 0], d.p_lower[0], d.p_uncensored[0], d.p_upper[0])
    _check_exact_far_limits(*got, m, s, lo, up, kind)
    t = truncated_standard_normal((lo - m) / s, (up - m) / s)
    if kind == "inside":
        assert (t.mu_t, t.v_t) == (0.0, 1.0)
    # with a second, ordinary component: its own moments, and Stein's Cov(Y1, clip(Y2)) =
    # S12 P_un,2 when the first is uncensored, 0 when it is a point mass
    S = np.array([[s * s, rho * s], [rho * s, 1.0]])
    r = clipped_normal_moments([m, 0.3], S, [lo, -1.0], [up, 1.0])
    got = (r.mean[0], r.cov[0, 0], r.p_lower[0], r.p_uncensored[0], r.p_upper[0])
    _check_exact_far_limits(*got, m, s, lo, up, kind)
    second = clipped_normal_moments_diag(0.3, 1.0, -1.0, 1.0)
    assert abs(r.mean[1] - second.mean[0]) <= 1e-15
    assert abs(r.cov[1, 1] / second.cov[0, 0] - 1) <= 1e-14
    p_un2 = norm.cdf(0.7) - norm.cdf(-1.3)
    expected = rho * s * p_un2 if kind == "inside" else 0.0
    assert abs(r.cov[0, 1] - expected) <= 1e-14 * abs(rho * s)
    assert r.cov[0, 1] == r.cov[1, 0]
