"""Shared helpers of the readers: bounded reading (gzip-aware), decoding, the one number
syntax, numeric blocks, and the limits that hold against hostile files.

Every failure becomes a :class:`~tobitkf.io.errors.ReadError` naming the file and line.

Limits (documented in ``docs/data.md``, "Limits and hostile input"):

* :data:`MAX_INPUT_BYTES`: the most a reader takes in, after decompression (a text file,
  a gunzipped text file, the arrays of an NPZ archive); gzip data are decompressed in a
  stream and refused as soon as they pass it.
* :func:`check_output_size`: what a reader allocates from counts the file declares is
  bounded by ``max(MIN_OUTPUT_BYTES, OUTPUT_BYTES_PER_INPUT_BYTE * file size)``.
* :data:`NUMBER`: plain ASCII decimal numbers only (no ``1_000``, no non-ASCII digits, no
  hex, no ``inf``; ``nan`` only where a format documents it).
* :data:`MAX_ABS_POSITION_M`: plausible coordinates, in metres after unit conversion.
* :data:`MIN_RATE_HZ`, :data:`MAX_RATE_HZ`: plausible frame rates.
"""

from __future__ import annotations

import gzip
import os
import re
import zlib
from collections.abc import Sequence
from typing import Any

import numpy as np
import orjson

from tobitkf.io.errors import OptionError, ReadError
from tobitkf.skeleton.sequence import KNOWN_UNITS

GZIP_MAGIC = b"\x1f\x8b"

#: most bytes a reader takes in after decompression (text, gunzipped text, NPZ arrays)
MAX_INPUT_BYTES = 256 * 2**20
#: a reader may allocate max(MIN_OUTPUT_BYTES, OUTPUT_BYTES_PER_INPUT_BYTE x input bytes)
MIN_OUTPUT_BYTES = 64 * 2**20
OUTPUT_BYTES_PER_INPUT_BYTE = 32
#: plausible coordinates: |x| <= MAX_ABS_POSITION_M metres (after unit conversion)
MAX_ABS_POSITION_M = 1e4
#: plausible coordinates in pixels or unknown units (no length to convert to metres)
MAX_ABS_POSITION_OTHER = 1e8
#: plausible frame rates (Hz), bounds included
MIN_RATE_HZ = 1e-3
MAX_RATE_HZ = 1e5
#: what a reader does with an implausible position: raise, or mark the sample missing
IMPLAUSIBLE = ("error", "missing")

_NUM = r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
#: the one accepted number syntax: optional sign, ASCII digits, optional fraction and exponent
NUMBER = re.compile(_NUM)
INTEGER = re.compile(r"[+-]?[0-9]+")
_CHUNK = 2**20


def size_text(n: int) -> str:
    """``n`` bytes in readable units (``"256 MiB"``)."""
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n} B"


def _too_large(path: str | os.PathLike[str], what: str) -> ReadError:
    return ReadError(
        path,
        None,
        f"{what} is larger than the limit of {size_text(MAX_INPUT_BYTES)} "
        "(tobitkf.io._text.MAX_INPUT_BYTES)",
    )


def read_bytes(path: str | os.PathLike[str]) -> bytes:
    """Whole file content, gunzipped (in a stream) when it starts with the gzip magic
    number; refused past :data:`MAX_INPUT_BYTES`."""
    limit = MAX_INPUT_BYTES
    try:
        with open(path, "rb") as fh:
            if fh.read(2) != GZIP_MAGIC:
                if os.fstat(fh.fileno()).st_size > limit:
                    raise _too_large(path, "the file")
                fh.seek(0)
                data = fh.read(limit + 1)
                if len(data) > limit:
                    raise _too_large(path, "the file")
                return data
            fh.seek(0)
            chunks: list[bytes] = []
            total = 0
            with gzip.GzipFile(fileobj=fh) as gz:
                while chunk := gz.read(min(_CHUNK, limit + 1 - total)):
                    total += len(chunk)
                    if total > limit:
                        raise _too_large(path, "the decompressed content")
                    chunks.append(chunk)
    except IsADirectoryError:
        raise ReadError(path, None, "expected a file, found a directory") from None
    except _GZIP_ERRORS as exc:
        raise _gzip_error(path, exc) from None
    return b"".join(chunks)


_GZIP_ERRORS = (EOFError, zlib.error, gzip.BadGzipFile)


def _gzip_error(path: str | os.PathLike[str], exc: BaseException) -> ReadError:
    return ReadError(path, None, f"corrupt or truncated gzip data ({exc})")


