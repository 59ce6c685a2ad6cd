"""The evaluation pipeline on synthetic pairs with known answers (issue 5's required tests)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tobitkf.evaluation.evaluate import (
    evaluate_methods,
    evaluate_without_truth,
    pool_scores,
    prepare_truth,
    resolve_method,
)
from tobitkf.evaluation.pairs import Pair, PairingTable
from tobitkf.evaluation.synthetic import generate_motion
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology, get_topology

NAMES = get_topology("kinect_v2").joints
MARKERS = tuple(f"M_{n}" for n in NAMES)
TABLE = PairingTable("test", tuple(Pair(n, (m,)) for n, m in zip(NAMES, MARKERS, strict=True)))


@pytest.fixture(scope="module")
def track() -> SkeletonSequence:
    return generate_motion("mixed", duration=9.0, seed=21)


def _identity(s):
    return s


def _mocap(track: SkeletonSequence, *, R=None, t=None, offsets=None, rate=60.0, delay=0.0):
    """A mocap recording of the same motion at `rate` Hz in another frame (z up, mm → m)."""
    tt = track.times()
    mt = np.arange(0.0, tt[-1] - delay + 1e-9, 1.0 / rate)
    from tobitkf.evaluation.alignment import resample

    p = resample(tt, track.positions, mt + delay)
    R = np.eye(3) if R is None else R
    t = np.zeros(3) if t is None else t
    p = (p - t) @ R  # track = R mocap + t
    if offsets is not None:
        p = p - offsets @ R
    topo = Topology.from_names(MARKERS, up_axis=2, name="markers")
    return SkeletonSequence(positions=p, topology=topo, fps=rate)


def test_reference_equal_to_truth_scores_zero(track) -> None:
    tab = evaluate_methods(track, track.positions, ["raw", ("copy", _identity)])
    for s in tab.scores:
        assert s.rmse == 0.0 and s.max == 0.0 and s.p95 == 0.0 and s.frames_over == 0
        assert all(v == 0.0 for v in s.rmse_groups.values())
        assert s.rmse_by_class["fine"] == 0.0
        assert s.lag_frames == 0
        assert all(a.rmse_best == 0.0 and a.rmse_fixed == 0.0 for a in s.angles.values())
        assert s.smoothness_M == pytest.approx(tab.truth_M)
    assert tab.class_counts["short_glitch"] == tab.class_counts["sustained"] == 0


def test_truth_delayed_by_two_frames_scores_a_lag_of_two(track) -> None:
    late = np.empty_like(track.positions)
    late[2:] = track.positions[:-2]
    late[:2] = track.positions[0]
    delayed = ("delayed", lambda s: s.replace(positions=late))
    tab = evaluate_methods(track, track.positions, ["raw", delayed], fixed_delay=0)
    s = tab.score("delayed")
    assert s.lag_frames == 2
    assert len(s.angles) == 4
    for a in s.angles.values():
        assert a.best_delay == 2 and a.rmse_best == pytest.approx(0, abs=1e-9)
    assert s.angles["left_elbow"].rmse_fixed > 0.1


def test_rigidly_moved_mocap_scores_zero_after_registration(track) -> None:
    R = Rotation.from_euler("xyz", [90, 10, -35], degrees=True).as_matrix()
    mocap = _mocap(track, R=R, t=np.array([0.4, -1.2, 2.0]))
    gt = prepare_truth(track, mocap, pairs=TABLE, offset_mode="none")
    assert abs(gt.fitted_time_alignment.offset_s) < 0.005
    tab = evaluate_methods(track, gt, ["raw"])
    assert tab.scores[0].rmse < 2e-3  # linear interpolation of 60 Hz samples only
    np.testing.assert_allclose(gt.registration.rotation, R, atol=1e-3)


def test_world_offsets_and_a_late_start_are_recovered(track) -> None:
    rng = np.random.default_rng(0)
    offs = rng.normal(scale=0.04, size=(25, 3))
    R = Rotation.from_euler("z", 120, degrees=True).as_matrix()
    mocap = _mocap(track, R=R, t=np.array([1.0, 0.0, 0.0]), offsets=offs, delay=0.25)
    gt = prepare_truth(track, mocap, pairs=TABLE, time="fit", offset_mode="world")
    assert gt.time_alignment.offset_s == pytest.approx(0.25, abs=0.01)
    tab = evaluate_methods(track, gt, ["raw"])
    assert tab.scores[0].rmse < 3e-3


def test_a_marker_the_mocap_never_saw_is_left_out_quietly(track) -> None:
    """A mocap marker missing in every frame (one never placed) leaves its joint unscored
    and the others as before, with no numpy warning about an empty slice: the time
    alignment picks its signals by their spread, and a pair with the missing marker has
    none."""
    import warnings

    mocap = _mocap(track, t=np.array([0.2, 0.0, 0.0]))
    positions = mocap.positions.copy()
    positions[:, 3] = np.nan  # the head's marker
    mocap = mocap.replace(positions=positions)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        gt = prepare_truth(track, mocap, pairs=TABLE, time="fit", offset_mode="none")
    assert abs(gt.fitted_time_alignment.offset_s) < 0.005
    assert np.isnan(gt.positions[:, 3]).all()
    tab = evaluate_methods(track, gt, ["raw"])
    assert tab.scores[0].rmse < 2e-3


def test_a_mocap_with_one_marker_is_refused_with_the_reason(track) -> None:
    """With one marker measured there is no distance between joints to align the
    times by: the error says so (it was the aligner's "no offset gives enough
    overlap")."""
    mocap = _mocap(track)
    positions = np.full_like(mocap.positions, np.nan)
    positions[:, 0] = mocap.positions[:, 0]
    with pytest.raises(ValueError, match="no two paired joints are measured together"):
        prepare_truth(track, mocap.replace(positions=positions), pairs=TABLE, time="fit")


def test_registration_held_fixed_and_glitches_classified(track) -> None:
    mocap = _mocap(track, R=Rotation.from_euler("x", -90, degrees=True).as_matrix())
    bad = track.positions.copy()
    rng = np.random.default_rng(3)
    frames = rng.random(track.n_frames) < 0.2  # 1 m glitches on 20 % of frames
    bad[frames, 11] += np.array([1.0, 0.0, 0.0])
    bad[100:130, 7] += np.array([0.0, 0.5, 0.0])  # a 30-frame sustained failure
    raw = track.replace(positions=bad)
    gt = prepare_truth(raw, mocap, pairs=TABLE, offset_mode="world", time="fixed")
    # the truth is still the clean motion: the glitches did not pull the registration
    assert np.nanmax(np.abs(gt.positions - track.positions)) < 5e-3
    fixed = ("fixed", lambda s: s.replace(positions=track.positions))
    tab = evaluate_methods(raw, gt, ["raw", fixed])
    r, f = tab.score("raw"), tab.score("fixed")
    assert tab.class_counts["sustained"] >= 30 and tab.class_counts["short_glitch"] > 0
    assert r.rmse_by_class["sustained"] == pytest.approx(0.5, abs=0.01)
    assert f.rmse < 3e-3 and f.rmse_by_class["sustained"] < 3e-3
    assert r.frames_over >= frames.sum()
    assert ("HandLeft", 100, 130) in tab.episodes
    json.dumps(tab.to_dict())  # renders to JSON
    assert "raw" in tab.to_text()
    pooled = pool_scores([tab, tab])
    assert pooled[0]["rmse_cm"] == pytest.approx(100 * r.rmse)
    assert pooled[0]["n_samples"] == 2 * r.counts["all"]


def test_pool_scores_is_the_rmse_over_all_samples(track) -> None:
    a = evaluate_methods(track, track.positions + 0.01, ["raw"])  # 1 cm per axis: √3 cm
    short = track.replace(
        positions=track.positions[:90], tracking_state=None, timestamps=track.timestamps[:90]
    )
    b = evaluate_methods(short, short.positions + 0.02, ["raw"])
    p = pool_scores([a, b])[0]
    na, nb = a.scores[0].counts["all"], b.scores[0].counts["all"]
    ref = np.sqrt((na * 3e-4 + nb * 12e-4) / (na + nb))
    assert p["rmse_cm"] == pytest.approx(100 * ref)


def test_evaluate_without_truth_lists_m_and_jumps(track) -> None:
    jumpy = track.positions.copy()
    jumpy[50, 3] += [0.0, -0.6, 0.0]
    seq = track.replace(positions=jumpy)
    tab = evaluate_without_truth(seq, ["raw", ("clean", lambda s: track)])
    raw = tab.rows[0]
    assert raw["jumps"][0]["joint"] == "Head" and raw["jumps"][0]["frame"] in (50, 51)
    assert raw["max_jump_m"] == pytest.approx(0.6, abs=0.05)
    assert raw["M"] > tab.rows[1]["M"]
    json.dumps(tab.to_dict())
    assert "raw" in tab.to_text()


def test_resolve_method_specs() -> None:
    assert resolve_method("raw")[0] == "raw"
    assert resolve_method(("mine", _identity))[1] is _identity
    with pytest.raises(ValueError, match="unknown method"):
        resolve_method("bogus")[1](None)
    with pytest.raises(ValueError, match="method spec"):
        resolve_method(("a", "b", "c", "d"))
    # "+rts" on a method without an RTS pass would only relabel it
    assert resolve_method("kf+rts")[0] == "kf+rts"
    for name in ("sgf+rts", "one_euro+rts", "robust+rts"):
        with pytest.raises(ValueError, match="has no RTS pass"):
            resolve_method(name)


def test_samples_missing_from_raw_are_in_no_glitch_class(track) -> None:
    # the raw track loses a hand for 30 frames; a method that fills the gap is scored on
    # the gap overall, but its per-class RMSEs stay on the samples raw is scored on
    holey = track.positions.copy()
    holey[50:80, 7] = np.nan
    raw = track.replace(positions=holey)
    filled = ("filled", lambda s: track.replace(positions=track.positions + 0.01))
    tab = evaluate_methods(raw, track.positions, ["raw", filled])
    r, f = tab.score("raw"), tab.score("filled")
    assert f.counts["all"] == r.counts["all"] + 30
    for name in ("fine", "short_glitch", "sustained"):
        assert f.counts[name] == r.counts[name] == tab.class_counts[name]
    assert f.rmse_by_class["fine"] == pytest.approx(0.01 * np.sqrt(3))


def test_default_methods_are_the_issue_comparison_plus_registered_robust_methods() -> None:
    from tobitkf.evaluation.evaluate import DEFAULT_METHODS, default_methods
    from tobitkf.smoothing.api import method_names

    names = default_methods()
    assert names[: len(DEFAULT_METHODS)] == list(DEFAULT_METHODS)
    assert set(names[len(DEFAULT_METHODS) :]) == {"robust", "robust_online"} & set(method_names())
    for name in names:  # every default resolves
        resolve_method(name)


def test_pool_scores_ignores_a_recording_without_scored_samples(track) -> None:
    a = evaluate_methods(track, track.positions + 0.01, ["raw"])
    empty = evaluate_methods(track, np.full_like(track.positions, np.nan), ["raw"])
    assert np.isnan(empty.scores[0].max)
    for tables in ([a, empty], [empty, a]):  # the order of the recordings does not matter
        p = pool_scores(tables)[0]
        assert p["max_cm"] == pytest.approx(100 * a.scores[0].max)
        assert p["M"] == pytest.approx(a.scores[0].smoothness_M)
        assert p["rmse_cm"] == pytest.approx(100 * a.scores[0].rmse)


def test_text_tables_give_whole_method_names(track) -> None:
    """The terminal tables of evaluate and benchmark cut no name ("robust_o")."""
    from tobitkf.evaluation.benchmark import run_benchmark

    long = "a_rather_long_method_label"
    tab = evaluate_methods(track, track.positions, ["raw", (long, _identity)])
    lines = tab.to_text().splitlines()
    assert any(line.lstrip().startswith(long + " ") for line in lines)
    assert len({len(line) for line in lines[:3]}) == 1  # the columns still line up
    bench = run_benchmark(0, ["raw", (long, _identity)], duration=2.0).to_text().splitlines()
    assert any(line.lstrip().startswith(long + " ") for line in bench)
    assert len({len(line) for line in bench[:3]}) == 1


def test_clipped_is_reported_only_for_methods_that_clip():
    """A method without censoring limits clips nothing: no clipped share (None, shown
    as "–"), not 0 %; the Tobit filters report theirs (here the track lies within the
    limits, so 0)."""
    import tobitkf as tk

    seq = tk.generate_motion(duration=2.0)
    noisy = seq.replace(
        positions=seq.positions + np.random.default_rng(0).normal(0, 0.01, seq.positions.shape)
    )
    tab = evaluate_methods(noisy, seq.positions, ["raw", "kf", "sgf", "robust", "atkf", "tkf"])
    clipped = {r["method"]: r["clipped_fraction"] for r in tab.rows()}
    assert all(clipped[m] is None for m in ("raw", "kf", "sgf", "robust"))
    assert clipped["atkf"] == 0.0 and clipped["tkf"] == 0.0
    for method, censors in (("kf", False), ("robust", False), ("tkf", True)):
        assert tk.smooth(noisy, method=method).metadata["diagnostics"]["censoring"] is censors


def test_a_fixed_delay_longer_than_the_track_is_refused():
    """It used to print NaN for every angle at the fixed delay."""
    seq = generate_motion(duration=1.0)
    with pytest.raises(ValueError, match="not shorter than the track"):
        evaluate_methods(seq, seq.positions, ["raw"], fixed_delay=seq.n_frames)
