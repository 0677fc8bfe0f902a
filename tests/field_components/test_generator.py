"""ZeroRF's generators and decoder: factor shapes at every resolution and box, where the factors are read from the
canvas (so upsampling and the shrink keep what was learned in place), gradients, initialisation, bad options."""

from __future__ import annotations

import math

import pytest
import torch

from fourierf_plugin.field_components.generator import (
    GeneratedVM,
    ZeroRFConfig,
    invalid_options,
    noise_lengths,
    parameter_count,
)
from fourierf_plugin.field_components.schedules import n_to_reso
from fourierf_plugin.field_components.tensor_grids import MAT_MODES, VEC_MODES
from fourierf_plugin.field_components.zerorf_decoder import ZeroRFDecoder, trunc_exp
from fourierf_plugin.model_components.occupancy import shrink_bounds

SMALL = ZeroRFConfig(noise_channels=4, feature_channels=3, plane_channels=(64, 32, 32), line_channels=(16, 16, 16))
"""Narrow generators (two ×2 upsamples): the same code paths as ZeroRF's widths, in milliseconds."""
FLAT = ZeroRFConfig(attention=False, noise_channels=3, feature_channels=5, plane_channels=(64,), line_channels=(8, 32))
"""No upsample level and no attention: the canvas is the noise."""
BOX = torch.tensor([[-1.5, -1.0, -0.5], [1.5, 1.0, 0.75]])  # non-cubic: 3 × 2 × 1.25
SIZE = (BOX[1] - BOX[0]).tolist()


def _grid(config: ZeroRFConfig = SMALL, init: int = 12**3, final: int = 20**3, seed: int = 0) -> GeneratedVM:
    return config.setup(
        canvas_box=BOX,
        reso=n_to_reso(init, SIZE),
        final_reso=n_to_reso(final, SIZE),
        generator=torch.Generator().manual_seed(seed),
    )


def _assert_vm_shapes(planes: list[torch.Tensor], lines: list[torch.Tensor], reso: list[int], channels: int) -> None:
    for plane, (m0, m1) in zip(planes, MAT_MODES, strict=True):
        assert tuple(plane.shape) == (channels, reso[m1], reso[m0])
    for line, v in zip(lines, VEC_MODES, strict=True):
        assert tuple(line.shape) == (channels, reso[v])


def test_factors_have_the_vm_shapes_at_every_resolution_of_a_non_cubic_box() -> None:
    grid = _grid()
    init, final = n_to_reso(12**3, SIZE), n_to_reso(20**3, SIZE)
    assert len(set(init)) == 3, "precondition: three different axis lengths"
    assert grid.resolution == init
    _assert_vm_shapes(*grid.factors(BOX), init, 3)
    for reso in (n_to_reso(16**3, SIZE), final, [5, 31, 2]):
        grid.resize(reso)
        assert grid.resolution == list(reso)
        _assert_vm_shapes(*grid.factors(BOX), list(reso), 3)


def test_the_canvas_is_the_noise_times_two_per_level_and_covers_the_final_grid() -> None:
    grid = _grid()
    final = n_to_reso(20**3, SIZE)
    planes, lines = grid.canvases()
    canvas = grid.canvas_resolution
    assert canvas == [4 * n for n in noise_lengths(SMALL, final)]  # two ×2 upsamples
    assert all(c >= r for c, r in zip(canvas, final, strict=True)), "the canvas is at least as fine as the final grid"
    _assert_vm_shapes(planes, lines, canvas, 3)


def test_an_explicit_noise_size_sets_the_longest_axis_and_keeps_the_box_proportions() -> None:
    final = n_to_reso(20**3, SIZE)
    lengths = noise_lengths(ZeroRFConfig(noise_resolution=20, plane_channels=(256, 128)), final)
    assert max(lengths) == 20
    assert lengths == [round(20 * r / max(final)) for r in final]


def test_at_the_canvas_resolution_the_factors_are_the_canvas_itself() -> None:
    grid = _grid()
    grid.resize(grid.canvas_resolution)
    with torch.no_grad():
        planes, lines = grid.factors(BOX)
        canvas_planes, canvas_lines = grid.canvases()
    for a, b in zip(planes + lines, canvas_planes + canvas_lines, strict=True):
        torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-5)


