"""Similarity alignment of two sets of points (Umeyama 1991), and pose errors of cameras after it.

Why: structure-from-motion recovers a scene only up to a similarity (scale, rotation, translation), so recovered
cameras are compared with reference ones after the best such alignment of their centres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Similarity:
    """x -> scale * rotation @ x + translation."""

    scale: float
    rotation: np.ndarray  # [3, 3], det +1
    translation: np.ndarray  # [3]

    def apply(self, points: np.ndarray) -> np.ndarray:
        return self.scale * np.asarray(points) @ self.rotation.T + self.translation


def umeyama(source: np.ndarray, target: np.ndarray) -> Similarity:
    """The least-squares similarity taking ``source`` [N, 3] onto ``target`` [N, 3] (a proper rotation, never a
    reflection). Needs at least three points that do not all lie on one line."""
    src = np.asarray(source, dtype=np.float64)
    dst = np.asarray(target, dtype=np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3:
        raise ValueError(f"umeyama needs two [N, 3] arrays of the same shape, got {src.shape} and {dst.shape}")
    if src.shape[0] < 3:
        raise ValueError(f"umeyama needs at least 3 point pairs, got {src.shape[0]}")
    mu_src, mu_dst = src.mean(axis=0), dst.mean(axis=0)
    src_c, dst_c = src - mu_src, dst - mu_dst
    covariance = dst_c.T @ src_c / len(src)
    u, singular, vt = np.linalg.svd(covariance)
    if singular[1] <= 1e-12 * max(singular[0], 1e-300):
        raise ValueError("umeyama needs points that do not all lie on one line")
    sign = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        sign[2, 2] = -1.0
    rotation = u @ sign @ vt
    variance = (src_c**2).sum() / len(src)
    scale = float(np.trace(np.diag(singular) @ sign) / variance)
    return Similarity(scale, rotation, mu_dst - scale * rotation @ mu_src)


def rotation_angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle in degrees of the rotation between ``a`` and ``b`` ([..., 3, 3] each)."""
    relative = np.asarray(a) @ np.swapaxes(np.asarray(b), -1, -2)
    cos = (np.trace(relative, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


@dataclass(frozen=True)
class PoseErrors:
    """Per-camera errors of estimated poses after aligning their centres to the reference ones."""

    similarity: Similarity
    rotation_deg: np.ndarray  # [N]
    centre_error: np.ndarray  # [N], in the reference's units
    reference_extent: float  # the largest distance between two reference camera centres

    @property
    def centre_error_percent(self) -> np.ndarray:
        return 100.0 * self.centre_error / self.reference_extent


def pose_errors(estimated_c2w: np.ndarray, reference_c2w: np.ndarray) -> PoseErrors:
    """Align ``estimated_c2w`` [N, 4, 4] to ``reference_c2w`` (same cameras, same camera-axis convention) by the
    similarity of their centres; rotation errors compare the aligned camera orientations."""
    est = np.asarray(estimated_c2w, dtype=np.float64)
    ref = np.asarray(reference_c2w, dtype=np.float64)
    sim = umeyama(est[:, :3, 3], ref[:, :3, 3])
    aligned_centres = sim.apply(est[:, :3, 3])
    aligned_rotations = sim.rotation @ est[:, :3, :3]
    centres = ref[:, :3, 3]
    extent = float(np.max(np.linalg.norm(centres[:, None] - centres[None], axis=-1)))
    return PoseErrors(
        similarity=sim,
        rotation_deg=rotation_angle_deg(aligned_rotations, ref[:, :3, :3]),
        centre_error=np.linalg.norm(aligned_centres - centres, axis=1),
        reference_extent=extent,
    )
