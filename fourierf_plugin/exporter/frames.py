"""Which coordinates an exported mesh is written in, and the map from the field's grid to them.

A field is sampled in its own coordinates: the run's normalised frame, normalised device coordinates (NDC) for a
forward-facing run, contracted coordinates for an unbounded one. A mesh is taken back to the normalised metric frame
(NDC or the contraction undone), then to the capture's own frame (the COLMAP model's or the ``transforms.json``'s)
with the inverse of the parser's normalisation, read from the run's ``dataparser_transforms.json``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import torch
import trimesh

from fourierf_plugin.data.dataparser_transforms import FILE_NAME, DataparserTransform, NdcFrame, RunFrame
from fourierf_plugin.model_components.ray_sampling import uncontract

Frame = Literal["capture", "normalised", "field"]
Space = Literal["capture", "normalised", "ndc", "contracted"]

NDC_NOTE = (
    "mesh is in NDC space: x, y in [-1, 1] are screen coordinates of the reference camera, z = -1 is the near "
    "plane and z = 1 is infinity (not metric world units)"
)
CONTRACTED_NOTE = (
    "mesh is in contracted coordinates: the inner cube [-1, 1]³ is the run's normalised frame, the space beyond it "
    "squeezed into [-2, 2]³"
)
NORMALISED_NOTE = "mesh is in the run's normalised frame (the poses the model trained on), not the capture's"
CONTRACTED_EDGE = 2.0 - 1e-4
"""Contracted points this close to the grid's outer face map back to (nearly) infinitely far: left out."""


@dataclass(frozen=True)
class MeshFrame:
    """Where a mesh's vertices go: the field's coordinates are mapped to ``space``; ``note`` says so in a line."""

    space: Space
    note: str
    ray_space: str = "euclidean"
    ndc: NdcFrame | None = None
    transform: DataparserTransform | None = None
    far: float | None = None
    """Metric distance (normalised frame) beyond which mapped-back geometry is left out; None keeps it all."""


def field_frame(ray_space: str) -> MeshFrame:
    """The field's own coordinates (what the trainer's and the viewer's meshes are written in)."""
    if ray_space == "ndc":
        return MeshFrame("ndc", NDC_NOTE, ray_space)
    if ray_space == "contracted":
        return MeshFrame("contracted", CONTRACTED_NOTE, ray_space)
    return MeshFrame("normalised", NORMALISED_NOTE, ray_space)


def resolve_frame(requested: Frame, ray_space: str, recorded: RunFrame | None, far: float | None = None) -> MeshFrame:
    """The frame an export can honour for ``requested``, with a note that says which it is and, when it is not the
    one asked for, why (a run without ``dataparser_transforms.json``)."""
    if requested == "field":
        return field_frame(ray_space)
    missing = f"this run has no {FILE_NAME} (it was trained before runs recorded their frame)"
    ndc = None
    if ray_space == "ndc":
        if recorded is None or recorded.ndc is None:
            return MeshFrame("ndc", f"{NDC_NOTE}; {missing}, so NDC cannot be undone", ray_space)
        ndc = recorded.ndc
        far = ndc.far
    if requested == "normalised":
        return MeshFrame("normalised", NORMALISED_NOTE, ray_space, ndc, None, far)
    if recorded is None:
        return MeshFrame("normalised", f"{NORMALISED_NOTE}: {missing}", ray_space, ndc, None, far)
    note = f"mesh is in the capture's frame (the parser's normalisation undone with {recorded.path})"
    return MeshFrame("capture", note, ray_space, ndc, recorded.transform, far)


def _metric(vertices: np.ndarray, frame: MeshFrame) -> tuple[np.ndarray, np.ndarray, bool]:
    """Field coordinates -> the normalised metric frame: (points, which are kept, whether the map mirrors)."""
    if frame.ray_space == "ndc":
        assert frame.ndc is not None
        keep = vertices[:, 2] < 1.0
        points = frame.ndc.to_metric(np.where(keep[:, None], vertices, 0.0))
        distance = -points[:, 2]  # depth in front of the reference camera
        return points, keep & (distance > 0), True  # NDC's map reverses orientation: faces are turned back
    if frame.ray_space == "contracted":
        keep = np.abs(vertices).max(axis=1) < CONTRACTED_EDGE
        points = uncontract(torch.from_numpy(np.where(keep[:, None], vertices, 0.0))).numpy()
        return points, keep, False
    return vertices, np.ones(len(vertices), dtype=bool), False


def map_mesh(mesh: trimesh.Trimesh, frame: MeshFrame) -> tuple[trimesh.Trimesh, int]:
    """``mesh`` (field coordinates) in ``frame``'s space, and how many faces were left out because they reach
    (nearly) infinitely far or beyond ``frame.far``."""
    if frame.space in ("ndc", "contracted") or len(mesh.vertices) == 0:
        return mesh, 0
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    points, keep, mirrored = _metric(vertices, frame)
    if frame.far is not None:
        keep &= np.linalg.norm(points, axis=1) <= frame.far
    keep &= np.isfinite(points).all(axis=1)
    if frame.transform is not None:
        points = frame.transform.to_capture(points)
        mirrored ^= bool(np.linalg.det(frame.transform.transform[:, :3]) < 0)
    out = mesh.copy()
    if mirrored:
        out.invert()
    out.vertices = np.where(keep[:, None], points, 0.0)
    faces_kept = keep[np.asarray(out.faces)].all(axis=1)
    dropped = int((~faces_kept).sum())
    if dropped:
        out.update_faces(faces_kept)
        out.remove_unreferenced_vertices()
    return out, dropped