def decode(path: str | os.PathLike[str], data: bytes) -> str:
    """UTF-8 text (a BOM is dropped); bad bytes are reported with their line number."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise ReadError(
            path, line, f"expected UTF-8 text, found byte 0x{data[exc.start]:02x} (binary file?)"
        ) from None


def read_lines(path: str | os.PathLike[str]) -> list[str]:
    """Lines of a text file without their line endings (``\\r\\n`` or ``\\n``).

    Index ``i`` of the result is line ``i + 1`` of the file.
    """
    text = decode(path, read_bytes(path))
    lines = text.split("\n")
    return [ln[:-1] if ln.endswith("\r") else ln for ln in lines]


def read_head(path: str | os.PathLike[str], size: int = 65536, *, check_gzip: bool = False) -> str:
    """The first ``size`` bytes (decompressed for gzip), decoded leniently; for sniffing.

    An unreadable file gives ``""``; so does gzip data that cannot be decompressed that
    far, unless ``check_gzip``: then the ReadError the readers raise for it
    ("corrupt or truncated gzip data").
    """
    try:
        with open(path, "rb") as fh:
            head = fh.read(size)
        if head[:2] == GZIP_MAGIC:
            with gzip.open(path, "rb") as gz:
                head = gz.read(size)
    except _GZIP_ERRORS as exc:  # before OSError: gzip.BadGzipFile is one
        if check_gzip:
            raise _gzip_error(path, exc) from None
        return ""
    except OSError:
        return ""
    return head.decode("utf-8", errors="replace")


def check_output_size(
    path: str | os.PathLike[str], nbytes: int, input_bytes: int, what: str
) -> None:
    """Refuse a file whose declared counts would make the reader allocate more than
    ``max(MIN_OUTPUT_BYTES, OUTPUT_BYTES_PER_INPUT_BYTE * input_bytes)``.

    ``nbytes`` is the reader's estimate for ``what`` (e.g. "20000 frames x 100 bodies").
    """
    limit = max(MIN_OUTPUT_BYTES, OUTPUT_BYTES_PER_INPUT_BYTE * input_bytes)
    if nbytes > limit:
        raise ReadError(
            path,
            None,
            f"{what} would need about {size_text(nbytes)} of memory for a file of "
            f"{size_text(input_bytes)}; the limit is {size_text(limit)} "
            f"(max of {size_text(MIN_OUTPUT_BYTES)} and {OUTPUT_BYTES_PER_INPUT_BYTE} x the "
            "file size)",
        )


def text_size(lines: Sequence[str]) -> int:
    """Characters of the text that ``lines`` came from (line endings counted as one)."""
    return sum(map(len, lines)) + len(lines)


def _shown(text: str) -> str:
    return text if len(text) <= 40 else text[:37] + "..."


def is_number(text: str) -> bool:
    """True when ``text`` (surrounding spaces and tabs allowed) is a plain decimal number."""
    return NUMBER.fullmatch(text.strip(" \t")) is not None


def parse_number(path: str | os.PathLike[str], line: int | None, text: str, what: str) -> float:
    """A finite float written as a plain ASCII decimal number (:data:`NUMBER`)."""
    s = text.strip(" \t")
    if NUMBER.fullmatch(s) is None:
        raise ReadError(path, line, f"expected {what} (a decimal number), found {_shown(text)!r}")
    value = float(s)
    if not np.isfinite(value):
        raise ReadError(path, line, f"expected a finite number for {what}, found {_shown(s)!r}")
    return value


def parse_int(
    path: str | os.PathLike[str],
    line: int | None,
    text: str,
    what: str,
    minimum: int | None = None,
) -> int:
    """An integer written with ASCII digits (optional sign), at least ``minimum``."""
    s = text.strip(" \t")
    if INTEGER.fullmatch(s) is None:
        raise ReadError(path, line, f"expected {what} (an integer), found {_shown(text)!r}")
    value = int(s)
    if minimum is not None and value < minimum:
        raise ReadError(path, line, f"expected {what} >= {minimum}, found {value}")
    return value


def check_rate(
    path: str | os.PathLike[str], line: int | None, fps: float, what: str, shown: str
) -> float:
    """``fps`` when it is a plausible rate (:data:`MIN_RATE_HZ` to :data:`MAX_RATE_HZ`),
    else a :class:`ReadError` showing ``what`` as written (``shown``)."""
    if not (np.isfinite(fps) and MIN_RATE_HZ <= fps <= MAX_RATE_HZ):
        raise ReadError(
            path,
            line,
            f"implausible {what} {_shown(shown)!r}: expected a frame rate from {MIN_RATE_HZ:g} "
            f"to {MAX_RATE_HZ:g} Hz",
        )
    return float(fps)


def check_implausible_option(implausible: str) -> None:
    """Validate a reader's ``implausible`` option (:data:`IMPLAUSIBLE`)."""
    if implausible not in IMPLAUSIBLE:
        raise OptionError(f"implausible must be one of {IMPLAUSIBLE}, found {implausible!r}")


