"""OpenPose JSON output folders, written here the way OpenPose's ``--write_json`` writes
them (``doc/02_output.md``; its JsonOfstream prints floats with C++ ``ostream``'s default
6 significant digits, ``%g``). Expected values are the written text parsed back with
``float``, never the reader's output."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tobitkf.io import ReadError, detect_format, load
from tobitkf.io.openpose import COCO18_JOINTS, read_openpose
from tobitkf.skeleton.topology import get_topology

EMPTY = (
    "face_keypoints_2d",
    "hand_left_keypoints_2d",
    "hand_right_keypoints_2d",
    "pose_keypoints_3d",
    "face_keypoints_3d",
    "hand_left_keypoints_3d",
    "hand_right_keypoints_3d",
)


def _g(x: float) -> str:
    return f"{x:g}"


def _person(kp: np.ndarray, person_id: int = -1, kp3=None) -> str:
    """One person as OpenPose writes it; ``kp`` (J, 3) x, y, c."""
    fields = [
        f'"person_id":[{person_id}]',
        '"pose_keypoints_2d":[' + ",".join(map(_g, kp.ravel())) + "]",
    ]
    for key in EMPTY:
        if key == "pose_keypoints_3d" and kp3 is not None:
            fields.append('"pose_keypoints_3d":[' + ",".join(map(_g, kp3.ravel())) + "]")
        else:
            fields.append(f'"{key}":[]')
    return "{" + ",".join(fields) + "}"


def _write_folder(folder, frames, video="clip"):
    """frames: list over frames of lists of person JSON strings."""
    folder.mkdir(parents=True, exist_ok=True)
    for t, people in enumerate(frames):
        text = '{"version":1.3,"people":[' + ",\n".join(people) + "]}"
        (folder / f"{video}_{t:012d}_keypoints.json").write_text(text)
    return folder


def _pose(rng, J, centre):
    kp = np.empty((J, 3))
    kp[:, :2] = centre + rng.uniform(-40, 40, size=(J, 2))
    kp[:, 2] = rng.uniform(0.05, 0.95, size=J)
    return np.array([[float(_g(v)) for v in row] for row in kp])  # as written


def test_body25_two_people_unlabelled_are_associated(tmp_path):
    rng = np.random.default_rng(0)
    T, J = 6, 25
    a = [_pose(rng, J, np.array([200.0 + 3 * t, 300.0])) for t in range(T)]
    b = [_pose(rng, J, np.array([900.0 - 3 * t, 320.0])) for t in range(T)]
    a[2][4] = 0.0  # RWrist of A not detected in frame 2: written 0 0 0
    frames = []
    for t in range(T):
        people = [_person(a[t]), _person(b[t])]
        frames.append(people[::-1] if t % 2 else people)  # OpenPose's order is not stable
    folder = _write_folder(tmp_path / "json", frames)
    assert detect_format(folder) == "openpose"
    seqs = load(folder, fps=25)
    assert len(seqs) == 2
    sa, sb = seqs  # in order of first appearance: A first in frame 0
    assert sa.topology == get_topology("openpose_body25")
    assert sa.units == "px" and sa.fps == 25.0 and sa.positions.shape == (T, J, 2)
    for seq, truth in ((sa, a), (sb, b)):
        for t in range(T):
            kp = truth[t]
            present = ~np.all(kp == 0, axis=1)
            np.testing.assert_array_equal(seq.positions[t][present], kp[present, :2])
            np.testing.assert_array_equal(seq.confidence[t], kp[:, 2])
    assert np.isnan(sa.positions[2, 4]).all() and sa.confidence[2, 4] == 0.0
    assert sa.body_id == 0 and sb.body_id == 1


def test_association_is_needed(tmp_path):
    """Without association the swapped order would mix the people: the test above fails if
    bodies were taken by their index in "people"."""
    rng = np.random.default_rng(1)
    a = [_pose(rng, 25, np.array([100.0, 100.0])) for _ in range(2)]
    b = [_pose(rng, 25, np.array([800.0, 100.0])) for _ in range(2)]
    folder = _write_folder(
        tmp_path / "j", [[_person(a[0]), _person(b[0])], [_person(b[1]), _person(a[1])]]
    )
    sa, sb = read_openpose(folder)
    np.testing.assert_array_equal(sa.positions[1], a[1][:, :2])
    np.testing.assert_array_equal(sb.positions[1], b[1][:, :2])


def test_person_ids_are_the_bodies_and_absence_is_nan(tmp_path):
    rng = np.random.default_rng(2)
    p = [_pose(rng, 18, np.array([300.0, 300.0])) for _ in range(3)]
    q = [_pose(rng, 18, np.array([310.0, 300.0])) for _ in range(3)]
    frames = [
        [_person(p[0], 7), _person(q[0], 3)],
        [_person(q[1], 3)],
        [_person(p[2], 7), _person(q[2], 3)],
    ]
    s3, s7 = read_openpose(_write_folder(tmp_path / "j", frames))
    assert (s3.body_id, s7.body_id) == (3, 7)
    assert s7.joint_names == COCO18_JOINTS and s7.topology.name == "openpose_coco18"
    assert np.isnan(s7.positions[1]).all() and np.isnan(s7.confidence[1]).all()
    np.testing.assert_array_equal(s7.positions[2], p[2][:, :2])
    np.testing.assert_array_equal(s3.confidence[1], q[1][:, 2])


def test_3d_keypoints_are_read_when_present(tmp_path):
    rng = np.random.default_rng(3)
    kp = _pose(rng, 25, np.array([1.0, 1.0]))
    kp3 = np.column_stack([rng.normal(size=(25, 3)).round(3), np.ones(25)])
    kp3[5] = 0.0  # failed reconstruction, written 0 0 0 0
    folder = _write_folder(tmp_path / "j", [[_person(kp, kp3=kp3)]])
    (s,) = read_openpose(folder)
    assert s.positions.shape == (1, 25, 3) and s.units is None
    expected = kp3[:, :3].copy()
    expected[5] = np.nan
    np.testing.assert_array_equal(s.positions[0], expected)
    (s2,) = read_openpose(folder, dims=2)
    np.testing.assert_array_equal(s2.positions[0], kp[:, :2])


def test_single_file_and_frame_order_by_number(tmp_path):
    rng = np.random.default_rng(4)
    poses = [_pose(rng, 25, np.array([100.0 + t, 100.0])) for t in range(11)]
    folder = _write_folder(tmp_path / "j", [[_person(k)] for k in poses])
    (s,) = load(folder)  # 10 sorts before 2 as text; frames follow the numbers
    np.testing.assert_array_equal(s.positions[10], poses[10][:, :2])
    one = folder / "clip_000000000003_keypoints.json"
    assert detect_format(one) == "openpose"
    (s1,) = load(one)
    np.testing.assert_array_equal(s1.positions[0], poses[3][:, :2])


@pytest.mark.parametrize(
    "text, match",
    [
        ('{"version":1.3}', "people"),
        ('{"people":[{"pose_keypoints_2d":[1,2]}]}', "x, y, c"),
        ('{"people":[{"pose_keypoints_2d":[1,2,"a"]}]}', "expected numbers"),
        ('{"people":[{"pose_keypoints_2d":[1,2,2.5]}]}', "outside"),
        ('{"people":[{"pose_keypoints_2d":[1,2,NaN]}]}', "invalid JSON"),
        ('{"people":[]}', "no person"),
        ("[1, 2", "invalid JSON"),
    ],
)
def test_bad_content_is_a_read_error_naming_the_file(tmp_path, text, match):
    folder = tmp_path / "j"
    folder.mkdir()
    f = folder / "v_000000000000_keypoints.json"
    f.write_text(text)
    with pytest.raises(ReadError, match=match) as err:
        read_openpose(folder)
    assert str(folder.name) in str(err.value)


def test_a_folder_of_something_else_is_refused(tmp_path):
    (tmp_path / "a.txt").write_text("x")
    with pytest.raises(ReadError, match="expected a file, found a directory"):
        load(tmp_path)


def test_json_dump_of_the_same_data_reads_the_same(tmp_path):
    """Pretty-printed JSON (e.g. re-saved by Python) is the same content."""
    kp = np.arange(75, dtype=float).reshape(25, 3) / 100.0 + 1.0
    kp[:, 2] = 0.5
    kp[0] = 0.0
    f = tmp_path / "x_000000000000_keypoints.json"
    f.write_text(
        json.dumps(
            {
                "version": 1.3,
                "people": [{"person_id": [-1], "pose_keypoints_2d": kp.ravel().tolist()}],
            },
            indent=2,
        )
    )
    (s,) = read_openpose(f)
    np.testing.assert_array_equal(s.positions[0, 1:], kp[1:, :2])
    assert np.isnan(s.positions[0, 0]).all()  # 0 0 0 is missing


def test_a_person_far_from_every_track_starts_a_new_body(tmp_path):
    """A leaves after frame 0 and B enters far away in frame 1: two bodies, not one that
    jumps across the image; a gate wider than the jump links them."""
    rng = np.random.default_rng(5)
    a = _pose(rng, 25, np.array([100.0, 300.0]))
    b = _pose(rng, 25, np.array([900.0, 300.0]))
    folder = _write_folder(tmp_path / "j", [[_person(a)], [_person(b)]])
    sa, sb = read_openpose(folder)
    assert np.isnan(sa.positions[1]).all() and np.isnan(sb.positions[0]).all()
    (one,) = read_openpose(folder, max_distance=5000.0)
    np.testing.assert_array_equal(one.positions[1], b[:, :2])


def test_batch_takes_an_openpose_folder_as_one_recording(tmp_path):
    from tobitkf.app.batch import discover_inputs, not_a_recording, readable_problem

    rng = np.random.default_rng(6)
    root = tmp_path / "videos"
    root.mkdir()
    folder = _write_folder(
        root / "clip_json", [[_person(_pose(rng, 25, np.array([9.0, 9.0])))]] * 3
    )
    (root / "notes").mkdir()
    (root / "notes" / "a.csv").write_text("x")
    for given in (root, folder):
        found = discover_inputs([given], skip=not_a_recording)
        assert folder in [f for f, _ in found]
        assert not any(f.parent == folder for f, _ in found)  # its frames are not inputs
    assert (root / "notes" / "a.csv") in [f for f, _ in discover_inputs([root])]
    assert readable_problem(folder) is None


def test_cli_smooths_an_openpose_folder(tmp_path):
    """``tobitkf smooth`` takes the folder as one recording (one output per recording)."""
    pytest.importorskip("click")
    from click.testing import CliRunner

    from tobitkf.app.commands import app

    rng = np.random.default_rng(7)
    poses = [_pose(rng, 25, np.array([300.0 + 2.0 * t, 300.0])) for t in range(40)]
    folder = _write_folder(tmp_path / "in" / "clip_json", [[_person(k)] for k in poses])
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["smooth", str(tmp_path / "in"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    (made,) = sorted(out.rglob("*.csv"))
    assert made.name.startswith(folder.name)
    (back,) = load(made)
    assert back.positions.shape == (40, 25, 2) and back.units == "px"
