"""A self-contained HTML report: metrics tables, coordinate traces, skeleton snapshots, GIF.

Every figure is embedded as a ``data:`` URI, so the page is one file that can be mailed
or attached to a lab notebook. Plotting uses :mod:`tobitkf.app.plots` (matplotlib, lazily).
"""

from __future__ import annotations

import html
import tempfile
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

GLITCH_THRESHOLD_M = 0.10

#: the glitch threshold of a track without a length unit (pixels, unknown): this share of
#: the body's height in the image (10 cm on a person 1.7 m tall)
GLITCH_SHARE_OF_HEIGHT = GLITCH_THRESHOLD_M / 1.7

#: methods drawn in the coordinate traces by default: the paper's filter, the best
#: published offline smoother, and ours (the tables always list every method)
FOCUS_METHODS = ("atkf", "kf+rts", "robust", "robust_online")

#: the method whose ±2 sd band the traces draw (the default smoother, when it is traced
#: and its output has a posterior sd)
BAND_METHOD = "robust"


@dataclass(frozen=True)
class TableSpec:
    """One table of the report."""

    title: str
    columns: list[str]
    rows: list[list[Any]]
    note: str = ""


@dataclass(frozen=True)
class ReportInput:
    """Everything a report shows.

    Attributes
    ----------
    title : page title
    raw : the input track (SkeletonSequence)
    methods : method name -> smoothed SkeletonSequence (same frames and joints as ``raw``)
    truth : (T, J, 3) ground truth in the raw track's frame and times, NaN where a joint
        has no mocap partner; None without ground truth
    tables : metric tables shown at the top
    notes : paragraphs of plain text (conclusions, caveats)
    figures : extra figures (name -> PNG bytes) to embed
    animate : methods drawn in the animation next to raw (default: the first method)
    traces : methods drawn in the coordinate traces (default: all; tables always show all)
    reference : without truth, the output the raw track is held against for the glitch
        shading (``BAND_METHOD``'s, run for this when it is not among ``methods``); None:
        ``BAND_METHOD`` in ``methods``, else the first method
    """

    title: str
    raw: Any
    methods: Mapping[str, Any]
    truth: np.ndarray | None = None
    tables: Sequence[TableSpec] = ()
    notes: Sequence[str] = ()
    figures: Mapping[str, bytes] = field(default_factory=dict)
    animate: Sequence[str] = ()  # methods shown in the GIF next to raw (default: the first)
    traces: Sequence[str] = ()  # methods drawn in the coordinate traces (default: all)
    reference: Any = None  # without truth: the output glitches are measured against


def glitch_mask(raw: np.ndarray, reference: np.ndarray, threshold: float = GLITCH_THRESHOLD_M):
    """Frames × joints where the raw track is more than ``threshold`` from a reference.

    Parameters
    ----------
    raw, reference : (T, J, D), D = 3 or 2 (image keypoints), in the same units
    threshold : in those units

    Returns
    -------
    (T, J) bool
    """
    err = np.linalg.norm(np.asarray(raw, float) - np.asarray(reference, float), axis=-1)
    return np.nan_to_num(err, nan=0.0) > threshold


def glitch_threshold(track: Any) -> tuple[float, str]:
    """The glitch threshold in ``track``'s units, and how the page says it.

    10 cm in a length unit (``0.1`` in metres, ``100`` in millimetres); for pixels or
    unknown units, :data:`GLITCH_SHARE_OF_HEIGHT` of the body's median height in the
    recording (the extent of its joints along the up axis)."""
    scale = track.metres_per_unit
    if scale is not None:
        return GLITCH_THRESHOLD_M / scale, f"{100 * GLITCH_THRESHOLD_M:.0f} cm"
    pos = np.asarray(track.positions, dtype=float)
    up = int(getattr(track.topology, "up_axis", 1)) if pos.shape[-1] == 3 else 1
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # frames with no joint at all
        heights = np.nanmax(pos[..., up], axis=1) - np.nanmin(pos[..., up], axis=1)
        height = float(np.nanmedian(heights)) if np.isfinite(heights).any() else 0.0
    threshold = GLITCH_SHARE_OF_HEIGHT * height if height > 0 else 1.0
    unit = track.units or "units"
    return threshold, (
        f"{threshold:.3g} {unit} ({100 * GLITCH_SHARE_OF_HEIGHT:.0f} % of the body's height)"
    )


