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
* Timestamps: ``timestamp_ms`` × 1e-3 when at least two frames have one; a frame
  without (a CSV frame with no rows: nobody detected) gets its time from its frame
  number, between its neighbours' (beyond the first or last stamp, at their median
  step); fps from the option or the file.
"""

from __future__ import annotations

import csv
import io
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
    decode,
    parse_rows,
    plausible_only,
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
    values = [
        [as_object(path, lm, f"{where}[{j}]").get(k) for k in _FIELDS] for j, lm in enumerate(items)
    ]
    return number_array(path, values, where, (N, 5), allow_null=True)


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
    times = _frame_times(np.array([np.nan if t is None else t for t in stamps], dtype=float))
    extra = {k: doc[k] for k in ("fps", "image_size") if k in doc}
    return frames, times, extra


def _frame_times(ms: np.ndarray) -> np.ndarray | None:
    """Seconds of each frame from its ``timestamp_ms`` (NaN where it has none): a frame
    without is placed by its frame number between the stamped ones around it (beyond
    the first or last, at their median step per frame); None with fewer than two stamps
    (one frame: its own)."""
    known = np.flatnonzero(~np.isnan(ms))
    if known.size == ms.size:
        return ms * 1e-3 if ms.size else None
    if known.size < 2:
        return None
    k = np.arange(ms.size)
    t = np.interp(k, known, ms[known])
    step = float(np.median(np.diff(ms[known]) / np.diff(known)))
    first, last = known[0], known[-1]
    t[:first] = ms[first] - (first - k[:first]) * step
    t[last + 1 :] = ms[last] + (k[last + 1 :] - last) * step
    return t * 1e-3


def _read_csv(path: Path) -> tuple[list[list[Person]], np.ndarray | None, dict[str, Any]]:
    text = decode(path, read_bytes(path))
    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        header = [h.strip() for h in next(reader)]
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
    numeric = [c for c in CSV_COLUMNS if c in col and c != "landmark"]
    idx = [col[c] for c in numeric]
    rows: list[str] = []
    names: list[str] = []
    lines: list[int] = []
    try:
        for row in reader:
            if not any(f.strip() for f in row):
                continue
            if len(row) != len(header):
                raise ReadError(
                    path, reader.line_num, f"expected {len(header)} fields, found {len(row)}"
                )
            rows.append(",".join(row[i] for i in idx))
            names.append(row[col["landmark"]].strip())
            lines.append(reader.line_num)
    except csv.Error as exc:
        raise ReadError(path, reader.line_num, f"invalid CSV ({exc})") from None
    if not rows:
        raise ReadError(path, None, "no landmark rows after the header")
    try:
        what = ", ".join(numeric)
        data = parse_rows(
            path, rows, lines, sep=",", ncols=len(numeric), what=what, allow_empty=True
        )
    except ReadError as exc:  # name the column: the fields counted are the numeric ones
        m = re.search(r"in field (\d+)", exc.reason)
        if m is None:
            raise
        column = numeric[int(m.group(1)) - 1]
        reason = exc.reason.replace(m.group(0), f"in column {column!r}")
        raise ReadError(path, exc.line, reason) from None
    v = {c: data[:, k] for k, c in enumerate(numeric)}
    frame = v["frame"]
    pose = v.get("pose", np.zeros(len(rows)))
    for what, a in (("frame", frame), ("pose", pose)):
        bad = ~((a >= 0) & (a < 2**31) & (a == np.round(a)))
        if bad.any():
            k = int(np.argmax(bad))
            raise ReadError(path, lines[k], f"expected a non-negative integer {what}")
    lm = np.empty(len(rows), dtype=np.int64)
    for k, name in enumerate(names):
        j = _INDEX.get(name)
        if j is None and name.isascii() and name.isdigit() and int(name) < N:
            j = int(name)
        if j is None:
            raise ReadError(path, lines[k], f"unknown MediaPipe Pose landmark {name[:40]!r}")
        lm[k] = j
    frame, pose = frame.astype(np.int64), pose.astype(np.int64)
    n_frames = int(frame.max()) + 1
    check_output_size(path, n_frames * 8 * N * 5 * 2, len(text), f"{n_frames} frames")
    key = (frame * 2**31 + pose) * N + lm
    order = np.argsort(key, kind="stable")
    dup = np.flatnonzero(np.diff(key[order]) == 0)
    if dup.size:
        k = int(order[dup[0] + 1])
        raise ReadError(
            path, lines[k], f"landmark {names[k]!r} twice in frame {frame[k]}, pose {pose[k]}"
        )
    times = None
    if "timestamp_ms" in v:
        ts = v["timestamp_ms"]
        per_frame = np.full(n_frames, np.nan)
        per_frame[frame] = ts
        clash = ~np.isnan(ts) & (ts != per_frame[frame]) | np.isnan(ts) & ~np.isnan(
            per_frame[frame]
        )
        if clash.any():
            k = int(np.argmax(clash))
            raise ReadError(path, lines[k], f"frame {frame[k]} has two timestamps")
        times = _frame_times(per_frame)
    image = np.full((len(rows), 5), np.nan)
    for f, c in enumerate(_FIELDS):
        if c in v:
            image[:, f] = v[c]
    has_world = any(f"world_{c}" in v for c in "xyz")
    world = np.full((len(rows), 5), np.nan)
    for f, c in enumerate("xyz"):
        if f"world_{c}" in v:
            world[:, f] = v[f"world_{c}"]
    world[:, 3:] = image[:, 3:]
    frames: list[list[Person]] = [[] for _ in range(n_frames)]
    group = frame * 2**31 + pose
    starts = np.flatnonzero(np.r_[True, np.diff(group[order]) != 0])
    for a, b in zip(starts, [*starts[1:], len(order)]):
        members = order[a:b]
        person = {"image": np.full((N, 5), np.nan)}
        person["image"][lm[members]] = image[members]
        if has_world:
            person["world"] = np.full((N, 5), np.nan)
            person["world"][lm[members]] = world[members]
        frames[int(frame[members[0]])].append(person)
    return frames, times, {}


def read_mediapipe(
    path: str | os.PathLike[str],
    landmarks: str = "auto",
    image_size: tuple[float, float] | None = None,
    fps: float | None = None,
    max_distance: float | None = None,
    implausible: str = "error",
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
    implausible : {"error", "missing"}
        What to do with a coordinate beyond the plausibility bound: raise a ReadError,
        or read the landmark as missing.
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
    near = "m" if key == "world" else None  # image landmarks: normalised, unknown unit
    tracks = associate(
        [[plausible_only(q[key][:, :2], near, implausible) for q in fr] for fr in frames],
        max_distance,
    )
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
        check_positions(p, pos, None, implausible, names=MEDIAPIPE_POSE_JOINTS, units=units)
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
    # above the generic CSV's score with a sidecar: the same results saved as pose.json
    # beside pose.csv look like a CSV with its sidecar to that sniffer
    return 95 if {"frame", "landmark", "x", "y"} <= cols else 0


register_format(
    "mediapipe", read_mediapipe, None, (".json", ".csv"), sniff_mediapipe,
    description="MediaPipe Pose landmarks (JSON / CSV layout in docs/data.md)",
)  # fmt: skip
