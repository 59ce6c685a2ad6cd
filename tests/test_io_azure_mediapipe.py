"""Azure Kinect Body Tracking JSON and MediaPipe Pose landmarks.

Azure fixtures are written the way the SDK sample ``offline_processor`` writes them:
nlohmann::json with ``std::setw(4)`` (4-space indent, keys sorted, shortest round-trip
doubles of the SDK's float32 values), which is ``json.dumps(indent=4, sort_keys=True)``
of the same document. MediaPipe fixtures are the Pose Landmarker's result fields
(``dataclasses.asdict`` of its landmarks) and the long CSV ``pandas`` writes of them.
Expected values are the written numbers with the documented conversions (mm -> m: × 1e-3;
confidence level / 3), never the reader's output.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from tobitkf.io import ReadError, detect_format, load
from tobitkf.io.azure_kinect import read_azure_kinect
from tobitkf.io.mediapipe import read_mediapipe
from tobitkf.skeleton.topology import AZURE_KINECT_JOINTS, MEDIAPIPE_POSE_JOINTS, get_topology

BONES = [
    ("SPINE_CHEST", "SPINE_NAVEL"), ("SPINE_NAVEL", "PELVIS"), ("SPINE_CHEST", "NECK"),
    ("NECK", "HEAD"), ("HEAD", "NOSE"),
]  # fmt: skip


def _azure_doc(rng, T=4, levels=False):
    """Two bodies: id 1 in every frame, id 2 from frame 1 on."""
    frames = []
    truth = {}
    for t in range(T):
        bodies = []
        for bid in (1, 2) if t else (1,):
            pos = rng.normal([0, 0, 2000], 300, size=(32, 3)).astype(np.float32).astype(float)
            ori = rng.normal(size=(32, 4)).astype(np.float32).astype(float)
            body = {
                "body_id": bid,
                "joint_positions": pos.tolist(),
                "joint_orientations": ori.tolist(),
            }
            if levels:
                lv = rng.integers(0, 4, size=32)
                body["joint_confidence_levels"] = lv.tolist()
                truth[(bid, t, "levels")] = lv
            truth[(bid, t)] = (pos, ori)
            bodies.append(body)
        frames.append(
            {
                "bodies": bodies,
                "frame_id": t,
                "num_bodies": len(bodies),
                "timestamp_usec": 133322 + 33333 * t,
            }
        )
    doc = {
        "bone_list": [list(b) for b in BONES],
        "frames": frames,
        "joint_names": list(AZURE_KINECT_JOINTS),
        "k4abt_sdk_version": "1.1.2",
        "source_file": "C:/rec/output.mkv",
    }
    return doc, truth


def _write_azure(path, doc):
    path.write_text(json.dumps(doc, indent=4, sort_keys=True) + "\n")
    return path


def test_azure_offline_processor_output(tmp_path):
    doc, truth = _azure_doc(np.random.default_rng(0))
    p = _write_azure(tmp_path / "out.json", doc)
    assert detect_format(p) == "azure_kinect"
    s1, s2 = load(p)
    assert (s1.body_id, s2.body_id) == (1, 2)
    assert s1.topology == get_topology("azure_kinect") and s1.units == "m"
    np.testing.assert_array_equal(s1.timestamps, (133322 + 33333 * np.arange(4)) * 1e-6)
    for t in range(4):
        pos, ori = truth[(1, t)]
        np.testing.assert_array_equal(s1.positions[t], pos * 1e-3)
        np.testing.assert_array_equal(s1.metadata["orientations"][t], ori)
    assert np.isnan(s2.positions[0]).all() and (s2.tracking_state[0] == 0).all()
    assert (s2.tracking_state[1:] == 2).all() and s1.confidence is None
    np.testing.assert_array_equal(s2.positions[3], truth[(2, 3)][0] * 1e-3)


def test_azure_confidence_levels(tmp_path):
    doc, truth = _azure_doc(np.random.default_rng(1), levels=True)
    (s1, _s2) = read_azure_kinect(_write_azure(tmp_path / "c.json", doc))
    for t in range(4):
        lv = truth[(1, t, "levels")]
        np.testing.assert_array_equal(s1.confidence[t], lv / 3)
        np.testing.assert_array_equal(s1.tracking_state[t], np.array([0, 1, 2, 2])[lv])


def test_azure_custom_joint_names_use_the_declared_bones(tmp_path):
    doc = {
        "bone_list": [["B", "A"], ["B", "C"]],
        "joint_names": ["A", "B", "C"],
        "frames": [
            {
                "bodies": [{"body_id": 5, "joint_positions": [[1, 2, 3], [4, 5, 6], [7, 8, 9]]}],
                "timestamp_usec": 0,
            }
        ],
    }
    (s,) = read_azure_kinect(_write_azure(tmp_path / "k.json", doc))
    assert s.joint_names == ("A", "B", "C")
    assert {(s.joint_names[a], s.joint_names[b]) for a, b in s.topology.bones} in (
        {("A", "B"), ("B", "C")},
        {("B", "A"), ("B", "C")},
    )


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda d: d.pop("frames"), "frames"),
        (lambda d: d["frames"][0].pop("timestamp_usec"), "timestamp_usec"),
        (lambda d: d["frames"][1].__setitem__("timestamp_usec", 1), "backwards"),
        (lambda d: d["frames"][0]["bodies"][0].__setitem__("body_id", "x"), "body_id"),
        (lambda d: d["frames"][1]["bodies"][0]["joint_positions"].pop(), "31 joints"),
        (lambda d: d["frames"][0]["bodies"][0]["joint_positions"][3].append(1), "rectangular"),
        (
            lambda d: d["frames"][0]["bodies"][0].__setitem__("joint_confidence_levels", [5] * 32),
            "0, 1, 2 or 3",
        ),
        (
            lambda d: d["frames"][0]["bodies"][0]["joint_positions"][0].__setitem__(0, 1e12),
            "implausible",
        ),
    ],
)
def test_azure_bad_content(tmp_path, mutate, match):
    doc, _ = _azure_doc(np.random.default_rng(2))
    mutate(doc)
    p = _write_azure(tmp_path / "bad.json", doc)
    with pytest.raises(ReadError, match=match) as err:
        read_azure_kinect(p)
    assert str(p) in str(err.value)


# ------------------------------------------------------------------------------ MediaPipe
def _landmarks(rng, centre, world=False):
    """33 landmark dicts with the fields of MediaPipe's (Normalized)Landmark dataclass."""
    xyz = rng.normal(0, 0.3, size=(33, 3)) if world else centre + rng.uniform(-0.1, 0.1, (33, 3))
    vis = rng.uniform(0, 1, 33)
    pres = rng.uniform(0, 1, 33)
    return [
        {"x": float(a), "y": float(b), "z": float(c), "visibility": float(v), "presence": float(q)}
        for (a, b, c), v, q in zip(xyz, vis, pres)
    ]


