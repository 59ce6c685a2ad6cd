"""Gates measured on the stream itself (``gates="stream"``, ``LiveSmoother(gates_from=
"stream")``): causal, the same live and in batch, and they grow with the motion."""

from __future__ import annotations

import numpy as np
import pytest

import tobitkf as tk
from test_live_units import NAMES, TOPO, _pixels  # noqa: F401
from tobitkf.evaluation.pose2d import Pose2DModel, corrupt_pose2d
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.smoothing.robust_scale import STREAM_FIRST, STREAM_LAST, stream_gate_frames


def _people(seed: int, still: int = 0, timestamps: bool = True):
    """Two people's true pixel tracks and what a pose estimator reports for them
    (the built-in 2-D benchmark's corruption), optionally standing still at first."""
    from tobitkf.evaluation.pose2d import _truth

    model = Pose2DModel()
    truth = _truth("mixed", 8.0, seed, model)
    if still:
        truth = [t.replace(positions=np.concatenate([np.repeat(t.positions[:1], still, 0),
                                                     t.positions]), timestamps=None, fps=30.0)
                 for t in truth]  # fmt: skip
    noisy, _ = corrupt_pose2d(truth, model, seed=seed)
    if not timestamps:
        noisy = [n.replace(timestamps=None, fps=30.0) for n in noisy]
    return truth, noisy


def _live(noisy, **kw):
    live = tk.LiveSmoother(noisy[0].topology, fps=noisy[0].fps or 30.0, gates_from="stream", **kw)
    pos = np.stack([n.positions for n in noisy], axis=1)
    conf = np.stack([n.confidence for n in noisy], axis=1)
    ts = noisy[0].timestamps
    return np.array([
        live.update(pos[t], confidence=conf[t], timestamp=None if ts is None else ts[t])
        for t in range(len(pos))
    ])  # fmt: skip


def _rmse(est, true, frames=slice(STREAM_FIRST, None)):
    """RMS distance of ``est`` from ``true`` over ``frames`` (by default from the first
    gate measurement on: before it, the stream's frames are returned as measured)."""
    e = np.linalg.norm(est[frames] - true[frames], axis=-1)
    return float(np.sqrt(np.nanmean(e**2)))


def test_the_measurement_frames():
    assert stream_gate_frames(STREAM_FIRST) == []
    assert stream_gate_frames(STREAM_FIRST + 1) == [16]
    assert stream_gate_frames(100) == [16, 32, 64]
    assert stream_gate_frames(10**6) == [16 * 2**k for k in range(9)]
    assert stream_gate_frames(10**6)[-1] == STREAM_LAST


@pytest.mark.parametrize("timestamps", [True, False])
def test_live_is_batch_exactly(timestamps):
    """The stream (two bodies in one array) gives what the batch run gives, bit for bit,
    with the recording's timestamps or at its frame rate (with the untangling too:
    tests/test_untangle_stream.py)."""
    _, noisy = _people(seed=1, timestamps=timestamps)
    batch = tk.smooth(noisy, "robust_online", gates="stream", untangle=False)
    np.testing.assert_array_equal(_live(noisy, untangle=False),
                                  np.stack([b.positions for b in batch], 1))  # fmt: skip


def test_the_first_frames_are_returned_as_measured():
    _, noisy = _people(seed=0)
    (out,) = tk.smooth(noisy[:1], "robust_online", gates="stream", untangle=False)
    raw = noisy[0].positions.copy()
    raw[noisy[0].confidence < 0.1] = np.nan  # below min_confidence: missing
    np.testing.assert_array_equal(out.positions[:STREAM_FIRST], raw[:STREAM_FIRST])
    assert np.isnan(out.std[:STREAM_FIRST]).all() and np.isfinite(out.std[STREAM_FIRST:]).any()
    frames = [h["frame"] for h in out.metadata["diagnostics"]["stream_gates"]]
    assert frames == stream_gate_frames(noisy[0].n_frames)


def _smoothed(noisy):
    """The stream gates' output with the people's swaps undone as a live stream undoes
    them (causally)."""
    return np.stack([o.positions for o in tk.smooth(noisy, "robust_online", gates="stream")], 1)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_glitches_are_removed(seed):
    """After the first measurement, the error is a fraction of the pose estimator's (its
    glitches are 30-200 px, its jitter 2 px)."""
    truth, noisy = _people(seed)
    out = _smoothed(noisy)
    true = np.stack([t.positions for t in truth], 1)
    raw = np.stack([n.positions for n in noisy], 1)
    assert _rmse(out, true) < 0.5 * _rmse(raw, true)


def test_gates_grow_when_a_still_stream_starts_to_move():
    """A stream that stands still for 3 s: the first measurements describe a still body;
    measured again as the count of frames doubles, the gates describe its motion (the
    rms speed more than doubles), and the motion that follows is kept, its glitches
    removed."""
    truth, noisy = _people(seed=0, still=90, timestamps=False)
    out = _smoothed(noisy)
    (smoothed, _) = tk.smooth(noisy, "robust_online", gates="stream")
    first, *_, last = smoothed.metadata["diagnostics"]["stream_gates"]
    assert np.median(last["speed_sd"]) > 2 * np.median(first["speed_sd"])
    true = np.stack([t.positions for t in truth], 1)
    raw = np.stack([n.positions for n in noisy], 1)
    late = slice(150, None)
    assert _rmse(out, true, late) < 0.1 * _rmse(raw, true, late)


