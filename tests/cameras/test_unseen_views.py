"""Unseen views: poses between the training cameras and the rays of small patches of them.

The patch rays must be exactly the rays ``Cameras.generate_rays`` gives those pixels (a patch of a training pose is a
patch of its photo), blended poses must be proper rotations that end on the two cameras, and patches must fit the
image.
"""

from __future__ import annotations

import pytest
import torch

from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.cameras.unseen_views import (
    blended_poses,
    nearest_rotation,
    patch_rays,
    random_corners,
    random_poses,
)
from tests.cameras.test_cameras import HEIGHT, WIDTH, make_cameras, rotation


def is_rotation(r: torch.Tensor) -> bool:
    eye = torch.eye(3, dtype=r.dtype).expand_as(r)
    return torch.allclose(r.transpose(-1, -2) @ r, eye, atol=1e-10) and bool((torch.linalg.det(r) > 0).all())


def test_nearest_rotation_keeps_rotations_and_repairs_others() -> None:
    rotations = torch.stack([rotation(i) for i in range(4)])
    torch.testing.assert_close(nearest_rotation(rotations), rotations, rtol=0, atol=1e-12)
    g = torch.Generator().manual_seed(3)
    messy = torch.randn(16, 3, 3, generator=g, dtype=torch.float64)
    messy[0] = torch.diag(torch.tensor([1.0, 1.0, -1.0], dtype=torch.float64))  # a reflection: det -1
    assert is_rotation(nearest_rotation(messy))


def test_blended_poses_end_on_the_two_cameras() -> None:
    c2w = make_cameras(n=3).camera_to_worlds
    first, second = torch.tensor([0, 2, 1]), torch.tensor([1, 0, 1])
    torch.testing.assert_close(blended_poses(c2w, first, second, torch.zeros(3)), c2w[first], rtol=0, atol=1e-12)
    torch.testing.assert_close(blended_poses(c2w, first, second, torch.ones(3)), c2w[second], rtol=0, atol=1e-12)
    half = blended_poses(c2w, first, second, torch.full((3,), 0.5, dtype=torch.float64))
    torch.testing.assert_close(half[:, :, 3], (c2w[first, :, 3] + c2w[second, :, 3]) / 2)
    assert is_rotation(half[:, :, :3])


def test_random_poses_lie_on_the_segments_between_cameras() -> None:
    """Two cameras: every centre is a + t (b - a) with t within the overshoot, every rotation proper."""
    c2w = make_cameras(n=2).camera_to_worlds
    poses = random_poses(c2w, 64, torch.Generator().manual_seed(0), overshoot=0.25)
    a, b = c2w[0, :, 3], c2w[1, :, 3]
    offset = poses[:, :, 3] - a
    t = offset @ (b - a) / (b - a).square().sum()
    torch.testing.assert_close(offset, t[:, None] * (b - a), rtol=0, atol=1e-12)
    assert float(t.min()) >= -0.25 and float(t.max()) <= 1.25
    assert is_rotation(poses[:, :, :3])


@pytest.mark.parametrize("normalize", [True, False])
def test_patch_rays_are_the_cameras_rays_of_those_pixels(normalize: bool) -> None:
    cams = make_cameras(n=2)
    corners = torch.tensor([[0, 0], [WIDTH - 5, HEIGHT - 5], [17, 9]])
    which = torch.tensor([0, 1, 1])
    origins, directions = patch_rays(cams, cams.camera_to_worlds[which], corners, 5, normalize=normalize)
    assert origins.shape == directions.shape == (3 * 25, 3)
    for k, (camera, (u, v)) in enumerate(zip(which.tolist(), corners.tolist(), strict=True)):
        o, d = cams.generate_rays(camera, normalize=normalize)
        rows = torch.arange(v, v + 5)[:, None] * WIDTH + torch.arange(u, u + 5)[None, :]
        torch.testing.assert_close(directions[k * 25 : (k + 1) * 25], d[rows.reshape(-1)], rtol=0, atol=1e-12)
        torch.testing.assert_close(origins[k * 25 : (k + 1) * 25], o[rows.reshape(-1)], rtol=0, atol=0)


def test_random_corners_fit_the_image_and_reach_its_far_corner() -> None:
    cams = make_cameras(n=1)
    corners = random_corners(cams, 4000, 8, torch.Generator().manual_seed(0))
    assert int(corners[:, 0].min()) == 0 and int(corners[:, 0].max()) == WIDTH - 8
    assert int(corners[:, 1].min()) == 0 and int(corners[:, 1].max()) == HEIGHT - 8


def test_a_patch_larger_than_the_image_is_refused() -> None:
    small = Cameras(torch.eye(4)[:3].unsqueeze(0), *(torch.ones(1),) * 4, width=6, height=4)
    with pytest.raises(ValueError, match="5×5 patch does not fit 6×4"):
        random_corners(small, 1, 5, torch.Generator())
