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
delay and window in frames). :meth:`DelayedSmoother.flush` returns the last ``D``
frames at the end of a stream, so nothing is lost. The work per frame is one run of
the method on at most ``W`` frames (bounded; docs/robust.md measures it).

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

from tobitkf.skeleton.sequence import KNOWN_UNITS, SkeletonSequence, TrackingState
from tobitkf.skeleton.topology import Topology, get_topology
from tobitkf.smoothing.api import DEFAULT_METHOD, check_params, get_method, smooth

__all__ = ["DelayedSmoother", "delay_frames", "smooth_delayed"]

Array = NDArray[np.float64]
_STATES = tuple(int(s) for s in TrackingState)


def _seconds(name: str, value: Any, positive: bool) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not math.isfinite(v) or v < 0 or (positive and v == 0):
        kind = "a positive number" if positive else "a number >= 0"
        raise ValueError(f"{name} must be {kind} of seconds, got {value!r}")
    return v


def delay_frames(delay: float, window: float, fps: float) -> tuple[int, int]:
    """``(D, W)``: the delay and the window in frames at ``fps`` (the delay rounded up,
    so a frame is never returned earlier than asked; the window rounded, and at least
    ``D + 1`` frames: the frame returned and the ``D`` after it)."""
    delay = _seconds("delay", delay, False)
    window = _seconds("window", window, True)
    fps = _seconds("fps", fps, True)
    D = math.ceil(delay * fps - 1e-9)
    W = max(round(window * fps), D + 1)
    return D, W


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


def _delay_meta(out: SkeletonSequence, delay: float, window: float, D: int, W: int) -> None:
    prov = out.metadata.setdefault("provenance", {})
    prov["delayed"] = {"delay": delay, "window": window, "delay_frames": D, "window_frames": W}


