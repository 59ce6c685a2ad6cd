"""``tobitkf evaluate``, ``report`` and ``benchmark``: methods against a truth."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import click
from rich.markup import escape
from rich.text import Text

from tobitkf.app.commands._common import (
    _fail,
    _finite,
    _fps_option,
    _input_format_option,
    _load_one,
    _need_matplotlib,
    _noticing_compiles,
    _print_table,
    _progress,
    _ticking,
    _topology_option,
    _units_option,
    _writable_file,
    _writable_folder,
    app,
    console,
    err_console,
)
from tobitkf.core.jsonable import dumps


# --------------------------------------------------------------------------- evaluate
def _method_list(text: str | None) -> list[str] | None:
    from tobitkf.evaluation.evaluate import resolve_method

    if not text:
        return None
    names = [m.strip() for m in text.split(",") if m.strip()]
    if not names:
        raise click.BadParameter("no method named", param_hint="--methods")
    for name in names:  # an unknown name fails before any file is read or fitted
        try:
            resolve_method(name)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--methods") from exc
    return names


def _for_units(specs: list[Any], track: Any, path: str) -> tuple[list[Any], str]:
    """The default methods that can smooth ``track``'s units, and the note saying which
    were left out (printed; empty when none): ``atkf``'s default half-widths are metres."""
    from tobitkf.app.report import methods_for_units

    kept, left_out = methods_for_units(specs, track)
    if not left_out:
        return kept, ""
    note = (
        f"Left out: {', '.join(left_out)} (default parameters in metres; this "
        f"recording is in {track.units or 'unknown units'}). To include one, name "
        "it in --methods with half-widths in the recording's units, e.g. atkf[c=20]."
    )
    err_console.print(f"{escape(path)}: {escape(note)}")
    return kept, note


@app.command()
@click.argument("tracks", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False))
@click.option(
    "-t",
    "--truth",
    "truths",
    multiple=True,
    type=click.Path(exists=True, dir_okay=False),
    help="Motion-capture file, one per TRACK, in the same order.",
)
@click.option(
    "--truth-replace",
    nargs=2,
    metavar="OLD NEW",
    default=None,
    help="Find each TRACK's motion-capture file by replacing OLD with NEW in its path "
    "(e.g. --truth-replace /Kinect/ /Vicon/), instead of --truth.",
)
@click.option(
    "--methods",
    default=None,
    help="Comma-separated methods (default: raw, kf, atkf, atkf2016, sgf, kf+rts, "
    "one_euro, kinect and our robust methods). `<name>+rts` = offline smoother.",
)
@click.option(
    "--pairs",
    type=click.Path(exists=True, dir_okay=False),
    default=None,
    help="CSV pairing table: track_joint,mocap_point[+mocap_point...].",
)
@click.option(
    "--fixed-delay",
    default=0,
    show_default=True,
    help="Delay (frames) used for every method in the fixed-delay angle RMSE.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON.")
