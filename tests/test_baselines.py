"""Tests of the baseline smoothers against independent scalar references."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tobitkf.smoothing.baselines import (
    KINECT_PRESETS,
    kinect_double_exponential,
    moving_average,
    one_euro,
    savgol,
)

# --------------------------------------------------------------------------- references


class _LowPass:
    """Exponential low-pass filter, as in the 1€ paper's pseudo-code."""

    def __init__(self) -> None:
        self.first = True
        self.hatxprev = 0.0

    def filter(self, x: float, alpha: float) -> float:
        if self.first:
            self.first = False
            hatx = x
        else:
            hatx = alpha * x + (1 - alpha) * self.hatxprev
        self.hatxprev = hatx
        return hatx


class _OneEuroRef:
    """Scalar 1€ filter transcribed from Casiez, Roussel, Vogel (2012), Algorithm."""

    def __init__(self, mincutoff: float, beta: float, dcutoff: float) -> None:
        self.first = True
        self.mincutoff, self.beta, self.dcutoff = mincutoff, beta, dcutoff
        self.xfilt = _LowPass()
        self.dxfilt = _LowPass()
        self.tprev = 0.0

    @staticmethod
    def alpha(rate: float, cutoff: float) -> float:
        tau = 1.0 / (2 * math.pi * cutoff)
        te = 1.0 / rate
        return 1.0 / (1.0 + tau / te)

    def __call__(self, x: float, t: float) -> float:
        if self.first:
            self.first = False
            dx = 0.0
            rate = 1.0  # unused: both low-pass filters return their input the first time
        else:
            rate = 1.0 / (t - self.tprev)
            dx = (x - self.xfilt.hatxprev) * rate
        self.tprev = t
        edx = self.dxfilt.filter(dx, self.alpha(rate, self.dcutoff))
        cutoff = self.mincutoff + self.beta * abs(edx)
        return self.xfilt.filter(x, self.alpha(rate, cutoff))


def _kinect_ref(series, states, s, c, pred, jitter, maxdev):
    """Scalar-loop transcription of the SDK sample FilterDoubleExponential::Update, one joint.

    series: list of 3-tuples; states: list of ints. Invalid frames (NaN / not tracked)
    follow the documented deviation: output raw, reset, next valid frame restarts.
    """
    jitter = max(1e-4, jitter)
    out = []
    count = 0
    prev_raw = prev_f = prev_trend = None
    for raw, st_ in zip(series, states, strict=True):
        raw = np.array(raw, dtype=float)
        if np.any(np.isnan(raw)) or st_ == 0:
            count = 0
            out.append(raw)
            continue
        jr, md = (2 * jitter, 2 * maxdev) if st_ == 1 else (jitter, maxdev)
        if count == 0:
            f = raw.copy()
            trend = np.zeros(3)
        elif count == 1:
            f = (raw + prev_raw) * 0.5
            diff = f - prev_f
            trend = diff * c + prev_trend * (1 - c)
        else:
            diff = raw - prev_f
            fdiff = abs(math.sqrt(float(diff @ diff)))
            if fdiff <= jr:
                f = raw * (fdiff / jr) + prev_f * (1 - fdiff / jr)
            else:
                f = raw.copy()
            f = f * (1 - s) + (prev_f + prev_trend) * s
            diff = f - prev_f
            trend = diff * c + prev_trend * (1 - c)
        count += 1
        p = f + trend * pred
        diff = p - raw
        fdiff = abs(math.sqrt(float(diff @ diff)))
        if fdiff > md:
            p = p * (md / fdiff) + raw * (1 - md / fdiff)
        prev_raw, prev_f, prev_trend = raw, f, trend
        out.append(p)
    return np.array(out)


# --------------------------------------------------------------------------- savgol


