"""Hard cases stay numerically stable (issue 6): extreme densities, rays, scales, occupancy, cutoffs and losses.

Every case goes through the real model (``FourieRFModel`` forward, backward, ``after_step``) or the real filters,
asserts finite outputs AND finite gradients, and, where an independent answer exists, compares against a float64
reference (the same model in double precision, or a numpy FFT). The unit-level compositing and ray–box checks in
tests/model_components/ are not repeated here; these tests exercise the whole chain. The models use a float32
decoder (``accel.decoder_precision``): the float64 comparisons test geometry, not the bf16 decoder.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from fourierf_plugin.accel import AccelConfig
from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.cameras.ndc import ndc_rays
from fourierf_plugin.field_components.fourier import filter_lines, filter_planes
from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig
from fourierf_plugin.model_components import losses
from fourierf_plugin.model_components.occupancy import vertex_grid
from fourierf_plugin.model_components.regularisers.occlusion import occlusion_penalty
from fourierf_plugin.model_components.rendering import composite_weights
from fourierf_plugin.models.fourierf import FourieRFModel, FourieRFModelConfig
from tests.helpers import BLENDER, ndc_model

BOUND, NEAR, FAR = 1.5, 2.0, 6.0  # the Blender box half-size and ray bounds
DISTANCE_SCALE = 25.0


# -- builders ---------------------------------------------------------------------------------------------------------
def small_field(**overrides) -> FieldConfig:
    """A 16³ grid with few components: the numerics are the same as at full size, the cost is not."""
    base = dict(
        n_voxels_init=16**3,
        n_voxels_final=24**3,
        density_components=(2, 2, 2),
        appearance_components=(3, 3, 3),
        appearance_dim=6,
        hidden_dim=16,
    )
    return FieldConfig(**{**base, **overrides})


def model_config(**kw) -> FourieRFModelConfig:
    """A model config on ``small_field()`` (unless another field is given) with a float32 decoder."""
    kw.setdefault("field", small_field())
    return FourieRFModelConfig(accel=AccelConfig(decoder_precision="float32"), **kw)


def blender_model(
    scale: float = 1.0, box: tuple[tuple[float, ...], tuple[float, ...]] | None = None, max_iters: int = 100, **kw
) -> FourieRFModel:
    """A Blender-like model (white background, euclidean rays) on the box scaled by ``scale``.

    ``distance_scale`` is divided by ``scale`` so σ·δ·scale is scale-free: a scaled scene must render the same.
    """
    config = model_config(distance_scale=DISTANCE_SCALE / scale, **kw)
    aabb = torch.tensor(box) if box is not None else torch.tensor([[-BOUND] * 3, [BOUND] * 3])
    return config.setup(
        scene_box=aabb * scale,
        near=NEAR * scale,
        far=FAR * scale,
        effects=BLENDER,
        max_iters=max_iters,
        generator=torch.Generator().manual_seed(0),
    )


def set_constant_density(model: FourieRFModel, value: float) -> None:
    """σ = ``value`` everywhere with a ReLU field: one plane·line product equals ``value``, all others are 0."""
    grid = model.field.density_grid
    with torch.no_grad():
        for p in [*grid.planes, *grid.lines]:
            p.zero_()
        grid.planes[0][0].fill_(1.0)
        grid.lines[0][0].fill_(value)
    model.field.invalidate()


def add_dense_slab(model: FourieRFModel, lo: int, hi: int, value: float) -> None:
    """Raise the density feature by ``value`` for z-vertices lo..hi-1 (plane 0 spans x, y; line 0 runs along z)."""
    grid = model.field.density_grid
    with torch.no_grad():
        grid.planes[0][0].fill_(1.0)
        grid.lines[0][0, lo:hi] += value
    model.field.invalidate()


def render(model: FourieRFModel, origins, directions, training: bool, f: float = 1.0) -> dict:
    """Forward with autograd at cutoff ``f`` in training or eval mode (training jitter comes from the model's
    seeded generator)."""
    model.field.prepare(f, f)
    dtype = next(model.parameters()).dtype
    return model.train(training)(origins.to(dtype), directions.to(dtype))


def backprop(model: FourieRFModel, out: dict, depth_unit: float = 1.0) -> dict[str, torch.Tensor]:
    """The real training loss (MSE + TV + L1 on the filtered grids) plus a small depth term (depth in
    ``depth_unit``s, so scaled scenes get the same loss) backpropagated; returns the gradients by name."""
    model.zero_grad(set_to_none=True)
    target = torch.full((out["rgb"].shape[0], 4), 0.5, dtype=out["rgb"].dtype)
    loss = sum(model.loss_dict(out, target, 0).values()) + out["depth"].sum() * 1e-3 / depth_unit
    assert torch.isfinite(loss), f"loss is {loss}"
    loss.backward()
    return {name: p.grad for name, p in model.named_parameters() if p.grad is not None}


def assert_finite(out: dict, grads: dict[str, torch.Tensor] | None = None) -> None:
    for key in ("rgb", "accumulation", "depth"):
        assert bool(torch.isfinite(out[key]).all()), f"{key} is not finite: {out[key]}"
    for name, grad in (grads or {}).items():
        assert bool(torch.isfinite(grad).all()), f"gradient of {name} is not finite"


def unit(v) -> torch.Tensor:
    t = torch.as_tensor(v, dtype=torch.float32)
    return t / t.norm(dim=-1, keepdim=True)


@torch.no_grad()
def compare_to_float64(model: FourieRFModel, origins, directions, atol: float = 2e-5) -> dict:
    """Eval render in float32 and again with the model cast to float64 (the reference; cast back afterwards):
    rgb and accumulation agree within ``atol``, depth within ``atol · far``. Returns the float64 outputs."""
    out32 = render(model, origins, directions, training=False)
    out64 = render(model.double(), origins.double(), directions.double(), training=False)
    model.float()
    for key, tol in (("rgb", atol), ("accumulation", atol), ("depth", atol * FAR)):
        err = float((out32[key].double() - out64[key]).abs().max()) if out32[key].numel() else 0.0
        assert err <= tol, f"{key}: float32 differs from float64 by {err:.3g} > {tol:.3g}"
    return out64


# -- densities: 1e4 and exactly 0 along whole rays ----------------------------------------------------------------
CENTRE_RAYS = (torch.tensor([[0.0, 0.0, 4.0], [0.3, -0.2, 4.0]]), unit([[0.0, 0.0, -1.0], [0.1, 0.05, -1.0]]))


def test_density_1e4_everywhere_is_opaque_finite_and_matches_float64() -> None:
    model = blender_model(field=small_field(density_activation="relu"))
    set_constant_density(model, 1e4)
    origins, directions = CENTRE_RAYS
    out = render(model, origins, directions, training=True)
    assert_finite(out, backprop(model, out))
    torch.testing.assert_close(out["accumulation"], torch.ones(2), atol=1e-6, rtol=0)
    # All the weight sits on the first sample inside the box, so depth is the box entry (2.5 along z for ray 0).
    assert float(out["depth"][0].detach()) == pytest.approx(2.5, abs=model.step_size)
    compare_to_float64(model, origins, directions)


def test_zero_density_along_whole_rays_gives_the_exact_background() -> None:
    model = blender_model(field=small_field(density_activation="relu"))
    set_constant_density(model, 0.0)
    origins, directions = CENTRE_RAYS
    out = render(model, origins, directions, training=True)
    grads = backprop(model, out)
    assert_finite(out, grads)
    assert torch.equal(out["rgb"], torch.ones(2, 3)), "no density: exactly the white background"
    assert torch.equal(out["accumulation"], torch.zeros(2))
    assert torch.equal(out["depth"], torch.full((2,), FAR)), "a miss reads as the far plane"
    compare_to_float64(model, origins, directions, atol=0.0)


# -- ~2000 samples per ray, float32 against float64 -----------------------------------------------------------------
def test_two_thousand_samples_per_ray_match_float64() -> None:
    """Model-level float32 vs float64 with ~2000 samples per ray and a dense shell.

    Bound asserted: |rgb32 - rgb64|, |acc32 - acc64| ≤ 2e-5 and |depth32 - depth64| ≤ 2e-5 · far (measured 2e-7 / 7e-7).
    """
    model = blender_model(step_ratio=0.013)  # step = 0.013 voxels: 2131 training / 1999 eval samples per ray
    assert model.samples_per_ray(training=True) >= 2000 and model.samples_per_ray(training=False) >= 1900
    add_dense_slab(model, 5, 8, 30.0)  # the softplus feature jumps from -10 (σ ≈ 4.5e-5) to ~+20 (σ ≈ 20)
    gen = torch.Generator().manual_seed(3)
    origins = torch.tensor([0.0, 0.0, 4.0]) + 0.4 * (torch.rand(6, 3, generator=gen) - 0.5)
    directions = unit(torch.tensor([0.0, 0.0, -1.0]) + 0.2 * (torch.rand(6, 3, generator=gen) - 0.5))
    out = render(model, origins, directions, training=True)
    assert out["rgb"].shape == (6, 3)
    assert_finite(out, backprop(model, out))
    ref = compare_to_float64(model, origins, directions)
    assert float(ref["accumulation"].max()) > 0.5, "precondition: the rays cross the dense shell"


def test_float32_compositing_of_2000_samples_against_float64() -> None:
    """``composite_weights`` in float32 against the float64 cumprod formula on 2000 samples, σ spanning 1e-4..1e4.

    Bound asserted: every weight and every ray's accumulation within 1e-5 of float64 (absolute). Why that bound:
    a float32 running sum of 2000 optical depths may lose up to ~N·eps ≈ 1.2e-4 of S relatively, i.e. up to
    max_S(S·e^-S)·1.2e-4 ≈ 4.4e-5 of transmittance; torch's CPU cumsum accumulates in float64 and the measured
    error is 4e-8, so 1e-5 leaves room for other backends while catching any real regression.
    """
    gen = torch.Generator().manual_seed(4)
    sigma = 10 ** (torch.rand(16, 2000, generator=gen) * 8 - 4)  # log-uniform 1e-4 .. 1e4: opaque within a few samples
    sigma[:8] = torch.rand(8, 2000, generator=gen) * 0.05  # optical depth ~2 over the whole ray: T spans (0.1, 1)
    deltas = torch.full((16, 2000), 0.0015)
    deltas[:, -1] = 0.0
    w32 = composite_weights(sigma.requires_grad_(), deltas, DISTANCE_SCALE)
    tau = sigma.detach().double() * deltas.double() * DISTANCE_SCALE
    alpha = 1.0 - torch.exp(-tau)
    trans = torch.cumprod(torch.cat([torch.ones(16, 1, dtype=torch.float64), 1.0 - alpha[:, :-1]], dim=-1), dim=-1)
    w64 = alpha * trans
    err = (w32.detach().double() - w64).abs()
    assert float(err.max()) <= 1e-5
    assert float((w32.detach().double().sum(-1) - w64.sum(-1)).abs().max()) <= 1e-5
    assert float(w64[:8].sum(-1).min()) < 0.9, "precondition: the thin rays keep transmittance well inside (0, 1)"
    w32.sum().backward()
    assert bool(torch.isfinite(sigma.grad).all())


# -- ray geometry through the model ---------------------------------------------------------------------------------
RAYS = {
    # name: (origin, direction, hits the box interior)
    "miss": ([3.0, 3.0, 4.0], [0.0, 0.0, -1.0], False),
    "graze an edge": ([BOUND, BOUND, 4.0], [0.0, 0.0, -1.0], False),
    "graze a corner diagonally": ([BOUND + 1.0, BOUND + 1.0, 4.0], [-1.0, -1.0, 0.0], False),
    # On a face plane the slab test is degenerate (TensoRF's 1e-6 stand-in for 0 makes the lower face a hit, the
    # upper one a miss): only finiteness and float64 agreement are asked.
    "lie in the upper x face": ([BOUND, 0.2, 4.0], [0.0, 0.0, -1.0], None),
    "lie in the lower x face": ([-BOUND, 0.2, 4.0], [0.0, 0.0, -1.0], None),
    "start inside": ([-1.4, 0.1, 0.2], [1.0, 0.0, 0.0], True),
    "parallel to x": ([-4.0, 0.3, -0.2], [1.0, 0.0, 0.0], True),
    "parallel to y": ([0.3, -4.0, -0.2], [0.0, 1.0, 0.0], True),
    "parallel to z": ([0.3, -0.2, 4.0], [0.0, 0.0, -1.0], True),
    "in the xy plane": ([-4.0, 0.5, 0.0], [3.0, -1.0, 0.0], True),
}


@pytest.mark.parametrize("name", list(RAYS))
def test_ray_geometry_is_finite_with_gradients_and_matches_float64(name: str) -> None:
    origin, direction, hits = RAYS[name]
    model = blender_model()
    add_dense_slab(model, 2, 14, 12.0)  # a dense slab so hits have weight
    origins, directions = torch.tensor([origin]), unit([direction])
    out = render(model, origins, directions, training=True)
    assert_finite(out, backprop(model, out))
    ref = compare_to_float64(model, origins, directions)
    if hits is True:
        assert float(ref["accumulation"][0]) > 1e-3, "the ray crosses the dense slab"
    elif hits is False:
        assert float(ref["accumulation"][0]) == 0.0, "a miss or a graze collects nothing"
        assert torch.equal(ref["rgb"], torch.ones(1, 3)) and float(ref["depth"][0]) == FAR


def test_batch_mixing_misses_and_hits_has_no_cross_talk() -> None:
    """A miss in the batch must not change the other rays (the sample count follows the longest ray)."""
    model = blender_model()
    hits = torch.tensor([[0.3, -0.2, 4.0]]), unit([[0.0, 0.0, -1.0]])
    mixed_o = torch.cat([hits[0], torch.tensor([[9.0, 9.0, 9.0]])])
    mixed_d = torch.cat([hits[1], unit([[1.0, 0.0, 0.0]])])
    alone = render(model, *hits, training=False)
    both = render(model, mixed_o, mixed_d, training=False)
    torch.testing.assert_close(both["rgb"][:1], alone["rgb"])
    torch.testing.assert_close(both["accumulation"][:1], alone["accumulation"])


# -- NDC: cameras on the near plane ---------------------------------------------------------------------------------
def camera_at(z: float, width: int = 8, height: int = 6, focal: float = 7.0) -> Cameras:
    c2w = torch.eye(4)[:3].unsqueeze(0).clone()
    c2w[0, :, 3] = torch.tensor([0.1, -0.05, z])
    one = torch.ones(1)
    return Cameras(c2w, one * focal, one * focal, one * width / 2, one * height / 2, width, height)


@pytest.mark.parametrize("z", [-1.0, 0.0, -1.0 - 1e-7, -3.0])
def test_camera_on_or_near_the_ndc_near_plane_is_finite(z: float) -> None:
    """A camera on the near plane (z = -1) maps its origins to z_ndc = -1 exactly; in front of or behind it too."""
    cams = camera_at(z)
    o, d = cams.generate_rays(0, normalize=False)
    o_ndc, d_ndc = ndc_rays(o, d, float(cams.fx[0]), cams.width, cams.height, near=1.0)
    ref_o, ref_d = ndc_rays(o.double(), d.double(), float(cams.fx[0]), cams.width, cams.height, near=1.0)
    assert bool(torch.isfinite(o_ndc).all() and torch.isfinite(d_ndc).all())
    torch.testing.assert_close(o_ndc.double(), ref_o, atol=1e-6, rtol=1e-6)
    torch.testing.assert_close(d_ndc.double(), ref_d, atol=1e-6, rtol=1e-6)
    torch.testing.assert_close(o_ndc[:, 2], torch.full((o.shape[0],), -1.0), atol=1e-6, rtol=0)

    model = ndc_model(model_config())
    out = render(model, o_ndc, d_ndc, training=True)
    assert_finite(out, backprop(model, out))
    assert math.isfinite(float(out["occlusion"].detach()))


# -- scenes scaled by 1e-3 and 1e3 ----------------------------------------------------------------------------------
@pytest.mark.parametrize("scale", [1e-3, 1e3])
def test_scaled_scene_renders_the_same_up_to_the_scaling_of_delta(scale: float) -> None:
    """The same parameters on a box scaled by s, rays scaled by s and δ·distance_scale kept: same images, depth·s."""
    reference, scaled = blender_model(), blender_model(scale)
    assert scaled.field.resolution == reference.field.resolution
    assert scaled.step_size == pytest.approx(reference.step_size * scale, rel=1e-6)
    add_dense_slab(reference, 4, 12, 11.0)
    with torch.no_grad():  # the decoder's init draws from torch's global RNG: copy every parameter over
        for mine, theirs in zip(scaled.parameters(), reference.parameters(), strict=True):
            mine.copy_(theirs)
    gen = torch.Generator().manual_seed(5)
    origins = torch.tensor([0.0, 0.0, 4.0]) + 0.6 * (torch.rand(8, 3, generator=gen) - 0.5)
    directions = unit(torch.tensor([0.0, 0.0, -1.0]) + 0.3 * (torch.rand(8, 3, generator=gen) - 0.5))

    # Density and colour at corresponding points are identical: the field works in normalised coordinates.
    pts = vertex_grid(reference.aabb, [5, 4, 3]).reshape(-1, 3) * 0.97
    for model in (reference, scaled):
        model.field.prepare(0.5, 0.5)
    torch.testing.assert_close(scaled.field.density(pts * scale), reference.field.density(pts), rtol=1e-4, atol=1e-6)
    torch.testing.assert_close(
        scaled.field.rgb(pts * scale, None), reference.field.rgb(pts, None), rtol=1e-4, atol=1e-6
    )

    out_ref = render(reference, origins, directions, training=True, f=0.5)
    out = render(scaled, origins * scale, directions, training=True, f=0.5)
    assert float(out_ref["accumulation"].detach().max()) > 0.1, "precondition: the rays see the dense slab"
    grads_ref, grads = backprop(reference, out_ref), backprop(scaled, out, depth_unit=scale)
    assert_finite(out, grads)
    torch.testing.assert_close(out["rgb"], out_ref["rgb"], atol=2e-4, rtol=0)
    torch.testing.assert_close(out["accumulation"], out_ref["accumulation"], atol=2e-4, rtol=0)
    torch.testing.assert_close(out["depth"] / scale, out_ref["depth"], atol=2e-3, rtol=0)
    for name, grad in grads_ref.items():
        torch.testing.assert_close(grads[name], grad, atol=1e-4 * float(grad.abs().max()) + 1e-9, rtol=1e-2)


# -- occupancy: nothing survives, and a thin slab -------------------------------------------------------------------
def test_empty_occupancy_grid_keeps_the_box_and_renders_the_background(capsys) -> None:
    """An update that finds no density keeps the box and the sampler; a grid with no cell on culls every sample."""
    model = blender_model(field=small_field(density_activation="relu"))
    set_constant_density(model, 0.0)
    box_before, reso_before = model.aabb.clone(), model.field.resolution
    first = model.occupancy_steps[0]
    model.after_step(first)
    assert "occupancy grid is empty" in capsys.readouterr().out
    assert torch.equal(model.aabb, box_before) and model.field.resolution == reso_before
    assert not model.occupancy.active, "an empty update must not switch every sample off"

    model = blender_model()
    model.occupancy.set(torch.zeros(16, 16, 16, dtype=torch.bool), model.aabb)
    out = render(model, *CENTRE_RAYS, training=True)
    grads = backprop(model, out)  # MSE has no path to the grids here; TV and L1 still do
    assert_finite(out, grads)
    assert torch.equal(out["rgb"], torch.ones(2, 3)) and torch.equal(out["accumulation"], torch.zeros(2))
    assert grads, "the regularisers keep the loss differentiable"


def thin_slab_model() -> FourieRFModel:
    """Density only where z is within one voxel of index 7 of the 16 z-vertices (an occupancy update shrinks to it)."""
    model = blender_model(field=small_field(density_activation="relu"), occupancy_threshold=0.5)
    set_constant_density(model, 0.0)
    with torch.no_grad():  # plane 0 spans (x, y), line 0 runs along z
        model.field.density_grid.planes[0][0].fill_(1.0)
        model.field.density_grid.lines[0][0, 7] = 200.0
    return model


def test_occupancy_after_shrinking_to_a_thin_slab_stays_finite_through_upsample() -> None:
    model = thin_slab_model()
    model.after_step(model.occupancy_steps[0])  # the first update shrinks the box
    size = (model.aabb[1] - model.aabb[0]).tolist()
    assert size[2] < 0.5 * size[0], f"precondition: the box became a thin slab, got {size}"
    assert min(model.field.resolution) >= 2
    assert model.step_size > 0 and model.samples_per_ray(training=True) >= 1

    rays = torch.tensor([[0.1, 0.2, 4.0], [0.1, 0.2, -4.0], [-4.0, 0.1, float(model.aabb[:, 2].mean())]])
    dirs = unit([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    out = render(model, rays, dirs, training=True, f=0.3)
    assert_finite(out, backprop(model, out))
    assert bool((out["accumulation"] > 0.5).all()), "every ray crosses the slab"
    compare_to_float64(model, rays, dirs)

    model.after_step(model.upsample_steps[0])  # upsample the shrunk grid from its filtered copy
    assert min(model.field.resolution) >= 2
    out = render(model, rays, dirs, training=True, f=0.3)
    assert_finite(out, backprop(model, out))


# -- cutoffs: f = 0, f = 1, bin edges, odd and non-square planes, 1-voxel lines --------------------------------------
def line_reference(x: np.ndarray, f: float) -> np.ndarray:
    """Independent line low-pass on the full (two-sided) spectrum: bin ±k weighted by the spec's rfft weight."""
    n = x.shape[-1]
    bins = n // 2 + 1
    c = bins * f
    k = np.minimum(np.arange(n), n - np.arange(n))  # |frequency| of each full-FFT bin
    weight = np.where(k < math.floor(c), 1.0, np.where(k == math.floor(c), c - math.floor(c), 0.0))
    weight = np.ones(n) if c >= bins else (np.where(k == 0, 1.0, 0.0) if c < 1 else weight)
    return np.fft.ifft(np.fft.fft(x, axis=-1) * weight, axis=-1).real


