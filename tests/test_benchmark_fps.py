"""The synthetic benchmark at other frame rates (``tobitkf benchmark --fps``).

A tracker's failure lasts a time, not a number of frames: the corruption's episode
lengths are frames at 30 fps (where they were measured) and keep their duration at
another rate.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import tobitkf as tk
from tobitkf.evaluation.corruption import INFERRED_DRIFT, SUSTAINED, CorruptionModel, corrupt

click = pytest.importorskip("click")
from click.testing import CliRunner  # noqa: E402

from tobitkf.app.commands import app  # noqa: E402

ONE_EACH = dict(sustained_per_second=1e-9, inferred_per_second=1e-9, spike_rate=0.0,
                drop_rate=0.0)  # fmt: skip


def _run_lengths(labels: np.ndarray, label: int) -> list[int]:
    """Frames of each joint's runs of ``label`` (one episode: the same run on its chain)."""
    hit = (labels == label).any(axis=1)
    return [int(hit.sum())] if hit.any() else []


@pytest.mark.parametrize("fps", [15.0, 30.0, 60.0, 120.0])
def test_an_episode_keeps_its_duration(fps):
    # one sustained failure of 24 frames at 30 fps (0.8 s) and one inferred drift of 36
    # (1.2 s): the same seconds at every rate
    model = CorruptionModel(sustained_length=(24, 24), inferred_length=(36, 36), **ONE_EACH)
    clean = tk.generate_motion("arms", duration=4.0, seed=1, fps=fps)
    out = corrupt(clean, model, seed=2)
    assert _run_lengths(out.labels, SUSTAINED) == [round(0.8 * fps)]
    inferred = _run_lengths(out.labels, INFERRED_DRIFT)
    # the later sustained episode may overwrite part of the drift's chain, never lengthen it
    assert len(inferred) == 1 and inferred[0] <= round(1.2 * fps)


def test_30_fps_draws_as_before():
    # the lengths as drawn, frame for frame: the 30 fps benchmark's tables did not change
    model = CorruptionModel(sustained_length=(7, 7), **ONE_EACH)
    out = corrupt(tk.generate_motion("arms", duration=3.0, seed=1), model, seed=3)
    assert _run_lengths(out.labels, SUSTAINED) == [7]


def test_cli_benchmark_at_another_rate():
    res = CliRunner().invoke(
        app, ["benchmark", "--fps", "15", "--duration", "4", "--methods", "raw", "--json"]
    )
    assert res.exit_code == 0, res.output
    settings = json.loads(res.output)[0]["settings"]
    assert settings["fps"] == 15.0
    # 60 frames less the dropped ones (2 % of the interior frames)
    assert 50 <= settings["n_frames"] <= 60


@pytest.mark.parametrize(
    "args, message",
    [
        (["--fps", "0"], "0"),
        (["--fps", "-30"], "-30"),
        (["--kind", "pose2d", "--fps", "0"], "0"),
    ],
)
def test_cli_benchmark_refuses_a_bad_rate(args, message):
    res = CliRunner().invoke(app, ["benchmark", "--duration", "2", *args])
    assert res.exit_code != 0
    assert message in res.output


@pytest.mark.parametrize("fps", [15.0, 30.0, 60.0])
def test_pose2d_episodes_keep_their_rate_and_duration(fps):
    # episodes start at `rate` per frame at 30 fps and last `length` frames at 30 fps: at
    # another rate, as many per second (a Poisson count: 300 expected over 1000 s, sd
    # 17; within 5 sd) and as many seconds long
    from tobitkf.evaluation.pose2d import _runs

    per30 = fps / 30.0
    T = int(30000 * per30)  # 1000 s
    runs = _runs(np.random.default_rng(0), T, 0.01, (6, 6), per30)
    assert abs(len(runs) - 300) < 5 * np.sqrt(300)
    assert {b - a for a, b in runs if b < T} == {round(6 * per30)}


def test_pose2d_at_30_fps_draws_as_before():
    # per30 = 1: the draws of the function without the scaling, frame for frame
    from tobitkf.evaluation.pose2d import _runs

    rng_a, rng_b = np.random.default_rng(3), np.random.default_rng(3)
    want = []
    for t in np.flatnonzero(rng_b.random(500) < 0.02):
        n = int(rng_b.integers(3, 21))
        want.append((int(t), min(500, int(t) + n)))
    assert _runs(rng_a, 500, 0.02, (3, 20)) == want


def test_cli_pose2d_benchmark_at_another_rate():
    res = CliRunner().invoke(app, ["benchmark", "--kind", "pose2d", "--fps", "15", "--duration",
                                   "3", "--methods", "raw", "--json"])  # fmt: skip
    assert res.exit_code == 0, res.output
    settings = json.loads(res.output)[0]["settings"]
    assert settings["fps"] == 15.0 and settings["n_frames"] == 45
