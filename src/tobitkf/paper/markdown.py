"""The reproductions as Markdown: what ``tobitkf reproduce ... --markdown`` and ``tobitkf
fit --markdown`` print, and what ``make docs-results`` puts into docs/reproduction.md.

Ours next to the paper's printed values (:mod:`tobitkf.paper.published`); every sentence
with a number is computed from the result it describes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from tobitkf.evaluation.markdown import _table
from tobitkf.paper.published import (
    PAPER_DECIMALS,
    PAPER_EQ23_SAMPLES,
    PAPER_TABLE1_RMSE,
    PAPER_TABLE2_NCI,
)

if TYPE_CHECKING:  # pragma: no cover
    from tobitkf.paper.covariance import CovarianceExample
    from tobitkf.paper.likelihood import RecoveryStudy
    from tobitkf.paper.oscillator import OscillatorResult

__all__ = [
    "covariance_markdown",
    "noise_fit_markdown",
    "oscillator_markdown",
    "recovery_markdown",
]

_LABELS = {"tkf": "TKF", "tkfc": "TKF^c", "kf": "KF (ignores censoring)"}
#: half a unit in the last printed decimal: "agrees to the printed decimals"
_PRINTED = 0.5 * 10.0**-PAPER_DECIMALS + 1e-12


def _matrix(M: np.ndarray, digits: int) -> str:
    """A symmetric matrix as its upper triangle, the lower one dotted."""
    rows = [
        ", ".join("·" if j < i else f"{M[i, j]:.{digits}f}" for j in range(M.shape[1]))
        for i in range(M.shape[0])
    ]
    return "`[" + ", ".join(f"[{r}]" for r in rows) + "]`"


def _entry(D: np.ndarray) -> str:
    i, j = np.unravel_index(int(np.argmax(np.abs(D))), D.shape)
    return f"{abs(D[i, j]):.2g} at entry ({i + 1}, {j + 1})"


def _count(n: int) -> str:
    return f"{n:,}".replace(",", " ")


def covariance_markdown(ex: CovarianceExample) -> str:
    """Eq. 23–25 next to ours, then what the differences say."""
    d = ex.differences
    p = ex.paper
    agree = {k: int(np.sum(np.abs(d[k]) <= _PRINTED)) for k in d}
    head = ["matrix", "ours", "paper", "max abs. difference"]
    rows = [
        [
            "exact censored covariance (eq. 21) vs eq. 24",
            _matrix(ex.exact, 6),
            _matrix(p["eq24_exact"], PAPER_DECIMALS),
            f"{np.abs(d['exact_minus_eq24']).max():.1e}",
        ],
        [
            "standard TKF `P_un H P H' P_un + R*` (eq. 22) vs eq. 25",
            _matrix(ex.standard_tkf, 6),
            _matrix(p["eq25_standard_tkf"], PAPER_DECIMALS),
            f"{np.abs(d['standard_tkf_minus_eq25']).max():.1e}",
        ],
        [
            f"Monte Carlo, {_count(ex.samples)} draws, seed {ex.seed}, vs eq. 23",
            _matrix(ex.monte_carlo, 6),
            _matrix(p["eq23_monte_carlo"], PAPER_DECIMALS),
            f"{np.abs(d['monte_carlo_minus_eq23']).max():.1e}",
        ],
    ]
    # the standard error the paper's own 10^7 draws would have, scaled from ours
    se_paper = ex.monte_carlo_se * math.sqrt(ex.samples / PAPER_EQ23_SAMPLES)
    z_paper = float(np.max(np.abs(d["eq23_minus_exact"]) / se_paper))
    ev, sv = ex.bracket_eigenvalues, ex.s_eigenvalues
    out = _table(head, rows)
    out += [
        "",
        f"- Eq. 24 agrees with our exact matrix to its {PAPER_DECIMALS} printed decimals in "
        f"{agree['exact_minus_eq24']} of 9 entries; eq. 25 with our standard TKF matrix in "
        f"{agree['standard_tkf_minus_eq25']} of 9.",
        f"- Standard errors of our Monte Carlo: {_matrix(ex.monte_carlo_se, 5)}; it is within "
        f"{ex.max_z_monte_carlo:.1f} standard errors of the exact matrix.",
        "- The paper's Monte Carlo (eq. 23) minus the exact matrix: largest "
        f"{_entry(d['eq23_minus_exact'])}, {z_paper:.1f} standard errors of "
        f"{_count(PAPER_EQ23_SAMPLES)} draws (ours scaled by √(N / {_count(PAPER_EQ23_SAMPLES)})).",
        "- The standard TKF's matrix minus the exact one: largest "
        f"{_entry(ex.standard_tkf - ex.exact)}.",
        "- Eigenvalues of the bracket matrix: "
        + ", ".join(f"{v:.4f}" for v in ev)
        + "; of S = bracket + I: "
        + ", ".join(f"{v:.4f}" for v in sv)
        + ".",
    ]
    return "\n".join(out) + "\n"


def _spread(v: np.ndarray, digits: int = 4) -> str:
    if v.size < 2:
        return f"{v.mean():.{digits}f}"
    return (
        f"{v.mean():.{digits}f} ± {v.std(ddof=1):.{digits}f} "
        f"[{v.min():.{digits}f}, {v.max():.{digits}f}]"
    )


def oscillator_markdown(res: OscillatorResult, transient: int = 100) -> str:
    """Tables 1 and 2 (paper, our first seed, our spread over the seeds), the seed counts,
    and NCI averaged after the first ``transient`` steps."""
    c = res.config
    seeds = res.seeds
    many = len(seeds) > 1  # [column] * many: the spread columns only with several seeds
    s0 = f"seed {seeds[0]}"
    over = f"over seeds {seeds[0]}–{seeds[-1]}"
    start = "drawn from N(x0, P0) per run" if c.random_x0 else "fixed at x0 = (5, 0)"
    out = [
        f"Oscillator (section 4.1): {c.runs} runs × {c.steps} steps, measurement-noise "
        f"variance {c.r}, Q = {c.q}² I, limits [{c.lower}, {c.upper}], true initial state "
        f"{start}; {100 * res.clipped_fraction:.1f} % of the measurements clipped ({s0}).",
        "",
        "Table 1, mean RMSE:",
        "",
    ]
    head = ["filter"]
    for x in ("x1", "x2"):
        head += [f"{x} paper", f"{x} {s0}"] + ([f"{x} {over} (mean ± sd [min, max])"] * many)
    rows = []
    for name in res.metrics:
        row = [_LABELS[name]]
        for i, x in enumerate(("rmse_x1", "rmse_x2")):
            paper = PAPER_TABLE1_RMSE.get(name)
            row += [f"{paper[i]:.4f}" if paper else "–", f"{res.metrics[name][x]:.4f}"]
            row += [_spread(res.per_seed[name][x])] * many
        rows.append(row)
    out += _table(head, rows)
    if many:
        z = [
            f"{_LABELS[n]} {x} {(PAPER_TABLE1_RMSE[n][i] - v.mean()) / v.std(ddof=1):+.1f}"
            for n in PAPER_TABLE1_RMSE
            for i, x in enumerate(("x1", "x2"))
            for v in [res.per_seed[n][f"rmse_{x}"]]
        ]
        out += [
            "",
            "Paper minus our mean over seeds, in standard deviations of our seed-to-seed "
            "spread: " + "; ".join(z) + ".",
        ]
    late = c.steps > 2 * transient
    head = ["filter", "paper (eq. 39)", f"abs, {s0}"] + [f"abs {over}"] * many
    head += [f"signed, {s0}"] + [f"signed {over}"] * many
    head += [f"abs, {s0}, k > {transient}", f"signed, {s0}, k > {transient}"] * late
    rows = []
    for name in res.metrics:
        m, ps = res.metrics[name], res.per_seed[name]
        paper = PAPER_TABLE2_NCI.get(name)
        row = [_LABELS[name], f"{paper:.4f}" if paper is not None else "–"]
        row += [f"{m['nci_abs']:.4f}"] + [_spread(ps["nci_abs"])] * many
        row += [f"{m['nci_signed']:.4f}"] + [_spread(ps["nci_signed"])] * many
        if late:
            row += [f"{res.nci_k[name][f][transient:].mean():.4f}" for f in ("abs", "signed")]
        rows.append(row)
    out += ["", "Table 2, mean NCI (eq. 39–40; abs: as printed, signed: Li & Zhao):", ""]
    out += _table(head, rows)
    beats = res.tkfc_beats_tkf()
    n = len(seeds)
    out += [
        "",
        f"TKF^c below TKF in {beats['rmse_x1']} of {n} seeds for the RMSE of x1, "
        f"{beats['rmse_x2']} of {n} for x2, {beats['nci_abs']} of {n} for NCI (abs).",
    ]
    return "\n".join(out) + "\n"


def recovery_markdown(study: RecoveryStudy) -> str:
    """The simulation study of the likelihood fits: truth, mean ± sd, bias, stderr."""
    from tobitkf.paper.likelihood import ESTIMATES

    c = study.config
    s = study.seeds
    seeds = f"seeds {s[0]}–{s[-1]}" if len(s) > 1 else f"seed {s[0]}"
    clip = study.clipped
    clip_sd = f" ± {100 * clip.std(ddof=1):.1f} %" if clip.size > 1 else ""
    out = [
        f"Scalar AR(1) `x_k = {c.a} x_(k-1) + w_k`, q = {c.q}, r = {c.r}, limits "
        f"({c.lower}, {c.upper}), {c.sequences} sequences × {c.steps} steps per data set; "
        f"{len(s)} simulated data sets ({seeds}); clipped {100 * clip.mean():.1f} %{clip_sd}.",
        "",
    ]
    rows = []
    for key, r in study.summary().items():
        sd = f" ± {r['sd']:.4f}" if math.isfinite(r["sd"]) else ""
        rows.append(
            [
                ESTIMATES[key][0],
                f"{r['truth']:g}",
                f"{r['mean']:.4f}{sd}",
                f"{round(100 * r['bias']):+d} %",  # no "-0 %"
                f"{r['mean_stderr']:.4f}" if math.isfinite(r["mean_stderr"]) else "",
            ]
        )
    head = ["estimate", "truth", "mean ± sd over data sets", "bias", "mean reported stderr"]
    out += _table(head, rows)
    return "\n".join(out) + "\n"


def _scalar(M: Any) -> str:
    """A fitted covariance in one cell: its value when it is a multiple of I, else diag."""
    M = np.asarray(M, dtype=float)
    d = np.diag(M)
    if np.allclose(M, d[0] * np.eye(len(d)), rtol=1e-12, atol=0):
        return f"{d[0]:.2e}"
    return "diag(" + ", ".join(f"{v:.2e}" for v in d) + ")"


def noise_fit_markdown(fits: Sequence[tuple[str, Any]]) -> str:
    """One row per fit (``(label, NoiseFit)``): likelihood, Q, its standard error, R,
    log-likelihood and the optimiser's note when it is not a plain convergence."""
    rows = []
    for label, f in fits:
        se = f.stderr.get("Q")
        se_txt = _scalar(se) if se is not None and np.all(np.isfinite(se)) else "–"
        note = "" if "at the search bound" not in f.message else "R or Q at the search bound"
        rows.append(
            [
                label,
                f.form,
                _scalar(f.Q),
                se_txt,
                _scalar(f.R) + (" (fitted)" if f.fit_r else " (fixed)"),
                f"{f.loglik:.1f}",
                note or ("converged" if f.success else "not converged"),
            ]
        )
    head = ["recording", "likelihood", "Q (m²)", "± stderr", "R (m²)", "log-likelihood", "note"]
    out = ["Q and R: position variances in m² (Q per frame step of the recording).", ""]
    return "\n".join(out + _table(head, rows)) + "\n"
