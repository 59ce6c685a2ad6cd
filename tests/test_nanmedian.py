"""The fast NaN-aware median and percentile of the gates taken from a recording
(``robust_scale.nanmedian_last``, ``nanpercentile_last``) are ``np.nanmedian`` and
``np.nanpercentile`` bit for bit: the outputs of every recording in pixels stay what
they were. Property-based: any shape, axis, NaN share, infinities and repeated values
(magnitudes below 1e300 for the median: at the edge of the float range numpy's own
paths disagree with each other)."""

from __future__ import annotations

import warnings

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from tobitkf.smoothing.robust_scale import _nanmedian, nanmedian_last, nanpercentile_last

values = st.one_of(
    st.floats(-1e300, 1e300, allow_nan=False),
    st.just(np.nan),
    st.sampled_from([np.inf, -np.inf, 0.0, 1.0]),
)


def _numpy(a, axis, q=None):
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        if q is not None:
            return np.nanpercentile(a, q, axis=axis)
        return np.nanmedian(a, axis=axis)


@settings(max_examples=300, deadline=None)
@given(a=hnp.arrays(np.float64, hnp.array_shapes(min_dims=1, max_dims=4, min_side=0, max_side=7),
                    elements=values),
       data=st.data())  # fmt: skip
def test_it_is_numpys_nanmedian(a, data):
    one = st.integers(-a.ndim, a.ndim - 1)
    several = st.lists(st.integers(0, a.ndim - 1), min_size=1, max_size=a.ndim, unique=True)
    axis = data.draw(st.one_of(one, several.map(tuple)))
    got, want = _nanmedian(a, axis=axis), _numpy(a, axis)
    assert np.shape(got) == np.shape(want)
    np.testing.assert_array_equal(got, want)
    if axis in (-1, a.ndim - 1):
        np.testing.assert_array_equal(nanmedian_last(a), want)


def test_large_arrays_and_all_nan_rows():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(40, 30, 61))
    a[rng.random(a.shape) < 0.3] = np.nan
    a[5, 7] = np.nan  # a row without a value: NaN, as numpy
    np.testing.assert_array_equal(nanmedian_last(a), _numpy(a, -1))
    assert np.isnan(nanmedian_last(a)[5, 7])


def test_one_value_at_the_end_of_the_float_range_is_its_own_median():
    big = np.finfo(float).max / 1.5
    assert nanmedian_last(np.array([np.nan, big, np.nan])) == big
    np.testing.assert_array_equal(nanmedian_last(np.array([[big, -big, big]])), [big])


@settings(max_examples=300, deadline=None)
@given(a=hnp.arrays(np.float64, hnp.array_shapes(min_dims=1, max_dims=3, min_side=0, max_side=9),
                    elements=st.one_of(st.floats(allow_nan=False), st.just(np.nan))),
       q=st.one_of(st.sampled_from([0.0, 50.0, 90.0, 95.0, 98.0, 100.0]),
                   st.floats(0, 100)))  # fmt: skip
def test_it_is_numpys_nanpercentile(a, q):
    got, want = nanpercentile_last(a, q), _numpy(a, -1, q)
    assert np.shape(got) == np.shape(want)
    np.testing.assert_array_equal(got, want)


def test_projected_bone_centres_are_numpys_per_bone():
    """All bones at once give each bone's ``np.nanpercentile`` of its lengths over time."""
    from tobitkf.skeleton.topology import get_topology
    from tobitkf.smoothing.robust_scale import BONE_MAX_FACTOR, _projected_bone_centres

    topo = get_topology("coco17")
    rng = np.random.default_rng(2)
    y = rng.normal(size=(50, 3, topo.n_joints, 2)) * 100
    y[rng.random(y.shape[:3]) < 0.2] = np.nan
    y[:, 1, 5] = np.nan  # a joint never seen: its bones NaN
    want = np.full((3, topo.n_joints), np.nan)
    for j, p in enumerate(topo.parents):
        if p >= 0:
            length = np.sqrt(np.sum((y[:, :, j] - y[:, :, p]) ** 2, axis=-1))
            want[:, j] = BONE_MAX_FACTOR * _numpy(length, 0, 95) / 2
    np.testing.assert_array_equal(_projected_bone_centres(y, topo.parents), want)


@settings(max_examples=200, deadline=None)
@given(a=hnp.arrays(np.float64, hnp.array_shapes(min_dims=1, max_dims=3, min_side=1, max_side=12),
                    elements=st.one_of(st.floats(-1e300, 1e300, allow_nan=False),
                                       st.just(np.nan), st.sampled_from([np.inf, -np.inf]))),
       window=st.sampled_from([1, 3, 5, 7]))  # fmt: skip
def test_the_running_median_is_numpys_over_windows(a, window):
    """The compiled running median is ``np.nanmedian`` over each centred window of the
    NaN-padded series (the NumPy form it replaced)."""
    from tobitkf.smoothing.robust_scale import _running_median

    T = a.shape[0]
    if T < window:
        want = a
    else:
        h = window // 2
        pad = np.concatenate([np.full((h, *a.shape[1:]), np.nan), a,
                              np.full((h, *a.shape[1:]), np.nan)])  # fmt: skip
        want = _numpy(np.lib.stride_tricks.sliding_window_view(pad, window, axis=0), -1)
    np.testing.assert_array_equal(_running_median(a, window), want)
