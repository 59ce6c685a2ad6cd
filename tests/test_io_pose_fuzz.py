"""Hypothesis fuzzing of the pose-estimator and TRC readers: arbitrary bytes, token soups
and mutations of valid files give a ReadError naming the file (or a valid result), never
another exception."""

from __future__ import annotations

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fuzzing import SETTINGS, check_reader, reader_fuzz_tests
from tobitkf.io import ReadError, load
from tobitkf.io.azure_kinect import read_azure_kinect
from tobitkf.io.mediapipe import read_mediapipe
from tobitkf.io.openpose import read_openpose
from tobitkf.io.trc import read_trc

READERS = {
    "openpose": (read_openpose, "_000000000000_keypoints.json"),
    "mediapipe_json": (read_mediapipe, ".json"),
    "mediapipe_csv": (read_mediapipe, ".csv"),
    "azure_kinect": (read_azure_kinect, ".json"),
    "trc": (read_trc, ".trc"),
}

TOKENS = st.sampled_from(
    [
        "{", "}", "[", "]", ",", ":", '"', "0", "1", "-1", "0.5", "1e400", "NaN", "null",
        "true", '"people"', '"pose_keypoints_2d"', '"person_id"', '"pose_keypoints_3d"',
        '"frames"', '"bodies"', '"body_id"', '"joint_positions"', '"joint_orientations"',
        '"timestamp_usec"', '"joint_confidence_levels"', '"joint_names"', '"bone_list"',
        '"pose_landmarks"', '"pose_world_landmarks"', '"x"', '"y"', '"visibility"',
        '"timestamp_ms"', "frame,landmark,x,y", "nose", "PathFileType", "\t", "\n", " ",
        "DataRate", "Units", "mm", "Frame#", "Time", "X1", "\x00", "é",
    ]
)  # fmt: skip
SOUP = st.lists(TOKENS, max_size=80).map("".join)


test_arbitrary_bytes, test_token_soup = reader_fuzz_tests(READERS, SOUP, full_path=False)


# valid small documents, mutated as JSON values (type confusion, wrong lengths, huge numbers)
def _openpose_doc():
    return {
        "version": 1.3,
        "people": [{"person_id": [-1], "pose_keypoints_2d": [1.0, 2.0, 0.5] * 25}],
    }


def _azure_doc():
    body = {
        "body_id": 1,
        "joint_positions": [[1.0, 2.0, 3.0]] * 32,
        "joint_orientations": [[1.0, 0, 0, 0]] * 32,
    }
    return {"frames": [{"bodies": [body], "timestamp_usec": 0}], "k4abt_sdk_version": "1.1"}


def _mediapipe_doc():
    lm = {"x": 0.5, "y": 0.5, "z": 0.0, "visibility": 0.9, "presence": 0.9}
    return {"frames": [{"pose_landmarks": [[lm] * 33], "pose_world_landmarks": [[lm] * 33]}]}


DOCS = {"openpose": _openpose_doc, "azure_kinect": _azure_doc, "mediapipe_json": _mediapipe_doc}
VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-(2**70), 2**70), st.floats(allow_nan=False),
    st.text(max_size=5), st.just([]), st.just({}), st.lists(st.integers(0, 3), max_size=40),
)  # fmt: skip


def _paths(doc, prefix=()):
    yield prefix
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc[:3]):
            yield from _paths(v, (*prefix, i))


@pytest.mark.parametrize("name", sorted(DOCS))
@SETTINGS
@given(data=st.data())
def test_mutated_documents(tmp_path, name, data):
    doc = DOCS[name]()
    paths = [p for p in _paths(doc) if p]
    where = data.draw(st.sampled_from(paths))
    target = doc
    for k in where[:-1]:
        target = target[k]
    if data.draw(st.booleans()):
        target[where[-1]] = data.draw(VALUES)
    elif isinstance(target, dict):
        del target[where[-1]]
    else:
        target.pop(where[-1])
    reader, ext = READERS[name]
    p = tmp_path / f"m{ext}"
    p.write_text(json.dumps(doc, allow_nan=True))
    check_reader(reader, p)


@SETTINGS
@given(text=SOUP)
def test_load_of_an_openpose_folder_never_crashes(tmp_path, text):
    folder = tmp_path / "op"
    folder.mkdir(exist_ok=True)
    (folder / "v_000000000000_keypoints.json").write_text(json.dumps(_openpose_doc()))
    (folder / "v_000000000001_keypoints.json").write_text(text)
    try:
        load(folder)
    except ReadError:
        pass


TRC = (
    "PathFileType\t4\t(X/Y/Z)\tw.trc\n"
    "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\n"
    "100\t100\t2\t2\tmm\t100\t1\n"
    "Frame#\tTime\tA\t\t\tB\n"
    "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\n"
    "\n"
    "1\t0.0\t1\t2\t3\t4\t5\t6\n"
    "2\t0.01\t1\t2\t3\t4\t5\t6\n"
)


_ROW = "{t},{ms},0,{j},0.5,0.5,0.1,0.9,0.8,0.1,0.2,0.3\n"
MEDIAPIPE_CSV = ",".join(("frame", "timestamp_ms", "pose", "landmark", *"xyz", "visibility"))
MEDIAPIPE_CSV += ",presence,world_x,world_y,world_z\n"
MEDIAPIPE_CSV += "".join(_ROW.format(t=t, ms=33 * t, j=j) for t in range(2) for j in range(33))


@pytest.mark.parametrize(
    "reader, text, sep, ext",
    [(read_trc, TRC, "\t", ".trc"), (read_mediapipe, MEDIAPIPE_CSV, ",", ".csv")],
    ids=["trc", "mediapipe_csv"],
)
@SETTINGS
@given(data=st.data())
def test_mutated_text(tmp_path, reader, text, sep, ext, data):
    """Up to three fields of a valid file replaced by tokens."""
    lines = [ln.split(sep) for ln in text.split("\n")]
    spots = [(i, j) for i, ln in enumerate(lines) for j in range(len(ln))]
    for _ in range(data.draw(st.integers(1, 3))):
        i, j = data.draw(st.sampled_from(spots))
        lines[i][j] = data.draw(TOKENS)
    p = tmp_path / f"m{ext}"
    p.write_text("\n".join(sep.join(ln) for ln in lines))
    check_reader(reader, p)
