"""``robust_scale.recording_gates`` against the form it had before it was made faster,
kept here as the reference (the noise, speed and margin parameters, which changed; the
bone gates' did not): the same gates bit for bit, so the outputs of every
recording in pixels or unknown units stay what they were. Property-based: any number of
frames, bodies and joints, 2-D and 3-D, missing samples, still joints and recordings
without a usable sample."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tobitkf.smoothing.robust_scale import (
    _MAD,
    MARGIN_SDS,
    MEDIAN_WINDOW,
    V_MAX_FACTOR,
    _fill,
    _nanmedian,
    _running_median,
    nanpercentile_last,
    recording_gates,
    speed_frames,
)


def _reference(ys, steps, parents, n_dims):
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        y = np.asarray(ys, dtype=float)[..., :n_dims]
        T, J = y.shape[0], y.shape[2]
        extent = _nanmedian(np.abs(y - _nanmedian(y, axis=(0, 1))[None, None]))
        tiny = 1e-9 * float(extent) if np.isfinite(extent) and extent > 0 else 1e-9
        if T >= 3:
            dd = y[2:] - 2 * y[1:-1] + y[:-2]
            sigma = _MAD * _nanmedian(np.abs(dd).transpose(2, 0, 1, 3).reshape(J, -1), axis=1)
            sigma = sigma / np.sqrt(6.0)
        else:
            sigma = np.full(J, np.nan)
        sigma = _fill(_fill(sigma, _nanmedian(_fill(sigma, np.nan))), tiny)
        if T >= 2:
            # speeds over about 1/30 s, and a running median of about 5 frames at 30 fps
            pos = steps[1:][np.isfinite(steps[1:]) & (steps[1:] > 0)]
            per30 = (1 / 30) / np.median(pos) if pos.size else 1.0
            lag = min(max(1, round(per30)), T - 1)
            w = round(MEDIAN_WINDOW * per30)
            window = max(MEDIAN_WINDOW, w + 1 if w % 2 == 0 else w)
            dt = steps[1:, None, None]
            dl = np.array([steps[1 + t : 1 + t + lag].sum() for t in range(T - lag)])
            v = (y[lag:] - y[:-lag]) / dl[:, None, None, None]
            speed = np.sqrt(np.sum(v * v, axis=-1))
            q90 = nanpercentile_last(speed.transpose(2, 0, 1).reshape(J, -1), 90)
            ym = _running_median(y, window)
            vm = (ym[1:] - ym[:-1]) / dt[..., None]
            flat = vm.transpose(2, 0, 1, 3).reshape(J, -1, n_dims)
            sm = np.sqrt(np.sum(flat * flat, axis=-1))
            q98 = nanpercentile_last(sm, 98)
            ms = np.nanmean(np.where((sm <= q98[:, None])[..., None], flat * flat, np.nan),
                            axis=(1, 2))  # fmt: skip
            speed_sd = np.sqrt(ms)
            vmax = V_MAX_FACTOR * q90
            vmax = np.maximum(_fill(vmax, np.nan), _nanmedian(_fill(vmax, np.nan)))
        else:
            speed_sd = vmax = np.full(J, np.nan)
        fallback = float(np.median(sigma)) / float(np.median(steps)) if steps.size else 1.0
        speed_sd = _fill(_fill(speed_sd, _nanmedian(_fill(speed_sd, np.nan))), fallback)
        vmax = _fill(vmax, V_MAX_FACTOR * fallback)
        dist_sd = float(np.median(sigma)) * np.sqrt(2.0 * n_dims)
        return {"noise_sd": sigma, "speed_sd": speed_sd, "v_max": vmax,
                "margin": MARGIN_SDS * dist_sd, "bone_tol_abs": MARGIN_SDS * dist_sd}  # fmt: skip


@settings(max_examples=150, deadline=None)
@given(
    T=st.integers(0, 40),
    B=st.integers(1, 3),
    J=st.integers(1, 5),
    dims=st.sampled_from([2, 3]),
    missing=st.sampled_from([0.0, 0.2, 0.7, 1.0]),
    still=st.booleans(),
    seed=st.integers(0, 2**16),
    rate=st.sampled_from([15.0, 30.0, 60.0, 120.0]),
)
def test_the_gates_are_the_references(T, B, J, dims, missing, still, seed, rate):
    rng = np.random.default_rng(seed)
    y = np.cumsum(rng.normal(0, 3, (T, B, J, dims)), axis=0) + 100 * rng.random((1, B, J, 1))
    if still and T:  # joints that never move (a recording that may be all still)
        frozen = rng.random(J) < 0.5
        y[:, :, frozen] = y[:1, :, frozen]
    y[rng.random((T, B, J)) < missing] = np.nan
    steps = np.full(T, 1 / rate) * rng.uniform(0.5, 1.5, T)
    parents = [-1] + [int(rng.integers(0, j)) for j in range(1, J)]
    got = recording_gates(y, steps, parents, dims)
    want = _reference(y, steps, parents, dims)
    for k in want:  # (the bone gates' parameters are not computed differently)
        np.testing.assert_array_equal(got[k], want[k], err_msg=k)


@pytest.mark.parametrize("seed", range(3))
def test_v_max_does_not_grow_with_the_frame_rate(seed):
    # a keypoint moving the same way (peak speed about 314 px/s) with 2 px of white noise,
    # recorded at 30, 60 and 120 fps: the frame-to-frame step of the faster recordings is
    # more of the noise (2 px at 120 fps is 340 px/s per axis), which taken as speed
    # would widen the speed gate; measured over steps of 1/30 s, v_max stays that of 30
    # fps (over seeds it moves by about 1 %)
    vmax = {}
    for fps in (30.0, 60.0, 120.0):
        rng = np.random.default_rng(seed)
        t = np.arange(int(20 * fps)) / fps
        y = np.stack([100 * np.sin(np.pi * t), 50 * np.cos(0.6 * np.pi * t)], -1)
        y = (y + rng.normal(0, 2.0, y.shape))[:, None, None, :]
        vmax[fps] = recording_gates(y, np.full(len(t), 1 / fps), [-1], 2)["v_max"][0]
    assert vmax[60.0] == pytest.approx(vmax[30.0], rel=0.05)
    assert vmax[120.0] == pytest.approx(vmax[30.0], rel=0.05)
    assert speed_frames(np.full(10, 1 / 30)) == (1, MEDIAN_WINDOW)
    assert speed_frames(np.full(10, 1 / 15)) == (1, MEDIAN_WINDOW)
    assert speed_frames(np.full(10, 1 / 60)) == (2, 11)
    assert speed_frames(np.full(10, 1 / 120)) == (4, 21)
    assert speed_frames(np.full(10, 1 / 50)) == (2, 9)  # 8.3 frames: 8, made odd
