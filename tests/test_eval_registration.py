"""Robust rigid registration: exact recovery, robustness to glitches, body-frame offsets."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from tobitkf.evaluation.registration import (
    choose_quaternion_order,
    fit_registration,
    kabsch,
    quat_to_matrix,
)
from tobitkf.evaluation.synthetic import generate_motion


@pytest.fixture(scope="module")
def motion() -> np.ndarray:
    return generate_motion("mixed", duration=6.0, seed=3).positions


def _rot(seed: int) -> np.ndarray:
    return Rotation.random(random_state=seed).as_matrix()


@settings(deadline=None, max_examples=40)
@given(seed=st.integers(0, 10_000), scale=st.booleans())
def test_kabsch_recovers_exact_similarity(seed: int, scale: bool) -> None:
    rng = np.random.default_rng(seed)
    src = rng.normal(size=(30, 3))
    R, t = _rot(seed), rng.normal(size=3) * 3
    s = float(rng.uniform(0.5, 2.0)) if scale else 1.0
    dst = s * src @ R.T + t
    R2, t2, s2 = kabsch(src, dst, scale=scale)
    np.testing.assert_allclose(R2, R, atol=1e-9)
    np.testing.assert_allclose(t2, t, atol=1e-9)
    assert s2 == pytest.approx(s, rel=1e-9)
    assert np.linalg.det(R2) == pytest.approx(1.0)


def test_kabsch_never_returns_a_reflection() -> None:
    rng = np.random.default_rng(0)
    src = rng.normal(size=(20, 3))
    dst = src * np.array([-1.0, 1.0, 1.0])  # a mirror image: best proper rotation only
    R, _, _ = kabsch(src, dst)
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_kabsch_validates_inputs() -> None:
    with pytest.raises(ValueError, match="at least 3"):
        kabsch(np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="shape"):
        kabsch(np.zeros((4, 3)), np.zeros((5, 3)))


@settings(deadline=None, max_examples=30)
@given(
    q=st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda v: np.linalg.norm(v) > 0.1)
)
def test_quat_to_matrix_matches_scipy(q: list[float]) -> None:
    xyzw = np.array(q)
    ref = Rotation.from_quat(xyzw).as_matrix()  # scipy: scalar last
    np.testing.assert_allclose(quat_to_matrix(xyzw, "xyzw"), ref, atol=1e-12)
    wxyz = np.roll(xyzw, 1)
    np.testing.assert_allclose(quat_to_matrix(wxyz, "wxyz"), ref, atol=1e-12)


def test_quat_to_matrix_zero_quaternion_is_nan() -> None:
    assert np.isnan(quat_to_matrix(np.zeros(4))).all()


def test_constant_rigid_transform_scores_zero_after_registration(motion: np.ndarray) -> None:
    R, t = _rot(7), np.array([1.0, -2.0, 0.5])
    # mocap = track expressed in another frame: track = R mocap + t
    mocap = (motion - t) @ R  # R^T (track - t)
    reg = fit_registration(motion, mocap, offset_mode="world")
    truth = reg.truth_in_track_frame(mocap)
    assert np.abs(truth - motion).max() < 1e-6
    np.testing.assert_allclose(reg.rotation, R, atol=1e-8)


def test_world_offsets_are_recovered(motion: np.ndarray) -> None:
    rng = np.random.default_rng(1)
    J = motion.shape[1]
    off = rng.normal(scale=0.05, size=(J, 3))
    R, t = _rot(11), np.array([0.2, 0.1, 3.0])
    mocap = (motion - t) @ R - off  # markers sit off the joint centres
    reg = fit_registration(motion, mocap, offset_mode="world")
    assert np.abs(reg.truth_in_track_frame(mocap) - motion).max() < 1e-6


def test_registration_not_pulled_by_one_metre_glitches(motion: np.ndarray) -> None:
    rng = np.random.default_rng(2)
    R, t = _rot(5), np.array([0.3, 1.0, -0.4])
    mocap = (motion - t) @ R
    track = motion.copy()
    T, J, _ = track.shape
    bad = rng.random(T) < 0.2  # 20 % of frames
    for k in np.flatnonzero(bad):
        joints = rng.random(J) < 0.5
        direction = rng.normal(size=3)
        track[k, joints] += direction / np.linalg.norm(direction)  # 1 m off
    track[bad, 0] += np.array([1.0, 0.0, 0.0])  # and at least one joint per bad frame
    for mode in ("none", "world"):
        reg = fit_registration(track, mocap, offset_mode=mode)
        angle = np.degrees(Rotation.from_matrix(reg.rotation @ R.T).magnitude())
        assert angle < 0.05, mode
        truth = reg.truth_in_track_frame(mocap)
        assert np.abs(truth - motion).max() < 1e-3, mode
    # a plain least-squares fit IS pulled (the robustness matters)
    R_ls, t_ls, _ = kabsch(mocap.reshape(-1, 3), track.reshape(-1, 3))
    assert np.abs(mocap @ R_ls.T + t_ls - motion).max() > 0.01


def _random_rotations(rng: np.random.Generator, T: int, J: int) -> np.ndarray:
    base = Rotation.random(J, random_state=int(rng.integers(1 << 30)))
    wob = Rotation.from_rotvec(rng.normal(scale=0.4, size=(T, J, 3)).reshape(-1, 3))
    return (wob * Rotation.concatenate([base] * T)).as_quat().reshape(T, J, 4)  # xyzw


def test_body_frame_offsets_and_quaternion_order(motion: np.ndarray) -> None:
    rng = np.random.default_rng(4)
    T, J, _ = motion.shape
    q = _random_rotations(rng, T, J)
    Q = quat_to_matrix(q, "xyzw")
    body_off = rng.normal(scale=0.06, size=(J, 3))
    R, t = _rot(9), np.array([0.0, 0.5, 2.0])
    # track = R (mocap + Q o) + t  =>  mocap = R^T (track - t) - Q o
    mocap = (motion - t) @ R - np.einsum("tjab,jb->tja", Q, body_off)
    reg, scores = choose_quaternion_order(motion, mocap, q)
    assert reg.quaternion_order == "xyzw"
    assert scores["xyzw"] < scores["wxyz"]
    np.testing.assert_allclose(reg.offsets, body_off, atol=1e-6)
    truth = reg.truth_in_track_frame(mocap, Q)
    assert np.abs(truth - motion).max() < 1e-6
    # given the same data in (w, x, y, z) order, the other order wins
    reg2, _ = choose_quaternion_order(motion, mocap, np.roll(q, 1, axis=-1))
    assert reg2.quaternion_order == "wxyz"


def test_fit_registration_validates() -> None:
    with pytest.raises(ValueError, match=r"\(T, J, 3\)"):
        fit_registration(np.zeros((5, 3)), np.zeros((5, 3)))
    with pytest.raises(ValueError, match="target_rotations"):
        fit_registration(np.zeros((5, 4, 3)), np.zeros((5, 4, 3)), offset_mode="body")
    with pytest.raises(ValueError, match="offset_mode"):
        fit_registration(np.zeros((5, 4, 3)), np.zeros((5, 4, 3)), offset_mode="bogus")
