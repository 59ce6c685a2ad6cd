"""Live smoothing with a fixed delay (``DelayedSmoother``, ``smooth_delayed``): the
stream gives its batch twin's frames; frame t depends on frames t - W + D + 1 .. t + D
only (and on its held noise fit's window, itself built here with ``smooth()``); with
the whole recording in view it is ``smooth()``; a causal method at delay 0 is itself;
what a delay buys on the synthetic benchmark."""

from __future__ import annotations

import math

import numpy as np
import pytest

import tobitkf as tk
from conftest import data_file
from tobitkf.io import load
from tobitkf.skeleton.sequence import SampleState


def _recording(seed=0, seconds=5.0, kind="mixed"):
    """A corrupted Kinect V2 recording (30 fps, irregular timestamps, tracking states)
    and its clean truth at the kept frames."""
    bad = tk.corrupt(tk.generate_motion(kind, duration=seconds, seed=seed), seed=seed)
    return bad.sequence, bad.truth


def _window(seq, a, b):
    """Frames ``a .. b - 1`` of ``seq`` as a recording of their own."""
    return seq.replace(positions=seq.positions[a:b], tracking_state=seq.tracking_state[a:b],
                       timestamps=seq.timestamps[a:b])  # fmt: skip


def _stream(seq, method="robust", positions=None, **kw):
    """Frames, sd and states a DelayedSmoother returns for ``seq`` (flush included), and
    the stream's frame indices at each return."""
    live = tk.DelayedSmoother(seq.topology, method, fps=seq.fps or 30.0, **kw)
    P = seq.positions if positions is None else positions
    pos, std, states, index = [], [], [], []
    for t in range(seq.n_frames):
        out = live.update(P[t],
                          None if seq.tracking_state is None else seq.tracking_state[t],
                          None if seq.timestamps is None else seq.timestamps[t])  # fmt: skip
        if out is None:
            assert live.frame_index == -1
            continue
        pos.append(out), std.append(live.std), states.append(live.sample_state)
        index.append(live.frame_index)
    rest = live.flush()
    return (np.concatenate([np.array(pos).reshape(-1, *rest.shape[1:]), rest]),
            np.concatenate([np.array(std).reshape(-1, *live.std.shape[1:]), live.std]),
            np.concatenate([np.array(states).reshape(-1, *live.std.shape[1:]),
                            live.sample_state]), index)  # fmt: skip


@pytest.mark.realdata
def test_the_stream_gives_the_batch_twins_frames():
    """KERAAL ELK streamed through robust with a 0.5 s delay: every frame (the flushed
    ones too), its sd and its states are smooth_delayed's, and each returned frame is the
    one 15 frames back."""
    seq = load(data_file("keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt"))[0]
    pos, std, states, index = _stream(seq, delay=0.5, window=4.0)
    batch = tk.smooth_delayed(seq, delay=0.5, window=4.0)
    np.testing.assert_array_equal(pos, batch.positions)
    np.testing.assert_array_equal(std, batch.std)
    np.testing.assert_array_equal(states, batch.sample_state)
    assert index == list(range(seq.n_frames - 15))
    assert (states == SampleState.REJECTED).any()
    assert batch.metadata["provenance"]["delayed"]["window_frames"] == 120
    assert batch.metadata["provenance"]["delayed"]["refit_frames"] == 30  # 1 s, the default
    fixed = tk.smooth_delayed(seq, delay=0.5, window=4.0, noise="fixed")
    assert fixed.metadata["provenance"]["delayed"]["refit_frames"] is None  # nothing held


@pytest.mark.realdata
@pytest.mark.parametrize("name", ["CTK", "ELK"])
def test_no_returned_step_is_larger_than_the_inputs(name):
    """Issue 10, point 4, across runs: consecutive frames come from different runs (the
    later one sees a frame more and may judge a failure otherwise), yet no returned step
    exceeds the joint's largest input step where the input is present at both frames.
    KERAAL CTK and ELK had such steps (up to 32 cm beyond) before the guard."""
    seq = load(data_file(f"keraal/G3-Kinect-{name}-P1T1-Unknown-C-0.txt"))[0]
    out = tk.smooth_delayed(seq, delay=0.5)
    present = np.isfinite(seq.positions).all(axis=-1)
    step_in = np.linalg.norm(np.diff(seq.positions, axis=0), axis=-1)
    both = present[1:] & present[:-1]
    largest = np.max(np.where(both, step_in, 0.0), axis=0)
    step_out = np.linalg.norm(np.diff(out.positions, axis=0), axis=-1)
    assert not (both & (step_out > largest[None] + 1e-9)).any()


