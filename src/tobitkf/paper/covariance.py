"""The illustrative covariance example of Loumponias et al. (2020), section 3.4.

The paper compares three 3×3 covariance matrices of a clipped normal vector
``y = clip(Y*, a, b)`` with ``Y* ~ N(m, S)``:

- eq. 23, ``R_s``: a Monte Carlo estimate (mean of 100 sample covariances of 10^5 draws);
- eq. 24, ``R_{k,2}``: the proposed exact censored covariance (eq. 21, TKF^c);
- eq. 25, ``R*_{k,2}``: the standard TKF's matrix (eq. 22, Allik 2016),
  ``P_un H P H' P_un + R*`` with ``R*_ii = R_ii v_T`` and the probabilities computed with
  the measurement-noise variance ``R_ii`` only.

The example sets ``m = (2, 2, 3)``, ``P⁻ = [[4,3,4],[3,4,4],[4,4,4]]`` (the "bracket"
matrix), ``H = R = I`` and ``S = H P⁻ H' + R``, with limits ``a = (-1, -3, 1)`` and
``b = (1, 7, 4)``. The bracket matrix is **not** a covariance matrix (its eigenvalues are
about -0.35, 1 and 11.35), but ``S = bracket + I`` is positive definite, so the clipped
distribution is well defined (MATH.md §5).

:func:`covariance_example` computes all three matrices and returns them next to the
paper's printed values. The oscillator experiment of section 4.1 lives in
:mod:`tobitkf.paper.oscillator`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tobitkf.paper.oscillator import (
    OscillatorConfig,
    OscillatorResult,
    noncredibility_index,
    oscillator_experiment,
    simulate_oscillator,
)
from tobitkf.paper.published import (
    PAPER_EQ23_MONTE_CARLO,
    PAPER_EQ24_EXACT,
    PAPER_EQ25_STANDARD_TKF,
    PAPER_TABLE1_RMSE,
    PAPER_TABLE2_NCI,
)

__all__ = [
    "EXAMPLE_BRACKET",
    "EXAMPLE_LOWER",
    "EXAMPLE_MEAN",
    "EXAMPLE_UPPER",
    "PAPER_EQ23_MONTE_CARLO",
    "PAPER_EQ24_EXACT",
    "PAPER_EQ25_STANDARD_TKF",
    "PAPER_TABLE1_RMSE",
    "PAPER_TABLE2_NCI",
    "CovarianceExample",
    "OscillatorConfig",
    "OscillatorResult",
    "covariance_example",
    "monte_carlo_clipped_covariance",
    "noncredibility_index",
    "oscillator_experiment",
    "simulate_oscillator",
    "standard_tkf_covariance",
]

# --- the example's inputs (Loumponias et al. 2020, section 3.4, text before eq. 23) -------
#: latent mean m_k = H (2, 2, 3)'
EXAMPLE_MEAN = np.array([2.0, 2.0, 3.0])
#: the bracket matrix, used as P⁻ (not positive semi-definite: eigenvalues -0.35, 1, 11.35)
EXAMPLE_BRACKET = np.array([[4.0, 3.0, 4.0], [3.0, 4.0, 4.0], [4.0, 4.0, 4.0]])
#: lower censoring limits a
EXAMPLE_LOWER = np.array([-1.0, -3.0, 1.0])
#: upper censoring limits b
EXAMPLE_UPPER = np.array([1.0, 7.0, 4.0])


def standard_tkf_covariance(
    mean: np.ndarray,
    P: np.ndarray,
    H: np.ndarray,
    R: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
) -> np.ndarray:
    """Standard TKF covariance of the censored measurement (Allik 2016; 2020 paper eq. 22).

    ``P_un H P H' P_un + R*`` where ``P_un = diag(Φ(β*_i) - Φ(α*_i))`` and
    ``R*_ii = R_ii v_T(α*_i, β*_i)``, with ``α*_i = (a_i - m_i)/√R_ii`` and
    ``β*_i = (b_i - m_i)/√R_ii`` (eq. 18–19: only the measurement noise, not ``S``).

    Parameters
    ----------
    mean : (p,) predicted measurement ``m = H x⁻``.
    P : (n, n) predicted state covariance ``P⁻``.
    H : (p, n) observation matrix.
    R : (p, p) measurement-noise covariance (only its diagonal is used for ``R*``).
    lower, upper : (p,) censoring limits.

    Returns
    -------
    (p, p) ndarray
    """
    from tobitkf.core.censored import truncated_standard_normal

    mean = np.asarray(mean, dtype=float)
    H = np.atleast_2d(np.asarray(H, dtype=float))
    P = np.atleast_2d(np.asarray(P, dtype=float))
    R = np.atleast_2d(np.asarray(R, dtype=float))
    r = np.sqrt(np.diag(R))
    alpha = (np.asarray(lower, dtype=float) - mean) / r
    beta = (np.asarray(upper, dtype=float) - mean) / r
    stats = truncated_standard_normal(alpha, beta)
    p_un = np.asarray(stats.p_uncensored, dtype=float)
    r_star = np.diag(np.diag(R) * np.asarray(stats.v_t, dtype=float))
    D = np.diag(p_un)
    return D @ H @ P @ H.T @ D + r_star


def monte_carlo_clipped_covariance(
    mean: np.ndarray,
    cov: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    *,
    samples: int = 1_000_000,
    seed: int | None = 0,
    chunk: int = 250_000,
) -> tuple[np.ndarray, np.ndarray]:
    """Monte Carlo covariance of ``clip(Y, a, b)``, ``Y ~ N(mean, cov)``, with standard errors.

    The standard error of entry ``(i, j)`` is ``sd[(y_i - ȳ_i)(y_j - ȳ_j)] / √N`` (the
    delta-method error of a sample covariance; the error of the mean is of smaller order).

    Parameters
    ----------
    mean : (p,); cov : (p, p) positive definite; lower, upper : (p,).
    samples : number of draws N (the paper used 100 × 10^5).
    seed : seed of ``numpy.random.default_rng``.
    chunk : draws generated at once (bounds memory).

    Returns
    -------
    cov_hat : (p, p) sample covariance (divisor N - 1).
    se : (p, p) standard errors of ``cov_hat``.
    """
    if samples < 2:
        raise ValueError(f"samples must be >= 2, got {samples}")
    mean = np.asarray(mean, dtype=float)
    cov = np.asarray(cov, dtype=float)
    lower = np.asarray(lower, dtype=float)
    upper = np.asarray(upper, dtype=float)
    p = mean.shape[-1]
    L = np.linalg.cholesky(cov)
    rng = np.random.default_rng(seed)
    start_state = rng.bit_generator.state

    def draws():
        done = 0
        while done < samples:
            m = min(chunk, samples - done)
            yield np.clip(mean + rng.standard_normal((m, p)) @ L.T, lower, upper)
            done += m

    # two passes over the same stream (the generator is rewound): the mean first, then
    # the centred second and fourth moments, so nothing cancels catastrophically.
    total = np.zeros(p)
    for y in draws():
        total += y.sum(axis=0)
    n = float(samples)
    mu = total / n
    rng.bit_generator.state = start_state
    second = np.zeros((p, p))
    fourth = np.zeros((p, p))
    for y in draws():
        d = y - mu
        outer = d[:, :, None] * d[:, None, :]
        second += outer.sum(axis=0)
        fourth += (outer**2).sum(axis=0)
    cov_hat = second / (n - 1.0)
    var_prod = np.maximum(fourth / n - (second / n) ** 2, 0.0)
    se = np.sqrt(var_prod / n)
    return cov_hat, se


def _format_matrix(M: np.ndarray, decimals: int = 4) -> list[str]:
    return ["  [" + "  ".join(f"{v: .{decimals}f}" for v in row) + " ]" for row in M]


@dataclass(frozen=True)
class CovarianceExample:
    """Result of :func:`covariance_example` (2020 paper, section 3.4, eq. 23–25).

    Attributes
    ----------
    exact : (3, 3) exact censored covariance (eq. 21/24).
    standard_tkf : (3, 3) standard TKF matrix (eq. 22/25).
    monte_carlo : (3, 3) Monte Carlo estimate (eq. 23).
    monte_carlo_se : (3, 3) standard errors of ``monte_carlo``.
    paper : dict ``{"eq23_monte_carlo", "eq24_exact", "eq25_standard_tkf"}`` of (3, 3).
    bracket_eigenvalues : (3,) eigenvalues of the bracket matrix (one is negative).
    s_eigenvalues : (3,) eigenvalues of ``S = bracket + I`` (all positive).
    samples, seed : Monte Carlo settings.
    """

    exact: np.ndarray
    standard_tkf: np.ndarray
    monte_carlo: np.ndarray
    monte_carlo_se: np.ndarray
    paper: dict[str, np.ndarray]
    bracket_eigenvalues: np.ndarray
    s_eigenvalues: np.ndarray
    samples: int
    seed: int | None
    inputs: dict[str, Any] = field(default_factory=dict)

    @property
    def differences(self) -> dict[str, np.ndarray]:
        """Measured minus printed, and Monte Carlo minus exact, each (3, 3)."""
        return {
            "exact_minus_eq24": self.exact - self.paper["eq24_exact"],
            "standard_tkf_minus_eq25": self.standard_tkf - self.paper["eq25_standard_tkf"],
            "monte_carlo_minus_eq23": self.monte_carlo - self.paper["eq23_monte_carlo"],
            "monte_carlo_minus_exact": self.monte_carlo - self.exact,
            "eq23_minus_exact": self.paper["eq23_monte_carlo"] - self.exact,
        }

    @property
    def max_z_monte_carlo(self) -> float:
        """Largest ``|MC - exact| / SE`` over the entries."""
        return float(np.max(np.abs(self.monte_carlo - self.exact) / self.monte_carlo_se))

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form (keys ``exact``, ``standard_tkf``, ``monte_carlo``,
        ``monte_carlo_se``, ``paper``, plus differences and eigenvalues)."""
        return {
            "exact": self.exact.tolist(),
            "standard_tkf": self.standard_tkf.tolist(),
            "monte_carlo": self.monte_carlo.tolist(),
            "monte_carlo_se": self.monte_carlo_se.tolist(),
            "paper": {k: v.tolist() for k, v in self.paper.items()},
            "differences": {k: v.tolist() for k, v in self.differences.items()},
            "max_abs_z_monte_carlo_vs_exact": self.max_z_monte_carlo,
            "bracket_eigenvalues": self.bracket_eigenvalues.tolist(),
            "bracket_is_positive_semidefinite": bool(self.bracket_eigenvalues.min() >= 0),
            "s_eigenvalues": self.s_eigenvalues.tolist(),
            "samples": self.samples,
            "seed": self.seed,
            "inputs": {k: np.asarray(v).tolist() for k, v in self.inputs.items()},
        }

    def format_text(self) -> str:
        """Human-readable report for the terminal."""
        ev = self.bracket_eigenvalues
        d = self.differences
        lines = [
            "Covariance example, Loumponias et al. 2020, section 3.4 (eq. 23-25)",
            "  m = (2, 2, 3), a = (-1, -3, 1), b = (1, 7, 4), H = R = I,",
            "  S = bracket + I, bracket = [[4,3,4],[3,4,4],[4,4,4]]",
            f"  NOTE: the bracket matrix is NOT positive semi-definite: eigenvalues "
            f"{ev[0]:.4f}, {ev[1]:.4f}, {ev[2]:.4f}.",
            "  It is used as P⁻ in eq. 25 exactly as printed; S = bracket + I is positive "
            f"definite (eigenvalues {', '.join(f'{v:.4f}' for v in self.s_eigenvalues)}).",
            "",
            "Exact censored covariance (eq. 21), measured:",
            *_format_matrix(self.exact, 6),
            "  paper eq. 24:",
            *_format_matrix(self.paper["eq24_exact"]),
            f"  difference (max |.| = {np.abs(d['exact_minus_eq24']).max():.2e}):",
            *_format_matrix(d["exact_minus_eq24"], 6),
            "",
            "Standard TKF matrix (eq. 22, P = bracket, H = R = I), measured:",
            *_format_matrix(self.standard_tkf, 6),
            "  paper eq. 25:",
            *_format_matrix(self.paper["eq25_standard_tkf"]),
            f"  difference (max |.| = {np.abs(d['standard_tkf_minus_eq25']).max():.2e}):",
            *_format_matrix(d["standard_tkf_minus_eq25"], 6),
            "",
            f"Monte Carlo covariance ({self.samples} draws, seed {self.seed}), measured:",
            *_format_matrix(self.monte_carlo, 6),
            "  standard errors:",
            *_format_matrix(self.monte_carlo_se, 6),
            "  paper eq. 23:",
            *_format_matrix(self.paper["eq23_monte_carlo"]),
            f"  MC - exact: max |z| = {self.max_z_monte_carlo:.2f} standard errors",
            "  paper eq. 23 - exact (the paper's own MC error):",
            *_format_matrix(d["eq23_minus_exact"], 6),
        ]
        return "\n".join(lines)


