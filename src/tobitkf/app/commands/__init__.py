"""The click application behind ``tobitkf`` (imported only when click is installed).

One module per group of commands; each registers its commands on the group ``app`` of
:mod:`._common` when imported, here.
"""

from __future__ import annotations

from tobitkf.app.commands import about, demo, evaluate, paper, smooth  # noqa: F401
from tobitkf.app.commands._common import app, console, err_console

__all__ = ["app", "console", "err_console"]
