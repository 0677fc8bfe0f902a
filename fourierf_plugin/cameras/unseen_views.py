"""Virtual cameras between the training cameras and small pixel patches of them (RegNeRF's unseen views).

Few-shot geometry goes wrong where no photo looks: between the views. RegNeRF regularises patches rendered from poses
no image was taken at; here such a pose lies on the segment between two random training cameras (a little beyond its
ends), its rotation the nearest rotation to the blend of theirs, so a forward-facing capture gets views between its
photos and an object gets views that still look at it.
"""

from __future__ import annotations

import torch
from torch import Tensor

from fourierf_plugin.cameras.cameras import Cameras, pinhole_directions


def nearest_rotation(matrices: Tensor) -> Tensor:
    """The rotation [..., 3, 3] nearest each matrix in the Frobenius norm (polar decomposition, det +1)."""
    u, _, vh = torch.linalg.svd(matrices)
    flip = torch.ones_like(matrices[..., 0, :])
    flip[..., -1] = torch.sign(torch.linalg.det(u @ vh))
    return (u * flip.unsqueeze(-2)) @ vh


def blended_poses(camera_to_worlds: Tensor, first: Tensor, second: Tensor, t: Tensor) -> Tensor:
    """Poses [P, 3, 4] a share ``t`` [P] of the way from camera ``first`` [P] to ``second`` [P].

    Centres move on the straight line; rotations are the nearest rotation to the linear blend (exact at t = 0 and 1,
    and between cameras that look roughly the same way, as few-shot captures do)."""
    a, b = camera_to_worlds[first], camera_to_worlds[second]
    blend = a + t.view(-1, 1, 1) * (b - a)
    return torch.cat([nearest_rotation(blend[:, :, :3]), blend[:, :, 3:]], dim=-1)


def random_poses(camera_to_worlds: Tensor, count: int, generator: torch.Generator, overshoot: float = 0.25) -> Tensor:
    """``count`` poses [count, 3, 4] between random pairs of the cameras, t ~ U(-overshoot, 1 + overshoot)."""
    n = camera_to_worlds.shape[0]
    device = camera_to_worlds.device
    first = torch.randint(n, (count,), generator=generator, device=device)
    second = torch.randint(n, (count,), generator=generator, device=device)
    t = torch.rand(count, generator=generator, device=device) * (1.0 + 2.0 * overshoot) - overshoot
    return blended_poses(camera_to_worlds, first, second, t.to(camera_to_worlds.dtype))


def patch_rays(
    cameras: Cameras, poses: Tensor, corners: Tensor, size: int, normalize: bool = True
) -> tuple[Tensor, Tensor]:
    """Rays [P * size², 3] through the ``size × size`` pixel centres from ``corners`` [P, 2] (u, v of the top-left
    pixel), row-major per patch, of pinhole cameras at ``poses`` [P, 3, 4] with camera 0's intrinsics.

    The same rays ``Cameras.generate_rays`` gives those pixels of a pinhole camera at such a pose: unit directions
    when ``normalize``, else z = -1 in the camera frame (what NDC expects)."""
    dtype, device = poses.dtype, poses.device
    steps = torch.arange(size, dtype=dtype, device=device)
    v = corners[:, 1:2, None].to(dtype) + steps.view(1, size, 1)  # [P, size, 1]
    u = corners[:, 0:1, None].to(dtype) + steps.view(1, 1, size)  # [P, 1, size]
    x = ((u + 0.5 - float(cameras.cx[0])) / float(cameras.fx[0])).expand(-1, size, size).reshape(len(poses), -1)
    y = ((v + 0.5 - float(cameras.cy[0])) / float(cameras.fy[0])).expand(-1, size, size).reshape(len(poses), -1)
    directions = pinhole_directions(x, y, poses[:, :, :3], normalize)
    origins = poses[:, None, :, 3].expand_as(directions)
    return origins.reshape(-1, 3).contiguous(), directions.reshape(-1, 3)


def random_corners(cameras: Cameras, count: int, size: int, generator: torch.Generator) -> Tensor:
    """Top-left pixels [count, 2] (u, v) of ``size × size`` patches that fit inside the image."""
    if size > min(cameras.width, cameras.height):
        raise ValueError(f"a {size}×{size} patch does not fit {cameras.width}×{cameras.height} images")
    device = generator.device
    u = torch.randint(cameras.width - size + 1, (count,), generator=generator, device=device)
    v = torch.randint(cameras.height - size + 1, (count,), generator=generator, device=device)
    return torch.stack([u, v], dim=-1)
