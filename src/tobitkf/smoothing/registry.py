"""The method registry: what a smoothing method is, and how one is added.

A method is a function that receives the bodies of a recording stacked time first
(:class:`SmoothInput`) and returns smoothed positions of the same shape (an array, or a
:class:`SmoothOutput` with diagnostics). It registers itself, in the module that defines
it, with :func:`register_method`; :func:`tobitkf.smooth`, :class:`tobitkf.LiveSmoother`,
the command line (``--method`` choices, ``tobitkf methods``), the evaluation defaults
and the docs all read this registry and keep no list of their own.

Example: a user method, no change to the package (docs/architecture.md)::

    import numpy as np
    import tobitkf as tk

    @tk.register_method("ewma", params={"alpha": 0.5}, causal=True,
                        description="exponentially weighted moving average")
    def ewma(inp, alpha):
        out = inp.ys.copy()                       # (T, B, J, 3), NaN = missing
        for t in range(1, out.shape[0]):
            prev = out[t - 1]
            out[t] = np.where(np.isnan(out[t]), prev, alpha * out[t] + (1 - alpha) * prev)
        return out

    tk.smooth(seq, method="ewma", alpha=0.3)
    tk.LiveSmoother("kinect_v2", method="ewma").update(frame)
"""

from __future__ import annotations

import keyword
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from tobitkf.skeleton.topology import Topology
from tobitkf.smoothing.params import Validator, over_default

