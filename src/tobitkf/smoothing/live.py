"""Live smoothing: one skeleton frame at a time, the same numbers as :func:`smooth`.

:class:`LiveSmoother` runs any *causal* registered method on a stream. A method that
registered a per-frame stepper (every built-in causal one: the Kalman-type methods,
``robust_online``, the 1€ and Kinect filters, the trailing moving average; constant
work per frame) runs through it; any other causal method runs by re-running its batch
form on the frames seen so far and returning the last frame, which is exact by
causality but costs time proportional to the stream's length. Fed the frames of a
recording one by one, it returns what ``smooth(recording, method)`` returns (tested),
without looking ahead.

Bodies may come and go: give a frame as a mapping ``{body_id: (J, 3) positions}``. A new
id starts a new filter; an id missing from a frame is predicted (its prediction is
returned) for ``max_missing`` seconds, then dropped. Each body's numbers are exactly those
of a LiveSmoother fed that body alone. Internally the bodies that appeared in the same
frame share one stepper (one array of bodies, one kernel call per frame: the steppers
treat bodies independently), so six people cost about what one array of six does; a
dropped body's slot is stepped with an empty frame until its whole group is gone.

Units. The physical parameters are in metres: a stream in ``"cm"`` or ``"mm"`` (say
so with ``units``) is converted to metres for the method and back, as :func:`smooth`
does. A stream of pixels (a 2-D stream, unless ``units`` says otherwise) or of unknown
units has no physical scale; the robust methods' gates (speed bound, margins, noise,
bone tolerance) are then measured on a sample recording of the same set-up
(``gates_from``, as :func:`smooth` measures them on the recording itself), on the
stream's own frames as they come (``gates_from="stream"``), or all of them are given in
the stream's units. Without any, the first frame is refused: gates in metres on pixels
would reject every motion.

Example
-------
>>> live = LiveSmoother("kinect_v2", method="atkf", fps=30)        # doctest: +SKIP
>>> for frame, states, t in sensor:                                # doctest: +SKIP
...     clean = live.update(frame, tracking_state=states, timestamp=t)
>>> people = live.update({7: frame_a, 9: frame_b}, timestamp=t)    # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tobitkf.skeleton.sequence import KNOWN_UNITS, SampleState, SkeletonSequence
from tobitkf.skeleton.topology import Topology, get_topology
from tobitkf.smoothing.api import (
    DEFAULT_LIVE_METHOD,
    check_params,
    get_method,
    method_names,
    run_method,
)
from tobitkf.smoothing.body_scale import check_body_scale
from tobitkf.smoothing.keypoints import (
    DEFAULT_MIN_CONFIDENCE,
    check_min_confidence,
    drop_third_axis,
    length_scale,
    low_confidence,
    pad_third_axis,
)
from tobitkf.smoothing.live_untangle import LiveUntangle
from tobitkf.smoothing.paper import REFERENCE_DT
from tobitkf.smoothing.params import as_bool, check_inferred_factor, check_up_axis
from tobitkf.smoothing.registry import LiveStepper, MethodSpec, SmoothInput
from tobitkf.smoothing.robust_scale import (
    GATE_PARAMS,
    STREAM_FIRST,
    STREAM_LAST,
    given_names,
    recording_gates,
    with_given,
)
from tobitkf.smoothing.stream_frames import (
    INFINITE,
    check_confidence,
    check_positions,
    check_states,
    timestamp_seconds,
)
from tobitkf.smoothing.timebase import (
    DEFAULT_INFERRED_NOISE_FACTOR,
    TRACKED_CODE,
    check_time_unit,
    frame_steps,
    measurements,
)
from tobitkf.smoothing.untangle import check_untangle, untangle_stats

__all__ = ["LiveSmoother", "live_methods"]

Array = NDArray[np.float64]


def live_methods() -> list[str]:
    """Names of the registered methods that can run live (causal with their defaults)."""
    return method_names(causal=True)


class _GuardedStepper:
    """A stepper whose output steps are held to the largest step its input made so far,
    where the input is present at both frames (``step_guard=True``): the causal step
    guard of :mod:`tobitkf.smoothing._step_guard`, frame by frame, as
    :func:`~tobitkf.smoothing.api.smooth` runs it on a whole recording; the shift is
    added to the variance of ``std``. Anything else is the wrapped stepper's."""

    def __init__(self, inner: Any) -> None:
        self.inner = inner
        self.std: Array | None = None
        self._state: tuple[Any, ...] | None = None

    def __getattr__(self, name: str) -> Any:  # uses_*, rejected, ...: the stepper's own
        return getattr(self.inner, name)

    def step(self, ys: Array, missing: Any, states: Any, dt: float, **kw: Any) -> Array:
        from tobitkf.smoothing import _step_guard as g

        out = np.array(self.inner.step(ys, missing, states, dt, **kw), dtype=float)
        std = getattr(self.inner, "std", None)
        B, J, D = out.shape
        if self._state is None or self._state[1].shape != (B, J):
            self._state = g.new_state(B, J, D)
        y = np.ascontiguousarray(ys, dtype=float)[None]
        std1 = None if std is None else np.asarray(std, dtype=float)[None]
        guarded = g.guard_output(y, np.asarray(missing)[None], out[None], std1, self._state)
        self.std = None if guarded is None else guarded[0]
        return out


