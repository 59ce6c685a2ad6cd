"""MMPose prediction JSON.

The files are built as MMPose writes them (it is not installed here: it needs PyTorch and
mmcv): each instance is what ``mmpose.structures.split_instances`` makes of a prediction
(``keypoints``, ``keypoint_scores``, ``bbox`` as a one-element list, ``bbox_score``), the
inferencer writes ``[{"frame_id": i, "instances": [...]}, ...]`` for a video
(``_finalize_video_processing``, frame ids from 0) and the demos
``{"meta_info": dataset_meta, "instance_info": [...]}`` with frame ids from 1, through
``json.dump`` (mmengine's JSON dump is ``json.dump``).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fuzzing import SETTINGS, check_reader
from tobitkf.io import ReadError, detect_format, load
from tobitkf.io.mmpose import read_mmpose
from tobitkf.skeleton.topology import COCO17_JOINTS


def _person(T, x0, seed, J=17, D=2):
    rng = np.random.default_rng(seed)
    base = rng.uniform(-60, 60, (J, D)) + x0
    return base[None] + np.cumsum(rng.normal(0, 1.5, (T, J, D)), axis=0)


def _instance(kp, scores, track=None):
    x0, y0 = kp[:, 0].min(), kp[:, 1].min()
    x1, y1 = kp[:, 0].max(), kp[:, 1].max()
    inst = {
        "keypoints": kp.tolist(),
        "keypoint_scores": scores.tolist(),
        "bbox": ([float(x0), float(y0), float(x1), float(y1)],),  # split_instances' tuple
        "bbox_score": 0.98,
    }
    if track is not None:
        inst["track_id"] = track
    return inst


def _write(path, frames, meta=None):
    doc = frames if meta is None else {"meta_info": meta, "instance_info": frames}
    path.write_text(json.dumps(doc, indent="  "))  # tuples become arrays, as in mmengine


def test_inferencer_video_output_two_people_in_shuffled_order(tmp_path):
    T = 30
    a, b = _person(T, 300, 1), _person(T, 900, 2)
    sa = np.random.default_rng(3).uniform(0.3, 0.95, (T, 17))
    sb = np.random.default_rng(4).uniform(0.3, 0.95, (T, 17))
    frames = []
    for t in range(T):
        insts = [_instance(a[t], sa[t]), _instance(b[t], sb[t])]
        frames.append({"frame_id": t, "instances": insts[:: 1 if t % 3 else -1]})
    frames[10]["instances"] = []  # nobody detected
    p = tmp_path / "video.json"
    _write(p, frames)
    assert detect_format(p) == "mmpose"
    seqs = load(p, fps=25)
    assert len(seqs) == 2
    got = {round(float(np.nanmean(s.positions[:, :, 0])), -2): s for s in seqs}
    for truth, scores in ((a, sa), (b, sb)):
        s = min(got.values(), key=lambda q: abs(np.nanmean(q.positions[:, :, 0]) - truth.mean()))
        keep = np.arange(T) != 10
        np.testing.assert_allclose(s.positions[keep], truth[keep])
        np.testing.assert_allclose(s.confidence[keep], scores[keep])
        assert np.isnan(s.positions[10]).all()
        assert s.topology.name == "coco17" and s.units == "px" and s.fps == 25.0
        assert s.metadata["person_ids"] == "associated"


def test_demo_output_with_meta_track_ids_and_frames_from_one(tmp_path):
    T = 12
    a = _person(T, 400, 5)
    names = ["root", "right_hip", "right_knee", "right_foot", "left_hip", "left_knee",
             "left_foot", "spine", "thorax", "neck_base", "head", "left_shoulder", "left_elbow",
             "left_wrist", "right_shoulder", "right_elbow", "right_wrist"]  # fmt: skip
    links = [[0, 1], [1, 2], [2, 3], [0, 4], [4, 5], [5, 6], [0, 7], [7, 8], [8, 9],
             [9, 10], [8, 11], [11, 12], [12, 13], [8, 14], [14, 15], [15, 16]]  # fmt: skip
    meta = {
        "dataset_name": "h36m",
        "keypoint_id2name": {str(i): n for i, n in enumerate(names)},  # int keys in JSON
        "skeleton_links": links,
        "sigmas": [0.025] * 17,
    }
    scores = np.full(17, 1.3)  # RTMPose's SimCC scores are not probabilities
    frames = [
        {"frame_id": t + 1, "instances": [_instance(a[t], scores, track=7)]} for t in range(T)
    ]
    del frames[4]  # a frame id missing from the file
    p = tmp_path / "demo.json"
    _write(p, frames, meta)
    (s,) = load(p)
    assert s.n_frames == T and s.body_id == 7 and s.metadata["person_ids"] == "track_id"
    assert np.isnan(s.positions[4]).all()
    np.testing.assert_allclose(np.delete(s.positions, 4, axis=0), np.delete(a, 4, axis=0))
    assert s.topology.joints == tuple(names) and s.topology.name == "h36m"
    assert {(names[p_], names[c]) for p_, c in s.topology.bones} == {
        (names[x], names[y]) for x, y in links
    }
    assert s.topology.joint_groups()["hands"] == [13, 16]
    assert np.nanmax(s.confidence) == 1.0 and s.metadata["confidence_clipped"]


def test_seventeen_keypoints_are_coco_in_2d_and_h36m_in_3d(tmp_path):
    p = tmp_path / "lift.json"
    kp3 = _person(5, 0, 8, D=3) / 1000
    _write(p, [{"frame_id": t, "instances": [{"keypoints": kp3[t].tolist(),
                                               "keypoint_scores": [1.0] * 17}]}
               for t in range(5)])  # fmt: skip
    (s,) = read_mmpose(p)
    assert s.topology.name == "h36m17" and s.n_dims == 3 and s.units is None
    meta = {"keypoint_id2name": dict(enumerate(COCO17_JOINTS))}
    kp2 = _person(5, 0, 9)
    frames = [{"frame_id": t, "instances": [_instance(kp2[t], np.ones(17))]} for t in range(5)]
    _write(p, frames, {k: {str(i): n for i, n in v.items()} for k, v in meta.items()})
    (s,) = read_mmpose(p)
    assert s.topology.name == "coco17"


def test_other_counts_have_no_bones_and_say_so(tmp_path):
    p = tmp_path / "wholebody.json"
    kp = _person(4, 0, 10, J=133)
    _write(p, [{"frame_id": t, "instances": [_instance(kp[t], np.ones(133))]} for t in range(4)])
    (s,) = read_mmpose(p)
    assert s.topology.bones == [] and "without bones" in s.metadata["reader_warnings"][0]


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ([], "no person"),
        ([{"frame_id": 0, "instances": [{"bbox": [[0, 0, 1, 1]]}]}], 'no "keypoints"'),
        ([{"frame_id": 0, "instances": [{"keypoints": [[1, 2, 3, 4]]}]}], "[[x, y], ...]"),
        ([{"frame_id": 0, "instances": [{"keypoints": [[1, 2]], "keypoint_scores": [1, 2]}]}],
         "2 values for 1 keypoints"),
        ([{"frame_id": 0, "instances": [{"keypoints": [[1, 2]]}]},
          {"frame_id": 0, "instances": [{"keypoints": [[1, 2]]}]}], "frame_id appears twice"),
        ([{"frame_id": "a", "instances": []}], "frame_id must be an integer"),
        ([{"frame_id": 0, "instances": [{"keypoints": [[1, 2]]}]},
          {"frame_id": 1, "instances": [{"keypoints": [[1, 2], [3, 4]]}]}], "different shapes"),
        ([{"frame_id": 0, "instances": [{"keypoints": [[1, 2]], "track_id": 1},
                                        {"keypoints": [[3, 4]], "track_id": 1}]}], "twice in one"),
        ({"instance_info": [], "meta_info": {"keypoint_id2name": {"0": "a"}}}, "no person"),
        ({"instance_info": [{"frame_id": 0, "instances": [{"keypoints": [[1, 2], [3, 4]]}]}],
          "meta_info": {"keypoint_id2name": {"0": "a"}}}, "names of the 2 keypoints"),
        ({"instance_info": [{"frame_id": 0, "instances": [{"keypoints": [[1, 2], [3, 4]]}]}],
          "meta_info": {"keypoint_id2name": {"0": "a", "1": "b"}, "skeleton_links": [[0, 5]]}},
         "outside 0..1"),
    ],
)  # fmt: skip
def test_malformed_files_are_read_errors(tmp_path, doc, message):
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(ReadError) as err:
        read_mmpose(p)
    assert message in str(err.value) and str(p) in str(err.value)


_TOKENS = st.sampled_from(
    ['{"frame_id": 0, ', '"instances": [', '{"keypoints": [[1, 2], [3, 4]]', "]", "}", ", ",
     '"keypoint_scores": [0.5, 2]', '"track_id": 3', '"meta_info": {}', '"instance_info": [',
     "null", "1e400", '"x"', "[", "{"]
)  # fmt: skip


@SETTINGS
@given(parts=st.lists(_TOKENS, max_size=30))
def test_token_soup(tmp_path, parts):
    p = tmp_path / "f.json"
    p.write_text("[" + "".join(parts))
    check_reader(read_mmpose, p)


def test_smoothed_output_round_trips_and_keeps_the_files_meta(tmp_path):
    import tobitkf as tk

    T = 25
    a = _person(T, 300, 11)
    a[5:9, 9] += 150  # a glitch of the left wrist
    scores = np.full((T, 17), 0.9)
    meta = {"dataset_name": "coco", "keypoint_id2name": dict(enumerate(COCO17_JOINTS))}
    frames = [{"frame_id": t + 1, "instances": [_instance(a[t], scores[t])]} for t in range(T)]
    src = tmp_path / "in.json"
    _write(src, frames, {k: v if k != "keypoint_id2name" else {str(i): n for i, n in v.items()}
                         for k, v in meta.items()})  # fmt: skip
    (seq,) = tk.load(src, fps=30)
    smoothed = tk.smooth(seq)
    out = tmp_path / "out.json"
    tk.save([smoothed], out, format="mmpose")
    doc = json.loads(out.read_text())
    assert doc["meta_info"]["dataset_name"] == "coco"  # the file's meta kept
    assert doc["meta_info"]["tobitkf"]["method"] == "robust"  # and the provenance added
    assert [f["frame_id"] for f in doc["instance_info"]] == list(range(1, T + 1))
    (back,) = tk.load(out)
    assert back.fps == 30.0  # MMPose keeps no rate: the writer's meta does
    np.testing.assert_allclose(back.positions, smoothed.positions)
    np.testing.assert_allclose(back.std, smoothed.std)
    np.testing.assert_array_equal(back.sample_state, smoothed.sample_state)
    # the glitch's samples were filled: their score is 0 (no detection lies there)
    filled = tk.SampleState.filled(smoothed.sample_state)
    assert filled[5:9, 9].all()
    np.testing.assert_allclose(back.confidence, np.where(filled, 0.0, scores))
    assert back.topology == seq.topology and back.metadata["person_ids"] == "track_id"


def test_a_sequence_from_another_tool_keeps_its_keypoints_and_bones(tmp_path):
    """Without an MMPose file's meta, the writer gives MMPose's own: the names
    (keypoint_id2name) and bones (skeleton_links) that read back as the same skeleton."""
    import tobitkf as tk

    names = ["head", "thorax", "abdomen", "wing_l", "wing_r"]
    topo = tk.Topology.from_names(names, [-1, 0, 1, 1, 1], name="fly")
    rng = np.random.default_rng(2)
    seq = tk.SkeletonSequence(rng.uniform(0, 500, (4, 5, 2)), topo, fps=25.0, units="px")
    tk.save([seq], tmp_path / "fly.json", format="mmpose")
    meta = json.loads((tmp_path / "fly.json").read_text())["meta_info"]
    assert meta["keypoint_id2name"] == {str(j): n for j, n in enumerate(names)}
    assert sorted(map(tuple, meta["skeleton_links"])) == [(0, 1), (1, 2), (1, 3), (1, 4)]
    (back,) = tk.load(tmp_path / "fly.json")
    assert back.joint_names == tuple(names) and back.topology.parents == topo.parents
    np.testing.assert_array_equal(back.positions, seq.positions)


def test_writer_several_people_and_missing_values(tmp_path):
    import tobitkf as tk

    topo = tk.get_topology("coco17")
    a, b = _person(6, 100, 12), _person(6, 700, 13)
    a[:2] = np.nan  # not yet in the picture
    b[3, 4] = np.nan  # one keypoint missing
    seqs = [tk.SkeletonSequence(a, topo, body_id="left"), tk.SkeletonSequence(b, topo, body_id=3)]
    p = tmp_path / "two.json"
    tk.save(seqs, p, format="mmpose")
    doc = json.loads(p.read_text())
    assert [len(f["instances"]) for f in doc["instance_info"]] == [1, 1, 2, 2, 2, 2]
    assert doc["instance_info"][3]["instances"][1]["keypoints"][4] == [None, None]
    back = {s.body_id: s for s in tk.load(p)}
    np.testing.assert_array_equal(back["left"].positions, a)
    np.testing.assert_array_equal(back[3].positions, b)
    with pytest.raises(ValueError, match="one keypoint layout"):
        tk.save(
            [
                seqs[0],
                tk.SkeletonSequence(
                    a[:, :5],
                    tk.get_topology("kinect_v2").subset(
                        ["SpineBase", "SpineMid", "Neck", "Head", "ShoulderLeft"]
                    ),
                ),
            ],
            p,
            format="mmpose",
        )


def test_a_skeleton_for_a_file_that_names_none(tmp_path):
    p = tmp_path / "halpe.json"
    kp = _person(4, 0, 14, J=25)
    _write(p, [{"frame_id": t, "instances": [_instance(kp[t], np.ones(25))]} for t in range(4)])
    (s,) = read_mmpose(p, topology="openpose_body25")
    assert s.topology.name == "openpose_body25" and "reader_warnings" not in s.metadata
    with pytest.raises(ReadError, match="25 keypoints, topology 'coco17' 17"):
        read_mmpose(p, topology="coco17")
    with pytest.raises(ReadError, match="unknown topology"):
        read_mmpose(p, topology="nope")
    coco = tmp_path / "coco.json"
    kp = _person(3, 0, 15)
    _write(coco, [{"frame_id": t, "instances": [_instance(kp[t], np.ones(17))]} for t in range(3)])
    assert read_mmpose(coco)[0].topology.name == "coco17"  # 17 in 2-D: COCO's by default
    (s,) = read_mmpose(coco, topology="h36m17")  # a 2-D Human3.6M model: as given
    assert s.topology.name == "h36m17"


def test_the_batch_topology_overrides_a_guess_by_the_count(tmp_path):
    """17 keypoints in 2-D are taken as COCO's when the file says nothing; a data set of a
    2-D Human3.6M model says otherwise with --topology (smooth_files(topology=))."""
    import tobitkf as tk

    src = tmp_path / "in"
    src.mkdir()
    kp = _person(20, 400, 16)
    _write(src / "h36m2d.json", [{"frame_id": t, "instances": [_instance(kp[t], np.ones(17))]}
                                 for t in range(20)])  # fmt: skip
    (guess,) = read_mmpose(src / "h36m2d.json")
    assert guess.topology.name == "coco17" and guess.metadata["topology_guessed"]
    (res,) = tk.smooth_files(src, tmp_path / "out", topology="h36m17", fps=30)
    assert res.ok
    assert json.loads((tmp_path / "out" / "h36m2d.robust.json").read_text())["topology"] == "h36m17"