@settings(deadline=None, max_examples=30)
@given(
    coeffs=st.lists(st.floats(-2, 2), min_size=4, max_size=4),
    T=st.integers(12, 60),
    half=st.integers(2, 5),
)
def test_savgol_cubic_passes_unchanged(coeffs, T, half):
    t = np.linspace(-1, 1, T)
    y = np.polyval(coeffs, t)
    x = np.stack([y, 2 * y, -y], axis=-1)[:, None, :]  # (T, 1, 3)
    out = savgol(x, window=2 * half + 1, polyorder=3)
    np.testing.assert_allclose(out, x, atol=1e-9)


def test_savgol_interior_is_local_least_squares_fit():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(40, 2, 3))
    out = savgol(x, window=7, polyorder=2)
    u = np.arange(-3, 4)
    for k in range(3, 37):
        for j in range(2):
            for d in range(3):
                coef = np.polyfit(u, x[k - 3 : k + 4, j, d], 2)
                assert out[k, j, d] == pytest.approx(np.polyval(coef, 0.0), abs=1e-10)


def test_savgol_nan_handling():
    T = 30
    t = np.arange(T, dtype=float)
    y = 0.01 * t**2 - 0.2 * t + 1.0  # quadratic: exact for polyorder 2
    x = np.stack([y, y, y], axis=-1)[:, None, :].repeat(2, axis=1)
    x[:4, 0, :] = np.nan  # leading gap on joint 0
    x[-3:, 0, 1] = np.nan  # trailing gap on one coordinate
    x[15, 1, :] = np.nan  # one-frame interior gap on joint 1
    x[20:26, 1, 2] = np.nan  # long interior gap
    out = savgol(x, window=5, polyorder=2, max_gap=3)
    assert np.all(np.isnan(out[:4, 0, :]))
    assert np.all(np.isnan(out[-3:, 0, 1]))
    assert np.all(np.isnan(out[20:26, 1, 2]))
    # exact where the span is gap-free and polynomial
    np.testing.assert_allclose(out[4:, 0, 0], y[4:], atol=1e-9)
    np.testing.assert_allclose(out[4:-3, 0, 1], y[4:-3], atol=1e-9)
    # the one-frame gap is filled (linear interpolation then smoothing: close to y)
    assert np.all(np.isfinite(out[15, 1, :]))
    np.testing.assert_allclose(out[15, 1, :], y[15], atol=0.02)


def test_savgol_short_series_and_errors():
    x = np.array([1.0, 2.0, 4.0])
    out = savgol(x, window=9, polyorder=2)  # window shrinks to 3: quadratic fit through 3 pts
    np.testing.assert_allclose(out, x, atol=1e-12)
    assert out.shape == x.shape
    # too short to smooth: returned unchanged, NaN kept where nothing was observed
    np.testing.assert_array_equal(savgol(np.array([1.0, np.nan, np.nan]), 5, 2)[0], 1.0)
    assert np.isnan(savgol(np.array([1.0, np.nan, np.nan]), 5, 2)[1:]).all()
    np.testing.assert_allclose(savgol(np.array([[1.0, 2.0], [3.0, 5.0]]), 9, 3), [[1, 2], [3, 5]])
    with pytest.raises(ValueError, match="odd"):
        savgol(np.zeros((10, 3)), window=8)
    with pytest.raises(ValueError, match="polyorder"):
        savgol(np.zeros((10, 3)), window=3, polyorder=3)


# --------------------------------------------------------------------------- moving average


@settings(deadline=None, max_examples=40)
@given(
    data=st.lists(st.one_of(st.floats(-10, 10), st.just(float("nan"))), min_size=1, max_size=30),
    half=st.integers(0, 4),
    centered=st.booleans(),
)
def test_moving_average_matches_brute_force(data, half, centered):
    x = np.array(data)
    window = 2 * half + 1 if centered else half + 1
    out = moving_average(x, window=window, centered=centered)
    T = len(x)
    for k in range(T):
        lo, hi = (k - half, k + half + 1) if centered else (k - window + 1, k + 1)
        vals = [v for v in x[max(lo, 0) : min(hi, T)] if not math.isnan(v)]
        if vals:
            assert out[k] == pytest.approx(sum(vals) / len(vals), abs=1e-9)
        else:
            assert math.isnan(out[k])


