"""Regenerate (or check) every results block in README.md and docs/*.md.

A results block is the output of a project command, between two markers::

    <!-- results: tobitkf evaluate A.txt --truth B.txt --markdown -->
    ...whatever the command printed...
    <!-- /results -->

The command runs in bash from the project root (globs and braces expand), with the
interpreter's own ``bin`` folder first on PATH, so ``tobitkf`` is the project's. Blocks
whose marker says ``results (bench):`` hold timings: they are regenerated only with
``--bench`` (``make bench``), never checked (timings are not reproducible).

    python tools/docs_results.py                 # rewrite every block (make docs-results)
    python tools/docs_results.py --check         # exit 1 when a block is stale
    python tools/docs_results.py --only keraal   # only blocks whose command contains it
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BLOCK = re.compile(
    r"(?P<open><!-- results(?P<bench> \(bench\))?:\s*(?P<cmd>.*?)\s*-->\n)"
    r"(?P<body>.*?)"
    r"(?P<close><!-- /results -->)",
    re.S,
)


@dataclass(frozen=True)
class Block:
    path: Path
    command: str
    body: str
    bench: bool


def documents() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def blocks(path: Path) -> list[Block]:
    text = path.read_text(encoding="utf-8")
    return [
        Block(path, " ".join(m["cmd"].split()), m["body"], bool(m["bench"]))
        for m in BLOCK.finditer(text)
    ]


def run(command: str) -> str:
    """What ``command`` prints (stdout), as it goes into a block."""
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env.setdefault("MPLBACKEND", "Agg")
    env["COLUMNS"] = "200"
    done = subprocess.run(
        ["bash", "-c", command], cwd=ROOT, env=env, capture_output=True, text=True, check=False
    )
    if done.returncode != 0:
        raise RuntimeError(f"`{command}` failed ({done.returncode}):\n{done.stderr[-2000:]}")
    # a command may print a log first and the block after a record separator
    return render(command, done.stdout.rsplit("\x1e\n", 1)[-1])


def render(command: str, output: str) -> str:
    return f"Printed by `{command}`:\n\n{output.rstrip()}\n"


_CACHE: dict[str, str] = {}  # a command shown in several files runs once

#: parts of the commands that take longest (tens of seconds: a method run once per frame,
#: maximum-likelihood fits, many recordings or settings), started first so that the
#: commands run at a time end together instead of one long command running alone at the end
SLOW = ("tools/delayed.py", "reproduce likelihood", "tools/sensitivity.py", "ui-prmd",
        "reproduce oscillator")  # fmt: skip


def slow_first(cmds: list[str]) -> list[str]:
    """``cmds`` with those of :data:`SLOW` first (in its order), the rest as given."""

    def rank(cmd: str) -> int:
        return next((i for i, part in enumerate(SLOW) if part in cmd.lower()), len(SLOW))

    return sorted(cmds, key=rank)  # stable: ties keep their order


def prefetch(paths: list[Path], *, only: str | None, jobs: int | None = None) -> None:
    """Run the result blocks' commands of ``paths`` (not the timings: they run alone)
    ``jobs`` at a time (default: the CPUs), into the cache :func:`update` reads: each
    is its own process, so the results are those of a run one by one, sooner."""
    cmds = []
    for path in paths:
        for b in blocks(path):
            if not b.bench and (not only or only in b.command) and b.command not in _CACHE:
                cmds.append(b.command)
    cmds = slow_first(list(dict.fromkeys(cmds)))
    with ThreadPoolExecutor(max_workers=jobs or os.cpu_count() or 1) as pool:
        for cmd, out in zip(cmds, pool.map(run, cmds), strict=True):
            _CACHE[cmd] = out


def update(path: Path, *, only: str | None, bench: bool, check: bool) -> list[str]:
    """Rewrite (or, with ``check``, compare) the blocks of one file; returns the stale ones."""
    text = path.read_text(encoding="utf-8")
    stale: list[str] = []
    cache = _CACHE

    def replace(m: re.Match[str]) -> str:
        cmd = " ".join(m["cmd"].split())
        if (only and only not in cmd) or (bool(m["bench"]) != bench):
            return m.group(0)
        if cmd not in cache:
            cache[cmd] = run(cmd)
        if cache[cmd] != m["body"]:
            stale.append(f"{path.relative_to(ROOT)}: {cmd}")
        return m["open"] + cache[cmd] + m["close"]

    new = BLOCK.sub(replace, text)
    if not check and new != text:
        path.write_text(new, encoding="utf-8")
    return stale


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="report stale blocks, write nothing")
    ap.add_argument("--only", help="only blocks whose command contains this text")
    ap.add_argument("--bench", action="store_true", help="the timing blocks instead")
    args = ap.parse_args(argv)
    if not args.bench:
        prefetch(documents(), only=args.only)
    stale = []
    for path in documents():
        stale += update(path, only=args.only, bench=args.bench, check=args.check)
    for s in stale:
        print(("stale: " if args.check else "updated: ") + s)
    return 1 if (args.check and stale) else 0


if __name__ == "__main__":
    raise SystemExit(main())
