"""The bone gate's blame: a joint that breaks its bones to two children that stayed put
is the one that failed (gate rule 2, docs/robust.md "Method")."""

from __future__ import annotations

import numpy as np
import pytest

from test_robust import _seq, _skeleton_motion
from tobitkf.skeleton.sequence import TrackingState
from tobitkf.skeleton.topology import get_topology
from tobitkf.smoothing.robust import robust_smooth
from tobitkf.smoothing.robust_gating import gate_measurements

FPS = 30.0
#: r - a; a's children b and c; b's child d and c's child e (b and c are inner joints)
PARENTS = (-1, 0, 1, 1, 2, 3)
REST = np.array([
    [0.0, 0.0, 0.0],
    [0.25, 0.0, 0.0],
    [0.35, 0.15, 0.0],
    [0.35, -0.15, 0.0],
    [0.45, 0.15, 0.0],
    [0.45, -0.15, 0.0],
])  # fmt: skip
LENGTHS = np.array([np.nan, 0.25, np.hypot(0.1, 0.15), np.hypot(0.1, 0.15), 0.1, 0.1])
A, B, C, D, E = 1, 2, 3, 4, 5
#: a turned about r so that it moves 20 cm, its own bone kept (its one-frame step)
TURN = 2 * np.arcsin(0.1 / 0.25)
A_OFF = 0.25 * np.array([np.cos(TURN), 0.0, np.sin(TURN)])


def _gate(ys: np.ndarray, parents=PARENTS, vmax_a: float = 3.0, vmax: float = 3.0,
          max_reject: float = np.inf, fps: float = FPS, inferred=None) -> np.ndarray:  # fmt: skip
    """gate_measurements with every joint's speed bound ``vmax`` m/s, a's ``vmax_a``."""
    vmax = np.full(len(parents), vmax)
    vmax[A] = vmax_a
    return gate_measurements(
        ys, np.arange(len(ys)) / fps, parents, vmax, margin=0.05,
        bone_len=LENGTHS[: len(parents)], bone_tol_abs=0.03, bone_tol_rel=0.15,
        max_reject=max_reject, inferred=inferred,
    )  # fmt: skip


def _track(T: int = 40, J: int = 6) -> np.ndarray:
    return np.repeat(REST[None, :J], T, axis=0).copy()


@pytest.mark.parametrize("vmax_a", [3.0, 6.0])
def test_a_joint_that_breaks_two_bones_to_still_children_is_the_one_rejected(vmax_a):
    # a moves 20 cm (its bone to r kept) for frames 10-29 and b, c stay: both of a's
    # bones to them break. At 3 m/s a's own speed gate rejects the first frame and the
    # rule keeps a rejected afterwards; at 6 m/s the step passes a's speed gate, and the
    # rule rejects a from its first frame. Either way b and c (and d, e) stay accepted.
    ys = _track()
    ys[10:30, A] = A_OFF
    acc = _gate(ys, vmax_a=vmax_a)
    assert not acc[10:30, A].any()
    assert acc[:10].all() and acc[30:].all()
    assert acc[:, [B, C, D, E]].all()
    # backwards in time the failure's end is its start: the same verdict
    back = _gate(ys[::-1].copy(), vmax_a=vmax_a)[::-1]
    np.testing.assert_array_equal(back, acc)


def test_one_still_child_is_not_enough():
    # c moves with a (its bone kept; every step inside the speed gates): only b's bone
    # breaks, and b is blamed as before
    ys = _track()
    ys[10:30, A] = A_OFF
    ys[10:30, [C, E]] += A_OFF - REST[A]
    acc = _gate(ys, vmax_a=6.0, vmax=6.0)
    assert acc[:, [A, C, E]].all()
    assert not acc[10:30, B].any()


@pytest.mark.parametrize("step", [0.2, 0.12])
def test_children_that_fail_together_are_still_blamed(step):
    # b and c (with d and e) step off together and stay there: 20 cm, out of their speed
    # gate (3 m/s for a frame + 5 cm), or 12 cm, inside it. a made no step, so the
    # broken bones are b's and c's
    ys = _track()
    ys[10:30, [B, C, D, E], 1] += step
    acc = _gate(ys)
    assert acc[:, [0, A]].all()
    assert not acc[10:30, [B, C]].any()


def test_children_that_jumped_or_were_failing_say_nothing_of_their_parent():
    # a's step passes its 6 m/s gate; b and c break their bones to it, but b and c
    # jumped out of their own speed gates in the same frame: a is accepted
    ys = _track()
    ys[10:30, A] = A_OFF
    ys[10:30, [B, C, D, E], 1] += 0.2
    acc = _gate(ys, vmax_a=6.0)
    assert acc[:, A].all() and not acc[10:30, [B, C]].any()
    # b and c have been 30 cm off, rejected, since frame 5 and stay put; a's step at
    # frame 10 breaks no bone that was right
    ys = _track()
    ys[5:30, [B, C, D, E], 2] += 0.3
    ys[10:30, A] = A_OFF
    acc = _gate(ys, vmax_a=6.0)
    assert acc[:, A].all() and not acc[5:30, [B, C]].any()


def test_a_child_that_flipped_about_its_parent_does_not_count():
    # b flips 30 cm about a's place to its mirror side (its bone kept) in the frame where
    # a moves: out of b's speed gate, so b did not go on as before, and only c is left
    ys = _track()
    ys[10:30, A] = A_OFF
    ys[10:30, B] = REST[A] + np.array([0.1, -0.15, 0.0])
    ys[10:30, D] = ys[10:30, B] + np.array([0.1, 0.0, 0.0])
    acc = _gate(ys, vmax_a=6.0)
    assert acc[10, A]
    # b flipped at frame 5 and was rejected there (its speed gate): at frame 6, where a
    # moves, b has not been accepted since, and does not count either
    ys = _track()
    ys[5:, B] = REST[A] + np.array([0.1, -0.15, 0.0])
    ys[5:, D] = ys[5:, B] + np.array([0.1, 0.0, 0.0])
    ys[6:30, A] = A_OFF
    acc = _gate(ys, vmax_a=6.0)
    assert not acc[5, B] and acc[6, A]


