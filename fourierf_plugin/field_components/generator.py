"""ZeroRF's deep image prior: untrained convolutional generators map fixed noise to the factors of a VM grid.

Why: a few views leave a free grid under-determined; a convolutional generator can only produce smooth, structured
feature maps early in training, which is ZeroRF's regulariser (Shi et al., CVPR 2024, "ZeroRF: Fast Sparse View 360°
Reconstruction with Zero Pretraining"). The grid the rest of the pipeline reads is an output, not a parameter.

Followed (the paper and its public code, eliphatfs/zerorf: ``lib/models/zerorf/generators.py`` and ``arch_1d.py``,
``lib/models/architecture/diffusers.py`` (its ``VAEDecoder``), ``zerorf.py`` and ``opt.py``):

* one generator per factor, three planes and three lines, each with its own fixed Gaussian noise of 8 channels, and
  16 output channels per factor (``TensorialGenerator`` with ``tensor_config`` xy, z, yz, x, zx, y);
* planes, a VAE-decoder network: conv_in → mid block (residual block, single-head self-attention, residual block) →
  five up blocks of two residual blocks at 256/128/64/64/32 channels, the first four ending in a nearest ×2 upsample
  and a 3×3 conv → GroupNorm, SiLU, conv_out; GroupNorm(32, eps 1e-6) and SiLU throughout; Kaiming-normal (fan-out)
  convolutions with zero biases, and the second conv of every residual block and the attention's output projection
  zeroed (each block starts as the identity);
* lines (``Decoder1D``): conv_in, five stages of (3-tap conv, GroupNorm(16), SiLU, linear resize) to 2, 4, 8, 16 and 16
  times the noise length at 128/128/128/64/32/32 channels, conv_out and a final SiLU, no biases;
* the canvas is 2^4 = 16 times the noise per axis (ZeroRF: noise 20 → 320² planes).

Where this differs, and why:

* **Coarse-to-fine and the shrink.** ZeroRF's grid is fixed; this pipeline upsamples it and crops it to the occupied
  box. The generators draw a *canvas* over the box the run starts with; the factors the sampler, occupancy grid and
  lookups see are the canvas resampled (bilinear, corners aligned) at the grid's current vertices. Upsampling
  regenerates the factors at the new resolution from the canvas; the shrink narrows the window the factors are read
  from. Both keep what was learned exactly where it was (re-drawing the canvas over a smaller box would stretch it).
* **Box shape.** ZeroRF's boxes are cubes; here each axis' noise length follows the box (the final grid's aspect).
* **Canvas size.** By default the smallest canvas at least as fine as the final grid (lego on a CPU: 128² planes),
  so the three methods share one grid; ZeroRF sizes the noise at about 1/40 of the image side instead
  (``noise_resolution``).
* **Initialisation** draws from the run's generator (seeded, reproducible), not the global one.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from fourierf_plugin.configs.base import InstantiateConfig
from fourierf_plugin.field_components.tensor_grids import GRID_SAMPLE, MAT_MODES, VEC_MODES, FactorLookup, vm_features

PLANE_GROUPS = 32
"""GroupNorm groups of the plane generators (the VAE decoder's); every plane width must be a multiple."""
LINE_GROUPS = 16
"""GroupNorm groups of the line generators (``Decoder1D``'s); every line width must be a multiple."""
PLANE_NORM_EPS = 1e-6


@dataclass
class ZeroRFConfig(InstantiateConfig):
    """The field's factors as outputs of ZeroRF's generators, decoded by ZeroRF's decoder (``models.zerorf``)."""

    _target: ClassVar[type | None] = None  # GeneratedVM, set below its definition
    noise_channels: int = 8
    """Channels of each generator's fixed noise (ZeroRF's --model-ch)."""
    feature_channels: int = 16
    """Channels of every generated plane and line (ZeroRF: 16; the decoder reads 3 × this)."""
    noise_resolution: int = 0
    """Noise length along the box's longest axis (ZeroRF's --model-res; the canvas is 2^(levels) times it);
    0 = the smallest canvas at least as fine as the final grid."""
    plane_channels: tuple[int, ...] = (256, 128, 64, 64, 32)
    """Widths of the plane generators' up blocks, coarse to fine (one ×2 upsample between two; multiples of 32)."""
    line_channels: tuple[int, ...] = (128, 128, 128, 64, 32, 32)
    """Widths of the line generators: conv_in's, then one per stage (at least two; multiples of 16 after the first)."""
    attention: bool = True
    """Self-attention in the plane generators' mid block (the VAE decoder has it)."""
    decoder_width: int = 64
    """Hidden width of ZeroRF's decoder (density and colour heads on one shared layer)."""

    @property
    def upsample_levels(self) -> int:
        return len(self.plane_channels) - 1


def invalid_options(config: ZeroRFConfig) -> list[tuple[str, str]]:
    """(option, what it must be) for every setting the generators cannot be built with; empty when all are valid."""
    problems = []

    def positive(name: str) -> None:
        value = getattr(config, name)
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            problems.append((name, "an integer >= 1"))

    for name in ("noise_channels", "feature_channels", "decoder_width"):
        positive(name)
    noise = config.noise_resolution
    if isinstance(noise, bool) or not isinstance(noise, int) or noise < 0:
        problems.append(("noise_resolution", "an integer >= 1, or 0 for a canvas as fine as the final grid"))
    planes, lines = tuple(config.plane_channels), tuple(config.line_channels)
    if not planes or any(not isinstance(c, int) or c < PLANE_GROUPS or c % PLANE_GROUPS for c in planes):
        problems.append(("plane_channels", f"one or more widths, each a positive multiple of {PLANE_GROUPS}"))
    stages = lines[1:]
    if (
        len(lines) < 2
        or any(not isinstance(c, int) or c < 1 for c in lines[:1])
        or any(not isinstance(c, int) or c < LINE_GROUPS or c % LINE_GROUPS for c in stages)
    ):
        problems.append(("line_channels", f"two or more widths >= 1, those after the first multiples of {LINE_GROUPS}"))
    return problems


def noise_lengths(config: ZeroRFConfig, final_reso: Sequence[int]) -> list[int]:
    """Noise length per axis: a canvas of ``2^levels`` times it covers the final grid (``noise_resolution`` 0), or
    ``noise_resolution`` along the longest axis and the others in the final grid's proportions."""
    scale = 2**config.upsample_levels
    if config.noise_resolution == 0:
        return [max(1, math.ceil(int(r) / scale)) for r in final_reso]
    longest = max(int(r) for r in final_reso)
    return [max(1, round(config.noise_resolution * int(r) / longest)) for r in final_reso]


def parameter_count(config: ZeroRFConfig) -> int:
    """Weights of the six generators (what a checkpoint and the optimiser hold), without building them."""
    c_in, c_out, widths, lines = (
        config.noise_channels,
        config.feature_channels,
        config.plane_channels,
        config.line_channels,
    )

    def conv(a: int, b: int, taps: int, bias: bool = True) -> int:
        return a * b * taps + (b if bias else 0)

    def residual(a: int, b: int) -> int:
        return 2 * a + conv(a, b, 9) + 2 * b + conv(b, b, 9) + (conv(a, b, 1) if a != b else 0)

    w0 = widths[0]
    plane = conv(c_in, w0, 9) + 2 * residual(w0, w0) + ((2 * w0 + 4 * (w0 * w0 + w0)) if config.attention else 0)
    previous = w0
    for i, width in enumerate(widths):
        plane += (
            residual(previous, width) + residual(width, width) + (conv(width, width, 9) if i < len(widths) - 1 else 0)
        )
        previous = width
    plane += 2 * widths[-1] + conv(widths[-1], c_out, 9)
    line = conv(c_in, lines[0], 3, bias=False) + conv(lines[-1], c_out, 3, bias=False)
    line += sum(conv(a, b, 3, bias=False) + 2 * b for a, b in itertools.pairwise(lines))
    return 3 * (plane + line)


# -- building blocks ---------------------------------------------------------------------------------------------------
class ResidualBlock(nn.Module):
    """GroupNorm, SiLU, 3×3 conv, twice, plus the input (1×1-projected when the width changes)."""

    def __init__(self, in_channels: int, out_channels: int) -> None:
        super().__init__()
        self.norm1 = nn.GroupNorm(PLANE_GROUPS, in_channels, eps=PLANE_NORM_EPS)
        self.conv1 = nn.Conv2d(in_channels, out_channels, 3, padding=1)
        self.norm2 = nn.GroupNorm(PLANE_GROUPS, out_channels, eps=PLANE_NORM_EPS)
        self.conv2 = nn.Conv2d(out_channels, out_channels, 3, padding=1)
        self.skip = nn.Conv2d(in_channels, out_channels, 1) if in_channels != out_channels else None

    def forward(self, x: Tensor) -> Tensor:
        h = self.conv1(F.silu(self.norm1(x)))
        h = self.conv2(F.silu(self.norm2(h)))
        return (x if self.skip is None else self.skip(x)) + h


class SelfAttention(nn.Module):
    """Single-head self-attention over the pixels of a [1, C, H, W] map, added to its input."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.norm = nn.GroupNorm(PLANE_GROUPS, channels, eps=PLANE_NORM_EPS)
        self.query = nn.Linear(channels, channels)
        self.key = nn.Linear(channels, channels)
        self.value = nn.Linear(channels, channels)
        self.out = nn.Linear(channels, channels)

    def forward(self, x: Tensor) -> Tensor:
        b, c, h, w = x.shape
        tokens = self.norm(x).reshape(b, c, h * w).transpose(1, 2)  # [B, HW, C]
        q, k, v = (layer(tokens).unsqueeze(1) for layer in (self.query, self.key, self.value))
        mixed = F.scaled_dot_product_attention(q, k, v).squeeze(1)
        return x + self.out(mixed).transpose(1, 2).reshape(b, c, h, w)


class PlaneGenerator(nn.Module):
    """Fixed noise [C_n, h, w] → a plane canvas [C, h·2^L, w·2^L] (L = ``len(widths) - 1``), a VAE decoder."""

    noise: Tensor

    def __init__(self, noise: Tensor, out_channels: int, widths: Sequence[int], attention: bool) -> None:
        super().__init__()
        self.register_buffer("noise", noise.unsqueeze(0).contiguous())
        self.conv_in = nn.Conv2d(noise.shape[0], widths[0], 3, padding=1)
        mid: list[nn.Module] = [ResidualBlock(widths[0], widths[0])]
        if attention:
            mid.append(SelfAttention(widths[0]))
        mid.append(ResidualBlock(widths[0], widths[0]))
        self.mid = nn.Sequential(*mid)
        self.blocks = nn.ModuleList()
        self.upsamples = nn.ModuleList()
        previous = widths[0]
        for i, width in enumerate(widths):
            self.blocks.append(nn.Sequential(ResidualBlock(previous, width), ResidualBlock(width, width)))
            if i < len(widths) - 1:
                self.upsamples.append(nn.Conv2d(width, width, 3, padding=1))
            previous = width
        self.norm_out = nn.GroupNorm(PLANE_GROUPS, widths[-1], eps=PLANE_NORM_EPS)
        self.conv_out = nn.Conv2d(widths[-1], out_channels, 3, padding=1)

    def forward(self) -> Tensor:
        x = self.mid(self.conv_in(self.noise))
        for i, block in enumerate(self.blocks):
            x = block(x)
            if i < len(self.upsamples):
                x = self.upsamples[i](F.interpolate(x, scale_factor=2.0, mode="nearest"))
        return self.conv_out(F.silu(self.norm_out(x)))[0]


class LineGenerator(nn.Module):
    """Fixed noise [C_n, n] → a line canvas [C, n·2^L]: (conv, GroupNorm, SiLU, linear resize) stages, ``Decoder1D``."""

    noise: Tensor

    def __init__(self, noise: Tensor, out_channels: int, widths: Sequence[int], levels: int) -> None:
        super().__init__()
        self.register_buffer("noise", noise.unsqueeze(0).contiguous())
        n = noise.shape[-1]
        stages = len(widths) - 1
        self.sizes = [n * 2 ** min(k, levels) for k in range(1, stages + 1)]
        self.sizes[-1] = n * 2**levels  # the canvas, whatever the number of stages
        self.conv_in = nn.Conv1d(noise.shape[0], widths[0], 3, padding=1, bias=False)
        self.stages = nn.ModuleList(
            nn.Sequential(
                nn.Conv1d(widths[k], widths[k + 1], 3, padding=1, bias=False),
                nn.GroupNorm(LINE_GROUPS, widths[k + 1]),
                nn.SiLU(),
            )
            for k in range(stages)
        )
        self.conv_out = nn.Conv1d(widths[-1], out_channels, 3, padding=1, bias=False)

    def forward(self) -> Tensor:
        x = self.conv_in(self.noise)
        for stage, size in zip(self.stages, self.sizes, strict=True):
            x = F.interpolate(stage(x), size=size, mode="linear", align_corners=False)
        return F.silu(self.conv_out(x))[0]


def _initialise(module: nn.Module, generator: torch.Generator) -> None:
    """ZeroRF's initialisation, drawn from ``generator``: plane convs Kaiming-normal (fan-out) with zero biases and
    every residual block's last conv and attention output zeroed; line convs and attention projections PyTorch's
    default (Kaiming-uniform, a = √5)."""
    for m in module.modules():
        if isinstance(m, PlaneGenerator):
            for conv in (c for c in m.modules() if isinstance(c, nn.Conv2d)):
                nn.init.kaiming_normal_(conv.weight, mode="fan_out", nonlinearity="relu", generator=generator)
                nn.init.zeros_(conv.bias)
            for block in (b for b in m.modules() if isinstance(b, ResidualBlock)):
                nn.init.zeros_(block.conv2.weight)
                nn.init.zeros_(block.conv2.bias)
        elif isinstance(m, (nn.Conv1d, nn.Linear)):
            nn.init.kaiming_uniform_(m.weight, a=math.sqrt(5.0), generator=generator)
            if m.bias is not None:
                bound = 1.0 / math.sqrt(m.weight.shape[1] * math.prod(m.weight.shape[2:]))
                nn.init.uniform_(m.bias, -bound, bound, generator=generator)
    for attention in (a for a in module.modules() if isinstance(a, SelfAttention)):
        nn.init.zeros_(attention.out.weight)
        nn.init.zeros_(attention.out.bias)


# -- the generated grid -----------------------------------------------------------------------------------------------
class GeneratedVM(nn.Module):
    """A VM grid whose planes and lines are generator outputs, read at the grid's current resolution and box.

    Layout as ``TensorVM``: plane i pairs axes ``MAT_MODES[i] = (m0, m1)`` as [C, R[m1], R[m0]], line i runs along
    ``VEC_MODES[i]`` as [C, R[v]]. The canvas spans ``canvas_box`` (the box at the start); ``factors(box)`` reads the
    window of ``box`` at ``resolution``. ``resize`` changes the resolution; the box is the caller's (the field's).
    """

    plane_axes: tuple[tuple[int, int], ...] = MAT_MODES
    line_axes: tuple[int, ...] = VEC_MODES
    canvas_box: Tensor
    reso: Tensor

    def __init__(
        self,
        config: ZeroRFConfig,
        canvas_box: Tensor,
        reso: Sequence[int],
        final_reso: Sequence[int],
        generator: torch.Generator,
    ) -> None:
        super().__init__()
        problems = invalid_options(config)
        if problems:
            listed = "; ".join(f"{name} must be {need}" for name, need in problems)
            raise ValueError(f"invalid ZeroRF options: {listed}")
        self.config = config
        levels = config.upsample_levels
        noise = noise_lengths(config, final_reso)
        self.planes = nn.ModuleList(
            PlaneGenerator(
                torch.randn(config.noise_channels, noise[m1], noise[m0], generator=generator),
                config.feature_channels,
                config.plane_channels,
                config.attention,
            )
            for m0, m1 in MAT_MODES
        )
        self.lines = nn.ModuleList(
            LineGenerator(
                torch.randn(config.noise_channels, noise[v], generator=generator),
                config.feature_channels,
                config.line_channels,
                levels,
            )
            for v in VEC_MODES
        )
        _initialise(self, generator)
        self.canvas_resolution = [n * 2**levels for n in noise]
        self.register_buffer("canvas_box", canvas_box.detach().clone().float())
        self.register_buffer("reso", torch.tensor([int(r) for r in reso], dtype=torch.long))
        self._host_reso: tuple[tuple[int, int], list[int]] | None = None

    @property
    def resolution(self) -> list[int]:
        """Per-axis vertex counts of the grid the pipeline sees (read from the device once per resize)."""
        key = (id(self.reso), self.reso._version)
        if self._host_reso is None or self._host_reso[0] != key:
            self._host_reso = (key, [int(r) for r in self.reso.tolist()])
        return list(self._host_reso[1])

    def resize(self, reso: Sequence[int]) -> None:
        """Read the factors at ``reso`` vertices per axis from now on (an upsample, or the vertex count of a crop)."""
        if len(reso) != 3 or any(int(r) < 2 for r in reso):
            raise ValueError(f"a grid needs 3 resolutions >= 2, got {list(reso)}")
        self.reso = torch.tensor([int(r) for r in reso], dtype=torch.long, device=self.reso.device)

    def canvases(self) -> tuple[list[Tensor], list[Tensor]]:
        """The generators' outputs: plane canvases [C, H_c, W_c] and line canvases [C, L_c] over ``canvas_box``."""
        return [g() for g in self.planes], [g() for g in self.lines]

    def factors(self, box: Tensor) -> tuple[list[Tensor], list[Tensor]]:
        """Planes [C, R[m1], R[m0]] and lines [C, R[v]] over ``box`` (inside the canvas box) at ``resolution``."""
        planes, lines = self.canvases()
        coords = self._vertex_coords(box)
        out_planes = [_resample_plane(p, coords[m0], coords[m1]) for p, (m0, m1) in zip(planes, MAT_MODES, strict=True)]
        out_lines = [_resample_line(x, coords[v]) for x, v in zip(lines, VEC_MODES, strict=True)]
        return out_planes, out_lines

    def _vertex_coords(self, box: Tensor) -> list[Tensor]:
        """The grid's vertices along each axis in the canvas' normalised coordinates ([-1, 1] = the canvas box)."""
        lo, hi = self.canvas_box[0], self.canvas_box[1]
        window = (box.to(lo.dtype) - lo) * (2.0 / (hi - lo)) - 1.0  # [2, 3]: the box's corners on the canvas
        steps = [torch.linspace(0.0, 1.0, r, device=lo.device, dtype=lo.dtype) for r in self.resolution]
        return [window[0, a] + (window[1, a] - window[0, a]) * steps[a] for a in range(3)]

    def features(
        self, planes: Sequence[Any], lines: Sequence[Any], xyz: Tensor, lookup: FactorLookup = GRID_SAMPLE
    ) -> list[Tensor]:
        """Per-component features [N, C] of each plane × line group at normalised points (as ``TensorVM``)."""
        return vm_features(planes, lines, xyz, lookup)


ZeroRFConfig._target = GeneratedVM


def _resample_plane(canvas: Tensor, u: Tensor, v: Tensor) -> Tensor:
    """Bilinear samples (corners aligned, border-clamped) of a [C, H, W] canvas at the grid u (→ W) × v (→ H)."""
    grid = torch.stack(torch.broadcast_tensors(u.view(1, -1), v.view(-1, 1)), dim=-1).unsqueeze(0)
    return F.grid_sample(canvas.unsqueeze(0), grid, mode="bilinear", align_corners=True, padding_mode="border")[0]


def _resample_line(canvas: Tensor, coords: Tensor) -> Tensor:
    """Linear samples (corners aligned, border-clamped) of a [C, L] canvas at normalised ``coords`` -> [C, R]."""
    return _resample_plane(canvas.unsqueeze(-1), torch.zeros_like(coords[:1]), coords)[:, :, 0]
