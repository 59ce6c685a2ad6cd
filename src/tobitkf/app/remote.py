"""Inputs and outputs named by fsspec URLs (``s3://``, ``gs://``, ``file://``, ...).

When an input or the output folder is a URL, the worker that runs a file copies the input
to a local temporary folder, smooths it there with the same function as always
(:func:`~tobitkf.app.batch.run_task`, so the output bytes are the same) and uploads the
output (side files first, the output last; on a local file system through a temporary
name and a rename, on an object store as whole objects, which appear complete or not
at all). Only the fsspec package and the protocol's own (``s3fs``, ``gcsfs``) are needed,
on the client and on the workers; credentials come from their usual places there.
"""

from __future__ import annotations

import dataclasses
import fnmatch
import posixpath
import tempfile
import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

from tobitkf.app.batch import FileSummary, Job, not_a_recording, run_task, strip_extension

__all__ = ["RemoteJob", "is_url", "plan_remote", "remote_outputs"]


def is_url(path: Any) -> bool:
    """True for a string naming a file through a protocol (``s3://...``)."""
    return isinstance(path, str) and "://" in path


def url_to_fs(url: str) -> tuple[Any, str]:
    """fsspec's file system and path of ``url`` (a clear ImportError without fsspec)."""
    try:
        import fsspec
    except ImportError as exc:
        raise ImportError(
            "inputs or outputs named by URL need fsspec: pip install 'tobitkf[dask]' "
            "(and the protocol's package, e.g. s3fs for s3://)"
        ) from exc
    return fsspec.core.url_to_fs(url)


@dataclass(frozen=True)
class RemoteJob:
    """One input and its output, named by URLs; ``size``: the input's, when listed."""

    source: str
    output: str
    output_format: str
    input_format: str = "auto"
    size: int | None = None
    input_fps: float | None = None
    input_topology: str | None = None
    input_units: str | None = None
    input_implausible: str = "error"

    def side_outputs(self) -> list[str]:
        """URLs of the output's side files (the CSV's JSON sidecar)."""
        from tobitkf.io import output_files

        folder = self.output.rsplit("/", 1)[0]
        names = [f.name for f in output_files(self.output.rsplit("/", 1)[1], self.output_format)]
        return [f"{folder}/{n}" for n in names[1:]]

    def run(
        self, method: str, params: dict[str, Any], offline: bool, expect: str | None
    ) -> FileSummary:
        """Copy the input here, smooth it, upload the output; a failure is a summary."""
        with tempfile.TemporaryDirectory(prefix="tobitkf-") as tmp:
            fs, path = url_to_fs(self.source)
            local = Path(tmp) / "in" / posixpath.basename(path)
            local.parent.mkdir()
            extra = {"planned_output": self.output}
            try:
                fs.get_file(path, str(local))
                _get_read_with(fs, path, local)
            except Exception as exc:
                why = f"cannot read it: {type(exc).__name__}: {exc}"
                return FileSummary(self.source, None, False, why, extra=extra)
            out_local = Path(tmp) / "out" / self.output.rsplit("/", 1)[1]
            job = Job(local, out_local, self.output_format, self.input_format, self.source,
                      self.input_fps, self.input_topology, self.input_units,
                      self.input_implausible)  # fmt: skip
            summary = run_task(job, method, params, offline, expect)
            error = summary.error.replace(str(local), self.source) if summary.error else None
            ok = summary.ok
            if ok and not summary.extra.get("skipped"):
                try:
                    _upload(out_local, self.output, self.output_format)
                except Exception as exc:
                    ok, error = False, f"cannot write {self.output}: {type(exc).__name__}: {exc}"
            return dataclasses.replace(
                summary,
                source=self.source,
                output=self.output if ok else None,
                ok=ok,
                error=error,
                extra={**summary.extra, **extra},
            )


def _get_read_with(fs: Any, path: str, local: Path) -> None:
    """Copy beside ``local`` the files a reader reads with the input at ``path`` (a
    UI-PRMD positions file's angles, an array's JSON sidecar) that exist there, each to
    where the reader will look for it beside the local copy."""
    from tobitkf.io import read_with

    there, here = read_with(PurePosixPath(path)), read_with(local)
    for src, dst in zip(there, here, strict=True):
        if fs.exists(str(src)):
            dst.parent.mkdir(parents=True, exist_ok=True)
            fs.get_file(str(src), str(dst))


