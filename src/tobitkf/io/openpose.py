"""OpenPose JSON output (``--write_json``): a folder of ``*_keypoints.json`` files, one
per frame (OpenPose ``doc/02_output.md``).

Each file is ``{"version": 1.3, "people": [{"person_id": [-1], "pose_keypoints_2d": [x0,
y0, c0, x1, ...], ..., "pose_keypoints_3d": [x0, y0, z0, c0, ...], ...}, ...]}``.

* Keypoints: BODY_25 (25 points, ``openpose_body25``) or COCO (18 points,
  ``openpose_coco18``), told apart by the length of ``pose_keypoints_2d``; another count
  gives joints named ``0``, ``1``, ... without bones.
* A point written as ``0 0 0`` (``0 0 0 0`` in 3-D) is missing: NaN position, confidence
  0 as written. ``c`` is the detection confidence in [0, 1] (in 3-D, 1 or 0: whether the
  reconstruction succeeded). A frame in which a person does not appear gives NaN
  positions and NaN confidence.
* ``dims``: 2 reads ``pose_keypoints_2d`` (units ``"px"``, image coordinates, y down); 3
  reads ``pose_keypoints_3d`` (units unknown: those of the camera calibration); by default
  3 when any person of the folder has 3-D keypoints, else 2.
* People become bodies. When every person carries a ``person_id`` other than -1 (OpenPose
  ``--tracking``), that id is the body; otherwise people are linked across frames by
  nearest neighbour (:mod:`tobitkf.io._association`: Hungarian assignment on the mean
  keypoint distance, gated at the body's size or ``max_distance``), bodies numbered 0, 1,
  ... in order of first appearance.
* Frames are ordered by the frame number in the name (``<video>_000000000012_keypoints``);
  OpenPose stores no frame rate: pass ``fps``.

``path`` is the folder or a single ``*_keypoints.json`` file (a one-frame recording).
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from tobitkf.io._association import associate
from tobitkf.io._json import as_list, as_object, load_json, number_array
from tobitkf.io._text import (
    check_output_size,
    check_positions,
    check_rate,
    plausible_only,
    read_head,
)
from tobitkf.io.errors import OptionError, ReadError
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology, get_topology

__all__ = ["COCO18_JOINTS", "read_openpose", "sniff_openpose", "sniff_openpose_dir"]

#: OpenPose COCO_18 body parts (``POSE_COCO_BODY_PARTS``)
COCO18_JOINTS = (
    "Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist",
    "RHip", "RKnee", "RAnkle", "LHip", "LKnee", "LAnkle", "REye", "LEye", "REar", "LEar",
)  # fmt: skip
# the tree of the COCO limbs (OpenPose's part pairs), rooted at the neck
COCO18_PARENTS = (1, -1, 1, 2, 3, 1, 5, 6, 1, 8, 9, 1, 11, 12, 0, 0, 14, 15)
_COCO18 = Topology.from_names(COCO18_JOINTS, COCO18_PARENTS, name="openpose_coco18")

_SUFFIX = "_keypoints.json"
_FRAME_NUMBER = re.compile(r"(\d+)_keypoints\.json$", re.IGNORECASE)
_KEYS = {2: ("pose_keypoints_2d",), 3: ("pose_keypoints_3d", "body_keypoints_3d")}


def _topology(n: int) -> Topology:
    if n == 25:
        return get_topology("openpose_body25")
    if n == 18:
        return _COCO18
    return Topology.from_names([str(i) for i in range(n)], name=f"openpose_{n}")


def _frame_files(path: Path) -> list[Path]:
    if not path.is_dir():
        return [path]
    files = [f for f in path.iterdir() if f.name.lower().endswith(_SUFFIX) and f.is_file()]
    if not files:
        raise ReadError(path, None, f"no *{_SUFFIX} files in this folder (OpenPose output)")

    def key(f: Path) -> tuple[int, str]:
        m = _FRAME_NUMBER.search(f.name)
        return (int(m.group(1)) if m else -1, f.name)

    return sorted(files, key=key)


def _people(path: Path, doc: Any) -> list[dict[str, Any]]:
    doc = as_object(path, doc, "the document")
    if "people" not in doc:
        raise ReadError(path, None, 'expected an OpenPose "people" array')
    people = as_list(path, doc["people"], '"people"')
    return [as_object(path, p, f"people[{i}]") for i, p in enumerate(people)]


def _keypoints(path: Path, person: dict[str, Any], i: int, dims: int) -> np.ndarray | None:
    """(J, dims + 1) array of a person's keypoints (None when the array is absent/empty)."""
    for key in _KEYS[dims]:
        if key in person:
            arr = number_array(path, person[key], f"people[{i}].{key}")
            if arr.ndim != 1 or arr.size % (dims + 1):
                raise ReadError(
                    path,
                    None,
                    f"expected people[{i}].{key} to be a flat list of "
                    f"{'x, y, z, c' if dims == 3 else 'x, y, c'} groups, found "
                    f"{arr.size} numbers",
                )
            return arr.reshape(-1, dims + 1) if arr.size else None
    return None


def _person_id(path: Path, person: dict[str, Any], i: int) -> int:
    if "person_id" not in person:
        return -1
    ids = number_array(path, person["person_id"], f"people[{i}].person_id")
    if ids.shape != (1,) or ids[0] != np.round(ids[0]) or abs(ids[0]) > 2**53:
        raise ReadError(path, None, f"expected people[{i}].person_id to be [an integer]")
    return int(ids[0])


