"""The reader-fuzzing harness shared by test_io_fuzz.py and test_io_pose_fuzz.py.

A reader given arbitrary bytes or a soup of its format's tokens must return a list of
valid sequences (no infinite positions) or raise a ReadError that names the file; any
other exception is a bug.
"""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tobitkf.io import ReadError
from tobitkf.skeleton.sequence import SkeletonSequence

SETTINGS = settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


def check_reader(reader, path, full_path: bool = True) -> None:
    """``reader(path)`` gives valid sequences or a ReadError naming ``path`` (the whole
    path, or its file name when ``full_path`` is false)."""
    try:
        result = reader(path)
    except ReadError as exc:
        assert (str(path) if full_path else path.name) in str(exc)
        return
    assert isinstance(result, list)
    for s in result:
        assert isinstance(s, SkeletonSequence)
        assert not np.isinf(s.positions).any()


def reader_fuzz_tests(readers: dict, soup, full_path: bool = True):
    """The two fuzz tests of ``readers`` (name -> (reader, file extension)): arbitrary
    bytes, and text from the ``soup`` strategy. Assign them to ``test_*`` names."""
    import pytest

    @pytest.mark.parametrize("name", sorted(readers))
    @SETTINGS
    @given(data=st.binary(max_size=400))
    def test_arbitrary_bytes(tmp_path, name, data):
        reader, ext = readers[name]
        p = tmp_path / f"f{ext}"
        p.write_bytes(data)
        check_reader(reader, p, full_path)

    @pytest.mark.parametrize("name", sorted(readers))
    @SETTINGS
    @given(text=soup)
    def test_token_soup(tmp_path, name, text):
        reader, ext = readers[name]
        p = tmp_path / f"f{ext}"
        p.write_text(text, encoding="utf-8")
        check_reader(reader, p, full_path)

    return test_arbitrary_bytes, test_token_soup
