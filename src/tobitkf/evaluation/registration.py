"""Robust rigid registration of a skeleton track onto motion-capture points.

The model (all positions in metres, time-first):

    track[t, j] ≈ R · (mocap[t, j] + offset_j(t)) + shift            (weighted, robust)

where ``mocap[t, j]`` is the mocap point paired with track joint ``j`` (already resampled
to the track's frame times), ``R`` a rotation (det +1), ``shift`` a translation, and the
per-pair offset either

* ``"none"``:  ``offset_j(t) = 0``;
* ``"world"``: a constant vector in the mocap world frame, ``offset_j(t) = o_j``;
* ``"body"``:  a constant vector in the mocap target's own frame,
  ``offset_j(t) = Q_j(t) · o_j`` with ``Q_j(t)`` the target's rotation (from its quaternion).

Markers and rigid-body targets sit on the skin, not at joint centres, so some offset is
always needed; a target that rotates with its segment (KERAAL) keeps a fixed offset in its
own frame.  The fit alternates a weighted Kabsch/Umeyama solve for ``(R, shift)`` with a
weighted mean for the offsets, inside an iteratively reweighted least-squares loop (Tukey
bisquare on the residual norm) whose scale is annealed from 0.5 m down to the robust scale
(1.4826 × median residual), so that tracking glitches (e.g. a hand 1 m off for 40 frames)
do not pull the transform, yet nothing is rejected before the fit is close.  World-frame
offsets are solved in closed form per joint (per-joint centring) after an offset-free
start; body-frame offsets start from the world-frame fit.  It is fitted once, on the raw
track, and then held fixed for every smoothing method
(:func:`RigidRegistration.truth_in_track_frame`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

OffsetMode = Literal["none", "world", "body"]

__all__ = [
    "OffsetMode",
    "RigidRegistration",
    "choose_quaternion_order",
    "fit_registration",
    "kabsch",
    "quat_to_matrix",
]


def kabsch(
    source: ArrayLike,
    target: ArrayLike,
    weights: ArrayLike | None = None,
    *,
    scale: bool = False,
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Weighted least-squares similarity transform ``target ≈ s R source + t`` (Umeyama 1991).

    Parameters
    ----------
    source, target : (N, 3) arrays of corresponding points (rows with NaN are ignored).
    weights : (N,) non-negative weights, default all 1.
    scale : fit the scale ``s`` too (Umeyama); default ``False`` (``s = 1``, Kabsch).

    Returns
    -------
    R : (3, 3) rotation, det +1.
    t : (3,) translation.
    s : float scale (1.0 when ``scale=False``).
    """
    src = np.asarray(source, dtype=float).reshape(-1, 3)
    dst = np.asarray(target, dtype=float).reshape(-1, 3)
    if src.shape != dst.shape:
        raise ValueError(f"kabsch: source {src.shape} and target {dst.shape} differ in shape")
    w = np.ones(len(src)) if weights is None else np.asarray(weights, dtype=float).reshape(-1)
    if w.shape != (len(src),):
        raise ValueError(f"kabsch: weights must have shape ({len(src)},), got {w.shape}")
    ok = np.isfinite(src).all(axis=1) & np.isfinite(dst).all(axis=1) & np.isfinite(w) & (w > 0)
    if ok.sum() < 3:
        raise ValueError(f"kabsch: need at least 3 finite weighted pairs, found {int(ok.sum())}")
    src, dst, w = src[ok], dst[ok], w[ok]
    w = w / w.sum()
    mu_s = w @ src
    mu_d = w @ dst
    xs = src - mu_s
    xd = dst - mu_d
    cov = (xd * w[:, None]).T @ xs  # (3, 3) = sum w (d - mu_d)(s - mu_s)^T
    u, sig, vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(u) * np.linalg.det(vt))
    d = 1.0 if d == 0 else d
    corr = np.diag([1.0, 1.0, d])
    rot = u @ corr @ vt
    s = 1.0
    if scale:
        var_s = float(w @ np.sum(xs**2, axis=1))
        s = float(np.sum(sig * np.diag(corr)) / var_s) if var_s > 0 else 1.0
    t = mu_d - s * rot @ mu_s
    return rot, t, s


