"""What the 2020 paper printed: the one place its published numbers live.

Loumponias et al. (2020), "An Improved Tobit Kalman Filter with Adaptive Censoring
Limits", Circuits, Systems, and Signal Processing. Transcribed from the paper to the
decimals it prints; each constant names its equation or table. The reproductions
(:mod:`tobitkf.paper.covariance`, :mod:`tobitkf.paper.oscillator`) print these next to
what they measure. Nothing here is computed.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "PAPER_DECIMALS",
    "PAPER_EQ23_MONTE_CARLO",
    "PAPER_EQ23_SAMPLES",
    "PAPER_EQ24_EXACT",
    "PAPER_EQ25_STANDARD_TKF",
    "PAPER_TABLE1_RMSE",
    "PAPER_TABLE2_NCI",
]

#: decimals the paper prints in eq. 23-25 and Tables 1-2
PAPER_DECIMALS = 4

# --- section 3.4, the illustrative example ------------------------------------------------
#: eq. 23, R_s: Monte Carlo (mean of 100 sample covariances of 10^5 draws each)
PAPER_EQ23_MONTE_CARLO = np.array(
    [[0.4648, 0.6962, 0.5083], [0.6962, 4.7754, 1.9195], [0.5083, 1.9195, 1.4384]]
)
#: draws behind eq. 23 (100 × 10^5, text before eq. 23)
PAPER_EQ23_SAMPLES = 10_000_000
#: eq. 24, R_{k,2}: exact censored covariance (eq. 21, the proposed TKF^c)
PAPER_EQ24_EXACT = np.array(
    [[0.4651, 0.6962, 0.5085], [0.6962, 4.7747, 1.9189], [0.5085, 1.9189, 1.4379]]
)
#: eq. 25, R*_{k,2}: the standard TKF's matrix (eq. 22)
PAPER_EQ25_STANDARD_TKF = np.array(
    [[0.2724, 0.4719, 0.5151], [0.4719, 5.0000, 3.2744], [0.5151, 3.2744, 3.2002]]
)

# --- section 4.1, the oscillator ------------------------------------------------------------
#: Table 1: mean RMSE of (x̂1, x̂2) over 100 runs
PAPER_TABLE1_RMSE: dict[str, tuple[float, float]] = {
    "tkf": (0.4434, 0.5464),
    "tkfc": (0.4066, 0.5192),
}
#: Table 2: mean NCI (eq. 39, with the absolute value as printed)
PAPER_TABLE2_NCI: dict[str, float] = {"tkf": 1.1760, "tkfc": 0.9898}