@click.option(
    "--markdown",
    "as_markdown",
    is_flag=True,
    help="Print Markdown tables (pooled, per recording, warnings), as in the docs.",
)
@click.option(
    "-o",
    "--out",
    "outdir",
    type=click.Path(file_okay=False),
    default=None,
    help="Also write results.json here: every recording's scores and the pooled table, "
    "as --json prints them.",
)
@_input_format_option("--format", help="Input format of every TRACK.")
@_input_format_option(
    "--truth-format", dest="truth_format", help="Input format of every --truth file."
)
@_fps_option(
    "Frame rate (Hz) of each TRACK that states none (keypoint tables, .npy arrays); "
    "a file with its own rate or timestamps keeps it."
)
@_topology_option(
    "Skeleton of each TRACK that names none (a .npy array's joints 0, 1, ...; MMPose "
    "output of an unknown model), e.g. h36m17 or coco17; files naming their own keep it."
)
@_units_option(
    "Length unit of each TRACK that states none (a CSV without its sidecar, read as "
    "metres in 3-D; a .npy array), e.g. mm; files stating their own keep it."
)
@_noticing_compiles
def evaluate(
    tracks,
    truths,
    truth_replace,
    methods,
    pairs,
    fixed_delay,
    as_json,
    as_markdown,
    outdir,
    input_format,
    truth_format,
    fps,
    topology,
    units,
):
    """Score smoothing methods on each TRACK against motion capture (or without it).

    With --truth: per-method RMSE (pooled, per joint group, by raw glitch class), p95,
    max, frames over 10 cm, smoothness M, hand lag and joint-angle RMSE; several
    TRACK/--truth pairs also get a pooled table. Without --truth: the paper's Table 3
    (smoothness M) and the largest jumps.
    """
    from tobitkf.evaluation.evaluate import (
        default_methods,
        evaluate_methods,
        evaluate_without_truth,
        pool_scores,
        prepare_truth,
    )

    method_specs = _method_list(methods) or default_methods()
    if truth_replace:
        if truths:
            _fail("give --truth or --truth-replace, not both")
        old, new = truth_replace
        absent = [p for p in tracks if old not in p]
        if absent:
            _fail(f"--truth-replace {old!r} {new!r}: {old!r} is not in the path {absent[0]}")
        truths = tuple(p.replace(old, new) for p in tracks)
        missing = [
            t for t, p in zip(truths, tracks, strict=True) if t == p or not Path(t).is_file()
        ]
        if missing:
            _fail(f"--truth-replace {old!r} {new!r}: no motion-capture file {missing[0]}")
    if truths and len(truths) != len(tracks):
        _fail(f"{len(tracks)} tracks but {len(truths)} --truth files; give one per track")
    if as_json and as_markdown:
        _fail("give --json or --markdown, not both")
    if as_markdown and not truths:
        _fail("--markdown prints the tables against ground truth: give --truth")
    if outdir:  # before the work, not after it
        _writable_folder(outdir, "results.json")
    quiet = as_json or as_markdown
    results: dict[str, Any] = {}
    tables = []
    warned: list[tuple[str, str]] = []
    with _progress() as progress:
        task = progress.add_task("evaluating", total=len(tracks) * len(method_specs), now="")
        for i, path in enumerate(tracks):
            progress.update(task, description=f"{Path(path).name} ({i + 1}/{len(tracks)})")
            track = _load_one(path, "track", input_format, fps=fps, topology=topology, units=units)
            run_specs = method_specs
            if not methods:  # the defaults, less those that cannot smooth this track
                run_specs, _note = _for_units(method_specs, track, path)
                progress.advance(task, len(method_specs) - len(run_specs))
            specs = _ticking(run_specs, progress, task)
            try:
                if truths:
                    mocap = _load_one(truths[i], "truth", truth_format)
                    gt = prepare_truth(track, mocap, pairs=pairs)
                    for warning in gt.notes.get("warnings", []):
                        err_console.print(
                            f"[yellow]warning[/yellow] {escape(path)}: {escape(warning)}"
                        )
                        warned.append((path, warning))
                    table = evaluate_methods(track, gt, specs, fixed_delay=fixed_delay)
                    tables.append(table)
                else:
                    table = evaluate_without_truth(track, specs)
            except (ValueError, KeyError) as exc:
                _fail(f"{path}: {exc}")
            results[path] = table.to_dict()
            if not quiet:
                console.rule(f"[bold]{path}" + (f"  vs  {truths[i]}" if truths else ""))
                _print_scores(table, "every column is in --json")
    pooled = pool_scores(tables) if len(tables) > 1 else None
    if pooled is not None:
        results["pooled"] = pooled
        if not quiet:
            # the ball's per-class shares are in --json and --markdown (too wide here)
            cols = [c for c in pooled[0] if c != "method" and not c.endswith("_in_95_ball_pct")]
            scale = {"M": 1e3}  # M is in m²; shown in 1e-3 m²
            names = {"M": "M e-3", "in_95_ball_pct": "in 95% ball"}
            _print_table(
                f"pooled over {len(tables)} recordings (cm)",
                ["method", *[names.get(c, c.removesuffix("_cm")) for c in cols]],
                [[r["method"], *[_scaled(r[c], scale.get(c, 1.0)) for c in cols]] for r in pooled],
            )
    if outdir:
        out = Path(outdir)
        (out / "results.json").write_text(dumps(results))
        if not quiet:
            console.print(f"wrote {out / 'results.json'}")
    if as_json:
        click.echo(dumps(results))
    elif as_markdown:
        from tobitkf.evaluation.markdown import evaluation_markdown

        click.echo(evaluation_markdown(tables, list(tracks), pooled, warned), nl=False)


def _scaled(value: Any, factor: float) -> Any:
    return value * factor if isinstance(value, float) and factor != 1.0 else value


