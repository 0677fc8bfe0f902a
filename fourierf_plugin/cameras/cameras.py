"""Pinhole cameras (OpenGL convention) and the rays through their pixel centres."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor


@dataclass
class Cameras:
    """A set of pinhole cameras sharing one image size.

    ``camera_to_worlds`` is [N, 3, 4] in the OpenGL convention used by NeRF-synthetic and LLFF after reordering:
    x right, y up, the camera looking down -z.
    """

    camera_to_worlds: Tensor  # [N, 3, 4] float32
    fx: Tensor  # [N]
    fy: Tensor  # [N]
    cx: Tensor  # [N]
    cy: Tensor  # [N]
    width: int
    height: int

    def __len__(self) -> int:
        return int(self.camera_to_worlds.shape[0])

    @property
    def centers(self) -> Tensor:
        """Camera centres in world space, [N, 3]."""
        return self.camera_to_worlds[:, :, 3]

    def subset(self, indices: list[int]) -> Cameras:
        idx = torch.as_tensor(indices, dtype=torch.long)
        return Cameras(
            self.camera_to_worlds[idx], self.fx[idx], self.fy[idx], self.cx[idx], self.cy[idx], self.width, self.height
        )

    def generate_rays(self, index: int, normalize: bool = True) -> tuple[Tensor, Tensor]:
        """Origins and directions [H*W, 3] through the pixel centres of camera ``index``, row-major.

        Directions are unit length when ``normalize`` so that ray parameters are metric distances.
        """
        v, u = torch.meshgrid(
            torch.arange(self.height, dtype=torch.float32),
            torch.arange(self.width, dtype=torch.float32),
            indexing="ij",
        )
        x = (u + 0.5 - self.cx[index]) / self.fx[index]
        y = -(v + 0.5 - self.cy[index]) / self.fy[index]
        dirs_cam = torch.stack([x, y, -torch.ones_like(x)], dim=-1).reshape(-1, 3)
        c2w = self.camera_to_worlds[index]
        directions = dirs_cam @ c2w[:, :3].T
        if normalize:
            directions = directions / directions.norm(dim=-1, keepdim=True)
        origins = c2w[:, 3].expand_as(directions).contiguous()
        return origins, directions
