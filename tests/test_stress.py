"""tools/stress.py: the real recordings at a lower rate, with added noise and with
dropped frames (docs/robust.md, "Stress tests on the real recordings")."""

from __future__ import annotations

import numpy as np
import pytest

import tobitkf as tk
from conftest import tool_module


def _tool():
    return tool_module("stress")


def _pair(T: int = 61, seed: int = 0):
    truth = tk.generate_motion("arms", duration=T / 30.0, seed=seed)
    noisy = truth.positions + np.random.default_rng(seed).normal(0, 0.01, truth.positions.shape)
    noisy[7, 3] = np.nan  # a missing sample is not scored
    track = truth.replace(positions=noisy, timestamps=np.arange(T) / 30.0 + 5.0)
    return track, truth.positions


def test_the_phases_of_every_nth_frame_partition_the_recording():
    track, _ = _pair()
    for every in (1, 2, 3):
        parts = [_tool().every_nth(track, every, ph) for ph in range(every)]
        assert sum(p.n_frames for p in parts) == track.n_frames
        back = np.empty_like(track.positions)
        for ph, p in enumerate(parts):
            back[ph::every] = p.positions
            np.testing.assert_array_equal(p.timestamps, track.timestamps[ph::every])
            assert p.fps == pytest.approx(30.0 / every)
        np.testing.assert_array_equal(back, track.positions)
    with pytest.raises(ValueError, match="phase"):
        _tool().every_nth(track, 2, 2)


def test_raw_at_every_nth_frame_scores_the_same_samples():
    # the phases pooled are every sample once: raw's pooled RMSE is the full rate's
    pairs = [_pair(61, 0), _pair(45, 1)]
    full = _tool().pooled_rmse(pairs, ["raw"])["raw"]
    err = np.concatenate([np.linalg.norm(t.positions - g, axis=-1).ravel() for t, g in pairs])
    assert full == pytest.approx(np.sqrt(np.nanmean(err**2)), rel=1e-12)
    for every in (2, 3):
        assert _tool().pooled_rmse(pairs, ["raw"], every=every)["raw"] == pytest.approx(
            full, rel=1e-12
        )


def test_added_noise_has_the_stated_size():
    # a track equal to its truth, given white noise of sd s per axis: the pooled RMSE is
    # s * sqrt(3) (the norm of three axes); 3 * 61 * 25 * 3 draws, so the relative
    # standard error of the mean square is sqrt(2 / n) = 0.5 %, and 3 % is six of them
    truth = tk.generate_motion("arms", duration=61 / 30.0, seed=0)
    pairs = [(truth, truth.positions)] * 3
    s = 0.004
    got = _tool().pooled_rmse(pairs, ["raw"], noise=s, seed=2)["raw"]
    assert got == pytest.approx(s * np.sqrt(3), rel=0.03)
    # the seed gives the draw: the same seed the same number, another seed another
    assert _tool().pooled_rmse(pairs, ["raw"], noise=s, seed=2)["raw"] == got
    assert _tool().pooled_rmse(pairs, ["raw"], noise=s, seed=3)["raw"] != got
    with pytest.raises(ValueError, match="sd"):
        _tool().with_noise(truth, -1.0, 0)


def test_the_table_has_a_row_per_condition_and_the_defaults_ratio():
    pairs = [_pair(61, 0)]
    lines = _tool().table(pairs, ["raw", "robust"], 2, [0.005], 2, 100.0, "cm")
    assert lines[0] == "| condition | raw | robust |"
    rows = lines[2:]
    assert [r.split(" | ")[0] for r in rows] == [
        "| as recorded (30 fps)",
        "| every 2nd frame (15 fps), 2 phases pooled",
        "| + 0.5 cm white noise per axis, 2 seeds",
    ]
    assert all(r.count(" %)") == 1 for r in rows)  # robust against raw, not raw itself
    assert " ± " in rows[2] and " ± " not in rows[0]


def test_the_command_line_refuses_bad_settings(capsys):
    main = _tool().main
    for argv, msg in (
        (["a.txt", "--every", "0"], "--truth-replace"),
        (["a.txt", "--every", "0", "--truth-replace", "a", "b"], "--every"),
        (["a.txt", "--noise", "-0.01", "--truth-replace", "a", "b"], "--noise"),
        (["a.txt", "--seeds", "1", "--truth-replace", "a", "b"], "--seeds"),
        (["a.txt", "--drop", "1.5", "--truth-replace", "a", "b"], "--drop"),
    ):
        with pytest.raises(SystemExit):
            main(argv)
        assert msg in capsys.readouterr().err


def test_dropped_frames_are_a_random_share_and_keep_the_ends():
    # each frame dropped with probability 0.3: 1998 inner frames, so the kept share has
    # sd sqrt(0.21 / 1998) = 1 %; within 5 of them. The first and last frames stay, the
    # timestamps of the others are kept (irregular steps)
    track, truth = _pair(2000)
    keep = _tool().drop_frames(track, 0.3, 4)
    assert keep[0] and keep[-1]
    assert abs(keep[1:-1].mean() - 0.7) < 0.05
    assert not np.array_equal(keep, _tool().drop_frames(track, 0.3, 5))
    # raw at the frames kept scores those samples only
    got = _tool().pooled_rmse([(track, truth)], ["raw"], drop=0.3, seed=4)["raw"]
    err = np.linalg.norm(track.positions[keep] - truth[keep], axis=-1)
    assert got == pytest.approx(np.sqrt(np.nanmean(err**2)), rel=1e-12)
    lines = _tool().table([(track, truth)], ["raw"], 1, [], 2, 100.0, "cm", [0.3])
    assert lines[-1].startswith("| 30 % of frames dropped at random, 2 seeds | ")
    with pytest.raises(ValueError, match="fraction"):
        _tool().drop_frames(track, 1.0, 0)
