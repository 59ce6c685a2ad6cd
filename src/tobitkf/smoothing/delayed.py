"""Live smoothing with a fixed delay: an offline method on a sliding window.

A causal method (:class:`~tobitkf.smoothing.live.LiveSmoother`) must judge each frame
when it arrives. Many live uses can wait a little (a rehabilitation exercise counted
and scored as it goes, a dashboard, a recording cleaned while it is made): returning
each frame ``delay`` seconds late lets the offline method see that much of the future,
and bridge a short failure from both of its ends instead of extrapolating into it.

:class:`DelayedSmoother` keeps the last ``window`` seconds of the stream and, at every
frame, runs an offline method (default :data:`~tobitkf.smoothing.api.DEFAULT_METHOD`,
``robust``) on them with :func:`~tobitkf.smooth`, returning the frame ``delay``
seconds back. Its batch twin :func:`smooth_delayed` gives, for a whole recording, the
frames a stream of it would have returned: frame ``t`` is the method's output at ``t``
on frames ``max(0, b - W) .. b - 1``, ``b = min(T, t + D + 1)`` (``D`` and ``W`` the
delay and window in frames), its noise fit held for ``refit`` seconds (:class:`_HeldFit`)
and its step from the frame returned before held to the input's (:class:`_Guard`).
:meth:`DelayedSmoother.flush` returns the last ``D`` frames at the end of a stream, so
nothing is lost. The work per frame is one run of the method on at most ``W`` frames
(bounded; docs/robust.md measures it).

Example
-------
>>> live = DelayedSmoother("kinect_v2", delay=0.5, fps=30)         # doctest: +SKIP
>>> for frame, t in sensor:                                        # doctest: +SKIP
...     clean = live.update(frame, timestamp=t)  # None for the first 15 frames
...     if clean is not None:
...         show(clean, live.timestamp)           # the time of the frame returned
>>> rest = live.flush()                          # the last 15 frames, (15, J, 3)
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tobitkf.skeleton.sequence import KNOWN_UNITS, SkeletonSequence
from tobitkf.skeleton.topology import Topology, get_topology
from tobitkf.smoothing.api import DEFAULT_METHOD, check_params, get_method, smooth
from tobitkf.smoothing.stream_frames import (
    INFINITE,
    check_confidence,
    check_positions,
    check_states,
    timestamp_seconds,
)
from tobitkf.smoothing.timebase import measurements

__all__ = ["DelayedSmoother", "delay_frames", "smooth_delayed"]

Array = NDArray[np.float64]


def _number(name: str, value: Any, positive: bool, unit: str = "seconds") -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not math.isfinite(v) or v < 0 or (positive and v == 0):
        kind = "a positive number" if positive else "a number >= 0"
        raise ValueError(f"{name} must be {kind} of {unit}, got {value!r}")
    return v


def _presence(before: tuple[bool, ...], now: tuple[bool, ...]) -> str:
    """The error for a frame that gives other inputs than the stream's first frame."""
    what = [n for n, b, h in zip(("tracking_state", "timestamp", "confidence"), before, now,
                                 strict=True) if b != h]  # fmt: skip
    return f"{', '.join(what)}: give it with every frame of a stream or with none"


def delay_frames(delay: float, window: float, fps: float) -> tuple[int, int]:
    """``(D, W)``: the delay and the window in frames at ``fps`` (the delay rounded up,
    so a frame is never returned earlier than asked; the window rounded, and at least
    ``D + 1`` frames: the frame returned and the ``D`` after it)."""
    delay = _number("delay", delay, False)
    window = _number("window", window, True)
    fps = _number("fps", fps, True, "frames per second")
    D = math.ceil(delay * fps - 1e-9)
    W = max(round(window * fps), D + 1)
    return D, W


def refit_frames(refit: float, fps: float) -> int:
    """Runs between two noise fits: ``refit`` seconds at ``fps``, at least 1 (every run
    fits)."""
    refit = _number("refit", refit, False)
    return max(1, round(refit * _number("fps", fps, True, "frames per second")))