def covariance_example(*, samples: int = 1_000_000, seed: int | None = 0) -> CovarianceExample:
    """Reproduce the illustrative example of the 2020 paper, section 3.4 (eq. 23–25).

    Parameters
    ----------
    samples : Monte Carlo draws (the paper used 100 × 10^5 = 10^7).
    seed : Monte Carlo seed.

    Returns
    -------
    CovarianceExample
    """
    from tobitkf.core.censored import clipped_normal_moments

    H = np.eye(3)
    R = np.eye(3)
    m = H @ EXAMPLE_MEAN
    S = H @ EXAMPLE_BRACKET @ H.T + R
    exact = np.asarray(clipped_normal_moments(m, S, EXAMPLE_LOWER, EXAMPLE_UPPER).cov)
    standard = standard_tkf_covariance(m, EXAMPLE_BRACKET, H, R, EXAMPLE_LOWER, EXAMPLE_UPPER)
    mc, se = monte_carlo_clipped_covariance(
        m, S, EXAMPLE_LOWER, EXAMPLE_UPPER, samples=samples, seed=seed
    )
    return CovarianceExample(
        exact=exact,
        standard_tkf=standard,
        monte_carlo=mc,
        monte_carlo_se=se,
        paper={
            "eq23_monte_carlo": PAPER_EQ23_MONTE_CARLO.copy(),
            "eq24_exact": PAPER_EQ24_EXACT.copy(),
            "eq25_standard_tkf": PAPER_EQ25_STANDARD_TKF.copy(),
        },
        bracket_eigenvalues=np.linalg.eigvalsh(EXAMPLE_BRACKET),
        s_eigenvalues=np.linalg.eigvalsh(S),
        samples=int(samples),
        seed=seed,
        inputs={"mean": m, "S": S, "lower": EXAMPLE_LOWER, "upper": EXAMPLE_UPPER},
    )
