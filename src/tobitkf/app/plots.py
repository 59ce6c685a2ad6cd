"""Figures for reports: coordinate traces, skeleton snapshots and animations.

All of matplotlib is imported inside the functions (it is an optional extra,
``pip install tobitkf[plot]``), with the non-interactive Agg backend, so the rest of
the package never pays for it.
"""

from __future__ import annotations

import base64
import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

AXIS_NAMES = ("x", "y", "z")

# one colour per method in every figure of a report (grey is the raw track's alone);
# names not listed here cycle through the rest of the palette
_FIXED_COLOURS = {
    "raw": "0.55",
    "truth": "black",
    "kf": "tab:blue",
    "atkf": "tab:orange",
    "atkf2016": "tab:brown",
    "tkf": "tab:olive",
    "tkfc": "tab:cyan",
    "sgf": "tab:purple",
    "savgol": "tab:purple",
    "kf+rts": "navy",
    "one_euro": "tab:pink",
    "kinect": "darkkhaki",
    "moving_average": "teal",
    "robust": "tab:green",
    "robust_online": "tab:red",
}


def _pyplot():
    try:
        import matplotlib
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("plotting needs matplotlib: pip install 'tobitkf[plot]'") from exc
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _colours(names: Sequence[str]) -> dict[str, Any]:
    plt = _pyplot()
    from matplotlib.colors import to_rgb

    taken = {to_rgb(c) for c in _FIXED_COLOURS.values()}
    cycle = [
        c
        for c in plt.rcParams["axes.prop_cycle"].by_key()["color"]
        if len(set(to_rgb(c))) > 1 and to_rgb(c) not in taken  # no greys, no fixed colours
    ] + ["goldenrod", "slateblue", "sienna", "darkcyan", "indigo", "crimson", "olivedrab"]
    out: dict[str, Any] = {}
    i = 0
    for name in names:
        if name in _FIXED_COLOURS:
            out[name] = _FIXED_COLOURS[name]
        else:
            out[name] = cycle[i % len(cycle)]
            i += 1
    return out


def figure_to_png(fig) -> bytes:
    """Render a matplotlib figure to PNG bytes and close it."""
    plt = _pyplot()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=96, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def png_data_uri(data: bytes, mime: str = "image/png") -> str:
    """A ``data:`` URI embedding ``data`` (for a self-contained HTML page)."""
    return f"data:{mime};base64," + base64.b64encode(data).decode("ascii")


def episodes(mask: np.ndarray) -> list[tuple[int, int]]:
    """Runs of True in a boolean vector, as half-open ``(start, stop)`` frame ranges.

    Parameters
    ----------
    mask : (T,) bool

    Returns
    -------
    list of (int, int)
    """
    m = np.asarray(mask, dtype=bool).ravel()
    if m.size == 0:
        return []
    edges = np.diff(np.concatenate(([0], m.astype(np.int8), [0])))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)
    return list(zip(starts.tolist(), stops.tolist()))


