"""Shared fixtures: where the real recordings live, and how a missing file is treated."""

from __future__ import annotations

import os
from pathlib import Path

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


@pytest.fixture
def shared_data():
    """Fixture form of :func:`data_file`."""
    return data_file