def pick_joints(mask: np.ndarray, raw: np.ndarray, n: int = 3) -> list[int]:
    """Joints to plot: those with most glitch frames, then those with the largest jumps."""
    from tobitkf.skeleton.sequence import largest_jumps

    counts = mask.sum(axis=0)
    jump, _ = largest_jumps(raw)
    score = counts * 1e3 + np.nan_to_num(jump, nan=0.0)
    return [int(j) for j in np.argsort(-score)[:n]]


def _table_html(spec: TableSpec) -> str:
    def cell(v: Any) -> str:
        if v is None:  # not applicable (raw has no clipping) or not measured
            return "–"
        if isinstance(v, (float, np.floating)):
            return "–" if not np.isfinite(v) else f"{float(v):.2f}"
        return html.escape(str(v))

    head = "".join(f"<th>{html.escape(c)}</th>" for c in spec.columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{cell(v)}</td>" for v in row) + "</tr>" for row in spec.rows
    )
    note = f"<p class='note'>{html.escape(spec.note)}</p>" if spec.note else ""
    return (
        f"<h2>{html.escape(spec.title)}</h2><div class='table-scroll'><table><thead>"
        f"<tr>{head}</tr></thead><tbody>{body}</tbody></table></div>{note}"
    )


#: frames of the animation, all drawn (at full rate) around the worst glitch
GIF_FRAMES = 120


