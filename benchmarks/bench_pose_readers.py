"""Speed of the pose-estimator readers and of the TRC / C3D writers (run by hand).

    .venv/bin/python benchmarks/bench_pose_readers.py               # 3000 frames
    .venv/bin/python benchmarks/bench_pose_readers.py --frames 9000

Files are written in a temporary folder the way the tools write them: an OpenPose JSON
folder (one ``*_keypoints.json`` per frame, two unlabelled people, BODY_25, face and hand
arrays empty), a MediaPipe JSON and its long CSV (one person, image and world landmarks),
an Azure Kinect ``offline_processor`` JSON (two bodies, 32 joints) and a TRC / C3D of 40
markers. Prints the best of ``--repeats`` wall-clock times and frames per second.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

import tobitkf as tk
from tobitkf.skeleton.topology import AZURE_KINECT_JOINTS, MEDIAPIPE_POSE_JOINTS, Topology


def best(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def openpose_folder(folder: Path, T: int, rng) -> None:
    folder.mkdir()
    empty = ",".join(
        f'"{k}":[]'
        for k in ("face_keypoints_2d", "hand_left_keypoints_2d", "hand_right_keypoints_2d")
    )
    for t in range(T):
        people = []
        for cx in (300.0, 900.0):
            kp = np.column_stack([cx + rng.normal(0, 40, (25, 2)), rng.uniform(0, 1, 25)])
            flat = ",".join(f"{v:g}" for v in kp.ravel())
            people.append(f'{{"person_id":[-1],"pose_keypoints_2d":[{flat}],{empty}}}')
        text = '{"version":1.3,"people":[' + ",".join(people) + "]}"
        (folder / f"v_{t:012d}_keypoints.json").write_text(text)


def mediapipe_files(folder: Path, T: int, rng) -> tuple[Path, Path]:
    frames, rows = [], ["frame,timestamp_ms,pose,landmark,x,y,z,visibility,world_x,world_y,world_z"]
    for t in range(T):
        im = rng.uniform(0, 1, (33, 4))
        w = rng.normal(0, 0.3, (33, 3))
        frames.append(
            {
                "timestamp_ms": 33 * t,
                "pose_landmarks": [
                    [dict(zip(("x", "y", "z", "visibility"), map(float, r))) for r in im]
                ],
                "pose_world_landmarks": [[dict(zip("xyz", map(float, r))) for r in w]],
            }
        )
        for j in range(33):
            vals = ",".join(repr(float(v)) for v in (*im[j], *w[j]))
            rows.append(f"{t},{33 * t},0,{MEDIAPIPE_POSE_JOINTS[j]},{vals}")
    js, cs = folder / "mp.json", folder / "mp.csv"
    js.write_text(json.dumps({"fps": 30, "frames": frames}))
    cs.write_text("\n".join(rows) + "\n")
    return js, cs


def azure_file(folder: Path, T: int, rng) -> Path:
    frames = []
    for t in range(T):
        bodies = [
            {
                "body_id": b,
                "joint_orientations": rng.normal(size=(32, 4)).astype(np.float32).tolist(),
                "joint_positions": rng.normal(0, 500, (32, 3)).astype(np.float32).tolist(),
            }
            for b in (1, 2)
        ]
        frames.append(
            {"bodies": bodies, "frame_id": t, "num_bodies": 2, "timestamp_usec": 33333 * t}
        )
    doc = {"frames": frames, "joint_names": list(AZURE_KINECT_JOINTS), "k4abt_sdk_version": "1"}
    p = folder / "azure.json"
    p.write_text(json.dumps(doc, indent=4, sort_keys=True))
    return p


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=3000)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    T, R = args.frames, args.repeats
    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        openpose_folder(d / "op", T, rng)
        js, cs = mediapipe_files(d, T, rng)
        az = azure_file(d, T, rng)
        markers = tk.SkeletonSequence(
            rng.normal(size=(T, 40, 3)), Topology.from_names([f"M{i}" for i in range(40)]), fps=100
        )
        cases = [
            ("openpose folder, 2 people (read)", lambda: tk.load(d / "op")),
            ("mediapipe JSON (read)", lambda: tk.load(js)),
            ("mediapipe CSV (read)", lambda: tk.load(cs)),
            ("azure kinect JSON, 2 bodies (read)", lambda: tk.load(az)),
            ("TRC, 40 markers (write)", lambda: tk.save(markers, d / "m.trc")),
            ("TRC, 40 markers (read)", lambda: tk.load(d / "m.trc")),
            ("C3D, 40 markers (write)", lambda: tk.save(markers, d / "m.c3d")),
            ("C3D, 40 markers (read)", lambda: tk.load(d / "m.c3d")),
        ]
        print(f"{T} frames, best of {R}")
        print(f"{'case':<40} {'seconds':>9} {'frames/s':>10}")
        for name, fn in cases:
            fn()  # warm (and writes the file the next read uses)
            s = best(fn, R)
            print(f"{name:<40} {s:>9.3f} {T / s:>10.0f}")


if __name__ == "__main__":
    main()