class _HeldFit:
    """When a method fits its noise to each window (``robust``'s ``noise="fit"``), the
    fit of one run in every ``R`` is held for the runs until the next: run ``k`` (the
    one that gives frame ``k``) fits when ``k % R == 0`` and otherwise takes the held
    fit as its ``noise`` (a run where a body has no held fit fits them all). The fit is
    most of a run's work (docs/robust.md), and a window moves by a few frames of many
    between two fits. The stream and :func:`smooth_delayed` share this schedule."""

    def __init__(self, params: Mapping[str, Any], R: int) -> None:
        self.active = R > 1 and isinstance(params.get("noise"), str) and params["noise"] == "fit"
        self.R = R
        self.fits: list[Any] = []

    def noise(self, k: int, b: int) -> Any:
        """The ``noise`` of body ``b`` in run ``k``: a held fit, or None (fit)."""
        if not self.active or k % self.R == 0 or b >= len(self.fits):
            return None
        return self.fits[b]

    def keep(self, k: int, outs: list[SkeletonSequence]) -> None:
        """Hold the fits of run ``k`` when it was a fit run."""
        if self.active and k % self.R == 0:
            self.fits = [o.metadata.get("diagnostics", {}).get("noise_fit") for o in outs]

    def run(self, k: int, seqs: list[SkeletonSequence], method: str,
            kwargs: Mapping[str, Any]) -> list[SkeletonSequence]:  # fmt: skip
        """Run ``k`` of the method on ``seqs`` (one per body), all in one call: with the
        held fits, each body its own (``noise=`` one fit per body), or, in a fit run,
        fitting them. Bodies that one call does not couple (metres: no untangling, gates
        as given) get what each gives alone; several people in pixels stay together,
        their identity swaps undone and their gates measured on all of them."""
        given = [self.noise(k, b) for b in range(len(seqs))]
        held = {} if any(g is None for g in given) else {"noise": given}
        out = list(smooth(seqs, method, **{**kwargs, **held}))
        self.keep(k, out)
        return out


class _Guard:
    """No returned step larger than the input's (issue 10, point 4), across the runs.

    Each run keeps its own output within the input's steps, but consecutive frames come
    from different runs: run ``t + 1`` sees one frame more, may judge a failure
    differently, and its frame ``t + 1`` can then jump from run ``t``'s frame ``t``
    further than the joint's input ever stepped. So the frames returned go through the
    step guard of the causal methods (:mod:`tobitkf.smoothing._step_guard`): a returned
    step where the input is present at both frames is held to the largest input step of
    the joint among the frames received so far (frame ``t + D`` when frame ``t`` is
    returned; all of them at the flush); the shift is added to the variance. An input
    sample is present as every method reads it (:func:`~tobitkf.smoothing.timebase.
    measurements`: not NaN, not NOT_TRACKED). The stream and :func:`smooth_delayed`
    guard alike."""

    def __init__(self) -> None:
        self.state: Any = None
        self.prev: tuple[Array, NDArray[np.bool_]] | None = None  # the last frame received

    @staticmethod
    def _frame(pos: Array, states: Any) -> tuple[Array, NDArray[np.bool_]]:
        """One input frame ``(B, J, D)`` as the guard reads it: float, and its absent
        samples."""
        y, missing = measurements(pos, states)
        return np.ascontiguousarray(y), missing

    def receive(self, pos: Array, states: Any) -> None:
        """A frame received (``(B, J, D)``): its step joins the largest steps."""
        from tobitkf.smoothing import _step_guard as g

        y, missing = self._frame(pos, states)
        if self.state is None:
            self.state = g.new_state(*missing.shape, y.shape[-1])
        elif self.prev is not None:
            g.largest_steps(np.stack([self.prev[0], y]), np.stack([self.prev[1], missing]),
                            self.state[1])  # fmt: skip
        self.prev = (y, missing)

    def give(self, pos: Array, states: Any, est: Array, std: Array | None) -> None:
        """Guard the frame returned, in place: ``est (B, J, D)`` and ``std (B, J)`` (or
        None) of the input frame ``pos``, ``states``."""
        from tobitkf.smoothing import _step_guard as g

        y, missing = self._frame(pos, states)
        var = np.zeros(missing.shape) if std is None else std**2
        out = np.array(est, dtype=float)[None]  # copies: the guard works in place
        v = np.array(var, dtype=float)[None]
        g.guard_frames(y[None], missing[None], out, v, 0, *self.state)
        # a step the run's own guard already held is held again to within rounding: left
        # as it is (the whole recording in view is then smooth()'s output exactly)
        moved = np.abs(out[0] - est).max(axis=-1) > 1e-12 * (1 + np.abs(est).max(axis=-1))
        est[moved] = out[0][moved]
        if std is not None:
            std[moved] = np.sqrt(v[0][moved])


