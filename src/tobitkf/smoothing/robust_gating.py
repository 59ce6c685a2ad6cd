"""The robust smoother's gates: which measurements are physically possible.

Speed gate, bone gate, chain rule, re-acquisition after ``max_reject``, offline
``min_run`` (:func:`drop_short_runs`) and the chain rule on the combined mask
(:func:`enforce_chain`), online confirmation (:func:`confirm_reacquisition`), and the
pseudo-measurements that carry a rejected joint with its parent
(:func:`carry_with_parent`). The rules and their reasons are in
:mod:`tobitkf.smoothing.robust` and docs/robust.md. Arrays are ``(T, J, 3)`` positions
with NaN for missing samples and ``(T, J)`` accept masks; time is looped over, joints
are vectorised.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "bone_lengths",
    "carry_with_parent",
    "confirm_reacquisition",
    "drop_short_runs",
    "enforce_chain",
    "gate_measurements",
    "joint_levels",
    "region_values",
]

Array = NDArray[np.float64]


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
