"""The run manifest of ``tobitkf smooth``: one JSON line per input, in the output folder.

``OUT/tobitkf-manifest.jsonl`` records, for every input a run has seen: its absolute
path, size and sha256, the output path, the status (``ok`` or ``failed``) and error
message, the method, the complete parameters (defaults included, with ``offline`` and the
formats), the tobitkf version, frames, bodies and seconds. Lines are appended (and
flushed) by the process that drives the run as each file finishes, so a run killed at any
point (SIGKILL included) keeps the record of every output it had been told of; a line cut
short by a kill is ignored when read. At the end of a run the file is rewritten (through
a temporary file and a rename) with one line per input, the latest, sorted by input.

**Resume**: an input is done when its latest entry is ``ok``, names the same method,
parameters and version (the formats as read and written, :func:`same_formats`), the
same output, and that output (with its side files) exists;
the worker that would process it first hashes the input and passes over it when the hash
is the recorded one (:func:`~tobitkf.app.batch.run_task`). ``--overwrite`` redoes
everything. One module for the local pool and for a Dask cluster.

An output folder named by an fsspec URL (``s3://bucket/out``) keeps its manifest there
too; object stores cannot append, so the file is rewritten whole every
:data:`REMOTE_FLUSH_SECONDS` and at the end (a killed client loses the record of at most
that many seconds of files, which a re-run does again), and there is no lock.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import IO, Any

__all__ = [
    "MANIFEST_NAME",
    "Manifest",
    "ManifestBusy",
    "file_digest",
    "recording_digest",
    "run_settings",
]

#: file name of the manifest in the output folder
MANIFEST_NAME = "tobitkf-manifest.jsonl"
#: how often the manifest of a remote output folder is rewritten, seconds
REMOTE_FLUSH_SECONDS = 10.0
#: entry fields that must equal the current run's for an input to be passed over
_SAME = ("method", "params", "tobitkf_version", "output")


class ManifestBusy(RuntimeError):
    """Another run is writing to the same output folder."""


def file_digest(path: str | os.PathLike[str], chunk: int = 1 << 20) -> tuple[int, str]:
    """``(size in bytes, sha256 hex digest)`` of a file, read in chunks."""
    h = hashlib.sha256()
    size = 0
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
            size += len(block)
    return size, h.hexdigest()


def recording_digest(path: str | os.PathLike[str]) -> tuple[int, str]:
    """``(size, sha256)`` of a recording: the file's size (what a listing shows, the
    resume's first check) and the sha256 of the file alone when it is read alone (as
    :func:`file_digest`), else of the file and the files read with it together (a
    UI-PRMD positions file and its angles, an array and its JSON sidecar:
    :func:`tobitkf.io.input_files`), so that a change to any of them redoes the output."""
    from tobitkf.io import input_files

    size, sha = file_digest(path)
    files = input_files(path)
    if len(files) == 1:
        return size, sha
    h = hashlib.sha256(f"{sha}\n".encode())
    for f in files[1:]:
        h.update(f"{file_digest(f)[1]}\n".encode())
    return size, h.hexdigest()


def _plain(value: Any) -> Any:
    """JSON round trip (tuples become lists, NaN null): what a read entry holds."""
    from tobitkf.core.jsonable import to_jsonable

    return json.loads(json.dumps(to_jsonable(value), sort_keys=True, allow_nan=False))


def run_settings(
    method: str,
    params: Mapping[str, Any],
    *,
    offline: bool = False,
    output_format: str = "auto",
    input_format: str = "auto",
    input_fps: float | None = None,
    input_topology: str | None = None,
    input_units: str | None = None,
    input_implausible: str = "error",
) -> dict[str, Any]:
    """What an output depends on besides its input: method, complete parameters
    (defaults filled in and validated, ``offline`` and the formats included) and the
    tobitkf version, as stored in the manifest. ``offline`` is whether the output used
    later frames (``--offline``, or a method that is offline by itself), as the output's
    provenance says; ``input_fps`` the rate given to inputs that state none,
    ``input_topology`` the skeleton given to inputs that name none, ``input_units`` the
    length unit given to inputs that state none, ``input_implausible`` what the readers
    did with implausible positions (recorded when not the default, ``"error"``, so that
    manifests written before the option still match)."""
    from tobitkf.core.version import __version__
    from tobitkf.smoothing.api import COMMON_KEYWORDS, check_params, get_method

    full = check_params(method, params)
    full.update({k: params[k] for k in COMMON_KEYWORDS if k in params})
    full["offline"] = bool(offline) or not get_method(method).is_causal(full)
    full["input_format"] = input_format
    if input_fps is not None:
        full["input_fps"] = float(input_fps)
    if input_topology is not None:
        full["input_topology"] = input_topology
    if input_units is not None:
        full["input_units"] = input_units
    if input_implausible != "error":
        full["input_implausible"] = input_implausible
    full["output_format"] = output_format
    return {"method": method, "params": _plain(full), "tobitkf_version": __version__}


def input_key(path: str | os.PathLike[str]) -> str:
    """How the manifest names a file: its absolute path, or its URL."""
    text = os.fspath(path)
    return text if "://" in text else os.path.abspath(text)


class Manifest:
    """The manifest of one output folder, open for one run (a context manager).

    While open it holds an exclusive lock on the file (``flock``, where the file system
    has it), so two runs cannot write to one folder at the same time.
    """

    def __init__(self, outdir: str | os.PathLike[str]) -> None:
        self._remote: tuple[Any, str] | None = None
        if isinstance(outdir, str) and "://" in outdir:
            import fsspec

            fs, root = fsspec.core.url_to_fs(outdir)
            self._remote = (fs, f"{root.rstrip('/')}/{MANIFEST_NAME}")
            self.path = Path(MANIFEST_NAME)  # not used for a remote folder
        else:
            self.path = Path(outdir) / MANIFEST_NAME
        #: (input, output) -> the latest entry of that pair, oldest first: an input smoothed
        #: into two outputs (two methods, two formats) keeps both, so either is passed over
        self.pairs: dict[tuple[str, Any], dict[str, Any]] = self._read()
        self._owners: dict[str, str] | None = None  # output -> input, built when asked
        self._file: IO[str] | None = None
        self._open = False
        self._flushed = time.monotonic()

    def _read(self) -> dict[tuple[str, Any], dict[str, Any]]:
        if self._remote is None:
            return _read_local(self.path)
        fs, path = self._remote
        if not fs.exists(path):
            return {}
        return parse_pairs(fs.cat_file(path).decode("utf-8").splitlines())

    # -- the run's file --------------------------------------------------------
    def __enter__(self) -> Manifest:
        self._open = True
        if self._remote is not None:
            self.pairs = self._read()
            self._owners = None
            return self
        self.path.parent.mkdir(parents=True, exist_ok=True)
        f = open(self.path, "a+", encoding="utf-8")
        try:
            import fcntl

            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except ImportError:  # pragma: no cover - not POSIX
            pass
        except OSError as exc:
            f.close()
            raise ManifestBusy(
                f"another tobitkf run is writing to {self.path.parent} (its manifest "
                f"{self.path.name} is locked)"
            ) from exc
        with open(self.path, "rb") as raw:
            raw.seek(0, os.SEEK_END)
            if raw.tell():
                raw.seek(-1, os.SEEK_END)
                if raw.read(1) != b"\n":  # a line cut short by a kill: start a new one
                    f.write("\n")
        self._file = f
        self.pairs = self._read()  # what the lock now guarantees
        self._owners = None
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Rewrite the file with the latest line of each input and output (the latest of
        an input last), then release the lock."""
        if self._remote is not None and self._open:
            self._open = False
            self._rewrite_remote()
        _LAST_READ.clear()  # the run is over: its parse is not kept for the process's life
        if self._file is None:
            return
        try:
            self._file.flush()
            _rewrite(self.path, self.pairs.values())
        finally:
            self._file.close()  # releases the lock
            self._file = None

    def record(self, entry: Mapping[str, Any]) -> None:
        """Append one entry (a line, flushed at once)."""
        entry = _plain(dict(entry))
        key = _pair(entry)
        self.pairs.pop(key, None)  # latest last
        self.pairs[key] = entry
        if self._owners is not None and entry.get("status") == "ok" and key[1]:
            self._owners[key[1]] = key[0]
        if self._file is not None:
            self._file.write(json.dumps(entry, sort_keys=True) + "\n")
            self._file.flush()
        elif self._remote is not None and self._open:
            if time.monotonic() - self._flushed > REMOTE_FLUSH_SECONDS:
                self._rewrite_remote()

    def _rewrite_remote(self) -> None:
        fs, path = self._remote
        lines = [json.dumps(e, sort_keys=True) + "\n" for e in self.pairs.values()]
        fs.pipe_file(path, "".join(lines).encode("utf-8"))
        self._flushed = time.monotonic()

    # -- resume ----------------------------------------------------------------
    def owner(self, output: Any) -> str | None:
        """The input whose result ``output`` holds: the input of the latest ``ok`` entry
        naming it (None when no entry does)."""
        if self._owners is None:
            self._owners = {
                out: inp for (inp, out), e in self.pairs.items() if out and e.get("status") == "ok"
            }
        return self._owners.get(input_key(output))

    def entry(self, source: Any, output: Any) -> dict[str, Any] | None:
        """The latest entry of ``source`` smoothed into ``output``, or None."""
        return self.pairs.get((input_key(source), input_key(output) if output else None))

    def done_digest(
        self,
        source: str | os.PathLike[str],
        output: str | os.PathLike[str],
        side_files: Iterable[str | os.PathLike[str]],
        settings: Mapping[str, Any],
        *,
        size: int | None = None,
        exists: Callable[[Any], bool] = os.path.isfile,
        output_format: str | None = None,
    ) -> str | None:
        """The recorded sha256 of ``source`` when its latest entry says it was done with
        these settings into ``output`` and that output still exists (with its side files)
        at the recorded size of the input; None when it must be (re)done. The caller
        still compares the hash with the file's (a worker does). For remote storage,
        ``size`` is the input's size and ``exists`` says whether an output is there.

        ``output_format``: the format this job writes (``auto`` resolved for this file).
        With it, the formats are compared as the files were read and written
        (:func:`same_formats`), not as typed."""
        entry = self.entry(source, output)
        if not entry or entry.get("status") != "ok" or not entry.get("sha256"):
            return None
        if self.owner(output) != input_key(source):  # another input's result replaced it
            return None
        want = {**settings, "output": input_key(output)}
        unused = entry.get("unused_settings") or ()
        if unused:  # a file with its own rate or skeleton does not depend on those given
            want["params"] = {k: v for k, v in want["params"].items() if k not in unused}
        have = entry
        if output_format is not None and isinstance(entry.get("formats"), dict):
            if not same_formats(entry, want["params"], output_format):
                return None
            have = {**entry, "params": _without_formats(entry.get("params"))}
            want["params"] = _without_formats(want["params"])
        if any(have.get(k) != want[k] for k in _SAME):
            return None
        try:
            if (os.path.getsize(source) if size is None else size) != entry.get("size"):
                return None
        except OSError:
            return None
        if not all(exists(p) for p in (output, *side_files)):
            return None
        return str(entry["sha256"])


