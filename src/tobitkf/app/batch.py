"""Smoothing many recordings: input discovery, output naming, atomic writes, summaries.

This is the library side of ``tobitkf smooth``: it never overwrites an input, writes
each output atomically (a temporary file in the output folder, then ``os.replace``),
and reports a bad file with its reason instead of stopping the whole run. A format's
side outputs (the CSV's JSON sidecar) are part of the output: planned, checked against
the inputs and written atomically with it.
"""

from __future__ import annotations

import errno
import fnmatch
import os
import re
import tempfile
import time
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: compound extensions stripped from input names before naming outputs
_COMPOUND = (".txt.gz", ".csv.gz", ".tsv.gz")
#: endings of the outputs whose file holds the provenance (NPZ, C3D, movement's netCDF,
#: DeepLabCut's HDF5); a CSV's is in its sidecar
_KEEPS_PROVENANCE = (".npz", ".c3d", ".nc", ".h5")


@dataclass(frozen=True)
class Job:
    """One input file and where its output goes (``source_label``: what the output's
    provenance names as its source, when not ``source`` itself: a staged copy's URL)."""

    source: Path
    output: Path
    output_format: str
    input_format: str = "auto"
    source_label: str | None = None
    #: frame rate (Hz) for an input that states none (no rate, no timestamps)
    input_fps: float | None = None
    #: skeleton (topology name) for an input that names none (an array's joints 0, 1, ...)
    input_topology: str | None = None
    #: length unit for an input that states none (a CSV without sidecar, an array)
    input_units: str | None = None
    #: what the reader does with a position beyond the plausibility bound ("error" or
    #: "missing", :func:`tobitkf.io.load`)
    input_implausible: str = "error"


@dataclass(frozen=True)
class FileSummary:
    """What happened to one file (a row of the summary table)."""

    source: str
    output: str | None
    ok: bool
    error: str | None = None
    bodies: int = 0
    frames: int = 0
    joints: int = 0
    clipped_percent: float = float("nan")
    missing_percent: float = float("nan")
    seconds: float = 0.0
    input_format: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    #: warnings the method gave for this file (e.g. limits the data contradict), once each
    warnings: tuple[str, ...] = ()


def strip_extension(name: str) -> str:
    """File name without its extension (``.txt.gz`` and similar count as one)."""
    lower = name.lower()
    for ext in _COMPOUND:
        if lower.endswith(ext):
            return name[: -len(ext)]
    return Path(name).stem


def discover_inputs(
    inputs: Sequence[str | Path],
    pattern: str = "*",
    *,
    recursive: bool = True,
    skip: Callable[[Path], bool] | None = None,
    skipped: list[Path] | None = None,
    problems: list[tuple[Path, str]] | None = None,
) -> list[tuple[Path, Path]]:
    """Expand files and folders into ``(file, base)`` pairs.

    A folder that is itself a recording (:func:`is_recording_folder`) is one input, like a
    file. Another folder contributes every file below it (recursively) whose name matches
    ``pattern`` and for which ``skip`` (e.g. :func:`tobitkf.io.is_companion_file`) is not true; the
    skipped files are appended to ``skipped`` when given. ``base`` is the folder, so
    outputs can keep the relative layout. A file is taken as given (neither the pattern
    nor ``skip`` filters explicit files); its base is its own folder. What a folder walk
    cannot enter or follow (an unreadable folder, a symlink loop, a dangling link) is
    appended to ``problems`` as ``(path, reason)`` instead of vanishing silently.

    Raises
    ------
    FileNotFoundError
        If an input does not exist.
    """
    found: list[tuple[Path, Path]] = []
    seen: set[Path] = set()
    if problems is None:
        problems = []
    for item in inputs:
        path = Path(item)
        if not path.exists():
            raise FileNotFoundError(f"input not found: {path}")
        if path.is_dir() and not is_recording_folder(path):
            for f in _walk(path, recursive, problems):
                if fnmatch.fnmatch(f.name, pattern) and not f.name.startswith("."):
                    if skip is not None and skip(f):
                        if skipped is not None:
                            skipped.append(f)
                        continue
                    if f.resolve() not in seen:
                        seen.add(f.resolve())
                        found.append((f, path))
        elif path.resolve() not in seen:
            seen.add(path.resolve())
            found.append((path, path.parent))
    return found