def test_bodies_and_timestamps_each_as_alone():
    """Two bodies in one (B, J, 3) stream with irregular timestamps: each body's frames are
    smooth_delayed of that body alone (robust treats bodies independently)."""
    a, _ = _recording(1, 4.0)
    b, _ = _recording(2, 4.0, "walk")
    T = min(a.n_frames, b.n_frames, 100)
    rng = np.random.default_rng(0)
    stamps = np.cumsum(rng.uniform(0.02, 0.05, T))
    bodies = [s.replace(positions=s.positions[:T], tracking_state=None, timestamps=stamps,
                        fps=30.0) for s in (a, b)]  # fmt: skip
    pos, std, _, _ = _stream(bodies[0], positions=np.stack([s.positions for s in bodies], 1),
                             delay=0.2, window=1.0, max_reject=0.5)  # fmt: skip
    for k, body in enumerate(bodies):
        alone = tk.smooth_delayed(body, delay=0.2, window=1.0, max_reject=0.5)
        np.testing.assert_array_equal(pos[:, k], alone.positions)
        np.testing.assert_array_equal(std[:, k], alone.std)


def test_whole_recording_in_view_is_smooth():
    """Delay and window longer than the recording: every frame comes from one run on the
    whole recording, which is smooth() itself."""
    seq, _ = _recording(3, 3.0)
    out = tk.smooth_delayed(seq, delay=10.0, window=20.0)
    full = tk.smooth(seq)
    np.testing.assert_array_equal(out.positions, full.positions)
    np.testing.assert_array_equal(out.std, full.std)
    pos, _, _, index = _stream(seq, delay=10.0, window=20.0)
    assert index == []  # all of it at the flush
    np.testing.assert_array_equal(pos, full.positions)


def test_a_causal_method_at_delay_zero_is_itself():
    """kf is causal: at delay 0 with the whole past in view, frame t of the run on frames
    0..t is frame t of the run on the whole recording (at 30 fps: with timestamps, a
    run's nominal step is read from the frames it has)."""
    seq, _ = _recording(4, 3.0)
    seq = seq.replace(timestamps=None, fps=30.0)
    out = tk.smooth_delayed(seq, "kf", delay=0.0, window=100.0)
    np.testing.assert_allclose(out.positions, tk.smooth(seq, "kf").positions, rtol=0,
                               atol=1e-12)  # fmt: skip


@pytest.mark.parametrize("t", [40, 75])
def test_frame_t_reads_only_its_window(t):
    """D = 6, W = 30 frames, the noise fitted at every frame (refit 0): frame t is
    unchanged when every frame after t + D, or before t + D + 1 - W, is replaced by
    garbage; it changes when frame t + D, or t + D + 1 - W, is (the noise fit reads the
    whole window)."""
    seq, _ = _recording(5, 4.0)
    kw = {"delay": 0.2, "window": 1.0, "max_reject": 0.5, "refit": 0.0}
    base = tk.smooth_delayed(seq, **kw).positions[t]
    rng = np.random.default_rng(t)

    def spoilt(frames):
        pos = seq.positions.copy()
        pos[frames] += rng.normal(0, 0.5, pos[frames].shape)
        return tk.smooth_delayed(seq.replace(positions=pos), **kw).positions[t]

    np.testing.assert_array_equal(spoilt(slice(t + 7, None)), base)
    np.testing.assert_array_equal(spoilt(slice(0, t + 7 - 30)), base)
    assert not np.array_equal(spoilt(slice(t + 6, t + 7)), base, equal_nan=True)
    assert not np.array_equal(spoilt(slice(t + 7 - 30, t + 8 - 30)), base, equal_nan=True)


