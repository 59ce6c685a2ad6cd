"""The robust smoother's noise, fitted to each recording by maximum likelihood.

The model is the smoother's own (:mod:`tobitkf.smoothing.robust`): per axis of each
joint an integrated Ornstein–Uhlenbeck velocity (``speed_sd``, ``tau``), measured with
white noise (``noise_sd``) plus a *coloured* error (``error_sd``, correlation time
``error_tau``), an OU process of its own (the kernels and the exact likelihood are in
:mod:`tobitkf.smoothing._noise_kernels`). Why the coloured part: on real recordings the
error of a tracker against motion capture is not white; a white-noise model attributes
its slow part to motion (too much process noise, too little smoothing) or, fitted by
hand, removes real motion with it. With ``error_sd = 0`` the model is exactly the fixed
smoother's.

Per recording (body) and per body region (hands, arms, torso, legs: the joints of a
region share one parameter set), :func:`fit_group` maximises the likelihood of the
samples the gates accepted (TRACKED ones; INFERRED, rejected, carried and missing
samples are left out). The total measurement variance ``m² = noise_sd² + error_sd²``
scales every variance of the model, so its maximum is in closed form; the optimiser
searches ``log(speed_sd / m)``, ``logit(error_sd² / m²)`` and ``log error_tau``, from the
physical defaults, within bounds that follow from the physics:

- ``speed_sd`` in ``[default / 100, v_max]``: the rms speed cannot exceed the region's
  largest speed; a still joint may be much slower than the default;
- ``m`` in ``[default noise_sd / 100, 10 √2 default noise_sd]``;
- ``error_tau`` in ``[one frame, tau]``: an error that stays correlated for longer than
  the body's velocity does is indistinguishable from posture (it would be removed from
  real slow motion), so it is left to the motion model.

``tau`` stays the given constant (the smoother's time scale of motion). The fit uses at
most ``fit_seconds`` of each recording (evenly spaced two-second blocks, each track
restarting at a block: ``inf`` = all of it), so its cost per recording is bounded. The
split of ``m²`` into a white and a coloured part is weakly identified when ``error_tau``
nears ``tau`` (the likelihood is flat along it; so is the smoother's output), the speed
and the total well (tests/test_robust_fit.py).

**A floor for the standard deviation** (:func:`sd_floor`). The samples' white noise can
also be read without any motion model, from their second differences (``1.4826 ·
median |Δ²y| / √6``, the statistic the gates in pixels use). Where a region's fitted
measurement error ``m`` is below it, the model has explained part of the noise as
motion (a fast joint at a low frame rate: feet in running), the smoother follows that
noise, and a standard deviation derived from ``m`` is too small; the region's
posterior variance is then scaled by ``(floor / m)²``. The estimate is unchanged.

The optimiser is L-BFGS-B's algorithm compiled together with the objective
(:func:`tobitkf.smoothing._minimize.minimize_profile`): one compiled call per region.
:func:`scipy.optimize.minimize` (L-BFGS-B), the optimiser before, added its own Python
work to each of its some 20 iterations per region, and importing it cost the command
line a noticeable part of its start-up. The stopping rule is scipy's (``ftol`` =
:data:`FIT_FTOL`, projected gradient 1e-5) with one more condition (the quasi-Newton
model sees no larger decrease ahead), so that in the flat valleys of this likelihood it
stops closer to the maximum than scipy's did, for 15–20 % more evaluations of the
objective (tests/test_robust_fit.py).

**A fit given** (:func:`check_given_noise`, :func:`given_noise_bodies`): ``noise`` may
also be a fit made before, in the form of ``metadata["diagnostics"]["noise_fit"]`` (per
region ``speed_sd``, ``noise_sd``, ``error_sd``, ``error_tau`` and ``fitted``; other
keys are ignored). The smoother then uses it as the fit would have been used, with no
optimisation: a region marked not fitted keeps the constants, and the floor of the
standard deviation is measured on the samples at hand. A live smoother that re-runs
``robust`` on a sliding window (:class:`~tobitkf.smoothing.delayed.DelayedSmoother`)
holds one fit for a while this way, and a recording can be smoothed with the noise
fitted on a longer one of the same sensor.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.smoothing.timebase import typical_step

__all__ = [
    "FIT_BLOCK_SECONDS",
    "GroupFit",
    "check_given_noise",
    "fit_blocks",
    "fit_group",
    "fit_noise_bodies",
    "given_noise_bodies",
    "sd_floor",
]

Array = NDArray[np.float64]

#: length of the blocks the fit samples from a long recording, s
FIT_BLOCK_SECONDS = 2.0
#: a region with fewer fitted joint-frames keeps its default noise
MIN_FIT_SAMPLES = 60
#: bounds relative to the defaults (module docstring)
SPEED_LOWER, NOISE_LOWER, NOISE_UPPER = 0.01, 0.01, 10.0
#: the share of the coloured error in the measurement variance stays in (0, 1)
LOGIT_MAX = 12.0
#: relative tolerance of the optimiser on the mean negative log-likelihood per sample
FIT_FTOL = 1e-6
#: iterations of the optimiser at most (it converges in about 20)
FIT_MAXITER = 200


def kernels() -> Any:
    """The compiled noise kernels (imports numba on first use)."""
    from tobitkf.smoothing import _noise_kernels

    return _noise_kernels


@dataclass(frozen=True)
class GroupFit:
    """Fitted noise of one body region of one recording (SI units: m, m/s, s).

    ``fitted`` is False when the region had fewer than ``MIN_FIT_SAMPLES`` usable
    joint-frames (the defaults are kept, ``error_sd = 0``); ``at_bound`` names the
    parameters that ended on a bound; ``n`` counts scalar samples (three per joint-frame).
    """

    speed_sd: float
    noise_sd: float
    error_sd: float
    error_tau: float
    loglik: float
    n: int
    fitted: bool
    at_bound: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        # written out: dataclasses.asdict deep-copies, 10 % of a batch's fitting time
        return {"speed_sd": self.speed_sd, "noise_sd": self.noise_sd,
                "error_sd": self.error_sd, "error_tau": self.error_tau,
                "loglik": self.loglik, "n": self.n, "fitted": self.fitted,
                "at_bound": list(self.at_bound)}  # fmt: skip


def fit_blocks(steps: Array, max_seconds: float) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """Frames the fit runs over and where the tracks restart: all frames when the
    recording lasts at most ``max_seconds``, else evenly spaced blocks of
    :data:`FIT_BLOCK_SECONDS` adding up to at most ``max_seconds`` (at least one)."""
    T = steps.shape[0]
    total = float(np.sum(steps[1:])) if T > 1 else 0.0
    dt = typical_step(steps) if T > 1 else 1.0
    blen = max(2, round(FIT_BLOCK_SECONDS / dt))
    # a recording with pauses may last longer than max_seconds on fewer frames than one
    # block: all of them (a block would start before the first frame)
    if not math.isfinite(max_seconds) or total <= max_seconds or T < blen:
        frames = np.arange(T, dtype=np.int64)
        restart = np.zeros(T, dtype=bool)
        return frames, restart
    # at most max_seconds, and no more blocks than the frames hold without overlapping
    nblocks = max(1, min(math.floor(max_seconds / (blen * dt)), T // blen))
    starts = np.unique(np.linspace(0, T - blen, nblocks).round().astype(np.int64))
    frames = (starts[:, None] + np.arange(blen)[None]).ravel()
    restart = np.zeros(frames.size, dtype=bool)
    restart[::blen] = True
    keep = np.concatenate([[True], np.diff(frames) > 0])  # overlapping blocks: once
    return np.ascontiguousarray(frames[keep]), np.ascontiguousarray(restart[keep])


#: the values of one region of a fit given (the rest of a report is ignored)
NOISE_KEYS = ("speed_sd", "noise_sd", "error_sd", "error_tau")


def _given_number(where: str, value: Any, positive: bool) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if isinstance(value, bool) or not math.isfinite(v) or v < 0 or (positive and v == 0):
        kind = "a positive finite number" if positive else "a finite number >= 0"
        raise ValueError(f"{where} must be {kind}, got {value!r}")
    return v


def check_given_noise(name: str, value: Any) -> dict[str, dict[str, Any]]:
    """A noise fit given for ``noise``: ``{region: {speed_sd, noise_sd, error_sd,
    error_tau, fitted}}`` for some of the body regions (hands, arms, torso, legs; the
    form of ``metadata["diagnostics"]["noise_fit"]``, whose other keys are ignored).

    A region with ``fitted`` false keeps the constants (its values are not read, as the
    fit's report of a region with too few samples has none that count). Otherwise
    ``speed_sd`` and ``error_tau`` must be positive, ``noise_sd`` and ``error_sd`` at
    least 0 and not both 0; ``units``, when given, is what the fit was made in (``"m"``,
    ``"px"`` or None; robust refuses the fit for data in other units). Returns plain
    floats and bools (JSON for the provenance)."""
    from tobitkf.skeleton.topology import GROUP_NAMES

    if not isinstance(value, Mapping) or not value:
        raise ValueError(
            f"{name} must be 'fit', 'fixed' or a noise fit given per body region "
            f"(metadata['diagnostics']['noise_fit']), got {value!r}"
        )
    unknown = sorted(map(str, set(value) - set(GROUP_NAMES)))
    if unknown:
        raise ValueError(f"{name}: unknown body regions {unknown}; the regions are {GROUP_NAMES}")
    out: dict[str, dict[str, Any]] = {}
    for g, region in value.items():
        where = f"{name}[{g!r}]"
        if not isinstance(region, Mapping):
            raise ValueError(f"{where} must be a mapping of {NOISE_KEYS}, got {region!r}")
        fitted = region.get("fitted", True)
        if not isinstance(fitted, (bool, np.bool_)):
            raise ValueError(f"{where}['fitted'] must be true or false, got {fitted!r}")
        if not fitted:
            out[g] = {"fitted": False}
            continue
        missing = [key for key in NOISE_KEYS if key not in region]
        if missing:
            raise ValueError(f"{where} lacks {missing}: give {NOISE_KEYS}")
        positive = ("speed_sd", "error_tau")
        vals = {k: _given_number(f"{where}[{k!r}]", region[k], k in positive) for k in NOISE_KEYS}
        if vals["noise_sd"] == 0 and vals["error_sd"] == 0:
            raise ValueError(f"{where}: noise_sd and error_sd are both 0 (no measurement noise)")
        out[g] = {**vals, "fitted": True}
        if "units" in region:  # what the fit was made in (robust's check_data compares)
            units = region["units"]
            if units not in ("m", "px", None):  # a fit of any lengths is in metres
                raise ValueError(f"{where}['units'] must be 'm' (any length: the fit is "
                                 f"in metres), 'px' or null, got {units!r}")  # fmt: skip
            out[g]["units"] = units
    return out


def _default_fits(B: int, J: int, speed_sd: Array, noise_sd: Array, tau: float) -> dict[str, Array]:
    """Per-joint arrays ``(B, J)`` of a region left at the constants (no coloured error)."""
    return {
        "speed_sd": np.broadcast_to(speed_sd, (B, J)).copy(),
        "noise_sd": np.broadcast_to(noise_sd, (B, J)).copy(),
        "error_sd": np.zeros((B, J)),
        "error_tau": np.full((B, J), tau if math.isfinite(tau) else 1.0),
    }


def given_noise_bodies(
    given: Mapping[str, Mapping[str, Any]],
    B: int,
    groups: dict[str, list[int]],
    *,
    tau: float,
    speed_sd: Array,
    noise_sd: Array,
) -> tuple[dict[str, Array], list[dict[str, dict[str, Any]]]]:
    """What :func:`fit_noise_bodies` returns, from a fit given (:func:`check_given_noise`)
    for every body: the per-joint arrays ``(B, J)`` and, per body, the region reports
    (the values used, ``given`` true). Every region with joints must be in ``given``."""
    absent = [g for g, idx in groups.items() if idx and g not in given]
    if absent:
        raise ValueError(f"noise: the fit given has no values for the body regions {absent}; "
                         "give every region of the skeleton")  # fmt: skip
    J = sum(len(idx) for idx in groups.values())
    out = _default_fits(B, J, speed_sd, noise_sd, tau)
    report: dict[str, dict[str, Any]] = {}
    for g, idx in groups.items():
        if not idx:
            continue
        region = given[g]
        if region.get("fitted"):
            for key in NOISE_KEYS:
                out[key][:, idx] = region[key]
            report[g] = {key: float(region[key]) for key in NOISE_KEYS}
        else:
            ix = idx[0]
            report[g] = {"speed_sd": float(speed_sd[ix]), "noise_sd": float(noise_sd[ix]),
                         "error_sd": 0.0, "error_tau": math.nan}  # fmt: skip
        report[g].update(fitted=bool(region.get("fitted")), given=True)
    return out, [{g: dict(r) for g, r in report.items()} for _ in range(B)]


def _steps_info(steps: Array, tau: float) -> tuple[float, Array]:
    """The typical step (median) and the OU coefficients of every step of ``steps``."""
    return typical_step(steps), kernels().ou_table(steps, tau)


def fit_group(
    yk: Array,
    rscale: Array,
    steps: Array,
    frames: NDArray[np.int64],
    restart: NDArray[np.bool_],
    *,
    tau: float,
    speed_sd: float,
    noise_sd: float,
    v_max: float,
    steps_info: tuple[float, Array] | None = None,
) -> GroupFit:
    """Maximum-likelihood noise of one group of tracks (module docstring).

    ``yk (T, N, 3)`` the samples (NaN = not used), ``rscale (T, N)`` their variance
    multipliers, ``steps (T,)``; ``speed_sd``, ``noise_sd`` the physical defaults (start
    and bounds), ``v_max`` the upper bound of ``speed_sd``; ``steps_info`` the
    :func:`_steps_info` of ``steps`` when the caller fits many groups on them.
    """
    from tobitkf.smoothing._minimize import minimize_profile

    k = kernels()
    yk = np.ascontiguousarray(yk, dtype=float)
    rscale = np.ascontiguousarray(rscale, dtype=float)
    steps = np.ascontiguousarray(steps, dtype=float)
    used = int(np.isfinite(yk[frames, :, 0]).sum())
    if used < MIN_FIT_SAMPLES:
        return GroupFit(speed_sd, noise_sd, 0.0, math.nan, math.nan, 0, False)
    dt, ou = steps_info if steps_info is not None else _steps_info(steps, tau)
    tau_q = tau if math.isfinite(tau) else 1.0  # q = 2 spd² / tau (spd² for tau = inf)
    hi_tau = tau if math.isfinite(tau) else 10.0  # a coloured error longer than this: posture
    # total measurement error m² = noise_sd² + error_sd²; the likelihood is maximised over
    # m² in closed form (it scales every variance), numerically over
    # theta = (log speed_sd / m, logit error_sd² / m², log error_tau)
    m_lo, m_hi = noise_sd * NOISE_LOWER, noise_sd * NOISE_UPPER * math.sqrt(2)
    s_lo, s_hi = speed_sd * SPEED_LOWER, max(v_max, speed_sd)
    lo = np.array([math.log(s_lo / m_hi), -LOGIT_MAX, math.log(min(dt, hi_tau))])
    hi = np.array([math.log(s_hi / m_lo), LOGIT_MAX, math.log(hi_tau)])
    m0 = noise_sd * math.sqrt(2)
    x0 = np.clip([math.log(speed_sd / m0), 0.0, math.log(math.sqrt(dt * hi_tau))], lo, hi)

    args = (yk, rscale, steps, ou, frames, restart, tau, tau_q)
    x, _, _, _ = minimize_profile(x0, lo, hi, *args, FIT_FTOL, FIT_MAXITER)
    th = np.clip(x, lo, hi)
    se, _, n = k.profile_sums(th, *args)
    ratio, phi = math.exp(th[0]), 1 / (1 + math.exp(-th[1]))
    m = math.sqrt(se / n)
    edge = [nm for nm, v, a, b in zip(("speed_sd", "error_sd", "error_tau"), th, lo, hi,
                                      strict=True) if v <= a + 1e-6 or v >= b - 1e-6]  # fmt: skip
    if not m_lo <= m <= m_hi:
        m = min(max(m, m_lo), m_hi)
        edge.append("noise_sd")
    spd = ratio * m
    if not s_lo <= spd <= s_hi:
        spd = min(max(spd, s_lo), s_hi)
        edge.append("speed_sd")
    sd, esd, etau = m * math.sqrt(1 - phi), m * math.sqrt(phi), math.exp(th[2])
    ll, n = k.loglik(yk, rscale, steps, frames, restart, 2 * spd**2 / tau_q, sd**2, esd**2,
                     tau, etau)  # fmt: skip
    return GroupFit(spd, sd, esd, etau, float(ll), int(n), True, tuple(sorted(set(edge))))


def fit_noise_bodies(
    yk: Array,
    use: NDArray[np.bool_],
    rscale: Array,
    steps: Array,
    groups: dict[str, list[int]],
    *,
    tau: float,
    speed_sd: Array,
    noise_sd: Array,
    v_max: Array,
    max_seconds: float,
) -> tuple[dict[str, Array], list[dict[str, dict[str, Any]]]]:
    """Fit every region of every body: ``yk (T, B, J, 3)``, ``use (T, B, J)`` the samples
    to fit on, ``rscale (T, B, J)``; ``speed_sd``, ``noise_sd``, ``v_max`` the per-joint
    defaults ``(J,)``.

    Returns per-joint arrays ``(B, J)`` (``speed_sd``, ``noise_sd``, ``error_sd``,
    ``error_tau``) and, per body, the region fits as dicts.
    """
    B, J = use.shape[1:]
    frames, restart = fit_blocks(steps, max_seconds)
    # only the fitted frames: the step before each stays its own
    yk, use, rscale, steps = yk[frames], use[frames], rscale[frames], steps[frames]
    frames = np.arange(frames.size, dtype=np.int64)
    out = _default_fits(B, J, speed_sd, noise_sd, tau)
    reports: list[dict[str, dict[str, Any]]] = []
    _fit_all(yk, use, rscale, steps, groups, tau, speed_sd, noise_sd, v_max, frames, restart,
             out, reports)  # fmt: skip
    return out, reports


def _fit_all(yk: Array, use: NDArray[np.bool_], rscale: Array, steps: Array,
             groups: dict[str, list[int]], tau: float, speed_sd: Array, noise_sd: Array,
             v_max: Array, frames: NDArray[np.int64], restart: NDArray[np.bool_],
             out: dict[str, Array], reports: list[dict[str, dict[str, Any]]]) -> None:  # fmt: skip
    B = use.shape[1]
    info = _steps_info(np.ascontiguousarray(steps, dtype=float), tau)  # once for all groups
    for b in range(B):
        rep: dict[str, dict[str, Any]] = {}
        for g, idx in groups.items():
            if not idx:
                continue
            ix = np.asarray(idx)
            y = np.where(use[:, b, ix, None], yk[:, b, ix], np.nan)
            fit = fit_group(
                y, rscale[:, b, ix], steps, frames, restart, tau=tau,
                speed_sd=float(speed_sd[ix[0]]), noise_sd=float(noise_sd[ix[0]]),
                v_max=float(v_max[ix[0]]), steps_info=info,
            )  # fmt: skip
            rep[g] = fit.to_dict()
            if fit.fitted:
                out["speed_sd"][b, ix] = fit.speed_sd
                out["noise_sd"][b, ix] = fit.noise_sd
                out["error_sd"][b, ix] = fit.error_sd
                out["error_tau"][b, ix] = fit.error_tau
        reports.append(rep)


def sd_floor(
    ys: Array,
    use: NDArray[np.bool_],
    groups: dict[str, list[int]],
    fits: dict[str, Array],
    reports: list[dict[str, dict[str, Any]]],
    n_dims: int,
) -> Array:
    """The variance scale ``(B, J)`` (>= 1) of the floor for the standard deviation
    (module docstring): per body and fitted region, ``(floor / m)²`` where the second
    differences' noise ``floor`` of the samples marked in ``use`` (``(T, B, J)``; at
    least :data:`MIN_FIT_SAMPLES` differences) exceeds the fitted ``m``, else 1. Adds
    ``noise_floor`` and ``sd_scale`` to each region's report."""
    from tobitkf.smoothing.robust_scale import second_difference_noise

    B, J = use.shape[1:]
    scale = np.ones((B, J))
    m = np.sqrt(fits["noise_sd"] ** 2 + fits["error_sd"] ** 2)
    for b in range(B):
        for g, idx in groups.items():
            report = reports[b].get(g)
            if not idx or report is None or not report.get("fitted"):
                continue
            ix = np.asarray(idx)
            y = np.where(use[:, b, ix, None], ys[:, b, ix, :n_dims], np.nan)
            floor, n = second_difference_noise(y)
            if n < MIN_FIT_SAMPLES:
                continue
            ratio = max(1.0, floor / float(np.max(m[b, ix])))
            scale[b, ix] = ratio**2
            report["noise_floor"], report["sd_scale"] = floor, ratio
    return scale
