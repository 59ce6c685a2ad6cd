"""Pairing tables: which motion-capture point(s) stand for which track joint.

A pair maps one track joint to one mocap point or to the mean of several (``LWRA+LWRB``).
Names are matched case-insensitively, ignoring spaces, underscores and hyphens, so
``"Right Hand"``, ``"right_hand"`` and ``"RightHand"`` are the same name.

User pairing file (CSV, UTF-8)::

    # comment lines and blank lines are ignored; an optional header line
    track_joint,mocap_point
    HandRight,Right Hand
    WristLeft,LWRA+LWRB

Built-in tables: :data:`KERAAL_PAIRS` (Kinect V2 joints ↔ the 17 ART rigid targets) and
:data:`UIPRMD_PAIRS` (UI-PRMD 22-joint Kinect hierarchy ↔ Plug-in Gait markers).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "KERAAL_PAIRS",
    "UIPRMD_PAIRS",
    "Pair",
    "PairingTable",
    "ResolvedPairs",
    "builtin_pairs",
    "normalise_name",
    "read_pairs",
]


def normalise_name(name: str) -> str:
    """Canonical form of a joint / marker name: lower case, no spaces, ``_`` or ``-``."""
    return re.sub(r"[\s_\-]+", "", str(name)).lower()


@dataclass(frozen=True)
class Pair:
    """One track joint and the mocap point(s) whose mean stands for it."""

    track_joint: str
    mocap_points: tuple[str, ...]

    def __str__(self) -> str:
        return f"{self.track_joint},{'+'.join(self.mocap_points)}"


@dataclass(frozen=True)
class ResolvedPairs:
    """A pairing table resolved against concrete name lists.

    Attributes
    ----------
    pairs : the pairs that resolved (both sides found).
    track_index : (P,) index of each pair's joint in the track.
    mocap_index : tuple of P tuples of mocap point indices (averaged).
    missing : pairs dropped because a name was not found, with the reason.
    """

    pairs: tuple[Pair, ...]
    track_index: tuple[int, ...]
    mocap_index: tuple[tuple[int, ...], ...]
    missing: tuple[tuple[Pair, str], ...]

    def mocap_positions(self, mocap: ArrayLike, n_track_joints: int) -> NDArray[np.float64]:
        """Mocap points laid out like the track: (T, M, 3) → (T, J, 3), NaN where unpaired."""
        m = np.asarray(mocap, dtype=float)
        out = np.full((*m.shape[:1], n_track_joints, 3), np.nan)
        for j, idx in zip(self.track_index, self.mocap_index):
            out[:, j] = m[:, list(idx)].mean(axis=1)
        return out

    def mocap_quaternions(self, quats: ArrayLike, n_track_joints: int) -> NDArray[np.float64]:
        """Target quaternions laid out like the track: (T, M, 4) → (T, J, 4).

        Only single-point pairs get a quaternion; averaged pairs and unpaired joints get NaN.
        """
        q = np.asarray(quats, dtype=float)
        out = np.full((*q.shape[:1], n_track_joints, 4), np.nan)
        for j, idx in zip(self.track_index, self.mocap_index):
            if len(idx) == 1:
                out[:, j] = q[:, idx[0]]
        return out


@dataclass(frozen=True)
class PairingTable:
    """An ordered set of :class:`Pair` with a name (``"keraal"``, ``"ui_prmd"``, a file)."""

    name: str
    pairs: tuple[Pair, ...]

    def __post_init__(self) -> None:
        seen: set[str] = set()
        for p in self.pairs:
            key = normalise_name(p.track_joint)
            if key in seen:
                raise ValueError(f"pairing table {self.name!r}: joint {p.track_joint!r} twice")
            seen.add(key)
            if not p.mocap_points or any(not s.strip() for s in p.mocap_points):
                raise ValueError(f"pairing table {self.name!r}: empty mocap point in {p}")

    def __len__(self) -> int:
        return len(self.pairs)

    def resolve(
        self, track_names: Sequence[str], mocap_names: Sequence[str], *, strict: bool = False
    ) -> ResolvedPairs:
        """Find every pair's indices in the given name lists.

        Parameters
        ----------
        track_names : the track's joint names (length J).
        mocap_names : the mocap's point names (length M).
        strict : raise ``ValueError`` when a name is missing instead of dropping the pair.
        """
        tmap = {normalise_name(n): i for i, n in enumerate(track_names)}
        mmap = {normalise_name(n): i for i, n in enumerate(mocap_names)}
        ok, ti, mi, missing = [], [], [], []
        for p in self.pairs:
            j = tmap.get(normalise_name(p.track_joint))
            if j is None:
                missing.append((p, f"track joint {p.track_joint!r} not in track"))
                continue
            idx = [mmap.get(normalise_name(s)) for s in p.mocap_points]
            bad = [s for s, i in zip(p.mocap_points, idx) if i is None]
            if bad:
                missing.append((p, f"mocap point(s) {bad} not in mocap"))
                continue
            ok.append(p)
            ti.append(j)
            mi.append(tuple(int(i) for i in idx))  # type: ignore[arg-type]
        if strict and missing:
            reasons = "; ".join(r for _, r in missing)
            raise ValueError(f"pairing table {self.name!r}: {reasons}")
        if not ok:
            raise ValueError(
                f"pairing table {self.name!r}: no pair matches; track joints "
                f"{list(track_names)[:6]}..., mocap points {list(mocap_names)[:6]}..."
            )
        return ResolvedPairs(tuple(ok), tuple(ti), tuple(mi), tuple(missing))

    def to_csv(self) -> str:
        """The table in the user file format (round-trips through :func:`read_pairs`)."""
        return "track_joint,mocap_point\n" + "".join(f"{p}\n" for p in self.pairs)


def _table(name: str, rows: Sequence[tuple[str, str]]) -> PairingTable:
    return PairingTable(name, tuple(Pair(j, tuple(m.split("+"))) for j, m in rows))


# Kinect V2 joint ↔ KERAAL ART rigid target.  A joint is paired with the target on the
# segment whose motion carries it (the elbow is the distal end of the upper arm, the wrist
# of the forearm, the knee of the thigh, the ankle of the tibia), so that a constant offset
# in the target's own frame (``offset_mode="body"``) describes the joint.  21 body joints:
# the 25 Kinect joints minus hand tips and thumbs.
KERAAL_PAIRS = _table(
    "keraal",
    [
        ("SpineBase", "Hips"),
        ("SpineMid", "Chest"),
        ("SpineShoulder", "Chest"),
        ("Neck", "Chest"),
        ("Head", "Head"),
        ("ShoulderLeft", "Left Shoulder"),
        ("ElbowLeft", "Left Arm"),
        ("WristLeft", "Left Forearm"),
        ("HandLeft", "Left Hand"),
        ("ShoulderRight", "Right Shoulder"),
        ("ElbowRight", "Right Arm"),
        ("WristRight", "Right Forearm"),
        ("HandRight", "Right Hand"),
        ("HipLeft", "Hips"),
        ("KneeLeft", "Left Thigh"),
        ("AnkleLeft", "Left Tibia"),
        ("FootLeft", "Left Foot"),
        ("HipRight", "Hips"),
        ("KneeRight", "Right Thigh"),
        ("AnkleRight", "Right Tibia"),
        ("FootRight", "Right Foot"),
    ],
)

# UI-PRMD Kinect hierarchy point (proximal end of the named segment) ↔ Plug-in Gait
# marker(s).  Markers sit on the skin; a world-frame offset absorbs the mean difference.
UIPRMD_PAIRS = _table(
    "ui_prmd",
    [
        ("Waist", "LASI+RASI+LPSI+RPSI"),
        ("Chest", "T10+STRN"),
        ("Neck", "C7+CLAV"),
        ("Head", "LFHD+RFHD+LBHD+RBHD"),
        ("Left upper arm", "LSHO"),
        ("Left forearm", "LELB"),
        ("Left hand", "LWRA+LWRB"),
        ("Right upper arm", "RSHO"),
        ("Right forearm", "RELB"),
        ("Right hand", "RWRA+RWRB"),
        ("Left upper leg", "LASI+LPSI"),
        ("Left lower leg", "LKNE"),
        ("Left foot", "LANK"),
        ("Left toes", "LTOE"),
        ("Right upper leg", "RASI+RPSI"),
        ("Right lower leg", "RKNE"),
        ("Right foot", "RANK"),
        ("Right toes", "RTOE"),
    ],
)


def builtin_pairs(name: str) -> PairingTable:
    """A built-in table by name: ``"keraal"`` or ``"ui_prmd"`` (also ``"uiprmd"``)."""
    key = normalise_name(name)
    if key == "keraal":
        return KERAAL_PAIRS
    if key in ("uiprmd", "uiprmdkinect"):
        return UIPRMD_PAIRS
    raise ValueError(f"unknown built-in pairing table {name!r}; expected 'keraal' or 'ui_prmd'")


def read_pairs(path: str | Path) -> PairingTable:
    """Read a user pairing file (module docstring for the format).

    Raises
    ------
    ValueError
        naming the file and line of a malformed row, an empty name, or a joint listed twice.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise ValueError(f"{p}: cannot read pairing file: {exc}") from exc
    pairs: list[Pair] = []
    seen: dict[str, int] = {}
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        cells = [c.strip() for c in line.split(",")]
        if len(cells) == 3 and cells[2] == "":
            cells = cells[:2]
        if len(cells) != 2:
            raise ValueError(
                f"{p}:{lineno}: expected 'track_joint,mocap_point[+mocap_point...]', got {raw!r}"
            )
        joint, points = cells
        if not pairs and normalise_name(joint) in ("trackjoint", "joint") and not seen:
            continue  # header
        if not joint:
            raise ValueError(f"{p}:{lineno}: empty track joint name")
        names = tuple(s.strip() for s in points.split("+"))
        if any(not s for s in names):
            raise ValueError(f"{p}:{lineno}: empty mocap point name in {points!r}")
        key = normalise_name(joint)
        if key in seen:
            raise ValueError(f"{p}:{lineno}: joint {joint!r} already paired on line {seen[key]}")
        seen[key] = lineno
        pairs.append(Pair(joint, names))
    if not pairs:
        raise ValueError(f"{p}: pairing file has no pairs")
    return PairingTable(str(p), tuple(pairs))
