"""Down-weighting the accepted samples the smoothed track does not explain (``robust``'s
``reweight``; docs/robust.md, Method 7).

The gates reject what is physically impossible. A sample can pass them and still be off
by far more than the noise: a keypoint that flicks to a neighbouring limb for a frame,
the first frames of a failure that enters slowly, a depth sensor's joint that wobbles
for a few frames. A Gaussian smoother gives such a sample the full weight of a good one.
The offline smoother therefore runs again with Huber's weights (an M-estimate by
iteratively reweighted least squares, as robust LOWESS does): each accepted sample's
residual from the previous pass, standardised by the recording's own residual scale,
and where it is beyond Huber's cut ``k`` the sample's variance is multiplied by
``|d| / k`` (its weight ``k / |d|``). Inside the cut nothing changes, so the fitted
noise keeps its meaning.

* The residual of a sample is its distance to the smoothed position (all axes at once),
  divided by the square root of the sample's own variance factor (INFERRED samples and
  keypoint confidences give larger ones).
* The scale is each joint's own, per body: the median of the squared standardised
  residuals over its accepted samples divided by the median of the chi-square
  distribution with as many degrees of freedom as the data have axes (what the median
  is for Gaussian noise), so that a recording's share of flicker does not inflate it.
  It is never below the white noise the samples themselves show in their second
  differences (the statistic the gates in pixels use), and neither reads a sample that
  repeats the one before it to the last bit (a joint the tracker holds, a repeated
  video frame, a synthetic joint at rest): a recording without noise leaves residuals
  near zero, and differences of rounding would otherwise count as outliers.
* The cut ``k`` is the 99 % point of the chi distribution with those degrees of
  freedom (3.37 in 3-D, 3.03 in 2-D): one good sample in a hundred is down-weighted, a
  little.
* Joints with fewer than :data:`MIN_SAMPLES` accepted samples that show their noise,
  or a zero scale, keep their weights.

Nothing here is fitted to data: the weight function, the cut and the scale estimate are
the textbook ones, and the number of passes (two: Cleveland's robust LOWESS) bounds the
cost; the floor is a guard against recordings without noise. numpy and scipy, no I/O.
"""

from __future__ import annotations

from functools import cache

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from tobitkf.smoothing.robust_scale import nanmedian_last

__all__ = [
    "HUBER_LEVEL",
    "MIN_SAMPLES",
    "HuberWeights",
    "held",
    "huber_cut",
    "huber_inflation",
    "white_noise",
]

#: the share of Gaussian samples inside Huber's cut
HUBER_LEVEL = 0.99
#: fewest accepted samples of a joint whose residuals give its scale
MIN_SAMPLES = 10


def huber_cut(n_dims: int) -> float:
    """Huber's cut on a standardised residual of ``n_dims`` axes: the :data:`HUBER_LEVEL`
    point of the chi distribution with ``n_dims`` degrees of freedom."""
    return float(np.sqrt(chi2.ppf(HUBER_LEVEL, n_dims)))


@cache
def _chi_point(dof: int) -> tuple[float, float]:
    return float(chi2.median(dof)), huber_cut(dof)


