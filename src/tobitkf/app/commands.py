"""The click application behind ``tobitkf`` (imported only when click is installed)."""

from __future__ import annotations

import os
import signal
import sys
import tempfile
from contextlib import ExitStack, contextmanager, nullcontext
from pathlib import Path
from typing import Any

import click
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from tobitkf.core.jsonable import dumps

console = Console()
if not console.is_terminal:  # files and pipes get whole tables, not 80-column cuts
    console = Console(width=160)
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
        # long file names fold onto a second line instead of being cut to "JointPositi…"
        table.add_column(col, justify="left" if i == 0 else "right", overflow="fold")
    for row in rows:
        table.add_row(*[_fmt(v, digits) for v in row])
    console.print(table)


class _RegistryChoice(click.Choice):
    """A ``click.Choice`` whose values are read from a registry when first needed, so
    that a method or format registered by a plugin is a valid choice and ``--help`` of
    the other commands does not pay for loading the registry."""

    def __init__(self, load: Any, extra: tuple[str, ...] = ()) -> None:
        self._load, self._extra = load, extra
        self.case_sensitive = True

    @property
    def choices(self) -> tuple[str, ...]:  # type: ignore[override]
        return (*self._extra, *self._load())


def _method_names() -> list[str]:
    from tobitkf.smoothing.api import method_names

    return method_names()


def _writable_formats() -> list[str]:
    from tobitkf.io import writable_formats

    return writable_formats()


def _readable_formats() -> list[str]:
    from tobitkf.io import formats

    return sorted(n for n, spec in formats().items() if spec.reader is not None)


def _input_format_option(
    *names: str, dest: str = "input_format", help: str = "Input format of every TRACK/PATH."
) -> Any:
    return click.option(
        *names,
        dest,
        default="auto",
        show_default=True,
        type=_RegistryChoice(_readable_formats, extra=("auto",)),
        help=help + " Auto-detected by default.",
    )


def _os_reason(exc: OSError) -> str:
    if isinstance(exc, PermissionError):
        return "permission denied"
    if isinstance(exc, FileExistsError):
        return "a file of that name exists (not a folder)"
    if isinstance(exc, NotADirectoryError):
        return "part of the path is a file, not a folder"
    return exc.strerror or str(exc)


def _writable_folder(folder: str | Path, what: str) -> Path:
    """Create ``folder`` if needed and check that a file can be written in it, before any
    work is done: one clear message instead of a traceback after minutes of work."""
    path = Path(folder)
    try:
        path.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=path, prefix=".tobitkf-write-check-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        _fail(f"cannot write {what} in {path}: {_os_reason(exc)}")
    return path


def _writable_file(path: str | Path, what: str) -> Path:
    """Check that ``path`` can be written (its folder writable, no folder in the way)."""
    target = Path(path)
    if target.is_dir():
        _fail(f"cannot write {what} {target}: it is a folder")
    _writable_folder(target.parent, what)
    return target


def _need_matplotlib(what: str) -> None:
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        _fail(f"{what} needs matplotlib, which is not installed: pip install 'tobitkf[plot]'")


@contextmanager
def _progress(quiet: bool = False, field: str = "{task.fields[now]}", transient: bool = True):
    """A progress display on stderr, shown only on a terminal (pipes and logs get none)."""
    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn(field),
        TimeElapsedColumn(),
        console=err_console,
        transient=transient,
        disable=quiet or not err_console.is_terminal,
    ) as progress:
        yield progress


def _ticking(specs: list[Any], progress: Any, task: Any) -> list[Any]:
    """Method specs that advance ``task`` after each method has run (name shown)."""
    from tobitkf.evaluation.evaluate import resolve_method

    wrapped = []
    for spec in specs:
        label, fn = resolve_method(spec)

        def run(seq, _fn=fn, _label=label):
            progress.update(task, now=_label)
            out = _fn(seq)
            progress.advance(task)
            return out

        wrapped.append((label, run))
    return wrapped