def test_an_upsample_reads_the_same_canvas_at_more_vertices() -> None:
    """Vertex j of an R-grid is vertex 2j of the (2R-1)-grid: an upsample keeps every value where it was."""
    grid = _grid()
    reso = grid.resolution
    with torch.no_grad():
        coarse_planes, coarse_lines = grid.factors(BOX)
        grid.resize([2 * r - 1 for r in reso])
        fine_planes, fine_lines = grid.factors(BOX)
    for coarse, fine in zip(coarse_planes, fine_planes, strict=True):
        torch.testing.assert_close(fine[:, ::2, ::2], coarse, atol=1e-5, rtol=1e-5)
    for coarse, fine in zip(coarse_lines, fine_lines, strict=True):
        torch.testing.assert_close(fine[:, ::2], coarse, atol=1e-5, rtol=1e-5)


def test_a_crop_reads_the_window_of_the_uncropped_factors() -> None:
    """The occupancy shrink: factors over the new box at the cropped vertex count are the old factors' window."""
    grid = _grid()
    reso = grid.resolution
    occupied = torch.tensor([[-0.7, -0.2, -0.3], [0.9, 0.8, 0.1]])
    lo, hi, box = shrink_bounds(occupied, BOX, reso)
    with torch.no_grad():
        planes, lines = grid.factors(BOX)
        grid.resize([h - low for low, h in zip(lo, hi, strict=True)])
        cropped_planes, cropped_lines = grid.factors(box)
    assert grid.resolution != reso, "precondition: the crop changed the grid"
    _assert_vm_shapes(cropped_planes, cropped_lines, grid.resolution, 3)
    for plane, cropped, (m0, m1) in zip(planes, cropped_planes, MAT_MODES, strict=True):
        torch.testing.assert_close(cropped, plane[:, lo[m1] : hi[m1], lo[m0] : hi[m0]], atol=1e-5, rtol=1e-5)
    for line, cropped, v in zip(lines, cropped_lines, VEC_MODES, strict=True):
        torch.testing.assert_close(cropped, line[:, lo[v] : hi[v]], atol=1e-5, rtol=1e-5)


def test_the_noise_is_fixed_and_only_the_networks_are_parameters() -> None:
    grid = _grid()
    noise = {name for name, _ in grid.named_buffers() if name.endswith("noise")}
    assert len(noise) == 6, "one fixed noise per factor"
    assert not any(name.endswith("noise") for name, _ in grid.named_parameters())
    with torch.no_grad():
        first = grid.factors(BOX)
        second = grid.factors(BOX)
    for a, b in zip(first[0] + first[1], second[0] + second[1], strict=True):
        assert torch.equal(a, b), "the same noise and weights give the same factors"


def test_the_same_seed_gives_the_same_generators_and_another_seed_does_not() -> None:
    a, b, c = _grid(seed=3), _grid(seed=3), _grid(seed=4)
    for (name, x), y in zip(a.state_dict().items(), b.state_dict().values(), strict=True):
        assert torch.equal(x, y), name
    assert not all(torch.equal(x, z) for x, z in zip(a.state_dict().values(), c.state_dict().values(), strict=True))


def test_zerorf_initialisation_zeroes_every_residual_branch_end_and_the_attention_output() -> None:
    grid = _grid(ZeroRFConfig(plane_channels=(64, 32), line_channels=(16, 16)))
    zeroed = [p for name, p in grid.named_parameters() if ".conv2." in name or ".out." in name]
    assert zeroed and all(float(p.detach().abs().max()) == 0.0 for p in zeroed)
    convs = [p for name, p in grid.named_parameters() if name.endswith("conv1.weight")]
    assert convs and all(float(p.detach().std()) > 0.0 for p in convs)


def test_gradients_reach_every_generator_parameter() -> None:
    """At initialisation the zeroed residual ends block the branches behind them (ZeroRF's identity start); after a
    step every weight of every generator, the attention included, receives a gradient."""
    grid = _grid(ZeroRFConfig(noise_channels=4, feature_channels=3, plane_channels=(64, 32),
                              line_channels=(16, 16)))  # fmt: skip
    optimizer = torch.optim.Adam(grid.parameters(), lr=1e-2)
    target = torch.Generator().manual_seed(9)
    for _ in range(2):
        optimizer.zero_grad()
        planes, lines = grid.factors(BOX)
        loss = sum(((f - torch.randn(f.shape, generator=target)) ** 2).mean() for f in planes + lines)
        loss.backward()
        optimizer.step()
    for name, p in grid.named_parameters():
        assert p.grad is not None and float(p.grad.abs().max()) > 0.0, name


