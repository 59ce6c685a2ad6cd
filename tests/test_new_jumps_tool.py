"""tools/new_jumps.py: the count of output steps larger than the input's largest
(docs/robust.md, "No new jumps")."""

from __future__ import annotations

import numpy as np
import pytest

import tobitkf as tk
from conftest import tool_module


def _seq(T: int = 8) -> tk.SkeletonSequence:
    topo = tk.get_topology("kinect_v2")
    pos = np.zeros((T, topo.n_joints, 3))
    pos[:, :, 0] = 0.01 * np.arange(T)[:, None]  # every input step 1 cm
    return tk.SkeletonSequence(positions=pos, topology=topo, fps=30.0)


def test_an_output_step_over_the_inputs_largest_is_counted_with_its_excess():
    nj = tool_module("new_jumps")
    seq = _seq()
    out = seq.positions.copy()
    out[5:, 3, 0] += 0.04  # joint 3: a 5 cm step at frame 5, 4 cm over the input's 1 cm
    out[6:, 4, 0] += 0.0005  # joint 4: 0.5 mm over, within the millimetre of rounding
    np.testing.assert_allclose(nj.new_jumps(seq, out), [0.04], rtol=1e-9)


def test_steps_where_the_input_is_absent_or_not_tracked_do_not_count():
    nj = tool_module("new_jumps")
    seq = _seq()
    pos = seq.positions.copy()
    pos[4, 3] = np.nan  # joint 3 absent at frame 4: no input step at 4 nor at 5
    states = np.full(pos.shape[:2], tk.TrackingState.TRACKED, dtype=np.int8)
    states[2, 7] = tk.TrackingState.NOT_TRACKED  # joint 7 not tracked at frame 2
    seq = seq.replace(positions=pos, tracking_state=states)
    out = seq.positions.copy()
    out[4, 3] = out[3, 3] + [0.5, 0, 0]  # a filled frame jumps: the input has no step there
    out[2, 7] = out[1, 7] + [0.5, 0, 0]
    assert nj.new_jumps(seq, out).size == 0
    out[6:, 3, 0] += 0.05  # a step between two present frames does count
    assert nj.new_jumps(seq, out).size == 1


@pytest.mark.parametrize("spec, method, offline", [("kf+rts", "kf", True), ("kf", "kf", False)])
@pytest.mark.parametrize("guard", [False, True])
def test_method_specs(spec, method, offline, guard):
    seq = _seq()
    seq = seq.replace(positions=seq.positions + 0.01 * np.sin(np.arange(8))[:, None, None])
    got = tool_module("new_jumps").runner(spec, guard)(seq)
    want = tk.smooth(seq, method=method, offline=offline, step_guard=guard)
    np.testing.assert_array_equal(got.positions, want.positions)
    assert got.metadata["provenance"]["params"].get("step_guard", False) is guard
