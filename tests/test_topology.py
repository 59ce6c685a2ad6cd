"""Topologies: built-in joint lists against the data README, tree validity, groups."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tobitkf.skeleton.topology import Topology, available_topologies, get_topology

# data README §9, written out independently of the module's tables
README_V2 = (
    "0 SpineBase, 1 SpineMid, 2 Neck, 3 Head, 4 ShoulderLeft, 5 ElbowLeft, 6 WristLeft, "
    "7 HandLeft, 8 ShoulderRight, 9 ElbowRight, 10 WristRight, 11 HandRight, 12 HipLeft, "
    "13 KneeLeft, 14 AnkleLeft, 15 FootLeft, 16 HipRight, 17 KneeRight, 18 AnkleRight, "
    "19 FootRight, 20 SpineShoulder, 21 HandTipLeft, 22 ThumbLeft, 23 HandTipRight, "
    "24 ThumbRight"
)
README_V2_PARENTS = (
    "1→0, 20→1, 2→20, 3→2, 4→20, 5→4, 6→5, 7→6, 21→7, 22→6, 8→20, 9→8, 10→9, "
    "11→10, 23→11, 24→10, 12→0, 13→12, 14→13, 15→14, 16→0, 17→16, 18→17, 19→18"
)


def test_kinect_v2_matches_readme():
    t = get_topology("kinect_v2")
    names = [item.split()[1] for item in README_V2.split(", ")]
    assert t.joints == tuple(names)
    expected = [-1] * 25
    for pair in README_V2_PARENTS.split(", "):
        child, parent = pair.split("→")
        expected[int(child)] = int(parent)
    assert t.parents == tuple(expected)
    assert t.up_axis == 1
    assert len(t.bones) == 24
    assert t.roots == [0]


@pytest.mark.parametrize(
    ("name", "n", "up"),
    [
        ("kinect_v2", 25, 1),
        ("kinect_v1", 20, 1),
        ("azure_kinect", 32, 1),
        ("mediapipe_pose", 33, 1),
        ("openpose_body25", 25, 1),
        ("ui_prmd", 22, 1),
        ("kinect_v2_21", 21, 1),
        ("krajjat", 21, 1),
        ("plug_in_gait_39", 39, 2),
        ("keraal_vicon_17", 17, 2),
        ("coco17", 17, 1),
        ("h36m17", 17, 1),
    ],
)
def test_builtin_sizes_trees_and_symmetry(name, n, up):
    t = get_topology(name)
    assert t.n_joints == n == len(t)
    assert t.up_axis == up
    # every joint reaches a root
    for j in range(n):
        k, steps = j, 0
        while k >= 0:
            k = t.parents[k]
            steps += 1
            assert steps <= n
    # symmetry pairs: left name then right name, each joint used at most once
    used = [i for pair in t.symmetry for i in pair]
    assert len(used) == len(set(used))
    for a, b in t.symmetry:
        assert "l" in t.joints[a][0].lower() or "left" in t.joints[a].lower()
        assert "r" in t.joints[b][0].lower() or "right" in t.joints[b].lower()
    mirror = t.mirror_indices()
    assert sorted(mirror) == list(range(n))
    assert [mirror[m] for m in mirror] == list(range(n))


def test_kinect_v2_symmetry_pairs_all_limbs():
    t = get_topology("kinect_v2")
    pairs = {(t.joints[a], t.joints[b]) for a, b in t.symmetry}
    for part in ("Shoulder", "Elbow", "Wrist", "Hand", "Hip", "Knee", "Ankle", "Foot",
                 "HandTip", "Thumb"):  # fmt: skip
        assert (part + "Left", part + "Right") in pairs
    assert len(pairs) == 10


def test_krajjat_topology_is_kinect_v2_subset_with_tree():
    t = get_topology("kinect_v2_21")
    assert t.joints[:5] == ("Head", "Neck", "SpineShoulder", "SpineMid", "SpineBase")
    v2 = get_topology("kinect_v2")
    assert set(t.joints) == set(v2.joints) - {"HandTipLeft", "ThumbLeft", "HandTipRight",
                                              "ThumbRight"}  # fmt: skip
    # every bone of the subset is a bone of kinect_v2 (no tips/thumbs removed inside chains)
    for p, c in t.bones:
        assert v2.parents[v2.index(t.joints[c])] == v2.index(t.joints[p])
    assert t.parents[t.index("SpineBase")] == -1


def test_ui_prmd_tree_matches_readme():
    t = get_topology("ui_prmd")
    text = (
        "0 Waist; 1 Spine (0); 2 Chest (1); 3 Neck (2); 4 Head (3); 5 Head tip (4); "
        "6 Left collar (2); 7 Left upper arm (6); 8 Left forearm (7); 9 Left hand (8); "
        "10 Right collar (2); 11 Right upper arm (10); 12 Right forearm (11); 13 Right hand (12); "
        "14 Left upper leg (0); 15 Left lower leg (14); 16 Left foot (15); 17 Left toes (16); "
        "18 Right upper leg (0); 19 Right lower leg (18); 20 Right foot (19); 21 Right toes (20)"
    )
    for k, item in enumerate(text.split("; ")):
        parent = int(item[item.index("(") + 1 : -1]) if "(" in item else -1
        assert t.parents[k] == parent


def test_joint_groups_partition_kinect_v2():
    t = get_topology("kinect_v2")
    g = t.joint_groups()
    assert set(g) == {"hands", "arms", "torso", "legs"}
    allj = sorted(i for v in g.values() for i in v)
    assert allj == list(range(25))
    names = {k: {t.joints[i] for i in v} for k, v in g.items()}
    assert names["hands"] == {"WristLeft", "HandLeft", "HandTipLeft", "ThumbLeft",
                              "WristRight", "HandRight", "HandTipRight", "ThumbRight"}  # fmt: skip
    assert names["arms"] == {"ShoulderLeft", "ElbowLeft", "ShoulderRight", "ElbowRight"}
    assert names["torso"] == {"SpineBase", "SpineMid", "Neck", "Head", "SpineShoulder"}
    assert names["legs"] == {"HipLeft", "KneeLeft", "AnkleLeft", "FootLeft", "HipRight",
                             "KneeRight", "AnkleRight", "FootRight"}  # fmt: skip


@pytest.mark.parametrize("name", ["kinect_v1", "azure_kinect", "kinect_v2_21", "ui_prmd"])
def test_joint_groups_partition_other_kinect_like(name):
    t = get_topology(name)
    g = t.joint_groups()
    assert sorted(i for v in g.values() for i in v) == list(range(t.n_joints))
    assert all(len(v) >= 2 for v in g.values())
    head = next(j for j in t.joints if j.lower().startswith("head"))
    assert t.index(head) in g["torso"]


def test_index_and_errors():
    t = get_topology("kinect_v2")
    assert t.index("HandRight") == 11
    with pytest.raises(KeyError, match="no joint 'Hand'"):
        t.index("Hand")
    with pytest.raises(KeyError, match="unknown topology"):
        get_topology("kinect_v9")
    assert "kinect_v2" in available_topologies()


def test_validation_errors():
    with pytest.raises(ValueError, match="duplicate"):
        Topology("x", ("a", "a"))
    with pytest.raises(ValueError, match="parents"):
        Topology("x", ("a", "b"), (-1,))
    with pytest.raises(ValueError, match="cycle"):
        Topology("x", ("a", "b", "c"), (-1, 2, 1))
    with pytest.raises(ValueError, match="invalid parent"):
        Topology("x", ("a", "b"), (-1, 5))
    with pytest.raises(ValueError, match="up_axis"):
        Topology("x", ("a",), up_axis=3)
    with pytest.raises(ValueError, match="symmetry"):
        Topology("x", ("a", "b"), symmetry=((0, 0),))
    with pytest.raises(ValueError, match="at least one joint"):
        Topology("x", ())


def test_from_names_with_parent_names_and_symmetry():
    t = Topology.from_names(
        ["pelvis", "LeftKnee", "RightKnee"], [None, "pelvis", "pelvis"], up_axis=2
    )
    assert t.parents == (-1, 0, 0)
    assert t.symmetry == ((1, 2),)
    assert t.up_axis == 2
    assert t.bones == [(0, 1), (0, 2)]
    plain = Topology.from_names(["a", "b"])
    assert plain.bones == [] and plain.roots == [0, 1]


def test_topology_is_frozen_and_hashable():
    t = get_topology("kinect_v2")
    with pytest.raises(AttributeError):
        t.name = "y"  # type: ignore[misc]
    assert hash(t) == hash(get_topology("kinect_v2"))


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_subset_keeps_ancestry(data):
    t = get_topology("kinect_v2")
    keep = data.draw(st.lists(st.sampled_from(t.joints), min_size=1, max_size=25, unique=True))
    sub = t.subset(keep)
    assert sub.joints == tuple(keep)
    for j, p in enumerate(sub.parents):
        if p >= 0:  # the new parent is an ancestor in the full tree
            k = t.parents[t.index(keep[j])]
            ancestors = []
            while k >= 0:
                ancestors.append(t.joints[k])
                k = t.parents[k]
            assert keep[p] in ancestors
        else:  # no kept ancestor
            k = t.parents[t.index(keep[j])]
            while k >= 0:
                assert t.joints[k] not in keep
                k = t.parents[k]


# COCO's person_keypoints category (annotations/person_keypoints_*.json): its keypoint
# names and its skeleton edges, 1-based, as the COCO files give them.
COCO_KEYPOINTS = (
    "nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hip",
    "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
)  # fmt: skip
COCO_SKELETON = (
    (16, 14), (14, 12), (17, 15), (15, 13), (12, 13), (6, 12), (7, 13), (6, 7), (6, 8),
    (7, 9), (8, 10), (9, 11), (2, 3), (1, 2), (1, 3), (2, 4), (3, 5), (4, 6), (5, 7),
)  # fmt: skip


def test_coco17_is_cocos_keypoints_and_a_tree_of_its_skeleton():
    t = get_topology("coco")
    assert t.name == "coco17" and t.joints == COCO_KEYPOINTS
    edges = {frozenset((a - 1, b - 1)) for a, b in COCO_SKELETON}
    assert all(frozenset(bone) in edges for bone in t.bones)  # every bone is a COCO edge
    assert len(t.bones) == 16 and t.roots == [0]  # a spanning tree of the 17 keypoints
    assert t.joint_groups() == {
        "hands": [9, 10],  # wrists
        "arms": [5, 6, 7, 8],  # shoulders, elbows
        "torso": [0, 1, 2, 3, 4],  # face
        "legs": [11, 12, 13, 14, 15, 16],  # hips, knees, ankles
    }
    assert len(t.symmetry) == 8  # every keypoint but the nose has its mirror


# Human3.6M's 17 joints as VideoPose3D (common/h36m_dataset.py) keeps them: its 32-joint
# tree with the joints [4, 5, 9, 10, 11, 16, 20, 21, 22, 23, 24, 28, 29, 30, 31] removed,
# each remaining joint re-attached to its nearest kept ancestor, and then, as it does
# ("Rewire shoulders to the correct parents"), both shoulders hung from joint 8.
H36M32_PARENTS = (
    -1, 0, 1, 2, 3, 4, 0, 6, 7, 8, 9, 0, 11, 12, 13, 14, 12, 16, 17, 18, 19, 20, 19, 22, 12,
    24, 25, 26, 27, 28, 27, 30,
)  # fmt: skip
H36M_REMOVED = (4, 5, 9, 10, 11, 16, 20, 21, 22, 23, 24, 28, 29, 30, 31)
H36M_LEFT = (4, 5, 6, 11, 12, 13)  # VideoPose3D's joints_left after the removal
H36M_RIGHT = (1, 2, 3, 14, 15, 16)


def test_h36m17_is_videopose3ds_reduced_human36m_tree():
    kept = [j for j in range(32) if j not in H36M_REMOVED]
    full = Topology(name="h36m32", joints=tuple(f"j{j}" for j in range(32)),
                    parents=H36M32_PARENTS)  # fmt: skip
    reduced = list(full.subset([f"j{j}" for j in kept]).parents)
    reduced[11] = reduced[14] = 8
    t = get_topology("h36m")
    assert t.name == "h36m17" and t.n_joints == 17
    assert t.parents == tuple(reduced)
    assert sorted(t.symmetry) == sorted(zip(H36M_LEFT, H36M_RIGHT, strict=True))
    groups = t.joint_groups()
    assert groups["hands"] == [13, 16] and groups["arms"] == [11, 12, 14, 15]
    assert groups["legs"] == [1, 2, 3, 4, 5, 6] and groups["torso"] == [0, 7, 8, 9, 10]