def _walk(folder: Path, recursive: bool, problems: list[tuple[Path, str]]) -> list[Path]:
    """Regular files below ``folder`` (sorted, symlinked folders not followed); what cannot
    be read or followed is recorded in ``problems`` with its reason."""
    files: list[Path] = []
    try:
        entries = sorted(os.scandir(folder), key=lambda e: e.name)
    except OSError as exc:
        problems.append((folder, f"cannot read this folder: {_reason(exc)}"))
        return files
    for entry in entries:
        p = Path(entry.path)
        try:
            if entry.is_dir(follow_symlinks=False):
                if recursive and not entry.name.startswith("."):
                    if is_recording_folder(p):  # e.g. an OpenPose JSON output folder
                        files.append(p)
                    else:
                        files.extend(_walk(p, recursive, problems))
                continue
            if entry.is_symlink():
                os.stat(p)  # raises for a dangling link or a loop
                if p.is_dir():
                    continue  # symlinked folders are not followed (no cycles)
            if p.is_file():
                files.append(p)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                problems.append((p, "symbolic link loop"))
            elif exc.errno == errno.ENOENT:
                problems.append((p, f"dangling symbolic link (to {os.readlink(p)})"))
            else:
                problems.append((p, _reason(exc)))
    return files


def _reason(exc: OSError) -> str:
    if isinstance(exc, PermissionError):
        return "permission denied"
    return exc.strerror or str(exc)


def readable_problem(path: str | os.PathLike[str]) -> str | None:
    """Why ``path`` cannot be opened for reading (permission, ...), or None when it can."""
    try:
        if os.path.isdir(path):  # a recording folder: it must be listable
            os.listdir(path)
            return None
        with open(path, "rb"):
            pass
    except OSError as exc:
        return f"cannot read it: {_reason(exc)}"
    return None


def smoothing_output_method(path: str | os.PathLike[str]) -> str | None:
    """The method that wrote ``path``, when it is a tobitkf smoothing output; else None.

    The rule: the name is ``<name>.<method><ext>`` with a registered method, and the file's
    provenance (the CSV's sidecar; in the file of an NPZ, C3D, movement ``.nc`` or
    DeepLabCut ``.h5``) names that method: a recording ``subject01.kinect.c3d`` is an
    input. A format that keeps no provenance (NTU, TRC, LightningPose's CSV) is recognised
    by its name alone, and only when tobitkf writes files of its extension: a recording
    named ``dance.kinect.bvh`` is an input.
    """
    from tobitkf.io import output_extension, writable_formats
    from tobitkf.smoothing.api import method_names

    p = Path(path)
    stem = strip_extension(p.name)
    if "." not in stem:
        return None
    method = stem.rsplit(".", 1)[1]
    if method not in method_names():
        return None
    lower = p.name.lower()
    if lower.endswith(".csv.gz"):  # never written by tobitkf
        return None
    if lower.endswith(".csv"):
        from tobitkf.io.generic_csv import sidecar_provenance

        prov = sidecar_provenance(p)
        if prov is None:  # no sidecar: a CSV format that keeps no provenance (LightningPose)?
            return method if _provenance_free_csv(p) else None
        return method if prov.get("method") == method else None
    if lower.endswith(_KEEPS_PROVENANCE):
        from tobitkf.io import load

        try:
            prov = load(p)[0].metadata.get("provenance") or {}
        except Exception:
            return None
        return method if isinstance(prov, dict) and prov.get("method") == method else None
    if not any(lower.endswith(output_extension(f)) for f in writable_formats()):
        return None  # tobitkf writes no such file: a recording's own name
    return method  # no provenance kept in the format: the name decides


def _provenance_free_csv(p: Path) -> bool:
    """True when ``p``'s content is a format other than the generic CSV that tobitkf
    writes as ``.csv`` (no sidecar, so its name decides, as for NTU)."""
    from tobitkf.io import detect_format, output_extension, writable_formats

    try:
        fmt = detect_format(p)
    except (OSError, ValueError):
        return False
    return fmt != "csv" and fmt in writable_formats() and output_extension(fmt) == ".csv"


