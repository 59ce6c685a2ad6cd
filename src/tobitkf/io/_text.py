"""Shared helpers of the text readers: reading (gzip-aware), decoding, numeric blocks.

Every failure becomes a :class:`~tobitkf.io.errors.ReadError` naming the file and line.
"""

from __future__ import annotations

import gzip
import os
import zlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tobitkf.io.errors import ReadError

GZIP_MAGIC = b"\x1f\x8b"


def read_bytes(path: str | os.PathLike[str]) -> bytes:
    """Whole file content, gunzipped when it starts with the gzip magic number."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except IsADirectoryError:
        raise ReadError(path, None, "expected a file, found a directory") from None
    if data[:2] == GZIP_MAGIC:
        try:
            data = gzip.decompress(data)
        except (OSError, EOFError, zlib.error) as exc:
            raise ReadError(path, None, f"corrupt or truncated gzip data ({exc})") from None
    return data


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


def read_head(path: str | os.PathLike[str], size: int = 65536) -> str:
    """The first ``size`` bytes (decompressed for gzip), decoded leniently; for sniffing."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(size)
        if head[:2] == GZIP_MAGIC:
            with gzip.open(path, "rb") as gz:
                head = gz.read(size)
    except (OSError, EOFError, zlib.error):
        return ""
    return head.decode("utf-8", errors="replace")


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


def parse_rows(
    path: str | os.PathLike[str],
    rows: Sequence[str],
    line_numbers: Sequence[int],
    *,
    sep: str | None,
    ncols: int | None = None,
    what: str = "values",
    allow_empty: bool = False,
    allow_inf: bool = False,
) -> np.ndarray:
    """Parse rows of numbers into a float array of shape (N, ncols).

    Parameters
    ----------
    rows : sequence of str
        One frame per row (already stripped of trailing separators if the format has them).
    line_numbers : sequence of int
        1-based file line number of each row (for error messages).
    sep : str or None
        Field separator; ``None`` splits on runs of whitespace.
    ncols : int, optional
        Required number of values per row; by default the first row's count.
    what : str
        Description of a row's expected content, used in messages.
    allow_empty : bool
        Empty fields become NaN (otherwise they are an error).
    allow_inf : bool
        Accept ``inf`` values (otherwise an error).
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
    arr = None
    if not allow_empty:  # fast path: numpy's C parser on the whole block
        try:
            fast = np.loadtxt(rows, dtype=float, delimiter=sep, comments=None, ndmin=2)
        except (ValueError, OverflowError, TypeError):
            fast = None
        if fast is not None and fast.shape == (len(rows), expected):
            arr = fast.ravel()
    if arr is None:
        flat = [t for toks in tokens for t in toks]
        if allow_empty:
            flat = [t if t.strip() else "nan" for t in flat]
        try:
            arr = np.array(flat, dtype=float)
        except (ValueError, OverflowError):
            _locate_bad_token(path, tokens, line_numbers, allow_empty)
            raise  # unreachable: _locate_bad_token always raises
    if not allow_inf and np.isinf(arr).any():
        k = int(np.flatnonzero(np.isinf(arr))[0])
        row, col = divmod(k, expected)
        raise ReadError(
            path,
            line_numbers[row],
            f"expected a finite number in field {col + 1}, found {tokens[row][col].strip()!r}",
        )
    return arr.reshape(len(rows), expected)


def _locate_bad_token(
    path: str | os.PathLike[str],
    tokens: Sequence[Sequence[str]],
    line_numbers: Sequence[int],
    allow_empty: bool,
) -> None:
    for toks, no in zip(tokens, line_numbers, strict=True):
        for j, t in enumerate(toks):
            if allow_empty and not t.strip():
                continue
            try:
                np.array([t], dtype=float)
            except (ValueError, OverflowError):
                shown = t if len(t) <= 40 else t[:37] + "..."
                raise ReadError(
                    path, no, f"expected a number in field {j + 1}, found {shown!r}"
                ) from None
    raise ReadError(path, None, "could not parse the numeric data")


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


def fmt_float(x: float) -> str:
    """Shortest text that reads back to exactly ``x`` (``nan`` for NaN)."""
    return repr(float(x))
