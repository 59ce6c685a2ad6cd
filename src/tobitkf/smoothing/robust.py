"""Robust skeleton smoothing: reject physically impossible measurements, then smooth.

Kinect-type trackers fail in two ways that a Kalman filter cannot undo by itself:
one-frame spikes, and *sustained* failures in which a limb is reported in a wrong but
stable place for 10–50 frames (KERAAL ELK: the whole right arm off by up to 1 m for 42
frames).  A filter that trusts every measurement follows the failure after a few frames;
the adaptive Tobit limits of the 2020 paper only slow it down, and they also clip
legitimate fast hand motion.  :func:`robust_smooth` instead decides, joint by joint and
frame by frame, whether a measurement is physically possible, treats the impossible
ones as missing, and smooths what is left with a velocity-state Kalman filter (and,
offline, the RTS smoother, which interpolates across rejected stretches).

Gating (per frame, joints from the root outwards)
-------------------------------------------------
A valid measurement ``y_j(t)`` is *accepted* when

1. **speed gate** — it is reachable from the joint's last accepted measurement
   ``y_j(s)``: ``|y_j(t) - y_j(s)| <= v_max_j (t - s) + margin``.  ``v_max`` is a
   physical bound by body region (hands 8, arms 5, torso 3, legs 10 m/s); the gate grows
   with the time since the last accepted sample, so a joint that really moved faster
   than ``v_max`` is re-acquired a frame or two later instead of being lost. A step from
   the previous frame's accepted sample is measured along the path the joint took about
   its parent, which keeps outside the shortest bone the bone gate accepts (a turn
   about the parent goes around, not across), less what the parent moved;
2. **bone gate** — if its parent was accepted in this frame, the bone to the parent has
   its normal length: ``| |y_j - y_parent| - L_j | <= bone_tol_abs + bone_tol_rel L_j``
   with ``L_j`` the recording's median bone length (offline) or the median of the
   lengths seen so far (online; in 3-D, when the length learnt for the bone's mirror
   image disagrees with its own, a bone that keeps the mirror's is accepted too, so a
   limb failing at a stream's start does not teach the gate a wrong length for good;
   before the bone has a length of its own, the mirror's stands in).
   A wrong bone is blamed on the distal joint, unless a joint's bones to two or more
   children with children of their own broke while those children went on as before
   (accepted in the previous frame, not INFERRED, a step inside their speed gate, their
   bone to the joint's last accepted place intact): then the joint is the one
   rejected, at the frame its own step starts the break and while its rejection lasts
   (up to ``max_reject``);
3. **chain** — if the parent was *rejected* in this frame the bone says nothing, and the
   joint is accepted only if it was accepted in the previous frame and did not jump
   (a wrong wrist makes its hand suspect: a hand that jumped together with a rejected
   wrist stays rejected until the wrist comes back).  Not jumping means a step inside
   its own speed gate and, at the frame where the parent's rejection starts, not the
   parent's step: a joint whose bone vector changed by less than its bone tolerance
   while the parent moved by more kept its bone to the parent's impossible place.

A joint rejected for longer than ``max_reject`` (2 s) is re-acquired as soon as it moves
plausibly from frame to frame (no lock-out behind a wrong reference).  Offline, the gate
runs forwards and backwards in time and a measurement is rejected when either pass
rejects it (failures often enter over 1–3 frames that only one direction flags), an
accepted run not longer than ``min_run`` (0.1 s) between two rejections is rejected too, and
the chain rule is applied once more to the combined mask (:func:`enforce_chain`), so a
wrist that failed together with its elbow is not left in place beside a bridged elbow.
Online, after a rejection longer than ``min_run`` a joint is believed again only once its
measurements have passed the gates for longer than ``min_run`` (:func:`confirm_reacquisition`, the
causal form of the same rule), the chain rule is applied forwards in time, and when a
rejection starts the last ``lookback`` (2) accepted frames are dropped from the filter
state (not from the output already emitted).  ``NOT_TRACKED`` joints and NaN are
missing; ``INFERRED`` joints get ``inferred_noise_factor`` times the measurement
variance.

Inferred joints
---------------
A joint the sensor only guessed (Kinect's ``INFERRED``, an occluded hand or foot) drifts
with the whole guessed chain, while the real bone keeps its length. Before the gates, an
inferred joint is put back at its bone's length from its parent, in the direction the
guess gives (:func:`~tobitkf.smoothing.robust_gating.project_inferred`; an inferred
child first moves with its inferred parent's correction). Offline the length is the
recording's median, online the median learnt so far (none yet: left as guessed); 3-D
only, since a bone seen in projection has no one length. ``inferred_bones=False`` turns
this off. The guesses of one occlusion share one error, which averaging does not
remove: its size is estimated from the recording (online from the frames so far) and
added to the standard deviation of the samples that rest on them
(:mod:`tobitkf.smoothing.robust_shared`, ``shared_errors=True``; the estimate is
unchanged).

Carrying
--------
A rejected joint is not left behind in space while the body moves on: it gets a
pseudo-measurement at its parent's position plus its offset from the parent the last
time both were accepted (:func:`carry_with_parent`; offline, a stretch with no earlier
good offset takes the next one), with a standard deviation equal to that bone's length,
since the limb may have rotated about the parent.  Offline each carried sample's variance
is also multiplied by the number of frames in ``tau`` (``carried_count``): consecutive
carried samples share one error, the limb's rotation since, which decorrelates over
``tau``, so a run of them counts as about one sample per ``tau`` against the real samples
at both ends of the bridge.  ``carry=False`` turns this off. The carried samples of a
stretch share one error, the joint's turn about its parent since its offset was seen:
offline, its size at each sample is taken from how far the joint's offset moved over as
many frames in the rest of the recording, and added to the standard deviation of the
samples that rest on them (:mod:`tobitkf.smoothing.robust_shared`); online, from the
frames so far (``shared_frame`` and ``guess_frame`` in the kernels, with two more scalar
filters per joint on the same gains for the weights).

Smoothing
---------
Each axis of each joint is an integrated Ornstein–Uhlenbeck velocity model,
``dv = -v/tau dt + sqrt(q) dW``, ``dx = v dt``, discretised exactly per time step (so
irregular timestamps are exact), with ``q = 2 speed_sd² / tau`` (the stationary velocity
standard deviation is ``speed_sd``, per body region) and measurement noise ``noise_sd``
(per region), ``H = [1, 0]``.  Offline, by default (``noise="fit"``), these noises are
fitted to the recording per body region by maximum likelihood, with a coloured
measurement error beside the white one, and the filter is the three-state one of that
model (:mod:`tobitkf.smoothing.robust_fit`); while a joint is not measured its process
noise is at least the constant's.  Offline the RTS smoother runs after the filter, and
then ``reweight`` (2) times more with Huber's weights on the accepted samples that the
pass before does not explain (:mod:`tobitkf.smoothing.robust_reweight`);
online (constants) the filter output is returned: across a rejected stretch the OU
velocity decays with ``tau`` (0.15 s), so a lost joint is extrapolated by at most about
``v * tau`` and then held. Online, a joint not accepted yet is returned as measured
(its filter starts at its first accepted sample; live, nobody knows whether it ever
will be), and no output step of a joint is larger than the largest step of its input so far
(:mod:`tobitkf.smoothing._step_guard`): after a long rejection the estimate catches up
over a few frames instead of snapping back in one, and the shift is added to its
standard deviation. Offline the same guard holds the smoothed output to the largest
input step of the whole recording (a bridge rarely needs it).

Implementation
--------------
Every rule and both filters are compiled kernels
(:mod:`tobitkf.smoothing._robust_kernels`, numba, cached on disk, imported on first use):
time is the only loop, all bodies of a recording go through one call. ``robust_online``
is a frame function with explicit state; the batch runner and the live stepper
(:class:`RobustStepper`, registered as the method's ``live``) both call it, so a live
stream gives exactly the batch result with constant work per frame.

The physical reasoning for every default is in ``docs/robust.md``.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology
from tobitkf.smoothing.chunks import chunks, map_chunks, threads
from tobitkf.smoothing.keypoints import (
    DEFAULT_MIN_CONFIDENCE,
    check_min_confidence,
    drop_third_axis,
    method_view,
)
from tobitkf.smoothing.params import (
    as_bool,
    check_inferred_factor,
    int_between,
    nonneg_float,
    nonneg_or_inf,
    one_of,
    over_default,
    positive_or_inf,
    region_value,
)
from tobitkf.smoothing.registry import SmoothInput, SmoothOutput, register_method
from tobitkf.smoothing.robust_gating import (
    bone_lengths,
    girdle_joints,
    joint_order,
    kernels,
    mirror_bones,
    region_values,
    reject_dropped_shoulders,
)
from tobitkf.smoothing.robust_reweight import HuberWeights
from tobitkf.smoothing.robust_scale import (
    GATE_PARAMS,
    is_given,
    recording_gates,
    stream_gate_frames,
    with_given,
)
from tobitkf.smoothing.robust_shared import MIN_CHANGES, MIN_PAIRS
from tobitkf.smoothing.timebase import (
    DEFAULT_INFERRED_NOISE_FACTOR,
    INFERRED_CODE,
    first_true,
    frame_steps,
    frame_times,
    readonly,
)

#: the largest ``lookback`` (frames): 10 s at 30 fps, far beyond how failures enter
MAX_LOOKBACK = 300

__all__ = ["ROBUST_DEFAULTS", "ROBUST_VALIDATORS", "robust_smooth"]

Array = NDArray[np.float64]

#: default parameters of the robust methods (see docs/robust.md for the reasoning)
ROBUST_DEFAULTS: dict[str, Any] = {
    # largest plausible joint speed per body region, m/s
    "v_max": {"hands": 8.0, "arms": 5.0, "torso": 3.0, "legs": 10.0},
    # noise allowance of the speed gate, m (a few standard deviations of hand jitter)
    "margin": 0.05,
    # bone-length tolerance: abs + rel * median length
    "bone_tol_abs": 0.03,
    "bone_tol_rel": 0.15,
    # typical (rms) joint speed per region, m/s, and velocity correlation time, s
    "speed_sd": {"hands": 1.0, "arms": 0.6, "torso": 0.3, "legs": 0.6},
    "tau": 0.15,
    # measurement noise standard deviation per region, m
    "noise_sd": {"hands": 0.015, "arms": 0.01, "torso": 0.007, "legs": 0.01},
    "bones": True,
    "two_pass": True,
    # longest believable tracking failure, s (KERAAL's longest: 48 frames = 1.6 s)
    "max_reject": 2.0,
    # offline: a shoulder whose clavicle points this far (degrees) below the recording's
    # usual angle to the spine's perpendicular, or 3.5 robust sds of it if more, is
    # rejected (about 10 of shoulder depression, 15 of angle noise of a clavicle, 5 of
    # the spine axis); inf: no rule
    "shoulder_drop": 30.0,
    # online: frames dropped from the state when a rejection starts (~67 ms at 30 fps)
    "lookback": 2,
    # offline: an accepted run between two rejections must last this long, s
    "min_run": 0.1,
    # rejected joints follow their parent (offset from the last good frame, sd = bone)
    "carry": True,
    # INFERRED joints (the sensor's guesses) are put back at their bone's length, 3-D
    "inferred_bones": True,
    # metric parameters: "physical" (as given, in metres or the data's units), "recording"
    # (taken from the recording: robust_scale), "auto" (physical for lengths, recording
    # for pixels and unknown units); robust_online also "stream" (taken from the frames
    # so far, re-measured as their count doubles: robust_scale.stream_gate_frames)
    "gates": "auto",
    # offline: "fit" = noise fitted per recording and body region by maximum likelihood
    # (robust_fit.py; speed_sd / noise_sd are then its start and bounds), "fixed" = as given;
    # or a fit made before, {region: {speed_sd, noise_sd, error_sd, error_tau, fitted}}
    "noise": "fit",
    # offline, noise="fit": at most this many seconds of each recording are fitted on, s
    "fit_seconds": 5.0,
    # offline: passes of the smoother that down-weight the accepted samples it does not
    # explain (Huber's weights on the residuals of the pass before; robust_reweight.py)
    "reweight": 2,
    # the errors that the INFERRED guesses of one occlusion and the carried
    # samples of one stretch share, taken from the recording (online: the frames so far),
    # are added to the sd of the samples resting on them (robust_shared.py); the
    # estimate is unchanged
    "shared_errors": True,
}


def _offline_gates(name: str, value: Any) -> str:
    """``robust``'s ``gates``: "stream" (the frames so far) is for the causal method."""
    if value == "stream":
        raise ValueError(
            f"{name} 'stream' (measured on the frames so far) is robust_online's; robust "
            "reads the whole recording: 'recording' (or 'auto') measures them there"
        )
    return one_of("auto", "physical", "recording")(name, value)


