"""The causal untangling (``untangle.StreamUntangler``, ``untangle_stream``,
``LiveSmoother(untangle=...)``): the offline decisions frame by frame, the same live and
in batch, and what a stream cannot know (a long swap, a swap under way at its start)."""

from __future__ import annotations

import numpy as np
import pytest

import tobitkf as tk
from test_live_stream_gates import _live, _rmse
from test_live_stream_gates import _people as _benchmark_people
from test_pose2d import _people as _two_people
from test_untangle_kernels import _people as _random_people
from tobitkf.smoothing.robust_scale import STREAM_FIRST
from tobitkf.smoothing.untangle import (
    MAX_SWAP_S,
    StreamUntangler,
    untangle,
    untangle_sequences,
    untangle_stats,
    untangle_stream,
)


def _causal(ys, pairs, margin, near, max_frames):
    st = StreamUntangler(pairs)
    st.set_stats(margin, near, max_frames)
    steps = [st.step(ys[t]) for t in range(len(ys))]
    return np.array([s[0] for s in steps]), np.array([s[1] for s in steps])


@pytest.mark.parametrize("seed", range(2))
@pytest.mark.parametrize("B", [1, 2, 3])
@pytest.mark.parametrize("dims", [2, 3])
@pytest.mark.parametrize("apart", [True, False])
def test_the_causal_loops_decide_as_offline(seed, B, dims, apart):
    """With the same statistics and no swap longer than ``max_frames``, frame by frame
    gives the offline decisions of the forward pass exactly (identity switches,
    left/right swaps, glitches, gaps, bodies and pairs a few noise sds apart); offline
    the left/right exchanges are also decided backwards and settled (``both_ways``)."""
    ys, missing, pairs = _random_people(seed, B, dims, apart)
    unit = 1.0 if dims == 2 else 0.0025
    for margin, near in ((6 * unit, np.inf), (6 * unit, 16 * unit), (60 * unit, np.inf)):
        want = untangle(ys, missing, pairs, margin, max_frames=10**6, near=near,
                        both_ways=False)  # fmt: skip
        got = _causal(ys, pairs, margin, near, 10**6)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])


def _swapped_wrists(start: int, stop: int, T: int = 300):
    """One person (neck, left and right wrist, pixels) whose wrists are exchanged as
    detected in frames ``start .. stop - 1``."""
    (_, a), _ = _two_people(T=T)
    p = a.positions.copy()
    p[start:stop, 1], p[start:stop, 2] = a.positions[start:stop, 2], a.positions[start:stop, 1]
    return a, p


def test_a_long_swap_is_undone_for_max_swap_s_then_taken_as_detected():
    """Offline, a swap longer than ``MAX_SWAP_S`` is left as detected from its start; a
    stream cannot wait for its end: its first ``max_frames`` frames are undone, then the
    frames are taken as detected. No exchange lasts longer than ``max_frames`` (the
    swap's real end then looks like a new one, and is undone no longer either)."""
    n = int(MAX_SWAP_S * 30)
    a, p = _swapped_wrists(100, 100 + n + 40)
    margin, near, max_frames = untangle_stats(p[:, None], a.times())
    assert max_frames == n
    _, exch = _causal(p[:, None], list(a.topology.symmetry), margin, near, max_frames)
    flags = exch[:, 0, 0]
    assert flags[100 : 100 + n].all() and not flags[:100].any()
    assert not flags[100 + n : 100 + n + 40].any()
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flags.astype(int), [0]])))
    assert (edges[1::2] - edges[::2]).max() == n
    _, offline = untangle(p[:, None], np.isnan(p[:, None]).any(-1), list(a.topology.symmetry),
                          margin, max_frames=max_frames, near=near)  # fmt: skip
    assert not offline.any()


def test_a_long_identity_switch_likewise():
    """The same for two people whose samples the tracker exchanges for longer than
    ``MAX_SWAP_S``: undone for ``max_frames`` frames, then taken as detected."""
    (_, a), (_, b) = _two_people(T=300)
    n = int(MAX_SWAP_S * 30)
    ys = np.stack([a.positions, b.positions], 1)
    ys[100 : 100 + n + 40] = ys[100 : 100 + n + 40, ::-1]
    margin, near, max_frames = untangle_stats(ys, a.times())
    order, _ = _causal(ys, list(a.topology.symmetry), margin, near, max_frames)
    moved = order[:, 0] != 0
    assert moved[100 : 100 + n].all() and not moved[:100].any()
    assert not moved[100 + n : 100 + n + 40].any()
    edges = np.flatnonzero(np.diff(np.concatenate([[0], moved.astype(int), [0]])))
    assert (edges[1::2] - edges[::2]).max() == n


