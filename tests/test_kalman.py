"""Plain KF and RTS smoother against the closed-form joint Gaussian posterior."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tobitkf.core.kalman import kalman_filter, rts_smooth
from tobitkf.core.model import LinearGaussian
from tobitkf.smoothing.paper import skeleton_model

# ---------------------------------------------------------------------------- brute force


def joint_prior(model, T, A_seq=None, Q_seq=None):
    """Mean (T n,) and covariance (T n, T n) of the stacked states s_0..s_{T-1}.

    s_0 = A_0 x0 + w_0 with x0 ~ N(x0, P0); s_t = A_t s_{t-1} + w_t.
    Built as s = M z + mean with z = (x0 - mean0, w_0, ..., w_{T-1}).
    """
    n = model.n
    As = [model.A if A_seq is None else A_seq[t] for t in range(T)]
    Qs = [model.Q if Q_seq is None else Q_seq[t] for t in range(T)]
    # linear map from (e0, w_0..w_{T-1}) to states
    M = np.zeros((T * n, (T + 1) * n))
    cov_z = np.zeros(((T + 1) * n, (T + 1) * n))
    cov_z[:n, :n] = model.P0
    for t in range(T):
        cov_z[(t + 1) * n : (t + 2) * n, (t + 1) * n : (t + 2) * n] = Qs[t]
    mean = np.zeros(T * n)
    prev_map = np.zeros((n, (T + 1) * n))
    prev_map[:, :n] = np.eye(n)
    prev_mean = np.asarray(model.x0, dtype=float)
    for t in range(T):
        cur = As[t] @ prev_map
        cur[:, (t + 1) * n : (t + 2) * n] += np.eye(n)
        M[t * n : (t + 1) * n] = cur
        prev_mean = As[t] @ prev_mean
        mean[t * n : (t + 1) * n] = prev_mean
        prev_map = cur
    return mean, M @ cov_z @ M.T


def joint_posterior(model, ys, upto, A_seq=None, Q_seq=None, R_seq=None):
    """Posterior mean/cov of all T states given y_0..y_upto (NaN components dropped)
    and the log density of those observations."""
    T = ys.shape[0]
    n = model.n
    mu, Sig = joint_prior(model, T, A_seq, Q_seq)
    rows, yv, Rblocks = [], [], []
    for t in range(upto + 1):
        R = model.R if R_seq is None else R_seq[t]
        obs = ~np.isnan(ys[t])
        for i in np.flatnonzero(obs):
            row = np.zeros(T * n)
            row[t * n : (t + 1) * n] = model.H[i]
            rows.append(row)
            yv.append(ys[t, i])
        Rblocks.append(R[np.ix_(obs, obs)])
    if not rows:
        return mu, Sig, 0.0
    Hb = np.array(rows)
    Rb = np.zeros((len(rows), len(rows)))
    k = 0
    for Rb_t in Rblocks:
        d = Rb_t.shape[0]
        Rb[k : k + d, k : k + d] = Rb_t
        k += d
    S = Hb @ Sig @ Hb.T + Rb
    e = np.array(yv) - Hb @ mu
    G = np.linalg.solve(S, Hb @ Sig).T
    post_mu = mu + G @ e
    post_S = Sig - G @ Hb @ Sig
    _, logdet = np.linalg.slogdet(S)
    logp = -0.5 * (len(yv) * np.log(2 * np.pi) + logdet + e @ np.linalg.solve(S, e))
    return post_mu, post_S, logp


def _random_model(rng, n, p, diagonal=False):
    if diagonal:
        A = np.diag(rng.uniform(0.5, 1.1, n))
        H = np.diag(rng.uniform(0.5, 1.5, n))
        Q = np.diag(rng.uniform(0.01, 0.2, n))
        R = np.diag(rng.uniform(0.05, 0.5, p))
        P0 = np.diag(rng.uniform(0.1, 1.0, n))
    else:
        A = rng.normal(size=(n, n)) * 0.4 + np.eye(n) * 0.7
        H = rng.normal(size=(p, n))
        B = rng.normal(size=(n, n))
        Q = 0.1 * B @ B.T + 0.01 * np.eye(n)
        C = rng.normal(size=(p, p))
        R = 0.2 * C @ C.T + 0.05 * np.eye(p)
        D = rng.normal(size=(n, n))
        P0 = 0.3 * D @ D.T + 0.1 * np.eye(n)
    return LinearGaussian(A=A, H=H, Q=Q, R=R, x0=rng.normal(size=n), P0=P0)


def _check_against_brute_force(model, ys, A_seq=None, Q_seq=None, R_seq=None):
    T, n = ys.shape[0], model.n
    res = kalman_filter(model, ys, A_seq=A_seq, Q_seq=Q_seq, R_seq=R_seq)
    sm = rts_smooth(model, res)
    prev_logp = 0.0
    for t in range(T):
        mu, S, logp = joint_posterior(model, ys, t, A_seq, Q_seq, R_seq)
        sl = slice(t * n, (t + 1) * n)
        np.testing.assert_allclose(res.means[t], mu[sl], rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(res.covs[t], S[sl, sl], rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(res.loglik[t], logp - prev_logp, rtol=1e-9, atol=1e-9)
        prev_logp = logp
        if t > 0:
            mu_p, S_p, _ = joint_posterior(model, ys, t - 1, A_seq, Q_seq, R_seq)
            np.testing.assert_allclose(res.predicted_means[t], mu_p[sl], rtol=1e-9, atol=1e-10)
            np.testing.assert_allclose(res.predicted_covs[t], S_p[sl, sl], rtol=1e-9, atol=1e-10)
    mu, S, _ = joint_posterior(model, ys, T - 1, A_seq, Q_seq, R_seq)
    for t in range(T):
        sl = slice(t * n, (t + 1) * n)
        np.testing.assert_allclose(sm.means[t], mu[sl], rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(sm.covs[t], S[sl, sl], rtol=1e-9, atol=1e-10)
    return res


# ---------------------------------------------------------------------------- tests


@pytest.mark.parametrize(("n", "p"), [(1, 1), (2, 1), (3, 2), (2, 3)])
def test_kf_and_rts_match_joint_posterior(n, p):
    rng = np.random.default_rng(10 * n + p)
    model = _random_model(rng, n, p)
    T = 7
    ys = rng.normal(size=(T, p)) * 2
    if p > 1:
        ys[2, 0] = np.nan  # one component missing, the other used
    ys[4] = np.nan  # fully missing step
    _check_against_brute_force(model, ys)


def test_kf_time_varying_matches_joint_posterior():
    rng = np.random.default_rng(5)
    model = _random_model(rng, 2, 2)
    T = 6
    A_seq = np.stack([_random_model(rng, 2, 2).A for _ in range(T)])
    Q_seq = np.stack([_random_model(rng, 2, 2).Q for _ in range(T)])
    R_seq = np.stack([_random_model(rng, 2, 2).R for _ in range(T)])
    ys = rng.normal(size=(T, 2))
    ys[3, 1] = np.nan
    res = _check_against_brute_force(model, ys, A_seq, Q_seq, R_seq)
    assert res.A_seq is not None


def test_fully_missing_step_is_pure_prediction():
    rng = np.random.default_rng(3)
    model = _random_model(rng, 2, 2)
    ys = rng.normal(size=(4, 2))
    ys[2] = np.nan
    res = kalman_filter(model, ys)
    np.testing.assert_array_equal(res.means[2], res.predicted_means[2])
    np.testing.assert_array_equal(res.covs[2], res.predicted_covs[2])
    assert res.loglik[2] == 0.0
    np.testing.assert_allclose(res.predicted_means[2], model.A @ res.means[1], rtol=1e-14)


def test_batch_axes_are_independent():
    rng = np.random.default_rng(4)
    model = _random_model(rng, 2, 2)
    x0 = rng.normal(size=(3, 2))
    mb = model.replace(x0=x0)
    ys = rng.normal(size=(5, 3, 2))
    ys[1, 2, 0] = np.nan
    res = kalman_filter(mb, ys)
    for b in range(3):
        single = kalman_filter(model.replace(x0=x0[b]), ys[:, b])
        np.testing.assert_allclose(res.means[:, b], single.means, rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(res.covs[:, b], single.covs, rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(res.loglik[:, b], single.loglik, rtol=1e-13)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 4), frac_missing=st.floats(0, 0.5))
def test_diagonal_path_equals_general_path(seed, n, frac_missing):
    rng = np.random.default_rng(seed)
    model = _random_model(rng, n, n, diagonal=True).replace(x0=rng.normal(size=(2, n)))
    T = 12
    ys = rng.normal(size=(T, 2, n)) * 3
    ys[rng.uniform(size=ys.shape) < frac_missing] = np.nan
    R_scale = rng.uniform(0.5, 4.0, size=(T, 2, n))
    A_seq = np.stack([np.diag(rng.uniform(0.5, 1.2, n)) for _ in range(T)])
    d = kalman_filter(model, ys, R_scale=R_scale, A_seq=A_seq)
    g = kalman_filter(model, ys, R_scale=R_scale, A_seq=A_seq, diagonal=False)
    assert d.diagonal and not g.diagonal
    np.testing.assert_allclose(d.means, g.means, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(d.covs, g.covs, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(d.predicted_covs, g.predicted_covs, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(d.loglik, g.loglik, rtol=1e-12, atol=1e-10)
    sd, sg = rts_smooth(model, d), rts_smooth(model, g)
    np.testing.assert_allclose(sd.means, sg.means, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sd.covs, sg.covs, rtol=1e-12, atol=1e-14)


def test_r_scale_equals_scaled_r():
    rng = np.random.default_rng(8)
    model = _random_model(rng, 2, 2)
    ys = rng.normal(size=(5, 2))
    scale = np.array([2.0, 0.5])
    d = np.sqrt(scale)
    R2 = model.R * d[:, None] * d[None, :]
    a = kalman_filter(model, ys, R_scale=np.broadcast_to(scale, (5, 2)))
    b = kalman_filter(model.replace(R=R2), ys)
    np.testing.assert_allclose(a.means, b.means, rtol=1e-13)
    np.testing.assert_allclose(a.loglik, b.loglik, rtol=1e-13)


def test_input_errors():
    model = skeleton_model()
    with pytest.raises(ValueError, match="ys: expected shape"):
        kalman_filter(model, np.zeros((5, 2)))
    with pytest.raises(ValueError, match="infinite"):
        kalman_filter(model, np.full((5, 3), np.inf))
    with pytest.raises(ValueError, match="A_seq: expected shape"):
        kalman_filter(model, np.zeros((5, 3)), A_seq=np.zeros((4, 3, 3)))
    with pytest.raises(ValueError, match="R_seq: not positive definite"):
        kalman_filter(model, np.zeros((5, 3)), R_seq=np.zeros((5, 3, 3)))
    with pytest.raises(ValueError, match="R_scale"):
        kalman_filter(model, np.zeros((5, 3)), R_scale=-1.0)
    with pytest.raises(ValueError, match="diagonal=True"):
        m = LinearGaussian(
            A=np.eye(2), H=np.eye(2), Q=[[1, 0.5], [0.5, 1]], R=np.eye(2), x0=[0, 0], P0=np.eye(2)
        )
        kalman_filter(m, np.zeros((3, 2)), diagonal=True)
    with pytest.raises(ValueError, match="batch shape"):
        kalman_filter(model.replace(x0=np.zeros((4, 3))), np.zeros((5, 2, 3)))


def test_zero_time_steps_give_empty_results_of_the_documented_shapes():
    """T = 0 (an empty recording) is not an error: every field has a leading 0 axis."""
    from tobitkf.core.tobit import adaptive_tobit_filter, tobit_filter

    rng = np.random.default_rng(6)
    for model in (_random_model(rng, 3, 3, diagonal=True), _random_model(rng, 3, 2)):
        n, p = model.n, model.p
        ys = np.zeros((0, 4, p))
        for res in (
            kalman_filter(model, ys),
            tobit_filter(model, ys, -1.0, 1.0),
            tobit_filter(model, ys, -1.0, 1.0, variant="standard"),
            adaptive_tobit_filter(model, ys, c=0.3),
        ):
            assert res.means.shape == res.predicted_means.shape == (0, 4, n)
            assert res.covs.shape == res.predicted_covs.shape == (0, 4, n, n)
            assert res.loglik.shape == (0, 4)
            for arr in (res.p_uncensored, res.clipped, res.lower, res.upper):
                assert arr.shape == (0, 4, p)
            assert rts_smooth(model, res).covs.shape == (0, 4, n, n)


def test_rts_with_singular_predicted_covariance_matches_joint_posterior():
    """Q and P0 singular (state 0 known exactly and constant): P⁻ is singular at every
    step; the smoother must still give the exact posterior (pseudo-inverse gain)."""
    model = LinearGaussian(
        A=np.eye(2), H=[[1.0, 1.0]], Q=np.diag([0.0, 0.2]), R=[[0.3]], x0=[0.5, 0.0],
        P0=np.diag([0.0, 1.0]),
    )  # fmt: skip
    ys = np.random.default_rng(9).normal(size=(6, 1))
    ys[3] = np.nan
    res = _check_against_brute_force(model, ys)
    assert np.linalg.matrix_rank(res.predicted_covs[2]) == 1


def test_sum_last_equals_numpy_sum_bit_for_bit():
    # the written-out sum over 3 components used per frame is numpy's own order
    from tobitkf.core.engine import sum_last

    rng = np.random.default_rng(5)
    for shape in ((7, 3), (4, 5, 3), (6, 2)):
        a = rng.normal(size=shape) * 10.0 ** rng.integers(-8, 8, size=shape)
        np.testing.assert_array_equal(sum_last(a), a.sum(axis=-1))


def test_keep_predicted_false_leaves_the_rest_unchanged():
    # without the predicted covariances (read by the RTS pass only) every other output
    # of the filters is the same, bit for bit
    from tobitkf.core.model import LinearGaussian
    from tobitkf.core.tobit import adaptive_tobit_filter, tobit_filter

    rng = np.random.default_rng(10)
    ys = np.cumsum(rng.normal(scale=0.1, size=(30, 4, 3)), axis=0)
    ys[rng.random((30, 4)) < 0.2] = np.nan
    model = LinearGaussian(
        A=np.eye(3), H=np.eye(3), Q=0.01 * np.eye(3), R=0.04 * np.eye(3), x0=np.zeros((4, 3)),
        P0=np.eye(3),
    )  # fmt: skip
    scale = rng.choice([1.0, 4.0], size=(30, 4, 3))
    runs = [
        lambda **k: kalman_filter(model, ys, R_scale=scale, **k),
        lambda **k: tobit_filter(model, ys, -0.5, 0.5, keep_probabilities=False, **k),
        lambda **k: adaptive_tobit_filter(model, ys, 0.3, **k),
    ]
    for run in runs:
        a, b = run(), run(keep_predicted=False)
        for name in ("means", "cov_data", "loglik", "clipped"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert np.isnan(b.predicted_cov_data).all()


@pytest.mark.parametrize("diagonal", [True, False])
def test_rts_refuses_a_result_without_predicted_covariances(diagonal):
    """keep_predicted=False drops what the smoother reads: it used to return the filtered
    means unchanged (diagonal path) or NaN (general path), silently."""
    m = LinearGaussian.random_walk(0.01, 0.1, dim=3)
    ys = np.random.default_rng(1).normal(size=(50, 3)).cumsum(0) * 0.1
    kept = kalman_filter(m, ys, diagonal=diagonal)
    assert not np.array_equal(rts_smooth(m, kept).means, kept.means)
    with pytest.raises(ValueError, match="keep_predicted=True"):
        rts_smooth(m, kalman_filter(m, ys, keep_predicted=False, diagonal=diagonal))