def _noise_choice(name: str, value: Any) -> Any:
    """``robust``'s ``noise``: "fit", "fixed", a fit given per body region
    (:func:`tobitkf.smoothing.robust_fit.check_given_noise`), or a list of such fits,
    one per body of the call (bodies smoothed together, each with its own fit)."""
    if isinstance(value, str) and value in ("fit", "fixed"):
        return value
    from tobitkf.smoothing.robust_fit import check_given_noise

    if isinstance(value, (list, tuple)):
        if not value:
            raise ValueError(f"{name}: an empty list of fits (give one per body)")
        return tuple(check_given_noise(f"{name}[{b}]", v) for b, v in enumerate(value))
    return check_given_noise(name, value)


#: most reweighting passes (each is one more run of the smoother)
MAX_REWEIGHT = 10

#: parameter validators (name -> check(name, value) -> value)
ROBUST_VALIDATORS: dict[str, Any] = {
    "v_max": region_value,
    "margin": nonneg_or_inf,
    "bone_tol_abs": nonneg_or_inf,
    "bone_tol_rel": nonneg_or_inf,
    "speed_sd": region_value,
    "tau": positive_or_inf,
    "noise_sd": region_value,
    "bones": as_bool,
    "two_pass": as_bool,
    "max_reject": positive_or_inf,
    "shoulder_drop": positive_or_inf,
    # frames re-predicted at a rejection's start (failures enter over a few); each one is
    # a copy of the filter's state per joint, so a bound keeps the memory reasonable
    "lookback": int_between(0, MAX_LOOKBACK),
    "min_run": nonneg_float,
    "carry": as_bool,
    "inferred_bones": as_bool,
    "gates": _offline_gates,
    "noise": _noise_choice,
    "fit_seconds": positive_or_inf,
    "shared_errors": as_bool,
    "reweight": int_between(0, MAX_REWEIGHT),
}

