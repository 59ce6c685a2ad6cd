"""Command-line interface: parse arguments, call the library, print. Nothing else.

Every command's work lives in the library; this module only turns options into calls
and results into tables, JSON or files. ``click`` and ``rich`` come with the ``cli``
extra (``pip install 'tobitkf[cli]'``).
"""

from __future__ import annotations

import json
import sys
from typing import Any


def main(argv: list[str] | None = None) -> int:
    """Console-script entry point (``tobitkf``)."""
    try:
        import click  # noqa: F401
        import rich  # noqa: F401
    except ImportError:
        sys.stderr.write(
            "tobitkf: the command-line tool needs click and rich: pip install 'tobitkf[cli]'\n"
        )
        return 2
    from tobitkf.app.commands import app

    try:
        app.main(args=argv, prog_name="tobitkf", standalone_mode=True)
    except SystemExit as exc:  # click exits with the command's status
        code = exc.code
        return code if isinstance(code, int) else (0 if code is None else 1)
    return 0


def to_jsonable(obj: Any) -> Any:
    """Convert numpy arrays / scalars and dataclasses to plain JSON types."""
    import dataclasses

    import numpy as np

    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        if hasattr(obj, "to_dict"):
            return to_jsonable(obj.to_dict())
        return {f.name: to_jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def dumps(obj: Any) -> str:
    """JSON text of ``obj`` (numpy-aware, NaN written as null)."""
    return json.dumps(to_jsonable(obj), indent=2, allow_nan=False)


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