class _HistoryStepper:
    """A causal method without a stepper: re-run it on the history, keep the last frame."""

    uses_positions = True
    uses_confidence = True

    def __init__(self, spec: MethodSpec, topology: Topology, up_axis: int, factor: float,
                 params: dict[str, Any]) -> None:  # fmt: skip
        self.spec, self.topology, self.up_axis, self.factor = spec, topology, up_axis, factor
        self.params = params
        self._frames: list[tuple[Array, Array, NDArray[np.bool_], Any, float]] = []

    def step(self, ys: Array, missing: NDArray[np.bool_], states: Any, dt: float,
             positions: Array | None = None, confidence: Any = None) -> Array:  # fmt: skip
        # copies: a caller may reuse its frame buffer for the next frame
        pos = ys if positions is None else positions
        conf = None if confidence is None else np.array(confidence, dtype=float)
        self._frames.append((pos.copy(), ys.copy(), missing.copy(), states, dt, conf))
        pos, y, miss, st, steps, cf = zip(*self._frames, strict=True)
        step_arr = np.asarray(steps, dtype=float)
        if all(s is None for s in st):
            states_arr = None
        else:  # states in some frames only (bodies keyed by id): None means all TRACKED
            tracked = np.full(missing.shape, TRACKED_CODE, np.int8)
            states_arr = np.stack([tracked if s is None else s for s in st])
        inp = SmoothInput(
            positions=np.stack(pos),
            ys=np.stack(y),
            missing=np.stack(miss),
            tracking_state=states_arr,
            steps=step_arr,
            times=np.concatenate([[0.0], np.cumsum(step_arr[1:])]),
            is_reference=bool(np.allclose(step_arr, REFERENCE_DT, rtol=1e-9, atol=0.0)),
            topology=self.topology,
            up_axis=self.up_axis,
            inferred_noise_factor=self.factor,
            confidence=None
            if all(c is None for c in cf)
            else np.stack([np.full(missing.shape, np.nan) if c is None else c for c in cf]),
        )
        result = run_method(self.spec, inp, self.params)
        # what LiveSmoother.std / .sample_state read: the method's own, at the last frame
        self.std = None if result.std is None else np.asarray(result.std[-1], dtype=float)
        rejected = [d.get("rejected") for d in result.diagnostics or ()]
        self.rejected = (
            None
            if all(r is None for r in rejected)
            else np.stack([np.zeros(missing.shape[1], bool) if r is None
                           else np.asarray(r, dtype=bool)[-1] for r in rejected])
        )  # fmt: skip
        return np.asarray(result.positions[-1], dtype=float)


@dataclass
class _Group:
    """Bodies keyed by id that appeared in the same frame: one stepper, one slot each
    (``gates_from="stream"``: one body, whose gates and stepper are in ``gates``)."""

    stepper: Any
    members: list[Any]  # body id of each slot (None once dropped)
    frames: int = 0
    gates: _StreamGates | None = None


#: a live stream's timestamps are judged to be seconds on their first this many steps
_TIME_UNIT_STEPS = 3


@dataclass
class _StreamGates:
    """``gates_from="stream"``, for a stream or one body of a keyed stream: the frames so
    far (as stepped) and their steps, the frame at which the gates are measured next,
    the frames' time as batch has it (the cumulated steps), and the stepper (None before
    the first measurement)."""

    frames: list[Array] = field(default_factory=list)
    steps: list[float] = field(default_factory=list)
    n: int = 0
    next: int = STREAM_FIRST
    clock: float = 0.0
    stepper: Any = None


@dataclass
class _Body:
    """One body of a stream keyed by id: its group and slot, when it was last seen."""

    group: _Group
    slot: int
    last_seen: float


def _group_frame(
    arr: Array, sts: list[Any] | None, rows: Sequence[int], confs: list[Any] | None = None
) -> tuple[Array, Any, Any]:
    """The frame of one group: slot ``s`` takes row ``rows[s]`` of the keyed frame's
    positions ``arr`` (and states ``sts``, confidences ``confs``), NaN where it is -1 (a
    body not in the frame, predicted, or a dropped slot). States: None unless one of its
    bodies has some (the others TRACKED then, which is what None means); confidences
    alike (NaN: none)."""
    pos, states = _group_positions(arr, sts, rows)
    if confs is None or all(confs[r] is None for r in rows if r >= 0):
        return pos, states, None
    conf = np.full(pos.shape[:2], np.nan)
    for s, r in enumerate(rows):
        if r >= 0 and confs[r] is not None:
            conf[s] = confs[r]
    return pos, states, conf


def _group_positions(arr: Array, sts: list[Any] | None, rows: Sequence[int]) -> tuple[Array, Any]:
    n = len(arr)
    if isinstance(rows, range) or rows == list(range(n)):
        pos = arr  # the usual frame: every body of the group, in its order
    else:
        pos = np.full((len(rows), *arr.shape[1:]), np.nan)
        slots = [s for s, r in enumerate(rows) if r >= 0]
        pos[slots] = arr[[rows[s] for s in slots]]
    if sts is None or all(sts[r] is None for r in rows if r >= 0):
        return pos, None
    states = np.full(pos.shape[:2], TRACKED_CODE, np.int8)
    for s, r in enumerate(rows):
        if r >= 0 and sts[r] is not None:
            states[s] = sts[r]
    return pos, states


class _FrameInfo:
    """One stepped frame ``(B, J)``, for ``LiveSmoother.std``, ``.sample_state`` and
    ``.clipped``: its output, missing samples, the stepper's sd, rejections and clipped
    flags, and the stream's metres per unit; the sd in the stream's units and the sample
    states, by the causal rules of
    :func:`~tobitkf.smoothing.output_states.sample_states`, on first use."""

    def __init__(self, out: Array, missing: Any, std: Any, rejected: Any, scale: float,
                 clipped: Any = None) -> None:  # fmt: skip
        self._raw = (out, missing, std, rejected, scale)
        self.clipped = clipped
        self._std: Any = None
        self._state: Any = None

    def std(self) -> Array | None:
        out, _, std, _, scale = self._raw
        if std is not None and self._std is None:
            self._std = np.where(np.isnan(out).any(axis=-1), np.nan, np.asarray(std, float))
            if scale != 1.0:
                self._std /= scale
        return self._std

    def state(self) -> NDArray[np.int8]:
        if self._state is None:
            out, missing, _, rejected, _ = self._raw
            finite = ~np.isnan(out).any(axis=-1)
            state = np.full(finite.shape, int(SampleState.EXTRAPOLATED), dtype=np.int8)
            state[~missing] = SampleState.MEASURED
            if rejected is not None:
                state[np.asarray(rejected) & ~missing] = SampleState.REJECTED
            state[~finite] = SampleState.NONE
            self._state = state
        return self._state


