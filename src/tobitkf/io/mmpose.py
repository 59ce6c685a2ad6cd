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

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tobitkf.core.jsonable import to_jsonable
from tobitkf.io._association import associate
from tobitkf.io._json import as_list, as_object, load_json, number_array
from tobitkf.io._pose import check_one_video, written_confidence
from tobitkf.io._text import check_output_size, check_positions, option_rate, plausible_only
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format, require_frames
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import (
    COCO17_JOINTS,
    UNNAMED,
    Topology,
    get_topology,
)

__all__ = ["read_mmpose", "sniff_mmpose", "write_mmpose"]


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


def _topology(
    path: Path, meta: dict[str, Any] | None, n: int, dims: int, given: Any = None
) -> Topology:
    """The file's names (meta_info), else the skeleton ``given``, else by the count."""
    names = _names(path, meta, n)
    if names is None and given is not None:
        topo = given if isinstance(given, Topology) else _named(path, given)
        if topo.n_joints != n:
            raise ReadError(path, None, f"{n} keypoints, topology {topo.name!r} {topo.n_joints}")
        return topo
    if names is None:
        if n == 17:
            return get_topology("coco17" if dims == 2 else "h36m17")
        return Topology.from_names([str(j) for j in range(n)], name=UNNAMED)
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


#: per-keypoint lists of an instance: MMPose's scores, and the standard deviation and
#: sample state tobitkf's writer adds (NaN where absent)
_PER_KEYPOINT = ("keypoint_scores", "keypoint_std", "keypoint_states")


def _per_keypoint(path: Path, inst: dict[str, Any], key: str, where: str, n: int) -> np.ndarray:
    if inst.get(key) is None:
        return np.full(n, np.nan)
    values = number_array(path, inst[key], f"{where}.{key}", allow_null=True)
    if values.shape != (n,):
        raise ReadError(path, None, f"{where}.{key}: {values.size} values for {n} keypoints")
    return values


def _named(path: Path, name: str) -> Topology:
    try:
        return get_topology(str(name))
    except KeyError as exc:
        raise ReadError(path, None, str(exc.args[0])) from None


def _instance(path: Path, inst: Any, where: str) -> tuple[np.ndarray, ...]:
    """(J, D) keypoints; (J,) scores, standard deviations and sample states (NaN
    without); and the track id (None without)."""
    inst = as_object(path, inst, where)
    if "keypoints" not in inst:
        raise ReadError(path, None, f'{where}: no "keypoints"')
    kp = number_array(path, inst["keypoints"], f"{where}.keypoints", allow_null=True)
    if kp.ndim != 2 or kp.shape[1] not in (2, 3) or len(kp) == 0:
        raise ReadError(
            path, None, f"{where}.keypoints: expected [[x, y], ...] or [[x, y, z], ...], found "
            f"shape {kp.shape}"
        )  # fmt: skip
    scores, std, states = (_per_keypoint(path, inst, k, where, len(kp)) for k in _PER_KEYPOINT)
    track = inst.get("track_id")
    if track is not None and (isinstance(track, bool) or not isinstance(track, (int, str))):
        raise ReadError(path, None, f"{where}.track_id: expected an integer or a string")
    return kp, scores, std, states, track


def read_mmpose(
    path: str | os.PathLike[str],
    *,
    fps: float | None = None,
    max_distance: float | None = None,
    topology: Topology | str | None = None,
    implausible: str = "error",
) -> list[SkeletonSequence]:
    """Read MMPose predictions (module docstring): one sequence per person, with the
    video's frame rate ``fps`` (the file has none), for people without a ``track_id``
    the association's gate ``max_distance`` as OpenPose's reader takes it, and
    ``topology`` (a name or a Topology) for a file whose meta does not name its keypoints
    (instead of the guess by their count). ``implausible`` (``"error"`` or
    ``"missing"``): what to do with a coordinate beyond the plausibility bound."""
    p = Path(path)
    fps = option_rate(p, fps)
    frames, meta = _frames(p, load_json(p))
    if fps is None and meta is not None and meta.get("fps") is not None:
        fps = option_rate(p, meta["fps"])  # written by tobitkf's writer
    ids: list[int] = []
    dets: list[list[tuple[Any, ...]]] = []
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
    shapes = {inst[0].shape for fr in dets for inst in fr}
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
    tracks_ids = [inst[-1] for fr in dets for inst in fr]
    tracked = all(t is not None for t in tracks_ids)
    if tracked:
        bodies = list(dict.fromkeys(tracks_ids))
        tracks = []
        for b in bodies:
            track = {}
            for t, fr in zip(at, dets, strict=True):
                mine = [k for k, inst in enumerate(fr) if inst[-1] == b]
                if len(mine) > 1:
                    raise ReadError(p, None, f"track_id {b!r} appears twice in one frame")
                if mine:
                    track[t] = mine[0]
            tracks.append(track)
        by_frame = dict(zip(at, dets, strict=True))
    else:
        by_frame = dict(zip(at, dets, strict=True))
        units = "px" if dims == 2 else None
        poses = [
            [plausible_only(inst[0], units, implausible) for inst in by_frame.get(t, [])]
            for t in range(T)
        ]
        tracks = associate(poses, max_distance)
        bodies = list(range(len(tracks)))
    check_output_size(p, len(tracks) * T * n_joints * (dims + 1) * 8, size, f"{len(tracks)} people")
    topo = _topology(p, meta, n_joints, dims, topology)
    guessed = topology is None and _names(p, meta, n_joints) is None and topo.name != UNNAMED
    notes = []
    if topo.name == UNNAMED:
        notes.append(
            f"{n_joints} keypoints and no keypoint names in the file: joints 0..J-1 without "
            "bones (the robust methods gate by speed only); give the skeleton "
            "(tobitkf smooth --topology)"
        )
    out = []
    for body, track in zip(bodies, tracks, strict=True):
        pos = np.full((T, n_joints, dims), np.nan)
        conf, std, states = (np.full((T, n_joints), np.nan) for _ in range(3))
        for t, d in track.items():
            pos[t], conf[t], std[t], states[t] = by_frame[t][d][:4]
        clipped = bool(np.any((conf > 1) | (conf < 0)))  # scores, not probabilities
        conf = np.clip(conf, 0.0, 1.0)  # NaN (no score) stays NaN
        check_positions(
            p, pos, None, implausible, names=topo.joints, units="px" if dims == 2 else None
        )
        meta_out: dict[str, Any] = {
            "source": str(p),
            "format": "mmpose",
            "person_ids": "track_id" if tracked else "associated",
            "frame_id_start": first,  # the writer numbers the frames alike
        }
        if guessed:  # by the count alone: --topology may say otherwise
            meta_out["topology_guessed"] = True
        if meta is not None:
            meta_out["mmpose_meta"] = meta  # written back by the writer
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
                std=None if np.isnan(std).all() else std,
                sample_state=_states(p, states),
            )
        )
    return out


