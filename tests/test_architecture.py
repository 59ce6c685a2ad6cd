"""The package's layout rules, checked on the source: no import cycle (lazy imports
included), arrows one way between the layers, and a math core that imports nothing of
tobitkf outside itself and no I/O, plotting or CLI library.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = SRC / "tobitkf"

# layer -> layers it may import (besides itself); the package root and __main__ may
# import anything (lazy public API, entry point)
ALLOWED = {
    "core": set(),
    "skeleton": {"core"},
    "smoothing": {"core", "skeleton"},
    "io": {"core", "skeleton"},
    "evaluation": {"core", "skeleton", "smoothing", "io"},
    "paper": {"core", "skeleton", "smoothing", "evaluation"},
    "app": {"core", "skeleton", "smoothing", "io", "evaluation", "paper"},
}
CORE_THIRD_PARTY = {"numpy", "scipy"}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path) -> set[str]:
    """Every module a file imports, at any depth (function bodies too: lazy imports
    count), resolved to full names; ``from a import b`` counts as ``a.b`` when that is a
    module, else as ``a``."""
    name = _module_name(path)
    is_pkg = path.name == "__init__.py"
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")
                base = base if is_pkg else base[:-1]
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            for a in node.names:
                out.add(f"{mod}.{a.name}" if _is_module(f"{mod}.{a.name}") else mod)
    return out


def _is_module(name: str) -> bool:
    rel = Path(*name.split("."))
    return (SRC / rel).with_suffix(".py").exists() or (SRC / rel / "__init__.py").exists()


def _graph() -> dict[str, set[str]]:
    files = sorted(PACKAGE.rglob("*.py"))
    return {
        _module_name(f): {m for m in _imports(f) if m == "tobitkf" or m.startswith("tobitkf.")}
        for f in files
    }


def _layer(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in ALLOWED else None


def _find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(n: str) -> list[str] | None:
        state[n] = 1
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if m not in graph or m == n:
                continue
            if state.get(m) == 1:
                return [*stack[stack.index(m) :], m]
            if m not in state and (found := visit(m)):
                return found
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(graph):
        if n not in state and (found := visit(n)):
            return found
    return None


def test_the_checker_sees_lazy_imports_and_cycles():
    g = {"tobitkf.a": {"tobitkf.b"}, "tobitkf.b": {"tobitkf.c"}, "tobitkf.c": {"tobitkf.a"}}
    assert _find_cycle(g) == ["tobitkf.a", "tobitkf.b", "tobitkf.c", "tobitkf.a"]
    assert _find_cycle({"tobitkf.a": {"tobitkf.b"}, "tobitkf.b": set()}) is None
    # an import inside a function body is found
    lazy = _imports(PACKAGE / "app" / "cli.py")
    assert "tobitkf.app.commands" in lazy


def test_no_import_cycle_anywhere_lazy_imports_included():
    assert _find_cycle(_graph()) is None


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_arrows_point_one_way(layer):
    bad = []
    for mod, deps in _graph().items():
        if _layer(mod) != layer:
            continue
        for d in deps:
            target = _layer(d)
            if d == "tobitkf" or (target not in (None, layer) and target not in ALLOWED[layer]):
                bad.append(f"{mod} -> {d}")
    assert not bad, f"{layer} may import only {sorted(ALLOWED[layer])}: {bad}"


def test_math_core_imports_numpy_and_scipy_only():
    stdlib_io = {"os", "io", "pathlib", "shutil", "tempfile", "gzip", "zipfile", "csv"}
    for f in sorted((PACKAGE / "core").rglob("*.py")):
        for m in _imports(f):
            top = m.split(".")[0]
            if top == "tobitkf":
                assert m.startswith("tobitkf.core"), f"{f.name} imports {m}"
            else:
                assert top not in stdlib_io, f"{f.name} imports {m} (the core has no I/O)"
                assert top in CORE_THIRD_PARTY or _is_stdlib(top), f"{f.name} imports {m}"


def _is_stdlib(name: str) -> bool:
    import sys

    return name in sys.stdlib_module_names or name == "__future__"


def test_every_package_module_is_in_a_layer():
    loose = [m for m in _graph() if m not in ("tobitkf", "tobitkf.__main__") and _layer(m) is None]
    assert not loose, f"modules outside the layers {sorted(ALLOWED)}: {loose}"
