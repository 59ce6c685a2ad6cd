"""``tobitkf.smooth``: smooth skeleton sequences with a registered method.

Every method is registered (:mod:`tobitkf.smoothing.registry`) in the module that
defines it; importing this module loads the built-in ones:

========================  ================================================================
``atkf``                  adaptive Tobit KF, 2020 paper (eq. 30–35, Alg. 2): R = 0.01 I,
                          Q = 0.0025 I, c = 0.34 m horizontal / 0.18 m vertical per 1/30 s
``atkf2016``              the same filter with the 2016 paper's c = (0.31, 0.18, 0.31),
                          Q = 0.001 I
``tkf``, ``tkfc``         Tobit KF (Allik 2016 / corrected 2020) with the Kinect device
                          limits x ∈ [-3, 3], y ∈ [-1.5, 3], z ∈ [0.5, 5] m
``kf``                    plain Kalman filter (random walk per joint)
``sgf`` / ``savgol``      Savitzky–Golay (window 9, order 3)
``one_euro``              1€ filter (Casiez et al. 2012)
``kinect``                Kinect SDK double-exponential joint filter (presets)
``moving_average``        centred or trailing box filter
``robust`` (default)      ours: physically impossible samples rejected, then RTS-smoothed
``robust_online``         ours, causal (the default of ``LiveSmoother``)
========================  ================================================================

The Kalman-type methods (:mod:`tobitkf.smoothing.kalman_methods`) describe time steps,
gaps, the up axis and tracking states; the robust pair is in
:mod:`tobitkf.smoothing.robust`. ``tobitkf methods`` lists the registry.

Output. A new :class:`SkeletonSequence` with the smoothed positions and the input's
timestamps, fps, topology, body id and metadata, plus:

* ``sample_state`` (T, J): :class:`~tobitkf.skeleton.sequence.SampleState` of every
  sample, worked out here for every method alike from the missing measurements, the
  method's ``rejected`` diagnostics, whether the output is finite and whether the method
  ran causally (see :func:`sample_states`);
* ``std`` (T, J): the posterior standard deviation, for methods that give one (the
  Kalman-type ones), else None;
* ``tracking_state``: the input's, except that filled samples (REJECTED, MISSING,
  EXTRAPOLATED) become INFERRED and samples without an estimate NOT_TRACKED (an input
  without states gets TRACKED elsewhere as soon as one sample is filled);
* ``metadata["provenance"]``: ``tobitkf_version``, ``method``, ``params`` (the complete
  parameter set used, fitted values included: the same dict as the diagnostics'),
  ``source`` (the input's path and format, when known) and ``input`` (the input's own
  provenance, when it was smoothed before);
* ``metadata["diagnostics"]``::

    clipped_fraction  (J,)  fraction of frames whose measurement was clipped (censored)
                            by the filter's limits (0 for methods without limits)
    censoring         bool  whether the method censors at all (the Tobit filters)
    filled_fraction   (J,)  fraction of frames with a missing (NaN or NOT_TRACKED) or
                            rejected measurement that got an estimate
    method, params          the method name and the complete parameter set used

and whatever the method adds (``robust``: ``rejected``, ``rejected_fraction``,
``bone_lengths``, offline ``noise_fit``, ``guess_error_sd``, ``guess_error_changes``).
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tobitkf.core.version import __version__
from tobitkf.skeleton.sequence import SkeletonSequence

# the built-in methods register themselves when imported
from tobitkf.smoothing import baselines as _baselines  # noqa: F401
from tobitkf.smoothing import kalman_methods as _kalman_methods  # noqa: F401
from tobitkf.smoothing import robust as _robust
from tobitkf.smoothing.arrays import sequence_from_array
from tobitkf.smoothing.body_scale import check_body_scale, unstated_unit_note
from tobitkf.smoothing.keypoints import (
    DEFAULT_MIN_CONFIDENCE,
    check_min_confidence,
    drop_third_axis,
    length_scale,
    method_view,
)
from tobitkf.smoothing.output_states import output_states, sample_states
from tobitkf.smoothing.params import as_bool, check_inferred_factor, check_up_axis
from tobitkf.smoothing.registry import (
    MethodSpec,
    SmoothInput,
    SmoothOutput,
    get_method,
    method_names,
    methods,
    register_method,
    unregister_method,
)
from tobitkf.smoothing.timebase import (
    DEFAULT_INFERRED_NOISE_FACTOR,
    check_time_unit,
    frame_steps,
    frame_times,
)
from tobitkf.smoothing.untangle import check_untangle, untangle_sequences

__all__ = [
    "COMMON_KEYWORDS",
    "DEFAULT_LIVE_METHOD",
    "DEFAULT_METHOD",
    "check_params",
    "get_method",
    "method_defaults",
    "method_names",
    "methods",
    "register_method",
    "run_method",
    "sample_states",
    "smooth",
    "unregister_method",
]

#: the method :func:`smooth` and ``tobitkf smooth`` use when none is named: the most
#: accurate offline method against motion capture (docs/evaluation.md)
DEFAULT_METHOD = "robust"
#: the method :class:`~tobitkf.smoothing.live.LiveSmoother` uses when none is named: the
#: most accurate causal one
DEFAULT_LIVE_METHOD = "robust_online"
#: keywords of :func:`smooth` accepted next to the method's parameters
COMMON_KEYWORDS = (
    "offline",
    "up_axis",
    "inferred_noise_factor",
    "min_confidence",
    "untangle",
    "step_guard",
)


def method_defaults(method: str) -> dict[str, Any]:
    """Default parameters of ``method`` (a copy)."""
    return dict(get_method(method).defaults)


def check_params(method: str, params: Mapping[str, Any]) -> dict[str, Any]:
    """Validate ``params`` for ``method`` and return the complete parameter set.

    Unknown names raise ``ValueError`` listing the valid ones; bad values raise
    ``ValueError`` naming the parameter. The keywords of :func:`smooth` itself
    (``offline``, ``up_axis``, ``inferred_noise_factor``) are accepted and checked too,
    but not returned.
    """
    spec = get_method(method)
    full = spec.validate(params, also_valid=COMMON_KEYWORDS)
    if "offline" in params:
        _check_offline(spec, as_bool("offline", params["offline"]))
    if params.get("up_axis") is not None:
        check_up_axis(params["up_axis"])
    if "inferred_noise_factor" in params:
        check_inferred_factor(params["inferred_noise_factor"])
    if "min_confidence" in params:
        check_min_confidence(params["min_confidence"])
    if "untangle" in params:
        check_untangle(params["untangle"])
    return full


def _refuse_other_containers(sequence: Any) -> None:
    """A ``TypeError`` that names the way in for the containers people pass by habit."""
    module = type(sequence).__module__.split(".")[0]
    if module == "pandas":
        raise TypeError(
            f"smooth takes a SkeletonSequence or a NumPy array, not a pandas "
            f"{type(sequence).__name__}: convert it with tobitkf.from_dataframe(df)"
        )
    if module == "xarray":
        raise TypeError(
            f"smooth takes a SkeletonSequence or a NumPy array, not an xarray "
            f"{type(sequence).__name__}: convert a movement dataset with "
            "tobitkf.from_movement(ds)"
        )
    if (
        isinstance(sequence, (list, tuple))
        and sequence
        and not any(isinstance(s, SkeletonSequence) for s in sequence)
    ):
        raise TypeError(
            f"smooth takes a SkeletonSequence, a list of them or a NumPy array, got a "
            f"{type(sequence).__name__} of {type(sequence[0]).__name__}: for keypoint "
            "coordinates pass np.asarray(...) of shape (T, J, D)"
        )


def _check_offline(spec: MethodSpec, offline: bool) -> None:
    if offline and not spec.offline_ok:
        # silently ignoring it would label a causal or non-causal output wrongly
        raise ValueError(
            f"offline=True adds an RTS pass, which method {spec.name!r} does not have; "
            f"methods with one: {', '.join(n for n, s in methods().items() if s.offline_ok)}"
            + {
                "robust": " ('robust' is offline already)",
                "robust_online": " ('robust' is the offline robust smoother)",
            }.get(spec.name, "")
        )


def run_method(spec: MethodSpec, inp: SmoothInput, params: Mapping[str, Any]) -> SmoothOutput:
    """Call a method's runner and check what it returns (a user's method may be wrong)."""
    # a body a thousand times too large is not in metres (unless the gates are measured
    # on the recording, whatever its unit); 1e-150 is in no unit
    measured = _robust.gates_measured(params)
    physical = inp.units == "m" and not measured
    radius = check_body_scale(inp.ys, metres=physical)
    # a 3-D array states no unit: a person's size tells which one it likely is
    note = None if measured else unstated_unit_note(radius, inp.units, inp.n_dims)
    if note is not None:
        warnings.warn(note, UserWarning, stacklevel=4)  # the caller of smooth
    if spec.check_data is not None:
        spec.check_data(params, inp.n_dims, inp.units)
    out = spec.run(inp, **params)
    if not isinstance(out, SmoothOutput):
        out = SmoothOutput(np.asarray(out, dtype=float))
    pos = np.asarray(out.positions, dtype=float)
    if pos.shape != inp.ys.shape:
        raise ValueError(
            f"method {spec.name!r} returned positions of shape {pos.shape}; "
            f"expected {inp.ys.shape} (frames, bodies, joints, 3)"
        )
    if out.diagnostics is not None and len(out.diagnostics) != inp.ys.shape[1]:
        raise ValueError(f"method {spec.name!r} returned diagnostics for a different body count")
    if out.std is not None and np.shape(out.std) != inp.missing.shape:
        raise ValueError(
            f"method {spec.name!r} returned std of shape {np.shape(out.std)}; expected "
            f"{inp.missing.shape} (frames, bodies, joints)"
        )
    return out


def guard_steps(result: SmoothOutput, inp: SmoothInput, causal: bool) -> SmoothOutput:
    """``result`` with no output step of a joint larger than the largest step its input
    made between two present samples, where the input is present at both frames (the
    step guard, :mod:`tobitkf.smoothing._step_guard`; ``causal``: the largest so far,
    else the whole recording's); the shift is added to the variance of ``std``."""
    from tobitkf.smoothing import _step_guard as g

    est = np.array(result.positions, dtype=float)  # a copy: the method's array is its own
    _, B, J, D = inp.ys.shape
    state = g.new_state(B, J, D)
    if not causal:
        g.largest_steps(inp.ys, np.ascontiguousarray(inp.missing), state[1])
    std = g.guard_output(inp.ys, inp.missing, est, result.std, state)
    return dataclasses.replace(result, positions=est, std=std)


def _provenance(spec: MethodSpec, params: dict[str, Any], meta: Mapping[str, Any]) -> dict:
    source = {k: meta[k] for k in ("source", "format") if meta.get(k) is not None}
    prov: dict[str, Any] = {
        "tobitkf_version": __version__,
        "method": spec.name,
        "params": dict(params),
        "source": {"path" if k == "source" else k: v for k, v in source.items()} or None,
    }
    if isinstance(meta.get("provenance"), Mapping):
        prov["input"] = dict(meta["provenance"])  # smoothed before: keep the chain
    return prov


def smooth(
    sequence: SkeletonSequence | Sequence[SkeletonSequence] | np.ndarray,
    method: str = DEFAULT_METHOD,
    *,
    offline: bool = False,
    up_axis: int | None = None,
    inferred_noise_factor: float = DEFAULT_INFERRED_NOISE_FACTOR,
    min_confidence: float = DEFAULT_MIN_CONFIDENCE,
    untangle: Any = "auto",
    fps: float | None = None,
    confidence: Any = None,
    units: str | None = None,
    topology: Any = None,
    timestamps: Any = None,
    step_guard: bool = False,
    **params: Any,
) -> Any:
    """Smooth every joint of a skeleton sequence (or a list of them, one per body), or
    the keypoint tracks of a NumPy array.

    Any sequence: 2-D or 3-D, in any ``units``, with or without ``confidence``
    (:mod:`tobitkf.smoothing.keypoints`: lengths are converted to metres for the method
    and back; pixels and unknown units make the robust methods take their gates from the
    recording, docs/robust.md).

    Parameters
    ----------
    sequence : SkeletonSequence, list of SkeletonSequence, or ndarray
        A list is smoothed body by body and a list is returned; bodies with the same
        number of frames, time base and topology go to the method together, stacked on
        a body axis. An array ``(T, J, D)`` (frames, keypoints, coordinates, D = 2 or 3)
        or ``(T, D)`` (one point), NaN where missing, gives an array of the same shape,
        like :func:`scipy.signal.savgol_filter`; ``fps``, ``timestamps``, ``confidence``,
        ``units`` and ``topology`` describe it
        (:func:`tobitkf.smoothing.arrays.sequence_from_array`: by default 30 fps, no
        confidence, unknown units, keypoints without bones) and are refused for
        sequences, which carry their own.
    method : str
        A registered method (``tobitkf methods``; default :data:`DEFAULT_METHOD`,
        ``"robust"``).
    offline : bool
        Run the RTS smoother after the filter (uses future frames); only for methods
        registered with ``offline_ok`` (the Kalman-type ones), ``ValueError`` otherwise.
    up_axis : int, optional
        Vertical axis (0, 1, 2); default: ``sequence.topology.up_axis``.
    inferred_noise_factor : float
        Measurement-variance multiplier (>= 1) for INFERRED joints.
    min_confidence : float
        Samples whose ``confidence`` is below this are missing (default
        :data:`~tobitkf.smoothing.keypoints.DEFAULT_MIN_CONFIDENCE`, 0.1); no effect on
        sequences without confidence.
    untangle : ``"auto"`` (default), True or False
        Undo identity swaps between the bodies of a list and left/right swaps within a
        body before smoothing (:mod:`tobitkf.smoothing.untangle`); ``"auto"``: for
        sequences in pixels or unknown units (pose-estimator output), not for tracks in
        metres. With ``gates="stream"`` the untangling is causal too, as live
        (:class:`~tobitkf.smoothing.untangle.StreamUntangler`).
    step_guard : bool
        Hold every output step of a joint to the largest step its input made between two
        present samples (:mod:`tobitkf.smoothing._step_guard`: a causal method the
        largest so far, any other the whole recording's), where the input is present at
        both frames; the shift is added to the standard deviation. The robust methods
        always do this; the paper's filters and the other published ones give their own
        output unless this is True (docs/robust.md, "No new jumps").
    **params
        Method parameters; :func:`method_defaults` lists them.

    Returns
    -------
    SkeletonSequence or list of SkeletonSequence
        Same metadata, positions replaced, ``metadata["diagnostics"]`` added (see module
        docstring).
    """
    spec = get_method(method)
    full = check_params(method, params)
    if up_axis is not None:
        up_axis = check_up_axis(up_axis)
    factor = check_inferred_factor(inferred_noise_factor)
    min_conf = check_min_confidence(min_confidence)
    untangle = check_untangle(untangle)
    offline = as_bool("offline", offline)
    _check_offline(spec, offline)
    guard = as_bool("step_guard", step_guard)
    opts = (offline, up_axis, factor, min_conf, untangle, guard)
    from tobitkf.smoothing.robust_scale import given_names

    given_params = given_names(params)  # a value per region: those regions only
    described = {"fps": fps, "confidence": confidence, "units": units, "topology": topology,
                 "timestamps": timestamps}  # fmt: skip
    if isinstance(sequence, np.ndarray):
        seq, single = sequence_from_array(sequence, **described)
        est = _smooth_group([seq], spec, full, *opts, given=given_params)[0].positions
        return est[:, 0] if single else est
    _refuse_other_containers(sequence)
    given = [k for k, v in described.items() if v is not None]
    if given:
        raise TypeError(
            f"{', '.join(given)}: only for an array; a SkeletonSequence carries its own "
            "(use sequence.replace(...) to change them)"
        )
    if isinstance(sequence, SkeletonSequence):
        _per_body(spec, full, 1)
        return _smooth_group([sequence], spec, full, *opts, given=given_params)[0]
    if isinstance(sequence, (str, bytes)) or not isinstance(sequence, Sequence):
        raise TypeError(
            "smooth expects a SkeletonSequence, a list of them or a NumPy array, got "
            f"{type(sequence).__name__}"
        )
    seqs = list(sequence)
    for i, s in enumerate(seqs):
        if not isinstance(s, SkeletonSequence):
            raise TypeError(
                f"smooth expects a SkeletonSequence, a list of them or a NumPy array; item "
                f"{i} is {type(s).__name__}"
            )
    out: list[Any] = [None] * len(seqs)
    groups: dict[Any, list[int]] = {}
    for i, s in enumerate(seqs):
        key = (
            s.n_frames,
            s.topology,
            s.fps,
            None if s.timestamps is None else s.timestamps.tobytes(),
            s.tracking_state is None,
            s.confidence is None,
            s.n_dims,
            s.units,
        )
        groups.setdefault(key, []).append(i)
    per_body = _per_body(spec, full, len(seqs))  # each group runs with its bodies' own
    for idx in groups.values():
        mine = {n: tuple(full[n][i] for i in idx) for n in per_body}
        res = _smooth_group(
            [seqs[i] for i in idx], spec, {**full, **mine}, *opts, given=given_params
        )
        for i, r in zip(idx, res, strict=True):
            out[i] = r
    return out


def _per_body(spec: MethodSpec, params: Mapping[str, Any], n: int) -> list[str]:
    """The parameters given one value per body (``spec.per_body``, a tuple), checked to
    give ``n``, one for each body of the call."""
    names = [k for k in spec.per_body if isinstance(params.get(k), tuple)]
    for k in names:
        if len(params[k]) != n:
            raise ValueError(f"{k}: {len(params[k])} given for {n} bod{'y' if n == 1 else 'ies'}"
                             " (one per body)")  # fmt: skip
    return names


def _read_only(a: np.ndarray) -> np.ndarray:
    view = a.view()
    view.flags.writeable = False
    return view


def _smooth_group(
    seqs: list[SkeletonSequence],
    spec: MethodSpec,
    params: dict[str, Any],
    offline: bool,
    up_axis: int | None,
    factor: float,
    min_conf: float = DEFAULT_MIN_CONFIDENCE,
    untangle: Any = "auto",
    step_guard: bool = False,
    given: frozenset[str] = frozenset(),
) -> list[SkeletonSequence]:
    """Smooth bodies sharing frames, topology, time base, dimension and units, stacked
    on a body axis (``given``: the parameters the caller gave, :class:`SmoothInput`)."""
    untangled = None
    if untangle is True or (untangle == "auto" and length_scale(seqs[0].units) is None):
        # gates measured on the frames so far: the untangling is causal too (what a live
        # stream of the recording gives)
        seqs, untangled = untangle_sequences(seqs, stream=params.get("gates") == "stream")
    ref = seqs[0]
    steps, nominal, is_reference = frame_steps(ref)
    if ref.timestamps is not None:
        check_time_unit(nominal, ref.fps)
    # (T, B, J, D); one body is a view, not a copy
    positions = (
        seqs[0].positions[:, None]
        if len(seqs) == 1
        else np.stack([s.positions for s in seqs], axis=1)
    )
    n_dims = positions.shape[-1]
    states = None
    if ref.tracking_state is not None:
        states = np.stack([s.tracking_state for s in seqs], axis=1)
    confidence = None
    if ref.confidence is not None:
        confidence = np.stack([s.confidence for s in seqs], axis=1)
    # scale: metres per unit; None: pixels / unknown
    scale, positions, ys, missing = method_view(
        positions, ref.units, states, confidence, min_conf, owned=len(seqs) > 1
    )
    positions, ys = _read_only(positions), _read_only(ys)  # a method must not write into them
    inp = SmoothInput(
        positions=positions,
        ys=ys,
        missing=missing,
        tracking_state=states,
        steps=steps,
        times=frame_times(ref, steps),
        is_reference=is_reference,
        topology=ref.topology,
        up_axis=ref.topology.up_axis if up_axis is None else up_axis,
        inferred_noise_factor=factor,
        offline=offline,
        confidence=confidence,
        units="m" if scale is not None else ref.units,
        n_dims=n_dims,
        given=given,
    )
    if ref.n_frames == 0:
        result = SmoothOutput(positions.copy())
    else:
        result = run_method(spec, inp, params)
        if step_guard:
            result = guard_steps(result, inp, causal=spec.is_causal(params) and not offline)
    returned = np.asarray(result.positions, dtype=float)
    est = drop_third_axis(returned, n_dims)
    if scale is not None and scale != 1.0:
        if np.may_share_memory(est, returned):  # the method's array: not ours to change
            est = est / scale
        else:  # a copy made here (2-D): converted in place
            est /= scale
    std = None
    if result.std is not None:
        std = np.asarray(result.std, dtype=float)
        if scale is not None and scale != 1.0:
            std = std / scale
    clipped = None if result.clipped is None else np.asarray(result.clipped, dtype=bool)
    extra = result.diagnostics or ({},) * len(seqs)
    causal = spec.is_causal(params) and not offline
    T = max(ref.n_frames, 1)
    used = {
        **params,
        **(result.params or {}),
        "offline": offline or not spec.is_causal(params),  # the output used later frames
        "inferred_noise_factor": factor,
        "up_axis": inp.up_axis,
    }
    if confidence is not None:
        used["min_confidence"] = min_conf
    if untangled is not None:
        used["untangle"] = True
    if step_guard:
        used["step_guard"] = True
    body_shape = (missing.shape[0], missing.shape[2])  # (T, J)
    rejected = np.stack(
        [
            np.broadcast_to(np.asarray(e.get("rejected", False), dtype=bool), body_shape)
            for e in extra
        ],
        axis=1,
    )
    # (T, B, J) at once; checked once for the batch: when a body would fail the sequence's
    # checks, every body goes through replace(), which raises the sequence's own error
    states_out = output_states(est, std, missing, rejected, states, causal)
    make = SkeletonSequence._replace_valid if states_out.valid else SkeletonSequence.replace
    out = []
    for b, s in enumerate(seqs):
        used_b = {**used, **(result.body_params[b] if result.body_params else {})}
        diagnostics = {
            **extra[b],
            "clipped_fraction": (
                np.zeros(missing.shape[-1]) if clipped is None else clipped[:, b].sum(axis=0) / T
            ),
            "censoring": clipped is not None,  # the method clips at limits (Tobit filters)
            "filled_fraction": states_out.filled[b] / T,
            "method": spec.name,
            "params": used_b,
            **({} if untangled is None else untangled[b]),
        }
        meta = dict(s.metadata)
        meta["diagnostics"] = diagnostics
        meta["provenance"] = _provenance(spec, used_b, s.metadata)
        if s.fps is None and s.timestamps is None:  # the rate the parameters in /s assumed
            meta["provenance"]["assumed_fps"] = 1.0 / float(inp.steps[0])
        out.append(
            make(
                s,
                positions=est[:, b],
                metadata=meta,
                std=None if states_out.std is None else states_out.std[:, b],
                sample_state=states_out.sample[:, b],
                tracking_state=states_out.tracking_state(b),
                confidence=None if s.confidence is None else s.confidence.copy(),
            )
        )
    return out