_FORMAT_KEYS = ("input_format", "output_format")


def _without_formats(params: Any) -> Any:
    if not isinstance(params, dict):
        return params
    return {k: v for k, v in params.items() if k not in _FORMAT_KEYS}


def same_formats(entry: Mapping[str, Any], params: Mapping[str, Any], output_format: str) -> bool:
    """Whether a run with ``params`` (the formats as typed) writing ``output_format`` (as
    resolved for the file) reads and writes the file as ``entry`` records it was:

    * the output format written is the same (``-f csv`` and ``auto`` on a Kinect file are
      one format; ``-f lightningpose`` writes another file under the same name);
    * the input format typed is the one typed then, or the one the reader then used
      (``-F ntu`` after ``auto`` read it as NTU). After an explicit format, ``auto`` redoes
      the file: which reader it picks is not known without reading the file.
    """
    used = entry.get("formats") or {}
    if used.get("output") != output_format:
        return False
    typed = params.get("input_format", "auto")
    then = (entry.get("params") or {}).get("input_format", "auto")
    return typed in (then, used.get("input"))


def make_entry(summary: Any, settings: Mapping[str, Any]) -> dict[str, Any]:
    """The manifest entry of one finished file (a :class:`~tobitkf.app.batch.FileSummary`
    with ``extra["size"]`` and ``extra["sha256"]`` when the input could be read)."""
    extra = summary.extra or {}
    unused = list(extra.get("unused_settings") or ())
    if unused:  # the rate or skeleton given did not apply: the output does not depend on it
        params = {k: v for k, v in settings["params"].items() if k not in unused}
        settings = {**settings, "params": params}
    size = extra.get("size")
    if size is None and "://" not in summary.source:
        try:
            size = os.path.getsize(summary.source)
        except OSError:
            size = None
    output = summary.output or extra.get("planned_output")  # a failure: where it would be
    return {
        "input": input_key(summary.source),
        "size": size,
        "sha256": extra.get("sha256"),
        "output": input_key(output) if output else None,
        "status": "ok" if summary.ok else "failed",
        "error": summary.error,
        "unused_settings": unused,
        **({"formats": extra["formats"]} if extra.get("formats") else {}),
        **settings,
        "frames": summary.frames,
        "bodies": summary.bodies,
        "seconds": round(float(summary.seconds), 6),
    }


