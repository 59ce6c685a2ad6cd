"""numba's ``njit`` for the kernels, with a cache wherever the installation allows one.

numba caches a compiled kernel beside its source (``__pycache__``) or, when that folder
is read-only, in the user's cache folder (``~/.cache/numba``). An installation in a
read-only ``site-packages`` run by a user without a writable home (a container's
``nobody``, a locked-down server) has neither, and numba then refused every
``cache=True`` kernel at import: ``RuntimeError: cannot cache function ...: no locator
available``. Here that case is found once, on a probe function beside the kernels, and
the cache goes to a folder of the user's in the system's temporary folder instead
(``NUMBA_CACHE_DIR``, when set, is numba's own choice and is left alone); if even that
cannot be written, the kernels compile in every process, uncached. Either is said once
in a :class:`UserWarning` naming ``NUMBA_CACHE_DIR``.
"""

from __future__ import annotations

import os
import tempfile
import warnings
from typing import Any

from numba import config
from numba import njit as _njit

__all__ = ["CACHE_OK", "njit"]


def _probe_function() -> int:  # pragma: no cover - never called, only decorated
    return 0


def _can_cache() -> bool:
    """True when numba finds a place to cache a kernel of this folder (decorating
    compiles nothing: it only looks for the place)."""
    try:
        _njit(cache=True)(_probe_function)
    except RuntimeError as exc:
        if "no locator available" not in str(exc):
            raise
        return False
    return True


def _set_up() -> bool:
    if _can_cache():
        return True
    user = os.getuid() if hasattr(os, "getuid") else os.environ.get("USERNAME", "user")
    folder = os.path.join(tempfile.gettempdir(), f"tobitkf-numba-{user}")
    try:
        os.makedirs(folder, mode=0o700, exist_ok=True)
    except OSError:
        pass
    if os.path.isdir(folder) and os.access(folder, os.W_OK):
        config.CACHE_DIR = folder
        if _can_cache():
            warnings.warn(
                "numba cannot cache tobitkf's kernels beside it (a read-only installation) "
                f"nor in the user's cache folder: they are cached in {folder}; set "
                "NUMBA_CACHE_DIR to a writable folder to choose (and run tobitkf warmup "
                "with it to fill it ahead)",
                UserWarning,
                stacklevel=2,
            )
            return True
        config.CACHE_DIR = ""
    warnings.warn(
        "numba cannot cache tobitkf's kernels anywhere (a read-only installation, no "
        "writable cache folder): they compile again in every process; set "
        "NUMBA_CACHE_DIR to a writable folder",
        UserWarning,
        stacklevel=2,
    )
    return False


#: numba can cache the kernels (beside them, in the user's cache or the fallback folder)
CACHE_OK = _set_up()


def njit(*args: Any, **kwargs: Any) -> Any:
    """numba's ``njit``; ``cache=True`` is dropped where nothing can be cached."""
    if not CACHE_OK:
        kwargs.pop("cache", None)
    return _njit(*args, **kwargs)
