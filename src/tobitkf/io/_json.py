"""Shared helpers of the JSON readers (OpenPose, MediaPipe, Azure Kinect): bounded reading,
strict parsing and typed access, every failure a :class:`ReadError` naming the file.

JSON has no line numbers worth reporting once parsed, so errors name the file and the
place in the document (``frames[3].bodies[0].joint_positions``).

Also the provenance as one JSON text (:func:`provenance_text`, :func:`provenance_from_text`)
for the binary formats that keep it in a text field of their own (a C3D parameter, a
netCDF or HDF5 attribute).
"""

from __future__ import annotations

import copy
import json
import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from tobitkf.core.jsonable import to_jsonable
from tobitkf.io._text import decode, read_bytes
from tobitkf.io.errors import ReadError
from tobitkf.skeleton.sequence import SkeletonSequence

__all__ = [
    "as_list",
    "as_object",
    "attach_provenance",
    "load_json",
    "number_array",
    "provenance_from_text",
    "provenance_text",
]


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


def provenance_text(sequences: Sequence[SkeletonSequence]) -> str | None:
    """The bodies' ``metadata["provenance"]`` as one line of ASCII JSON: the provenance
    when every body has the same one, else a list with each body's (``null`` where it has
    none); None when no body has one."""
    provs = [s.metadata.get("provenance") for s in sequences]
    if all(p is None for p in provs):
        return None
    texts = [json.dumps(to_jsonable(p), separators=(",", ":"), allow_nan=False) for p in provs]
    if len(set(texts)) == 1:
        return texts[0]
    return "[" + ",".join(texts) + "]"


def provenance_from_text(
    path: str | os.PathLike[str], text: Any, n_bodies: int, where: str
) -> list[dict[str, Any] | None]:
    """Each of ``n_bodies`` bodies' provenance from :func:`provenance_text`'s JSON (str or
    bytes) found in ``where`` of the file; a ReadError naming ``where`` when it is not
    that JSON."""
    if isinstance(text, bytes):
        text = text.decode("utf-8", errors="replace")
    try:
        doc = json.loads(str(text), parse_constant=_no_constant)
    except (ValueError, RecursionError) as exc:
        msg = exc.msg if isinstance(exc, json.JSONDecodeError) else type(exc).__name__
        raise ReadError(path, None, f"{where} is not the provenance's JSON ({msg})") from None
    if isinstance(doc, dict):
        return [copy.deepcopy(doc) for _ in range(n_bodies)]
    if (
        isinstance(doc, list)
        and len(doc) == n_bodies
        and all(p is None or isinstance(p, dict) for p in doc)
    ):
        return doc
    raise ReadError(
        path, None,
        f"{where} must hold a JSON object (the provenance) or a list of {n_bodies} "
        f"(one per body), found {_kind(doc)}"
        + (f" of {len(doc)}" if isinstance(doc, list) else ""),
    )  # fmt: skip


def attach_provenance(
    path: str | os.PathLike[str], sequences: Sequence[SkeletonSequence], text: Any, where: str
) -> None:
    """Put the provenance that :func:`provenance_text` wrote in ``where`` of the file into
    each body's ``metadata["provenance"]`` (nothing when ``text`` is None)."""
    if text is None:
        return
    for s, prov in zip(sequences, provenance_from_text(path, text, len(sequences), where),
                       strict=True):  # fmt: skip
        if prov is not None:
            s.metadata["provenance"] = prov
