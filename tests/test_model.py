"""LinearGaussian validation, the skeleton helper, and the result containers."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tobitkf.core.model import (
    FilterResult,
    LinearGaussian,
    SmootherResult,
    embed_diagonal,
    first_observed,
)
from tobitkf.smoothing.paper import skeleton_model


def _model(**kw):
    base = dict(
        A=[[1.0, 0.1], [0.0, 1.0]],
        H=[[1.0, 0.0]],
        Q=0.01 * np.eye(2),
        R=[[0.5]],
        x0=[0.0, 0.0],
        P0=np.eye(2),
    )
    base.update(kw)
    return LinearGaussian(**base)


def test_valid_model_properties():
    m = _model()
    assert (m.n, m.p) == (2, 1)
    assert m.batch_shape == ()
    assert not m.is_diagonal
    assert m.A.dtype == float and not m.A.flags.writeable
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.A = np.eye(2)  # type: ignore[misc]


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        (dict(A=np.eye(3)), "H: expected shape"),
        (dict(A=np.ones((2, 3))), "A: expected a square"),
        (dict(H=np.ones((1, 3))), "H: expected shape"),
        (dict(Q=np.eye(3)), "Q: expected shape"),
        (dict(R=np.eye(2)), "R: expected shape"),
        (dict(Q=[[1.0, 0.5], [0.0, 1.0]]), "Q: not symmetric"),
        (dict(Q=[[1.0, 2.0], [2.0, 1.0]]), "Q: not positive semi-definite"),
        (dict(R=[[0.0]]), "R: not positive definite"),
        (dict(R=[[np.nan]]), "R: contains NaN"),
        (dict(x0=[0.0, np.nan]), "x0: contains NaN"),
        (dict(x0=[0.0, 0.0, 0.0]), "x0: expected shape"),
        (dict(P0=np.eye(3)), "P0: expected shape"),
        (dict(P0=-np.eye(2)), "P0: not positive semi-definite"),
        (dict(x0=np.zeros((4, 2)), P0=np.broadcast_to(np.eye(2), (3, 2, 2))), "do not broadcast"),
    ],
)
def test_validation_errors(kw, match):
    with pytest.raises(ValueError, match=match):
        _model(**kw)


def test_psd_but_singular_q_accepted_and_batch_x0():
    m = _model(Q=np.zeros((2, 2)), x0=np.zeros((5, 4, 2)))
    assert m.batch_shape == (5, 4)


def test_skeleton_helper_and_first_observed():
    ys = np.full((4, 2, 3), np.nan)
    ys[1, 0] = [1.0, 2.0, 3.0]
    ys[0, 0, 1] = 7.0
    ys[2, 1, 2] = -1.0
    x0 = first_observed(ys)
    np.testing.assert_array_equal(x0, [[1.0, 7.0, 3.0], [0.0, 0.0, -1.0]])
    m = skeleton_model(q=[1e-3, 2e-3, 3e-3], r=0.01, ys=ys)
    assert m.is_diagonal and m.batch_shape == (2,)
    np.testing.assert_array_equal(m.x0, x0)
    np.testing.assert_array_equal(np.diag(m.Q), [1e-3, 2e-3, 3e-3])
    np.testing.assert_array_equal(m.P0, 0.01 * np.eye(3))  # p0 defaults to r
    np.testing.assert_array_equal(m.A, np.eye(3))
    d = skeleton_model()
    np.testing.assert_array_equal(d.Q, 0.0025 * np.eye(3))
    np.testing.assert_array_equal(d.R, 0.01 * np.eye(3))
    np.testing.assert_array_equal(d.x0, np.zeros(3))


def test_skeleton_helper_names_a_wrong_shape():
    for kw, name in (
        (dict(q=[1e-3, 2e-3]), "q"),
        (dict(r=[[0.01] * 3]), "r"),
        (dict(p0=[1, 2]), "p0"),
    ):
        with pytest.raises(ValueError, match=rf"^{name}: expected one value or one per axis"):
            skeleton_model(**kw)


def test_replace_revalidates():
    m = _model()
    m2 = m.replace(R=[[2.0]])
    assert m2.R[0, 0] == 2.0 and m.R[0, 0] == 0.5
    with pytest.raises(ValueError):
        m.replace(R=[[-1.0]])


def test_embed_diagonal_and_lazy_covs():
    rng = np.random.default_rng(1)
    v = rng.uniform(0.1, 1.0, size=(5, 2, 3))
    full = embed_diagonal(v)
    assert full.shape == (5, 2, 3, 3)
    for t in range(5):
        for b in range(2):
            np.testing.assert_array_equal(full[t, b], np.diag(v[t, b]))
    z = np.zeros((5, 2, 3))
    res = FilterResult(
        means=z, predicted_means=z, cov_data=v, predicted_cov_data=2 * v, diagonal=True,
        loglik=np.zeros((5, 2)), p_lower=z, p_uncensored=z + 1, p_upper=z,
        clipped=z.astype(bool), limits=(z - np.inf, z + np.inf),
    )  # fmt: skip
    np.testing.assert_array_equal(res.covs, full)
    np.testing.assert_array_equal(res.predicted_covs, 2 * full)
    np.testing.assert_array_equal(res.variances, v)
    assert res.batch_shape == (2,) and res.n_steps == 5
    sm = SmootherResult(means=z, cov_data=full, diagonal=False)
    np.testing.assert_array_equal(sm.variances, v)


def test_a_stack_of_covariances_is_checked_each_against_its_own_scale():
    """Rounding tolerance is per matrix: a large matrix's rounding (eigenvalue -1e-5 at
    scale 1e6, within 1e-10 of it) passes beside a small one, which used to be held to
    the small one's tolerance (the tolerances broadcast across the stack)."""
    from tobitkf.core.model import check_covariance

    big = 1e6 * np.array([[1.0, 1.0], [1.0, 1.0]]) + np.diag([-1e-5, 0.0])  # eig ~ -5e-6
    assert np.linalg.eigvalsh(big)[0] < -1e-6
    small = np.eye(2)
    check_covariance("stack", np.stack([big, small]))
    with pytest.raises(ValueError, match="not positive semi-definite"):
        check_covariance("stack", np.stack([small - np.diag([2.0, 0.0]), big]))
