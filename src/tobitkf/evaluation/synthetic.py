"""Clean skeleton motion with known truth: a built-in generator and a BVH mapping.

:func:`generate_motion` builds Kinect V2 joint positions (25 joints, SDK order, camera
space: x to the subject's right, y up, z = distance from the sensor, metres) by forward
kinematics of a simple body model with adult bone lengths (scaled by the subject's
height), for three movements used in rehabilitation recordings:

* ``"walk"``:  walking towards the sensor (hip/knee gait cycle, counter-swinging arms,
  pelvis bob from the stance leg);
* ``"arms"``:  lateral arm raising (shoulder abduction to ~150°, slight elbow flexion);
* ``"squat"``: squatting (hip and knee flexion to ~100°, trunk lean, feet planted);
* ``"mixed"``: the three in sequence.

Amplitudes, tempo, height and start position vary with the seed.  :func:`bvh_to_kinect`
maps the CMU BVH skeleton (``cmu-mocap/scaled_131_01.bvh``) to Kinect-like joints and
resamples it to 30 fps.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tobitkf.skeleton.topology import get_topology

__all__ = [
    "BVH_TO_KINECT",
    "KINECT_V2_JOINTS",
    "MOTIONS",
    "bvh_to_kinect",
    "generate_motion",
    "generate_positions",
]

KINECT_V2_JOINTS = get_topology("kinect_v2").joints
_J = {n: i for i, n in enumerate(KINECT_V2_JOINTS)}
MOTIONS = ("walk", "arms", "squat", "mixed")

# bone lengths (m) for a 1.75 m adult
_B = {
    "spine_low": 0.25, "spine_high": 0.24, "neck": 0.07, "head": 0.13,
    "shoulder_w": 0.18, "shoulder_drop": 0.04, "upper_arm": 0.28, "forearm": 0.26,
    "hand": 0.08, "hand_tip": 0.07, "thumb": 0.05, "hip_w": 0.08, "hip_drop": 0.06,
    "thigh": 0.42, "shank": 0.41, "ankle_h": 0.07, "foot": 0.13,
}  # fmt: skip
_FLOOR_Y = -1.05  # sensor about 1 m above the floor


def _rx(a: NDArray) -> NDArray:
    """Rotation about the body's lateral x axis; positive moves -y towards -z (forward)."""
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(a), np.ones_like(a)
    return np.stack(
        [np.stack([o, z, z], -1), np.stack([z, c, s], -1), np.stack([z, -s, c], -1)], -2
    )


