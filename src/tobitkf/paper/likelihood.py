"""Does maximum likelihood recover the noise of a censored series? (2020 paper eq. 26–29)

A simulation study on a scalar AR(1) observed through a clipping sensor::

    x_k = a x_{k-1} + w_k,  w ~ N(0, q);   y*_k = x_k + v_k,  v ~ N(0, r)
    y_k = clip(y*_k, lower, upper),        x_0 ~ N(0, q / (1 - a²)) (stationary)

Each simulated data set (``sequences`` independent series of ``steps`` samples, one
shared q) is fitted five ways with :func:`tobitkf.core.likelihood.fit_noise`: q with the
corrected (TKF^c, eq. 27) likelihood and r known; q and r jointly with it; q with the
standard TKF likelihood (eq. 29); q with the plain Gaussian (Kalman) likelihood that
ignores the censoring. :func:`likelihood_recovery` repeats this over data sets with
consecutive seeds; the spread between data sets is what the reported standard errors
should match. The paper prints no such study, so there is no paper column.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "ESTIMATES",
    "RecoveryConfig",
    "RecoveryStudy",
    "likelihood_recovery",
    "simulate_ar1",
]

#: what is estimated: key -> (label, the parameter's true value attribute)
ESTIMATES: dict[str, tuple[str, str]] = {
    "q_corrected": ("q, corrected (TKF^c) likelihood, r known", "q"),
    "q_joint": ("q, corrected, q and r jointly", "q"),
    "r_joint": ("r, corrected, q and r jointly", "r"),
    "q_standard": ("q, standard TKF likelihood (eq. 29), r known", "q"),
    "q_gaussian": ("q, plain Gaussian likelihood (censoring ignored), r known", "q"),
}


@dataclass(frozen=True)
class RecoveryConfig:
    """The simulated model and the size of one data set.

    Attributes
    ----------
    a : AR(1) coefficient.
    q, r : true process- and measurement-noise variances.
    lower, upper : clipping limits of the sensor.
    sequences, steps : independent series per data set, samples per series.
    """

    a: float = 0.95
    q: float = 0.1
    r: float = 0.1
    lower: float = -1.2
    upper: float = 0.7
    sequences: int = 20
    steps: int = 200

    def __post_init__(self) -> None:
        if not -1.0 < self.a < 1.0:
            raise ValueError(f"a must be in (-1, 1) (a stationary series), got {self.a}")
        if self.q <= 0 or self.r <= 0:
            raise ValueError(f"q and r must be > 0, got {self.q} and {self.r}")
        if not self.lower < self.upper:
            raise ValueError(f"need lower < upper, got {self.lower} and {self.upper}")
        if self.sequences < 1 or self.steps < 2:
            raise ValueError("need sequences >= 1 and steps >= 2")

    @property
    def stationary_variance(self) -> float:
        return self.q / (1.0 - self.a**2)

    def to_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def simulate_ar1(config: RecoveryConfig, seed: int) -> np.ndarray:
    """One data set, ``(steps, sequences, 1)`` clipped measurements.

    Draw order (fixed, so a seed reproduces exactly): the stationary initial states, then
    per step the process noise, then all measurement noise at once.
    """
    rng = np.random.default_rng(seed)
    B = config.sequences
    x = rng.standard_normal(B) * np.sqrt(config.stationary_variance)
    xs = np.empty((config.steps, B))
    for k in range(config.steps):
        x = config.a * x + np.sqrt(config.q) * rng.standard_normal(B)
        xs[k] = x
    y = xs + np.sqrt(config.r) * rng.standard_normal((config.steps, B))
    return np.clip(y, config.lower, config.upper)[..., None]


def _fit_one(config: RecoveryConfig, y: np.ndarray) -> dict[str, tuple[float, float]]:
    """The five estimates of one data set: ``{key: (estimate, reported stderr)}``."""
    from tobitkf.core.likelihood import fit_noise

    model = {
        "A": [[config.a]],
        "H": [[1.0]],
        "x0": [0.0],
        "P0": [[config.stationary_variance]],
    }
    lim = ([config.lower], [config.upper])
    known_r = [[config.r]]
    q = fit_noise(y, *lim, R=known_r, **model)
    qr = fit_noise(y, *lim, fit_r=True, **model)
    std = fit_noise(y, *lim, R=known_r, form="standard", compute_stderr=False, **model)
    gauss = fit_noise(y, R=known_r, form="gaussian", compute_stderr=False, **model)
    nan = float("nan")
    return {
        "q_corrected": (float(q.Q[0, 0]), float(q.stderr["Q"][0, 0])),
        "q_joint": (float(qr.Q[0, 0]), float(qr.stderr["Q"][0, 0])),
        "r_joint": (float(qr.R[0, 0]), float(qr.stderr["R"][0, 0])),
        "q_standard": (float(std.Q[0, 0]), nan),
        "q_gaussian": (float(gauss.Q[0, 0]), nan),
    }


@dataclass(frozen=True)
class RecoveryStudy:
    """Result of :func:`likelihood_recovery`.

    Attributes
    ----------
    config : the simulated model.
    seeds : one seed per data set.
    clipped : (K,) fraction of clipped samples per data set.
    estimates : ``{key: (K,)}`` per data set, keys of :data:`ESTIMATES`.
    stderr : ``{key: (K,)}`` reported standard errors (NaN where not computed).
    seconds : wall time.
    """

    config: RecoveryConfig
    seeds: tuple[int, ...]
    clipped: np.ndarray
    estimates: dict[str, np.ndarray]
    stderr: dict[str, np.ndarray] = field(repr=False)
    seconds: float = float("nan")

    def truth(self, key: str) -> float:
        return float(getattr(self.config, ESTIMATES[key][1]))

    def summary(self) -> dict[str, dict[str, float]]:
        """Per estimate: truth, mean, sd over data sets, relative bias, mean stderr."""
        out = {}
        for key, v in self.estimates.items():
            truth = self.truth(key)
            se = self.stderr[key]
            out[key] = {
                "truth": truth,
                "mean": float(v.mean()),
                "sd": float(v.std(ddof=1)) if v.size > 1 else float("nan"),
                "bias": float(v.mean() / truth - 1.0),
                "mean_stderr": float(se.mean()) if np.all(np.isfinite(se)) else float("nan"),
            }
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "config": self.config.to_dict(),
            "seeds": list(self.seeds),
            "clipped": self.clipped.tolist(),
            "estimates": {k: v.tolist() for k, v in self.estimates.items()},
            "stderr": {k: v.tolist() for k, v in self.stderr.items()},
            "summary": self.summary(),
            "seconds": self.seconds,
        }

    def format_text(self) -> str:
        c = self.config
        n = len(self.seeds)
        lines = [
            f"Maximum-likelihood recovery: AR(1) a = {c.a}, q = {c.q}, r = {c.r}, limits "
            f"({c.lower}, {c.upper}), {c.sequences} sequences x {c.steps} steps",
            f"  {n} data set{'s' * (n > 1)} (seeds {self.seeds[0]}..{self.seeds[-1]}), "
            f"clipped {100 * self.clipped.mean():.1f} %, time {self.seconds:.1f} s",
            "",
        ]
        for key, s in self.summary().items():
            sd = f" ± {s['sd']:.4f}" if np.isfinite(s["sd"]) else ""
            se = f", mean stderr {s['mean_stderr']:.4f}" if np.isfinite(s["mean_stderr"]) else ""
            lines.append(
                f"  {ESTIMATES[key][0]:<58} {s['mean']:.4f}{sd} "
                f"(truth {s['truth']:g}, bias {round(100 * s['bias']):+d} %{se})"
            )
        return "\n".join(lines)


def likelihood_recovery(
    *,
    datasets: int = 20,
    seed: int = 100,
    config: RecoveryConfig | None = None,
    progress: Callable[[int], None] | None = None,
) -> RecoveryStudy:
    """Simulate ``datasets`` data sets (seeds ``seed, seed + 1, ...``) and fit each five ways.

    Parameters
    ----------
    datasets : number of simulated data sets (at least 1; 2 for a spread).
    seed : seed of the first data set.
    config : the model (defaults: a = 0.95, q = r = 0.1, limits (-1.2, 0.7), 20 × 200).
    progress : called with the index of each data set once it is fitted.

    Returns
    -------
    RecoveryStudy
    """
    import time

    if datasets < 1:
        raise ValueError(f"datasets must be >= 1, got {datasets}")
    config = config or RecoveryConfig()
    t0 = time.perf_counter()
    seeds = tuple(int(seed) + i for i in range(datasets))
    clipped, rows = [], []
    for i, s in enumerate(seeds):
        y = simulate_ar1(config, s)
        clipped.append(float(np.mean((y <= config.lower) | (y >= config.upper))))
        rows.append(_fit_one(config, y))
        if progress is not None:
            progress(i)
    return RecoveryStudy(
        config=config,
        seeds=seeds,
        clipped=np.asarray(clipped),
        estimates={k: np.array([r[k][0] for r in rows]) for k in ESTIMATES},
        stderr={k: np.array([r[k][1] for r in rows]) for k in ESTIMATES},
        seconds=time.perf_counter() - t0,
    )
