"""Tobit filters: reductions to the KF, hand-written loops from the papers' equations,
the censored-gain safeguard, Monte Carlo optimality of the TKF^c update, long random runs,
and the per-axis path against the general one."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from scipy.stats import norm

from tobitkf.core.engine import make_step_model
from tobitkf.core.kalman import kalman_filter
from tobitkf.core.model import LinearGaussian
from tobitkf.core.tobit import (
    EPS_CENSORED,
    adaptive_tobit_filter,
    atkf_update,
    tkfc_update,
    tobit_filter,
)
from tobitkf.smoothing.paper import skeleton_model

# ---------------------------------------------------------------------------- helpers


def _spd(rng, k, scale=1.0):
    B = rng.normal(size=(k, k))
    return scale * (B @ B.T / k + 0.2 * np.eye(k))


def _general_model(rng, n=3, p=2, batch=()):
    return LinearGaussian(
        A=np.eye(n) * 0.9 + 0.1 * rng.normal(size=(n, n)),
        H=rng.normal(size=(p, n)),
        Q=_spd(rng, n, 0.05),
        R=_spd(rng, p, 0.3),
        x0=rng.normal(size=(*batch, n)),
        P0=_spd(rng, n),
    )


def _diag_model(rng, n=3, batch=(), a_identity=False):
    a = np.ones(n) if a_identity else rng.uniform(0.7, 1.1, n)
    return LinearGaussian(
        A=np.diag(a),
        H=np.diag(rng.uniform(0.5, 1.5, n)),
        Q=np.diag(rng.uniform(0.01, 0.1, n)),
        R=np.diag(rng.uniform(0.05, 0.5, n)),
        x0=rng.normal(size=(*batch, n)),
        P0=np.diag(rng.uniform(0.1, 1.0, n)),
    )


def _close(a, b, tol=1e-12):
    np.testing.assert_allclose(a, b, rtol=tol, atol=tol)


def oscillator(K, seed):
    """The 2020 paper's oscillator (eq. 36-38): returns states (K, 2), clipped y (K, 1)."""
    rng = np.random.default_rng(seed)
    w = 0.005 * 2 * np.pi
    A = 0.999 * np.array([[np.cos(w), -np.sin(w)], [np.sin(w), np.cos(w)]])
    x = np.array([5.0, 0.0])
    xs, ys = [], []
    for _ in range(K):
        x = A @ x + rng.normal(scale=0.05, size=2)
        xs.append(x)
        ys.append(np.clip(x[0] + rng.normal(scale=np.sqrt(0.5)), -0.5, 0.5))
    model = LinearGaussian(
        A=A, H=[[1.0, 0.0]], Q=0.05**2 * np.eye(2), R=[[0.5]], x0=[5.0, 0.0], P0=np.eye(2)
    )
    return model, np.array(xs), np.array(ys)[:, None]


# ---------------------------------------------------------------------------- reductions


def test_infinite_limits_reduce_to_kf_general_and_diagonal():
    rng = np.random.default_rng(0)
    for model in (_general_model(rng, batch=(4,)), _diag_model(rng, batch=(4,))):
        ys = rng.normal(size=(30, 4, model.p)) * 2
        ys[5, 1, 0] = np.nan
        ys[9, 2] = np.nan
        kf = kalman_filter(model, ys)
        tc = tobit_filter(model, ys, -np.inf, np.inf, variant="corrected")
        _close(tc.means, kf.means)
        _close(tc.covs, kf.covs)
        at = adaptive_tobit_filter(model, ys, c=np.inf)
        _close(at.means, kf.means)
        _close(at.covs, kf.covs)
        # Tobit log-likelihood: product of the marginals N(m_i, S_ii) (eq. 27-28); the KF's
        # is the joint Gaussian density; they agree when S is diagonal
        m_pred = kf.predicted_means @ model.H.T
        S = model.H @ kf.predicted_covs @ model.H.T + model.R
        s2 = np.diagonal(S, axis1=-2, axis2=-1)
        marg = np.nansum(norm.logpdf(ys, m_pred, np.sqrt(s2)), axis=-1)
        _close(tc.loglik, marg, 1e-11)
        _close(at.loglik[1:], marg[1:], 1e-11)
        _close(at.loglik[0], kf.loglik[0], 1e-11)
        if model.is_diagonal:
            _close(tc.loglik, kf.loglik, 1e-11)
        assert np.all(tc.p_uncensored == 1.0) and not tc.clipped.any()


