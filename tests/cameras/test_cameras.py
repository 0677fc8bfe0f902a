"""Cameras: pinhole rays unchanged, distorted rays that project back onto their pixels, and input checks."""

from __future__ import annotations

import math

import pytest
import torch

from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.cameras.distortion import distort

WIDTH, HEIGHT, FX, FY, CX, CY = 64, 48, 50.0, 52.0, 31.2, 24.7
PHONE = (-0.12, 0.03, -0.004, 0.0, 1e-3, -5e-4)
FISHEYE = (0.05, -0.01, 0.002, -0.0005, 0.0, 0.0)


def rotation(seed: int) -> torch.Tensor:
    """A random rotation in float64 (QR of a Gaussian matrix, signs fixed so that det = +1)."""
    g = torch.Generator().manual_seed(seed)
    q, r = torch.linalg.qr(torch.randn(3, 3, generator=g, dtype=torch.float64))
    q = q * torch.sign(torch.diagonal(r))
    return q if torch.det(q) > 0 else -q


def make_cameras(
    model: str = "PINHOLE", coeffs: tuple[float, ...] | None = None, n: int = 2, dtype: torch.dtype = torch.float64
) -> Cameras:
    c2w = torch.stack([torch.cat([rotation(i), torch.tensor([[1.0], [-2.0], [0.5 * i]])], dim=1) for i in range(n)])

    def full(value: float) -> torch.Tensor:
        return torch.full((n,), value, dtype=dtype)

    distortion = None if coeffs is None else torch.tensor([coeffs] * n, dtype=dtype)
    return Cameras(c2w.to(dtype), full(FX), full(FY), full(CX), full(CY), WIDTH, HEIGHT, model, distortion)


def pixel_centres() -> tuple[torch.Tensor, torch.Tensor]:
    v, u = torch.meshgrid(
        torch.arange(HEIGHT, dtype=torch.float64), torch.arange(WIDTH, dtype=torch.float64), indexing="ij"
    )
    return (u + 0.5).reshape(-1), (v + 0.5).reshape(-1)


