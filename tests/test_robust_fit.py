"""The robust smoother's fitted noise (robust_fit.py, _noise_kernels.py).

The likelihood and the smoother are checked against an independent brute-force Kalman
filter / RTS smoother in numpy whose discretisation comes from the matrix exponential
(Van Loan), not from the kernels' closed forms; the fit against known parameters on
tracks simulated from the model itself (Monte Carlo, stated standard errors); its
compiled optimiser against scipy's L-BFGS-B (the optimiser before it) and a tightly
converged scipy run on the fit's own objective.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from scipy.optimize import minimize

import tobitkf as tk
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.smoothing import _minimize
from tobitkf.smoothing import _noise_kernels as nk
from tobitkf.smoothing import _robust_kernels as rk
from tobitkf.smoothing.robust import _smooth_run as smooth_run
from tobitkf.smoothing.robust_fit import FIT_FTOL, fit_blocks, fit_group, fit_noise_bodies

TAU = 0.15


def expm(M: np.ndarray) -> np.ndarray:
    """Matrix exponential by scaling and squaring of a 24-term Taylor series (small
    matrices; scipy's Padé routine is slow on a busy machine)."""
    s = max(0, int(np.ceil(np.log2(max(np.abs(M).sum(axis=1).max(), 1e-300) / 0.5))))
    A = M / 2.0**s
    out, term = np.eye(len(M)), np.eye(len(M))
    for k in range(1, 25):
        term = term @ A / k
        out = out + term
    for _ in range(s):
        out = out @ out
    return out


@functools.cache
def _discrete(dt: float, q: float, sc2: float, tau: float, tau_c: float):
    """Exact (A, Q) of the continuous model ``dx = v dt``, ``dv = -v/tau dt + sqrt(q) dW``,
    ``dc = -c/tau_c dt + sqrt(2 sc2 / tau_c) dW'`` by Van Loan's matrix exponential."""
    F = np.array([[0.0, 1.0, 0.0], [0.0, -1.0 / tau, 0.0], [0.0, 0.0, -1.0 / tau_c]])
    W = np.diag([0.0, q, 2 * sc2 / tau_c])
    M = np.zeros((6, 6))
    M[:3, :3], M[:3, 3:], M[3:, 3:] = -F, W, F.T
    E = expm(M * dt)
    A = E[3:, 3:].T
    return A, A @ E[:3, 3:]


def _p0(r: float, q: float, sc2: float, tau: float) -> np.ndarray:
    return np.array([[r + sc2, 0.0, -sc2], [0.0, q * tau / 2, 0.0], [-sc2, 0.0, sc2]])


def _brute_loglik(yk, rscale, steps, frames, restart, q, r, sc2, tau, tau_c) -> float:
    H = np.array([1.0, 0.0, 1.0])
    ll = 0.0
    for j in range(yk.shape[1]):
        for i in range(3):
            x = P = None
            for m, t in enumerate(frames):
                if restart[m]:
                    x = None
                y = yk[t, j, i]
                if x is not None:
                    A, Q = _discrete(float(steps[t]), q, sc2, tau, tau_c)
                    x, P = A @ x, A @ P @ A.T + Q
                if not np.isfinite(y):
                    continue
                rv = r * rscale[t, j]
                if x is None:
                    x, P = np.array([y, 0.0, 0.0]), _p0(rv, q, sc2, tau)
                    continue
                S = H @ P @ H + rv
                e = y - H @ x
                ll -= 0.5 * (math.log(2 * math.pi * S) + e * e / S)
                K = P @ H / S
                x, P = x + K * e, P - np.outer(K, H @ P)
    return ll


def _brute_smooth(y, rvar, steps, q, sc2, tau, tau_c):
    """Filter from frame 0 at the first sample (that sample updated too), then RTS (the
    gain with the pseudo-inverse of the prediction's covariance: without coloured error
    it is singular)."""
    T = y.shape[0]
    H = np.array([1.0, 0.0, 1.0])
    first = int(np.flatnonzero(np.isfinite(y))[0])
    x, P = np.array([y[first], 0.0, 0.0]), _p0(rvar[first], q[first], sc2, tau)
    xs, Ps, xp, Pp, As = [], [], [], [], []
    for t in range(T):
        A, Q = _discrete(float(steps[t]), float(q[t]), sc2, tau, tau_c)
        if t > 0:
            x, P = A @ x, A @ P @ A.T + Q
        xp.append(x)
        Pp.append(P)
        As.append(A)
        if np.isfinite(y[t]):
            S = H @ P @ H + rvar[t]
            K = P @ H / S
            x, P = x + K * (y[t] - H @ x), P - np.outer(K, H @ P)
        xs.append(x)
        Ps.append(P)
    est, var = np.empty(T), np.empty(T)
    est[-1], var[-1] = xs[-1][0], Ps[-1][0, 0]
    sx, sP = xs[-1], Ps[-1]
    for t in range(T - 2, -1, -1):
        G = Ps[t] @ As[t + 1].T @ np.linalg.pinv(Pp[t + 1])
        sx = xs[t] + G @ (sx - xp[t + 1])
        sP = Ps[t] + G @ (sP - Pp[t + 1]) @ G.T
        est[t], var[t] = sx[0], sP[0, 0]
    return est, var


def _irregular_steps(T: int, rng) -> np.ndarray:
    return 1 / 30 + rng.uniform(-0.004, 0.004, size=T)


def test_likelihood_equals_a_brute_force_kalman_likelihood():
    rng = np.random.default_rng(1)
    T, N = 44, 2
    steps = _irregular_steps(T, rng)
    yk = np.cumsum(rng.normal(scale=0.01, size=(T, N, 3)), axis=0)
    yk[rng.random((T, N)) < 0.15] = np.nan  # gaps
    yk[:5, 1] = np.nan  # a track that starts late
    rscale = np.where(rng.random((T, N)) < 0.2, 4.0, 1.0)
    frames, restart = fit_blocks(steps, np.inf)
    blocks = np.concatenate([np.arange(0, 20), np.arange(26, 44)])  # two blocks
    restart_b = np.zeros(blocks.size, dtype=bool)
    restart_b[[0, 20]] = True
    cases = ((3.0, 1e-4, 4e-5, 0.06), (0.5, 2e-4, 0.0, 0.1), (8.0, 1e-5, 1e-4, 0.15))
    for q, r, sc2, tau_c in cases:
        for fr, rs in ((frames, restart), (blocks, restart_b)):
            got, n = nk.loglik(yk, rscale, steps, fr, rs, q, r, sc2, TAU, tau_c)
            want = _brute_loglik(yk, rscale, steps, fr, rs, q, r, sc2, TAU, tau_c)
            assert abs(got - want) <= 1e-9 * max(1.0, abs(want)), (got, want)
            # three scalar samples per joint-frame after each track's first in a block
            assert n == 3 * (np.isfinite(yk[fr, :, 0]).sum() - (N if fr is frames else 2 * N))


def test_profile_likelihood_is_the_likelihood_at_the_closed_form_scale():
    rng = np.random.default_rng(2)
    T, N = 60, 2
    steps = _irregular_steps(T, rng)
    yk = np.cumsum(rng.normal(scale=0.01, size=(T, N, 3)), axis=0)
    rscale = np.ones((T, N))
    frames, restart = fit_blocks(steps, np.inf)
    ou = rk.ou_table(steps, TAU)
    th = np.array([np.log(40.0), 0.3, np.log(0.05)])
    se, _, n = nk.profile_sums(th, yk, rscale, steps, ou, frames, restart, TAU, TAU)
    m2 = se / n
    phi = 1 / (1 + np.exp(-th[1]))
    q = 2 * np.exp(th[0]) ** 2 / TAU * m2
    ll, _ = nk.loglik(yk, rscale, steps, frames, restart, q, (1 - phi) * m2, phi * m2, TAU,
                      np.exp(th[2]))  # fmt: skip
    f, g = nk.profile_nll_grad(th, th - 5, th + 5, yk, rscale, steps, ou, frames, restart, TAU,
                               TAU)  # fmt: skip
    assert f == pytest.approx(-ll / n, rel=1e-12)
    # the scale is the maximiser: the likelihood falls on either side
    for s in (0.9, 1.1):
        ls, _ = nk.loglik(yk, rscale, steps, frames, restart, q * s, (1 - phi) * m2 * s,
                          phi * m2 * s, TAU, np.exp(th[2]))  # fmt: skip
        assert ls < ll
    # the gradient by central differences of the function itself
    for i in range(3):
        e = np.zeros(3)
        e[i] = 1e-5
        fp = nk._profile_nll(th + e, yk, rscale, steps, ou, frames, restart, TAU, TAU)
        fm = nk._profile_nll(th - e, yk, rscale, steps, ou, frames, restart, TAU, TAU)
        assert g[i] == pytest.approx((fp - fm) / 2e-5, rel=1e-3, abs=1e-6)


def test_smoother_without_coloured_error_is_the_generic_kalman_core():
    # sc2 = 0: the two-state OU smoother (the fixed-noise `robust`), checked against the
    # package's generic Kalman filter + RTS smoother, joint by joint
    from tobitkf.core.kalman import kalman_filter, rts_smooth
    from tobitkf.core.model import LinearGaussian
    from tobitkf.smoothing.robust import _ou_matrices

    rng = np.random.default_rng(3)
    T, B, J = 90, 2, 4
    steps = _irregular_steps(T, rng)
    yk = np.cumsum(rng.normal(scale=0.01, size=(T, B, J, 3)), axis=0)
    yk[rng.random((T, B, J)) < 0.2] = np.nan
    yk[:7, 0, 1] = np.nan
    yk[:, 1, 2] = np.nan  # a joint without samples: NaN throughout
    rvar = np.where(rng.random((T, B, J)) < 0.3, 4e-4, 1e-4)
    qj = np.array([2.0, 5.0, 9.0, 1.0])
    q = np.ascontiguousarray(np.broadcast_to(qj, (T, B, J)))
    # written as a chunk (bodies 1..B) of larger outputs: the other bodies stay untouched
    v3, three = np.full((T, B + 2, J), -7.0), np.full((T, B + 2, J, 3), -7.0)
    smooth_run(yk, rvar, steps, q, np.zeros((B, J)), TAU, np.full((B, J), 0.1), three, v3, 1,
               None)  # fmt: skip
    assert (three[:, [0, B + 1]] == -7.0).all() and (v3[:, [0, B + 1]] == -7.0).all()
    A, Q = _ou_matrices(steps, TAU)
    for b in range(B):
        for j in range(J):
            ok = np.isfinite(yk[:, b, j, 0])
            if not ok.any():
                assert np.isnan(three[:, 1 + b, j]).all() and np.isnan(v3[:, 1 + b, j]).all()
                continue
            f = int(np.argmax(ok))  # frame 0 starts at the first sample, velocity 0
            Aj, Qj = A.copy(), qj[j] * Q
            Aj[0], Qj[0] = np.eye(2), 0.0
            model = LinearGaussian(
                A=A[1], H=np.array([[1.0, 0.0]]), Q=Qj[1], R=np.array([[1.0]]),
                x0=np.stack([yk[f, b, j], np.zeros(3)], axis=-1),
                P0=np.diag([rvar[f, b, j], qj[j] * TAU / 2]),
            )  # fmt: skip
            scale = np.broadcast_to(rvar[:, b, j, None, None], (T, 3, 1))
            res = kalman_filter(model, yk[:, b, j, :, None], A_seq=Aj, Q_seq=Qj, R_scale=scale)
            post = rts_smooth(model, res)
            np.testing.assert_allclose(three[:, 1 + b, j], post.means[..., 0], rtol=0, atol=1e-12)
            np.testing.assert_allclose(v3[:, 1 + b, j], post.variances[:, 0, 0], rtol=1e-9)


def test_smoother_equals_a_brute_force_rts_smoother():
    rng = np.random.default_rng(4)
    T = 60
    steps = _irregular_steps(T, rng)
    y = np.cumsum(rng.normal(scale=0.01, size=(T, 1, 1, 3)), axis=0)
    y[rng.random(T) < 0.2] = np.nan
    y[:3] = np.nan
    rvar = np.where(rng.random((T, 1, 1)) < 0.3, 9e-4, 1e-4)
    q = np.where(rng.random((T, 1, 1)) < 0.3, 13.0, 2.0)  # the floor in gaps: per step
    sc2, tau_c = 2e-4, 0.07
    var, est = np.empty((T, 1, 1)), np.empty((T, 1, 1, 3))
    smooth_run(y, rvar, steps, q, np.full((1, 1), sc2), TAU, np.full((1, 1), tau_c), est,
               var, 0, None)  # fmt: skip
    for i in range(3):
        want, wvar = _brute_smooth(y[:, 0, 0, i], rvar[:, 0, 0], steps, q[:, 0, 0], sc2, TAU,
                                   tau_c)  # fmt: skip
        np.testing.assert_allclose(est[:, 0, 0, i], want, rtol=0, atol=1e-11)
        np.testing.assert_allclose(var[:, 0, 0], wvar, rtol=1e-8, atol=1e-16)


def test_smoother_in_several_blocks_equals_the_brute_force_smoother_per_joint():
    # more joints than one block of SIMD lanes holds, the last block partly filled, each
    # joint with its own noise, gaps and coloured error: every joint as if smoothed alone
    rng = np.random.default_rng(6)
    T, B, J = 25, 3, nk.L // 2 + 3
    steps = _irregular_steps(T, rng)
    y = np.cumsum(rng.normal(scale=0.01, size=(T, B, J, 3)), axis=0)
    y[rng.random((T, B, J)) < 0.2] = np.nan
    y[:, 1, 2] = np.nan  # a joint without samples: no estimate
    rvar = rng.choice([1e-4, 9e-4], size=(T, B, J))
    q = rng.choice([2.0, 13.0], size=(T, B, J))
    sc2 = rng.choice([0.0, 2e-4], size=(B, J))
    tau_c = rng.choice([0.05, 0.3], size=(B, J))
    var, est = np.empty((T, B, J)), np.empty((T, B, J, 3))
    smooth_run(y, rvar, steps, q, sc2, TAU, tau_c, est, var, 0, None)
    assert np.isnan(est[:, 1, 2]).all() and np.isnan(var[:, 1, 2]).all()
    for b in range(B):
        for j in range(J):
            if (b, j) == (1, 2):
                continue
            for i in range(3):
                want, wvar = _brute_smooth(y[:, b, j, i], rvar[:, b, j], steps, q[:, b, j],
                                           sc2[b, j], TAU, tau_c[b, j])  # fmt: skip
                np.testing.assert_allclose(est[:, b, j, i], want, rtol=0, atol=1e-11)
                np.testing.assert_allclose(var[:, b, j], wvar, rtol=1e-8, atol=1e-16)


def test_smoother_of_a_constant_position_is_the_weighted_mean():
    # no motion noise, no coloured error: the prediction's covariance has rank one (the
    # position's variance), the singular branch of the RTS gain. The position is then a
    # constant seen through white noise: the estimate at every frame is the mean of the
    # samples, the first counted twice (it starts the filter and updates it), and its
    # variance r / (n + 1)
    rng = np.random.default_rng(7)
    T, r = 30, 4e-4
    y = rng.normal(scale=0.02, size=(T, 1, 1, 3)) + 1.0
    y[[0, 1, 7, 8, 20]] = np.nan
    var, est = np.empty((T, 1, 1)), np.empty((T, 1, 1, 3))
    smooth_run(y, np.full((T, 1, 1), r), np.full(T, 1 / 30), np.zeros((T, 1, 1)),
               np.zeros((1, 1)), TAU, np.full((1, 1), 0.1), est, var, 0, None)  # fmt: skip
    seen = y[np.isfinite(y[:, 0, 0, 0]), 0, 0]
    n = len(seen)
    want = (seen.sum(axis=0) + seen[0]) / (n + 1)
    np.testing.assert_allclose(est[:, 0, 0], np.broadcast_to(want, (T, 3)), rtol=0, atol=1e-12)
    np.testing.assert_allclose(var[:, 0, 0], r / (n + 1), rtol=1e-9)


def _simulate(rng, T, N, dt, spd, sd, esd, etau):
    """Tracks of the model itself: x, v integrated OU, c an OU error, white noise."""
    q = 2 * spd**2 / TAU
    A, Q = _discrete(dt, q, esd**2, TAU, etau)
    L = np.linalg.cholesky(Q + 1e-30 * np.eye(3))
    s = np.zeros((N, 3, 3))  # (track, axis, state)
    s[..., 1] = rng.normal(scale=spd, size=(N, 3))
    s[..., 2] = rng.normal(scale=esd, size=(N, 3))
    y = np.empty((T, N, 3))
    for t in range(T):
        if t:
            s = s @ A.T + rng.normal(size=s.shape) @ L.T
        y[t] = s[..., 0] + s[..., 2] + rng.normal(scale=sd, size=(N, 3))
    return y


def test_fit_recovers_known_noise_within_monte_carlo_error():
    # 16 replicates of 6 tracks x 600 frames (20 s at 30 fps) of the model itself. The
    # mean of each estimate is within 4 standard errors (sd over replicates / 4) of the
    # truth. The split of the measurement error into white and coloured parts is weakly
    # identified (their sd over replicates is large, and so is the standard error; a
    # coloured error as slow as the motion trades places with it), the speed is not:
    # each replicate within 10 % of it.
    # The optimiser reaches the likelihood of the truth (to within 1 log unit).
    truth = {"speed_sd": 0.4, "noise_sd": 0.004, "error_sd": 0.008, "error_tau": 0.05}
    R, T, N, dt = 16, 600, 6, 1 / 30
    rng = np.random.default_rng(5)
    steps = np.full(T, dt)
    frames, restart = fit_blocks(steps, np.inf)
    est = {k: [] for k in truth}
    q = 2 * truth["speed_sd"] ** 2 / TAU
    for _ in range(R):
        y = _simulate(rng, T, N, dt, *truth.values())
        f = fit_group(y, np.ones((T, N)), steps, frames, restart, tau=TAU, speed_sd=1.0,
                      noise_sd=0.01, v_max=8.0)  # fmt: skip
        ll_truth, _ = nk.loglik(y, np.ones((T, N)), steps, frames, restart, q,
                                truth["noise_sd"] ** 2, truth["error_sd"] ** 2, TAU,
                                truth["error_tau"])  # fmt: skip
        assert f.fitted and f.loglik > ll_truth - 1.0
        for k in truth:
            est[k].append(getattr(f, k))
    for k, v in truth.items():
        e = np.asarray(est[k])
        se = e.std(ddof=1) / math.sqrt(R)
        assert abs(e.mean() - v) < 4 * se, (k, e.mean(), se, v)
    assert np.all(np.abs(np.asarray(est["speed_sd"]) / truth["speed_sd"] - 1) < 0.1)


def test_white_noise_gives_no_coloured_error():
    rng = np.random.default_rng(6)
    T, N, dt = 600, 6, 1 / 30
    y = _simulate(rng, T, N, dt, 0.4, 0.006, 0.0, 0.05)
    steps = np.full(T, dt)
    frames, restart = fit_blocks(steps, np.inf)
    f = fit_group(y, np.ones((T, N)), steps, frames, restart, tau=TAU, speed_sd=1.0,
                  noise_sd=0.01, v_max=8.0)  # fmt: skip
    # the total measurement error is the white one; a coloured share, if any, is small
    assert math.hypot(f.noise_sd, f.error_sd) == pytest.approx(0.006, rel=0.15)
    assert f.error_sd < 0.5 * f.noise_sd


def test_fit_blocks_cover_the_budget_with_restarts():
    steps = np.full(3000, 1 / 30)  # 100 s
    frames, restart = fit_blocks(steps, 10.0)
    assert frames.size == 300 and restart.sum() == 5  # five blocks of 2 s
    assert np.all(np.diff(frames)[~restart[1:]] == 1)
    f_all, r_all = fit_blocks(steps, np.inf)
    assert f_all.size == 3000 and not r_all.any()


def _body(seed: int, sd: float) -> SkeletonSequence:
    rng = np.random.default_rng(seed)
    clean = tk.generate_motion("arms", duration=8.0, seed=seed)
    pos = clean.positions + rng.normal(scale=sd, size=clean.positions.shape)
    return SkeletonSequence(pos, clean.topology, fps=clean.fps)


def test_fitted_noise_is_recorded_per_body_in_the_provenance():
    quiet, noisy = _body(1, 0.002), _body(2, 0.02)
    outs = tk.smooth([quiet, noisy], "robust")  # one call, two bodies
    sds = []
    for out in outs:
        prov = out.metadata["provenance"]["params"]
        fit = out.metadata["diagnostics"]["noise_fit"]
        groups = out.topology.joint_groups()
        assert prov["noise"] == "fit"
        for g, idx in groups.items():
            for name in ("speed_sd", "noise_sd", "error_sd", "error_tau"):
                assert all(prov[name][i] == fit[g][name] for i in idx)
        sds.append(np.hypot(fit["torso"]["noise_sd"], fit["torso"]["error_sd"]))
    # each body its own: the measurement error found is the one added (per axis)
    assert sds[0] == pytest.approx(0.002, rel=0.3) and sds[1] == pytest.approx(0.02, rel=0.3)
    fixed = tk.smooth(quiet, "robust", noise="fixed").metadata["provenance"]["params"]
    assert "error_sd" not in fixed and fixed["noise"] == "fixed"


def test_fit_without_coloured_error_bound_is_the_fixed_smoother():
    # every region without usable samples keeps its defaults: the fitted mode then runs
    # the fixed model (error_sd = 0) and gives the fixed mode's numbers
    seq = _body(3, 0.005)
    short = seq.replace(positions=seq.positions[:2])
    a = tk.smooth(short, "robust", noise="fit")
    b = tk.smooth(short, "robust", noise="fixed")
    assert not any(v["fitted"] for v in a.metadata["diagnostics"]["noise_fit"].values())
    np.testing.assert_allclose(a.positions, b.positions, rtol=0, atol=1e-12)


def test_online_keeps_fixed_noise():
    seq = _body(4, 0.005)
    with pytest.raises(ValueError, match="noise"):
        tk.smooth(seq, "robust_online", noise="fit")
    out = tk.smooth(seq, "robust_online")
    assert out.metadata["provenance"]["params"]["noise"] == "fixed"


def test_fit_bodies_respects_bounds():
    rng = np.random.default_rng(7)
    T, J = 300, 2
    steps = np.full(T, 1 / 30)
    yk = np.repeat(rng.normal(size=(1, 1, J, 3)), T, axis=0) + rng.normal(
        scale=1e-3, size=(T, 1, J, 3)
    )  # a still joint: the speed wants to be 0
    out, rep = fit_noise_bodies(
        yk, np.ones((T, 1, J), dtype=bool), np.ones((T, 1, J)), steps, {"torso": [0, 1]},
        tau=TAU, speed_sd=np.full(J, 0.3), noise_sd=np.full(J, 0.007), v_max=np.full(J, 3.0),
        max_seconds=np.inf,
    )  # fmt: skip
    assert out["speed_sd"][0, 0] >= 0.003 - 1e-15
    assert out["error_tau"][0, 0] <= TAU + 1e-12
    assert rep[0]["torso"]["fitted"]


def test_evaluate_scores_a_method_with_other_parameters():
    from tobitkf.evaluation.scores import resolve_method

    seq = _body(5, 0.005)
    label, fn = resolve_method("robust[noise=fixed;tau=0.2;fit_seconds=inf]")
    assert label == "robust[noise=fixed;tau=0.2;fit_seconds=inf]"
    want = tk.smooth(seq, "robust", noise="fixed", tau=0.2, fit_seconds=np.inf)
    np.testing.assert_array_equal(fn(seq).positions, want.positions)
    with pytest.raises(ValueError, match="key=value"):
        resolve_method("robust[noise]")


@functools.cache
def _optimised_fits() -> tuple:
    """Every region fit of the fixtures, optimised by fit_group (the compiled minimiser)
    and again by scipy's L-BFGS-B, the optimiser before it, with the same objective,
    bounds, start and ftol, and by scipy with tight tolerances (the reference minimum):
    model replicates as in test_fit_recovers_known_noise_within_monte_carlo_error, white
    noise, and bodies of the built-in motions with added noise or the Kinect-like
    corruption (``tk.corrupt``). Per fit ``(kind, ours, scipy's, tight, objective args)``,
    each result ``(x, f)``."""
    calls = []
    real = _minimize.minimize_profile

    def spy(*a):
        out = real(*a)
        calls.append((a, out))
        return out

    _minimize.minimize_profile = spy
    try:
        T, N, dt = 600, 6, 1 / 30
        steps = np.full(T, dt)
        frames, restart = fit_blocks(steps, np.inf)
        rng = np.random.default_rng(5)
        kinds = []
        for esd in (0.008, 0.008, 0.008, 0.008, 0.008, 0.008, 0.0):
            y = _simulate(rng, T, N, dt, 0.4, 0.004, esd, 0.05)
            fit_group(y, np.ones((T, N)), steps, frames, restart, tau=TAU, speed_sd=1.0,
                      noise_sd=0.01, v_max=8.0)  # fmt: skip
            kinds.append("model")
        bodies = [_body(1, 0.002), _body(2, 0.02)]
        for seed, motion in ((8, "walk"), (9, "squat")):
            clean = tk.generate_motion(motion, duration=8.0, seed=seed)
            bodies.append(tk.corrupt(clean, seed=seed).sequence)
        for body in bodies:
            n = len(calls)
            tk.smooth(body, "robust")
            kinds += ["body"] * (len(calls) - n)
    finally:
        _minimize.minimize_profile = real
    out = []
    for kind, ((x0, lo, hi, *args, ftol, _), (x, f, _, _)) in zip(kinds, calls, strict=True):
        assert ftol == FIT_FTOL
        scipy = _scipy_fit(x0, lo, hi, args, ftol=FIT_FTOL)
        tight = _scipy_fit(x0, lo, hi, args, ftol=1e-14, gtol=1e-10, maxiter=1000)
        out.append((kind, (x, f), scipy, tight, (lo, hi, args)))
    return tuple(out)


def _scipy_fit(x0, lo, hi, args, **options) -> tuple:
    """``(x, f)`` of scipy's L-BFGS-B on the noise fit's objective, as fit_group ran it."""
    r = minimize(nk.profile_nll_grad, x0, args=(lo, hi, *args), jac=True, method="L-BFGS-B",
                 bounds=list(zip(lo, hi, strict=True)), options=options)  # fmt: skip
    return r.x, r.fun


def _gaps(fits) -> tuple[np.ndarray, np.ndarray]:
    """Per fit, how far above the lowest objective found (ours, scipy's, the tight run's)
    ours and scipy's end, relative to ``max(|f|, 1)`` as the stopping rule measures."""
    ours, scipy = [], []
    for _, (_, f), (_, fs), (_, ft), _ in fits:
        best = min(f, fs, ft)
        ours.append((f - best) / max(abs(best), 1.0))
        scipy.append((fs - best) / max(abs(best), 1.0))
    return np.asarray(ours), np.asarray(scipy)


def test_compiled_optimiser_ends_at_or_below_scipys_objective():
    # Each fit within the stopping rule's resolution of scipy's (both stop when an
    # iteration gains less than FIT_FTOL relative; in a flat valley that is far from the
    # minimum, and two scipy runs from starts 1e-9 apart differ by up to 5e-7), and on
    # average closer to the minimum than scipy's (the extra condition of its stopping rule).
    fits = _optimised_fits()
    assert len(fits) > 20
    for kind, (_, f), (_, fs), _, _ in fits:
        assert f <= fs + FIT_FTOL * max(abs(fs), 1.0), (kind, f, fs)
    ours, scipy = _gaps(fits)
    assert ours.mean() <= scipy.mean()


def test_compiled_optimiser_is_within_the_statistical_resolution_of_the_maximum():
    # the likelihood-ratio statistic between its result and the maximum, 2 n (f - f_max)
    # with n samples, is below the median of chi² with 3 degrees of freedom: the result is
    # inside the 50 % confidence region of the three parameters
    from scipy.stats import chi2

    for kind, (x, f), (_, fs), (_, ft), (lo, hi, args) in _optimised_fits():
        n = nk.profile_sums(np.clip(x, lo, hi), *args)[2]  # f is per sample
        assert 2 * n * (f - min(f, fs, ft)) <= chi2.ppf(0.5, 3), (kind, f, fs, ft, n)


def test_compiled_optimiser_finds_the_speed_and_total_error_of_the_maximum():
    # speed_sd and the total measurement error m (well identified, the module docstring)
    # at the lowest objective found: ours within 1 % of them, or at least as close as
    # scipy's (scipy's own, stopped early in a flat valley, can be further off)
    def speed_and_total(x, lo, hi, args):
        th = np.clip(x, lo, hi)
        se, _, n = nk.profile_sums(th, *args)
        m = math.sqrt(se / n)
        return np.array([math.exp(th[0]) * m, m])

    for kind, (x, f), (xs, fs), (xt, ft), (lo, hi, args) in _optimised_fits():
        best = (x, xs, xt)[int(np.argmin([f, fs, ft]))]
        want = speed_and_total(best, lo, hi, args)
        err = np.abs(speed_and_total(x, lo, hi, args) / want - 1)
        err_scipy = np.abs(speed_and_total(xs, lo, hi, args) / want - 1)
        assert np.all(err <= np.maximum(err_scipy, 0.01)), (kind, err, err_scipy)


@pytest.mark.parametrize("dims", [3, 2])
def test_the_fit_reads_tracked_samples_only(dims):
    # INFERRED samples are left out of the noise fit: the fit is the one of the same
    # recording with those samples missing (nothing is rejected in either)
    from tobitkf.evaluation.synthetic import generate_motion

    truth = generate_motion("arms", duration=4.0, seed=2)
    rng = np.random.default_rng(5)
    pos = truth.positions + rng.normal(scale=0.005, size=truth.positions.shape)
    pos = pos[..., :dims]
    states = np.full(pos.shape[:2], 2, dtype=np.int8)
    guessed = rng.random(states.shape) < 0.1
    states[guessed] = 1
    with_guesses = truth.replace(positions=pos, tracking_state=states)
    without = truth.replace(positions=np.where(guessed[..., None], np.nan, pos),
                            tracking_state=np.full_like(states, 2))  # fmt: skip
    a = tk.smooth(with_guesses, method="robust").metadata["diagnostics"]
    b = tk.smooth(without, method="robust").metadata["diagnostics"]
    assert not a["rejected"].any() and not b["rejected"].any()
    assert a["noise_fit"] == b["noise_fit"]
