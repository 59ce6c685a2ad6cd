"""Format registry: readers, writers, extensions and content sniffers; load / save.

A format is registered with :func:`register_format`. ``detect_format`` asks every
sniffer for a score on the file's first 64 KB (0 = not this format, higher = more sure)
and breaks ties by the file extension; with no positive score it falls back to the
extension alone when that is unambiguous. A directory is offered to the formats that read
folders (``sniff_dir``, e.g. an OpenPose JSON output folder).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from tobitkf.io._text import check_implausible_option, read_head
from tobitkf.io.errors import OptionError, ReadError
from tobitkf.skeleton.sequence import SkeletonSequence

__all__ = [
    "FormatSpec",
    "detect_format",
    "formats",
    "get_format",
    "input_files",
    "is_companion_file",
    "load",
    "output_extension",
    "output_files",
    "read_with",
    "register_format",
    "save",
    "unregister_format",
    "writable_formats",
]

Reader = Callable[..., list[SkeletonSequence]]
Writer = Callable[..., None]
Sniffer = Callable[[Path, str], int]
DirSniffer = Callable[[Path], int]


@dataclass(frozen=True)
class FormatSpec:
    """A registered file format."""

    name: str
    reader: Reader | None
    writer: Writer | None
    extensions: tuple[str, ...]
    sniff: Sniffer | None
    description: str = ""
    companion: Callable[[Path], bool] | None = None
    side_outputs: Callable[[Path], list[Path]] | None = None
    sniff_dir: DirSniffer | None = None
    read_with: Callable[[Path], list[Path]] | None = None
    output_ext: str | None = None


_FORMATS: dict[str, FormatSpec] = {}
_ALIASES: dict[str, str] = {}


def register_format(
    name: str,
    reader: Reader | None,
    writer: Writer | None = None,
    extensions: Iterable[str] = (),
    sniff: Sniffer | None = None,
    *,
    description: str = "",
    aliases: Iterable[str] = (),
    companion: Callable[[Path], bool] | None = None,
    side_outputs: Callable[[Path], list[Path]] | None = None,
    sniff_dir: DirSniffer | None = None,
    read_with: Callable[[Path], list[Path]] | None = None,
    output_ext: str | None = None,
) -> FormatSpec:
    """Register (or replace) a file format.

    Parameters
    ----------
    name : str
        Format name used by ``load(..., format=name)`` and ``save(..., format=name)``.
    reader : callable ``(path, **options) -> list[SkeletonSequence]`` or None
    writer : callable ``(sequences, path, **options) -> None`` or None
    extensions : iterable of str
        Lower-case file name endings including the dot (``".csv"``, ``".txt.gz"``).
    sniff : callable ``(path, head_text) -> int`` or None
        Score of the file's content (0 = not this format).
    aliases : iterable of str
        Other names accepted for this format.
    companion : callable ``(path) -> bool``, optional
        True for a file that is the second half of a recording read through another
        file (batch tools skip it, see :func:`is_companion_file`).
    side_outputs : callable ``(path) -> list of Path``, optional
        The files the writer writes beside ``path`` (the CSV's JSON sidecar); batch tools
        treat them as part of the output (:func:`output_files`).
    sniff_dir : callable ``(directory) -> int``, optional
        Score of a directory for a format whose recordings are folders (0 = not this
        format); the reader then receives the directory's path.
    read_with : callable ``(path) -> list of Path``, optional
        The other files the reader reads with ``path`` when it is one of this format's
        recordings (a UI-PRMD positions file's angles, an array's JSON sidecar), given
        any path (``[]`` when it is none of this format's): batch tools hash them with
        the recording (:func:`input_files`), so that editing one redoes its output.
    output_ext : str, optional
        The ending of the writer's outputs when it is not the first of ``extensions``:
        a format that shares its files' ending with another, and so claims none for
        detection (a LightningPose CSV is a ``.csv``, read as one by its content).
    """
    spec = FormatSpec(
        name=name,
        reader=reader,
        writer=writer,
        extensions=tuple(e.lower() for e in extensions),
        sniff=sniff,
        description=description,
        companion=companion,
        side_outputs=side_outputs,
        sniff_dir=sniff_dir,
        read_with=read_with,
        output_ext=None if output_ext is None else output_ext.lower(),
    )
    _FORMATS[name] = spec
    for a in aliases:
        _ALIASES[a] = name
    return spec


def require_frames(sequences: Iterable[SkeletonSequence], fmt: str) -> None:
    """Refuse a recording with no frame for a format whose files cannot be read back
    without one (a ``ValueError`` naming the format), instead of writing such a file."""
    if all(s.n_frames == 0 for s in sequences):
        raise ValueError(
            f"the recording has no frame, and {fmt} files without one cannot be read back "
            "(format='npz' keeps an empty recording)"
        )


def require_rate_grid(seq: SkeletonSequence, rate: float, fmt: str) -> None:
    """Refuse a recording whose frames a format that keeps a frame rate and no times (C3D,
    NTU) would read back at other times: a ``ValueError`` naming the first frame more than
    half a frame off the grid ``first + k / rate`` (irregular or dropped frames, another
    rate). Timing jitter within half a frame is kept as the grid's times."""
    if seq.timestamps is None and seq.fps is None:
        return  # no timing to keep
    t = seq.times()
    if t.size < 2:
        return
    off = (t - t[0]) * rate - np.arange(t.size)
    bad = np.abs(off) > 0.5
    if bad.any():
        k = int(np.argmax(bad))
        raise ValueError(
            f"{fmt} files keep a frame rate ({rate:g} Hz), not each frame's time: frame {k}, "
            f"{t[k] - t[0]:.4g} s after the first, would be read back at {k / rate:.4g} s; "
            "write trc, csv or npz, which keep the times"
        )


def unregister_format(name: str) -> None:
    """Remove a registered format (and its aliases)."""
    _FORMATS.pop(name, None)
    for alias in [a for a, n in _ALIASES.items() if n == name]:
        del _ALIASES[alias]


def is_companion_file(path: str | os.PathLike[str]) -> bool:
    """True when ``path`` is the second half of a recording read through another file
    (e.g. a UI-PRMD Kinect ``..._angles`` file, whose ``..._positions`` sibling exists),
    as the formats' ``companion`` predicates say.

    Loading a companion file works (it returns the pair's skeleton), but batch tools
    walking a folder should skip it so that each recording is processed once.
    """
    p = Path(path)
    return any(s.companion is not None and s.companion(p) for s in _FORMATS.values())


def read_with(path: str | os.PathLike[str]) -> list[Path]:
    """The files a reader would read with ``path`` (the formats' ``read_with``), whether
    they exist or not, once each, in the formats' order (the same for any folder)."""
    p = Path(path)
    found: list[Path] = []
    for spec in _FORMATS.values():
        if spec.read_with is not None:
            found.extend(f for f in spec.read_with(p) if f != p and f not in found)
    return found


def input_files(path: str | os.PathLike[str]) -> list[Path]:
    """``path`` and the existing files read with it (:func:`read_with`)."""
    return [Path(path), *(f for f in read_with(path) if f.is_file())]


def writable_formats() -> list[str]:
    """Sorted names of the registered formats that have a writer."""
    return sorted(n for n, s in _FORMATS.items() if s.writer is not None)


def output_extension(name: str) -> str:
    """The file ending a writer's output gets: the format's first extension."""
    spec = get_format(name)
    if spec.writer is None:
        raise ValueError(f"format {name!r} cannot be written; writable: {writable_formats()}")
    if spec.output_ext is not None:
        return spec.output_ext
    if not spec.extensions:
        raise ValueError(f"format {name!r} names no ending for its files (output_ext)")
    return spec.extensions[0]


def output_files(path: str | os.PathLike[str], name: str) -> list[Path]:
    """Every file that writing format ``name`` to ``path`` produces: ``path`` first, then
    the format's side outputs (e.g. ``a.csv`` -> ``a.csv``, ``a.json``)."""
    spec = get_format(name)
    p = Path(path)
    return [p, *(Path(x) for x in (spec.side_outputs(p) if spec.side_outputs else ()))]


def formats() -> dict[str, FormatSpec]:
    """All registered formats by name."""
    return dict(_FORMATS)


def get_format(name: str) -> FormatSpec:
    """Registered format by name or alias."""
    key = _ALIASES.get(name, name)
    try:
        return _FORMATS[key]
    except KeyError:
        raise ValueError(f"unknown format {name!r}; expected one of {sorted(_FORMATS)}") from None


def _extension_matches(path: Path) -> list[str]:
    lower = path.name.lower()
    best: list[tuple[int, str]] = []
    for spec in _FORMATS.values():
        lengths = [len(e) for e in spec.extensions if lower.endswith(e)]
        if lengths:
            best.append((max(lengths), spec.name))
    if not best:
        return []
    top = max(n for n, _ in best)
    return [name for n, name in best if n == top]


def detect_format(path: str | os.PathLike[str]) -> str:
    """Name of the format of ``path``, from its content and its extension.

    Raises
    ------
    ReadError
        When the file is missing, empty, holds gzip data that cannot be decompressed, or
        matches no registered format.
    """
    p = Path(path)
    if not p.exists():
        raise ReadError(p, None, "file not found")
    if p.is_dir():
        return _detect_directory(p)
    if p.stat().st_size == 0:
        raise ReadError(p, None, "empty file: expected skeleton data")
    head = read_head(p, check_gzip=True)  # a broken gzip: no reader can read it
    by_ext = set(_extension_matches(p))
    scored: list[tuple[int, int, str]] = []
    for spec in _FORMATS.values():
        if spec.sniff is None or spec.reader is None:
            continue
        try:
            score = int(spec.sniff(p, head))
        except Exception:  # a sniffer never decides by crashing
            score = 0
        if score > 0:
            scored.append((score, int(spec.name in by_ext), spec.name))
    if scored:
        scored.sort(reverse=True)
        return scored[0][2]
    readable = [n for n in by_ext if _FORMATS[n].reader is not None]
    if len(readable) == 1:
        return readable[0]
    raise ReadError(
        p,
        None,
        "unrecognised content: expected one of the formats "
        f"{sorted(n for n, s in _FORMATS.items() if s.reader is not None)}",
    )


def _detect_directory(path: Path) -> str:
    """Name of the folder format with the best positive ``sniff_dir`` score."""
    scored: list[tuple[int, str]] = []
    folder_formats = []
    for spec in _FORMATS.values():
        if spec.sniff_dir is None or spec.reader is None:
            continue
        folder_formats.append(spec.name)
        try:
            score = int(spec.sniff_dir(path))
        except Exception:  # a sniffer never decides by crashing
            score = 0
        if score > 0:
            scored.append((score, spec.name))
    if scored:
        return max(scored)[1]
    raise ReadError(
        path,
        None,
        "expected a file, found a directory (folders are read by the formats "
        f"{sorted(folder_formats)}, and this one holds none of their files)",
    )


def load(
    path: str | os.PathLike[str], format: str = "auto", **options: Any
) -> list[SkeletonSequence]:
    """Read a recording: one :class:`SkeletonSequence` per body.

    Parameters
    ----------
    path : str or PathLike
    format : str
        A registered format name, or ``"auto"`` (:func:`detect_format`).
    **options
        Passed to the reader (e.g. ``points="markers"`` for C3D). Every built-in reader
        takes ``implausible="missing"``: a coordinate beyond the plausibility bound is
        read as missing instead of raising a ReadError.

    Raises
    ------
    ReadError
        Bad content (names file, line and what was expected).
    """
    p = Path(path)
    if not p.exists():
        raise ReadError(p, None, "file not found")
    name = detect_format(p) if format in (None, "auto") else format
    spec = get_format(name)
    if spec.reader is None:
        raise ValueError(f"format {spec.name!r} has no reader")
    if "implausible" in options:
        options = _implausible_option(spec, options)
    try:
        result = spec.reader(p, **options)
    except (ReadError, OptionError, ImportError, OSError, TypeError):
        raise
    except (ValueError, IndexError, KeyError, ArithmeticError) as exc:  # safety net
        raise ReadError(p, None, f"invalid {spec.name} content ({exc})") from exc
    return list(result)


def _implausible_option(spec: FormatSpec, options: dict[str, Any]) -> dict[str, Any]:
    """``options`` for ``spec``'s reader: ``implausible`` checked, and left out for a
    registered reader without that parameter when it asks for the default (``"error"``);
    asking such a reader for ``"missing"`` is an :class:`OptionError`."""
    import inspect

    check_implausible_option(options["implausible"])
    try:
        params = inspect.signature(spec.reader).parameters  # type: ignore[arg-type]
    except (TypeError, ValueError):  # no signature: pass it on
        return options
    if "implausible" in params or any(p.kind is p.VAR_KEYWORD for p in params.values()):
        return options
    if options["implausible"] == "error":
        return {k: v for k, v in options.items() if k != "implausible"}
    raise OptionError(
        f"the {spec.name} reader has no implausible option: it cannot read implausible "
        "positions as missing"
    )


def save(
    sequences: SkeletonSequence | Sequence[SkeletonSequence],
    path: str | os.PathLike[str],
    format: str | None = None,
    **options: Any,
) -> None:
    """Write sequences (one per body) to ``path``.

    Parameters
    ----------
    sequences : SkeletonSequence or list of them
    path : str or PathLike
    format : str, optional
        A registered format with a writer (``"csv"``, ``"npz"``, ``"ntu"``); by default
        from the extension.
    """
    if isinstance(sequences, SkeletonSequence):
        sequences = [sequences]
    seqs = list(sequences)
    for s in seqs:
        if not isinstance(s, SkeletonSequence):
            raise TypeError(f"expected SkeletonSequence objects, found {type(s).__name__}")
    p = Path(path)
    if format in (None, "auto"):
        names = [n for n in _extension_matches(p) if _FORMATS[n].writer is not None]
        if len(names) != 1:
            writable = writable_formats()
            raise ValueError(
                f"cannot choose an output format from the name {p.name!r}; "
                f"pass format= one of {writable}"
            )
        format = names[0]
    spec = get_format(format)
    if spec.writer is None:
        writable = writable_formats()
        raise ValueError(f"format {spec.name!r} cannot be written; writable formats: {writable}")
    spec.writer(seqs, p, **options)