# --------------------------------------------------------------------------- report
@app.command()
@click.argument("track", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "-t",
    "--truth",
    type=click.Path(exists=True, dir_okay=False),
    default=None,
    help="Motion-capture file recorded together with TRACK.",
)
@click.option(
    "-o",
    "--output",
    default="report.html",
    show_default=True,
    type=click.Path(),
    help="HTML file to write; a folder (existing, or a path ending in /) gets report.html.",
)
@click.option("--methods", default=None, help="Comma-separated methods (see evaluate).")
@click.option(
    "--pairs",
    type=click.Path(exists=True, dir_okay=False),
    default=None,
    help="CSV pairing table for --truth.",
)
@click.option("--no-gif", is_flag=True, help="Leave out the skeleton animation.")
@_input_format_option("--format", help="Input format of TRACK.")
@_input_format_option("--truth-format", dest="truth_format", help="Input format of --truth.")
@_fps_option(
    "Frame rate (Hz) of TRACK if it states none; a file with its own rate or timestamps keeps it."
)
@_topology_option("Skeleton of TRACK if it names none, e.g. h36m17 or coco17.")
@_units_option("Length unit of TRACK if it states none (a CSV without its sidecar), e.g. mm.")
@_noticing_compiles
def report(
    track, truth, output, methods, pairs, no_gif, input_format, truth_format, fps, topology, units
):
    """Write a self-contained HTML report: metrics, traces, skeletons, animation."""
    from tobitkf.app.report import track_report
    from tobitkf.evaluation.evaluate import default_methods

    specs = _method_list(methods) or default_methods()
    if Path(output).is_dir() or str(output).endswith(("/", os.sep)):
        output = str(Path(output) / "report.html")  # not a file named after the folder
    _need_matplotlib("the report's figures")
    _writable_file(output, "the report")  # before seconds of evaluating and drawing
    raw = _load_one(track, "track", input_format, fps=fps, topology=topology, units=units)
    mocap = _load_one(truth, "truth", truth_format) if truth else None
    notes = []
    if not methods:  # the defaults, less those that cannot smooth this track's units
        specs, left_out = _for_units(specs, raw, track)
        if left_out:
            notes.append(left_out)
    # one step per method, then the figures (the slowest part with the animation)
    with _progress() as progress:
        task = progress.add_task(Path(track).name, total=len(specs) + 1, now="")
        try:
            path, table = track_report(
                raw,
                output,
                mocap=mocap,
                methods=_ticking(specs, progress, task),
                pairs=pairs,
                gif=not no_gif,
                notes=notes,
                on_drawing=lambda: progress.update(task, now="drawing figures"),
            )
        except ImportError as exc:
            _fail(str(exc))
        except (ValueError, KeyError) as exc:
            _fail(f"{track}: {exc}")
    for warning in (getattr(table, "truth", None) or {}).get("notes", {}).get("warnings", []):
        err_console.print(f"[yellow]warning[/yellow] {track}: {warning}")
    _print_scores(table, "every column is in the report")
    console.print(f"report written to {Path(path).resolve()}")


def _print_scores(table: Any, where: str) -> None:
    """A recording's scores: the whole table for a pipe, a log file or a terminal wide
    enough; a narrow terminal gets a few columns, whole words, instead of lines wrapped
    into each other (``where`` says where the rest is)."""
    from tobitkf.app.report import summary_rows

    text = table.to_text()
    if not console.is_terminal or max(map(len, text.splitlines()), default=0) <= console.width:
        console.print(Text(text), highlight=False, soft_wrap=True)
        return
    rows = summary_rows(table)
    _print_table(f"summary ({where})", list(rows[0]), [list(r.values()) for r in rows])