def _mp_frames(rng, T=5):
    frames = []
    for t in range(T):
        people = [(_landmarks(rng, np.array([0.25 + 0.01 * t, 0.5, 0])), _landmarks(rng, 0, True))]
        if t != 2:  # nobody detected in frame 2
            people.append((_landmarks(rng, np.array([0.75, 0.5, 0])), _landmarks(rng, 0, True)))
        if t % 2:
            people = people[::-1]
        frames.append(people)
    return frames


def _mp_json(frames, path, **top):
    doc = dict(top)
    doc["frames"] = [
        {
            "timestamp_ms": 33 * t,
            "pose_landmarks": [im for im, _ in people],
            "pose_world_landmarks": [w for _, w in people],
        }
        for t, people in enumerate(frames)
    ]
    path.write_text(json.dumps(doc))
    return path


def _array(lms, keys=("x", "y", "z", "visibility", "presence")):
    return np.array([[lm[k] for k in keys] for lm in lms])


def test_mediapipe_json_world_and_image(tmp_path):
    frames = _mp_frames(np.random.default_rng(3))
    p = _mp_json(frames, tmp_path / "pose.json", fps=30)
    assert detect_format(p) == "mediapipe"
    a, b = load(p)  # world landmarks by default
    assert a.units == "m" and a.positions.shape == (5, 33, 3) and a.fps == 30.0
    assert a.joint_names == MEDIAPIPE_POSE_JOINTS
    np.testing.assert_array_equal(a.timestamps, 33 * np.arange(5) * 1e-3)
    for t, people in enumerate(frames):
        _im, w = people[1] if t % 2 and t != 2 else people[0]  # person A (left) is body 0
        np.testing.assert_array_equal(a.positions[t], _array(w, "xyz"))
        np.testing.assert_array_equal(a.confidence[t], _array(w, ["visibility"])[:, 0])
        np.testing.assert_array_equal(a.metadata["presence"][t], _array(w, ["presence"])[:, 0])
    assert np.isnan(b.positions[2]).all()
    ai, _bi = read_mediapipe(p, landmarks="image", image_size=(1280, 720))
    assert ai.units == "px" and ai.positions.shape == (5, 33, 2)
    im0 = _array(frames[0][0][0])
    np.testing.assert_array_equal(ai.positions[0], im0[:, :2] * [1280, 720])
    np.testing.assert_array_equal(ai.metadata["image_z"][0], im0[:, 2])
    (n,) = read_mediapipe(_mp_json(frames[:1], tmp_path / "one.json"), landmarks="image")[:1]
    assert n.units is None
    np.testing.assert_array_equal(n.positions[0], im0[:, :2])