def _check_window(params: Mapping[str, Any], window: float) -> None:
    """A method that gives a joint up after ``max_reject`` seconds of rejection (robust)
    judges a failure by the rest of the window (its median bone lengths, its noise fit),
    so a failure it may still reject must be less than half the window: on KERAAL a 2 s
    window gave results worse than the raw track (docs/robust.md)."""
    mr = params.get("max_reject")
    if mr is not None and math.isfinite(float(mr)) and window < 2 * float(mr):
        raise ValueError(
            f"window {window:g} s is shorter than twice max_reject ({float(mr):g} s): a "
            f"failure the method may reject would be half the window or more; give "
            f"window >= {2 * float(mr):g} (or a smaller max_reject)"
        )


def _bounds(t: int, n: int, D: int, W: int) -> tuple[int, int]:
    """The frames ``a .. b - 1`` whose run gives frame ``t`` when ``n`` frames exist."""
    b = min(n, t + D + 1)
    return max(0, b - W), b


def _frames(seq: SkeletonSequence, a: int, b: int) -> SkeletonSequence:
    """Frames ``a .. b - 1`` of ``seq`` (its measurements only: no earlier output)."""

    def cut(x: Any) -> Any:
        return None if x is None else x[a:b]

    return seq.replace(positions=seq.positions[a:b], tracking_state=cut(seq.tracking_state),
                       timestamps=cut(seq.timestamps), confidence=cut(seq.confidence),
                       std=None, sample_state=None)  # fmt: skip


def _delay_meta(out: SkeletonSequence, delay: float, window: float, D: int, W: int,
                R: int | None) -> None:  # fmt: skip
    """``provenance["delayed"]``: the settings in seconds and in frames (``refit_frames``
    None: no fit held, the method fits at every run or not at all)."""
    prov = out.metadata.setdefault("provenance", {})
    prov["delayed"] = {"delay": delay, "window": window, "delay_frames": D, "window_frames": W,
                       "refit_frames": R}  # fmt: skip


def smooth_delayed(
    sequence: SkeletonSequence,
    method: str = DEFAULT_METHOD,
    *,
    delay: float = 0.5,
    window: float = 10.0,
    refit: float = 1.0,
    **kwargs: Any,
) -> SkeletonSequence:
    """What :class:`DelayedSmoother` returns for a stream of ``sequence``, frame by frame
    (its positions, ``std`` and ``sample_state``; module docstring).

    ``delay`` and ``window`` are in seconds, turned into frames with the sequence's
    ``fps`` (30 when it has none) by :func:`delay_frames`; ``refit`` as for
    :class:`DelayedSmoother`; ``kwargs`` go to :func:`~tobitkf.smooth` (method
    parameters, ``untangle``, ...). The metadata are those of the last run, with
    ``provenance["delayed"]`` added. Costs one run of the method per frame."""
    if not isinstance(sequence, SkeletonSequence):
        raise TypeError(f"smooth_delayed expects a SkeletonSequence, got {type(sequence).__name__}")
    D, W = delay_frames(delay, window, sequence.fps or 30.0)
    full = check_params(method, kwargs)
    _check_window(full, float(window))
    hold = _HeldFit(full, refit_frames(refit, sequence.fps or 30.0))
    T = sequence.n_frames
    pos = np.full(sequence.positions.shape, np.nan)
    std = np.full(sequence.positions.shape[:2], np.nan)
    states = np.zeros(sequence.positions.shape[:2], np.int8)
    last: SkeletonSequence | None = None
    runs: dict[tuple[int, int], SkeletonSequence] = {}
    guard, received = _Guard(), 0
    ts = sequence.tracking_state

    def state(t: int) -> Any:
        return None if ts is None else ts[t][None]

    for t in range(T):
        while received < min(T, t + D + 1):  # the frames a stream has when it returns t
            guard.receive(sequence.positions[received][None], state(received))
            received += 1
        a, b = _bounds(t, T, D, W)
        if (a, b) not in runs:  # the last D frames share one run (the stream's flush)
            runs = {(a, b): hold.run(t, [_frames(sequence, a, b)], method, kwargs)[0]}
        last = runs[(a, b)]
        pos[t] = last.positions[t - a]
        if last.std is not None:
            std[t] = last.std[t - a]
        if last.sample_state is not None:
            states[t] = last.sample_state[t - a]
        guard.give(sequence.positions[t][None], state(t), pos[t][None],
                   None if last.std is None else std[t][None])  # fmt: skip
    if last is None:
        raise ValueError("smooth_delayed: the sequence has no frames")
    out = last.replace(positions=pos, timestamps=sequence.timestamps, fps=sequence.fps,
                       tracking_state=sequence.tracking_state, confidence=sequence.confidence,
                       std=None if last.std is None else std,
                       sample_state=None if last.sample_state is None else states,
                       metadata=dict(last.metadata))  # fmt: skip
    _delay_meta(out, float(delay), float(window), D, W, hold.R if hold.active else None)
    return out


