"""The robust smoother's gates taken from the recording itself (pixels, unknown units).

The physical defaults of :mod:`tobitkf.smoothing.robust` (speeds in m/s, margins and
noise in m) mean nothing for 2-D keypoints in pixels or for 3-D tracks in unknown units.
There, every metric parameter is derived from robust statistics of the recording (all
bodies of one call pooled, joint by joint; see docs/robust.md, "Keypoints in any unit"):

* ``noise_sd`` (per joint): ``1.4826 · median |Δ²y| / √6`` over the axes and the frames
  with three consecutive samples — the second difference of white noise of standard
  deviation σ has standard deviation σ√6, and smooth motion adds little to it;
* ``speed_sd`` (per joint): root-mean-square velocity per axis of the 5-frame running
  median of the positions (a glitch of up to two frames does not move it, nor does most
  of the jitter), over the steps up to the joint's 98th percentile of that speed;
* ``v_max`` (per joint): ``V_MAX_FACTOR`` (4) times the joint's 90th percentile of
  frame-to-frame speed, and at least the median of that over the joints (a joint that
  hardly moved in the recording may still move as fast as the others);
* above 30 fps, where these were set, the running median spans the same time (its
  frames rounded, plus one if even), and the speeds of ``v_max`` are measured over steps
  of ``SPEED_STEP`` (1/30 s: two frames at 60 fps), not over a frame: a faster
  recording's frame-to-frame step is more of its noise, which taken as speed widened the
  gate; at 30 fps and below both are as they were (:func:`speed_frames`);
* ``margin`` and ``bone_tol_abs``: ``MARGIN_SDS`` (3) standard deviations of the
  distance between two noisy samples, ``3 σ √(2 D)`` with σ the median ``noise_sd``;
* the bone gate, 3-D: ``bone_tol_rel`` = ``BONE_TOL_SPREAD`` (4) times the median over
  the bones of the relative robust spread (``1.4826 · MAD / median``) of the bone's
  length over time; 2-D: one-sided — a projected bone is foreshortened as the limb turns
  out of the image plane, anywhere between 0 and its full length, but never longer: a
  length is accepted up to ``BONE_MAX_FACTOR`` (1.1) times the bone's 95th percentile
  (plus ``bone_tol_abs``), and any shorter one is (``bone_centre``, ``bone_tol_rel = 1``).

These statistics read the whole recording, so ``robust_online`` with them is causal in
its estimates but not in its parameters. A live stream (``LiveSmoother``) has them
measured on a sample recording of the same set-up (``gates_from``), or is given all of
:data:`GATE_PARAMS` in its own units.

``gates="stream"`` (``robust_online`` only; ``LiveSmoother(gates_from="stream")``) is
the causal form: the gates are measured on every frame before frame ``n`` at the frames
``n`` of :func:`stream_gate_frames` (``STREAM_FIRST`` = 16, then each time the count of
frames doubles, up to ``STREAM_LAST`` = 4096), and hold from there to the next; the
filter starts at frame ``STREAM_FIRST``, and the frames before it are returned as
measured (no standard deviation). A stream that starts still has small gates at first,
which grow as it shows its motion.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "BONE_MAX_FACTOR",
    "BONE_TOL_SPREAD",
    "GATE_PARAMS",
    "MARGIN_SDS",
    "MEDIAN_WINDOW",
    "SPEED_STEP",
    "STREAM_FIRST",
    "STREAM_LAST",
    "V_MAX_FACTOR",
    "noise_scale",
    "recording_gates",
    "second_difference_noise",
    "stream_gate_frames",
]

Array = NDArray[np.float64]

#: v_max = V_MAX_FACTOR x the joint's 90th percentile of speed over SPEED_STEP (the
#: physical defaults are 5-17 times the typical speed of their region)
V_MAX_FACTOR = 4.0
#: speeds are measured over steps of about this long, s (one frame at 30 fps, where the
#: factors were set; the frames of a faster recording are summed into such steps: its
#: frame-to-frame step is more of its noise)
SPEED_STEP = 1.0 / 30.0
#: margin = MARGIN_SDS standard deviations of the distance between two noisy samples
MARGIN_SDS = 3.0
#: bone_tol_rel = BONE_TOL_SPREAD x the median relative spread of the bone lengths
BONE_TOL_SPREAD = 4.0
#: the longest plausible 2-D bone: this times the 95th percentile of its lengths
BONE_MAX_FACTOR = 1.1
#: frames of the running median the typical speed is measured on (above 30 fps: the
#: frames in the time these are at 30 fps, rounded, plus one if even)
MEDIAN_WINDOW = 5
#: consistency factor of the median absolute deviation for a normal distribution
_MAD = 1.4826
#: the parameters :func:`recording_gates` gives (besides the 2-D ``bone_centre``)
GATE_PARAMS = ("noise_sd", "speed_sd", "v_max", "margin", "bone_tol_abs", "bone_tol_rel")


def given_names(params: dict[str, Any]) -> frozenset[str]:
    """The parameters a caller gave, as :class:`~tobitkf.smoothing.registry.SmoothInput`
    names them: a whole value by its name, a value per body region (``v_max={"hands":
    6}``) by ``"<name>:<region>"`` for each region named, so that the regions not named
    keep what the recording measured (:func:`with_given`)."""
    out = set()
    for k, v in params.items():
        if isinstance(v, dict) and v and all(isinstance(g, str) for g in v):
            out.update(f"{k}:{g}" for g in v)
        else:
            out.add(k)
    return frozenset(out)


def is_given(name: str, given: frozenset[str]) -> bool:
    """Whether the caller gave ``name``, whole or for some body region."""
    return name in given or any(g.startswith(name + ":") for g in given)


def with_given(
    derived: dict[str, Any], params: dict[str, Any], given: frozenset[str], groups: dict
) -> dict[str, Any]:
    """The gates measured on the recording (``derived``) less what the caller gave: a
    parameter given whole is left out (the caller's stands), one given for some body
    regions keeps the measured values of the joints of the other regions, with the
    caller's at the named regions' joints (``groups``: region -> joint indices). A region
    the skeleton does not have changes nothing."""
    out = {}
    for k, v in derived.items():
        if k in given:
            continue
        named = [g.split(":", 1)[1] for g in given if g.startswith(k + ":")]
        if named and np.ndim(v) == 1:
            v = np.array(v, dtype=float)
            for region in named:
                v[list(groups.get(region, []))] = float(params[k][region])
        out[k] = v
    return out


@contextmanager
def _quiet() -> Iterator[None]:
    """Silence numpy's all-NaN-slice warnings (a joint never seen gives NaN)."""
    with warnings.catch_warnings(), np.errstate(invalid="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


def nanmedian_last(d: Array) -> Array:
    """``np.nanmedian(d, axis=-1)`` bit for bit (NaN where a row has no value), without
    its masked-array (small arrays) or ``apply_along_axis`` (large ones) machinery: a
    sort and two picks, tens of times faster on the frames of a recording."""
    s = np.sort(d, axis=-1)  # NaN last
    n = np.count_nonzero(~np.isnan(d), axis=-1)
    if s.shape[-1] == 0:
        return np.full(n.shape, np.nan)
    lo = np.maximum((n - 1) // 2, 0)[..., None]  # the two middle values (one when odd)
    hi = (n // 2)[..., None]
    lo_v = np.take_along_axis(s, lo, axis=-1)[..., 0]
    with np.errstate(invalid="ignore", over="ignore"):  # -inf and inf: NaN, as numpy's
        out = lo_v + np.take_along_axis(s, hi, axis=-1)[..., 0]
        out /= 2
    # an odd count: the middle value itself (not (x + x) / 2, which overflows near the
    # float range's end); a row without a value picks NaN
    return np.where(n % 2 == 1, lo_v, out)[()]  # [()]: a number for one row, as numpy


def nanpercentile_last(d: Array, q: float) -> Array:
    """``np.nanpercentile(d, q, axis=-1)`` bit for bit (its default linear method, the same
    operations: the virtual index ``(n - 1) q``, numpy's interpolation at both ends),
    without its ``apply_along_axis`` over rows."""
    s = np.sort(d, axis=-1)  # NaN last
    n = np.count_nonzero(~np.isnan(d), axis=-1)
    if s.shape[-1] == 0:
        return np.full(n.shape, np.nan)
    virtual = (n - 1) * np.true_divide(q, 100)
    below = np.floor(virtual)
    # at or past the last value numpy takes it twice (so the weight does not matter); a
    # row without a value picks NaN
    above = virtual >= n - 1
    lo = np.maximum(np.where(above, n - 1, below), 0).astype(np.intp)[..., None]
    hi = np.maximum(np.where(above, n - 1, below + 1), 0).astype(np.intp)[..., None]
    gamma = virtual - below
    a = np.take_along_axis(s, lo, axis=-1)[..., 0]
    b = np.take_along_axis(s, hi, axis=-1)[..., 0]
    with np.errstate(invalid="ignore", over="ignore"):
        diff = b - a
        out = np.where(gamma >= 0.5, b - diff * (1 - gamma), a + diff * gamma)
    return out[()]


def _nanmedian(a: Array, axis: Any = None) -> Any:
    """``np.nanmedian(a, axis)``: for one axis or several, the fast form (the axes moved
    last and flattened into one, as numpy itself does)."""
    if isinstance(axis, (int, np.integer)):
        axis = (axis,)
    if isinstance(axis, tuple) and axis:
        a = np.asarray(a, dtype=float)
        k = len(axis)
        moved = np.moveaxis(a, axis, tuple(range(a.ndim - k, a.ndim)))
        lead = moved.shape[: a.ndim - k]
        return nanmedian_last(moved.reshape(*lead, math.prod(moved.shape[a.ndim - k :])))
    with _quiet():
        return np.nanmedian(a, axis=axis)


def _fill(values: Array, fallback: float) -> Array:
    """Non-finite or non-positive entries replaced by ``fallback``."""
    return np.where(np.isfinite(values) & (values > 0), values, fallback)


def _running_median(y: Array, window: int) -> Array:
    """Centred running median over time (axis 0) of an odd ``window``, NaN-aware;
    shorter at the ends (compiled: :mod:`._scale_kernels`)."""
    T = y.shape[0]
    if T < window:
        return y
    from tobitkf.smoothing._scale_kernels import running_median

    flat = np.ascontiguousarray(y, dtype=float).reshape(T, -1)
    out = np.empty(flat.shape)
    running_median(flat, int(window), out)
    return out.reshape(y.shape)


def speed_frames(steps: Array) -> tuple[int, int]:
    """``(lag, window)`` for a recording whose frames come ``steps (T,)`` s after the one
    before (the first ignored; the median step counts): the frames in a step of
    ``SPEED_STEP`` (at least 1) and the running median's window: the frames in the time of
    ``MEDIAN_WINDOW`` frames at 30 fps, rounded, plus one if even (at least
    ``MEDIAN_WINDOW``); ``(1, MEDIAN_WINDOW)`` at 30 fps and below, and without a usable
    step."""
    s = np.asarray(steps, dtype=float)[1:]
    s = s[np.isfinite(s) & (s > 0)]
    if not s.size:
        return 1, MEDIAN_WINDOW
    frames = SPEED_STEP / float(np.median(s))
    lag = max(1, round(frames))
    window = round(MEDIAN_WINDOW * frames)
    window = max(MEDIAN_WINDOW, window + 1 - window % 2)
    return int(lag), int(window)


def _sums(a: Array, n: int) -> Array:
    """Sums of ``n`` consecutive values of ``a`` (``a`` itself for 1)."""
    if n == 1:
        return a
    return np.lib.stride_tricks.sliding_window_view(a, n).sum(axis=-1)


def _projected_bone_centres(y: Array, parents: Any) -> Array:
    """(B, J) half the longest plausible projected length of each bone: a 2-D bone is
    never longer than the limb itself (foreshortening only shortens it), so the bone gate
    becomes one-sided, ``0 - tol_abs <= length <= 2 * centre + tol_abs`` (``bone_tol_rel``
    = 1). The longest plausible length is ``BONE_MAX_FACTOR`` (1.1) times the 95th
    percentile of the recorded lengths (a few per cent of glitches do not reach it)."""
    B, J = y.shape[1], y.shape[2]
    out = np.full((B, J), np.nan)
    par = np.asarray(parents, dtype=np.intp)
    child = np.flatnonzero(par >= 0)
    if child.size:  # every bone at once: lengths (T, B, K), percentile over time
        length = np.sqrt(np.sum((y[:, :, child] - y[:, :, par[child]]) ** 2, axis=-1))
        out[:, child] = BONE_MAX_FACTOR * nanpercentile_last(length.transpose(1, 2, 0), 95) / 2
    return out


def second_difference_noise(ys: Array) -> tuple[float, int]:
    """White noise per axis read from the samples' second differences over time (axis 0),
    ``1.4826 · median |Δ²y| / √6`` (NaN without any), and how many differences it read."""
    y = np.asarray(ys, dtype=float)
    if y.shape[0] < 3:
        return math.nan, 0
    dd = np.abs(y[2:] - 2 * y[1:-1] + y[:-2]).reshape(-1)
    n = int(np.count_nonzero(np.isfinite(dd)))
    # np.nanmedian of a 1-D array is the median of its non-NaN values (without its
    # machinery for axes, which costs more than the median here)
    return (float(_MAD * np.median(dd[~np.isnan(dd)]) / np.sqrt(6.0)) if n else math.nan), n


def noise_scale(ys: Array) -> float:
    """The recording's measurement noise standard deviation per axis: the median over
    joints of ``noise_sd`` (:func:`second_difference_noise`), > 0."""
    sigma, _ = second_difference_noise(ys)
    return sigma if np.isfinite(sigma) and sigma > 0 else 1e-9


#: gates="stream": the frames the gates are first measured on (about half a second at
#: 30 fps; fewer give no stable median of the second differences)
STREAM_FIRST = 16
#: gates="stream": the last measurement reads this many frames (two minutes and more at
#: 30 fps); the gates then hold, and a live stream keeps no more frames than these
STREAM_LAST = 4096


def stream_gate_frames(n_frames: int) -> list[int]:
    """The frames ``n < n_frames`` at which ``gates="stream"`` measures the gates on the
    frames ``0 .. n-1``: ``STREAM_FIRST``, twice that, ... up to ``STREAM_LAST``."""
    out = []
    n = STREAM_FIRST
    while n < n_frames and n <= STREAM_LAST:
        out.append(n)
        n *= 2
    return out


def recording_gates(ys: Array, steps: Array, parents: Any, n_dims: int) -> dict[str, Any]:
    """Metric parameters of the robust methods from the recording (module docstring).

    ``ys`` (T, B, J, >= n_dims) with NaN where missing; ``steps`` (T,) seconds before
    each frame; ``parents`` (J,). Returns ``noise_sd``, ``speed_sd``, ``v_max`` (J,) and
    ``margin``, ``bone_tol_abs``, ``bone_tol_rel`` (floats), all positive, and for 2-D
    ``bone_centre`` (B, J), the bone lengths the offline gate compares with.
    """
    y = np.asarray(ys, dtype=float)[..., :n_dims]
    T, J = y.shape[0], y.shape[2]
    steps = np.asarray(steps, dtype=float)
    if T >= 3:
        dd = y[2:] - 2 * y[1:-1] + y[:-2]  # (T-2, B, J, D)
        sigma = _MAD * _nanmedian(np.abs(dd).transpose(2, 0, 1, 3).reshape(J, -1), axis=1)
        sigma = sigma / np.sqrt(6.0)
    else:
        sigma = np.full(J, np.nan)
    sigma = _fill(sigma, _nanmedian(_fill(sigma, np.nan)))
    if not (np.isfinite(sigma) & (sigma > 0)).all():
        # a degenerate recording (static, or too short): a scale from the data's spread
        # (a median over every sample: measured only when needed)
        extent = _nanmedian(np.abs(y - _nanmedian(y, axis=(0, 1))[None, None]))
        sigma = _fill(sigma, 1e-9 * float(extent) if np.isfinite(extent) and extent > 0 else 1e-9)
    if T >= 2:
        lag, window = speed_frames(steps)
        lag = min(lag, T - 1)
        dt = steps[1:, None, None]
        dl = _sums(steps[1:], lag)[:, None, None]  # the time of each step of lag frames
        v = (y[lag:] - y[:-lag]) / dl[..., None]  # (T-lag, B, J, D)
        speed = np.sqrt(np.sum(v * v, axis=-1))  # NaN where a sample is missing
        with _quiet():
            q90 = nanpercentile_last(speed.transpose(2, 0, 1).reshape(J, -1), 90)
        # the typical speed from the running median of the positions, which a glitch of
        # up to window // 2 frames does not move, and without its top 2 %
        ym = _running_median(y, window)
        vm = (ym[1:] - ym[:-1]) / dt[..., None]
        flat = vm.transpose(2, 0, 1, 3).reshape(J, -1, n_dims)
        sm = np.sqrt(np.sum(flat * flat, axis=-1))
        with _quiet():
            q98 = nanpercentile_last(sm, 98)
        # the mean square over the steps kept (np.nanmean's own sum and count, without
        # its copy: a sample left out adds 0, a kept one is finite)
        keep = np.broadcast_to((sm <= q98[:, None])[..., None], flat.shape)
        with np.errstate(invalid="ignore", divide="ignore"):
            ms = np.where(keep, flat * flat, 0.0).sum(axis=(1, 2)) / keep.sum(axis=(1, 2))
        speed_sd = np.sqrt(ms)
        vmax = V_MAX_FACTOR * q90
        vmax = np.maximum(_fill(vmax, np.nan), _nanmedian(_fill(vmax, np.nan)))
    else:
        speed_sd = vmax = np.full(J, np.nan)
    fallback_speed = float(np.median(sigma)) / float(np.median(steps)) if steps.size else 1.0
    speed_sd = _fill(_fill(speed_sd, _nanmedian(_fill(speed_sd, np.nan))), fallback_speed)
    vmax = _fill(vmax, V_MAX_FACTOR * fallback_speed)
    dist_sd = float(np.median(sigma)) * np.sqrt(2.0 * n_dims)
    out: dict[str, Any] = {
        "noise_sd": sigma,
        "speed_sd": speed_sd,
        "v_max": vmax,
        "margin": MARGIN_SDS * dist_sd,
        "bone_tol_abs": MARGIN_SDS * dist_sd,
    }
    if n_dims == 2:
        out["bone_tol_rel"] = 1.0
        out["bone_centre"] = _projected_bone_centres(y, parents)
        return out
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
    out["bone_tol_rel"] = BONE_TOL_SPREAD * float(np.median(rel)) if rel else np.inf
    return out