@pytest.mark.parametrize("t", [45, 50, 59])
def test_a_held_fit_is_the_fit_of_its_run(t):
    """refit 0.5 s (R = 15 runs), D = 6, W = 30 frames: frame t is the method's output on
    its own window with the noise given as the fit of run k0 = 15 * (t // 15) (its window
    frames k0 + D + 1 - W .. k0 + D), built here with smooth() alone."""
    seq, _ = _recording(7, 4.0)
    kw = {"max_reject": 0.5}
    out = tk.smooth_delayed(seq, delay=0.2, window=1.0, refit=0.5, **kw)
    k0 = 15 * (t // 15)
    fit = tk.smooth(_window(seq, k0 + 7 - 30, k0 + 7), **kw).metadata["diagnostics"]["noise_fit"]
    own = tk.smooth(_window(seq, t + 7 - 30, t + 7), noise=fit, **kw)
    np.testing.assert_array_equal(out.positions[t], own.positions[-7])
    np.testing.assert_array_equal(out.std[t], own.std[-7])
    every = tk.smooth_delayed(seq, delay=0.2, window=1.0, refit=0.0, **kw)
    assert np.array_equal(out.positions[t], every.positions[t]) == (t == k0)


def test_a_held_fit_reads_the_fit_runs_window():
    """Frame 50 (R = 15: its fit is run 45's, read on frames 22 .. 51) changes with a
    small shift of frame 22, before its own window (27 .. 56), and not with garbage in
    frames 0 .. 21."""
    seq, _ = _recording(8, 4.0)
    kw = {"delay": 0.2, "window": 1.0, "max_reject": 0.5, "refit": 0.5}
    base = tk.smooth_delayed(seq, **kw).positions[50]

    def spoilt(frames, sd):
        pos = seq.positions.copy()
        pos[frames] += np.random.default_rng(1).normal(0, sd, pos[frames].shape)
        return tk.smooth_delayed(seq.replace(positions=pos), **kw).positions[50]

    np.testing.assert_array_equal(spoilt(slice(0, 22), 0.5), base)
    assert not np.array_equal(spoilt(slice(22, 23), 0.005), base, equal_nan=True)


@pytest.mark.parametrize("t", [45, 50, 59])
def test_bodies_a_run_couples_hold_their_fits_together(t):
    """Two people in one pixel array, their identities exchanged for a stretch: one run
    untangles them and measures the gates on both, so they are smoothed in one call,
    each with its own fit held (``noise=`` one per body). Frame t is built here with
    smooth() alone: the two bodies' own window, given the fits of the coupled run k0 =
    15 * (t // 15) (refit 0.5 s, D = 6, W = 30); it differs from fitting at every frame
    exactly off the fit runs. In metres each body is its own, and holds its fit too."""
    a, _ = _recording(10, 3.0)
    b, _ = _recording(11, 3.0, "walk")
    T = min(a.n_frames, b.n_frames, 80)
    pos = np.stack([a.positions[:T, :, :2] * 500, b.positions[:T, :, :2] * 500 + 300], 1)
    pos[30:45] = pos[30:45, ::-1]  # an identity switch of half a second
    px = tk.SkeletonSequence(pos[:, 0], a.topology, fps=30.0, units=None)
    kw = {"delay": 0.2, "window": 1.0, "max_reject": 0.5, "refit": 0.5}
    held, _, _, _ = _stream(px, positions=pos, **kw)

    def bodies(lo, hi):  # the stream's window as DelayedSmoother hands it to smooth()
        return [tk.SkeletonSequence(pos[lo:hi, i], a.topology, fps=30.0, body_id=i)
                for i in (0, 1)]  # fmt: skip

    k0 = 15 * (t // 15)
    fits = [o.metadata["diagnostics"]["noise_fit"]
            for o in tk.smooth(bodies(k0 + 7 - 30, k0 + 7), max_reject=0.5)]  # fmt: skip
    own = tk.smooth(bodies(t + 7 - 30, t + 7), noise=fits, max_reject=0.5)
    for i in (0, 1):
        np.testing.assert_array_equal(held[t, i], own[i].positions[-7])
    every, _, _, _ = _stream(px, positions=pos, **{**kw, "refit": 0.0})
    assert np.array_equal(held[t], every[t]) == (t == k0)
    m = {"delay": 0.2, "window": 1.0, "max_reject": 0.5}
    metres = np.stack([a.positions[:T], b.positions[:T]], 1)
    plain = a.replace(positions=a.positions[:T], tracking_state=None, timestamps=None)
    held_m, _, _, _ = _stream(plain, positions=metres, **m)
    every_m, _, _, _ = _stream(plain, positions=metres, refit=0.0, **m)
    assert not np.array_equal(held_m, every_m, equal_nan=True)


def test_refit_is_checked():
    seq, _ = _recording(9, 1.0)
    for bad in (-1.0, math.nan, "often"):
        with pytest.raises(ValueError, match="refit must be a number >= 0"):
            tk.DelayedSmoother(seq.topology, refit=bad)
        with pytest.raises(ValueError, match="refit must be a number >= 0"):
            tk.smooth_delayed(seq, refit=bad)


def test_a_pixel_stream_needs_no_gates():
    """A 2-D stream in unknown units: robust measures its gates on the window, from the
    first frame on (a window of one frame too), as smooth() does on a recording."""
    seq, _ = _recording(6, 2.0)
    px = tk.SkeletonSequence(seq.positions[:, :, :2] * 500, seq.topology, fps=30.0, units=None)
    pos, _, _, _ = _stream(px, delay=0.1, window=1.0, max_reject=0.5)
    assert pos.shape == px.positions.shape
    np.testing.assert_array_equal(
        pos, tk.smooth_delayed(px, delay=0.1, window=1.0, max_reject=0.5).positions
    )
    assert np.isfinite(pos[5:]).mean() > 0.95


def test_a_delay_beats_the_causal_default_on_the_benchmark():
    """Built-in motions, 6 s, seeds 0-7, pooled: robust 0.5 s late is closer to the truth
    than robust_online, which must judge each frame at once. Not on every seed: a failure
    longer than the delay is judged as causally (seed 2's lasts more than 1 s)."""
    late = online = 0.0
    for seed in range(8):
        seq, truth = _recording(seed, 6.0)

        def sse(s, truth=truth):
            return float(np.nansum((s.positions - truth) ** 2))

        late += sse(tk.smooth_delayed(seq, delay=0.5))
        online += sse(tk.smooth(seq, "robust_online"))
    assert late < 0.9 * online


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        ({"delay": -1}, "delay must be a number >= 0"),
        ({"delay": float("nan")}, "delay must be"),
        ({"window": 0}, "window must be a positive number"),
        ({"fps": "fast"}, "fps must be a positive number"),
        ({"units": "inch"}, "units must be one of"),
        ({"offline": True}, "offline"),
        ({"tau": -1}, "tau"),
        ({"min_confidence": 2}, "min_confidence"),
        ({"untangle": "sometimes"}, "untangle"),
    ],
)
def test_bad_settings_are_refused(kw, message):
    with pytest.raises(ValueError, match=message):
        tk.DelayedSmoother("kinect_v2", **kw)


