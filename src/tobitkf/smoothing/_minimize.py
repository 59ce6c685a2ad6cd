"""Compiled minimiser of a smooth function of a few variables in a box (numba, ``cache=True``).

It is the optimiser of the robust smoother's noise fit (:mod:`tobitkf.smoothing.robust_fit`):
three parameters, a compiled objective. :func:`scipy.optimize.minimize` (L-BFGS-B) adds its
Python work to every one of its iterations (and its import, to the start-up); here the
whole fit is one compiled call (:func:`minimize_profile`).

The algorithm is L-BFGS-B's (Byrd, Lu, Nocedal & Zhu 1995, with the projection of Morales &
Nocedal 2011; scipy's settings), on a dense matrix: with a few variables the quasi-Newton
matrix ``B`` (``y'y / s'y`` of the last pair times the identity, then the BFGS updates of
the last 10 pairs ``s, y``, as L-BFGS-B's) is rebuilt in full. Each iteration from ``x``,
gradient ``g``:

1. the generalized Cauchy point: the first minimum of the quadratic model along the
   projected steepest-descent path ``P(x - t g)`` (a variable at a bound whose gradient
   pushes it outwards stays there; one whose breakpoint is passed is fixed at its bound);
2. the Newton step of the model in the variables still free there, projected onto the box;
   when that is not a descent direction, the step is cut where it leaves the box instead;
3. a line search along the (feasible) direction for the strong Wolfe conditions
   (sufficient decrease 1e-3, curvature 0.9), at most 20 evaluations, first step 1, longer
   steps up to the box; a point where the objective is not finite or is at least
   :data:`INVALID_F` counts as too far;
4. the pair ``s, y`` is stored when the curvature ``s'y`` is positive. A failed line search
   (or no descent direction) forgets the pairs (``B = I``) once; a second failure in a row
   stops (:data:`NO_PROGRESS`, the last point is kept).

It stops where scipy's L-BFGS-B would (the max-norm of the projected gradient
``P(x - g) - x`` at most ``gtol``, or a relative reduction of the objective in an iteration
``(f_k - f_k+1) / max(|f_k|, |f_k+1|, 1) <= ftol``) once the model agrees: its decrease
along the next direction, ``-g'd / 2``, is at most ``ftol max(|f|, 1) / 10``
(:data:`MODEL_TOL`); or after ``maxiter`` iterations. Without that condition a short step,
or a small gradient, in a flat valley (the noise fit's coloured share) ends the search
where the model still sees a larger decrease ahead, and where it ends depends on luck,
up to 5e-4 of the objective above the minimum; with it the objective ends closer to the
minimum than scipy's (tests/test_robust_fit.py), for 15–20 % more evaluations.

Reverse communication, as scipy's Fortran: :func:`start` and :func:`step` never call the
objective, the caller evaluates it where ``x`` says (``step`` moves ``x``) until ``step``
returns something else than :data:`EVALUATE`; ``x`` is then the result.
:func:`minimize_profile` is that loop compiled around the noise fit's objective,
:func:`minimize` the same loop in Python for any ``fun(x) -> (f, g)`` (the tests).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from tobitkf.smoothing._noise_kernels import profile_nll_grad
from tobitkf.smoothing._numba_cache import njit

__all__ = [
    "CONVERGED_F",
    "CONVERGED_G",
    "EVALUATE",
    "INVALID_F",
    "INVALID_START",
    "MAX_ITER",
    "NO_PROGRESS",
    "minimize",
    "minimize_profile",
    "start",
    "step",
]

_jit = njit(cache=True, nogil=True)

#: what :func:`step` returns: evaluate at ``x`` again; else why it stopped
EVALUATE, CONVERGED_F, CONVERGED_G, MAX_ITER, NO_PROGRESS, INVALID_START = range(6)
#: objective values at or above this mark points outside the function's domain
INVALID_F = 1e30
#: the line search: sufficient decrease, curvature, evaluations per search (scipy's)
C1, C2, MAX_LS = 1e-3, 0.9, 20
#: default tolerance of the projected gradient's max-norm (scipy's)
GTOL = 1e-5
#: pairs ``s, y`` the matrix is built from (scipy's)
MEMORY = 10
#: stop only when the model's decrease ahead is at most this fraction of ``ftol``
MODEL_TOL = 0.1
EPS = 2.220446049250313e-16

# the scalars of the state: objective at the iterate, slope along the direction, the trial
# step, the bracket's low end (best point so far: step, f, slope) and high end (step, f),
# the largest feasible step, trials in this search, iterations, evaluations, stored pairs,
# phase (start / line search)
_N_SCALARS = 14
_FK, _DPHI0, _ALPHA, _LO, _FLO, _DLO, _HI, _FHI, _AMAX, _NLS, _NIT, _NFEV, _NPAIRS, _PHASE = range(
    _N_SCALARS
)
_START, _SEARCH = 0.0, 1.0


@_jit
def start(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple:
    """A new state for minimising from ``x`` (clipped into the box in place; evaluate the
    objective there first): ``(scalars, B, x_k, g_k, direction, g at the bracket's low
    end, S, Y)``, the last two the stored pairs, oldest first."""
    n = x.shape[0]
    for i in range(n):
        x[i] = min(max(x[i], lo[i]), hi[i])
    sc = np.zeros(_N_SCALARS)
    sc[_PHASE] = _START
    B = np.zeros((n, n))
    _set_identity(B, 1.0)
    return (sc, B, x.copy(), np.zeros(n), np.zeros(n), np.zeros(n), np.zeros((MEMORY, n)),
            np.zeros((MEMORY, n)))  # fmt: skip


@_jit
def step(
    state: tuple,
    x: np.ndarray,
    f: float,
    g: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    ftol: float,
    gtol: float,
    maxiter: int,
) -> int:
    """Take ``f`` and ``g`` at ``x`` (where the last call asked) and move ``x`` to the next
    point to evaluate (:data:`EVALUATE`) or to the result (any other status)."""
    sc, B, xk, gk, d, glo, _, _ = state
    sc[_NFEV] += 1
    valid = math.isfinite(f) and f < INVALID_F
    for i in range(x.shape[0]):
        valid = valid and math.isfinite(g[i])
    small = False  # the last iteration gained at most ftol (relative)
    if sc[_PHASE] == _START:
        sc[_FK] = f
        if not valid:
            return INVALID_START
        _copy(xk, x)
        _copy(gk, g)
    else:  # a trial of the line search
        a = sc[_ALPHA]
        wolfe = False
        if not valid or f > sc[_FK] + C1 * a * sc[_DPHI0] or f >= sc[_FLO]:
            sc[_HI] = a  # too far: the minimum is before
            sc[_FHI] = f if valid else np.inf
        else:
            dphi = _dot(g, d)
            wolfe = abs(dphi) <= -C2 * sc[_DPHI0]
            if not wolfe:
                if (dphi > 0.0 and sc[_HI] > sc[_LO]) or (dphi < 0.0 and sc[_HI] < sc[_LO]):
                    sc[_HI] = sc[_LO]  # past the minimum: between here and the low end
                    sc[_FHI] = sc[_FLO]
                sc[_LO] = a
                sc[_FLO] = f
                sc[_DLO] = dphi
                _copy(glo, g)
        if wolfe:
            small = _new_iterate(state, x, f, g, a, ftol)
        else:
            sc[_NLS] += 1
            lo_a, hi_a = sc[_LO], sc[_HI]
            ended = sc[_NLS] >= MAX_LS or abs(hi_a - lo_a) * _maxabs(d) <= 10 * EPS * (
                1 + _maxabs(xk)
            )
            if math.isinf(hi_a) and lo_a >= sc[_AMAX]:
                ended = True  # still going down at the box: stop there
            if not ended:
                if math.isinf(hi_a):
                    a = min(4.0 * lo_a, sc[_AMAX])  # not bracketed yet: extrapolate
                else:
                    a = _interpolate(lo_a, sc[_FLO], sc[_DLO], hi_a, sc[_FHI])
                sc[_ALPHA] = a
                _move(x, xk, a, d, lo, hi)
                return EVALUATE
            if lo_a > 0.0:  # the best point found (sufficient decrease), if not a Wolfe one
                _move(x, xk, lo_a, d, lo, hi)
                small = _new_iterate(state, x, sc[_FLO], glo.copy(), lo_a, ftol)
            else:  # no decrease along this direction: forget the pairs, once
                _copy(x, xk)
                if sc[_NPAIRS] == 0:
                    return NO_PROGRESS
                sc[_NPAIRS] = 0
                _set_identity(B, 1.0)
                if _search(state, x, lo, hi):
                    return EVALUATE
                _copy(x, xk)
                return NO_PROGRESS
    # at a new iterate x_k: the next direction (with the pairs forgotten if the model has
    # no descent direction), then stop or start its line search
    g_small = _pg_norm(xk, gk, lo, hi) <= gtol
    ok = _search(state, x, lo, hi)
    if not ok and sc[_NPAIRS] > 0:
        sc[_NPAIRS] = 0
        _set_identity(B, 1.0)
        ok = _search(state, x, lo, hi)
    scale = max(abs(sc[_FK]), 1.0)
    stop = (g_small or small) and (ftol <= 0.0 or -0.5 * sc[_DPHI0] <= MODEL_TOL * ftol * scale)
    if ok and not stop:
        if sc[_NIT] < maxiter:
            return EVALUATE
        _copy(x, xk)
        return MAX_ITER
    _copy(x, xk)
    if g_small:
        return CONVERGED_G
    if small:
        return CONVERGED_F
    return NO_PROGRESS


@_jit
def _new_iterate(state: tuple, x: np.ndarray, f: float, g: np.ndarray, a: float,
                 ftol: float) -> bool:  # fmt: skip
    """The line search's point ``x = x_k + a d`` becomes ``x_k``; the pair ``s, y`` is
    stored and ``B`` rebuilt. True when the iteration gained at most ``ftol`` (relative)."""
    sc, B, xk, gk, _, _, S, Y = state
    n = x.shape[0]
    s = np.empty(n)
    y = np.empty(n)
    for i in range(n):
        s[i] = x[i] - xk[i]
        y[i] = g[i] - gk[i]
    fold = sc[_FK]
    _copy(xk, x)
    _copy(gk, g)
    sc[_FK] = f
    sc[_NIT] += 1
    sy = _dot(s, y)
    if sy > EPS * (-sc[_DPHI0] * a):  # positive curvature (else the pair is skipped)
        m = int(sc[_NPAIRS])
        if m == MEMORY:  # forget the oldest
            for k in range(MEMORY - 1):
                _copy(S[k], S[k + 1])
                _copy(Y[k], Y[k + 1])
            m -= 1
        _copy(S[m], s)
        _copy(Y[m], y)
        sc[_NPAIRS] = m + 1
        _set_identity(B, _dot(y, y) / sy)
        for k in range(m + 1):
            bs = _matvec(B, S[k])
            sbs = _dot(S[k], bs)
            syk = _dot(S[k], Y[k])
            for i in range(n):
                for j in range(n):
                    B[i, j] += Y[k, i] * Y[k, j] / syk - bs[i] * bs[j] / sbs
    return fold - f <= ftol * max(abs(fold), abs(f), 1.0)


@_jit
def _search(state: tuple, x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Start a line search from ``x_k``: the direction, and ``x`` at the first trial step
    (1); False when there is no descent direction."""
    sc, B, xk, gk, d, glo, _, _ = state
    _direction(B, xk, gk, lo, hi, d)
    dphi0 = _dot(gk, d)
    if not dphi0 < 0.0:
        return False
    amax = 1e10  # the largest step along d inside the box (at least 1: x_k + d is inside)
    for i in range(d.shape[0]):
        if d[i] > 0.0:
            amax = min(amax, (hi[i] - xk[i]) / d[i])
        elif d[i] < 0.0:
            amax = min(amax, (lo[i] - xk[i]) / d[i])
    sc[_DPHI0] = dphi0
    sc[_ALPHA] = 1.0
    sc[_LO] = 0.0
    sc[_FLO] = sc[_FK]
    sc[_DLO] = dphi0
    sc[_HI] = np.inf
    sc[_FHI] = np.inf
    sc[_AMAX] = max(amax, 1.0)
    sc[_NLS] = 0.0
    sc[_PHASE] = _SEARCH
    _copy(glo, gk)
    _move(x, xk, 1.0, d, lo, hi)
    return True