def is_recording_folder(path: Path) -> bool:
    """True for a folder that a registered format reads as one recording (an OpenPose
    JSON output folder): batch tools take it as one input instead of walking into it."""
    from tobitkf.io import ReadError, detect_format

    try:
        detect_format(path)
    except (ReadError, OSError):
        return False
    return True


def not_a_recording(path: Path) -> bool:
    """True for files a folder walk should pass over: companion files read with their
    recording (UI-PRMD angles) and files whose extension no registered reader claims
    (README.md, images, ...). A bad file with a known extension is not passed over: it
    is read and reported with its reason.
    """
    from tobitkf.io import formats, is_companion_file

    if path.is_dir():
        return not is_recording_folder(path)
    name = path.name.lower()
    known = {ext for spec in formats().values() for ext in spec.extensions}
    if not any(name.endswith(ext) for ext in known):
        return True
    return is_companion_file(path)


def default_output_format(input_format: str | None) -> str:
    """``ntu`` inputs stay NTU (every extra field kept); everything else becomes CSV."""
    return "ntu" if input_format == "ntu" else "csv"


def plan_jobs(
    pairs: Sequence[tuple[Path, Path]],
    outdir: str | Path,
    *,
    method: str,
    output_format: str = "auto",
    detect: Callable[[Path], str] | None = None,
    input_format: str = "auto",
    overwrite: bool = False,
    input_fps: float | None = None,
    input_topology: str | None = None,
    input_units: str | None = None,
    input_implausible: str = "error",
    recorded: Callable[[Path], bool] | None = None,
) -> tuple[list[Job], list[FileSummary]]:
    """Decide the output path of each input.

    Outputs are ``OUTDIR/<relative folder>/<name>.<method><ext>``. A planned output that
    would be an input file, or the output of an earlier input, is refused for that file.
    An existing file at an output name is replaced only when it is an earlier tobitkf
    output (:func:`smoothing_output_method`, or ``recorded(path)``: the output folder's
    manifest names it as an output, e.g. a CSV whose sidecar was deleted) or
    ``overwrite`` is true; any other file there is left alone and the input refused with
    the reason.

    Returns
    -------
    jobs : list of Job
    refused : list of FileSummary for inputs that cannot be processed
    """
    outdir = Path(outdir)
    inputs = {p.resolve() for p, _ in pairs}
    taken: dict[Path, Path] = {}
    jobs: list[Job] = []
    refused: list[FileSummary] = []
    for src, base in pairs:
        fmt = output_format
        if fmt == "auto":
            in_fmt = None if input_format == "auto" else input_format
            if in_fmt is None and detect is not None:
                try:
                    in_fmt = detect(src)
                except Exception as exc:  # what reading it would say (an empty file...)
                    # refused now: a guessed output name could collide with another
                    # input's and hide the reason
                    why = readable_problem(src) or f"{type(exc).__name__}: {exc}"
                    refused.append(FileSummary(str(src), None, False, why))
                    continue
            fmt = default_output_format(in_fmt)
        from tobitkf.io import output_extension, output_files

        ext = output_extension(fmt)  # ValueError naming the writable formats
        try:
            rel = src.parent.resolve().relative_to(base.resolve())
        except ValueError:
            rel = Path()
        out = outdir / rel / f"{strip_extension(src.name)}.{method}{ext}"
        files = output_files(out, fmt)  # the output and its side files (CSV sidecar)
        reason = None
        for f in files:
            if f.resolve() in inputs:
                reason = f"output {f} would overwrite an input"
            elif f.resolve() in taken:
                other = taken[f.resolve()]
                reason = f"output {f} is already the output of {other} " + (
                    f"(files named alike in one folder, {other.name} and {src.name}: "
                    "smooth one of them into another output folder)"
                    if other.parent.resolve() == src.parent.resolve()
                    else "(files of one name from different folders: give the folder they "
                    "share, whose layout the outputs keep)"
                )
            elif f.is_dir():
                reason = f"output {f} is a folder"
            elif (
                not overwrite
                and f.exists()
                and smoothing_output_method(out) is None
                and not (recorded is not None and recorded(out))
            ):
                reason = (
                    f"{f} exists and is not a tobitkf output; it is left alone "
                    "(--overwrite replaces it)"
                )
            if reason:
                break
        if reason:
            refused.append(FileSummary(str(src), None, False, reason))
            continue
        taken.update({f.resolve(): src for f in files})
        jobs.append(
            Job(
                src,
                out,
                fmt,
                input_format,
                input_fps=input_fps,
                input_topology=input_topology,
                input_units=input_units,
                input_implausible=input_implausible,
            )
        )
    return jobs, refused