def test_a_swap_under_way_at_the_first_measurement_is_seen_from_its_start():
    """The statistics come at frame ``STREAM_FIRST``; the frames before are returned as
    detected, but they set the loops' state, so a swap that began before is undone
    until it ends (and not the frames after it)."""
    a, p = _swapped_wrists(8, 25)
    _, exch = untangle_stream(p[:, None], a.times(), list(a.topology.symmetry))
    assert np.flatnonzero(exch[:, 0, 0]).tolist() == list(range(STREAM_FIRST, 25))


@pytest.mark.parametrize("timestamps", [True, False])
def test_live_untangles_as_batch_does(timestamps):
    """``LiveSmoother(gates_from="stream")`` undoes the pose estimator's swaps as
    ``smooth(..., gates="stream")`` does, bit for bit, and closer to the truth than
    without (the benchmark's left/right swaps)."""
    truth, noisy = _benchmark_people(seed=1, timestamps=timestamps)
    batch = tk.smooth(noisy, "robust_online", gates="stream")
    assert any(b.metadata["diagnostics"]["lr_swapped"].any() for b in batch)
    out = np.stack([b.positions for b in batch], 1)
    np.testing.assert_array_equal(_live(noisy), out)
    plain = np.stack(
        [b.positions for b in tk.smooth(noisy, "robust_online", gates="stream", untangle=False)],
        1,
    )
    true = np.stack([t.positions for t in truth], 1)
    assert _rmse(out, true) < 0.8 * _rmse(plain, true)


@pytest.mark.parametrize("method", ["kf", "one_euro"])
def test_a_method_without_gates_untangles_live_too(method):
    """A method without gates measures nothing but the untangling on the stream
    (``gates_from="stream"``): live equals the causal untangling of the recording
    (``untangle_sequences(stream=True)``) smoothed by the method, and the pose
    estimator's swaps undone bring it closer to the truth."""
    truth, noisy = _benchmark_people(seed=1)
    live = _live(noisy, method=method)
    untangled, info = untangle_sequences(noisy, stream=True)
    assert any(i["lr_swapped"].any() for i in info)
    batch = np.stack([b.positions for b in tk.smooth(untangled, method, untangle=False)], 1)
    np.testing.assert_allclose(live, batch, rtol=0, atol=1e-9)
    plain = np.stack([b.positions for b in tk.smooth(noisy, method, untangle=False)], 1)
    true = np.stack([t.positions for t in truth], 1)
    assert _rmse(live, true) < 0.8 * _rmse(plain, true)


def test_a_method_without_gates_untangles_with_a_sample():
    """``gates_from=<recording>`` gives a method without gates the untangling's
    statistics: the wrists' swap is undone, frame for frame."""
    a, p = _swapped_wrists(80, 95, T=200)
    live = tk.LiveSmoother(a.topology, "kf", fps=30, gates_from=a)
    flags = []
    for t in range(len(p)):
        live.update(p[t])
        flags.append(bool(live.swapped["lr_swapped"][0]))
    assert np.flatnonzero(flags).tolist() == list(range(80, 95))


def test_a_keyed_stream_follows_the_people_through_an_identity_switch():
    """Two tracked ids whose samples the tracker exchanges for 20 frames: live, with the
    statistics from a sample recording, each id keeps its own person; ``swapped`` says
    when."""
    (t0, a), (t1, b) = _two_people()
    pa, pb = a.positions.copy(), b.positions.copy()
    pa[50:70], pb[50:70] = b.positions[50:70], a.positions[50:70]
    live = tk.LiveSmoother(a.topology, fps=30, gates_from=a)
    seen = []
    out = {7: [], 9: []}
    for t in range(len(pa)):
        res = live.update({7: pa[t], 9: pb[t]})
        out[7].append(res[7])
        out[9].append(res[9])
        seen.append(live.swapped["identity_swapped"][7])
    assert np.flatnonzero(seen).tolist() == list(range(50, 70))
    for key, truth in ((7, t0), (9, t1)):
        assert np.nanmax(np.linalg.norm(np.array(out[key]) - truth, axis=-1)) < 15


