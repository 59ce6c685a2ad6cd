"""The robust smoother's gates taken from the recording itself (pixels, unknown units).

The physical defaults of :mod:`tobitkf.smoothing.robust` (speeds in m/s, margins and
noise in m) mean nothing for 2-D keypoints in pixels or for 3-D tracks in unknown units.
There, every metric parameter is derived from robust statistics of the recording (all
bodies of one call pooled, joint by joint; see docs/robust.md, "Keypoints in any unit"):

* ``noise_sd`` (per joint): ``1.4826 · median |Δ²y| / √6`` over the axes and the frames
  with three consecutive samples — the second difference of white noise of standard
  deviation σ has standard deviation σ√6, and smooth motion adds little to it;
* ``speed_sd`` (per joint): root-mean-square velocity per axis over the steps up to the
  joint's 90th percentile of speed (glitches, a few per cent of the steps, are above it),
  with the noise's share ``2 σ² / dt²`` taken off (at least a tenth of it is kept);
* ``v_max`` (per joint): ``V_MAX_FACTOR`` (4) times the joint's 90th percentile of
  frame-to-frame speed, and at least the median of that over the joints (a joint that
  hardly moved in the recording may still move as fast as the others);
* ``margin`` and ``bone_tol_abs``: ``MARGIN_SDS`` (3) standard deviations of the
  distance between two noisy samples, ``3 σ √(2 D)`` with σ the median ``noise_sd``;
* ``bone_tol_rel``: ``BONE_TOL_SPREAD`` (4) times the median over the bones of the
  relative robust spread (``1.4826 · MAD / median``) of the bone's length over time — a
  2-D bone is foreshortened as the limb turns out of the image plane, so its length varies
  by as much as the recording shows, not by a fixed 15 %.

These statistics read the whole recording, so ``robust_online`` with them is causal in
its estimates but not in its parameters; live smoothing needs ``gates="physical"`` and
values in the data's units.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["BONE_TOL_SPREAD", "MARGIN_SDS", "V_MAX_FACTOR", "recording_gates"]

Array = NDArray[np.float64]

#: v_max = V_MAX_FACTOR x the joint's 90th percentile of frame-to-frame speed (the
#: physical defaults are 5-17 times the typical speed of their region)
V_MAX_FACTOR = 4.0
#: margin = MARGIN_SDS standard deviations of the distance between two noisy samples
MARGIN_SDS = 3.0
#: bone_tol_rel = BONE_TOL_SPREAD x the median relative spread of the bone lengths
BONE_TOL_SPREAD = 4.0
#: consistency factor of the median absolute deviation for a normal distribution
_MAD = 1.4826


@contextmanager
def _quiet() -> Iterator[None]:
    """Silence numpy's all-NaN-slice warnings (a joint never seen gives NaN)."""
    with warnings.catch_warnings(), np.errstate(invalid="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


def _nanmedian(a: Array, axis: Any = None) -> Any:
    with _quiet():
        return np.nanmedian(a, axis=axis)


def _fill(values: Array, fallback: float) -> Array:
    """Non-finite or non-positive entries replaced by ``fallback``."""
    return np.where(np.isfinite(values) & (values > 0), values, fallback)


def recording_gates(ys: Array, steps: Array, parents: Any, n_dims: int) -> dict[str, Any]:
    """Metric parameters of the robust methods from the recording (module docstring).

    ``ys`` (T, B, J, >= n_dims) with NaN where missing; ``steps`` (T,) seconds before
    each frame; ``parents`` (J,). Returns ``noise_sd``, ``speed_sd``, ``v_max`` (J,) and
    ``margin``, ``bone_tol_abs``, ``bone_tol_rel`` (floats), all positive.
    """
    y = np.asarray(ys, dtype=float)[..., :n_dims]
    T, J = y.shape[0], y.shape[2]
    steps = np.asarray(steps, dtype=float)
    # a scale for degenerate recordings (static, or too short): the spread of the data
    extent = _nanmedian(np.abs(y - _nanmedian(y, axis=(0, 1))[None, None]))
    tiny = 1e-9 * float(extent) if np.isfinite(extent) and extent > 0 else 1e-9
    if T >= 3:
        dd = y[2:] - 2 * y[1:-1] + y[:-2]  # (T-2, B, J, D)
        sigma = _MAD * _nanmedian(np.abs(dd).transpose(2, 0, 1, 3).reshape(J, -1), axis=1)
        sigma = sigma / np.sqrt(6.0)
    else:
        sigma = np.full(J, np.nan)
    sigma = _fill(_fill(sigma, _nanmedian(_fill(sigma, np.nan))), tiny)
    if T >= 2:
        dt = steps[1:, None, None]
        v = (y[1:] - y[:-1]) / dt[..., None]  # (T-1, B, J, D)
        speed = np.sqrt(np.sum(v * v, axis=-1))  # NaN where a sample is missing
        flat_speed = speed.transpose(2, 0, 1).reshape(J, -1)
        with _quiet():
            q90 = np.nanpercentile(flat_speed, 90, axis=1)
        inner = flat_speed <= q90[:, None]
        v2 = np.where(inner[..., None], (v * v).transpose(2, 0, 1, 3).reshape(J, -1, n_dims),
                      np.nan)  # fmt: skip
        with _quiet():
            ms = np.nanmean(v2.reshape(J, -1), axis=1)
        noise_v = 2 * sigma**2 / float(np.median(steps)) ** 2
        speed_sd = np.sqrt(np.maximum(ms - noise_v, 0.01 * ms))
        vmax = V_MAX_FACTOR * q90
        vmax = np.maximum(_fill(vmax, np.nan), _nanmedian(_fill(vmax, np.nan)))
    else:
        speed_sd = vmax = np.full(J, np.nan)
    fallback_speed = float(np.median(sigma)) / float(np.median(steps)) if steps.size else 1.0
    speed_sd = _fill(_fill(speed_sd, _nanmedian(_fill(speed_sd, np.nan))), fallback_speed)
    vmax = _fill(vmax, V_MAX_FACTOR * fallback_speed)
    dist_sd = float(np.median(sigma)) * np.sqrt(2.0 * n_dims)
    rel = []
    for j, p in enumerate(parents):
        if p < 0:
            continue
        length = np.sqrt(np.sum((y[:, :, j] - y[:, :, p]) ** 2, axis=-1)).ravel()
        length = length[np.isfinite(length)]
        if length.size >= 3:
            med = float(np.median(length))
            if med > 0:
                rel.append(_MAD * float(np.median(np.abs(length - med))) / med)
    tol_rel = BONE_TOL_SPREAD * float(np.median(rel)) if rel else np.inf
    return {
        "noise_sd": sigma,
        "speed_sd": speed_sd,
        "v_max": vmax,
        "margin": MARGIN_SDS * dist_sd,
        "bone_tol_abs": MARGIN_SDS * dist_sd,
        "bone_tol_rel": tol_rel,
    }
