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

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.skeleton.sequence import SkeletonSequence

__all__ = [
    "ROBUST_DEFAULTS",
    "ROBUST_VALIDATORS",
    "bone_lengths",
    "gate_measurements",
    "joint_levels",
    "region_values",
    "robust_smooth",
]

Array = NDArray[np.float64]

#: default parameters of :func:`robust_smooth` (see docs/robust.md for the reasoning)
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
    "inferred_noise_factor": 4.0,
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


# ----------------------------------------------------------------------------- validators
_REGIONS = ("hands", "arms", "torso", "legs")


def _v_region(name: str, value: Any) -> Any:
    """A positive number, or a mapping with a positive number for every body region."""
    if isinstance(value, Mapping):
        missing = [g for g in _REGIONS if g not in value]
        extra = sorted(set(value) - set(_REGIONS))
        if missing or extra:
            raise ValueError(
                f"{name} needs one value per body region {_REGIONS}; "
                f"missing {missing}, unknown {extra}"
            )
        return {g: _v_pos(f"{name}[{g}]", value[g]) for g in _REGIONS}
    return _v_pos(name, value)


def _v_pos(name: str, value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not (v > 0):
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return v


def _v_nonneg(name: str, value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not (v >= 0):
        raise ValueError(f"{name} must be >= 0, got {value!r}")
    return v


def _v_bool(name: str, value: Any) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be true or false, got {value!r}")
    return bool(value)


def _v_int(name: str, value: Any) -> int:
    if isinstance(value, bool) or int(value) != value or int(value) < 0:
        raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
    return int(value)


#: parameter validators (name -> check(name, value) -> value), for the smooth() registry
ROBUST_VALIDATORS: dict[str, Any] = {
    "v_max": _v_region,
    "margin": _v_nonneg,
    "bone_tol_abs": _v_nonneg,
    "bone_tol_rel": _v_nonneg,
    "speed_sd": _v_region,
    "tau": _v_pos,
    "noise_sd": _v_region,
    "bones": _v_bool,
    "two_pass": _v_bool,
    "max_reject": _v_pos,
    "lookback": _v_int,
    "min_run": _v_nonneg,
    "carry": _v_bool,
}


# ----------------------------------------------------------------------------- helpers
def joint_levels(parents: tuple[int, ...] | list[int]) -> list[NDArray[np.intp]]:
    """Joint indices grouped by depth in the tree (roots first)."""
    J = len(parents)
    depth = np.full(J, -1)
    for _ in range(J + 1):
        changed = False
        for j, p in enumerate(parents):
            if depth[j] >= 0:
                continue
            if p < 0:
                depth[j] = 0
                changed = True
            elif depth[p] >= 0:
                depth[j] = depth[p] + 1
                changed = True
        if not changed:
            break
    if np.any(depth < 0):
        raise ValueError(f"parents {list(parents)} contain a cycle")
    return [np.flatnonzero(depth == d) for d in range(int(depth.max()) + 1)]


def region_values(topology: Any, values: Any, name: str) -> Array:
    """Per-joint values ``(J,)`` from a number, a ``(J,)`` array or a region mapping."""
    J = topology.n_joints
    if isinstance(values, Mapping):
        groups = topology.joint_groups()
        out = np.full(J, np.nan)
        for g, idx in groups.items():
            if idx:
                if g not in values:
                    raise ValueError(f"{name}: no value for body region {g!r}")
                out[idx] = float(values[g])
        return out
    arr = np.broadcast_to(np.asarray(values, dtype=float), (J,)).copy()
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ValueError(f"{name} must be positive, got {values!r}")
    return arr


def bone_lengths(positions: Array, parents: Any) -> Array:
    """Median length of each joint's bone to its parent over frames, ``(J,)`` (NaN for roots)."""
    pos = np.asarray(positions, dtype=float)
    J = pos.shape[1]
    out = np.full(J, np.nan)
    for j, p in enumerate(parents):
        if p < 0:
            continue
        d = np.linalg.norm(pos[:, j] - pos[:, p], axis=-1)
        d = d[np.isfinite(d)]
        if d.size:
            out[j] = float(np.median(d))
    return out


def gate_measurements(
    ys: Array,
    times: Array,
    parents: Any,
    v_max: Array,
    *,
    margin: float,
    bone_len: Array | None,
    bone_tol_abs: float,
    bone_tol_rel: float,
    online_bones: bool = False,
    max_reject: float = np.inf,
) -> NDArray[np.bool_]:
    """Causal accept / reject decision for every measurement (module docstring).

    Parameters
    ----------
    ys : (T, J, 3) measurements, NaN = missing.
    times : (T,) seconds, non-decreasing.
    parents : (J,) parent index per joint, -1 for roots.
    v_max : (J,) speed bound, m/s.
    margin : noise allowance of the speed gate, m.
    bone_len : (J,) reference bone lengths (NaN: no bone check), or None for no bone gate.
    bone_tol_abs, bone_tol_rel : bone tolerance ``abs + rel * L``.
    online_bones : use, at frame t, the median of the bone lengths of the frames accepted
        before t instead of ``bone_len`` (causal; the bone gate starts after 15 of them;
        a joint re-locked by ``max_reject`` learns its bone length again, so wrong
        first frames cannot lock it out).
    max_reject : seconds; a joint rejected for longer than this is re-acquired as soon as
        its measurement moves plausibly from the previous frame's (no lock-out when the
        reference itself was wrong).

    Returns
    -------
    (T, J) bool, True = accepted.
    """
    ys = np.asarray(ys, dtype=float)
    T, J, _ = ys.shape
    par = np.asarray(parents, dtype=int)
    levels = joint_levels(tuple(int(p) for p in par))
    acc = np.zeros((T, J), dtype=bool)
    last = np.full((J, 3), np.nan)
    last_t = np.full(J, np.nan)
    prev_acc = np.zeros(J, dtype=bool)
    rej_since = np.full(J, np.nan)
    valid_all = np.isfinite(ys).all(axis=-1)
    use_bones = bone_len is not None
    hist: list[list[float]] = [[] for _ in range(J)]
    L_cur = np.full(J, np.nan)
    for t in range(T):
        if online_bones and use_bones and t % 5 == 0:
            for j in range(J):
                if len(hist[j]) >= 15:
                    L_cur[j] = float(np.median(hist[j][-600:]))
        L = L_cur if online_bones else bone_len
        tt = times[t]
        dt_prev = times[t] - times[t - 1] if t > 0 else np.inf
        acc_t = np.zeros(J, dtype=bool)
        for idx in levels:
            y = ys[t, idx]
            valid = valid_all[t, idx]
            d = np.linalg.norm(y - last[idx], axis=-1)
            elapsed = tt - last_t[idx]
            gate = v_max[idx] * elapsed + margin
            has_last = np.isfinite(last_t[idx])
            gate_ok = ~has_last | (d <= gate)
            step_ok = prev_acc[idx] & (d <= v_max[idx] * dt_prev + margin)
            if t > 0:
                raw_step = np.linalg.norm(y - ys[t - 1, idx], axis=-1)
                relock = (tt - rej_since[idx] > max_reject) & (
                    raw_step <= v_max[idx] * dt_prev + margin
                )
            else:
                relock = np.zeros(len(idx), dtype=bool)
            p = par[idx]
            is_root = p < 0
            pp = np.where(is_root, 0, p)
            parent_acc = np.where(is_root, True, acc_t[pp])
            if use_bones:
                blen = np.linalg.norm(y - ys[t, pp], axis=-1)
                Lj = L[idx]
                tol = bone_tol_abs + bone_tol_rel * Lj
                bone_ok = ~np.isfinite(Lj) | ~(np.abs(blen - Lj) > tol)
                bone_ok |= is_root
            else:
                bone_ok = np.ones(len(idx), dtype=bool)
            ok = valid & ((gate_ok & np.where(parent_acc, bone_ok, step_ok)) | relock)
            acc_t[idx] = ok
            if online_bones and use_bones:
                # a re-lock means the learnt bone length was wrong: learn it again
                for k in np.flatnonzero(relock & ~(gate_ok & bone_ok & parent_acc)):
                    hist[idx[k]] = []
                    L_cur[idx[k]] = np.nan
                for k in np.flatnonzero(ok & parent_acc & ~is_root):
                    hist[idx[k]].append(float(blen[k]))
        upd = acc_t
        last[upd] = ys[t, upd]
        last_t[upd] = tt
        prev_acc = acc_t
        valid_t = valid_all[t]
        start = valid_t & ~acc_t & ~np.isfinite(rej_since)
        rej_since[start] = tt
        rej_since[acc_t] = np.nan
        acc[t] = acc_t
    return acc


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
    from tobitkf.core.kalman import kalman_filter, rts_smooth
    from tobitkf.core.model import LinearGaussian

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


def enforce_chain(
    acc: NDArray[np.bool_],
    ys: Array,
    times: Array,
    parents: Any,
    v_max: Array,
    margin: float,
    *,
    backward: bool = True,
) -> NDArray[np.bool_]:
    """Apply the chain rule (gate rule 3) to a combined accept mask, both ways in time.

    Offline the forward and backward gates are combined by AND, joint by joint; a wrist
    may then be accepted by both passes in frames where its elbow is rejected by one of
    them, which leaves a bridged elbow next to a failed wrist (a worse limb than either
    raw or fully bridged).  Here a joint whose parent is rejected (or missing) in frame
    ``t`` stays accepted only if it was accepted in the neighbouring frame and did not
    jump from it; the sweep runs forwards, then (unless ``backward=False``, the causal
    form used online) backwards, from the root outwards.
    """
    out = acc.copy()
    T = out.shape[0]
    par = np.asarray(parents, dtype=int)
    levels = [idx[par[idx] >= 0] for idx in joint_levels(tuple(int(p) for p in par))]
    sweeps = [(range(1, T), -1), (range(T - 2, -1, -1), 1)]
    for order, step in sweeps if backward else sweeps[:1]:
        for t in order:
            s = t + step
            bound = v_max * abs(times[t] - times[s]) + margin
            for idx in levels:
                orphan = out[t, idx] & ~out[t, par[idx]]
                if not orphan.any():
                    continue
                moved = np.linalg.norm(ys[t, idx] - ys[s, idx], axis=-1)
                keep = out[s, idx] & (moved <= bound[idx])
                out[t, idx] &= ~orphan | keep
    return out


def confirm_reacquisition(
    acc: NDArray[np.bool_], missing: NDArray[np.bool_], times: Array, min_run: float
) -> NDArray[np.bool_]:
    """Causal counterpart of :func:`drop_short_runs` for the online filter.

    After a rejection that lasted at least ``min_run`` seconds (a sustained failure, not
    a one-frame spike), a joint's measurements are believed again only once they have
    kept passing the gates for ``min_run`` seconds; until then they stay rejected.
    Inside a long failure a wrong sample sometimes passes the gates for a frame or two
    (its bone happens to fit); online we cannot look ahead, so we wait.
    """
    out = acc.copy()
    T, J = acc.shape
    if min_run <= 0 or T < 2:
        return out
    rej_begin = np.full(J, np.nan)  # start of the current rejection stretch
    conf_begin = np.full(J, np.nan)  # start of the current confirmation, if any
    for t in range(T):
        valid = ~missing[t]
        r = valid & ~acc[t]
        a = valid & acc[t]
        # a rejection starts a stretch, or continues it and cancels its confirmation
        rej_begin[r & np.isnan(rej_begin)] = times[t]
        conf_begin[r] = np.nan
        # the first accepted sample after a stretch: a long stretch needs confirmation
        first = a & np.isfinite(rej_begin) & np.isnan(conf_begin)
        long = first & (times[t] - rej_begin >= min_run)
        conf_begin[long] = times[t]
        rej_begin[first & ~long] = np.nan
        waiting = a & np.isfinite(conf_begin)
        still = waiting & (times[t] - conf_begin < min_run)
        out[t, still] = False
        done = waiting & ~still
        conf_begin[done] = np.nan
        rej_begin[done] = np.nan
    return out


def carry_with_parent(ys: Array, acc: NDArray[np.bool_], parents: Any) -> tuple[Array, Array]:
    """Pseudo-measurements that carry rejected joints along with their parents (causal).

    A rejected joint is placed at its parent's position (measured, or itself carried)
    plus the joint's offset from the parent the last time both were accepted: a hand
    whose measurement is rejected moves on with its wrist instead of staying behind in
    space.  The joint may have rotated about its parent since, so the pseudo-measurement
    is only as certain as that offset is long.

    Returns
    -------
    pseudo : (T, J, 3) positions, NaN where there is none (accepted or missing samples,
        roots, no earlier offset, no parent position).
    radius : (T, J) length of the offset used (the bone length), NaN where no pseudo.
    """
    T, J, _ = ys.shape
    par = np.asarray(parents, dtype=int)
    valid = np.isfinite(ys).all(axis=-1)
    pseudo = np.full_like(ys, np.nan)
    radius = np.full((T, J), np.nan)
    anchor = np.where(acc[..., None], ys, np.nan)
    off = np.full((J, 3), np.nan)
    levels = [idx[par[idx] >= 0] for idx in joint_levels(tuple(int(p) for p in par))]
    for t in range(T):
        for idx in levels:
            p = par[idx]
            rej = valid[t, idx] & ~acc[t, idx]
            cand = anchor[t, p] + off[idx]
            put = rej & np.isfinite(cand).all(axis=-1)
            if put.any():
                pseudo[t, idx[put]] = cand[put]
                anchor[t, idx[put]] = cand[put]
                radius[t, idx[put]] = np.linalg.norm(off[idx[put]], axis=-1)
            both = acc[t, idx] & acc[t, p]
            off[idx[both]] = ys[t, idx[both]] - ys[t, p[both]]
    return pseudo, radius


def drop_short_runs(
    acc: NDArray[np.bool_], rejected: NDArray[np.bool_], times: Array, min_run: float
) -> NDArray[np.bool_]:
    """Reject accepted runs shorter than ``min_run`` seconds lying between two rejections.

    Offline only.  Inside a long tracking failure a wrong sample sometimes passes the
    gates (its bone happens to have the right length); the RTS smoother would then bend
    the whole bridge across the failure towards that one sample.  A re-acquisition is
    believed only when it lasts ``min_run`` seconds.
    """
    out = acc.copy()
    T, J = acc.shape
    if T < 3 or min_run <= 0:
        return out
    for j in range(J):
        a = acc[:, j]
        edges = np.flatnonzero(np.diff(np.r_[0, a.astype(np.int8), 0]))
        for s, e in zip(edges[::2], edges[1::2], strict=True):  # run [s, e)
            if s == 0 or e >= T:
                continue
            # the neighbours of the run: last non-missing before, first after
            before = np.flatnonzero(rejected[:s, j] | acc[:s, j])
            after = np.flatnonzero(rejected[e:, j] | acc[e:, j])
            if not (before.size and after.size):
                continue
            if rejected[before[-1], j] and rejected[e + after[0], j]:
                if times[e - 1] - times[s] < min_run:
                    out[s:e, j] = False
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


def _times(sequence: SkeletonSequence) -> tuple[Array, Array]:
    from tobitkf.smoothing.api import frame_steps

    steps, _, _ = frame_steps(sequence)
    if sequence.timestamps is not None:
        times = np.asarray(sequence.timestamps, dtype=float)
    else:
        times = np.concatenate([[0.0], np.cumsum(steps[1:])])
    return times, steps


# ----------------------------------------------------------------------------- public
def robust_smooth(
    sequence: SkeletonSequence,
    *,
    offline: bool = True,
    v_max: Any = None,
    margin: float | None = None,
    bone_tol_abs: float | None = None,
    bone_tol_rel: float | None = None,
    speed_sd: Any = None,
    tau: float | None = None,
    noise_sd: Any = None,
    inferred_noise_factor: float | None = None,
    bones: bool | None = None,
    two_pass: bool | None = None,
    max_reject: float | None = None,
    lookback: int | None = None,
    min_run: float | None = None,
    carry: bool | None = None,
) -> SkeletonSequence:
    """Reject physically impossible measurements, then smooth (module docstring).

    Parameters
    ----------
    sequence : SkeletonSequence, positions (T, J, 3) in metres.
    offline : True (default): bone lengths from the whole recording, forward + backward
        gating, RTS smoother (interpolates across rejected stretches).  False: causal
        (online) — running bone lengths, forward gating, Kalman filter output only.
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
    inferred_noise_factor : variance multiplier for INFERRED joints (default 4).
    bones : use the bone gate (default True).
    two_pass : offline only: also gate backwards in time (default True).
    max_reject : s; a joint rejected longer than this is re-acquired as soon as it moves
        plausibly from frame to frame (default 2).
    lookback : online only: accepted frames dropped from the state when a rejection
        starts (default 2).
    min_run : offline only: an accepted run between two rejections shorter than this
        (s) is rejected too (default 0.1).
    carry : rejected joints are carried along with their parent (pseudo-measurement at
        the parent plus the last good offset, standard deviation = that bone's length),
        instead of only being predicted by their own motion model (default True).

    Returns
    -------
    SkeletonSequence
        Positions replaced; ``metadata["diagnostics"]`` = ``rejected_fraction`` (J,),
        ``filled_fraction`` (J,) (missing or rejected samples that got an estimate),
        ``clipped_fraction`` (J,) zeros (no censoring here; kept for the smooth()
        diagnostics layout), ``rejected`` (T, J) bool mask, ``bone_lengths`` (J,),
        ``method`` (``"robust"`` / ``"robust_online"``) and ``params``.
    """
    if not isinstance(sequence, SkeletonSequence):
        raise TypeError(f"robust_smooth expects a SkeletonSequence, got {type(sequence).__name__}")
    topo = sequence.topology
    given = {
        "v_max": v_max,
        "margin": margin,
        "bone_tol_abs": bone_tol_abs,
        "bone_tol_rel": bone_tol_rel,
        "speed_sd": speed_sd,
        "tau": tau,
        "noise_sd": noise_sd,
        "inferred_noise_factor": inferred_noise_factor,
        "bones": bones,
        "two_pass": two_pass,
        "max_reject": max_reject,
        "lookback": lookback,
        "min_run": min_run,
        "carry": carry,
    }
    # the registry's validators, so a direct call is checked as smooth() checks it (no
    # silent bool("no") or int(1.5)); per-joint (J,) arrays are left to region_values
    params: dict[str, Any] = {}
    for name in ROBUST_DEFAULTS:
        value = given[name]
        if value is None:
            params[name] = ROBUST_DEFAULTS[name]
        elif name == "inferred_noise_factor":
            v = _v_pos(name, value)
            if not (1.0 <= v < np.inf):
                raise ValueError(f"inferred_noise_factor must be >= 1 and finite, got {value!r}")
            params[name] = v
        elif ROBUST_VALIDATORS[name] is _v_region and np.ndim(value) > 0:
            params[name] = value
        else:
            params[name] = ROBUST_VALIDATORS[name](name, value)
    params["offline"] = bool(offline)
    vmax = region_values(topo, params["v_max"], "v_max")
    spd = region_values(topo, params["speed_sd"], "speed_sd")
    # stationary velocity variance of the OU model is q tau / 2
    qa = 2 * spd**2 / params["tau"] if np.isfinite(params["tau"]) else spd**2
    sd = region_values(topo, params["noise_sd"], "noise_sd")

    from tobitkf.smoothing.api import _inferred_r_scale, _measurements

    T, J = sequence.n_frames, sequence.n_joints
    states = sequence.tracking_state
    ys, missing = _measurements(sequence.positions, states)
    parents = topo.parents
    if T == 0:
        return sequence.replace(metadata={**sequence.metadata, "diagnostics": {}})
    times, steps = _times(sequence)
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
    r_scale = _inferred_r_scale(states, ~missing, params["inferred_noise_factor"])
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
            yk,
            acc,
            steps,
            params["tau"],
            qa,
            sd**2,
            r_scale,
            int(params["lookback"]),
            carried,
        )
    # no estimate before a joint's first valid measurement, none for joints never accepted
    valid = ~missing
    first = np.where(valid.any(axis=0), np.argmax(valid, axis=0), T)
    before = np.arange(T)[:, None] < first[None, :]
    est[before] = np.nan
    never = ~acc.any(axis=0)
    est[:, never] = ys[:, never]
    filled = (missing | rejected) & np.isfinite(est).all(axis=-1)
    used = dict(params)
    used["v_max"] = vmax.tolist()
    used["speed_sd"] = spd.tolist()
    used["noise_sd"] = sd.tolist()
    diagnostics = {
        "rejected_fraction": rejected.sum(axis=0) / T,
        "filled_fraction": filled.sum(axis=0) / T,
        "clipped_fraction": np.zeros(J),
        "rejected": rejected,
        "bone_lengths": L if L is not None else np.full(J, np.nan),
        "method": "robust" if offline else "robust_online",
        "params": used,
    }
    meta = dict(sequence.metadata)
    meta["diagnostics"] = diagnostics
    return sequence.replace(positions=est, metadata=meta)
