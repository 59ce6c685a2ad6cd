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

Gating (per frame, joints from the root outwards, vectorised over joints)
--------------------------------------------------------------------------
A valid measurement ``y_j(t)`` is *accepted* when

1. **speed gate** — it is reachable from the joint's last accepted measurement
   ``y_j(s)``: ``|y_j(t) - y_j(s)| <= v_max_j (t - s) + margin``.  ``v_max`` is a
   physical bound by body region (hands 8, arms 5, torso 3, legs 10 m/s); the gate grows
   with the time since the last accepted sample, so a joint that really moved faster
   than ``v_max`` is re-acquired a frame or two later instead of being lost;
2. **bone gate** — if its parent was accepted in this frame, the bone to the parent has
   its normal length: ``| |y_j - y_parent| - L_j | <= bone_tol_abs + bone_tol_rel L_j``
   with ``L_j`` the recording's median bone length (offline) or the median of the
   lengths seen so far (online).  A wrong bone is blamed on the distal joint;
3. **chain** — if the parent was *rejected* in this frame the bone says nothing, and the
   joint is accepted only if it was accepted in the previous frame and did not jump
   (a wrong wrist makes its hand suspect: a hand that jumped together with a rejected
   wrist stays rejected until the wrist comes back).

A joint rejected for longer than ``max_reject`` (2 s) is re-acquired as soon as it moves
plausibly from frame to frame (no lock-out behind a wrong reference).  Offline, the gate
runs forwards and backwards in time and a measurement is rejected when either pass
rejects it (failures often enter over 1–3 frames that only one direction flags), an
accepted run shorter than ``min_run`` (0.1 s) between two rejections is rejected too, and
the chain rule is applied once more to the combined mask (:func:`enforce_chain`), so a
wrist that failed together with its elbow is not left in place beside a bridged elbow.
Online, after a rejection of at least ``min_run`` a joint is believed again only once its
measurements have passed the gates for ``min_run`` (:func:`confirm_reacquisition`, the
causal form of the same rule), the chain rule is applied forwards in time, and when a
rejection starts the last ``lookback`` (2) accepted frames are dropped from the filter
state (not from the output already emitted).  ``NOT_TRACKED`` joints and NaN are
missing; ``INFERRED`` joints get ``inferred_noise_factor`` times the measurement
variance.

Carrying
--------
A rejected joint is not left behind in space while the body moves on: it gets a
pseudo-measurement at its parent's position plus its offset from the parent the last
time both were accepted (:func:`carry_with_parent`; offline, a stretch with no earlier
good offset takes the next one), with a standard deviation equal to that bone's length,
since the limb may have rotated about the parent.  ``carry=False`` turns this off.

Smoothing
---------
Each axis of each joint is an integrated Ornstein–Uhlenbeck velocity model,
``dv = -v/tau dt + sqrt(q) dW``, ``dx = v dt``, discretised exactly per time step (so
irregular timestamps are exact), with ``q = 2 speed_sd² / tau`` (the stationary velocity
standard deviation is ``speed_sd``, per body region) and measurement noise ``noise_sd``
(per region), ``H = [1, 0]``.  Offline the RTS smoother runs after the filter; online the
filter output is returned: across a rejected stretch the OU velocity decays with
``tau`` (0.15 s), so a lost joint is extrapolated by at most about ``v * tau`` and then
held.

The physical reasoning for every default is in ``docs/robust.md``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.core.kalman import kalman_filter, rts_smooth
from tobitkf.core.model import LinearGaussian
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology
from tobitkf.smoothing.params import (
    as_bool,
    at_least_int,
    check_inferred_factor,
    nonneg_float,
    nonneg_or_inf,
    positive_or_inf,
    region_value,
)
from tobitkf.smoothing.registry import SmoothInput, SmoothOutput, register_method
from tobitkf.smoothing.robust_gating import (
    bone_lengths,
    carry_with_parent,
    confirm_reacquisition,
    drop_short_runs,
    enforce_chain,
    gate_measurements,
    region_values,
)
from tobitkf.smoothing.timebase import (
    DEFAULT_INFERRED_NOISE_FACTOR,
    frame_steps,
    frame_times,
    inferred_r_scale,
    measurements,
)

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
    # online: frames dropped from the state when a rejection starts (~67 ms at 30 fps)
    "lookback": 2,
    # offline: an accepted run between two rejections must last this long, s
    "min_run": 0.1,
    # rejected joints follow their parent (offset from the last good frame, sd = bone)
    "carry": True,
}

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
    "lookback": at_least_int(0),
    "min_run": nonneg_float,
    "carry": as_bool,
}


