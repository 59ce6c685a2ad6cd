"""INFERRED joints put back at their bone's length (``inferred_bones``, robust pair)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import tobitkf as tk
from tobitkf.evaluation.synthetic import generate_motion
from tobitkf.skeleton.sequence import TrackingState
from tobitkf.skeleton.topology import get_topology
from tobitkf.smoothing.robust_gating import project_inferred

TOPO = get_topology("kinect_v2")
PARENTS = np.asarray(TOPO.parents)
CHAIN = [TOPO.index(n) for n in ("WristRight", "HandRight", "HandTipRight", "ThumbRight")]


def _same(a: np.ndarray, b: np.ndarray) -> None:
    np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12, equal_nan=True)


@settings(max_examples=150, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    p_inferred=st.floats(0.0, 1.0),
    p_missing=st.floats(0.0, 0.3),
    p_no_length=st.floats(0.0, 0.5),
)
def test_projection_keeps_direction_and_sets_the_length(seed, p_inferred, p_missing, p_no_length):
    rng = np.random.default_rng(seed)
    T, J = 4, TOPO.n_joints
    y = rng.normal(size=(T, J, 3))
    y[rng.random((T, J)) < p_missing] = np.nan
    inferred = rng.random((T, J)) < p_inferred
    L = rng.uniform(0.01, 0.5, J)
    L[rng.random(J) < p_no_length] = np.nan
    out = project_inferred(y, inferred, TOPO.parents, L)
    for t in range(T):
        for j in range(J):
            p = PARENTS[j]
            if p < 0 or not inferred[t, j] or np.isnan(y[t, j]).any():
                _same(out[t, j], y[t, j])  # tracked, missing and roots: untouched
                continue
            # an inferred parent's correction moves the child first (the chain as a whole)
            moved = out[t, p] - y[t, p] if inferred[t, p] and np.isfinite(y[t, p]).all() else 0
            base = y[t, j] + moved
            v = base - out[t, p]
            if np.isfinite(L[j]) and np.isfinite(v).all() and np.linalg.norm(v) > 0:
                w = out[t, j] - out[t, p]
                assert np.linalg.norm(w) == pytest.approx(L[j], rel=1e-12)
                # the same direction from the parent: parallel and not reversed
                np.testing.assert_allclose(np.cross(w, v), 0.0, atol=1e-12)
                assert np.dot(w, v) > 0
            else:
                _same(out[t, j], base)


def _drifting_chain(drift: float, seed: int = 0):
    """The built-in arm motion, 5 mm noise, and the right hand chain INFERRED for 2 s
    while the whole chain drifts (a smoothstep up to ``drift`` m, then back) along the
    forearm: the sensor's guess keeps the hand's shape but not the forearm's length."""
    truth = generate_motion("arms", duration=8.0, seed=seed)
    noise = np.random.default_rng(seed).normal(scale=0.005, size=truth.positions.shape)
    pos = truth.positions + noise
    states = np.full(pos.shape[:2], int(TrackingState.TRACKED), dtype=np.int8)
    a, b = 90, 150
    s = np.linspace(0, 1, b - a)
    grow = drift * np.sin(np.pi * s) ** 2
    elbow, wrist = TOPO.index("ElbowRight"), TOPO.index("WristRight")
    axis = truth.positions[a:b, wrist] - truth.positions[a:b, elbow]
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    pos[a:b, CHAIN] += (grow[:, None] * axis)[:, None, :]
    states[a:b, CHAIN] = TrackingState.INFERRED
    seq = truth.replace(positions=pos, tracking_state=states)
    return seq, truth.positions, (slice(a, b), CHAIN)


def _err(out, truth, where) -> float:
    d = out.positions[where] - truth[where]
    return float(np.sqrt(np.mean(np.sum(d**2, axis=-1))))


@pytest.mark.parametrize("method", ["robust", "robust_online"])
def test_a_chain_drifting_along_its_bone_is_put_back(method):
    # 5 cm of drift along the forearm stays inside the bone gate's tolerance (3 cm + 15 %
    # of 25 cm), so without the rule the drift is accepted as motion
    seq, truth, where = _drifting_chain(0.05)
    with_rule = _err(tk.smooth(seq, method=method), truth, where)
    without = _err(tk.smooth(seq, method=method, inferred_bones=False), truth, where)
    raw = float(np.sqrt(np.mean(np.sum((seq.positions[where] - truth[where]) ** 2, axis=-1))))
    assert without > 0.7 * raw  # the drift is followed: 5 cm peak, about 3 cm rms
    assert with_rule < 0.5 * without


@pytest.mark.parametrize("method", ["robust", "robust_online"])
def test_the_gates_judge_the_projected_guess(method):
    # 12 cm along the forearm breaks the bone gate's tolerance: the raw guess is
    # rejected, the guess put back at the bone's length passes
    seq, _, (frames, chain) = _drifting_chain(0.12)
    rejected = tk.smooth(seq, method=method).metadata["diagnostics"]["rejected"]
    assert not rejected[frames, chain].any()
    off = tk.smooth(seq, method=method, inferred_bones=False).metadata["diagnostics"]["rejected"]
    assert off[frames, chain[0]].sum() >= 5


@pytest.mark.parametrize("method", ["robust", "robust_online"])
def test_tracked_recordings_are_unchanged(method):
    seq, _, _ = _drifting_chain(0.05)
    tracked = seq.replace(tracking_state=np.full_like(seq.tracking_state, 2))
    a = tk.smooth(tracked, method=method)
    b = tk.smooth(tracked, method=method, inferred_bones=False)
    np.testing.assert_array_equal(a.positions, b.positions)


def test_two_dimensional_bones_are_not_projected_batch_or_live():
    # a bone seen in projection has no one length: 2-D keypoints keep their guesses
    seq, _, _ = _drifting_chain(0.05)
    for flat in (seq.replace(positions=seq.positions[..., :2]),
                 seq.replace(positions=seq.positions[..., :2] * 500, units="px")):  # fmt: skip
        for method in ("robust", "robust_online"):
            a = tk.smooth(flat, method=method)
            b = tk.smooth(flat, method=method, inferred_bones=False)
            np.testing.assert_array_equal(a.positions, b.positions)
    flat = seq.replace(positions=seq.positions[..., :2])  # 2-D, in metres: say so live
    live = tk.LiveSmoother(TOPO, method="robust_online", fps=seq.fps, units="m")
    frames = np.stack([live.update(flat.positions[k], flat.tracking_state[k])
                       for k in range(flat.n_frames)])  # fmt: skip
    _same(frames, tk.smooth(flat, method="robust_online", inferred_bones=False).positions)
    # and in 3-D the stream does project, as the batch does
    live = tk.LiveSmoother(TOPO, method="robust_online", fps=seq.fps)
    frames = np.stack([live.update(seq.positions[k], seq.tracking_state[k])
                       for k in range(seq.n_frames)])  # fmt: skip
    _same(frames, tk.smooth(seq, method="robust_online").positions)
