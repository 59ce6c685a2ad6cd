"""Accuracy and smoothness metrics of a track against registered ground truth.

All functions take time-first arrays in the track frame, metres: ``estimate`` and
``truth`` of shape (T, J, 3) with NaN for missing samples or unpaired joints; a sample
counts only where both are finite.

Glitch classes (:func:`classify_glitches`) come from the RAW track's error, so that every
method is scored on the same samples: a sample (frame, joint) is a *glitch* when the raw
error exceeds ``threshold`` (default 0.10 m); consecutive glitch frames of one joint form an
episode; an episode of at most ``short_max`` frames (default 4) is a *short glitch*, longer
ones are *sustained*.  Everything else is *fine*.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tobitkf.evaluation.alignment import find_lag

__all__ = [
    "FINE",
    "GLITCH_CLASS_NAMES",
    "SHORT_GLITCH",
    "SUSTAINED_GLITCH",
    "classify_glitches",
    "glitch_episodes",
    "in_sd_ball",
    "joint_errors",
    "pool_shares",
    "rmse",
    "sample_share",
    "smoothness",
    "smoothness_per_component",
    "top_jumps",
    "velocity_lag",
]

FINE, SHORT_GLITCH, SUSTAINED_GLITCH = 0, 1, 2
GLITCH_CLASS_NAMES = {FINE: "fine", SHORT_GLITCH: "short_glitch", SUSTAINED_GLITCH: "sustained"}


def _check(estimate: ArrayLike, truth: ArrayLike) -> tuple[NDArray, NDArray]:
    e = np.asarray(estimate, dtype=float)
    t = np.asarray(truth, dtype=float)
    if e.shape != t.shape or e.ndim != 3 or e.shape[-1] != 3:
        raise ValueError(f"estimate {e.shape} and truth {t.shape} must both be (T, J, 3)")
    return e, t


def joint_errors(estimate: ArrayLike, truth: ArrayLike) -> NDArray[np.float64]:
    """Euclidean error per frame and joint, (T, J) metres; NaN where either is missing."""
    e, t = _check(estimate, truth)
    return np.linalg.norm(e - t, axis=-1)


def rmse(errors: ArrayLike, mask: ArrayLike | None = None) -> float:
    """Root mean square of the finite errors (optionally only where ``mask``); NaN if none."""
    err = np.asarray(errors, dtype=float)
    ok = np.isfinite(err)
    if mask is not None:
        ok &= np.asarray(mask, dtype=bool)
    return float(np.sqrt(np.mean(err[ok] ** 2))) if ok.any() else float("nan")


def in_sd_ball(
    estimate: ArrayLike, truth: ArrayLike, std: ArrayLike, level: float = 0.95
) -> NDArray[np.float64]:
    """Whether each sample's error lies in the ``level`` ball of its own uncertainty.

    A method that reports a per-axis posterior standard deviation ``sd`` claims that its
    error ``e`` (D coordinates) is Gaussian with covariance ``sd² I``; then ``|e|² / sd²`` is
    chi-square with D degrees of freedom, and ``|e|² <= chi2.ppf(level, D) * sd²`` holds with
    probability ``level``.  The share of samples for which it holds (the mean of this
    array) is the method's coverage: ``level`` when the sd is honest, less when it is too
    small (over-confident), more when it is too large.

    Parameters
    ----------
    estimate, truth : (T, J, D) positions (D = 3, or 2 for image keypoints).
    std : (T, J) per-axis standard deviation, same units.
    level : probability of the ball (default 0.95: chi2.ppf(0.95, 3) = 7.81).

    Returns
    -------
    (T, J) float: 1.0 inside, 0.0 outside, NaN where the estimate, the truth or the sd is
    missing (or the sd is not finite).
    """
    from scipy.stats import chi2

    e = np.asarray(estimate, dtype=float)
    t = np.asarray(truth, dtype=float)
    sd = np.asarray(std, dtype=float)
    if e.shape != t.shape or e.ndim != 3 or sd.shape != e.shape[:2]:
        raise ValueError(
            f"estimate {e.shape}, truth {t.shape} must be (T, J, D) and std {sd.shape} (T, J)"
        )
    sq = np.sum((e - t) ** 2, axis=-1)
    bound = chi2.ppf(level, e.shape[-1]) * sd**2
    out = (sq <= bound).astype(float)
    out[~(np.isfinite(sq) & np.isfinite(bound))] = np.nan
    return out


def sample_share(values: ArrayLike, mask: ArrayLike | None = None) -> tuple[float, int]:
    """Mean of the finite ``values`` (optionally only where ``mask``) and their number;
    ``(nan, 0)`` if none (e.g. the share of :func:`in_sd_ball` hits, with the number to
    weight it by when pooling)."""
    v = np.asarray(values, dtype=float)
    ok = np.isfinite(v)
    if mask is not None:
        ok &= np.asarray(mask, dtype=bool)
    n = int(ok.sum())
    return (float(v[ok].mean()) if n else float("nan")), n


def pool_shares(shares: Sequence[float | None], counts: Sequence[int]) -> float | None:
    """Shares of several parts (e.g. recordings) pooled by their numbers of samples:
    ``Σ n_i s_i / Σ n_i`` over the parts with samples, i.e. the share over all their
    samples; None when every share is None (no part has the quantity), NaN when no
    part has a sample."""
    if all(s is None for s in shares):
        return None
    num = den = 0.0
    for s, n in zip(shares, counts, strict=True):
        if n and s is not None and np.isfinite(s):
            num += n * s
            den += n
    return num / den if den else float("nan")


def glitch_episodes(flags: ArrayLike) -> list[tuple[int, int, int]]:
    """Runs of True along time, per joint: list of ``(joint, start, stop)`` (stop exclusive).

    Parameters
    ----------
    flags : (T, J) bool.
    """
    f = np.asarray(flags, dtype=bool)
    if f.ndim != 2:
        raise ValueError(f"flags must be (T, J), got {f.shape}")
    pad = np.zeros((1, f.shape[1]), dtype=bool)
    d = np.diff(np.vstack([pad, f, pad]).astype(np.int8), axis=0)
    out = []
    for j in range(f.shape[1]):
        starts = np.flatnonzero(d[:, j] == 1)
        stops = np.flatnonzero(d[:, j] == -1)
        out.extend((j, int(a), int(b)) for a, b in zip(starts, stops))
    return sorted(out, key=lambda x: (x[1], x[0]))


def classify_glitches(
    raw_errors: ArrayLike, threshold: float = 0.10, short_max: int = 4
) -> NDArray[np.int8]:
    """Label each (frame, joint) sample by the raw track's error (module docstring).

    Parameters
    ----------
    raw_errors : (T, J) raw-track error (m).
    threshold : glitch threshold (m), default 0.10.
    short_max : longest episode (frames) still called a short glitch, default 4.

    Returns
    -------
    (T, J) int8: ``FINE`` (0), ``SHORT_GLITCH`` (1), ``SUSTAINED_GLITCH`` (2); missing
    samples (NaN raw error) are FINE-labelled, so a caller scoring methods that fill
    gaps must take them out (:func:`~tobitkf.evaluation.evaluate.evaluate_methods` labels
    them -1).
    """
    err = np.asarray(raw_errors, dtype=float)
    flags = np.nan_to_num(err, nan=0.0) > threshold
    labels = np.zeros(err.shape, dtype=np.int8)
    for j, a, b in glitch_episodes(flags):
        labels[a:b, j] = SHORT_GLITCH if b - a <= short_max else SUSTAINED_GLITCH
    return labels


def smoothness_per_component(positions: ArrayLike) -> NDArray[np.float64]:
    """The paper's m_i (2020, eq. 41) for every coordinate of every joint.

    ``m_i = average_k (g_{k+1,i} - g_{k,i})²`` over k = 1..n-1, where ``g_{k,i}`` is
    component i (one coordinate of one joint) of the track at frame k.  Steps touching a
    missing sample are skipped.

    Parameters
    ----------
    positions : (T, J, 3) metres.

    Returns
    -------
    (J, 3) m_i in m² per frame².
    """
    p = np.asarray(positions, dtype=float)
    if p.ndim != 3 or len(p) < 2:
        raise ValueError(f"positions must be (T>=2, J, 3), got {p.shape}")
    d2 = np.diff(p, axis=0) ** 2
    with np.errstate(invalid="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return np.nanmean(d2, axis=0)


def smoothness(positions: ArrayLike, joints: Sequence[int] | None = None) -> float:
    """The paper's overall M: the average of m_i (eq. 41) over all components (m²).

    Parameters
    ----------
    positions : (T, J, 3).
    joints : restrict to these joint indices (default all joints with data).
    """
    m = smoothness_per_component(positions)
    if joints is not None:
        m = m[list(joints)]
    return float(np.nanmean(m)) if np.isfinite(m).any() else float("nan")


def velocity_lag(
    estimate: ArrayLike, truth: ArrayLike, joints: Sequence[int], max_lag: int = 10
) -> tuple[int, float, float]:
    """Lag (frames) of the estimate behind the truth from cross-correlated velocities.

    The per-frame velocity of each coordinate of each given joint (e.g. the hands) is
    correlated between estimate and truth over lags ``-max_lag..max_lag``; positive lag =
    the estimate is late (``estimate[t] ≈ truth[t - lag]``).

    Returns
    -------
    (lag, lag_refined, correlation) : int frames, sub-frame float, peak mean correlation.
    """
    e, t = _check(estimate, truth)
    j = list(joints)
    ve = np.diff(e[:, j], axis=0).reshape(len(e) - 1, -1)
    vt = np.diff(t[:, j], axis=0).reshape(len(t) - 1, -1)
    res = find_lag(vt, ve, max_lag=min(max_lag, len(vt) - 3))
    return res.lag, res.lag_refined, res.correlation


def top_jumps(
    positions: ArrayLike, joint_names: Sequence[str] | None = None, n: int = 5
) -> list[dict]:
    """The ``n`` largest one-frame jumps ``|p[t+1] - p[t]|`` of any joint.

    Returns
    -------
    list of dicts ``{"frame": t+1, "joint": name or index, "jump_m": float}``, largest first.
    """
    p = np.asarray(positions, dtype=float)
    jumps = np.linalg.norm(np.diff(p, axis=0), axis=-1)
    flat = np.nan_to_num(jumps, nan=-1.0).ravel()
    order = np.argsort(-flat, kind="stable")[:n]  # ties: earliest first
    out = []
    for k in order:
        if flat[k] < 0:
            break
        t, j = divmod(int(k), p.shape[1])
        name = joint_names[j] if joint_names is not None else j
        out.append({"frame": t + 1, "joint": name, "jump_m": float(flat[k])})
    return out