def option_rate(path: str | os.PathLike[str], fps: Any) -> float | None:
    """A reader's ``fps=`` option: None, or a plausible rate (:func:`check_rate`); not a
    number is an :class:`OptionError`."""
    if fps is None:
        return None
    if isinstance(fps, bool) or not isinstance(fps, (int, float, np.number)):
        raise OptionError(f"fps must be a number, found {fps!r}")
    return check_rate(path, None, float(fps), "fps", repr(fps))


def check_positions(
    path: str | os.PathLike[str],
    positions: np.ndarray,
    line_numbers: Sequence[int] | None,
    implausible: str = "error",
    *,
    names: Sequence[str] | None = None,
    state: np.ndarray | None = None,
    units: str | None = "m",
) -> None:
    """Apply the plausibility bound :data:`MAX_ABS_POSITION_M` to positions (T, J, D) in
    ``units`` (the bound converted to them; :data:`MAX_ABS_POSITION_OTHER` for pixels and
    unknown units).

    With ``implausible="error"`` the first coordinate out of bounds raises a
    :class:`ReadError` naming the line of its frame (``line_numbers[t]``, if known), the
    joint and the value; with ``"missing"`` such joints become NaN (and NOT_TRACKED = 0
    in ``state``), in place.
    """
    check_implausible_option(implausible)
    bound = _bound(units)
    unit_text = "(unknown units)" if units is None else units
    bad = _beyond(positions, units)
    if not bad.any():
        return
    joint_bad = bad.any(axis=-1)
    if implausible == "missing":
        positions[joint_bad] = np.nan
        if state is not None:
            state[joint_bad] = 0
        return
    t, j, a = (int(i) for i in np.argwhere(bad)[0])
    joint = names[j] if names is not None else f"{j + 1}"
    raise ReadError(
        path,
        None if line_numbers is None else line_numbers[t],
        f"implausible position {float(positions[t, j, a])!r} {unit_text} ({'xyz'[a]} of "
        f"joint {joint}, frame {t}, counted from 0): expected |value| <= {bound:g} "
        f"{unit_text}; tobitkf.load(path, implausible='missing') (tobitkf smooth "
        "--implausible missing) reads such samples as missing",
    )


def _bound(units: str | None) -> float:
    per_unit = None if units is None else KNOWN_UNITS.get(units)
    return MAX_ABS_POSITION_OTHER if per_unit is None else MAX_ABS_POSITION_M / per_unit


def _beyond(points: np.ndarray, units: str | None) -> np.ndarray:
    """The coordinates beyond the plausibility bound in ``units`` (inf too; NaN not)."""
    with np.errstate(invalid="ignore"):
        return ~(np.abs(points) <= _bound(units)) & ~np.isnan(points)


def plausible_only(points: np.ndarray, units: str | None, implausible: str) -> np.ndarray:
    """``points`` (..., D) as a reader with ``implausible="missing"`` will read them: a
    copy with NaN rows where a coordinate is beyond the bound of :func:`check_positions`
    (``points`` itself otherwise). For the association of unlabelled people, which
    must not see such a coordinate as a second person."""
    if implausible != "missing":
        return points
    bad = _beyond(points, units).any(axis=-1)
    if not bad.any():
        return points
    out = np.array(points, dtype=float)
    out[bad] = np.nan
    return out


def nonempty(lines: Sequence[str], start: int = 0) -> tuple[list[str], list[int]]:
    """Non-blank lines from index ``start`` and their 1-based line numbers."""
    rows: list[str] = []
    numbers: list[int] = []
    for i in range(start, len(lines)):
        ln = lines[i]
        if ln.strip():
            rows.append(ln)
            numbers.append(i + 1)
    return rows, numbers


_ROW_PATTERNS: dict[tuple[str | None, bool, bool], re.Pattern[str]] = {}