def test_bad_frames_are_refused_and_change_nothing():
    seq, _ = _recording(7, 1.0)
    live = tk.DelayedSmoother(seq.topology, delay=0.1, window=1.0, max_reject=0.5)
    P = seq.positions
    live.update(P[0], timestamp=0.0)
    bad = [
        ({"positions": P[1, :5]}, "5 joints"),
        ({"positions": P[1, :, :2]}, "differs from the stream's"),
        ({"positions": np.where(np.arange(25)[:, None] == 3, np.inf, P[1])}, "infinite"),
        ({"positions": {1: P[1]}}, "not keyed by body id"),
        ({"positions": P[1], "timestamp": -1.0}, "comes before"),
        ({"positions": P[1]}, "timestamp: give it with every frame"),
        (
            {"positions": P[1], "timestamp": 0.1, "tracking_state": [2] * 25},
            "tracking_state: give it with every frame",
        ),
        (
            {"positions": P[1], "timestamp": 0.1, "tracking_state": [5] * 25},
            "tracking_state: expected integers",
        ),
        ({"positions": P[1], "timestamp": 0.1, "confidence": [2.0] * 25}, r"in \[0, 1\]"),
    ]
    for args, message in bad:
        with pytest.raises(ValueError, match=message):
            live.update(**args)
    assert live.n_frames == 1
    ok = [live.update(P[t], timestamp=t / 30) for t in range(1, 10)]
    assert [o is None for o in ok] == [True] * 2 + [False] * 7  # D = 3 frames
    assert live.frame_index == 6 and live.timestamp == pytest.approx(6 / 30)
    assert live.flush().shape == (3, 25, 3)
    with pytest.raises(ValueError, match="flushed"):
        live.update(P[10], timestamp=10 / 30)
    live.reset()
    assert live.update(P[0]) is None and live.n_frames == 1


