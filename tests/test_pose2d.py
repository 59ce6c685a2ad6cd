"""Swaps undone before smoothing, the 2-D corruption model, and the pose2d benchmark."""

from __future__ import annotations

import numpy as np
import pytest

import tobitkf as tk
from tobitkf.evaluation.pose2d import (
    POSE2D_LABELS,
    Pose2DModel,
    _truth,
    corrupt_pose2d,
    run_pose2d_benchmark,
)
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology
from tobitkf.smoothing.untangle import (
    MAX_SWAP_S,
    settle,
    untangle,
    untangle_sequences,
    untangle_stats,
)

NAMES = ("neck", "left_wrist", "right_wrist")
TOPO = Topology.from_names(NAMES, edges=[(0, 1), (0, 2)])


def _people(T=200, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(T) / 30
    out = []
    for k, x0 in enumerate((300.0, 700.0)):
        base = np.stack([x0 + 40 * np.sin(t + k), 300 + 20 * np.cos(1.3 * t)], -1)
        pos = base[:, None] + np.array([[0, 0], [-80, 60], [80, 60]])
        pos[:, 1:, 1] += 30 * np.sin(2 * t + k)[:, None]
        noisy = pos + rng.normal(size=pos.shape) * 1.5
        out.append((pos, SkeletonSequence(noisy, TOPO, fps=30.0, units="px", body_id=k)))
    return out


def test_identity_swap_undone_exactly():
    (t0, a), (t1, b) = _people()
    pa, pb = a.positions.copy(), b.positions.copy()
    pa[50:70], pb[50:70] = b.positions[50:70], a.positions[50:70]
    (ua, ub), info = untangle_sequences([a.replace(positions=pa), b.replace(positions=pb)])
    np.testing.assert_array_equal(ua.positions, a.positions)
    np.testing.assert_array_equal(ub.positions, b.positions)
    assert np.flatnonzero(info[0]["identity_swapped"]).tolist() == list(range(50, 70))
    # through smooth: the smoothed tracks follow the true identities
    out = tk.smooth([a.replace(positions=pa), b.replace(positions=pb)], "kf", offline=True)
    for o, truth in zip(out, (t0, t1), strict=True):
        assert np.nanmax(np.linalg.norm(o.positions - truth, axis=-1)) < 15


def test_left_right_swap_undone_and_glitch_left_alone():
    (_, a), _ = _people()
    p = a.positions.copy()
    p[80:95, 1], p[80:95, 2] = a.positions[80:95, 2], a.positions[80:95, 1]
    p[120:123, 1] += [150, -90]  # a glitch of one wrist: not a swap
    p[140:146, 2] = np.nan  # a gap
    (u,), info = untangle_sequences([a.replace(positions=p)])
    swapped = info[0]["lr_swapped"]
    assert swapped.shape == (200, 1)
    assert np.flatnonzero(swapped[:, 0]).tolist() == list(range(80, 95))
    np.testing.assert_array_equal(u.positions[80:95], a.positions[80:95])
    np.testing.assert_array_equal(u.positions[120:123], p[120:123])
    # a glitch of one wrist just before a swap: the other wrist decides (both choices of
    # the glitched one are far from its last sample)
    q = a.positions.copy()
    q[77:80, 1] += [-90, 260]
    q[80:95, 1], q[80:95, 2] = a.positions[80:95, 2], a.positions[80:95, 1]
    (u,), info = untangle_sequences([a.replace(positions=q)])
    assert np.flatnonzero(info[0]["lr_swapped"][:, 0]).tolist() == list(range(80, 95))


def test_long_swaps_are_left_as_detected():
    """A 'swap' longer than MAX_SWAP_S is taken as right as detected (docstring)."""
    (_, a), (_, b) = _people(T=300)
    n = int(MAX_SWAP_S * 30) + 10
    pa, pb = a.positions.copy(), b.positions.copy()
    pa[100 : 100 + n], pb[100 : 100 + n] = b.positions[100 : 100 + n], a.positions[100 : 100 + n]
    (ua, _), info = untangle_sequences([a.replace(positions=pa), b.replace(positions=pb)])
    np.testing.assert_array_equal(ua.positions, pa)
    assert not info[0]["identity_swapped"].any()


def test_untangle_only_for_pixels_unless_asked():
    (_, a), (_, b) = _people()
    pa, pb = a.positions.copy(), b.positions.copy()
    pa[50:70], pb[50:70] = b.positions[50:70], a.positions[50:70]
    metres = [s.replace(positions=p / 1000, units="m") for s, p in ((a, pa), (b, pb))]
    out = tk.smooth(metres, "kf")
    assert "identity_swapped" not in out[0].metadata["diagnostics"]
    out = tk.smooth(metres, "kf", untangle=True)
    assert out[0].metadata["diagnostics"]["identity_swapped"][50:70].all()
    assert out[0].metadata["diagnostics"]["params"]["untangle"] is True
    with pytest.raises(ValueError, match="untangle"):
        tk.smooth(metres, "kf", untangle="yes")


def test_corruption_labels_say_what_was_done():
    m = Pose2DModel()
    truth = _truth("arms", 6.0, 3, m)
    noisy, labels = corrupt_pose2d(truth, m, seed=3)
    true = np.stack([s.positions for s in truth], 1)
    pos = np.stack([s.positions for s in noisy], 1)
    conf = np.stack([s.confidence for s in noisy], 1)
    err = np.linalg.norm(pos - true, axis=-1)
    clean = labels == 0
    # jitter only: 2-D Gaussian of at most 3 px per axis; 7 sd is never reached in 1e4 draws
    assert np.nanmax(err[clean]) < 7 * 3.0 * np.sqrt(2)
    assert np.all(np.isnan(pos[labels == 3])) and np.all(np.isnan(conf[labels == 3]))
    assert np.all(conf[labels == 1] <= 0.5) and np.all(conf[clean] >= 0.7)
    assert set(np.unique(labels)) <= set(POSE2D_LABELS)
    assert all(s.units == "px" and s.n_dims == 2 for s in noisy)


def test_default_beats_the_baselines_on_pose2d():
    """The issue's requirement: the default beats savgol, the 1€ filter and KF+RTS, and
    leaves clean samples within the noise (2 px per axis: 2.8 px rms distance)."""
    table = run_pose2d_benchmark(
        seed=1, duration=6.0, methods=["raw", "robust", "savgol", "one_euro", "kf+rts"]
    )
    robust = table.row("robust")["rmse_px"]
    for other in ("savgol", "one_euro", "kf+rts", "raw"):
        assert robust < table.row(other)["rmse_px"], other
    assert table.row("robust")["clean_px"] < 2.0 * np.sqrt(2)
    assert table.label_counts["id_swap"] + table.label_counts["lr_swap"] > 0


def test_cli_pose2d_benchmark():
    from click.testing import CliRunner

    from tobitkf.app.commands import app

    res = CliRunner().invoke(
        app, ["benchmark", "--kind", "pose2d", "--duration", "3", "--methods", "raw,robust",
              "--markdown"],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "| robust |" in res.output and "pixels" in res.output
    res = CliRunner().invoke(app, ["benchmark", "--kind", "pose2d", "--source", "x.bvh"])
    assert res.exit_code != 0 and "generator" in res.output


def test_metric_methods_report_their_sd_in_pixels():
    # the benchmark runs metric methods (tuned in metres) on metre-scaled keypoints and
    # converts back: the standard deviation goes back to pixels with the positions
    from tobitkf.evaluation.pose2d import _method

    seqs = [s for _, s in _people()]
    m = 0.002  # metres per pixel
    _, fn = _method("atkf", m)
    out = fn(seqs)
    ref = tk.smooth([s.replace(positions=s.positions * m, units="m") for s in seqs], "atkf")
    for o, r in zip(out, ref, strict=True):
        assert o.units == "px"
        np.testing.assert_allclose(o.positions, r.positions / m, rtol=1e-12)
        np.testing.assert_allclose(o.std, r.std / m, rtol=1e-12)


def _crossing(fps=15.0, T=30, cross=10.5, speed=60.0, seed=0):
    """A neck and two wrists at ``fps``: the wrists move at ``speed`` px per frame in
    opposite directions along x and cross at frame ``cross`` (a hand passing the other
    in front of the body), 4 px apart in y; the truth and a noisy SkeletonSequence."""
    rng = np.random.default_rng(seed)
    f = np.arange(T, dtype=float)
    x = speed * (f - cross)
    pos = np.zeros((T, 3, 2))
    pos[:, 0] = [400.0, 200.0]
    pos[:, 1, 0], pos[:, 1, 1] = 400.0 + x, 300.0
    pos[:, 2, 0], pos[:, 2, 1] = 400.0 - x, 304.0
    noisy = pos + rng.normal(size=pos.shape) * 1.5
    return pos, SkeletonSequence(noisy, TOPO, fps=fps, units="px")


def test_wrists_that_cross_in_a_frame_are_not_exchanged():
    """Two joints of a pair that pass each other between two frames (at 15 fps a
    hand's motion is tens of pixels per frame) are each nearer the other's last sample
    after the crossing: by position alone the crossing is an exchange, and the labels
    were then exchanged from there on. Each joint is compared with where its own motion
    takes it (its last sample moved on by its last step): nothing is exchanged."""
    truth, seq = _crossing()
    (u,), info = untangle_sequences([seq])
    assert not info[0]["lr_swapped"].any()
    np.testing.assert_array_equal(u.positions, seq.positions)
    assert np.abs(u.positions - truth).max() < 10  # each wrist on its own track
    # a real swap of the crossing wrists, after they crossed, is still undone exactly
    p = seq.positions.copy()
    p[16:21, 1], p[16:21, 2] = seq.positions[16:21, 2], seq.positions[16:21, 1]
    (u,), info = untangle_sequences([seq.replace(positions=p)])
    assert np.flatnonzero(info[0]["lr_swapped"][:, 0]).tolist() == list(range(16, 21))
    np.testing.assert_array_equal(u.positions, seq.positions)


def test_the_motion_across_a_gap_is_per_frame():
    """A wrist missing for two frames just before the crossing: its step across the gap
    is three frames' motion, and its velocity is that step over three frames (taken as
    one frame's, it would overshoot by two frames' motion at the crossing and read the
    crossing as an exchange)."""
    _, seq = _crossing(T=30, cross=12.5)
    p = seq.positions.copy()
    p[9:11, 1] = np.nan
    _, info = untangle_sequences([seq.replace(positions=p)])
    assert not info[0]["lr_swapped"].any()


def _untangle_pair(p, near=np.inf, **kw):
    """The left/right exchanges of one person's wrists ``p (T, 3, 2)`` offline, with
    the recording's own margin and ``max_frames``."""
    margin, _, max_frames = untangle_stats(p[:, None], np.arange(len(p)) / 30.0)
    _, exch = untangle(p[:, None], np.isnan(p[:, None]).any(-1), list(TOPO.symmetry), margin,
                       max_frames=max_frames, near=near, **kw)  # fmt: skip
    return exch[:, 0, 0]


def test_a_swap_that_begins_after_a_glitch_is_undone():
    """The 2-D benchmark's seed 1 at 15 fps: the second person's right hand tip
    glitches 114 px off for two frames (a plausible step at that rate), then the two
    hand tips are swapped for eight frames. Forwards in time the glitch is the right
    tip's reference when the swap starts, so neither choice is clearly nearer; the
    swapped samples become the references, and the swap's end looks like the start of
    one, exchanged for 23 frames of clean samples. Backwards in time the end is the
    start, with no glitch beside it. Offline both passes are made, and where they differ
    the labelling with the shorter tracks is kept: the frames the corruption swapped
    (and the glitch's two, which decide nothing either way)."""
    model = Pose2DModel()
    truth = _truth("mixed", 10.0, 1, model, 15.0)
    noisy, labels = corrupt_pose2d(truth, model, seed=1)
    ys = np.stack([s.positions for s in noisy], axis=1)
    pairs = list(noisy[0].topology.symmetry)
    joints = noisy[0].topology.joints
    p = next(k for k, (lj, _) in enumerate(pairs) if joints[lj] == "HandTipLeft")
    margin, near, max_frames = untangle_stats(ys, noisy[0].times())
    swapped = np.flatnonzero((labels[:, 1, pairs[p][0]] == 4) & (labels[:, 1, pairs[p][1]] == 4))
    assert swapped.tolist() == list(range(119, 127))
    runs = {}
    for both_ways in (False, True):
        order, exch = untangle(ys, np.isnan(ys).any(-1), pairs, margin, max_frames=max_frames,
                               near=near, both_ways=both_ways)  # fmt: skip
        assert (order[100:] == np.arange(2)).all()  # no identity switch there
        runs[both_ways] = np.flatnonzero(exch[:, 1, p]).tolist()
    assert runs[False] == list(range(127, 150))  # (what it was)
    # every swapped frame undone, and no frame exchanged where both tips are clean (the
    # glitch's own frames decide nothing either way)
    lj, rj = pairs[p]
    clean = np.flatnonzero((labels[:, 1, lj] == 0) & (labels[:, 1, rj] == 0))
    assert set(swapped) <= set(runs[True]) and not set(clean) & set(runs[True])


def test_a_recording_that_begins_swapped_is_undone():
    """Forwards in time the first frame is taken as right; a recording whose wrists are
    exchanged in its first ten frames then looked right there, and its whole rest
    exchanged (longer than ``MAX_SWAP_S``, so left as detected). Backwards, the swap is
    ten frames long. Both labellings give tracks of the same length: the one that
    exchanges fewer frames is kept."""
    (_, a), _ = _people(T=200)
    p = a.positions.copy()
    p[:10, 1], p[:10, 2] = a.positions[:10, 2], a.positions[:10, 1]
    assert not _untangle_pair(p, both_ways=False).any()
    assert np.flatnonzero(_untangle_pair(p)).tolist() == list(range(10))


def test_settle_keeps_the_shorter_tracks():
    """:func:`settle` by hand: two wrists 100 px apart and still, the passes differing
    over frames 3..8; the labelling whose tracks jump more (each jump 100 px per wrist)
    loses whichever pass made it; agreeing frames are kept; tracks of the same length
    within the margin: fewer exchanged frames."""
    T = 10
    yo = np.zeros((T, 1, 3, 2))
    yo[:, 0, 2, 0] = 100.0  # the right wrist at x = 100, the left at 0
    yo[3:6, 0, [1, 2]] = yo[3:6, 0, [2, 1]]  # exchanged as detected in 3..5
    right = np.zeros((T, 1, 1), bool)
    right[3:6] = True
    wrong = np.zeros((T, 1, 1), bool)
    wrong[6:8] = True  # another pass: exchanged 6..7 instead (two jumps more)
    left, rgt = np.array([1]), np.array([2])
    np.testing.assert_array_equal(settle(yo, right, wrong, left, rgt, 1.0), right)
    np.testing.assert_array_equal(settle(yo, wrong, right, left, rgt, 1.0), right)
    both = right | wrong  # agreeing with `right` where they agree
    np.testing.assert_array_equal(settle(yo, both, both, left, rgt, 1.0), both)
    still = np.zeros((T, 1, 3, 2))  # the wrists at one place: every labelling as long
    many, few = np.ones((T, 1, 1), bool), right
    np.testing.assert_array_equal(settle(still, many, few, left, rgt, 1.0), few)
    np.testing.assert_array_equal(settle(still, few, many, left, rgt, 1.0), few)
    # shorter by less than the margin is no shorter: fewer exchanged frames decide
    np.testing.assert_array_equal(settle(yo, right, wrong, left, rgt, 1000.0), wrong)
    np.testing.assert_array_equal(settle(yo, wrong, right, left, rgt, 1000.0), wrong)


@pytest.mark.parametrize("people", [1, 2])
@pytest.mark.parametrize("method", ["robust", "robust_online", "kf"])
def test_a_recording_with_no_frame_in_pixels(people, method):
    """No frame: nothing to untangle, and every method returns no frame, as it does for
    the same recording in metres (the untangling's run lengths once failed to reshape
    an empty array)."""
    seqs = [SkeletonSequence(np.zeros((0, 3, 2)), TOPO, fps=30.0, units="px", body_id=k)
            for k in range(people)]  # fmt: skip
    out = tk.smooth(seqs, method=method)
    assert [o.positions.shape for o in out] == [(0, 3, 2)] * people
    _, info = untangle_sequences(seqs)
    assert info[0]["lr_swapped"].shape == (0, 1)
