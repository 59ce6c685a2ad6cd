"""The robust smoother's gates: which measurements are physically possible.

Speed gate, bone gate, chain rule, re-acquisition after ``max_reject``, offline
``min_run`` (:func:`drop_short_runs`) and the chain rule on the combined mask
(:func:`enforce_chain`), online confirmation (:func:`confirm_reacquisition`), and the
pseudo-measurements that carry a rejected joint with its parent
(:func:`carry_with_parent`), and the sensor's guessed (INFERRED) joints put back at
their bone's length (:func:`project_inferred`). The rules and their reasons are in
:mod:`tobitkf.smoothing.robust` and docs/robust.md. Arrays are ``(T, J, 3)`` positions
with NaN for missing samples and ``(T, J)`` accept masks.

The rules are implemented once, as compiled kernels in
:mod:`tobitkf.smoothing._robust_kernels` (imported on first use, so that importing
tobitkf does not import numba); the functions here are their one-body forms.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tobitkf.smoothing.robust_scale import _MAD

__all__ = [
    "GIRDLE_JOINTS",
    "GIRDLE_MIN_SAMPLES",
    "GIRDLE_SPREAD",
    "bone_lengths",
    "carry_with_parent",
    "clavicle_elevation",
    "confirm_reacquisition",
    "drop_short_runs",
    "enforce_chain",
    "gate_measurements",
    "girdle_joints",
    "joint_levels",
    "joint_order",
    "kernels",
    "mirror_bones",
    "project_inferred",
    "region_values",
    "reject_dropped_shoulders",
]

Array = NDArray[np.float64]


def joint_levels(parents: tuple[int, ...] | list[int]) -> list[NDArray[np.intp]]:
    """Joint indices grouped by depth in the tree (roots first)."""
    return [level.copy() for level in _levels(tuple(int(p) for p in parents))]


@functools.lru_cache(maxsize=64)
def _levels(parents: tuple[int, ...]) -> list[NDArray[np.intp]]:
    """:func:`joint_levels`, cached (a live smoother asks at every frame)."""
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
    arr = np.asarray(values, dtype=float)
    if arr.ndim > 0 and arr.shape != (J,):
        raise ValueError(
            f"{name}: one number, one per body region, or one per joint ({J} for topology "
            f"{topology.name!r}); got {arr.size} values"
        )
    arr = np.broadcast_to(arr, (J,)).copy()
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ValueError(f"{name} must be positive, got {values!r}")
    return arr


def kernels() -> Any:
    """The compiled kernels module (imports numba on first use)."""
    from tobitkf.smoothing import _robust_kernels

    return _robust_kernels


def joint_order(parents: Any) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """``(parents, order)`` as the kernels take them: int64 parents and the joints sorted
    by depth in the tree (roots first)."""
    par = np.ascontiguousarray(parents, dtype=np.int64)
    levels = joint_levels(tuple(int(p) for p in par))
    return par, np.ascontiguousarray(np.concatenate(levels), dtype=np.int64)


def _gate_params(J: int, v_max: Any, margin: float, tol_abs: float = np.inf,
                 tol_rel: float = np.inf) -> tuple[Array, Array]:  # fmt: skip
    k = kernels()
    pj = np.zeros((J, k.N_PJ))
    pj[:, k.J_VMAX] = np.broadcast_to(np.asarray(v_max, dtype=float), (J,))
    pj[:, k.J_MIRROR] = -1  # no mirror rule (it needs the topology's pairs)
    pf = np.zeros(k.N_PF)
    pf[k.P_MARGIN], pf[k.P_TOL_ABS], pf[k.P_TOL_REL] = margin, tol_abs, tol_rel
    return pj, pf


def _body(a: Any, dtype: Any = float) -> NDArray[Any]:
    """(T, J, ...) -> (T, 1, J, ...) contiguous, the kernels' layout."""
    return np.ascontiguousarray(np.asarray(a, dtype=dtype)[:, None])


