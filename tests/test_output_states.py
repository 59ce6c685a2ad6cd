"""The states of a smoothed output (smoothing/output_states.py, _state_kernels.py).

Each compiled rule against its plain numpy definition, written out here, on random
inputs; then through ``tk.smooth`` with user methods that return what the checks of a
sequence refuse (inf positions, negative std) or a std where there is no estimate, and
the batch path of ``_replace_valid`` against ``replace``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import tobitkf as tk
from tobitkf.skeleton.sequence import SampleState, SkeletonSequence, TrackingState
from tobitkf.skeleton.topology import Topology
from tobitkf.smoothing import _state_kernels as k
from tobitkf.smoothing.output_states import output_states, output_tracking, sample_states
from tobitkf.smoothing.timebase import measurements

M, R, X, E, NONE = (int(s) for s in SampleState)


def _sample_states_ref(missing, rejected, finite, causal):
    """The rule written out sample by sample, column by column (time first)."""
    T, N = missing.shape[0], math.prod(missing.shape[1:])
    miss = missing.reshape(T, N)
    rej = np.broadcast_to(rejected, missing.shape).reshape(T, N)
    fin = finite.reshape(T, N)
    out = np.empty(miss.shape, dtype=np.int8)
    for n in range(miss.shape[1]):
        used = [t for t in range(T) if not miss[t, n] and not rej[t, n]]
        for t in range(T):
            if not fin[t, n]:
                out[t, n] = NONE
            elif not miss[t, n]:
                out[t, n] = R if rej[t, n] else M
            elif not causal and used and used[0] < t < used[-1]:
                out[t, n] = X  # between two used measurements of the joint
            else:
                out[t, n] = E
    return out.reshape(missing.shape)


def _tracking_ref(states, sample):
    filled = (sample >= R) & (sample <= E)
    out = np.full(sample.shape, int(TrackingState.TRACKED), dtype=np.int8)
    if states is not None:
        out[:] = states
    out[filled] = TrackingState.INFERRED
    out[sample == NONE] = TrackingState.NOT_TRACKED
    return out, filled.sum(axis=0)


def _masks(seed: int, shape: tuple[int, ...], p: float) -> np.ndarray:
    return np.random.default_rng(seed).random(shape) < p


@settings(max_examples=60, deadline=None)
@given(
    T=st.integers(0, 12),
    cols=st.tuples(st.integers(1, 3), st.integers(1, 4)),
    p=st.floats(0.0, 1.0),
    causal=st.booleans(),
    seed=st.integers(0, 2**32 - 1),
)
def test_sample_states_follow_the_rule_sample_by_sample(T, cols, p, causal, seed):
    shape = (T, *cols)
    missing, rejected, finite = (_masks(seed + i, shape, p) for i in range(3))
    finite |= ~missing & _masks(seed + 3, shape, 0.8)  # mostly: measured samples have one
    got = sample_states(missing, rejected, finite, causal)
    assert got.dtype == np.int8 and got.shape == shape
    assert np.array_equal(got, _sample_states_ref(missing, rejected, finite, causal))


def test_sample_states_of_one_joint():
    # a gap between two used measurements, rejected samples, no estimate at the start
    missing = np.array([1, 0, 1, 1, 0, 0, 1], dtype=bool)[:, None]
    rejected = np.array([0, 0, 0, 0, 1, 0, 0], dtype=bool)[:, None]
    finite = np.array([0, 1, 1, 1, 1, 1, 1], dtype=bool)[:, None]
    assert sample_states(missing, rejected, finite, False)[:, 0].tolist() == [
        NONE, M, X, X, R, M, E,
    ]  # fmt: skip
    assert sample_states(missing, rejected, finite, True)[:, 0].tolist() == [
        NONE, M, E, E, R, M, E,
    ]  # fmt: skip
    # a scalar ``rejected`` broadcasts; a rejected missing sample is missing
    assert sample_states(missing, True, finite, False)[:, 0].tolist() == [
        NONE, R, E, E, R, R, E,
    ]  # fmt: skip


@settings(max_examples=60, deadline=None)
@given(
    T=st.integers(0, 10),
    N=st.integers(1, 6),
    with_states=st.booleans(),
    seed=st.integers(0, 2**32 - 1),
)
def test_output_tracking_and_filled_counts_follow_their_definition(T, N, with_states, seed):
    rng = np.random.default_rng(seed)
    sample = rng.integers(-1, 6, size=(T, 2, N)).astype(np.int8)  # codes out of range too
    states = rng.integers(0, 3, size=(T, 2, N)).astype(np.int8) if with_states else None
    got, filled = output_tracking(states, sample)
    want, want_filled = _tracking_ref(states, sample)
    assert got.dtype == np.int8 and np.array_equal(got, want)
    assert np.array_equal(filled, want_filled)


_values = st.sampled_from([0.0, -0.0, 1.5, -2.0, 1e308, np.nan, np.inf, -np.inf])


@settings(max_examples=80, deadline=None)
@given(
    T=st.integers(0, 6),
    N=st.integers(1, 5),
    D=st.integers(1, 3),
    data=st.data(),
)
def test_finite_samples_and_std_flags_follow_their_definition(T, N, D, data):
    est = np.array(data.draw(st.lists(_values, min_size=T * N * D, max_size=T * N * D)))
    est = est.reshape(T, N, D)
    std = np.array(data.draw(st.lists(_values, min_size=T * N, max_size=T * N))).reshape(T, N)
    finite, has_inf = k.finite_samples(est)
    assert np.array_equal(finite, np.isfinite(est).all(axis=-1))
    assert has_inf == bool(np.isinf(est).any())
    stray, bad = k.std_flags(std, finite)
    assert stray == bool((~finite & ~np.isnan(std)).any())
    assert bad == bool((finite & (np.isinf(std) | (std < 0))).any())


def test_output_states_of_a_batch():
    rng = np.random.default_rng(1)
    T, B, J = 30, 3, 4
    est = rng.normal(size=(T, B, J, 3))
    est[rng.random((T, B, J)) < 0.2, 1] = np.nan
    missing, rejected = _masks(2, (T, B, J), 0.3), _masks(3, (T, B, J), 0.2)
    states = rng.integers(0, 3, size=(T, B, J)).astype(np.int8)
    std = rng.uniform(0.0, 1.0, size=(T, B, J))  # a std everywhere: NaN'd where no estimate
    finite = np.isfinite(est).all(axis=-1)
    for causal in (False, True):
        out = output_states(est, std, missing, rejected, states, causal)
        want = _sample_states_ref(missing, rejected, finite, causal)
        assert np.array_equal(out.sample, want)
        assert np.array_equal(out.tracking, _tracking_ref(states, want)[0])
        assert np.array_equal(out.filled, ((missing | rejected) & finite).sum(axis=0))
        assert np.array_equal(out.std, np.where(finite, std, np.nan), equal_nan=True)
        assert out.valid
    assert not output_states(est, -std, missing, rejected, states, False).valid
    est[0, 0, 0, 0] = -np.inf
    assert not output_states(est, None, missing, rejected, None, False).valid
    # no input states: a body with nothing filled gets none
    gap = np.zeros((T, B, J), dtype=bool)
    gap[4, 0, 2] = True  # body 0 filled once, body 1 and 2 never
    none = output_states(np.nan_to_num(est), None, gap, ~gap & gap, None, False)
    assert none.tracking_state(0)[4, 2] == TrackingState.INFERRED
    assert none.tracking_state(1) is None and none.tracking_state(2) is None


# ---------------------------------------------------------------- through smooth


@pytest.fixture
def returning_method():
    """A user method returning its input's measurements, with a std, both changed by
    parameters: ``bad`` = "inf" puts an inf position at body 1, "negative" a negative
    std at body 1, "stray" a std where the position is NaN."""

    def run(inp, bad):
        est = np.array(inp.ys)
        std = np.full(inp.missing.shape, 0.1)
        std[inp.missing] = np.nan
        if bad == "inf":
            est[5, 1, 0, 0] = np.inf
        elif bad == "negative":
            std[5, 1, 1] = -1.0
        elif bad == "stray":
            std[inp.missing] = 0.5
        return tk.SmoothOutput(est, std=std)

    tk.register_method("test_returning", run, params={"bad": "none"}, causal=True)
    yield "test_returning"
    tk.unregister_method("test_returning")


def _bodies(n: int = 3) -> list[SkeletonSequence]:
    rng = np.random.default_rng(0)
    topo = Topology.from_names(["a", "b"], up_axis=1, name="pair")
    out = []
    for _ in range(n):
        pos = rng.normal(size=(20, 2, 3))
        pos[3:6, 0] = np.nan
        out.append(SkeletonSequence(pos, topo, fps=30.0))
    return out


def test_smooth_keeps_the_sequence_checks_of_a_method_output(returning_method):
    with pytest.raises(ValueError, match="positions must be finite or NaN, found inf"):
        tk.smooth(_bodies(), method=returning_method, bad="inf")
    with pytest.raises(ValueError, match="std values must be >= 0 and finite"):
        tk.smooth(_bodies(), method=returning_method, bad="negative")
    # a std where there is no estimate is NaN'd, not refused
    for out in tk.smooth(_bodies(), method=returning_method, bad="stray"):
        assert np.array_equal(np.isnan(out.std), out.sample_state == NONE)
        assert (out.sample_state[3:6, 0] == NONE).all()


def test_smoothed_bodies_equal_checked_ones(returning_method):
    bodies = _bodies()
    out = tk.smooth(bodies, method=returning_method)
    for s, o in zip(bodies, out, strict=True):
        checked = s.replace(
            positions=o.positions, std=o.std, sample_state=o.sample_state,
            tracking_state=o.tracking_state, metadata=o.metadata,
        )  # fmt: skip
        for f in ("positions", "std", "sample_state", "tracking_state"):
            a, b = getattr(o, f), getattr(checked, f)
            if f == "tracking_state":  # no input states, nothing filled: none
                assert a is None and b is None
            else:
                assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True)
        assert (o.topology, o.fps, o.units, o.body_id) == (s.topology, s.fps, s.units, s.body_id)
    with pytest.raises(TypeError, match="not fields"):
        bodies[0]._replace_valid(position=bodies[0].positions)


def test_a_partly_nan_measurement_is_missing_on_every_axis():
    pos = np.arange(4 * 2 * 3, dtype=float).reshape(4, 2, 3)
    ys, missing = measurements(pos, None)
    assert ys is pos and not missing.any()  # nothing to change: not copied
    pos[1, 0, 2] = np.nan
    pos[2, 1] = np.nan
    ys, missing = measurements(pos, None)
    assert missing.tolist() == [[False, False], [True, False], [False, True], [False, False]]
    assert np.isnan(ys[1, 0]).all() and np.isnan(ys[2, 1]).all()
    assert np.array_equal(ys[~missing], pos[~missing])
