"""LiveSmoother's units: lengths converted to metres, gates for pixel streams measured on
a sample recording (``gates_from``) or given, never metres applied to pixels."""

from __future__ import annotations

import numpy as np
import pytest

import tobitkf as tk
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology
from tobitkf.smoothing.robust_scale import GATE_PARAMS

NAMES = ("head", "neck", "left_hand", "right_hand", "tail")
TOPO = Topology.from_names(
    NAMES, edges=[("neck", "head"), ("neck", "left_hand"), ("neck", "right_hand"),
                  ("neck", "tail")],
)  # fmt: skip


def _pixels(T=150, seed=0):
    """Keypoints moving about 4 px per frame with 2 px of noise, and two glitches."""
    rng = np.random.default_rng(seed)
    t = np.arange(T) / 30.0
    centre = np.stack([300 + 120 * np.sin(1.0 * t), 200 + 60 * np.cos(0.7 * t)], -1)
    offsets = np.array([[0, -40], [0, 0], [-35, 10], [35, 10], [0, 60]], dtype=float)
    truth = centre[:, None] + offsets[None]
    y = truth + rng.normal(size=truth.shape) * 2.0
    y[40, 2] += 150.0
    y[90:94, 3] -= 120.0
    return truth, y


def _stream(live, frames):
    return np.array([live.update(f) for f in frames])


def test_a_pixel_stream_without_gates_is_refused_at_its_first_frame():
    """Gates in metres on pixels reject every motion (the stream froze at its first
    frame): refused, naming both ways out, and the stream is left as it was."""
    _, y = _pixels()
    live = tk.LiveSmoother(TOPO, fps=30)
    with pytest.raises(ValueError, match="gates_from") as err:
        live.update(y[0])
    assert all(name in str(err.value) for name in GATE_PARAMS)
    assert live.n_frames == 0
    with pytest.raises(ValueError, match="gates_from"):  # keyed by id alike
        tk.LiveSmoother(TOPO, fps=30).update({1: y[0]})
    with pytest.raises(ValueError, match="gates_from"):  # 3-D, said to be pixels
        tk.LiveSmoother(TOPO, fps=30, units="px").update(np.zeros((5, 3)))


def test_gates_measured_on_the_recording_itself_give_the_batch_numbers():
    """A stream whose gates are measured on its own recording is ``smooth(recording,
    "robust_online")``, which measures them there (exactly: the same frame function)."""
    _, y = _pixels()
    seq = SkeletonSequence(positions=y, topology=TOPO, fps=30, units="px")
    batch = tk.smooth(seq, method="robust_online").positions
    live = tk.LiveSmoother(TOPO, fps=30, gates_from=seq)
    np.testing.assert_array_equal(_stream(live, y), batch)
    # an array sample at the smoother's fps measures the same gates
    live = tk.LiveSmoother(TOPO, fps=30, gates_from=y)
    np.testing.assert_array_equal(_stream(live, y), batch)


def test_gates_from_another_recording_follow_the_motion():
    """Gates measured on another take of the same set-up: the glitches are removed and
    the clean samples kept (the error stays near the noise, far below the glitches')."""
    truth, y = _pixels(seed=1)
    _, sample = _pixels(seed=2)
    out = _stream(tk.LiveSmoother(TOPO, fps=30, gates_from=sample), y)
    err = np.linalg.norm(out - truth, axis=-1)
    assert err[40, 2] < 20 and err[90:94, 3].max() < 40  # the glitches: 150 and 120 px
    assert np.median(err) < 3.0  # 2 px noise per axis


def test_given_gates_in_pixels_are_used_as_given():
    _, y = _pixels()
    seq = SkeletonSequence(positions=y, topology=TOPO, fps=30, units="px")
    gates = tk.smooth(seq, method="robust_online").metadata["provenance"]["params"]
    given = {k: gates[k] for k in GATE_PARAMS}
    out = _stream(tk.LiveSmoother(TOPO, fps=30, **given), y)
    np.testing.assert_array_equal(out, tk.smooth(seq, method="robust_online").positions)
    # the user's word that the defaults are in the stream's units: no refusal
    tk.LiveSmoother(TOPO, fps=30, gates="physical").update(y[0])


@pytest.mark.parametrize("units", ["mm", "cm"])
def test_millimetres_and_centimetres_are_smoothed_as_metres(units):
    """A stream in mm (cm) gives the metre stream's output in mm (cm), as smooth() does."""
    _, y = _pixels()
    metres = np.concatenate([y, 50 + 0 * y[..., :1]], -1) / 100  # a 3-D track, ~1 m
    factor = {"mm": 1000.0, "cm": 100.0}[units]
    ref = _stream(tk.LiveSmoother(TOPO, fps=30), metres)
    out = _stream(tk.LiveSmoother(TOPO, fps=30, units=units), metres * factor)
    np.testing.assert_allclose(out / factor, ref, rtol=1e-9, atol=1e-12)
    seq = SkeletonSequence(positions=metres * factor, topology=TOPO, fps=30, units=units)
    np.testing.assert_allclose(out, tk.smooth(seq, method="robust_online").positions,
                               rtol=1e-9, atol=1e-9 * factor)  # fmt: skip
    # gates measured on a sample in the stream's units: the same gates, in metres
    in_m = _stream(tk.LiveSmoother(TOPO, fps=30, gates_from=metres), metres)
    scaled = tk.LiveSmoother(TOPO, fps=30, units=units, gates_from=metres * factor)
    np.testing.assert_allclose(_stream(scaled, metres * factor) / factor, in_m, rtol=1e-9,
                               atol=1e-12)  # fmt: skip