def _row_pattern(sep: str | None, allow_empty: bool, allow_nan: bool) -> re.Pattern[str]:
    """A compiled pattern matching a whole row of :data:`NUMBER` fields (cached)."""
    key = (sep, allow_empty, allow_nan)
    if key not in _ROW_PATTERNS:
        value = f"(?:{_NUM}|[+-]?[nN][aA][nN])" if allow_nan else _NUM
        if sep is None:
            row = f"[ \\t]*{value}(?:[ \\t]+{value})*[ \\t]*"
        else:
            blank = "[ ]" if sep == "\t" else "[ \\t]"
            field = f"{blank}*(?:{value}){'?' if allow_empty else ''}{blank}*"
            row = f"{field}(?:{re.escape(sep)}{field})*"
        _ROW_PATTERNS[key] = re.compile(row)
    return _ROW_PATTERNS[key]


def parse_rows(
    path: str | os.PathLike[str],
    rows: Sequence[str],
    line_numbers: Sequence[int],
    *,
    sep: str | None,
    ncols: int | None = None,
    what: str = "values",
    allow_empty: bool = False,
    allow_nan: bool = False,
) -> np.ndarray:
    """Parse rows of numbers into a float array of shape (N, ncols).

    Every field must be a plain decimal number (:data:`NUMBER`) with a finite value.

    Parameters
    ----------
    rows : sequence of str
        One frame per row (already stripped of trailing separators if the format has them).
    line_numbers : sequence of int
        1-based file line number of each row (for error messages).
    sep : str or None
        Field separator; ``None`` splits on runs of spaces and tabs.
    ncols : int, optional
        Required number of values per row; by default the first row's count.
    what : str
        Description of a row's expected content, used in messages.
    allow_empty : bool
        Empty fields become NaN (otherwise they are an error).
    allow_nan : bool
        A ``nan`` field (any case) becomes NaN (otherwise it is an error).
    """
    if not rows:
        raise ReadError(path, None, f"no data rows: expected {what}")
    if sep is None:
        tokens = [r.split() for r in rows]
    else:
        tokens = [r.split(sep) for r in rows]
    counts = np.fromiter((len(t) for t in tokens), dtype=np.int64, count=len(tokens))
    expected = int(counts[0]) if ncols is None else int(ncols)
    bad = np.flatnonzero(counts != expected)
    if bad.size:
        k = int(bad[0])
        if ncols is None:
            msg = (
                f"inconsistent frame length: expected {expected} values (as on line "
                f"{line_numbers[0]}), found {int(counts[k])}"
            )
        else:
            msg = f"expected {expected} values ({what}), found {int(counts[k])}"
        raise ReadError(path, line_numbers[k], msg)
    # Only the characters of NUMBER (and nan) pass; on those, numpy's and Python's float
    # parsers accept exactly the NUMBER grammar, so the (slower) row pattern only has to
    # find the culprit when something fails.
    if not _plain_characters(rows, sep, allow_nan):
        _raise_first_bad_row(path, rows, tokens, line_numbers, sep, allow_empty, allow_nan)
    arr = None
    if not allow_empty:  # fast path: numpy's C parser on the whole block
        try:
            fast = np.loadtxt(rows, dtype=float, delimiter=sep, comments=None, ndmin=2)
        except ValueError:
            fast = None
        if fast is not None and fast.shape == (len(rows), expected):
            arr = fast.ravel()
    if arr is None:
        flat = [t for toks in tokens for t in toks]
        if allow_empty:
            flat = [t if t.strip() else "nan" for t in flat]
        try:
            arr = np.array(flat, dtype=float)
        except ValueError:
            _raise_first_bad_row(path, rows, tokens, line_numbers, sep, allow_empty, allow_nan)
    if np.isinf(arr).any():
        k = int(np.flatnonzero(np.isinf(arr))[0])
        row, col = divmod(k, expected)
        raise ReadError(
            path,
            line_numbers[row],
            f"expected a finite number in field {col + 1}, found {tokens[row][col].strip()!r}",
        )
    return arr.reshape(len(rows), expected)


_NUMBER_CHARACTERS = b"0123456789+-.eE \t"


def _plain_characters(rows: Sequence[str], sep: str | None, allow_nan: bool) -> bool:
    """True when ``rows`` hold only the characters of numbers, blanks and ``sep``."""
    try:
        data = "".join(rows).encode("ascii")
    except UnicodeEncodeError:
        return False
    allowed = _NUMBER_CHARACTERS + (sep or "").encode("ascii") + (b"nNaA" if allow_nan else b"")
    return not data.translate(None, allowed)


