"""Input discovery, output naming and parameter parsing behind `tobitkf smooth`."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tobitkf.app.batch import discover_inputs, parse_param, plan_jobs, strip_extension


def _touch(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("x")
    return path


def test_strip_extension_handles_compound_suffixes():
    assert strip_extension("m01_s01_e01_positions.txt.gz") == "m01_s01_e01_positions"
    assert strip_extension("a.b.csv") == "a.b"
    assert strip_extension("S001C001P001R001A001.skeleton") == "S001C001P001R001A001"


def test_discover_recurses_and_filters_only_folders(tmp_path):
    a = _touch(tmp_path / "in" / "a.csv")
    b = _touch(tmp_path / "in" / "sub" / "b.csv")
    _touch(tmp_path / "in" / "sub" / "c.txt")
    _touch(tmp_path / "in" / ".hidden.csv")
    explicit = _touch(tmp_path / "other" / "d.txt")
    found = discover_inputs([tmp_path / "in", explicit], "*.csv")
    assert [f for f, _ in found] == [a, b, explicit]
    # the same file named twice is processed once
    assert len(discover_inputs([a, a])) == 1
    with pytest.raises(FileNotFoundError, match="nope"):
        discover_inputs([tmp_path / "nope"])


def test_plan_keeps_relative_layout_and_never_overwrites_inputs(tmp_path):
    root = tmp_path / "in"
    a = _touch(root / "a.csv")
    b = _touch(root / "sub" / "a.csv")
    jobs, refused = plan_jobs(
        discover_inputs([root]), tmp_path / "out", method="atkf", output_format="csv"
    )
    assert not refused
    assert [j.output for j in jobs] == [
        tmp_path / "out" / "a.atkf.csv",
        tmp_path / "out" / "sub" / "a.atkf.csv",
    ]
    # an output that would land on an input is refused for that file only
    clash = _touch(root / "x.atkf.csv")
    jobs, refused = plan_jobs(
        [(root / "x.csv", root), (clash, root)], root, method="atkf", output_format="csv"
    )
    assert any("overwrite an input" in r.error for r in refused)
    assert a.read_text() == "x" and b.read_text() == "x"


def test_plan_refuses_two_inputs_with_the_same_output(tmp_path):
    a = _touch(tmp_path / "one" / "rec.csv")
    b = _touch(tmp_path / "two" / "rec.csv")
    jobs, refused = plan_jobs(
        [(a, a.parent), (b, b.parent)], tmp_path / "out", method="kf", output_format="npz"
    )
    assert len(jobs) == 1 and jobs[0].output.suffix == ".npz"
    assert len(refused) == 1 and "already the output" in refused[0].error


def test_plan_auto_format_keeps_ntu(tmp_path):
    a = _touch(tmp_path / "S001.skeleton")
    b = _touch(tmp_path / "k.txt")
    jobs, _ = plan_jobs(
        [(a, tmp_path), (b, tmp_path)],
        tmp_path / "o",
        method="atkf",
        detect=lambda p: "ntu" if p.suffix == ".skeleton" else "keraal_kinect",
    )
    assert [j.output.suffix for j in jobs] == [".skeleton", ".csv"]


def test_a_file_no_format_claims_fails_with_its_own_reason(tmp_path):
    """An empty S001.skeleton beside rec.csv: auto could only guess its output (CSV), which
    would collide with the CSV's and hide why it fails."""
    from tobitkf.io import detect_format
    from tobitkf.io.registry import ReadError

    a = tmp_path / "rec.csv"
    a.write_text("a_x,a_y,a_z\n0,0,0\n")
    b = tmp_path / "rec.skeleton"
    b.write_bytes(b"")
    with pytest.raises(ReadError) as why:
        detect_format(b)
    jobs, refused = plan_jobs(
        [(a, tmp_path), (b, tmp_path)], tmp_path / "o", method="kf", detect=detect_format
    )
    assert [j.source for j in jobs] == [a]
    assert [(r.source, r.error) for r in refused] == [(str(b), f"ReadError: {why.value}")]


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("q=0.001", ("q", 0.001)),
        ("window=9", ("window", 9)),
        ("c=0.3,0.2,0.3", ("c", (0.3, 0.2, 0.3))),
        ("preset=v2_sample", ("preset", "v2_sample")),
        ("centered=false", ("centered", False)),
        ("jitter-radius=0.05", ("jitter_radius", 0.05)),
        ("up_axis=None", ("up_axis", None)),
        ("v_max=hands:6", ("v_max", {"hands": 6.0})),
        ("v_max=hands:6, arms:4.5", ("v_max", {"hands": 6.0, "arms": 4.5})),
        ("preset=a:b", ("preset", "a:b")),  # text with a colon stays text
    ],
)
def test_parse_param(text, expected):
    assert parse_param(text) == expected


def test_parse_param_rejects_malformed():
    with pytest.raises(ValueError, match="key=value"):
        parse_param("q0.001")
    with pytest.raises(ValueError, match="empty name"):
        parse_param("=3")


@settings(max_examples=100, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False))
def test_parse_param_float_round_trip(x):
    key, value = parse_param(f"q={x!r}")
    assert key == "q" and float(value) == x


def test_discover_skips_companion_files_only_inside_folders(tmp_path):
    rec = _touch(tmp_path / "in" / "x_positions.csv")
    comp = _touch(tmp_path / "in" / "x_angles.csv")
    skipped: list[Path] = []
    found = discover_inputs([tmp_path / "in"], skip=lambda p: "_angles" in p.name, skipped=skipped)
    assert [f for f, _ in found] == [rec] and skipped == [comp]
    # a file named explicitly is never skipped
    assert [f for f, _ in discover_inputs([comp], skip=lambda p: True)] == [comp]


def test_not_a_recording_passes_over_docs_and_companions_but_not_bad_recordings(tmp_path):
    from tobitkf.app.batch import not_a_recording

    assert not_a_recording(_touch(tmp_path / "README.md"))
    assert not_a_recording(_touch(tmp_path / "photo.png"))
    assert not not_a_recording(_touch(tmp_path / "broken.csv"))
    assert not not_a_recording(_touch(tmp_path / "x_positions.txt.gz"))
    folder = tmp_path / "Kinect"
    _touch(folder / "Positions" / "m01_positions.txt.gz")
    angles = _touch(folder / "Angles" / "m01_angles.txt.gz")
    assert not_a_recording(angles)  # read together with its positions file
