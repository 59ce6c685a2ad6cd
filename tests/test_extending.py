"""The worked examples of docs/architecture.md ("Extending tobitkf"), run as written:
a user method through smooth and LiveSmoother, a file format, a topology, all without
editing the package."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

DOC = Path(__file__).resolve().parents[1] / "docs" / "architecture.md"


def _examples() -> dict[str, str]:
    text = DOC.read_text(encoding="utf-8")
    part = text[text.index("## Extending tobitkf") :]
    out = {}
    for title, body in re.findall(r"### (.+?)\n(.*?)(?=\n### |\n## |\Z)", part, re.S):
        blocks = re.findall(r"```python\n(.*?)```", body, re.S)
        if blocks:
            out[title.split("(")[0].strip()] = "\n".join(blocks)
    return out


@pytest.fixture
def clean_registries():
    import tobitkf as tk
    from tobitkf.io import unregister_format
    from tobitkf.skeleton import topology

    before = set(topology.available_topologies())
    yield
    tk.unregister_method("ewma")
    unregister_format("xyz")
    for name in set(topology.available_topologies()) - before:
        topology._BUILTINS.pop(name)


def test_the_doc_has_the_three_examples():
    assert set(_examples()) == {"A smoothing method", "A file format", "A topology"}


@pytest.mark.parametrize("title", ["A smoothing method", "A file format", "A topology"])
def test_worked_example_runs_as_written(title, clean_registries):
    code = _examples()[title]
    exec(compile(code, f"docs/architecture.md: {title}", "exec"), {"__name__": "example"})


def test_a_user_method_is_a_cli_choice_and_refused_when_it_returns_a_wrong_shape(
    clean_registries, tmp_path
):
    import numpy as np
    from click.testing import CliRunner

    import tobitkf as tk
    from tobitkf.app.commands import app

    tk.register_method("ewma", lambda inp: inp.ys[:-1], params={})
    seq = tk.generate_motion("arms", duration=1.0, seed=0)
    with pytest.raises(ValueError, match=r"method 'ewma' returned positions of shape"):
        tk.smooth(seq, method="ewma")
    tk.register_method("ewma", lambda inp: np.nan_to_num(inp.ys), params={}, replace=True)
    tk.save([seq], tmp_path / "a.csv")
    res = CliRunner().invoke(app, ["smooth", str(tmp_path / "a.csv"), "-o", str(tmp_path / "o"),
                                   "-m", "ewma"])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert (tmp_path / "o" / "a.ewma.csv").exists()
    with pytest.raises(ValueError, match="already registered"):
        tk.register_method("ewma", lambda inp: inp.ys, params={})
    with pytest.raises(ValueError, match="cannot run live"):
        tk.LiveSmoother(seq.topology, method="ewma")  # not declared causal
