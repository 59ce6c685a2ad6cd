"""The pose data model: (T, J, D) positions with D = 2 or 3, confidence, units, and
topologies built from the joint names and bones a pose file declares."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tobitkf.io.npz import read_npz, write_npz
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology, parents_from_edges

NAMES = ("snout", "leftear", "rightear", "tailbase")


def _seq(D=2, **kw):
    rng = np.random.default_rng(0)
    return SkeletonSequence(rng.normal(size=(5, 4, D)) * 100, Topology.from_names(NAMES), **kw)


def test_two_and_three_dimensional_positions():
    assert _seq(2).n_dims == 2 and _seq(3).n_dims == 3
    with pytest.raises(ValueError, match=r"\(T, J, 3\) or \(T, J, 2\)"):
        _seq(4)
    with pytest.raises(ValueError, match=r"\(T, J, 3\) or \(T, J, 2\)"):
        _seq(1)


def test_units_default_metres_for_3d_unknown_for_2d():
    assert _seq(3).units == "m" and _seq(3).metres_per_unit == 1.0
    assert _seq(2).units is None and _seq(2).metres_per_unit is None
    assert _seq(3, units=None).units is None  # unknown, said explicitly
    assert _seq(2, units="PX").units == "px" and _seq(2, units="px").metres_per_unit is None
    assert _seq(3, units="mm").metres_per_unit == 0.001
    with pytest.raises(ValueError, match="units must be one of"):
        _seq(2, units="furlong")
    # replace keeps the units
    assert _seq(2, units="px").replace(fps=30.0).units == "px"


def test_confidence_validated_and_sliced():
    conf = np.linspace(0, 1, 20).reshape(5, 4)
    conf[2, 1] = np.nan
    s = _seq(confidence=conf, body_id="mouse1")
    assert s.body_id == "mouse1"
    np.testing.assert_array_equal(s.confidence, conf)
    sub = s.select_joints(["tailbase", "snout"])
    np.testing.assert_array_equal(sub.confidence, conf[:, [3, 0]])
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        _seq(confidence=conf * 2)
    with pytest.raises(ValueError, match="shape"):
        _seq(confidence=conf[:, :3])
    conf_in = conf.copy()
    s = _seq(confidence=conf_in)
    conf_in[0, 0] = 0.5  # the sequence holds its own copy
    assert s.confidence[0, 0] == 0.0


def test_topology_from_directed_edges_is_that_tree():
    t = Topology.from_names(NAMES, edges=[("snout", "leftear"), ("snout", "rightear"),
                                          ("snout", "tailbase")])  # fmt: skip
    assert t.parents == (-1, 0, 0, 0)
    assert t.symmetry == ((1, 2),)  # left/right from the names
    assert Topology.from_names("abc", edges=[(2, 1), (1, 0)]).parents == (1, 2, -1)


def test_topology_from_a_graph_with_a_cycle_is_a_spanning_tree():
    # both ears joined to each other and to the snout: a triangle
    t = Topology.from_names(NAMES, edges=[(0, 1), (0, 2), (1, 2), (2, 1)])
    assert t.parents == (-1, 0, 0, -1)  # tailbase has no bone
    with pytest.raises(ValueError, match="not a joint"):
        Topology.from_names(NAMES, edges=[("snout", "tail")])
    with pytest.raises(ValueError, match="not both"):
        Topology.from_names(NAMES, parents=[-1, 0, 0, 0], edges=[(0, 1)])


@settings(max_examples=200, deadline=None)
@given(
    n=st.integers(1, 8),
    raw=st.lists(st.tuples(st.integers(0, 7), st.integers(0, 7)), max_size=20),
)
def test_parents_from_edges_is_a_forest_of_declared_bones(n, raw):
    edges = [(a % n, b % n) for a, b in raw]
    parents = parents_from_edges([f"j{i}" for i in range(n)], edges)
    undirected = {frozenset(e) for e in edges if e[0] != e[1]}
    for j, p in enumerate(parents):
        if p >= 0:
            assert frozenset((p, j)) in undirected  # every bone is a declared edge
    Topology(name="t", joints=tuple(f"j{i}" for i in range(n)), parents=parents)  # no cycle
    # connected components are kept: a bone per joint beyond the first of each component
    comp = list(range(n))

    def find(i):
        while comp[i] != i:
            i = comp[i]
        return i

    for e in undirected:
        a, b = tuple(e)
        comp[find(a)] = find(b)
    n_components = len({find(i) for i in range(n)})
    assert sum(p >= 0 for p in parents) == n - n_components


def test_npz_round_trip_of_2d_confidence_and_units(tmp_path):
    conf = np.linspace(0, 1, 20).reshape(5, 4)
    conf[1, 1] = np.nan
    a = _seq(2, confidence=conf, units="px", body_id="mouse1", fps=30.0)
    b = _seq(3, units="mm")
    path = tmp_path / "x.npz"
    write_npz([a, b], path)
    ra, rb = read_npz(path)
    np.testing.assert_array_equal(ra.positions, a.positions)
    np.testing.assert_array_equal(ra.confidence, conf)
    assert (ra.units, ra.body_id, ra.n_dims) == ("px", "mouse1", 2)
    assert (rb.units, rb.confidence, rb.n_dims) == ("mm", None, 3)
