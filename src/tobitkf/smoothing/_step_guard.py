"""Step guard (numba, ``cache=True``): no output step larger than the input's.

A causal filter that rejected a joint for a while extrapolates it; when the measurements
are believed again, the estimate would snap back in one frame, and that snap can be
larger than any step the sensor itself ever made for that joint (KIMORE Ex3 ElbowRight:
0.637 m against 0.422 m). The guard limits each output step of a joint to the largest
step of its input seen so far (between two consecutive present samples), where the
input is present at both frames: the output then catches up over a few frames instead.
Where the input itself was absent (a gap), the output is free to move as the estimate
does: the input has no step there to compare with, and holding the output back would
make it lag behind a joint that reappears elsewhere. The shift ``d`` this adds to an estimate is
added to its uncertainty (``std² + |d|² / D``, ``std`` being the RMS over the D axes).

Causal, with explicit state, so the batch runner (whole recording) and the live stepper
(one frame per call) give the same numbers. The offline smoother runs the same guard
with the whole recording's largest input steps as the limit from the first frame on
(:func:`largest_steps`): a smoothed bridge that rejoins the measurements with a step
larger than the input ever made is held to it in the same way. Positions are
``(T, B, J, D)``, NaN where there is no estimate; ``missing (T, B, J)`` marks absent
input samples.
"""

from __future__ import annotations

import math

import numpy as np

from tobitkf.smoothing._numba_cache import njit


def new_state(B: int, J: int, D: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Guard state: previous input (NaN: absent), its largest step so far (-1: none yet),
    previous output."""
    return (
        np.full((B, J, D), np.nan),
        np.full((B, J), -1.0),
        np.full((B, J, D), np.nan),
        np.zeros(D),  # scratch
    )


@njit(cache=True, nogil=True)
def largest_steps(ys: np.ndarray, missing: np.ndarray, largest: np.ndarray) -> None:
    """``largest (B, J)``: the largest step of each joint's input over the whole
    recording (between two consecutive present samples; -1 where there is none). Given
    to :func:`guard_frames` as its starting state, the limit is the whole recording's
    from the first frame on: the offline guard."""
    T, B, J, D = ys.shape
    for t in range(1, T):
        for b in range(B):
            for j in range(J):
                if missing[t, b, j] or missing[t - 1, b, j]:
                    continue
                s = 0.0
                for k in range(D):
                    s += (ys[t, b, j, k] - ys[t - 1, b, j, k]) ** 2
                s = math.sqrt(s)
                if s > largest[b, j]:
                    largest[b, j] = s


@njit(cache=True, nogil=True)
def guard_frames(
    ys: np.ndarray,
    missing: np.ndarray,
    est: np.ndarray,
    var: np.ndarray,
    b0: int,
    prev_y: np.ndarray,
    largest: np.ndarray,
    prev_out: np.ndarray,
    d: np.ndarray,
) -> None:
    """Limit, in place, the steps of ``est`` (and widen ``var``, the variance) frame by
    frame; the state arrays are updated for the next call. Body ``b`` of ``ys``,
    ``missing`` and the state is body ``b0 + b`` of ``est`` and ``var`` (a chunk)."""
    T, B, J, D = ys.shape
    for t in range(T):
        for b in range(B):
            bo = b0 + b
            for j in range(J):
                both = False  # the input is present at t - 1 and at t
                if not missing[t, b, j]:
                    if not math.isnan(prev_y[b, j, 0]):
                        both = True
                        s = 0.0
                        for k in range(D):
                            s += (ys[t, b, j, k] - prev_y[b, j, k]) ** 2
                        s = math.sqrt(s)
                        if s > largest[b, j]:
                            largest[b, j] = s
                    for k in range(D):
                        prev_y[b, j, k] = ys[t, b, j, k]
                else:
                    prev_y[b, j, 0] = math.nan
                lim = largest[b, j]
                if both and not math.isnan(prev_out[b, j, 0]) and not math.isnan(est[t, bo, j, 0]):
                    n = 0.0
                    for k in range(D):
                        d[k] = est[t, bo, j, k] - prev_out[b, j, k]
                        n += d[k] * d[k]
                    n = math.sqrt(n)
                    if n > lim:
                        shift = 0.0
                        for k in range(D):
                            new = prev_out[b, j, k] + d[k] * (lim / n)
                            shift += (est[t, bo, j, k] - new) ** 2
                            est[t, bo, j, k] = new
                        var[t, bo, j] += shift / D
                for k in range(D):
                    prev_out[b, j, k] = est[t, bo, j, k]


def guard_output(
    ys: np.ndarray, missing: np.ndarray, est: np.ndarray, std: np.ndarray | None, state: tuple
) -> np.ndarray | None:
    """:func:`guard_frames` on a method's output ``est (T, B, J, D)`` (changed in place)
    with its standard deviation ``std (T, B, J)`` or None, the state carried in
    ``state`` (:func:`new_state`); returns the standard deviation with the shifts
    added (None without one). For methods that do not guard themselves
    (``smooth(..., step_guard=True)``, batch and live alike)."""
    var = np.zeros(missing.shape) if std is None else np.asarray(std, dtype=float) ** 2
    guard_frames(ys, np.ascontiguousarray(missing), est, var, 0, *state)
    return None if std is None else np.sqrt(var)