@contextmanager
def _sigterm_as_interrupt():
    """SIGTERM stops a run like Ctrl-C does (workers terminated, summary printed)."""

    def handler(signum, frame):
        raise KeyboardInterrupt

    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread (e.g. a test runner's thread): leave it
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _check_cluster_options(cluster: str | None, workers: int | None, jobs: int) -> None:
    if workers is not None and cluster != "local":
        raise click.BadParameter("goes with --cluster local", param_hint="--workers")
    if cluster is not None and jobs != 1:
        raise click.BadParameter(
            "is the local process pool; with --cluster the cluster's workers run the files",
            param_hint="--jobs",
        )


@contextmanager
def _dask_client(cluster: str | None, workers: int | None):
    """A Dask client for --cluster (None without it), with a clear message when Dask is
    missing or the scheduler cannot be reached."""
    if cluster is None:
        yield None
        return
    from tobitkf.app.cluster import connect

    with ExitStack() as stack:
        try:
            client = stack.enter_context(connect(cluster, workers))
        except ImportError as exc:
            _fail(str(exc))
        except OSError as exc:  # timeouts included: no scheduler there
            _fail(f"cannot connect to the Dask scheduler at {cluster}: {exc}")
        except ValueError as exc:  # not an address
            _fail(
                f"--cluster {cluster}: {exc}; expected a scheduler address (tcp://host:8786), "
                "a scheduler file (*.json) or local"
            )
        yield client


def _parse_params(params: tuple[str, ...]) -> dict[str, Any]:
    from tobitkf.app.batch import parse_param

    out: dict[str, Any] = {}
    for text in params:
        try:
            key, value = parse_param(text)
        except ValueError as exc:
            raise click.BadParameter(str(exc), param_hint="--param") from exc
        out[key] = value
    return out


class _InputPath(click.Path):
    """A path that must exist, or an fsspec URL (``s3://...``), checked when listed."""

    def convert(self, value, param, ctx):
        if isinstance(value, str) and "://" in value:
            return value
        return super().convert(value, param, ctx)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="tobitkf")
def app() -> None:
    """Tobit Kalman filtering of censored measurements, and skeleton-track smoothing."""