@_jit
def _direction(
    B: np.ndarray, x: np.ndarray, g: np.ndarray, lo: np.ndarray, hi: np.ndarray, d: np.ndarray
) -> None:
    """The search direction ``d`` from ``x``: generalized Cauchy point of the model
    ``g'p + p'Bp/2`` along ``P(x - t g)``, then the model's minimum over the variables
    still free there (module docstring, steps 1 and 2)."""
    n = x.shape[0]
    t = np.empty(n)  # breakpoints: where each variable reaches its bound
    dc = np.empty(n)  # the path's direction on the current segment
    fixed = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        if (x[i] <= lo[i] and g[i] >= 0.0) or (x[i] >= hi[i] and g[i] <= 0.0):
            fixed[i] = True  # held by its bound
            t[i] = 0.0
        elif g[i] < 0.0:
            t[i] = (x[i] - hi[i]) / g[i]
        elif g[i] > 0.0:
            t[i] = (x[i] - lo[i]) / g[i]
        else:
            t[i] = np.inf
        dc[i] = 0.0 if fixed[i] else -g[i]
    z = np.zeros(n)  # Cauchy point - x
    tc = 0.0
    while True:
        bd = _matvec(B, dc)
        fp = _dot(g, dc) + _dot(z, bd)  # the model's slope and curvature along the path
        fpp = _dot(dc, bd)
        if fp >= 0.0 or fpp <= 0.0:
            break
        dt = -fp / fpp
        b = -1
        tb = np.inf
        for i in range(n):
            if dc[i] != 0.0 and t[i] < tb:
                tb, b = t[i], i
        if b < 0 or tc + dt <= tb:
            for i in range(n):
                z[i] += dt * dc[i]
            break
        for i in range(n):  # on to the next breakpoint; its variable stays at its bound
            z[i] += (tb - tc) * dc[i]
        z[b] = (hi[b] if dc[b] > 0.0 else lo[b]) - x[b]
        dc[b] = 0.0
        fixed[b] = True
        tc = tb
    free = np.empty(n, dtype=np.int64)
    nf = 0
    for i in range(n):
        if not fixed[i]:
            free[nf] = i
            nf += 1
    _copy(d, z)
    if nf == 0:
        return
    r = _matvec(B, z)  # + g: the model's gradient at the Cauchy point, free variables
    Bf = np.empty((nf, nf))
    rf = np.empty(nf)
    for k in range(nf):
        rf[k] = -(g[free[k]] + r[free[k]])
        for m in range(nf):
            Bf[k, m] = B[free[k], free[m]]
    u = _solve_spd(Bf, rf)
    if u.shape[0] == 0:
        return  # not positive definite (rounding): the Cauchy point
    for k in range(nf):  # projected onto the box
        i = free[k]
        d[i] = min(max(x[i] + z[i] + u[k], lo[i]), hi[i]) - x[i]
    if _dot(g, d) < 0.0:
        return
    amax = 1.0  # not a descent direction: cut the step where it leaves the box
    for k in range(nf):
        i = free[k]
        if u[k] > 0.0:
            amax = min(amax, (hi[i] - x[i] - z[i]) / u[k])
        elif u[k] < 0.0:
            amax = min(amax, (lo[i] - x[i] - z[i]) / u[k])
    amax = max(amax, 0.0)
    for k in range(nf):
        i = free[k]
        d[i] = z[i] + amax * u[k]


