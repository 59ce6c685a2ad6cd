"""Time alignment of a track and a motion-capture recording.

Two recordings of the same motion share no clock and no coordinate frame, so the timing is
found from *frame-independent* signals: distances between paired points (hand to pelvis,
hand to hand, head to ankle, ...), which any rigid transform leaves unchanged and which
a constant marker-to-joint offset changes only slightly.  Correlation (not squared error)
is used, so a constant bias in those distances does not matter either.

Conventions
-----------
* Mocap frame ``k`` is at track time ``offset + k / rate`` (seconds), see :func:`mocap_times`.
* A lag ``L`` (frames) means ``signal[t] ≈ reference[t - L]``: positive = the signal is late.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import minimize, minimize_scalar

__all__ = [
    "LagEstimate",
    "TimeAlignment",
    "distance_signals",
    "find_lag",
    "fit_time_alignment",
    "mocap_times",
    "resample",
]


def resample(times_src: ArrayLike, values: ArrayLike, times_dst: ArrayLike) -> NDArray[np.float64]:
    """Linear interpolation of a time-first array to new times.

    Parameters
    ----------
    times_src : (N,) strictly increasing sample times.
    values : (N, ...) samples (NaN samples propagate to the neighbouring interval).
    times_dst : (T,) query times.

    Returns
    -------
    (T, ...) interpolated values; NaN outside ``[times_src[0], times_src[-1]]``.
    """
    ts = np.asarray(times_src, dtype=float)
    td = np.asarray(times_dst, dtype=float)
    v = np.asarray(values, dtype=float)
    if ts.ndim != 1 or len(ts) != len(v):
        raise ValueError(f"resample: times {ts.shape} do not match values {v.shape}")
    if len(ts) < 2 or np.any(np.diff(ts) <= 0):
        raise ValueError("resample: source times must be strictly increasing, at least 2")
    pos = np.interp(td, ts, np.arange(len(ts), dtype=float), left=np.nan, right=np.nan)
    ok = np.isfinite(pos)
    i0 = np.clip(np.floor(np.where(ok, pos, 0)).astype(int), 0, len(ts) - 2)
    frac = np.where(ok, pos, 0) - i0
    frac = frac.reshape((-1,) + (1,) * (v.ndim - 1))
    lo, hi = v[i0], v[i0 + 1]
    with np.errstate(invalid="ignore"):
        mix = lo * (1 - frac) + hi * frac
    # an exact hit on a sample must not pick up NaN from its neighbour times 0
    out = np.where(frac == 0, lo, np.where(frac == 1, hi, mix))
    out[~ok] = np.nan
    return out


def mocap_times(
    n_frames: int,
    rate: float,
    offset: float = 0.0,
    clock: ArrayLike | None = None,
    nominal: float | None = None,
) -> NDArray[np.float64]:
    """Track-clock times of mocap frames: ``offset + k / rate``, k = 0..n-1 (seconds).

    ``clock``: the mocap's own frame times from its first (s), for a file with timestamps
    (irregular frames); they are read at its ``nominal`` rate, so that at ``rate`` they
    stretch by ``nominal / rate``: ``offset + clock * nominal / rate``."""
    if rate <= 0:
        raise ValueError(f"mocap rate must be positive, got {rate}")
    if clock is None:
        return offset + np.arange(n_frames) / float(rate)
    c = np.asarray(clock, dtype=float)
    if len(c) != n_frames:
        raise ValueError(f"clock has {len(c)} times for {n_frames} mocap frames")
    return offset + c * (float(nominal or rate) / float(rate))


def distance_signals(
    positions: ArrayLike,
    joint_pairs: Sequence[tuple[int, int]] | None = None,
) -> NDArray[np.float64]:
    """Distances between pairs of points over time (rigid-invariant signals).

    Parameters
    ----------
    positions : (T, J, 3).
    joint_pairs : pairs ``(i, j)``; default all pairs among joints that are finite somewhere.

    Returns
    -------
    (T, K) distances, K = number of pairs.
    """
    p = np.asarray(positions, dtype=float)
    if joint_pairs is None:
        ok = np.flatnonzero(np.isfinite(p).all(-1).any(0))
        joint_pairs = [(int(a), int(b)) for n, a in enumerate(ok) for b in ok[n + 1 :]]
    if not joint_pairs:
        raise ValueError("distance_signals: need at least two joints with data")
    i = np.array([a for a, _ in joint_pairs])
    j = np.array([b for _, b in joint_pairs])
    return np.linalg.norm(p[:, i] - p[:, j], axis=-1)


def _zcorr(a: NDArray[np.float64], b: NDArray[np.float64], min_overlap: int) -> float:
    """Mean over columns of the Pearson correlation on rows where both are finite."""
    ok = np.isfinite(a) & np.isfinite(b)
    n = ok.sum(axis=0)
    x = np.where(ok, a, 0.0)
    y = np.where(ok, b, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        x = np.where(ok, x - x.sum(axis=0) / n, 0.0)
        y = np.where(ok, y - y.sum(axis=0) / n, 0.0)
        den = np.sqrt((x * x).sum(axis=0) * (y * y).sum(axis=0))
        c = (x * y).sum(axis=0) / den
    use = (n >= min_overlap) & (den > 0)
    return float(c[use].mean()) if use.any() else float("nan")


@dataclass(frozen=True)
class LagEstimate:
    """Result of :func:`find_lag`.

    lag : int, best lag in frames (positive = signal late).
    lag_refined : float, sub-frame lag from a parabola through the peak.
    correlation : float, mean correlation at ``lag``.
    correlations : dict lag -> correlation over the searched range.
    """

    lag: int
    lag_refined: float
    correlation: float
    correlations: dict[int, float]

    def to_dict(self) -> dict:
        return asdict(self)


def find_lag(
    reference: ArrayLike, signal: ArrayLike, max_lag: int = 15, *, min_overlap: int = 10
) -> LagEstimate:
    """Integer lag maximising the correlation of ``signal[t]`` with ``reference[t - lag]``.

    Parameters
    ----------
    reference, signal : (T,) or (T, K) signals on the same frame grid (K are averaged).
    max_lag : search ``-max_lag .. max_lag`` frames.
    min_overlap : minimum number of overlapping finite frames per column.

    Returns
    -------
    LagEstimate
    """
    a = np.asarray(reference, dtype=float)
    b = np.asarray(signal, dtype=float)
    a = a[:, None] if a.ndim == 1 else a.reshape(len(a), -1)
    b = b[:, None] if b.ndim == 1 else b.reshape(len(b), -1)
    if a.shape != b.shape:
        raise ValueError(f"find_lag: reference {a.shape} and signal {b.shape} differ")
    T = len(a)
    if max_lag < 0 or max_lag >= T - 2:
        raise ValueError(f"find_lag: max_lag must be in [0, {T - 3}], got {max_lag}")
    corr: dict[int, float] = {}
    for lag in range(-max_lag, max_lag + 1):
        if lag >= 0:
            c = _zcorr(a[: T - lag], b[lag:], min_overlap)
        else:
            c = _zcorr(a[-lag:], b[: T + lag], min_overlap)
        corr[lag] = c
    vals = np.array([corr[k] for k in corr])
    if not np.isfinite(vals).any():
        raise ValueError("find_lag: no lag had enough overlapping finite samples")
    best = int(list(corr)[int(np.nanargmax(vals))])
    refined = float(best)
    if -max_lag < best < max_lag:
        y0, y1, y2 = corr[best - 1], corr[best], corr[best + 1]
        den = y0 - 2 * y1 + y2
        if np.isfinite(den) and den < 0:
            refined = best + 0.5 * (y0 - y2) / den
    return LagEstimate(best, refined, corr[best], corr)


@dataclass(frozen=True)
class TimeAlignment:
    """Mocap timing in the track's clock: mocap frame k is at ``offset_s + k / rate_hz``.

    correlation : mean correlation of the alignment signals at the optimum.
    overlap : fraction of track frames covered by the mocap after alignment.
    rate_fitted : whether the rate was fitted (else it was fixed to the nominal rate).
    """

    offset_s: float
    rate_hz: float
    correlation: float
    overlap: float
    rate_fitted: bool

    def to_dict(self) -> dict:
        return asdict(self)


def fit_time_alignment(
    track_times: ArrayLike,
    track_signal: ArrayLike,
    mocap_signal: ArrayLike,
    *,
    rate: float,
    fit_rate: bool = False,
    rate_range: tuple[float, float] | None = None,
    offset_range: tuple[float, float] | None = None,
    min_overlap: float = 0.5,
    grid: int = 41,
    mocap_clock: ArrayLike | None = None,
    candidates: int = 8,
) -> TimeAlignment:
    """Fit the mocap time offset (and optionally its rate) to the track.

    The score is the mean Pearson correlation, over the signal columns, of the track
    signal and the mocap signal resampled at the track times (linear interpolation),
    computed on the overlap; offsets that leave less than ``min_overlap`` of the track
    covered are rejected.  A grid search over (offset, rate) is refined by Nelder–Mead
    (a fine local grid when the rate is held), from each of the ``candidates`` best local
    maxima of the grid: in a periodic movement (gait) the next cycle's peak can top the
    grid while the true one, refined, is higher.

    Parameters
    ----------
    track_times : (T,) track frame times (s).
    track_signal : (T, K) or (T,) frame-independent signals from the track.
    mocap_signal : (N, K) or (N,) the same signals from the mocap, per mocap frame.
    rate : nominal mocap rate (Hz); the fixed rate when ``fit_rate`` is False.
    fit_rate : fit the rate too (UI-PRMD: cut separately, effective rate 80–100 Hz).
    rate_range : (lo, hi) Hz for the rate search; default ``(0.75 rate, 1.1 rate)``.
    offset_range : (lo, hi) seconds; default ± the longer recording's duration.
    min_overlap : minimum covered fraction of the track.
    grid : grid points per searched dimension.
    mocap_clock : (N,) the mocap's own frame times from its first (s), at ``rate``, for a
        mocap with timestamps (:func:`mocap_times`); default ``k / rate``.
    candidates : grid maxima refined.

    Returns
    -------
    TimeAlignment
    """
    tt = np.asarray(track_times, dtype=float)
    a = np.asarray(track_signal, dtype=float)
    b = np.asarray(mocap_signal, dtype=float)
    a = a[:, None] if a.ndim == 1 else a
    b = b[:, None] if b.ndim == 1 else b
    if len(a) != len(tt):
        raise ValueError(f"track_signal has {len(a)} rows for {len(tt)} track times")
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"track ({a.shape[1]}) and mocap ({b.shape[1]}) signal counts differ")
    N = len(b)
    if rate_range is None:
        rate_range = (0.75 * rate, 1.1 * rate) if fit_rate else (rate, rate)
    clock = None if mocap_clock is None else np.asarray(mocap_clock, dtype=float)
    span = N / rate if clock is None else float(clock[-1] - clock[0]) + 1.0 / rate
    dur = max(tt[-1] - tt[0], span * rate / rate_range[0])
    if offset_range is None:
        offset_range = (tt[0] - dur, tt[-1] + 0.0)
    need = max(int(np.ceil(min_overlap * len(tt))), 5)

    def score(offset: float, r: float) -> tuple[float, float]:
        if r <= 0:
            return -np.inf, 0.0
        mt = mocap_times(N, r, offset, clock, rate)
        res = resample(mt, b, tt)
        cover = np.isfinite(res).all(axis=1)
        if cover.sum() < need:
            return -np.inf, cover.mean()
        return _zcorr(a, res, need), float(cover.mean())

    offs = np.linspace(*offset_range, max(grid * 4, 2))
    rates = np.linspace(*rate_range, grid) if fit_rate else np.array([rate])
    table = np.array([[score(o, r)[0] for o in offs] for r in rates])  # (rates, offsets)
    if not np.isfinite(table).any():
        raise ValueError(
            "fit_time_alignment: no offset gives enough overlap (the motion capture must "
            f"cover at least {100 * min_overlap:.0f} % of the track's {tt[-1] - tt[0]:.2f} s; "
            f"it lasts {span:.2f} s at {rate:g} Hz)"
        )
    step_o = offs[1] - offs[0] if len(offs) > 1 else 0.1
    step_r = rates[1] - rates[0] if len(rates) > 1 else 1.0
    found = []
    for i, k in _grid_maxima(table, candidates):
        start = (float(table[i, k]), float(offs[k]), float(rates[i]))
        o, r = _refine(score, start, step_o, step_r, rate, rate_range, fit_rate)
        s, _ = score(o, r)
        if not (np.isfinite(s) and s >= start[0] - 1e-12):
            (s, o, r) = start
        found.append((s, o, r))
    s, o, r = max(found)
    s, cover = score(o, r)
    return TimeAlignment(o, r, float(s), float(cover), bool(fit_rate))


def _grid_maxima(table: NDArray[np.float64], n: int) -> list[tuple[int, int]]:
    """Indices (rate, offset) of the ``n`` highest local maxima of a score grid (finite
    cells at least as high as their finite neighbours), highest first."""
    t = np.where(np.isfinite(table), table, -np.inf)
    padded = np.pad(t, 1, constant_values=-np.inf)
    peak = np.isfinite(t)
    R, K = t.shape
    for di in (-1, 0, 1):
        for dk in (-1, 0, 1):
            if di or dk:
                peak &= t >= padded[1 + di : 1 + di + R, 1 + dk : 1 + dk + K]
    cells = np.argwhere(peak)
    order = np.argsort(-t[peak], kind="stable")[:n]
    return [(int(cells[j][0]), int(cells[j][1])) for j in order]


def _refine(
    score: Any,
    start: tuple[float, float, float],
    step_o: float,
    step_r: float,
    rate: float,
    rate_range: tuple[float, float],
    fit_rate: bool,
) -> tuple[float, float]:
    """A grid maximum refined: Nelder–Mead over (offset, rate), or a fine grid of
    offsets when the rate is held."""
    _, o0, r0 = start
    if not fit_rate:  # a fine grid, then a bounded scalar search between its points
        fine = np.linspace(o0 - step_o, o0 + step_o, 81)
        vals = np.array([score(o, rate)[0] for o in fine])
        if not np.isfinite(vals).any():
            return o0, float(rate)
        o1 = float(fine[int(np.nanargmax(np.where(np.isfinite(vals), vals, np.nan)))])
        h = fine[1] - fine[0]

        def g(o: float) -> float:
            s, _ = score(o, rate)
            return -s if np.isfinite(s) else 1e3

        res = minimize_scalar(g, bounds=(o1 - h, o1 + h), method="bounded",
                              options={"xatol": 1e-6})  # fmt: skip
        o2 = float(res.x)
        return (o2 if g(o2) <= g(o1) else o1), float(rate)

    def f(x: NDArray[np.float64]) -> float:
        if not rate_range[0] <= x[1] <= rate_range[1]:
            return 1e3
        s, _ = score(x[0], x[1])
        return -s if np.isfinite(s) else 1e3

    res = minimize(
        f,
        np.array([o0, r0]),
        method="Nelder-Mead",
        options={
            "initial_simplex": np.array([[o0, r0], [o0 + step_o, r0], [o0, r0 + step_r]]),
            "xatol": 1e-4,
            "fatol": 1e-7,
            "maxiter": 400,
        },
    )
    return float(res.x[0]), float(res.x[1])
