"""Rotations and forward kinematics shared by the hierarchy readers (BVH, UI-PRMD Kinect)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["axis_rotation", "forward_kinematics"]


def axis_rotation(axis: int, deg: np.ndarray) -> np.ndarray:
    """Right-handed rotation by ``deg`` degrees about axis 0 (x), 1 (y) or 2 (z).

    Returns
    -------
    ndarray, shape (*deg.shape, 3, 3)
    """
    a = np.deg2rad(np.asarray(deg, dtype=float))
    c, s = np.cos(a), np.sin(a)
    R = np.zeros((*a.shape, 3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[..., axis, axis] = 1.0
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., i, j] = -s
    R[..., j, i] = s
    return R


def forward_kinematics(
    local_rot: np.ndarray, local_offset: np.ndarray, parents: Sequence[int]
) -> tuple[np.ndarray, np.ndarray]:
    """Global rotations and positions of a joint tree.

    A root (parent -1) has ``R = local_rot`` and ``p = local_offset``; a joint j with
    parent p has ``R_j = R_p · local_rot_j`` and ``p_j = p_p + R_p · local_offset_j``.

    Parameters
    ----------
    local_rot : ndarray, shape (T, J, 3, 3)
    local_offset : ndarray, shape (T, J, 3)
    parents : sequence of int, length J
        Parent index per joint; every parent precedes its child.

    Returns
    -------
    rot : ndarray, shape (T, J, 3, 3)
    pos : ndarray, shape (T, J, 3)
    """
    rot = np.empty_like(local_rot)
    pos = np.empty_like(local_offset)
    for j, p in enumerate(parents):
        if p < 0:
            rot[:, j] = local_rot[:, j]
            pos[:, j] = local_offset[:, j]
        else:
            rot[:, j] = rot[:, p] @ local_rot[:, j]
            pos[:, j] = pos[:, p] + np.einsum("tab,tb->ta", rot[:, p], local_offset[:, j])
    return rot, pos
