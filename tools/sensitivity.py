"""How much the robust pair's results depend on each parameter (docs/robust.md).

One parameter at a time is changed from its default, for ``robust`` and
``robust_online`` alike: halved and doubled (every region's value for the per-region
ones), or a switch turned off. Each row gives the pooled RMSE (cm) against the truth of
the three data sets the defaults are judged on, scored as ``tobitkf evaluate`` and
``tobitkf benchmark`` score them:

* KERAAL: the three Kinect / Vicon pairs (``G3-Kinect-*-P1T1-Unknown-C-0.txt``);
* UI-PRMD: the nine subject-1 episodes (``m0*_s01_e0*``);
* synthetic: the built-in benchmark, mean over ``--seeds`` seeds (``tobitkf benchmark``).

A parameter that a method does not read (``two_pass`` and the noise fit offline only,
``lookback`` online only) shows "–" for it. The defaults' row is what ``tobitkf evaluate``
and ``tobitkf benchmark`` print for the two methods (tests/test_sensitivity.py).

    python tools/sensitivity.py [--data ../shared/data] [--seeds 5]
"""

from __future__ import annotations

import argparse
import glob
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tobitkf.evaluation.benchmark import run_benchmark, seed_spread
from tobitkf.evaluation.evaluate import evaluate_paths, pool_scores
from tobitkf.smoothing.robust import ROBUST_DEFAULTS

ROOT = Path(__file__).resolve().parents[1]
METHODS = ("robust", "robust_online")
#: parameters one method does not read
OFFLINE_ONLY = {"two_pass", "noise", "fit_seconds", "shoulder_drop", "reweight"}
ONLINE_ONLY = {"lookback"}
#: the numeric parameters, halved and doubled
SCALED = (
    "v_max", "margin", "bone_tol_abs", "bone_tol_rel", "speed_sd", "noise_sd", "tau",
    "max_reject", "min_run", "lookback", "fit_seconds", "shoulder_drop", "reweight",
)  # fmt: skip
#: the switches, turned off
SWITCHES = ("bones", "two_pass", "carry", "inferred_bones")
#: not swept, and why
NOT_SWEPT = {
    "gates": "chooses where the metric parameters come from (metres here either way)",
    "shared_errors": "changes the standard deviation, not the estimate",
}


def _scaled(value: Any, factor: float) -> Any:
    if isinstance(value, dict):
        return {k: v * factor for k, v in value.items()}
    if isinstance(value, int) and not isinstance(value, bool):
        return max(0, round(value * factor))
    return value * factor


def variants() -> list[tuple[str, str, dict[str, Any]]]:
    """``(parameter, value as shown, params)`` rows: the defaults, then one change each."""
    rows: list[tuple[str, str, dict[str, Any]]] = [("defaults", "", {})]
    for name in SCALED:
        for factor in (0.5, 2.0):
            value = _scaled(ROBUST_DEFAULTS[name], factor)
            shown = f"× {factor:g}" if isinstance(value, dict) else f"{value:g}"
            rows.append((name, shown, {name: value}))
    rows += [(name, "off", {name: False}) for name in SWITCHES]
    rows.append(("noise", "fixed", {"noise": "fixed"}))
    return rows


def applies(method: str, params: dict[str, Any]) -> bool:
    names = set(params)
    if method == "robust_online":
        return not names & OFFLINE_ONLY
    return not names & ONLINE_ONLY


Scorer = Callable[[list[tuple[str, str, dict[str, Any]]]], dict[str, float]]


def keraal_uiprmd(paths: Sequence[str], replace: tuple[str, str]) -> Scorer:
    """Pooled RMSE (cm) per method label over Kinect / mocap pairs, as `tobitkf evaluate`."""

    def score(specs: list[tuple[str, str, dict[str, Any]]]) -> dict[str, float]:
        tables = [evaluate_paths(p, p.replace(*replace), specs)[1] for p in paths]
        return {r["method"]: r["rmse_cm"] for r in pool_scores(tables)}

    return score


def synthetic(seeds: int) -> Scorer:
    """Mean RMSE (cm) over seeds of the built-in benchmark, as `tobitkf benchmark`."""

    def score(specs: list[tuple[str, str, dict[str, Any]]]) -> dict[str, float]:
        tables = [run_benchmark(seed, specs) for seed in range(seeds)]
        return {r["method"]: r["rmse"][0] * 100 for r in seed_spread(tables)}

    return score


def sweep(scorers: dict[str, Scorer]) -> tuple[dict[str, dict[str, float]], list[Any]]:
    """Every variant of both methods (and raw, kf+rts) scored on every data set."""
    rows = variants()
    specs: list[tuple[str, str, dict[str, Any]]] = [("raw", "raw", {}), ("kf+rts", "kf+rts", {})]
    for i, (_, _, params) in enumerate(rows):
        specs += [(f"{m}#{i}", m, params) for m in METHODS if applies(m, params)]
    runnable = [s for s in specs if s[0] != "raw"]
    results = {}
    for name, scorer in scorers.items():
        print(f"{name}: {len(specs)} runs", file=sys.stderr, flush=True)
        results[name] = scorer([("raw", lambda s: s), *runnable])  # type: ignore[list-item]
    return results, rows


def markdown(results: dict[str, dict[str, float]], rows: list[Any]) -> str:
    sets = list(results)

    def cell(name: str, label: str) -> str:
        v = results[name].get(label)
        return "–" if v is None or not math.isfinite(v) else f"{v:.2f}"

    lines = [
        "Pooled RMSE against the truth, cm, with one parameter changed from its default "
        "(both methods alike):",
        "",
        "| | " + " | ".join(sets) + " |",
        "|---|" + "---|" * len(sets),
    ]
    lines += [f"| {ref} | " + " | ".join(cell(s, ref) for s in sets) + " |"
              for ref in ("raw", "kf+rts")]  # fmt: skip
    lines += [
        "",
        "| parameter | value | " + " | ".join(f"{s} {m}" for s in sets for m in METHODS) + " |",
        "|---|---|" + "---|" * (len(sets) * len(METHODS)),
    ]
    for i, (name, shown, _) in enumerate(rows):
        cells = [cell(s, f"{m}#{i}") for s in sets for m in METHODS]
        lines.append(f"| {name} | {shown} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--seeds", type=int, default=5)
    args = ap.parse_args(argv)
    data = Path(args.data)
    keraal = sorted(glob.glob(str(data / "keraal" / "G3-Kinect-*-P1T1-Unknown-C-0.txt")))
    positions = data / "ui-prmd" / "Segmented Movements" / "Kinect" / "Positions"
    uiprmd = sorted(glob.glob(str(positions / "m0*_s01_e0*_positions.txt.gz")))
    if len(keraal) != 3 or len(uiprmd) != 9:
        print(f"{data}: expected 3 KERAAL and 9 UI-PRMD recordings, found {len(keraal)} "
              f"and {len(uiprmd)}", file=sys.stderr)  # fmt: skip
        return 2
    scorers = {
        "KERAAL": keraal_uiprmd(keraal, ("-Kinect-", "-Vicon-")),
        "UI-PRMD": keraal_uiprmd(uiprmd, ("/Kinect/", "/Vicon/")),
        "synthetic": synthetic(args.seeds),
    }
    with np.errstate(all="ignore"):
        results, rows = sweep(scorers)
    print(markdown(results, rows), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
