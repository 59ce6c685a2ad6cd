"""Metrics: errors, glitch classes, the paper's M (eq. 41), lag, joint angles."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tobitkf.evaluation.angles import (
    angle_rmse_at_delay,
    angle_rmse_best_delay,
    joint_angle,
    joint_angles,
)
from tobitkf.evaluation.metrics import (
    FINE,
    SHORT_GLITCH,
    SUSTAINED_GLITCH,
    classify_glitches,
    glitch_episodes,
    joint_errors,
    rmse,
    smoothness,
    smoothness_per_component,
    top_jumps,
    velocity_lag,
)
from tobitkf.evaluation.synthetic import generate_motion


def test_joint_errors_and_rmse_by_hand() -> None:
    est = np.zeros((2, 2, 3))
    tru = np.zeros((2, 2, 3))
    tru[0, 0] = [3.0, 4.0, 0.0]  # error 5
    tru[1, 1] = np.nan
    e = joint_errors(est, tru)
    assert e[0, 0] == 5.0 and np.isnan(e[1, 1])
    assert rmse(e) == pytest.approx(np.sqrt(25 / 3))
    assert rmse(e, mask=np.array([[True, False], [False, False]])) == 5.0
    assert np.isnan(rmse(np.full(3, np.nan)))


def test_glitch_classes_follow_episode_lengths() -> None:
    err = np.zeros((20, 2))
    err[2, 0] = 0.5  # 1 frame
    err[5:9, 0] = 0.2  # 4 frames: still short
    err[10:15, 0] = 0.3  # 5 frames: sustained
    err[0:20, 1] = 0.05  # under threshold
    err[19, 1] = 0.11  # at the end
    lab = classify_glitches(err, threshold=0.1, short_max=4)
    assert lab[2, 0] == SHORT_GLITCH and (lab[5:9, 0] == SHORT_GLITCH).all()
    assert (lab[10:15, 0] == SUSTAINED_GLITCH).all()
    assert lab[9, 0] == FINE and (lab[:19, 1] == FINE).all() and lab[19, 1] == SHORT_GLITCH
    eps = glitch_episodes(err > 0.1)
    assert (0, 10, 15) in eps and (1, 19, 20) in eps and len(eps) == 4


@settings(deadline=None, max_examples=30)
@given(seed=st.integers(0, 10_000), T=st.integers(2, 30), J=st.integers(1, 5))
def test_smoothness_matches_the_definition(seed: int, T: int, J: int) -> None:
    rng = np.random.default_rng(seed)
    g = rng.normal(size=(T, J, 3))
    # brute force eq. 41: m_i = mean over k = 1..n-1 of (g_{k+1,i} - g_{k,i})^2
    m = np.empty((J, 3))
    for j in range(J):
        for i in range(3):
            m[j, i] = sum((g[k + 1, j, i] - g[k, j, i]) ** 2 for k in range(T - 1)) / (T - 1)
    np.testing.assert_allclose(smoothness_per_component(g), m, rtol=1e-12)
    assert smoothness(g) == pytest.approx(m.mean())


def test_smoothness_of_uniform_motion_and_missing_steps() -> None:
    p = np.zeros((11, 1, 3))
    p[:, 0, 0] = 0.02 * np.arange(11)  # 2 cm per frame on x only
    assert smoothness(p) == pytest.approx(0.02**2 / 3)
    p[5, 0, 0] = np.nan  # the two steps touching frame 5 are skipped
    assert smoothness_per_component(p)[0, 0] == pytest.approx(0.02**2)


def test_velocity_lag_of_truth_delayed_by_two_frames() -> None:
    truth = generate_motion("mixed", duration=8.0, seed=2).positions
    est = np.empty_like(truth)
    est[2:] = truth[:-2]  # the estimate shows what happened 2 frames ago
    est[:2] = truth[0]
    lag, refined, corr = velocity_lag(est, truth, joints=[7, 11], max_lag=8)
    assert lag == 2
    assert abs(refined - 2) < 0.3
    assert corr > 0.9
    assert velocity_lag(truth, truth, joints=[7, 11])[0] == 0


def test_largest_jumps() -> None:
    p = np.zeros((5, 2, 3))
    p[3, 1] = [0.0, 0.5, 0.0]
    jumps = top_jumps(p, ["a", "b"], n=2)
    assert jumps[0] == {"frame": 3, "joint": "b", "jump_m": 0.5}
    assert jumps[1]["frame"] == 4 and jumps[1]["jump_m"] == 0.5


def test_joint_angle_known_values() -> None:
    assert joint_angle([1, 0, 0], [0, 0, 0], [0, 1, 0]) == pytest.approx(90.0)
    assert joint_angle([1, 0, 0], [0, 0, 0], [-1, 0, 0]) == pytest.approx(180.0)
    assert joint_angle([1, 0, 0], [0, 0, 0], [1, 1e-9, 0]) == pytest.approx(0.0, abs=1e-6)
    assert joint_angle([1, 0, 0], [0, 0, 0], [1, 1, 0]) == pytest.approx(45.0)
    assert np.isnan(joint_angle([0, 0, 0], [0, 0, 0], [1, 0, 0]))


@settings(deadline=None, max_examples=30)
@given(seed=st.integers(0, 10_000), s=st.floats(0.1, 10))
def test_joint_angle_is_invariant_to_rotation_translation_scale(seed: int, s: float) -> None:
    rng = np.random.default_rng(seed)
    a, b, c = rng.normal(size=(3, 3))
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    t = rng.normal(size=3)
    ang = joint_angle(a, b, c)
    u, v = a - b, c - b
    ref = np.degrees(np.arccos(np.clip(u @ v / np.linalg.norm(u) / np.linalg.norm(v), -1, 1)))
    assert ang == pytest.approx(ref, abs=1e-6)
    assert joint_angle(s * q @ a + t, s * q @ b + t, s * q @ c + t) == pytest.approx(ang, abs=1e-6)


def test_joint_angles_by_name_for_kinect_and_uiprmd_names() -> None:
    seq = generate_motion("squat", duration=4.0, seed=1)
    ang = joint_angles(seq.positions, seq.joint_names)
    assert set(ang) == {"right_elbow", "left_elbow", "right_knee", "left_knee"}
    # the generator's knee flexion reaches 85-110 degrees: the knee angle drops to 70-95
    assert 65 < ang["left_knee"].min() < 100 and ang["left_knee"].max() > 175
    names = ["Right upper leg", "Right lower leg", "Right foot"]
    p = np.array([[[0, 1, 0], [0, 0, 0], [1, 0, 0]]], dtype=float)
    assert joint_angles(p, names)["right_knee"][0] == pytest.approx(90.0)


def test_the_best_delay_keeps_half_the_samples() -> None:
    """Ten frames: at delay 9 one pair is compared, and it happens to match; the search
    keeps to delays that compare at least half the samples (5 here)."""
    truth = np.arange(10, dtype=float) * 10.0
    est = truth + 3.0  # 3 degrees off at delay 0
    est[9] = truth[0]  # delay +9 compares est[9] with truth[0]: exactly equal
    assert angle_rmse_at_delay(est, truth, 9) == 0.0
    _, d = angle_rmse_best_delay(est, truth, max_delay=9)
    assert abs(d) <= 5
    # NaN samples count as missing pairs: only 4 of 10 at delay 0 leave delay 2 (2 pairs)
    holes = np.where(np.arange(10) < 4, truth, np.nan)
    assert angle_rmse_best_delay(holes, truth, max_delay=3)[1] in (0, 1, -1)


def test_angle_rmse_at_best_and_fixed_delay() -> None:
    t = np.linspace(0, 6, 200)
    truth = 90 + 40 * np.sin(t)
    est = np.empty_like(truth)
    est[3:] = truth[:-3]  # 3 frames late
    est[:3] = truth[0]
    best, d = angle_rmse_best_delay(est, truth, max_delay=6)
    assert d == 3 and best == pytest.approx(0.0, abs=1e-9)
    at0 = angle_rmse_at_delay(est, truth, 0)
    ref = np.sqrt(np.mean((est - truth) ** 2))
    assert at0 == pytest.approx(ref)
    assert at0 > 1.0
    assert angle_rmse_at_delay(truth, truth, -2) == pytest.approx(
        np.sqrt(np.mean((truth[:-2] - truth[2:]) ** 2))
    )
