"""Shared helpers of the JSON readers (OpenPose, MediaPipe, Azure Kinect): bounded reading,
strict parsing and typed access, every failure a :class:`ReadError` naming the file.

JSON has no line numbers worth reporting once parsed, so errors name the file and the
place in the document (``frames[3].bodies[0].joint_positions``).
"""

from __future__ import annotations

import json
import os
from typing import Any

import numpy as np

from tobitkf.io._text import decode, read_bytes
from tobitkf.io.errors import ReadError

__all__ = ["as_list", "as_object", "load_json", "number_array"]


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number JSON allows")


def load_json(path: str | os.PathLike[str]) -> Any:
    """The parsed JSON document of ``path`` (bounded size, UTF-8; ``NaN`` and ``Infinity``
    refused)."""
    text = decode(path, read_bytes(path))
    if not text.strip():
        raise ReadError(path, None, "empty file: expected a JSON document")
    try:
        return json.loads(text, parse_constant=_no_constant)
    except json.JSONDecodeError as exc:
        raise ReadError(path, exc.lineno, f"invalid JSON ({exc.msg}, column {exc.colno})") from None
    except (ValueError, RecursionError) as exc:
        raise ReadError(path, None, f"invalid JSON ({type(exc).__name__}: {exc})") from None


def _kind(value: Any) -> str:
    return {dict: "an object", list: "an array", str: "a string", bool: "a boolean"}.get(
        type(value), "null" if value is None else "a number"
    )


def as_object(path: str | os.PathLike[str], value: Any, where: str) -> dict[str, Any]:
    """``value`` when it is a JSON object, else a ReadError naming ``where``."""
    if not isinstance(value, dict):
        raise ReadError(path, None, f"expected {where} to be an object, found {_kind(value)}")
    return value


def as_list(path: str | os.PathLike[str], value: Any, where: str) -> list[Any]:
    """``value`` when it is a JSON array, else a ReadError naming ``where``."""
    if not isinstance(value, list):
        raise ReadError(path, None, f"expected {where} to be an array, found {_kind(value)}")
    return value


def number_array(
    path: str | os.PathLike[str],
    value: Any,
    where: str,
    shape: tuple[int, ...] | None = None,
    *,
    allow_null: bool = False,
) -> np.ndarray:
    """A float array from a (nested) JSON array of numbers.

    ``shape`` (if given) must match exactly; booleans and strings are refused; ``null``
    becomes NaN when ``allow_null``.
    """
    as_list(path, value, where)
    allowed = (int, float, type(None)) if allow_null else (int, float)
    try:  # the leaves as an object array: one C pass over the nesting
        obj = np.array(value, dtype=object)
    except (ValueError, TypeError, RecursionError):
        obj = None
    kinds = set() if obj is None else set(map(type, obj.flat))
    if obj is None or not kinds <= set(allowed):
        leaf = None if obj is None else next(x for x in obj.flat if type(x) not in allowed)
        if obj is None or isinstance(leaf, list):
            raise ReadError(
                path,
                None,
                f"expected {where} to be a rectangular array of numbers, found "
                "nested arrays of unequal lengths",
            )
        raise ReadError(
            path, None, f"expected numbers in {where}, found {_kind(leaf)} ({str(leaf)[:40]!r})"
        )
    try:
        arr = obj.astype(float)
    except (OverflowError, ValueError, TypeError):
        raise ReadError(path, None, f"expected numbers in {where}, found a huge integer") from None
    if shape is not None and arr.shape != shape:
        raise ReadError(path, None, f"expected {where} of shape {shape}, found shape {arr.shape}")
    if np.isinf(arr).any():
        raise ReadError(path, None, f"expected finite numbers in {where}, found a huge number")
    return arr
