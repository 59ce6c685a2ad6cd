"""Identity and left/right swaps undone in a live stream (``LiveSmoother(untangle=...)``).

The glue between :class:`~tobitkf.smoothing.untangle.StreamUntangling` (the decisions
and their statistics, the same as :func:`~tobitkf.smoothing.untangle.untangle_stream`
in batch) and a stream's frames: each frame's positions, tracking states and scores
reordered together before the method sees them, and what was changed.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.smoothing.untangle import StreamUntangling, apply

__all__ = ["LiveUntangle"]

Array = NDArray[np.float64]


class LiveUntangle:
    """A stream's untangling (:class:`~tobitkf.smoothing.untangle.StreamUntangling`:
    ``stats`` measured on a sample, or None to measure them on the stream's frames so
    far), each frame's positions, tracking states and scores reordered together, and
    what the last frame changed (``identity_swapped``, ``lr_swapped``)."""

    def __init__(self, pairs: Any, stats: tuple[float, float, int] | None) -> None:
        self.untangling = StreamUntangling(pairs, stats)
        self.pairs = self.untangling.pairs
        self.identity_swapped: NDArray[np.bool_] = np.zeros(0, dtype=bool)
        self.lr_swapped: NDArray[np.bool_] = np.zeros((0, len(self.pairs)), dtype=bool)

    def frame(self, y: Array, keys: list[Any] | None, time: float, *others: Any) -> tuple[Any, ...]:
        """One frame: ``y (B, J, D)`` as detected, the rows' ``keys`` (None: the row
        numbers), the frame's time (s) and per-row arrays ``(B, J)`` or lists of B
        arrays ``(J,)`` / None to reorder with it; returns ``y`` and ``others``
        reordered."""
        order, exch = self.untangling.step(y, keys, time)
        ids = np.arange(len(y))
        self.identity_swapped, self.lr_swapped = order != ids, exch
        if (order == ids).all() and not exch.any():
            return (y, *others)
        return (self._apply(y, order, exch), *(self._apply(o, order, exch) for o in others))

    def _apply(self, a: Any, order: NDArray[np.intp], exch: NDArray[np.bool_]) -> Any:
        """Rows of ``a`` reordered by ``order``, pairs exchanged where ``exch``: an array
        as :func:`~tobitkf.smoothing.untangle.apply` does a recording's; a list of rows
        (a keyed frame's, None where a body has none) row by row."""
        if a is None:
            return None
        if not isinstance(a, list):
            return apply(np.asarray(a)[None], order[None], exch[None], self.pairs)[0]
        out = []
        for i, ex in zip(order, exch, strict=True):
            r = a[i]
            if r is not None and ex.any():
                r = np.array(r)
                for p in np.flatnonzero(ex):
                    lj, rj = self.pairs[p]
                    r[[lj, rj]] = r[[rj, lj]]
            out.append(r)
        return out

    def forget(self, keys: Any) -> None:
        """Bodies dropped from a keyed stream."""
        self.untangling.forget(keys)
