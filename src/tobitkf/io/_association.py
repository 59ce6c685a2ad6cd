"""Identity of unlabelled detections across frames (pose estimators without tracking).

OpenPose (``person_id`` -1) and MediaPipe Pose write, per frame, a list of detected people
in no stable order. :func:`associate` links them into tracks frame by frame: the cost of
giving detection ``d`` to track ``k`` is the mean distance between the keypoints present
in both (the track's last observed position of each keypoint); the assignment minimises
the total cost (Hungarian algorithm, :func:`scipy.optimize.linear_sum_assignment`). A
pair farther apart than the gate, or with no keypoint in common, is not linked, and the
detection starts a new track.

The default gate is the size of the track's body: the diagonal of the bounding box of its
last observed keypoints (a person does not move by their own size between two frames).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["associate"]


def _distance(track: np.ndarray, det: np.ndarray) -> float:
    """Mean keypoint distance over the keypoints present in both (inf if none)."""
    d = np.linalg.norm(track - det, axis=-1)
    ok = np.isfinite(d)
    return float(d[ok].mean()) if ok.any() else np.inf


def _size(pose: np.ndarray) -> float:
    ok = np.isfinite(pose).all(axis=-1)
    if ok.sum() < 2:
        return 0.0
    p = pose[ok]
    return float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))


def associate(
    frames: Sequence[Sequence[np.ndarray]], max_distance: float | None = None
) -> list[dict[int, int]]:
    """Link per-frame detections into tracks.

    Parameters
    ----------
    frames : sequence over frames of sequences of (J, D) arrays
        The detections of each frame (NaN for a missing keypoint).
    max_distance : float, optional
        Largest mean keypoint distance (in the positions' units) at which a detection
        continues a track; by default the track's body size (module docstring).

    Returns
    -------
    list of dict
        One per track, in order of first appearance: ``{frame index: detection index}``.
    """
    tracks: list[dict[int, int]] = []
    last: list[np.ndarray] = []  # last observed position of each keypoint, per track
    # scipy.optimize takes 0.4 s to import: only when a file has people to associate
    from scipy.optimize import linear_sum_assignment

    for t, dets in enumerate(frames):
        n_det = len(dets)
        assigned: dict[int, int] = {}
        if tracks and n_det:
            cost = np.array([[_distance(last[k], d) for d in dets] for k in range(len(tracks))])
            gate = np.array(
                [
                    _size(last[k]) if max_distance is None else max_distance
                    for k in range(len(tracks))
                ]
            )
            allowed = np.isfinite(cost) & (cost <= gate[:, None])
            big = (np.nanmax(np.where(allowed, cost, 0.0)) + 1.0) * (n_det + len(tracks) + 1)
            rows, cols = linear_sum_assignment(np.where(allowed, cost, big))
            for k, d in zip(rows, cols):
                if allowed[k, d]:
                    assigned[int(d)] = int(k)
        for d in range(n_det):
            k = assigned.get(d)
            if k is None:
                tracks.append({})
                last.append(np.full_like(np.asarray(dets[d], dtype=float), np.nan))
                k = len(tracks) - 1
            tracks[k][t] = d
            pose = np.asarray(dets[d], dtype=float)
            seen = np.isfinite(pose).all(axis=-1)
            last[k][seen] = pose[seen]
    return tracks