def _rz(a: NDArray) -> NDArray:
    """Rotation about the forward axis (z); positive moves -y towards +x."""
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(a), np.ones_like(a)
    return np.stack(
        [np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2
    )


def _ry(a: NDArray) -> NDArray:
    """Rotation about the vertical axis (yaw)."""
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(a), np.ones_like(a)
    return np.stack(
        [np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2
    )


def _mv(m: NDArray, v: Sequence[float] | NDArray) -> NDArray:
    return np.einsum("tab,b->ta", m, np.asarray(v, dtype=float))


def _smoothstep(x: NDArray) -> NDArray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def _whole_cycles(t: NDArray, period: float) -> float:
    """The period closest to ``period`` that fits a whole number of cycles in ``t``."""
    span = t[-1] - t[0] + (t[1] - t[0] if len(t) > 1 else 0.0)
    return span / max(round(span / period), 1)


def _params(kind: str, n: int, fps: float, rng: np.random.Generator) -> dict[str, NDArray]:
    """Per-frame angles (rad) and pelvis motion for one movement."""
    t = np.arange(n) / fps
    z = np.zeros(n)
    p = {k: z.copy() for k in (
        "hip_l", "hip_r", "knee_l", "knee_r", "sflex_l", "sflex_r", "sabd_l", "sabd_r",
        "elbow_l", "elbow_r", "lean", "yaw", "forward", "plant")}  # fmt: skip
    env = _smoothstep(t / 0.6) * _smoothstep((t[-1] - t) / 0.6)  # start and end at rest
    if kind == "walk":
        f = rng.uniform(0.8, 1.0)  # gait cycles per second
        w = 2 * np.pi * f * t
        hip = np.radians(rng.uniform(20, 28)) * env
        knee = np.radians(rng.uniform(45, 60)) * env
        p["hip_l"], p["hip_r"] = hip * np.sin(w), -hip * np.sin(w)
        p["knee_l"] = knee * np.clip(np.sin(w + 1.2), 0, None) + np.radians(5) * env
        p["knee_r"] = knee * np.clip(np.sin(w + 1.2 + np.pi), 0, None) + np.radians(5) * env
        arm = np.radians(rng.uniform(12, 22)) * env
        p["sflex_l"], p["sflex_r"] = -arm * np.sin(w), arm * np.sin(w)
        p["elbow_l"] = p["elbow_r"] = np.radians(15) * env
        p["sabd_l"] = p["sabd_r"] = np.radians(6) * env
        speed = rng.uniform(0.08, 0.15)  # short steps towards the sensor (m/s)
        p["forward"] = np.cumsum(speed * env) / fps
        p["yaw"] = np.radians(rng.uniform(-4, 4)) * np.sin(w / 2) * env
    elif kind == "arms":
        period = _whole_cycles(t, rng.uniform(3.0, 4.5))
        lift = 0.5 - 0.5 * np.cos(2 * np.pi * t / period)
        top = np.radians(rng.uniform(130, 160))
        p["sabd_l"] = top * lift * env
        p["sabd_r"] = top * (0.5 - 0.5 * np.cos(2 * np.pi * t / period - 0.15)) * env
        p["elbow_l"] = p["elbow_r"] = np.radians(rng.uniform(5, 20)) * env
        p["sflex_l"] = p["sflex_r"] = np.radians(10) * lift * env
    elif kind == "squat":
        period = _whole_cycles(t, rng.uniform(3.0, 4.0))
        depth = 0.5 - 0.5 * np.cos(2 * np.pi * t / period)
        kmax = np.radians(rng.uniform(85, 110))
        p["knee_l"] = p["knee_r"] = kmax * depth * env
        p["hip_l"] = p["hip_r"] = 0.9 * kmax * depth * env
        p["lean"] = 0.35 * kmax * depth * env
        p["sflex_l"] = p["sflex_r"] = np.radians(rng.uniform(60, 90)) * depth * env
        p["plant"] = np.ones(n)
    else:
        raise ValueError(f"unknown motion {kind!r}; expected one of {MOTIONS}")
    return p


def generate_positions(params: dict[str, NDArray], scale: float = 1.0) -> NDArray[np.float64]:
    """Forward kinematics: per-frame parameters → (T, 25, 3) body-frame positions.

    The body frame has the pelvis (SpineBase) at x = z = 0 facing -z, y up, the floor at
    ``_FLOOR_Y``; ``params`` holds hip/knee/shoulder/elbow angles (rad), trunk ``lean``,
    ``yaw``, ``forward`` pelvis displacement (m) and ``plant`` (1 = keep the feet still).
    """
    b = {k: v * scale for k, v in _B.items()}
    n = len(params["hip_l"])
    out = np.zeros((n, 25, 3))
    trunk = _rx(params["lean"])
    sb = np.zeros((n, 3))
    legs = {}
    for side, sx in (("l", -1.0), ("r", 1.0)):
        hip = _mv(np.repeat(np.eye(3)[None], n, 0), [sx * b["hip_w"], -b["hip_drop"], 0.0])
        thigh_r = _rx(params[f"hip_{side}"])
        shank_r = _rx(params[f"hip_{side}"] - params[f"knee_{side}"])
        knee = hip + _mv(thigh_r, [0, -b["thigh"], 0])
        ankle = knee + _mv(shank_r, [0, -b["shank"], 0])
        foot = ankle + np.array([0.0, -b["ankle_h"] * 0.5, -b["foot"]])
        legs[side] = (hip, knee, ankle, foot)
    # pelvis height from the longer (stance) leg; the ankle sits ankle_h above the floor
    drop = np.maximum(-legs["l"][2][:, 1], -legs["r"][2][:, 1])
    sb[:, 1] = _FLOOR_Y + b["ankle_h"] + drop
    plant = params["plant"]
    ankle_z = 0.5 * (legs["l"][2][:, 2] + legs["r"][2][:, 2])
    sb[:, 2] = -params["forward"] - plant * ankle_z
    yaw = _ry(params["yaw"])

    def put(name: str, local: NDArray) -> None:
        out[:, _J[name]] = sb + np.einsum("tab,tb->ta", yaw, local)

    zero = np.zeros((n, 3))
    put("SpineBase", zero)
    for side, (hip, knee, ankle, foot) in legs.items():
        s = "Left" if side == "l" else "Right"
        put(f"Hip{s}", hip)
        put(f"Knee{s}", knee)
        put(f"Ankle{s}", ankle)
        put(f"Foot{s}", foot)
    smid = _mv(trunk, [0, b["spine_low"], 0])
    ssh = _mv(trunk, [0, b["spine_low"] + b["spine_high"], 0])
    neck = ssh + _mv(trunk, [0, b["neck"], 0])
    put("SpineMid", smid)
    put("SpineShoulder", ssh)
    put("Neck", neck)
    put("Head", neck + _mv(trunk, [0, b["head"], -0.02 * scale]))
    for side, sx in (("l", -1.0), ("r", 1.0)):
        s = "Left" if side == "l" else "Right"
        sh = ssh + _mv(trunk, [sx * b["shoulder_w"], -b["shoulder_drop"], 0])
        arm_r = trunk @ _rz(sx * params[f"sabd_{side}"]) @ _rx(params[f"sflex_{side}"])
        elbow = sh + _mv(arm_r, [0, -b["upper_arm"], 0])
        fore_r = arm_r @ _rx(params[f"elbow_{side}"])
        wrist = elbow + _mv(fore_r, [0, -b["forearm"], 0])
        hand = wrist + _mv(fore_r, [0, -b["hand"], 0])
        tip = hand + _mv(fore_r, [0, -b["hand_tip"], 0])
        thumb = wrist + _mv(fore_r, [-sx * 0.02 * scale, -b["thumb"], -0.03 * scale])
        put(f"Shoulder{s}", sh)
        put(f"Elbow{s}", elbow)
        put(f"Wrist{s}", wrist)
        put(f"Hand{s}", hand)
        put(f"HandTip{s}", tip)
        put(f"Thumb{s}", thumb)
    return out


def generate_motion(
    kind: str = "mixed",
    *,
    duration: float = 10.0,
    fps: float = 30.0,
    seed: int | None = 0,
    height: float | None = None,
) -> object:
    """A clean Kinect V2 skeleton sequence with known truth.

    Parameters
    ----------
    kind : ``"walk"``, ``"arms"``, ``"squat"`` or ``"mixed"`` (the three in sequence).
    duration : seconds (each of the three parts gets a third for ``"mixed"``).
    fps : frame rate (default 30, the Kinect's).
    seed : random seed (tempo, amplitudes, height, start position).
    height : subject height in metres (default: drawn from 1.60–1.90).

    Returns
    -------
    SkeletonSequence
        positions (T, 25, 3) metres in Kinect camera space, topology ``kinect_v2``,
        all joints TRACKED, timestamps ``k / fps``, ``metadata["motion"] = kind``.
    """
    if kind not in MOTIONS:
        raise ValueError(f"unknown motion {kind!r}; expected one of {MOTIONS}")
    if duration <= 0 or fps <= 0:
        raise ValueError(f"duration and fps must be positive, got {duration}, {fps}")
    rng = np.random.default_rng(seed)
    h = float(height) if height is not None else float(rng.uniform(1.60, 1.90))
    n = round(duration * fps)
    if n < 10:
        raise ValueError(f"need at least 10 frames, duration*fps = {n}")
    parts = ("walk", "arms", "squat") if kind == "mixed" else (kind,)
    sizes = np.diff(np.linspace(0, n, len(parts) + 1).round().astype(int))
    chunks = [_params(k, int(m), fps, rng) for k, m in zip(parts, sizes, strict=True)]
    params = {k: np.concatenate([c[k] for c in chunks]) for k in chunks[0]}
    # walking moves the pelvis; later parts start where the walk ended
    params["forward"] = np.maximum.accumulate(params["forward"])
    pos = generate_positions(params, scale=h / 1.75)
    start = np.array([rng.uniform(-0.3, 0.3), 0.0, rng.uniform(3.0, 3.4)])
    pos = pos + start
    return _kinect_sequence(
        pos, fps, {"motion": kind, "height_m": h, "seed": seed, "format": "synthetic"}
    )


def _kinect_sequence(positions: NDArray, fps: float, metadata: dict) -> object:
    """A Kinect V2 SkeletonSequence of clean positions: all TRACKED, timestamps ``k / fps``."""
    from tobitkf.skeleton.sequence import SkeletonSequence, TrackingState

    T, J = positions.shape[:2]
    return SkeletonSequence(
        positions=positions,
        topology=get_topology("kinect_v2"),
        tracking_state=np.full((T, J), int(TrackingState.TRACKED), dtype=np.int8),
        timestamps=np.arange(T) / fps,
        fps=fps,
        metadata=metadata,
    )


# ------------------------------------------------------------------------------- BVH
# Kinect V2 joint <- CMU BVH joint(s) (mean of several)
BVH_TO_KINECT: dict[str, tuple[str, ...]] = {
    "SpineBase": ("Hips",), "SpineMid": ("Chest",), "Neck": ("lowerneck", "Neck"),
    "Head": ("Head",), "SpineShoulder": ("Chest2", "lowerneck"),
    "ShoulderLeft": ("LeftShoulder",), "ElbowLeft": ("LeftElbow",),
    "WristLeft": ("LeftWrist",), "HandLeft": ("LFingers",), "HandTipLeft": ("LFingers_End",),
    "ThumbLeft": ("LThumb_End",), "ShoulderRight": ("RightShoulder",),
    "ElbowRight": ("RightElbow",), "WristRight": ("RightWrist",), "HandRight": ("RFingers",),
    "HandTipRight": ("RFingers_End",), "ThumbRight": ("RThumb_End",), "HipLeft": ("LeftHip",),
    "KneeLeft": ("LeftKnee",), "AnkleLeft": ("LeftAnkle",), "FootLeft": ("LeftToe",),
    "HipRight": ("RightHip",), "KneeRight": ("RightKnee",), "AnkleRight": ("RightAnkle",),
    "FootRight": ("RightToe",),
}  # fmt: skip


def bvh_to_kinect(
    path: str | Path, *, fps: float = 30.0, distance: float = 3.2, floor_y: float = _FLOOR_Y
) -> object:
    """The CMU BVH recording as a Kinect V2 sequence (truth for synthetic benchmarks).

    Joints are mapped by :data:`BVH_TO_KINECT`, resampled from the file's rate to ``fps`` by
    linear interpolation, and placed in Kinect camera space: BVH y up stays y up, the
    subject is turned to face the sensor (180° about y), its mean position is put
    ``distance`` metres in front of the sensor and the lowest foot point on ``floor_y``.
    Units are taken as metres (the scaled CMU file).

    Returns
    -------
    SkeletonSequence (topology ``kinect_v2``, all TRACKED, timestamps ``k / fps``).
    """
    from tobitkf.evaluation.alignment import resample
    from tobitkf.io.bvh import read_bvh

    (bvh,) = read_bvh(path, end_sites=True)
    names, pos, ft = bvh.joint_names, bvh.positions, 1.0 / float(bvh.fps)
    idx = {n: i for i, n in enumerate(names)}
    missing = [m for ms in BVH_TO_KINECT.values() for m in ms if m not in idx]
    if missing:
        raise ValueError(f"{path}: BVH joints {missing} not found (expected the CMU skeleton)")
    kin = np.stack(
        [pos[:, [idx[m] for m in BVH_TO_KINECT[j]]].mean(axis=1) for j in KINECT_V2_JOINTS], 1
    )
    t_src = np.arange(len(kin)) * ft
    t_dst = np.arange(0.0, t_src[-1] + 1e-9, 1.0 / fps)
    kin = resample(t_src, kin, t_dst)
    kin = kin * np.array([-1.0, 1.0, -1.0])  # BVH subject faces +z; a Kinect subject faces -z
    centre = np.nanmean(kin[:, 0], axis=0)
    kin = kin - np.array([centre[0], 0.0, centre[2]])
    kin[..., 2] += distance
    kin[..., 1] += floor_y - np.nanmin(kin[:, [_J["FootLeft"], _J["FootRight"]], 1])
    return _kinect_sequence(kin, fps, {"source": str(path), "format": "bvh_to_kinect"})