#: a sample's measurement variance is multiplied by 1 / max(confidence, this)^2
MIN_CONFIDENCE_WEIGHT = 0.01


def _online_reweight(name: str, value: Any) -> int:
    """``robust_online``'s ``reweight``: 0 (it updates with each sample as it comes)."""
    if int_between(0, MAX_REWEIGHT)(name, value) != 0:
        raise ValueError(
            f"{name} is robust's (offline: passes over the whole recording); robust_online "
            "weighs each sample once, as it comes: give 0 or leave it out"
        )
    return 0


#: robust_online keeps the given noise (a causal fit would gain little: docs/robust.md,
#: "Which choices"); its shared errors come from the frames so far
ONLINE_DEFAULTS: dict[str, Any] = {**ROBUST_DEFAULTS, "noise": "fixed", "reweight": 0}
ONLINE_VALIDATORS: dict[str, Any] = {
    **ROBUST_VALIDATORS,
    "noise": one_of("fixed"),
    "gates": one_of("auto", "physical", "recording", "stream"),
    "reweight": _online_reweight,
}


def _ou_matrices(steps: Array, tau: float) -> tuple[Array, Array]:
    """Transition and unit-q process noise ``(T, 2, 2)`` of the integrated OU velocity model.

    ``dv = -v/tau dt + sqrt(q) dW``, ``dx = v dt``, discretised exactly over each step;
    ``tau = inf`` is the constant-velocity (white-acceleration) model. (The filters use
    the same coefficients, :func:`tobitkf.smoothing._robust_kernels.ou_coeffs`.)
    """
    c = kernels().ou_table(np.ascontiguousarray(steps, dtype=float), float(tau))
    T = c.shape[0]
    A = np.zeros((T, 2, 2))
    A[:, 0, 0] = 1.0
    A[:, 0, 1], A[:, 1, 1] = c[:, 0], c[:, 1]
    Q = np.empty((T, 2, 2))
    Q[:, 0, 0], Q[:, 1, 1] = c[:, 2], c[:, 4]
    Q[:, 0, 1] = Q[:, 1, 0] = c[:, 3]
    return A, Q


class _Setup:
    """What the kernels take for one topology and parameter set (per joint and global)."""

    def __init__(self, topo: Topology, params: dict[str, Any], n_dims: int = 3) -> None:
        k = kernels()
        J = topo.n_joints
        self.vmax = region_values(topo, params["v_max"], "v_max")
        self.spd = region_values(topo, params["speed_sd"], "speed_sd")
        self.sd = region_values(topo, params["noise_sd"], "noise_sd")
        tau = params["tau"]
        # stationary velocity variance of the OU model is q tau / 2
        qa = 2 * self.spd**2 / tau if np.isfinite(tau) else self.spd**2
        self.groups = topo.joint_groups()
        self.girdle = girdle_joints(topo.joints)  # the shoulder-girdle rule's joints
        self.parents, self.order = joint_order(topo.parents)
        self.pj = np.zeros((J, k.N_PJ))
        self.pj[:, k.J_VMAX] = self.vmax
        self.pj[:, k.J_Q] = qa
        self.pj[:, k.J_R] = self.sd**2
        self.pj[:, k.J_SD] = self.sd
        self.pj[:, k.J_V0] = qa * tau / 2 if np.isfinite(tau) else 1.0
        self.pj[:, k.J_MIRROR] = mirror_bones(topo)  # 3-D only (the kernel reads I_NDIMS)
        self.pf = np.zeros(k.N_PF)
        self.pf[k.P_MARGIN] = params["margin"]
        self.pf[k.P_TOL_ABS] = params["bone_tol_abs"]
        self.pf[k.P_TOL_REL] = params["bone_tol_rel"]
        self.pf[k.P_MAX_REJECT] = params["max_reject"]
        self.pf[k.P_MIN_RUN] = params["min_run"]
        self.pf[k.P_TAU] = tau
        self.pi = np.zeros(k.N_PI, dtype=np.int64)
        self.pi[k.I_BONES] = bool(params["bones"])
        self.pi[k.I_CARRY] = bool(params["carry"])
        self.pi[k.I_LOOKBACK] = int(params["lookback"])
        self.pi[k.I_TWO_PASS] = bool(params["two_pass"])
        self.pi[k.I_SHARED] = bool(params["shared_errors"])
        self.pi[k.I_MIN_PAIRS] = MIN_PAIRS
        self.pi[k.I_MIN_CHANGES] = MIN_CHANGES
        self.pi[k.I_NDIMS] = n_dims  # the sequence's coordinates (a live stream: per frame)
        self.resolved = {
            "v_max": self.vmax.tolist(),
            "speed_sd": self.spd.tolist(),
            "noise_sd": self.sd.tolist(),
        }

    def args(self) -> tuple[Any, ...]:
        return self.parents, self.order, self.pj, self.pf, self.pi


def _inferred(states: Any, shape: tuple[int, ...]) -> NDArray[np.bool_]:
    """The INFERRED samples ``shape`` (T, B, J) (none without tracking states)."""
    if states is None:
        return np.zeros(shape, dtype=bool)
    return np.ascontiguousarray(np.asarray(states) == INFERRED_CODE)


def _inferred_scale(
    inferred: NDArray[np.bool_], missing: NDArray[np.bool_], factor: float,
    confidence: Any = None,
) -> Array:  # fmt: skip
    """Measurement-variance multiplier per sample: ``factor`` for valid INFERRED ones,
    times ``1 / confidence²`` where a confidence is given (the standard deviation grows
    as the estimator's score falls; NaN confidence: 1)."""
    out = np.where(inferred & ~missing, factor, 1.0)
    if confidence is not None:
        c = np.asarray(confidence, dtype=float)
        w = np.where(np.isnan(c), 1.0, 1.0 / np.maximum(c, MIN_CONFIDENCE_WEIGHT) ** 2)
        out = np.ascontiguousarray(out * w)
    return out


def _guesses(inferred: NDArray[np.bool_], inferred_bones: bool, n_dims: int) -> NDArray[np.bool_]:
    """The INFERRED samples put back at their bone's length (``project_frame``): none
    with ``inferred_bones`` off, and none in 2-D, where a bone seen in projection has no
    one length."""
    return inferred if inferred_bones and n_dims == 3 else np.zeros(inferred.shape, dtype=bool)


def _sample_inputs(
    states: Any, missing: NDArray[np.bool_], factor: float, confidence: Any,
    inferred_bones: bool, n_dims: int,
) -> tuple[NDArray[np.bool_], Array, NDArray[np.bool_]]:  # fmt: skip
    """What the kernels take of the samples ``missing (T, B, J)``: the INFERRED ones, their
    variance multipliers (:func:`_inferred_scale`) and the guesses put back at their
    bone's length (:func:`_guesses`); the same for batch, stream gates and live."""
    inferred = _inferred(states, missing.shape)
    rinf = _inferred_scale(inferred, missing, factor, confidence)
    return inferred, rinf, _guesses(inferred, inferred_bones, n_dims)


def gates_measured(params: Mapping[str, Any]) -> bool:
    """Whether the gates were asked to be measured on the data (``gates``: on the
    recording or on the frames so far), whatever the data's unit."""
    return params.get("gates") in ("recording", "stream")