def quat_to_matrix(q: ArrayLike, order: Literal["xyzw", "wxyz"] = "xyzw") -> NDArray[np.float64]:
    """Rotation matrices from quaternions (normalised first).

    Parameters
    ----------
    q : (..., 4) quaternions; all-zero or non-finite quaternions give NaN matrices.
    order : component order in the last axis, ``"xyzw"`` (scalar last) or ``"wxyz"``.

    Returns
    -------
    (..., 3, 3) rotation matrices ``M`` such that ``M @ v`` rotates ``v`` from the body frame
    to the world frame.
    """
    q = np.asarray(q, dtype=float)
    if q.shape[-1] != 4:
        raise ValueError(f"quat_to_matrix: last axis must have length 4, got shape {q.shape}")
    if order == "xyzw":
        x, y, z, w = np.moveaxis(q, -1, 0)
    elif order == "wxyz":
        w, x, y, z = np.moveaxis(q, -1, 0)
    else:
        raise ValueError(f"quat_to_matrix: order must be 'xyzw' or 'wxyz', got {order!r}")
    n = np.sqrt(w * w + x * x + y * y + z * z)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.where(n > 1e-12, n, np.nan)
        w, x, y, z = w / n, x / n, y / n, z / n
    m = np.empty((*q.shape[:-1], 3, 3))
    m[..., 0, 0] = 1 - 2 * (y * y + z * z)
    m[..., 0, 1] = 2 * (x * y - z * w)
    m[..., 0, 2] = 2 * (x * z + y * w)
    m[..., 1, 0] = 2 * (x * y + z * w)
    m[..., 1, 1] = 1 - 2 * (x * x + z * z)
    m[..., 1, 2] = 2 * (y * z - x * w)
    m[..., 2, 0] = 2 * (x * z - y * w)
    m[..., 2, 1] = 2 * (y * z + x * w)
    m[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return m


@dataclass(frozen=True)
class RigidRegistration:
    """A fitted registration of mocap points onto a track (see the module docstring).

    Attributes
    ----------
    rotation : (3, 3) ``R``.
    translation : (3,) ``shift`` (track frame, metres).
    scale : float (1.0 unless fitted with ``scale=True``).
    offsets : (J, 3) per-pair offsets ``o_j`` (mocap world frame for ``"world"``, target frame
        for ``"body"``, zeros for ``"none"``); NaN for unpaired joints.
    offset_mode : ``"none"``, ``"world"`` or ``"body"``.
    weights : (T, J) final robust weights in [0, 1] (0 = treated as outlier / missing).
    residual_rms : float, RMS residual (metres) over inlier samples (weight > 0.5).
    robust_scale : float, final robust residual scale (metres).
    inlier_fraction : float, fraction of finite samples with weight > 0.5.
    n_iterations : int.
    quaternion_order : str or None, the order used for ``"body"`` offsets.
    """

    rotation: NDArray[np.float64]
    translation: NDArray[np.float64]
    scale: float
    offsets: NDArray[np.float64]
    offset_mode: OffsetMode
    weights: NDArray[np.float64] = field(repr=False)
    residual_rms: float
    robust_scale: float
    inlier_fraction: float
    n_iterations: int
    quaternion_order: str | None = None

    def transform_points(self, points: ArrayLike) -> NDArray[np.float64]:
        """Apply ``s R p + shift`` to points of shape (..., 3) (mocap frame → track frame)."""
        p = np.asarray(points, dtype=float)
        return self.scale * p @ self.rotation.T + self.translation

    def truth_in_track_frame(
        self, mocap: ArrayLike, target_rotations: ArrayLike | None = None
    ) -> NDArray[np.float64]:
        """Registered ground truth for each track joint.

        Parameters
        ----------
        mocap : (T, J, 3) paired mocap points (mocap frame, metres), NaN where unpaired.
        target_rotations : (T, J, 3, 3) target rotations, required for ``"body"`` offsets.

        Returns
        -------
        (T, J, 3) ``R (mocap + offset(t)) + shift`` in the track frame.
        """
        m = np.asarray(mocap, dtype=float)
        return self.transform_points(
            m + _offset_seq(self.offsets, self.offset_mode, m, target_rotations)
        )

    def summary(self) -> dict:
        """JSON-ready summary (rotation as nested lists, lengths in metres)."""
        return {
            "rotation": self.rotation.tolist(),
            "translation_m": self.translation.tolist(),
            "scale": self.scale,
            "offset_mode": self.offset_mode,
            "offset_norms_m": np.linalg.norm(self.offsets, axis=-1).tolist(),
            "residual_rms_m": self.residual_rms,
            "robust_scale_m": self.robust_scale,
            "inlier_fraction": self.inlier_fraction,
            "n_iterations": self.n_iterations,
            "quaternion_order": self.quaternion_order,
        }


def _offset_seq(
    offsets: NDArray[np.float64],
    mode: OffsetMode,
    mocap: NDArray[np.float64],
    target_rotations: ArrayLike | None,
) -> NDArray[np.float64]:
    """Offsets as a (T, J, 3) array in the mocap world frame."""
    o = np.nan_to_num(offsets)
    if mode == "none":
        return np.zeros_like(mocap)
    if mode == "world":
        return np.broadcast_to(o, mocap.shape)
    if target_rotations is None:
        raise ValueError("body-frame offsets need target_rotations of shape (T, J, 3, 3)")
    rots = np.asarray(target_rotations, dtype=float)
    if rots.shape != (*mocap.shape, 3):
        raise ValueError(f"target_rotations must have shape {(*mocap.shape, 3)}, got {rots.shape}")
    out = np.einsum("tjab,jb->tja", rots, o)
    # Joints whose target has no orientation fall back to a zero offset.
    return np.where(np.isfinite(out), out, 0.0)


def _tukey(r: NDArray[np.float64], c: float) -> NDArray[np.float64]:
    u = r / c
    return np.where(u < 1.0, (1.0 - u * u) ** 2, 0.0)


def fit_registration(
    track: ArrayLike,
    mocap: ArrayLike,
    *,
    offset_mode: OffsetMode = "world",
    target_rotations: ArrayLike | None = None,
    scale: bool = False,
    tukey_c: float = 4.685,
    anneal_start: float = 0.5,
    anneal_rate: float = 0.7,
    min_scale: float = 0.005,
    max_iter: int = 100,
    tol: float = 1e-7,
    quaternion_order: str | None = None,
) -> RigidRegistration:
    """Fit ``track ≈ R (mocap + offset) + shift`` robustly (module docstring).

    Parameters
    ----------
    track : (T, J, 3) raw track (track frame, metres); NaN = missing.
    mocap : (T, J, 3) mocap point paired with each joint, resampled to the track frames
        (mocap frame, metres); NaN = unpaired / missing.
    offset_mode : ``"none"``, ``"world"`` (default) or ``"body"``.
    target_rotations : (T, J, 3, 3) target rotations (mocap frame) for ``"body"``.
    scale : also fit a global scale (Umeyama).  Default ``False``.
    tukey_c : Tukey bisquare constant in units of the residual scale.
    anneal_start, anneal_rate : graduated non-convexity: the residual scale starts at
        ``anneal_start`` metres (so the first solve is plain least squares) and shrinks by
        ``anneal_rate`` per iteration down to the robust scale
        ``1.4826 · median(|residual|)`` (floored at ``min_scale``).  Rejecting samples only
        gradually keeps the fit from locking onto a wrong start, e.g. from discarding the
        one moving arm that pins the rotation down when everything else stands still.
    max_iter, tol : IRLS stopping rule (max change of the transformed points, metres).
    quaternion_order : label stored in the result (for reporting only).

    Returns
    -------
    RigidRegistration
    """
    return _fit_registration(
        track, mocap, offset_mode=offset_mode, target_rotations=target_rotations, scale=scale,
        tukey_c=tukey_c, anneal_start=anneal_start, anneal_rate=anneal_rate,
        min_scale=min_scale, max_iter=max_iter, tol=tol, quaternion_order=quaternion_order,
    )  # fmt: skip


def _fit_registration(
    track: ArrayLike,
    mocap: ArrayLike,
    *,
    offset_mode: OffsetMode = "world",
    target_rotations: ArrayLike | None = None,
    scale: bool = False,
    tukey_c: float = 4.685,
    anneal_start: float = 0.5,
    anneal_rate: float = 0.7,
    min_scale: float = 0.005,
    max_iter: int = 100,
    tol: float = 1e-7,
    quaternion_order: str | None = None,
    world_start: RigidRegistration | None = None,
) -> RigidRegistration:
    """:func:`fit_registration`; ``world_start`` is the world-offset fit that a body-offset
    fit starts from, when the caller already has it (:func:`choose_quaternion_order`)."""
    y = np.asarray(track, dtype=float)
    m = np.asarray(mocap, dtype=float)
    if y.ndim != 3 or y.shape[-1] != 3:
        raise ValueError(f"track must have shape (T, J, 3), got {y.shape}")
    if m.shape != y.shape:
        raise ValueError(f"mocap must have the track's shape {y.shape}, got {m.shape}")
    if offset_mode not in ("none", "world", "body"):
        raise ValueError(f"offset_mode must be 'none', 'world' or 'body', got {offset_mode!r}")
    if not (anneal_start > 0 and 0 < anneal_rate < 1):
        raise ValueError("anneal_start must be > 0 and anneal_rate in (0, 1)")
    T, J, _ = y.shape
    rots = None
    if offset_mode == "body":
        if target_rotations is None:
            raise ValueError("offset_mode='body' needs target_rotations (T, J, 3, 3)")
        rots = np.asarray(target_rotations, dtype=float)
        if rots.shape != (T, J, 3, 3):
            raise ValueError(f"target_rotations must have shape {(T, J, 3, 3)}, got {rots.shape}")
        # A joint whose target has no orientation falls back to a world offset of zero.
        rots = np.where(np.isfinite(rots), rots, 0.0)
    finite = np.isfinite(y).all(-1) & np.isfinite(m).all(-1)
    if finite.sum() < 3:
        raise ValueError("fit_registration: fewer than 3 finite paired samples")
    offsets = np.zeros((J, 3))
    w = finite.astype(float)
    R, t, s = np.eye(3), np.zeros(3), 1.0
    prev = None
    sigma = np.inf
    n_it = 0

    def wmean(a: NDArray, w: NDArray) -> NDArray:
        """Per-joint weighted mean over time of (T, J, 3); median where no weight is left."""
        ww = np.where(finite, w, 0.0)
        num = np.sum(np.where(finite[..., None], a, 0.0) * ww[..., None], axis=0)
        den = ww.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            out = num / den[:, None]
        empty = den <= 1e-9
        if not empty.any():
            return out
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # unpaired joints: all NaN
            med = np.nanmedian(np.where(finite[:, empty, None], a[:, empty], np.nan), axis=0)
        out[empty] = np.nan_to_num(med)
        return out

    def solve_offsets(R, t, s, w):
        # residual in mocap frame: R^T (y - t)/s - m  ≈ offset (world), Q^T of it (body)
        back = np.einsum("ba,tjb->tja", R, y - t) / s - m
        if offset_mode == "body":
            back = np.einsum("tjba,tjb->tja", rots, back)
        return wmean(back, w)

    def residuals(R, t, s, offsets):
        pred = s * (m + _offset_seq(offsets, offset_mode, m, rots)) @ R.T + t
        return np.linalg.norm(y - pred, axis=-1), pred

    paired = finite.any(axis=0)
    if offset_mode == "world":
        # start from the offset-free fit: the whole skeleton's shape pins the rotation down,
        # whereas per-joint offsets leave only the motion to do it (little when most joints
        # stand still, e.g. one arm raised), so a random start could lock onto noise
        init = _fit_registration(
            y, m, offset_mode="none", scale=scale, tukey_c=tukey_c, anneal_start=anneal_start,
            anneal_rate=anneal_rate, min_scale=min_scale, max_iter=max_iter, tol=tol,
        )  # fmt: skip
    if offset_mode == "body":
        # start from the world-offset fit: its rotation, weights and (time-median) offsets
        init = world_start if world_start is not None else _fit_registration(
            y, m, offset_mode="world", scale=scale, tukey_c=tukey_c, anneal_start=anneal_start,
            anneal_rate=anneal_rate, min_scale=min_scale, max_iter=max_iter, tol=tol,
        )  # fmt: skip
        R, t, s = init.rotation, init.translation, init.scale
        offsets = solve_offsets(R, t, s, np.zeros_like(w))  # plain medians
    for it in range(max_iter):
        n_it = it + 1
        if offset_mode == "none":
            R, t, s = kabsch(m[finite], y[finite], w[finite], scale=scale)
        elif offset_mode == "world":
            if it == 0:
                R, s = init.rotation, init.scale
            else:
                # per-joint centring removes the (unknown) offsets from the rotation fit
                mc = m - wmean(m, w)
                yc = y - wmean(y, w)
                R, _, s = kabsch(mc[finite], yc[finite], w[finite], scale=scale)
            c = wmean(y - s * m @ R.T, w)  # (J, 3) = t + s R o_j
            t = c[paired].mean(axis=0)
            offsets = (c - t) @ R / s
        else:
            src = m + _offset_seq(offsets, offset_mode, m, rots)
            R, t, s = kabsch(src[finite], y[finite], w[finite], scale=scale)
            offsets = solve_offsets(R, t, s, w)
        r, pred = residuals(R, t, s, offsets)
        rf = r[finite]
        robust = max(1.4826 * float(np.median(rf)), min_scale)
        annealing = anneal_start * anneal_rate**it
        sigma = max(robust, annealing)
        w = np.where(finite, _tukey(np.where(finite, r, np.inf), tukey_c * sigma), 0.0)
        if prev is not None and annealing < robust:
            change = float(np.nanmax(np.abs(pred - prev)))
            if change < tol:
                break
        prev = pred
    r, _ = residuals(R, t, s, offsets)
    inl = finite & (w > 0.5)
    rms = float(np.sqrt(np.mean(r[inl] ** 2))) if inl.any() else float("nan")
    offsets = np.where(finite.any(axis=0)[:, None], offsets, np.nan)
    return RigidRegistration(
        rotation=R,
        translation=t,
        scale=s,
        offsets=offsets,
        offset_mode=offset_mode,
        weights=w,
        residual_rms=rms,
        robust_scale=sigma,
        inlier_fraction=float(inl.sum() / max(finite.sum(), 1)),
        n_iterations=n_it,
        quaternion_order=quaternion_order,
    )


def choose_quaternion_order(
    track: ArrayLike,
    mocap: ArrayLike,
    quaternions: ArrayLike,
    **kwargs,
) -> tuple[RigidRegistration, dict[str, float]]:
    """Fit body-frame offsets with both quaternion orders and keep the better one.

    The quaternion order of a data set is often undocumented or documented wrongly; the
    order under which a constant offset in the target's frame explains the track best (the
    smaller robust residual) is the right one.

    Parameters
    ----------
    track, mocap : (T, J, 3) as in :func:`fit_registration`.
    quaternions : (T, J, 4) target quaternions paired with each joint (NaN/zero = none).
    **kwargs : passed to :func:`fit_registration`.

    Returns
    -------
    best : RigidRegistration (``quaternion_order`` set).
    scores : dict order -> inlier residual RMS (metres) for ``"xyzw"`` and ``"wxyz"``.
    """
    # both orders start from the same world-offset fit: compute it once
    world = fit_registration(track, mocap, offset_mode="world", **kwargs)
    fits = {}
    for order in ("xyzw", "wxyz"):
        rots = quat_to_matrix(quaternions, order=order)
        fits[order] = _fit_registration(
            track,
            mocap,
            offset_mode="body",
            target_rotations=rots,
            quaternion_order=order,
            world_start=world,
            **kwargs,
        )
    # Compare by a robust score that does not depend on each fit's own inlier choice.
    scores = {k: float(f.robust_scale) for k, f in fits.items()}
    best = min(fits, key=lambda k: (scores[k], fits[k].residual_rms))
    return fits[best], {k: fits[k].residual_rms for k in fits} | {
        f"{k}_robust_scale": scores[k] for k in fits
    }
