"""The speed gate measures the path a joint took about its parent, not the chord
(``_robust_kernels._shell_path``; docs/robust.md, Method, 1).

A bone does not shrink below the shortest length the bone gate accepts, so a joint that
turns about its parent goes around that ball, not across it. The path is checked
against the great-circle arc it tends to when the ball fills the sphere (an independent
closed form), its bounds (chord <= path <= arc, hypothesis) and the chord where the
ball is not in the way; the gate against a forearm that flips about its elbow across a
dropped frame (its chord inside a hand's speed gate for that time, its path not), with
the elbow accepted and rejected, and against a turn a wrist can make.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tobitkf.smoothing._robust_kernels import _shell_path
from tobitkf.smoothing.robust_gating import gate_measurements

FPS = 30.0


def _pair(a: float, b: float, theta: float) -> tuple[float, ...]:
    """A at distance a on the x axis, B at distance b at angle theta in the x-y plane."""
    return (a, 0.0, 0.0, b * math.cos(theta), b * math.sin(theta), 0.0)


def test_the_path_tends_to_the_great_circle_arc_as_the_ball_fills_the_sphere():
    for theta in (0.3, 1.0, 2.0, math.pi):
        a = 0.26
        path = _shell_path(*_pair(a, a, theta), a * (1 - 1e-12))
        assert path == pytest.approx(a * theta, rel=1e-5)


def test_the_chord_where_the_ball_is_not_in_the_way():
    args = _pair(0.26, 0.26, 0.5)
    chord = math.dist(args[:3], args[3:])
    assert _shell_path(*args, 0.0) == chord  # no ball
    assert _shell_path(*args, -0.1) == chord
    # the chord's nearest point to the parent is 0.26 cos(0.25) = 0.252 away
    assert _shell_path(*args, 0.25) == chord
    assert _shell_path(*args, 0.26) == chord  # A on the ball's surface: no bound
    assert _shell_path(*_pair(0.26, 0.1, 2.0), 0.2) == math.dist(
        *np.reshape(_pair(0.26, 0.1, 2.0), (2, 3))
    )


@settings(max_examples=200, deadline=None)
@given(
    a=st.floats(0.05, 1.0),
    theta=st.floats(0.0, math.pi),
    f1=st.floats(0.0, 0.999),
    f2=st.floats(0.0, 0.999),
)
def test_the_path_lies_between_the_chord_and_the_arc_and_grows_with_the_ball(a, theta, f1, f2):
    args = _pair(a, a, theta)
    chord = math.dist(args[:3], args[3:])
    lo, hi = sorted((f1 * a, f2 * a))
    p_lo, p_hi = _shell_path(*args, lo), _shell_path(*args, hi)
    tol = 1e-12 * (1 + a)
    assert chord - tol <= p_lo <= p_hi + tol  # a larger ball is more in the way
    assert p_hi <= a * theta + tol  # the arc at the bone's own length keeps outside


def _arm(T: int = 40) -> np.ndarray:
    """shoulder (root) at the origin, elbow 25 cm along x, wrist 26 cm beyond it."""
    ys = np.zeros((T, 3, 3))
    ys[:, 1, 0] = 0.25
    ys[:, 2, 0] = 0.51
    return ys


def _gate(ys: np.ndarray, times: np.ndarray) -> np.ndarray:
    """The Kinect's arm and hand bounds (5 and 8 m/s), the robust bone tolerance."""
    return gate_measurements(
        ys, times, (-1, 0, 1), np.array([3.0, 5.0, 8.0]), margin=0.05,
        bone_len=np.array([np.nan, 0.25, 0.26]), bone_tol_abs=0.03, bone_tol_rel=0.15,
    )  # fmt: skip


def _dropped(T: int, frame: int) -> np.ndarray:
    """The times of T frames at 30 fps with ``frame`` dropped (a step of 2/30 s there)."""
    t = np.arange(T + 1) / FPS
    return np.delete(t, frame)


def test_a_forearm_flipped_about_its_elbow_across_a_dropped_frame_is_rejected():
    # the wrist turns 180 degrees about the still elbow: 52 cm of chord in 2/30 s, inside
    # a hand's 8 m/s (58 cm with the margin), but around the bone's shortest accepted
    # length (26 - 6.9 cm) the path is 67 cm: faster than a hand
    T = 30
    ys = _arm(T)
    ys[12:, 2, 0] = 0.25 - 0.26  # from frame 12 on, on the other side of the elbow
    times = _dropped(T, 12)  # frame 12 comes 2/30 s after frame 11
    acc = _gate(ys, times)
    assert acc[:12].all()
    assert not acc[12, 2]  # the flip
    assert acc[12, :2].all()
    # the speed gate grows with the time since the wrist's last accepted sample (rule 1):
    # a real flip, made faster than a hand can, is taken again a frame later
    assert acc[13:].all()


def test_a_wrist_flipped_about_its_rejected_elbow_stays_rejected_until_it_is_back():
    # the elbow breaks its bone at frame 5 (jumps 37 cm) and stays there; the wrist does
    # not move with it, so it stays accepted (rule 3). Across a dropped frame the wrist
    # flips about the elbow's (wrong) place, its bone kept: its chord is inside its own
    # step bound, its path is not, and with its parent rejected it waits for the parent
    T = 40
    ys = _arm(T)
    w = np.array([0.51, -0.26, 0.0])  # the elbow's wrong place, 26 cm from the wrist
    ys[5:30, 1] = w
    ys[15:30, 2] = 2 * w - ys[0, 2]  # the wrist's antipode about it
    ys[30:, 2] = ys[0, 2]
    times = _dropped(T, 15)
    acc = _gate(ys, times)
    assert not acc[5:30, 1].any() and acc[30:, 1].all()
    assert acc[5:15, 2].all()
    assert not acc[15:30, 2].any()
    assert acc[30:, 2].all()


@pytest.mark.parametrize("dropped", [False, True])
def test_a_turn_a_wrist_can_make_is_accepted(dropped):
    # 45 degrees about the elbow in one frame (20 cm of path: 6 m/s), or 90 degrees
    # across a dropped frame (41 cm in 2/30 s: 6 m/s)
    T = 30
    ys = _arm(T)
    turn = math.pi / 2 if dropped else math.pi / 4
    ys[12:, 2, 0] = 0.25 + 0.26 * math.cos(turn)
    ys[12:, 2, 1] = 0.26 * math.sin(turn)
    times = _dropped(T, 12) if dropped else np.arange(T) / FPS
    assert _gate(ys, times).all()


def test_what_the_parent_moved_carries_the_joint_part_of_the_way():
    # the elbow moves 15 cm (4.5 m/s) while the forearm turns 90 degrees back about it:
    # the wrist's own step is 28 cm, inside its gate; about the elbow it went 38 cm or
    # more, of which the elbow's motion accounts for 15
    T = 30
    ys = _arm(T)
    ys[12:, 1, 1] = 0.15
    ys[12:, 2] = ys[12:, 1] + np.array([0.0, -0.26, 0.0])
    assert _gate(ys, np.arange(T) / FPS).all()