def use_recording_gates(params: dict[str, Any], units: str | None) -> bool:
    """Whether the metric parameters come from the recording (``gates``, ``units``)."""
    gates = params.get("gates", "auto")
    return gates == "recording" or (gates == "auto" and units not in ("m", "cm", "mm"))


def _offline(
    ys: Array,
    missing: NDArray[np.bool_],
    times: Array,
    steps: Array,
    rinf: Array,
    setup: _Setup,
    params: dict[str, Any],
    L_fixed: Array,
    inferred: NDArray[np.bool_],
    out: tuple[Array, NDArray[np.bool_], Array],
    b0: int,
) -> Any:
    """``robust``: gates both ways, short runs, chain, carrying, OU filter + RTS.

    One kernel call per stage for all bodies (compiling them as one would take longer).
    Writes bodies ``b0 ..`` of ``out = (est (T, B0, J, 3), rejected (T, B0, J), var (T,
    B0, J))``, ``var`` the smoothed position variance (per axis; the axes share it);
    returns ``(fits, guess)``: ``fits`` None (fixed noise) or the fitted per-joint arrays
    ``(B, J)`` and the per-body region fits; ``guess`` None (no INFERRED sample used, or
    ``shared_errors`` off) or the per-axis variance of the guesses' error and the steps
    it rests on, per body (:mod:`.robust_shared`).
    """
    k = kernels()
    par, order, pj, pf, _ = setup.args()
    B, J = missing.shape[1:]
    acc = k.gate_both(ys, times, np.ascontiguousarray(-times[::-1]), par, order, pj, pf,
                      L_fixed, np.ascontiguousarray(inferred), bool(params["bones"]),
                      float(params["max_reject"]), bool(params["two_pass"]),
                      k.new_state(B, J, 0), k.new_state(B, J, 0))  # fmt: skip
    if setup.girdle is not None and setup.pi[k.I_NDIMS] == 3:  # a shoulder dropped too far
        acc = reject_dropped_shoulders(acc, ys, setup.girdle, float(params["shoulder_drop"]))
    if params["min_run"] > 0:
        acc = k.drop_short_runs_run(acc, ~missing & ~acc, times, float(params["min_run"]))
    if params["two_pass"]:
        acc = k.enforce_chain_run(acc, ys, times, par, order, pj, float(params["margin"]), True)
    est, rejected, var = out
    bs = slice(b0, b0 + missing.shape[1])
    np.logical_and(~missing, ~acc, out=rejected[:, bs])
    fits = None
    sd = np.broadcast_to(pj[:, k.J_SD], missing.shape[1:])
    if params["noise"] == "fit":
        # fitted on the accepted samples the sensor vouches for (not INFERRED ones)
        fits = _fit_noise(ys, acc & ~inferred, rinf, steps, setup, params)
        sd = fits[0]["noise_sd"]
    elif isinstance(params["noise"], (Mapping, tuple)):  # fits made before, used as its own
        from tobitkf.smoothing.robust_fit import given_noise_bodies

        given = params["noise"]
        kw = {"tau": float(params["tau"]), "speed_sd": setup.spd, "noise_sd": setup.sd}
        if isinstance(given, tuple):  # one fit per body: this chunk's bodies' own
            parts = [given_noise_bodies(g, 1, setup.groups, **kw) for g in given[b0 : b0 + B]]
            fits = ({name: np.concatenate([f[0][name] for f in parts]) for name in parts[0][0]},
                    [f[1][0] for f in parts])  # fmt: skip
        else:
            fits = given_noise_bodies(given, B, setup.groups, **kw)
        sd = fits[0]["noise_sd"]
    rvar = sd**2 * rinf  # a new (T, B, J) array: the carried samples' are written in
    tau = float(params["tau"])
    if params["carry"]:
        yk = np.empty(ys.shape)  # the accepted samples and the carried ones
        k.carry_both(ys, acc, par, order, np.ascontiguousarray(np.broadcast_to(sd, (B, J))),
                     steps, tau, yk, rvar)  # fmt: skip
    else:
        yk = np.where(acc[..., None], ys, np.nan)
    if fits is None:  # the constants: the same smoother without a coloured error
        q = np.ascontiguousarray(np.broadcast_to(pj[:, k.J_Q], missing.shape))
        sc2, tau_c = np.zeros((B, J)), np.ones((B, J))
    else:
        f = fits[0]
        q = 2 * f["speed_sd"] ** 2 / tau if np.isfinite(tau) else f["speed_sd"] ** 2
        # a joint that is not measured (rejected or missing) moves as the physics allows,
        # not as fitted on the tracked samples: failures come with fast motion and
        # occlusion, so the physical typical speed is the floor there
        q = np.ascontiguousarray(np.where(acc, q, np.maximum(q, pj[:, k.J_Q])))
        sc2, tau_c = f["error_sd"] ** 2, f["error_tau"]
    guess, shared = None, None
    if params["shared_errors"]:  # what the guesses and the carried samples share, in the sd
        # the coordinates there are (a 2-D sequence has a third axis of zeros)
        guess, shared = _shared_errors(ys[..., : setup.pi[k.I_NDIMS]], acc, inferred, yk,
                                       steps, par, order, float(params["max_reject"]))  # fmt: skip
    _smooth_run(yk, rvar, steps, q, sc2, tau, tau_c, est, var, b0, shared)
    if params["reweight"]:  # the samples the track does not explain, down-weighted
        weights = HuberWeights(ys, acc, rinf)
        for _ in range(int(params["reweight"])):
            _smooth_run(yk, rvar * weights(est[:, bs]), steps, q, sc2, tau, tau_c, est, var, b0,
                        shared)  # fmt: skip
    if fits is not None:  # the sd is at least what the samples' own noise says
        from tobitkf.smoothing.robust_fit import sd_floor

        var[:, bs] *= sd_floor(ys, acc & ~inferred, setup.groups, fits[0], fits[1],
                               int(setup.pi[k.I_NDIMS]))[None]  # fmt: skip
    # no estimate before a joint's first valid sample; joints never accepted stay raw
    first = first_true(~missing)
    for b, j in zip(*np.nonzero(first), strict=True):
        est[: first[b, j], b0 + b, j] = np.nan
        var[: first[b, j], b0 + b, j] = np.nan
    for b, j in zip(*np.nonzero(~acc.any(axis=0)), strict=True):
        est[:, b0 + b, j] = ys[:, b, j]
        var[:, b0 + b, j] = np.nan  # raw, not smoothed: no posterior
    return fits, guess


def _shared_errors(
    ys: Array, acc: NDArray[np.bool_], inferred: NDArray[np.bool_], yk: Array, steps: Array,
    par: NDArray[np.int64], order: NDArray[np.int64], max_reject: float,
) -> tuple[tuple[Array, NDArray[np.int64]] | None, Array | None]:  # fmt: skip
    """The errors the guesses and the carried samples share (:mod:`.robust_shared`):
    the guesses' per-axis error variance and the steps it rests on, per body (None
    without guesses), and the smoother's ``shared`` input, ``(T, B, J)`` (None when no
    sample shares an error); ``yk`` the samples the smoother gets."""
    from tobitkf.smoothing import robust_shared as rs

    guess = None
    guess_sd = carried_sd = None
    used = inferred & acc
    if used.any():
        guess = rs.guess_error_variance(ys, acc, inferred)
        guess_sd = np.where(used, np.sqrt(guess[0])[None, :, None], np.nan)
    carried = ~acc & np.isfinite(yk[..., 0])
    if carried.any():
        max_lag = rs.max_lag_frames(max_reject, steps)
        carried_sd = rs.carried_error_sd(ys, acc, carried, par, order, max_lag)
    return guess, rs.shared_signal(guess_sd, carried_sd, acc.shape)