def read_openpose(
    path: str | os.PathLike[str],
    fps: float | None = None,
    dims: int | None = None,
    max_distance: float | None = None,
    implausible: str = "error",
) -> list[SkeletonSequence]:
    """Read an OpenPose JSON output folder (or one ``*_keypoints.json`` file).

    Parameters
    ----------
    fps : float, optional
        Frame rate of the video (OpenPose does not store it).
    dims : {2, 3}, optional
        Read the 2-D (pixels) or 3-D keypoints (module docstring for the default).
    max_distance : float, optional
        Gate of the association of unlabelled people, in the keypoints' units (default:
        the body's size).
    implausible : {"error", "missing"}
        What to do with a coordinate beyond the plausibility bound: raise a ReadError,
        or read the keypoint as missing.

    Returns
    -------
    list of SkeletonSequence, one per body: positions (T, J, dims) with NaN where missing,
    ``confidence`` (T, J), ``units`` "px" (2-D) or None (3-D), ``metadata["files"]``.
    """
    if dims not in (None, 2, 3):
        raise OptionError(f"dims must be 2, 3 or None, found {dims!r}")
    p = Path(path)
    if fps is not None:
        fps = check_rate(p, None, float(fps), "fps", repr(fps))
    files = _frame_files(p)
    # per frame and person: (2-D keypoints, 3-D keypoints, person_id); the parsed documents
    # (with face and hand arrays) are not kept
    parsed: list[list[tuple[np.ndarray | None, np.ndarray | None, int]]] = []
    for f in files:
        people = _people(f, load_json(f))
        parsed.append(
            [
                (_keypoints(f, q, i, 2), _keypoints(f, q, i, 3), _person_id(f, q, i))
                for i, q in enumerate(people)
            ]
        )
    if dims is None:
        dims = 3 if any(k3 is not None for fr in parsed for _k2, k3, _i in fr) else 2
    frames: list[list[np.ndarray]] = []
    ids: list[list[int]] = []
    n_joints = None
    for f, people in zip(files, parsed):
        dets, pids = [], []
        for i, (k2, k3, pid) in enumerate(people):
            kp = k3 if dims == 3 else k2
            if kp is None:
                continue
            if n_joints is None:
                n_joints = kp.shape[0]
            elif kp.shape[0] != n_joints:
                raise ReadError(
                    f, None, f"people[{i}] has {kp.shape[0]} keypoints, earlier people {n_joints}"
                )
            dets.append(kp)
            pids.append(pid)
        frames.append(dets)
        ids.append(pids)
    if n_joints is None:
        raise ReadError(p, None, f"no person with {dims}-D pose keypoints in the OpenPose output")
    T = len(frames)
    units = "px" if dims == 2 else None
    labelled = all(i != -1 for pids in ids for i in pids)
    if labelled:
        bodies = sorted({i for pids in ids for i in pids})
        tracks = [{t: pids.index(b) for t, pids in enumerate(ids) if b in pids} for b in bodies]
        if any(len(set(pids)) != len(pids) for pids in ids):
            raise ReadError(p, None, "a person_id appears twice in one frame")
    else:
        poses = [
            [plausible_only(_missing_to_nan(kp)[:, :dims], units, implausible) for kp in dets]
            for dets in frames
        ]
        tracks = associate(poses, max_distance)
        bodies = list(range(len(tracks)))
    input_bytes = sum(f.stat().st_size for f in files)
    check_output_size(
        p, len(tracks) * T * n_joints * (dims + 1) * 8, input_bytes, f"{len(tracks)} bodies"
    )
    topo = _topology(n_joints)
    out = []
    for body, track in zip(bodies, tracks):
        pos = np.full((T, n_joints, dims), np.nan)
        conf = np.full((T, n_joints), np.nan)
        for t, d in track.items():
            kp = frames[t][d]
            pos[t] = _missing_to_nan(kp)[:, :dims]
            conf[t] = kp[:, dims]
        if np.any((conf < 0) | (conf > 1)):
            t, j = (int(v) for v in np.argwhere((conf < 0) | (conf > 1))[0])
            raise ReadError(
                files[t], None, f"confidence {conf[t, j]!r} of keypoint {j} outside [0, 1]"
            )
        check_positions(p, pos, None, implausible, names=topo.joints, units=units)
        out.append(
            SkeletonSequence(
                positions=pos,
                topology=topo,
                fps=fps,
                body_id=body,
                confidence=conf,
                units=units,
                metadata={
                    "source": str(p),
                    "format": "openpose",
                    "files": [f.name for f in files],
                    "person_ids": "person_id" if labelled else "associated",
                },
            )
        )
    return out


def _missing_to_nan(kp: np.ndarray) -> np.ndarray:
    """Copy of (J, D + 1) keypoints with the all-zero rows' positions NaN."""
    out = kp.copy()
    out[np.all(kp == 0.0, axis=1), :-1] = np.nan
    return out


def sniff_openpose(path: Path, head: str) -> int:
    """Score of one file: a JSON object with ``"people"`` and pose keypoints."""
    start = head.lstrip()[:1]
    if start == "{" and '"people"' in head and "_keypoints_" in head:
        return 80 if path.name.lower().endswith(_SUFFIX) else 60
    return 0


def sniff_openpose_dir(path: Path) -> int:
    """Score of a folder: it holds ``*_keypoints.json`` files whose first is OpenPose's."""
    first = next(
        (f for f in sorted(path.iterdir()) if f.name.lower().endswith(_SUFFIX) and f.is_file()),
        None,
    )
    if first is None:
        return 0
    return 90 if sniff_openpose(first, read_head(first)) else 10


register_format(
    "openpose", read_openpose, None, (_SUFFIX,), sniff_openpose,
    description="OpenPose JSON output folder (BODY_25 / COCO-18, 2-D or 3-D)",
    sniff_dir=sniff_openpose_dir,
)  # fmt: skip