def _ou_matrices(steps: Array, tau: float) -> tuple[Array, Array]:
    """Transition and unit-q process noise ``(T, 2, 2)`` of the integrated OU velocity model.

    ``dv = -v/tau dt + sqrt(q) dW``, ``dx = v dt``, discretised exactly over each step;
    ``tau = inf`` is the constant-velocity (white-acceleration) model.
    """
    dt = np.asarray(steps, dtype=float)
    T = dt.shape[0]
    A = np.zeros((T, 2, 2))
    Q = np.empty((T, 2, 2))
    if not np.isfinite(tau):
        A[:, 0, 0] = A[:, 1, 1] = 1.0
        A[:, 0, 1] = dt
        Q[:, 0, 0] = dt**3 / 3
        Q[:, 0, 1] = Q[:, 1, 0] = dt**2 / 2
        Q[:, 1, 1] = dt
        return A, Q
    rho = np.exp(-dt / tau)
    om = -np.expm1(-dt / tau)  # 1 - rho, accurate for small steps
    om2 = -np.expm1(-2 * dt / tau)  # 1 - rho^2
    A[:, 0, 0] = 1.0
    A[:, 0, 1] = tau * om
    A[:, 1, 1] = rho
    Q[:, 0, 0] = tau**2 * (dt - 2 * tau * om + 0.5 * tau * om2)
    Q[:, 0, 1] = Q[:, 1, 0] = 0.5 * tau**2 * om**2
    Q[:, 1, 1] = 0.5 * tau * om2
    # Q_xx suffers cancellation for dt << tau: use the series dt^3/3 - dt^4/(4 tau) there
    small = dt < 1e-3 * tau
    Q[small, 0, 0] = dt[small] ** 3 / 3 - dt[small] ** 4 / (4 * tau)
    return A, Q


def _cv_smooth(
    ys: Array,
    steps: Array,
    tau: float,
    q: Array,
    r: Array,
    r_scale: Array | None,
    offline: bool,
) -> Array:
    """OU-velocity KF (+ RTS) per axis; ys (T, J, 3) with NaN missing; q, r (J,)."""
    out = np.full_like(ys, np.nan)
    A_seq, base_Q = _ou_matrices(steps, tau)
    # joints sharing (q, r) run in one vectorised pass
    keys = np.stack([q, r], axis=1)
    for key in np.unique(keys, axis=0):
        idx = np.flatnonzero(np.all(keys == key, axis=1))
        qa, rr = float(key[0]), float(key[1])
        y = ys[:, idx, :, None]  # (T, j, 3, 1)
        valid = np.isfinite(y[..., 0])
        first = np.argmax(valid, axis=0)  # (j, 3)
        has = valid.any(axis=0)
        x0p = np.take_along_axis(y[..., 0], first[None], axis=0)[0]
        x0 = np.stack([np.where(has, x0p, 0.0), np.zeros_like(x0p)], axis=-1)  # (j, 3, 2)
        # P0: position known to the noise, velocity from its stationary distribution
        P0 = np.diag([rr, qa * tau / 2 if np.isfinite(tau) else 1.0])
        model = LinearGaussian(
            A=A_seq[0],
            H=np.array([[1.0, 0.0]]),
            Q=qa * base_Q[0],
            R=np.array([[rr]]),
            x0=x0,
            P0=P0,
        )
        kwargs: dict[str, Any] = {"A_seq": A_seq, "Q_seq": qa * base_Q}
        if r_scale is not None:
            kwargs["R_scale"] = r_scale[:, idx, :, None]
        # the first step predicts from x0 with A_seq[0]; start at the first sample itself
        A_seq0 = A_seq.copy()
        A_seq0[0] = np.eye(2)
        Q0 = kwargs["Q_seq"].copy()
        Q0[0] = 0.0
        kwargs["A_seq"], kwargs["Q_seq"] = A_seq0, Q0
        res = kalman_filter(model, y, **kwargs)
        means = rts_smooth(model, res).means if offline else res.means
        out[:, idx, :] = means[..., 0]
    return out