# --------------------------------------------------------------------------- smooth
@app.command()
@click.argument("inputs", nargs=-1, required=True, type=_InputPath(exists=True))
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
    default="robust",
    show_default=True,
    type=_RegistryChoice(_method_names),
    metavar="NAME",
    help="Smoothing method (see `tobitkf methods`). The default, robust, rejects "
    "physically impossible samples and smooths the rest; atkf is the 2020 paper's filter, "
    "which does not beat raw Kinect against Vicon (docs/evaluation.md).",
)
@click.option(
    "-f",
    "--format",
    "output_format",
    default="auto",
    show_default=True,
    type=_RegistryChoice(_writable_formats, extra=("auto",)),
    help="Output format; auto keeps NTU as NTU and writes CSV otherwise.",
)
@_input_format_option(
    "-F", "--input-format", help="Input format of every file read (-f is the output's)."
)
@click.option(
    "--overwrite",
    is_flag=True,
    help="Replace files at the output names that are not earlier tobitkf outputs "
    "(earlier outputs are always replaced).",
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
@click.option(
    "--cluster",
    metavar="ADDRESS",
    help="Run the files as tasks on a Dask cluster: a scheduler address "
    "(tcp://host:8786), a scheduler file (*.json), or 'local' (a LocalCluster on this "
    "machine). Needs the dask extra; see docs/cluster.md.",
)
@click.option(
    "--workers",
    type=click.IntRange(1, 1024),
    help="Worker processes of --cluster local (default: one per core).",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def smooth(
    inputs,
    outdir,
    method,
    output_format,
    input_format,
    overwrite,
    params,
    offline,
    pattern,
    jobs,
    cluster,
    workers,
    as_json,
):
    """Smooth skeleton recordings (files or folders, searched recursively).

    OUTDIR gets a manifest (tobitkf-manifest.jsonl, one line per input); a re-run passes
    over inputs done before with the same method and parameters (--overwrite redoes them).
    Inputs and OUTDIR may be fsspec URLs (s3://bucket/folder; docs/cluster.md).
    """
    from tobitkf.app.manifest import ManifestBusy
    from tobitkf.app.pool import Interrupted
    from tobitkf.app.runner import plan_run, run_planned
    from tobitkf.smoothing.api import check_params, get_method

    kwargs = _parse_params(params)
    offline = bool(kwargs.pop("offline", False)) or offline  # -p offline=true == --offline
    try:
        check_params(method, kwargs)
    except (ValueError, TypeError) as exc:
        raise click.BadParameter(str(exc), param_hint="--param") from exc
    if offline and not get_method(method).offline_ok:
        _fail(f"--offline runs an RTS pass, which method {method!r} does not have")
    _check_cluster_options(cluster, workers, jobs)
    if "://" not in outdir:
        _writable_folder(outdir, "the outputs")  # once, before any file is read
    try:
        plan = plan_run(
            inputs,
            outdir,
            method,
            pattern=pattern,
            output_format=output_format,
            input_format=input_format,
            overwrite=overwrite,
        )
    except (FileNotFoundError, ImportError) as exc:
        _fail(str(exc))
    problems, ours, passed_over = plan.found.problems, plan.found.ours, plan.found.passed_over
    job_list, refused = plan.jobs, plan.refused
    if not as_json:
        for path, why in problems:
            err_console.print(f"[yellow]skipped[/yellow] {escape(str(path))}: {escape(why)}")
        if ours:
            names = ", ".join(p.name for p in ours[:3])
            more = f" and {len(ours) - 3} more" if len(ours) > 3 else ""
            err_console.print(
                f"passed over {len(ours)} file(s) that are tobitkf outputs of an earlier "
                f"run (smoothing them again would write *.{method}.{method}.*): {names}{more}"
            )
    if passed_over and not as_json:
        names = ", ".join(p.name for p in passed_over[:3])
        more = f" and {len(passed_over) - 3} more" if len(passed_over) > 3 else ""
        err_console.print(
            f"passed over {len(passed_over)} file(s) that are not recordings or are read "
            f"together with one: {names}{more}"
        )
    if not job_list and not refused:
        _fail("no input files found")
    if job_list and (cluster is None or cluster == "local"):
        _warm_kernels(method, as_json)
    with _progress(as_json, "{task.fields[frames]} frames", transient=False) as progress:
        task = progress.add_task(f"smoothing ({method})", total=len(job_list), frames=0)
        frames = [0]

        def done(summary):
            frames[0] += summary.frames
            progress.update(task, advance=1, frames=frames[0])

        interrupted = None
        with _sigterm_as_interrupt(), _dask_client(cluster, workers) as client:
            try:
                results = run_planned(
                    job_list,
                    refused,
                    outdir,
                    method,
                    kwargs,
                    offline=offline,
                    output_format=output_format,
                    input_format=input_format,
                    overwrite=overwrite,
                    n_jobs=jobs,
                    client=client,
                    on_done=done,
                )
            except ManifestBusy as exc:
                _fail(str(exc))
            except Interrupted as stop:  # Ctrl-C / SIGTERM: summarise what was done
                interrupted = stop
                results = [stop.done[i] for i in sorted(stop.done)] + refused
    skipped = [r for r in results if r.extra.get("skipped")]
    results = [r for r in results if not r.extra.get("skipped")]
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
        if rows or not skipped:
            _print_table(
                f"tobitkf smooth --method {method}" + (" --offline" if offline else ""),
                [
                    "file",
                    "bodies",
                    "frames",
                    "joints",
                    "% clipped/rejected",
                    "% missing",
                    "seconds",
                ],
                rows,
            )
        if skipped:
            err_console.print(
                f"passed over {len(skipped)} file(s) done by an earlier run with the same "
                "method and parameters (manifest in the output folder; --overwrite redoes them)"
            )
        if rows or skipped:
            console.print(f"outputs in {Path(outdir).resolve()}")
        for r in results:
            for w in r.warnings:
                err_console.print(f"[yellow]warning[/yellow] {escape(r.source)}: {escape(w)}")
        for r in failed:
            err_console.print(f"[red]FAILED[/red] {escape(r.source)}: {escape(str(r.error))}")
    if interrupted is not None:
        left = len(job_list) - len(interrupted.done)
        err_console.print(
            f"[yellow]interrupted[/yellow]: {len(interrupted.done)} of {len(job_list)} "
            f"file(s) done, {left} not started or stopped; every output written is complete"
        )
        sys.exit(130)
    if failed:
        sys.exit(1)


def _warm_kernels(method: str, quiet: bool) -> None:
    """Compile ``method``'s kernels once here, before the files (parallel workers then
    load them instead of each compiling them), and say so when it takes a while."""
    from tobitkf.smoothing.warmup import warm

    def notice():
        if not quiet:
            err_console.print(
                f"compiling the kernels of {method} for this machine (first run only: "
                "they are cached for later runs; `tobitkf warmup` does it ahead)"
            )

    warm(method, on_compile=notice)


# --------------------------------------------------------------------------- info
@app.command()
@click.argument("path", type=click.Path(exists=True))
@_input_format_option("--format", help="Input format.")
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
def info(path, input_format, as_json):
    """Describe what the reader finds in a recording."""
    from tobitkf.app.info import describe

    try:
        report = describe(path, format=input_format)
    except (ValueError, OSError, ImportError) as exc:
        _fail(str(exc))
    if as_json:
        click.echo(dumps(report))
        return
    console.print(f"[bold]{path}[/bold]  format: {report['format']}  bodies: {report['bodies']}")
    for k, body in enumerate(report["sequences"], start=1):
        label = f"body {k}" + ("" if body["body_id"] is None else f" (id {body['body_id']})")
        console.print(
            f"{escape(label)}: {body['frames']} frames, {body['joints']} joints "
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
    """List the smoothing methods, what they are and their default parameters."""
    from tobitkf.smoothing.api import methods as registered

    rows = []
    for name, spec in sorted(registered().items()):
        kind = ("causal" if spec.is_causal() else "offline") + (", +rts" if spec.offline_ok else "")
        defaults = ", ".join(
            f"{k}={v}" + (f" {_PARAM_UNITS[k]}" if k in _PARAM_UNITS and v is not None else "")
            for k, v in spec.defaults.items()
        )
        rows.append([name, kind, spec.description, defaults])
    _print_table("smoothing methods", ["method", "runs", "what it is", "defaults"], rows)
    console.print(
        "units: positions in metres; q, r are variances (m², q per 1/30 s step), c and "
        "limits in metres, speeds in m/s, times in seconds, windows in frames, cut-offs in Hz"
    )


@app.command()
@click.option(
    "-m", "--method", "names", multiple=True, type=_RegistryChoice(_method_names),
    help="Only this method (repeatable); default: every registered method.",
)  # fmt: skip
@click.option(
    "-j", "--jobs", default=2, show_default=True, type=click.IntRange(1),
    help="Methods compiled at once, each in its own process.",
)  # fmt: skip
def warmup(names, jobs):
    """Compile the methods' kernels into numba's cache, ahead of the work.

    The first run of a compiled method on a machine (or after an upgrade) compiles its
    kernels: seconds, about ten for the default method. Later processes load them from
    the cache. Run this once after installing, or on each node of a cluster whose cache
    is not shared (NUMBA_CACHE_DIR sets where the cache is).
    """
    from tobitkf.smoothing.warmup import warmup as run_warmup

    names = list(names) or None
    rows = []
    with _progress(False, "{task.fields[now]}", transient=True) as progress:
        total = len(names) if names else len(_method_names())
        task = progress.add_task("compiling", total=total, now="")

        def done(name, seconds):
            rows.append([name, seconds])
            progress.update(task, advance=1, now=name)

        run_warmup(names, jobs=jobs, on_done=done)
    rows.sort()
    _print_table("tobitkf warmup: kernels compiled and cached", ["method", "compile seconds"],
                 [[n, round(s, 1)] for n, s in rows])  # fmt: skip
    console.print("0 seconds: the method's kernels were in the cache already, or it has none")


#: units of the built-in methods' parameters, shown by `tobitkf methods`
_PARAM_UNITS = {
    "q": "m²/step",
    "r": "m²",
    "c": "m",
    "c_horizontal": "m",
    "c_vertical": "m",
    "lower": "m",
    "upper": "m",
    "v_max": "m/s",
    "speed_sd": "m/s",
    "noise_sd": "m",
    "margin": "m",
    "bone_tol_abs": "m",
    "tau": "s",
    "min_run": "s",
    "window": "frames",
    "lookback": "frames",
    "mincutoff": "Hz",
    "dcutoff": "Hz",
    "jitter_radius": "m",
    "max_deviation_radius": "m",
}


# --------------------------------------------------------------------------- evaluate
def _load_one(path: str, what: str, input_format: str = "auto"):
    from tobitkf.app.batch import readable_problem
    from tobitkf.io import load

    problem = readable_problem(path)
    if problem:
        _fail(f"{what} {path}: {problem}")
    try:
        seqs = load(path, format=input_format)
    except (ValueError, OSError, ImportError) as exc:
        _fail(f"cannot read {what} {path}: {exc}")
    if not seqs:
        _fail(f"{what} {path} holds no skeleton")
    if len(seqs) > 1:
        err_console.print(f"{path}: {len(seqs)} bodies; using the first ({seqs[0].body_id})")
    return seqs[0]


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
    help="Comma-separated methods (default: raw,kf,atkf,atkf2016,sgf,kf+rts,"
    "one_euro,kinect and our robust methods). `<name>+rts` = offline smoother.",
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
    help="Also write results.json (and per-recording tables) here.",
)
@_input_format_option("--format", help="Input format of every TRACK.")
@_input_format_option(
    "--truth-format", dest="truth_format", help="Input format of every --truth file."
)
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
):
    """Score smoothing methods on TRACK against motion capture (or without it).

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
        truths = tuple(p.replace(old, new) for p in tracks)
        missing = [
            t for t, p in zip(truths, tracks, strict=True) if t == p or not Path(t).is_file()
        ]
        if missing:
            _fail(f"--truth-replace {old!r} {new!r}: no motion-capture file {missing[0]}")
    if truths and len(truths) != len(tracks):
        _fail(f"{len(tracks)} tracks but {len(truths)} --truth files; give one per track")
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
            specs = _ticking(method_specs, progress, task)
            track = _load_one(path, "track", input_format)
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
                console.print(table.to_text(), highlight=False, soft_wrap=True)
    pooled = pool_scores(tables) if len(tables) > 1 else None
    if pooled is not None:
        results["pooled"] = pooled
        if not quiet:
            cols = [c for c in pooled[0] if c != "method"]
            scale = {"M": 1e3}  # M is in m²; shown in 1e-3 m²
            names = {"M": "M e-3"}
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
    type=click.Path(dir_okay=False),
    help="HTML file to write.",
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
def report(track, truth, output, methods, pairs, no_gif, input_format, truth_format):
    """Write a self-contained HTML report: metrics, traces, skeletons, animation."""
    from tobitkf.app.report import track_report
    from tobitkf.evaluation.evaluate import default_methods

    specs = _method_list(methods) or default_methods()
    _need_matplotlib("the report's figures")
    _writable_file(output, "the report")  # before seconds of evaluating and drawing
    raw = _load_one(track, "track", input_format)
    mocap = _load_one(truth, "truth", truth_format) if truth else None
    with console.status("evaluating and drawing..."):
        try:
            path, table = track_report(
                raw, output, mocap=mocap, methods=specs, pairs=pairs, gif=not no_gif
            )
        except ImportError as exc:
            _fail(str(exc))
        except (ValueError, KeyError) as exc:
            _fail(f"{track}: {exc}")
    for warning in (getattr(table, "truth", None) or {}).get("notes", {}).get("warnings", []):
        err_console.print(f"[yellow]warning[/yellow] {track}: {warning}")
    console.print(table.to_text(), highlight=False, soft_wrap=True)
    console.print(f"report written to {Path(path).resolve()}")


# --------------------------------------------------------------------------- benchmark
@app.command()
@click.option("--seed", default=0, show_default=True, help="Seed of motion and corruption.")
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
@click.option("--duration", default=10.0, show_default=True, help="Seconds of motion.")
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
def benchmark(seed, seeds, motion, source, duration, methods, as_json, as_markdown, kind):
    """Every method on a corrupted synthetic recording with known truth (RMSE by glitch)."""
    if kind == "pose2d":
        _benchmark_pose2d(seed, seeds, motion, source, duration, methods, as_json, as_markdown)
        return
    from tobitkf.evaluation.benchmark import run_benchmark, seed_spread
    from tobitkf.evaluation.evaluate import default_methods

    specs = _method_list(methods) or default_methods()
    tables = _over_seeds(
        "benchmark",
        seed,
        seeds,
        lambda s: run_benchmark(
            seed=s, methods=specs, motion=motion, source=source, duration=duration
        ),
    )
    if as_json:
        click.echo(dumps([t.to_dict() for t in tables]))
        return
    spread = seed_spread(tables)
    if as_markdown:
        from tobitkf.evaluation.markdown import benchmark_markdown

        click.echo(benchmark_markdown(spread, list(range(seed, seed + seeds))), nl=False)
        return
    if seeds == 1:
        console.print(tables[0].to_text(), highlight=False, soft_wrap=True)
        return
    keys = [k for k in spread[0] if k != "method"]
    rows = [
        [r["method"], *[f"{100 * r[k][0]:.2f} ± {100 * r[k][1]:.2f}" for k in keys]] for r in spread
    ]
    _print_table(
        f"RMSE (cm), mean ± sd over seeds {seed}..{seed + seeds - 1}", ["method", *keys], rows
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


def _benchmark_pose2d(seed, seeds, motion, source, duration, methods, as_json, as_markdown):
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
        lambda s: run_pose2d_benchmark(seed=s, methods=specs, motion=motion, duration=duration),
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
    rows = [[r["method"], *[f"{r[k][0]:.2f} ± {r[k][1]:.2f}" for k in keys]] for r in spread]
    _print_table(
        f"RMSE (px), mean ± sd over seeds {seed}..{seed + seeds - 1}",
        ["method", *(k.removesuffix("_px") for k in keys)],
        rows,
    )


# --------------------------------------------------------------------------- reproduce
@app.group()
def reproduce():
    """Regenerate the 2020 paper's synthetic results, next to what the paper printed."""


def _show_paper_result(
    result: Any, as_json: bool, outdir: Any, figures: str | None, markdown: str | None = None
) -> None:
    """Print a reproduction result (text, JSON, or Markdown with the name of its function in
    :mod:`tobitkf.paper.markdown`) and write its figures when asked."""
    if as_json:
        click.echo(dumps(result.to_dict()))
    elif markdown:
        from tobitkf.paper import markdown as paper_markdown

        click.echo(getattr(paper_markdown, markdown)(result), nl=False)
    else:  # markup=False: "[min, max]" is text, not a rich style
        console.print(result.format_text(), highlight=False, soft_wrap=True, markup=False)
    if outdir:
        from tobitkf.paper import figures as paper_figures

        for p in getattr(paper_figures, figures)(result, outdir):
            err_console.print(f"wrote {p}")


@reproduce.command("covariance-example")
@click.option(
    "--samples",
    default=1_000_000,
    show_default=True,
    type=click.IntRange(1),
    help="Monte Carlo samples for eq. 23.",
)
@click.option("--seed", default=0, show_default=True)
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@click.option(
    "--markdown", "as_markdown", is_flag=True, help="Print Markdown, next to the paper's."
)
@click.option(
    "--out",
    "outdir",
    type=click.Path(file_okay=False),
    default=None,
    help="Write figures (PNG) here.",
)
def covariance_example_cmd(samples, seed, as_json, as_markdown, outdir):
    """Section 3.4: exact censored covariance vs the standard TKF's vs Monte Carlo."""
    from tobitkf.paper.covariance import covariance_example

    if outdir:
        _need_matplotlib("--out (the figures)")
        _writable_folder(outdir, "the figures")
    result = covariance_example(samples=samples, seed=seed)
    markdown = "covariance_markdown" if as_markdown else None
    _show_paper_result(result, as_json, outdir, "covariance_example_figure", markdown)


@reproduce.command("oscillator")
@click.option(
    "--runs", default=100, show_default=True, type=click.IntRange(1), help="Monte Carlo runs."
)
@click.option(
    "--steps", default=1000, show_default=True, type=click.IntRange(2), help="Time steps per run."
)
@click.option("--seed", default=0, show_default=True, help="First seed.")
@click.option(
    "--seeds",
    default=1,
    show_default=True,
    type=click.IntRange(1, 1000),
    help="Repeat with this many seeds and report the spread.",
)
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@click.option(
    "--markdown", "as_markdown", is_flag=True, help="Print Markdown, next to the paper's."
)
@click.option(
    "--out",
    "outdir",
    type=click.Path(file_okay=False),
    default=None,
    help="Write Fig. 2 and Fig. 3 (PNG) here.",
)
@click.option(
    "--random-x0",
    is_flag=True,
    help="Draw each run's true start from N(x0, P0) instead of x0 (the paper is ambiguous).",
)
@click.option(
    "--measurement-variance",
    "r",
    default=0.5,
    show_default=True,
    type=click.FloatRange(min=0, min_open=True),
    help="Variance of the measurement noise (the paper's '0.5'; 0.25 reads it as an sd).",
)
def oscillator_cmd(runs, steps, seed, seeds, as_json, as_markdown, outdir, random_x0, r):
    """Section 4.1: Tables 1 and 2 (RMSE and NCI) for TKF, TKF^c and the KF."""
    from tobitkf.paper.oscillator import OscillatorConfig, oscillator_experiment

    if outdir:
        _need_matplotlib("--out (the figures)")
        _writable_folder(outdir, "the figures")
    try:
        config = OscillatorConfig(runs=runs, steps=steps, random_x0=random_x0, r=r)
    except ValueError as exc:
        _fail(str(exc))
    with (
        err_console.status(f"{runs} runs x {steps} steps x {seeds} seed(s)...")
        if err_console.is_terminal
        else nullcontext()
    ):
        result = oscillator_experiment(seed=seed, seeds=seeds, config=config)
    markdown = "oscillator_markdown" if as_markdown else None
    _show_paper_result(result, as_json, outdir, "oscillator_figures", markdown)


@reproduce.command("likelihood")
@click.option(
    "--datasets",
    default=20,
    show_default=True,
    type=click.IntRange(1, 10_000),
    help="Simulated data sets (about 6 s each).",
)
@click.option("--seed", default=100, show_default=True, help="Seed of the first data set.")
@click.option(
    "--limits",
    nargs=2,
    type=float,
    default=(-1.2, 0.7),
    show_default=True,
    help="Clipping limits of the simulated sensor (narrower: more censoring).",
)
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@click.option("--markdown", "as_markdown", is_flag=True, help="Print a Markdown table.")
def likelihood_cmd(datasets, seed, limits, as_json, as_markdown):
    """Eq. 26-29: does maximum likelihood recover q and r of a censored AR(1)?"""
    from tobitkf.paper.likelihood import RecoveryConfig, likelihood_recovery

    try:
        config = RecoveryConfig(lower=limits[0], upper=limits[1])
    except ValueError as exc:
        _fail(str(exc))
    with _progress() as progress:
        task = progress.add_task("fitting", total=datasets, now="")
        result = likelihood_recovery(
            datasets=datasets,
            seed=seed,
            config=config,
            progress=lambda i: progress.update(task, completed=i + 1, now=f"seed {seed + i}"),
        )
    markdown = "recovery_markdown" if as_markdown else None
    _show_paper_result(result, as_json, None, None, markdown)


# --------------------------------------------------------------------------- fit
@app.command()
@click.argument("paths", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False))
@click.option("--per-joint", is_flag=True, help="One Q per joint instead of one shared Q.")
@click.option(
    "--structure",
    "q_structure",
    default="scalar",
    show_default=True,
    type=click.Choice(["scalar", "diagonal", "full"]),
    help="Structure of Q.",
)
@click.option("--fit-r", is_flag=True, help="Also estimate R (R = r I).")
@click.option(
    "--form",
    default="corrected",
    show_default=True,
    type=click.Choice(["corrected", "standard", "gaussian"]),
    help="Likelihood: censored with S (corrected), with R (standard), or plain KF.",
)
@click.option("--json", "as_json", is_flag=True, help="Print as JSON.")
@click.option("--markdown", "as_markdown", is_flag=True, help="Print one Markdown row per fit.")
@_input_format_option("--format", help="Input format of every PATH.")
def fit(paths, per_joint, q_structure, fit_r, form, as_json, as_markdown, input_format):
    """Maximum-likelihood estimate of the process noise Q of skeleton recordings.

    Q and R are variances of positions in m² (Q per frame step of the recording)."""
    from tobitkf.smoothing.fit import fit_skeleton_noise

    results: dict[str, Any] = {}
    rows: list[tuple[str, Any]] = []  # (label, fit) for --markdown
    quiet = as_json or as_markdown
    for path in paths:
        seq = _load_one(path, "recording", input_format)
        kwargs: dict[str, Any] = {
            "per_joint": per_joint,
            "q_structure": q_structure,
            "fit_r": fit_r,
            "form": form,
        }
        if form == "gaussian":
            kwargs["c"] = None
        try:
            if per_joint:  # one fit per joint, with a progress display on a terminal
                res = {}
                with _progress(quiet=quiet) as progress:
                    task = progress.add_task(f"fitting {path}", total=seq.n_joints, now="")
                    for j, joint in enumerate(seq.joint_names):
                        progress.update(task, now=joint)
                        try:
                            res.update(fit_skeleton_noise(seq, joints=[j], **kwargs))
                        except ValueError as exc:  # fewer than two observed frames
                            if "at least two observed" not in str(exc):
                                raise
                        progress.advance(task)
                if not res:
                    raise ValueError("no joint has at least two observed frames")
            else:
                with console.status(f"fitting {path}...") if not quiet else nullcontext():
                    res = fit_skeleton_noise(seq, **kwargs)
        except ValueError as exc:
            _fail(f"{path}: {exc}")
        results[path] = (
            {k: v.to_dict() for k, v in res.items()} if isinstance(res, dict) else res.to_dict()
        )
        name = Path(path).name
        rows += (
            [(f"{name}: {joint}", r) for joint, r in res.items()]
            if isinstance(res, dict)
            else [(name, res)]
        )
        if not quiet:
            console.rule(f"[bold]{path}")
            console.print("Q and R: position variances in m² (Q per frame step)")
            if isinstance(res, dict):
                for joint, r in res.items():
                    console.print(f"[bold]{joint}[/bold]")
                    console.print(r.format_text(), highlight=False)
            else:
                console.print(res.format_text(), highlight=False)
    if as_json:
        click.echo(dumps(results))
    elif as_markdown:
        from tobitkf.paper.markdown import noise_fit_markdown

        click.echo(noise_fit_markdown(rows), nl=False)


# --------------------------------------------------------------------------- demo
@app.command()
@click.option(
    "-o",
    "--out",
    "outdir",
    default="demo-output",
    show_default=True,
    type=click.Path(file_okay=False),
    help="Folder for the recordings and report.",
)
@click.option("--seed", default=0, show_default=True)
@click.option("--no-gif", is_flag=True, help="Leave out the skeleton animation.")
def demo(outdir, seed, no_gif):
    """The main job end to end on the built-in synthetic recording (no files needed)."""
    from tobitkf.app.demo import run_demo

    _need_matplotlib("the demo's report")
    _writable_folder(outdir, "the demo's files")  # before generating and smoothing
    with console.status("generating, smoothing, scoring, drawing..."):
        result = run_demo(outdir, seed=seed, gif=not no_gif)
    console.print("[bold]RMSE against the known truth, by glitch type (cm)[/bold]")
    console.print(result.table.to_text(), highlight=False, soft_wrap=True)
    for f in result.files:
        console.print(f"wrote {f}")
    console.print(f"report: {result.report.resolve()}")
