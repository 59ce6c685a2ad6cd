"""``robust`` with a noise fit given (``noise={region: {...}}``, the form of
``metadata["diagnostics"]["noise_fit"]``): a fit given back is the fit itself; a region
given at the constants, or marked not fitted, is the fixed smoother; the values given
are the ones used; bad fits are refused with the reason."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import tobitkf as tk
from tobitkf.skeleton.sequence import SampleState
from tobitkf.smoothing.robust_fit import NOISE_KEYS, check_given_noise

REGIONS = ("hands", "arms", "torso", "legs")


def _recording(seed=0, seconds=4.0):
    bad = tk.corrupt(tk.generate_motion("mixed", duration=seconds, seed=seed), seed=seed)
    return bad.sequence


def _constants(fitted=True):
    """The default constants of every region as a given fit (no coloured error)."""
    d = tk.method_defaults("robust")
    return {g: {"speed_sd": d["speed_sd"][g], "noise_sd": d["noise_sd"][g], "error_sd": 0.0,
                "error_tau": d["tau"], "fitted": fitted} for g in REGIONS}  # fmt: skip


def test_a_fit_given_back_is_the_fit():
    """The fit of a recording, given back as ``noise``, gives the fitted smoother's
    positions, sd and states bit for bit, through JSON too (NaN written as null)."""
    seq = _recording(1)
    fitted = tk.smooth(seq)
    fit = fitted.metadata["diagnostics"]["noise_fit"]
    assert all(fit[g]["fitted"] for g in REGIONS)
    for back in (fit, json.loads(json.dumps(fit).replace("NaN", "null"))):
        out = tk.smooth(seq, noise=back)
        np.testing.assert_array_equal(out.positions, fitted.positions)
        np.testing.assert_array_equal(out.std, fitted.std)
        np.testing.assert_array_equal(out.sample_state, fitted.sample_state)
        report = out.metadata["diagnostics"]["noise_fit"]
        assert all(report[g]["given"] for g in REGIONS)
        for g in REGIONS:
            for key in ("speed_sd", "noise_sd", "error_sd", "error_tau"):
                assert report[g][key] == fit[g][key]


@pytest.mark.parametrize("fitted", [True, False])
def test_the_constants_given_are_the_fixed_smoother(fitted):
    """Every region given at the constants (or marked not fitted, whose values are then
    the constants) runs the fixed model: noise="fixed"'s positions. The sd is at least
    the fixed one's (the floor of the samples' own noise may widen it)."""
    seq = _recording(2)
    fixed = tk.smooth(seq, noise="fixed")
    out = tk.smooth(seq, noise=_constants(fitted))
    np.testing.assert_allclose(out.positions, fixed.positions, rtol=0, atol=1e-12)
    ok = np.isfinite(fixed.std)
    assert (out.std[ok] >= fixed.std[ok] * (1 - 1e-12)).all()
    if not fitted:
        np.testing.assert_allclose(out.std, fixed.std, rtol=1e-12)


def test_the_values_given_are_used():
    """A track of white noise of 2 cm about a still point: given that noise and a slow
    joint it comes out far closer to the point than the samples are; given a noise a
    hundred times smaller and a fast joint it follows every sample it used."""
    rng = np.random.default_rng(3)
    seq = _recording(3)
    still = np.broadcast_to(seq.positions[:1], seq.positions.shape)
    noisy = still + rng.normal(0, 0.02, still.shape)
    seq = seq.replace(positions=noisy, tracking_state=None)
    region = {"speed_sd": 0.01, "error_sd": 0.0, "error_tau": 0.15, "fitted": True}
    right = tk.smooth(seq, noise={g: {**region, "noise_sd": 0.02} for g in REGIONS})
    fast = {**region, "speed_sd": 3.0, "noise_sd": 0.0002}
    small = tk.smooth(seq, noise={g: fast for g in REGIONS})
    assert np.sqrt(np.nanmean((right.positions - still) ** 2)) < 0.5 * 0.02
    used = small.sample_state == SampleState.MEASURED
    assert used.mean() > 0.5
    assert np.abs(small.positions - noisy)[used].max() < 0.1 * 0.02
    # its sd is at least the samples' own noise (the floor of a fit, applied to a given one)
    assert small.metadata["diagnostics"]["noise_fit"]["torso"]["sd_scale"] > 10
    assert np.nanmedian(small.std[used]) > 0.25 * 0.02
    assert right.metadata["provenance"]["params"]["noise"]["torso"]["noise_sd"] == 0.02


@pytest.mark.parametrize(
    ("given", "message"),
    [
        ("guess", "must be .fit., .fixed. or a noise fit"),
        ({}, "noise fit given per body region"),
        ([1, 2], "noise fit given per body region"),
        ({"head": {}}, "unknown body regions"),
        ({"hands": 0.1}, "must be a mapping"),
        ({"hands": {"speed_sd": 1.0}}, "lacks"),
        (
            {"hands": {"speed_sd": 0.0, "noise_sd": 0.01, "error_sd": 0, "error_tau": 0.1}},
            r"\['speed_sd'\] must be a positive",
        ),
        (
            {"hands": {"speed_sd": 1.0, "noise_sd": -0.01, "error_sd": 0, "error_tau": 0.1}},
            r"\['noise_sd'\] must be a finite number >= 0",
        ),
        (
            {"hands": {"speed_sd": 1.0, "noise_sd": 0.01, "error_sd": 0, "error_tau": math.nan}},
            r"\['error_tau'\] must be a positive",
        ),
        ({"hands": {"speed_sd": 1.0, "noise_sd": 0, "error_sd": 0, "error_tau": 0.1}}, "both 0"),
        (
            {
                "hands": {
                    "speed_sd": 1.0,
                    "noise_sd": 0.01,
                    "error_sd": 0,
                    "error_tau": 0.1,
                    "fitted": "yes",
                }
            },
            "true or false",
        ),
    ],
)
def test_a_bad_fit_is_refused(given, message):
    seq = _recording(4, 1.0)
    with pytest.raises(ValueError, match=message):
        tk.smooth(seq, noise=given)


def test_every_region_of_the_skeleton_must_be_given():
    seq = _recording(5, 1.0)
    given = _constants()
    del given["legs"]
    check_given_noise("noise", given)  # a fit of some regions is a valid value ...
    with pytest.raises(ValueError, match=r"no values for the body regions \['legs'\]"):
        tk.smooth(seq, noise=given)  # ... but this skeleton has legs


def test_the_causal_method_keeps_its_constants():
    with pytest.raises(ValueError, match="noise"):
        tk.smooth(_recording(6, 1.0), "robust_online", noise=_constants())


_positive = st.floats(1e-6, 1e3, allow_nan=False, allow_infinity=False)
_region = st.fixed_dictionaries(
    {"speed_sd": _positive, "noise_sd": _positive, "error_sd": _positive, "error_tau": _positive},
    optional={"fitted": st.just(True), "loglik": st.floats(), "at_bound": st.just([])},
)
_fit = st.dictionaries(st.sampled_from(REGIONS), st.one_of(_region, st.just({"fitted": False})),
                       min_size=1)  # fmt: skip


@settings(max_examples=200, deadline=None)
@given(_fit)
def test_a_valid_fit_is_read_as_given(fit):
    """Any fit of positive values is read back as the same numbers (the report's other
    keys dropped), survives JSON, and reading it again changes nothing."""
    out = check_given_noise("noise", fit)
    assert set(out) == set(fit)
    for g, region in fit.items():
        if region.get("fitted", True):
            assert out[g] == {**{k: region[k] for k in NOISE_KEYS}, "fitted": True}
        else:
            assert out[g] == {"fitted": False}
    assert check_given_noise("noise", json.loads(json.dumps(out))) == out


def test_one_fit_per_body_is_each_bodys_own():
    """``noise=[fit_a, fit_b]`` for two bodies smoothed in one call gives each body what
    it gives alone with its own fit, whether the two run together (same frames and
    skeleton) or apart (``smooth`` groups the bodies it can run together), and each
    body's provenance records its own fit."""
    a, b = _recording(11), _recording(12)
    other = tk.corrupt(tk.generate_motion("arms", duration=4.0, seed=13), seed=13).sequence
    for second in (b, other):
        fits = [tk.smooth(s).metadata["diagnostics"]["noise_fit"] for s in (a, second)]
        outs = tk.smooth([a, second], noise=fits)
        for seq, fit, out in zip((a, second), fits, outs, strict=True):
            alone = tk.smooth(seq, noise=fit)
            np.testing.assert_array_equal(out.positions, alone.positions)
            np.testing.assert_array_equal(out.std, alone.std)
            given = out.metadata["provenance"]["params"]["noise"]
            assert given["hands"]["speed_sd"] == fit["hands"]["speed_sd"]
    with pytest.raises(ValueError, match="noise: 1 given for 2 bodies"):
        tk.smooth([a, b], noise=fits[:1])
    with pytest.raises(ValueError, match="noise: 2 given for 1 body"):
        tk.smooth(a, noise=fits)
    with pytest.raises(ValueError, match="empty list of fits"):
        tk.smooth([a, b], noise=[])
    with pytest.raises(ValueError, match=r"noise\[1\]\['torso'\]"):
        tk.smooth([a, b], noise=[fits[0], {**fits[0], "torso": {"speed_sd": 0}}])


def test_per_body_names_the_methods_own_parameters():
    with pytest.raises(ValueError, match="per_body names unknown parameters"):
        tk.register_method("per_body_typo", lambda inp, x: inp.ys, params={"x": 1},
                           per_body=("y",))  # fmt: skip


def test_one_fit_per_body_in_chunks(monkeypatch):
    """A batch cut into chunks of one body (tobitkf.smoothing.chunks) gives each chunk
    its own bodies' fits: the numbers of the bodies smoothed alone."""
    from tobitkf.smoothing import chunks

    base, rng = _recording(14, 2.0), np.random.default_rng(14)
    # one group (same frames): three noisy copies, each with a fit of its own
    seqs = [base.replace(positions=base.positions + rng.normal(0, sd, base.positions.shape))
            for sd in (0.002, 0.01, 0.03)]  # fmt: skip
    fits = [tk.smooth(s).metadata["diagnostics"]["noise_fit"] for s in seqs]
    monkeypatch.setattr(chunks, "CHUNK_BYTES", 1)  # a body per chunk
    for seq, fit, out in zip(seqs, fits, tk.smooth(seqs, noise=fits), strict=True):
        np.testing.assert_array_equal(out.positions, tk.smooth(seq, noise=fit).positions)
