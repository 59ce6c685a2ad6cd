"""Results in README.md and docs/ cannot go stale: every results table sits in a block
that names the command printing it, and the blocks say what the commands print now."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from conftest import data_file, tool_module

ROOT = Path(__file__).resolve().parents[1]
# files whose every results table must be generated (more join as they are converted)
STRICT = ("README.md", "docs/evaluation.md", "docs/robust.md", "docs/reproduction.md")
# a header cell that makes a table a results table (methods, filters, recordings, estimates)
RESULT_COLUMNS = {"method", "recording", "rmse", "filter", "estimate", "matrix"}


def _tool():
    return tool_module("docs_results")


def _outside_blocks(text: str) -> str:
    return _tool().BLOCK.sub("", text)


def test_blocks_are_well_formed():
    tool = _tool()
    for path in tool.documents():
        text = path.read_text(encoding="utf-8")
        assert text.count("<!-- results") == text.count("<!-- /results -->"), path
        for b in tool.blocks(path):
            assert b.body.startswith(f"Printed by `{b.command}`"), (path, b.command)


@pytest.mark.parametrize("name", STRICT)
def test_no_results_table_is_typed_by_hand(name):
    rest = _outside_blocks((ROOT / name).read_text(encoding="utf-8"))
    # a results table has a RESULT_COLUMNS header (a table of parameters and their
    # physical reasons may quote numbers)
    typed, in_results = [], False
    for line in rest.splitlines():
        if not line.startswith("|"):
            in_results = False
            continue
        cells = [c.strip().lower() for c in line.strip("|").split("|")]
        if not in_results and set(cells) & RESULT_COLUMNS:
            in_results = True
        if in_results and re.search(r"\d\.\d", line):
            typed.append(line)
    assert not typed, f"{name}: results typed outside a results block: {typed[:3]}"


def test_the_checker_finds_a_changed_number(tmp_path, monkeypatch):
    tool = _tool()
    doc = tmp_path / "doc.md"
    cmd = "printf '| a | 1.25 |\\n'"
    doc.write_text(
        f"x\n<!-- results: {cmd} -->\n{tool.render(cmd, '| a | 1.26 |')}<!-- /results -->\n"
    )
    monkeypatch.setattr(tool, "ROOT", tmp_path)
    tool.prefetch([doc], only=None)  # as the check of every block runs them
    assert tool.update(doc, only=None, bench=False, check=True) == [f"doc.md: {cmd}"]
    assert tool.update(doc, only=None, bench=False, check=False)
    assert tool.update(doc, only=None, bench=False, check=True) == []
    assert [b.body for b in tool.blocks(doc)] == [tool.render(cmd, "| a | 1.25 |")]


def test_the_longest_commands_start_first():
    # two at a time: a long command started last would run alone at the end
    tool = _tool()
    cmds = ["tobitkf benchmark --seeds 5", "tobitkf fit a.txt", "python tools/delayed.py a.txt",
            "tobitkf reproduce likelihood --datasets 5"]  # fmt: skip
    assert tool.slow_first(cmds) == [cmds[2], cmds[3], cmds[0], cmds[1]]


@pytest.mark.realdata
@pytest.mark.slow
def test_every_results_block_matches_what_its_command_prints():
    data_file("keraal/G3-Kinect-ELK-P1T1-Unknown-C-0.txt")  # skips (or fails in CI) without data
    tool = _tool()
    tool.prefetch(tool.documents(), only=None)  # the commands two at a time (2 cores)
    stale = []
    for path in tool.documents():
        stale += tool.update(path, only=None, bench=False, check=True)
    assert not stale, "stale results (run `make docs-results`):\n" + "\n".join(stale)
