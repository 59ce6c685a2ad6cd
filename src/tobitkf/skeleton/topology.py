"""Skeleton topologies: joint names, parents (bones), left/right symmetry and up axis.

A :class:`Topology` is a frozen description of a point set. Devices with a kinematic tree
(Kinect, Azure Kinect, MediaPipe, OpenPose, UI-PRMD, BVH) give a parent per joint; marker
sets (Vicon Plug-in Gait, KERAAL ART targets, Qualisys, C3D) are plain named point sets in
which every point is a root (parent ``-1``) and there are no bones.

Up axis: Kinect camera space has y up (``1``); Vicon / Qualisys / C3D worlds have z up
(``2``); BVH has y up. Azure Kinect, MediaPipe and OpenPose use image-like frames whose
y axis points *down*; their up axis is still the y axis (``1``), the sign is not stored.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

__all__ = [
    "UNNAMED",
    "Topology",
    "available_topologies",
    "get_topology",
    "parents_from_edges",
    "register_topology",
]

GROUP_NAMES = ("hands", "arms", "torso", "legs")
#: the name of a reader's topology when the file names no skeleton (an array, MMPose
#: output of an unknown model): joints ``0``, ``1``, ... without bones; the batch tools'
#: ``--topology`` replaces it
UNNAMED = "unnamed"


@dataclass(frozen=True)
class Topology:
    """Joint names, kinematic tree and symmetry of a skeleton.

    Parameters
    ----------
    name : str
        Identifier (e.g. ``"kinect_v2"``), used by :func:`get_topology`.
    joints : tuple of str, length J
        Unique joint (or marker) names in array order.
    parents : tuple of int, length J
        Parent index of each joint, ``-1`` for a root. Must describe a forest (no cycles).
    symmetry : tuple of (int, int)
        Left/right pairs ``(left, right)`` of joint indices.
    up_axis : int
        Vertical axis of the coordinate frame: 0 = x, 1 = y, 2 = z.
    """

    name: str
    joints: tuple[str, ...]
    parents: tuple[int, ...] = ()
    symmetry: tuple[tuple[int, int], ...] = ()
    up_axis: int = 1
    _index: dict[str, int] = field(init=False, repr=False, compare=False, hash=False)

    def __post_init__(self) -> None:
        joints = tuple(str(j) for j in self.joints)
        object.__setattr__(self, "joints", joints)
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"topology name must be a non-empty string, found {self.name!r}")
        n = len(joints)
        if n == 0:
            raise ValueError(f"topology {self.name!r}: expected at least one joint, found 0")
        if len(set(joints)) != n:
            dup = sorted({j for j in joints if joints.count(j) > 1})
            raise ValueError(f"topology {self.name!r}: duplicate joint names {dup}")
        parents = tuple(int(p) for p in self.parents) if self.parents else (-1,) * n
        if len(parents) != n:
            raise ValueError(
                f"topology {self.name!r}: expected {n} parents (one per joint), "
                f"found {len(parents)}"
            )
        for j, p in enumerate(parents):
            if p < -1 or p >= n or p == j:
                raise ValueError(
                    f"topology {self.name!r}: joint {j} ({joints[j]}) has invalid parent {p}; "
                    f"expected -1 or an index in [0, {n}) other than {j}"
                )
        for j in range(n):  # cycle check: walking up must reach a root within n steps
            k, steps = j, 0
            while k != -1:
                k = parents[k]
                steps += 1
                if steps > n:
                    raise ValueError(
                        f"topology {self.name!r}: parents form a cycle through joint {joints[j]}"
                    )
        object.__setattr__(self, "parents", parents)
        sym = tuple((int(a), int(b)) for a, b in self.symmetry)
        for a, b in sym:
            if not (0 <= a < n and 0 <= b < n) or a == b:
                raise ValueError(
                    f"topology {self.name!r}: invalid symmetry pair ({a}, {b}); "
                    f"expected two different indices in [0, {n})"
                )
        object.__setattr__(self, "symmetry", sym)
        if self.up_axis not in (0, 1, 2):
            raise ValueError(
                f"topology {self.name!r}: up_axis must be 0, 1 or 2, found {self.up_axis!r}"
            )
        object.__setattr__(self, "up_axis", int(self.up_axis))
        object.__setattr__(self, "_index", {name: i for i, name in enumerate(joints)})

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_names(
        cls,
        names: Iterable[str],
        parents: Sequence[int] | Sequence[str | None] | None = None,
        up_axis: int = 1,
        *,
        name: str = "custom",
        symmetry: Sequence[tuple[int, int]] | None = None,
        edges: Iterable[tuple[int | str, int | str]] | None = None,
    ) -> Topology:
        """Build a topology from joint names (and the bones a file declares, if any).

        Parameters
        ----------
        names : iterable of str, length J
        parents : sequence of int (``-1`` root) or of parent names (``None`` root), optional
            Without it every joint is a root (a plain point set, no bones).
        up_axis : int
            0 = x, 1 = y, 2 = z.
        name : str
            Topology name.
        symmetry : sequence of (int, int), optional
            Left/right pairs; by default inferred from the names (``Left``/``Right``,
            ``left_``/``right_``, ``L``/``R`` prefixes, ``_l``/``_r`` suffixes).
        edges : iterable of (a, b) joint names or indices, optional
            Bones as a pose file declares them (a DeepLabCut ``skeleton``, SLEAP
            ``edge_inds``), instead of ``parents``: see :func:`parents_from_edges`.
        """
        joints = tuple(str(n) for n in names)
        if edges is not None:
            if parents is not None:
                raise ValueError("give parents or edges, not both")
            parents = parents_from_edges(joints, edges)
        if parents is not None:
            index = {j: i for i, j in enumerate(joints)}
            resolved = []
            for p in parents:
                if p is None:
                    resolved.append(-1)
                elif isinstance(p, str):
                    if p not in index:
                        raise ValueError(f"unknown parent joint {p!r}; expected one of {joints}")
                    resolved.append(index[p])
                else:
                    resolved.append(int(p))
            parents_t: tuple[int, ...] = tuple(resolved)
        else:
            parents_t = (-1,) * len(joints)
        sym = tuple(symmetry) if symmetry is not None else infer_symmetry(joints)
        return cls(name=name, joints=joints, parents=parents_t, symmetry=sym, up_axis=up_axis)

    # ------------------------------------------------------------------ queries
    @property
    def n_joints(self) -> int:
        """Number of joints J."""
        return len(self.joints)

    def __len__(self) -> int:
        return len(self.joints)

    def index(self, name: str) -> int:
        """Index of joint ``name``; ``KeyError`` naming the known joints otherwise."""
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(
                f"topology {self.name!r} has no joint {name!r}; joints: {list(self.joints)}"
            ) from None

    def indices(self, names: Iterable[str]) -> list[int]:
        """Indices of several joints, in the given order."""
        return [self.index(n) for n in names]

    @property
    def bones(self) -> list[tuple[int, int]]:
        """``(parent, child)`` index pairs, one per non-root joint, in joint order."""
        return [(p, j) for j, p in enumerate(self.parents) if p >= 0]

    @property
    def roots(self) -> list[int]:
        """Indices of the root joints (parent ``-1``)."""
        return [j for j, p in enumerate(self.parents) if p < 0]

    def mirror_indices(self) -> list[int]:
        """Permutation that swaps left and right joints (identity for unpaired joints)."""
        perm = list(range(self.n_joints))
        for a, b in self.symmetry:
            perm[a], perm[b] = b, a
        return perm

    def joint_groups(self) -> dict[str, list[int]]:
        """Joint indices per body region: ``hands``, ``arms``, ``torso``, ``legs``.

        Regions (by joint name, so it works for every Kinect-like topology): ``hands`` =
        wrists, hands, hand tips, thumbs, fingers; ``arms`` = collars/clavicles, shoulders,
        elbows, upper arms and forearms; ``legs`` = hips, knees, ankles, feet, toes, heels
        and leg segments; ``torso`` = everything else (spine, pelvis, neck, head, face).
        Every joint is in exactly one group.
        """
        return {g: list(idx) for g, idx in _groups_of(self.joints).items()}

    def subset(self, names: Sequence[str], name: str | None = None) -> Topology:
        """Topology restricted to ``names`` (in that order).

        A joint whose parent is dropped is re-attached to its nearest kept ancestor (or
        becomes a root). Symmetry pairs with both joints kept are preserved.
        """
        idx = self.indices(names)
        if len(set(idx)) != len(idx):
            raise ValueError(f"duplicate joints in selection {list(names)}")
        new_of_old = {old: new for new, old in enumerate(idx)}
        parents = []
        for old in idx:
            p = self.parents[old]
            while p >= 0 and p not in new_of_old:
                p = self.parents[p]
            parents.append(new_of_old[p] if p >= 0 else -1)
        sym = tuple(
            (new_of_old[a], new_of_old[b])
            for a, b in self.symmetry
            if a in new_of_old and b in new_of_old
        )
        return Topology(
            name=name or f"{self.name}_subset",
            joints=tuple(self.joints[i] for i in idx),
            parents=tuple(parents),
            symmetry=sym,
            up_axis=self.up_axis,
        )


def parents_from_edges(
    joints: Sequence[str], edges: Iterable[tuple[int | str, int | str]]
) -> tuple[int, ...]:
    """Parent of each joint from undirected or directed bones ``(a, b)``.

    When the edges read as ``(parent, child)`` form a forest (every joint has at most one
    incoming edge and there is no cycle), that is the tree (SLEAP's directed skeletons).
    Otherwise (a graph such as MediaPipe's connections, or DeepLabCut's undirected
    ``skeleton``) the tree is a breadth-first spanning forest of the graph, each component
    rooted at its joint listed first; edges that would close a cycle are left out.
    Self-loops and repeated edges are ignored; an unknown joint is a ``ValueError``.
    """
    joints = tuple(joints)
    index = {j: i for i, j in enumerate(joints)}
    n = len(joints)

    def resolve(v: int | str) -> int:
        if isinstance(v, str) and v in index:
            return index[v]
        if not isinstance(v, str):
            try:
                i = int(v)
            except (TypeError, ValueError):
                i = -1
            if 0 <= i < n:
                return i
        raise ValueError(f"bone end {v!r} is not a joint; joints: {list(joints)}")

    pairs = []
    for e in edges:
        a, b = e
        ia, ib = resolve(a), resolve(b)
        if ia != ib and (ia, ib) not in pairs and (ib, ia) not in pairs:
            pairs.append((ia, ib))
    parents = [-1] * n
    directed = True
    for a, b in pairs:
        if parents[b] != -1:
            directed = False
            break
        parents[b] = a
    if directed:
        for j in range(n):  # a cycle never reaches a root
            k, steps = j, 0
            while k != -1 and steps <= n:
                k, steps = parents[k], steps + 1
            if k != -1:
                directed = False
                break
    if directed:
        return tuple(parents)
    neighbours: list[list[int]] = [[] for _ in range(n)]
    for a, b in pairs:
        neighbours[a].append(b)
        neighbours[b].append(a)
    parents = [-1] * n
    seen = [False] * n
    for root in range(n):
        if seen[root]:
            continue
        seen[root] = True
        queue = [root]
        while queue:
            u = queue.pop(0)
            for v in neighbours[u]:
                if not seen[v]:
                    seen[v] = True
                    parents[v] = u
                    queue.append(v)
    return tuple(parents)


# ---------------------------------------------------------------------- name helpers
_FOOT = re.compile(r"foot|toe", re.I)
_HAND = re.compile(
    r"hand|wrist|thumb|finger|pinky|_index$|fin$|wr[ab]$|^[lr]hn|^[lr]ra[oalp]$", re.I
)
_TORSO = re.compile(
    r"spine|center|mid|pelvis|waist|neck|head|chest|nose|eye|mouth|back|^hips?$|ear(?!m)", re.I
)
_ARM = re.compile(
    r"shoulder|elbow|arm|collar|clavicle|sho$|elb$|upa$|frm$|^[lr]hu[oalp]$|^[lr]cl[oalp]$", re.I
)
_LEG = re.compile(
    r"hip|knee|ankle|foot|toe|heel|leg|thigh|shin|tibia|kne$|ank$|hee$|thi$|tib$|^[lr](fe|ti)[oalp]$",
    re.I,
)


@functools.lru_cache(maxsize=64)
def _groups_of(joints: tuple[str, ...]) -> dict[str, tuple[int, ...]]:
    """The regions of :meth:`Topology.joint_groups` (cached: a live smoother asks at
    every frame, and the names' patterns cost a few hundred searches)."""
    groups: dict[str, list[int]] = {g: [] for g in GROUP_NAMES}
    for i, j in enumerate(joints):
        groups[_classify(j)].append(i)
    return {g: tuple(idx) for g, idx in groups.items()}


def _classify(joint: str) -> str:
    if _FOOT.search(joint):
        return "legs"
    if _HAND.search(joint):
        return "hands"
    if _TORSO.search(joint):
        return "torso"
    if _ARM.search(joint):
        return "arms"
    if _LEG.search(joint):
        return "legs"
    return "torso"


_SWAPS = (
    ("Left", "Right"),
    ("left", "right"),
    ("LEFT", "RIGHT"),
)


def infer_symmetry(joints: Sequence[str]) -> tuple[tuple[int, int], ...]:
    """Left/right pairs found from joint names (``Left``/``Right`` anywhere, ``L``/``R``
    as first letter, ``_l``/``_r`` or ``_L``/``_R`` suffixes)."""
    index = {j: i for i, j in enumerate(joints)}
    pairs: list[tuple[int, int]] = []
    for i, j in enumerate(joints):
        candidates = [j.replace(a, b) for a, b in _SWAPS if a in j]
        if j[:1] == "L" and len(j) > 1:
            candidates.append("R" + j[1:])
        if j[:1] == "l" and len(j) > 1 and not j.startswith("left"):
            candidates.append("r" + j[1:])
        for suf_l, suf_r in (("_l", "_r"), ("_L", "_R")):
            if j.endswith(suf_l):
                candidates.append(j[: -len(suf_l)] + suf_r)
        for c in candidates:
            k = index.get(c)
            if k is not None and k != i:
                pairs.append((i, k))
                break
    return tuple(pairs)


# ---------------------------------------------------------------------- built-ins
KINECT_V2_JOINTS = (
    "SpineBase", "SpineMid", "Neck", "Head", "ShoulderLeft", "ElbowLeft", "WristLeft",
    "HandLeft", "ShoulderRight", "ElbowRight", "WristRight", "HandRight", "HipLeft",
    "KneeLeft", "AnkleLeft", "FootLeft", "HipRight", "KneeRight", "AnkleRight", "FootRight",
    "SpineShoulder", "HandTipLeft", "ThumbLeft", "HandTipRight", "ThumbRight",
)  # fmt: skip
# data README §9 (Kinect SDK JointType)
KINECT_V2_PARENTS = (
    -1, 0, 20, 2, 20, 4, 5, 6, 20, 8, 9, 10, 0, 12, 13, 14, 0, 16, 17, 18, 1, 7, 6, 11, 10,
)  # fmt: skip

KINECT_V1_JOINTS = (
    "HipCenter", "Spine", "ShoulderCenter", "Head", "ShoulderLeft", "ElbowLeft", "WristLeft",
    "HandLeft", "ShoulderRight", "ElbowRight", "WristRight", "HandRight", "HipLeft",
    "KneeLeft", "AnkleLeft", "FootLeft", "HipRight", "KneeRight", "AnkleRight", "FootRight",
)  # fmt: skip
KINECT_V1_PARENTS = (-1, 0, 1, 2, 2, 4, 5, 6, 2, 8, 9, 10, 0, 12, 13, 14, 0, 16, 17, 18)

AZURE_KINECT_JOINTS = (
    "PELVIS", "SPINE_NAVEL", "SPINE_CHEST", "NECK", "CLAVICLE_LEFT", "SHOULDER_LEFT",
    "ELBOW_LEFT", "WRIST_LEFT", "HAND_LEFT", "HANDTIP_LEFT", "THUMB_LEFT", "CLAVICLE_RIGHT",
    "SHOULDER_RIGHT", "ELBOW_RIGHT", "WRIST_RIGHT", "HAND_RIGHT", "HANDTIP_RIGHT",
    "THUMB_RIGHT", "HIP_LEFT", "KNEE_LEFT", "ANKLE_LEFT", "FOOT_LEFT", "HIP_RIGHT",
    "KNEE_RIGHT", "ANKLE_RIGHT", "FOOT_RIGHT", "HEAD", "NOSE", "EYE_LEFT", "EAR_LEFT",
    "EYE_RIGHT", "EAR_RIGHT",
)  # fmt: skip
AZURE_KINECT_PARENTS = (
    -1, 0, 1, 2, 2, 4, 5, 6, 7, 8, 7, 2, 11, 12, 13, 14, 15, 14, 0, 18, 19, 20, 0, 22, 23,
    24, 3, 26, 26, 26, 26, 26,
)  # fmt: skip

MEDIAPIPE_POSE_JOINTS = (
    "nose", "left_eye_inner", "left_eye", "left_eye_outer", "right_eye_inner", "right_eye",
    "right_eye_outer", "left_ear", "right_ear", "mouth_left", "mouth_right", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_pinky",
    "right_pinky", "left_index", "right_index", "left_thumb", "right_thumb", "left_hip",
    "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle", "left_heel",
    "right_heel", "left_foot_index", "right_foot_index",
)  # fmt: skip
# MediaPipe defines connections, not a tree; this tree is rooted at the nose and follows
# the POSE_CONNECTIONS graph (shoulders hang from the nose, hips from the shoulders).
MEDIAPIPE_POSE_PARENTS = (
    -1, 0, 1, 2, 0, 4, 5, 3, 6, 0, 0, 0, 0, 11, 12, 13, 14, 15, 16, 15, 16, 15, 16, 11, 12,
    23, 24, 25, 26, 27, 28, 27, 28,
)  # fmt: skip

OPENPOSE_BODY25_JOINTS = (
    "Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist",
    "MidHip", "RHip", "RKnee", "RAnkle", "LHip", "LKnee", "LAnkle", "REye", "LEye", "REar",
    "LEar", "LBigToe", "LSmallToe", "LHeel", "RBigToe", "RSmallToe", "RHeel",
)  # fmt: skip
OPENPOSE_BODY25_PARENTS = (
    1, -1, 1, 2, 3, 1, 5, 6, 1, 8, 9, 10, 8, 12, 13, 0, 0, 15, 16, 14, 14, 14, 11, 11, 11,
)  # fmt: skip

# data README §2: joint order and parents of the UI-PRMD Kinect hierarchy
UI_PRMD_JOINTS = (
    "Waist", "Spine", "Chest", "Neck", "Head", "HeadTip", "LeftCollar", "LeftUpperArm",
    "LeftForearm", "LeftHand", "RightCollar", "RightUpperArm", "RightForearm", "RightHand",
    "LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "LeftToes", "RightUpperLeg", "RightLowerLeg",
    "RightFoot", "RightToes",
)  # fmt: skip
UI_PRMD_PARENTS = (-1, 0, 1, 2, 3, 4, 2, 6, 7, 8, 2, 10, 11, 12, 0, 14, 15, 16, 0, 18, 19, 20)

# data README §4: the 21-joint order of the krajjat Kinect TSV (SDK names, not SDK order)
KRAJJAT_JOINTS = (
    "Head", "Neck", "SpineShoulder", "SpineMid", "SpineBase", "ShoulderLeft", "ElbowLeft",
    "WristLeft", "HandLeft", "ShoulderRight", "ElbowRight", "WristRight", "HandRight",
    "HipLeft", "KneeLeft", "AnkleLeft", "FootLeft", "HipRight", "KneeRight", "AnkleRight",
    "FootRight",
)  # fmt: skip

# data README §2: the 39 Plug-in Gait markers of the UI-PRMD Vicon files
PLUG_IN_GAIT_39 = (
    "LFHD", "RFHD", "LBHD", "RBHD", "C7", "T10", "CLAV", "STRN", "RBAK", "LSHO", "LUPA",
    "LELB", "LFRM", "LWRA", "LWRB", "LFIN", "RSHO", "RUPA", "RELB", "RFRM", "RWRA", "RWRB",
    "RFIN", "LASI", "RASI", "LPSI", "RPSI", "LTHI", "LKNE", "LTIB", "LANK", "LHEE", "LTOE",
    "RTHI", "RKNE", "RTIB", "RANK", "RHEE", "RTOE",
)  # fmt: skip

# data README §1: the 17 ART rigid-body targets of the KERAAL Vicon files
KERAAL_VICON_17 = (
    "RightForearm", "LeftForearm", "RightArm", "LeftArm", "Chest", "RightThigh", "LeftThigh",
    "RightShoulder", "LeftShoulder", "RightHand", "LeftHand", "RightFoot", "LeftFoot", "Hips",
    "Head", "RightTibia", "LeftTibia",
)  # fmt: skip


# The 17 COCO keypoints (COCO's person_keypoints order), the layout of most 2-D pose
# estimators (MMPose / RTMPose, ViTPose, YOLO-pose, Detectron2, AlphaPose's COCO model).
# COCO declares a skeleton graph, not a tree; this tree is the breadth-first spanning
# tree of that graph from the nose (``parents_from_edges``): COCO has no neck, and its
# edges hang the shoulders from the ears, the hips from the shoulders.
COCO17_JOINTS = (
    "nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hip",
    "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
)  # fmt: skip
COCO17_PARENTS = (-1, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 5, 6, 11, 12, 13, 14)

# The 17 Human3.6M joints in the order of the 3-D pose lifters (VideoPose3D's h36m
# skeleton with its static joints removed; MotionBERT, MHFormer, PoseFormer): the pelvis
# root, the legs, the spine to the head, then the arms from the thorax.
H36M17_JOINTS = (
    "Pelvis", "RHip", "RKnee", "RAnkle", "LHip", "LKnee", "LAnkle", "Spine", "Thorax",
    "Nose", "Head", "LShoulder", "LElbow", "LWrist", "RShoulder", "RElbow", "RWrist",
)  # fmt: skip
H36M17_PARENTS = (-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 9, 8, 11, 12, 8, 14, 15)


def _build(name: str, joints: Sequence[str], parents: Sequence[int] | None, up: int) -> Topology:
    t = Topology.from_names(joints, parents, up_axis=up, name=name)
    return t


def _kinect_v2_21() -> Topology:
    v2 = _BUILTINS["kinect_v2"]
    return v2.subset(KRAJJAT_JOINTS, name="kinect_v2_21")


_BUILTINS: dict[str, Topology] = {}
_BUILTINS["kinect_v2"] = _build("kinect_v2", KINECT_V2_JOINTS, KINECT_V2_PARENTS, 1)
_BUILTINS["kinect_v1"] = _build("kinect_v1", KINECT_V1_JOINTS, KINECT_V1_PARENTS, 1)
_BUILTINS["azure_kinect"] = _build("azure_kinect", AZURE_KINECT_JOINTS, AZURE_KINECT_PARENTS, 1)
_BUILTINS["mediapipe_pose"] = _build(
    "mediapipe_pose", MEDIAPIPE_POSE_JOINTS, MEDIAPIPE_POSE_PARENTS, 1
)
_BUILTINS["openpose_body25"] = _build(
    "openpose_body25", OPENPOSE_BODY25_JOINTS, OPENPOSE_BODY25_PARENTS, 1
)
_BUILTINS["ui_prmd"] = _build("ui_prmd", UI_PRMD_JOINTS, UI_PRMD_PARENTS, 1)
_BUILTINS["coco17"] = _build("coco17", COCO17_JOINTS, COCO17_PARENTS, 1)
_BUILTINS["h36m17"] = _build("h36m17", H36M17_JOINTS, H36M17_PARENTS, 1)
_BUILTINS["kinect_v2_21"] = _kinect_v2_21()
_BUILTINS["plug_in_gait_39"] = _build("plug_in_gait_39", PLUG_IN_GAIT_39, None, 2)
_BUILTINS["keraal_vicon_17"] = _build("keraal_vicon_17", KERAAL_VICON_17, None, 2)

_ALIASES = {
    "krajjat": "kinect_v2_21",
    "kinect": "kinect_v2",
    "kinect_v2_25": "kinect_v2",
    "body25": "openpose_body25",
    "openpose": "openpose_body25",
    "mediapipe": "mediapipe_pose",
    "uiprmd": "ui_prmd",
    "ui_prmd_vicon": "plug_in_gait_39",
    "keraal_vicon": "keraal_vicon_17",
    "coco": "coco17",
    "coco_17": "coco17",
    "h36m": "h36m17",
    "h36m_17": "h36m17",
    "human36m": "h36m17",
}


def register_topology(topology: Topology, *, overwrite: bool = False) -> None:
    """Make ``topology`` available by name through :func:`get_topology`."""
    if topology.name in _BUILTINS and not overwrite:
        raise ValueError(f"a topology named {topology.name!r} already exists")
    _BUILTINS[topology.name] = topology


def available_topologies() -> list[str]:
    """Names accepted by :func:`get_topology` (aliases excluded)."""
    return sorted(_BUILTINS)


def get_topology(name: str) -> Topology:
    """Built-in (or registered) topology by name.

    Names: ``kinect_v2`` (25, SDK order), ``kinect_v1`` (20), ``azure_kinect`` (32),
    ``mediapipe_pose`` (33), ``openpose_body25`` (25), ``coco17`` / ``coco`` (17 COCO
    keypoints), ``h36m17`` / ``h36m`` (17 Human3.6M joints of the 3-D lifters),
    ``ui_prmd`` (22),
    ``kinect_v2_21`` / ``krajjat`` (21, krajjat TSV order), ``plug_in_gait_39`` (39
    markers, z up), ``keraal_vicon_17`` (17 ART targets, z up).
    """
    key = str(name).strip()
    key = _ALIASES.get(key.lower(), key)
    if key in _BUILTINS:
        return _BUILTINS[key]
    if key.lower() in _BUILTINS:
        return _BUILTINS[key.lower()]
    raise KeyError(f"unknown topology {name!r}; expected one of {available_topologies()}")