def read_entries(path: str | os.PathLike[str]) -> dict[str, dict[str, Any]]:
    """Input path -> latest entry, from a manifest file (missing file: empty). Lines
    that are not whole JSON objects (cut short by a kill) are ignored."""
    try:
        f = open(path, encoding="utf-8")
    except FileNotFoundError:
        return {}
    with f:
        return parse_entries(f)


def _pair(entry: Mapping[str, Any]) -> tuple[str, Any]:
    return entry["input"], entry.get("output")


def parse_pairs(lines: Iterable[str]) -> dict[tuple[str, Any], dict[str, Any]]:
    """(input, output) -> latest entry, oldest first, from manifest lines (broken lines
    ignored)."""
    out: dict[tuple[str, Any], dict[str, Any]] = {}
    for line in lines:
        try:
            entry = json.loads(line)
        except ValueError:
            continue
        if (
            isinstance(entry, dict)
            and isinstance(entry.get("input"), str)
            and isinstance(entry.get("output"), (str, type(None)))
        ):
            out.pop(_pair(entry), None)  # latest last
            out[_pair(entry)] = entry
    return out


def parse_entries(lines: Iterable[str]) -> dict[str, dict[str, Any]]:
    """Input path -> latest entry, from manifest lines (broken lines ignored)."""
    return {e["input"]: e for e in parse_pairs(lines).values()}


#: the last local manifest parsed: (path, (inode, size, mtime)) -> its pairs. A run
#: reads its folder's manifest to plan, on opening and again under the lock; for 10^5
#: inputs a parse takes seconds, so an unchanged file is parsed once
_LAST_READ: dict[tuple[str, tuple[int, int, int]], dict[tuple[str, Any], dict[str, Any]]] = {}


def _read_local(path: Path) -> dict[tuple[str, Any], dict[str, Any]]:
    try:
        with open(path, encoding="utf-8") as f:
            st = os.fstat(f.fileno())
            key = (os.path.realpath(path), (st.st_ino, st.st_size, st.st_mtime_ns))
            if key not in _LAST_READ:
                pairs = parse_pairs(f)
                _LAST_READ.clear()
                _LAST_READ[key] = pairs
    except FileNotFoundError:
        return {}
    return dict(_LAST_READ[key])  # the run changes its own copy (entries are replaced)


def _rewrite(path: Path, entries: Iterable[Mapping[str, Any]]) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".part")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            for e in entries:
                f.write(json.dumps(e, sort_keys=True) + "\n")
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