def project(cams: Cameras, index: int, directions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Pixel (u, v) where each world direction from the camera centre is imaged: pinhole projection, then the lens."""
    local = directions.double() @ cams.camera_to_worlds[index, :, :3].double()  # R^T d, OpenGL camera axes
    x, y = local[:, 0] / -local[:, 2], -local[:, 1] / -local[:, 2]  # OpenCV normalised (y down, z forward)
    coeffs = torch.zeros(6) if cams.distortion is None else cams.distortion[index]
    xd, yd = distort(x, y, coeffs, cams.camera_model)
    return FX * xd + CX, FY * yd + CY


def reference_pinhole_rays(cams: Cameras, index: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The pinhole formula generate_rays used before distortion existed (float32, unit directions)."""
    v, u = torch.meshgrid(
        torch.arange(cams.height, dtype=torch.float32), torch.arange(cams.width, dtype=torch.float32), indexing="ij"
    )
    x = (u + 0.5 - cams.cx[index]) / cams.fx[index]
    y = -(v + 0.5 - cams.cy[index]) / cams.fy[index]
    dirs = torch.stack([x, y, -torch.ones_like(x)], dim=-1).reshape(-1, 3) @ cams.camera_to_worlds[index, :, :3].T
    dirs = dirs / dirs.norm(dim=-1, keepdim=True)
    return cams.camera_to_worlds[index, :, 3].expand_as(dirs), dirs


@pytest.mark.parametrize(
    ("model", "coeffs"), [("PINHOLE", None), ("SIMPLE_PINHOLE", (0.0,) * 6), ("OPENCV", (0.0,) * 6)]
)
def test_undistorted_cameras_keep_the_pinhole_rays_bit_for_bit(model: str, coeffs: tuple | None) -> None:
    cams = make_cameras(model, coeffs, dtype=torch.float32)
    assert cams.distortion_of(1) is None  # the fast path
    origins, dirs = cams.generate_rays(1)
    ref_origins, ref_dirs = reference_pinhole_rays(cams, 1)
    assert dirs.dtype == torch.float32 and dirs.shape == (WIDTH * HEIGHT, 3)
    assert torch.equal(dirs, ref_dirs) and torch.equal(origins, ref_origins)


@pytest.mark.parametrize(
    ("model", "coeffs"), [("OPENCV", PHONE), ("OPENCV_FISHEYE", FISHEYE), ("OPENCV_FISHEYE", None)]
)
@pytest.mark.parametrize("normalize", [True, False])
def test_each_distorted_ray_projects_back_onto_its_pixel_centre(model: str, coeffs: tuple | None, normalize: bool):
    cams = make_cameras(model, coeffs)
    u, v = pixel_centres()
    for index in range(len(cams)):
        origins, dirs = cams.generate_rays(index, normalize=normalize)
        assert dirs.dtype == torch.float64
        torch.testing.assert_close(origins, cams.camera_to_worlds[index, :, 3].expand_as(origins), rtol=0, atol=0)
        pu, pv = project(cams, index, dirs)
        assert float(torch.maximum((pu - u).abs(), (pv - v).abs()).max()) < 1e-6
        # ... and the lens matters: at the corners the pinhole ray of the same pixel is more than a pixel off.
        pinhole = make_cameras().generate_rays(index)[1]
        assert float((pinhole - cams.generate_rays(index)[1]).norm(dim=-1).max()) * FX > 1.0


def test_unnormalised_distorted_rays_have_z_minus_one_in_the_camera_frame() -> None:
    """What NDC needs: the direction's camera-frame z is -1, its x, y the undistorted point (y up)."""
    cams = make_cameras("OPENCV", PHONE)
    _, dirs = cams.generate_rays(0, normalize=False)
    local = dirs @ cams.camera_to_worlds[0, :, :3]
    torch.testing.assert_close(local[:, 2], torch.full_like(local[:, 2], -1.0), rtol=0, atol=1e-12)
    _, unit = cams.generate_rays(0)
    torch.testing.assert_close(unit, dirs / dirs.norm(dim=-1, keepdim=True), rtol=0, atol=1e-12)


def test_a_fisheye_wider_than_180_degrees_sees_behind_itself_only_with_unit_rays() -> None:
    """Equidistant with zero coefficients and a short focal length: the image corners lie more than 90° off axis."""
    c2w = torch.cat([torch.eye(3, dtype=torch.float64), torch.zeros(3, 1, dtype=torch.float64)], dim=1)[None]
    one = torch.ones(1, dtype=torch.float64)
    cams = Cameras(c2w, one * 16, one * 16, one * 32, one * 24, 64, 48, "OPENCV_FISHEYE", None)
    _, dirs = cams.generate_rays(0)
    corner_angle = math.hypot(31.5, 23.5) / 16  # r_d = theta with zero coefficients
    torch.testing.assert_close(-dirs[0, 2], torch.tensor(math.cos(corner_angle), dtype=torch.float64))
    assert corner_angle > math.pi / 2 and bool((dirs[:, 2] > 0).any())  # OpenGL looks down -z: these look back
    with pytest.raises(ValueError, match="90° or more off its axis"):
        cams.generate_rays(0, normalize=False)


def test_float32_cameras_get_float32_rays_close_to_the_float64_ones() -> None:
    rays64 = make_cameras("OPENCV", PHONE).generate_rays(1)[1]
    rays32 = make_cameras("OPENCV", PHONE, dtype=torch.float32).generate_rays(1)[1]
    assert rays32.dtype == torch.float32
    assert float((rays32.double() - rays64).abs().max()) < 1e-6


def test_subset_keeps_the_lens_of_each_camera() -> None:
    cams = make_cameras("OPENCV", PHONE, n=3)
    cams.distortion[2, 0] = -0.2
    sub = cams.subset([2, 0])
    assert sub.camera_model == "OPENCV" and len(sub) == 2
    assert torch.equal(sub.distortion, cams.distortion[[2, 0]])
    assert torch.equal(sub.generate_rays(0)[1], cams.generate_rays(2)[1])


def test_bad_camera_models_and_distortion_shapes_are_value_errors() -> None:
    cams = make_cameras()
    parts = (cams.camera_to_worlds, cams.fx, cams.fy, cams.cx, cams.cy, WIDTH, HEIGHT)
    with pytest.raises(ValueError, match="unknown camera model 'FOV'"):
        Cameras(*parts, "FOV")
    with pytest.raises(ValueError, match=r"distortion must be \[2, 6\].*got \(2, 4\)"):
        Cameras(*parts, "OPENCV", torch.zeros(2, 4))
    with pytest.raises(ValueError, match="PINHOLE does not use k1"):
        Cameras(*parts, "PINHOLE", torch.tensor([PHONE, PHONE]))