def test_the_stream_keeps_its_own_copy_of_the_frames():
    """A camera loop that reuses one array for every frame: the gates are measured on
    the frames as they were, not on the last one repeated."""
    _, y = _pixels(T=120)
    y = np.concatenate([y, 0 * y[..., :1] + 500.0], axis=-1)  # 3-D: the frame is used as is
    seq = SkeletonSequence(positions=y, topology=TOPO, fps=30, units=None)
    batch = tk.smooth(seq, "robust_online", gates="stream").positions
    live = tk.LiveSmoother(TOPO, fps=30, gates_from="stream", units="m")
    buf = np.empty_like(y[0])
    out = []
    for frame in y:
        buf[...] = frame
        out.append(live.update(buf).copy())
    np.testing.assert_array_equal(np.array(out), batch)


def test_each_body_of_a_keyed_stream_has_its_own_gates():
    """Keyed by id, each body is exactly a stream of it alone: bodies 7 and 9 arrive
    together but their gates are measured each on its own frames; body 5 arrives at
    frame 30, and its gates are first measured at its own 16th frame. (Untangled, the
    bodies are not independent: their samples may be exchanged; untangle=False.)"""
    _, noisy = _people(seed=2)
    _, more = _people(seed=3)
    tracks = {7: noisy[0], 9: noisy[1], 5: more[0]}
    start = {7: 0, 9: 0, 5: 30}
    ts = noisy[0].timestamps
    topo = noisy[0].topology
    keyed = tk.LiveSmoother(topo, fps=30, gates_from="stream", untangle=False)
    alone = {b: tk.LiveSmoother(topo, fps=30, gates_from="stream", untangle=False)
             for b in tracks}  # fmt: skip
    for t in range(noisy[0].n_frames):
        ids = [b for b in tracks if t >= start[b]]
        out = keyed.update({b: tracks[b].positions[t] for b in ids},
                           confidence={b: tracks[b].confidence[t] for b in ids},
                           timestamp=ts[t])  # fmt: skip
        for b in ids:
            expected = alone[b].update(tracks[b].positions[t], confidence=tracks[b].confidence[t],
                                       timestamp=ts[t])  # fmt: skip
            np.testing.assert_array_equal(out[b], expected, err_msg=f"body {b}, frame {t}")


def test_what_stream_gates_refuse():
    _, y = _pixels()
    # a method without gates: the untangling only (test_untangle_stream), its parameters
    # as they were
    kf = tk.LiveSmoother(TOPO, method="kf", gates_from="stream")
    assert kf.params == tk.LiveSmoother(TOPO, method="kf").params
    with pytest.raises(ValueError, match="'stream'"):
        tk.LiveSmoother(TOPO, gates_from="streem")
    seq = SkeletonSequence(positions=y, topology=TOPO, fps=30, units="px")
    with pytest.raises(ValueError, match="is robust_online's; robust reads the whole"):
        tk.smooth(seq, "robust", gates="stream")
    with pytest.raises(ValueError, match="gates_from='stream'"):  # named as a way out
        tk.LiveSmoother(TOPO).update(y[0])


def test_a_gate_parameter_given_is_not_replaced_by_the_measured_one():
    """In pixels the gates are measured on the recording (or the stream), except the ones
    the caller gives: a speed bound of a million px/s rejects no glitch, batch and live."""
    _, noisy = _people(seed=2)
    (one,) = noisy[:1]
    measured = tk.smooth(one)
    assert (measured.sample_state == tk.SampleState.REJECTED).sum() > 20  # the glitches
    loose = tk.smooth(one, v_max=1e6, margin=1e6, bone_tol_abs=1e6, bone_tol_rel=1e6)
    assert (loose.sample_state == tk.SampleState.REJECTED).sum() == 0
    assert set(np.ravel(loose.metadata["provenance"]["params"]["v_max"])) == {1e6}
    kw = {"v_max": 1e6, "margin": 1e6, "bone_tol_abs": 1e6, "bone_tol_rel": 1e6}
    (batch,) = tk.smooth([one], "robust_online", gates="stream", untangle=False, **kw)
    assert (batch.sample_state == tk.SampleState.REJECTED).sum() == 0
    np.testing.assert_array_equal(_live([one], untangle=False, **kw)[:, 0], batch.positions)


