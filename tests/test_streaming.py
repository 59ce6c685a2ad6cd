"""StreamingFilter reproduces the batch filters frame by frame, exactly."""

from __future__ import annotations

import zlib

import numpy as np
import pytest

from tobitkf.core.kalman import kalman_filter
from tobitkf.core.model import LinearGaussian
from tobitkf.core.streaming import StreamingFilter
from tobitkf.core.tobit import adaptive_tobit_filter, tobit_filter
from tobitkf.smoothing.paper import skeleton_model


def _general_model(rng, batch=(2,)):
    n, p = 3, 2
    B = rng.normal(size=(n, n))
    C = rng.normal(size=(p, p))
    return LinearGaussian(
        A=np.eye(n) * 0.9 + 0.1 * rng.normal(size=(n, n)),
        H=rng.normal(size=(p, n)),
        Q=0.05 * (B @ B.T + np.eye(n)),
        R=0.2 * (C @ C.T + np.eye(p)),
        x0=rng.normal(size=(*batch, n)),
        P0=np.eye(n),
    )


def _data(rng, T, shape):
    ys = rng.normal(size=(T, *shape)) * rng.choice([0.1, 1.0, 10.0], size=(T, *shape))
    ys[rng.uniform(size=ys.shape) < 0.1] = np.nan
    ys[3] = np.nan  # a fully missing frame
    return ys


def _batch(method, model, ys, **kw):
    if method == "kf":
        return kalman_filter(model, ys, **kw)
    if method == "tkf":
        return tobit_filter(model, ys, variant="standard", **kw)
    if method == "tkfc":
        return tobit_filter(model, ys, variant="corrected", **kw)
    return adaptive_tobit_filter(model, ys, **kw)


def _assert_same(stream_out, res, t):
    mean, cov = stream_out
    np.testing.assert_array_equal(mean, res.means[t])
    np.testing.assert_array_equal(cov, res.covs[t])


@pytest.mark.parametrize("method", ["kf", "tkf", "tkfc", "atkf"])
@pytest.mark.parametrize("kind", ["diagonal", "general"])
def test_streaming_equals_batch_exactly(method, kind):
    rng = np.random.default_rng(zlib.crc32(f"{method}-{kind}".encode()))
    T = 25
    if kind == "diagonal":
        model = skeleton_model(q=[1e-3, 2e-3, 3e-3], r=0.01, x0=rng.normal(size=(4, 3)))
        ys = _data(rng, T, (4, 3)) * 0.2
    else:
        model = _general_model(rng)
        ys = _data(rng, T, (2, 2))
    p = model.p
    R_scale = rng.uniform(0.5, 3.0, size=(T, *ys.shape[1:]))
    batch_kw: dict = {"R_scale": R_scale}
    stream_kw: dict = {}
    if method in ("tkf", "tkfc"):
        lo = -0.3 - rng.uniform(size=p)
        up = 0.2 + rng.uniform(size=p)
        batch_kw.update(lower=lo, upper=up)
        stream_kw.update(lower=lo, upper=up)
    if method == "atkf":
        c = rng.uniform(0.05, 0.5, size=p)
        batch_kw.update(c=c)
        stream_kw.update(c=c)
    res = _batch(method, model, ys, **batch_kw)
    f = StreamingFilter(model, method, **stream_kw)
    assert f.mean is None and f.cov is None
    for t in range(T):
        out = f.step(ys[t], R_scale=R_scale[t])
        _assert_same(out, res, t)
        np.testing.assert_array_equal(f.loglik, res.loglik[t])
        np.testing.assert_array_equal(f.variances, res.variances[t])
        np.testing.assert_array_equal(f.last.x_pred, res.predicted_means[t])
        shape = res.lower[t].shape
        np.testing.assert_array_equal(np.broadcast_to(f.last.lower, shape), res.lower[t])
        np.testing.assert_array_equal(np.broadcast_to(f.last.upper, shape), res.upper[t])
    assert f.t == T
    # reset: the same frames give the same results again
    f.reset()
    assert f.t == 0 and f.mean is None
    for t in range(5):
        _assert_same(f.step(ys[t], R_scale=R_scale[t]), res, t)


