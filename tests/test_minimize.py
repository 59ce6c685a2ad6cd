"""The compiled box-constrained minimiser (smoothing/_minimize.py) on problems with known
solutions: a quadratic whose minimum has a bound active (solved by hand), Rosenbrock's
function inside and against a bound, starts on a bound, points outside the function's
domain, and random convex quadratics in random boxes against the exact minimum found by
trying every set of active bounds (a property test: the KKT conditions hold). Its
comparison with scipy's L-BFGS-B on the noise fit's own objective is in
tests/test_robust_fit.py.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tobitkf.smoothing._minimize import (
    CONVERGED_F,
    CONVERGED_G,
    INVALID_F,
    INVALID_START,
    MAX_ITER,
    minimize,
)

CONVERGED = (CONVERGED_F, CONVERGED_G)


def quadratic(A, b):
    A, b = np.asarray(A, dtype=float), np.asarray(b, dtype=float)
    return lambda x: (0.5 * x @ A @ x - b @ x, A @ x - b)


def rosenbrock(x):
    f = np.sum(100 * (x[1:] - x[:-1] ** 2) ** 2 + (1 - x[:-1]) ** 2)
    g = np.zeros_like(x)
    g[:-1] = -400 * x[:-1] * (x[1:] - x[:-1] ** 2) - 2 * (1 - x[:-1])
    g[1:] += 200 * (x[1:] - x[:-1] ** 2)
    return f, g


def projected_gradient(x, g, lo, hi):
    return np.clip(x - g, lo, hi) - x


def test_quadratic_with_an_active_bound_reaches_the_minimum_solved_by_hand():
    A = np.array([[4.0, 1.0, 0.5], [1.0, 3.0, 1.0], [0.5, 1.0, 2.0]])
    b = np.array([1.0, 2.0, 9.0])
    lo, hi = -np.ones(3), np.ones(3)
    assert np.linalg.solve(A, b)[2] > 1  # the free minimum is outside the box
    # so x2 = 1 at the minimum, and the other two minimise the rest
    want = np.array([*np.linalg.solve(A[:2, :2], b[:2] - A[:2, 2]), 1.0])
    assert np.all(np.abs(want[:2]) < 1) and (A @ want - b)[2] < 0  # inside; pushed out
    x, f, nit, status = minimize(quadratic(A, b), np.zeros(3), lo, hi, ftol=1e-12, gtol=1e-9)
    assert status in CONVERGED and nit < 30
    assert x[2] == 1.0  # exactly on its bound
    np.testing.assert_allclose(x, want, rtol=0, atol=1e-8)
    assert f == pytest.approx(quadratic(A, b)(want)[0], rel=1e-12)


def test_rosenbrock_reaches_its_minimum_inside_a_box_and_against_a_bound():
    # inside [-2, 2]³ the minimum (1, 1, 1), from the classic start
    x, f, _, status = minimize(rosenbrock, [-1.2, 1.0, 1.0], [-2.0] * 3, [2.0] * 3,
                               ftol=1e-12, gtol=1e-9)  # fmt: skip
    assert status in CONVERGED
    np.testing.assert_allclose(x, 1.0, rtol=0, atol=1e-6)
    assert f < 1e-12
    # with x0 <= 0.5 the minimum is (0.5, 0.25): (1 - x0)² >= 1/4 there, 0 at x1 = x0²
    x, f, _, status = minimize(rosenbrock, [-1.2, 1.0], [-2.0, -2.0], [0.5, 2.0],
                               ftol=1e-12, gtol=1e-9)  # fmt: skip
    assert status in CONVERGED
    assert x[0] == 0.5
    assert x[1] == pytest.approx(0.25, abs=1e-8) and f == pytest.approx(0.25, rel=1e-12)


def test_starts_on_a_bound():
    fun = quadratic(2 * np.eye(2), [4.0, -2.0])  # free minimum (2, -1): outside [0, 1]²
    lo, hi = np.zeros(2), np.ones(2)
    # at the solution (1, 0), both variables pushed against their bounds: no step at all
    x, _, nit, status = minimize(fun, [1.0, 0.0], lo, hi)
    assert status == CONVERGED_G and nit == 0 and x.tolist() == [1.0, 0.0]
    # from the opposite corner, pulled away from both bounds, to the other two
    x, _, _, status = minimize(fun, [0.0, 1.0], lo, hi)
    assert status in CONVERGED and x.tolist() == [1.0, 0.0]
    # a start outside the box starts from its projection
    x, _, _, status = minimize(fun, [5.0, -5.0], lo, hi)
    assert status == CONVERGED_G and x.tolist() == [1.0, 0.0]
    # on the lower bounds with the minimum (0.3, 0.6) inside: leaves them
    x, _, _, status = minimize(quadratic(2 * np.eye(2), [0.6, 1.2]), [0.0, 0.0], lo, hi,
                               ftol=1e-12, gtol=1e-9)  # fmt: skip
    assert status in CONVERGED
    np.testing.assert_allclose(x, [0.3, 0.6], rtol=0, atol=1e-9)


@pytest.mark.parametrize("bad", [INVALID_F, math.inf, math.nan])
def test_points_outside_the_domain_are_stepped_back_from(bad):
    # sum (x - 1)² defined for x > 0.5 only; the first step from x0 = 5 (along -g, to -3)
    # lands outside it
    seen = []

    def fun(x):
        seen.append(x.copy())
        if np.any(x <= 0.5):
            return bad, np.full(x.shape, bad)
        return np.sum((x - 1) ** 2), 2 * (x - 1)

    x, _, _, status = minimize(fun, [5.0, 5.0], [-10.0] * 2, [10.0] * 2, ftol=1e-12, gtol=1e-9)
    assert status in CONVERGED and any(np.any(s <= 0.5) for s in seen)
    np.testing.assert_allclose(x, 1.0, rtol=0, atol=1e-8)
    # a start outside the domain: nothing to do
    x, _, nit, status = minimize(fun, [0.0, 2.0], [-10.0] * 2, [10.0] * 2)
    assert status == INVALID_START and nit == 0 and x.tolist() == [0.0, 2.0]


def test_relative_reduction_stops_on_a_large_objective():
    # 1e6 + sum (x - 3)⁴ from 0: the first iteration gains less than 1e-3 of f (its scale is
    # max(|f|, 1) = 1e6), so ftol = 1e-3 stops there, far from the minimum (the gradient is
    # large); a tiny ftol goes on to it
    def fun(x):
        return 1e6 + np.sum((x - 3) ** 4), 4 * (x - 3) ** 3

    box = ([-10.0] * 2, [10.0] * 2)
    x, f, nit, status = minimize(fun, [0.0, 0.0], *box, ftol=1e-3, gtol=1e-12)
    assert status == CONVERGED_F and nit == 1
    assert np.max(np.abs(fun(x)[1])) > 1
    x2, f2, nit2, _ = minimize(fun, [0.0, 0.0], *box, ftol=1e-15, gtol=1e-12)
    assert nit2 > 5 and f2 < f and np.all(np.abs(x2 - 3) < 0.1)


def test_maxiter_stops_early():
    x, _, nit, status = minimize(rosenbrock, [-1.2, 1.0], [-2.0] * 2, [2.0] * 2, maxiter=3)
    assert status == MAX_ITER and nit == 3
    assert rosenbrock(x)[0] < rosenbrock(np.array([-1.2, 1.0]))[0]


def box_qp_minimum(A, b, lo, hi):
    """``(x, f)`` at the exact minimum of ``x'Ax / 2 - b'x`` over the box (``A`` positive
    definite): every pattern of free / at-lower / at-upper variables gives a stationary
    point of the free ones; the minimum is the best of the feasible ones (its own pattern's
    is feasible)."""
    best_x, best_f = None, math.inf
    for pattern in itertools.product(range(3), repeat=b.size):
        p = np.array(pattern)
        free = p == 0
        x = np.where(p == 1, lo, hi)
        if free.any():
            rhs = b[free] - A[np.ix_(free, ~free)] @ x[~free]
            x[free] = np.linalg.solve(A[np.ix_(free, free)], rhs)
        if np.all(x >= lo) and np.all(x <= hi):
            f = 0.5 * x @ A @ x - b @ x
            if f < best_f:
                best_x, best_f = x, f
    return best_x, best_f


@settings(deadline=None, max_examples=60)
@given(n=st.integers(1, 4), seed=st.integers(0, 2**32 - 1))
def test_random_convex_quadratics_in_random_boxes_end_at_the_kkt_point(n, seed):
    rng = np.random.default_rng(seed)
    M = rng.uniform(-2, 2, size=(n, n))
    A = M @ M.T + 0.05 * np.eye(n)  # condition number up to about 1e3
    b = rng.normal(scale=3.0, size=n)
    lo = rng.uniform(-2, 1, size=n)
    hi = lo + rng.uniform(0.01, 3, size=n)
    x0 = rng.uniform(lo, hi)
    # ftol = 0: the projected-gradient test alone stops it
    x, _, _, status = minimize(quadratic(A, b), x0, lo, hi, ftol=0.0, gtol=1e-6)
    assert status == CONVERGED_G
    assert np.all(x >= lo) and np.all(x <= hi)
    # KKT, to the tolerance: no gradient along a free variable, none pushing one off its
    # bound (the projected gradient), and so near the exact minimum: for a strongly convex
    # function |x - x*| <= (1 + L) / mu |P(x - g) - x| (L, mu: largest and smallest
    # eigenvalue of A; from the projection's and the minimum's optimality conditions)
    pg = projected_gradient(x, A @ x - b, lo, hi)
    assert np.max(np.abs(pg)) <= 1e-6
    want_x, _ = box_qp_minimum(A, b, lo, hi)
    lam = np.linalg.eigvalsh(A)
    assert np.linalg.norm(x - want_x) <= (1 + lam[-1]) / lam[0] * np.linalg.norm(pg) + 1e-12
