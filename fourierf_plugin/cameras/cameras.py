"""Cameras (OpenGL convention, pinhole or with lens distortion) and the rays through their pixel centres."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from fourierf_plugin.cameras.distortion import (
    DISTORTION_KEYS,
    check_camera_model,
    check_coefficients,
    has_distortion,
    undistorted_directions,
)


def pinhole_directions(x: Tensor, y: Tensor, rotation: Tensor, normalize: bool) -> Tensor:
    """World directions [..., N, 3] through OpenCV normalised coordinates ``x``, ``y`` [..., N] (y down) of cameras
    with ``rotation`` [..., 3, 3] (OpenGL axes, looking down -z): z = -1 in the camera frame, unit if ``normalize``."""
    dirs_cam = torch.stack([x, -y, -torch.ones_like(x)], dim=-1)
    directions = dirs_cam @ rotation.transpose(-1, -2)
    if normalize:
        directions = directions / directions.norm(dim=-1, keepdim=True)
    return directions


@dataclass
class Cameras:
    """A set of cameras sharing one image size and one camera model.

    ``camera_to_worlds`` is [N, 3, 4] in the OpenGL convention used by NeRF-synthetic and LLFF after reordering:
    x right, y up, the camera looking down -z. ``distortion`` holds each camera's lens coefficients in
    :data:`~fourierf_plugin.cameras.distortion.DISTORTION_KEYS` order for ``camera_model`` (see that module).
    """

    camera_to_worlds: Tensor  # [N, 3, 4] float32
    fx: Tensor  # [N]
    fy: Tensor  # [N]
    cx: Tensor  # [N]
    cy: Tensor  # [N]
    width: int
    height: int
    camera_model: str = "PINHOLE"  # PINHOLE, SIMPLE_PINHOLE, OPENCV or OPENCV_FISHEYE (one model per set)
    distortion: Tensor | None = None  # [N, 6] (k1, k2, k3, k4, p1, p2); None = no distortion

    def __post_init__(self) -> None:
        check_camera_model(self.camera_model)
        n = len(self)
        if self.distortion is not None and tuple(self.distortion.shape) != (n, len(DISTORTION_KEYS)):
            raise ValueError(
                f"distortion must be [{n}, {len(DISTORTION_KEYS)}] ({', '.join(DISTORTION_KEYS)} per camera), "
                f"got {tuple(self.distortion.shape)}"
            )
        if self.distortion is not None:
            check_coefficients(self.distortion, self.camera_model)

    def __len__(self) -> int:
        return int(self.camera_to_worlds.shape[0])

    @property
    def centers(self) -> Tensor:
        """Camera centres in world space, [N, 3]."""
        return self.camera_to_worlds[:, :, 3]

    def subset(self, indices: list[int]) -> Cameras:
        idx = torch.as_tensor(indices, dtype=torch.long)
        return Cameras(
            self.camera_to_worlds[idx],
            self.fx[idx],
            self.fy[idx],
            self.cx[idx],
            self.cy[idx],
            self.width,
            self.height,
            self.camera_model,
            None if self.distortion is None else self.distortion[idx],
        )

    def distortion_of(self, index: int) -> Tensor | None:
        """Camera ``index``'s coefficients [6], or None when it is an ideal pinhole (the fast path of rays)."""
        coeffs = None if self.distortion is None else self.distortion[index]
        if not has_distortion(coeffs, self.camera_model):
            return None
        return torch.zeros(len(DISTORTION_KEYS), dtype=torch.float64) if coeffs is None else coeffs

    def generate_rays(self, index: int, normalize: bool = True) -> tuple[Tensor, Tensor]:
        """Origins and directions [H*W, 3] through the pixel centres of camera ``index``, row-major.

        Directions are unit length when ``normalize`` so that ray parameters are metric distances; otherwise they
        have z = -1 in the camera frame (what NDC expects). A distorted camera's pixel centres are undistorted
        first (in float64), so each ray is the one the lens actually images onto that pixel. Rays come in the
        dtype of ``camera_to_worlds``.
        """
        c2w = self.camera_to_worlds[index]
        coeffs = self.distortion_of(index)
        if coeffs is None:  # the fast path: pinhole directions straight from the pixel grid
            x, y = self._normalized_pixel_centers(index, c2w.dtype)
            directions = pinhole_directions(x.reshape(-1), y.reshape(-1), c2w[:, :3], normalize)
        else:
            directions = self._distorted_directions(index, coeffs, normalize).to(c2w.dtype)
        origins = c2w[:, 3].expand_as(directions).contiguous()
        return origins, directions

    def _distorted_directions(self, index: int, coeffs: Tensor, normalize: bool) -> Tensor:
        """World directions [H*W, 3] (float64) of camera ``index``'s undistorted pixel centres."""
        xd, yd = self._normalized_pixel_centers(index, torch.float64)
        d = undistorted_directions(xd, yd, coeffs, self.camera_model).reshape(-1, 3)  # unit, OpenCV axes
        if not normalize:
            if bool((d[:, 2] <= 0).any()):
                raise ValueError(
                    f"camera {index} ({self.camera_model}) sees rays 90° or more off its axis, which cannot be "
                    "scaled to z = -1 (unnormalised / NDC rays); use normalized rays for such a wide lens"
                )
            d = d / d[:, 2:]
        dirs_cam = torch.stack([d[:, 0], -d[:, 1], -d[:, 2]], dim=-1)  # OpenCV -> OpenGL camera axes
        directions = dirs_cam @ self.camera_to_worlds[index, :, :3].to(torch.float64).T
        if normalize:  # the rotation may be orthonormal only to float32 precision
            directions = directions / directions.norm(dim=-1, keepdim=True)
        return directions

    def _normalized_pixel_centers(self, index: int, dtype: torch.dtype) -> tuple[Tensor, Tensor]:
        """OpenCV normalised coordinates [H, W] of the pixel centres: x = (u + 0.5 - cx) / fx, y down."""
        device = self.camera_to_worlds.device
        v, u = torch.meshgrid(
            torch.arange(self.height, dtype=dtype, device=device),
            torch.arange(self.width, dtype=dtype, device=device),
            indexing="ij",
        )
        x = (u + 0.5 - self.cx[index].to(dtype)) / self.fx[index].to(dtype)
        y = (v + 0.5 - self.cy[index].to(dtype)) / self.fy[index].to(dtype)
        return x, y