def test_standard_tkf_equals_kf_with_infinite_limits_and_diagonal_r():
    rng = np.random.default_rng(1)
    m = _general_model(rng, n=3, p=2)
    m = m.replace(R=np.diag([0.3, 0.7]))
    ys = rng.normal(size=(25, 2))
    kf = kalman_filter(m, ys)
    tk = tobit_filter(m, ys, variant="standard")
    _close(tk.means, kf.means)
    _close(tk.covs, kf.covs)


def test_time_varying_limits_equal_constant_ones():
    rng = np.random.default_rng(2)
    m = _general_model(rng)
    ys = rng.normal(size=(15, 2))
    lo, up = np.array([-0.5, -1.0]), np.array([0.4, 1.0])
    a = tobit_filter(m, ys, lo, up)
    b = tobit_filter(m, ys, lower_seq=np.broadcast_to(lo, (15, 2)), upper_seq=up[None])
    np.testing.assert_array_equal(a.means, b.means)
    np.testing.assert_array_equal(a.lower, b.lower)


# ---------------------------------------------------------------------------- hand loops


def _truncated(alpha, beta):
    Pa, Pb = norm.cdf(alpha), norm.sf(beta)
    Pu = norm.cdf(beta) - norm.cdf(alpha)
    mu = (norm.pdf(alpha) - norm.pdf(beta)) / Pu
    vt = 1 + (alpha * norm.pdf(alpha) - beta * norm.pdf(beta)) / Pu - mu**2
    return Pa, Pu, Pb, mu, vt


def hand_tkf_oscillator(model, ys, a, b, variant):
    """Scalar-measurement TKF / TKF^c written from the 2020 paper (Algorithm 1, eq. 12-22)
    and MATH.md §2-4, plus the documented safeguard ε s² (P_a + P_b)."""
    A, H, Q, R = model.A, model.H[0], model.Q, model.R[0, 0]
    x, P = model.x0.copy(), model.P0.copy()
    out_x, out_P, out_ll = [], [], []
    for y in ys[:, 0]:
        x = A @ x
        P = A @ P @ A.T + Q
        m = H @ x
        S = H @ P @ H + R
        s2 = R if variant == "standard" else S
        s = np.sqrt(s2)
        alpha, beta = (a - m) / s, (b - m) / s
        Pa, Pu, Pb, mu, vt = _truncated(alpha, beta)
        Pxy = P @ H * Pu  # eq. 12
        if variant == "standard":
            Ey = Pu * (m + s * mu) + Pa * a + Pb * b
            Pyy = Pu * (H @ P @ H) * Pu + R * vt  # eq. 22
        else:
            Ef = alpha * Pa + beta * Pb + mu * Pu
            Vf = (
                Pu * vt
                + Pa * Pu * (mu - alpha) ** 2
                + Pb * Pu * (beta - mu) ** 2
                + Pa * Pb * (beta - alpha) ** 2
            )
            Ey, Pyy = m + s * Ef, S * Vf
        Pyy = Pyy + EPS_CENSORED * s2 * (Pa + Pb)
        K = Pxy / Pyy
        x = x + K * (y - Ey)
        P = P - np.outer(K, Pxy)
        if y <= a:
            ll = norm.logcdf(alpha)
        elif y >= b:
            ll = norm.logsf(beta)
        else:
            ll = norm.logpdf((y - m) / s) - np.log(s)
        out_x.append(x)
        out_P.append(P)
        out_ll.append(ll)
    return np.array(out_x), np.array(out_P), np.array(out_ll)


