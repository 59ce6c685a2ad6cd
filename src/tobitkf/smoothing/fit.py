"""Fit the skeleton filters to data: the ATKF limits from motion capture
(:func:`fit_limits`) and the process noise from a recording (:func:`fit_skeleton_noise`).

Limits
------

The 2020 paper (Sect. 5, before eq. 30) set ``c = (0.34, 0.18, 0.34)`` m per frame at
30 fps from the largest per-frame displacement of each coordinate seen in Vicon data.
:func:`fit_limits` does the same for the user's own motion type: it takes ground-truth
tracks (optical motion capture, any rate), scales every per-frame displacement to a
1/30 s step, and returns the per-axis maximum (``method="max"``, the paper's choice) or a
high quantile (``method="quantile"``, robust to a stray marker swap).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from tobitkf.core.likelihood import Form, NoiseFit, fit_noise
from tobitkf.smoothing.paper import (
    ATKF_C_HORIZONTAL,
    ATKF_C_VERTICAL,
    KINECT_DEVICE_LOWER,
    KINECT_DEVICE_UPPER,
    PAPER_R,
    REFERENCE_DT,
)

__all__ = ["LimitsFit", "fit_limits", "fit_skeleton_noise"]


@dataclass(frozen=True)
class LimitsFit:
    """Result of :func:`fit_limits`.

    Attributes
    ----------
    c : ndarray, shape (3,)
        The limits per axis of the input's coordinate frame (x, y, z), metres per 1/30 s.
    maxima : ndarray, shape (3,)
        Largest absolute per-axis displacement, scaled to 1/30 s.
    quantiles : ndarray, shape (3,)
        The ``q`` quantile of the absolute scaled displacements per axis.
    q : float
        Quantile level used for ``quantiles``.
    method : str
        "max" or "quantile": which of the two became ``c``.
    fps : float or None
        Frame rate used (None when per-step timestamps were used).
    n_steps : int
        Number of displacements used: (step, joint) pairs with all three axes finite,
        over all inputs.
    up_axis : int
        Vertical axis of the input (0, 1 or 2).
    """

    c: NDArray[np.float64]
    maxima: NDArray[np.float64]
    quantiles: NDArray[np.float64]
    q: float
    method: str
    fps: float | None
    n_steps: int
    up_axis: int

    @property
    def c_vertical(self) -> float:
        """Limit on the up axis (the paper's 0.18 m)."""
        return float(self.c[self.up_axis])

    @property
    def c_horizontal(self) -> float:
        """Larger of the two horizontal limits (the paper used one value for both)."""
        return float(np.max(np.delete(self.c, self.up_axis)))

    def as_params(self) -> dict[str, Any]:
        """Parameters for ``tobitkf.smooth(..., method="atkf", **fit.as_params())``."""
        return {"c": tuple(float(v) for v in self.c)}


def _one_input(
    item: Any, fps: float | None
) -> tuple[NDArray[np.float64], NDArray[np.float64], float | None, int | None]:
    """Positions ``(T, J, 3)``, steps ``(T-1,)``, the rate used and the topology's up axis."""
    positions = getattr(item, "positions", None)
    up = None
    if positions is None:  # a bare array
        pos = np.asarray(item, dtype=float)
        timestamps = None
        own_fps = None
    else:
        pos = np.asarray(positions, dtype=float)
        timestamps = getattr(item, "timestamps", None)
        own_fps = getattr(item, "fps", None)
        topology = getattr(item, "topology", None)
        up = getattr(topology, "up_axis", None)
    if pos.ndim == 2:
        pos = pos[:, None, :]
    if pos.ndim != 3 or pos.shape[-1] != 3:
        raise ValueError(f"positions must have shape (T, J, 3), got {pos.shape}")
    T = pos.shape[0]
    if T < 2:
        raise ValueError(f"need at least 2 frames to measure displacements, got {T}")
    if fps is not None:
        if not np.isfinite(fps) or fps <= 0:
            raise ValueError(f"fps must be a positive number, got {fps!r}")
        steps = np.full(T - 1, 1.0 / fps)
        used: float | None = float(fps)
    elif timestamps is not None:
        t = np.asarray(timestamps, dtype=float)
        if t.shape != (T,):
            raise ValueError(f"timestamps must have shape ({T},), got {t.shape}")
        steps = np.diff(t)
        if not np.all(np.isfinite(steps)) or np.any(steps <= 0):
            raise ValueError("timestamps must be finite and strictly increasing")
        used = None
    elif own_fps is not None:
        steps = np.full(T - 1, 1.0 / float(own_fps))
        used = float(own_fps)
    else:
        raise ValueError(
            "the frame rate is unknown: pass fps= (the input has neither timestamps nor fps)"
        )
    return pos, steps, used, up


def fit_limits(
    ground_truth: Any,
    fps: float | None = None,
    method: str = "max",
    q: float = 0.999,
    up_axis: int | None = None,
) -> LimitsFit:
    """Per-axis censoring limits ``c`` from clean motion capture (2020 paper, Sect. 5).

    For every joint and axis, the displacement between consecutive frames
    ``d_k = x_k - x_{k-1}`` is scaled to the reference step of 1/30 s,
    ``d_k · (1/30) / dt_k``, so that data recorded at 60 or 120 Hz give limits for the
    30 fps filter (:func:`tobitkf.smooth` rescales them again for other rates). Steps
    touching a missing sample (NaN) are ignored.

    Parameters
    ----------
    ground_truth : SkeletonSequence, ndarray (T, J, 3), or a list of them
        Clean tracks in metres. A list is pooled (all must share the axes).
    fps : float, optional
        Frame rate in Hz; overrides the sequence's timestamps / fps. Required for bare
        arrays.
    method : {"max", "quantile"}
        ``c`` = largest absolute scaled displacement per axis (the paper's choice), or
        its ``q`` quantile.
    q : float
        Quantile level in (0, 1] (also reported with ``method="max"``).
    up_axis : int, optional
        Vertical axis (0, 1, 2) for :attr:`LimitsFit.c_vertical`; default: the
        topology's, else 1 (y up).

    Returns
    -------
    LimitsFit
    """
    if method not in ("max", "quantile"):
        raise ValueError(f"method must be 'max' or 'quantile', got {method!r}")
    if not (0.0 < q <= 1.0):
        raise ValueError(f"q must be in (0, 1], got {q!r}")
    items: Sequence[Any]
    if isinstance(ground_truth, (list, tuple)):
        items = ground_truth
        if not items:
            raise ValueError("ground_truth is an empty list")
    else:
        items = [ground_truth]
    chunks = []
    fps_used: set[float | None] = set()
    ups: set[int] = set()
    for item in items:
        pos, steps, used, up = _one_input(item, fps)
        fps_used.add(used)
        if up is not None:
            ups.add(int(up))
        scaled = np.diff(pos, axis=0) * (REFERENCE_DT / steps)[:, None, None]
        chunks.append(np.abs(scaled).reshape(-1, 3))
    d = np.concatenate(chunks, axis=0)
    ok = np.all(np.isfinite(d), axis=1)
    d = d[ok]
    if d.shape[0] == 0:
        raise ValueError("no pair of consecutive finite frames: cannot measure displacements")
    maxima = d.max(axis=0)
    quantiles = np.quantile(d, q, axis=0)
    if up_axis is None:
        up_axis = ups.pop() if len(ups) == 1 else 1
    if up_axis not in (0, 1, 2):
        raise ValueError(f"up_axis must be 0, 1 or 2, got {up_axis!r}")
    c = maxima if method == "max" else quantiles
    return LimitsFit(
        c=np.array(c, dtype=float),
        maxima=np.array(maxima, dtype=float),
        quantiles=np.array(quantiles, dtype=float),
        q=float(q),
        method=method,
        fps=fps_used.pop() if len(fps_used) == 1 else None,
        n_steps=int(d.shape[0]),
        up_axis=int(up_axis),
    )


# ---------------------------------------------------------------------------------------
# skeleton noise: the likelihood of the core on (T, J, 3) tracks

#: 2020 paper eq. 30–35: ATKF half-widths (x, y = up, z) in metres per frame at 30 fps.
DEFAULT_SKELETON_C = (ATKF_C_HORIZONTAL, ATKF_C_VERTICAL, ATKF_C_HORIZONTAL)


def fit_skeleton_noise(
    sequence: Any,
    *,
    per_joint: bool = False,
    c: Sequence[float] | np.ndarray | None = None,
    lower: Any = None,
    upper: Any = None,
    r: float = PAPER_R,
    fit_r: bool = False,
    q_structure: Literal["scalar", "diagonal", "full"] = "scalar",
    form: Form = "corrected",
    p0: float | None = None,
    joints: Sequence[int] | None = None,
    **fit_kwargs: Any,
) -> NoiseFit | dict[Any, NoiseFit]:
    """Fit the skeleton filter's Q (A = H = I per joint, 3-D) to one recording.

    Each joint is one sequence of the batch; by default all joints share one Q
    (2020 paper §4.2: Q "can be estimated using the likelihood functions"); with
    ``per_joint=True`` every joint gets its own fit.

    Which limits are used:

    - ``form="corrected"`` (default): the adaptive ATKF limits ``x̂_{k-1} ± c`` with
      ``c`` defaulting to :data:`DEFAULT_SKELETON_C`; or, when ``lower``/``upper`` are
      given, TKF^c with those fixed limits.
    - ``form="standard"`` (eq. 29): fixed limits, ``lower``/``upper`` or by default the
      Kinect v2 device limits :data:`~tobitkf.smoothing.paper.KINECT_DEVICE_LOWER` / ``_UPPER``.
    - ``form="gaussian"``: a plain KF, no limits (``c``, ``lower``, ``upper`` ignored).

    Parameters
    ----------
    sequence : (T, J, 3) positions in metres (NaN = missing), or an object with a
        ``positions`` attribute of that shape (e.g. ``tobitkf.SkeletonSequence``);
        ``joint_names`` is used for the keys of the per-joint result when present. A
        ``SkeletonSequence`` in centimetres or millimetres is fitted in metres; one in
        pixels or unknown units, or with 2-D keypoints, is refused with the reason.
    per_joint : one fit per joint instead of one shared Q.
    c : (3,) adaptive half-widths in metres per frame (the defaults are for 30 fps: scale
        them for other frame rates).
    lower, upper : (3,) fixed limits.
    r : measurement-noise variance (R = r I), the start value when ``fit_r``.
    fit_r, q_structure, form : as in :func:`fit_noise`.
    p0 : initial covariance scale (default ``r``).
    joints : indices of the joints to use (default all with at least 2 observed frames).
    **fit_kwargs : passed on to :func:`fit_noise`.

    Returns
    -------
    NoiseFit (shared Q) or ``{joint name or index: NoiseFit}`` when ``per_joint``.
    """
    pos = np.asarray(getattr(sequence, "positions", sequence), dtype=float)
    if pos.ndim == 3 and pos.shape[-1] == 2:
        raise ValueError(
            "the paper's skeleton noise model is 3-D, in metres, and these are 2-D "
            "keypoints (x, y); to smooth them, use tobitkf.smooth or `tobitkf smooth`, "
            "whose robust method fits the noise of each recording in its own units"
        )
    if pos.ndim != 3 or pos.shape[-1] != 3:
        raise ValueError(f"skeleton positions must be (T, J, 3), got shape {pos.shape}")
    if hasattr(sequence, "metres_per_unit"):  # a SkeletonSequence: its unit, in metres
        k = sequence.metres_per_unit
        if k is None:
            what = "pixels" if sequence.units == "px" else "unknown units"
            raise ValueError(
                f"positions in {what}: the paper's skeleton noise model (its limits c and "
                "R) is in metres; give the recording's length unit (--units on the "
                "command line, SkeletonSequence.replace(units=...) in Python)"
            )
        pos = pos * k
    J = pos.shape[1]
    jn = getattr(sequence, "joint_names", None)
    if callable(jn):  # a method rather than a property
        jn = jn()
    names = list(jn) if jn is not None and len(jn) == J else list(range(J))
    observed = np.isfinite(pos).all(axis=-1)  # (T, J)
    idx = list(range(J)) if joints is None else [int(j) for j in joints]
    idx = [j for j in idx if observed[:, j].sum() >= 2]
    if not idx:
        raise ValueError("no joint has at least two observed frames")
    fixed = lower is not None or upper is not None
    if c is not None and fixed:
        raise ValueError("give either c (adaptive limits) or lower/upper (fixed), not both")
    if form == "gaussian":
        c, lower, upper = None, None, None
    elif form == "standard":
        if c is not None:
            raise ValueError("form='standard' uses fixed limits (lower/upper), not c")
        if not fixed:
            lower, upper = np.asarray(KINECT_DEVICE_LOWER), np.asarray(KINECT_DEVICE_UPPER)
    elif not fixed:
        c = np.asarray(DEFAULT_SKELETON_C if c is None else c, dtype=float)
    first = np.array([pos[np.argmax(observed[:, j]), j] for j in idx])  # (J', 3)
    eye = np.eye(3)
    P0 = (r if p0 is None else p0) * eye
    common = dict(
        A=eye, H=eye, P0=P0, q_structure=q_structure, fit_r=fit_r, R=r * eye, form=form, c=c
    )
    common.update(fit_kwargs)
    if not per_joint:
        return fit_noise(pos[:, idx], lower, upper, x0=first, **common)
    out: dict[Any, NoiseFit] = {}
    for k, j in enumerate(idx):
        out[names[j]] = fit_noise(pos[:, j], lower, upper, x0=first[k], **common)
    return out