def plane_reference(x: np.ndarray, f: float) -> np.ndarray:
    """Independent plane low-pass: the disc dist ≤ f·max(H, W)/√2 around the centre of the fftshift-ed spectrum."""
    h, w = x.shape[-2:]
    kh, kw = np.meshgrid(np.arange(h) - h // 2, np.arange(w) - w // 2, indexing="ij")
    disc = (kh**2 + kw**2 <= f * f * max(h, w) ** 2 / 2.0).astype(np.float64)
    spectrum = np.fft.fftshift(np.fft.fft2(x, axes=(-2, -1)), axes=(-2, -1)) * disc
    return np.fft.ifft2(np.fft.ifftshift(spectrum, axes=(-2, -1)), axes=(-2, -1)).real


def edge_cutoffs(length: int) -> list[float]:
    """f = 0, 1, and just below/above the first and the last bin edge of a line of ``length``."""
    bins = length // 2 + 1
    edges = sorted({1 / bins, (bins - 1) / bins} - {0.0, 1.0})
    out = [0.0, 1.0]
    for e in edges:
        out += [max(0.0, e - 1e-6), min(1.0, e + 1e-6)]
    return out


LINE_LENGTHS = [1, 2, 3, 7, 16, 17]
PLANE_SHAPES = [(1, 1), (1, 9), (9, 1), (2, 3), (5, 8), (7, 7), (16, 9)]


@pytest.mark.parametrize("length", LINE_LENGTHS)
def test_line_cutoff_extremes_and_bin_edges_match_a_float64_fft(length: int) -> None:
    x64 = np.random.default_rng(length).normal(size=(3, length))
    for f in edge_cutoffs(length):
        x = torch.tensor(x64, dtype=torch.float32, requires_grad=True)
        out = filter_lines(x, f)
        (out * torch.arange(length, dtype=torch.float32)).sum().backward()
        assert bool(torch.isfinite(out).all() and torch.isfinite(x.grad).all()), f
        np.testing.assert_allclose(out.detach().double().numpy(), line_reference(x64, f), atol=2e-6, err_msg=f"f={f}")
        if f == 0.0 or length == 1:
            np.testing.assert_allclose(
                out.detach().numpy(), np.broadcast_to(x64.mean(-1, keepdims=True), x64.shape), atol=1e-6
            )
        if f == 1.0:
            assert out is x, "f = 1 is exactly unfiltered TensoRF"


@pytest.mark.parametrize("shape", PLANE_SHAPES, ids=[f"{h}x{w}" for h, w in PLANE_SHAPES])
def test_plane_cutoff_extremes_and_ring_edges_match_a_float64_fft(shape: tuple[int, int]) -> None:
    h, w = shape
    x64 = np.random.default_rng(h * 31 + w).normal(size=(2, h, w))
    rho2 = sorted({kh * kh + kw * kw for kh in range(h // 2 + 1) for kw in range(w // 2 + 1)} - {0})
    # f where the disc radius crosses the first and the last ring of frequencies, just below and above.
    rings = [math.sqrt(2.0 * r) / max(h, w) for r in rho2[:1] + rho2[-1:]]
    cutoffs = [0.0, 1.0] + [min(1.0, max(0.0, r * (1 + s))) for r in rings for s in (-1e-6, 1e-6)]
    for f in cutoffs:
        x = torch.tensor(x64, dtype=torch.float32, requires_grad=True)
        out = filter_planes(x, f)
        out.pow(2).sum().backward()
        assert bool(torch.isfinite(out).all() and torch.isfinite(x.grad).all()), f
        np.testing.assert_allclose(out.detach().double().numpy(), plane_reference(x64, f), atol=2e-6, err_msg=f"f={f}")


def test_field_on_an_odd_non_square_grid_at_extreme_cutoffs() -> None:
    """A non-cubic box gives odd, non-square planes; every cutoff from 0 to 1 keeps density, colour and grads finite."""
    model = blender_model(box=((-1.5, -0.8, -0.3), (1.5, 0.8, 0.3)))
    reso = model.field.resolution
    assert len(set(reso)) == 3 and any(r % 2 for r in reso), f"precondition: odd non-square planes, got {reso}"
    origins, directions = torch.tensor([[0.1, 0.1, 4.0], [-4.0, 0.05, 0.0]]), unit([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    length = max(reso)
    for f in edge_cutoffs(length):
        out = render(model, origins, directions, training=True, f=f)
        assert_finite(out, backprop(model, out))
    model.field.prepare(0.0, 0.0)
    pts = vertex_grid(model.aabb, [4, 3, 3]).reshape(-1, 3)
    density = model.field.density(pts).detach()
    assert float(density.max() - density.min()) <= 1e-6 * float(density.max()), "f = 0: DC only, a constant field"


# -- upsample and shrink on a filtered grid ------------------------------------------------------------------------
def test_upsample_at_f0_gives_constant_raw_factors() -> None:
    """The upsample interpolates the *filtered* factors: at f = 0 only each factor's mean survives, exactly."""
    model = blender_model()
    model.field.prepare(0.0, 0.0)
    means = [p.detach().mean(dim=(-2, -1)) for p in model.field.density_grid.planes]
    model._upsample([20, 21, 23])
    assert model.field.resolution == [20, 21, 23]
    for plane, mean in zip(model.field.density_grid.planes, means, strict=True):
        torch.testing.assert_close(plane.detach(), mean[:, None, None].expand_as(plane), atol=1e-6, rtol=0)
    for line in model.field.density_grid.lines:
        assert float((line - line.mean(dim=-1, keepdim=True)).detach().abs().max()) <= 1e-6
    out = render(model, *CENTRE_RAYS, training=True, f=0.0)
    assert_finite(out, backprop(model, out))


def test_upsample_from_a_filtered_grid_matches_a_float64_reference() -> None:
    model = blender_model()
    f = 0.3
    raw = [p.detach().double().clone() for p in model.field.density_grid.planes]
    model.field.prepare(f, f)
    target = [19, 23, 21]  # odd, non-square
    model._upsample(target)
    for new, old, (m0, m1) in zip(
        model.field.density_grid.planes, raw, model.field.density_grid.plane_axes, strict=True
    ):
        ref = F.interpolate(
            filter_planes(old, f).unsqueeze(0), size=(target[m1], target[m0]), mode="bilinear", align_corners=True
        )[0]
        torch.testing.assert_close(new.detach().double(), ref, atol=1e-5, rtol=0)
    # The resized (odd) planes filter again at the next step's cutoff without trouble.
    out = render(model, *CENTRE_RAYS, training=True, f=0.35)
    assert_finite(out, backprop(model, out))


def test_shrink_then_filter_and_upsample_keep_gradients_finite() -> None:
    """Cropping the raw grid to the slab (odd sizes) then filtering at f < 1 and upsampling: all finite."""
    model = thin_slab_model()
    model.after_step(model.occupancy_steps[0])
    cropped = model.field.resolution
    assert cropped != [16, 16, 16], "precondition: the shrink cropped the grid"
    for f in (0.0, 0.3, 1.0):
        out = render(model, *CENTRE_RAYS, training=True, f=f)
        assert_finite(out, backprop(model, out))
    model.after_step(model.upsample_steps[0])
    assert all(a >= b for a, b in zip(model.field.resolution, cropped, strict=True))
    out = render(model, *CENTRE_RAYS, training=True, f=0.3)
    assert_finite(out, backprop(model, out))


# -- losses that would go NaN ---------------------------------------------------------------------------------------
def test_regularisers_on_an_empty_mask_are_finite() -> None:
    """NDC model with every cell off: the occlusion term sees only zero densities and stays 0 and differentiable."""
    model = ndc_model(model_config())
    model.occupancy.set(torch.zeros(16, 17, 10, dtype=torch.bool), model.aabb)
    cams = camera_at(-1.0)
    o, d = cams.generate_rays(0, normalize=False)
    out = render(model, *ndc_rays(o, d, float(cams.fx[0]), cams.width, cams.height), training=True)
    assert float(out["occlusion"].detach()) == 0.0
    assert float(out["accumulation"].detach().abs().max()) == 0.0
    assert_finite(out, backprop(model, out))


def test_zero_ray_batch_gives_finite_losses() -> None:
    sigma = torch.zeros(0, 32, requires_grad=True)
    assert math.isfinite(float(occlusion_penalty(sigma, 20 / 128, 1.0).detach()))
    assert math.isfinite(float(losses.mse(torch.zeros(0, 3), torch.zeros(0, 3))))


@pytest.mark.parametrize("training", [True, False], ids=["training", "eval"])
@pytest.mark.parametrize("scene", ["blender", "ndc"])
def test_zero_ray_forward_is_empty_and_finite(scene: str, training: bool) -> None:
    """Zero rays through the model give empty outputs, not errors (the data manager never asks for such a batch):
    rgb [0, 3], accumulation and depth [0] in the input's dtype; the field is never queried; the ray terms of a loss
    built from them are exactly 0 (not NaN), and backward runs, with zero-size gradients for the rays."""
    model = blender_model() if scene == "blender" else ndc_model(model_config())
    queried = []
    density, rgb = model.field.density, model.field.rgb
    model.field.density = lambda xyz: queried.append(xyz.shape[0]) or density(xyz)  # type: ignore[method-assign]
    model.field.rgb = lambda xyz, d: queried.append(xyz.shape[0]) or rgb(xyz, d)  # type: ignore[method-assign]
    origins = torch.zeros(0, 3, requires_grad=True)
    directions = torch.zeros(0, 3, requires_grad=True)

    out = render(model, origins, directions, training=training)
    assert queried == [], "nothing to march: the field must not be evaluated"
    for key, shape in (("rgb", (0, 3)), ("accumulation", (0,)), ("depth", (0,))):
        assert tuple(out[key].shape) == shape and out[key].dtype == torch.float32, key
    assert ("occlusion" in out) == (training and scene == "ndc")

    terms = model.loss_dict(out, torch.zeros(0, 4), 0)
    assert float(terms["mse"].detach()) == 0.0
    if "occlusion" in out:
        assert float(out["occlusion"].detach()) == 0.0 and float(terms["occlusion"].detach()) == 0.0
    ray_terms = terms["mse"] + terms.get("occlusion", 0.0) + out["depth"].sum() + out["accumulation"].sum()
    ray_grads = torch.autograd.grad(
        ray_terms, (origins, directions), retain_graph=True, allow_unused=True, materialize_grads=True
    )
    assert [tuple(g.shape) for g in ray_grads] == [(0, 3), (0, 3)]
    grads = backprop(model, out)  # the training loss (MSE + TV + L1, finite) plus a depth term
    assert grads and all(bool(torch.isfinite(g).all()) for g in grads.values())


@pytest.mark.parametrize("scene", ["blender", "ndc"])
def test_zero_ray_render_is_empty(scene: str) -> None:
    """``render_rays`` of no rays returns empty images (it chunks the rays; no chunk must not mean no output)."""
    model = blender_model() if scene == "blender" else ndc_model(model_config())
    out = model.render_rays(torch.zeros(0, 3), torch.zeros(0, 3), step=0)
    assert {k: tuple(v.shape) for k, v in out.items()} == {"rgb": (0, 3), "accumulation": (0,), "depth": (0,)}
    assert model.training, "render_rays restores the mode it found"
