"""The skeleton constants of the papers, each written once.

Loumponias et al. 2020 ("Adaptive Tobit Kalman-based tracking of the skeleton", §4–5)
and 2016 (the first ATKF). Everything else in the package reads them from here.
"""

from __future__ import annotations

from typing import Any

from numpy.typing import ArrayLike

__all__ = [
    "ATKF2016_C_HORIZONTAL",
    "ATKF2016_C_VERTICAL",
    "ATKF2016_Q",
    "ATKF_C_HORIZONTAL",
    "ATKF_C_VERTICAL",
    "KINECT_DEVICE_LOWER",
    "KINECT_DEVICE_UPPER",
    "PAPER_Q",
    "PAPER_R",
    "REFERENCE_DT",
    "skeleton_model",
]

#: the frame step the papers' constants refer to: the Kinect V2 rate, 30 fps (s)
REFERENCE_DT = 1.0 / 30.0
#: process-noise variance per axis, m² per 1/30 s (2020, eq. 35)
PAPER_Q = 0.0025
#: measurement-noise variance per axis, m² (2020, eq. 30)
PAPER_R = 0.01
#: ATKF half-widths, m per 1/30 s: horizontal axes and the vertical (up) axis (2020, eq. 33)
ATKF_C_HORIZONTAL = 0.34
ATKF_C_VERTICAL = 0.18
#: the 2016 paper's ATKF: process noise and half-widths
ATKF2016_Q = 0.001
ATKF2016_C_HORIZONTAL = 0.31
ATKF2016_C_VERTICAL = 0.18
#: Kinect V2 device limits (2020, §4.2), Kinect camera axes (x right, y up, z depth), m
KINECT_DEVICE_LOWER = (-3.0, -1.5, 0.5)
KINECT_DEVICE_UPPER = (3.0, 3.0, 5.0)


def skeleton_model(
    q: ArrayLike = PAPER_Q,
    r: ArrayLike = PAPER_R,
    x0: ArrayLike | None = None,
    p0: ArrayLike | None = None,
    *,
    ys: ArrayLike | None = None,
) -> Any:
    """Per-joint 3-D position model of the 2020 paper (eq. 30, 35): A = H = I.

    :meth:`tobitkf.LinearGaussian.random_walk` with the paper's Q = 0.0025 I and
    R = 0.01 I as defaults; ``x0``, ``p0`` and ``ys`` as there.
    """
    from tobitkf.core.model import LinearGaussian

    return LinearGaussian.random_walk(q, r, x0, p0, ys=ys)
