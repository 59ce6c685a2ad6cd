"""Figures of the papers' synthetic experiments (PNG files; matplotlib imported lazily).

- :func:`oscillator_figures`: Fig. 2 (per-run RMSE difference TKF − TKF^c) and Fig. 3
  (NCI(k) over time) of the 2020 paper, from an :class:`OscillatorResult`.
- :func:`covariance_example_figure`: the three covariance matrices of eq. 23–25 next to
  the paper's, as heat maps of the differences.

Each function takes an output directory, creates it if needed, writes PNG files and
returns their paths.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from tobitkf.paper.covariance import CovarianceExample
    from tobitkf.paper.oscillator import OscillatorResult

__all__ = ["covariance_example_figure", "oscillator_figures"]


def _pyplot():
    try:
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("figures need matplotlib: pip install 'tobitkf[plot]'") from exc
    return plt


def oscillator_figures(result: OscillatorResult, out_dir: str | Path) -> list[Path]:
    """Write ``oscillator_fig2_rmse_difference.png`` and ``oscillator_fig3_nci.png``.

    Fig. 2: per run, RMSE(TKF) − RMSE(TKF^c) of x1 and x2 (positive = TKF^c better).
    Fig. 3: NCI(k) over time for TKF, TKF^c and the KF, the paper's absolute-value form
    (eq. 39) on top and the textbook signed form below.

    Parameters
    ----------
    result : an :class:`~tobitkf.paper.oscillator.OscillatorResult`.
    out_dir : output directory (created if missing).

    Returns
    -------
    list of the two written paths.
    """
    plt = _pyplot()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    seed = result.seeds[0]

    diff = result.rmse_runs["tkf"] - result.rmse_runs["tkfc"]  # (M, 2)
    runs = np.arange(1, diff.shape[0] + 1)
    fig, axes = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    for i, ax in enumerate(axes):
        ax.bar(runs, diff[:, i], color=np.where(diff[:, i] >= 0, "tab:blue", "tab:red"))
        ax.axhline(0.0, color="black", lw=0.8)
        ax.set_ylabel(f"RMSE x{i + 1}: TKF − TKF^c")
        ax.set_title(
            f"x{i + 1}: mean difference {diff[:, i].mean():.4f}, "
            f"TKF^c better in {(diff[:, i] > 0).sum()}/{diff.shape[0]} runs",
            fontsize=9,
        )
    axes[-1].set_xlabel("run")
    fig.suptitle(f"Oscillator, Fig. 2 of Loumponias et al. 2020 (seed {seed})", fontsize=10)
    fig.tight_layout()
    fig2 = out / "oscillator_fig2_rmse_difference.png"
    fig.savefig(fig2, dpi=120)
    plt.close(fig)

    labels = {"tkf": "TKF", "tkfc": "TKF^c", "kf": "KF"}
    fig, axes = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True)
    for ax, form, title in (
        (axes[0], "abs", "NCI(k), |log| as printed (eq. 39)"),
        (axes[1], "signed", "NCI(k), signed (textbook)"),
    ):
        for name, series in result.nci_k.items():
            k = np.arange(1, series[form].shape[0] + 1)
            ax.plot(
                k,
                series[form],
                lw=0.8,
                label=f"{labels.get(name, name)} (mean {series[form].mean():.3f})",
            )
        ax.axhline(0.0, color="black", lw=0.6)
        ax.set_title(title, fontsize=9)
        ax.set_ylabel("NCI")
        ax.legend(fontsize=8)
    axes[-1].set_xlabel("time step k")
    fig.suptitle(f"Oscillator, Fig. 3 of Loumponias et al. 2020 (seed {seed})", fontsize=10)
    fig.tight_layout()
    fig3 = out / "oscillator_fig3_nci.png"
    fig.savefig(fig3, dpi=120)
    plt.close(fig)
    return [fig2, fig3]


def covariance_example_figure(result: CovarianceExample, out_dir: str | Path) -> list[Path]:
    """Write ``covariance_example.png``: measured matrices and their differences from the
    paper's eq. 23–25 as annotated heat maps.

    Returns
    -------
    list with the written path.
    """
    plt = _pyplot()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    d = result.differences
    panels = [
        ("exact (eq. 21)", result.exact, "{:.4f}"),
        ("standard TKF (eq. 22)", result.standard_tkf, "{:.4f}"),
        (f"Monte Carlo, N={result.samples}", result.monte_carlo, "{:.4f}"),
        ("exact − paper eq. 24", d["exact_minus_eq24"], "{:.1e}"),
        ("std TKF − paper eq. 25", d["standard_tkf_minus_eq25"], "{:.1e}"),
        ("(MC − exact) / SE", d["monte_carlo_minus_exact"] / result.monte_carlo_se, "{:.2f}"),
    ]
    fig, axes = plt.subplots(2, 3, figsize=(10, 6.5))
    for ax, (title, M, fmt) in zip(axes.ravel(), panels):
        lim = float(np.max(np.abs(M))) or 1.0
        ax.imshow(M, cmap="coolwarm", vmin=-lim, vmax=lim)
        for i in range(M.shape[0]):
            for j in range(M.shape[1]):
                ax.text(j, i, fmt.format(M[i, j]), ha="center", va="center", fontsize=8)
        ax.set_title(title, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    ev = result.bracket_eigenvalues
    fig.suptitle(
        "Covariance example, Loumponias et al. 2020 §3.4; bracket matrix eigenvalues "
        f"{ev[0]:.3f}, {ev[1]:.3f}, {ev[2]:.3f} (not PSD)",
        fontsize=10,
    )
    fig.tight_layout()
    path = out / "covariance_example.png"
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return [path]