def _smooth_run(
    yk: Array, rvar: Array, steps: Array, q: Array, sc2: Array, tau: float, tau_c: Array,
    est: Array, var: Array, b0: int, shared: Array | None,
) -> None:  # fmt: skip
    """The fitted-noise kernels' ``smooth_run`` of ``yk`` (T, B, J, 3) into ``est`` and
    ``var`` (T, B0, J, ...), each array handed over as rows of frames (views)."""
    fit_kernels().smooth_run(_rows(yk), _rows(rvar), steps, _rows(q), sc2, tau, tau_c,
                             _rows(est), _rows(var), b0, yk.shape[2], shared)  # fmt: skip


def _rows(a: Array) -> Array:
    """``a`` as (frames, the rest): a view of it, never a copy (the outputs are written),
    which a C-contiguous array's reshape is."""
    if not a.flags.c_contiguous:
        raise ValueError(f"smooth_run takes C-contiguous arrays, found strides {a.strides}")
    return a.reshape(a.shape[0], -1)


def fit_kernels() -> Any:
    """The compiled kernels of the fitted-noise smoother (imports numba on first use)."""
    from tobitkf.smoothing import robust_fit

    return robust_fit.kernels()


def _fit_noise(
    ys: Array, use: NDArray[np.bool_], rinf: Array, steps: Array, setup: _Setup,
    params: dict[str, Any],
) -> tuple[dict[str, Array], list[dict[str, Any]]]:  # fmt: skip
    """Noise per body and region by maximum likelihood (:mod:`.robust_fit`), on the
    measurements ``ys`` marked in ``use``."""
    from tobitkf.smoothing.robust_fit import fit_noise_bodies

    return fit_noise_bodies(
        ys, use, rinf, steps, setup.groups, tau=float(params["tau"]), speed_sd=setup.spd,
        noise_sd=setup.sd, v_max=setup.vmax, max_seconds=float(params["fit_seconds"]),
    )  # fmt: skip


def step_guard() -> Any:
    """The compiled step guard (imports numba on first use)."""
    from tobitkf.smoothing import _step_guard

    return _step_guard


def _robust_bodies(
    ys: Array,
    missing: NDArray[np.bool_],
    states: Any,
    times: Array,
    steps: Array,
    topo: Topology,
    params: dict[str, Any],
    factor: float,
    offline: bool,
    confidence: Any = None,
    units: str | None = "m",
    n_dims: int = 3,
    given: frozenset[str] = frozenset(),
) -> tuple[Array, Array, list[dict[str, Any]], dict[str, Any]]:
    """Gate and smooth every body: ys (T, B, J, 3) NaN where missing.

    The parameters taken from the recording (pixels, unknown units) pool all bodies and
    are derived once, from the whole batch (a gate parameter the caller gave, named in
    ``given``, is the caller's); everything else is per body and runs a chunk
    of bodies at a time (:mod:`tobitkf.smoothing.chunks`) into outputs allocated once,
    so the working set stays bounded and the numbers are those of one piece.

    Returns the estimates, their posterior standard deviations (T, B, J), one
    diagnostics dict per body and the resolved per-joint parameters.
    """
    T, B, J = missing.shape
    if isinstance(params["noise"], tuple) and len(params["noise"]) != B:
        raise ValueError(f"noise: {len(params['noise'])} fits given for {B} bodies (one per body)")
    if params["gates"] == "stream":  # online only (its validator)
        return _stream_gated(ys, missing, states, times, steps, topo, params, factor,
                             confidence, n_dims, given)  # fmt: skip
    derived: dict[str, Any] = {}
    centre = None
    if use_recording_gates(params, units):
        derived = recording_gates(ys, steps, topo.parents, n_dims)
        centre = derived.pop("bone_centre", None)
        params = {**params, **with_given(derived, params, given, topo.joint_groups())}
    setup = _Setup(topo, params, n_dims)
    times = np.ascontiguousarray(times, dtype=float)
    steps = np.ascontiguousarray(steps, dtype=float)
    est, var = np.empty((T, B, J, 3)), np.empty((T, B, J))
    rejected = np.zeros((T, B, J), dtype=bool)
    L = np.empty((B, J)) if params["bones"] else None
    fits: Any = None

    def run(b: slice) -> tuple[Array | None, Any, Any]:
        return _robust_chunk(
            ys[:, b], missing[:, b], None if states is None else states[:, b],
            None if confidence is None else confidence[:, b],
            None if centre is None else centre[b], times, steps, topo, setup, params, factor,
            offline, n_dims, (est, rejected, var), b.start,
        )  # fmt: skip

    # a chunk of bodies at a time, written into the outputs in place (chunks in threads)
    n_threads = threads()
    parts = chunks(B, T * J * 3 * 8, spread=n_threads)
    guess_sd, guess_n = np.full(B, np.nan), np.zeros(B, dtype=np.int64)
    for b, (lengths, f, g) in zip(parts, map_chunks(run, parts, n_threads), strict=True):
        if L is not None:
            L[b] = lengths
        if g is not None:
            guess_sd[b], guess_n[b] = np.sqrt(g[0]), g[1]
        if f is not None:
            if fits is None:
                fits = ({name: np.empty((B, J)) for name in f[0]}, [])
            for name, a in f[0].items():
                fits[0][name][b] = a
            fits[1].extend(f[1])
    # a variance a hair below zero is rounding (a track with almost no noise, whose fit
    # finds next to none): its sd is 0, not NaN
    std = np.sqrt(np.maximum(var, 0.0, out=var), out=var)
    if derived and not is_given("noise_sd", given) and not _second_differences(missing):
        # the recording's noise could not be read (its floor stands in): an sd of ~0
        # would claim a certainty nothing measured
        std[...] = np.nan
        warnings.warn(
            f"no joint has three frames in a row ({T} frames), so the recording's noise "
            f"cannot be measured in its units ({units!r}): no standard deviation is given "
            "(NaN); give noise_sd= in the data's units for one",
            UserWarning,
            stacklevel=2,
        )
    diags = [_body_diags(rejected, L, b) for b in range(B)]
    if offline:  # robust_shared: NaN without guesses, with too few changes or switched off
        for b in range(B):
            diags[b]["guess_error_sd"] = float(guess_sd[b])
            diags[b]["guess_error_changes"] = int(guess_n[b])
    resolved = _resolved(setup, derived)
    body_params = None
    if fits is not None:
        arrays, reports = fits
        for report in reports:  # a fit holds for data in these units only (_noise_units)
            for r in report.values():
                r["units"] = units
        # per joint the values used; per region the fit itself, which `noise=` takes back
        # (tobitkf.io.read_noise_fit reads it from an output file)
        noise_given = params["noise"]
        body_params = tuple(
            {
                **{name: a[b].tolist() for name, a in arrays.items()},
                "noise_fit": {g: dict(r) for g, r in reports[b].items()},
                # each body's own fit given, not the list of all of them
                **({"noise": noise_given[b]} if isinstance(noise_given, tuple) else {}),
            }
            for b in range(B)
        )
        for b in range(B):
            diags[b]["noise_fit"] = reports[b]
    return est, std, diags, resolved, body_params


