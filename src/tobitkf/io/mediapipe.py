"""MediaPipe Pose landmarks, as JSON or CSV (a layout tobitkf defines: MediaPipe writes no
files; these are the results of its Pose Landmarker, field for field).

**JSON** (``.json``): the ``PoseLandmarkerResult`` of every frame, landmarks as objects
with the attributes of MediaPipe's ``NormalizedLandmark`` / ``Landmark`` dataclasses
(``dataclasses.asdict`` gives exactly these; ``null`` for an unset value)::

    {"fps": 30, "image_size": [1280, 720],                    # both optional
     "frames": [{"timestamp_ms": 0,                           # optional
                 "pose_landmarks": [[{"x": 0.51, "y": 0.32, "z": -0.41,
                                      "visibility": 0.99, "presence": 0.98}, ...33], ...],
                 "pose_world_landmarks": [[{"x": 0.02, ...}, ...33], ...]}, ...]}

``pose_landmarks`` / ``pose_world_landmarks`` hold one list of 33 landmarks per detected
person (``[]`` when nobody is detected); a single list of 33 landmarks (the legacy
``mp.solutions.pose`` result, ``results.pose_landmarks.landmark``) is one person.

**CSV** (``.csv``, one row per landmark, any row order; the long table that
``pandas.DataFrame.to_csv(index=False)`` writes from the same results)::

    frame,timestamp_ms,pose,landmark,x,y,z,visibility,presence,world_x,world_y,world_z

``frame``, ``landmark`` (MediaPipe's name, e.g. ``left_wrist``, or its index 0-32), ``x``
and ``y`` are required; the others are optional columns; an empty field is an unset
value; ``pose`` (default 0) tells the people of a frame apart. A landmark absent from a
frame is missing.

Reading (``landmarks``):

* ``"world"``: the world landmarks, 3-D in metres (``units="m"``, origin between the
  hips); ``"image"``: the image landmarks, 2-D normalised to [0, 1] of the image width and
  height (``units=None``), or pixels (``units="px"``) when ``image_size`` (width, height)
  is given or in the file; their ``z`` is kept in ``metadata["image_z"]``. ``"auto"``
  (default): world when the file has world landmarks, else image.
* ``confidence`` = ``visibility`` (the likelihood that the landmark is visible, in
  [0, 1]); ``presence`` is kept in ``metadata["presence"]``.
* People are bodies 0, 1, ... linked across frames by nearest neighbour on the image
  landmarks (:mod:`tobitkf.io._association`; world landmarks are all centred on the hips
  and cannot tell people apart).
* Timestamps: ``timestamp_ms`` × 1e-3 when every frame has one; fps from the option or
  the file.
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path
from typing import Any

import numpy as np

from tobitkf.io._association import associate
from tobitkf.io._json import as_list, as_object, load_json, number_array
from tobitkf.io._text import (
    NUMBER,
    check_output_size,
    check_positions,
    check_rate,
    decode,
    read_bytes,
    read_head,
)
from tobitkf.io.errors import OptionError, ReadError
from tobitkf.io.registry import register_format
from tobitkf.skeleton.sequence import SkeletonSequence
from tobitkf.skeleton.topology import MEDIAPIPE_POSE_JOINTS, get_topology

__all__ = ["CSV_COLUMNS", "read_mediapipe", "sniff_mediapipe"]

N = len(MEDIAPIPE_POSE_JOINTS)
_FIELDS = ("x", "y", "z", "visibility", "presence")
#: the columns of the CSV layout (frame, landmark, x and y required)
CSV_COLUMNS = (
    "frame", "timestamp_ms", "pose", "landmark", "x", "y", "z", "visibility", "presence",
    "world_x", "world_y", "world_z",
)  # fmt: skip
_INDEX = {name: i for i, name in enumerate(MEDIAPIPE_POSE_JOINTS)}

# one person in one frame: "image" / "world" -> (33, 5) x, y, z, visibility, presence
Person = dict[str, np.ndarray]


def _landmarks(path: Path, value: Any, where: str) -> np.ndarray:
    """(33, 5) array of a list of 33 landmark objects."""
    items = as_list(path, value, where)
    if len(items) != N:
        raise ReadError(path, None, f"expected {N} landmarks in {where}, found {len(items)}")
    out = np.full((N, 5), np.nan)
    for j, lm in enumerate(items):
        lm = as_object(path, lm, f"{where}[{j}]")
        vals = [lm.get(k) for k in _FIELDS]
        out[j] = number_array(path, vals, f"{where}[{j}]", (5,), allow_null=True)
    return out


def _people(path: Path, value: Any, where: str) -> list[np.ndarray]:
    items = as_list(path, value, where)
    if items and isinstance(items[0], dict):  # legacy: one person's landmarks
        return [_landmarks(path, items, where)]
    return [_landmarks(path, p, f"{where}[{i}]") for i, p in enumerate(items)]


def _read_json(path: Path) -> tuple[list[list[Person]], np.ndarray | None, dict[str, Any]]:
    doc = as_object(path, load_json(path), "the document")
    if "frames" not in doc:
        raise ReadError(path, None, 'expected a "frames" array (MediaPipe Pose JSON)')
    frames_in = as_list(path, doc["frames"], '"frames"')
    frames: list[list[Person]] = []
    stamps = []
    for t, fr in enumerate(frames_in):
        where = f"frames[{t}]"
        fr = as_object(path, fr, where)
        image = _people(path, fr.get("pose_landmarks", []), f"{where}.pose_landmarks")
        world = _people(path, fr.get("pose_world_landmarks", []), f"{where}.pose_world_landmarks")
        if image and world and len(image) != len(world):
            raise ReadError(
                path, None, f"{where}: {len(image)} image poses but {len(world)} world poses"
            )
        people = []
        for i in range(max(len(image), len(world))):
            person = {}
            if image:
                person["image"] = image[i]
            if world:
                person["world"] = world[i]
            people.append(person)
        frames.append(people)
        ts = fr.get("timestamp_ms")
        stamps.append(None if ts is None else number_array(path, [ts], f"{where}.timestamp_ms")[0])
    times = np.array(stamps, dtype=float) * 1e-3 if stamps and None not in stamps else None
    extra = {k: doc[k] for k in ("fps", "image_size") if k in doc}
    return frames, times, extra


def _csv_number(path: Path, line: int, text: str, column: str) -> float:
    s = text.strip()
    if not s:
        return np.nan
    if NUMBER.fullmatch(s) is None or not np.isfinite(float(s)):
        raise ReadError(path, line, f"expected a number in column {column!r}, found {s[:40]!r}")
    return float(s)


def _read_csv(path: Path) -> tuple[list[list[Person]], np.ndarray | None, dict[str, Any]]:
    text = decode(path, read_bytes(path))
    rows = csv.reader(io.StringIO(text, newline=""))
    try:
        header = [h.strip() for h in next(rows)]
    except StopIteration:
        raise ReadError(path, None, "empty file: expected a MediaPipe CSV header") from None
    except csv.Error as exc:
        raise ReadError(path, 1, f"invalid CSV ({exc})") from None
    if header and header[0] == "":  # a pandas index column
        header[0] = "_index"
    unknown = [h for h in header if h not in CSV_COLUMNS and h != "_index"]
    missing = [c for c in ("frame", "landmark", "x", "y") if c not in header]
    if unknown or missing or len(set(header)) != len(header):
        raise ReadError(
            path,
            1,
            f"expected the MediaPipe CSV columns {list(CSV_COLUMNS)} (frame, landmark, x, y "
            f"required, each once); unknown {unknown}, missing {missing}",
        )
    col = {h: i for i, h in enumerate(header)}
    cells: dict[tuple[int, int], dict[str, np.ndarray]] = {}
    stamps: dict[int, float] = {}
    try:
        for row in rows:
            line = rows.line_num
            if not any(f.strip() for f in row):
                continue
            if len(row) != len(header):
                raise ReadError(path, line, f"expected {len(header)} fields, found {len(row)}")
            frame = _csv_number(path, line, row[col["frame"]], "frame")
            pose = _csv_number(path, line, row[col["pose"]], "pose") if "pose" in col else 0.0
            for v, what in ((frame, "frame"), (pose, "pose")):
                if not (np.isfinite(v) and v == int(v) and 0 <= v < 2**31):
                    raise ReadError(path, line, f"expected a non-negative integer {what}")
            name = row[col["landmark"]].strip()
            j = _INDEX.get(name)
            if j is None and name.isascii() and name.isdigit() and int(name) < N:
                j = int(name)
            if j is None:
                raise ReadError(path, line, f"unknown MediaPipe Pose landmark {name[:40]!r}")
            vals = {c: _csv_number(path, line, row[col[c]], c) for c in col if c in CSV_COLUMNS[4:]}
            if "timestamp_ms" in col:
                ts = _csv_number(path, line, row[col["timestamp_ms"]], "timestamp_ms")
                if stamps.setdefault(int(frame), ts) != ts and not np.isnan(ts):
                    raise ReadError(path, line, f"frame {int(frame)} has two timestamps")
            key = (int(frame), int(pose))
            person = cells.setdefault(
                key, {"image": np.full((N, 5), np.nan), "world": np.full((N, 5), np.nan)}
            )
            if not np.isnan(person["image"][j, 0]) or not np.isnan(person["world"][j, 0]):
                raise ReadError(
                    path, line, f"landmark {name!r} twice in frame {key[0]}, pose {key[1]}"
                )
            person["image"][j] = [vals.get(k, np.nan) for k in _FIELDS]
            person["world"][j, :3] = [vals.get(f"world_{k}", np.nan) for k in "xyz"]
            person["world"][j, 3:] = person["image"][j, 3:]
    except csv.Error as exc:
        raise ReadError(path, rows.line_num, f"invalid CSV ({exc})") from None
    if not cells:
        raise ReadError(path, None, "no landmark rows after the header")
    n_frames = max(f for f, _ in cells) + 1
    check_output_size(path, n_frames * 8 * N * 5 * 2, len(text), f"{n_frames} frames")
    has_world = any(c in col for c in ("world_x", "world_y", "world_z"))
    frames: list[list[Person]] = [[] for _ in range(n_frames)]
    for (f, _pose), person in sorted(cells.items()):
        if not has_world:
            del person["world"]
        frames[f].append(person)
    times = None
    if stamps and len(stamps) == n_frames and not np.isnan(list(stamps.values())).any():
        times = np.array([stamps[f] for f in range(n_frames)]) * 1e-3
    return frames, times, {}


def read_mediapipe(
    path: str | os.PathLike[str],
    landmarks: str = "auto",
    image_size: tuple[float, float] | None = None,
    fps: float | None = None,
    max_distance: float | None = None,
) -> list[SkeletonSequence]:
    """Read MediaPipe Pose landmarks (JSON or CSV layout of the module docstring).

    Parameters
    ----------
    landmarks : {"auto", "world", "image"}
    image_size : (width, height), optional
        Pixels per unit of the normalised image coordinates: image landmarks in pixels.
    fps : float, optional
    max_distance : float, optional
        Association gate in normalised image units (default: the body's size).
    """
    if landmarks not in ("auto", "world", "image"):
        raise OptionError(f"landmarks must be 'auto', 'world' or 'image', found {landmarks!r}")
    p = Path(path)
    json_like = read_head(p, 4096).lstrip().lstrip("\ufeff")[:1] in ("{", "[")
    frames, times, extra = _read_json(p) if json_like else _read_csv(p)
    people = [q for fr in frames for q in fr]
    if not people:
        raise ReadError(p, None, "no pose in any frame")
    has_world = all("world" in q for q in people)
    has_image = all("image" in q for q in people)
    kind = landmarks if landmarks != "auto" else ("world" if has_world else "image")
    if (kind == "world" and not has_world) or (kind == "image" and not has_image):
        raise ReadError(p, None, f"the file has no {kind} landmarks for every pose")
    if fps is None and "fps" in extra:
        fps = number_array(p, [extra["fps"]], '"fps"')[0]
    if fps is not None:
        fps = check_rate(p, None, float(fps), "fps", repr(fps))
    if image_size is None and "image_size" in extra:
        size = number_array(p, extra["image_size"], '"image_size"', (2,))
        if not np.all(size > 0):
            raise ReadError(p, None, f'expected "image_size" (width, height) > 0, found {size}')
        image_size = (float(size[0]), float(size[1]))
    scale = None
    if image_size is not None:
        scale = np.asarray(image_size, dtype=float)
        if scale.shape != (2,) or not np.all(np.isfinite(scale) & (scale > 0)):
            raise OptionError(f"image_size must be (width, height) > 0, found {image_size!r}")
    key = "image" if has_image else "world"
    tracks = associate([[q[key][:, :2] for q in fr] for fr in frames], max_distance)
    T = len(frames)
    dims = 3 if kind == "world" else 2
    out = []
    for b, track in enumerate(tracks):
        data = np.full((T, N, 5), np.nan)
        image_z = np.full((T, N), np.nan)
        for t, d in track.items():
            data[t] = frames[t][d][kind]
            if "image" in frames[t][d]:
                image_z[t] = frames[t][d]["image"][:, 2]
        conf, presence = data[:, :, 3], data[:, :, 4]
        for what, v in (("visibility", conf), ("presence", presence)):
            if np.any((v < 0) | (v > 1)):
                raise ReadError(p, None, f"{what} outside [0, 1] in pose {b}")
        pos = data[:, :, :dims].copy()
        if kind == "image" and scale is not None:
            pos *= scale
        units = "m" if kind == "world" else ("px" if scale is not None else None)
        check_positions(p, pos, None, "error", names=MEDIAPIPE_POSE_JOINTS, units=units)
        meta: dict[str, Any] = {"source": str(p), "format": "mediapipe", "landmarks": kind}
        meta["presence"] = presence.copy()
        if kind == "image":
            meta["image_z"] = image_z
        out.append(
            SkeletonSequence(
                positions=pos,
                topology=get_topology("mediapipe_pose"),
                timestamps=times,
                fps=fps,
                body_id=b,
                confidence=None if np.isnan(conf).all() else conf.copy(),
                units=units,
                metadata=meta,
            )
        )
    return out


def sniff_mediapipe(path: Path, head: str) -> int:
    """Score: JSON with ``pose_landmarks`` / ``pose_world_landmarks``, or a CSV whose header
    has MediaPipe's columns."""
    start = head.lstrip()[:1]
    if start == "{":
        return 85 if '"pose_landmarks"' in head or '"pose_world_landmarks"' in head else 0
    first = head.split("\n", 1)[0].strip().lstrip("\ufeff")
    cols = {c.strip() for c in first.split(",")}
    return 85 if {"frame", "landmark", "x", "y"} <= cols else 0


register_format(
    "mediapipe", read_mediapipe, None, (".json", ".csv"), sniff_mediapipe,
    description="MediaPipe Pose landmarks (JSON / CSV layout in docs/data.md)",
)  # fmt: skip
