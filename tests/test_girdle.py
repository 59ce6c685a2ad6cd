"""The shoulder-girdle rule of the offline ``robust`` (docs/robust.md, Method 5): a
shoulder whose clavicle points far below the recording's own usual angle to the spine's
perpendicular is rejected; how far is the larger of ``shoulder_drop`` degrees and 3.5
robust standard deviations of the recording's own angle. Built on the generator's
Kinect motion, whose right shoulder is moved along a circle about the shoulder centre
(its bone length kept, its steps small: only this rule can see it)."""

from __future__ import annotations

import numpy as np
import pytest

import tobitkf as tk
from tobitkf.smoothing.robust_gating import (
    GIRDLE_SPREAD,
    clavicle_elevation,
    girdle_joints,
    reject_dropped_shoulders,
)

SM, SS, RIGHT = 1, 20, 8  # SpineMid, SpineShoulder, ShoulderRight in kinect_v2


def _lowered(pos, frames, degrees):
    """``pos`` with the right clavicle's elevation lowered by ``degrees`` (an array, one
    per frame of ``frames``), its length kept."""
    out = pos.copy()
    for t, d in zip(frames, degrees, strict=True):
        u = out[t, SS] - out[t, SM]
        u /= np.linalg.norm(u)
        c = out[t, RIGHT] - out[t, SS]
        along = c @ u
        perp = c - along * u
        phi = np.arctan2(along, np.linalg.norm(perp)) - np.radians(d)
        out[t, RIGHT] = out[t, SS] + np.linalg.norm(c) * (
            np.cos(phi) * perp / np.linalg.norm(perp) + np.sin(phi) * u
        )
    return out


def _recording(seed=0, rest=0.0, sway=0.0):
    """Ten seconds of the generator's motion with 3 mm of noise; the right clavicle
    lowered by ``rest`` degrees throughout, and swaying by ``sway`` degrees up and down
    (a 2 s period, lowest at frame 110)."""
    seq = tk.generate_motion("mixed", duration=10.0, seed=seed)
    rng = np.random.default_rng(seed)
    pos = seq.positions + rng.normal(0, 0.003, seq.positions.shape)
    T = len(pos)
    pos = _lowered(pos, range(T), rest + sway * np.cos(2 * np.pi * (np.arange(T) - 110) / 60))
    return seq.replace(positions=pos, tracking_state=None)


def _dropped(seq, degrees):
    """``seq`` with the right shoulder lowered by ``degrees`` more in frames 100-119,
    entering and leaving over 4 frames."""
    ramp = np.concatenate([np.linspace(0, 1, 5)[1:], np.ones(12), np.linspace(1, 0, 5)[:-1]])
    return seq.replace(positions=_lowered(seq.positions, range(100, 120), degrees * ramp))


def _rejected(seq, **kw):
    return tk.smooth(seq, "robust", **kw).metadata["diagnostics"]["rejected"][:, RIGHT]


@pytest.mark.parametrize("rest", [0.0, -25.0])
def test_a_shoulder_dropped_below_its_usual_angle_is_rejected(rest):
    """45 degrees below the recording's usual angle, whatever that angle is (a person
    or tracker whose shoulders rest low, ``rest``): rejected at the full drop, and
    nowhere else that the other gates do not reject; not with the rule off."""
    seq = _dropped(_recording(rest=rest), 45.0)
    with_rule, without = _rejected(seq), _rejected(seq, shoulder_drop=np.inf)
    assert with_rule[104:116].all()
    assert not without[100:120].any()
    assert not (with_rule & ~without)[np.r_[0:100, 120 : len(seq.positions)]].any()


def test_a_drop_within_the_threshold_is_kept():
    seq = _dropped(_recording(), 20.0)
    assert not _rejected(seq)[100:120].any()
    # the threshold is the parameter: 15 degrees catch it
    assert _rejected(seq, shoulder_drop=15.0)[104:116].all()


def test_a_recording_whose_angle_varies_widely_is_left_alone():
    """A clavicle angle that sways by 25 degrees up and down says little about a posture
    beyond that: 3.5 robust sds of it (about 90 degrees) are more than a 45-degree drop
    at the sway's lowest (70 degrees below the usual angle), which is then kept; with
    only the 30 degrees it would not be."""
    seq = _dropped(_recording(sway=25.0), 45.0)
    elev = clavicle_elevation(seq.positions[:, None], girdle_joints(seq.topology.joints))
    x = elev[:, 0, 1]
    spread = 1.4826 * np.median(np.abs(x - np.median(x)))
    assert GIRDLE_SPREAD * spread > 45.0 + 25.0
    assert not (_rejected(seq) & ~_rejected(seq, shoulder_drop=np.inf))[100:120].any()
    assert (usual := np.median(x)) - x[104:116].max() > 30.0, usual


def test_the_elevation_is_the_angle_built():
    """The clavicle elevation of a shoulder lowered by d degrees from the perpendicular
    is -d (the construction above, measured back)."""
    seq = _recording()
    flat = _lowered(seq.positions, range(len(seq.positions)), np.zeros(len(seq.positions)))
    u = flat[:, SS] - flat[:, SM]
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    # put the right clavicle in the perpendicular plane first, then lower it by 30
    c = flat[:, RIGHT] - flat[:, SS]
    c -= np.sum(c * u, axis=-1, keepdims=True) * u
    flat[:, RIGHT] = flat[:, SS] + c
    low = _lowered(flat, range(len(flat)), np.full(len(flat), 30.0))
    elev = clavicle_elevation(low[:, None], girdle_joints(seq.topology.joints))
    np.testing.assert_allclose(elev[:, 0, 1], -30.0, atol=1e-9)


def test_other_skeletons_and_too_few_samples_have_no_rule():
    assert girdle_joints(("a", "b")) is None
    seq = _dropped(_recording(), 45.0)
    girdle = girdle_joints(seq.topology.joints)
    # frames 76-104: the drop reaches 45 degrees in the last two (the rule would see it
    # in 30 frames: 75-104), but 29 accepted angles are too few to tell a usual angle
    acc = np.ones((29, 1, 25), dtype=bool)
    few = reject_dropped_shoulders(acc, seq.positions[76:105, None], girdle, 30.0)
    enough = reject_dropped_shoulders(acc[:1].repeat(30, 0), seq.positions[75:105, None],
                                      girdle, 30.0)  # fmt: skip
    assert not enough[-2:, 0, RIGHT].any()
    assert few.all()


def test_a_raised_shoulder_and_a_projection_are_not_judged():
    """The rule is one-sided (a shrug raises a shoulder far more than it can be
    depressed), and 3-D only (a projected clavicle's angle is not the body's)."""
    raised = _dropped(_recording(), -45.0)
    assert not (_rejected(raised) & ~_rejected(raised, shoulder_drop=np.inf)).any()
    seq = _dropped(_recording(), 45.0)
    px = seq.replace(positions=seq.positions[..., :2] * 500, units="px")
    np.testing.assert_array_equal(_rejected(px), _rejected(px, shoulder_drop=np.inf))