class DelayedSmoother:
    """Smooth a live stream with an offline method, each frame returned ``delay`` late.

    Parameters
    ----------
    topology : Topology or name
        Skeleton of the stream.
    method : str
        A registered method (default ``DEFAULT_METHOD``, ``"robust"``); any method
        works, causal or not. Parameters as for :func:`tobitkf.smooth`.
    delay : float
        Seconds each frame is returned late (rounded up to whole frames at ``fps``);
        0 makes the method causal (the frame is judged on the past only).
    window : float
        Seconds of the stream the method sees at each frame (default 10; at least the
        delay and one frame, and twice the method's ``max_reject``, 4 s for ``robust``).
        The work per frame grows with it.
    refit : float
        Seconds between two fits of the noise (default 1), when the method fits it to
        each window (``robust``'s default ``noise="fit"``): the fit is most of a run's
        work, so in between the runs take the last fit as given (``noise=`` one fit per
        body of the array). 0 fits at every frame; keyed bodies are each their own
        stream.
    fps : float
        Frame rate: turns ``delay`` and ``window`` into frames, and times the frames
        when no timestamps are given.
    units : str, optional
        As :class:`~tobitkf.smoothing.live.LiveSmoother` (``"m"``, ``"cm"``, ``"mm"``,
        ``"px"``; None: metres in 3-D, unknown in 2-D). A stream in pixels needs no
        gates given: ``robust`` measures them on the window, as :func:`smooth` does on
        a recording.
    **kwargs
        Method parameters and :func:`smooth`'s options (``untangle``,
        ``min_confidence``, ``inferred_noise_factor``).

    Frames are ``(J, D)`` or ``(B, J, D)`` (D = 3 or 2; the first frame fixes it), NaN
    for a missing joint, or ``{body_id: (J, D)}`` (:meth:`update`). A frame that is
    refused (``ValueError``) leaves the stream unchanged.
    """

    def __init__(
        self,
        topology: Topology | str = "kinect_v2",
        method: str = DEFAULT_METHOD,
        *,
        delay: float = 0.5,
        window: float = 10.0,
        refit: float = 1.0,
        fps: float = 30.0,
        units: str | None = None,
        **kwargs: Any,
    ) -> None:
        get_method(method)  # an unknown method fails here, not at the first frame
        options = {k: kwargs.pop(k) for k in ("untangle", "min_confidence",
                                              "inferred_noise_factor") if k in kwargs}  # fmt: skip
        if "offline" in kwargs:
            raise ValueError("offline: DelayedSmoother runs the method as smooth() does; "
                             "give the method's own parameters")  # fmt: skip
        self.params = check_params(method, {**kwargs, **options})  # the options checked too
        if units is not None and (not isinstance(units, str) or units not in KNOWN_UNITS):
            raise ValueError(f"units must be one of {sorted(KNOWN_UNITS)} or None, got {units!r}")
        self.D, self.W = delay_frames(delay, window, fps)
        self.R = refit_frames(refit, fps)
        _check_window(self.params, float(window))
        self.delay, self.window, self.fps = float(delay), float(window), float(fps)
        self.refit = float(refit)
        self.topology = get_topology(topology) if isinstance(topology, str) else topology
        if not isinstance(self.topology, Topology):
            raise TypeError(f"topology must be a Topology or a name, got {type(topology).__name__}")
        self.method, self.units, self._options = method, units, options
        self._given = kwargs  # the method parameters as given (each keyed body's smoother)
        self.reset()

    def reset(self) -> None:
        """Forget the stream; the next frame starts a new one."""
        # the last W frames, stacked: positions (n, B, J, D), tracking states (n, B, J),
        # timestamps (n,), confidence (n, B, J); None for what the stream does not give
        # (one copy per frame, not a stack of W frames)
        self._stacked: list[Any] = [None] * 4
        self._shape: tuple[int, ...] | None = None
        self._has: tuple[bool, bool, bool] | None = None  # states, timestamps, confidence
        self._flushed = False
        self.n_frames = 0  # frames received
        #: index (from 0) of the last frame returned, -1 before the first
        self.frame_index = -1
        #: timestamp of the last frame returned (None without timestamps)
        self.timestamp: float | None = None
        #: posterior sd of the frame(s) last returned, in the stream's units (None: the
        #: method gives none); after :meth:`flush`, one row per frame returned
        self.std: Array | None = None
        #: SampleState codes of the frame(s) last returned
        self.sample_state: NDArray[np.int8] | None = None
        # a stream keyed by body id: each body's own smoother, its first frame in the
        # stream, its last frame in which it was seen (None: not keyed, or no frame yet)
        self._bodies: dict[Any, DelayedSmoother] | None = None
        self._seen: dict[Any, tuple[int, int]] = {}
        self._stamps: deque[float | None] = deque(maxlen=self.D + 1)
        self._hold = _HeldFit(self.params, self.R)
        self._last: list[SkeletonSequence] | None = None  # the run on the buffer as it is
        self._guard = _Guard()

    def update(
        self,
        positions: ArrayLike | Mapping[Any, ArrayLike],
        tracking_state: ArrayLike | Mapping[Any, ArrayLike] | None = None,
        timestamp: float | None = None,
        confidence: ArrayLike | Mapping[Any, ArrayLike] | None = None,
    ) -> Any:
        """Take one frame; return the frame ``delay`` back, smoothed (shaped as
        ``positions``), or None while fewer than ``delay`` frames have followed the first.
        :attr:`frame_index`, :attr:`timestamp`, :attr:`std` and :attr:`sample_state`
        describe the frame returned. Arguments as for ``LiveSmoother.update``.

        Keyed by body id (``positions`` a mapping ``{body_id: (J, D)}``, and
        ``tracking_state`` and ``confidence`` mappings of the same ids, or None): returns
        ``{body_id: (J, D)}`` for the bodies that were in the stream at the frame
        returned, an empty mapping while no frame is returned yet (``std`` and
        ``sample_state`` are such mappings too). Each body is
        smoothed alone, as a stream of its own from its first frame, missing in the
        frames it is absent from; a body is forgotten once its last frame has been
        returned (absent for more than ``delay``), so nothing of it is lost, and an id
        that comes back after that starts a new track. A stream is keyed or not from its
        first frame on."""
        if self._flushed:
            raise ValueError("this stream was flushed (it has ended); reset() starts a new one")
        keyed = isinstance(positions, Mapping)
        if self.n_frames and keyed != (self._bodies is not None):
            raise ValueError("this stream is keyed by body id: pass {body_id: positions}"
                             if self._bodies is not None else
                             "this stream is not keyed by body id: pass an array")  # fmt: skip
        if keyed:
            return self._update_keyed(positions, tracking_state, timestamp, confidence)
        return self._push(self._checked(positions, tracking_state, timestamp, confidence))

    def flush(self) -> Any:
        """End the stream: return the frames not returned yet (the last ``delay``), from
        one run on the final window, stacked ``(n, J, D)`` (``(n, B, J, D)``; keyed:
        ``{body_id: (n_b, J, D)}``, each body up to its last frame); ``std`` and
        ``sample_state`` then have one row per frame. Afterwards :meth:`update` refuses
        frames until :meth:`reset`."""
        self._flushed = True
        if self._bodies is not None:
            return self._flush_keyed()
        start = self.frame_index + 1
        if start >= self.n_frames:
            shape = (0, *self._shape) if self._shape is not None else (0, 0, 0)
            # no rows, as the positions: empty arrays (None: a method that gives no sd)
            gives_sd = self.std is not None or self.n_frames == 0
            self.std = np.empty(shape[:-1]) if gives_sd else None
            self.sample_state = np.empty(shape[:-1], dtype=np.int8)
            return np.empty(shape)
        first = self.n_frames - self._held()
        rows = list(range(start - first, self.n_frames - first))
        # the last frame's run (the window has not changed since), or the first run
        out = self._last if self._last is not None else self._run(0)
        pos, self.std, self.sample_state = self._give(out, rows, self.n_frames - 1)
        return pos

    # ------------------------------------------------------------------ keyed by body id
    def _update_keyed(self, frames: Mapping[Any, Any], states: Any, timestamp: Any,
                      confidence: Any) -> dict[Any, Array]:  # fmt: skip
        for name, m in (("tracking_state", states), ("confidence", confidence)):
            if m is not None and (not isinstance(m, Mapping) or set(m) != set(frames)):
                raise ValueError(f"{name}: a mapping of the same body ids as positions")
        has = (states is not None, timestamp is not None, confidence is not None)
        if self._has is not None and has != self._has:
            raise ValueError(_presence(self._has, has))
        stamp = timestamp_seconds(timestamp)
        prev = self._stamps[-1] if self._stamps else None
        if stamp is not None and prev is not None and stamp < prev:
            raise ValueError(f"timestamp {stamp} comes before the previous frame's ({prev})")
        bodies = self._bodies if self._bodies is not None else {}
        new = {b: self._body() for b in frames if b not in bodies}
        checked = {}
        for b, frame in frames.items():  # every body checked before any is changed
            body = bodies.get(b) or new[b]
            try:
                if np.ndim(frame) != 2:
                    raise ValueError(f"positions: expected shape (J, D), found {np.shape(frame)}")
                sb = None if states is None else states[b]
                cb = None if confidence is None else confidence[b]
                checked[b] = body._checked(frame, sb, stamp, cb)
            except ValueError as exc:
                raise ValueError(f"body {b!r}: {exc}") from None
        # the frame is good: from here on it is part of the stream
        self._bodies, self._has = bodies, has
        bodies.update(new)
        n = self.n_frames
        for b in frames:
            self._seen[b] = (self._seen.get(b, (n, n))[0], n)
        self.n_frames += 1
        self._stamps.append(stamp)
        t = n - self.D
        out, std, st = {}, {}, {}
        for b, body in list(bodies.items()):
            res = body._push(checked[b] if b in checked else body._absent(stamp))
            if res is not None:
                out[b], std[b], st[b] = res, body.std, body.sample_state
            if self._seen[b][1] <= t:  # its last frame has just been returned
                del bodies[b], self._seen[b]
        self.frame_index = max(t, -1)
        self.timestamp = self._stamps[0] if t >= 0 else None
        self.std = std if any(v is not None for v in std.values()) else None
        self.sample_state = st or None
        return out

    def _body(self) -> DelayedSmoother:
        """A smoother of the same settings for one body of a keyed stream."""
        return DelayedSmoother(self.topology, self.method, delay=self.delay,
                               window=self.window, refit=self.refit, fps=self.fps,
                               units=self.units, **self._options, **self._given)  # fmt: skip

    def _absent(self, stamp: float | None) -> tuple:
        """This body's frame when the stream's frame does not have it: every joint
        missing (NOT_TRACKED, no confidence)."""
        pos = np.full((1, *self._shape), np.nan)
        has_states, _, has_conf = self._has or (False, False, False)
        st = np.zeros(pos.shape[:-1], np.int8) if has_states else None
        cf = np.full(pos.shape[:-1], np.nan) if has_conf else None
        return pos, st, stamp, cf

    def _flush_keyed(self) -> dict[Any, Array]:
        out, std, st = {}, {}, {}
        for b, body in (self._bodies or {}).items():
            first, last = self._seen[b]
            start = first + body.frame_index + 1  # its first frame not returned yet
            rows = body.flush()
            keep = max(0, min(len(rows), last - start + 1))  # up to its last frame
            out[b] = rows[:keep]
            std[b] = None if body.std is None else body.std[:keep]
            st[b] = None if body.sample_state is None else body.sample_state[:keep]
        self.std = std if any(v is not None for v in std.values()) else None
        self.sample_state = st or None
        self.frame_index = self.n_frames - 1
        return out

    # ------------------------------------------------------------------ one array stream
    def _push(self, frame: tuple) -> Array | None:
        """Take a checked frame (:meth:`_checked`); the frame ``delay`` back, or None."""
        self._guard.receive(frame[0], frame[1])
        for i, x in enumerate(frame):
            if x is not None:
                x = np.asarray(x, dtype=float if i == 2 else None)[None]
                old = self._stacked[i]
                if old is not None:  # the last W - 1 frames, then this one
                    x = np.concatenate([old[max(0, len(old) - self.W + 1) :], x])
                self._stacked[i] = x
        self.n_frames += 1
        t = self.n_frames - 1 - self.D
        if t < 0:
            return None
        first = self.n_frames - self._held()
        self._last = self._run(t)
        pos, std, states = self._give(self._last, [t - first], t)
        self.std = None if std is None else std[0]
        self.sample_state = None if states is None else states[0]
        return pos[0]

    # ------------------------------------------------------------------ internals
    def _held(self) -> int:
        """Frames in the window (the last ``W`` received)."""
        return 0 if self._stacked[0] is None else len(self._stacked[0])

    def _stamp(self, row: int) -> float | None:
        """The timestamp of window row ``row`` (None: the stream has none)."""
        stamps = self._stacked[2]
        return None if stamps is None else float(stamps[row])

    def _run(self, k: int) -> list[SkeletonSequence]:
        """Run ``k`` (the one giving frame ``k``) of the method on the buffered frames,
        one sequence per body."""
        P, S, ts, C = self._stacked  # (n, B, J, D), (n, B, J), (n,), (n, B, J)
        units = {} if self.units is None else {"units": self.units}
        seqs = [
            SkeletonSequence(
                P[:, b],
                self.topology,
                tracking_state=None if S is None else S[:, b],
                timestamps=ts,
                fps=self.fps,
                body_id=b,
                confidence=None if C is None else C[:, b],
                **units,
            )
            for b in range(P.shape[1])
        ]
        return self._hold.run(k, seqs, self.method, {**self._options, **self._given})

    def _give(
        self, out: list[SkeletonSequence], rows: list[int], last: int
    ) -> tuple[Array, Any, Any]:
        """Rows ``rows`` of the run's output (positions, sd, states; ``None`` for what the
        method does not give), each with a frame axis first and shaped as the stream's
        frames; ``last``: the stream index of the last of them."""
        single = len(self._shape or ()) == 2

        def take(field: str) -> Any:
            if getattr(out[0], field) is None:
                return None
            return np.stack([getattr(s, field)[rows] for s in out], axis=1)  # (n, B, ...)

        pos, std, states = take("positions"), take("std"), take("sample_state")
        P, S = self._stacked[0], self._stacked[1]
        for i, row in enumerate(rows):  # in time order, from the previous frame returned
            self._guard.give(P[row], None if S is None else S[row], pos[i],
                             None if std is None else std[i])  # fmt: skip
        self.frame_index = last
        self.timestamp = self._stamp(last - (self.n_frames - self._held()))
        if single:
            return tuple(None if a is None else a[:, 0] for a in (pos, std, states))
        return pos, std, states

    def _checked(self, positions: Any, states: Any, timestamp: Any, confidence: Any) -> tuple:
        """A frame checked against the stream, with a body axis; nothing is changed when
        it is refused."""
        pos = check_positions(positions, self.topology)
        if self._shape is not None and pos.shape != self._shape:
            raise ValueError(
                f"positions: shape {pos.shape} differs from the stream's {self._shape}"
            )
        if np.isinf(pos).any():
            raise ValueError(INFINITE)
        body = pos.shape[:-1]
        st = check_states(states, body)
        cf = check_confidence(confidence, body)
        # copies: the window keeps them, and a caller may reuse its frame buffers
        pos, cf = np.array(pos), None if cf is None else np.array(cf)
        ts = timestamp_seconds(timestamp)
        if ts is not None:
            prev = self._stamp(-1) if self._held() else None
            if prev is not None and ts < prev:
                raise ValueError(f"timestamp {ts} comes before the previous frame's ({prev})")
        has = (st is not None, ts is not None, cf is not None)
        if self._has is not None and has != self._has:
            raise ValueError(_presence(self._has, has))
        self._shape, self._has = pos.shape, has
        if pos.ndim == 2:
            pos = pos[None]
            st = None if st is None else st[None]
            cf = None if cf is None else cf[None]
        return pos, st, ts, cf