def _chi_points(dof: NDArray[np.int_]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The chi-square median and Huber's cut for each degrees of freedom in ``dof``
    (small integers: a few distinct values; scipy's quantiles cost more than the pass of a
    short window that :class:`~tobitkf.DelayedSmoother` runs per frame)."""
    values, index = np.unique(dof, return_inverse=True)
    points = np.array([_chi_point(int(v)) for v in values]).reshape(-1, 2)
    at = points[index.reshape(dof.shape)]  # (..., 2)
    return at[..., 0], at[..., 1]


#: the normal's standard deviation over its median absolute deviation
_MAD = 1.4826


class HuberWeights:
    """The variance multipliers of Huber's weights for one recording's samples.

    ``ys`` ``(T, B, J, D)`` the samples, ``use`` ``(T, B, J)`` the accepted ones (only
    they are weighed), ``rinf`` ``(T, B, J)`` each sample's variance factor (1 for a
    plain sample). What does not depend on the estimate is computed once: the axes that
    carry coordinates (where some accepted sample is not zero: a 2-D sequence stored
    with a third axis of zeros has 2, the residual's degrees of freedom), the samples that
    show their noise (accepted, not :func:`held`) and their :func:`white_noise`. Calling
    the object with a pass's estimate ``est`` (the shape of ``ys``) gives the multiplier
    ``(T, B, J)`` (>= 1; 1 where not weighed) of each sample for the next pass."""

    def __init__(
        self, ys: NDArray[np.float64], use: NDArray[np.bool_], rinf: NDArray[np.float64]
    ) -> None:
        self.ys, self.rinf = ys, rinf
        self.ok = use & np.isfinite(ys).all(axis=-1)
        live = np.any(np.where(self.ok[..., None], ys, 0.0) != 0, axis=0)  # (B, J, D)
        dof = live.sum(axis=-1)
        self.own = self.ok & ~held(ys)  # the samples that show their noise
        self.enough = (self.own.sum(axis=0) >= MIN_SAMPLES) & (dof > 0)
        self.chi_median, self.cut = _chi_points(np.maximum(dof, 1))
        self.floor = white_noise(ys, self.own, live) ** 2

    def __call__(self, est: NDArray[np.float64]) -> NDArray[np.float64]:
        d2 = np.sum((self.ys - est) ** 2, axis=-1) / self.rinf
        scale = np.full(self.enough.shape, np.nan)
        if self.enough.any():
            med = nanmedian_last(np.moveaxis(np.where(self.own, d2, np.nan), 0, -1)[self.enough])
            scale[self.enough] = np.fmax(med / self.chi_median[self.enough],
                                         self.floor[self.enough])  # fmt: skip
        good = self.enough & (scale > 0)
        with np.errstate(invalid="ignore"):
            d = np.sqrt(np.where(self.ok, d2, np.nan) / np.where(good, scale, np.nan)[None])
        infl = np.maximum(1.0, d / self.cut[None])  # NaN: not weighed
        return np.where(np.isfinite(infl), infl, 1.0)


def huber_inflation(
    ys: NDArray[np.float64],
    est: NDArray[np.float64],
    use: NDArray[np.bool_],
    rinf: NDArray[np.float64],
) -> NDArray[np.float64]:
    """``HuberWeights(ys, use, rinf)(est)``: one pass's multipliers."""
    return HuberWeights(ys, use, rinf)(est)


def held(ys: NDArray[np.float64]) -> NDArray[np.bool_]:
    """``(T, B, J)``: the sample is the one before it, to the last bit, on every axis (a
    tracker holding a joint, a repeated video frame, a synthetic joint at rest)."""
    out = np.zeros(ys.shape[:-1], dtype=bool)
    out[1:] = np.all(ys[1:] == ys[:-1], axis=-1)
    return out


def white_noise(
    ys: NDArray[np.float64], ok: NDArray[np.bool_], live: NDArray[np.bool_]
) -> NDArray[np.float64]:
    """Per body and joint ``(B, J)``, the white noise per axis of the samples marked in
    ``ok`` ``(T, B, J)``, on the axes marked in ``live`` ``(B, J, D)``, read from their
    second differences over three consecutive frames (``1.4826 · median |Δ²y| / √6``, as
    :func:`tobitkf.smoothing.robust_scale.second_difference_noise`); NaN without any."""
    y = np.where(ok[..., None] & live[None], ys, np.nan)
    dd = np.abs(y[2:] - 2 * y[1:-1] + y[:-2])
    T2, B, J, D = dd.shape
    flat = np.moveaxis(dd, 0, 2).reshape(B, J, T2 * D)
    return _MAD * nanmedian_last(flat) / np.sqrt(6.0)