# --------------------------------------------------------------------------- benchmark
@app.command()
@click.option(
    "--seed",
    default=0,
    show_default=True,
    type=click.IntRange(min=0),
    help="Seed of motion and corruption.",
)
@click.option(
    "--seeds",
    default=1,
    show_default=True,
    type=click.IntRange(1, 1000),
    help="Repeat over this many consecutive seeds and average.",
)
@click.option(
    "--motion",
    default="mixed",
    show_default=True,
    type=click.Choice(["mixed", "walk", "arms", "squat"]),
)
@click.option(
    "--source",
    default="generator",
    show_default=True,
    help="'generator' (built in) or the path of a BVH file.",
)
@click.option(
    "--duration",
    default=10.0,
    show_default=True,
    type=click.FloatRange(min=0, max=3600, min_open=True),
    callback=lambda _ctx, _param, v: _finite(v, "--duration"),
    help="Seconds of motion.",
)
@click.option("--methods", default=None, help="Comma-separated methods (see evaluate).")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@click.option("--markdown", "as_markdown", is_flag=True, help="Print a Markdown table.")
@click.option(
    "--kind",
    default="kinect",
    show_default=True,
    type=click.Choice(["kinect", "pose2d"]),
    help="kinect: 3-D Kinect-like corruption (cm); pose2d: two people's 2-D keypoints "
    "in pixels with confidence, glitches and identity / left-right swaps (px).",
)
@click.option(
    "--fps",
    default=30.0,
    show_default=True,
    type=click.FloatRange(min=0, min_open=True),
    help="Frame rate of the recording: the motion is generated (or the BVH resampled) "
    "at it, and failures keep their duration in seconds.",
)
@_noticing_compiles
def benchmark(seed, seeds, motion, source, duration, methods, as_json, as_markdown, kind, fps):
    """Every method on a corrupted synthetic recording with known truth (RMSE by glitch)."""
    if as_json and as_markdown:
        _fail("give --json or --markdown, not both")
    if kind == "pose2d":
        _benchmark_pose2d(seed, seeds, motion, source, duration, methods, as_json, as_markdown,
                          fps)  # fmt: skip
        return
    from tobitkf.evaluation.benchmark import run_benchmark, seed_ball, seed_spread
    from tobitkf.evaluation.evaluate import default_methods

    specs = _method_list(methods) or default_methods()
    tables = _over_seeds(
        "benchmark",
        seed,
        seeds,
        lambda s: run_benchmark(
            seed=s, methods=specs, motion=motion, source=source, duration=duration, fps=fps
        ),
    )
    if as_json:
        click.echo(dumps([t.to_dict() for t in tables]))
        return
    spread = seed_spread(tables)
    if as_markdown:
        from tobitkf.evaluation.markdown import benchmark_markdown

        seed_list = list(range(seed, seed + seeds))
        click.echo(benchmark_markdown(spread, seed_list, seed_ball(tables)), nl=False)
        return
    if seeds == 1:
        console.print(Text(tables[0].to_text()), highlight=False, soft_wrap=True)
        return
    keys = [k for k in spread[0] if k != "method"]
    rows = [
        [r["method"], *[f"{100 * r[k][0]:.2f} ± {100 * r[k][1]:.2f}" for k in keys], b]
        for r, b in zip(spread, (b["in_95_ball_pct"] for b in seed_ball(tables)), strict=True)
    ]
    _print_table(
        f"RMSE (cm), mean ± sd over seeds {seed}..{seed + seeds - 1}; in 95% ball: % of "
        "samples within the 95 % ball of the method's sd (pooled)",
        ["method", *keys, "in 95% ball"],
        rows,
    )


def _over_seeds(label: str, seed: int, seeds: int, run: Any) -> list[Any]:
    """``run(s)`` for the consecutive seeds, with progress; a bad input fails cleanly."""
    tables = []
    with _progress() as progress:
        task = progress.add_task(label, total=seeds, now="")
        for s in range(seed, seed + seeds):
            progress.update(task, now=f"seed {s}")
            try:
                tables.append(run(s))
            except (ValueError, OSError) as exc:
                _fail(str(exc))
            progress.advance(task)
    return tables


def _benchmark_pose2d(seed, seeds, motion, source, duration, methods, as_json, as_markdown,
                      fps=30.0):  # fmt: skip
    """``benchmark --kind pose2d``: the 2-D pose-estimator benchmark (docs/pose.md)."""
    from tobitkf.evaluation.pose2d import (
        POSE2D_METHODS,
        pose2d_markdown,
        pose2d_spread,
        run_pose2d_benchmark,
    )

    if str(source) != "generator":
        _fail("--kind pose2d projects the built-in motions; --source must be 'generator'")
    specs = _method_list(methods) or list(POSE2D_METHODS)
    tables = _over_seeds(
        "pose2d benchmark",
        seed,
        seeds,
        lambda s: run_pose2d_benchmark(
            seed=s, methods=specs, motion=motion, duration=duration, fps=fps
        ),
    )
    if as_json:
        click.echo(dumps([t.to_dict() for t in tables]))
        return
    spread = pose2d_spread(tables)
    seed_list = list(range(seed, seed + seeds))
    if as_markdown:
        click.echo(pose2d_markdown(spread, seed_list), nl=False)
        return
    keys = [k for k in spread[0] if k != "method"]

    def cell(mean: float, sd: float) -> str:  # as --markdown: "–" where nothing is scored
        if not math.isfinite(mean):
            return "–"
        return f"{mean:.2f}" if seeds == 1 else f"{mean:.2f} ± {sd:.2f}"

    rows = [[r["method"], *[cell(*r[k]) for k in keys]] for r in spread]
    over = f"seed {seed}" if seeds == 1 else f"mean ± sd over seeds {seed}..{seed + seeds - 1}"
    _print_table(
        f"RMSE (px), {over}",
        ["method", *(k.removesuffix("_px") for k in keys)],
        rows,
    )