def test_given_parameters_override_the_measured_gates():
    _, y = _pixels()
    live = tk.LiveSmoother(TOPO, fps=30, gates_from=y, v_max=1e6)
    assert live.params["v_max"] == 1e6
    assert np.all(np.asarray(live.params["margin"]) > 0)  # the others measured
    assert live.params["margin"] != tk.LiveSmoother(TOPO, fps=30).params["margin"]


def test_bad_gates_and_units_are_refused():
    _, y = _pixels()
    with pytest.raises(ValueError, match="units"):
        tk.LiveSmoother(TOPO, units="inch")
    # a method without gates takes the untangling's statistics only
    kf = tk.LiveSmoother(TOPO, method="kf", gates_from=y)
    assert kf.params == tk.LiveSmoother(TOPO, method="kf").params
    with pytest.raises(ValueError, match="J = 5"):
        tk.LiveSmoother(TOPO, method="kf", gates_from=y[:, :3])  # still checked
    with pytest.raises(ValueError, match="J = 5"):
        tk.LiveSmoother(TOPO, gates_from=y[:, :3])
    with pytest.raises(ValueError, match="in 'px', the stream in 'mm'"):
        seq = SkeletonSequence(positions=y, topology=TOPO, fps=30, units="px")
        tk.LiveSmoother(TOPO, units="mm", gates_from=seq)
    live = tk.LiveSmoother(TOPO, gates_from=y)  # 2-D gates, 3-D stream
    with pytest.raises(ValueError, match="measured on a sample with 2"):
        live.update(np.zeros((5, 3)))


def test_a_sample_without_motion_is_refused():
    """Gates measured on a still (or empty) sample would reject every step: the stream
    froze on its first frame. Refused when the smoother is made."""
    _, y = _pixels()
    for still in (np.repeat(y[:1], 50, axis=0), np.full_like(y, np.nan)):
        with pytest.raises(ValueError, match="no motion"):
            tk.LiveSmoother(TOPO, gates_from=still)


def test_a_sample_in_other_units_than_the_stream_is_refused():
    """A 3-D stream is in metres unless told otherwise: a sample in mm would give gates
    a thousand times too wide (outlier rejection silently off)."""
    _, y = _pixels()
    mm = SkeletonSequence(np.concatenate([y, 0 * y[..., :1] + 500], -1), TOPO, fps=30,
                          units="mm")  # fmt: skip
    with pytest.raises(ValueError, match="units='mm'"):
        tk.LiveSmoother(TOPO, gates_from=mm)
    tk.LiveSmoother(TOPO, gates_from=mm, units="mm")  # said: fine


def test_a_refused_first_frame_and_reset_leave_the_coordinates_open():
    live = tk.LiveSmoother("kinect_v2", method="kf")
    with pytest.raises(ValueError, match="24 joints"):
        live.update(np.zeros((24, 2)))
    live.update(np.zeros((25, 3)))  # the refused 2-D frame fixed nothing
    with pytest.raises(ValueError, match="body 2"):  # keyed: the same
        tk.LiveSmoother("kinect_v2", method="kf").update({1: np.zeros((25, 2)),
                                                          2: np.zeros((24, 2))})  # fmt: skip
    live.reset()
    live.update(np.zeros((25, 2)))  # forgotten: a new stream may be 2-D


def _scored(seed=3):
    """The pixel track with scores: some below the threshold, the glitches doubtful."""
    _, y = _pixels()
    rng = np.random.default_rng(seed)
    conf = rng.uniform(0.2, 1.0, y.shape[:2])
    conf[rng.uniform(size=conf.shape) < 0.05] = 0.05  # below 0.1: missing
    conf[40, 2] = 0.3
    conf[5, 1] = np.nan  # no score for this one
    return y, conf


@pytest.mark.parametrize("method", ["robust_online", "kf", "one_euro"])
def test_a_stream_with_confidence_gives_the_batch_numbers(method):
    """Scores below min_confidence make a sample missing, above it the robust methods
    weigh it, live as in smooth(): fed its frames, the stream is the batch result."""
    y, conf = _scored()
    seq = SkeletonSequence(positions=y, topology=TOPO, fps=30, units="px", confidence=conf)
    params = {} if method != "kf" else {"q": 4.0, "r": 4.0}
    gates = seq if method == "robust_online" else None
    batch = tk.smooth(seq, method=method, untangle=False, **params).positions
    live = tk.LiveSmoother(TOPO, method, fps=30, gates_from=gates, **params)
    out = np.array([live.update(f, confidence=c) for f, c in zip(y, conf, strict=True)])
    np.testing.assert_allclose(out, batch, rtol=0, atol=1e-9)
    # keyed by id alike
    keyed = tk.LiveSmoother(TOPO, method, fps=30, gates_from=gates, **params)
    got = np.array(
        [keyed.update({7: f}, confidence={7: c})[7] for f, c in zip(y, conf, strict=True)]
    )
    np.testing.assert_allclose(got, batch, rtol=0, atol=1e-9)


def test_bad_confidence_is_refused_and_leaves_the_stream():
    y, conf = _scored()
    live = tk.LiveSmoother(TOPO, "kf", fps=30)
    for bad in (conf[0, :3], conf[0] + 2, "high"):
        with pytest.raises(ValueError, match="confidence"):
            live.update(y[0], confidence=bad)
    assert live.n_frames == 0
    live.update(y[0], confidence=conf[0])
    with pytest.raises(ValueError, match="mapping"):
        tk.LiveSmoother(TOPO, "kf").update({1: y[0]}, confidence=conf[0])