def test_fitting_the_factors_lowers_the_loss() -> None:
    grid = _grid()
    optimizer = torch.optim.Adam(grid.parameters(), lr=2e-3)
    planes_target = [torch.sin(torch.linspace(0, 6, p.shape[-1])).expand_as(p) for p in grid.factors(BOX)[0]]
    losses = []
    for _ in range(25):
        optimizer.zero_grad()
        planes, _ = grid.factors(BOX)
        loss = sum(((p - t) ** 2).mean() for p, t in zip(planes, planes_target, strict=True))
        loss.backward()
        optimizer.step()
        losses.append(float(loss.detach()))
    assert losses[-1] < 0.5 * losses[0]


@pytest.mark.parametrize(
    ("changes", "option"),
    [
        ({"noise_channels": 0}, "noise_channels"),
        ({"feature_channels": 0}, "feature_channels"),
        ({"decoder_width": 0}, "decoder_width"),
        ({"noise_resolution": -1}, "noise_resolution"),
        ({"plane_channels": ()}, "plane_channels"),
        ({"plane_channels": (256, 0)}, "plane_channels"),
        ({"plane_channels": (256, 48)}, "plane_channels"),  # GroupNorm's 32 groups do not divide 48 channels
        ({"line_channels": (128,)}, "line_channels"),
        ({"line_channels": (128, 24)}, "line_channels"),  # 16 groups do not divide 24
    ],
)
def test_bad_options_are_named(changes: dict, option: str) -> None:
    config = ZeroRFConfig(**changes)
    assert [name for name, _ in invalid_options(config)] == [option]
    with pytest.raises(ValueError, match=option):
        GeneratedVM(config, BOX, [8, 8, 8], [16, 16, 16], torch.Generator().manual_seed(0))


def test_the_defaults_are_zerorfs_and_valid() -> None:
    config = ZeroRFConfig()
    assert invalid_options(config) == []
    assert (config.noise_channels, config.feature_channels, config.upsample_levels) == (8, 16, 4)  # 16× canvas


# -- the decoder --------------------------------------------------------------------------------------------------
def test_trunc_exp_is_exp_with_a_clamped_gradient() -> None:
    x = torch.tensor([-20.0, 0.0, 3.0, 20.0, 200.0], requires_grad=True)
    y = trunc_exp(x)
    torch.testing.assert_close(y[:4], torch.exp(x[:4].detach()))
    assert torch.isfinite(y).all(), "a huge pre-activation stays finite"
    y.sum().backward()
    expected = torch.exp(torch.tensor([-15.0, 0.0, 3.0, 15.0, 15.0]))
    torch.testing.assert_close(x.grad, expected)


def test_the_decoder_starts_view_independent_and_its_colour_reaches_0_and_1() -> None:
    decoder = ZeroRFDecoder(6, 16, view_dependent=True, generator=torch.Generator().manual_seed(0))
    features = torch.randn(32, 6, generator=torch.Generator().manual_seed(1))
    hidden = decoder.hidden(features)
    d1 = torch.nn.functional.normalize(torch.randn(32, 3), dim=-1)
    d2 = torch.nn.functional.normalize(torch.randn(32, 3), dim=-1)
    assert torch.equal(decoder.rgb(hidden, d1), decoder.rgb(hidden, d2)), "the direction layer starts at zero"
    with torch.no_grad():
        decoder.color_head.bias[:] = 50.0
        assert float(decoder.rgb(hidden, d1).min()) > 1.0, "ZeroRF widens the sigmoid by 0.001 above 1 ..."
        decoder.color_head.bias[:] = -50.0
        assert float(decoder.rgb(hidden, d1).max()) < 0.0, "... and below 0, so both are reachable"
    sigma = decoder.density(hidden)
    assert sigma.shape == (32,) and bool((sigma > 0).all())
    with pytest.raises(ValueError, match="directions"):
        decoder.rgb(hidden, None)


def test_xavier_weights_and_zero_biases() -> None:
    decoder = ZeroRFDecoder(48, 64, view_dependent=False, generator=torch.Generator().manual_seed(0))
    assert decoder.view_layer is None
    bound = math.sqrt(6.0 / (48 + 64))
    weight = decoder.base.weight.detach()
    assert float(weight.abs().max()) <= bound
    assert float(weight.std()) > 0.5 * bound / math.sqrt(3.0)
    for layer in (decoder.base, decoder.density_head, decoder.color_head):
        assert float(layer.bias.detach().abs().max()) == 0.0


@pytest.mark.parametrize(
    "config",
    [
        ZeroRFConfig(),
        SMALL,
        FLAT,
    ],
)
def test_the_parameter_count_is_that_of_the_built_generators(config: ZeroRFConfig) -> None:
    grid = _grid(config)
    assert parameter_count(config) == sum(p.numel() for p in grid.parameters())