def _causal_filter(
    ys: Array,
    acc: NDArray[np.bool_],
    steps: Array,
    tau: float,
    q: Array,
    r: Array,
    r_scale: Array | None,
    lookback: int,
    carried: NDArray[np.bool_] | None = None,
) -> Array:
    """Causal OU-velocity Kalman filter per axis with roll-back at rejection onsets.

    Same model as :func:`_cv_smooth` (started at a joint's first accepted sample with
    P = diag(r, stationary velocity variance)).  When a joint's measurement is
    rejected right after an accepted one, the last ``lookback`` accepted frames are
    dropped from its *state* (re-predicted from the state before them): the entry of a
    tracking failure is often gradual, and its first frames pass the gates.  Outputs
    already emitted for those frames are not changed (the filter stays causal).
    """
    T, J, _ = ys.shape
    N = J * 3
    y = ys.reshape(T, N)
    ok = np.repeat(acc, 3, axis=1) & np.isfinite(y)
    if carried is None:
        extra = np.zeros_like(ok)
    else:
        extra = np.repeat(carried, 3, axis=1) & np.isfinite(y)
    qn = np.repeat(q, 3)
    rn = np.repeat(r, 3)[None, :] * (1.0 if r_scale is None else r_scale.reshape(T, N))
    rn = np.broadcast_to(rn, (T, N))
    A_seq, base_Q = _ou_matrices(steps, tau)
    v0 = qn * tau / 2 if np.isfinite(tau) else np.ones(N)
    xs = np.zeros((T, N, 2))
    Ps = np.zeros((T, N, 2, 2))
    x = np.zeros((N, 2))
    P = np.zeros((N, 2, 2))
    started = np.zeros(N, dtype=bool)
    out = np.full((T, N), np.nan)
    prev_ok = np.zeros(N, dtype=bool)

    def predict(x: Array, P: Array, t: int, sel: Any) -> tuple[Array, Array]:
        A = A_seq[t]
        Q = qn[sel, None, None] * base_Q[t]
        return x @ A.T, A @ P @ A.T + Q

    for t in range(T):
        if lookback > 0 and t > lookback:
            onset = started & prev_ok & ~ok[t]
            if onset.any():
                s0 = t - lookback - 1
                sel = onset & ok[s0]  # keep it simple: only when the base frame was good
                if sel.any():
                    xb, Pb = xs[s0, sel], Ps[s0, sel]
                    for k in range(s0 + 1, t):
                        xb, Pb = predict(xb, Pb, k, sel)
                    x[sel], P[sel] = xb, Pb
        # predict (frame 0 and fresh starts: nothing to predict from)
        if t > 0:
            xp, Pp = predict(x, P, t, slice(None))
            x = np.where(started[:, None], xp, x)
            P = np.where(started[:, None, None], Pp, P)
        new = ok[t] & ~started
        if new.any():
            x[new, 0] = y[t, new]
            x[new, 1] = 0.0
            P[new] = 0.0
            P[new, 0, 0] = rn[t, new]
            P[new, 1, 1] = v0[new]
            started |= new
        upd = (ok[t] | extra[t]) & ~new & started
        if upd.any():
            S = P[upd, 0, 0] + rn[t, upd]
            K = P[upd, :, 0] / S[:, None]
            innov = y[t, upd] - x[upd, 0]
            x[upd] = x[upd] + K * innov[:, None]
            P[upd] = P[upd] - K[:, :, None] * P[upd, 0, :][:, None, :]
            P[upd] = 0.5 * (P[upd] + np.swapaxes(P[upd], -1, -2))
        xs[t], Ps[t] = x, P
        out[t] = np.where(started, x[:, 0], np.nan)
        prev_ok = ok[t]
    return out.reshape(T, J, 3)