@pytest.mark.parametrize("method", ["kf", "tkfc", "atkf"])
def test_streaming_time_varying_per_step_arguments(method):
    """dt-dependent Q, A, R and per-step limits / half-widths given frame by frame equal
    the batch *_seq arguments."""
    rng = np.random.default_rng(7)
    T = 20
    model = skeleton_model(x0=rng.normal(size=(3, 3)))
    ys = _data(rng, T, (3, 3)) * 0.2
    dt = rng.uniform(0.02, 0.06, size=T)
    Q_seq = (dt / (1 / 30))[:, None, None] * 0.0025 * np.eye(3)
    R_seq = np.broadcast_to(0.01 * np.eye(3), (T, 3, 3)) * rng.uniform(0.5, 2.0, (T, 1, 1))
    A_seq = np.broadcast_to(np.eye(3), (T, 3, 3)) * rng.uniform(0.95, 1.0, (T, 1, 1))
    kw: dict = {"Q_seq": Q_seq, "R_seq": R_seq, "A_seq": A_seq}
    step_kw = [{"Q": Q_seq[t], "R": R_seq[t], "A": A_seq[t]} for t in range(T)]
    init: dict = {}
    if method == "tkfc":
        lo = rng.uniform(-0.6, -0.1, size=(T, 3, 3))
        up = lo + rng.uniform(0.2, 1.0, size=(T, 3, 3))
        kw.update(lower_seq=lo, upper_seq=up)
        for t in range(T):
            step_kw[t].update(lower=lo[t], upper=up[t])
    if method == "atkf":
        c_seq = (dt / (1 / 30))[:, None, None] * np.array([0.34, 0.18, 0.34])
        c_seq = np.broadcast_to(c_seq, (T, 3, 3))
        kw.update(c_seq=c_seq)
        init["c"] = 1.0  # overridden every step
        for t in range(T):
            step_kw[t].update(c=c_seq[t])
    res = _batch(method, model, ys, **kw)
    f = StreamingFilter(model, method, **init)
    for t in range(T):
        _assert_same(f.step(ys[t], **step_kw[t]), res, t)


def test_non_diagonal_override_switches_to_general_path():
    rng = np.random.default_rng(9)
    model = skeleton_model(x0=rng.normal(size=(2, 3)))
    ys = _data(rng, 12, (2, 3)) * 0.2
    Q_seq = np.broadcast_to(0.0025 * np.eye(3), (12, 3, 3)).copy()
    Q_seq[6:] += 0.001 * (np.ones((3, 3)) - np.eye(3))
    res = adaptive_tobit_filter(model, ys, c=[0.34, 0.18, 0.34], Q_seq=Q_seq)
    assert not res.diagonal
    f = StreamingFilter(model, "atkf", c=[0.34, 0.18, 0.34])
    assert f.diagonal
    for t in range(12):
        mean, cov = f.step(ys[t], Q=Q_seq[t])
        np.testing.assert_allclose(mean, res.means[t], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(cov, res.covs[t], rtol=1e-12, atol=1e-16)
    assert not f.diagonal


def test_streaming_errors():
    model = skeleton_model()
    with pytest.raises(ValueError, match="method"):
        StreamingFilter(model, "ukf")
    with pytest.raises(ValueError, match="needs c"):
        StreamingFilter(model, "atkf")
    with pytest.raises(TypeError, match="LinearGaussian"):
        StreamingFilter("model", "kf")  # type: ignore[arg-type]
    f = StreamingFilter(model, "tkfc", lower=-1.0, upper=1.0)
    with pytest.raises(ValueError, match="y: expected shape"):
        f.step(np.zeros(2))
    f.step(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="batch shape"):
        f.step(np.zeros((5, 3)))
    with pytest.raises(ValueError, match="lower limit must be <"):
        f.step(np.zeros((4, 3)), lower=2.0)
    with pytest.raises(ValueError, match="Q: expected shape"):
        f.step(np.zeros((4, 3)), Q=np.eye(2))
    # arguments that do not broadcast to the frame are named (not numpy's message)
    with pytest.raises(ValueError, match=r"lower: shape \(2,\) does not broadcast"):
        f.step(np.zeros((4, 3)), lower=np.zeros(2))
    with pytest.raises(ValueError, match=r"R_scale: shape \(5, 3\) does not broadcast"):
        f.step(np.zeros((4, 3)), R_scale=np.ones((5, 3)))
    g = StreamingFilter(model, "atkf", c=[0.3, 0.3])
    with pytest.raises(ValueError, match=r"c: shape \(2,\) does not broadcast"):
        g.step(np.zeros(3))


def test_streaming_equals_batch_atkf_constant_identity_model():
    """The batch ATKF on a constant A = H = I model forms its limits after the loop from
    the means; they must equal the ones the streaming filter forms at every step."""
    rng = np.random.default_rng(31)
    model = skeleton_model(x0=rng.normal(size=(5, 3)))
    ys = _data(rng, 30, (5, 3)) * 0.3
    c = np.array([0.34, 0.18, 0.34])
    res = adaptive_tobit_filter(model, ys, c=c)
    f = StreamingFilter(model, "atkf", c=c)
    for t in range(30):
        _assert_same(f.step(ys[t]), res, t)
        shape = res.lower[t].shape
        np.testing.assert_array_equal(np.broadcast_to(f.last.lower, shape), res.lower[t])
        np.testing.assert_array_equal(np.broadcast_to(f.last.upper, shape), res.upper[t])
        if t > 0:  # step 0 is a KF step (no censoring quantities)
            u = f.last.update
            np.testing.assert_array_equal(u.clipped, res.clipped[t])
            np.testing.assert_array_equal(np.broadcast_to(u.p_lower, shape), res.p_lower[t])
    assert res.clipped.any()
