"""tools/error_breakdown.py: the bounds of what better gates or bridging could reach, and
(--truth-check) the truth's own bone-length failures, found
by the bone gate's rule (docs/robust.md, "Where the remaining KERAAL error is")."""

from __future__ import annotations

import numpy as np

from conftest import tool_module


def _tool():
    return tool_module("error_breakdown")


def _chain(T: int = 30) -> np.ndarray:
    """A truth of three joints in a line (root, 0.3 m bone, 0.25 m bone), drifting."""
    t = np.zeros((T, 3, 3))
    t[:, :, 0] = np.linspace(0, 1, T)[:, None]
    t[:, 1, 1] = 0.3
    t[:, 2, 1] = 0.55
    return t


def test_a_stretched_bone_flags_exactly_its_frames_and_both_ends():
    eb = _tool()
    truth = _chain()
    # bone 1->2 (0.25 m, tolerance 0.03 + 0.15 * 0.25 = 0.0675 m)
    truth[[5, 6, 7], 2, 1] += 0.20  # stretched: off
    truth[[12, 13], 2, 1] += 0.06  # within the tolerance: not off
    truth[20, 2] = np.nan  # missing: not off
    off = eb.truth_inconsistent(truth, (-1, 0, 1), tol_abs=0.03, tol_rel=0.15)
    expect = np.zeros((30, 3), dtype=bool)
    expect[[5, 6, 7], 1] = expect[[5, 6, 7], 2] = True
    np.testing.assert_array_equal(off, expect)


def test_the_default_tolerance_is_the_robust_bone_gates():
    eb = _tool()
    from tobitkf.smoothing.robust import ROBUST_DEFAULTS

    truth = _chain()
    tol = ROBUST_DEFAULTS["bone_tol_abs"] + ROBUST_DEFAULTS["bone_tol_rel"] * 0.3
    truth[3, 0, 1] -= tol + 0.005  # root moves away from joint 1: bone 0->1 just off
    truth[9, 0, 1] -= tol - 0.005  # just within
    off = eb.truth_inconsistent(truth, (-1, 0, 1))
    assert sorted(zip(*np.nonzero(off))) == [(3, 0), (3, 1)]


def test_bounds_drop_the_classes_made_exact():
    # class -> (samples, raw sse, method sse); sums by hand
    total = {
        "glitch, accepted": (1, 9.0, 4.0),
        "glitch, rejected": (1, 16.0, 1.0),
        "good, accepted": (2, 2.0, 2.0),
        "good, rejected": (1, 1.0, 3.0),
    }
    assert _tool().bounds(total) == [
        ("as measured", 10.0),
        ("every rejected sample exactly right", 6.0),
        ("every glitch and every rejected sample exactly right", 2.0),
    ]


def test_compare_split_puts_each_sample_in_the_class_of_what_each_method_did():
    eb = _tool()
    e_method = np.array([[1.0, 2.0], [3.0, np.nan], [4.0, 0.5]])
    e_other = np.array([[2.0, 2.0], [1.0, 5.0], [np.nan, 1.5]])
    rej_method = np.array([[False, True], [True, False], [False, True]])
    rej_other = np.array([[False, True], [False, True], [True, False]])
    split = eb.compare_split(e_method, e_other, rej_method, rej_other)
    # (0,0) both accepted; (0,1) both rejected; (1,0) only the method; (1,1) and (2,0)
    # lack an error; (2,1) only the method
    assert split == {
        "both accepted": (1, 1.0, 4.0),
        "both rejected": (1, 4.0, 4.0),
        "only the other rejected": (0, 0.0, 0.0),
        "only the method rejected": (2, 9.0 + 0.25, 1.0 + 2.25),
    }


def test_compare_bounds_swap_in_the_methods_error_class_by_class():
    split = {
        "both accepted": (10, 1.0, 2.0),
        "both rejected": (5, 3.0, 7.0),
        "only the other rejected": (1, 0.5, 4.0),
        "only the method rejected": (2, 6.0, 5.0),
    }
    rows = _tool().compare_bounds(split)
    assert [v for _, v in rows] == [18.0, 17.0, 13.0, 9.5, 10.5]
    assert rows[-1][1] == sum(v[1] for v in split.values())  # the method's own
