"""NDC rays (spec §1.2, §7.4): the near-plane shift, z' = -1 + 2t, perspective projection, and the NDC sampler."""

from __future__ import annotations

import math

import pytest
import torch

from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.cameras.ndc import ndc_rays
from fourierf_plugin.data.datamanager import camera_rays
from fourierf_plugin.data.parsers.llff import NDC_BOX, LLFFDataParserConfig
from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig
from fourierf_plugin.models.fourierf import FourieRFModelConfig
from tests.conftest import require_shared
from tests.helpers import ndc_model as build_ndc_model

FOCAL, WIDTH, HEIGHT = 40.0, 64, 48


def project(points: torch.Tensor, focal: float = FOCAL, width: int = WIDTH, height: int = HEIGHT, near: float = 1.0):
    """NDC of world points (camera frame = world frame, looking down -z): perspective x, y and z = 1 + 2n/z."""
    x, y, z = points.unbind(-1)
    return torch.stack([-focal / (width / 2) * x / z, -focal / (height / 2) * y / z, 1 + 2 * near / z], dim=-1)


def random_rays(n: int, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """Forward-facing rays in float64: origins near the world origin, directions with d_z < 0 (not unit)."""
    g = torch.Generator().manual_seed(seed)
    origins = (torch.rand(n, 3, generator=g, dtype=torch.float64) - 0.5) * torch.tensor([1.0, 1.0, 0.4])
    directions = torch.cat(
        [(torch.rand(n, 2, generator=g, dtype=torch.float64) - 0.5), -torch.ones(n, 1, dtype=torch.float64)], dim=-1
    )
    return origins, directions * (0.5 + torch.rand(n, 1, generator=g, dtype=torch.float64))


def identity_camera(width: int = WIDTH, height: int = HEIGHT, focal: float = FOCAL) -> Cameras:
    c2w = torch.cat([torch.eye(3), torch.zeros(3, 1)], dim=1)[None]
    one = torch.ones(1)
    return Cameras(c2w, one * focal, one * focal, one * width / 2, one * height / 2, width, height)


def test_origin_is_shifted_to_the_near_plane() -> None:
    """After the shift o_z = -near, so o'_z = -1 and d'_z = 2 n / n = 2, for any origin and direction."""
    o, d = random_rays(64)
    o_ndc, d_ndc = ndc_rays(o, d, FOCAL, WIDTH, HEIGHT, near=1.0)
    torch.testing.assert_close(o_ndc[:, 2], torch.full_like(o_ndc[:, 2], -1.0), rtol=0, atol=1e-12)
    torch.testing.assert_close(d_ndc[:, 2], torch.full_like(d_ndc[:, 2], 2.0), rtol=0, atol=1e-12)


def test_points_on_the_ray_map_to_z_equals_minus_one_plus_two_t() -> None:
    """A world point at depth z on the ray is o' + t d' with t = (z_ndc + 1) / 2 = 1 + n / z, in [0, 1)."""
    o, d = random_rays(32, seed=1)
    o_ndc, d_ndc = ndc_rays(o, d, FOCAL, WIDTH, HEIGHT)
    t0 = -(1.0 + o[:, 2]) / d[:, 2]  # parameter of the near-plane crossing
    for extra in (0.0, 0.5, 3.0, 40.0, 1e4):
        world = o + (t0 + extra).unsqueeze(-1) * d  # at or beyond the near plane
        expected = project(world)
        t = (expected[:, 2] + 1) / 2
        assert bool(((t >= -1e-12) & (t < 1)).all())
        torch.testing.assert_close(expected[:, 2], 1 + 2 * 1.0 / world[:, 2])
        torch.testing.assert_close(o_ndc + t.unsqueeze(-1) * d_ndc, expected, rtol=1e-9, atol=1e-9)
        torch.testing.assert_close((o_ndc + t.unsqueeze(-1) * d_ndc)[:, 2], -1 + 2 * t, rtol=0, atol=1e-12)


def test_near_plane_is_t0_and_infinity_is_t1() -> None:
    o, d = random_rays(16, seed=2)
    o_ndc, d_ndc = ndc_rays(o, d, FOCAL, WIDTH, HEIGHT)
    far = o + 1e9 * d
    torch.testing.assert_close(o_ndc + d_ndc, project(far), rtol=0, atol=1e-6)  # t = 1 is the point at infinity
    near = o + (-(1.0 + o[:, 2]) / d[:, 2]).unsqueeze(-1) * d
    torch.testing.assert_close(o_ndc, project(near))


def test_other_near_plane() -> None:
    o, d = random_rays(16, seed=3)
    o_ndc, d_ndc = ndc_rays(o, d, FOCAL, WIDTH, HEIGHT, near=2.0)
    torch.testing.assert_close(o_ndc[:, 2], torch.full_like(o_ndc[:, 2], -1.0))
    world = o + (-(2.0 + o[:, 2]) / d[:, 2] + 5.0).unsqueeze(-1) * d
    expected = project(world, near=2.0)
    t = ((expected[:, 2] + 1) / 2).unsqueeze(-1)
    torch.testing.assert_close(o_ndc + t * d_ndc, expected)


def test_centre_ray_stays_on_the_axis() -> None:
    o = torch.zeros(1, 3)
    d = torch.tensor([[0.0, 0.0, -1.0]])
    o_ndc, d_ndc = ndc_rays(o, d, FOCAL, WIDTH, HEIGHT)
    for t in torch.linspace(0, 1, 11):
        p = o_ndc + t * d_ndc
        assert p[0, 0].item() == 0.0 and p[0, 1].item() == 0.0
        assert p[0, 2].item() == pytest.approx(-1 + 2 * t.item())


def test_centre_pixel_of_a_camera_at_the_origin_stays_on_the_axis() -> None:
    """Odd image size: the middle pixel's centre is the principal point."""
    cams = identity_camera(width=5, height=3, focal=4.0)
    o, d = camera_rays(cams, 0, "ndc")
    centre = 1 * 5 + 2  # row 1, column 2
    assert o[centre, :2].abs().max().item() < 1e-7 and d[centre, :2].abs().max().item() < 1e-7
    assert o[centre, 2].item() == pytest.approx(-1.0) and d[centre, 2].item() == pytest.approx(2.0)


def test_rays_of_a_camera_at_the_origin_are_parallel_in_ndc_and_hit_their_pixel() -> None:
    """From the NDC centre of projection every ray is parallel to z, at x' = (u + 0.5 - W/2) / (W/2)."""
    cams = identity_camera()
    o, d = camera_rays(cams, 0, "ndc")
    assert d[:, :2].abs().max().item() < 1e-6
    v, u = torch.meshgrid(torch.arange(HEIGHT), torch.arange(WIDTH), indexing="ij")
    x_expected = ((u + 0.5 - WIDTH / 2) / (WIDTH / 2)).reshape(-1)
    y_expected = (-(v + 0.5 - HEIGHT / 2) / (HEIGHT / 2)).reshape(-1)
    torch.testing.assert_close(o[:, 0], x_expected.float())
    torch.testing.assert_close(o[:, 1], y_expected.float())


def test_ndc_xy_is_the_perspective_projection() -> None:
    """x' = -(f / (W/2)) x / z, y' = -(f / (H/2)) y / z for points in front of the near plane."""
    g = torch.Generator().manual_seed(4)
    points = torch.rand(50, 3, generator=g, dtype=torch.float64) * torch.tensor([4.0, 4.0, -20.0]) - torch.tensor(
        [2.0, 2.0, 1.5]
    )
    o = torch.zeros_like(points)
    o_ndc, d_ndc = ndc_rays(o, points, FOCAL, WIDTH, HEIGHT)  # the ray from the origin through each point
    t = 1 + 1.0 / points[:, 2:]
    p = o_ndc + t * d_ndc
    torch.testing.assert_close(p[:, 0], -FOCAL / (WIDTH / 2) * points[:, 0] / points[:, 2])
    torch.testing.assert_close(p[:, 1], -FOCAL / (HEIGHT / 2) * points[:, 1] / points[:, 2])


def test_euclidean_rays_are_unit_and_ndc_rays_are_not() -> None:
    cams = identity_camera()
    _, d_euc = camera_rays(cams, 0, "euclidean")
    torch.testing.assert_close(d_euc.norm(dim=-1), torch.ones(d_euc.shape[0]))
    _, d_ndc = camera_rays(cams, 0, "ndc")
    assert bool((d_ndc.norm(dim=-1) - 2.0).abs().max() < 1e-5)


def test_fern_rays_stay_inside_the_ndc_box() -> None:
    """Every pixel ray of 6 fern cameras (3 training, 3 hold-out; 252x189) stays in the NDC box for t in [0, 1).

    The tolerance is float32 rounding of z' = -1 at t = 0 (the origin sits exactly on the box face).
    """
    fern = require_shared("data", "llff", "fern")
    box = torch.tensor(NDC_BOX) + torch.tensor([[-1e-5], [1e-5]])
    t = torch.linspace(0.0, 0.999, 12).view(1, -1, 1)
    for split in ("train", "test"):
        cams = LLFFDataParserConfig(data=fern, downscale=16, num_views=3).setup().get_outputs(split).cameras
        for i in range(len(cams)):
            o, d = camera_rays(cams, i, "ndc")
            assert bool(torch.isfinite(o).all() and torch.isfinite(d).all())
            pts = o.unsqueeze(1) + t * d.unsqueeze(1)
            inside = ((pts >= box[0]) & (pts <= box[1])).all(dim=-1)
            assert bool(inside.all()), f"{split} camera {i}: {int((~inside).sum())} samples leave the NDC box"


# -- the model's NDC sampler ----------------------------------------------------------------------------------------


@pytest.fixture
def ndc_model():
    return build_ndc_model(FourieRFModelConfig(field=FieldConfig(n_voxels_init=4096, n_voxels_final=13824)))


def model_samples(model, num_rays: int, seed: int, training: bool):
    """The model's samples along NDC rays in training or eval mode, their directions and the count it asked for;
    every ray gets that many samples, the last interval 0 and the others scaled by |d| (the spacing in t is
    checked by each test)."""
    o, d = random_rays(num_rays, seed=seed)
    o, d = ndc_rays(o.float(), d.float(), FOCAL, WIDTH, HEIGHT)
    samples = model.train(training).sample(o, d)
    n = model.samples_per_ray(training=training)
    assert samples.t.shape == (num_rays, n)
    expected = torch.cat([samples.t[:, 1:] - samples.t[:, :-1], torch.zeros(num_rays, 1)], dim=1)
    torch.testing.assert_close(samples.deltas, expected * d.norm(dim=-1, keepdim=True))
    return samples, n


def test_ndc_training_samples_cover_zero_to_one_plus_a_bin(ndc_model) -> None:
    samples, n = model_samples(ndc_model, 64, seed=5, training=True)
    t = samples.t
    assert bool((t >= 0).all()) and bool((t < 1 + 1 / n).all())
    assert bool((t[:, 1:] > t[:, :-1]).all()), "jittered samples stay ordered"
    jitter = t - torch.linspace(0, 1, n)
    assert bool((jitter >= 0).all()) and bool((jitter < 1 / n).all())
    assert jitter.std().item() > 0.1 / n, "training jitter is per sample"


def test_ndc_eval_samples_are_evenly_spaced(ndc_model) -> None:
    samples, n = model_samples(ndc_model, 8, seed=6, training=False)
    torch.testing.assert_close(samples.t, torch.linspace(0, 1, n).expand(8, n))


def test_ndc_forward_is_finite_and_uses_unit_view_directions(ndc_model) -> None:
    o, d = random_rays(32, seed=7)
    o, d = ndc_rays(o.float(), d.float(), FOCAL, WIDTH, HEIGHT)
    ndc_model.prepare(0)
    out = ndc_model.train()(o, d)
    for key in ("rgb", "accumulation", "depth"):
        assert bool(torch.isfinite(out[key]).all()), key
    assert "occlusion" in out and math.isfinite(out["occlusion"].item())
    background = out["background"].numpy()
    assert (background == 0).all() or (background == 1).all(), "photos train on black or white per batch"
    for mode in (ndc_model.train(), ndc_model.eval()):
        view = mode.sample(o, d).view_directions
        torch.testing.assert_close(view, d / d.norm(dim=-1, keepdim=True))
        torch.testing.assert_close(view.norm(dim=-1), torch.ones(32))
