"""Shared fixtures: where the real recordings live, and how a missing file is treated;
the project's tools (``tools/*.py``, not a package) as modules."""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path
from types import ModuleType

import pytest

DATA_DIR = Path(
    os.environ.get("TOBITKF_DATA", Path(__file__).resolve().parents[1] / ".." / "shared" / "data")
).resolve()


def data_file(relative: str) -> Path:
    """Path of a file under ``../shared/data``.

    Skips the test when the file is missing, unless ``TOBITKF_REQUIRE_DATA=1`` (set by
    ``.ci/run``), in which case a missing file fails the test.
    """
    path = DATA_DIR / relative
    if not path.exists():
        msg = f"real-data file not found: {path}"
        if os.environ.get("TOBITKF_REQUIRE_DATA") == "1":
            pytest.fail(msg + " (TOBITKF_REQUIRE_DATA=1)")
        pytest.skip(msg)
    return path


def tool_module(name: str) -> ModuleType:
    """``tools/<name>.py`` imported once as the module ``name`` (registered in
    ``sys.modules`` first: dataclasses look their module up there)."""
    if name not in sys.modules:
        path = Path(__file__).resolve().parents[1] / "tools" / f"{name}.py"
        spec = importlib.util.spec_from_file_location(name, path)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    return sys.modules[name]


@pytest.fixture
def shared_data():
    """Fixture form of :func:`data_file`."""
    return data_file