def test_moving_average_shape_and_errors():
    x = np.random.default_rng(1).normal(size=(20, 4, 3))
    assert moving_average(x, 5).shape == x.shape
    with pytest.raises(ValueError, match="odd"):
        moving_average(x, 4, centered=True)
    assert moving_average(x, 4, centered=False).shape == x.shape


# --------------------------------------------------------------------------- 1€ filter


@settings(deadline=None, max_examples=25)
@given(
    seed=st.integers(0, 10_000),
    mincutoff=st.floats(0.05, 5.0),
    beta=st.floats(0.0, 2.0),
    dcutoff=st.floats(0.1, 5.0),
    irregular=st.booleans(),
)
def test_one_euro_matches_scalar_reference(seed, mincutoff, beta, dcutoff, irregular):
    rng = np.random.default_rng(seed)
    T = 40
    x = np.cumsum(rng.normal(scale=0.05, size=(T, 2, 3)), axis=0)
    if irregular:
        t = np.cumsum(rng.uniform(0.01, 0.1, size=T))
        out = one_euro(x, timestamps=t, mincutoff=mincutoff, beta=beta, dcutoff=dcutoff)
    else:
        t = np.arange(T) / 30.0
        out = one_euro(x, 30.0, mincutoff=mincutoff, beta=beta, dcutoff=dcutoff)
    for j in range(2):
        for d in range(3):
            ref = _OneEuroRef(mincutoff, beta, dcutoff)
            expected = [ref(x[k, j, d], t[k]) for k in range(T)]
            np.testing.assert_allclose(out[:, j, d], expected, rtol=1e-10, atol=1e-12)


def test_one_euro_nan_holds_and_uses_elapsed_time():
    rng = np.random.default_rng(3)
    T = 30
    x = np.cumsum(rng.normal(scale=0.05, size=T))
    t = np.arange(T) / 30.0
    xn = x.copy()
    xn[[0, 1, 10, 11, 12]] = np.nan
    out = one_euro(xn, 30.0, mincutoff=1.0, beta=0.5, dcutoff=1.0)
    assert np.all(np.isnan(out[:2]))
    np.testing.assert_array_equal(out[10:13], out[9])  # hold
    # reference: the filter only sees the finite samples, at their own times
    ref = _OneEuroRef(1.0, 0.5, 1.0)
    keep = np.isfinite(xn)
    expected = [ref(v, tt) for v, tt in zip(xn[keep], t[keep], strict=True)]
    np.testing.assert_allclose(out[keep], expected, rtol=1e-10)


def test_one_euro_constant_signal_and_errors():
    x = np.full((10, 3), 1.5)
    np.testing.assert_allclose(one_euro(x, 60.0, beta=1.0), x)
    with pytest.raises(ValueError, match="mincutoff"):
        one_euro(x, mincutoff=0.0)
    with pytest.raises(ValueError, match="increasing"):
        one_euro(x, timestamps=np.zeros(10))
    with pytest.raises(ValueError, match="timestamps"):
        one_euro(x, timestamps=np.arange(5.0))


# --------------------------------------------------------------------------- Kinect SDK


@settings(deadline=None, max_examples=25)
@given(
    seed=st.integers(0, 10_000),
    preset=st.sampled_from(["default", "v2_sample"]),
    with_states=st.booleans(),
)
def test_kinect_matches_sdk_transcription(seed, preset, with_states):
    rng = np.random.default_rng(seed)
    T, J = 35, 4
    # random walk with occasional large jumps so both jitter branches and the clamp fire
    steps = rng.normal(scale=0.02, size=(T, J, 3))
    steps[rng.random((T, J)) < 0.1] *= 15
    x = 1.0 + np.cumsum(steps, axis=0)
    states = rng.choice([0, 1, 2], p=[0.05, 0.25, 0.7], size=(T, J)) if with_states else None
    if with_states:
        x[rng.random((T, J)) < 0.05] = np.nan
    out = kinect_double_exponential(x, tracking_state=states, preset=preset)
    params = {
        "default": (0.5, 0.5, 0.5, 0.05, 0.04),
        "v2_sample": (0.25, 0.25, 0.25, 0.03, 0.05),
    }[preset]
    for j in range(J):
        st_j = states[:, j] if with_states else [2] * T
        ref = _kinect_ref(list(x[:, j]), list(st_j), *params)
        np.testing.assert_allclose(out[:, j], ref, rtol=1e-10, atol=1e-12, equal_nan=True)