def _raise_first_bad_row(
    path: str | os.PathLike[str],
    rows: Sequence[str],
    tokens: Sequence[Sequence[str]],
    line_numbers: Sequence[int],
    sep: str | None,
    allow_empty: bool,
    allow_nan: bool,
) -> None:
    match = _row_pattern(sep, allow_empty, allow_nan).fullmatch
    for k, row in enumerate(rows):
        if match(row) is None:
            _raise_bad_field(path, tokens[k], line_numbers[k], allow_empty, allow_nan)
    raise ReadError(path, None, "could not parse the numeric data")  # pragma: no cover


def _raise_bad_field(
    path: str | os.PathLike[str],
    tokens: Sequence[str],
    line: int,
    allow_empty: bool,
    allow_nan: bool,
) -> None:
    """Raise the :class:`ReadError` for the first field of a row that is not a number."""
    for j, t in enumerate(tokens):
        s = t.strip(" \t")
        if (allow_empty and not s) or (allow_nan and s.lstrip("+-").lower() == "nan"):
            continue
        if NUMBER.fullmatch(s) is None:
            raise ReadError(
                path,
                line,
                f"expected a finite number in field {j + 1}, found {_shown(t)!r} (plain "
                f"ASCII decimal numbers{', or nan,' if allow_nan else ''} only)",
            )
    bad = next((c for c in "".join(tokens) if not (c.isascii() and c.isprintable())), None)
    found = f"the character U+{ord(bad):04X}" if bad is not None else "a malformed separator"
    raise ReadError(path, line, f"expected decimal numbers and separators, found {found}")


def check_times(
    path: str | os.PathLike[str],
    times: np.ndarray,
    line_numbers: Sequence[int],
    what: str = "time value",
) -> None:
    """Raise :class:`ReadError` at the first row whose time is missing or goes backwards.

    ``times`` (N,) seconds as parsed (NaN for an empty field); ``line_numbers`` the file
    line of each row. Equal consecutive times are allowed (duplicated stamps).
    """
    missing = np.flatnonzero(~np.isfinite(times))
    if missing.size:
        k = int(missing[0])
        raise ReadError(path, line_numbers[k], f"expected a {what}, found an empty field")
    back = np.flatnonzero(np.diff(times) < 0)
    if back.size:
        k = int(back[0]) + 1
        raise ReadError(
            path,
            line_numbers[k],
            f"expected non-decreasing {what}s, found {float(times[k])!r} after "
            f"{float(times[k - 1])!r}",
        )


def zeros_to_nan(positions: np.ndarray, state: np.ndarray | None = None) -> np.ndarray:
    """Mark joints reported at exactly (0, 0, 0) as missing, in place.

    Depth sensors report an untracked joint as the origin; it becomes NaN (and
    ``NOT_TRACKED`` = 0 in ``state`` when given) instead of a jump to the origin.

    Returns
    -------
    zero : ndarray of bool, shape positions.shape[:-1]
    """
    zero = np.all(positions == 0.0, axis=-1)
    if zero.any():
        positions[zero] = np.nan
        if state is not None:
            state[zero] = 0
    return zero


def missing_state(positions: np.ndarray) -> np.ndarray | None:
    """Tracking state (T, J) for a format without one: NOT_TRACKED (0) where a joint is
    missing, TRACKED (2) elsewhere; ``None`` when nothing is missing."""
    missing = np.isnan(positions).any(axis=-1)
    if not missing.any():
        return None
    return np.where(missing, 0, 2).astype(np.int8)


def fmt_float(x: float) -> str:
    """Shortest text that reads back to exactly ``x`` (``nan`` for NaN)."""
    return repr(float(x))


def fmt_floats(a: np.ndarray, nan: str = "nan") -> list[str]:
    """Shortest text that reads back to exactly each value of ``a`` (flattened in C
    order); ``nan`` for NaN, ``inf`` / ``-inf`` for infinities.

    The digits are orjson's (Ryu: the shortest digits that round-trip), about 30 times
    faster than ``repr`` on full-precision doubles, which made writing a smoothed CSV
    cost more than smoothing it. The text can differ from ``repr`` in form, not in
    value: ``0.00001`` for ``1e-05``, ``1e-7`` for ``1e-07``.
    """
    flat = np.ascontiguousarray(a, dtype=np.float64).reshape(-1)
    if flat.size == 0:
        return []
    text = orjson.dumps(flat, option=orjson.OPT_SERIALIZE_NUMPY).decode("ascii")
    out = text[1:-1].split(",")
    bad = np.flatnonzero(~np.isfinite(flat))  # orjson writes them as null
    for i, v in zip(bad.tolist(), flat[bad].tolist(), strict=True):
        out[i] = nan if v != v else repr(v)
    return out