@pytest.mark.parametrize("variant", ["standard", "corrected"])
def test_oscillator_first_steps_against_hand_loop(variant):
    model, _, ys = oscillator(60, seed=3)
    res = tobit_filter(model, ys, -0.5, 0.5, variant=variant)
    hx, hP, hll = hand_tkf_oscillator(model, ys, -0.5, 0.5, variant)
    np.testing.assert_allclose(res.means, hx, rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(res.covs, hP, rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(res.loglik, hll, rtol=1e-9, atol=1e-9)
    assert res.clipped[:, 0].sum() == np.sum((ys <= -0.5) | (ys >= 0.5))


def test_oscillator_rmse_tkfc_beats_tkf():
    """Table 1 setting, 100 Monte Carlo runs filtered as one batch. MATH.md §5 (checked
    independently): mean RMSE TKF ≈ (0.448, 0.480), TKF^c ≈ (0.410, 0.447), ± 0.015
    between seeds; TKF^c < TKF."""
    rng = np.random.default_rng(2020)
    M, K = 100, 1000
    model, _, _ = oscillator(1, seed=0)
    x = np.broadcast_to(np.array([5.0, 0.0]), (M, 2))
    xs = np.empty((K, M, 2))
    for k in range(K):
        x = x @ model.A.T + rng.normal(scale=0.05, size=(M, 2))
        xs[k] = x
    ys = np.clip(xs[..., :1] + rng.normal(scale=np.sqrt(0.5), size=(K, M, 1)), -0.5, 0.5)
    rmse = {}
    for v in ("standard", "corrected"):
        r = tobit_filter(model, ys, -0.5, 0.5, variant=v)
        rmse[v] = np.sqrt(np.mean((r.means - xs) ** 2, axis=0)).mean(axis=0)
    assert np.all(rmse["corrected"] < rmse["standard"])
    np.testing.assert_allclose(rmse["standard"], [0.448, 0.480], atol=0.045)
    np.testing.assert_allclose(rmse["corrected"], [0.410, 0.447], atol=0.045)


def test_atkf_scalar_against_algorithm_2():
    """1-D ATKF written from Algorithm 2: KF at k = 1, then limits x̂_{k-1} ± c, clip,
    TKF^c update (eq. 12, 20, 21 for one component)."""
    rng = np.random.default_rng(4)
    q, r, c = 0.0025, 0.01, 0.15
    T = 80
    truth = np.cumsum(rng.normal(scale=0.05, size=T))
    ys = truth + rng.normal(scale=0.1, size=T)
    ys[rng.uniform(size=T) < 0.1] += 1.0  # jumps
    model = LinearGaussian(A=[[1.0]], H=[[1.0]], Q=[[q]], R=[[r]], x0=[0.0], P0=[[1.0]])
    res = adaptive_tobit_filter(model, ys[:, None], c=[c])
    x, P = 0.0, 1.0
    for k in range(T):
        lo, hi = x - c, x + c
        P = P + q
        S = P + r
        if k == 0:
            K = P / S
            x = x + K * (ys[k] - x)
            P = P - K * P
        else:
            y = min(max(ys[k], lo), hi)
            s = np.sqrt(S)
            alpha, beta = (lo - x) / s, (hi - x) / s
            Pa, Pu, Pb, mu, vt = _truncated(alpha, beta)
            Ey = x + s * (alpha * Pa + beta * Pb + mu * Pu)
            Vf = (
                Pu * vt
                + Pa * Pu * (mu - alpha) ** 2
                + Pb * Pu * (beta - mu) ** 2
                + Pa * Pb * (beta - alpha) ** 2
            )
            Pyy = S * Vf + EPS_CENSORED * S * (Pa + Pb)
            K = P * Pu / Pyy
            x = x + K * (y - Ey)
            P = P - K * P * Pu
            np.testing.assert_allclose(res.lower[k, 0], lo, rtol=1e-13, atol=1e-15)
            np.testing.assert_allclose(res.p_uncensored[k, 0], Pu, rtol=1e-10)
        np.testing.assert_allclose(res.means[k, 0], x, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(res.covs[k, 0, 0], P, rtol=1e-10)
    assert res.clipped.any()
    assert np.isneginf(res.lower[0]).all() and np.isposinf(res.upper[0]).all()


# ---------------------------------------------------------------------------- safeguard


@pytest.mark.parametrize("diagonal", [True, False])
def test_gain_vanishes_smoothly_when_almost_surely_censored(diagonal):
    """Mean 5…40 sd below the lower limit: the gain stays finite, bounded, and decays."""
    n = 2
    model = LinearGaussian(
        A=np.eye(n), H=np.eye(n), Q=np.zeros((n, n)), R=0.5 * np.eye(n),
        x0=np.zeros(n), P0=0.5 * np.eye(n),
    )  # fmt: skip
    sm = make_step_model(model, diagonal)
    s = 1.0  # sqrt(S) = sqrt(0.5 + 0.5)
    kf_gain = 0.5
    ks = np.arange(5.0, 40.5, 0.5)
    gains = []
    for k in ks:
        lower = np.array([k * s, -np.inf])
        upper = np.array([k * s + 1.0, np.inf])
        xp = np.zeros(n)
        Pp = 0.5 * np.ones(n) if diagonal else 0.5 * np.eye(n)
        y = np.array([k * s, 0.3])  # censored at the lower limit, second component plain
        u = tkfc_update(xp, Pp, y, sm, lower, upper)
        K = u.gain if diagonal else np.diagonal(u.gain)
        assert np.all(np.isfinite(u.x)) and np.all(np.isfinite(u.P))
        assert np.isclose(K[1], kf_gain, rtol=1e-12)  # the uncensored axis is a KF
        gains.append(K[0])
    gains = np.array(gains)
    assert np.all(np.isfinite(gains)) and np.all(gains >= 0)
    # bounded: TKF^c's gain grows like α²/2 x the KF gain until the safeguard takes over
    # (α ≈ 5.5 for ε = 1e-9); without it the gain would keep growing, then become 0/0
    assert gains.max() < 20 * kf_gain
    after = gains[ks >= 5.5]
    assert np.all(np.diff(after) <= 0)  # monotone decay once the safeguard dominates
    assert gains[ks == 10][0] < 1e-12
    assert gains[-1] < 1e-300


def test_far_outside_limits_no_nan_any_variant():
    """The oscillator's own first steps: the mean is 5 sd above b and more (α > 8.3)."""
    model, _, ys = oscillator(30, seed=7)
    far = model.replace(x0=[40.0, 0.0])
    for v in ("standard", "corrected"):
        r = tobit_filter(far, ys, -0.5, 0.5, variant=v)
        assert np.all(np.isfinite(r.means)) and np.all(np.isfinite(r.covs))
        assert np.all(np.isfinite(r.loglik))


# ---------------------------------------------------------------------------- Monte Carlo


def test_tkfc_update_is_the_linear_mmse_estimator_monte_carlo():
    """x ~ N(x⁻, P⁻), y = clip(H x + v): with TKF^c's E[y], Pxy, Pyy the update is the best
    linear estimator, so the error has mean 0, is uncorrelated with y, and has covariance
    P (the updated one). Checked within 4.5 standard errors."""
    rng = np.random.default_rng(11)
    n, p, N = 2, 2, 200_000
    model = _general_model(rng, n=n, p=p)
    xp = np.array([0.3, -0.2])
    Pp = np.array([[1.0, 0.4], [0.4, 0.8]])
    m = model.H @ xp
    lower, upper = m + np.array([-0.8, -np.inf]), m + np.array([0.5, 0.7])
    sm = make_step_model(model, False)
    xs = rng.multivariate_normal(xp, Pp, size=N)
    ystar = xs @ model.H.T + rng.multivariate_normal(np.zeros(p), model.R, size=N)
    ys = np.clip(ystar, lower, upper)
    u = tkfc_update(xp, Pp, ys, sm, lower, upper)  # moments shared, y batched (N, p)
    err = xs - u.x
    se = err.std(axis=0) / np.sqrt(N)
    assert np.all(np.abs(err.mean(axis=0)) < 4.5 * se)
    yc = ys - ys.mean(axis=0)
    for a in range(n):
        for b in range(p):
            z = err[:, a] * yc[:, b]
            assert abs(z.mean()) < 4.5 * z.std() / np.sqrt(N)
    P_post = u.P[0]
    for a in range(n):
        for b in range(n):
            z = err[:, a] * err[:, b]
            assert abs(z.mean() - P_post[a, b]) < 4.5 * z.std() / np.sqrt(N)


# ---------------------------------------------------------------------------- missing data


@pytest.mark.parametrize("variant", ["standard", "corrected"])
def test_missing_component_equals_reduced_model(variant):
    rng = np.random.default_rng(12)
    m = _general_model(rng, n=3, p=2)
    ys = rng.normal(size=(6, 2))
    ys[3, 1] = np.nan
    lo, up = np.array([-0.3, -0.5]), np.array([0.6, 0.2])
    full = tobit_filter(m, ys, lo, up, variant=variant)
    # step 3 by hand with the reduced model (component 0 only), starting from step 2
    red = LinearGaussian(A=m.A, H=m.H[:1], Q=m.Q, R=m.R[:1, :1], x0=full.means[2], P0=full.covs[2])
    one = tobit_filter(red, ys[3:4, :1], lo[:1], up[:1], variant=variant)
    _close(full.means[3], one.means[0], 1e-11)
    _close(full.covs[3], one.covs[0], 1e-11)
    _close(full.loglik[3], one.loglik[0], 1e-11)


# ---------------------------------------------------------------------------- long runs


@settings(max_examples=12, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    method=st.sampled_from(["tkf", "tkfc", "atkf"]),
    diagonal=st.booleans(),
)
def test_long_runs_with_wild_measurements_stay_finite_psd(seed, method, diagonal):
    rng = np.random.default_rng(seed)
    if diagonal:
        m = _diag_model(rng, n=2, batch=(3,), a_identity=bool(rng.integers(2)))
    else:
        m = _general_model(rng, n=2, p=2, batch=(3,))
    T = 40
    ys = rng.normal(size=(T, 3, 2)) * rng.choice([0.1, 1.0, 50.0, 1e4], size=(T, 3, 2))
    ys[rng.uniform(size=ys.shape) < 0.1] = np.nan
    lo, up = np.array([-1.0, -0.5]), np.array([1.0, 0.3])
    if method == "atkf":
        r = adaptive_tobit_filter(m, ys, c=[0.2, 0.1])
    else:
        variant = "standard" if method == "tkf" else "corrected"
        r = tobit_filter(m, ys, lo, up, variant=variant)
    for arr in (r.means, r.covs, r.loglik, r.p_uncensored):
        assert np.all(np.isfinite(arr))
    P = r.covs
    np.testing.assert_array_equal(P, np.swapaxes(P, -1, -2))
    eig = np.linalg.eigvalsh(P)
    assert np.all(eig >= -1e-12 * np.abs(eig).max())


# ---------------------------------------------------------------------------- diag vs general


@settings(max_examples=15, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    method=st.sampled_from(["tkf", "tkfc", "atkf", "atkf_I"]),
    missing=st.floats(0, 0.4),
)
@example(seed=1264, method="tkf", missing=0.0)  # 2.3e-11 apart: rounding, not logic
def test_diagonal_path_equals_general_path(seed, method, missing):
    rng = np.random.default_rng(seed)
    model = _diag_model(rng, n=3, batch=(2,), a_identity=method == "atkf_I")
    T = 15
    ys = rng.normal(size=(T, 2, 3)) * rng.choice([0.2, 1.0, 5.0], size=(T, 2, 3))
    ys[rng.uniform(size=ys.shape) < missing] = np.nan
    R_scale = rng.uniform(0.5, 3.0, size=(T, 2, 3))
    kw = dict(R_scale=R_scale)
    if method.startswith("atkf"):
        c = rng.uniform(0.05, 1.0, size=3)
        run = lambda d: adaptive_tobit_filter(model, ys, c=c, diagonal=d, **kw)  # noqa: E731
    else:
        lo = rng.uniform(-1.0, -0.1, size=(T, 2, 3))
        up = lo + rng.uniform(0.1, 2.0, size=(T, 2, 3))
        variant = "standard" if method == "tkf" else "corrected"
        run = lambda d: tobit_filter(  # noqa: E731
            model, ys, lower_seq=lo, upper_seq=up, variant=variant, diagonal=d, **kw
        )
    d, g = run(None), run(False)
    assert d.diagonal and not g.diagonal
    # the two paths round differently (scalar recursions against matrix solves through
    # the truncated moments); with sd scales up to 25x apart they drift to ~1e-11 in 15
    # steps (seed 1264), while a wrong formula is off by far more than 1e-10
    _close(d.means, g.means, 1e-10)
    _close(d.covs, g.covs, 1e-10)
    _close(d.loglik, g.loglik, 1e-10)
    _close(d.p_uncensored, g.p_uncensored, 1e-10)
    _close(d.lower, g.lower, 1e-10)
    np.testing.assert_array_equal(d.clipped, g.clipped)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), scale=st.sampled_from([1e-4, 0.1, 1.0, 100.0]))
def test_atkf_symmetric_closed_form_equals_tkfc_update(seed, scale):
    """The A = I closed form of the ATKF step against the generic TKF^c update with the
    limits m ± c (narrow, ordinary and almost surely censored intervals)."""
    rng = np.random.default_rng(seed)
    model = _diag_model(rng, n=3, a_identity=True)
    # dyadic H, x⁻ and c, so that the limits m ± c are exact: both updates then see the
    # same interval (rounding m ± c perturbs a width w by ~1e-16/w relative, 1e-10 for the
    # narrowest intervals here, which made the comparison fail for ~1 seed in 1000)
    model = model.replace(H=np.round(model.H * 2.0**20) / 2.0**20)
    sm = make_step_model(model, True)
    assert sm.a_identity
    xp = np.round(rng.normal(size=(4, 3)) * 2.0**10) / 2.0**10
    vp = rng.uniform(0.01, 2.0, size=(4, 3))
    c = np.round(scale * rng.uniform(0.01, 1.0, size=(4, 3)) * 2.0**40) / 2.0**40
    y = xp * sm.H + rng.normal(size=(4, 3)) * rng.choice([0.1, 1.0, 10.0], size=(4, 3))
    y[0, 1] = np.nan
    m = sm.H * xp
    assert np.all((m + c) - m == c) and np.all(m - (m - c) == c)
    fast = atkf_update(xp, vp, y, sm, m - c, m + c, c)
    ref = tkfc_update(xp, vp, y, sm, m - c, m + c, c)
    tol = 1e-10
    np.testing.assert_allclose(fast.x, ref.x, rtol=tol, atol=tol * np.abs(c).max())
    np.testing.assert_allclose(fast.P, ref.P, rtol=tol, atol=1e-300)
    np.testing.assert_allclose(fast.p_uncensored, ref.p_uncensored, rtol=tol, atol=1e-300)
    np.testing.assert_allclose(fast.loglik, ref.loglik, rtol=1e-9)
    np.testing.assert_array_equal(fast.clipped, ref.clipped)


def test_input_errors():
    m = skeleton_model()
    ys = np.zeros((4, 3))
    with pytest.raises(ValueError, match="variant"):
        tobit_filter(m, ys, variant="bogus")
    with pytest.raises(ValueError, match="lower limit must be <"):
        tobit_filter(m, ys, 1.0, 0.0)
    with pytest.raises(ValueError, match="does not broadcast"):
        tobit_filter(m, ys, np.zeros(2), 1.0)
    with pytest.raises(ValueError, match="c: half-widths"):
        adaptive_tobit_filter(m, ys, c=0.0)
    with pytest.raises(ValueError, match="give c"):
        adaptive_tobit_filter(m, ys)
    with pytest.raises(ValueError, match="either c or c_seq"):
        adaptive_tobit_filter(m, ys, c=1.0, c_seq=np.ones((4, 3)))


# ---------------------------------------------------------------------------- real data


@pytest.mark.realdata
def test_atkf_on_real_kinect_glitches():
    """KERAAL ELK (Kinect V2, 30 Hz): the right hand tip / thumb jump by ~1 m in one frame
    (data README). With the paper's defaults (eq. 30, 33, 35) ATKF must damp those jumps
    far more than the KF, leave the trunk untouched by censoring, and the streaming filter
    must reproduce the batch run exactly."""
    from conftest import data_file

    raw = np.loadtxt(data_file("keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt"))
    ys = raw.reshape(raw.shape[0], 25, 7)[..., :3]  # positions (T, 25, 3), y up
    model = skeleton_model(ys=ys)
    c = np.array([0.34, 0.18, 0.34])
    at = adaptive_tobit_filter(model, ys, c=c)
    kf = kalman_filter(model, ys)

    def max_jump(x):
        return np.linalg.norm(np.diff(x, axis=0), axis=-1).max(axis=0)

    raw_j, kf_j, at_j = max_jump(ys), max_jump(kf.means), max_jump(at.means)
    tips = [23, 24]  # HandTipRight, ThumbRight
    assert np.all(raw_j[tips] > 0.8)
    assert np.all(at_j[tips] < 0.5 * kf_j[tips])
    assert np.all(at_j[tips] < 0.25 * raw_j[tips])
    assert not at.clipped[:, [0, 1, 12, 16]].any()  # SpineBase, SpineMid, hips: no clipping
    assert np.all(np.isfinite(at.means)) and np.all(at.covs >= 0)
    from tobitkf.core.streaming import StreamingFilter

    f = StreamingFilter(model, "atkf", c=c)
    for t in range(ys.shape[0]):
        mean, _ = f.step(ys[t])
        np.testing.assert_array_equal(mean, at.means[t])


def test_last_call_memo_equals_the_function():
    # the ATKF's memo of log_ndtr / erf: same numbers as calling the function, whatever
    # part of the argument repeats; and what it returns is the caller's to change
    from scipy import special

    from tobitkf.core.tobit import _LastCall

    memo = _LastCall(special.log_ndtr)
    rng = np.random.default_rng(8)
    x = rng.uniform(-40, 5, size=(6, 5, 3))
    for _ in range(6):
        got = memo(x)
        np.testing.assert_array_equal(got, special.log_ndtr(x))
        got[...] = 0.0
        x = x.copy()
        x[rng.random(x.shape) < 0.1] = rng.uniform(-40, 5)
    np.testing.assert_array_equal(memo(x[:2]), special.log_ndtr(x[:2]))  # other shape


@pytest.mark.parametrize("variant", ["standard", "corrected"])
def test_posterior_variances_stay_between_zero_and_the_prediction(variant):
    # issue 14 point 6: with Q/R >= 1e16 the standard TKF's v = v⁻ - Pxy²/Pyy cancelled
    # to negative values (-1.8e134 with R = 1, Q = 1e150). A linear update can only shrink
    # the variance: 0 <= v <= v⁻ at every step, whatever the scale. 600 random scales
    # (before the fix, 1 run in 90 of the standard TKF broke this)
    rng = np.random.default_rng(20261124)
    for _ in range(600):
        q, r = 10 ** rng.uniform(-10, 200), 10 ** rng.uniform(-10, 50)
        model = LinearGaussian(
            A=np.eye(1), H=np.eye(1), Q=q * np.eye(1), R=r * np.eye(1),
            x0=np.zeros(1), P0=r * np.eye(1),
        )  # fmt: skip
        ys = rng.normal(size=(10, 1)) * np.sqrt(q) * rng.uniform(0, 3)
        lo, up = -abs(rng.normal()) * np.sqrt(q), abs(rng.normal()) * np.sqrt(q)
        with np.errstate(all="ignore"):
            res = tobit_filter(model, ys, lo, up, variant=variant)
        v, vp = res.variances, res.predicted_variances
        assert np.all(np.isfinite(res.means)) and np.all(np.isfinite(v)), (q, r)
        assert np.all(v >= 0) and np.all(v <= vp * (1 + 1e-12)), (q, r)


def test_an_uncensored_measurement_far_out_keeps_the_tkfc_finite():
    # issue 14 point 6: a measurement 1e154 sd from the prediction
    model = LinearGaussian(
        A=np.eye(1), H=np.eye(1), Q=np.eye(1), R=np.eye(1), x0=np.zeros(1), P0=np.eye(1)
    )
    res = tobit_filter(model, np.full((5, 1), 1e154), 0.0, np.inf, variant="corrected")
    assert np.all(np.isfinite(res.means)) and np.all(np.isfinite(res.loglik))
    # it moves towards the measurement, never past it
    m = res.means[:, 0]
    assert np.all(np.diff(m) > 0) and np.all((m > 0) & (m <= 1e154))


# ------------------------------------------------- standardised limits beyond 1e154 sd


def _scalar_model(x0, P0, Q, R):
    x0 = np.asarray(x0, dtype=float)
    return LinearGaussian(A=np.eye(1), H=np.eye(1), Q=[[Q]], R=[[R]], x0=x0, P0=[[P0]])


@pytest.mark.parametrize("variant", ["standard", "corrected"])
def test_subnormal_r_exact_limits_not_nan(variant):
    """R = 1e-320 (√R = 1e-160: limits 1e160 sd away, z² infinite). A prediction inside
    the limits: the limits are as if infinite (the KF); one beyond them, certainly
    censored (P_un = 0, Pxy = 0): no gain, the prediction is kept. They were NaN."""
    ys = np.array([[[0.3], [0.4]], [[0.5], [0.6]], [[-0.2], [0.1]]])  # (T, batch, p)
    model = _scalar_model([[0.0], [3.0]], 1e-320, 0.0, 1e-320)
    res = tobit_filter(model, ys, -1.0, 1.0, variant=variant)
    with np.errstate(over="ignore"):  # the KF's log-likelihood: 1/S overflows
        kf = kalman_filter(model.replace(x0=[[0.0]]), ys[:, :1])
    np.testing.assert_array_equal(res.means[:, :1], kf.means)
    np.testing.assert_array_equal(res.covs[:, :1], kf.covs)
    np.testing.assert_array_equal(res.means[:, 1], 3.0)
    np.testing.assert_array_equal(res.covs[:, 1], 1e-320)
    # the standard TKF (probabilities from R alone): with P0 = Q = 1 the measurement is
    # exact, the posterior mean is the measurement and the variance ~R
    model = _scalar_model([[0.0], [3.0]], 1.0, 1.0, 1e-320)
    res = tobit_filter(model, ys, -1.0, 1.0, variant="standard")
    np.testing.assert_allclose(res.means[:, 0], ys[:, 0], rtol=4e-16, atol=0)
    assert np.all(res.covs[:, 0] <= 1e-320)
    np.testing.assert_array_equal(res.means[:, 1], 3.0)
    np.testing.assert_array_equal(res.covs[:, 1, 0, 0], [2.0, 3.0, 4.0])


@pytest.mark.parametrize("diagonal", [True, False])
def test_limits_beyond_1e154_sd_tkfc_is_the_kf(diagonal):
    """S ~ 1e-300 and limits ±1e5: 7e154 sd away, z² infinite. TKF^c with limits that
    far is the KF (P_un = 1, E[y] = m, Cov[y] = S); the general path also through the
    cross-covariances (correlated states). They were NaN."""
    rng = np.random.default_rng(3)
    P0 = 1e-300 * _spd(rng, 2)
    Q = np.diag([1e-300, 2e-300]) if diagonal else 1e-300 * _spd(rng, 2)
    P0 = np.diag(np.diag(P0)) if diagonal else P0
    model = LinearGaussian(
        A=np.eye(2), H=np.eye(2), Q=Q, R=np.diag([1e-300, 3e-300]), x0=[0.0, 1.0], P0=P0
    )
    ys = 1e-150 * rng.normal(size=(20, 2)) + [0.0, 1.0]
    kf = kalman_filter(model, ys, diagonal=diagonal)
    tc = tobit_filter(model, ys, -1e5, 1e5, variant="corrected", diagonal=diagonal)
    assert np.all(tc.p_uncensored == 1.0)
    np.testing.assert_allclose(tc.means, kf.means, rtol=1e-15, atol=0)
    np.testing.assert_allclose(tc.covs, kf.covs, rtol=1e-12, atol=0)


@pytest.mark.parametrize("variant", ["standard", "corrected"])
@pytest.mark.parametrize("r", [1e-300, 1e-320, 1e-6])
def test_a_certainly_censored_component_is_dropped_on_the_general_path(variant, r):
    """Correlated states, the first measured component certainly censored (its
    prediction 5 far beyond the limit ±1 in sd of R): it carries no information, and the
    filter equals a Kalman filter that measures the second component alone. With R =
    1e-300 the general path gave NaN (its variance's inverse overflowed, times a zero
    innovation)."""
    P0 = np.array([[1.0, 0.6], [0.6, 1.0]])
    kw = dict(A=np.eye(2), Q=0.1 * P0, x0=[5.0, 0.0], P0=P0)
    both = LinearGaussian(H=np.eye(2), R=np.diag([r, r]), **kw)
    ys = np.array([[1.0, 0.2], [1.0, 0.3], [1.0, -0.1]])
    res = tobit_filter(both, ys, -1.0, 1.0, variant=variant, diagonal=False)
    if variant == "corrected":  # probabilities from S = HPH + R: not certain there
        assert np.all(np.isfinite(res.means)) and np.all(np.isfinite(res.covs))
        return
    assert np.all(res.p_uncensored[:, 0] == 0.0)
    one = LinearGaussian(H=np.array([[0.0, 1.0]]), R=np.array([[r]]), **kw)
    kf = kalman_filter(one, ys[:, 1:])
    np.testing.assert_allclose(res.means, kf.means, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(res.covs, kf.covs, rtol=1e-9, atol=1e-15)