def test_kinect_inferred_doubles_radii():
    # a 6 cm step: outside J = 0.05 (tracked) but inside 2 J = 0.1 (inferred)
    T = 6
    x = np.zeros((T, 2, 3))
    x[3:, :, 0] = 0.06  # step of 6 cm at frame 3
    st_ = np.full((T, 2), 2)
    st_[:, 1] = 1
    out = kinect_double_exponential(x, tracking_state=st_, preset="default")
    # tracked joint: |step| 0.06 > J = 0.05 -> jitter filter passes raw; inferred: damped
    assert out[3, 0, 0] > out[3, 1, 0]
    ref_t = _kinect_ref(list(x[:, 0]), [2] * T, 0.5, 0.5, 0.5, 0.05, 0.04)
    ref_i = _kinect_ref(list(x[:, 1]), [1] * T, 0.5, 0.5, 0.5, 0.05, 0.04)
    np.testing.assert_allclose(out[:, 0], ref_t, atol=1e-12)
    np.testing.assert_allclose(out[:, 1], ref_i, atol=1e-12)


def test_kinect_output_within_max_deviation_of_raw():
    rng = np.random.default_rng(7)
    x = np.cumsum(rng.normal(scale=0.1, size=(50, 5, 3)), axis=0)
    out = kinect_double_exponential(x, preset="default", smoothing=0.9)
    dev = np.linalg.norm(out - x, axis=-1)
    assert dev.max() <= 0.04 + 1e-12


def test_kinect_errors():
    x = np.zeros((5, 2, 3))
    with pytest.raises(ValueError, match="preset"):
        kinect_double_exponential(x, preset="nope")
    with pytest.raises(ValueError, match="tracking_state"):
        kinect_double_exponential(x, tracking_state=np.ones((5, 3)))
    with pytest.raises(ValueError, match="smoothing"):
        kinect_double_exponential(x, smoothing=1.5)


