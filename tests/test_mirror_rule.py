"""The online bone gate's mirror rule (docs/robust.md, Method 6).

A stream that starts while a limb is failing teaches the online bone gate a wrong length
for it; without a second reference, the limb's good samples that follow are rejected as
broken bones until ``max_reject`` (2 s) has passed. The rule compares the length learnt
for a bone with the one learnt for its mirror image and, when the two disagree, also
accepts a sample that keeps the mirror's length.
"""

from __future__ import annotations

import numpy as np
import pytest

import tobitkf as tk
from tobitkf.skeleton.topology import Topology, get_topology
from tobitkf.smoothing.robust_gating import mirror_bones

CHAIN = ("WristRight", "HandRight", "HandTipRight", "ThumbRight")
OFFSET = np.array([0.0, 0.4, 0.0])  # a hand chain put 40 cm off, its own bones intact


def test_mirror_bones_pairs_the_bones_that_mirror_each_other():
    topo = get_topology("kinect_v2")
    names = topo.joints
    m = mirror_bones(topo)
    pairs = {names[a]: (names[b] if b >= 0 else None) for a, b in enumerate(m)}
    # the parents are a left/right pair too, or the same joint
    assert pairs["ElbowLeft"] == "ElbowRight" and pairs["ElbowRight"] == "ElbowLeft"
    assert pairs["ShoulderLeft"] == "ShoulderRight"  # both on SpineShoulder
    assert pairs["HipRight"] == "HipLeft"  # both on SpineBase
    assert pairs["ThumbLeft"] == "ThumbRight"
    for trunk in ("SpineBase", "SpineMid", "Neck", "Head", "SpineShoulder"):
        assert pairs[trunk] is None
    # a pair hung on different trunk joints: its bones are not each other's mirror
    odd = Topology("odd", ("root", "neck", "left", "right"), (-1, 0, 0, 1), ((2, 3),))
    assert mirror_bones(odd).tolist() == [-1, -1, -1, -1]


@pytest.mark.parametrize("n_dims, rejected", [(3, False), (2, True)])
def test_a_projection_has_no_mirror_rule(n_dims, rejected):
    # the first failure folds the forearm to a fifth of its length; in 3-D the good
    # samples after it come back at once, in 2-D (where the two sides' projected lengths
    # differ with the pose: no second reference) they wait for max_reject as before
    clean = tk.generate_motion("arms", duration=4.0, seed=0)
    names = clean.topology.joints
    idx = [names.index(n) for n in CHAIN]
    y = clean.positions.copy()
    fold = 0.8 * (y[3:25, idx[0]] - y[3:25, names.index("ElbowRight")])
    y[3:25, idx] -= fold[:, None]
    out = tk.smooth(tk.SkeletonSequence(y[..., :n_dims], clean.topology, fps=30.0),
                    "robust_online")  # fmt: skip
    rej = out.metadata["diagnostics"]["rejected"][25:45, idx[0]]
    assert (rej.sum() >= 15) if rejected else (rej.sum() <= 3)


def _stream(
    first: slice,
    later: slice | None = None,
    other: slice | None = None,
    no_left: bool = False,
    long_left: float = 0.0,
    other_offset: tuple[float, float, float] = (0.25, 0.0, 0.0),
):
    clean = tk.generate_motion("arms", duration=4.0, seed=0)
    idx = [clean.topology.joints.index(n) for n in CHAIN]
    y = clean.positions + np.random.default_rng(0).normal(scale=0.003, size=clean.positions.shape)
    y[first, idx] += OFFSET
    if later is not None:
        y[later, idx] += OFFSET
    if other is not None:  # a failure of another size: the wrist's bone fits neither side
        y[other, idx] += other_offset
    if long_left:  # the left forearm longer by this much
        names = clean.topology.joints
        left = [names.index(n.replace("Right", "Left")) for n in CHAIN]
        d = y[:, left[0]] - y[:, names.index("ElbowLeft")]
        y[:, left] += (long_left * d / np.linalg.norm(d, axis=-1, keepdims=True))[:, None]
    if no_left:  # the mirror's bone is never seen, so never learnt
        y[:, [clean.topology.joints.index(n.replace("Right", "Left")) for n in CHAIN]] = np.nan
    out = tk.smooth(tk.SkeletonSequence(y, clean.topology, fps=30.0), "robust_online")
    return clean, out, idx[0]


def test_good_samples_after_a_failure_at_the_start_are_accepted():
    # frames 3-24 failed: the wrist's bone is learnt (15 samples) mostly from the failure
    clean, out, w = _stream(slice(3, 25), slice(60, 80))
    rej = out.metadata["diagnostics"]["rejected"][:, w]
    err = np.linalg.norm(out.positions[:, w] - clean.positions[:, w], axis=-1)
    # the good samples that follow: accepted (the confirmation may hold one or two)
    assert rej[25:45].sum() <= 3
    assert np.sqrt(np.mean(err[30:50] ** 2)) < 0.02  # the 40 cm failure is left behind
    # a failure once both lengths agree is still rejected throughout
    assert rej[60:80].all()


