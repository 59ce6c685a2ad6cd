"""Azure Kinect Body Tracking JSON: the output of the SDK samples' ``offline_processor``
(microsoft/Azure-Kinect-Samples, ``body-tracking-samples/offline_processor``).

Layout::

    {"k4abt_sdk_version": "1.1.2", "source_file": "rec.mkv",
     "joint_names": ["PELVIS", ...], "bone_list": [["SPINE_CHEST", "SPINE_NAVEL"], ...],
     "frames": [{"timestamp_usec": 133322, "frame_id": 0, "num_bodies": 1,
                 "bodies": [{"body_id": 1,
                             "joint_positions": [[x, y, z], ...],        # 32 joints, mm
                             "joint_orientations": [[w, x, y, z], ...]}]}]}

* Positions are millimetres in the depth camera's frame (y down, z forward); they are
  **converted to metres** (``units="m"``), like every other Kinect reader of tobitkf.
* One sequence per ``body_id`` (the tracker's identity), over all frames of the file:
  NaN (and NOT_TRACKED) in frames where the body is absent. Timestamps are
  ``timestamp_usec`` × 1e-6 (device time); ``fps`` is 30 unless given.
* ``joint_orientations`` (w, x, y, z) are kept as ``metadata["orientations"]`` (T, J, 4).
* Joint names and bones come from ``joint_names`` / ``bone_list`` when the file has them
  (the built-in ``azure_kinect`` topology when they are the SDK's 32 joints).
* Confidence levels (``k4abt_joint_confidence_level_t``): the sample does not write them;
  a body may carry ``"joint_confidence_levels": [c0, c1, ...]`` (one integer per joint,
  as the SDK's ``skeleton.joints[j].confidence_level``). They map to ``confidence``
  level / 3 (NONE 0 → 0, LOW 1 → 1/3, MEDIUM 2 → 2/3, HIGH 3 → 1) and to the tracking
  state (NONE → NOT_TRACKED, LOW → INFERRED, MEDIUM / HIGH → TRACKED). Without them
  ``confidence`` is None and every present joint is TRACKED.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from tobitkf.io._json import as_list, as_object, load_json, number_array
from tobitkf.io._text import check_output_size, check_positions, check_rate
from tobitkf.io.errors import ReadError
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import Topology, get_topology

__all__ = ["CONFIDENCE_LEVELS", "read_azure_kinect", "sniff_azure_kinect"]

#: k4abt_joint_confidence_level_t -> (confidence, tracking state)
CONFIDENCE_LEVELS = {0: (0.0, 0), 1: (1 / 3, 1), 2: (2 / 3, 2), 3: (1.0, 2)}
_LEVEL_KEYS = ("joint_confidence_levels", "confidence_levels")
AZURE_FPS = 30.0


def _topology(path: Path, doc: dict[str, Any], n_joints: int) -> Topology:
    builtin = get_topology("azure_kinect")
    names = doc.get("joint_names")
    if names is None:
        if n_joints == builtin.n_joints:
            return builtin
        return Topology.from_names([str(i) for i in range(n_joints)], name="azure_kinect_custom")
    names = as_list(path, names, '"joint_names"')
    if len(names) != n_joints or not all(isinstance(n, str) and n for n in names):
        raise ReadError(path, None, f'expected "joint_names" to be {n_joints} non-empty strings')
    if len(set(names)) != len(names):
        raise ReadError(path, None, '"joint_names" holds duplicate names')
    if tuple(names) == builtin.joints:
        return builtin
    bones = doc.get("bone_list")
    edges = None
    if bones is not None:
        edges = []
        for i, b in enumerate(as_list(path, bones, '"bone_list"')):
            pair = as_list(path, b, f"bone_list[{i}]")
            if len(pair) != 2 or not all(isinstance(n, str) and n in names for n in pair):
                raise ReadError(path, None, f"expected bone_list[{i}] to be two joint names")
            edges.append((pair[0], pair[1]))
    return Topology.from_names(names, edges=edges, name="azure_kinect_custom")


def read_azure_kinect(
    path: str | os.PathLike[str], fps: float | None = AZURE_FPS, implausible: str = "error"
) -> list[SkeletonSequence]:
    """Read an Azure Kinect Body Tracking ``offline_processor`` JSON file.

    Parameters
    ----------
    fps : float, optional
        Nominal frame rate (30 by default; the file stores timestamps only).
    implausible : {"error", "missing"}
        What to do with a position beyond the plausibility bound.

    Returns
    -------
    list of SkeletonSequence, one per ``body_id`` in order of first appearance.
    """
    p = Path(path)
    if fps is not None:
        fps = check_rate(p, None, float(fps), "fps", repr(fps))
    doc = as_object(p, load_json(p), "the document")
    if "frames" not in doc:
        raise ReadError(p, None, 'expected a "frames" array (Azure Kinect offline_processor JSON)')
    frames = as_list(p, doc["frames"], '"frames"')
    if not frames:
        raise ReadError(p, None, '"frames" is empty')
    T = len(frames)
    stamps = np.empty(T)
    found: dict[Any, dict[int, dict[str, Any]]] = {}
    n_joints = None
    for t, fr in enumerate(frames):
        where = f"frames[{t}]"
        fr = as_object(p, fr, where)
        if "timestamp_usec" not in fr:
            raise ReadError(p, None, f"{where} has no timestamp_usec")
        ts = fr["timestamp_usec"]
        if isinstance(ts, bool) or not isinstance(ts, (int, float)) or not 0 <= ts < 2**63:
            raise ReadError(p, None, f"expected {where}.timestamp_usec to be a count of µs")
        stamps[t] = float(ts) * 1e-6
        for b, body in enumerate(as_list(p, fr.get("bodies", []), f"{where}.bodies")):
            bw = f"{where}.bodies[{b}]"
            body = as_object(p, body, bw)
            bid = body.get("body_id")
            if isinstance(bid, bool) or not isinstance(bid, int):
                raise ReadError(p, None, f"expected {bw}.body_id to be an integer")
            pos = number_array(p, body.get("joint_positions"), f"{bw}.joint_positions")
            if pos.ndim != 2 or pos.shape[1] != 3 or pos.shape[0] == 0:
                raise ReadError(p, None, f"expected {bw}.joint_positions to be [x, y, z] triples")
            if n_joints is None:
                n_joints = pos.shape[0]
            if pos.shape[0] != n_joints:
                raise ReadError(
                    p, None, f"{bw} has {pos.shape[0]} joints, earlier bodies {n_joints}"
                )
            entry: dict[str, Any] = {"positions": pos}
            if "joint_orientations" in body:
                entry["orientations"] = number_array(
                    p, body["joint_orientations"], f"{bw}.joint_orientations", (n_joints, 4)
                )
            for key in _LEVEL_KEYS:
                if key in body:
                    lv = number_array(p, body[key], f"{bw}.{key}", (n_joints,))
                    if not np.isin(lv, list(CONFIDENCE_LEVELS)).all():
                        raise ReadError(p, None, f"expected {bw}.{key} to hold 0, 1, 2 or 3")
                    entry["levels"] = lv.astype(int)
                    break
            if t in found.setdefault(bid, {}):
                raise ReadError(p, None, f"body_id {bid} appears twice in {where}")
            found[bid][t] = entry
    if np.any(np.diff(stamps) < 0):
        k = int(np.argmax(np.diff(stamps) < 0)) + 1
        raise ReadError(p, None, f"frames[{k}].timestamp_usec goes backwards")
    if not found:
        raise ReadError(p, None, "no body in any frame")
    check_output_size(
        p, len(found) * T * n_joints * 8 * 8, p.stat().st_size, f"{len(found)} bodies"
    )
    topo = _topology(p, doc, n_joints)
    out = []
    for bid, per_frame in found.items():
        pos = np.full((T, n_joints, 3), np.nan)
        state = np.zeros((T, n_joints), dtype=np.int8)
        orient = np.full((T, n_joints, 4), np.nan)
        has_levels = any("levels" in e for e in per_frame.values())
        conf = np.full((T, n_joints), np.nan) if has_levels else None
        for t, e in per_frame.items():
            pos[t] = e["positions"] * 1e-3
            state[t] = 2
            if "orientations" in e:
                orient[t] = e["orientations"]
            if "levels" in e:
                conf[t] = [CONFIDENCE_LEVELS[v][0] for v in e["levels"]]
                state[t] = [CONFIDENCE_LEVELS[v][1] for v in e["levels"]]
        check_positions(p, pos, None, implausible, names=topo.joints, state=state)
        meta = {
            "source": str(p),
            "format": "azure_kinect",
            "units_in_file": "mm",
            "sdk_version": doc.get("k4abt_sdk_version"),
            "orientations": orient,
        }
        out.append(
            SkeletonSequence(
                positions=pos,
                topology=topo,
                tracking_state=state,
                timestamps=stamps.copy(),
                fps=fps,
                body_id=bid,
                confidence=conf,
                units="m",
                metadata=meta,
            )
        )
    return out


def sniff_azure_kinect(path: Path, head: str) -> int:
    """Score: a JSON object with the offline processor's keys."""
    if head.lstrip()[:1] != "{":
        return 0
    # nlohmann::json writes keys sorted: "bone_list" and "frames" open the file
    if '"k4abt_sdk_version"' in head or ('"bone_list"' in head and '"frames"' in head):
        return 90
    if '"joint_positions"' in head and '"bodies"' in head and '"timestamp_usec"' in head:
        return 70
    return 0


register_format(
    "azure_kinect", read_azure_kinect, None, (".json",), sniff_azure_kinect,
    description="Azure Kinect Body Tracking JSON (offline_processor; mm -> m)",
    aliases=("k4abt",),
)  # fmt: skip
