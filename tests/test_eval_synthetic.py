"""Synthetic motion, BVH mapping, corruption model and the benchmark."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import data_file
from tobitkf.evaluation.benchmark import benchmark_track, run_benchmark
from tobitkf.evaluation.corruption import (
    CLEAN,
    INFERRED_DRIFT,
    SPIKE,
    SUSTAINED,
    CorruptionModel,
    corrupt,
    jump_statistics,
)
from tobitkf.evaluation.synthetic import MOTIONS, bvh_to_kinect, generate_motion
from tobitkf.io.bvh import read_bvh
from tobitkf.skeleton.sequence import TrackingState
from tobitkf.skeleton.topology import get_topology

BONES = get_topology("kinect_v2").bones


def _bone_lengths(p: np.ndarray) -> np.ndarray:
    return np.array([np.linalg.norm(p[:, a] - p[:, b], axis=-1) for a, b in BONES])


@pytest.mark.parametrize("kind", MOTIONS)
def test_generator_is_a_rigid_plausible_body(kind: str) -> None:
    seq = generate_motion(kind, duration=9.0, seed=4)
    p = seq.positions
    assert p.shape == (270, 25, 3) and seq.fps == 30.0 and np.isfinite(p).all()
    L = _bone_lengths(p)
    assert L.std(axis=1).max() < 1e-9  # bones keep their length
    # an adult: head above the ankles by 1.3-1.8 m at rest; feet on or above the floor
    h = p[0, 3, 1] - p[0, [14, 18], 1].min()
    assert 1.3 < h < 1.8
    assert p[:, [14, 18], 1].min() > -1.06
    # in front of the sensor, left shoulder at smaller x than the right (Kinect camera space)
    assert 1.5 < p[:, 0, 2].min() and p[:, 0, 2].max() < 4.5
    assert (p[:, 4, 0] < p[:, 8, 0]).all()
    # human speeds: no joint faster than 4 m/s (0.13 m per frame)
    assert np.linalg.norm(np.diff(p, axis=0), axis=-1).max() < 0.13


def test_generator_is_seeded() -> None:
    a = generate_motion("mixed", duration=3.0, seed=7).positions
    b = generate_motion("mixed", duration=3.0, seed=7).positions
    c = generate_motion("mixed", duration=3.0, seed=8).positions
    assert np.array_equal(a, b) and not np.allclose(a, c)
    with pytest.raises(ValueError, match="unknown motion"):
        generate_motion("dance")


def test_squat_keeps_the_feet_planted_and_arms_rise() -> None:
    p = generate_motion("squat", duration=6.0, seed=1).positions
    assert np.ptp(p[:, 14], axis=0).max() < 1e-9  # ankles fixed
    assert np.ptp(p[:, 0, 1]) > 0.25  # pelvis goes down
    q = generate_motion("arms", duration=6.0, seed=1).positions
    assert (q[:, 11, 1] - q[:, 8, 1]).max() > 0.3  # hand above the shoulder


def test_read_bvh_chains_offsets(tmp_path) -> None:
    f = tmp_path / "t.bvh"
    f.write_text(
        "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition "
        "Zrotation Yrotation Xrotation\n JOINT Knee\n {\n  OFFSET 0 -1 0\n  CHANNELS 3 "
        "Zrotation Yrotation Xrotation\n  End Site\n  {\n   OFFSET 0 -1 0\n  }\n }\n}\n"
        "MOTION\nFrames: 2\nFrame Time: 0.5\n"
        "1 2 3 0 0 0 0 0 0\n"
        "0 0 0 90 0 0 0 0 90\n"
    )
    (seq,) = read_bvh(f, end_sites=True)
    names, pos = tuple(seq.joint_names), seq.positions
    assert names == ("Hips", "Knee", "Knee_End") and seq.fps == 2.0
    np.testing.assert_allclose(pos[0], [[1, 2, 3], [1, 1, 3], [1, 0, 3]], atol=1e-12)
    # frame 2: root turned 90 deg about z: (0,-1,0) -> (1,0,0); the knee's own 90 deg
    # about x then turns its child offset (0,-1,0) -> (0,0,-1) -> root z-rot -> (0,0,-1)
    np.testing.assert_allclose(pos[1, 1], [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(pos[1, 2], [1, 0, -1], atol=1e-12)


def test_cmu_bvh_maps_to_kinect_joints() -> None:
    seq = bvh_to_kinect(data_file("cmu-mocap/scaled_131_01.bvh"))
    p = seq.positions
    assert seq.fps == 30.0 and p.shape[1] == 25
    assert abs(p.shape[0] - 995 / 4) <= 1  # 120 Hz -> 30 Hz
    L = _bone_lengths(p)
    assert L.std(axis=1).max() < 0.01
    thigh = L[next(i for i, (a, b) in enumerate(BONES) if (a, b) == (12, 13))].mean()
    assert 0.3 < thigh < 0.5
    assert (p[:, 4, 0] < p[:, 8, 0]).mean() > 0.8  # faces the sensor


@pytest.fixture(scope="module")
def clean():
    return generate_motion("mixed", duration=10.0, seed=11)


@pytest.mark.parametrize("seed", [0, 3, 7, 12])
def test_corruption_labels_match_what_was_done(clean, seed: int) -> None:
    c = corrupt(clean, seed=seed)
    err = np.linalg.norm(c.sequence.positions - c.truth, axis=-1)
    assert (c.truth == clean.positions[c.kept]).all()
    counts = c.counts()
    assert all(counts[k] > 0 for k in ("clean", "spike", "sustained", "inferred"))
    assert err[c.labels == SPIKE].min() > 0.15  # 0.2-1 m minus jitter
    assert err[c.labels == SPIKE].max() < 1.1
    assert err[c.labels == SUSTAINED].min() > 0.1
    assert np.percentile(err[c.labels == CLEAN], 99) < 0.04  # jitter only
    st = c.sequence.tracking_state
    assert (st[c.labels == INFERRED_DRIFT] == TrackingState.INFERRED).all()
    assert (st[c.labels != INFERRED_DRIFT] == TrackingState.TRACKED).all()
    # sustained episodes last 10-50 frames (before frame dropping shortens them a little)
    from tobitkf.evaluation.metrics import glitch_episodes

    lengths = [b - a for _, a, b in glitch_episodes(c.labels == SUSTAINED)]
    assert min(lengths) >= 8 and max(lengths) <= 50


def test_corruption_drops_frames_and_jitters_time(clean) -> None:
    c = corrupt(clean, CorruptionModel(drop_rate=0.1), seed=1)
    n = clean.n_frames
    assert 0.8 * n < len(c.kept) < 0.97 * n
    ts = c.sequence.timestamps
    assert np.all(np.diff(ts) >= 0)
    np.testing.assert_allclose(ts, clean.times()[c.kept], atol=0.01)
    assert np.diff(ts).max() > 1.5 / 30  # a dropped frame leaves a double step


def test_corruption_is_seeded_and_can_be_switched_off(clean) -> None:
    a = corrupt(clean, seed=5).sequence.positions
    b = corrupt(clean, seed=5).sequence.positions
    assert np.array_equal(a, b)
    off = CorruptionModel(
        jitter={}, spike_rate=0, sustained_per_second=0, inferred_per_second=0, drop_rate=0,
        time_jitter=0,
    )  # fmt: skip
    off = CorruptionModel(
        **{**off.to_dict(), "jitter": {g: 0.0 for g in ("torso", "arms", "legs", "hands")}}
    )
    c = corrupt(clean, off, seed=5)
    assert np.array_equal(c.sequence.positions, clean.positions)
    assert (c.labels == CLEAN).all()
    with pytest.raises(ValueError, match="drop_rate"):
        CorruptionModel(drop_rate=0.7)


def test_jump_statistics_on_known_noise() -> None:
    rng = np.random.default_rng(0)
    p = np.zeros((2000, 2, 3)) + rng.normal(scale=0.004, size=(2000, 2, 3))
    p[1000, 0] += [0.5, 0, 0]
    s = jump_statistics(p)
    assert s["jitter_m"]["all"] == pytest.approx(0.004, rel=0.1)
    assert s["jump_rate"] == pytest.approx(2 / (1999 * 2))
    assert s["glitch_run_lengths"] == [1]


def test_benchmark_scores_raw_against_known_truth(clean) -> None:
    c = corrupt(clean, seed=2)
    tab = benchmark_track(c, ["raw", ("truth", lambda s: s.replace(positions=c.truth))])
    raw = tab.row("raw")
    err = np.linalg.norm(c.sequence.positions - c.truth, axis=-1)
    assert raw.rmse == pytest.approx(np.sqrt(np.mean(err**2)))
    assert raw.rmse_by_label["spike"] == pytest.approx(
        np.sqrt(np.mean(err[c.labels == SPIKE] ** 2))
    )
    perfect = tab.row("truth")
    assert perfect.rmse == 0.0 and all(v == 0.0 for v in perfect.rmse_by_label.values())
    assert perfect.lag_frames == 0
    assert "raw" in tab.to_text() and tab.to_dict()["rows"][0]["method"] == "raw"


def test_run_benchmark_smoothing_removes_spikes_not_sustained_failures() -> None:
    tab = run_benchmark(seed=0, methods=["raw", "sgf", "kf"], duration=8.0)
    raw, sgf, kf = tab.row("raw"), tab.row("sgf"), tab.row("kf")
    assert sgf.rmse_by_label["spike"] < 0.5 * raw.rmse_by_label["spike"]
    assert kf.rmse_by_label["spike"] < 0.5 * raw.rmse_by_label["spike"]
    # a 10-50 frame failure is not a glitch to a smoother: it stays (within 25 %)
    assert sgf.rmse_by_label["sustained"] > 0.75 * raw.rmse_by_label["sustained"]
    assert raw.smoothness_M > sgf.smoothness_M


def test_seed_spread_is_mean_and_sd_over_seeds() -> None:
    from tobitkf.evaluation.benchmark import seed_spread

    tabs = [run_benchmark(seed=s, methods=["raw", "sgf"], duration=4.0) for s in (0, 1)]
    spread = seed_spread(tabs)
    assert [r["method"] for r in spread] == ["raw", "sgf"]
    for r in spread:
        a, b = (t.row(r["method"]) for t in tabs)
        assert r["rmse"] == pytest.approx(((a.rmse + b.rmse) / 2, abs(a.rmse - b.rmse) / 2))
        for k, v in a.rmse_by_label.items():
            w = b.rmse_by_label[k]
            assert r[k] == pytest.approx(((v + w) / 2, abs(v - w) / 2))
    with pytest.raises(ValueError, match="no tables"):
        seed_spread([])