def bone_lengths(positions: Array, parents: Any) -> Array:
    """Median length of each joint's bone to its parent over frames (NaN for roots).

    ``positions (T, ..., J, 3)`` gives ``(..., J)``: one length per joint of every body.
    """
    pos = np.asarray(positions, dtype=float)
    T, J = pos.shape[0], pos.shape[-2]
    if T == 0 or pos.size == 0:
        return np.full(pos.shape[1:-1], np.nan)
    flat = np.ascontiguousarray(pos.reshape(T, -1, J, 3))
    par, _ = joint_order(parents)
    return kernels().bone_lengths_run(flat, par).reshape(pos.shape[1:-1])


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
    inferred: NDArray[np.bool_] | None = None,
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
        before t (the last 600 of them, refreshed every 5 frames) instead of ``bone_len``
        (causal; the bone gate starts after 15 of them; a joint re-locked by
        ``max_reject`` learns its bone length again, so wrong first frames cannot lock
        it out).
    max_reject : seconds; a joint rejected for longer than this is re-acquired as soon as
        its measurement moves plausibly from the previous frame's (no lock-out when the
        reference itself was wrong).
    inferred : (T, J) the sensor's guessed (INFERRED) samples, which are no witness of
        the bone gate's blame; None: none.

    Returns
    -------
    (T, J) bool, True = accepted.
    """
    y = _body(ys)
    J = y.shape[2]
    par, order = joint_order(parents)
    pj, pf = _gate_params(J, v_max, margin, bone_tol_abs, bone_tol_rel)
    L = np.full((1, J), np.nan) if bone_len is None else np.asarray(bone_len, float)[None]
    k = kernels()
    acc = np.zeros(y.shape[:3], dtype=bool)
    guess = (np.zeros(y.shape[:3], dtype=bool) if inferred is None
             else np.ascontiguousarray(np.asarray(inferred, dtype=bool)[:, None]))  # fmt: skip
    k.gate_pass(
        y, np.ascontiguousarray(times, dtype=float), par, order, pj, pf,
        np.ascontiguousarray(L), guess, bone_len is not None, bool(online_bones),
        float(max_reject), k.new_state(1, J, 0), False, acc,
    )  # fmt: skip
    return acc[:, 0]


#: the shoulder-girdle rule's joints: the spine joint below the shoulder centre, the
#: shoulder centre, and the two shoulders (Kinect's names; other skeletons: no rule)
GIRDLE_JOINTS = ("SpineMid", "SpineShoulder", "ShoulderLeft", "ShoulderRight")
#: the rule's threshold is at least this many robust standard deviations of the
#: recording's own clavicle angle (the usual outlier bound of a modified z-score)
GIRDLE_SPREAD = 3.5
#: fewer accepted angles than this (a second at 30 fps) describe no posture: no rule
GIRDLE_MIN_SAMPLES = 30


def mirror_bones(topology: Any) -> NDArray[np.intp]:
    """``(J,)``: for each joint the joint whose bone (to its parent) is the mirror image of
    its own, -1 for none: the topology's left/right pairs whose parents are the same joint
    (shoulders, hips) or a pair too (elbow and elbow). The online bone gate's mirror rule
    (docs/robust.md, Method 6) compares the lengths learnt for the two."""
    parents = [int(p) for p in topology.parents]
    mirror = topology.mirror_indices()
    out = np.full(len(parents), -1, dtype=np.intp)
    for a, b in enumerate(mirror):
        pa, pb = parents[a], parents[b]
        if b != a and pa >= 0 and pb >= 0 and mirror[pa] == pb:
            out[a] = b
    return out


def girdle_joints(joints: Any) -> tuple[int, int, int, int] | None:
    """The indices of :data:`GIRDLE_JOINTS` in ``joints``, or None when one is absent."""
    names = list(joints)
    if not all(n in names for n in GIRDLE_JOINTS):
        return None
    a, b, c, d = (names.index(n) for n in GIRDLE_JOINTS)
    return a, b, c, d


def clavicle_elevation(ys: Array, girdle: tuple[int, int, int, int]) -> Array:
    """``(T, B, 2)`` degrees: each clavicle's (shoulder centre to left / right shoulder)
    angle above the plane perpendicular to the spine axis (spine joint to shoulder
    centre) at the shoulder centre, of ``ys (T, B, J, 3)``; NaN where a joint is
    missing."""
    y = np.asarray(ys, dtype=float)
    sm, ss = y[:, :, girdle[0]], y[:, :, girdle[1]]
    with np.errstate(invalid="ignore", divide="ignore"):
        axis = (ss - sm) / np.linalg.norm(ss - sm, axis=-1, keepdims=True)
        out = np.empty((*y.shape[:2], 2))
        for k, j in enumerate(girdle[2:]):
            c = y[:, :, j] - ss
            c = c / np.linalg.norm(c, axis=-1, keepdims=True)
            out[..., k] = np.degrees(np.arcsin(np.clip(np.sum(c * axis, axis=-1), -1, 1)))
    return out


def reject_dropped_shoulders(
    acc: NDArray[np.bool_], ys: Array, girdle: tuple[int, int, int, int], drop: float
) -> NDArray[np.bool_]:
    """The shoulder-girdle rule (offline; docs/robust.md, Method 5): a shoulder whose
    clavicle points further below the recording's own usual angle than ``drop`` degrees,
    or than ``GIRDLE_SPREAD`` robust standard deviations of that angle if more, is
    rejected. The usual angle and its spread are the median and the scaled MAD over the
    frames where the shoulder, the shoulder centre and the spine joint were accepted
    (at least ``GIRDLE_MIN_SAMPLES`` of them). ``acc (T, B, J)`` is not changed."""
    out = acc.copy()
    if not np.isfinite(drop):
        return out
    elev = clavicle_elevation(ys, girdle)
    sm, ss = girdle[0], girdle[1]
    for k, j in enumerate(girdle[2:]):
        for b in range(acc.shape[1]):
            e = elev[:, b, k]
            x = e[acc[:, b, j] & acc[:, b, ss] & acc[:, b, sm] & np.isfinite(e)]
            if x.size < GIRDLE_MIN_SAMPLES:
                continue
            usual = float(np.median(x))
            spread = _MAD * float(np.median(np.abs(x - usual)))
            with np.errstate(invalid="ignore"):
                out[:, b, j] &= ~(usual - e > max(drop, GIRDLE_SPREAD * spread))
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
    y = _body(ys)
    par, order = joint_order(parents)
    pj, _ = _gate_params(y.shape[2], v_max, margin)
    out = kernels().enforce_chain_run(
        _body(acc, bool), y, np.ascontiguousarray(times, dtype=float), par, order, pj,
        float(margin), bool(backward),
    )  # fmt: skip
    return out[:, 0]


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
    out = kernels().confirm_run(
        _body(acc, bool), _body(missing, bool), np.ascontiguousarray(times, dtype=float),
        float(min_run),
    )  # fmt: skip
    return out[:, 0]


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
    par, order = joint_order(parents)
    pseudo, radius = kernels().carry_run(_body(ys), _body(acc, bool), par, order, False)
    return pseudo[:, 0], radius[:, 0]


def project_inferred(ys: Array, inferred: NDArray[np.bool_], parents: Any, lengths: Array) -> Array:
    """The INFERRED joints put back at their bone's length (per frame, roots outwards).

    A joint the sensor only guessed (occluded: Kinect's INFERRED) is often wrong by a
    drift of the whole guessed chain, while its bone keeps its length: the joint keeps
    its direction from its parent (as placed by the parent's own correction) and moves
    to the distance ``lengths[j]`` from it. An inferred joint whose parent is inferred
    too first moves with the parent's correction. Tracked and missing joints, roots, and
    joints without a parent position or a length (NaN) are not projected.

    ``ys (T, J, 3)``, ``inferred (T, J)``, ``lengths (J,)``; returns a new ``(T, J, 3)``.
    """
    par, order = joint_order(parents)
    L = np.ascontiguousarray(np.asarray(lengths, dtype=float).reshape(1, -1))
    return kernels().project_run(_body(ys), _body(inferred, bool), par, order, L)[:, 0]


def drop_short_runs(
    acc: NDArray[np.bool_], rejected: NDArray[np.bool_], times: Array, min_run: float
) -> NDArray[np.bool_]:
    """Reject accepted runs shorter than ``min_run`` seconds lying between two rejections.

    Offline only.  Inside a long tracking failure a wrong sample sometimes passes the
    gates (its bone happens to have the right length); the RTS smoother would then bend
    the whole bridge across the failure towards that one sample.  A re-acquisition is
    believed only when it lasts ``min_run`` seconds.
    """
    out = kernels().drop_short_runs_run(
        _body(acc, bool), _body(rejected, bool), np.ascontiguousarray(times, dtype=float),
        float(min_run),
    )  # fmt: skip
    return out[:, 0]