def _robust_body(
    ys: Array,
    missing: NDArray[np.bool_],
    states: Any,
    times: Array,
    steps: Array,
    topo: Topology,
    params: dict[str, Any],
    factor: float,
    offline: bool,
) -> tuple[Array, dict[str, Any]]:
    """Gate and smooth one body: ys (T, J, 3) NaN where missing; returns (est, diagnostics)."""
    T, J = missing.shape
    vmax = region_values(topo, params["v_max"], "v_max")
    spd = region_values(topo, params["speed_sd"], "speed_sd")
    # stationary velocity variance of the OU model is q tau / 2
    qa = 2 * spd**2 / params["tau"] if np.isfinite(params["tau"]) else spd**2
    sd = region_values(topo, params["noise_sd"], "noise_sd")
    parents = topo.parents
    L = bone_lengths(ys, parents) if params["bones"] else None
    gate_kw = dict(
        margin=params["margin"],
        bone_len=L,
        bone_tol_abs=params["bone_tol_abs"],
        bone_tol_rel=params["bone_tol_rel"],
        max_reject=params["max_reject"],
    )
    if offline:
        acc = gate_measurements(ys, times, parents, vmax, **gate_kw)
        if params["two_pass"]:
            acc_b = gate_measurements(ys[::-1], -times[::-1], parents, vmax, **gate_kw)[::-1]
            acc &= acc_b
    else:
        acc = gate_measurements(ys, times, parents, vmax, online_bones=True, **gate_kw)
    if offline and params["min_run"] > 0:
        acc = drop_short_runs(acc, ~missing & ~acc, times, params["min_run"])
    if offline and params["two_pass"]:
        acc = enforce_chain(acc, ys, times, parents, vmax, params["margin"])
    if not offline and params["min_run"] > 0:
        acc = confirm_reacquisition(acc, missing, times, params["min_run"])
        acc = enforce_chain(acc, ys, times, parents, vmax, params["margin"], backward=False)
    rejected = ~missing & ~acc
    yk = ys.copy()
    yk[~acc] = np.nan
    r_scale = inferred_r_scale(states, ~missing, factor)
    carried = np.zeros((T, J), dtype=bool)
    if params["carry"]:
        pseudo, radius = carry_with_parent(ys, acc, parents)
        if offline:  # a stretch with no earlier good offset takes the next one
            pb, rb = carry_with_parent(ys[::-1], acc[::-1], parents)
            take = ~np.isfinite(radius) & np.isfinite(rb[::-1])
            pseudo[take], radius[take] = pb[::-1][take], rb[::-1][take]
        carried = np.isfinite(pseudo).all(axis=-1)
        yk[carried] = pseudo[carried]
        # standard deviation = the bone length: the joint may have rotated about its parent
        scale = np.maximum(1.0, (np.nan_to_num(radius) / sd[None, :]) ** 2)
        rs = np.ones((T, J, 3)) if r_scale is None else r_scale.copy()
        rs[carried] = scale[carried][:, None]
        r_scale = rs
    if offline:
        est = _cv_smooth(yk, steps, params["tau"], qa, sd**2, r_scale, True)
    else:
        est = _causal_filter(
            yk, acc, steps, params["tau"], qa, sd**2, r_scale, int(params["lookback"]), carried
        )
    # no estimate before a joint's first valid measurement, none for joints never accepted
    valid = ~missing
    first = np.where(valid.any(axis=0), np.argmax(valid, axis=0), T)
    before = np.arange(T)[:, None] < first[None, :]
    est[before] = np.nan
    never = ~acc.any(axis=0)
    est[:, never] = ys[:, never]
    resolved = {"v_max": vmax.tolist(), "speed_sd": spd.tolist(), "noise_sd": sd.tolist()}
    diagnostics = {
        "rejected_fraction": rejected.sum(axis=0) / T,
        "rejected": rejected,
        "bone_lengths": L if L is not None else np.full(J, np.nan),
        "resolved": resolved,
    }
    return est, diagnostics


def _run(inp: SmoothInput, offline: bool, params: dict[str, Any]) -> SmoothOutput:
    """Runner: every body of ``inp`` gated and smoothed on its own."""
    B = inp.ys.shape[1]
    est = np.full_like(inp.ys, np.nan)
    diags = []
    for b in range(B):
        states = None if inp.tracking_state is None else inp.tracking_state[:, b]
        est[:, b], d = _robust_body(
            inp.ys[:, b],
            inp.missing[:, b],
            states,
            inp.times,
            inp.steps,
            inp.topology,
            params,
            inp.inferred_noise_factor,
            offline,
        )
        diags.append(d)
    resolved = diags[0].pop("resolved") if diags else {}
    for d in diags[1:]:
        d.pop("resolved")
    return SmoothOutput(est, diagnostics=tuple(diags), params=resolved)