def smooth_delayed(
    sequence: SkeletonSequence,
    method: str = DEFAULT_METHOD,
    *,
    delay: float = 0.5,
    window: float = 10.0,
    **kwargs: Any,
) -> SkeletonSequence:
    """What :class:`DelayedSmoother` returns for a stream of ``sequence``, frame by frame
    (its positions, ``std`` and ``sample_state``; module docstring).

    ``delay`` and ``window`` are in seconds, turned into frames with the sequence's
    ``fps`` (30 when it has none) by :func:`delay_frames`; ``kwargs`` go to
    :func:`~tobitkf.smooth` (method parameters, ``untangle``, ...). The metadata are
    those of the last run, with ``provenance["delayed"]`` added. Costs one run of the
    method per frame."""
    if not isinstance(sequence, SkeletonSequence):
        raise TypeError(f"smooth_delayed expects a SkeletonSequence, got {type(sequence).__name__}")
    D, W = delay_frames(delay, window, sequence.fps or 30.0)
    T = sequence.n_frames
    pos = np.full(sequence.positions.shape, np.nan)
    std = np.full(sequence.positions.shape[:2], np.nan)
    states = np.zeros(sequence.positions.shape[:2], np.int8)
    last: SkeletonSequence | None = None
    runs: dict[tuple[int, int], SkeletonSequence] = {}
    for t in range(T):
        a, b = _bounds(t, T, D, W)
        if (a, b) not in runs:  # the last D frames share one run (the stream's flush)
            runs = {(a, b): smooth(_frames(sequence, a, b), method, **kwargs)}
        last = runs[(a, b)]
        pos[t] = last.positions[t - a]
        if last.std is not None:
            std[t] = last.std[t - a]
        if last.sample_state is not None:
            states[t] = last.sample_state[t - a]
    if last is None:
        raise ValueError("smooth_delayed: the sequence has no frames")
    out = last.replace(positions=pos, timestamps=sequence.timestamps, fps=sequence.fps,
                       tracking_state=sequence.tracking_state, confidence=sequence.confidence,
                       std=None if last.std is None else std,
                       sample_state=None if last.sample_state is None else states,
                       metadata=dict(last.metadata))  # fmt: skip
    _delay_meta(out, float(delay), float(window), D, W)
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
        delay and one frame). The work per frame grows with it.
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
    for a missing joint. A stream keyed by body id is not taken: use one smoother per
    id. A frame that is refused (``ValueError``) leaves the stream unchanged.
    """

    def __init__(
        self,
        topology: Topology | str = "kinect_v2",
        method: str = DEFAULT_METHOD,
        *,
        delay: float = 0.5,
        window: float = 10.0,
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
        self.params = check_params(method, kwargs)
        if units is not None and (not isinstance(units, str) or units not in KNOWN_UNITS):
            raise ValueError(f"units must be one of {sorted(KNOWN_UNITS)} or None, got {units!r}")
        self.D, self.W = delay_frames(delay, window, fps)
        self.delay, self.window, self.fps = float(delay), float(window), float(fps)
        self.topology = get_topology(topology) if isinstance(topology, str) else topology
        if not isinstance(self.topology, Topology):
            raise TypeError(f"topology must be a Topology or a name, got {type(topology).__name__}")
        self.method, self.units, self._options = method, units, options
        self.reset()

    def reset(self) -> None:
        """Forget the stream; the next frame starts a new one."""
        # (positions (B, J, D), tracking state or None, timestamp or None, confidence or None)
        self._buffer: deque[tuple[Array, Any, float | None, Any]] = deque(maxlen=self.W)
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

    def update(
        self,
        positions: ArrayLike,
        tracking_state: ArrayLike | None = None,
        timestamp: float | None = None,
        confidence: ArrayLike | None = None,
    ) -> Array | None:
        """Take one frame; return the frame ``delay`` back, smoothed (shaped as
        ``positions``), or None while fewer than ``delay`` frames have followed the first.
        :attr:`frame_index`, :attr:`timestamp`, :attr:`std` and :attr:`sample_state`
        describe the frame returned. Arguments as for ``LiveSmoother.update`` (no
        mapping of body ids)."""
        if self._flushed:
            raise ValueError("this stream was flushed (it has ended); reset() starts a new one")
        frame = self._checked(positions, tracking_state, timestamp, confidence)
        self._buffer.append(frame)
        self.n_frames += 1
        t = self.n_frames - 1 - self.D
        if t < 0:
            return None
        first = self.n_frames - len(self._buffer)
        pos, std, states = self._give(self._run(), [t - first], t)
        self.std = None if std is None else std[0]
        self.sample_state = None if states is None else states[0]
        return pos[0]

    def flush(self) -> Array:
        """End the stream: return the frames not returned yet (the last ``delay``), from
        one run on the final window, stacked ``(n, J, D)`` (``(n, B, J, D)``); ``std`` and
        ``sample_state`` then have one row per frame. Afterwards :meth:`update` refuses
        frames until :meth:`reset`."""
        self._flushed = True
        start = self.frame_index + 1
        if start >= self.n_frames:
            shape = (0, *self._shape) if self._shape is not None else (0, 0, 0)
            self.std = self.sample_state = None
            return np.empty(shape)
        first = self.n_frames - len(self._buffer)
        rows = list(range(start - first, self.n_frames - first))
        pos, self.std, self.sample_state = self._give(self._run(), rows, self.n_frames - 1)
        return pos

    # ------------------------------------------------------------------ internals
    def _run(self) -> list[SkeletonSequence]:
        """The method on the buffered frames, one sequence per body."""
        pos, states, stamps, conf = zip(*self._buffer, strict=True)
        P = np.stack(pos)  # (n, B, J, D)
        S = None if states[0] is None else np.stack(states)
        C = None if conf[0] is None else np.stack(conf)
        ts = None if stamps[0] is None else np.asarray(stamps, dtype=float)
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
        return list(smooth(seqs, self.method, **self._options, **self.params))

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
            a = np.stack([getattr(s, field)[rows] for s in out], axis=1)  # (n, B, ...)
            return a[:, 0] if single else a

        self.frame_index = last
        self.timestamp = self._buffer[last - (self.n_frames - len(self._buffer))][2]
        return take("positions"), take("std"), take("sample_state")

    def _checked(self, positions: Any, states: Any, timestamp: Any, confidence: Any) -> tuple:
        """A frame checked against the stream, with a body axis; nothing is changed when
        it is refused."""
        if isinstance(positions, Mapping):
            raise ValueError("positions: a stream keyed by body id needs one DelayedSmoother "
                             "per id (or LiveSmoother, which takes them together)")  # fmt: skip
        try:
            pos = np.array(positions, dtype=float)
        except (TypeError, ValueError):
            raise ValueError("positions: expected numbers of shape (J, D) or (B, J, D)") from None
        if pos.ndim not in (2, 3) or pos.shape[-1] not in (2, 3):
            raise ValueError(
                f"positions: expected shape (J, D) or (B, J, D) with D = 3 or 2, found {pos.shape}"
            )
        if pos.shape[-2] != self.topology.n_joints:
            raise ValueError(f"positions: {pos.shape[-2]} joints, but topology "
                             f"{self.topology.name!r} has {self.topology.n_joints}")  # fmt: skip
        if self._shape is not None and pos.shape != self._shape:
            raise ValueError(
                f"positions: shape {pos.shape} differs from the stream's {self._shape}"
            )
        if np.isinf(pos).any():
            raise ValueError("positions: infinite values (use NaN for a missing joint)")
        body = pos.shape[:-1]
        st = None
        if states is not None:
            st = np.asarray(states)
            if st.shape != body or not np.isin(st, _STATES).all():
                raise ValueError(f"tracking_state: expected codes {_STATES} of shape {body}")
            st = st.astype(np.int8)
        cf = None
        if confidence is not None:
            try:
                cf = np.array(confidence, dtype=float)
            except (TypeError, ValueError):
                raise ValueError("confidence: expected numbers in [0, 1]") from None
            if cf.shape != body or np.any((cf < 0) | (cf > 1)):
                raise ValueError(f"confidence: expected scores in [0, 1] of shape {body}")
        ts = None
        if timestamp is not None:
            try:
                ts = float(timestamp)
            except (TypeError, ValueError):
                ts = math.nan
            if not math.isfinite(ts):
                raise ValueError(f"timestamp must be a finite number of seconds, got {timestamp!r}")
            prev = self._buffer[-1][2] if self._buffer else None
            if prev is not None and ts < prev:
                raise ValueError(f"timestamp {ts} comes before the previous frame's ({prev})")
        has = (st is not None, ts is not None, cf is not None)
        if self._has is not None and has != self._has:
            what = [n for n, h0, h1 in zip(("tracking_state", "timestamp", "confidence"),
                                           self._has, has, strict=True) if h0 != h1]  # fmt: skip
            raise ValueError(
                f"{', '.join(what)}: give it with every frame of a stream or with none"
            )
        self._shape, self._has = pos.shape, has
        if pos.ndim == 2:
            pos = pos[None]
            st = None if st is None else st[None]
            cf = None if cf is None else cf[None]
        return pos, st, ts, cf
