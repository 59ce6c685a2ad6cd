"""``tobitkf smooth`` (files and folders, locally or on a Dask cluster) and ``tobitkf warmup``."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import click
from rich.markup import escape

from tobitkf.app.commands._common import (
    _check_cluster_options,
    _dask_client,
    _fail,
    _fps_option,
    _input_format_option,
    _InputPath,
    _ListsChoices,
    _method_names,
    _parse_params,
    _print_table,
    _progress,
    _RegistryChoice,
    _sigterm_as_interrupt,
    _topology_option,
    _units_option,
    _writable_folder,
    _writable_formats,
    app,
    console,
    err_console,
)
from tobitkf.core.jsonable import dumps


def _not_a_file_name(outdir: str) -> None:
    """A usage error for ``-o out.c3d`` (a new folder named like an output file, which
    would then hold ``<input>.robust.csv``): -o is the folder, -f the format."""
    from tobitkf.io import output_extension, writable_formats

    if outdir.endswith(("/", os.sep)) or ("://" not in outdir and Path(outdir).is_dir()):
        return  # a folder, said so or existing, whatever its name
    name = outdir.rsplit("/", 1)[-1].lower()
    for fmt in writable_formats():
        ext = output_extension(fmt)
        if name.endswith(ext) and len(name) > len(ext):
            raise click.BadParameter(
                f"{outdir!r} looks like a file name, but -o is the folder the outputs go "
                f"into, each named after its input (walk.txt gives walk.<method>{ext}); "
                f"for {fmt} output give a folder and -f {fmt}",
                param_hint="-o/--outdir",
            )


def _writer_installed(output_format: str) -> None:
    """Fail once, before any file, when the output format's writer needs a package that
    is not installed (each file failed with it, after reading and smoothing): a tiny
    recording is written to a temporary folder, and only an ImportError counts."""
    if output_format == "auto":  # CSV or NTU: no optional package
        return
    import tempfile

    from tobitkf.io import output_extension, save
    from tobitkf.smoothing.warmup import tiny_recording

    with tempfile.TemporaryDirectory() as folder:
        probe = Path(folder) / f"probe{output_extension(output_format)}"
        try:
            save([tiny_recording()], probe, format=output_format)
        except ImportError as exc:
            _fail(f"-f {output_format}: {exc}")
        except Exception:  # a tiny recording this format cannot hold: no matter
            pass


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
    metavar="FORMAT",
    cls=_ListsChoices,
    help="Output format; auto keeps NTU as NTU and writes CSV otherwise.",
)
@_input_format_option(
    "-F", "--input-format", help="Input format of every file read (-f is the output's)."
)
@_fps_option(
    "Frame rate (Hz) of inputs that state none (pose-estimator tables, keypoint "
    "JSON); files with their own rate or timestamps keep it. Without it such files are "
    "smoothed as 30 fps, and the summary says so."
)
@_topology_option(
    "Skeleton of inputs that name none (a .npy array's joints 0, 1, ...; MMPose "
    "output of an unknown model), e.g. h36m17 or coco17 (an unknown name lists the "
    "others); files naming their own keep it."
)
@_units_option(
    "Length unit of inputs that state none (a CSV without its sidecar, read as metres "
    "in 3-D; a .npy array): the robust gates are physical speeds and lengths, so a "
    "track in millimetres needs --units mm. Files stating their own keep it."
)
@click.option(
    "--implausible",
    type=click.Choice(["error", "missing"]),
    default="error",
    show_default=True,
    help="A position beyond the plausibility bound (10 km, or 1e8 px in pixels or unknown "
    "units): "
    "error fails the file, naming the frame and joint; missing reads such samples as "
    "missing, and the method fills them.",
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
    help="Method parameter, e.g. -p q=0.001 -p c=0.3,0.2,0.3, per body region -p "
    "v_max=hands:6,arms:4 (the regions not named keep their defaults, or in pixels the "
    "values measured on the recording); repeatable.",
)
@click.option(
    "--noise-from",
    "noise_from",
    type=click.Path(exists=True, dir_okay=False),
    metavar="FILE",
    help="robust: the noise fit recorded in FILE (an earlier robust output, or its "
    "sidecar .json, or a JSON of the fit) instead of fitting each input's own; e.g. "
    "short clips with the noise of a long recording of the same sensor and person.",
)
@click.option(
    "--offline",
    is_flag=True,
    help="Run the RTS smoother after Kalman-type methods (uses future frames).",
)
@click.option(
    "--step-guard",
    is_flag=True,
    help="Hold every output step of a joint to the largest step its input made. The "
    "robust methods always do; the published filters (kf, atkf, tkfc, kinect, ...) may "
    "overshoot it otherwise (docs/robust.md, 'No new jumps').",
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
@click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="Print the summary as JSON: one entry per input, those done by an earlier run "
    "with extra.skipped true.",
)
def smooth(
    inputs,
    outdir,
    method,
    output_format,
    input_format,
    fps,
    topology,
    units,
    implausible,
    overwrite,
    params,
    noise_from,
    offline,
    step_guard,
    pattern,
    jobs,
    cluster,
    workers,
    as_json,
):
    """Smooth skeleton recordings (files or folders, searched recursively; hidden files
    and folders, named with a leading '.', are not searched).

    OUTDIR gets a manifest (tobitkf-manifest.jsonl, one line per input and output); a
    re-run passes over inputs done before into the same output with the same method and
    parameters (--overwrite redoes them).
    Inputs and OUTDIR may be fsspec URLs (s3://bucket/folder; docs/cluster.md).
    """
    from tobitkf.app.batch import strip_extension
    from tobitkf.app.manifest import ManifestBusy
    from tobitkf.app.pool import Interrupted
    from tobitkf.app.runner import plan_run, run_planned
    from tobitkf.smoothing.api import check_params, get_method

    kwargs = _parse_params(params)
    offline = bool(kwargs.pop("offline", False)) or offline  # -p offline=true == --offline
    step_guard = bool(kwargs.pop("step_guard", False)) or step_guard  # smooth's, not the method's
    try:
        check_params(method, kwargs)
    except (ValueError, TypeError) as exc:
        raise click.BadParameter(str(exc), param_hint="--param") from exc
    if noise_from is not None:
        kwargs = _noise_from(noise_from, method, kwargs)
        try:  # the fit's values, checked as robust checks them
            check_params(method, kwargs)
        except (ValueError, TypeError) as exc:
            raise click.BadParameter(str(exc), param_hint="--noise-from") from exc
    if offline and not get_method(method).offline_ok:
        try:  # the library's reason, naming the methods that have one
            check_params(method, {"offline": True})
        except ValueError as exc:  # a usage error (exit 2), as the other options' are
            raise click.BadParameter(str(exc), param_hint="--offline") from exc
    if step_guard:
        kwargs["step_guard"] = True  # passed to tobitkf.smooth with the method's parameters
    _check_cluster_options(cluster, workers, jobs)
    _not_a_file_name(outdir)
    _writer_installed(output_format)
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
            fps=fps,
            topology=topology,
            units=units,
            implausible=implausible,
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
            stem = strip_extension(ours[0].name)
            again = f"{stem}.{method}{ours[0].name[len(stem) :]}"
            err_console.print(
                f"passed over {len(ours)} file(s) that are tobitkf outputs of an earlier "
                f"run (smoothing them again would write {again}): {names}{more}"
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
                    # local workers share this machine's kernel cache
                    warm_first=cluster is None or cluster == "local",
                    on_compile=None if as_json else _compiling_notice(method),
                    fps=fps,
                    topology=topology,
                    units=units,
                    implausible=implausible,
                )
            except ManifestBusy as exc:
                _fail(str(exc))
            except Interrupted as stop:  # Ctrl-C / SIGTERM: summarise what was done
                interrupted = stop
                results = [stop.done[i] for i in sorted(stop.done)] + refused
    if as_json:  # every input, those done by an earlier run too (extra.skipped)
        click.echo(dumps([r.__dict__ for r in results]))
    skipped = [r for r in results if r.extra.get("skipped")]
    results = [r for r in results if not r.extra.get("skipped")]
    failed = [r for r in results if not r.ok]
    if not as_json:
        ok = [r for r in results if r.ok]
        rows = [
            [
                name,
                r.bodies,
                r.frames,
                r.joints,
                r.clipped_percent,
                r.missing_percent,
                r.seconds,
            ]
            for r, name in zip(ok, _shown_names([r.source for r in ok]), strict=True)
        ]
        # a data set: its totals, not a screen per file
        shown = [_totals(rows)] if len(rows) > MAX_TABLE_ROWS else rows
        if rows:
            _print_table(
                f"tobitkf smooth --method {method}" + (" --offline" if offline else ""),
                [
                    "file",
                    "bodies",
                    "frames",
                    "joints",
                    "% clipped/rejected",
                    "% not measured",  # missing, NOT_TRACKED or below min_confidence
                    "seconds",
                ],
                shown,
            )
        if skipped:
            err_console.print(
                f"passed over {len(skipped)} file(s) done by an earlier run with the same "
                "method and parameters (manifest in the output folder; --overwrite redoes them)"
            )
        if rows or skipped:
            where = outdir if "://" in outdir else Path(outdir).resolve()
            console.print(f"outputs in {where}")
        for r in results:
            for w in r.warnings:
                err_console.print(f"[yellow]warning[/yellow] {escape(r.source)}: {escape(w)}")
        for r in failed:
            err_console.print(f"[red]FAILED[/red] {escape(r.source)}: {escape(str(r.error))}")
        if interrupted is None:  # the tally, last, where a long run's end is read
            tally = [f"{len(rows)} smoothed"]
            tally += [f"{len(failed)} failed"] if failed else []
            tally += [f"{len(skipped)} passed over as done"] if skipped else []
            err_console.print(("[red]" if failed else "") + ", ".join(tally))
    if interrupted is not None:
        left = len(job_list) - len(interrupted.done)
        err_console.print(
            f"[yellow]interrupted[/yellow]: {len(interrupted.done)} of {len(job_list)} "
            f"file(s) done, {left} not started or stopped; every output written is complete"
        )
        sys.exit(130)
    if failed:
        sys.exit(1)


#: files of a run listed one per row in its summary; more are summed in one row (the
#: manifest and --json have every file)
MAX_TABLE_ROWS = 50


def _totals(rows: list[list]) -> list:
    """One summary row for many files: their count, bodies, frames, widest skeleton, the
    percentages weighted by frames, and the seconds summed."""
    import numpy as np

    frames = np.array([r[2] for r in rows], dtype=float)
    weight = frames if frames.sum() > 0 else None

    def mean(k: int) -> float:
        v = np.array([r[k] for r in rows], dtype=float)
        ok = np.isfinite(v)
        if not ok.any():
            return float("nan")
        return float(np.average(v[ok], weights=None if weight is None else weight[ok]))

    return [f"{len(rows)} files (every one in the manifest and --json)",
            sum(r[1] for r in rows), int(frames.sum()), max(r[3] for r in rows),
            mean(4), mean(5), sum(r[6] for r in rows)]  # fmt: skip


def _noise_from(path: str, method: str, kwargs: dict) -> dict:
    """``kwargs`` with ``noise`` the fit recorded in ``path`` (``--noise-from``)."""
    from tobitkf.io.noise_fit import read_noise_fit
    from tobitkf.smoothing.api import method_defaults

    if method_defaults(method).get("noise") != "fit":  # robust_online keeps its constants
        raise click.BadParameter(
            f"{method} takes no noise fit (robust, which fits its own, does)",
            param_hint="--noise-from",
        )
    if "noise" in kwargs:
        raise click.BadParameter(
            "give the noise once: -p noise=... or --noise-from", param_hint="--noise-from"
        )
    try:
        return {**kwargs, "noise": read_noise_fit(path)}
    except (OSError, ValueError) as exc:
        raise click.BadParameter(str(exc), param_hint="--noise-from") from exc


def _shown_names(sources: list[str]) -> list[str]:
    """The files' names, or, when two share a name, their paths below the folder they
    all sit in (a Kinect and a Vicon m01_s01_e01_positions.txt.gz)."""
    names = [Path(s).name for s in sources]
    if len(set(names)) == len(names):
        return names
    import os

    local = [s for s in sources if "://" not in s]
    if len(local) != len(sources):
        return sources
    root = os.path.commonpath([os.path.dirname(os.path.abspath(s)) for s in local])
    return [os.path.relpath(os.path.abspath(s), root) for s in local]


def _compiling_notice(method: str):
    def notice():
        err_console.print(
            f"compiling the kernels of {method} for this machine: seconds to a minute or two, "
            "first run only (they are cached for later runs; `tobitkf warmup` does it ahead)"
        )

    return notice


@app.command()
@click.option(
    "-m", "--method", "names", multiple=True, type=_RegistryChoice(_method_names),
    metavar="NAME", help="Only this method (repeatable); default: every registered method.",
)  # fmt: skip
@click.option(
    "-j", "--jobs", default=2, show_default=True, type=click.IntRange(1),
    help="Methods compiled at once, each in its own process.",
)  # fmt: skip
def warmup(names, jobs):
    """Compile the methods' kernels into numba's cache, ahead of the work.

    The first run of a compiled method on a machine (or after an upgrade) compiles its
    kernels: seconds for most methods, a minute or two for the default one on a slow
    machine. Later processes load them from the cache. Run this once after installing,
    or on each node of a cluster whose cache is not shared (NUMBA_CACHE_DIR sets where
    the cache is).
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
