"""Command-line interface: parse arguments, call the library, print. Nothing else.

Every command's work lives in the library; this module only turns options into calls
and results into tables, JSON or files. ``click`` and ``rich`` come with the ``cli``
extra (``pip install 'tobitkf[cli]'``).
"""

from __future__ import annotations

import sys


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


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
