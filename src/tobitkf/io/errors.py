"""The error every reader raises on bad input."""

from __future__ import annotations

import os

__all__ = ["OptionError", "ReadError"]


class ReadError(ValueError):
    """A file could not be read: names the file, the line (if known) and what was wrong.

    Parameters
    ----------
    path : str or PathLike
        The file being read.
    line : int or None
        1-based line number where the problem was found (``None`` for whole-file problems
        or binary formats).
    message : str
        What was expected and what was found.
    """

    def __init__(self, path: str | os.PathLike[str], line: int | None, message: str) -> None:
        self.path = os.fspath(path)
        self.line = line
        self.reason = message
        where = f"{self.path}, line {line}" if line is not None else self.path
        super().__init__(f"{where}: {message}")

    def __reduce__(self):  # picklable across process pools
        return (type(self), (self.path, self.line, self.reason))


class OptionError(ValueError):
    """An invalid reader or writer option (a caller error, not a content error)."""