def atomic_save(sequences: Sequence[Any], path: Path, output_format: str) -> None:
    """Write ``sequences`` to ``path`` through a temporary file and a rename.

    The format's side outputs (the CSV's sidecar) are written beside the temporary file
    and renamed first, so the output appears complete. An interrupted run leaves at most
    hidden temporary files, never a half-written output.
    """
    from tobitkf.io import output_files, save

    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(
        dir=path.parent, prefix=f".{path.name}.", suffix=f".part{path.suffix}"
    )
    os.close(fd)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; outputs get the usual mode
    temps = output_files(tmp, output_format)
    try:
        save(list(sequences), tmp, format=output_format)
        # side files first, the output last: whoever sees the output sees its sidecar
        for src, dst in reversed(list(zip(temps, output_files(path, output_format)))):
            if src.exists():
                os.replace(src, dst)
    except BaseException:
        for f in temps:
            if f.exists():
                f.unlink()
        raise


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _percent(values: Iterable[np.ndarray]) -> float:
    arrays = [np.asarray(v, dtype=float).ravel() for v in values]
    arrays = [a for a in arrays if a.size]
    if not arrays:
        return float("nan")
    return 100.0 * float(np.nanmean(np.concatenate(arrays)))


def _with_rate(sequences: list[Any], fps: float | None) -> tuple[list[Any], tuple[str, ...]]:
    """The sequences with ``fps`` where they state no rate (nor timestamps), and what was
    assumed (a warning for the summary) where none was given either."""
    from tobitkf.io.unstated import states_no_rate, with_unstated

    if not any(states_no_rate(s) for s in sequences):
        return sequences, ()
    if fps is not None:
        return with_unstated(sequences, fps=fps), ()
    return sequences, ("the file states no frame rate: smoothed as 30 fps (give --fps)",)


def _with_given(sequences: list[Any], topology: str | None, units: str | None) -> list[Any]:
    """The sequences with topology ``topology`` where the file named no skeleton and in
    ``units`` where it stated no length unit."""
    from tobitkf.io.unstated import with_unstated

    return with_unstated(sequences, topology=topology, units=units, option="--topology")


def _unused_settings(sequences: list[Any]) -> list[str]:
    """The run settings this file did not use (its own rate, skeleton, unit): a re-run
    with other values of them need not redo it (:mod:`tobitkf.app.manifest`)."""
    from tobitkf.io.unstated import names_no_skeleton, states_no_rate, states_no_units

    unused = []
    if not any(states_no_rate(s) for s in sequences):
        unused.append("input_fps")
    if not any(names_no_skeleton(s) for s in sequences):
        unused.append("input_topology")
    if not any(states_no_units(s) for s in sequences):
        unused.append("input_units")
    return unused


def _not_measured(smoothed: Any, raw: Any) -> np.ndarray:
    """Samples without a measurement the method used: NaN or not tracked in the input,
    or below the confidence threshold (the output's sample states 2, 3 and 4)."""
    states = getattr(smoothed, "sample_state", None)
    if states is not None:
        return np.isin(states, (2, 3, 4))
    return np.isnan(raw.positions).any(axis=-1)