def plot_joint_traces(
    times: np.ndarray,
    series: Mapping[str, np.ndarray],
    *,
    title: str = "",
    shade: Sequence[tuple[int, int]] = (),
    unit: str = "m",
    shade_label: str = "glitch",
    bands: Mapping[str, np.ndarray] | None = None,
    y_down: bool = False,
):
    """Per-axis coordinate traces of one joint (like Fig. 1, 2, 4, 6 of the 2020 paper).

    Parameters
    ----------
    times : (T,) seconds
    series : mapping name -> (T, D) positions, D = 3 or 2 (one panel per axis); ``"raw"``
        and ``"truth"`` get fixed colours
    title : str
    shade : frame ranges ``(start, stop)`` to shade (glitch episodes)
    unit : axis label unit
    shade_label : the shading's entry in the legend
    bands : mapping name -> (T,) per-axis posterior sd of that series: a light band of
        ±2 sd in the series' colour around its curve on every axis, behind the lines,
        with the legend entry ``"<name> ± 2 sd"``
    y_down : the y axis points down (image keypoints): its panel is drawn upside down,
        so a keypoint moving up in the image moves up in the panel

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _pyplot()
    times = np.asarray(times, dtype=float)
    colours = _colours(list(series))
    # half a frame on each side of a shaded episode, in the track's own time step
    half = 0.5 * float(np.median(np.diff(times))) if len(times) > 1 else 0.0
    n_axes = np.asarray(next(iter(series.values()))).shape[-1] if series else 3
    fig, axes = plt.subplots(n_axes, 1, figsize=(9, 0.7 + 1.95 * n_axes), sharex=True)
    for k, ax in enumerate(axes):
        for start, stop in shade:
            lo = times[min(start, len(times) - 1)]
            hi = times[min(max(stop - 1, start), len(times) - 1)]
            ax.axvspan(lo - half, hi + half, color="tab:red", alpha=0.12, lw=0)
        for name, sd in (bands or {}).items():
            if name not in series:
                continue
            v = np.asarray(series[name], dtype=float)[:, k]
            half_width = 2.0 * np.asarray(sd, dtype=float)[: len(v)]
            ax.fill_between(times[: len(v)], v - half_width, v + half_width, color=colours[name],
                            alpha=0.18, lw=0, zorder=0.5, label=f"{name} ± 2 sd")  # fmt: skip
        for name, values in series.items():
            v = np.asarray(values, dtype=float)
            style = {"lw": 1.6 if name == "truth" else 1.1}
            if name == "raw":
                style.update(lw=0.9, marker=".", ms=2.5)
            ax.plot(times[: len(v)], v[:, k], label=name, color=colours[name], **style)
        ax.set_ylabel(f"{AXIS_NAMES[k]} [{unit}]")
        if y_down and k == 1:
            ax.invert_yaxis()
            ax.set_ylabel(f"y [{unit}], down")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    # one legend above the plots (never over a curve), the shading included
    handles, labels = axes[0].get_legend_handles_labels()
    for name in bands or {}:  # a band's entry right after its curve's
        band, curve = f"{name} ± 2 sd", name
        if band in labels and curve in labels:
            i = labels.index(band)
            entry = handles.pop(i), labels.pop(i)
            at = labels.index(curve) + 1
            handles.insert(at, entry[0])
            labels.insert(at, entry[1])
    if shade:
        from matplotlib.patches import Patch

        handles.append(Patch(color="tab:red", alpha=0.12, lw=0))
        labels.append(shade_label)
    ncol = min(len(labels), 8) or 1
    rows = -(-len(labels) // ncol)
    top = 1.0 - (0.028 * rows + (0.035 if title else 0.0)) * 6.5 / fig.get_figheight()
    if title:
        fig.suptitle(title, y=0.995)
    fig.legend(
        handles,
        labels,
        loc="upper center",
        bbox_to_anchor=(0.5, 1.0 - (0.035 if title else 0.0) * 6.5 / fig.get_figheight()),
        ncol=ncol,
        fontsize=8,
        frameon=False,
    )
    fig.tight_layout(rect=(0, 0, 1, top))
    return fig


def _view_axes(up_axis: int) -> tuple[int, int]:
    """Horizontal and vertical coordinate for a frontal view with ``up_axis`` vertical."""
    horizontal = 0 if up_axis != 0 else 1
    return horizontal, up_axis


def _view_box(points: np.ndarray, percentile: float, pad: float) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corner of the box drawn around ``points`` (N, D): from the
    ``percentile``-th to the ``100 - percentile``-th percentile per coordinate, widened by
    ``pad`` times the box's largest side (the same look in metres, millimetres or pixels)."""
    d = points.shape[-1]
    finite = points[np.all(np.isfinite(points), axis=1)]
    if not finite.size:
        return np.zeros(d), np.ones(d)
    lo = np.percentile(finite, percentile, axis=0)
    hi = np.percentile(finite, 100 - percentile, axis=0)
    margin = pad * float(np.max(hi - lo)) or 1.0
    return lo - margin, hi + margin


def _frame_axes(ax, lo, hi, h: int, v: int, y_down: bool) -> None:
    """A skeleton panel: the box ``lo``..``hi`` on coordinates ``h`` and ``v``, equal
    scales, no ticks; the vertical axis drawn downwards for image keypoints."""
    ax.set_xlim(lo[h], hi[h])
    ax.set_ylim((hi[v], lo[v]) if y_down else (lo[v], hi[v]))
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])


