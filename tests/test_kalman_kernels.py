"""The compiled Kalman kernel (smoothing/_kalman_kernels.py) against the numpy core.

``run_kalman`` (the kernel) must give the numbers of ``run_kalman_core`` (the core's
``kalman_filter`` / ``tobit_filter`` / ``adaptive_tobit_filter`` + ``rts_smooth``) on
random data with gaps, INFERRED samples, irregular time steps and censored samples, and
on the real recordings; its normal functions must match scipy's.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import special

import tobitkf as tk
from conftest import data_file
from test_censored import FAR_TWO_SIDED
from tobitkf.core.censored import clipped_normal_variance_diag, truncated_standard_normal
from tobitkf.smoothing import _kalman_kernels as k
from tobitkf.smoothing import paper
from tobitkf.smoothing.api import check_params
from tobitkf.smoothing.kalman_methods import run_kalman, run_kalman_core
from tobitkf.smoothing.registry import SmoothInput
from tobitkf.smoothing.timebase import frame_steps, frame_times, measurements

METHODS = {  # registered name: (kind, variant)
    "kf": ("kf", None),
    "tkf": ("tkf", "standard"),
    "tkfc": ("tkf", "corrected"),
    "atkf": ("atkf", None),
    "atkf2016": ("atkf", None),
}


def test_ndtr_and_log_ndtr_match_scipy() -> None:
    x = np.concatenate(
        [np.linspace(-60, 40, 4001), -np.logspace(0, 150, 300), [-np.inf, np.inf, 0.0]]
    )
    nd = np.array([k.ndtr(v) for v in x])
    # deep tails: libm and cephes erfc differ by a few ulp; below 1e-300 by subnormals
    np.testing.assert_allclose(nd, special.ndtr(x), rtol=1e-13, atol=1e-300)
    lnd = np.array([k.log_ndtr(v) for v in x])
    np.testing.assert_allclose(lnd, special.log_ndtr(x), rtol=1e-13, atol=1e-300)


def _random_moment_inputs(rng: np.random.Generator, n: int) -> tuple:
    m = rng.normal(scale=3.0, size=n)
    v = rng.uniform(0.01, 4.0, size=n)
    lo = rng.normal(scale=3.0, size=n)
    width = np.exp(rng.uniform(-12, 3, size=n))  # narrow intervals included
    up = lo + width
    lo[: n // 8] = -np.inf
    up[n // 8 : n // 4] = np.inf
    far = slice(n // 4, n // 4 + n // 8)  # whole interval 5 to 500 sd away
    m[far] = lo[far] - np.sqrt(v[far]) * np.exp(rng.uniform(np.log(5), np.log(500), n // 8))
    return m, v, lo, up


def test_truncated_and_clipped_moments_match_the_core() -> None:
    rng = np.random.default_rng(1)
    m, v, lo, up = _random_moment_inputs(rng, 4000)
    s = np.sqrt(v)
    ts = truncated_standard_normal((lo - m) / s, (up - m) / s)
    got = np.array([k.truncated((a - mm) / ss, (b - mm) / ss) for mm, ss, a, b in
                    zip(m, s, lo, up, strict=True)])  # fmt: skip
    # probabilities to 1e-11 relative; the standardised moments also to 1e-15 absolute
    # (narrow intervals hundreds of sd out cancel in both implementations)
    refs = (ts.p_lower, ts.p_uncensored, ts.p_upper, ts.mu_t, ts.v_t)
    for col, (ref, atol) in enumerate(zip(refs, (1e-30,) * 3 + (1e-15,) * 2, strict=True)):
        np.testing.assert_allclose(got[:, col], ref, rtol=1e-11, atol=atol)
    ref = clipped_normal_variance_diag(m, v, lo, up)
    got = np.array([k.clipped_diag(*a) for a in zip(m, v, lo, up, strict=True)])
    for col, atol in enumerate((1e-15, 1e-15, 1e-30, 1e-30, 1e-30)):
        np.testing.assert_allclose(got[:, col], ref[col], rtol=1e-11, atol=atol)


def _input(pos: np.ndarray, states, steps: np.ndarray, offline: bool) -> SmoothInput:
    topo = tk.get_topology("kinect_v2")
    ys, missing = measurements(pos, states)
    is_ref = bool(np.allclose(steps, paper.REFERENCE_DT, rtol=1e-9, atol=0.0))
    return SmoothInput(
        positions=pos, ys=ys, missing=missing, tracking_state=states, steps=steps,
        times=np.concatenate([[0.0], np.cumsum(steps[1:])]), is_reference=is_ref,
        topology=topo, up_axis=topo.up_axis, inferred_noise_factor=4.0, offline=offline,
    )  # fmt: skip


def _compare(inp: SmoothInput, name: str, atol: float = 1e-12, **params) -> int:
    kind, variant = METHODS[name]
    full = check_params(name, params)
    with warnings.catch_warnings(record=True) as w_got:
        warnings.simplefilter("always")
        got = run_kalman(inp, kind, variant, **full)
    with warnings.catch_warnings(record=True) as w_ref:
        warnings.simplefilter("always")
        ref = run_kalman_core(inp, kind, variant, **full)
    assert [str(w.message) for w in w_got] == [str(w.message) for w in w_ref]
    np.testing.assert_array_equal(np.isnan(got.positions), np.isnan(ref.positions))
    np.testing.assert_allclose(got.positions, ref.positions, rtol=0, atol=atol, equal_nan=True)
    np.testing.assert_allclose(got.std, ref.std, rtol=0, atol=atol, equal_nan=True)
    np.testing.assert_array_equal(got.clipped, ref.clipped)
    assert got.params == ref.params
    return int(np.count_nonzero(ref.clipped))


def _random_walks(rng: np.random.Generator, T: int, B: int, J: int) -> np.ndarray:
    pos = np.cumsum(rng.normal(scale=0.03, size=(T, B, J, 3)), axis=0)
    pos += np.array([0.0, 0.0, 2.0])
    pos += rng.normal(scale=0.05, size=pos.shape)
    jumps = rng.uniform(size=(T, B, J)) < 0.03
    pos[jumps] += rng.uniform(-1.0, 1.0, size=(int(jumps.sum()), 3))
    gaps = rng.uniform(size=(T, B, J)) < 0.05
    pos[gaps] = np.nan
    pos[:40, 0, 3] = np.nan  # a joint that starts late
    pos[50:90, 1, 2] = np.nan  # a long gap
    pos[:, 1, 4] = np.nan  # never seen
    return pos


@pytest.mark.parametrize("name", list(METHODS))
@pytest.mark.parametrize("offline", [False, True])
@pytest.mark.parametrize("regular", [True, False])
def test_kernel_equals_the_core_on_random_data(name: str, offline: bool, regular: bool) -> None:
    rng = np.random.default_rng(7)
    T, B, J = 150, 2, 6
    pos = _random_walks(rng, T, B, J)
    states = rng.choice(np.array([1, 2], dtype=np.int8), size=(T, B, J), p=[0.2, 0.8])
    steps = np.full(T, paper.REFERENCE_DT)
    if not regular:
        steps = rng.uniform(0.2, 2.0, size=T) * paper.REFERENCE_DT
    # limits the positions cross (censored samples) for the fixed-limit filters; joints
    # then sit up to 6 sd beyond a limit for tens of frames, where the update's gain is a
    # ratio of tail quantities (the safeguard of core/tobit.py) and the few-ulp
    # differences between libm's erfc (kernel) and cephes' (scipy) grow to ~1e-11 m
    # (with scipy's ndtr / log_ndtr put in the kernel: 9e-13)
    atol = 1e-12
    params: dict = {}
    if name in ("tkf", "tkfc"):
        lower, upper = (-0.3, -0.3, 1.8), (0.3, 0.3, 2.2)
        params = {"lower": lower, "upper": upper}
        atol = 5e-11
        # a sensor clipped at the limits reports the limits (censored samples); a fifth of
        # the samples stay beyond them (their limit is lifted: used as measured)
        clip = rng.uniform(size=pos.shape[:-1]) < 0.8
        pos[clip] = np.clip(pos[clip], lower, upper)
    clipped = _compare(_input(pos, states, steps, offline), name, atol, **params)
    if name != "kf":
        assert clipped > 50  # the censored update was exercised
    _compare(_input(pos, None, steps, offline), name, atol, **params)


def test_kernel_equals_the_core_with_gaps_on_the_reference_clock() -> None:
    """ATKF on a 30 fps clock: c stays unscaled without gaps, is scaled for every joint
    as soon as one has a gap (including one that ends the recording)."""
    rng = np.random.default_rng(3)
    T = 80
    # within the 1e-9 of a 30 fps clock, but c scaled by these steps would differ from c
    steps = np.full(T, paper.REFERENCE_DT * (1.0 + 5e-10))
    pos = _random_walks(rng, T, 2, 6)
    pos[:] = np.where(np.isnan(pos), 0.1, pos)  # no gaps
    _compare(_input(pos, None, steps, False), "atkf")
    pos[70:, 0, 1] = np.nan  # a gap at the end only
    _compare(_input(pos, None, steps, False), "atkf")


@pytest.mark.parametrize(
    "relative", ["kimore/JointPositionExercise1.csv", "keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt"]
)
def test_kernel_equals_the_core_on_real_recordings(relative: str) -> None:
    seq = tk.load(data_file(relative))[0]
    steps, _, _ = frame_steps(seq)
    pos = seq.positions[:, None]
    states = None if seq.tracking_state is None else seq.tracking_state[:, None]
    assert frame_times(seq, steps).shape == steps.shape
    for name in METHODS:
        for offline in (False, True):
            _compare(_input(pos, states, steps, offline), name)
    # a sensor with a narrower range: the recording clipped at its limits (censored). The
    # estimates then run up to 3 sd beyond a limit, where the gain is ill-conditioned:
    # ulp-level differences (libm's exp / log / erfc against numpy's and cephes') grow to
    # 1.1e-10 m with tkf on KERAAL (3e-14 with tkfc)
    lower, upper = (-0.2, -0.5, 1.0), (0.2, 0.5, 3.0)
    clipped = np.clip(pos, lower, upper)
    for name in ("tkf", "tkfc"):
        inp = _input(clipped, states, steps, False)
        assert _compare(inp, name, 5e-10, lower=lower, upper=upper) > 0


@pytest.mark.parametrize(("a", "b", "mu", "v"), FAR_TWO_SIDED)
def test_truncated_far_two_sided_interval_high_precision(a, b, mu, v) -> None:
    # the exact values of tests/test_censored.py (120-digit decimal arithmetic)
    _, _, _, mu_t, v_t, _, _ = k.truncated(a, b)
    assert abs(mu_t - mu) <= 1e-15 * abs(mu)
    assert abs(v_t / v - 1) <= 1e-13


@pytest.mark.parametrize("kind", ["inside", "below", "above"])
@pytest.mark.parametrize("z", [2e154, 1e200, 1e300])
@pytest.mark.parametrize("m", [-3.0, 0.0, 0.7])
def test_limits_beyond_1e154_sd_give_the_exact_limits(kind: str, z: float, m: float) -> None:
    # z² overflows: the uncensored moments (limits outside), or the point mass at the nearer
    # limit (interval beyond the mean) -- they were NaN
    s = 1e-145
    d = z * s
    lo, up = {"inside": (m - d, m + d), "below": (-np.inf, m - d), "above": (m + d, m + 2 * d)}[
        kind
    ]
    mean, var, p_lo, p_un, p_up = k.clipped_diag(m, s * s, lo, up)
    if kind == "inside":
        assert (p_lo, p_un, p_up) == (0.0, 1.0, 0.0) and mean == m and var == s * s
        assert k.truncated((lo - m) / s, (up - m) / s)[3:5] == (0.0, 1.0)
    else:
        edge = up if kind == "below" else lo
        assert (p_lo, p_up) == ((0.0, 1.0) if kind == "below" else (1.0, 0.0)) and p_un == 0.0
        assert abs(mean - edge) <= 4e-16 * d and var == 0.0


@pytest.mark.parametrize("name", ["tkf", "tkfc"])
def test_subnormal_noise_gives_finite_estimates_equal_to_the_core(name: str) -> None:
    # r = q = 1e-320: the standardised limits are ~1e158 (tkf^c: NaN before) and the
    # safeguard ε S underflows to 0 where a joint is certainly censored (0/0 before)
    rng = np.random.default_rng(5)
    T, B, J = 100, 2, 6
    pos = _random_walks(rng, T, B, J)
    lower, upper = (-0.3, -0.3, 1.8), (0.3, 0.3, 2.2)
    pos = np.clip(pos, lower, upper)
    # a joint first seen 0.2 m beyond the upper x limit (used as measured), then reported
    # at that limit: certainly censored (P_un = 0), so the estimate stays where it was
    pos[:, 0, 0, 1:] = (0.0, 2.0)
    pos[:, 0, 0, 0] = 0.3
    pos[0, 0, 0, 0] = 0.5
    steps = np.full(T, paper.REFERENCE_DT)
    inp = _input(pos, None, steps, False)
    kind, variant = METHODS[name]
    full = check_params(name, {"lower": lower, "upper": upper, "r": (1e-320,) * 3,
                               "q": (1e-320,) * 3})  # fmt: skip
    got = run_kalman(inp, kind, variant, **full)
    seen = ~np.isnan(pos[..., 0])
    assert np.all(np.isfinite(got.positions[seen]))
    np.testing.assert_array_equal(got.positions[:, 0, 0, 0], 0.5)
    _compare(inp, name, 1e-12, **{k_: full[k_] for k_ in ("lower", "upper", "r", "q")})