def _second_differences(missing: NDArray[np.bool_]) -> bool:
    """Whether some joint of some body is present at three frames in a row (the noise is
    read from second differences, :func:`~tobitkf.smoothing.robust_scale.recording_gates`)."""
    present = ~missing
    return bool((present[2:] & present[1:-1] & present[:-2]).any())


def _stream_gated(
    ys: Array,
    missing: NDArray[np.bool_],
    states: Any,
    times: Array,
    steps: Array,
    topo: Topology,
    params: dict[str, Any],
    factor: float,
    confidence: Any,
    n_dims: int,
    given: frozenset[str] = frozenset(),
) -> tuple[Array, Array, list[dict[str, Any]], dict[str, Any], None]:
    """``robust_online`` with ``gates="stream"``: the frames before the first of
    :func:`stream_gate_frames` as measured (no sd), then the online frame function with
    the gates measured on the frames so far, re-measured at each of those frames (its
    state carried across), all bodies in one call: what ``LiveSmoother(gates_from=
    "stream")`` gives frame by frame. Returns what :func:`_robust_bodies` does."""
    T, B, J = missing.shape
    k = kernels()
    est, var = np.empty((T, B, J, 3)), np.full((T, B, J), np.nan)
    rejected = np.zeros((T, B, J), dtype=bool)
    frames = stream_gate_frames(T)
    first = frames[0] if frames else T
    est[:first] = np.where(missing[:first, ..., None], np.nan, ys[:first])
    y_all = readonly(np.ascontiguousarray(ys, dtype=float))
    missing = np.ascontiguousarray(missing, dtype=bool)
    times = np.ascontiguousarray(times, dtype=float)
    steps = np.ascontiguousarray(steps, dtype=float)
    inferred, rinf, guesses = _sample_inputs(
        states, missing, factor, confidence, params["inferred_bones"], n_dims
    )
    setup, derived, history, segments = None, {}, [], []
    for a, b in zip(frames, [*frames[1:], T], strict=True):
        derived = recording_gates(ys[:a], steps[:a], topo.parents, n_dims)
        derived.pop("bone_centre", None)
        mine = with_given(derived, params, given, topo.joint_groups())  # the caller's win
        setup = _Setup(topo, {**params, **mine}, n_dims)
        history.append({"frame": a, **{g: derived[g] for g in GATE_PARAMS}})
        segments.append((a, b, setup))
    state = _online_run(y_all, missing, (inferred, rinf, guesses), times, steps, segments,
                        params, (est, rejected, var), 0)  # fmt: skip
    std = np.sqrt(np.maximum(var, 0.0, out=var), out=var)
    if setup is None:  # too short for a first measurement: the frames as measured
        setup = _Setup(topo, params, n_dims)
    L = state[3][..., k.S_L_CUR].copy() if params["bones"] and frames else None
    diags = [{**_body_diags(rejected, L, b), "stream_gates": history} for b in range(B)]
    return est, std, diags, _resolved(setup, derived), None


def _body_diags(rejected: NDArray[np.bool_], L: Array | None, b: int) -> dict[str, Any]:
    """Body ``b``'s diagnostics: its rejections ``(T, J)``, their share per joint and the
    bone lengths its gate compared with (NaN without bones)."""
    return {
        "rejected_fraction": rejected[:, b].sum(axis=0) / rejected.shape[0],
        "rejected": rejected[:, b],
        "bone_lengths": L[b] if L is not None else np.full(rejected.shape[2], np.nan),
    }


def _resolved(setup: _Setup, derived: dict[str, Any]) -> dict[str, Any]:
    """The per-joint parameters used, with the global ones taken from the recording."""
    resolved = dict(setup.resolved)
    for name in ("margin", "bone_tol_abs", "bone_tol_rel"):
        if name in derived:
            resolved[name] = float(derived[name])
    return resolved


def _robust_chunk(
    ys: Array,
    missing: NDArray[np.bool_],
    states: Any,
    confidence: Any,
    centre: Array | None,
    times: Array,
    steps: Array,
    topo: Topology,
    setup: _Setup,
    params: dict[str, Any],
    factor: float,
    offline: bool,
    n_dims: int,
    out: tuple[Array, NDArray[np.bool_], Array],
    b0: int,
) -> tuple[Array | None, Any, Any]:
    """The per-body work of :func:`_robust_bodies` for some bodies, parameters resolved:
    writes bodies ``b0 ..`` of ``out = (est (T, B0, J, 3), rejected (T, B0, J), var (T,
    B0, J))`` and returns ``(bone lengths (B, J) or None, fits, guess)`` (:func:`_offline`;
    online both None); ``centre`` (B, J): the 2-D bone gate's lengths from the recording,
    or None."""
    B, J = missing.shape[1:]
    ys = readonly(np.ascontiguousarray(ys, dtype=float))  # one compiled version
    k = kernels()
    missing = np.ascontiguousarray(missing, dtype=bool)
    inferred, rinf, guesses = _sample_inputs(
        states, missing, factor, confidence, params["inferred_bones"], n_dims
    )
    fits = guess = None
    L = None  # (B, J): the bone lengths the gate compared with at the end (reported)
    if offline:
        # the recording's median bone lengths (2-D from the recording: the gate compares
        # with the centre of the one-sided range)
        L = bone_lengths(ys, topo.parents) if params["bones"] else None
        L_gate = L if centre is None else centre
        L_fixed = np.full((B, J), np.nan) if L_gate is None else np.ascontiguousarray(L_gate)
        projected = ys
        if L is not None and guesses.any():  # at the recording's bone lengths
            projected = readonly(k.project_run(ys, guesses, setup.parents, setup.order, L_fixed))
        fits, guess = _offline(projected, missing, times, steps, rinf, setup, params, L_fixed,
                               inferred, out, b0)  # fmt: skip
        # no output step larger than the input's largest (offline: the whole recording's)
        guard = step_guard()
        g_state = guard.new_state(B, J, ys.shape[-1])
        guard.largest_steps(ys, missing, g_state[1])
        guard.guard_frames(ys, missing, out[0], out[2], b0, *g_state)
    else:
        state = _online_run(ys, missing, (inferred, rinf, guesses), times, steps,
                            [(0, ys.shape[0], setup)], params, out, b0)  # fmt: skip
        if params["bones"]:  # the lengths learnt by the end of the recording
            L = state[3][..., k.S_L_CUR].copy()
    return L, fits, guess


def _online_run(
    ys: Array, missing: NDArray[np.bool_], inputs: tuple[Any, Any, Any], times: Array,
    steps: Array, segments: list[tuple[int, int, _Setup]], params: dict[str, Any],
    out: tuple[Array, NDArray[np.bool_], Array], b0: int,
) -> Any:  # fmt: skip
    """``robust_online`` over frames ``segments`` ``(a, b, setup)`` (one for the whole
    recording; ``gates="stream"``: one per gate measurement), the filter's state carried
    from one to the next, each followed by the step guard (no output step larger than
    the input's largest so far): the online frame function, as the live stepper runs it.
    ``inputs`` are :func:`_sample_inputs`' ``(inferred, rinf, guesses)``; writes bodies
    ``b0 ..`` of ``out``; returns the filter's state."""
    k = kernels()
    B, J = missing.shape[1:]
    inferred, rinf, guesses = inputs
    est, rejected, var = out
    state = k.new_state(B, J, int(params["lookback"]), bool(params["shared_errors"]))
    work = k.new_work(B, J)
    guard = step_guard()
    g_state = guard.new_state(B, J, ys.shape[-1])
    for a, b, setup in segments:
        f = slice(a, b)
        k.online_frames(ys[f], missing[f], rinf[f], guesses[f], inferred[f], times[f],
                        steps[f], *setup.args(), state, *work, est[f], rejected[f], var[f],
                        b0)  # fmt: skip
        guard.guard_frames(ys[f], missing[f], est[f], var[f], b0, *g_state)
    return state


