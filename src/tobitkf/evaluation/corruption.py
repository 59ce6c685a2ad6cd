"""A Kinect-like corruption model with labels of what was done to each sample.

Given a clean sequence (the truth), :func:`corrupt` returns what a Kinect V2 might have
reported, plus a (T, J) label array.  Error types, in the order they are applied:

``jitter`` (every sample)
    white Gaussian noise per axis, standard deviation by joint group (torso 1 mm, arms and
    legs 2 mm, hands 6 mm), times ``depth_factor`` on the depth axis z.
``INFERRED`` drift (label 3)
    episodes of ``inferred_length`` frames (at 30 fps: see below) on a distal joint chain
    (a hand or a foot with its children) during which the tracking state is INFERRED and
    the position drifts away from the truth (a smooth random path reaching up to
    ``inferred_drift`` m).
``SUSTAINED`` failure (label 2)
    episodes of ``sustained_length`` frames (10–50) during which a hand chain (wrist, hand,
    tip, thumb) or foot chain is displaced by a vector of ``sustained_offset`` m (0.2–1 m),
    switched on and off within a frame, wobbling slightly; the state stays TRACKED (the
    sensor does not know it failed — the real KERAAL ELK hand was ~1 m off for 42 frames).
``SPIKE`` (label 1)
    single-frame displacements of ``spike_size`` m (0.2–1 m) in a random direction; the
    per joint-frame probability is ``spike_rate`` times a group factor (hands 1, arms 0.25,
    legs 0.15, torso 0.05).
(Episode counts are Poisson with the given rate per second, but at least one of each
enabled type, so that every recording exercises every error type. Episode lengths are
frames at 30 fps, the Kinect's rate at which they were measured; a recording at another
rate gets episodes of the same duration, ``round(length · fps / 30)`` frames, at least 1.
Spikes stay one frame long, and jitter per sample.)

dropped frames and irregular time steps
    each interior frame is dropped with probability ``drop_rate``; kept frames get their
    nominal time plus Gaussian timestamp jitter (``time_jitter`` s), kept increasing.

Calibration (measured on the real data with :func:`jump_statistics`): robust jitter from
the median absolute second difference / √6 — KERAAL (CTK, the cleanest) hands ≈ 5 mm
(including hand tips and thumbs), arms ≈ 0.8 mm, torso ≈ 0.2 mm, legs ≈ 0.3 mm; KIMORE
hands 2–8 mm, arms 0.3–2 mm, torso 0.1–1.3 mm, legs 0.3–4 mm (those include some true
motion, so they are upper bounds).  One-frame jumps > 0.2 m occur on 0.01–1.9 % of
joint-frames (KIMORE Ex1 0.01 %, Ex3 0.5 %, Ex5 1.9 %; KERAAL 0.14–1.0 %), 80–90 % of them
on hands and wrists.  KERAAL's glitches are mostly sustained (14–48 frames): ~3 episodes in
19 s of recording.  KIMORE marks 9–19 % of samples INFERRED (feet, hands, arms).  The
defaults sit inside these ranges: spikes on 0.5 % of hand joint-frames, 0.12 sustained
episodes per second, 0.2 inferred episodes per second, 2 % dropped frames.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "CLEAN",
    "INFERRED_DRIFT",
    "LABEL_NAMES",
    "SPIKE",
    "SUSTAINED",
    "CorruptedTrack",
    "CorruptionModel",
    "corrupt",
    "jump_statistics",
]

CLEAN, SPIKE, SUSTAINED, INFERRED_DRIFT = 0, 1, 2, 3
LABEL_NAMES = {CLEAN: "clean", SPIKE: "spike", SUSTAINED: "sustained", INFERRED_DRIFT: "inferred"}

_GROUP_JITTER = {"torso": 0.001, "arms": 0.002, "legs": 0.002, "hands": 0.006}
_GROUP_SPIKE = {"hands": 1.0, "arms": 0.25, "legs": 0.15, "torso": 0.05}


@dataclass(frozen=True)
class CorruptionModel:
    """Parameters of :func:`corrupt` (module docstring); lengths in metres, times in s,
    episode lengths in frames at 30 fps.

    ``jitter`` maps joint group → noise standard deviation per axis; set a rate to 0 to
    switch an error type off.
    """

    jitter: dict[str, float] = field(default_factory=lambda: dict(_GROUP_JITTER))
    depth_factor: float = 1.5
    spike_rate: float = 0.005
    spike_group_factor: dict[str, float] = field(default_factory=lambda: dict(_GROUP_SPIKE))
    spike_size: tuple[float, float] = (0.2, 1.0)
    sustained_per_second: float = 0.12
    sustained_length: tuple[int, int] = (10, 50)
    sustained_offset: tuple[float, float] = (0.2, 1.0)
    inferred_per_second: float = 0.2
    inferred_length: tuple[int, int] = (15, 60)
    inferred_drift: float = 0.10
    drop_rate: float = 0.02
    time_jitter: float = 0.002

    def __post_init__(self) -> None:
        for name in ("spike_rate", "sustained_per_second", "inferred_per_second", "drop_rate"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a non-negative number, got {v!r}")
        if self.drop_rate >= 0.5:
            raise ValueError(f"drop_rate must be below 0.5, got {self.drop_rate}")
        for name in ("spike_size", "sustained_length", "sustained_offset", "inferred_length"):
            lo, hi = getattr(self, name)
            if not 0 <= lo <= hi:
                raise ValueError(f"{name} must be (lo, hi) with 0 <= lo <= hi, got {(lo, hi)}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class CorruptedTrack:
    """Output of :func:`corrupt`.

    sequence : the corrupted SkeletonSequence (kept frames only, irregular timestamps,
        tracking states).
    truth : (T', J, 3) the clean positions at the kept frames.
    labels : (T', J) int8: ``CLEAN``, ``SPIKE``, ``SUSTAINED``, ``INFERRED_DRIFT``.
    kept : (T',) indices of the kept frames in the clean sequence.
    model : the :class:`CorruptionModel` used; seed : the seed.
    """

    sequence: Any
    truth: NDArray[np.float64]
    labels: NDArray[np.int8]
    kept: NDArray[np.int64]
    model: CorruptionModel
    seed: int | None

    def counts(self) -> dict[str, int]:
        """Number of samples per label."""
        return {n: int(np.sum(self.labels == k)) for k, n in LABEL_NAMES.items()}


def _chains(names: tuple[str, ...]) -> dict[str, list[int]]:
    idx = {n: i for i, n in enumerate(names)}

    def pick(*ns: str) -> list[int]:
        return [idx[n] for n in ns if n in idx]

    out = {
        "hand_left": pick("WristLeft", "HandLeft", "HandTipLeft", "ThumbLeft"),
        "hand_right": pick("WristRight", "HandRight", "HandTipRight", "ThumbRight"),
        "foot_left": pick("AnkleLeft", "FootLeft"),
        "foot_right": pick("AnkleRight", "FootRight"),
    }
    return {k: v for k, v in out.items() if v}


def _groups(topology: Any, J: int) -> dict[str, list[int]]:
    try:
        return topology.joint_groups()
    except AttributeError:
        return {"torso": list(range(J))}


def _episodes(
    rng: np.random.Generator, n_frames: int, per_frame: float, length: tuple[int, int],
    per30: float = 1.0,
) -> list[tuple[int, int]]:  # fmt: skip
    """Random episodes ``(start, stop)``: a Poisson count, at least one when the rate is > 0;
    ``length`` in frames at 30 fps, ``per30`` the recording's frames per frame at 30 fps."""
    k = max(int(rng.poisson(per_frame * n_frames)), 1 if per_frame > 0 else 0)
    out = []
    for _ in range(k):
        L = int(rng.integers(length[0], length[1] + 1))
        if per30 != 1.0:  # the same duration at the recording's rate (30 fps: as drawn)
            L = max(1, round(L * per30))
        a = int(rng.integers(0, max(n_frames - L, 1)))
        out.append((a, min(a + L, n_frames)))
    return out


def _unit(rng: np.random.Generator, n: int) -> NDArray[np.float64]:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def corrupt(
    clean: Any, model: CorruptionModel | None = None, *, seed: int | None = 0
) -> CorruptedTrack:
    """Apply the Kinect-like corruption model to a clean sequence (module docstring).

    Parameters
    ----------
    clean : SkeletonSequence with finite positions (T, J, 3); Kinect-like joint names give
        the hand / foot chains for sustained failures and inferred drift.
    model : :class:`CorruptionModel` (default parameters when None).
    seed : random seed; the same seed gives the same corruption.

    Returns
    -------
    CorruptedTrack
    """
    from tobitkf.skeleton.sequence import TrackingState

    model = model or CorruptionModel()
    rng = np.random.default_rng(seed)
    truth = np.asarray(clean.positions, dtype=float)
    T, J, _ = truth.shape
    fps = float(clean.fps or 30.0)
    pos = truth.copy()
    labels = np.zeros((T, J), dtype=np.int8)
    state = np.full((T, J), int(TrackingState.TRACKED), dtype=np.int8)
    groups = _groups(clean.topology, J)
    chains = _chains(tuple(clean.joint_names))
    chain_names = sorted(chains)

    # jitter
    sd = np.full(J, _GROUP_JITTER["arms"])
    for g, idx in groups.items():
        sd[idx] = model.jitter.get(g, sd[idx])
    axis_f = np.array([1.0, 1.0, model.depth_factor])
    pos += rng.normal(size=(T, J, 3)) * sd[None, :, None] * axis_f

    # inferred drift
    if chain_names and model.inferred_per_second > 0:
        rate = model.inferred_per_second / fps
        for a, b in _episodes(rng, T, rate, model.inferred_length, fps / 30.0):
            idx = chains[chain_names[int(rng.integers(len(chain_names)))]]
            n = b - a
            # smooth drift: a random direction, growing like a smoothstep, plus a slow wobble
            amp = rng.uniform(0.3, 1.0) * model.inferred_drift
            s = np.linspace(0, 1, n)
            grow = s * s * (3 - 2 * s) if n > 1 else np.ones(1)
            drift = amp * grow[:, None] * _unit(rng, 1)
            pos[a:b, idx] += drift[:, None, :]
            labels[a:b, idx] = INFERRED_DRIFT
            state[a:b, idx] = int(TrackingState.INFERRED)

    # sustained failures (hands mostly: 3 of 4 episodes)
    if chain_names and model.sustained_per_second > 0:
        rate = model.sustained_per_second / fps
        for a, b in _episodes(rng, T, rate, model.sustained_length, fps / 30.0):
            hands = [c for c in chain_names if c.startswith("hand")]
            feet = [c for c in chain_names if c.startswith("foot")]
            pool = hands if (hands and (not feet or rng.random() < 0.75)) else feet
            idx = chains[pool[int(rng.integers(len(pool)))]]
            off = rng.uniform(*model.sustained_offset) * _unit(rng, 1)[0]
            wobble = np.cumsum(rng.normal(scale=0.005, size=(b - a, 3)), axis=0)
            pos[a:b, idx] = truth[a:b, idx] + off + wobble[:, None, :]
            pos[a:b, idx] += rng.normal(size=(b - a, len(idx), 3)) * 0.005
            labels[a:b, idx] = SUSTAINED
            state[a:b, idx] = int(TrackingState.TRACKED)

    # one-frame spikes
    if model.spike_rate > 0:
        rate = np.full(J, model.spike_rate * model.spike_group_factor.get("arms", 0.25))
        for g, idx in groups.items():
            rate[idx] = model.spike_rate * model.spike_group_factor.get(g, 0.25)
        hit = (rng.random((T, J)) < rate[None, :]) & (labels == CLEAN)
        t_idx, j_idx = np.nonzero(hit)
        size = rng.uniform(*model.spike_size, size=len(t_idx))
        pos[t_idx, j_idx] += size[:, None] * _unit(rng, len(t_idx))
        labels[t_idx, j_idx] = SPIKE

    # dropped frames and irregular time steps
    keep = np.ones(T, dtype=bool)
    if model.drop_rate > 0 and T > 2:
        keep[1:-1] = rng.random(T - 2) >= model.drop_rate
    kept = np.flatnonzero(keep)
    t0 = clean.times() if hasattr(clean, "times") else np.arange(T) / fps
    ts = t0[kept] + rng.normal(scale=model.time_jitter, size=len(kept))
    ts = np.maximum.accumulate(ts)
    seq = clean.replace(
        positions=pos[kept],
        tracking_state=state[kept],
        timestamps=ts,
        fps=fps,
        metadata={**clean.metadata, "corruption": model.to_dict(), "corruption_seed": seed},
        std=None,  # a smoothed track's uncertainty no longer describes the corrupted one
        sample_state=None,
    )
    return CorruptedTrack(seq, truth[kept], labels[kept], kept, model, seed)


def jump_statistics(positions: Any, topology: Any = None, threshold: float = 0.2) -> dict:
    """Statistics used to calibrate the corruption model on a real track.

    Parameters
    ----------
    positions : (T, J, 3) a real track (metres).
    topology : its Topology (for joint groups); None = one group.
    threshold : a one-frame jump larger than this (m) counts as a jump.

    Returns
    -------
    dict with ``jitter_m`` (group → median |second difference| · 1.4826 / √6, an upper
    bound of the white-noise standard deviation since true motion adds to it),
    ``jump_rate`` (fraction of joint-frames with a jump > threshold), ``jumps_by_group``,
    and ``glitch_run_lengths`` (lengths of runs of frames a joint spends more than
    ``threshold`` away from its median-filtered (9 frames) path).
    """
    from scipy.ndimage import median_filter

    p = np.asarray(positions, dtype=float)
    _T, J, _ = p.shape
    groups = _groups(topology, J) if topology is not None else {"all": list(range(J))}
    d2 = np.diff(p, 2, axis=0)
    jitter = {
        g: float(np.nanmedian(np.abs(d2[:, idx])) * 1.4826 / np.sqrt(6))
        for g, idx in groups.items()
        if idx
    }
    jumps = np.linalg.norm(np.diff(p, axis=0), axis=-1) > threshold
    med = median_filter(p, size=(9, 1, 1), mode="nearest")
    off = np.linalg.norm(p - med, axis=-1) > threshold
    from tobitkf.evaluation.metrics import glitch_episodes

    runs = [b - a for _, a, b in glitch_episodes(off)]
    return {
        "jitter_m": jitter,
        "jump_rate": float(jumps.mean()),
        "jumps_by_group": {g: int(jumps[:, idx].sum()) for g, idx in groups.items() if idx},
        "glitch_run_lengths": runs,
    }