def _states(path: Path, states: np.ndarray) -> np.ndarray | None:
    """tobitkf's sample states (0-4) as written by :func:`write_mmpose`; NONE (4) where a
    body was not in the frame."""
    if np.isnan(states).all():
        return None
    filled = np.where(np.isnan(states), 4.0, states)
    if np.any((filled != np.round(filled)) | (filled < 0) | (filled > 4)):
        raise ReadError(path, None, "keypoint_states: expected sample states 0 to 4")
    return filled.astype(np.int8)


def write_mmpose(sequences: Sequence[SkeletonSequence], path: str | os.PathLike[str]) -> None:
    """Write sequences (one per person, same keypoints) as MMPose predictions in the
    demos' layout: ``{"meta_info": ..., "instance_info": [{"frame_id": n, "instances":
    [...]}, ...]}``.

    ``meta_info`` is the one read from an MMPose file (if any) with ``tobitkf``, the
    output's provenance, and ``fps`` added (the reader takes the rate back from it);
    without one, the keypoints' names (``keypoint_id2name``) and bones
    (``skeleton_links``), as MMPose's dataset meta gives them.
    Each person present in a frame is an instance with ``keypoints``,
    ``keypoint_scores`` (the confidence, where there is one; 0 where a smoother filled
    the sample: no detection lies there), ``track_id`` (the body
    id) and, for smoothed output, ``keypoint_std`` and ``keypoint_states`` (tobitkf's
    sample states); a missing value is ``null``. Frames are numbered as in the file
    read (``metadata["frame_id_start"]``), else from 0.
    """
    seqs = list(sequences)
    if not seqs:
        raise ValueError("no sequence to write")
    require_frames(seqs, "MMPose")
    check_one_video(seqs)
    shape = {(s.n_joints, s.n_dims) for s in seqs}
    if len(shape) > 1:
        raise ValueError(f"MMPose instances share one keypoint layout; found {sorted(shape)}")
    start = seqs[0].metadata.get("frame_id_start", 0)
    if isinstance(start, bool) or not isinstance(start, (int, np.integer)):
        raise ValueError(f"metadata frame_id_start must be an integer, found {start!r}")
    T = max(s.n_frames for s in seqs)
    frames: list[dict[str, Any]] = [{"frame_id": int(start) + t, "instances": []} for t in range(T)]
    for k, s in enumerate(seqs):
        track = k if s.body_id is None else s.body_id
        score = written_confidence(s)
        for t in np.flatnonzero(~np.isnan(s.positions).all(axis=(1, 2))):
            inst: dict[str, Any] = {"keypoints": s.positions[t]}
            for key, values in zip(_PER_KEYPOINT, (score, s.std, s.sample_state)):
                if values is not None:
                    inst[key] = values[t]
            inst["track_id"] = track
            frames[t]["instances"].append(inst)
    meta = next((s.metadata["mmpose_meta"] for s in seqs if "mmpose_meta" in s.metadata), {})
    meta = dict(meta)
    topo = seqs[0].topology
    if "keypoint_id2name" not in meta and topo.name != UNNAMED:  # the names read back
        meta["keypoint_id2name"] = {str(j): name for j, name in enumerate(topo.joints)}
        if "skeleton_links" not in meta and topo.bones:
            meta["skeleton_links"] = [[int(a), int(b)] for a, b in topo.bones]
    if seqs[0].fps is not None:  # MMPose keeps none; tobitkf's reader takes it back
        meta["fps"] = seqs[0].fps
    if "provenance" in seqs[0].metadata:
        meta["tobitkf"] = seqs[0].metadata["provenance"]
    doc = {"meta_info": meta, "instance_info": frames}
    text = json.dumps(to_jsonable(doc), allow_nan=False)
    Path(path).write_text(text + "\n", encoding="utf-8")


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
    "mmpose", read_mmpose, write_mmpose, (".json",), sniff_mmpose,
    description="MMPose predictions JSON (a video's frames and instances)",
)  # fmt: skip