@_jit
def _solve_spd(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``A⁻¹ b`` by Cholesky for a small symmetric positive definite ``A``; an empty array
    when ``A`` is not (numerically) positive definite."""
    n = b.shape[0]
    L = np.zeros((n, n))
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return np.empty(0)
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    y = np.empty(n)
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i]
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s -= L[k, i] * y[k]
        y[i] = s / L[i, i]
    return y


@_jit
def _interpolate(lo_a: float, flo: float, dlo: float, hi_a: float, fhi: float) -> float:
    """The next trial step inside the bracket: the minimum of the quadratic through the
    low end's value and slope and the high end's value, kept 10 % away from either end
    (halfway when the high end has no usable value)."""
    w = hi_a - lo_a
    frac = 0.5
    if math.isfinite(fhi):
        den = 2.0 * (fhi - flo - dlo * w)
        if den > 0.0:
            frac = min(max(-dlo * w / den, 0.1), 0.9)
    return lo_a + frac * w


@_jit
def _move(x: np.ndarray, xk: np.ndarray, a: float, d: np.ndarray, lo: np.ndarray,
          hi: np.ndarray) -> None:  # fmt: skip
    """``x = x_k + a d``, clipped into the box (rounding)."""
    for i in range(x.shape[0]):
        x[i] = min(max(xk[i] + a * d[i], lo[i]), hi[i])


@_jit
def _pg_norm(x: np.ndarray, g: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """Max-norm of the projected gradient ``P(x - g) - x``."""
    m = 0.0
    for i in range(x.shape[0]):
        m = max(m, abs(min(max(x[i] - g[i], lo[i]), hi[i]) - x[i]))
    return m


@_jit
def _copy(dst: np.ndarray, src: np.ndarray) -> None:
    for i in range(dst.shape[0]):
        dst[i] = src[i]


@_jit
def _set_identity(B: np.ndarray, scale: float) -> None:
    for i in range(B.shape[0]):
        for j in range(B.shape[1]):
            B[i, j] = scale if i == j else 0.0


@_jit
def _matvec(A: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``A v`` in plain loops (numba's ``@`` calls BLAS: threads for a 3 x 3 product)."""
    n = v.shape[0]
    out = np.zeros(n)
    for i in range(n):
        for j in range(n):
            out[i] += A[i, j] * v[j]
    return out


@_jit
def _dot(a: np.ndarray, b: np.ndarray) -> float:
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i] * b[i]
    return s


