"""The states of a smoothed output, worked out by :func:`tobitkf.smooth` for every method
alike: the :class:`SampleState` of every sample, the output's tracking states, the filled
counts, and the checks of the method's estimate and standard deviations.

:func:`output_states` does it for all bodies of a batch at once, each rule one compiled
pass over the ``(T, B, J)`` arrays (:mod:`tobitkf.smoothing._state_kernels`), so that
``smooth`` can build the bodies' sequences without checking them one by one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.skeleton.sequence import SampleState
from tobitkf.smoothing.timebase import readonly

__all__ = ["OutputStates", "output_states", "output_tracking", "sample_states"]


def _columns(a: Any, shape: tuple[int, ...], dtype: Any) -> NDArray[Any]:
    """``a`` broadcast to ``shape (T, ...)`` as a read-only C-ordered ``(T, N)`` array of
    ``dtype`` (a view when it is one already): one compiled version of each kernel."""
    a = np.ascontiguousarray(np.broadcast_to(np.asarray(a, dtype=dtype), shape))
    return readonly(a.reshape(shape[0], math.prod(shape[1:])))


def sample_states(missing: Any, rejected: Any, finite: Any, causal: bool) -> NDArray[np.int8]:
    """:class:`SampleState` of every sample, time first (arrays of one shape (T, ...)).

    ``missing``: no measurement (NaN or NOT_TRACKED); ``rejected``: a measurement the
    method judged impossible; ``finite``: the output has a position; ``causal``: the
    output at frame k used frames up to k only. A sample without a position is NONE; one
    whose measurement was used is MEASURED; a rejected one REJECTED; any other fill is
    MISSING when the method is not causal and used measurements of that joint exist both
    before and after it, else EXTRAPOLATED.
    """
    from tobitkf.smoothing import _state_kernels  # numba: only when a method runs

    shape = np.shape(missing)
    cols = [_columns(a, shape, bool) for a in (missing, rejected, finite)]
    return _state_kernels.sample_states(*cols, bool(causal)).reshape(shape)


def output_tracking(
    states: Any | None, sample: NDArray[np.int8]
) -> tuple[NDArray[np.int8], NDArray[np.int64]]:
    """The output's tracking states, ``sample.shape (T, ...)``: filled samples
    (REJECTED, MISSING, EXTRAPOLATED) INFERRED, samples without an estimate NOT_TRACKED,
    the others as in ``states`` (TRACKED where the input has none); and the number of
    filled samples, summed over time ``(...)``."""
    from tobitkf.smoothing import _state_kernels  # numba: only when a method runs

    shape = np.shape(sample)
    codes = _columns(sample, shape, np.int8)
    given = codes if states is None else _columns(states, shape, np.int8)  # not read if None
    out, filled = _state_kernels.tracking_states(given, codes, states is not None)
    return out.reshape(shape), filled.reshape(shape[1:])


@dataclass(frozen=True)
class OutputStates:
    """What :func:`output_states` works out of a batch's output."""

    #: ``(T, B, J)`` :class:`SampleState` codes
    sample: NDArray[np.int8]
    #: ``(T, B, J)`` tracking states (:func:`output_tracking`)
    tracking: NDArray[np.int8]
    #: ``(B, J)`` number of filled samples (missing or rejected, with an estimate)
    filled: NDArray[np.int64]
    #: the std with NaN wherever there is no estimate (None: the method gave none)
    std: NDArray[np.float64] | None
    #: the input had tracking states
    has_states: bool
    #: no position is infinite and every estimate's std is >= 0 and finite, or NaN: the
    #: checks of :class:`~tobitkf.skeleton.sequence.SkeletonSequence` pass
    valid: bool

    def tracking_state(self, b: int) -> NDArray[np.int8] | None:
        """Body ``b``'s output tracking states; None when the input had none and
        nothing of the body was filled."""
        if self.has_states or self.filled[b].any():
            return self.tracking[:, b]
        return None


def output_states(
    est: NDArray[np.float64],
    std: NDArray[np.float64] | None,
    missing: NDArray[np.bool_],
    rejected: NDArray[np.bool_],
    states: NDArray[np.int8] | None,
    causal: bool,
) -> OutputStates:
    """The states of a batch's output ``est (T, B, J, D)`` with posterior ``std (T, B,
    J)`` (or None), from the input's ``missing``, the method's ``rejected`` and the
    input's tracking ``states`` (``(T, B, J)`` each, states None when there are none).

    A std other than NaN where there is no estimate becomes NaN (as a rule the method's
    NaN are there already).
    """
    from tobitkf.smoothing import _state_kernels  # numba: only when a method runs

    T, B, J, D = est.shape
    shape = (T, B, J)
    flat = readonly(np.ascontiguousarray(est, dtype=float).reshape(T, B * J, D))
    finite, has_inf = _state_kernels.finite_samples(flat)
    finite = readonly(finite)
    sample = sample_states(missing, rejected, finite.reshape(shape), causal)
    valid = not has_inf
    if std is not None:
        stray, bad = _state_kernels.std_flags(_columns(std, shape, float), finite)
        if stray:
            std = np.where(sample == SampleState.NONE, np.nan, std)
        valid = valid and not bad
    tracking, filled = output_tracking(states, sample)
    return OutputStates(
        sample=sample,
        tracking=tracking,
        filled=filled,
        std=std,
        has_states=states is not None,
        valid=valid,
    )
