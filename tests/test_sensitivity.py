"""tools/sensitivity.py: the one-at-a-time sweep of the robust pair (docs/robust.md)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from conftest import tool_module
from tobitkf.smoothing.robust import ONLINE_DEFAULTS, ROBUST_DEFAULTS

ROOT = Path(__file__).resolve().parents[1]
KERAAL = (
    "tobitkf evaluate ../shared/data/keraal/G3-Kinect-*-P1T1-Unknown-C-0.txt "
    "--truth-replace -Kinect- -Vicon- --markdown"
)
UIPRMD = (
    'tobitkf evaluate "../shared/data/ui-prmd/Segmented Movements/Kinect/Positions/"'
    "m0*_s01_e0*_positions.txt.gz --truth-replace /Kinect/ /Vicon/ --markdown"
)
BENCHMARK = "tobitkf benchmark --seeds 5 --markdown"


def _load(name: str):
    return tool_module(name)


def test_every_parameter_is_swept_or_said_why_not():
    tool = _load("sensitivity")
    swept = {n for _, _, params in tool.variants()[1:] for n in params}
    assert swept | set(tool.NOT_SWEPT) == set(ROBUST_DEFAULTS)
    assert not swept & set(tool.NOT_SWEPT)
    assert set(ONLINE_DEFAULTS) == set(ROBUST_DEFAULTS)


def test_each_variant_changes_one_parameter_from_its_default():
    tool = _load("sensitivity")
    rows = tool.variants()
    assert rows[0] == ("defaults", "", {})
    for name, shown, params in rows[1:]:
        assert list(params) == [name]
        default, value = ROBUST_DEFAULTS[name], params[name]
        if isinstance(default, dict):  # every region scaled alike
            assert shown in ("× 0.5", "× 2")
            factor = 0.5 if shown == "× 0.5" else 2.0
            assert value == {k: v * factor for k, v in default.items()}
        elif isinstance(default, bool):
            assert default is True and value is False and shown == "off"
        elif isinstance(default, str):
            assert value != default
        else:
            assert value in (default * 0.5, default * 2) or (
                isinstance(default, int) and value in (round(default / 2), default * 2)
            )
            assert value != default
    # halved and doubled: two rows per numeric parameter
    names = [n for n, _, p in rows[1:] if not isinstance(p[n], (bool, str))]
    assert all(names.count(n) == 2 for n in names)


def test_a_parameter_a_method_does_not_read_is_not_run_for_it():
    tool = _load("sensitivity")
    assert not tool.applies("robust_online", {"two_pass": False})
    assert not tool.applies("robust_online", {"fit_seconds": 10.0})
    assert not tool.applies("robust", {"lookback": 4})
    assert tool.applies("robust", {"min_run": 0.2})
    assert tool.applies("robust_online", {"min_run": 0.2})


def _block(command: str) -> str:
    tool = _load("docs_results")
    found = [b.body for b in tool.blocks(ROOT / "docs" / "robust.md") if b.command == command]
    assert found, f"no block `{command}` in docs/robust.md"
    return found[0]


def _first_column(body: str, label: str) -> float:
    """The value after ``label`` in the first table row that starts with it."""
    m = re.search(rf"^\| {re.escape(label)} \| ([0-9.]+)", body, re.M)
    assert m, label
    return float(m.group(1))


@pytest.mark.parametrize(
    ("column", "command"),
    [(0, KERAAL), (1, UIPRMD), (2, BENCHMARK)],
    ids=["keraal", "uiprmd", "synthetic"],
)
def test_the_defaults_row_is_what_evaluate_and_benchmark_print(column, command):
    """The sweep scores as ``tobitkf evaluate`` / ``benchmark`` do: its reference rows and
    its defaults row equal those commands' own results blocks."""
    sweep = _block("python tools/sensitivity.py")
    other = _block(command)
    for ref in ("raw", "kf+rts"):
        row = re.search(rf"^\| {re.escape(ref)} \| (.*) \|$", sweep, re.M)
        assert row, ref
        assert float(row.group(1).split(" | ")[column]) == _first_column(other, ref)
    defaults = re.search(r"^\| defaults \|  \| (.*) \|$", sweep, re.M)
    assert defaults
    cells = defaults.group(1).split(" | ")
    for k, method in enumerate(("robust", "robust_online")):
        assert float(cells[2 * column + k]) == _first_column(other, method)
