"""The click application behind ``tobitkf`` (imported only when click is installed)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from tobitkf.cli import dumps

console = Console()
err_console = Console(stderr=True)


def _fail(message: str) -> None:
    raise click.ClickException(message)


def _fmt(value: Any, digits: int = 2) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        if value != value:  # NaN
            return "-"
        return f"{value:.{digits}f}"
    return str(value)


def _print_table(title: str, columns: list[str], rows: list[list[Any]], digits: int = 2) -> None:
    table = Table(title=title, title_justify="left")
    for i, col in enumerate(columns):
        table.add_column(col, justify="left" if i == 0 else "right")
    for row in rows:
        table.add_row(*[_fmt(v, digits) for v in row])
    console.print(table)


def _parse_params(params: tuple[str, ...]) -> dict[str, Any]:
    from tobitkf.batch import parse_param

    out: dict[str, Any] = {}
    for text in params:
        try:
            key, value = parse_param(text)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--param") from exc
        out[key] = value
    return out


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="tobitkf")
def app() -> None:
    """Tobit Kalman filtering of censored measurements, and skeleton-track smoothing."""


# --------------------------------------------------------------------------- smooth
@app.command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path(exists=True))
@click.option(
    "-o",
    "--outdir",
    default="smoothed",
    show_default=True,
    type=click.Path(),
    help="Folder for the outputs (created if needed). Inputs are never overwritten.",
)
@click.option(
    "-m",
    "--method",
    default="atkf",
    show_default=True,
    help="Smoothing method (see `tobitkf methods`).",
)
@click.option(
    "-f",
    "--format",
    "output_format",
    default="auto",
    show_default=True,
    type=click.Choice(["auto", "csv", "npz", "ntu"]),
    help="Output format; auto keeps NTU as NTU and writes CSV otherwise.",
)
@click.option(
    "-p",
    "--param",
    "params",
    multiple=True,
    metavar="KEY=VALUE",
    help="Method parameter, e.g. -p q=0.001 -p c=0.3,0.2,0.3 (repeatable).",
)
@click.option(
    "--offline",
    is_flag=True,
    help="Run the RTS smoother after Kalman-type methods (uses future frames).",
)
@click.option(
    "--glob",
    "pattern",
    default="*",
    show_default=True,
    help="File-name pattern for files found in input folders.",
)
@click.option(
    "-j",
    "--jobs",
    default=1,
    show_default=True,
    type=click.IntRange(1, 64),
    help="Files processed in parallel.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def smooth(inputs, outdir, method, output_format, params, offline, pattern, jobs, as_json):
    """Smooth skeleton recordings (files or folders, searched recursively)."""
    from tobitkf.batch import discover_inputs, plan_jobs, run_jobs
    from tobitkf.io import detect_format
    from tobitkf.skeleton.smooth import METHODS, check_params

    if method not in METHODS:
        _fail(f"unknown method {method!r}; choose from: {', '.join(sorted(METHODS))}")
    kwargs = _parse_params(params)
    try:
        check_params(method, kwargs)
    except (ValueError, TypeError) as exc:
        raise click.BadParameter(str(exc), param_hint="--param") from exc
    try:
        pairs = discover_inputs(inputs, pattern)
    except FileNotFoundError as exc:
        _fail(str(exc))
    if not pairs:
        _fail("no input files found")
    job_list, refused = plan_jobs(
        pairs, outdir, method=method, output_format=output_format, detect=detect_format
    )
    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[frames]} frames"),
        TimeElapsedColumn(),
        console=err_console,
        transient=False,
        disable=as_json or not err_console.is_terminal,
    ) as progress:
        task = progress.add_task(f"smoothing ({method})", total=len(job_list), frames=0)
        frames = [0]

        def done(summary):
            frames[0] += summary.frames
            progress.update(task, advance=1, frames=frames[0])

        results = run_jobs(job_list, method, kwargs, offline=offline, n_jobs=jobs, on_done=done)
    results = list(results) + refused
    failed = [r for r in results if not r.ok]
    if as_json:
        click.echo(dumps([r.__dict__ for r in results]))
    else:
        rows = [
            [
                Path(r.source).name,
                r.bodies,
                r.frames,
                r.joints,
                r.clipped_percent,
                r.missing_percent,
                r.seconds,
            ]
            for r in results
            if r.ok
        ]
        _print_table(
            f"tobitkf smooth --method {method}" + (" --offline" if offline else ""),
            ["file", "bodies", "frames", "joints", "% clipped", "% missing", "seconds"],
            rows,
        )
        if rows:
            console.print(f"outputs in {Path(outdir).resolve()}")
        for r in failed:
            err_console.print(f"[red]FAILED[/red] {r.source}: {r.error}")
    if failed:
        sys.exit(1)


# --------------------------------------------------------------------------- info
@app.command()
@click.argument("path", type=click.Path(exists=True, dir_okay=False))
@click.option(
    "--format",
    "input_format",
    default="auto",
    show_default=True,
    help="Input format (auto-detected by default).",
)
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
def info(path, input_format, as_json):
    """Describe what the reader finds in a recording."""
    from tobitkf.skeleton.inspect import describe

    try:
        report = describe(path, format=input_format)
    except (ValueError, OSError, ImportError) as exc:
        _fail(str(exc))
    if as_json:
        click.echo(dumps(report))
        return
    console.print(f"[bold]{path}[/bold]  format: {report['format']}  bodies: {report['bodies']}")
    for body in report["sequences"]:
        console.print(
            f"body {body['body_id']}: {body['frames']} frames, {body['joints']} joints "
            f"({body['topology']}), rate {_fmt(body['fps'])} Hz, duration "
            f"{_fmt(body['duration_s'])} s, missing {_fmt(body['missing_percent'])} %"
        )
        if body.get("dt_range"):
            lo, med, hi = body["dt_range"]
            console.print(f"  time steps: min {lo:.4f} s, median {med:.4f} s, max {hi:.4f} s")
        if body.get("tracking_states"):
            states = ", ".join(f"{k}: {v}" for k, v in body["tracking_states"].items())
            console.print(f"  tracking states: {states}")
        rows = [[j["joint"], j["largest_jump_m"], j["frame"], j["missing"]] for j in body["jumps"]]
        _print_table(
            "largest frame-to-frame jump per joint",
            ["joint", "jump [m]", "at frame", "missing"],
            rows,
            digits=3,
        )


# --------------------------------------------------------------------------- methods
@app.command()
def methods():
    """List the smoothing methods and their default parameters."""
    from tobitkf.skeleton.smooth import METHODS, method_defaults

    rows = []
    for name in sorted(METHODS):
        defaults = method_defaults(name)
        rows.append([name, ", ".join(f"{k}={v}" for k, v in defaults.items())])
    _print_table("smoothing methods", ["method", "defaults"], rows)