def _run(inp: SmoothInput, offline: bool, params: dict[str, Any]) -> SmoothOutput:
    """Runner: every body of ``inp`` gated and smoothed on its own, all in one call."""
    est, std, diags, resolved, body_params = _robust_bodies(
        inp.ys, inp.missing, inp.tracking_state, inp.times, inp.steps, inp.topology, params,
        inp.inferred_noise_factor, offline, inp.confidence, inp.units, inp.n_dims, inp.given,
    )  # fmt: skip
    return SmoothOutput(est, std=std, diagnostics=tuple(diags), params=resolved if diags else {},
                        body_params=body_params)  # fmt: skip


class RobustStepper:
    """Live form of ``robust_online``: one ``online_frames`` call per frame.

    The state (per body and joint: last accepted sample and its time, rejection and
    confirmation starts, the window of bone lengths, the OU filter state with its
    ``lookback`` history) lives in arrays; the batch runner runs the same frame
    function over a recording, so a stream gives exactly the batch numbers. Work per
    frame is constant (the bone-length window holds at most 600 lengths).
    """

    def __init__(self, topology: Topology, up_axis: int, inferred_noise_factor: float,
                 **params: Any) -> None:  # fmt: skip
        full = dict(ONLINE_DEFAULTS)
        full.update(params)
        self.topology = topology
        self.setup = _Setup(topology, full)
        self.factor = inferred_noise_factor
        self.inferred_bones = bool(full["inferred_bones"])
        self._state: Any = None
        self._time = 0.0

    def retune(self, **params: Any) -> None:
        """New parameters from the next frame on, the state kept (``gates="stream"``: the
        gates measured anew on the frames so far). ``lookback`` and ``shared_errors``
        shape the state: they must be those it was made with."""
        full = dict(ONLINE_DEFAULTS)
        full.update(params)
        self.setup = _Setup(self.topology, full)

    uses_n_dims = True  # the stream's coordinates: inferred joints keep their bones in 3-D
    uses_confidence = True  # a pose estimator's scores weigh the samples, as in batch
    # the gates read the frames' times, which batch takes from the timestamps as they are:
    # duplicated ones are 0 s apart there, while their step is a tenth of the nominal one
    uses_time = True

    def step(self, ys: Array, missing: NDArray[np.bool_], states: Any, dt: float,
             n_dims: int = 3, confidence: Any = None,
             time: float | None = None) -> Array:  # fmt: skip
        """Smooth one frame: ys (B, J, 3) NaN where missing (``n_dims`` 2: a third axis of
        zeros); returns (B, J, 3). ``time``: the frame's timestamp (batch: ``times``), else
        the cumulated steps (batch without timestamps)."""
        k = kernels()
        B, J = missing.shape
        if self._state is None:
            self._state = k.new_state(B, J, int(self.setup.pi[k.I_LOOKBACK]),
                                      bool(self.setup.pi[k.I_SHARED]))  # fmt: skip
            self._scratch = k.new_work(B, J)
            self._guard = step_guard().new_state(B, J, ys.shape[-1])
            self._time = 0.0 if time is None else float(time)
        else:  # the batch times: the timestamps, else the cumulated steps
            self._time = self._time + dt if time is None else float(time)
        out = np.empty((1, B, J, 3))
        self.rejected = np.zeros((B, J), dtype=bool)
        self.std = np.empty((B, J))
        # one read-only frame for both kernels: the types of the batch call, so nothing
        # compiles twice
        self.setup.pi[k.I_NDIMS] = n_dims
        y1 = readonly(np.ascontiguousarray(ys, dtype=float)[None])
        m1 = np.ascontiguousarray(missing, dtype=bool)[None]
        inferred, rinf, guesses = _sample_inputs(
            None if states is None else np.asarray(states)[None], m1, self.factor,
            None if confidence is None else np.asarray(confidence)[None], self.inferred_bones,
            n_dims,
        )  # fmt: skip
        k.online_frames(
            y1, m1, rinf, guesses, inferred, np.array([self._time]), np.array([float(dt)]),
            *self.setup.args(), self._state, *self._scratch, out, self.rejected[None],
            self.std[None], 0,
        )  # fmt: skip
        step_guard().guard_frames(y1, m1, out, self.std[None], 0, *self._guard)
        np.sqrt(np.maximum(self.std, 0.0, out=self.std), out=self.std)
        return out[0]


