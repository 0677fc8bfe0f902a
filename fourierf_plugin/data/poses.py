"""Camera poses read from a dataset: the check that a camera-to-world rotates (not squashes or mirrors), and the
pure pose geometry the parsers normalise scenes with (recentring, orientation, the cameras' focus).

Why the check runs at parse time: a zero or singular matrix otherwise passes every shape check and ends in NaN rays,
a crash in the first training step far from the file that caused it.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import torch

from fourierf_plugin.cameras.camera_paths import average_pose

ROTATION_TOLERANCE = 1e-2
"""How far R^T R may be from the identity (and det R from 1): room for rounded JSON, none for a scaled or zero R."""


def rotation_problem(c2w: np.ndarray) -> str | None:
    """Why the 3x3 rotation of a camera-to-world ([3, 4] or [4, 4]) is not a rotation, or None when it is one."""
    r = np.asarray(c2w, dtype=np.float64)[:3, :3]
    det = float(np.linalg.det(r))
    if abs(det) < 1e-9:
        return "its rotation is singular (a zero or degenerate matrix)"
    if det < 0:
        return f"its rotation mirrors (determinant {det:.3g})"
    error = float(np.abs(r.T @ r - np.eye(3)).max())
    if error > ROTATION_TOLERANCE or abs(det - 1.0) > ROTATION_TOLERANCE:
        return f"its rotation is not orthonormal (|R^T R - I| = {error:.3g}, determinant {det:.3g})"
    return None


def recenter_poses(c2w: np.ndarray) -> np.ndarray:
    """Express every [N, 3, 4] pose relative to the average pose (a rigid motion of the whole scene).

    LLFF's recentring: the average pose (mean centre, mean viewing and up axes) becomes the identity, so a
    forward-facing capture looks down -z from near the origin whatever world frame it was written in.
    """
    avg = np.eye(4)
    avg[:3] = average_pose(torch.from_numpy(np.ascontiguousarray(c2w))).double().numpy()
    homo = np.concatenate([c2w, np.broadcast_to(np.array([0, 0, 0, 1.0]), (c2w.shape[0], 1, 4))], axis=1)
    return (np.linalg.inv(avg) @ homo)[:, :3]


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation [3, 3] taking the direction ``a`` onto ``b`` (a half turn about a perpendicular axis
    when they are opposite)."""
    a = np.asarray(a, dtype=np.float64) / np.linalg.norm(a)
    b = np.asarray(b, dtype=np.float64) / np.linalg.norm(b)
    axis = np.cross(a, b)
    sin, cos = float(np.linalg.norm(axis)), float(a @ b)
    if sin < 1e-12:
        if cos > 0:
            return np.eye(3)
        perpendicular = np.cross(a, np.eye(3)[int(np.abs(a).argmin())])
        perpendicular /= np.linalg.norm(perpendicular)
        return 2.0 * np.outer(perpendicular, perpendicular) - np.eye(3)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]]) / sin
    return np.eye(3) + sin * k + (1.0 - cos) * (k @ k)


Orientation = Literal["up", "pca", "none"]


def orientation_rotation(c2w: np.ndarray, method: Orientation) -> np.ndarray:
    """The world rotation [3, 3] that turns a capture upright, as nerfstudio orients poses.

    ``up``: the cameras' mean up (y) axis becomes +z. ``pca``: the axis along which the camera centres vary least
    becomes z (pointing to the side of the mean camera up), the most varying one x. ``none``: the identity.
    """
    c2w = np.asarray(c2w, dtype=np.float64)
    if method == "none":
        return np.eye(3)
    up = c2w[:, :3, 1].mean(axis=0)
    if method == "up":
        return np.eye(3) if np.linalg.norm(up) < 1e-9 else rotation_between(up, np.array([0.0, 0.0, 1.0]))
    if method != "pca":
        raise ValueError(f"unknown orientation method {method!r}")
    centres = c2w[:, :3, 3] - c2w[:, :3, 3].mean(axis=0)
    _, vectors = np.linalg.eigh(centres.T @ centres)  # ascending eigenvalues
    rotation = vectors[:, ::-1].T.copy()  # rows: most varying -> x, least -> z
    if np.linalg.det(rotation) < 0:
        rotation[2] *= -1.0
    if (rotation @ up)[2] < 0:  # a half turn about x keeps it proper and puts the cameras' up on +z's side
        rotation[1:] *= -1.0
    return rotation


def focus_point(c2w: np.ndarray, min_spread: float = 1e-2) -> np.ndarray | None:
    """The point nearest to every camera's optical axis (least squares), or None when the axes do not converge.

    Why None: nearly parallel axes (a forward-facing rig) make the solve ill-conditioned, and a "focus" behind
    some camera is not something the cameras look at. ``min_spread`` bounds the mean sin² of the axes' spread.
    """
    c2w = np.asarray(c2w, dtype=np.float64)
    views = -c2w[:, :3, 2] / np.linalg.norm(c2w[:, :3, 2], axis=1, keepdims=True)
    centres = c2w[:, :3, 3]
    projectors = np.eye(3)[None] - views[:, :, None] * views[:, None, :]  # [N, 3, 3]: off-axis part of a vector
    lhs = projectors.sum(axis=0)
    if np.linalg.eigvalsh(lhs)[0] < min_spread * len(c2w):
        return None
    focus = np.linalg.solve(lhs, (projectors @ centres[:, :, None]).sum(axis=0))[:, 0]
    if (((focus - centres) * views).sum(axis=1) <= 0).any():
        return None
    return focus
