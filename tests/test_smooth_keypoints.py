"""Smoothing any keypoint sequence: 2-D, units other than metres, confidence."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import tobitkf as tk
from tobitkf.skeleton.sequence import SampleState, SkeletonSequence
from tobitkf.skeleton.topology import Topology
from tobitkf.smoothing.api import method_names
from tobitkf.smoothing.robust_scale import recording_gates

NAMES = ("head", "neck", "left_hand", "right_hand", "tail")
EDGES = [("neck", "head"), ("neck", "left_hand"), ("neck", "right_hand"), ("neck", "tail")]
TOPO = Topology.from_names(NAMES, edges=EDGES)


def _track(T=240, D=2, noise=2.0, seed=0):
    """Smooth motion in pixels plus white noise of ``noise`` px."""
    rng = np.random.default_rng(seed)
    t = np.arange(T) / 30.0
    centre = np.stack([300 + 60 * np.sin(0.8 * t), 200 + 30 * np.cos(0.5 * t)], -1)
    offsets = np.array([[0, -40], [0, 0], [-35, 10], [35, 10], [0, 60]], dtype=float)
    wave = 15 * np.sin(2 * np.pi * 0.7 * t)[:, None, None] * np.array([[0, 0], [0, 0],
                                                                      [0, 1], [0, -1],
                                                                      [1, 0]])  # fmt: skip
    truth = centre[:, None] + offsets[None] + wave
    if D == 3:
        truth = np.concatenate([truth, 500 + 10 * np.sin(t)[:, None, None] + 0 * truth[..., :1]],
                               -1)  # fmt: skip
    return truth, truth + rng.normal(size=truth.shape) * noise


@pytest.mark.parametrize("method", method_names())
def test_2d_equals_3d_with_a_zero_axis(method):
    """A 2-D sequence smooths exactly as the same sequence with a third axis of zeros."""
    _, y = _track()
    y = y / 1000  # metres: every method's parameters apply as they are
    y[30:35, 2] = np.nan
    two = SkeletonSequence(y, TOPO, fps=30.0, units="m")
    three = SkeletonSequence(np.concatenate([y, 0 * y[..., :1]], -1), TOPO, fps=30.0)
    kw2 = kw3 = {}
    if method in ("tkf", "tkfc"):  # the Kinect's default limits are 3-D: give 2 (and 3)
        kw2 = {"lower": (-3.0, -1.5), "upper": (3.0, 3.0)}
        kw3 = {"lower": (-3.0, -1.5, -np.inf), "upper": (3.0, 3.0, np.inf)}
    a, b = tk.smooth(two, method, **kw2), tk.smooth(three, method, **kw3)
    assert a.positions.shape == y.shape
    np.testing.assert_array_equal(a.positions, b.positions[..., :2])
    np.testing.assert_array_equal(a.sample_state, b.sample_state)


@pytest.mark.parametrize("method", ["robust", "robust_online", "kf", "one_euro"])
def test_millimetres_are_smoothed_as_metres(method):
    _, y = _track(D=3, noise=10.0)  # read as mm
    mm = SkeletonSequence(y, TOPO, fps=30.0, units="mm")
    m = SkeletonSequence(y / 1000, TOPO, fps=30.0, units="m")
    # exact: the fixed noise (a fitted one moves with rounding-level input changes within
    # the optimiser's tolerance: tests/test_robust_fit.py)
    kw = {"noise": "fixed"} if method == "robust" else {}
    a, b = tk.smooth(mm, method, **kw), tk.smooth(m, method, **kw)
    assert a.units == "mm"
    np.testing.assert_allclose(a.positions / 1000, b.positions, rtol=0, atol=1e-12)
    if b.std is not None:
        np.testing.assert_allclose(a.std / 1000, b.std, rtol=1e-9)


@pytest.mark.parametrize("method", ["robust", "robust_online"])
def test_recording_gates_are_equivariant(method):
    """Gates taken from the recording: scaling and shifting the data scales and shifts
    the output the same way (the physical gates would not)."""
    _, y = _track()
    y[100, 2] += [90, -70]
    kw = {"noise": "fixed"} if method == "robust" else {}  # exact (as above)
    base = tk.smooth(SkeletonSequence(y, TOPO, fps=30.0, units="px"), method, **kw)
    for k, shift in ((0.01, 5.0), (37.0, -1000.0)):
        out = tk.smooth(SkeletonSequence(y * k + shift, TOPO, fps=30.0, units="px"), method,
                        **kw)  # fmt: skip
        np.testing.assert_allclose((out.positions - shift) / k, base.positions, atol=1e-7)
        np.testing.assert_array_equal(out.sample_state, base.sample_state)


def test_recording_noise_estimate():
    """noise_sd from the second differences: white noise of 2 px on smooth motion.
    Per joint the MAD estimate over n = 2 axes x 3998 second differences has a relative
    standard error of about 1.17 / sqrt(n) = 1.3 % (more with the correlation of
    neighbouring second differences, under 2 %); 5 % is beyond 2.5 of them."""
    _, y = _track(T=4000, noise=2.0, seed=3)
    g = recording_gates(y[:, None], np.full(4000, 1 / 30), TOPO.parents, 2)
    np.testing.assert_allclose(g["noise_sd"], 2.0, rtol=0.05)
    assert np.all(g["v_max"] > 0) and g["margin"] > 0 and np.isfinite(g["bone_tol_rel"])


@pytest.mark.parametrize("method", ["robust", "robust_online"])
def test_noise_free_pixels_get_a_finite_sd(method):
    """A track with no noise at all (constant velocity, exact pixels): the fit finds next
    to no noise, and the smoother's variance, a rounding error away from zero, gives an
    sd of about zero, not NaN and a numpy warning (found by hand, 2-D and pixels)."""
    t = np.arange(50.0)
    x = np.stack(
        [np.tile(640 + 0.5 * t[:, None], (1, 4)), np.tile(144 + np.arange(4) * 13.0, (50, 1))],
        -1,
    )
    seq = SkeletonSequence(positions=x, topology=Topology.from_names(list("abcd")), fps=30,
                           units="px")  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = tk.smooth(seq, method=method)
    assert np.isfinite(out.std).all()
    assert np.all(out.std >= 0) and out.std.max() < 1e-3  # px: the track has no noise
    np.testing.assert_allclose(out.positions, x, atol=1e-6)


def test_pixel_glitches_removed_clean_samples_kept():
    truth, y = _track(noise=2.0, seed=1)
    glitch = [(40, 2), (41, 2), (90, 0), (150, 4), (151, 4), (152, 4)]
    for t, j in glitch:
        y[t, j] += [120, -80]
    out = tk.smooth(SkeletonSequence(y, TOPO, fps=30.0, units="px"))
    rej = out.metadata["diagnostics"]["rejected"]
    for t, j in glitch:
        assert rej[t, j], (t, j)
        assert np.linalg.norm(out.positions[t, j] - truth[t, j]) < 10
    clean = np.ones(rej.shape, bool)
    for t, j in glitch:
        clean[t, j] = False
    assert rej[clean].mean() < 0.01
    # clean samples: the error is below the noise (2 px per axis -> 2.8 px rms distance)
    err = np.linalg.norm(out.positions - truth, axis=-1)[clean]
    assert np.sqrt(np.mean(err**2)) < 2.0


def test_confidence_below_threshold_is_missing():
    _, y = _track()
    conf = np.full(y.shape[:2], 0.9)
    conf[50:53, 1] = 0.05
    s = SkeletonSequence(y, TOPO, fps=30.0, confidence=conf)
    out = tk.smooth(s, "kf")
    assert np.all(SampleState.filled(out.sample_state[50:53, 1]))
    assert np.all(out.sample_state[:50] == SampleState.MEASURED)
    assert out.metadata["diagnostics"]["params"]["min_confidence"] == 0.1
    kept = tk.smooth(s, "kf", min_confidence=0.0)
    assert np.all(kept.sample_state == SampleState.MEASURED)
    with pytest.raises(ValueError, match="min_confidence"):
        tk.smooth(s, "kf", min_confidence=1.5)


def test_confidence_weighs_the_robust_smoother():
    _, y = _track()
    s = SkeletonSequence(y, TOPO, fps=30.0, units="px", confidence=np.ones(y.shape[:2]))
    plain = tk.smooth(s.replace(confidence=None))
    np.testing.assert_array_equal(tk.smooth(s).positions, plain.positions)  # weight 1
    moved = y.copy()
    moved[60, 3] += [6, 0]  # a small, plausible error
    conf = np.ones(y.shape[:2])
    pulls = []
    for c in (1.0, 0.5, 0.2):
        conf[60, 3] = c
        out = tk.smooth(s.replace(positions=moved, confidence=conf.copy()))
        ref = tk.smooth(s.replace(confidence=conf.copy()))
        assert not out.metadata["diagnostics"]["rejected"][60, 3]
        pulls.append(out.positions[60, 3, 0] - ref.positions[60, 3, 0])
    assert pulls[0] > pulls[1] > pulls[2] > 0  # less confidence, less pull


def test_robust_smooth_direct_form_takes_2d():
    _, y = _track()
    s = SkeletonSequence(y, TOPO, fps=30.0, units="px")
    from tobitkf.smoothing.robust import robust_smooth

    a = robust_smooth(s)
    np.testing.assert_allclose(a.positions, tk.smooth(s).positions, atol=1e-9)


def test_live_2d_equals_batch_online():
    """A 2-D stream gives the batch robust_online result (same parameters)."""
    _, y = _track(T=90)
    params = {"v_max": 400.0, "margin": 10.0, "noise_sd": 2.0, "speed_sd": 60.0,
              "bone_tol_abs": 10.0, "gates": "physical"}  # fmt: skip
    batch = tk.smooth(SkeletonSequence(y, TOPO, fps=30.0, units="px"), "robust_online",
                      untangle=False, **params)  # fmt: skip
    live = tk.LiveSmoother(TOPO, "robust_online", fps=30.0, **params)
    out = np.stack([live.update(frame) for frame in y])
    assert out.shape == y.shape
    np.testing.assert_allclose(out, batch.positions, atol=1e-9)
    with pytest.raises(ValueError, match="2 coordinates"):
        live.update(np.zeros((len(NAMES), 3)))


@pytest.mark.parametrize("T", [1, 2])
def test_a_recording_too_short_to_read_its_noise_gets_no_sd(T):
    """In pixels the noise is read from second differences: with fewer than three frames
    nothing measured it, so the sd is NaN (with a warning), not the floor's ~0; a given
    noise_sd, or lengths in metres (the physical constants), give one."""
    rng = np.random.default_rng(T)
    pos = 300 + rng.normal(0, 2, (T, 4, 2))
    seq = tk.SkeletonSequence(pos, tk.Topology.from_names(list("abcd")), fps=30.0, units="px")
    with pytest.warns(UserWarning, match="three frames in a row"):
        out = tk.smooth(seq)
    assert np.isnan(out.std).all() and np.isfinite(out.positions).all()
    assert (tk.smooth(seq, noise_sd=2.0).std > 0.5).all()
    metres = seq.replace(positions=np.concatenate([pos / 1000, np.ones((T, 4, 1))], -1), units="m")
    assert (tk.smooth(metres).std > 1e-4).all()
    three = seq.replace(positions=300 + rng.normal(0, 2, (3, 4, 2)))
    assert (tk.smooth(three).std > 0.1).all()


def test_the_assumed_frame_rate_is_in_the_provenance():
    """Without fps or timestamps the speeds (px/s) are per 1/30 s: the provenance says
    so, and says nothing when the rate was given."""
    rng = np.random.default_rng(8)
    seq = tk.SkeletonSequence(300 + rng.normal(0, 2, (40, 4, 2)),
                              tk.Topology.from_names(list("abcd")), units="px")  # fmt: skip
    assert tk.smooth(seq).metadata["provenance"]["assumed_fps"] == 30.0
    assert "assumed_fps" not in tk.smooth(seq.replace(fps=50.0)).metadata["provenance"]
    stamped = seq.replace(timestamps=np.arange(40) / 25.0)
    assert "assumed_fps" not in tk.smooth(stamped).metadata["provenance"]