def robust_smooth(
    sequence: SkeletonSequence,
    *,
    offline: bool = True,
    inferred_noise_factor: float = DEFAULT_INFERRED_NOISE_FACTOR,
    **params: Any,
) -> SkeletonSequence:
    """Reject physically impossible measurements, then smooth (module docstring).

    ``smooth(sequence, "robust", **params)`` (offline) or ``"robust_online"`` (causal)
    does the same through the registry; this is the direct form.

    Parameters
    ----------
    sequence : SkeletonSequence, positions (T, J, 3) in metres.
    offline : True (default): bone lengths from the whole recording, forward + backward
        gating, RTS smoother (interpolates across rejected stretches).  False: causal
        (online) — running bone lengths, forward gating, Kalman filter output only.
    inferred_noise_factor : variance multiplier for INFERRED joints (default 4).
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
    lookback : online only: accepted frames dropped from the state when a rejection
        starts (default 2).
    min_run : an accepted run between two rejections shorter than this (s) is rejected
        too offline, and must be confirmed for this long online (default 0.1).
    carry : rejected joints are carried along with their parent (pseudo-measurement at
        the parent plus the last good offset, standard deviation = that bone's length),
        instead of only being predicted by their own motion model (default True).

    Returns
    -------
    SkeletonSequence
        Positions replaced; ``metadata["diagnostics"]`` = ``rejected_fraction`` (J,),
        ``filled_fraction`` (J,) (missing or rejected samples that got an estimate),
        ``clipped_fraction`` (J,) zeros (no censoring here), ``rejected`` (T, J) bool
        mask, ``bone_lengths`` (J,), ``method`` (``"robust"`` / ``"robust_online"``) and
        ``params``.
    """
    if not isinstance(sequence, SkeletonSequence):
        raise TypeError(f"robust_smooth expects a SkeletonSequence, got {type(sequence).__name__}")
    offline = as_bool("offline", offline)
    factor = check_inferred_factor(inferred_noise_factor)
    unknown = sorted(set(params) - set(ROBUST_DEFAULTS))
    if unknown:
        raise ValueError(
            f"unknown parameters {unknown} for robust_smooth; valid: {sorted(ROBUST_DEFAULTS)}"
        )
    full = dict(ROBUST_DEFAULTS)
    full.update({k: ROBUST_VALIDATORS[k](k, v) for k, v in params.items()})
    T, J = sequence.n_frames, sequence.n_joints
    if T == 0:
        return sequence.replace(metadata={**sequence.metadata, "diagnostics": {}})
    states = sequence.tracking_state
    ys, missing = measurements(sequence.positions, states)
    steps = frame_steps(sequence)[0]
    est, diag = _robust_body(
        ys, missing, states, frame_times(sequence, steps), steps, sequence.topology, full,
        factor, offline,
    )  # fmt: skip
    used = {**full, **diag.pop("resolved"), "inferred_noise_factor": factor, "offline": offline}
    filled = (missing | diag["rejected"]) & np.isfinite(est).all(axis=-1)
    diagnostics = {
        **diag,
        "filled_fraction": filled.sum(axis=0) / T,
        "clipped_fraction": np.zeros(J),
        "method": "robust" if offline else "robust_online",
        "params": used,
    }
    return sequence.replace(
        positions=est, metadata={**sequence.metadata, "diagnostics": diagnostics}
    )


def _register(name: str, offline: bool, description: str) -> None:
    def run(inp: SmoothInput, **params: Any) -> SmoothOutput:
        return _run(inp, offline, params)

    register_method(
        name,
        run,
        params=ROBUST_DEFAULTS,
        validators=ROBUST_VALIDATORS,
        description=description,
        causal=not offline,
    )


_register("robust", True, "physical speed / bone-length gating, OU-velocity RTS smoother")
_register("robust_online", False, "physical speed / bone-length gating, causal OU-velocity KF")