def run_job(job: Job, method: str, params: dict[str, Any], offline: bool = False) -> FileSummary:
    """Read, smooth and write one file; any failure becomes a summary with its reason."""
    from tobitkf.io import detect_format, load
    from tobitkf.smoothing.api import smooth

    start = time.perf_counter()
    try:
        problem = readable_problem(job.source)
        if problem:
            return FileSummary(str(job.source), None, False, problem)
        in_fmt = detect_format(job.source) if job.input_format == "auto" else job.input_format
        sequences = load(job.source, format=in_fmt, implausible=job.input_implausible)
        if not sequences:
            raise ValueError("the file holds no skeleton")
        unused = _unused_settings(sequences)
        sequences = _with_given(sequences, job.input_topology, job.input_units)
        sequences, rate = _with_rate(sequences, job.input_fps)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            # one call: the bodies of a file are smoothed together, as tk.smooth(list)
            # does (pose estimators' individuals: their swaps undone, their gates pooled)
            smoothed = smooth(sequences, method=method, offline=offline, **params)
        read = [str(n) for seq in sequences for n in seq.metadata.get("reader_warnings") or ()]
        said = tuple(dict.fromkeys([*read, *rate, *(str(w.message) for w in caught)]))
        for s in smoothed:  # the file read, whatever the sequence's metadata says (NPZ)
            s.metadata["provenance"]["source"] = {
                "path": job.source_label or str(job.source),
                "format": in_fmt,
                # the reader's option: implausible positions read as missing ("missing")
                "implausible": job.input_implausible,
            }
        atomic_save(smoothed, job.output, job.output_format)
    except Exception as exc:  # reported per file; the run goes on
        return FileSummary(
            str(job.source),
            None,
            False,
            f"{type(exc).__name__}: {exc}",
            seconds=time.perf_counter() - start,
        )
    diags = [s.metadata.get("diagnostics", {}) for s in smoothed]
    missing = [_not_measured(s, raw) for s, raw in zip(smoothed, sequences, strict=True)]
    return FileSummary(
        source=str(job.source),
        output=str(job.output),
        ok=True,
        bodies=len(sequences),
        frames=max(s.n_frames for s in sequences),
        joints=max(s.n_joints for s in sequences),
        # Tobit methods clip measurements; the robust methods reject them instead
        clipped_percent=_percent(
            d.get("rejected_fraction", d.get("clipped_fraction", [])) for d in diags
        ),
        missing_percent=_percent(missing),
        seconds=time.perf_counter() - start,
        input_format=in_fmt,
        warnings=said,
        # the formats as read and written (for resume: auto and what it resolved to)
        extra={
            "unused_settings": unused,
            "formats": {"input": in_fmt, "output": job.output_format},
        },
    )


def run_task(
    job: Job,
    method: str,
    params: dict[str, Any],
    offline: bool = False,
    expect: str | None = None,
) -> FileSummary:
    """:func:`run_job` with the input's size and sha256 in the summary's ``extra`` (for
    the manifest, :mod:`tobitkf.app.manifest`). When ``expect`` (the sha256 a manifest
    recorded for a finished output) is the input's, nothing is read or written: the
    summary is ok with ``extra["skipped"]`` true. The per-file work of every run, local
    pool or Dask cluster. A job that is not a :class:`Job` but has a ``run`` method (a
    job on remote storage, :mod:`tobitkf.app.remote`) runs itself.
    """
    from tobitkf.app.manifest import recording_digest

    if not isinstance(job, Job):
        return job.run(method, params, offline, expect)

    start = time.perf_counter()
    try:
        size, sha = recording_digest(job.source)
    except OSError:  # run_job says why it cannot be read
        size, sha = None, None
    extra: dict[str, Any] = {"size": size, "sha256": sha, "planned_output": str(job.output)}
    if expect is not None and sha == expect:
        extra["skipped"] = True
        return FileSummary(
            str(job.source), str(job.output), True, seconds=time.perf_counter() - start, extra=extra
        )
    summary = run_job(job, method, params, offline)
    summary.extra.update(extra)
    return summary


def _run_job_star(args: tuple[Job, str, dict[str, Any], bool, str | None]) -> FileSummary:
    return run_task(*args)


