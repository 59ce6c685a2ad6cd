"""Figures render to real, non-empty images; glitch episodes are found exactly."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("matplotlib")

from tobitkf.app import plots

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def test_episodes_examples():
    assert plots.episodes(np.array([0, 1, 1, 0, 0, 1], bool)) == [(1, 3), (5, 6)]
    assert plots.episodes(np.zeros(4, bool)) == []
    assert plots.episodes(np.ones(3, bool)) == [(0, 3)]


@settings(max_examples=200, deadline=None)
@given(st.lists(st.booleans(), max_size=60))
def test_episodes_cover_exactly_the_true_frames(bits):
    mask = np.array(bits, dtype=bool)
    rebuilt = np.zeros_like(mask)
    eps = plots.episodes(mask)
    for start, stop in eps:
        assert start < stop
        rebuilt[start:stop] = True
    assert np.array_equal(rebuilt, mask)
    # runs are maximal: consecutive episodes never touch
    assert all(b[0] > a[1] for a, b in itertools.pairwise(eps))


def test_traces_and_skeleton_figures_are_png(tmp_path):
    T = 40
    t = np.arange(T) / 30
    raw = np.stack([np.sin(t), np.cos(t), t], axis=1)
    fig = plots.plot_joint_traces(
        t, {"raw": raw, "atkf": raw * 0.9, "truth": raw}, shade=[(5, 9)], title="HandRight"
    )
    png = plots.figure_to_png(fig)
    assert png.startswith(PNG_MAGIC) and len(png) > 5000

    parents = [-1, 0, 1]
    pos = np.random.default_rng(0).normal(size=(T, 3, 3))
    fig = plots.plot_skeleton_frames({"raw": pos, "kf": pos}, [0, 10, 20], parents)
    assert plots.figure_to_png(fig).startswith(PNG_MAGIC)


def test_animation_is_a_gif_with_frames(tmp_path):
    from PIL import Image

    T = 30
    pos = np.cumsum(np.random.default_rng(1).normal(scale=0.01, size=(T, 3, 3)), axis=0)
    out = plots.animate_skeletons({"raw": pos, "atkf": pos}, [-1, 0, 1], tmp_path / "a.gif", step=3)
    with Image.open(out) as im:
        assert im.format == "GIF"
        assert getattr(im, "n_frames", 1) == len(range(0, T, 3))


def test_a_method_keeps_its_colour_across_figures_and_grey_is_raw_only():
    from matplotlib.colors import to_rgb

    few = plots._colours(["raw", "robust", "truth"])
    many = plots._colours(
        [
            "raw",
            "kf",
            "atkf",
            "sgf",
            "kf+rts",
            "one_euro",
            "kinect",
            "robust",
            "robust_online",
            "my_filter",
            "truth",
        ]
    )
    assert to_rgb(few["robust"]) == to_rgb(many["robust"])
    colours = [to_rgb(c) for name, c in many.items() if name != "raw"]
    assert all(len(set(c)) > 1 or c == (0.0, 0.0, 0.0) for c in colours)  # no grey but raw
    assert len(set(colours)) == len(colours)  # all distinct


def _gif_frames(path):
    """Every frame of a GIF as an RGB array, and each frame's delay in ms."""
    from PIL import Image, ImageSequence

    with Image.open(path) as im:
        frames = [np.asarray(f.convert("RGB")) for f in ImageSequence.Iterator(im)]
        delays = [f.info.get("duration") for f in ImageSequence.Iterator(im)]
    return frames, delays


def test_animation_shows_a_marker_set_without_bones(tmp_path):
    # three markers, no bones (every parent -1), as motion capture files give them
    T = 12
    pos = np.zeros((T, 3, 3))
    pos[:, :, 0] = [0.0, 0.3, 0.6]
    pos[:, :, 1] = [0.0, 1.0, 0.5]
    out = plots.animate_skeletons({"robust": pos}, [-1, -1, -1], tmp_path / "m.gif")
    frames, _ = _gif_frames(out)
    green = np.array([44, 160, 44])  # robust's colour, tab:green (text and box are black)
    for rgb in frames:
        near = np.all(np.abs(rgb.astype(int) - green) < 30, axis=-1)
        assert near.sum() >= 3  # the markers are drawn, not an empty box


def test_animation_keeps_white_white_and_each_methods_own_colour(tmp_path):
    """One palette for every frame (at most GIF_COLOURS colours), holding the page's white
    and each method's colour exactly: the small dots of a marker set are not merged into
    another colour, and the background is not tinted."""
    from matplotlib.colors import to_rgb

    T = 12
    pos = np.zeros((T, 3, 3))
    pos[:, :, 0] = [0.0, 0.3, 0.6]
    pos[:, :, 1] = np.linspace(0, 1, T)[:, None] + [0.0, 1.0, 0.5]
    names = ("raw", "robust", "kf")
    out = plots.animate_skeletons(dict.fromkeys(names, pos), [-1, -1, -1], tmp_path / "m.gif")
    frames, _ = _gif_frames(out)
    colours = np.unique(np.concatenate([f.reshape(-1, 3) for f in frames]), axis=0)
    assert len(colours) <= plots.GIF_COLOURS
    for rgb in frames:
        values, counts = np.unique(rgb.reshape(-1, 3), axis=0, return_counts=True)
        assert tuple(values[np.argmax(counts)]) == (255, 255, 255)  # the background
        for name in names:
            exact = np.round(255 * np.array(to_rgb(plots._colours(names)[name]))).astype(int)
            assert np.all(rgb == exact, axis=-1).sum() >= 3, name  # its markers


def test_animation_of_a_fast_recording_is_not_played_ten_times_too_slowly(tmp_path):
    """Browsers play a GIF delay under 20 ms as 100 ms: 120 Hz gets 20 ms frames
    (slowed down, every frame shown), 25 Hz keeps its own 40 ms."""
    pos = np.cumsum(np.random.default_rng(2).normal(scale=0.01, size=(20, 3, 3)), axis=0)
    for fps, delay in ((120.0, 20), (25.0, 40)):
        out = plots.animate_skeletons(
            {"raw": pos}, [-1, 0, 1], tmp_path / f"a{fps:.0f}.gif", fps=fps, window=(0, 20)
        )
        frames, delays = _gif_frames(out)
        assert len(frames) == 20
        assert all(d == delay for d in delays[:-1]), delays