class LiveSmoother:
    """Smooth a live skeleton stream frame by frame.

    Frames are ``(J, 3)`` (or ``(B, J, 3)``), or ``(J, 2)`` image keypoints (the first
    frame fixes it). Live, nothing of the recording is known in advance: the methods'
    parameters apply as given, in metres (module docstring, "Units").

    Parameters
    ----------
    topology : Topology or name
        Skeleton of the stream (its up axis places the vertical limit of ``atkf``).
    method : str
        A causal registered method (:func:`live_methods`; default
        ``DEFAULT_LIVE_METHOD``, ``"robust_online"``); parameters as for
        :func:`tobitkf.smooth`.
    fps : float
        Nominal frame rate, used when no timestamps are given (and for the first step).
    up_axis : int, optional
        Overrides the topology's up axis.
    inferred_noise_factor : float
        Measurement-noise variance multiplier for INFERRED joints (as in ``smooth``).
    max_missing : float
        Seconds a body keyed by id is predicted after its last frame before it is dropped
        (default 1).
    units : str, optional
        ``"m"``, ``"cm"``, ``"mm"`` (converted to metres for the method and back) or
        ``"px"``; None: metres for a 3-D stream, pixels for a 2-D one.
    min_confidence : float
        A sample whose ``confidence`` (``update``) is below this is missing (default 0.1,
        as in :func:`smooth`); above it the robust methods weigh it by its score.
    gates_from : SkeletonSequence or ndarray, optional
        A recording of the same set-up (same camera or tracker, same units as the stream;
        an array ``(T, J, D)`` or ``(T, B, J, D)`` at ``fps``, NaN where missing): the
        robust methods' gates are measured on it as :func:`smooth` measures them on a
        recording in pixels (``robust_scale.recording_gates``); parameters given here
        override them. Needed, unless those parameters are all given, for a stream in
        pixels or unknown units. ``"stream"``: measured on the stream's own frames as they
        come (:func:`~tobitkf.smoothing.robust_scale.stream_gate_frames`: on the first 16
        frames, then again each time their count doubles, up to 4096; the first 16 are
        returned as measured), all six of them; what ``smooth(recording,
        "robust_online", gates="stream")`` gives. In a stream keyed by body id, each body
        has its own (and its own stepper: the bodies are not stepped as one array). For
        a method without gates (``kf``, ``one_euro``, ...) either form gives the
        untangling's statistics only.
    untangle : ``"auto"`` (default), True or False
        Undo identity swaps between the bodies of a frame (the rows of a ``(B, J, D)``
        frame, or the ids of a keyed one) and left/right swaps within each, causally,
        before the method sees them (:mod:`tobitkf.smoothing.untangle`, "Causal form");
        ``"auto"``: for a stream in pixels or unknown units, when ``gates_from`` gives
        what the decisions are measured on (the sample, or the stream's frames so far).
        What was undone in the last frame: :attr:`swapped`.
    **params
        Method parameters; unknown names raise ``ValueError`` listing the valid ones.
        ``step_guard=True`` holds every output step of a joint to the largest step its
        input made so far, as ``smooth(..., step_guard=True)`` does (the robust methods
        always do).
    """

    def __init__(
        self,
        topology: Topology | str = "kinect_v2",
        method: str = DEFAULT_LIVE_METHOD,
        *,
        fps: float = 30.0,
        up_axis: int | None = None,
        inferred_noise_factor: float | None = None,
        max_missing: float = 1.0,
        units: str | None = None,
        gates_from: Any = None,
        min_confidence: float = DEFAULT_MIN_CONFIDENCE,
        untangle: Any = "auto",
        **params: Any,
    ) -> None:
        self.spec = get_method(method)
        self.untangle = check_untangle(untangle)
        self._sample_untangle: tuple[float, float, int] | None = None
        if "offline" in params:
            raise ValueError("offline smoothing needs the whole recording: it cannot run live")
        params = dict(params)
        # smooth(..., step_guard=True) as it runs live: the causal guard, frame by frame
        self.step_guard = as_bool("step_guard", params.pop("step_guard", False))
        self.params = check_params(method, params)
        if units is not None and (not isinstance(units, str) or units not in KNOWN_UNITS):
            raise ValueError(f"units must be one of {sorted(KNOWN_UNITS)} or None, got {units!r}")
        self.units = units
        self.min_confidence = check_min_confidence(min_confidence)
        self._given = given_names(params)  # a value per region: those regions only
        if not self.spec.is_causal(self.params):
            raise ValueError(
                f"method {method!r} cannot run live (it looks ahead in time); causal "
                f"methods: {', '.join(live_methods())}"
            )
        try:
            fps_ok = float(fps) > 0 and np.isfinite(float(fps))
        except (TypeError, ValueError):
            fps_ok = False
        if not fps_ok:
            raise ValueError(f"fps must be a positive number, got {fps!r}")
        self.topology = get_topology(topology) if isinstance(topology, str) else topology
        self.method = method
        self.up_axis = int(self.topology.up_axis) if up_axis is None else check_up_axis(up_axis)
        self.inferred_noise_factor = (
            DEFAULT_INFERRED_NOISE_FACTOR
            if inferred_noise_factor is None
            else check_inferred_factor(inferred_noise_factor)
        )
        self.fps = float(fps)
        try:
            ok = float(max_missing) >= 0 and np.isfinite(float(max_missing))
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise ValueError(f"max_missing must be a number of seconds >= 0, got {max_missing!r}")
        self.max_missing = float(max_missing)
        self._gates_dims: int | None = None  # the coordinates of the gates' sample
        self._scale = 1.0  # metres per unit of the stream (set at its first frame)
        # "stream": the untangling's statistics, and a gated method's gates, measured on
        # the stream's own frames (a method without gates: the untangling only)
        self._stream_untangle = isinstance(gates_from, str) and gates_from == "stream"
        self._stream_gates = self._stream_untangle and self._gated
        if self._stream_gates:
            self.params = check_params(self.method, {**self.params, "gates": "stream"})
        elif self._stream_untangle:
            pass
        elif isinstance(gates_from, str):
            raise ValueError(
                f"gates_from: a recording of the same set-up or 'stream', got {gates_from!r}"
            )
        elif gates_from is not None:
            self._measure_gates(gates_from)
        if self.untangle is True and not self._stream_untangle and self._sample_untangle is None:
            raise ValueError(
                "untangle=True: the swaps are judged against the noise and the steps "
                "measured on gates_from (a recording of the same set-up, or 'stream')"
            )
        self.reset()

    @property
    def _gated(self) -> bool:
        """Whether the method has the robust family's gates (metric parameters)."""
        return "gates" in self.spec.defaults

    def _measure_gates(self, sample: Any) -> None:
        """The untangling's statistics and (a gated method) the robust gates measured on
        ``sample`` (``gates_from``), under the given ones."""
        if isinstance(sample, SkeletonSequence):
            stream = self._stream_units(sample.n_dims)
            if sample.units is not None and sample.units != stream:
                raise ValueError(
                    f"gates_from: the sample is in {sample.units!r}, the stream in {stream!r}"
                    f" (say units={sample.units!r} if the stream is in the sample's units)"
                )
            pos, states, steps = sample.positions, sample.tracking_state, frame_steps(sample)[0]
            low = low_confidence(sample.confidence, self.min_confidence)
            if low is not None:  # what the method would not see: missing, as in smooth()
                pos = np.where(low[..., None], np.nan, pos)
        else:
            try:
                pos = np.asarray(sample, dtype=float)
            except (TypeError, ValueError):
                raise ValueError("gates_from: expected a SkeletonSequence or an array") from None
            states, steps = None, np.full(len(pos), 1.0 / self.fps)
        if pos.ndim == 3:
            pos = pos[:, None]
            states = None if states is None else np.asarray(states)[:, None]
        J = self.topology.n_joints
        if pos.ndim != 4 or pos.shape[2] != J or pos.shape[3] not in (2, 3) or len(pos) < 3:
            raise ValueError(
                f"gates_from: expected at least 3 frames of shape (J, D) or (B, J, D) with "
                f"J = {J} and D = 2 or 3, found {pos.shape}"
            )
        if np.isinf(pos).any():
            raise ValueError(f"gates_from: {INFINITE}")
        dims = pos.shape[-1]
        times = (sample.times() if isinstance(sample, SkeletonSequence)
                 else np.arange(len(pos)) / self.fps)  # fmt: skip
        self._sample_untangle = untangle_stats(pos, times)  # in the stream's units
        if not self._gated:  # a method without gates: the untangling's statistics only
            return
        scale = length_scale(self._stream_units(dims))
        if scale is not None and scale != 1.0:
            pos = pos * scale
        ys, _ = measurements(pad_third_axis(pos), states)
        moved = np.abs(np.diff(ys[..., :dims], axis=0))
        if not np.nanmax(moved, initial=0.0) > 0:  # NaN steps (missing) do not count
            raise ValueError(
                "gates_from: the sample shows no motion (every joint missing or still): the "
                "gates would reject every step; give a recording of the set-up in use"
            )
        gates = recording_gates(ys, steps, self.topology.parents, dims)
        measured = with_given(
            {k: gates[k] for k in GATE_PARAMS}, self.params, self._given,
            self.topology.joint_groups(),
        )  # fmt: skip
        self.params = check_params(self.method, {**self.params, **measured})
        self._gates_dims = dims

    def _start_untangle(self, dims: int) -> None:
        """At the first frame: whether swaps are undone (``untangle``), and on what."""
        self._untangling = None
        if self.untangle is False:
            return
        if self.untangle == "auto" and length_scale(self._stream_units(dims)) is not None:
            return  # a track in metres (or cm, mm): as smooth(), left as it is
        if self._stream_untangle or self._sample_untangle is not None:
            stats = None if self._stream_untangle else self._sample_untangle
            self._untangling = LiveUntangle(self.topology.symmetry, stats)

    @property
    def swapped(self) -> dict[str, Any] | None:
        """What the untangling changed in the last frame: ``identity_swapped`` (a body
        took another's samples) and ``lr_swapped`` (per pair of
        ``topology.symmetry``), shaped as :attr:`std` (a keyed stream: per id); None
        when the stream is not untangled."""
        u = self._untangling
        if u is None or self.n_frames == 0:
            return None
        ident, lr = u.identity_swapped, u.lr_swapped
        if self._keys is not None:
            return {"identity_swapped": dict(zip(self._keys, ident.tolist(), strict=True)),
                    "lr_swapped": dict(zip(self._keys, lr, strict=True))}  # fmt: skip
        if self._single:
            return {"identity_swapped": bool(ident[0]), "lr_swapped": lr[0]}
        return {"identity_swapped": ident, "lr_swapped": lr}

    def _frame_time(self, timestamp: float | None) -> float:
        """The frame's time as ``SkeletonSequence.times()`` has it: its timestamp, else
        its index over ``fps``."""
        t = timestamp_seconds(timestamp)
        return self.n_frames / self.fps if t is None else t

    def _stream_units(self, dims: int) -> str:
        """The stream's units: as given, else metres in 3-D and pixels in 2-D."""
        return self.units if self.units is not None else ("m" if dims == 3 else "px")

    def _check_gates(self, dims: int) -> None:
        """At the first frame: the robust gates can apply to a stream of ``dims``."""
        if self._stream_gates:  # measured on the stream itself, in its own units
            scale = length_scale(self._stream_units(dims))
            self._scale = 1.0 if scale is None else scale
            return
        if self._gates_dims is not None:
            scale = length_scale(self._stream_units(dims))
            self._scale = 1.0 if scale is None else scale
            if dims != self._gates_dims:
                raise ValueError(
                    f"positions: {dims} coordinates, but the gates were measured on a "
                    f"sample with {self._gates_dims}"
                )
            return
        units = self._stream_units(dims)
        scale = length_scale(units)
        self._scale = 1.0 if scale is None else scale
        if self.spec.check_data is not None:  # what the batch run checks first
            self.spec.check_data(self.params, dims, "m" if scale is not None else units)
        if not self._gated or scale is not None:
            return
        if self.params.get("gates") == "physical":  # the user's word: in the stream's units
            return
        missing = [k for k in GATE_PARAMS if k not in self._given]  # regions: not whole
        if missing:
            raise ValueError(
                f"a stream in {units}"
                + (
                    " (2-D keypoints without units= are taken as pixels)"
                    if self.units is None
                    else ""
                )
                + f" has no physical scale, and {self.method!r}'s gates are "
                f"in metres: pass gates_from=<a recording of the same set-up> to measure "
                f"them (as smooth() does), gates_from='stream' to measure them on the "
                f"stream's own frames as they come, or give {', '.join(missing)} in the "
                f"stream's units (or units='m' if it is in metres)"
            )

    def __getstate__(self) -> dict[str, Any]:
        """Pickling (a saved stream, or one handed to another process): the method is
        kept by its name, and looked up again in the registry when unpickled."""
        state = dict(self.__dict__)
        state["spec"] = self.spec.name
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        state = dict(state)
        state["spec"] = get_method(state["spec"])  # a method of one's own: register it first
        self.__dict__.update(state)

    def reset(self) -> None:
        """Forget the stream; the next frame starts new tracks (and may have another
        number of coordinates, unless the gates were measured on a sample)."""
        self._dims: int | None = None
        self._stepper: LiveStepper | _HistoryStepper | None = None
        self._shape: tuple[int, ...] | None = None
        self._single = False
        self._last_timestamp: float | None = None
        self._bodies: dict[Any, _Body] | None = None  # streams keyed by body id
        # the last frame's ids when they were every body tracked, all in one group in its
        # slot order: the same ids again step that group as they are (no regrouping)
        self._same: tuple[tuple[Any, ...], _Group, list[_Body]] | None = None
        self._clock = 0.0
        self._first_steps: list[float] = []  # the stamps' first steps (their unit)
        self._time: float | None = None  # the timestamp of the frame being stepped
        self._size_checked = False  # a frame with a body has passed check_body_scale
        self.n_frames = 0
        self._stream = _StreamGates()  # gates_from="stream", a stream of arrays
        self._untangling: LiveUntangle | None = None  # set at the first frame
        self._keys: list[Any] | None = None  # a keyed stream's ids in the last frame
        # the last frame, for .std and .sample_state (per body when keyed: its group's
        # frame and its slot there)
        self._last: _FrameInfo | None = None
        self._keyed_info: dict[Any, tuple[_FrameInfo, int]] | None = None

    @property
    def std(self) -> Any:
        """The last frame's posterior standard deviation per sample, in the stream's units
        (``(J,)``, ``(B, J)``, or ``{body_id: (J,)}`` for a keyed stream, as
        :meth:`update` returned the positions; NaN where there is no estimate or the
        frame was returned as measured); None when the method gives none (the 1€ and
        Kinect filters, the moving average). Batch gives the same (``smooth(...).std``)."""
        return self._frame_info(0)

    @property
    def sample_state(self) -> Any:
        """The last frame's :class:`~tobitkf.skeleton.sequence.SampleState` codes, shaped
        as :attr:`std`: MEASURED, REJECTED (judged impossible and filled), EXTRAPOLATED
        (no measurement: predicted from the frames so far) or NONE (no estimate yet); as
        ``smooth(...).sample_state`` of a causal method."""
        return self._frame_info(1)

    def _frame_info(self, k: int) -> Any:
        """The last frame's sd (``k`` 0), sample states (1) or clipped flags (2), shaped
        as :meth:`update` returned its positions."""

        def value(info: _FrameInfo) -> Any:
            if k == 0:
                return info.std()
            return info.state() if k == 1 else info.clipped

        if self._keyed_info is not None:
            rows = {b: value(info) for b, (info, _) in self._keyed_info.items()}
            if k != 1 and all(v is None for v in rows.values()):
                return None
            return {b: rows[b][self._keyed_info[b][1]] for b in rows}
        if self._last is None:
            return None
        v = value(self._last)
        return v if v is None or not self._single else v[0]

    @property
    def clipped(self) -> Any:
        """Which joints' last measurements were clipped (censoring methods), shaped as
        :attr:`std` (``{body_id: (J,)}`` for a keyed stream), else None."""
        return self._frame_info(2)

    @property
    def bodies(self) -> list[Any]:
        """Ids of the bodies being tracked (seen within ``max_missing``), in arrival order."""
        return list(self._bodies or ())

    def _new_stepper(self) -> LiveStepper | _HistoryStepper | _GuardedStepper:
        args = (self.topology, self.up_axis, self.inferred_noise_factor)
        if self.spec.live is not None:
            stepper: Any = self.spec.live(*args, **self.params)
        else:
            stepper = _HistoryStepper(self.spec, *args, self.params)
        return _GuardedStepper(stepper) if self.step_guard else stepper

    def _step_seconds(self, timestamp: float | None) -> tuple[float, float | None]:
        nominal = 1.0 / self.fps
        t = timestamp_seconds(timestamp)
        if self.n_frames and (t is None) != (self._last_timestamp is None):
            # a stream timed by its stamps and by fps by turns has no one time base (and
            # DelayedSmoother refuses it alike)
            raise ValueError("timestamp: give it with every frame of a stream or with none")
        if t is None:
            return nominal, self._last_timestamp
        if self._last_timestamp is None:
            return nominal, t
        if t < self._last_timestamp:
            raise ValueError(f"timestamps must not decrease: {t} after {self._last_timestamp}")
        d = t - self._last_timestamp
        if d > 0 and len(self._first_steps) < _TIME_UNIT_STEPS:
            # the stamps' unit, judged on their first steps (as batch on their median)
            self._first_steps.append(d)
            if len(self._first_steps) == _TIME_UNIT_STEPS:
                try:
                    check_time_unit(float(np.median(self._first_steps)), self.fps)
                except ValueError:
                    self._first_steps.pop()  # the frame is refused: judged again on the next
                    raise
        return max(d, 0.1 * nominal), t

    def update(
        self,
        positions: ArrayLike | Mapping[Any, ArrayLike],
        tracking_state: ArrayLike | Mapping[Any, ArrayLike] | None = None,
        timestamp: float | None = None,
        confidence: ArrayLike | Mapping[Any, ArrayLike] | None = None,
    ) -> Any:
        """Filter one frame.

        Parameters
        ----------
        positions : array_like, shape (J, 3) or (B, J, 3) for B bodies
            Metres; NaN for a missing joint (infinite values are refused).
        tracking_state : array_like of int, shape (J,) or (B, J), optional
            0 not tracked (treated as missing), 1 inferred (noisier), 2 tracked.
        timestamp : float, optional
            Seconds; without it frames are 1/fps apart.
        confidence : array_like, shape (J,) or (B, J), optional
            A pose estimator's score in [0, 1] per joint (NaN: none); below
            ``min_confidence`` the joint is missing, above it the robust methods weigh it,
            as :func:`smooth` does.

        Returns
        -------
        ndarray, shape like ``positions``
            Smoothed positions; NaN for a joint not measured yet.

        A frame that is refused (``ValueError``) leaves the stream unchanged.

        With ``positions`` a mapping ``{body_id: (J, 3)}`` (and ``tracking_state`` and
        ``confidence`` mappings of the same ids, or None), returns ``{body_id: (J, 3)}``
        for every body tracked: those in the frame and those still predicted (missing for
        at most ``max_missing`` seconds). A stream is either keyed by id or not, from its
        first frame on.
        """
        if isinstance(positions, Mapping):
            return self._update_bodies(positions, tracking_state, timestamp, confidence)
        if self._bodies is not None:
            raise ValueError("this stream is keyed by body id: pass {body_id: positions}")
        dims = self._dims
        pos, states = self._check_frame(positions, tracking_state)
        try:
            conf = check_confidence(confidence, pos.shape[:-1])
        except ValueError:
            self._dims = dims
            raise
        shape = pos.shape
        if self._shape is not None and shape[:-1] != self._shape:
            raise ValueError(
                f"positions: batch shape {shape[:-1]} differs from the stream's {self._shape}"
            )
        dt, stamp = self._step_seconds(timestamp)
        # everything checked: from here on the frame is part of the stream
        self._shape = shape[:-1]
        self._single = pos.ndim == 2
        if self._untangling is not None:
            pos, states, conf = self._untangle_frame(pos, states, conf, timestamp)
        self._time = None if timestamp is None else stamp
        if self._stream_gates:
            out = self._stream_step(self._stream, pos, states, dt, conf)
        else:
            if self._stepper is None:
                self._stepper = self._new_stepper()
            out = self._step(self._stepper, pos, states, dt, conf)
        self._last_timestamp = stamp
        self.n_frames += 1
        return out

    def _untangle_frame(self, pos: Array, states: Any, conf: Any, timestamp: Any) -> tuple:
        """An array frame with its swaps undone (positions, states and scores together)."""
        one = pos.ndim == 2

        def rows(a: Any) -> Any:
            return None if a is None else (np.asarray(a)[None] if one else a)

        y, st, cf = self._untangling.frame(rows(pos), None, self._frame_time(timestamp),
                                           rows(states), rows(conf))  # fmt: skip
        if one:
            return y[0], None if st is None else st[0], None if cf is None else cf[0]
        return y, st, cf

    def _step(self, stepper: Any, pos: Array, states: Any, dt: float, conf: Any = None) -> Array:
        ys, missing, batch_states, conf, batch_pos = self._inputs(pos, states, conf)
        return self._output(self._step_inputs(stepper, ys, missing, batch_states, dt, conf,
                                              batch_pos), pos)  # fmt: skip

    def _inputs(self, pos: Array, states: Any, conf: Any) -> tuple[Any, ...]:
        """A frame as the steppers take it: ``(ys, missing, states, confidence,
        positions)`` with a body axis, in metres where the stream has a length unit, a
        third axis of zeros in 2-D, NaN where missing or below ``min_confidence``."""
        single = pos.ndim == 2
        batch_pos = pos[None] if single else pos
        batch_states = None if states is None else (states[None] if single else states)
        if self._scale != 1.0:  # centimetres or millimetres: the method works in metres
            batch_pos = batch_pos * self._scale
        if not self._size_checked:  # as the batch run (api.run_method), on each frame
            # until one shows a body; gates measured on the stream or on a sample use no
            # physical constant, whatever the unit
            measured = self._stream_gates or self._gates_dims is not None
            metres = not measured and length_scale(self._stream_units(pos.shape[-1])) is not None
            size = check_body_scale(batch_pos[None], metres=metres)
            self._size_checked = bool(np.isfinite(size).any())
        batch_pos = pad_third_axis(batch_pos)  # 2-D: a third axis of zeros, dropped below
        ys, missing = measurements(batch_pos, batch_states)
        if conf is not None:  # below the threshold: missing, for every method (as smooth)
            conf = conf[None] if single else conf
            low = low_confidence(conf, self.min_confidence)
            if low is not None and (low & ~missing).any():
                missing = missing | low
                ys = np.where(missing[..., None], np.nan, ys)
        return ys, missing, batch_states, conf, batch_pos

    def _step_inputs(self, stepper: Any, ys: Array, missing: Any, batch_states: Any,
                     dt: float, conf: Any, batch_pos: Array,
                     time: float | None = None) -> Array:  # fmt: skip
        """One step of ``stepper`` on a frame from :meth:`_inputs` (with its body axis);
        ``time``: the frame's time when the timestamps give none."""
        kw: dict[str, Any] = {}
        if conf is not None and getattr(stepper, "uses_confidence", False):
            kw["confidence"] = conf  # the scores weigh the samples kept
        if getattr(stepper, "uses_positions", False):  # the positions as given, too
            kw["positions"] = batch_pos
        if getattr(stepper, "uses_n_dims", False):  # the stream's coordinates (2 or 3)
            kw["n_dims"] = self._dims
        if getattr(stepper, "uses_time", False):  # the frame's timestamp (None: not given)
            kw["time"] = self._time if self._time is not None else time
        out = np.asarray(stepper.step(ys, missing, batch_states, dt, **kw))
        self._note(out, missing, getattr(stepper, "std", None), getattr(stepper, "rejected", None),
                   getattr(stepper, "clipped", None))  # fmt: skip
        return out

    def _note(self, out: Array, missing: Any, std: Any, rejected: Any, clipped: Any = None) -> None:
        """Keep what :attr:`std`, :attr:`sample_state` and :attr:`clipped` give of the
        frame just stepped (worked out only when they are read: a stream that never reads
        them pays nothing for them)."""
        self._last = _FrameInfo(out.copy(), missing, std, rejected, self._scale, clipped)

    def _output(self, out: Array, pos: Array) -> Array:
        """A stepper's output ``(B, J, 3)`` in the stream's coordinates, units and shape."""
        out = drop_third_axis(out, pos.shape[-1])
        if self._scale != 1.0:
            out = out / self._scale
        return out[0] if pos.ndim == 2 else out

    def _stream_step(
        self, gates: _StreamGates, pos: Array, states: Any, dt: float, conf: Any
    ) -> Array:
        """``gates_from="stream"``: the gates measured on the frames so far at the frames
        of :func:`~tobitkf.smoothing.robust_scale.stream_gate_frames` (the stepper starts
        at the first, and is retuned, its state kept, at the others); before the first,
        the frame as measured. What ``smooth(..., gates="stream")`` gives."""
        ys, missing, batch_states, conf, batch_pos = self._inputs(pos, states, conf)
        if gates.n == gates.next and gates.n <= STREAM_LAST:  # then the gates hold
            measured = recording_gates(np.stack(gates.frames), np.asarray(gates.steps),
                                       self.topology.parents, self._dims)  # fmt: skip
            mine = with_given({k: measured[k] for k in GATE_PARAMS}, self.params,
                              self._given, self.topology.joint_groups())  # fmt: skip
            params = {**self.params, **mine}
            if gates.stepper is None:
                gates.stepper = self.spec.live(
                    self.topology, self.up_axis, self.inferred_noise_factor, **params
                )
            else:
                gates.stepper.retune(**params)
            gates.next *= 2
        # the frame's time as batch has it without timestamps (the cumulated steps from
        # the first frame's): the stepper starts at a later frame than the stream
        gates.clock += dt
        if gates.n < STREAM_LAST:  # what the next measurements read
            gates.frames.append(np.array(ys))  # a copy: ys may be the caller's array
            gates.steps.append(dt)
        else:
            gates.frames, gates.steps = [], []
        gates.n += 1
        if gates.stepper is None:
            raw = np.where(missing[..., None], np.nan, ys)
            self._note(raw, missing, np.full(missing.shape, np.nan), None)
            return self._output(raw, pos)
        out = self._step_inputs(gates.stepper, ys, missing, batch_states, dt, conf, batch_pos,
                                gates.clock)  # fmt: skip
        return self._output(out, pos)

    def _update_bodies(
        self, frames: Mapping[Any, ArrayLike], states: Any, timestamp: float | None,
        confidence: Any = None,
    ) -> dict[Any, Array]:  # fmt: skip
        if self._shape is not None:
            raise ValueError("this stream is not keyed by body id: pass an array of positions")
        dims = self._dims
        bodies, arr, sts = self._check_bodies(frames, states)
        try:
            confs = self._keyed_confidence(confidence, bodies)
        except ValueError:
            self._dims = dims
            raise
        dt, stamp = self._step_seconds(timestamp)
        # everything checked: from here on the frame is part of the stream
        if self._untangling is not None:
            arr, sts, confs = self._untangling.frame(arr, bodies, self._frame_time(timestamp),
                                                     sts, confs)  # fmt: skip
        self._keys = bodies
        self._clock += dt
        self._time = None if timestamp is None else stamp
        same = self._same
        if same is not None and same[0] == tuple(bodies):
            out = self._step_same(same[1], same[2], bodies, arr, sts, dt, confs)
        else:
            out = self._regroup(bodies, arr, sts, dt, confs)
        self._last_timestamp = stamp
        self.n_frames += 1
        return out

    def _keyed_confidence(self, confidence: Any, bodies: list[Any]) -> list[Any] | None:
        """A keyed frame's confidences, one per body (None: none), or None."""
        if confidence is None:
            return None
        if not isinstance(confidence, Mapping):
            raise ValueError("confidence: expected a mapping {body_id: scores} like positions")
        unknown = [b for b in confidence if b not in bodies]
        if unknown:
            raise ValueError(f"confidence for bodies not in the frame: {unknown}")
        J = self.topology.n_joints
        out = []
        for body in bodies:
            try:
                out.append(check_confidence(confidence.get(body), (J,)))
            except ValueError as exc:
                raise ValueError(f"body {body!r}: {exc}") from None
        return out

    def _step_group(self, group: _Group, pos: Array, states: Any, dt: float, conf: Any) -> Array:
        """One frame of a keyed stream's group: its stepper, or its own stream gates."""
        if group.gates is not None:
            return self._stream_step(group.gates, pos, states, dt, conf)
        return self._step(group.stepper, pos, states, dt, conf)

    def _step_same(self, group: _Group, entries: list[_Body], bodies: list[Any], arr: Array,
                   sts: list[Any] | None, dt: float,
                   confs: list[Any] | None = None) -> dict[Any, Array]:  # fmt: skip
        """The usual frame: the bodies of the last one, every slot of its only group."""
        pos, states, conf = _group_frame(arr, sts, range(len(arr)), confs)
        res = self._step_group(group, pos, states, dt, conf)
        group.frames += 1
        for entry in entries:
            entry.last_seen = self._clock
        self._keyed_info = {b: self._slot_info(s) for s, b in enumerate(bodies)}
        return dict(zip(bodies, res, strict=True))

    def _slot_info(self, slot: int) -> tuple[_FrameInfo, int]:
        """The group just stepped's frame, and a body's slot in it."""
        return self._last, slot  # type: ignore[return-value]

    def _regroup(
        self, bodies: list[Any], arr: Array, sts: list[Any] | None, dt: float,
        confs: list[Any] | None = None,
    ) -> dict[Any, Array]:  # fmt: skip
        """Any frame: bodies dropped, new ones grouped, each group stepped."""
        if self._bodies is None:
            self._bodies = {}
        row = {b: i for i, b in enumerate(bodies)}  # each id's row of arr
        for body in [b for b in self._bodies if b not in row]:
            entry = self._bodies[body]
            if self._clock - entry.last_seen > self.max_missing:
                del self._bodies[body]  # gone: dropped (its slot gets empty frames)
                if self._untangling is not None:
                    self._untangling.forget([body])
                entry.group.members[entry.slot] = None
        new = [b for b in bodies if b not in self._bodies]
        # new ids start new filters: one group for all of them when the method has a
        # stepper (bodies independent in it), else one each (a history re-run)
        # (gates_from="stream": one each too, every body its own gates)
        one_group = self.spec.live is not None and not self._stream_gates
        for members in [new] if one_group else [[b] for b in new]:
            if members:
                group = (
                    _Group(None, list(members), gates=_StreamGates())
                    if self._stream_gates
                    else _Group(self._new_stepper(), list(members))
                )
                for slot, body in enumerate(members):
                    self._bodies[body] = _Body(group, slot, self._clock)
        results: dict[Any, Array] = {}
        infos: dict[Any, tuple[_FrameInfo, int]] = {}
        groups = {id(e.group): e.group for e in self._bodies.values()}.values()
        for group in groups:  # groups with at least one body tracked
            rows = [row.get(b, -1) for b in group.members]
            step = dt if group.frames else 1.0 / self.fps
            pos, states, conf = _group_frame(arr, sts, rows, confs)
            res = self._step_group(group, pos, states, step, conf)
            group.frames += 1
            results.update((b, r) for b, r in zip(group.members, res) if b is not None)
            infos.update((b, self._slot_info(s)) for s, b in enumerate(group.members)
                         if b is not None)  # fmt: skip
        for body in bodies:
            self._bodies[body].last_seen = self._clock
        out = {b: results[b] for b in bodies}
        if len(out) < len(self._bodies):
            out.update({b: results[b] for b in self._bodies if b not in row})
        self._keyed_info = {b: infos[b] for b in out}
        self._same = None
        if bodies and len(bodies) == len(self._bodies):
            group = self._bodies[bodies[0]].group
            if group.members == bodies:  # every body tracked, one group, in slot order
                self._same = (tuple(bodies), group, [self._bodies[b] for b in bodies])
        return out

    def _check_bodies(
        self, frames: Mapping[Any, ArrayLike], states: Any
    ) -> tuple[list[Any], Array, list[Any] | None]:
        """A keyed frame, checked: its ids, their positions stacked ``(n, J, D)`` and
        their tracking states (None, or an array or None per id)."""
        if states is not None and not isinstance(states, Mapping):
            raise ValueError("tracking_state: expected a mapping {body_id: states} like positions")
        bodies = list(frames)
        J = self.topology.n_joints
        if states is None and bodies:
            # the usual frame in one numpy call; anything else is checked body by body
            # below, for the message naming the first faulty one
            try:
                arr = np.asarray([frames[b] for b in bodies], dtype=float)
            except (TypeError, ValueError):
                arr = np.empty(0)
            D = arr.shape[-1]
            if (arr.ndim == 3 and arr.shape[1] == J and self._dims in (None, D)
                    and D in (2, 3) and not np.isinf(arr).any()):  # fmt: skip
                if self._dims is None:
                    self._check_gates(D)
                    self._start_untangle(D)
                self._dims = D
                return bodies, arr, None
        dims = self._dims  # a refused frame leaves it as it was
        try:
            checked, arr = self._checked_bodies(frames, states, bodies)
        except ValueError:
            self._dims = dims
            raise
        if not checked:
            arr = np.empty((0, J, self._dims or 3))
        return bodies, arr, None if states is None else [st for _, st in checked]

    def _checked_bodies(
        self, frames: Mapping[Any, ArrayLike], states: Any, bodies: list[Any]
    ) -> tuple[list[tuple[Array, Any]], Array]:
        """Each body's frame checked on its own (the message names the first faulty one)."""
        checked = []
        for body in bodies:
            st = None if states is None else states.get(body)
            try:
                pos, st = self._check_frame(frames[body], st, check_inf=False)
            except ValueError as exc:
                raise ValueError(f"body {body!r}: {exc}") from None
            if pos.ndim != 2:
                raise ValueError(f"body {body!r}: expected positions of shape (J, 3)")
            checked.append((pos, st))
        # infinite values: one check over all the bodies (a numpy call costs microseconds)
        arr = np.stack([p for p, _ in checked]) if checked else np.empty(0)
        if checked and np.isinf(arr).any():
            body = next(b for b, (p, _) in zip(bodies, checked) if np.isinf(p).any())
            raise ValueError(f"body {body!r}: {INFINITE}")
        unknown = [] if states is None else [b for b in states if b not in frames]
        if unknown:
            raise ValueError(f"tracking_state for bodies not in the frame: {unknown}")
        return checked, arr

    def _check_frame(
        self, positions: ArrayLike, tracking_state: Any, check_inf: bool = True
    ) -> tuple[Array, Any]:
        pos = check_positions(positions, self.topology, self._dims)
        shape = pos.shape
        if self._dims is None:
            self._check_gates(shape[-1])
            self._start_untangle(shape[-1])
        if check_inf and np.isinf(pos).any():
            raise ValueError(INFINITE)
        states = check_states(tracking_state, shape[:-1])
        self._dims = shape[-1]  # the frame is good: its coordinates are the stream's
        return pos, states