def test_mediapipe_csv_from_pandas_matches_json(tmp_path):
    frames = _mp_frames(np.random.default_rng(4))
    rows = []
    for t, people in enumerate(frames):
        for k, (im, w) in enumerate(people):
            for j, (li, lw) in enumerate(zip(im, w)):
                row = {"frame": t, "timestamp_ms": 33 * t, "pose": k}
                row["landmark"] = MEDIAPIPE_POSE_JOINTS[j]
                row.update({k_: li[k_] for k_ in ("x", "y", "z", "visibility", "presence")})
                row.update({f"world_{c}": lw[c] for c in "xyz"})
                rows.append(row)
    df = pd.DataFrame(rows).sample(frac=1.0, random_state=0)  # any row order
    csv_path = tmp_path / "pose.csv"
    df.to_csv(csv_path)  # with pandas' default index column
    assert detect_format(csv_path) == "mediapipe"
    from_csv = read_mediapipe(csv_path, landmarks="image")
    from_json = read_mediapipe(_mp_json(frames, tmp_path / "p.json"), landmarks="image")
    for c, j in zip(from_csv, from_json):
        np.testing.assert_array_equal(c.positions, j.positions)
        np.testing.assert_array_equal(c.confidence, j.confidence)
        np.testing.assert_array_equal(c.timestamps, j.timestamps)
    _mp_json(frames, tmp_path / "pose.json")  # the same results as JSON beside the CSV
    assert detect_format(csv_path) == "mediapipe"
    world = read_mediapipe(csv_path)
    assert world[0].units == "m"
    np.testing.assert_array_equal(world[0].positions[0], _array(frames[0][0][1], "xyz"))


def test_mediapipe_frames_without_a_stamp_get_times_from_their_frame_number(tmp_path):
    """A CSV has no rows for a frame where nobody was detected: the frames around keep
    their stamps (60 fps here), the empty ones are placed by their frame number."""
    rng = np.random.default_rng(6)
    rows = []
    for t in range(12):
        if t in (0, 1, 5, 6, 7):  # nobody: no rows (also before the first stamp)
            continue
        for j, lm in enumerate(_landmarks(rng, np.array([0.5, 0.5, 0]))):
            row = {"frame": t, "timestamp_ms": 1000 + 1000 * t / 60, "pose": 0}
            row["landmark"] = MEDIAPIPE_POSE_JOINTS[j]
            rows.append({**row, **lm})
    pd.DataFrame(rows).to_csv(tmp_path / "gaps.csv", index=False)
    (seq,) = read_mediapipe(tmp_path / "gaps.csv", landmarks="image")
    np.testing.assert_allclose(seq.timestamps, 1 + np.arange(12) / 60, rtol=1e-12)
    assert np.isnan(seq.positions[[0, 1, 5, 6, 7]]).all()
    # JSON frames without a timestamp_ms likewise; one stamp alone gives no times
    frames = _mp_frames(rng, T=4)
    doc = json.loads(_mp_json(frames, tmp_path / "p.json").read_text())
    del doc["frames"][1]["timestamp_ms"]
    (tmp_path / "p.json").write_text(json.dumps(doc))
    np.testing.assert_allclose(
        read_mediapipe(tmp_path / "p.json")[0].timestamps, 0.033 * np.arange(4)
    )
    for fr in doc["frames"][1:]:
        fr.pop("timestamp_ms", None)
    (tmp_path / "p.json").write_text(json.dumps(doc))
    assert read_mediapipe(tmp_path / "p.json")[0].timestamps is None


def test_mediapipe_legacy_single_pose_and_nulls(tmp_path):
    lms = _landmarks(np.random.default_rng(5), np.array([0.5, 0.5, 0.0]))
    lms[3]["visibility"] = None  # unset in the dataclass
    p = tmp_path / "legacy.json"
    p.write_text(json.dumps({"frames": [{"pose_landmarks": lms}]}))
    (s,) = read_mediapipe(p)
    assert s.units is None and np.isnan(s.confidence[0, 3])
    np.testing.assert_array_equal(s.positions[0], _array(lms, "xy"))


@pytest.mark.parametrize(
    "text, match",
    [
        ('{"frames": [{"pose_landmarks": [[{"x": 1}]]}]}', "expected 33 landmarks"),
        ('{"frames": []}', "no pose"),
        ("frame,landmark,x,y\n0,elbow,1,2\n", "unknown MediaPipe Pose landmark"),
        ("frame,landmark,x,y\n0,nose,1,abc\n", "number in column 'y'"),
        ("frame,landmark,x,y\n0,nose,1,2\n0,nose,1,2\n", "twice"),
        ("frame,landmark,x,yy\n", "columns"),
        ("frame,landmark,x,y,visibility\n0,0,1,2,1.5\n", r"outside \[0, 1\]"),
        ("frame,landmark,x,y\n-1,0,1,2\n", "non-negative integer"),
    ],
)
def test_mediapipe_bad_content(tmp_path, text, match):
    p = tmp_path / ("m.json" if text.startswith("{") else "m.csv")
    p.write_text(text)
    with pytest.raises(ReadError, match=match) as err:
        read_mediapipe(p)
    assert str(p) in str(err.value)