def make_figures(
    inp: ReportInput,
    *,
    gif: bool = True,
    n_joints: int = 3,
    captions: dict[str, str] | None = None,
) -> dict[str, bytes]:
    """Render the report's figures; returns name -> PNG or GIF bytes.

    ``captions``, when given, is filled with name -> what the figure shows."""
    if captions is None:
        captions = {}
    from tobitkf.app import plots

    raw = np.asarray(inp.raw.positions, dtype=float)
    names = list(inp.methods)
    # without truth, the raw track is held against the default smoother, which rejects
    # glitches (a plain Kalman filter follows a sustained one and lags a fast movement)
    ref_name = BAND_METHOD if BAND_METHOD in names else names[0] if names else ""
    if inp.truth is not None:
        reference = inp.truth
    elif inp.reference is not None:
        ref_name, reference = BAND_METHOD, np.asarray(inp.reference.positions)
    else:
        reference = np.asarray(inp.methods[ref_name].positions) if names else raw
    threshold, threshold_text = glitch_threshold(inp.raw)
    mask = glitch_mask(raw, reference, threshold)
    times = np.asarray(inp.raw.times(), dtype=float)
    figures: dict[str, bytes] = dict(inp.figures)
    joint_names = list(inp.raw.joint_names)
    against = (
        "the truth"
        if inp.truth is not None
        else f"the {ref_name} output" + (" (not drawn)" if ref_name not in names else "")
        if names or inp.reference is not None
        else ""
    )
    shade_label = f"raw > {threshold_text.split(' (')[0]} from {against}"
    image = raw.shape[-1] == 2  # image keypoints: pixels, y pointing down
    unit = inp.raw.units or "units"
    axes_text = "x and y (pointing down, as in the image)" if image else "x, y and z"
    for j in pick_joints(mask, raw, n_joints):
        series: dict[str, np.ndarray] = {"raw": raw[:, j]}
        for name in [n for n in inp.traces if n in inp.methods] or names:
            series[name] = np.asarray(inp.methods[name].positions, float)[:, j]
        if inp.truth is not None and np.isfinite(inp.truth[:, j]).any():
            series["truth"] = inp.truth[:, j]
        std = getattr(inp.methods.get(BAND_METHOD), "std", None) if BAND_METHOD in series else None
        bands = {BAND_METHOD: np.asarray(std, float)[:, j]} if std is not None else {}
        shade = plots.episodes(mask[:, j])
        fig = plots.plot_joint_traces(
            times,
            series,
            title=f"{joint_names[j]}",
            shade=shade,
            unit=unit,
            shade_label=shade_label,
            bands=bands,
            y_down=image,
        )
        name = f"traces_{joint_names[j]}.png"
        figures[name] = plots.figure_to_png(fig)
        band_text = (
            f" Light band in {BAND_METHOD}'s colour ({BAND_METHOD} ± 2 sd): the {BAND_METHOD} "
            "curve plus and minus twice its own posterior standard deviation on each axis, "
            "where it says the true position lies (about 95 % of the time on one axis, if "
            "the sd is honest)."
            if bands
            else ""
        )
        shade_text = (
            f" Shaded red: frames where the raw track is more than {threshold_text} from "
            f"{against}. {joint_names[j]} is one of the {n_joints} joints with the most such "
            "frames."
            if shade
            else f" No frame of {joint_names[j]} is more than {threshold_text} from "
            f"{against} (nothing shaded); it is one of the {n_joints} joints with the "
            "largest one-frame jumps."
        )
        captions[name] = (
            f"{joint_names[j]}: {axes_text} over time, raw track (grey dots) against "
            f"{', '.join(n for n in series if n != 'raw')}.{band_text}{shade_text}"
            if len(series) > 1
            else f"{joint_names[j]}: {axes_text} over time, the raw track alone (no method "
            f"or truth to compare it with); one of the {n_joints} joints with the largest "
            "one-frame jumps."
        )

    # skeletons before, during and after the worst glitch (the raw track alone: the
    # sample furthest from the mean of its two neighbours, the top of a one-frame spike)
    err = np.linalg.norm(raw - reference, axis=-1)
    furthest = f"where the raw track is furthest from {against}"
    if not against and raw.shape[0] > 2:
        err = np.zeros(raw.shape[:2])
        err[1:-1] = np.linalg.norm(raw[1:-1] - 0.5 * (raw[:-2] + raw[2:]), axis=-1)
        furthest = "where a raw sample is furthest from its neighbouring frames"
    worst = int(np.nanargmax(np.nan_to_num(err, nan=-1.0).max(axis=1))) if raw.size else 0
    # a recording without glitches is not said to have a worst one
    around = (
        f"the worst glitch at frame {worst}"
        if mask.any()
        else f"frame {worst}, where the raw track is furthest from {against} (no glitch: "
        f"never more than {threshold_text})"
    )
    T = raw.shape[0]
    cols = sorted({max(0, worst - 10), worst, min(T - 1, worst + 10)})
    frames: dict[str, np.ndarray] = {"raw": raw}
    for name in names:
        frames[name] = np.asarray(inp.methods[name].positions, float)
    if inp.truth is not None:
        frames["truth"] = inp.truth
    parents = list(inp.raw.topology.parents)
    up = int(getattr(inp.raw.topology, "up_axis", 1))
    fig = plots.plot_skeleton_frames(
        frames,
        cols,
        parents,
        up_axis=up,
        frame_labels=[f"frame {c}" + (" (worst)" if c == worst else "") for c in cols],
        title="skeletons around the worst glitch"
        if mask.any()
        else f"skeletons where raw is furthest from {against}"
        if against
        else "skeletons around the raw track's largest spike",
        y_down=image,
    )
    figures["skeletons_worst_glitch.png"] = plots.figure_to_png(fig)
    # the recording's own axes, not "from the front": Kinect camera space has x to the
    # sensor's left, so a person facing it is drawn as in a mirror
    h, v = (plots.AXIS_NAMES[k] for k in plots._view_axes(up))
    view = (
        "as in the image"
        if image
        else f"in the recording's {h}-{v} plane ({h} to the right, {v} up)"
    )
    captions["skeletons_worst_glitch.png"] = (
        f"Skeletons {view} at frames {', '.join(map(str, cols))}: around frame "
        f"{worst}, {furthest}; one column per method."
    )

    if gif and names:
        shown = [n for n in inp.animate if n in frames] or names[:1]
        anim = {"raw": raw, **{n: frames[n] for n in shown}}
        if inp.truth is not None:
            anim["truth"] = inp.truth
        # every frame of a window around the worst glitch: a one-frame spike is seen
        start = int(np.clip(worst - GIF_FRAMES // 2, 0, max(0, T - GIF_FRAMES)))
        stop = min(T, start + GIF_FRAMES)
        fps = float(inp.raw.fps or 30.0)
        with tempfile.TemporaryDirectory() as tmp:
            path = plots.animate_skeletons(
                anim,
                parents,
                Path(tmp) / "anim.gif",
                fps=fps,
                up_axis=up,
                window=(start, stop),
                y_down=image,
            )
            figures["animation.gif"] = path.read_bytes()
        slowed = fps / plots.gif_playback_fps(fps)
        speed = (
            "real time"
            if slowed < 1.05
            else f"slowed down {slowed:.1f} times: a GIF plays at most "
            f"{plots.GIF_MAX_FPS:.0f} frames a second"
        )
        captions["animation.gif"] = (
            f"Animation of frames {start} to {stop - 1} ({(stop - start) / fps:.1f} s, every "
            f"frame, {speed}) around {around}: "
            f"{', '.join(anim)} side by side."
        )
    return figures


_CSS = """
body{font-family:system-ui,sans-serif;max-width:1300px;margin:2em auto;padding:0 1em;
color:#222}
h1,h2{overflow-wrap:anywhere}
figure{margin:1em 0}
.table-scroll{overflow-x:auto;max-width:100%;margin:0.5em 0 1em}
table{border-collapse:collapse}
th{vertical-align:bottom}
th,td{border:1px solid #ccc;padding:3px 8px;text-align:right;font-size:0.9em}
th:first-child,td:first-child{text-align:left}
th{background:#f3f3f3} img{max-width:100%;border:1px solid #eee;margin:0.3em 0}
.note{color:#555;font-size:0.9em}
.warning{border-left:4px solid #c60;background:#fff4e5;padding:0.4em 0.8em}
"""


def render_html(
    inp: ReportInput,
    figures: Mapping[str, bytes],
    captions: Mapping[str, str] | None = None,
) -> str:
    """The report page as one HTML string with embedded figures (``captions``: name ->
    what the figure shows; the name when missing)."""
    captions = captions or {}
    from tobitkf.app.plots import png_data_uri

    parts = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'>",
        "<meta name='viewport' content='width=device-width, initial-scale=1'>",
        f"<title>{html.escape(inp.title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{html.escape(inp.title)}</h1>",
    ]
    for note in inp.notes:  # a warning (a doubtful time fit) stands out from the text
        css = " class='warning'" if note.startswith("Warning:") else ""
        parts.append(f"<p{css}>{html.escape(note)}</p>")
    for spec in inp.tables:
        parts.append(_table_html(spec))
    parts.append("<h2>Figures</h2>")
    for name, data in figures.items():
        mime = "image/gif" if name.endswith(".gif") else "image/png"
        parts.append(
            f"<figure><img alt='{html.escape(name)}' src='{png_data_uri(data, mime)}'>"
            f"<figcaption class='note'>{html.escape(captions.get(name, name))}</figcaption>"
            "</figure>"
        )
    parts.append("</body></html>")
    return "\n".join(parts)


def write_report(inp: ReportInput, path: str | Path, *, gif: bool = True) -> Path:
    """Render figures and write the self-contained HTML report to ``path``."""
    captions: dict[str, str] = {}
    figures = make_figures(inp, gif=gif, captions=captions)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.part")
    tmp.write_text(render_html(inp, figures, captions), encoding="utf-8")
    tmp.replace(path)
    return path


def _table_from_rows(title: str, rows: Sequence[Mapping[str, Any]], note: str = "") -> TableSpec:
    columns = list(rows[0]) if rows else []
    return TableSpec(title, columns, [[r.get(c) for c in columns] for r in rows], note)


#: column headers of the accuracy table (the unit is in the table's title)
_HEADERS = {
    "rmse_cm": "RMSE",
    "hands_cm": "hands",
    "arms_cm": "arms",
    "torso_cm": "torso",
    "legs_cm": "legs",
    "p95_cm": "p95",
    "max_cm": "max",
    "frames_over": "frames > 10 cm",
    "fine_cm": "fine",
    "short_glitch_cm": "short glitch",
    "sustained_cm": "sustained",
    "lag_frames": "hand lag (frames)",
    "in_95_ball_pct": "in 95% ball (%)",
}


def _angle_header(key: str) -> str:
    """``right_elbow_best_deg`` -> ``right elbow best``: short enough to fit the page."""
    for suffix in ("_best_deg", "_fixed_deg", "_delay"):
        if key.endswith(suffix):
            return f"{key[: -len(suffix)].replace('_', ' ')} {suffix.split('_')[1]}"
    return key


def _mean_percent(value: Any) -> float | None:
    if value is None:
        return None
    arr = np.asarray(value, dtype=float)
    return 100.0 * float(np.nanmean(arr)) if arr.size and np.isfinite(arr).any() else None


def _display_row(row: Mapping[str, Any], output: Any = None) -> dict[str, Any]:
    """An accuracy row for display: angles dropped (own table), M in 1e-3 m², readable
    headers, and what the method did to the measurements: the Tobit filters clip them
    (clipped %), the robust methods reject impossible ones (rejected %); "–" where a
    method does neither (raw, the baselines)."""
    diag = (getattr(output, "metadata", None) or {}).get("diagnostics") or {}
    rejected = _mean_percent(diag.get("rejected_fraction"))
    out: dict[str, Any] = {}
    for k, v in row.items():
        if k.endswith(("_deg", "_delay")):
            continue
        if k == "M":
            out["M (1e-3 m²)"] = None if v is None else 1e3 * v
        elif k == "clipped_fraction":
            clipped = None if v is None or rejected is not None else 100.0 * v
            out["clipped (%)"] = clipped
            out["rejected (%)"] = rejected
        else:
            out[_HEADERS.get(k, k)] = v
    return out


def no_truth_rows(table: Any) -> list[dict[str, Any]]:
    """The rows of a :class:`~tobitkf.evaluation.evaluate.NoTruthTable` as the report
    shows them: M in 1e-3 m² and jumps in cm when the track has a length unit, else in
    its own units (pixels)."""
    metric = table.units == "m"
    unit = table.units or "units"
    return [
        {
            "method": r["method"],
            ("M (1e-3 m²)" if metric else f"M ({unit}²)"): (1e3 if metric else 1) * r["M"],
            f"largest jump ({'cm' if metric else unit})": (100 if metric else 1) * r["max_jump_m"],
            "at": f"{r['jumps'][0]['joint']} frame {r['jumps'][0]['frame']}" if r["jumps"] else "-",
        }
        for r in table.rows
    ]


def summary_rows(table: Any) -> list[dict[str, Any]]:
    """A few columns per method for a narrow terminal (the page has every column): RMSE,
    max and the 95 % ball against ground truth, else :func:`no_truth_rows`."""
    if not hasattr(table, "score"):
        return no_truth_rows(table)
    keys = {"method": "method", "RMSE": "RMSE (cm)", "max": "max (cm)"}
    keys["in 95% ball (%)"] = "in 95% ball (%)"
    return [{v: _display_row(r).get(k) for k, v in keys.items()} for r in table.rows()]


def _source_name(seq: Any) -> str:
    """The file name a sequence was read from (not its folders: the page may be mailed)."""
    source = (getattr(seq, "metadata", None) or {}).get("source")
    return Path(str(source)).name if source else "recording"


def _title(track: Any, mocap: Any = None) -> str:
    # a file of several bodies: which one the page shows
    body = f" (body {track.body_id})" if getattr(track, "body_id", None) is not None else ""
    against = f" against {_source_name(mocap)}" if mocap is not None else ""
    return f"tobitkf report: {_source_name(track)}{body}{against}"


def methods_for_units(specs: Sequence[Any], track: Any) -> tuple[list[Any], list[str]]:
    """The method specs that run on ``track`` with their default parameters, and the names
    left out: those whose defaults are lengths in metres (``atkf``'s half-widths) cannot
    smooth pixels or unknown units (``tobitkf report`` without ``--methods``)."""
    from tobitkf.smoothing.registry import methods

    registered = methods()
    units = "m" if track.metres_per_unit is not None else track.units
    kept, left_out = [], []
    for spec in specs:
        method = registered.get(spec.removesuffix("+rts")) if isinstance(spec, str) else None
        try:
            if method is not None and method.check_data is not None:
                method.check_data(dict(method.defaults), track.n_dims, units)
        except ValueError:
            left_out.append(spec)
            continue
        kept.append(spec)
    return kept, left_out


def _band_reference(track: Any) -> Any:
    """``BAND_METHOD``'s output of ``track``, the glitch shading's reference without truth
    when the methods shown do not include it (a Kalman filter follows a sustained glitch,
    so shading against it would miss the glitch); None when it cannot smooth the track."""
    from tobitkf.smoothing.api import smooth

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return smooth(track, BAND_METHOD)
    except (ValueError, KeyError):
        return None


def track_report(
    track: Any,
    path: str | Path,
    *,
    mocap: Any = None,
    truth: np.ndarray | None = None,
    methods: Sequence[Any] | None = None,
    pairs: Any = None,
    title: str | None = None,
    gif: bool = True,
    notes: Sequence[str] = (),
    on_drawing: Any = None,
) -> tuple[Path, Any]:
    """Evaluate methods on ``track`` and write the HTML report (``tobitkf report``).

    Parameters
    ----------
    track : SkeletonSequence, the raw recording
    path : output HTML path
    mocap : optional motion-capture SkeletonSequence; it is paired, time-aligned and
        registered onto the raw track (:func:`tobitkf.evaluation.evaluate.prepare_truth`)
    truth : optional (T, J, 3) ground truth already in the track's frame (synthetic data)
    methods : method specs for :func:`~tobitkf.evaluation.evaluate.evaluate_methods`
    pairs : pairing table or CSV path for ``mocap``
    title, gif, notes : page title, whether to embed the animation, extra paragraphs
    on_drawing : optional ``on_drawing()``, called when the methods have run and the
        figures are drawn (the command line's progress)

    Returns
    -------
    (path, table) : the written report and the evaluation table
    """
    from tobitkf.evaluation.evaluate import (
        DEFAULT_METHODS,
        evaluate_methods,
        evaluate_without_truth,
        prepare_truth,
    )

    methods = list(methods or DEFAULT_METHODS)
    outputs: dict[str, Any] = {}
    truth_positions = None
    if mocap is not None:  # scored in metres: the page's traces too (truth.metric)
        from tobitkf.evaluation.truth import metric

        track = metric(track, "track")
    if mocap is not None or truth is not None:
        gt = prepare_truth(track, mocap, pairs=pairs) if mocap is not None else truth
        if mocap is not None:  # a doubtful time fit must be seen on the page, not only in a log
            notes = [*notes, *(f"Warning: {w}." for w in gt.notes.get("warnings", []))]
        table = evaluate_methods(track, gt, methods, outputs=outputs)
        truth_positions = gt.positions if mocap is not None else np.asarray(truth, float)
        tables = [
            _table_from_rows(
                "Accuracy against ground truth (cm, lag in frames)",
                [_display_row(r, outputs.get(r["method"])) for r in table.rows()],
                note="fine / short_glitch / sustained: samples where the RAW track is within "
                "10 cm of the truth, off for at most 4 frames, or off for longer. "
                "in 95% ball: % of samples whose 3-D error lies within the 95 % ball of the "
                "method's own posterior sd (95 if the sd is honest; – : no sd). "
                "clipped (%): measurements a Tobit filter took as clipped at the sensor's "
                "limits; rejected (%): samples the robust methods judged physically "
                "impossible and filled; – : the method does neither.",
            )
        ]
        angle_rows = [
            {
                "method": r["method"],
                **{k: v for k, v in r.items() if k.endswith(("_deg", "_delay"))},
            }
            for r in table.rows()
        ]
        angle_rows = [{_angle_header(k): v for k, v in r.items()} for r in angle_rows]
        if angle_rows and len(angle_rows[0]) > 1:
            tables.append(
                _table_from_rows(
                    "Joint angles against ground truth: RMSE in degrees at the best delay (best, "
                    "delay in frames) and at one fixed delay for every method (fixed)",
                    angle_rows,
                )
            )
    else:
        table = evaluate_without_truth(track, methods, outputs=outputs)
        rows = no_truth_rows(table)
        tables = [_table_from_rows("Smoothness M (2020 paper eq. 41) and largest jumps", rows)]
    smoothed = {k: v for k, v in outputs.items() if k != "raw" and hasattr(v, "positions")}
    reference = None
    if truth_positions is None and smoothed and BAND_METHOD not in smoothed:
        reference = _band_reference(track)
    inp = ReportInput(
        title=title or _title(track, mocap),
        raw=track,
        methods=smoothed,
        truth=truth_positions,
        tables=tables,
        notes=list(notes),
        animate=[m for m in ("atkf", "robust") if m in smoothed],
        traces=[m for m in FOCUS_METHODS if m in smoothed],
        reference=reference,
    )
    if on_drawing is not None:
        on_drawing()
    return write_report(inp, path, gif=gif), table