def test_one_body_left_right_swap_live():
    """One person in an array stream: the wrists' swap undone, reported per pair."""
    a, p = _swapped_wrists(80, 95, T=200)
    live = tk.LiveSmoother(a.topology, fps=30, gates_from=a)
    flags = []
    for t in range(len(p)):
        live.update(p[t])
        flags.append(bool(live.swapped["lr_swapped"][0]))
    assert np.flatnonzero(flags).tolist() == list(range(80, 95))


def test_when_the_stream_is_not_untangled():
    (_, a), _ = _two_people()
    # metres: left as they are with "auto" (as smooth()), nothing reported
    live = tk.LiveSmoother(a.topology, "kf", fps=30, units="m")
    live.update(a.positions[0] / 1000)
    assert live.swapped is None
    # asked for, with nothing to measure the decisions on: refused
    with pytest.raises(ValueError, match="untangle=True"):
        tk.LiveSmoother(a.topology, fps=30, untangle=True, units="m")
    with pytest.raises(ValueError, match="untangle"):
        tk.LiveSmoother(a.topology, fps=30, untangle="yes")
    # switched off
    live = tk.LiveSmoother(a.topology, fps=30, gates_from=a, untangle=False)
    live.update(a.positions[0])
    assert live.swapped is None


@pytest.mark.parametrize("causal", [False, True])
def test_a_glitch_of_both_wrists_at_once_is_no_reference(causal):
    """Both wrists glitch in the same frames: the left one onto the right wrist's place
    (two frames), the right one 300 px away (eight). The left one's samples look like an
    exchange, the right one's count for neither side (too far from both). The exchange
    must end when the left wrist is back: the glitches are no reference for the frames
    after them. (When every sample was a reference, the right wrist's glitch became the
    left side's last sample and the exchange lasted to the end of the recording, shorter
    than MAX_SWAP_S after it.)"""
    (_, a), _ = _two_people(T=140)
    p = a.positions.copy()
    p[100:102, 1] = p[100:102, 2] + np.array([8.0, 5.0])
    p[100:108, 2] += np.array([0.0, 300.0])
    margin, near, max_frames = untangle_stats(p[:, None], a.times())
    pairs = list(a.topology.symmetry)
    if causal:
        _, exch = _causal(p[:, None], pairs, margin, near, max_frames)
    else:
        _, exch = untangle(p[:, None], np.isnan(p[:, None]).any(-1), pairs, margin,
                           max_frames=max_frames, near=near)  # fmt: skip
    flags = exch[:, 0, 0]
    assert not flags[:100].any()
    assert not flags[102:].any()


@pytest.mark.parametrize("causal", [False, True])
def test_a_reference_grows_stale_and_is_taken_again(causal):
    """The left wrist is missing for 30 frames while it moves 150 px away, and comes back
    there: too far from its last sample for one frame's step, so that sample stays its
    reference for a while. The step allowed from a reference grows with the frames since
    it was stored, so the wrist is taken again. Thirty frames later the right wrist
    glitches for one frame onto the place the left one left: no exchange (with the left
    wrist's reference still the place it left, the glitch looked like a left wrist and
    the pair was exchanged)."""
    from test_pose2d import TOPO

    rng = np.random.default_rng(0)
    T = 160
    t = np.arange(T)
    p = np.zeros((T, 3, 2))
    p[:, 0] = [400.0, 200.0]  # neck
    p[:, 1, 0] = 250.0 + np.clip(t - 50, 0, 30) * 5.0  # the left wrist moves 150 px ...
    p[:, 1, 1] = 300.0
    p[:, 2] = [700.0, 300.0]  # the right wrist stays
    p += rng.normal(0, 1.5, p.shape)
    p[50:80, 1] = np.nan  # ... while it is missing
    p[110, 2] = [252.0, 301.0]  # the right wrist's glitch
    a = tk.SkeletonSequence(p, TOPO, fps=30.0, units="px")
    margin, near, max_frames = untangle_stats(p[:, None], a.times())
    assert near < 150  # the wrist's return is not one plausible step
    pairs = list(TOPO.symmetry)
    if causal:
        _, exch = _causal(p[:, None], pairs, margin, near, max_frames)
    else:
        _, exch = untangle(p[:, None], np.isnan(p[:, None]).any(-1), pairs, margin,
                           max_frames=max_frames, near=near)  # fmt: skip
    assert not exch.any()