def test_a_child_that_left_its_parents_last_place_does_not_count():
    # at 15 fps b's speed gate (3 m/s for 1/15 s + 5 cm) lets it step 20 cm; it does,
    # in the frame where a moves: b's bone to a is broken whichever place of a it is
    # measured to, so b went on differently, and only c is left as a witness against a
    ys = _track()
    ys[10:30, A] = A_OFF
    ys[10:30, [B, D], 1] += 0.2
    acc = _gate(ys, vmax_a=6.0, fps=15.0)
    assert acc[:, A].all()
    assert not acc[10:30, B].any()


def test_children_the_sensor_only_guessed_do_not_count():
    # as the first test, but b and c are INFERRED (a sensor's guesses, which it keeps
    # still while it does not see them): no witnesses, and the broken bones are theirs
    ys = _track()
    ys[10:30, A] = A_OFF
    inferred = np.zeros(ys.shape[:2], dtype=bool)
    inferred[:, [B, C]] = True
    acc = _gate(ys, vmax_a=6.0, inferred=inferred)
    assert acc[:, A].all()
    assert not acc[10:30, [B, C]].any()
    inferred[:, C] = False  # one witness left: not enough either
    assert _gate(ys, vmax_a=6.0, inferred=inferred)[:, A].all()


def test_children_at_the_end_of_a_chain_do_not_count():
    # b and c without children of their own (a hand's tip and thumb): as before the
    # rule, the broken bones are theirs
    ys = _track(J=4)
    ys[10:30, A] = A_OFF
    acc = _gate(ys, parents=PARENTS[:4], vmax_a=6.0)
    assert acc[:, A].all()
    assert not acc[10:30, [B, C]].any()


def test_the_blame_ends_after_max_reject():
    # a stays off for 2 s: after max_reject (1 s) a is taken back (no lock-out), and from
    # there the broken bones are blamed on b and c again
    ys = _track(T=100)
    ys[10:70, A] = A_OFF
    acc = _gate(ys, max_reject=1.0)
    back = 10 + int(np.argmax(acc[10:, A]))
    assert 10 + FPS <= back <= 10 + FPS + 2
    assert not acc[back:70, B].any() and not acc[back:70, C].any()
    assert acc[:back, [B, C]].all()


@pytest.mark.parametrize("offline", [True, False])
def test_a_shifted_shoulder_centre_keeps_the_shoulders(offline):
    # Kinect's upper trunk (SpineShoulder, Neck, Head) turned 15 cm off about SpineMid for
    # 40 frames, the shoulders left where they are: the shoulder centre is rejected and
    # bridged, the shoulders stay measured (they were rejected before the rule)
    # an upright trunk: the shoulder centre 25 cm above SpineMid, the clavicles 17 cm
    truth = _skeleton_motion(bones={
        "SpineShoulder": (0.0, 0.25, 0.0), "Neck": (0.0, 0.06, 0.0), "Head": (0.0, 0.1, 0.0),
        "ShoulderLeft": (-0.17, -0.02, 0.0), "ShoulderRight": (0.17, -0.02, 0.0),
    })  # fmt: skip
    topo = get_topology("kinect_v2")
    meas = truth + np.random.default_rng(2).normal(scale=0.003, size=truth.shape)
    mid, centre = topo.index("SpineMid"), topo.index("SpineShoulder")
    trunk = [centre, topo.index("Neck"), topo.index("Head")]
    shoulders = [topo.index("ShoulderLeft"), topo.index("ShoulderRight")]
    a, b = 100, 140
    # the trunk tilted 35 degrees sideways about SpineMid: the centre moves 15 cm towards
    # one shoulder, one clavicle shortens to 4 cm and the other lengthens to 31 cm
    ang = np.radians(35.0)
    R = np.array([[np.cos(ang), -np.sin(ang), 0.0], [np.sin(ang), np.cos(ang), 0.0],
                  [0.0, 0.0, 1.0]])  # fmt: skip
    rel = meas[a:b, trunk] - meas[a:b, mid, None]
    meas[a:b, trunk] = meas[a:b, mid, None] + rel @ R.T
    shift = np.linalg.norm(meas[a:b, centre] - truth[a:b, centre], axis=-1)
    assert shift.min() > 0.1
    out = robust_smooth(_seq(meas), offline=offline)
    rej = out.metadata["diagnostics"]["rejected"]
    assert rej[a:b, centre].mean() > 0.9
    assert not rej[:, shoulders].any()
    err = np.linalg.norm(out.positions[a:b, centre] - truth[a:b, centre], axis=-1)
    assert np.sqrt((err**2).mean()) < 0.3 * np.sqrt((shift**2).mean())
    # the same with the shoulders INFERRED throughout (left where the sensor guessed them:
    # inferred_bones off): guesses are no witnesses, and the shoulders are blamed again
    states = np.full(meas.shape[:2], TrackingState.TRACKED, dtype=np.int8)
    states[:, shoulders] = TrackingState.INFERRED
    out = robust_smooth(_seq(meas, states), offline=offline, inferred_bones=False)
    rej = out.metadata["diagnostics"]["rejected"]
    assert rej[a:b, centre].mean() < 0.1  # its first frame may be its speed gate's
    assert rej[a:b, shoulders].mean() > 0.9
