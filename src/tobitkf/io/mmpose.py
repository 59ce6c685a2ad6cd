"""MMPose prediction JSON: what MMPose (RTMPose, ViTPose, HRNet, the 3-D lifters) saves for
a video.

Two layouts, both a list of frames ``{"frame_id": n, "instances": [instance, ...]}``:

* the list itself (``MMPoseInferencer(...)(video, pred_out_dir=...)``);
* ``{"meta_info": {...}, "instance_info": [frames]}`` (the demos' ``--save-predictions``,
  e.g. ``demo/topdown_demo_with_mmdet.py``), ``meta_info`` being the model's dataset
  meta: keypoint names (``keypoint_id2name``) and bones (``skeleton_links``).

An instance (one detected person) has ``keypoints`` ``[[x, y], ...]`` (or ``[x, y, z]``
from the 3-D inferencer), ``keypoint_scores`` and, when a tracker ran, ``track_id``.

* Frames go where their ``frame_id`` says (ids counted from the smallest; a frame id
  missing from the file is a frame where nobody was detected). MMPose does not store the
  frame rate: ``fps=`` (``tobitkf smooth --fps``).
* The skeleton: the names and bones of ``meta_info`` when the file has them; otherwise,
  by the keypoint count, 17 keypoints are COCO's (``coco17``) in 2-D and Human3.6M's
  (``h36m17``, the lifters' output) in 3-D; another count gives joints ``0``, ``1``, ...
  without bones (and a note in ``metadata["reader_warnings"]``).
* People: by ``track_id`` when every instance has one, else linked across frames by
  nearest neighbour (:mod:`tobitkf.io._association`), as OpenPose's.
* Scores become ``confidence``; RTMPose's SimCC scores are not probabilities and may
  leave [0, 1]: they are clipped into it and ``metadata["confidence_clipped"]`` says so.
* Units: pixels in 2-D, unknown in 3-D.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from tobitkf.io._association import associate
from tobitkf.io._json import as_list, as_object, load_json, number_array
from tobitkf.io._text import check_output_size, check_positions, option_rate
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import (
    COCO17_JOINTS,
    Topology,
    get_topology,
)

__all__ = ["read_mmpose", "sniff_mmpose"]


def _frames(path: Path, doc: Any) -> tuple[list[Any], dict[str, Any] | None]:
    """The frame list and the meta (None when the file has none)."""
    if isinstance(doc, dict):
        if "instance_info" not in doc:
            raise ReadError(path, None, 'expected "instance_info" (MMPose predictions)')
        meta = doc.get("meta_info")
        meta = None if meta is None else as_object(path, meta, "meta_info")
        return as_list(path, doc["instance_info"], "instance_info"), meta
    return as_list(path, doc, "the document"), None


def _names(path: Path, meta: dict[str, Any] | None, n: int) -> list[str] | None:
    """Keypoint names from ``meta_info["keypoint_id2name"]`` (an object or a list)."""
    if meta is None or meta.get("keypoint_id2name") is None:
        return None
    raw = meta["keypoint_id2name"]
    if isinstance(raw, dict):
        try:
            pairs = sorted((int(k), v) for k, v in raw.items())
        except ValueError:
            raise ReadError(
                path, None, "meta_info.keypoint_id2name: keys must be indices"
            ) from None
        raw = [v for _k, v in pairs] if [k for k, _v in pairs] == list(range(len(pairs))) else None
    if not isinstance(raw, list) or len(raw) != n or not all(isinstance(v, str) for v in raw):
        raise ReadError(
            path, None, f"meta_info.keypoint_id2name: expected the names of the {n} keypoints"
        )
    return list(raw)


def _topology(path: Path, meta: dict[str, Any] | None, n: int, dims: int) -> Topology:
    names = _names(path, meta, n)
    if names is None:
        if n == 17:
            return get_topology("coco17" if dims == 2 else "h36m17")
        return Topology.from_names([str(j) for j in range(n)], name="mmpose")
    if tuple(names) == COCO17_JOINTS:
        return get_topology("coco17")
    links = None if meta is None else meta.get("skeleton_links")
    edges = None
    if links:
        arr = number_array(path, links, "meta_info.skeleton_links")
        if arr.ndim != 2 or arr.shape[1] != 2 or np.any(arr != np.round(arr)):
            raise ReadError(path, None, "meta_info.skeleton_links: expected index pairs")
        if arr.min() < 0 or arr.max() >= n:
            raise ReadError(path, None, f"meta_info.skeleton_links: an index outside 0..{n - 1}")
        edges = [(int(a), int(b)) for a, b in arr]
    dataset = meta.get("dataset_name") if meta is not None else None
    try:
        return Topology.from_names(
            names, edges=edges, name=str(dataset) if isinstance(dataset, str) else "mmpose"
        )
    except ValueError as exc:
        raise ReadError(path, None, f"meta_info: {exc}") from None


def _instance(path: Path, inst: Any, where: str) -> tuple[np.ndarray, np.ndarray, Any]:
    """(J, D) keypoints, (J,) scores (NaN without), and the track id (None without)."""
    inst = as_object(path, inst, where)
    if "keypoints" not in inst:
        raise ReadError(path, None, f'{where}: no "keypoints"')
    kp = number_array(path, inst["keypoints"], f"{where}.keypoints", allow_null=True)
    if kp.ndim != 2 or kp.shape[1] not in (2, 3) or len(kp) == 0:
        raise ReadError(
            path, None, f"{where}.keypoints: expected [[x, y], ...] or [[x, y, z], ...], found "
            f"shape {kp.shape}"
        )  # fmt: skip
    scores = np.full(len(kp), np.nan)
    if inst.get("keypoint_scores") is not None:
        s = number_array(path, inst["keypoint_scores"], f"{where}.keypoint_scores")
        if s.shape != (len(kp),):
            raise ReadError(
                path, None, f"{where}.keypoint_scores: {s.size} scores for {len(kp)} keypoints"
            )
        scores = s
    track = inst.get("track_id")
    if track is not None and (isinstance(track, bool) or not isinstance(track, (int, str))):
        raise ReadError(path, None, f"{where}.track_id: expected an integer or a string")
    return kp, scores, track


def read_mmpose(
    path: str | os.PathLike[str],
    *,
    fps: float | None = None,
    max_distance: float | None = None,
) -> list[SkeletonSequence]:
    """Read MMPose predictions (module docstring): one sequence per person, with the
    video's frame rate ``fps`` (the file has none) and, for people without a
    ``track_id``, the association's gate ``max_distance`` as OpenPose's reader takes it."""
    p = Path(path)
    fps = option_rate(p, fps)
    frames, meta = _frames(p, load_json(p))
    ids: list[int] = []
    dets: list[list[tuple[np.ndarray, np.ndarray, Any]]] = []
    for i, fr in enumerate(frames):
        fr = as_object(p, fr, f"frame {i}")
        fid = fr.get("frame_id", i)
        if isinstance(fid, bool) or not isinstance(fid, int):
            raise ReadError(p, None, f"frame {i}: frame_id must be an integer, found {fid!r}")
        ids.append(fid)
        insts = as_list(p, fr.get("instances", []), f"frame {i}.instances")
        dets.append([_instance(p, q, f"frame {i}.instances[{k}]") for k, q in enumerate(insts)])
    if len(set(ids)) != len(ids):
        raise ReadError(p, None, "a frame_id appears twice")
    shapes = {kp.shape for fr in dets for kp, _s, _t in fr}
    if not shapes:
        raise ReadError(p, None, "no person detected in any frame")
    if len(shapes) > 1:
        raise ReadError(p, None, f"instances of different shapes {sorted(shapes)}")
    ((n_joints, dims),) = shapes
    first = min(ids)
    T = max(ids) - first + 1
    size = p.stat().st_size
    check_output_size(p, T * n_joints * (dims + 1) * 8, size, f"{T} frames")
    at = [fid - first for fid in ids]
    tracks_ids = [t for fr in dets for _k, _s, t in fr]
    tracked = all(t is not None for t in tracks_ids)
    if tracked:
        bodies = list(dict.fromkeys(tracks_ids))
        tracks = []
        for b in bodies:
            track = {}
            for t, fr in zip(at, dets, strict=True):
                mine = [k for k, (_kp, _s, tid) in enumerate(fr) if tid == b]
                if len(mine) > 1:
                    raise ReadError(p, None, f"track_id {b!r} appears twice in one frame")
                if mine:
                    track[t] = mine[0]
            tracks.append(track)
        by_frame = dict(zip(at, dets, strict=True))
    else:
        by_frame = dict(zip(at, dets, strict=True))
        poses = [[kp for kp, _s, _t in by_frame.get(t, [])] for t in range(T)]
        tracks = associate(poses, max_distance)
        bodies = list(range(len(tracks)))
    check_output_size(p, len(tracks) * T * n_joints * (dims + 1) * 8, size, f"{len(tracks)} people")
    topo = _topology(p, meta, n_joints, dims)
    notes = []
    if topo.name == "mmpose" and not topo.bones:
        notes.append(
            f"{n_joints} keypoints and no keypoint names in the file: joints 0..J-1 without "
            "bones (the robust methods gate by speed only)"
        )
    out = []
    for body, track in zip(bodies, tracks, strict=True):
        pos = np.full((T, n_joints, dims), np.nan)
        conf = np.full((T, n_joints), np.nan)
        for t, d in track.items():
            kp, s, _tid = by_frame[t][d]
            pos[t], conf[t] = kp, s
        clipped = bool(np.any((conf > 1) | (conf < 0)))  # scores, not probabilities
        conf = np.clip(conf, 0.0, 1.0)  # NaN (no score) stays NaN
        check_positions(p, pos, None, names=topo.joints, units="px" if dims == 2 else None)
        meta_out: dict[str, Any] = {
            "source": str(p),
            "format": "mmpose",
            "person_ids": "track_id" if tracked else "associated",
        }
        if clipped:
            meta_out["confidence_clipped"] = True
        if notes:
            meta_out["reader_warnings"] = list(notes)
        out.append(
            SkeletonSequence(
                positions=pos,
                topology=topo,
                fps=fps,
                body_id=body,
                confidence=None if np.isnan(conf).all() else conf,
                units="px" if dims == 2 else None,
                metadata=meta_out,
            )
        )
    return out


def sniff_mmpose(path: Path, head: str) -> int:
    """Score: JSON holding frames with ``frame_id`` and ``instances`` (or
    ``instance_info``)."""
    start = head.lstrip()[:1]
    if start == "[" and '"frame_id"' in head and '"instances"' in head:
        return 80
    if start == "{" and '"instance_info"' in head:
        return 80
    if start == "{" and '"meta_info"' in head and '"keypoint_id2name"' in head:
        return 70  # the meta may fill the first 64 KB
    return 0


register_format(
    "mmpose", read_mmpose, None, (".json",), sniff_mmpose,
    description="MMPose predictions JSON (a video's frames and instances)",
)  # fmt: skip
