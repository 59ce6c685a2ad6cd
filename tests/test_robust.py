"""Tests of tobitkf.smoothing.robust: physical gating + OU-velocity Kalman smoothing."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import tobitkf as tk
from conftest import data_file
from tobitkf.skeleton.sequence import SkeletonSequence, TrackingState
from tobitkf.skeleton.topology import get_topology
from tobitkf.smoothing.robust import _ou_matrices, robust_smooth
from tobitkf.smoothing.robust_gating import (
    bone_lengths,
    carry_with_parent,
    confirm_reacquisition,
    enforce_chain,
    gate_measurements,
    joint_levels,
)

FPS = 30.0


def _skeleton_motion(T: int = 240, seed: int = 0, wave_speed: float = 0.0,
                     bones: dict | None = None) -> np.ndarray:  # fmt: skip
    """A rigid Kinect V2 skeleton (constant bones) swaying slowly; optional right-arm wave.

    Built by forward kinematics from fixed bone vectors so bone lengths are exactly
    constant; ``wave_speed`` (m/s) swings the right forearm about the elbow so the right
    hand reaches roughly that peak speed. ``bones``: joint name -> its bone vector from
    its parent, m, in place of the random ones.
    """
    topo = get_topology("kinect_v2")
    rng = np.random.default_rng(seed)
    J = topo.n_joints
    offs = rng.normal(size=(J, 3))
    offs /= np.linalg.norm(offs, axis=1, keepdims=True)
    offs *= rng.uniform(0.06, 0.3, size=(J, 1))
    t = np.arange(T) / FPS
    pos = np.zeros((T, J, 3))
    root = np.stack([0.1 * np.sin(0.5 * t), 0.05 * np.sin(0.3 * t), 2.5 + 0.1 * np.cos(0.4 * t)], 1)
    # a horizontal right forearm: wrist 25 cm from the elbow, hand 8 cm further
    for name, off in (
        ("WristRight", (0.25, 0.0, 0.0)),
        ("HandRight", (0.08, 0.0, 0.0)),
        ("HandTipRight", (0.06, 0.01, 0.0)),
        ("ThumbRight", (0.03, 0.04, 0.0)),
    ):
        offs[topo.index(name)] = off
    for name, off in (bones or {}).items():
        offs[topo.index(name)] = off
    for j in topo_order(topo):
        p = topo.parents[j]
        pos[:, j] = root if p < 0 else pos[:, p] + offs[j]
    if wave_speed:
        # swing the right forearm chain about the elbow (z axis through the elbow)
        names = topo.joints
        elbow = names.index("ElbowRight")
        chain = [names.index(n) for n in ("WristRight", "HandRight", "HandTipRight", "ThumbRight")]
        hand = names.index("HandRight")
        rel = pos[:, chain] - pos[:, elbow, None]
        r_xy = np.hypot(*(pos[0, hand, :2] - pos[0, elbow, :2]))
        omega = 2 * np.pi * 2.0  # a brisk 2 Hz wave
        ang = (wave_speed / (omega * r_xy)) * np.sin(omega * t)
        c, s = np.cos(ang)[:, None], np.sin(ang)[:, None]
        x, y = rel[..., 0].copy(), rel[..., 1].copy()
        rel[..., 0], rel[..., 1] = c * x - s * y, s * x + c * y
        pos[:, chain] = pos[:, elbow, None] + rel
    return pos


def topo_order(topo) -> list[int]:
    return [int(j) for lvl in joint_levels(topo.parents) for j in lvl]


def _seq(pos: np.ndarray, states=None) -> SkeletonSequence:
    return SkeletonSequence(positions=pos, topology="kinect_v2", fps=FPS, tracking_state=states)


def _rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.nanmean(np.sum((a - b) ** 2, axis=-1))))


def _hand_chain(topo) -> list[int]:
    return [topo.index(n) for n in ("WristRight", "HandRight", "HandTipRight", "ThumbRight")]


# ----------------------------------------------------------------------------- helpers
def test_joint_levels_and_bone_lengths():
    parents = (-1, 0, 1, 1, 3)
    levels = joint_levels(parents)
    assert [lvl.tolist() for lvl in levels] == [[0], [1], [2, 3], [4]]
    with pytest.raises(ValueError):
        joint_levels((1, 0))
    pos = np.zeros((5, 5, 3))
    pos[:, 1, 0] = 1.0
    pos[:, 2, 0] = 3.0  # bone 1->2 has length 2
    pos[:, 3, 0] = 1.0
    pos[:, 3, 1] = 0.5
    pos[:, 4] = pos[:, 3] + [0, 0, 0.25]
    pos[2, 2, 0] = 100.0  # one outlier does not move the median
    L = bone_lengths(pos, parents)
    np.testing.assert_allclose(L[1:], [1.0, 2.0, 0.5, 0.25])
    assert np.isnan(L[0])


def test_ou_matrices_match_dense_integration():
    # exact discretisation vs a fine Euler integration of the covariance ODE
    tau, dt = 0.15, 1 / 30
    A, Q = _ou_matrices(np.array([dt]), tau)
    F = np.array([[0.0, 1.0], [0.0, -1.0 / tau]])
    G = np.array([[0.0, 0.0], [0.0, 1.0]])
    n = 20000
    h = dt / n
    P = np.zeros((2, 2))
    Phi = np.eye(2)
    for _ in range(n):
        P = P + h * (F @ P + P @ F.T + G)
        Phi = Phi + h * F @ Phi
    np.testing.assert_allclose(A[0], Phi, rtol=1e-3, atol=1e-9)
    np.testing.assert_allclose(Q[0], P, rtol=2e-3, atol=1e-12)
    # tau = inf: constant velocity
    A, Q = _ou_matrices(np.array([dt]), np.inf)
    np.testing.assert_allclose(A[0], [[1, dt], [0, 1]])
    np.testing.assert_allclose(Q[0], [[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])


# ----------------------------------------------------------------------------- synthetic
@pytest.mark.parametrize("offline", [True, False])
def test_sustained_hand_failure_is_rejected(offline):
    truth = _skeleton_motion()
    topo = get_topology("kinect_v2")
    rng = np.random.default_rng(1)
    meas = truth + rng.normal(scale=0.004, size=truth.shape)
    chain = _hand_chain(topo)
    a, b = 100, 130  # 30 frames, the whole hand chain 0.8 m off (wrist bone violated)
    meas[a:b, chain] += np.array([0.0, 0.8, 0.0])
    out = robust_smooth(_seq(meas), offline=offline)
    d = out.metadata["diagnostics"]
    rej = d["rejected"]
    # most of the failure is rejected on every joint of the chain
    assert rej[a:b][:, chain].mean() > 0.9
    # and little else is rejected
    outside = np.ones(len(truth), dtype=bool)
    outside[a - 5 : b + 5] = False
    assert rej[outside].mean() < 0.01
    err_raw = _rmse(meas[a:b, chain], truth[a:b, chain])
    err = _rmse(out.positions[a:b, chain], truth[a:b, chain])
    assert err_raw > 0.75
    assert err < 0.25 * err_raw  # well below raw
    assert d["rejected_fraction"].shape == (topo.n_joints,)
    assert d["method"] == ("robust" if offline else "robust_online")


@pytest.mark.parametrize("offline", [True, False])
def test_clean_motion_passes_nearly_unchanged(offline):
    truth = _skeleton_motion(seed=3)
    rng = np.random.default_rng(2)
    meas = truth + rng.normal(scale=0.002, size=truth.shape)
    out = robust_smooth(_seq(meas), offline=offline)
    assert out.metadata["diagnostics"]["rejected"].mean() < 0.002
    assert _rmse(out.positions, meas) < 0.004
    assert _rmse(out.positions, truth) < _rmse(meas, truth) + 0.001


@pytest.mark.parametrize("offline", [True, False])
def test_fast_legitimate_motion_is_not_rejected(offline):
    truth = _skeleton_motion(seed=4, wave_speed=3.1)
    topo = get_topology("kinect_v2")
    hand = topo.index("HandRight")
    speed = np.linalg.norm(np.diff(truth[:, hand], axis=0), axis=-1) * FPS
    assert speed.max() > 2.8  # the hand really reaches ~3 m/s
    out = robust_smooth(_seq(truth), offline=offline)
    chain = _hand_chain(topo)
    assert out.metadata["diagnostics"]["rejected"][:, chain].sum() == 0
    # the smoother rounds the 2 Hz wave slightly; causal filtering lags by a few cm at most
    assert _rmse(out.positions[:, chain], truth[:, chain]) < (0.01 if offline else 0.03)


def test_one_frame_spikes_rejected_offline():
    truth = _skeleton_motion(seed=5)
    topo = get_topology("kinect_v2")
    meas = truth.copy()
    hand = topo.index("HandLeft")
    frames = [30, 90, 150]
    meas[frames, hand] += np.array([0.5, -0.3, 0.2])
    out = robust_smooth(_seq(meas))
    assert out.metadata["diagnostics"]["rejected"][frames, hand].all()
    assert np.max(np.linalg.norm(out.positions[:, hand] - truth[:, hand], axis=-1)) < 0.01


def test_missing_and_tracking_states():
    truth = _skeleton_motion(seed=6)
    topo = get_topology("kinect_v2")
    meas = truth.copy()
    states = np.full(truth.shape[:2], int(TrackingState.TRACKED), dtype=np.int8)
    knee = topo.index("KneeLeft")
    states[50:60, knee] = TrackingState.NOT_TRACKED
    meas[50:60, knee] = 0.0  # what the sensor reports: zeros, must not be used
    elbow = topo.index("ElbowLeft")
    meas[0:5, elbow] = np.nan
    out = robust_smooth(_seq(meas, states))
    d = out.metadata["diagnostics"]
    assert np.isnan(out.positions[0:5, elbow]).all()  # nothing observed yet
    assert np.isfinite(out.positions[5:, elbow]).all()
    # the not-tracked stretch is interpolated, not pulled to the origin
    assert np.max(np.linalg.norm(out.positions[50:60, knee] - truth[50:60, knee], axis=-1)) < 0.02
    assert d["rejected"][50:60, knee].sum() == 0  # missing, not rejected
    assert d["filled_fraction"][knee] == pytest.approx(10 / len(truth))


def test_irregular_timestamps_and_validation():
    truth = _skeleton_motion(T=120, seed=7)
    ts = np.cumsum(np.r_[0.0, np.random.default_rng(0).uniform(0.02, 0.05, 119)])
    seq = SkeletonSequence(positions=truth, topology="kinect_v2", timestamps=ts)
    out = robust_smooth(seq)
    assert _rmse(out.positions, truth) < 0.003
    with pytest.raises(ValueError):
        robust_smooth(seq, tau=0.0)
    with pytest.raises(ValueError):
        robust_smooth(seq, margin=-1)
    with pytest.raises(ValueError, match="unknown"):
        robust_smooth(seq, v_max={"handz": 8.0})  # a region that is not one
    # a mapping names the regions it changes; the others keep their defaults
    some = robust_smooth(seq, v_max={"hands": 8.0, "legs": 6.0})
    every = robust_smooth(seq, v_max={"hands": 8.0, "arms": 5.0, "torso": 3.0, "legs": 6.0})
    np.testing.assert_array_equal(some.positions, every.positions)
    used = some.metadata["diagnostics"]["params"]["v_max"]
    legs = seq.topology.joint_groups()["legs"]
    assert np.all(np.asarray(used)[legs] == 6.0)
    assert np.array_equal(used, every.metadata["diagnostics"]["params"]["v_max"])
    with pytest.raises(ValueError, match=r"one per joint \(25 for topology 'kinect_v2'\); got 3"):
        robust_smooth(seq, v_max=(6.0, 5.0, 4.0))
    with pytest.raises(TypeError):
        robust_smooth(truth)
    # checked as smooth() checks them, not coerced (bool("no") is True, int(1.5) is 1)
    for bad in ({"bones": "no"}, {"lookback": 1.5}, {"inferred_noise_factor": np.nan}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            robust_smooth(seq, **bad)
    # per-joint arrays are still accepted and equal the same values given per region
    J = seq.n_joints
    by_joint = robust_smooth(seq, v_max=np.full(J, 6.0), speed_sd=np.full(J, 0.5))
    by_number = robust_smooth(seq, v_max=6.0, speed_sd=0.5)
    np.testing.assert_array_equal(by_joint.positions, by_number.positions)


def test_gate_relocks_after_max_reject():
    # a joint whose first frames are wrong would otherwise be locked out for ever
    T = 150
    ys = np.zeros((T, 1, 3))
    ys[:10, 0, 0] = 1.0  # wrong start, then the true position (a 1 m jump)
    acc = gate_measurements(
        ys,
        np.arange(T) / FPS,
        (-1,),
        np.array([0.5]),
        margin=0.01,
        bone_len=None,
        bone_tol_abs=0.03,
        bone_tol_rel=0.15,
        max_reject=1.0,
    )
    # v_max 0.5 m/s: the gate reaches 1 m after 2 s; max_reject re-locks after 1 s
    assert acc[:10, 0].all()
    first_back = 10 + int(np.argmax(acc[10:, 0]))
    assert 35 <= first_back <= 45


def _chain_gate(ys: np.ndarray, fps: float = FPS) -> np.ndarray:
    """gate_measurements on a root - a - b chain (a 25 cm, b 8 cm further along x), the
    Kinect arm / hand speed bounds and the robust bone tolerance."""
    return gate_measurements(
        ys, np.arange(len(ys)) / fps, (-1, 0, 1), np.array([3.0, 5.0, 8.0]), margin=0.05,
        bone_len=np.array([np.nan, 0.25, 0.08]), bone_tol_abs=0.03, bone_tol_rel=0.15,
    )  # fmt: skip


def _chain_track(T: int = 40) -> np.ndarray:
    ys = np.zeros((T, 3, 3))
    ys[:, 1, 0] = 0.25
    ys[:, 2, 0] = 0.33
    return ys


def test_a_child_that_jumps_with_its_rejected_parent_shares_its_failure():
    # a and b jump 20 cm together in one frame: a's bone breaks (32 cm for 25), b's does
    # not, and b's step is inside its own speed gate (8 m/s / 30 + 5 cm = 32 cm), so only
    # the shared step tells that b went with a's impossible place
    ys = _chain_track()
    ys[10:30, 1:, 1] += 0.2
    acc = _chain_gate(ys)
    assert not acc[10:30, 1].any()
    assert not acc[10:30, 2].any()  # from the first frame on, until its parent is back
    assert acc[:10].all() and acc[30:].all()
    # the same backwards in time: the failure's end is its entry there
    back = _chain_gate(ys[::-1].copy())[::-1]
    np.testing.assert_array_equal(back, acc)


def test_a_child_that_did_not_share_its_parents_step_stays_accepted():
    # a alone jumps (b stays put): b did not move, it keeps the chain rule's exception
    ys = _chain_track()
    ys[10:30, 1, 1] += 0.2
    acc = _chain_gate(ys)
    assert not acc[10:30, 1].any() and acc[:, 2].all()
    # a and b drift together 3.6 cm a frame (1.1 m/s) until a's bone is off: a shared
    # step no larger than b's bone tolerance (3 cm + 15 % of 8 cm) is motion, not a failure
    ys = _chain_track()
    ys[10:, 1:, 1] += 0.036 * np.arange(1, 31)[:, None]
    acc = _chain_gate(ys)
    assert not acc[:, 1].all()  # a is rejected once its bone is 6.75 cm long
    assert acc[:, 2].all()
    # a is off from frame 10 on; from frame 20 a and b move together 5 cm a frame: the
    # steps of a parent that was already wrong are its motion, which a right child shares
    ys = _chain_track()
    ys[10:, 1, 1] += 0.2
    ys[20:, 1:, 0] += 0.05 * np.minimum(np.arange(1, 21), 6)[:, None]
    acc = _chain_gate(ys)
    assert not acc[10:, 1].any() and acc[:, 2].all()


_VEC = st.tuples(*[st.floats(-0.14, 0.14, allow_nan=False)] * 3)


@settings(max_examples=300, deadline=None)
@given(da=_VEC, dev=_VEC, scale=st.sampled_from([0.1, 0.3, 0.5, 1.0]),
       fps=st.sampled_from([10.0, 15.0, 30.0, 60.0]))  # fmt: skip
def test_shared_step_rule_property(da, dev, scale, fps):
    # a and b step by da and db = da + dev (dev scaled, so that both sides of b's bone
    # tolerance are drawn) at frame 10 and stay there; wherever a is rejected at that
    # frame, b (accepted before, its step inside its own speed gate) is rejected exactly
    # when a moved by more than b's bone tolerance and b made the same step: to within
    # that tolerance per frame of 30 fps (more in a longer frame, never less)
    da = np.array(da)
    db = np.clip(da + scale * np.array(dev), -0.14, 0.14)
    ys = _chain_track(20)
    ys[10:, 1] += da
    ys[10:, 2] += db
    acc = _chain_gate(ys, fps)
    assert acc[:10].all()
    tol_b = 0.03 + 0.15 * 0.08
    same = tol_b * max(1.0, 30.0 / fps)
    shared = np.linalg.norm(da) > tol_b and np.linalg.norm(db - da) <= same
    if not acc[10, 1]:
        if np.linalg.norm(db) > 8.0 / fps + 0.05:  # outside b's own speed gate
            assert not acc[10, 2]
        else:
            assert acc[10, 2] == (not shared)


@pytest.mark.parametrize("fps, shared", [(30.0, False), (15.0, True), (10.0, True)])
def test_the_same_step_allows_the_childs_turn_in_a_longer_frame(fps, shared):
    # a breaks its bone with a 20 cm step (rejected); b goes with it and, in the same
    # frame, turns 6 cm about a (its own motion: more than its bone tolerance of 4.2 cm,
    # less than two of them). In a frame of 1/30 s that is not the same step; in one of
    # 1/15 s, where b's own turn about a in a frame may be twice as large, it is, and b
    # shares a's failure until a is back
    ys = _chain_track()
    ys[10:30, 1:, 1] += 0.2
    ys[10:30, 2, 2] += 0.06
    acc = _chain_gate(ys, fps)
    assert not acc[10:30, 1].any() and acc[:10].all() and acc[30:, 1].all()
    if shared:
        assert not acc[10:30, 2].any()
    else:
        assert acc[10:30, 2].all()


@pytest.mark.parametrize("offline", [True, False])
def test_hand_chain_failure_inside_the_hand_speed_gate_is_rejected(offline):
    # the whole hand chain 25 cm off for 30 frames: a step the hand can make in a frame
    # (8 m/s), so the wrist's broken bone is what rejects the hand, tip and thumb with it
    truth = _skeleton_motion()
    topo = get_topology("kinect_v2")
    meas = truth + np.random.default_rng(1).normal(scale=0.004, size=truth.shape)
    chain = _hand_chain(topo)
    a, b = 100, 130
    meas[a:b, chain] += np.array([0.0, 0.25, 0.0])
    out = robust_smooth(_seq(meas), offline=offline)
    rej = out.metadata["diagnostics"]["rejected"]
    assert rej[a:b][:, chain].mean() > 0.9
    err_raw = _rmse(meas[a:b, chain], truth[a:b, chain])
    assert _rmse(out.positions[a:b, chain], truth[a:b, chain]) < 0.3 * err_raw


def test_enforce_chain_rejects_child_that_entered_with_a_rejected_parent():
    # shoulder (root) - elbow - wrist; the elbow is rejected in frames 5-14.  The wrist was
    # rejected in 5-7 (it jumped with the elbow) but then moved smoothly, so gates run in
    # each direction separately can accept it in 8-14: a failed wrist next to a bridged
    # elbow.  The chain rule keeps it rejected until its parent is back.
    T = 20
    ys = np.zeros((T, 3, 3))
    ys[:, 1, 0] = 0.25
    ys[:, 2, 0] = 0.50
    ys[5:15, 1:, 1] = 0.3 + 0.001 * np.arange(10)[:, None]  # elbow and wrist off together
    acc = np.ones((T, 3), dtype=bool)
    acc[5:15, 1] = False
    acc[5:8, 2] = False
    times = np.arange(T) / FPS
    vmax = np.full(3, 5.0)
    out = enforce_chain(acc, ys, times, (-1, 0, 1), vmax, 0.05)
    assert not out[5:15, 2].any()
    assert out[:5, 2].all() and out[15:, 2].all()
    np.testing.assert_array_equal(out[:, :2], acc[:, :2])  # parents are never changed


def test_enforce_chain_keeps_child_that_stayed_put():
    # the elbow alone glitches; the wrist was accepted before and after and did not jump,
    # so it stays accepted (the exception of the chain rule), in both time directions
    T = 20
    ys = np.zeros((T, 3, 3))
    ys[:, 1, 0] = 0.25
    ys[:, 2, 0] = 0.50
    ys[5:15, 1, 1] = 0.4
    acc = np.ones((T, 3), dtype=bool)
    acc[5:15, 1] = False
    out = enforce_chain(acc, ys, np.arange(T) / FPS, (-1, 0, 1), np.full(3, 5.0), 0.05)
    np.testing.assert_array_equal(out, acc)
    # ...but not when it jumped at the moment its parent was rejected
    ys[5:, 2, 1] = 0.4
    out = enforce_chain(acc, ys, np.arange(T) / FPS, (-1, 0, 1), np.full(3, 5.0), 0.05)
    assert not out[5:15, 2].any() and out[15:, 2].all()


def test_confirm_reacquisition_is_causal_and_only_after_long_failures():
    times = np.arange(30) * 0.1  # 10 fps, min_run 0.25 s = 2.5 frames
    acc = np.ones((30, 3), dtype=bool)
    missing = np.zeros((30, 3), dtype=bool)
    acc[5, 0] = False  # joint 0: a one-frame spike, shorter than min_run
    acc[5:10, 1] = False  # joint 1: a 0.5 s failure, then good data from frame 10
    acc[5:10, 2] = False  # joint 2: the same, with a one-frame flicker inside it ...
    acc[8, 2] = True
    acc[10:20, 2] = False  # ... and a stray sample at 12 (and missing frames at 15, 16)
    acc[12, 2] = True
    missing[15:17, 2] = True
    acc[15:17, 2] = False
    out = confirm_reacquisition(acc, missing, times, 0.25)
    np.testing.assert_array_equal(out[:, 0], acc[:, 0])  # spikes: re-accepted at once
    assert not out[5:13, 1].any() and out[13:, 1].all()  # 10, 11, 12 wait for 0.25 s
    assert not out[5:23, 2].any() and out[23:, 2].all()  # flicker and stray sample too
    assert out[:5].all()
    # causal: the decision at t does not depend on later frames
    cut = confirm_reacquisition(acc[:11], missing[:11], times[:11], 0.25)
    np.testing.assert_array_equal(cut, out[:11])


def test_carry_with_parent_moves_a_rejected_chain_with_its_parent():
    # shoulder - elbow - wrist; elbow and wrist rejected in 5-9 while the shoulder walks on:
    # the pseudo-measurements keep each joint's last good offset from its parent
    T = 12
    ys = np.zeros((T, 3, 3))
    ys[:, 0, 0] = 0.1 * np.arange(T)  # the shoulder moves 10 cm per frame
    ys[:, 1] = ys[:, 0] + [0.0, -0.25, 0.0]
    ys[:, 2] = ys[:, 1] + [0.0, -0.2, 0.05]
    ys[5:10, 1:] += 1.0  # the failed measurements: nothing of them may leak through
    acc = np.ones((T, 3), dtype=bool)
    acc[5:10, 1:] = False
    pseudo, radius = carry_with_parent(ys, acc, (-1, 0, 1))
    expect_elbow = ys[5:10, 0] + [0.0, -0.25, 0.0]
    np.testing.assert_allclose(pseudo[5:10, 1], expect_elbow, atol=1e-12)
    expect_wrist = expect_elbow + np.array([0.0, -0.2, 0.05])
    np.testing.assert_allclose(pseudo[5:10, 2], expect_wrist, atol=1e-12)
    np.testing.assert_allclose(radius[5:10, 1], 0.25)
    np.testing.assert_allclose(radius[5:10, 2], np.hypot(0.2, 0.05))
    assert np.isnan(pseudo[acc]).all()  # accepted samples get none
    # no earlier good offset (rejected from the first frame): nothing to carry causally
    acc0 = acc.copy()
    acc0[:10, 2] = False
    p0, _ = carry_with_parent(ys, acc0, (-1, 0, 1))
    assert np.isnan(p0[:10, 2]).all()


def test_rejected_hand_follows_its_wrist():
    # the whole skeleton translates 0.6 m while the right hand's measurements are wrong
    # (frozen where the failure began); the carried hand keeps up with the wrist
    topo = get_topology("kinect_v2")
    truth = _skeleton_motion(T=120, seed=3)
    truth = truth + np.linspace(0.0, 0.6, 120)[:, None, None] * np.array([1.0, 0.0, 0.0])
    ys = truth.copy()
    h = topo.index("HandRight")
    ys[40:90, h] = ys[40, h] + [0.0, 0.5, 0.0]  # 0.5 m off and frozen for 50 frames
    seq = SkeletonSequence(positions=ys, topology=topo, fps=FPS)
    for offline in (True, False):
        out = robust_smooth(seq, offline=offline)
        err = np.linalg.norm(out.positions[40:90, h] - truth[40:90, h], axis=-1)
        held = robust_smooth(seq, offline=offline, carry=False).positions
        err_held = np.linalg.norm(held[40:90, h] - truth[40:90, h], axis=-1)
        assert err.max() < 0.08, (offline, err.max())
        assert err.max() < err_held.max()


# ----------------------------------------------------------------------------- real data
def test_keraal_pooled_rmse_below_raw():
    from tobitkf.evaluation.evaluate import prepare_truth
    from tobitkf.io import load

    num = {"raw": 0.0, "robust": 0.0, "robust_online": 0.0}
    den = 0
    for ex in ("CTK", "ELK", "RTK"):
        track = load(data_file(f"keraal/G3-Kinect-{ex}-P1T1-Unknown-C-0.txt"))[0]
        mocap = load(data_file(f"keraal/G3-Vicon-{ex}-P1T1-Unknown-C-0.txt"))[0]
        truth = prepare_truth(track, mocap)
        outs = {
            "raw": track.positions,
            "robust": robust_smooth(track).positions,
            "robust_online": robust_smooth(track, offline=False).positions,
        }
        for k, p in outs.items():
            e = np.sum((p - truth.positions) ** 2, axis=-1)[:, truth.paired]
            num[k] += float(np.nansum(e))
        den += int(
            np.isfinite(np.sum((track.positions - truth.positions) ** 2, -1))[:, truth.paired].sum()
        )
    rmse = {k: np.sqrt(v / den) for k, v in num.items()}
    # measured: raw 11.7 cm, robust 5.8 cm, robust_online 6.4 cm
    assert rmse["raw"] > 0.10
    assert rmse["robust"] < rmse["raw"] - 0.015
    assert rmse["robust_online"] < rmse["raw"] - 0.01


def test_validators_for_the_registry():
    from tobitkf.smoothing.robust import ROBUST_DEFAULTS, ROBUST_VALIDATORS

    assert set(ROBUST_VALIDATORS) == set(ROBUST_DEFAULTS) - {"inferred_noise_factor"}
    for name, check in ROBUST_VALIDATORS.items():
        check(name, ROBUST_DEFAULTS[name])  # defaults are valid
    assert ROBUST_VALIDATORS["v_max"]("v_max", 4) == 4.0
    with pytest.raises(ValueError, match="torso"):
        ROBUST_VALIDATORS["v_max"]("v_max", {"hands": 8, "arms": 5, "legs": 6})
    with pytest.raises(ValueError):
        ROBUST_VALIDATORS["tau"]("tau", 0)
    with pytest.raises(ValueError):
        ROBUST_VALIDATORS["lookback"]("lookback", 1.5)
    with pytest.raises(ValueError):
        ROBUST_VALIDATORS["bones"]("bones", "yes")


def test_inferred_joints_get_less_weight():
    truth = _skeleton_motion(seed=8)
    topo = get_topology("kinect_v2")
    rng = np.random.default_rng(3)
    meas = truth + rng.normal(scale=0.01, size=truth.shape)
    states = np.full(truth.shape[:2], int(TrackingState.TRACKED), dtype=np.int8)
    foot = topo.index("FootLeft")
    states[:, foot] = TrackingState.INFERRED
    seq = _seq(meas, states)
    e1 = _rmse(robust_smooth(seq, inferred_noise_factor=1.0).positions[:, foot], truth[:, foot])
    e4 = _rmse(robust_smooth(seq).positions[:, foot], truth[:, foot])
    # a slowly moving joint: more measurement variance -> more averaging -> closer to truth
    assert e4 < 0.9 * e1  # measured ratio 0.84
    with pytest.raises(ValueError):
        robust_smooth(seq, inferred_noise_factor=0.5)


@pytest.mark.parametrize("exercise", [1, 3, 5])
def test_kimore_robust_never_jumps_more_than_raw(exercise):
    # a joint held in space while the body moves on snaps back with a jump larger than any
    # in the raw data (robust_online on Ex3 did: 1.24 m against 0.72 m raw)
    from tobitkf.io import load

    seq = load(data_file(f"kimore/JointPositionExercise{exercise}.csv"))[0]

    def largest_jump(p):
        return np.nanmax(np.linalg.norm(np.diff(p, axis=0), axis=-1))

    raw = largest_jump(seq.positions)
    for offline in (True, False):
        assert largest_jump(robust_smooth(seq, offline=offline).positions) < raw


# ----------------------------------------------------------------------------- references
def _ou_reference(ys, states, tau, q, r, factor, offline, drop=None, with_sd=False):
    """The OU-velocity filter (+ RTS) per axis by the package's generic Kalman core.

    ``ys (T, J, 3)`` NaN where missing; nothing is rejected; INFERRED samples get
    ``factor`` times the variance; ``drop``: frames whose samples the filter skips.
    Offline: started at frame 0 from the joint's first sample with velocity 0 and
    P0 = diag(r0, q tau / 2), then updated with every sample. Online: the state *is* the
    first sample (velocity 0, P = diag(r0, q tau / 2)), the filter runs from there. r0 is
    the first sample's variance (times ``factor`` when it is INFERRED).
    """
    from tobitkf.core.kalman import kalman_filter, rts_smooth
    from tobitkf.core.model import LinearGaussian

    T, J, _ = ys.shape
    A, Q = _ou_matrices(np.full(T, 1 / FPS), tau)
    y = ys.copy()
    if drop is not None:
        y[drop] = np.nan
    rs = np.where(states == TrackingState.INFERRED, factor, 1.0)
    means = np.full((T, J, 3), np.nan)
    sds = np.full((T, J), np.nan)
    for j in range(J):
        f = int(np.argmax(np.isfinite(ys[:, j, 0])))  # the first sample
        s = 0 if offline else f
        yj = y[s:, j].copy()
        if not offline:
            yj[0] = np.nan  # the state starts at it: no update
        Aj, Qj = A[s:].copy(), q * Q[s:]
        Aj[0], Qj[0] = np.eye(2), 0.0  # the first step starts at x0 itself
        x0 = np.stack([ys[f, j], np.zeros(3)], axis=-1)  # (3, 2)
        P0 = np.diag([r * rs[f, j], q * tau / 2])  # the first sample's own variance
        model = LinearGaussian(A=A[1], H=np.array([[1.0, 0.0]]), Q=q * Q[1],
                               R=np.array([[r]]), x0=x0, P0=P0)  # fmt: skip
        scale = np.broadcast_to(rs[s:, j, None, None], (T - s, 3, 1))
        res = kalman_filter(model, yj[..., None], A_seq=Aj, Q_seq=Qj, R_scale=scale)
        post = rts_smooth(model, res) if offline else res
        means[f:, j] = post.means[..., 0][f - s :]
        sds[f:, j] = np.sqrt(post.variances[:, 0, 0])[f - s :]  # axis x (the axes share it)
    return (means, sds) if with_sd else means


@pytest.mark.parametrize("offline", [True, False])
def test_ou_smoother_equals_the_generic_kalman_core_when_nothing_is_rejected(offline):
    # gates wide open: robust is then the OU-velocity KF (+ RTS) of the Kalman core
    truth = _skeleton_motion(T=90, seed=9)
    rng = np.random.default_rng(4)
    ys = truth + rng.normal(scale=0.01, size=truth.shape)
    ys[:6, 3] = np.nan  # Head appears late
    ys[30:41, 7] = np.nan  # a gap in HandLeft
    states = np.full(ys.shape[:2], int(TrackingState.TRACKED), dtype=np.int8)
    states[rng.random(states.shape) < 0.1] = TrackingState.INFERRED
    tau, spd, sd = 0.15, 0.5, 0.01
    # the guesses as independent measurements, as the core treats them (test_robust_shared);
    # one pass of the smoother (no reweighting: test_reweight)
    params = dict(v_max=1e6, bones=False, speed_sd=spd, noise_sd=sd, tau=tau, lookback=0,
                  noise="fixed", shared_errors=False, reweight=0)  # fmt: skip
    out = robust_smooth(_seq(ys, states), offline=offline, **params)
    assert not out.metadata["diagnostics"]["rejected"].any()
    ref, ref_sd = _ou_reference(
        ys, states, tau, 2 * spd**2 / tau, sd**2, 4.0, offline, with_sd=True
    )
    np.testing.assert_array_equal(np.isnan(out.positions), np.isnan(ref))
    np.testing.assert_allclose(out.positions, ref, rtol=0, atol=1e-12, equal_nan=True)
    # the posterior standard deviation is the core's (filtered online, smoothed offline)
    np.testing.assert_allclose(out.std, ref_sd, rtol=1e-9, atol=0, equal_nan=True)
    via_smooth = tk.smooth(_seq(ys, states), "robust" if offline else "robust_online", **params)
    np.testing.assert_allclose(via_smooth.std, ref_sd, rtol=1e-9, atol=0, equal_nan=True)


def test_online_lookback_drops_the_last_frames_before_a_rejection_from_the_state():
    # at the onset of a rejection the last `lookback` accepted frames leave the filter
    # state; the outputs already emitted stay; while the joint is rejected the filter
    # predicts as if those frames had never been measured. (At the onset of a plain gap
    # nothing is dropped: tests/test_policy.py.)
    truth = _skeleton_motion(T=80, seed=10)
    ys = truth + np.random.default_rng(5).normal(scale=0.01, size=truth.shape)
    hand = get_topology("kinect_v2").index("HandLeft")
    jumped = ys.copy()
    jumped[40:50, hand] += [0.0, 2.0, 0.0]  # 2 m off: out of the speed gate for 10 frames
    states = np.full(ys.shape[:2], int(TrackingState.TRACKED), dtype=np.int8)
    tau, spd, sd = 0.15, 0.5, 0.01
    params = dict(v_max=3.0, bones=False, speed_sd=spd, noise_sd=sd, tau=tau, lookback=2,
                  carry=False, min_run=0.0)  # fmt: skip
    res = robust_smooth(_seq(jumped), offline=False, **params)
    assert res.metadata["diagnostics"]["rejected"][:, hand].nonzero()[0].tolist() == list(
        range(40, 50)
    )
    out = res.positions
    gap = ys.copy()
    gap[40:50, hand] = np.nan  # what a rejected sample is to the filter
    q, r = 2 * spd**2 / tau, sd**2
    plain = _ou_reference(gap, states, tau, q, r, 1.0, False)
    rolled = _ou_reference(gap, states, tau, q, r, 1.0, False, drop=(slice(38, 40), hand))
    np.testing.assert_allclose(out[:40, hand], plain[:40, hand], rtol=0, atol=1e-12)
    np.testing.assert_allclose(out[40:50, hand], rolled[40:50, hand], rtol=0, atol=1e-12)
    assert np.abs(rolled[45, hand] - plain[45, hand]).max() > 1e-4  # it made a difference
    other = [j for j in range(ys.shape[1]) if j != hand]
    np.testing.assert_allclose(out[:, other], plain[:, other], rtol=0, atol=1e-12)


def test_online_bone_window_is_the_median_of_the_last_600_lengths():
    # the bounded window the online bone gate keeps, against np.median(history[-600:])
    from tobitkf.smoothing import _robust_kernels as k

    H, W = k.BONE_WINDOW, k.BONE_BAND
    for seed, every in ((6, 1), (7, 3)):
        rng = np.random.default_rng(seed)
        st = k.new_state(1, 2, 0)
        val, mult, cnt = st[5][0], st[6][0], st[7][0]
        hist: list[float] = []
        for i in range(3000):
            if i in (700, 720):  # a re-lock forgets the lengths learnt so far
                hist = []
                k._window_reset(val, cnt, 1)
            v = float(rng.choice([0.3, 0.31, 0.5]) if i % 7 == 0 else rng.normal(0.3, 0.02))
            v = v + 0.2 if 1500 <= i < 1800 else v  # a drift: the median leaves the band
            v = 0.4 if 2200 <= i < 2500 else v  # one length many times
            hist.append(v)
            k._bone_push(val, mult, cnt, 1, v)  # joint 1 of two
            n = int(cnt[1, k.W_N])
            assert n == min(len(hist), H)
            if i % every:
                continue
            assert k._window_median(val, mult, cnt, 1) == np.median(hist[-H:])
            # the band holds exactly the window's lengths between its bounds, the counts
            # the others
            w = np.array(hist[-H:])
            lo, hi = val[1, k.W_LO], val[1, k.W_HI]
            assert cnt[1, k.W_BELOW] == (w < lo).sum() and cnt[1, k.W_ABOVE] == (w > hi).sum()
            m = cnt[1, k.W_BAND]
            values, copies = np.unique(w[(w >= lo) & (w <= hi)], return_counts=True)
            np.testing.assert_array_equal(val[1, H : H + m], values)
            np.testing.assert_array_equal(mult[1, :m], copies)
            assert m <= W
        assert not val[0, : k.W_LO].any() and not mult[0].any() and not cnt[0].any()


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(1, 1600),
    distinct=st.integers(1, 50),
    drift=st.floats(-0.3, 0.3),
    resets=st.lists(st.integers(0, 1600), max_size=3),
)
def test_online_bone_window_median_property(seed, n, distinct, drift, resets):
    # any stream of lengths (few distinct values or many, drifting, re-locked): after
    # every push the window's median is np.median of the last BONE_WINDOW lengths
    from tobitkf.smoothing import _robust_kernels as k

    rng = np.random.default_rng(seed)
    levels = rng.uniform(0.1, 0.5, size=distinct)
    st_ = k.new_state(1, 1, 0)
    val, mult, cnt = st_[5][0], st_[6][0], st_[7][0]
    hist: list[float] = []
    for i in range(n):
        if i in resets:
            hist = []
            k._window_reset(val, cnt, 0)
        v = float(rng.choice(levels) + drift * i / 1600)
        hist.append(v)
        k._bone_push(val, mult, cnt, 0, v)
        if i % 11 == 0 or i == n - 1:
            assert k._window_median(val, mult, cnt, 0) == np.median(hist[-k.BONE_WINDOW :])


def test_kernels_run_as_plain_python_with_jit_disabled():
    # NUMBA_DISABLE_JIT=1 runs the same code uncompiled (for debugging): same numbers
    import os
    import subprocess
    import sys

    pos = _skeleton_motion(T=40, seed=11)
    chain = _hand_chain(get_topology("kinect_v2"))
    pos[22:32, chain] += [0.0, 0.6, 0.0]  # a sustained failure of the right hand: gates at work
    script = (
        "import sys, numpy as np\n"
        "from tobitkf.skeleton.sequence import SkeletonSequence\n"
        "from tobitkf.smoothing.robust import robust_smooth\n"
        "pos = np.load(sys.argv[1])\n"
        "seq = SkeletonSequence(positions=pos, topology='kinect_v2', fps=30.0)\n"
        "np.save(sys.argv[2], np.stack([robust_smooth(seq, offline=o).positions "
        "for o in (True, False)]))\n"
    )
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as tmp:
        np.save(Path(tmp) / "in.npy", pos)
        env = {**os.environ, "NUMBA_DISABLE_JIT": "1"}
        subprocess.run([sys.executable, "-c", script, str(Path(tmp) / "in.npy"),
                        str(Path(tmp) / "out.npy")], check=True, env=env)  # fmt: skip
        plain = np.load(Path(tmp) / "out.npy")
    seq = _seq(pos)
    for i, offline in enumerate((True, False)):
        out = robust_smooth(seq, offline=offline)
        assert out.metadata["diagnostics"]["rejected"][22:32, chain].mean() > 0.5
        np.testing.assert_allclose(plain[i], out.positions, rtol=0, atol=1e-12)


def test_importing_tobitkf_does_not_import_numba():
    import subprocess
    import sys

    code = (
        "import sys, tobitkf, tobitkf.smoothing.api, tobitkf.smoothing.robust\n"
        "assert 'numba' not in sys.modules, 'numba imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_online_a_parent_that_appears_late_does_not_hold_its_child_back():
    # a missing parent is no evidence against its child (only a rejected parent is): the
    # wrist is accepted and filtered from its first sample although its elbow appears only
    # at frame 10 (before issue 14 point 6 the chain rule kept it rejected, and the output
    # was the raw measurement, then NaN wherever the wrist was missing too)
    topo = get_topology("kinect_v2")
    ys = _skeleton_motion(T=60, seed=12)
    elbow, wrist = topo.index("ElbowLeft"), topo.index("WristLeft")
    ys[:10, elbow] = np.nan
    out = robust_smooth(_seq(ys), offline=False)
    rej = out.metadata["diagnostics"]["rejected"]
    assert not rej[:, wrist].any()
    assert np.isnan(out.positions[:10, elbow]).all()
    assert np.abs(out.positions[:, wrist] - ys[:, wrist]).max() < 0.01


def test_bone_lengths_equal_np_median_of_the_finite_lengths():
    # brute force: per body and joint, np.median of the finite distances to the parent
    rng = np.random.default_rng(13)
    parents = (-1, 0, 1, 1, 3)
    T, B = 41, 3
    pos = rng.normal(size=(T, B, 5, 3))
    pos[:, 1, 2] = pos[:, 1, 1] + [0.2, 0.0, 0.0]  # a constant bone: all lengths equal
    pos[rng.random((T, B, 5)) < 0.2] = np.nan  # odd and even counts of finite lengths
    pos[:, 2, 4] = np.nan  # a bone never seen
    L = bone_lengths(pos, parents)
    assert L.shape == (B, 5) and np.isnan(L[:, 0]).all() and np.isnan(L[2, 4])
    for b in range(B):
        for j in range(1, 5):
            d = np.linalg.norm(pos[:, b, j] - pos[:, b, parents[j]], axis=-1)
            d = d[np.isfinite(d)]
            if d.size:
                assert L[b, j] == np.median(d)
    np.testing.assert_array_equal(bone_lengths(pos[:, 1], parents), L[1])