def robust_smooth(
    sequence: SkeletonSequence,
    *,
    offline: bool = True,
    inferred_noise_factor: float = DEFAULT_INFERRED_NOISE_FACTOR,
    min_confidence: float = DEFAULT_MIN_CONFIDENCE,
    **params: Any,
) -> SkeletonSequence:
    """Reject physically impossible measurements, then smooth (module docstring).

    ``smooth(sequence, "robust", **params)`` (offline) or ``"robust_online"`` (causal)
    does the same through the registry; this is the direct form.

    Parameters
    ----------
    sequence : SkeletonSequence, positions (T, J, D) (any units: lengths are converted
        to metres; pixels and unknown units take the gates from the recording, ``gates``).
    offline : True (default): bone lengths from the whole recording, forward + backward
        gating, RTS smoother (interpolates across rejected stretches).  False: causal
        (online) — running bone lengths, forward gating, Kalman filter output only.
    inferred_noise_factor : variance multiplier for INFERRED joints (default 4).
    min_confidence : samples whose confidence is below this are missing (default 0.1);
        the others get the measurement variance times ``1 / confidence²``.
    v_max : speed bound, m/s: a number, (J,) values or a mapping per body region
        (``hands``, ``arms``, ``torso``, ``legs``); default hands 8, arms 5, torso 3, legs 10.
    margin : speed-gate noise allowance, m (default 0.05).
    bone_tol_abs, bone_tol_rel : bone gate ``|length - L| <= abs + rel * L`` (default
        0.03 m + 15 %).
    speed_sd : stationary (rms) joint speed of the OU velocity model, m/s (number, (J,)
        or per region; default hands 1.0, arms 0.6, torso 0.3, legs 0.6); the velocity
        noise density is ``q = 2 speed_sd² / tau`` (``speed_sd²`` when ``tau = inf``).
    tau : velocity correlation time, s (default 0.15; ``inf`` = constant velocity).
    noise_sd : measurement noise standard deviation, m (default hands 15 mm, arms 10,
        torso 7, legs 10).
    bones : use the bone gate (default True).
    two_pass : offline only: also gate backwards in time (default True).
    max_reject : s; a joint rejected longer than this is re-acquired as soon as it moves
        plausibly from frame to frame (default 2).
    shoulder_drop : offline only, skeletons with Kinect's spine and shoulder joints, 3-D:
        a shoulder whose clavicle points more than this (degrees) below the recording's
        usual angle to the spine's perpendicular, or 3.5 robust standard deviations of
        that angle if more, is rejected (default 30; ``inf``: no rule).
    lookback : online only: accepted frames dropped from the state when a rejection
        starts (default 2).
    min_run : an accepted run between two rejections not longer than this (s) is rejected
        too offline, and must be confirmed for longer than this online (default 0.1).
    carry : rejected joints are carried along with their parent (pseudo-measurement at
        the parent plus the last good offset, standard deviation = that bone's length),
        instead of only being predicted by their own motion model (default True).
    inferred_bones : INFERRED joints (the sensor's guesses) are put back at their bone's
        length before the gates, keeping their direction from the parent; an inferred
        chain first moves with its parent's correction (default True; 3-D only). The
        length is the recording's median offline, the one learnt so far online.
    noise : offline only: ``"fit"`` (default) fits ``speed_sd`` and ``noise_sd`` (given
        values: the start and bounds) and a coloured error (``error_sd``, ``error_tau``)
        to the recording per body region (:mod:`tobitkf.smoothing.robust_fit`; the
        fitted values are in ``params`` and ``diagnostics["noise_fit"]``); ``"fixed"``
        uses the values as given (online always); a fit made before (a
        ``diagnostics["noise_fit"]`` mapping, every region of the skeleton; from a file:
        :func:`tobitkf.io.noise_fit.read_noise_fit`) is used as the fit would be,
        without fitting (:func:`~tobitkf.smoothing.robust_fit.check_given_noise`); a
        recording in other units than the fit's (each region's ``units``) refuses it;
        through :func:`tobitkf.smooth`, several bodies take a list of fits, one each.
    fit_seconds : the most of the recording the fit reads, s (default 5; ``inf`` = all).
    shared_errors : True (default) adds the errors that the INFERRED guesses of one
        occlusion and the carried samples of one stretch share, estimated from the
        recording (online from the frames so far), to the standard deviation of the
        samples resting on them (:mod:`tobitkf.smoothing.robust_shared`; the estimate is
        unchanged; offline ``diagnostics["guess_error_sd"]``); False keeps each sample's
        own error as if independent.
    reweight : offline, passes of the smoother after the first with Huber's weights on
        the accepted samples the pass before does not explain (default 2; 0: none;
        :mod:`tobitkf.smoothing.robust_reweight`). ``robust_online`` takes only 0.
    gates : ``"auto"`` (default: the metric parameters as given for lengths, from the
        recording for pixels and unknown units), ``"physical"`` (as given, in the data's
        units after conversion of lengths to metres) or ``"recording"``
        (:mod:`tobitkf.smoothing.robust_scale`).

    Returns
    -------
    SkeletonSequence
        Positions replaced; ``metadata["diagnostics"]`` = ``rejected_fraction`` (J,),
        ``filled_fraction`` (J,) (missing or rejected samples that got an estimate),
        ``clipped_fraction`` (J,) zeros (no censoring here), ``rejected`` (T, J) bool
        mask, ``bone_lengths`` (J,) (the lengths the bone gate compared with: offline
        the recording's medians, online the ones learnt by its end), ``method``
        (``"robust"`` / ``"robust_online"``) and ``params``; offline also ``noise_fit``
        (with ``noise="fit"``), ``guess_error_sd`` and ``guess_error_changes`` (the
        guesses' per-axis error in the smoother's units, metres for lengths, and the
        steps it rests on: NaN and 0 without an estimate).
    """
    if not isinstance(sequence, SkeletonSequence):
        raise TypeError(f"robust_smooth expects a SkeletonSequence, got {type(sequence).__name__}")
    offline = as_bool("offline", offline)
    factor = check_inferred_factor(inferred_noise_factor)
    min_conf = check_min_confidence(min_confidence)
    unknown = sorted(set(params) - set(ROBUST_DEFAULTS))
    if unknown:
        raise ValueError(
            f"unknown parameters {unknown} for robust_smooth; valid: {sorted(ROBUST_DEFAULTS)}"
        )
    full = dict(ROBUST_DEFAULTS if offline else ONLINE_DEFAULTS)
    checks = ROBUST_VALIDATORS if offline else ONLINE_VALIDATORS
    full.update({k: checks[k](k, over_default(v, full[k])) for k, v in params.items()})
    T, J = sequence.n_frames, sequence.n_joints
    if T == 0:
        return sequence.replace(metadata={**sequence.metadata, "diagnostics": {}})
    states = sequence.tracking_state
    conf = sequence.confidence
    scale, _, ys, missing = method_view(sequence.positions, sequence.units, states, conf, min_conf)
    steps = frame_steps(sequence)[0]
    est, std, diags, resolved, body_params = _robust_bodies(
        ys[:, None], missing[:, None], None if states is None else states[:, None],
        frame_times(sequence, steps), steps, sequence.topology, full, factor, offline,
        None if conf is None else conf[:, None], "m" if scale is not None else sequence.units,
        sequence.n_dims,
    )  # fmt: skip
    est, std, diag = drop_third_axis(est[:, 0], sequence.n_dims), std[:, 0], diags[0]
    if scale not in (None, 1.0):
        est, std = est / scale, std / scale
    used = {**full, **resolved, **(body_params[0] if body_params else {}),
            "inferred_noise_factor": factor, "offline": offline}  # fmt: skip
    if conf is not None:
        used["min_confidence"] = min_conf
    filled = (missing | diag["rejected"]) & np.isfinite(est).all(axis=-1)
    diagnostics = {
        **diag,
        "filled_fraction": filled.sum(axis=0) / T,
        "clipped_fraction": np.zeros(J),
        "method": "robust" if offline else "robust_online",
        "params": used,
    }
    return sequence.replace(
        positions=est, std=std, metadata={**sequence.metadata, "diagnostics": diagnostics}
    )


def _noise_units(params: Mapping[str, Any], n_dims: int, units: str | None) -> None:
    """``check_data``: a noise fit given (``noise=``) that says the units it was fitted
    in must be those of this recording as the method sees it (metres for any length):
    a fit made in pixels would be a thousandfold off on metres, and silently."""
    noise = params.get("noise")
    if isinstance(noise, Mapping):
        noise = (noise,)
    if not isinstance(noise, tuple):
        return
    made = {r["units"] for fit in noise for r in fit.values() if "units" in r}
    for u in made:
        if u != units:
            raise ValueError(
                f"noise: the fit given was made on a recording in {u or 'unknown units'}, "
                f"and this one is in {units or 'unknown units'}: a fit holds only for data "
                "in its own units (lengths count as metres)"
            )


def _register(name: str, offline: bool, description: str) -> None:
    def run(inp: SmoothInput, **params: Any) -> SmoothOutput:
        return _run(inp, offline, params)

    register_method(
        name,
        run,
        params=ROBUST_DEFAULTS if offline else ONLINE_DEFAULTS,
        validators=ROBUST_VALIDATORS if offline else ONLINE_VALIDATORS,
        description=description,
        causal=not offline,
        live=None if offline else RobustStepper,
        check_data=_noise_units if offline else None,
        per_body=("noise",) if offline else (),
    )


_register("robust", True, "physical speed / bone-length gating, OU-velocity RTS smoother")
_register("robust_online", False, "physical speed / bone-length gating, causal OU-velocity KF")