__all__ = [
    "LiveStepper",
    "MethodSpec",
    "SmoothInput",
    "SmoothOutput",
    "get_method",
    "method_names",
    "methods",
    "register_method",
    "unregister_method",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class SmoothInput:
    """What a method receives: the bodies of one time base, stacked, time first.

    Attributes
    ----------
    positions : (T, B, J, 3) the positions as given (NaN = missing)
    ys : (T, B, J, 3) the measurements: NaN where missing or NOT_TRACKED
    missing : (T, B, J) bool, True where ``ys`` is NaN
    tracking_state : (T, B, J) int8 Kinect states (0 not tracked, 1 inferred, 2 tracked)
        or None
    steps : (T,) seconds before each frame (``steps[0]`` is the nominal step)
    times : (T,) seconds, the time of each frame
    is_reference : every step is 1/30 s (the papers' rate)
    topology : the skeleton (joint names, parents, up axis, body regions)
    up_axis : the vertical axis (0, 1, 2)
    inferred_noise_factor : variance multiplier for INFERRED joints
    offline : an RTS pass was asked for (only methods registered with ``offline_ok``)
    confidence : (T, B, J) a pose estimator's score in [0, 1] of every sample (NaN = none
        for that sample; samples below ``min_confidence`` are missing already), or None
    units : the unit of the positions as the method sees them (``"m"``: lengths are
        converted to metres before a method runs; ``"px"`` or None = unknown)
    n_dims : coordinates of the sequence (2 or 3); a 2-D sequence reaches the method
        with a third axis of zeros (NaN where missing), so ``ys`` is always
        ``(T, B, J, 3)``, and that axis is dropped from the output
    given : the names of the parameters the caller gave (the others are defaults): a
        parameter a method could measure on the recording is the caller's when given
    """

    positions: Array
    ys: Array
    missing: NDArray[np.bool_]
    tracking_state: NDArray[np.int8] | None
    steps: Array
    times: Array
    is_reference: bool
    topology: Topology
    up_axis: int
    inferred_noise_factor: float
    offline: bool = False
    confidence: Array | None = None
    units: str | None = "m"
    n_dims: int = 3
    given: frozenset[str] = frozenset()

    @property
    def n_frames(self) -> int:
        return int(self.ys.shape[0])


@dataclass(frozen=True)
class SmoothOutput:
    """What a method returns when it has more to say than the positions.

    Attributes
    ----------
    positions : (T, B, J, 3)
    clipped : (T, B, J) bool, samples censored by the method's limits, or None
    diagnostics : one dict per body, merged into ``metadata["diagnostics"]``, or None
    params : resolved parameters to record beside the given ones (e.g. ``c`` in the
        sequence's axes), or None
    std : (T, B, J) posterior standard deviation of each position (metres, the
        root-mean-square over the axes of the per-axis standard deviations; NaN where
        there is no estimate), or None when the method gives none
    body_params : one mapping per body of parameters resolved for that body alone (e.g.
        noise fitted to it), recorded over ``params`` for that body, or None
    """

    positions: Array
    clipped: NDArray[np.bool_] | None = None
    diagnostics: tuple[dict[str, Any], ...] | None = None
    params: Mapping[str, Any] | None = None
    std: Array | None = None
    body_params: tuple[Mapping[str, Any], ...] | None = None


class LiveStepper(Protocol):
    """One live stream of a method: ``step`` is called once per frame, in order.

    A stepper that reads the positions as given (not only ``ys``, where NOT_TRACKED
    samples are NaN) sets a class attribute ``uses_positions = True``: ``step`` then
    also receives ``positions=`` (B, J, 3). One that depends on the stream's number of
    coordinates sets ``uses_n_dims = True`` and receives ``n_dims=`` (2 or 3; a 2-D
    stream reaches ``step`` with a third axis of zeros). One that reads the frames'
    times (as batch reads ``SmoothInput.times``) sets ``uses_time = True`` and receives
    ``time=``, the frame's timestamp in seconds (None when the stream gives none).
    After ``step``, a stepper may hold ``std`` ``(B, J)`` (the frame's posterior sd, in
    the method's units) and ``rejected`` ``(B, J)`` (samples judged impossible):
    ``LiveSmoother.std`` and ``.sample_state`` read them."""

    def step(
        self,
        ys: Array,
        missing: NDArray[np.bool_],
        states: NDArray[np.int8] | None,
        dt: float,
    ) -> Array:
        """Smooth one frame: ys (B, J, 3) NaN where missing; returns (B, J, 3)."""
        ...


#: ``live(topology, up_axis, inferred_noise_factor, **params) -> LiveStepper``
LiveFactory = Callable[..., LiveStepper]
Runner = Callable[..., Any]


@dataclass(frozen=True)
class MethodSpec:
    """One registered smoothing method.

    Attributes
    ----------
    name : the name ``smooth(..., method=name)`` takes
    run : ``run(inp: SmoothInput, **params) -> ndarray | SmoothOutput``
    defaults : parameter name -> default value (every parameter the method takes)
    validators : parameter name -> ``check(name, value) -> value``
    description : one line for ``tobitkf methods`` and the docs
    causal : the output at frame k depends on frames up to k only (it can run live); a
        bool, or ``causal(params) -> bool`` when a parameter decides
    offline_ok : ``smooth(..., offline=True)`` runs an RTS pass (``run`` reads
        ``inp.offline``)
    check : ``check(params) -> None``, raises ``ValueError`` for parameter sets that do
        not fit together (e.g. ``polyorder >= window``), or None
    live : factory of a per-frame :class:`LiveStepper` (constant work per frame), or
        None: a causal method without one runs live by re-running on the history
    check_data : ``check_data(params, n_dims, units) -> None``, raises ``ValueError`` for
        data its parameters cannot mean anything for (limits in metres on pixels), or
        None; called before a batch run and at a live stream's first frame, with the
        coordinates (2 or 3) and the units the method sees (``"m"`` for any length)
    per_body : names of parameters that may be given one value per body: a list, which
        the validator turns into a tuple, whose item ``i`` is body ``i``'s (``smooth``
        hands each group of bodies it runs together their own items)
    """

    name: str
    run: Runner
    defaults: Mapping[str, Any]
    validators: Mapping[str, Validator] = field(default_factory=dict)
    description: str = ""
    causal: bool | Callable[[Mapping[str, Any]], bool] = False
    offline_ok: bool = False
    check: Callable[[dict[str, Any]], None] | None = None
    live: LiveFactory | None = None
    check_data: Callable[[Mapping[str, Any], int, str | None], None] | None = None
    per_body: tuple[str, ...] = ()

    def is_causal(self, params: Mapping[str, Any] | None = None) -> bool:
        """Whether the method with ``params`` (default: its defaults) is causal."""
        if callable(self.causal):
            return bool(self.causal({**self.defaults, **(params or {})}))
        return bool(self.causal)

    def validate(
        self, params: Mapping[str, Any], also_valid: tuple[str, ...] = ()
    ) -> dict[str, Any]:
        """The complete parameter set: defaults overridden by ``params``, each validated
        (a mapping given for a mapping default, such as a per-region value, overrides the
        keys it names).

        Unknown names raise ``ValueError`` listing the valid ones (and ``also_valid``,
        names the caller accepts beside the method's own; they are not returned).
        """
        unknown = sorted(set(params) - set(self.defaults) - set(also_valid))
        if unknown:
            more = f" (and {', '.join(also_valid)})" if also_valid else ""
            raise ValueError(
                f"unknown parameter{'s' if len(unknown) > 1 else ''} "
                f"{', '.join(map(repr, unknown))} for method {self.name!r}; valid parameters: "
                f"{', '.join(sorted(self.defaults)) or '(none)'}{more}"
            )
        params = {k: v for k, v in params.items() if k not in also_valid}
        out = dict(self.defaults)
        for name, value in params.items():
            value = over_default(value, self.defaults[name])
            check = self.validators.get(name)
            out[name] = value if check is None else check(name, value)
        if self.check is not None:
            self.check(out)
        return out


_METHODS: dict[str, MethodSpec] = {}


def register_method(
    name: str,
    run: Runner | None = None,
    *,
    params: Mapping[str, Any] | None = None,
    validators: Mapping[str, Validator] | None = None,
    description: str = "",
    causal: bool | Callable[[Mapping[str, Any]], bool] = False,
    offline_ok: bool = False,
    check: Callable[[dict[str, Any]], None] | None = None,
    live: LiveFactory | None = None,
    replace: bool = False,
    check_data: Callable[[Mapping[str, Any], int, str | None], None] | None = None,
    per_body: tuple[str, ...] = (),
) -> Any:
    """Register a smoothing method; usable as a decorator when ``run`` is omitted.

    Parameters
    ----------
    name : str
        A Python identifier (``"kf+rts"``-style names are the evaluation's notation for
        ``offline=True``).
    run : callable
        ``run(inp, **params)`` with ``inp`` a :class:`SmoothInput`; returns the smoothed
        positions ``(T, B, J, 3)`` or a :class:`SmoothOutput`.
    params : mapping
        Every parameter the method takes, with its default.
    validators : mapping, optional
        Parameter name -> ``check(name, value) -> value`` (see
        :mod:`tobitkf.smoothing.params`); a parameter without one is passed as given.
    description, causal, offline_ok, check, live, check_data, per_body :
        As in :class:`MethodSpec`.
    replace : bool
        Replace a method of the same name instead of raising ``ValueError``.

    Returns
    -------
    The :class:`MethodSpec` (or, as a decorator, the function itself).
    """
    if not isinstance(name, str) or not name.isidentifier() or keyword.iskeyword(name):
        raise ValueError(f"method name must be a Python identifier, got {name!r}")
    defaults = dict(params or {})
    checks = dict(validators or {})
    extra = sorted(set(checks) - set(defaults))
    if extra:
        raise ValueError(f"validators for unknown parameters {extra} of method {name!r}")
    unknown = sorted(set(per_body) - set(defaults))
    if unknown:
        raise ValueError(f"per_body names unknown parameters {unknown} of method {name!r}")
    if not (isinstance(causal, bool) or callable(causal)):
        raise TypeError(
            f"causal must be True, False or a function of the parameters, got {causal!r}"
        )
    for flag, value in (("offline_ok", offline_ok), ("replace", replace)):
        if not isinstance(value, bool):
            raise TypeError(f"{flag} must be True or False, got {value!r}")

    def add(fn: Runner) -> MethodSpec:
        if not callable(fn):
            raise TypeError(f"run must be callable, got {type(fn).__name__}")
        if name in _METHODS and not replace:
            raise ValueError(f"method {name!r} is already registered (pass replace=True)")
        spec = MethodSpec(
            name=name,
            run=fn,
            defaults=defaults,
            validators=checks,
            description=description,
            causal=causal,
            offline_ok=offline_ok,
            check=check,
            live=live,
            check_data=check_data,
            per_body=tuple(per_body),
        )
        _METHODS[name] = spec
        return spec

    if run is None:

        def decorator(fn: Runner) -> Runner:
            add(fn)
            return fn

        return decorator
    return add(run)


def unregister_method(name: str) -> None:
    """Remove a registered method (no error when it is not registered)."""
    _METHODS.pop(name, None)


def get_method(name: str) -> MethodSpec:
    """The registered method ``name``; ``ValueError`` listing the valid names otherwise."""
    spec = _METHODS.get(name) if isinstance(name, str) else None
    if spec is None:
        raise ValueError(f"unknown method {name!r}; valid methods: {', '.join(sorted(_METHODS))}")
    return spec


def methods() -> dict[str, MethodSpec]:
    """All registered methods by name (a copy)."""
    return dict(_METHODS)


def method_names(*, causal: bool | None = None) -> list[str]:
    """Sorted names of the registered methods (only the causal ones with ``causal=True``)."""
    return sorted(n for n, s in _METHODS.items() if causal is None or s.is_causal() == causal)