@_jit
def _maxabs(a: np.ndarray) -> float:
    m = 0.0
    for i in range(a.shape[0]):
        m = max(m, abs(a[i]))
    return m


@_jit
def minimize_profile(
    x0: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    yk: np.ndarray,
    rscale: np.ndarray,
    steps: np.ndarray,
    ou: np.ndarray,
    frames: np.ndarray,
    restart: np.ndarray,
    tau: float,
    tau_q: float,
    ftol: float,
    maxiter: int,
) -> tuple:
    """Minimise :func:`~tobitkf.smoothing._noise_kernels.profile_nll_grad` over the box
    ``[lo, hi]`` from ``x0`` (the data arguments are its own): ``(x, f, iterations,
    status)``, ``status`` one of this module's stop codes (:data:`CONVERGED_F`, ...)."""
    x = x0.copy()
    state = start(x, lo, hi)
    status = EVALUATE
    while status == EVALUATE:
        f, g = profile_nll_grad(x, lo, hi, yk, rscale, steps, ou, frames, restart, tau, tau_q)
        status = step(state, x, f, g, lo, hi, ftol, GTOL, maxiter)
    return x, state[0][_FK], int(state[0][_NIT]), status


def minimize(
    fun: Callable[[np.ndarray], tuple[float, Any]],
    x0: Any,
    lo: Any,
    hi: Any,
    *,
    ftol: float = 1e-6,
    gtol: float = GTOL,
    maxiter: int = 200,
) -> tuple[np.ndarray, float, int, int]:
    """The same minimiser driven from Python: ``fun(x) -> (f, gradient)``; returns
    ``(x, f, iterations, status)`` as :func:`minimize_profile`."""
    lo = np.ascontiguousarray(lo, dtype=float)
    hi = np.ascontiguousarray(hi, dtype=float)
    x = np.array(x0, dtype=float)
    state = start(x, lo, hi)
    status = EVALUATE
    while status == EVALUATE:
        f, g = fun(x.copy())
        g = np.ascontiguousarray(g, dtype=float)
        status = step(state, x, float(f), g, lo, hi, float(ftol), float(gtol), int(maxiter))
    return x, float(state[0][_FK]), int(state[0][_NIT]), int(status)
