"""Results as Markdown tables: what ``tobitkf evaluate --markdown`` and ``tobitkf
benchmark --markdown`` print, and what ``make docs-results`` puts into the README and the
docs (so no result there is ever typed by hand)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["benchmark_markdown", "evaluation_markdown"]

_GROUPS = ("hands", "arms", "torso", "legs")
#: the column of the share of samples inside the 95 % ball of the method's own sd
BALL_HEADER = "in 95% ball"
_CLASSES = (("fine", "fine"), ("short_glitch", "short"), ("sustained", "sustained"))


def _num(v: Any, digits: int = 2) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return f"{v:.{digits}f}"


def _change(v: float, raw: float) -> str:
    if not (math.isfinite(v) and math.isfinite(raw) and raw > 0):
        return "–"
    return f"{100 * (v / raw - 1):+.0f} %"


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    return [
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
        *("| " + " | ".join(r) + " |" for r in rows),
    ]


def _ball_by_class(
    rows: Sequence[dict[str, Any]], classes: Sequence[tuple[str, str]], what: str
) -> list[str]:
    """The share in the 95 % sd ball per class (``<class>_in_95_ball_pct``), for the
    methods with an sd; nothing when no method has one."""
    rows = [r for r in rows if r.get("in_95_ball_pct") is not None]
    if not rows:
        return []
    return [
        "",
        f"Samples within the 95 % ball of the method's own standard deviation, % (95 when "
        f"the sd is honest), by {what}:",
        "",
        *_table(
            ["method", BALL_HEADER, *(n for _, n in classes)],
            [
                [r["method"], _num(r["in_95_ball_pct"], 1)]
                + [_num(r.get(f"{c}_in_95_ball_pct"), 1) for c, _ in classes]
                for r in rows
            ],
        ),
    ]


def evaluation_markdown(
    tables: Sequence[Any],
    labels: Sequence[str],
    pooled: Sequence[dict[str, Any]] | None = None,
    warnings: Sequence[tuple[str, str]] = (),
) -> str:
    """Markdown of an evaluation against ground truth.

    Parameters
    ----------
    tables : one :class:`~tobitkf.evaluation.evaluate.EvaluationTable` per recording.
    labels : a short name per recording (file names).
    pooled : :func:`~tobitkf.evaluation.evaluate.pool_scores` of the tables (several
        recordings), or None.
    warnings : ``(label, text)`` of the time alignment, printed under the tables.

    Returns
    -------
    The pooled table (RMSE in cm, change against raw, per joint group and per raw glitch
    class, max, frames with a joint more than 10 cm off, % of samples in the 95 % ball of
    the method's sd), the ball's share per raw class (methods with an sd), then RMSE per
    recording, then the warnings.
    """
    if pooled is None:
        from tobitkf.evaluation.evaluate import pool_scores

        pooled = pool_scores(tables[:1])
    raw = next((r["rmse_cm"] for r in pooled if r["method"] == "raw"), float("nan"))
    header = ["method", "RMSE", "vs raw", *_GROUPS, *(n for _, n in _CLASSES), "max",
              "frames > 10 cm", BALL_HEADER]  # fmt: skip
    rows = [
        [
            r["method"],
            _num(r["rmse_cm"]),
            _change(r["rmse_cm"], raw) if r["method"] != "raw" else "",
            *(_num(r.get(f"{g}_cm")) for g in _GROUPS),
            *(_num(r.get(f"{c}_cm")) for c, _ in _CLASSES),
            _num(r.get("max_cm"), 1),
            str(r.get("frames_over", "–")),
            _num(r.get("in_95_ball_pct"), 1),
        ]
        for r in pooled
    ]
    n = sum(int(r.get("n_samples", 0)) for r in pooled[:1])
    what = f"{len(tables)} recording{'s' if len(tables) > 1 else ''}, {n:,} samples"
    out = [f"RMSE against motion capture, cm ({what}; pooled over recordings):", ""]
    out += _table(header, rows)
    out += _ball_by_class(pooled, _CLASSES, "raw class")
    if len(tables) > 1:
        methods = [s.method for s in tables[0].scores]
        out += ["", "RMSE per recording, cm:", ""]
        out += _table(
            ["recording", *methods],
            [
                [Path(lab).name, *(_num(100 * t.score(m).rmse) for m in methods)]
                for lab, t in zip(labels, tables, strict=True)
            ],
        )
    if warnings:
        out += ["", "Warnings of the time alignment (their numbers deserve less trust):", ""]
        out += [f"- {Path(lab).name}: {text}" for lab, text in warnings]
    return "\n".join(out) + "\n"


def benchmark_markdown(
    spread: Sequence[dict[str, Any]],
    seeds: Sequence[int],
    ball: Sequence[dict[str, Any]] | None = None,
) -> str:
    """Markdown of :func:`~tobitkf.evaluation.benchmark.seed_spread`: RMSE in cm, mean ±
    standard deviation over the seeds, overall and by glitch label; then, given ``ball``
    (:func:`~tobitkf.evaluation.benchmark.seed_ball`), the share of samples in each
    method's 95 % sd ball, pooled over the seeds, overall and by label."""
    out = spread_markdown(spread, seeds, total="rmse", unit="cm", scale=100.0)
    if ball:
        from tobitkf.evaluation.corruption import LABEL_NAMES

        labels = [(name, name) for name in LABEL_NAMES.values()]
        lines = _ball_by_class(ball, labels, "label (pooled over the seeds)")
        out += "\n".join(lines) + "\n" if lines else ""
    return out


def spread_markdown(
    spread: Sequence[dict[str, Any]],
    seeds: Sequence[int],
    *,
    total: str,
    unit: str,
    scale: float = 1.0,
    suffix: str = "",
) -> str:
    """RMSE table of a seed spread (``method`` and ``(mean, sd)`` pairs): the ``total``
    column as mean ± sd with its change against ``raw``, every other column's mean;
    values times ``scale``, in ``unit``; ``suffix`` is cut from the column names."""
    keys = [k for k in spread[0] if k not in ("method", total)]
    raw = next((r[total][0] for r in spread if r["method"] == "raw"), float("nan"))
    rows = [
        [
            r["method"],
            f"{_num(scale * r[total][0])} ± {_num(scale * r[total][1])}",
            _change(r[total][0], raw) if r["method"] != "raw" else "",
            *(_num(scale * r[k][0]) for k in keys),
        ]
        for r in spread
    ]
    seed_text = f"seeds {seeds[0]}–{seeds[-1]}" if len(seeds) > 1 else f"seed {seeds[0]}"
    out = [
        f"RMSE against the known truth, {unit} (mean ± sd over {seed_text}; by label: mean):",
        "",
    ]
    names = [k[: -len(suffix)] if suffix and k.endswith(suffix) else k for k in keys]
    out += _table(["method", "RMSE", "vs raw", *names], rows)
    return "\n".join(out) + "\n"