@pytest.mark.parametrize(
    ("delay", "window", "fps", "frames"),
    [
        (0.28, 1.0, 25.0, (7, 25)),  # 0.28 * 25 is 7.000000000000001 in floating point
        (0.21, 1.0, 30.0, (7, 30)),  # 6.3 frames: rounded up, never early
        (0.0, 2.0, 25.0, (0, 50)),
        (0.5, 0.1, 30.0, (15, 16)),  # a window shorter than the delay: the delay and one
    ],
)
def test_delay_and_window_in_frames(delay, window, fps, frames):
    assert tk.smoothing.delayed.delay_frames(delay, window, fps) == frames


def test_keyed_bodies_each_as_a_stream_of_its_own():
    """Bodies keyed by id: 1 throughout (absent for 3 frames, fewer than D = 6: kept,
    missing there), 2 from frame 20, 3 in frames 0-40 and again from 50 (absent for
    more than D: forgotten once its frame 40 is returned, then a new track), 4 up to 2
    frames before the end (its flush stops at its last frame). Each body's
    frames are smooth_delayed of its own track from its first frame to D frames after
    its last (NaN where absent); nothing of any body is lost, the flush included."""
    T, D, kw = 70, 6, {"delay": 0.2, "window": 1.0, "max_reject": 0.5}
    recs = [_recording(s, 3.0)[0] for s in (8, 9, 10, 12)]
    stamps = recs[0].timestamps[:T]
    present = {1: np.ones(T, bool), 2: np.arange(T) >= 20,
               3: (np.arange(T) <= 40) | (np.arange(T) >= 50),
               4: np.arange(T) <= T - 3}  # fmt: skip
    present[1][30:33] = False
    live = tk.DelayedSmoother(recs[0].topology, fps=30.0, **kw)
    got: dict = {}
    for t in range(T):
        frame = {b: recs[b - 1].positions[t] for b in present if present[b][t]}
        out = live.update(frame, timestamp=stamps[t])
        assert (out == {}) if t < D else set(out) <= {1, 2, 3, 4}
        for b, pos in out.items():
            got.setdefault((b, t - D), (pos, live.std[b]))
    start = live.frame_index + 1
    rest = live.flush()
    assert {b: len(r) for b, r in rest.items()} == {1: D, 2: D, 3: D, 4: D - 2}
    for b, rows in rest.items():
        for k, row in enumerate(rows):
            got[(b, start + k)] = (row, live.std[b][k])
    tracks = [(1, 0, T - 1), (2, 20, T - 1), (3, 0, 40), (3, 50, T - 1), (4, 0, T - 3)]
    for b, first, last in tracks:
        stop = min(last + D, T - 1) + 1
        pos = recs[b - 1].positions[first:stop].copy()
        pos[~present[b][first:stop]] = np.nan
        seq = tk.SkeletonSequence(pos, recs[0].topology, timestamps=stamps[first:stop], fps=30.0)
        twin = tk.smooth_delayed(seq, **kw)
        for t in range(first, last + 1):
            frame, sd = got.pop((b, t))
            np.testing.assert_array_equal(frame, twin.positions[t - first])
            np.testing.assert_array_equal(sd, twin.std[t - first])
    assert not got  # no frame of a body outside its tracks


def test_keyed_frames_are_checked_whole():
    seq, _ = _recording(11, 1.0)
    P = seq.positions
    live = tk.DelayedSmoother(seq.topology, delay=0.1, window=1.0, max_reject=0.5)
    live.update({1: P[0], 2: P[0] + 1}, timestamp=0.0)
    bad = [
        ({"positions": {1: P[1], 2: P[1, :5]}, "timestamp": 0.1}, "body 2: positions: 5 joints"),
        (
            {"positions": {1: P[1], 2: np.stack([P[1]] * 2)}, "timestamp": 0.1},
            r"body 2: .*\(J, D\)",
        ),
        (
            {"positions": {1: P[1]}, "timestamp": 0.1, "tracking_state": {2: [2] * 25}},
            "same body ids",
        ),
        ({"positions": {7: P[1]}}, "timestamp: give it with every frame"),  # a new body
        ({"positions": {7: P[1]}, "timestamp": -1.0}, "comes before"),
        ({"positions": P[1], "timestamp": 0.1}, "keyed by body id"),
    ]
    for args, message in bad:
        with pytest.raises(ValueError, match=message):
            live.update(**args)
    assert live.n_frames == 1 and set(live._bodies) == {1, 2}
    plain = tk.DelayedSmoother(seq.topology, delay=0.1, window=1.0, max_reject=0.5)
    plain.update(P[0])
    with pytest.raises(ValueError, match="not keyed"):
        plain.update({1: P[1]})