def test_a_bone_that_fits_neither_side_is_still_rejected():
    # while the learnt length is still the failure's, a sample that keeps neither it nor
    # the mirror's is a broken bone
    _, out, w = _stream(slice(3, 25), other=slice(30, 34))
    assert out.metadata["diagnostics"]["rejected"][30:34, w].all()


def test_lengths_that_agree_leave_the_gate_as_it_was():
    # the left forearm 6 cm longer (within the right one's tolerance, 3 cm + 15 %): a
    # right wrist 13 cm too far out fits the left length, and is still rejected
    _, out, w = _stream(slice(0, 0), long_left=0.06, other=slice(30, 34), other_offset=(0, 0, 0.25))
    assert out.metadata["diagnostics"]["rejected"][30:34, w].all()


def test_without_the_mirror_length_the_own_one_decides():
    _, out, w = _stream(slice(0, 0), later=slice(60, 80), no_left=True)
    rej = out.metadata["diagnostics"]["rejected"][:, w]
    assert rej[60:80].all() and not rej[20:60].any()


@pytest.mark.parametrize("method", ["robust_online"])
def test_live_takes_the_same_decisions(method):
    clean, out, _ = _stream(slice(3, 25))
    idx = [clean.topology.joints.index(n) for n in CHAIN]
    y = clean.positions + np.random.default_rng(0).normal(scale=0.003, size=clean.positions.shape)
    y[3:25, idx] += OFFSET
    live = tk.LiveSmoother(clean.topology, method=method, fps=30.0)
    got = np.stack([live.update(f) for f in y])
    np.testing.assert_array_equal(got, out.positions)


@pytest.mark.parametrize("fps", [15.0, 30.0])
def test_the_bone_gate_starts_after_half_a_second_at_a_low_rate(fps):
    # a hand chain fails from frame 8 on. At 15 fps the gate has its lengths after 0.5 s
    # of them (at its refresh of frame 10; 8 good, 2 failed: the median is good) instead
    # of after 15 (a second), and the failure is rejected from frame 12 (the frames
    # before are its confirmation); 15 frames later without this. At 30 fps, 15 frames
    # are 0.5 s: as before, the failure passes until the gate starts at frame 15 (where
    # the failure's own window is one short, the left forearm's length stands in).
    clean = tk.generate_motion("arms", duration=3.0, seed=0, fps=fps)
    idx = [clean.topology.joints.index(n) for n in CHAIN]
    y = clean.positions.copy()
    y[8:28, idx] += OFFSET
    out = tk.smooth(tk.SkeletonSequence(y, clean.topology, fps=fps), "robust_online")
    rej = out.metadata["diagnostics"]["rejected"][:, idx[0]]
    if fps < 30:
        assert rej[12:28].all()
    else:
        assert not rej[9:15].any()


@pytest.mark.parametrize("fps", [30.0, 240.0])
def test_a_limb_without_a_length_yet_borrows_its_mirrors(fps):
    # the right hand chain is not seen for its first 0.7 s and then appears 40 cm further
    # along the forearm for 0.7 s: its own bone has no length yet (nothing accepted), the
    # left forearm's is
    # learnt by then and stands in for it, so the failure is rejected from its first
    # sample, and the good samples after it are accepted. Without the borrowed length
    # the failure passes and its length is learnt.
    clean = tk.generate_motion("arms", duration=3.0, seed=0, fps=fps)
    idx = [clean.topology.joints.index(n) for n in CHAIN]
    y = clean.positions + np.random.default_rng(1).normal(scale=0.003, size=clean.positions.shape)
    a, b = int(0.7 * fps), int(1.4 * fps)
    names = clean.topology.joints
    d = y[a:b, idx[0]] - y[a:b, names.index("ElbowRight")]
    y[:a, idx] = np.nan
    y[a:b, idx] += (0.4 * d / np.linalg.norm(d, axis=-1, keepdims=True))[:, None]
    out = tk.smooth(tk.SkeletonSequence(y, clean.topology, fps=fps), "robust_online")
    rej = out.metadata["diagnostics"]["rejected"][:, idx[0]]
    assert rej[a:b].all()
    settled = slice(b + int(0.2 * fps), b + int(0.7 * fps))  # after the confirmation
    assert not rej[settled].any()
    err = np.linalg.norm(out.positions[settled, idx[0]] - clean.positions[settled, idx[0]], axis=-1)
    assert np.sqrt(np.mean(err**2)) < 0.02


def test_after_a_relock_the_own_length_is_learnt_again():
    # a joint re-locked after max_reject (the measurement trusted over the old length)
    # does not borrow the mirror's length while it learns its own again: the right
    # forearm measured half as long again from 0.5 s on (another person's arm, say) is rejected
    # until the re-lock at 2.5 s and accepted from then on
    fps = 30.0
    clean = tk.generate_motion("arms", duration=5.0, seed=0, fps=fps)
    names = clean.topology.joints
    idx = [names.index(n) for n in CHAIN]
    y = clean.positions.copy()
    d = y[:, idx[0]] - y[:, names.index("ElbowRight")]
    y[15:, idx] += 0.5 * d[15:, None]
    out = tk.smooth(tk.SkeletonSequence(y, clean.topology, fps=fps), "robust_online")
    rej = out.metadata["diagnostics"]["rejected"][:, idx[0]]
    assert rej[16:70].all()
    assert not rej[80:].any()