def _kinect_numpy(
    arr: np.ndarray,
    state: np.ndarray,
    s: float,
    c: float,
    pred: float,
    jitter0: float,
    maxdev0: float,
) -> np.ndarray:
    """The filter as numpy operations per frame over the batch: an independent form of
    the package's compiled, joint-by-joint kernel."""
    T = arr.shape[0]
    batch = arr.shape[1:-1]

    out = np.empty_like(arr)
    f_prev = np.zeros(batch + arr.shape[-1:])
    b_prev = np.zeros_like(f_prev)
    r_prev = np.zeros_like(f_prev)
    count = np.zeros(batch, dtype=np.int64)
    for k in range(T):
        r = arr[k]
        valid = np.all(np.isfinite(r), axis=-1) & (state[k] != 0)
        inferred = state[k] == 1
        jit = np.where(inferred, 2.0 * jitter0, jitter0)[..., None]
        mdev = np.where(inferred, 2.0 * maxdev0, maxdev0)
        rr = np.where(valid[..., None], r, 0.0)
        # frame 1: start
        f0 = rr
        b0 = np.zeros_like(rr)
        # frame 2
        f1 = 0.5 * (rr + r_prev)
        b1 = c * (f1 - f_prev) + (1.0 - c) * b_prev
        # later frames: jitter filter then double exponential
        d = np.linalg.norm(rr - f_prev, axis=-1, keepdims=True)
        w = d / jit
        fj = np.where(d <= jit, w * rr + (1.0 - w) * f_prev, rr)
        f2 = (1.0 - s) * fj + s * (f_prev + b_prev)
        b2 = c * (f2 - f_prev) + (1.0 - c) * b_prev
        c0 = (count == 0)[..., None]
        c1 = (count == 1)[..., None]
        f = np.where(c0, f0, np.where(c1, f1, f2))
        b = np.where(c0, b0, np.where(c1, b1, b2))
        pk = f + pred * b
        e = np.linalg.norm(pk - rr, axis=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(e > mdev, mdev / np.where(e > 0, e, 1.0), 1.0)[..., None]
        pk = np.where(ratio < 1.0, ratio * pk + (1.0 - ratio) * rr, pk)
        out[k] = np.where(valid[..., None], pk, r)
        r_prev = np.where(valid[..., None], rr, r_prev)
        f_prev = np.where(valid[..., None], f, f_prev)
        b_prev = np.where(valid[..., None], b, b_prev)
        count = np.where(valid, count + 1, 0)
    return out


def test_kinect_compiled_kernel_equals_numpy_form_wide_batch():
    # the compiled kernel (joint by joint) and the numpy form (frame by frame over the
    # batch) are the same arithmetic: bit for bit, on a batch with bodies and NaN / states
    rng = np.random.default_rng(3)
    T, B, J = 60, 3, 25
    x = np.cumsum(rng.normal(scale=0.03, size=(T, B, J, 3)), axis=0)
    x[rng.random((T, B, J)) < 0.05] = np.nan
    states = rng.choice([0, 1, 2], p=[0.05, 0.25, 0.7], size=(T, B, J))
    for preset, params in KINECT_PRESETS.items():
        out = kinect_double_exponential(x, tracking_state=states, preset=preset)
        args = [params[k] for k in ("smoothing", "correction", "prediction")]
        ref = _kinect_numpy(x, states, *args, max(1e-4, params["jitter_radius"]),
                            params["max_deviation_radius"])  # fmt: skip
        np.testing.assert_array_equal(out, ref)
        b = 1
        for j in (0, 7, 24):
            sdk = _kinect_ref(list(x[:, b, j]), list(states[:, b, j]), *params.values())
            np.testing.assert_allclose(out[:, b, j], sdk, rtol=1e-10, atol=1e-12, equal_nan=True)


def test_moving_average_wide_batch_matches_brute_force():
    # wide batches run frame by frame over a ring of cumulated rows
    rng = np.random.default_rng(4)
    x = rng.normal(size=(40, 100, 3))
    x[rng.random(x.shape) < 0.1] = np.nan
    for window, centered in ((5, True), (4, False)):
        out = moving_average(x, window=window, centered=centered)
        for k in range(x.shape[0]):
            lo, hi = (k - window // 2, k + window // 2 + 1) if centered else (k - window + 1, k + 1)
            seg = x[max(lo, 0) : hi]
            with np.errstate(invalid="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                np.testing.assert_allclose(out[k], np.nanmean(seg, axis=0), rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize(("window", "centered"), [(1, True), (5, True), (4, False), (7, False)])
def test_moving_average_columns_are_independent_and_chunks_change_nothing(
    window, centered, monkeypatch
):
    # each column's output is bit for bit the same whichever columns are smoothed with
    # it, in one piece or a chunk of columns at a time, also with windows longer than T
    from tobitkf.smoothing import chunks

    rng = np.random.default_rng(9)
    for T in (1, 3, 30):
        x = rng.normal(size=(T, 120, 3))
        x[rng.random(x.shape[:-1]) < 0.2] = np.nan
        whole = moving_average(x, window=window, centered=centered)
        narrow = np.stack(
            [moving_average(x[:, j], window=window, centered=centered) for j in range(120)],
            axis=1,
        )
        np.testing.assert_array_equal(whole, narrow)
        with monkeypatch.context() as m:
            m.setattr(chunks, "CHUNK_BYTES", 8 * T * 7)  # 7 columns a chunk
            np.testing.assert_array_equal(
                moving_average(x, window=window, centered=centered), whole
            )
