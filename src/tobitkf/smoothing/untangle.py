"""Identity swaps between bodies and left/right swaps within one, undone before gating.

Pose estimators swap things the Kinect does not: a tracker gives person A's keypoints
to person B for a few frames (an identity switch), and a 2-D estimator labels the left
wrist as the right one (a left/right swap). Both look like large jumps of several
keypoints at once; the gates would reject them and bridge the gap, but the swapped
samples are good measurements of the *other* identity or joint. Here, frame by frame
and in time order, each frame's samples are assigned to the identities (and to the
joints of each left/right pair) that continue the previous frame best:

* identities: the cost of body ``b``'s samples continuing body ``c`` is the median over
  joints of the distance from ``b``'s sample to ``c``'s last one; a frame is an
  identity exchange when the assignment of least total cost (Hungarian) costs less than
  ``RATIO`` (0.5) times keeping every body and at least ``margin`` less;
* left/right pairs: a frame exchanges a pair when exchanging it costs less than
  ``RATIO`` times keeping it (sum of the two distances to where the two joints are
  expected) and at least ``margin`` less; a joint of the pair counts only when one of
  its two choices is a plausible step (``NEAR_FACTOR`` (3) times the recording's 95th
  percentile of steps): after a glitch both are far, and the other joint decides.
  A joint is expected where its last sample and its last step take it (the step over
  the frames between its last two stored samples, per frame), or at its last sample
  when that was not stored at the frame before (after a glitch or a gap its motion is
  old). Two joints of a pair that pass each other between two frames (two hands
  crossing, the ankles in a walk, at a low frame rate) are each nearer the other's last
  sample afterwards; by position alone that is an exchange, by their motion it is not.

Each frame is compared with the samples assigned last (so the end of a swap is found
as its start was); when neither choice is clearly better, the previous frame's choice
stands. A joint of a pair whose sample, as assigned, is no plausible step from where it
was expected keeps its last one (a glitch is no reference: otherwise a glitch of both
joints at once, one onto the other's place, anchored an exchange that lasted until
``MAX_SWAP_S``); the plausible step grows by a typical step (the recording's 95th
percentile of frame-to-frame steps) for each frame since the reference was stored, so
a joint that moved while it was missing is taken again.

Offline, the left/right loop runs backwards in time too (:func:`settle`). One pass
misses a swap where its start is unclear (a glitch of one joint just before it: the
glitch is that joint's reference when the swap starts), then takes the swap's end for
the start of one; the other pass meets that end first, as its start. Where the two
passes differ, the labelling under which the pair's two tracks are shorter (by more
than ``margin``, counting the steps into and out of the stretch) is kept, and the one
that exchanges fewer frames when neither is. A swap under way at the start of the
recording is undone too: forwards its first frame is taken as right, backwards its
last.

Most of a recording is right as detected: a stretch reassigned for longer than
``MAX_SWAP_S`` (2 s) is taken as a spurious exchange (after a gap the last samples are
stale) and left as detected.

"Where the data make it clear": when the two candidates are about as good (bodies or
paired joints close together) nothing changes. ``margin`` is ``MARGIN_SDS`` (3) standard
deviations of the distance between two noisy samples, the noise measured on the
recording (:mod:`tobitkf.smoothing.robust_scale`).

:func:`tobitkf.smooth` runs this before any method with ``untangle="auto"`` (the
default) on sequences in pixels or unknown units — pose-estimator output; Kinect and
motion-capture tracks in metres are left as they are unless ``untangle=True`` — and
reports the frames it changed in ``diagnostics["identity_swapped"]`` (T,) and
``diagnostics["lr_swapped"]`` (T, P) of each output.

**Causal form** (:class:`StreamUntangler`, :func:`untangle_stream`): the same frame
loops, one frame at a time, for a live stream (``LiveSmoother(untangle=...)``) and for
``smooth(..., gates="stream")``. Two things differ, because a stream has not seen the
end: the margin and the plausible step are measured on the frames so far (at the
frames where ``gates="stream"`` measures its gates; before the first, nothing is
exchanged, and at the first the loops go over the frames so far, returned as detected,
so that a swap under way is seen from its start) or on a sample recording of the
set-up; and a swap is undone for its first ``MAX_SWAP_S`` only: after that the frames
are taken as detected, and the loop goes on from them as if nothing had been exchanged
(offline, a longer swap is left as detected from its start); and there is no backward
pass. With the same statistics and no swap longer than that, the decisions are the
offline forward pass's (``tests/test_untangle_stream.py``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.smoothing.robust_scale import STREAM_FIRST, STREAM_LAST, _quiet

__all__ = [
    "MAX_SWAP_S",
    "NEAR_FACTOR",
    "RATIO",
    "StreamUntangler",
    "StreamUntangling",
    "check_untangle",
    "settle",
    "untangle",
    "untangle_sequences",
    "untangle_stats",
    "untangle_stream",
]

Array = NDArray[np.float64]


def check_untangle(value: Any) -> Any:
    """The ``untangle`` option of :func:`tobitkf.smooth` and ``LiveSmoother``, checked."""
    if value == "auto" or isinstance(value, bool):
        return value
    raise ValueError(f"untangle must be 'auto', True or False, got {value!r}")


#: a new assignment must cost less than this times the current one
RATIO = 0.5
#: longest swap undone, s: a tracker's identity switch or a left/right confusion is
#: corrected by the estimator within a second or two; a longer "swap" is more likely a
#: spurious exchange (after a gap, the last samples are stale) than a real one
MAX_SWAP_S = 2.0
#: a plausible step: NEAR_FACTOR times the recording's 95th percentile of frame-to-frame
#: steps (over all joints), plus the margin
NEAR_FACTOR = 3.0


def _assign(cost: Array) -> NDArray[np.intp]:
    """Body index for each identity minimising the total cost (rows: identities)."""
    from scipy.optimize import linear_sum_assignment

    big = np.where(np.isfinite(cost), cost, 1e300)
    rows, cols = linear_sum_assignment(big)
    out = np.arange(cost.shape[0])
    out[rows] = cols
    return out


def _choose(cost: Array, current: NDArray[np.intp], margin: float) -> NDArray[np.intp]:
    """One frame's identity decision (``cost[a, b]``: body ``b`` as identity ``a``): the
    least-cost assignment when it costs less than ``RATIO`` times the current one and at
    least ``margin`` less, else ``current``. Two bodies: keep or exchange (the compiled
    loop's own step); more: scipy's assignment, asked only when every cost is finite."""
    B = len(current)
    if B == 2:
        c = _kernels().two_choice(cost, int(current[0]), int(current[1]), float(margin), RATIO)
        return np.array(c, dtype=np.intp)
    ids = np.arange(B)
    now = cost[ids, current]
    if np.isfinite(cost).all():
        best = _assign(cost)
        new = cost[ids, best].sum()
        if new < RATIO * now.sum() and now.sum() - new > margin:
            return best
    return current


def _runs_to_undo(changed: NDArray[np.bool_], max_frames: int) -> NDArray[np.bool_]:
    """Frames of the runs of ``changed`` (along axis 0) no longer than ``max_frames``."""
    out = np.zeros_like(changed)
    T = changed.shape[0]
    width = int(np.prod(changed.shape[1:]))  # (-1 cannot be inferred from no frame)
    flat = changed.reshape(T, width)
    res = out.reshape(T, width)
    for k in range(flat.shape[1]):
        col = flat[:, k]
        if not col.any():
            continue
        edges = np.flatnonzero(np.diff(np.concatenate([[0], col.astype(np.int8), [0]])))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            if b - a <= max_frames:
                res[a:b, k] = True
    return out


def _kernels() -> Any:
    """The compiled frame loops (imports numba on first use)."""
    from tobitkf.smoothing import _untangle_kernels

    return _untangle_kernels


def untangle(
    ys: Array,
    missing: NDArray[np.bool_],
    pairs: Any,
    margin: float,
    *,
    bodies: bool = True,
    max_frames: int = 60,
    near: float = np.inf,
    both_ways: bool = True,
) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
    """Per-frame body order and left/right exchanges that undo swaps (module docstring).


    Parameters
    ----------
    ys : (T, B, J, D) measurements, NaN where missing.
    missing : (T, B, J).
    pairs : (left, right) joint index pairs.
    margin : least cost improvement (in the data's units) that counts.
    bodies : also undo identity swaps between bodies (B >= 2).
    max_frames : longest swap undone.
    near : longest plausible frame-to-frame step of a joint: a joint of a pair is
        evidence only when one of its two choices is within it.
    both_ways : decide the left/right exchanges backwards in time too, and settle where
        the two passes differ (:func:`settle`); ``False``: forwards only, as the causal
        form decides.

    Returns
    -------
    order : (T, B) — identity ``a`` takes body ``order[t, a]``'s samples at frame t.
    exchanged : (T, B, P) — pair p of identity a is exchanged at frame t.
    """
    T, B = missing.shape[:2]
    pairs = [(int(a), int(b)) for a, b in pairs]
    P = len(pairs)
    order = np.tile(np.arange(B), (T, 1))
    k = _kernels()
    ys = np.ascontiguousarray(ys, dtype=float)
    if bodies and B == 2:  # keep or exchange: all of it compiled
        k.two_identities(ys, float(margin), RATIO, order)
    elif bodies and B > 2:  # the least-cost assignment of each frame by scipy
        current = np.arange(B)
        last = np.full(ys.shape[1:], np.nan)  # per identity: its last assigned samples
        cost, scratch = np.empty((B, B)), np.empty(ys.shape[2])
        for t in range(T):
            y = ys[t]
            k.identity_costs(y, last, cost, scratch)  # cost[a, b]: body b as identity a
            current = _choose(cost, current, margin)
            order[t] = current
            k.keep_last(np.ascontiguousarray(y[current]), last)
    if bodies and B > 1:
        moved = (order != np.arange(B)).any(axis=1)
        keep_raw = moved & ~_runs_to_undo(moved, max_frames)
        order[keep_raw] = np.arange(B)
    exchanged = np.zeros((T, B, P), dtype=bool)
    if P:
        yo = np.ascontiguousarray(ys[np.arange(T)[:, None], order])  # identity order
        left = np.array([a for a, _ in pairs], dtype=np.intp)
        right = np.array([b for _, b in pairs], dtype=np.intp)
        k.pair_exchanges(yo, left, right, float(margin), float(near), NEAR_FACTOR, RATIO,
                         exchanged)  # fmt: skip
        if both_ways:  # and backwards in time: where the two differ, the smoother labels
            back = np.zeros_like(exchanged)
            k.pair_exchanges(np.ascontiguousarray(yo[::-1]), left, right, float(margin),
                             float(near), NEAR_FACTOR, RATIO, back)  # fmt: skip
            exchanged = settle(yo, exchanged, back[::-1], left, right, float(margin))
        exchanged &= _runs_to_undo(exchanged, max_frames)
    return order, exchanged


def settle(
    yo: Array, fwd: NDArray[np.bool_], bwd: NDArray[np.bool_], left: Any, right: Any, margin: float
) -> NDArray[np.bool_]:
    """The left/right exchanges of the two passes in time (``fwd``, ``bwd`` (T, B, P) of
    ``yo (T, B, J, D)``, identity order), settled: where they agree, theirs; over each
    stretch where they differ, the labelling under which the pair's two tracks are
    shorter by more than ``margin``, from the frame before the stretch to the frame
    after it (so the steps into and out of it count); when neither is, the one that
    exchanges fewer frames (most of a recording is right as detected), and the forward
    one when they exchange as many."""
    out = fwd.copy()
    T = fwd.shape[0]
    for b, p in zip(*np.nonzero((fwd != bwd).any(axis=0)), strict=True):
        differ = np.concatenate([[0], (fwd[:, b, p] != bwd[:, b, p]).astype(np.int8), [0]])
        edges = np.flatnonzero(np.diff(differ))
        for a, e in zip(edges[::2], edges[1::2], strict=True):
            lo, hi = max(a - 1, 0), min(e + 1, T)
            yl, yr = yo[lo:hi, b, left[p]], yo[lo:hi, b, right[p]]
            f, w = fwd[lo:hi, b, p], bwd[lo:hi, b, p]
            cf, cw = _labelled_length(yl, yr, f), _labelled_length(yl, yr, w)
            if cw < cf - margin or (abs(cw - cf) <= margin and w.sum() < f.sum()):
                out[lo:hi, b, p] = w
    return out


def _labelled_length(yl: Array, yr: Array, exchanged: NDArray[np.bool_]) -> float:
    """The length of a pair's two tracks ``(n, D)`` with the frames ``exchanged (n,)``
    exchanged: the steps between consecutive present samples of each, summed."""
    c = exchanged[:, None]
    total = 0.0
    for y in (np.where(c, yr, yl), np.where(c, yl, yr)):
        z = y[~np.isnan(y).any(axis=-1)]
        if len(z) > 1:
            total += float(np.linalg.norm(np.diff(z, axis=0), axis=-1).sum())
    return total


def apply(a: Array, order: NDArray[np.intp], exchanged: NDArray[np.bool_], pairs: Any) -> Array:
    """``a`` (T, B, J, ...) reordered: bodies by ``order``, pairs exchanged."""
    T = order.shape[0]
    out = a[np.arange(T)[:, None], order]
    if exchanged.any():
        out = out.copy()
        for p, (left, right) in enumerate(pairs):
            m = exchanged[:, :, p]
            lv, rv = out[:, :, left][m], out[:, :, right][m]
            tmp = out[:, :, left].copy()
            tmp[m] = rv
            tmp2 = out[:, :, right].copy()
            tmp2[m] = lv
            out[:, :, left], out[:, :, right] = tmp, tmp2
    return out


def untangle_stats(ys: Array, times: Array) -> tuple[float, float, int]:
    """``(margin, near, max_frames)`` measured on the frames ``ys (T, B, J, D)`` as
    detected (NaN where missing) at ``times (T,)`` s: ``MARGIN_SDS`` standard deviations
    of the distance between two noisy samples, ``NEAR_FACTOR`` times the 95th
    percentile of the frame-to-frame steps plus the margin, and ``MAX_SWAP_S`` in frames
    of the median time step (1/30 s without one)."""
    from tobitkf.smoothing.robust_scale import MARGIN_SDS, noise_scale

    D = ys.shape[-1]
    margin = MARGIN_SDS * noise_scale(ys) * np.sqrt(2.0 * D)
    steps = np.diff(np.asarray(times, dtype=float))
    step = float(np.median(steps)) if steps.size and np.median(steps) > 0 else 1 / 30
    max_frames = max(1, round(MAX_SWAP_S / step))
    with _quiet():
        step_q95 = np.nanpercentile(np.linalg.norm(np.diff(ys, axis=0), axis=-1), 95)
    near = NEAR_FACTOR * float(step_q95) + margin if np.isfinite(step_q95) else np.inf
    return float(margin), float(near), int(max_frames)


class _Identity:
    """What the causal loops keep of one identity: its last assigned samples, its last
    samples with the pairs corrected that were a plausible step, how many frames ago
    each was stored and its velocity then, which pairs are exchanged and for how long."""

    __slots__ = ("last", "page", "plast", "pvel", "run", "state")

    def __init__(self, J: int, D: int, P: int) -> None:
        self.last = np.full((J, D), np.nan)
        self.plast = np.full((J, D), np.nan)
        self.page = np.zeros(J, dtype=np.int64)
        self.pvel = np.full((J, D), np.nan)
        self.state = np.zeros(P, dtype=np.bool_)
        self.run = np.zeros(P, dtype=np.int64)


class StreamUntangler:
    """:func:`untangle`, causal: frame by frame, each frame's bodies (rows) assigned to
    the identities and each pair exchanged or not, against the samples assigned before
    (module docstring, "Causal form"); the compiled steps of the offline loops.

    The rows of a frame carry keys (a stream's body ids; ``None``: the row numbers): an
    identity is a key. When the keys of a frame differ from the last frame's (a body
    came or went), the identity assignment starts again from the rows as detected; each
    key's last samples and pair choices are kept.
    """

    def __init__(self, pairs: Any, *, bodies: bool = True) -> None:
        self.pairs = [(int(a), int(b)) for a, b in pairs]
        self.left = np.array([a for a, _ in self.pairs], dtype=np.intp)
        self.right = np.array([b for _, b in self.pairs], dtype=np.intp)
        self.bodies = bodies
        # no statistics yet: no exchange can be clear (the loops still follow the frames)
        self.margin, self.near, self.max_frames = np.inf, np.inf, 1
        self._keys: list[Any] | None = None
        self._current = np.zeros(0, dtype=np.intp)
        self._run = 0  # frames the identity loop's order has differed from the rows'
        self._ids: dict[Any, _Identity] = {}

    def set_stats(self, margin: float, near: float, max_frames: int) -> None:
        """The statistics the decisions use from the next frame on (:func:`untangle_stats`)."""
        self.margin, self.near, self.max_frames = float(margin), float(near), int(max_frames)

    def forget(self, keys: Any) -> None:
        """Drop what is kept of identities that will not come back."""
        for key in keys:
            self._ids.pop(key, None)

    def step(
        self, y: Array, keys: list[Any] | None = None
    ) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
        """One frame ``y (B, J, D)`` (NaN where missing): ``order (B,)`` (identity ``a``
        takes row ``order[a]``'s samples) and ``exchanged (B, P)`` (pair ``p`` of
        identity ``a`` exchanged), as :func:`untangle` returns them for a frame."""
        y = np.ascontiguousarray(y, dtype=float)
        B, J, D = y.shape
        P = len(self.pairs)
        keys = list(range(B)) if keys is None else list(keys)
        ids = np.arange(B)
        if keys != self._keys:  # another cast: the rows as detected
            self._keys, self._current, self._run = keys, ids.copy(), 0
        idents = []
        for key in keys:
            ident = self._ids.get(key)
            if ident is None:
                ident = self._ids[key] = _Identity(J, D, P)
            idents.append(ident)
        k = _kernels()
        order = ids
        if self.bodies and B > 1:
            cost = np.empty((B, B))
            k.identity_costs(y, np.stack([i.last for i in idents]), cost, np.empty(J))
            current = _choose(cost, self._current, self.margin)
            moved = bool((current != ids).any())
            self._run = self._run + 1 if moved else 0
            if self._run > self.max_frames:  # too long for a swap: the rows as detected
                current, self._run = ids.copy(), 0
            self._current = order = current
        for a, ident in enumerate(idents):  # the loop's own assignment, as offline
            k.keep_last1(y[order[a]], ident.last)
        exchanged = np.zeros((B, P), dtype=bool)
        if P:
            yc, pred = np.empty((J, D)), np.empty((J, D))
            for a, ident in enumerate(idents):
                k.pair_step(y[order[a]], ident.plast, ident.page, ident.pvel, ident.state,
                            ident.run, self.left, self.right, self.margin, self.near,
                            NEAR_FACTOR, RATIO, self.max_frames, yc, pred)  # fmt: skip
                exchanged[a] = ident.state
        return order, exchanged


class StreamUntangling:
    """:class:`StreamUntangler` with its statistics: given once (``stats``, measured on a
    sample recording by :func:`untangle_stats`), or, with ``stats=None``, measured on the
    frames so far where ``gates="stream"`` measures its gates. Before the first of
    those nothing is exchanged; at the first, the loops go over the frames so far
    (returned as detected), so that a swap under way is seen from its start (module
    docstring, "Causal form"). A live stream and :func:`untangle_stream` both step it."""

    def __init__(
        self, pairs: Any, stats: tuple[float, float, int] | None = None, *, bodies: bool = True
    ) -> None:
        self.core = StreamUntangler(pairs, bodies=bodies)
        self.pairs = self.core.pairs
        self.from_stream = stats is None
        if stats is not None:
            self.core.set_stats(*stats)
        self._frames: list[dict[Any, Array]] = []  # the frames so far, row by key
        self._times: list[float] = []
        self._n = 0  # frames seen
        self._next = STREAM_FIRST

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

    def step(
        self, y: Array, keys: list[Any] | None, time: float
    ) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
        """One frame ``y (B, J, D)`` as detected, its rows' ``keys`` (None: the row
        numbers) and time (s): ``(order, exchanged)`` as :meth:`StreamUntangler.step`
        gives them (the rows as detected before the first measurement)."""
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
            if self._n <= STREAM_FIRST:  # no statistics yet: as detected
                return np.arange(len(y)), np.zeros((len(y), len(self.pairs)), dtype=bool)
        return self.core.step(y, keys)

    def forget(self, keys: Any) -> None:
        """Bodies dropped from a keyed stream."""
        self.core.forget(keys)


def untangle_stream(
    ys: Array, times: Array, pairs: Any, *, bodies: bool = True
) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
    """The causal untangling of a recording ``ys (T, B, J, D)`` at ``times (T,)``, its
    statistics measured on the frames so far (:class:`StreamUntangling`): what a live
    stream of it gives (``order (T, B)``, ``exchanged (T, B, P)``)."""
    T, B = ys.shape[:2]
    st = StreamUntangling(pairs, bodies=bodies)
    order = np.tile(np.arange(B), (T, 1))
    exchanged = np.zeros((T, B, len(st.pairs)), dtype=bool)
    for t in range(T):
        order[t], exchanged[t] = st.step(ys[t], None, float(times[t]))
    return order, exchanged


def untangle_sequences(
    seqs: list[Any], *, stream: bool = False
) -> tuple[list[Any], list[dict[str, Any]]]:
    """Sequences of one group (same frames and topology) with swaps undone: positions,
    confidence and tracking states reordered together; and per sequence the frames
    changed (``identity_swapped`` (T,), ``lr_swapped`` (T, P)). ``stream``: the causal
    form (:func:`untangle_stream`)."""
    ys = np.stack([s.positions for s in seqs], axis=1)
    missing = np.isnan(ys).any(axis=-1)
    pairs = list(seqs[0].topology.symmetry)
    if stream:
        order, exch = untangle_stream(ys, seqs[0].times(), pairs)
    else:
        margin, near, max_frames = untangle_stats(ys, seqs[0].times())
        order, exch = untangle(ys, missing, pairs, margin, max_frames=max_frames, near=near)
    info = [
        {
            "identity_swapped": order[:, a] != a,
            "lr_swapped": exch[:, a],
        }
        for a in range(len(seqs))
    ]
    if (order == np.arange(len(seqs))).all() and not exch.any():
        return seqs, info
    pos = apply(ys, order, exch, pairs)
    out = []
    for a, s in enumerate(seqs):
        fields: dict[str, Any] = {"positions": pos[:, a]}
        for name in ("confidence", "tracking_state"):
            if getattr(s, name) is not None:
                stacked = np.stack([getattr(x, name) for x in seqs], axis=1)
                fields[name] = apply(stacked, order, exch, pairs)[:, a]
        out.append(s.replace(**fields))
    return out, info