def run_jobs(
    jobs: Sequence[Job],
    method: str,
    params: dict[str, Any],
    *,
    offline: bool = False,
    n_jobs: int = 1,
    on_done: Callable[[FileSummary], None] | None = None,
    expect: Sequence[str | None] | None = None,
) -> list[FileSummary]:
    """Run every job, in parallel processes when ``n_jobs > 1``; results in input order.

    ``expect[i]``, when given, is the sha256 a manifest recorded for job ``i``'s finished
    output: the job is passed over when its input still has it (:func:`run_task`).

    Ctrl-C raises :class:`~tobitkf.app.pool.Interrupted` with the summaries finished so
    far (``done``: job index -> FileSummary). With several processes a job whose worker
    process dies is retried once alone; if it kills that worker too it is reported as
    failed and the others go on (:mod:`tobitkf.app.pool`).
    """
    hashes = list(expect) if expect is not None else [None] * len(jobs)
    args = [(job, method, params, offline, h) for job, h in zip(jobs, hashes, strict=True)]

    def report(i: int, summary: FileSummary) -> None:
        if on_done:
            on_done(summary)

    try:
        results = _run_all(jobs, args, n_jobs, report)
    finally:  # a worker killed mid-write (Ctrl-C, a crash) leaves its temporary file
        remove_partial_outputs(jobs)
    return [results[i] for i in range(len(jobs))]


def remove_partial_outputs(jobs: Sequence[Job]) -> list[Path]:
    """Delete the temporary files of :func:`atomic_save` left by the given jobs (a process
    killed while writing); returns what was removed. Finished outputs are not touched."""
    by_dir: dict[Path, set[str]] = {}
    for job in jobs:
        if not isinstance(job, Job):  # remote storage: nothing staged here
            continue
        by_dir.setdefault(job.output.parent, set()).add(job.output.name)
    removed = []
    for folder, names in by_dir.items():
        if not folder.is_dir():
            continue
        for f in folder.glob(".*.part*"):
            base = f.name[1:].rsplit(".part", 1)[0].rsplit(".", 1)[0]  # .NAME.RANDOM.part...
            if base in names:
                f.unlink(missing_ok=True)
                removed.append(f)
    return removed


def _run_all(
    jobs: Sequence[Job], args: list[Any], n_jobs: int, report: Callable[[int, Any], None]
) -> dict[int, FileSummary]:
    from tobitkf.app.pool import Interrupted, run_in_workers

    if n_jobs <= 1 or len(jobs) <= 1:
        results: dict[int, FileSummary] = {}
        try:
            for i, a in enumerate(args):
                results[i] = _run_job_star(a)
                report(i, results[i])
        except KeyboardInterrupt:
            raise Interrupted(results) from None
    else:

        def died(i: int) -> FileSummary:
            return FileSummary(
                str(jobs[i].source),
                None,
                False,
                "the worker process died while reading or smoothing it, twice (out of "
                "memory, or a crash in native code); nothing was written",
            )

        results = run_in_workers(
            _run_job_star, args, n_jobs, on_result=report, on_worker_death=died
        )
    return results


def parse_param(text: str) -> tuple[str, Any]:
    """Parse ``key=value`` from the command line.

    Values become int, float, a tuple of floats (comma-separated), a mapping of names to
    numbers (``hands:6,arms:4``: per body region; the regions not named keep their
    defaults), a bool (``true``/``false``) or stay a string.
    """
    if "=" not in text:
        raise ValueError(f"parameter {text!r} is not of the form key=value")
    key, raw = text.split("=", 1)
    key = key.strip().replace("-", "_")
    raw = raw.strip()
    if not key:
        raise ValueError(f"parameter {text!r} has an empty name")
    low = raw.lower()
    if low in ("true", "false"):
        return key, low == "true"
    if low in ("none", "null"):
        return key, None
    try:
        return key, int(raw)
    except ValueError:
        pass
    try:
        return key, float(raw)
    except ValueError:
        pass
    if "," in raw:
        try:
            return key, tuple(float(v) for v in raw.split(","))
        except ValueError:
            pass
    items = [item.partition(":") for item in raw.split(",")]
    if all(sep and _NAME.fullmatch(name.strip()) for name, sep, _ in items):
        names = [name.strip() for name, _, _ in items]
        if len(set(names)) < len(names):
            raise ValueError(f"parameter {text!r} names a key twice")
        try:
            return key, {name.strip(): float(value) for name, _, value in items}
        except ValueError:
            pass  # text with a colon: the method's check says what it expects
    return key, raw


_NAME = re.compile(r"[A-Za-z_]\w*")