def test_a_gate_given_for_some_regions_keeps_the_measured_gates_of_the_others():
    """v_max={"hands": ...} on pixel data: the hands get the caller's bound, every other
    joint keeps the bound measured on the recording (they used to get the metre
    constants 3, 5, 10 as px/s and a third of the samples were rejected); a region the
    skeleton lacks changes nothing. Batch robust, and LiveSmoother's stream gates."""
    _, noisy = _people(seed=2)
    (one,) = noisy[:1]
    hands = one.topology.joint_groups()["hands"]
    others = np.setdiff1d(np.arange(one.n_joints), hands)
    measured = np.asarray(tk.smooth(one).metadata["provenance"]["params"]["v_max"])
    got = tk.smooth(one, v_max={"hands": 12345.0})
    v = np.asarray(got.metadata["provenance"]["params"]["v_max"])
    np.testing.assert_array_equal(v[others], measured[others])
    assert set(v[hands]) == {12345.0}
    # the stream's measured gates alike: batch (gates="stream"), and live equal to it
    kw = {"untangle": False}
    ref = tk.smooth([one], "robust_online", gates="stream", **kw)[0]
    (batch,) = tk.smooth([one], "robust_online", gates="stream", v_max={"hands": 7.0}, **kw)
    sv = np.asarray(batch.metadata["provenance"]["params"]["v_max"])
    np.testing.assert_array_equal(
        sv[others], np.asarray(ref.metadata["provenance"]["params"]["v_max"])[others]
    )
    assert set(sv[hands]) == {7.0}
    np.testing.assert_array_equal(_live([one], v_max={"hands": 7.0}, **kw)[:, 0], batch.positions)
    # a region this skeleton lacks (an animal's keypoints, all 'torso'): as if nothing
    # were given
    names = [f"point{j}" for j in range(one.n_joints)]
    animal = one.replace(topology=tk.Topology.from_names(names, list(one.topology.parents)))
    assert animal.topology.joint_groups()["hands"] == []
    np.testing.assert_array_equal(
        tk.smooth(animal, v_max={"hands": 6.0}).positions, tk.smooth(animal).positions
    )


def test_the_gates_hold_after_the_last_measurement():
    """A stream longer than twice STREAM_LAST frames: its last gate measurement is at
    frame STREAM_LAST and the frames kept for it are let go; every frame after that is
    stepped with those gates, as batch does (the next measurement was once scheduled at
    2 STREAM_LAST, on no frames: an error on every frame from there on)."""
    _, y = _pixels(T=2 * STREAM_LAST + 40)
    seq = SkeletonSequence(positions=y, topology=TOPO, fps=30, units="px")
    batch = tk.smooth(seq, "robust_online", gates="stream").positions
    live = tk.LiveSmoother(TOPO, fps=30, gates_from="stream", units="px")
    out = np.array([live.update(frame) for frame in y])
    np.testing.assert_array_equal(out, batch)


@pytest.mark.parametrize("method", ["robust_online", "kf", "atkf"])
def test_a_stream_pickled_midway_goes_on_as_the_original(method):
    """Saved to disk or handed to another process (pickle, deepcopy): the copy returns
    what the original returns. The method's registry entry was a local function, which
    pickle refused even before the first frame."""
    import copy
    import pickle

    _, y = _pixels(T=120)
    y = np.concatenate([y, 0 * y[..., :1] + 500.0], axis=-1)
    kw = {"gates_from": "stream", "units": "px"}
    if method != "robust_online":  # the paper's filters, in metres
        y, kw = y / 500.0, {"units": "m"}
    live = tk.LiveSmoother(TOPO, method, fps=30, **kw)
    pickle.loads(pickle.dumps(live))  # before the first frame
    for frame in y[:50]:
        live.update(frame)
    copies = [pickle.loads(pickle.dumps(live)), copy.deepcopy(live)]
    for frame in y[50:]:
        expected = live.update(frame)
        for other in copies:
            np.testing.assert_array_equal(other.update(frame), expected)
            np.testing.assert_array_equal(other.std, live.std)


@pytest.mark.parametrize(("factor", "unit"), [(1e3, "milliseconds"), (1e6, "microseconds")])
def test_timestamps_in_milliseconds_are_refused_not_taken_as_seconds(factor, unit):
    """MediaPipe and Azure Kinect stamp frames in ms or µs: taken as seconds, a frame
    lasted half a minute and nothing was rejected or smoothed (the output was the input).
    Batch, live (on the stream's first three steps) and delayed say so; seconds pass."""
    _, y = _pixels(T=60)
    y = np.concatenate([y, 0 * y[..., :1] + 500.0], axis=-1) / 500.0  # metres
    stamps = np.arange(len(y)) / 30.0
    seq = SkeletonSequence(positions=y, topology=TOPO, fps=30, units="m")
    for fps in (30.0, None):
        with pytest.raises(ValueError, match=f"look like {unit}"):
            tk.smooth(seq.replace(timestamps=stamps * factor, fps=fps), "robust")
    tk.smooth(seq.replace(timestamps=stamps), "robust")
    tk.smooth(seq.replace(timestamps=stamps * 30.0, fps=None), "robust")  # one frame a second
    live = tk.LiveSmoother(TOPO, fps=30, units="m")
    for k in range(3):
        live.update(y[k], timestamp=stamps[k] * factor)
    with pytest.raises(ValueError, match=f"look like {unit}"):
        live.update(y[3], timestamp=stamps[3] * factor)
    live = tk.LiveSmoother(TOPO, fps=30, units="m")
    for k in range(10):
        live.update(y[k], timestamp=stamps[k])