def plot_skeleton_frames(
    frames: Mapping[str, np.ndarray],
    frame_indices: Sequence[int],
    parents: Sequence[int],
    *,
    up_axis: int = 1,
    frame_labels: Sequence[str] | None = None,
    title: str = "",
    y_down: bool = False,
):
    """Skeletons at a few frames, one column per method (like Fig. 5 of the 2020 paper).

    Parameters
    ----------
    frames : mapping name -> (T, J, D) positions, D = 3 or 2
    frame_indices : frames to draw (rows)
    parents : (J,) parent index per joint, -1 for the root
    up_axis : which coordinate is vertical
    frame_labels : row labels (default "frame k")
    title : figure title
    y_down : the vertical coordinate points down (image keypoints): drawn downwards

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _pyplot()
    names = list(frames)
    colours = _colours(names)
    h, v = _view_axes(up_axis)
    d = np.asarray(frames[names[0]]).shape[-1]
    allpts = np.concatenate(
        [np.asarray(frames[n])[list(frame_indices)].reshape(-1, d) for n in names]
    )
    lo, hi = _view_box(allpts, 0.0, 0.06)
    nrow = len(frame_indices)
    fig, axes = plt.subplots(
        nrow, len(names), figsize=(1.5 * len(names) + 0.6, 2.4 * nrow), squeeze=False
    )
    for c, name in enumerate(names):
        pos = np.asarray(frames[name], dtype=float)
        for r, t in enumerate(frame_indices):
            ax = axes[r, c]
            p = pos[t]
            for j, par in enumerate(parents):
                if par >= 0:
                    ax.plot([p[par, h], p[j, h]], [p[par, v], p[j, v]], color=colours[name])
            ax.plot(p[:, h], p[:, v], ".", color=colours[name], ms=3)
            _frame_axes(ax, lo, hi, h, v, y_down)
            if r == 0:
                ax.set_title(name, fontsize=9)
            if c == 0:
                ax.set_ylabel(frame_labels[r] if frame_labels else f"frame {t}", fontsize=9)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


#: GIF frames per second a browser plays at most: it stores delays in 1/100 s and plays
#: a delay under 2/100 s (more than 50 frames a second) at 1/10 s instead
GIF_MAX_FPS = 50.0


def gif_playback_fps(fps: float) -> float:
    """Frames per second a GIF of ``fps`` frames a second is written with: ``fps`` itself,
    between 1 and :data:`GIF_MAX_FPS` (a faster recording plays slowed down, every frame
    shown, instead of ten times too slowly)."""
    return float(min(max(1.0, fps), GIF_MAX_FPS))


def animate_skeletons(
    frames: Mapping[str, np.ndarray],
    parents: Sequence[int],
    path: str | Path,
    *,
    fps: float = 30.0,
    up_axis: int = 1,
    step: int = 2,
    max_frames: int = 150,
    window: tuple[int, int] | None = None,
    y_down: bool = False,
) -> Path:
    """Write an animated GIF with the skeletons of several methods side by side.

    Parameters
    ----------
    frames : mapping name -> (T, J, D) positions (same T), D = 3 or 2; the joints are
        drawn as dots and the bones as lines (a marker set without bones shows its dots)
    parents : (J,) parent index per joint, -1 for the root
    path : output ``.gif`` path
    fps : frame rate of the input; the GIF plays at ``fps / step``, at most
        :data:`GIF_MAX_FPS` (:func:`gif_playback_fps`)
    up_axis : coordinate drawn vertically
    y_down : the vertical coordinate points down (image keypoints): drawn downwards
    step : draw every ``step``-th frame
    max_frames : at most this many GIF frames (the step grows for long recordings)
    window : frames ``(start, stop)`` to draw, every one of them (full rate: a one-frame
        spike is seen); ``step`` and ``max_frames`` then do not apply

    Returns
    -------
    pathlib.Path
    """
    plt = _pyplot()

    names = list(frames)
    arrays = [np.asarray(frames[n], dtype=float) for n in names]
    T = arrays[0].shape[0]
    if window is not None:
        step = 1
        idx = np.arange(max(0, window[0]), min(T, window[1]))
    else:
        step = max(step, int(np.ceil(T / max_frames)))
        idx = np.arange(0, T, step)
    if idx.size == 0:
        raise ValueError(f"animate_skeletons: no frame to draw (window {window}, {T} frames)")
    colours = _colours(names)
    h, v = _view_axes(up_axis)
    # the frames drawn set the view, a few wild samples do not (a spike leaves the box
    # for a frame instead of shrinking every skeleton to a speck)
    d = arrays[0].shape[-1]
    allpts = np.concatenate([a[idx].reshape(-1, d) for a in arrays])
    lo, hi = _view_box(allpts, 0.5, 0.09)
    fig, axes = plt.subplots(1, len(names), figsize=(2.6 * len(names), 3.2), squeeze=False)
    lines = []
    for ax, name in zip(axes[0], names):
        _frame_axes(ax, lo, hi, h, v, y_down)
        ax.set_title(name, fontsize=9)
        segs = [ax.plot([], [], color=colours[name])[0] for par in parents if par >= 0]
        segs.append(ax.plot([], [], ".", color=colours[name], ms=3)[0])  # the joints
        lines.append(segs)
    label = fig.text(0.01, 0.01, "", fontsize=8)
    bones = [(j, par) for j, par in enumerate(parents) if par >= 0]

    def draw(t: int):
        for segs, a in zip(lines, arrays):
            p = a[t]
            for seg, (j, par) in zip(segs, bones):
                seg.set_data([p[par, h], p[j, h]], [p[par, v], p[j, v]])
            segs[-1].set_data(p[:, h], p[:, v])
        label.set_text(f"t = {t / fps:5.2f} s   frame {t}")
        return [s for segs in lines for s in segs]

    images = []
    for t in idx:
        draw(int(t))
        fig.canvas.draw()
        images.append(np.asarray(fig.canvas.buffer_rgba())[..., :3].copy())
    plt.close(fig)
    path = Path(path)
    _save_gif(images, path, 1000.0 / gif_playback_fps(fps / step), [colours[n] for n in names])
    return path


#: colours of an animation's shared palette: the figure has a few flat colours (white,
#: black, one per method) and their anti-aliased edges; 32 keep the edges smooth
GIF_COLOURS = 32
#: a palette colour this close (per channel) to another is left out: Pillow maps a pixel
#: to a palette colour by a coarse search, which may take (254, 253, 253) for white
GIF_TWIN = 8


def _save_gif(
    images: Sequence[np.ndarray], path: Path, frame_ms: float, keep: Sequence[Any] = ()
) -> None:
    """Write RGB frames as a looping GIF with one palette for all of them and Pillow's
    frame differencing: a third to a half of the size of a GIF with a palette per frame.

    The palette holds white, black and the colours ``keep`` (each method's: a few small
    dots of a colour must not be merged into another), then the colours of the first,
    middle and last frames (median cut) up to :data:`GIF_COLOURS`, less near twins."""
    from matplotlib.colors import to_rgb
    from PIL import Image

    fixed = [(255, 255, 255), (0, 0, 0)]
    fixed += [tuple(round(255 * c) for c in to_rgb(k)) for k in keep]
    picks = [images[0], images[len(images) // 2], images[-1]]
    sample = Image.fromarray(np.concatenate(picks, axis=0))
    n_free = max(GIF_COLOURS - len(fixed), 2)
    free = sample.quantize(colors=n_free, method=Image.Quantize.MEDIANCUT).getpalette()
    rgb = list(fixed)
    for i in range(min(n_free, len(free) // 3)):  # not a near twin of one already in:
        colour = tuple(free[3 * i : 3 * i + 3])  # Pillow's mapping might take the twin
        if all(max(abs(a - b) for a, b in zip(colour, c)) > GIF_TWIN for c in rgb):
            rgb.append(colour)
    palette = Image.new("P", (1, 1))
    palette.putpalette([c for colour in rgb for c in colour])
    frames = [
        Image.fromarray(a).quantize(palette=palette, dither=Image.Dither.NONE) for a in images
    ]
    frames[0].save(
        path,
        format="GIF",
        save_all=True,
        append_images=frames[1:],
        duration=int(frame_ms),
        loop=0,
        optimize=True,
    )


def plot_bar_table(rows: Mapping[str, float], *, title: str = "", unit: str = "cm"):
    """Horizontal bar chart of one metric per method (e.g. pooled RMSE)."""
    plt = _pyplot()
    names = list(rows)
    values = [rows[n] for n in names]
    colours = _colours(names)
    fig, ax = plt.subplots(figsize=(6, 0.35 * len(names) + 1.2))
    ax.barh(names, values, color=[colours[n] for n in names])
    ax.invert_yaxis()
    ax.set_xlabel(unit)
    for i, val in enumerate(values):
        ax.text(val, i, f" {val:.2f}", va="center", fontsize=8)
    if title:
        ax.set_title(title)
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    return fig
