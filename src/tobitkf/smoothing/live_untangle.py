"""Identity and left/right swaps undone in a live stream (``LiveSmoother(untangle=...)``).

The glue between :class:`~tobitkf.smoothing.untangle.StreamUntangler` (the decisions)
and a stream's frames: the statistics the decisions need, measured on a sample recording
of the set-up once, or on the stream's own frames as they come (at the frames where
``gates="stream"`` measures its gates, as :func:`~tobitkf.smoothing.untangle.
untangle_stream` does in batch); and each frame's positions, tracking states and scores
reordered together before the method sees them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.smoothing.robust_scale import STREAM_FIRST, STREAM_LAST
from tobitkf.smoothing.untangle import StreamUntangler, untangle_stats

__all__ = ["LiveUntangle"]

Array = NDArray[np.float64]


class LiveUntangle:
    """A stream's untangling: ``stats`` measured on a sample (``(margin, near,
    max_frames)``), or None to measure them on the stream's frames so far."""

    def __init__(self, pairs: Any, stats: tuple[float, float, int] | None) -> None:
        self.core = StreamUntangler(pairs)
        self.pairs = self.core.pairs
        self.from_stream = stats is None
        if stats is not None:
            self.core.set_stats(*stats)
        self._frames: list[dict[Any, Array]] = []  # the frames so far, row by key
        self._times: list[float] = []
        self._n = 0  # frames seen
        self._next = STREAM_FIRST
        self.identity_swapped: NDArray[np.bool_] = np.zeros(0, dtype=bool)
        self.lr_swapped: NDArray[np.bool_] = np.zeros((0, len(self.pairs)), dtype=bool)

    def _measure(self, n: int) -> None:
        """The statistics of the first ``n`` frames (every key seen, NaN where absent)."""
        keys = list(dict.fromkeys(k for f in self._frames for k in f))
        J, D = next(iter(next(f for f in self._frames if f).values())).shape
        ys = np.full((n, len(keys), J, D), np.nan)
        col = {k: i for i, k in enumerate(keys)}
        for t, f in enumerate(self._frames):
            for k, y in f.items():
                ys[t, col[k]] = y
        self.core.set_stats(*untangle_stats(ys, np.asarray(self._times)))

    def frame(self, y: Array, keys: list[Any] | None, time: float, *others: Any) -> tuple[Any, ...]:
        """One frame: ``y (B, J, D)`` as detected, the rows' ``keys`` (None: the row
        numbers), the frame's time (s) and per-row arrays ``(B, J)`` or lists of B
        arrays ``(J,)`` / None to reorder with it; returns ``y`` and ``others``
        reordered."""
        if self.from_stream:
            n = self._n
            if n == self._next <= STREAM_LAST:
                if any(self._frames):
                    self._measure(n)
                    if n == STREAM_FIRST:  # the frames so far (returned as detected) set
                        for f in self._frames:  # the loops' state
                            rows = list(f)
                            self.core.step(np.stack([f[k] for k in rows]) if rows
                                           else y[:0], rows)  # fmt: skip
                self._next *= 2
            if n < STREAM_LAST:  # what the next measurements read
                rows = range(len(y)) if keys is None else keys
                self._frames.append({k: np.array(y[i]) for i, k in enumerate(rows)})
                self._times.append(float(time))
            else:
                self._frames, self._times = [], []
            self._n = n + 1
        ids = np.arange(len(y))
        if self.from_stream and self._n <= STREAM_FIRST:  # no statistics yet: as detected
            self.identity_swapped = np.zeros(len(y), dtype=bool)
            self.lr_swapped = np.zeros((len(y), len(self.pairs)), dtype=bool)
            return (y, *others)
        order, exch = self.core.step(y, keys)
        self.identity_swapped, self.lr_swapped = order != ids, exch
        if (order == ids).all() and not exch.any():
            return (y, *others)
        return (self._apply(y, order, exch), *(self._apply(o, order, exch) for o in others))

    def _apply(self, a: Any, order: NDArray[np.intp], exch: NDArray[np.bool_]) -> Any:
        """Rows of ``a`` reordered by ``order``, pairs exchanged where ``exch``."""
        if a is None:
            return None
        if isinstance(a, list):
            rows = [a[i] for i in order]
            out = []
            for r, ex in zip(rows, exch, strict=True):
                if r is not None and ex.any():
                    r = np.array(r)
                    for p in np.flatnonzero(ex):
                        lj, rj = self.pairs[p]
                        r[[lj, rj]] = r[[rj, lj]]
                out.append(r)
            return out
        out = np.array(a)[order]
        for b, p in zip(*np.nonzero(exch), strict=True):
            lj, rj = self.pairs[p]
            out[b, [lj, rj]] = out[b, [rj, lj]]
        return out

    def forget(self, keys: Any) -> None:
        """Bodies dropped from a keyed stream."""
        self.core.forget(keys)
