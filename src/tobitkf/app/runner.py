"""Smoothing whole folders, locally or on a Dask cluster, with a manifest and resume.

:func:`smooth_files` is the Python face of ``tobitkf smooth``; :func:`run_planned` is
the part both share: the manifest opened in the output folder, finished inputs passed
over, the files run in the local process pool (:func:`~tobitkf.app.batch.run_jobs`) or
on a Dask cluster (:func:`~tobitkf.app.cluster.run_on_cluster`), and each file recorded
as it finishes.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tobitkf.app import batch
from tobitkf.app.batch import (
    FileSummary,
    Job,
    discover_inputs,
    not_a_recording,
    plan_jobs,
    remove_partial_outputs,
    smoothing_output_method,
)
from tobitkf.app.manifest import MANIFEST_NAME, Manifest, make_entry, run_settings

__all__ = ["Discovered", "Plan", "discover_recordings", "plan_run", "run_planned", "smooth_files"]


@dataclass
class Discovered:
    """The inputs found, and what was passed over and why."""

    pairs: list[tuple[Path, Path]]
    #: earlier tobitkf outputs found in the input folders (not smoothed again)
    ours: list[Path] = field(default_factory=list)
    #: files that are not recordings (companion files left out)
    passed_over: list[Path] = field(default_factory=list)
    #: folders and links that could not be read or followed, with the reason
    problems: list[tuple[Path, str]] = field(default_factory=list)


def discover_recordings(inputs: Sequence[str | os.PathLike[str]], pattern: str = "*") -> Discovered:
    """The recordings among files and folders (folders searched recursively), passing
    over earlier tobitkf outputs, manifests and files that are not recordings.

    Raises FileNotFoundError when an input does not exist.
    """
    from tobitkf.io import is_companion_file

    found = Discovered([])
    skipped: list[Path] = []

    def skip(path: Path) -> bool:
        if path.name == MANIFEST_NAME:
            return True
        if not_a_recording(path):
            return True
        if smoothing_output_method(path):  # an earlier run's output, e.g. smoothing in place
            found.ours.append(path)
            return True
        return False

    found.pairs = discover_inputs(
        [Path(p) for p in inputs], pattern, skip=skip, skipped=skipped, problems=found.problems
    )
    # files read with a recording (a CSV's sidecar, UI-PRMD angles) need no mention
    found.passed_over = [
        p
        for p in skipped
        if not is_companion_file(p) and p not in found.ours and p.name != MANIFEST_NAME
    ]
    return found


@dataclass
class Plan:
    """The jobs of a run, the inputs refused, and what discovery passed over."""

    jobs: list[Any]
    refused: list[FileSummary]
    found: Discovered


def is_remote(inputs: Sequence[Any], outdir: Any) -> bool:
    """True when an input or the output folder is named by a URL (``s3://...``)."""
    return any(isinstance(p, str) and "://" in p for p in (*inputs, outdir))


def plan_run(
    inputs: Sequence[str | os.PathLike[str]],
    outdir: str | os.PathLike[str],
    method: str,
    *,
    pattern: str = "*",
    output_format: str = "auto",
    input_format: str = "auto",
    overwrite: bool = False,
    fps: float | None = None,
    topology: str | None = None,
    units: str | None = None,
    implausible: str = "error",
) -> Plan:
    """Find the inputs and plan their outputs (:func:`~tobitkf.app.batch.plan_jobs`, or
    :func:`~tobitkf.app.remote.plan_remote` when a URL is involved).

    Raises FileNotFoundError when an input does not exist.
    """
    if is_remote(inputs, outdir):
        from tobitkf.app.remote import plan_remote

        jobs, refused = plan_remote(
            [os.fspath(p) for p in inputs],
            os.fspath(outdir),
            method=method,
            pattern=pattern,
            output_format=output_format,
            input_format=input_format,
            input_fps=fps,
            input_topology=topology,
            input_units=units,
            input_implausible=implausible,
        )
        return Plan(list(jobs), refused, Discovered([]))
    from tobitkf.io import detect_format

    found = discover_recordings(inputs, pattern)
    earlier = Manifest(outdir)  # read only: which outputs earlier runs wrote
    jobs, refused = plan_jobs(
        found.pairs,
        outdir,
        method=method,
        output_format=output_format,
        detect=detect_format,
        input_format=input_format,
        overwrite=overwrite,
        input_fps=fps,
        input_topology=topology,
        input_units=units,
        input_implausible=implausible,
        recorded=lambda path: earlier.owner(path) is not None,
    )
    return Plan(list(jobs), refused, found)


def _expected(manifest: Manifest, jobs: Sequence[Any], outdir: Any, settings: dict) -> list:
    """The recorded sha256 of each job done before (None: to be done)."""
    from tobitkf.io import output_files

    if any(not isinstance(j, Job) for j in jobs):
        from tobitkf.app.remote import remote_outputs

        there = remote_outputs(os.fspath(outdir))
        return [
            manifest.done_digest(
                j.source,
                j.output,
                j.side_outputs(),
                settings,
                size=j.size,
                exists=there.__contains__,
                output_format=j.output_format,
            )
            for j in jobs
        ]
    return [
        manifest.done_digest(
            j.source,
            j.output,
            output_files(j.output, j.output_format)[1:],
            settings,
            output_format=j.output_format,
        )
        for j in jobs
    ]


def _not_anothers(manifest: Manifest, jobs: Sequence[Any]) -> tuple[list[Any], list[FileSummary]]:
    """The jobs whose output is not another input's result (by the manifest), and a
    refusal for each of the others: smoothing it would replace that result (one folder
    per subject into one output folder, each subject's files named alike)."""
    from tobitkf.app.manifest import input_key

    keep, refused = [], []
    for j in jobs:
        owner = manifest.owner(j.output)
        if owner is None or owner == input_key(j.source):
            keep.append(j)
            continue
        refused.append(
            FileSummary(
                str(j.source),
                None,
                False,
                f"output {j.output} holds the result of {owner} (the output folder's "
                "manifest); it is left alone: smooth this file into another output folder, "
                "or give the folder both inputs share, whose layout the outputs keep "
                "(--overwrite replaces it)",
            )
        )
    return keep, refused


def _skipped(summary: FileSummary, entry: dict[str, Any] | None) -> FileSummary:
    """A passed-over file's summary with the frames and bodies its manifest entry has."""
    entry = entry or {}
    return dataclasses.replace(
        summary, frames=int(entry.get("frames") or 0), bodies=int(entry.get("bodies") or 0)
    )


def run_planned(
    jobs: Sequence[Job],
    refused: Sequence[FileSummary],
    outdir: str | os.PathLike[str],
    method: str,
    params: dict[str, Any],
    *,
    offline: bool = False,
    output_format: str = "auto",
    input_format: str = "auto",
    overwrite: bool = False,
    n_jobs: int = 1,
    client: Any = None,
    on_done: Callable[[FileSummary], None] | None = None,
    warm_first: bool | None = None,
    on_compile: Callable[[], Any] | None = None,
    fps: float | None = None,
    topology: str | None = None,
    units: str | None = None,
    implausible: str = "error",
) -> list[FileSummary]:
    """Run planned jobs with the output folder's manifest; summaries in job order, then
    the refused inputs. A file passed over (done before, :mod:`tobitkf.app.manifest`)
    has ``extra["skipped"]`` true. ``client``: a :class:`distributed.Client` (the files
    run on its cluster) or None (the local pool of ``n_jobs`` processes).

    ``warm_first`` (default: when the files run here, ``client`` None): compile the
    method's kernels into numba's cache in this process before the files, so that
    workers load them instead of each compiling them (:mod:`tobitkf.smoothing.warmup`);
    ``on_compile`` is called if that compiles anything (e.g. to say why it waits).
    ``fps``: the frame rate the jobs give inputs that state none (recorded in the
    manifest's settings, so that another rate redoes them; a file with its own rate
    or timestamps is not redone for it). ``topology``: the skeleton (a topology name) the
    jobs give inputs that name none, recorded alike; ``units``: the length unit given to
    inputs that state none, alike; ``implausible``: what the readers do with a position
    beyond the plausibility bound (:func:`tobitkf.io.load`), recorded alike.

    Raises :class:`~tobitkf.app.pool.Interrupted` on Ctrl-C (the manifest keeps every
    file finished) and :class:`~tobitkf.app.manifest.ManifestBusy` when another run
    writes to ``outdir``.
    """
    settings = run_settings(
        method,
        params,
        offline=offline,
        output_format=output_format,
        input_format=input_format,
        input_fps=fps,
        input_topology=topology,
        input_units=units,
        input_implausible=implausible,
    )
    with Manifest(outdir) as manifest:
        if not overwrite:
            jobs, others = _not_anothers(manifest, jobs)
            refused = [*others, *refused]
        expect = [None] * len(jobs) if overwrite else _expected(manifest, jobs, outdir, settings)
        for r in refused:
            manifest.record(make_entry(r, settings))
        if (client is None if warm_first is None else warm_first) and None in expect:
            from tobitkf.smoothing.warmup import warm

            warm(method, on_compile=on_compile)

        def done(summary: FileSummary) -> FileSummary:
            if summary.extra.get("skipped"):
                summary = _skipped(summary, manifest.entry(summary.source, summary.output))
            else:
                manifest.record(make_entry(summary, settings))
            if on_done is not None:
                on_done(summary)
            return summary

        if client is None:
            results = batch.run_jobs(  # looked up at call time (tests patch it)
                jobs, method, params, offline=offline, n_jobs=n_jobs, on_done=done, expect=expect
            )
            results = [
                _skipped(r, manifest.entry(r.source, r.output)) if r.extra.get("skipped") else r
                for r in results
            ]
        else:
            from tobitkf.app.cluster import run_on_cluster

            found: dict[int, FileSummary] = {}
            try:
                run_on_cluster(
                    client,
                    jobs,
                    method,
                    params,
                    offline=offline,
                    expect=expect,
                    on_result=lambda i, s: found.__setitem__(i, done(s)),
                )
            finally:  # a worker killed mid-write leaves its temporary file
                remove_partial_outputs(jobs)
            results = [found[i] for i in range(len(jobs))]
    return [*results, *refused]


def smooth_files(
    inputs: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
    out_dir: str | os.PathLike[str],
    method: str | None = None,
    *,
    params: dict[str, Any] | None = None,
    client: Any = None,
    jobs: int = 1,
    offline: bool = False,
    output_format: str = "auto",
    input_format: str = "auto",
    pattern: str = "*",
    overwrite: bool = False,
    on_done: Callable[[FileSummary], None] | None = None,
    fps: float | None = None,
    topology: str | None = None,
    units: str | None = None,
    implausible: str = "error",
) -> list[FileSummary]:
    """Smooth every recording in ``inputs`` (files or folders, searched recursively) into
    ``out_dir``, as ``tobitkf smooth`` does, and return one summary per input.

    Parameters
    ----------
    inputs : path or list of paths; fsspec URLs (``s3://bucket/ntu/``) work too.
    out_dir : folder for the outputs (created), a path or an fsspec URL; it also gets the
        run's manifest, ``tobitkf-manifest.jsonl`` (:mod:`tobitkf.app.manifest`).
    method : registered smoothing method (default :data:`tobitkf.DEFAULT_METHOD`).
    params : method parameters (``tobitkf methods`` lists them).
    client : an existing :class:`distributed.Client`: the files run as tasks on its
        cluster, whose workers read and write the files themselves (they must see the
        same paths). None: the local pool of ``jobs`` processes.
    overwrite : redo inputs the manifest says are done, and replace files at the output
        names that are not tobitkf outputs.
    on_done : called with each file's summary as it finishes (e.g. a progress bar).
    fps : frame rate (Hz) of inputs that state none (no rate, no timestamps); without it
        they are smoothed as 30 fps, and their summaries say so.
    topology : skeleton (a name of :func:`tobitkf.available_topologies`) of inputs that
        name none (an array's joints ``0``, ``1``, ...); files naming their own keep it.
    units : length unit (``"mm"``, ``"cm"``, ``"m"``, ``"px"``) of inputs that state none
        (a CSV without its sidecar, read as metres in 3-D; a ``.npy`` array, unknown);
        files stating their own keep it.
    implausible : ``"error"`` (default: a file with a position beyond the plausibility
        bound fails) or ``"missing"`` (such positions are read as missing and smoothed
        over, :func:`tobitkf.io.load`).

    Returns
    -------
    list of :class:`~tobitkf.app.batch.FileSummary`
        ``ok``, ``error``, ``output``, ``frames``, ``bodies``, ``seconds``; ``extra``
        holds the input's ``size`` and ``sha256`` and ``skipped`` (done by an earlier
        run, passed over).
    """
    from tobitkf.smoothing.api import DEFAULT_METHOD

    method = method or DEFAULT_METHOD
    if topology is not None:
        from tobitkf.skeleton.topology import get_topology

        topology = get_topology(topology).name  # KeyError naming the known ones
    from tobitkf.skeleton.sequence import KNOWN_UNITS

    if units is not None and units not in KNOWN_UNITS:
        raise ValueError(f"units must be one of {sorted(KNOWN_UNITS)}, got {units!r}")
    from tobitkf.io._text import check_implausible_option

    check_implausible_option(implausible)  # before any file is read
    params = dict(params or {})
    offline = bool(params.pop("offline", False)) or offline
    if isinstance(inputs, (str, os.PathLike)):
        inputs = [inputs]
    plan = plan_run(
        list(inputs),
        out_dir,
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
    refused = [
        *plan.refused,
        *(FileSummary(str(p), None, False, why) for p, why in plan.found.problems),
    ]
    return run_planned(
        plan.jobs,
        refused,
        out_dir,
        method,
        params,
        offline=offline,
        output_format=output_format,
        input_format=input_format,
        overwrite=overwrite,
        n_jobs=jobs,
        client=client,
        on_done=on_done,
        fps=fps,
        topology=topology,
        units=units,
        implausible=implausible,
    )