def _upload(local: Path, url: str, output_format: str) -> None:
    """Side files first, the output last; through a temporary name on a local file system."""
    from fsspec.implementations.local import LocalFileSystem

    from tobitkf.io import output_files

    fs, path = url_to_fs(url)
    folder = posixpath.dirname(path)
    fs.makedirs(folder, exist_ok=True)
    for f in reversed(output_files(local, output_format)):
        if not f.exists():
            continue
        dst = posixpath.join(folder, f.name)
        if isinstance(fs, LocalFileSystem):
            tmp = posixpath.join(folder, f".{f.name}.{uuid.uuid4().hex[:8]}.part")
            fs.put_file(str(f), tmp)
            fs.mv(tmp, dst)
        else:
            fs.put_file(str(f), dst)


def _ours(name: str) -> bool:
    """An earlier tobitkf output, by its name (``<name>.<method><ext>``)."""
    from tobitkf.smoothing.api import method_names

    stem = strip_extension(name)
    return "." in stem and stem.rsplit(".", 1)[1] in method_names()


def plan_remote(
    inputs: Sequence[str],
    out_url: str,
    *,
    method: str,
    pattern: str = "*",
    output_format: str = "auto",
    input_format: str = "auto",
    input_fps: float | None = None,
    input_topology: str | None = None,
    input_units: str | None = None,
    input_implausible: str = "error",
) -> tuple[list[RemoteJob], list[FileSummary]]:
    """Jobs for inputs named by URLs or paths (folders listed recursively) with outputs
    under ``out_url`` (a URL or a path), keeping the relative layout; the output format
    ``auto`` keeps ``.skeleton`` (NTU) files NTU and writes CSV otherwise.

    Raises FileNotFoundError when an input does not exist.
    """
    from tobitkf.app.batch import default_output_format
    from tobitkf.io import output_extension, read_with

    out_fs, out_root = url_to_fs(out_url)
    jobs: list[RemoteJob] = []
    refused: list[FileSummary] = []
    taken: dict[str, str] = {}
    for item in inputs:
        fs, root = url_to_fs(item)
        if not fs.exists(root):
            raise FileNotFoundError(f"input not found: {item}")
        folder = fs.isdir(root)
        if folder:
            listing = fs.find(root, detail=True)
            base = root.rstrip("/")
        else:
            listing = {root: fs.info(root)}
            base = posixpath.dirname(root)
        # files read with another listed file (UI-PRMD angles, an array's sidecar)
        companions = {
            str(f) for path in listing for f in read_with(PurePosixPath(path)) if str(f) in listing
        }
        for path in sorted(listing):
            name = posixpath.basename(path)
            if folder:  # a file named explicitly is taken as given
                if name.startswith(".") or not fnmatch.fnmatch(name, pattern):
                    continue
                if name == "tobitkf-manifest.jsonl" or not_a_recording(Path(name)) or _ours(name):
                    continue
                if path in companions:
                    continue
            in_fmt = input_format
            if in_fmt == "auto" and name.lower().endswith(".skeleton"):
                in_fmt = "ntu"
            fmt = default_output_format(in_fmt) if output_format == "auto" else output_format
            rel = posixpath.relpath(posixpath.dirname(path), base)
            target = out_root.rstrip("/") + ("" if rel == "." else f"/{rel}")
            out = f"{target}/{strip_extension(name)}.{method}{output_extension(fmt)}"
            source = fs.unstrip_protocol(path)
            if out in taken:
                why = f"output {out} is already the output of {taken[out]}"
                refused.append(FileSummary(source, None, False, why))
                continue
            taken[out] = source
            size = listing[path].get("size")
            jobs.append(RemoteJob(source, out_fs.unstrip_protocol(out), fmt, input_format, size,
                                  input_fps, input_topology, input_units,
                                  input_implausible))  # fmt: skip
    return jobs, refused


def remote_outputs(out_url: str) -> set[str]:
    """URLs of every file under ``out_url`` (one listing, for resume)."""
    fs, root = url_to_fs(out_url)
    if not fs.exists(root):
        return set()
    return {fs.unstrip_protocol(p) for p in fs.find(root)}