def test_the_window_holds_twice_the_longest_rejection():
    """robust gives a joint up after max_reject (2 s): a 3 s window is refused, a 3 s
    window with max_reject 1.5 s is not; kf has no such limit."""
    with pytest.raises(ValueError, match="twice max_reject"):
        tk.DelayedSmoother("kinect_v2", window=3.0)
    seq, _ = _recording(13, 1.0)
    with pytest.raises(ValueError, match="twice max_reject"):
        tk.smooth_delayed(seq, window=3.0)
    tk.DelayedSmoother("kinect_v2", window=3.0, max_reject=1.5)
    tk.DelayedSmoother("kinect_v2", "kf", window=1.0)


def test_confidence_and_tracking_states_reach_the_method():
    """A stream with a pose estimator's scores and tracking states gives what
    smooth_delayed gives of the recording carrying them; the scores change the result
    (the robust methods weigh samples by them)."""
    seq, _ = _recording(14, 2.0)
    rng = np.random.default_rng(14)
    conf = rng.uniform(0.05, 1.0, seq.positions.shape[:2])
    scored = seq.replace(confidence=conf)
    kw = {"delay": 0.2, "window": 1.0, "max_reject": 0.5}
    live = tk.DelayedSmoother(seq.topology, fps=30.0, **kw)
    out = [live.update(seq.positions[t], seq.tracking_state[t], seq.timestamps[t], conf[t])
           for t in range(seq.n_frames)]  # fmt: skip
    pos = np.concatenate([np.array([o for o in out if o is not None]), live.flush()])
    twin = tk.smooth_delayed(scored, **kw)
    np.testing.assert_array_equal(pos, twin.positions)
    assert not np.array_equal(twin.positions, tk.smooth_delayed(seq, **kw).positions,
                              equal_nan=True)  # fmt: skip


def test_a_reused_frame_buffer_is_copied():
    """A camera loop writes every frame into one buffer (positions and scores): the
    window keeps what each frame was, as with fresh arrays."""
    seq, _ = _recording(15, 1.0)
    conf = np.random.default_rng(15).uniform(0.2, 1.0, seq.positions.shape[:2])
    kw = {"delay": 0.1, "window": 1.0, "max_reject": 0.5}
    fresh = tk.DelayedSmoother(seq.topology, **kw)
    reused = tk.DelayedSmoother(seq.topology, **kw)
    pos_buf, conf_buf = np.empty(seq.positions.shape[1:]), np.empty(conf.shape[1:])
    for t in range(seq.n_frames):
        a = fresh.update(seq.positions[t].copy(), confidence=conf[t].copy())
        pos_buf[:], conf_buf[:] = seq.positions[t], conf[t]
        b = reused.update(pos_buf, confidence=conf_buf)
        assert (a is None and b is None) or np.array_equal(a, b, equal_nan=True)
    np.testing.assert_array_equal(fresh.flush(), reused.flush())


def test_a_flush_with_nothing_left_gives_empty_rows_of_everything():
    """delay=0 returns every frame at once: the flush has no rows, and its std and
    sample states are empty arrays of the same shape as the positions' rows, not None."""
    seq, _ = _recording(seconds=1.0)
    live = tk.DelayedSmoother(seq.topology, delay=0.0, window=4.0, fps=30.0)
    for frame in seq.positions[:20]:
        live.update(frame)
    rest = live.flush()
    assert rest.shape == (0, 25, 3)
    assert live.std.shape == (0, 25) and live.sample_state.shape == (0, 25)
    assert live.sample_state.dtype == np.int8
