"""A noise fit read back from a file, for ``robust``'s ``noise=`` (``tobitkf smooth
--noise-from``).

``robust`` fits its process and measurement noise to each recording and body region,
and records the fit in every output's provenance (``params["noise_fit"]``): in a CSV's
JSON sidecar, in an NPZ's metadata, in any format that keeps provenance. Giving that fit
back (``tk.smooth(other, noise=fit)``) smooths another recording, a short clip of the
same sensor and person say, with the noise of the long one, exactly as the long one was
smoothed (docs/robust.md, "A fit given").

:func:`read_noise_fit` takes any of:

- a tobitkf output that keeps provenance (CSV with its sidecar, NPZ, ...), or the CSV's
  sidecar ``.json`` itself;
- a JSON file holding the fit: ``{"hands": {"speed_sd": ..., ...}, ...}`` (the form of
  ``metadata["diagnostics"]["noise_fit"]``), or an object with it under ``noise_fit``.

It only reads: the values are checked where they are used (``robust``'s ``noise``).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from tobitkf.io.errors import ReadError
from tobitkf.io.generic_csv import SIDECAR_FORMAT
from tobitkf.io.registry import load

__all__ = ["read_noise_fit"]

#: a fit is small; a JSON file larger than this is not one
_MAX_JSON_BYTES = 16 * 2**20


def read_noise_fit(path: str | os.PathLike[str], body: int | None = None) -> dict[str, Any]:
    """The noise fit recorded in ``path`` (module doc), as ``robust``'s ``noise=`` takes it.

    Parameters
    ----------
    path : a tobitkf output (any format that keeps provenance), its CSV sidecar, or a
        JSON file of the fit.
    body : which body's fit, when the file holds several bodies smoothed with
        different fits (index in the file's order). None: the file's one fit, an error
        when its bodies differ.

    Raises
    ------
    ValueError
        naming the file, when it holds no fit: not a tobitkf output, smoothed by another
        method or with ``noise="fixed"``, or its bodies' fits differ and ``body`` is None.
    FileNotFoundError
        when there is no such file.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    doc = _json_document(p)
    if doc is not None and doc.get("format") == SIDECAR_FORMAT:
        # a CSV's sidecar: the provenance its bodies share, else each body's own
        shared = doc.get("provenance")
        bodies = doc.get("bodies") if isinstance(doc.get("bodies"), list) else []
        provs = [shared] if shared else [e.get("provenance") for e in bodies if isinstance(e, dict)]
    elif doc is not None and _looks_like_fit(doc.get("noise_fit", doc)):
        return dict(doc.get("noise_fit", doc))
    else:  # a recording: the provenance of its bodies
        try:
            provs = [s.metadata.get("provenance") for s in load(p)]
        except ReadError as exc:
            raise ValueError(
                f"{p}: neither a noise fit (an object of body regions, e.g. "
                '{"hands": {"speed_sd": ..., "noise_sd": ..., "error_sd": ..., '
                '"error_tau": ..., "fitted": true}, ...}, or one under "noise_fit") nor a '
                "tobitkf output that records one (a CSV with its sidecar, an NPZ, ...)"
            ) from exc
    return _pick(p, [_fit_of(p, prov) for prov in provs], body)


def _json_document(p: Path) -> dict[str, Any] | None:
    """The file's JSON object when it is a ``.json`` file of one, else None (another format,
    which :func:`tobitkf.io.load` reads)."""
    if p.suffix.lower() != ".json" or p.stat().st_size > _MAX_JSON_BYTES:
        return None
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        return None  # not JSON text: perhaps a keypoint format's
    return doc if isinstance(doc, dict) else None


def _looks_like_fit(fit: Any) -> bool:
    """A mapping of regions, each a mapping with a ``speed_sd`` (the checks are robust's)."""
    return (
        isinstance(fit, Mapping)
        and bool(fit)
        and all(isinstance(v, Mapping) and "speed_sd" in v for v in fit.values())
    )


def _fit_of(p: Path, prov: Any) -> dict[str, Any]:
    """The fit one body's provenance records, or the reason it holds none."""
    if not isinstance(prov, Mapping):
        raise ValueError(f"{p}: not a tobitkf output (no provenance): it holds no noise fit")
    params = prov.get("params") if isinstance(prov.get("params"), Mapping) else {}
    fit = params.get("noise_fit")
    if _looks_like_fit(fit):
        return dict(fit)
    method = prov.get("method")
    if method != "robust":
        raise ValueError(
            f"{p}: smoothed with {method!r}, which fits no noise (robust does, with "
            "noise=fit, its default)"
        )
    raise ValueError(
        f"{p}: smoothed by robust with noise={params.get('noise', '?')!r}, or by a tobitkf "
        "before fits were recorded: it holds no noise fit (smooth it again with noise=fit)"
    )


def _pick(p: Path, fits: list[dict[str, Any]], body: int | None) -> dict[str, Any]:
    """One fit of the file's bodies' (``body`` module doc)."""
    if not fits:
        raise ValueError(f"{p}: no body in the file, so no noise fit")
    if body is not None:
        if not 0 <= body < len(fits):
            raise ValueError(f"{p}: body {body} asked for, the file has {len(fits)}")
        return fits[body]
    texts = {json.dumps(f, sort_keys=True, default=str) for f in fits}
    if len(texts) > 1:
        raise ValueError(
            f"{p}: its {len(fits)} bodies were smoothed with different noise fits; "
            "name one (read_noise_fit(path, body=k))"
        )
    return fits[0]
