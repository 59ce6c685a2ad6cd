"""Tests of tobitkf.smooth: method registry, time-step scaling, tracking states, diagnostics."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import data_file
from tobitkf.skeleton.sequence import SkeletonSequence, TrackingState
from tobitkf.skeleton.topology import Topology
from tobitkf.smoothing.api import (
    check_params,
    method_defaults,
    methods,
    smooth,
)

METHODS = methods()
ALL_METHODS = sorted(METHODS)


def _seq(pos, up_axis=1, **kw):
    names = [f"j{i}" for i in range(pos.shape[1])]
    return SkeletonSequence(
        np.asarray(pos, float), Topology.from_names(names, up_axis=up_axis), **kw
    )


def _still(T=300, J=3, sigma=0.01, seed=0):
    """Still joints at (0.2, 0.5, 2.5) m (inside the Kinect device limits) plus noise."""
    rng = np.random.default_rng(seed)
    truth = np.array([0.2, 0.5, 2.5])
    return truth, truth + rng.normal(scale=sigma, size=(T, J, 3))


def _scalar_kf_ref(y, q_steps, r, r_mult):
    T = len(y)
    out = np.full(T, np.nan)
    finite = np.flatnonzero(np.isfinite(y))
    x, P = float(y[finite[0]]), float(r)
    for k in range(T):
        P = P + q_steps[k]
        if np.isfinite(y[k]):
            K = P / (P + r * r_mult[k])
            x = x + K * (y[k] - x)
            P = (1 - K) * P
        if k >= finite[0]:
            out[k] = x
    return out


# --------------------------------------------------------------------------- registry


def test_registry_names_and_defaults():
    expected = {
        "atkf",
        "atkf2016",
        "tkf",
        "tkfc",
        "kf",
        "sgf",
        "savgol",
        "one_euro",
        "kinect",
        "moving_average",
        "robust",
        "robust_online",
    }
    assert set(METHODS) == expected
    d = method_defaults("atkf")
    assert (d["q"], d["r"], d["c_horizontal"], d["c_vertical"]) == (0.0025, 0.01, 0.34, 0.18)
    d = method_defaults("atkf2016")
    assert (d["q"], d["c_horizontal"], d["c_vertical"]) == (0.001, 0.31, 0.18)
    assert method_defaults("tkf")["lower"] == (-3.0, -1.5, 0.5)
    assert method_defaults("tkfc")["upper"] == (3.0, 3.0, 5.0)
    # every method's defaults smooth a small sequence; the diagnostics name the method
    # and hold the full parameter set
    truth, pos = _still(T=40, J=3)
    seq = _seq(pos, fps=30.0)
    for name in METHODS:
        out = smooth(seq, name)
        assert out.positions.shape == pos.shape
        assert np.isfinite(out.positions).all(), name
        # a still joint stays near where it is (no method diverges on its defaults)
        assert np.abs(out.positions[10:] - truth).max() < 0.05, name
        diag = out.metadata["diagnostics"]
        assert diag["method"] == name
        defaults = method_defaults(name)
        assert set(defaults) <= set(diag["params"]), name
        for key, value in defaults.items():
            if value is not None and not isinstance(value, dict):
                assert diag["params"][key] == value, (name, key)
        # the defaults given explicitly pass the validators unchanged
        explicit = smooth(seq, name, **defaults)
        np.testing.assert_array_equal(explicit.positions, out.positions)


def test_unknown_parameter_lists_valid_ones():
    with pytest.raises(ValueError, match=r"unknown parameter 'window'.*valid parameters: c, "):
        check_params("atkf", {"window": 3})
    with pytest.raises(ValueError, match="valid methods"):
        check_params("nope", {})
    with pytest.raises(ValueError, match="unknown parameter"):
        smooth(_seq(np.zeros((5, 1, 3))), "sgf", beta=1.0)


@pytest.mark.parametrize(
    ("method", "params", "match"),
    [
        ("atkf", {"q": -1.0}, "q must be positive"),
        ("atkf", {"c": (0.1, 0.2)}, "3 numbers"),
        ("kf", {"r": "big"}, "r must"),
        ("tkf", {"lower": (0, 0, 0), "upper": (1, -1, 1)}, "below upper"),
        ("sgf", {"window": 4}, "odd"),
        ("sgf", {"window": 5, "polyorder": 5}, "polyorder"),
        ("savgol", {"window": 5, "polyorder": 5}, "polyorder"),
        ("moving_average", {"window": 0}, "integer >= 1"),
        ("kinect", {"preset": "fast"}, "preset"),
        ("kinect", {"smoothing": 2.0}, r"\[0, 1\]"),
        ("one_euro", {"mincutoff": 0}, "mincutoff"),
        ("moving_average", {"window": 4}, "odd"),
        ("atkf", {"up_axis": 3}, "up_axis"),
        ("atkf", {"inferred_noise_factor": 0.5}, ">= 1"),
    ],
)
def test_bad_values_are_rejected(method, params, match):
    with pytest.raises(ValueError, match=match):
        check_params(method, params)


def test_check_params_fills_defaults():
    out = check_params("atkf", {"q": 0.01, "up_axis": 2})
    assert out["q"] == 0.01 and out["r"] == 0.01 and "up_axis" not in out
    assert check_params("moving_average", {"window": 4, "centered": False})["window"] == 4


# --------------------------------------------------------------------------- behaviour


@pytest.mark.parametrize("method", ALL_METHODS)
def test_still_joint_stays_still(method):
    truth, pos = _still()
    out = smooth(_seq(pos, fps=30.0), method).positions
    assert np.isfinite(out).all()
    T = pos.shape[0]
    # the mean over time is unbiased: within 4 standard errors (sigma / sqrt(T)) of truth,
    # allowing for the correlation a smoother introduces (factor 3 on the standard error)
    se = 0.01 / np.sqrt(T)
    np.testing.assert_allclose(out[30:].mean(axis=0), np.broadcast_to(truth, (3, 3)), atol=12 * se)
    # and no method adds jitter
    assert out.std(axis=0).max() <= 0.0105


def test_kf_matches_independent_scalar_filter_with_irregular_steps_and_inferred():
    rng = np.random.default_rng(1)
    T = 60
    dt = rng.uniform(0.02, 0.09, size=T - 1)
    t = np.concatenate([[0.0], np.cumsum(dt)])
    pos = 1.0 + np.cumsum(rng.normal(scale=0.02, size=(T, 2, 3)), axis=0)
    pos[10:13, 0] = np.nan
    states = np.full((T, 2), TrackingState.TRACKED)
    states[20:40, 1] = TrackingState.INFERRED
    states[45, 1] = TrackingState.NOT_TRACKED
    seq = _seq(pos, timestamps=t, tracking_state=states)
    out = smooth(seq, "kf", q=0.003, r=0.02, inferred_noise_factor=5.0).positions
    nominal = np.median(dt)
    steps = np.concatenate([[nominal], dt])
    q_steps = 0.003 * steps / (1 / 30)
    for j in range(2):
        y = pos[:, j].copy()
        if j == 1:
            y[45] = np.nan  # not tracked: predicted, not updated
        mult = np.where(states[:, j] == TrackingState.INFERRED, 5.0, 1.0)
        for d in range(3):
            ref = _scalar_kf_ref(y[:, d], q_steps, 0.02, mult)
            np.testing.assert_allclose(out[:, j, d], ref, rtol=1e-9, atol=1e-12)


def test_inferred_joints_are_trusted_less():
    T = 40
    pos = np.zeros((T, 2, 3)) + np.array([0.0, 0.5, 2.0])
    pos[20:, :, 0] += 0.1  # a 10 cm step in x for both joints
    states = np.full((T, 2), TrackingState.TRACKED)
    states[:, 1] = TrackingState.INFERRED
    out = smooth(_seq(pos, tracking_state=states, fps=30.0), "kf").positions
    move_tracked = out[20, 0, 0] - out[19, 0, 0]
    move_inferred = out[20, 1, 0] - out[19, 1, 0]
    assert 0 < move_inferred < 0.75 * move_tracked
    # factor 1 treats them alike
    same = smooth(_seq(pos, tracking_state=states, fps=30.0), "kf", inferred_noise_factor=1.0)
    np.testing.assert_allclose(same.positions[:, 0], same.positions[:, 1])


def test_nan_and_not_tracked_frames_are_filled_by_prediction():
    _, pos = _still(T=80, J=2)
    pos[:5, 0] = np.nan  # before the first measurement: stays NaN
    pos[30:40, 0] = np.nan
    states = np.full((80, 2), TrackingState.TRACKED)
    states[50:55, 1] = TrackingState.NOT_TRACKED
    pos[50:55, 1] = 9.0  # garbage reported for not-tracked joints must be ignored
    res = smooth(_seq(pos, tracking_state=states, fps=30.0), "kf")
    out = res.positions
    assert np.isnan(out[:5, 0]).all()
    assert np.isfinite(out[5:]).all()
    # a random walk predicts by holding the last estimate
    np.testing.assert_array_equal(out[30:40, 0], np.broadcast_to(out[29, 0], (10, 3)))
    np.testing.assert_array_equal(out[50:55, 1], np.broadcast_to(out[49, 1], (5, 3)))
    np.testing.assert_allclose(res.metadata["diagnostics"]["filled_fraction"], [10 / 80, 5 / 80])


@pytest.mark.parametrize("method", ALL_METHODS)
def test_no_nan_where_input_is_finite_and_metadata_kept(method):
    rng = np.random.default_rng(2)
    pos = np.array([0.1, 0.4, 2.2]) + np.cumsum(rng.normal(scale=0.01, size=(50, 4, 3)), axis=0)
    pos[7, 2] = np.nan
    seq = _seq(pos, fps=30.0, body_id=7, metadata={"source": "x"})
    res = smooth(seq, method)
    assert np.isfinite(res.positions[np.isfinite(pos).all(axis=-1)]).all()
    assert res.body_id == 7 and res.metadata["source"] == "x" and res.fps == 30.0
    assert "diagnostics" not in seq.metadata  # input untouched
    diag = res.metadata["diagnostics"]
    assert diag["method"] == method
    assert diag["clipped_fraction"].shape == (4,) and diag["filled_fraction"].shape == (4,)
    assert set(method_defaults(method)) <= set(diag["params"])


def test_offline_differs_and_is_smoother():
    rng = np.random.default_rng(3)
    T = 200
    t = np.arange(T) / 30
    truth = np.stack([0.3 * np.sin(t), 0.5 + 0.1 * np.cos(2 * t), 2.5 + 0 * t], axis=-1)
    pos = truth[:, None, :] + rng.normal(scale=0.01, size=(T, 2, 3))
    seq = _seq(pos, fps=30.0)
    on = smooth(seq, "kf").positions
    off = smooth(seq, "kf", offline=True).positions
    assert not np.allclose(on, off)

    def roughness(x):
        return np.sum(np.diff(x, n=2, axis=0) ** 2)

    assert roughness(off) < 0.5 * roughness(on)
    # and closer to the truth (the smoother uses future frames)
    err = lambda x: np.sqrt(np.mean((x - truth[:, None, :]) ** 2))  # noqa: E731
    assert err(off) < err(on)


def test_list_of_bodies_matches_one_by_one():
    _, a = _still(T=40, J=2, seed=4)
    _, b = _still(T=40, J=2, seed=5)
    _, c = _still(T=30, J=2, seed=6)
    seqs = [_seq(a, fps=30.0), _seq(b, fps=30.0), _seq(c, fps=60.0)]
    out = smooth(seqs, "kf", offline=True)
    assert isinstance(out, list) and len(out) == 3
    for s, o in zip(seqs, out, strict=True):
        np.testing.assert_allclose(o.positions, smooth(s, "kf", offline=True).positions)
    with pytest.raises(TypeError, match="item 1"):
        smooth([seqs[0], "x"], "kf")


def test_fps_other_than_30_scales_q():
    # at 60 fps a random walk has half the per-step variance: the scalar reference with
    # q/2 must match
    rng = np.random.default_rng(8)
    pos = 1.0 + np.cumsum(rng.normal(scale=0.01, size=(40, 1, 3)), axis=0)
    out = smooth(_seq(pos, fps=60.0), "kf").positions
    q_steps = np.full(40, 0.0025 / 2)
    ref = _scalar_kf_ref(pos[:, 0, 1], q_steps, 0.01, np.ones(40))
    np.testing.assert_allclose(out[:, 0, 1], ref, rtol=1e-9)


# --------------------------------------------------------------------------- Tobit methods


def test_atkf_reduces_a_one_frame_spike():
    truth, pos = _still(T=60, J=2, sigma=0.005)
    pos[30, 0, 0] += 0.5  # horizontal
    pos[30, 1, 1] += 0.5  # vertical
    res = smooth(_seq(pos, fps=30.0), "atkf")
    out = res.positions
    kf = smooth(_seq(pos, fps=30.0), "kf").positions
    dev_atkf = np.abs(out[30, 0, 0] - truth[0]), np.abs(out[30, 1, 1] - truth[1])
    dev_kf = np.abs(kf[30, 0, 0] - truth[0]), np.abs(kf[30, 1, 1] - truth[1])
    # raw deviation 0.5 m. The plain KF (gain ~0.39 at steady state) follows ~0.2 m; ATKF
    # clips the measurement to the prior +- c (0.34 m horizontal, 0.18 m vertical) first,
    # so it follows at most about gain * c (~0.13 m and ~0.07 m)
    for a, k, c in zip(dev_atkf, dev_kf, (0.34, 0.18), strict=True):
        assert a < 0.3 * 0.5
        assert a < 0.75 * k
        assert a < 0.5 * c
    diag = res.metadata["diagnostics"]
    assert diag["clipped_fraction"][0] >= 1 / 60 and diag["clipped_fraction"][1] >= 1 / 60
    assert diag["params"]["c"] == pytest.approx((0.34, 0.18, 0.34))


def test_atkf_vertical_limit_follows_the_up_axis():
    _, pos = _still(T=40, J=1, sigma=0.002)
    pos[20:, 0, 2] += 0.25  # a real 25 cm step on z
    z_up = smooth(_seq(pos, up_axis=2, fps=30.0), "atkf")
    y_up = smooth(_seq(pos, up_axis=1, fps=30.0), "atkf")
    assert z_up.metadata["diagnostics"]["params"]["c"] == pytest.approx((0.34, 0.34, 0.18))
    # 0.25 > 0.18: clipped when z is up, not when z is horizontal
    assert z_up.metadata["diagnostics"]["clipped_fraction"][0] > 0
    assert y_up.metadata["diagnostics"]["clipped_fraction"][0] == 0
    over = smooth(_seq(pos, up_axis=1, fps=30.0), "atkf", up_axis=2)
    np.testing.assert_allclose(over.positions, z_up.positions)


def test_atkf_limits_widen_after_a_gap():
    from tobitkf.core.model import LinearGaussian
    from tobitkf.core.tobit import adaptive_tobit_filter

    _, pos = _still(T=60, J=1, sigma=0.003)
    pos[20:50] = np.nan  # one second unobserved ...
    pos[50:, 0, 0] += 0.6  # ... during which the joint moved 0.6 m (> c = 0.34)
    out = smooth(_seq(pos, fps=30.0), "atkf").positions
    # reference: the filter with c_seq = c * (time since the last measurement) / (1/30)
    c = np.array([0.34, 0.18, 0.34])
    n = np.ones(60)
    n[50] = 31.0  # frame 50 comes 31 frames after frame 19
    c_seq = (c[None, :] * n[:, None])[:, None, :]
    R = 0.01 * np.eye(3)
    model = LinearGaussian(A=np.eye(3), H=np.eye(3), Q=0.0025 * np.eye(3), R=R, x0=pos[0], P0=R)
    ref = adaptive_tobit_filter(model, pos, None, c_seq=c_seq).means
    np.testing.assert_allclose(out, ref, rtol=1e-9, atol=1e-12)
    # the reappearing joint is not censored: after a 1 s gap the predicted variance is
    # large and the filter jumps most of the way at once
    assert out[50, 0, 0] - out[49, 0, 0] > 0.4


def test_atkf_irregular_steps_match_explicit_q_seq_and_c_seq():
    from tobitkf.core.model import LinearGaussian
    from tobitkf.core.tobit import adaptive_tobit_filter

    rng = np.random.default_rng(9)
    T = 50
    dt = rng.choice([1 / 30, 2 / 30, 1 / 15.0, 0.05], size=T - 1)
    t = np.concatenate([[0.0], np.cumsum(dt)])
    pos = np.array([0.2, 0.4, 2.0]) + np.cumsum(rng.normal(scale=0.03, size=(T, 3, 3)), axis=0)
    pos[25, 1] += 0.4
    got = smooth(_seq(pos, timestamps=t), "atkf").positions
    nominal = np.median(dt)
    steps = np.concatenate([[nominal], dt])
    Q_seq = np.stack([0.0025 * np.eye(3) * (s * 30.0) for s in steps])
    c_seq = np.stack([np.array([0.34, 0.18, 0.34]) * (s * 30.0) for s in steps])[:, None, :]
    model = LinearGaussian(
        A=np.eye(3),
        H=np.eye(3),
        Q=0.0025 * np.eye(3),
        R=0.01 * np.eye(3),
        x0=pos[0],
        P0=0.01 * np.eye(3),
    )
    ref = adaptive_tobit_filter(model, pos, None, Q_seq=Q_seq, c_seq=c_seq).means
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12)


def test_tkf_device_limits_clip_far_measurements():
    _, pos = _still(T=40, J=1, sigma=0.005)
    pos[:, 0, 2] = 5.0 + 0.3  # beyond the 5 m depth limit: the sensor would report 5.0
    pos[:, 0, 2] = np.minimum(pos[:, 0, 2], 5.0)
    res = smooth(_seq(pos, fps=30.0), "tkfc")
    assert res.metadata["diagnostics"]["clipped_fraction"][0] > 0.9
    # Tobit estimates move beyond the limit; the plain KF cannot
    kf = smooth(_seq(pos, fps=30.0), "kf").positions
    assert res.positions[-1, 0, 2] > kf[-1, 0, 2]


# --------------------------------------------------------------------------- real data


KINECT_FILES = [
    "kimore/JointPositionExercise1.csv",
    "kimore/JointPositionExercise3.csv",
    "kimore/JointPositionExercise5.csv",
    "keraal/G3-Kinect-CTK-P1T1-Unknown-C-0.txt",
    "keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt",
    "keraal/G3-Kinect-RTK-P1T1-Unknown-C-0.txt",
    "krajjat/sequence_ainhoa_trimmed.tsv",  # irregular timestamps, ~16.7 Hz
]


def _load_kinect(rel: str) -> SkeletonSequence:
    """Through tobitkf.io when available, else a minimal parser of the two formats."""
    path = data_file(rel)
    try:
        from tobitkf.io import load

        return load(path)[0]
    except ImportError:
        if not rel.startswith(("kimore", "keraal")):
            pytest.skip("tobitkf.io not available")
    lines = [ln.strip().rstrip(",") for ln in path.read_text().splitlines() if ln.strip()]
    if rel.startswith("kimore"):
        data = np.array([ln.split(",") for ln in lines], dtype=float).reshape(len(lines), 25, 4)
        pos, states = data[..., :3], data[..., 3].astype(np.int8)
    else:
        data = np.array([ln.split() for ln in lines], dtype=float).reshape(len(lines), 25, 7)
        pos, states = data[..., :3], None
    return SkeletonSequence(pos, "kinect_v2", tracking_state=states, fps=30.0)


_SEQ_CACHE: dict[str, SkeletonSequence] = {}


def _cached(rel: str) -> SkeletonSequence:
    if rel not in _SEQ_CACHE:
        _SEQ_CACHE[rel] = _load_kinect(rel)
    return _SEQ_CACHE[rel]


@pytest.mark.parametrize("method", ALL_METHODS)
@pytest.mark.parametrize("rel", KINECT_FILES)
def test_every_method_on_real_kinect_files(rel, method):
    seq = _cached(rel)
    finite = np.isfinite(seq.positions).all(axis=-1)
    out = smooth(seq, method).positions
    assert out.shape == seq.positions.shape
    assert np.isfinite(out[finite]).all()


@pytest.mark.parametrize(
    ("rel", "hands"),
    [
        ("kimore/JointPositionExercise3.csv", ["HandLeft", "HandRight", "WristLeft"]),
        ("keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt", ["HandRight", "HandTipRight"]),
        ("keraal/G3-Kinect-RTK-P1T1-Unknown-C-0.txt", ["HandLeft", "WristLeft"]),
    ],
)
def test_atkf_removes_real_jumps(rel, hands):
    seq = _load_kinect(rel)
    out = smooth(seq, "atkf")
    idx = seq.topology.indices(hands)
    raw_jump = np.nanmax(np.linalg.norm(np.diff(seq.positions[:, idx], axis=0), axis=-1))
    new_jump = np.nanmax(np.linalg.norm(np.diff(out.positions[:, idx], axis=0), axis=-1))
    assert raw_jump > 0.2
    assert new_jump < 0.5 * raw_jump


def test_atkf_keeps_a_still_joint_still_on_kimore():
    seq = _load_kinect("kimore/JointPositionExercise1.csv")
    out = smooth(seq, "atkf")
    for name in ("SpineBase", "FootLeft"):
        j = seq.topology.index(name)
        raw_mean = np.nanmean(seq.positions[:, j], axis=0)
        new_mean = np.nanmean(out.positions[:, j], axis=0)
        assert np.max(np.abs(new_mean - raw_mean)) < 0.005


@settings(deadline=None, max_examples=40)
@given(
    method=st.sampled_from(ALL_METHODS),
    T=st.integers(1, 25),
    J=st.integers(1, 3),
    seed=st.integers(0, 10_000),
    nan_rate=st.sampled_from([0.0, 0.2, 0.6]),
    with_states=st.booleans(),
    timing=st.sampled_from(["none", "fps", "timestamps", "duplicated"]),
    offline=st.booleans(),
)
def test_fuzz_any_method_finite_where_observed(
    method, T, J, seed, nan_rate, with_states, timing, offline
):
    rng = np.random.default_rng(seed)
    pos = np.array([0.2, 0.5, 2.5]) + np.cumsum(rng.normal(scale=0.05, size=(T, J, 3)), axis=0)
    pos[rng.random((T, J)) < nan_rate] = np.nan
    kw: dict = {}
    if with_states:
        kw["tracking_state"] = rng.choice([0, 1, 2], size=(T, J))
    if timing == "fps":
        kw["fps"] = float(rng.choice([15.0, 30.0, 60.0, 120.0]))
    elif timing in ("timestamps", "duplicated"):
        steps = rng.uniform(0.01, 0.1, size=T)
        if timing == "duplicated":
            steps[rng.random(T) < 0.3] = 0.0
        kw["timestamps"] = np.cumsum(steps)
    seq = _seq(pos, **kw)
    offline = offline and METHODS[method].offline_ok  # others refuse it (tested below)
    res = smooth(seq, method, offline=offline)
    out = res.positions
    assert out.shape == pos.shape
    observed = np.isfinite(pos).all(axis=-1)
    if with_states:
        observed &= kw["tracking_state"] != TrackingState.NOT_TRACKED
    assert np.isfinite(out[observed]).all()
    diag = res.metadata["diagnostics"]
    for key in ("clipped_fraction", "filled_fraction"):
        assert diag[key].shape == (J,)
        assert np.all((diag[key] >= 0) & (diag[key] <= 1))


def test_atkf_keeps_still_feet_still_on_keraal():
    # CTK ("hiding face"): the feet stand still; raw jitter is a few millimetres
    seq = _load_kinect("keraal/G3-Kinect-CTK-P1T1-Unknown-C-0.txt")
    out = smooth(seq, "atkf")
    for name in ("AnkleLeft", "AnkleRight", "FootLeft"):
        j = seq.topology.index(name)
        raw = seq.positions[:, j]
        raw_mean = raw.mean(axis=0)
        new = out.positions[:, j]
        assert np.max(np.abs(new.mean(axis=0) - raw_mean)) < 0.001
        assert np.max(np.abs(new - raw_mean)) < 0.015  # every frame within 1.5 cm
        # no added jitter (the ankles drift slowly, so a lagging filter may not reduce it)
        assert np.all(new.std(axis=0) <= 1.1 * raw.std(axis=0))


@pytest.mark.parametrize("method", ["sgf", "one_euro", "kinect", "robust", "robust_online"])
def test_offline_is_refused_where_there_is_no_rts_pass(method):
    seq = _seq(np.zeros((10, 2, 3)))
    with pytest.raises(ValueError, match=f"offline=True.*{method!r} does not have"):
        smooth(seq, method, offline=True)


def test_the_defaults_are_the_robust_pair():
    import tobitkf as tk

    seq = tk.generate_motion("arms", duration=1.0, seed=0)
    assert (tk.DEFAULT_METHOD, tk.DEFAULT_LIVE_METHOD) == ("robust", "robust_online")
    assert tk.smooth(seq).metadata["diagnostics"]["method"] == "robust"
    assert tk.LiveSmoother(seq.topology).method == "robust_online"
    assert tk.methods()[tk.DEFAULT_LIVE_METHOD].is_causal()


def test_elapsed_since_valid_is_the_frame_step_unless_after_a_gap():
    # independent reference: walk each joint's frames, remembering its last valid time
    from tobitkf.smoothing.timebase import elapsed_since_valid

    rng = np.random.default_rng(6)
    T = 50
    steps = np.full(T, 1 / 30.0)
    steps[1:] += rng.uniform(0, 0.01, T - 1)
    valid = rng.random((T, 4, 3)) > 0.3
    got = elapsed_since_valid(steps, valid)
    times = np.cumsum(steps)
    for idx in np.ndindex(valid.shape[1:]):
        last = None
        for k in range(T):
            if last is None or last == k - 1:
                assert got[(k, *idx)] == steps[k]  # exactly the step, no round-off
            else:
                assert got[(k, *idx)] == times[k] - times[last]
            if valid[(k, *idx)]:
                last = k
    full = elapsed_since_valid(steps, np.ones((T, 2), dtype=bool))
    np.testing.assert_array_equal(full, np.broadcast_to(steps[:, None], (T, 2)))


def test_smooth_kalman_positions_are_writable_and_std_nan_where_no_estimate():
    rng = np.random.default_rng(7)
    pos = np.cumsum(rng.normal(scale=0.01, size=(40, 6, 3)), axis=0)
    pos[:5, 3] = np.nan
    for method in ("kf", "atkf"):
        for offline in (False, True):
            out = smooth(_seq(pos, fps=30.0), method, offline=offline)
            out.positions[0, 0, 0] = 1.0  # the output is the caller's to change
            assert np.array_equal(np.isnan(out.std), np.isnan(out.positions).any(axis=-1))
            assert np.isnan(out.positions[:5, 3]).all()


@pytest.mark.parametrize(("method", "window"), [("sgf", 1001), ("moving_average", 301)])
def test_a_window_longer_than_the_recording_is_refused(method, window):
    # issue 14: sgf window=1001 on a 193-frame recording replaced the data by a global fit
    seq = _seq(np.random.default_rng(0).normal(size=(193, 2, 3)))
    with pytest.raises(ValueError, match=r"window \d+ frames is longer than the recording"):
        smooth(seq, method, window=window)
    smooth(seq, method, window=191)  # fits: accepted
    short = _seq(np.random.default_rng(0).normal(size=(4, 2, 3)))
    smooth(short, method)  # shorter than the default window: shrinks, as documented
