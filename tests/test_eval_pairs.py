"""Pairing tables: built-in tables, the CSV format and its validation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tobitkf.evaluation.pairs import (
    KERAAL_PAIRS,
    UIPRMD_PAIRS,
    Pair,
    PairingTable,
    builtin_pairs,
    normalise_name,
    read_pairs,
)
from tobitkf.skeleton.topology import get_topology


def test_normalise_name() -> None:
    assert normalise_name("Right Hand") == normalise_name("right_hand") == "righthand"
    assert normalise_name("Left-upper arm") == "leftupperarm"


def test_builtin_tables_resolve_against_the_reader_topologies() -> None:
    k = KERAAL_PAIRS.resolve(
        get_topology("kinect_v2").joints, get_topology("keraal_vicon_17").joints
    )
    assert len(k.pairs) == 21 and not k.missing
    u = UIPRMD_PAIRS.resolve(get_topology("ui_prmd").joints, get_topology("plug_in_gait_39").joints)
    assert len(u.pairs) == len(UIPRMD_PAIRS) and not u.missing
    assert builtin_pairs("KERAAL") is KERAAL_PAIRS and builtin_pairs("ui-prmd") is UIPRMD_PAIRS
    with pytest.raises(ValueError, match="unknown"):
        builtin_pairs("nope")


def test_mocap_positions_average_listed_points() -> None:
    table = PairingTable("t", (Pair("a", ("m1", "m2")), Pair("c", ("m3",))))
    r = table.resolve(["a", "b", "c"], ["m1", "m2", "m3"])
    mocap = np.arange(2 * 3 * 3, dtype=float).reshape(2, 3, 3)
    out = r.mocap_positions(mocap, 3)
    np.testing.assert_allclose(out[:, 0], (mocap[:, 0] + mocap[:, 1]) / 2)
    assert np.isnan(out[:, 1]).all()
    np.testing.assert_allclose(out[:, 2], mocap[:, 2])
    q = r.mocap_quaternions(np.ones((2, 3, 4)), 3)
    assert np.isnan(q[:, 0]).all() and (q[:, 2] == 1).all()  # averaged pairs get none


def test_resolve_drops_or_rejects_missing_names() -> None:
    table = PairingTable("t", (Pair("a", ("m1",)), Pair("zz", ("m1",)), Pair("b", ("nope",))))
    r = table.resolve(["a", "b"], ["m1"])
    assert [p.track_joint for p in r.pairs] == ["a"] and len(r.missing) == 2
    with pytest.raises(ValueError, match="zz"):
        table.resolve(["a", "b"], ["m1"], strict=True)
    with pytest.raises(ValueError, match="no pair matches"):
        table.resolve(["x"], ["y"])


def test_csv_round_trip(tmp_path: Path) -> None:
    f = tmp_path / "pairs.csv"
    f.write_text(UIPRMD_PAIRS.to_csv())
    back = read_pairs(f)
    assert back.pairs == UIPRMD_PAIRS.pairs


def test_csv_comments_blank_lines_and_trailing_comma(tmp_path: Path) -> None:
    f = tmp_path / "p.csv"
    f.write_text("# my pairs\n\nHandRight, Right Hand,\nWristLeft,LWRA + LWRB\n")
    t = read_pairs(f)
    assert t.pairs == (Pair("HandRight", ("Right Hand",)), Pair("WristLeft", ("LWRA", "LWRB")))


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("a,b\nc\n", r"p.csv:2: expected"),
        ("a,b,c\n", r"p.csv:1: expected"),
        ("a,x+\n", r"p.csv:1: empty mocap point"),
        (",x\n", r"p.csv:1: empty track joint"),
        ("a,x\nA,y\n", r"p.csv:2: joint 'A' already paired on line 1"),
        ("# only a comment\n", "no pairs"),
    ],
)
def test_csv_errors_name_file_and_line(tmp_path: Path, text: str, match: str) -> None:
    f = tmp_path / "p.csv"
    f.write_text(text)
    with pytest.raises(ValueError, match=match):
        read_pairs(f)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="cannot read"):
        read_pairs(tmp_path / "none.csv")
