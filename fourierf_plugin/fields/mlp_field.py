"""An MLP radiance field (NeRF / mip-NeRF's network) read through FreeNeRF's masked positional encoding.

The trunk is ``depth`` ReLU layers of ``width`` with the encoded input concatenated again after layer ``skip``; a
linear density head (softplus of the raw value plus ``density_bias``, with Gaussian noise on the raw value in
training where ``density_noise`` > 0) and a colour branch (a bottleneck, the encoded view direction, one layer of
``view_width``, a sigmoid stretched by ``rgb_padding``). Weights are Glorot-uniform, biases zero.

``prepare(f_density, f_color)`` takes the share of the encoding's bands that is visible (``frequency_mask``), the
positions' and the directions' alike, so the model's schedule, the viewer's sliders and the mesh export's frequency
cap act on it as they act on a grid's cutoff. The PE reads positions in a box fixed at construction; ``crop`` only
narrows where rays are sampled, and ``upsample`` only refines the grid the sampler steps and the occupancy grid use:
neither touches a parameter.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from fourierf_plugin.field_components.frequency_mask import band_mask, encode, encoded_width
from fourierf_plugin.fields.grid_ops import FilteredFactors
from fourierf_plugin.fields.prepared_field import FilteredGrids, PreparedField


@dataclass
class MLPFieldConfig:
    """The network and the frequency regularisation of ``freenerf`` (FreeNeRF's values)."""

    depth: int = 8
    """Layers of the trunk (NeRF, mip-NeRF: 8)."""
    width: int = 256
    """Width of the trunk (NeRF, mip-NeRF: 256)."""
    skip: int = 4
    """The encoded input joins the trunk again after this layer (NeRF, mip-NeRF: 4); 0 = never."""
    view_width: int = 128
    """Width of the colour branch's layer (NeRF, mip-NeRF: 128)."""
    position_bands: int = 10
    """Encoding bands of the positions (FreeNeRF's Blender code, NeRF's PE: 10; its mip-NeRF base has 16 of an
    integrated encoding, whose cone width damps the high bands; plain PE at 16 would alias at these sample steps)."""
    direction_bands: int = 4
    """Encoding bands of the view directions (FreeNeRF: 4)."""
    ramp_fraction: float = 0.9
    """Fraction of the run over which the visible bands open from none to all (FreeNeRF: 90 %)."""
    density_bias: float = -1.0
    """Added to the raw density before the softplus (mip-NeRF: -1)."""
    density_noise: float = 0.0
    """Standard deviation of the noise on the raw density in training (FreeNeRF: 0 on Blender, 1 on LLFF)."""
    rgb_padding: float = 0.001
    """The sigmoid is stretched to [-padding, 1 + padding] (mip-NeRF: 0.001)."""


def _linear(n_in: int, n_out: int, generator: torch.Generator) -> nn.Linear:
    """A linear layer with Glorot-uniform weights and zero biases (mip-NeRF's initialisation), drawn from
    ``generator``."""
    layer = nn.Linear(n_in, n_out)
    with torch.no_grad():
        nn.init.xavier_uniform_(layer.weight, generator=generator)
        layer.bias.zero_()
    return layer


class MLPField(PreparedField):
    replaces_parameters = False

    def __init__(
        self,
        config: MLPFieldConfig,
        aabb: Tensor,
        reso: Sequence[int],
        view_dependent: bool,
        generator: torch.Generator,
        noise_generator: torch.Generator | None = None,
    ) -> None:
        """``aabb``: the box the encoding reads positions in (and, until a crop, the sampled box); ``reso``: the
        sampling grid; ``noise_generator``: where the density noise is drawn (on the device the field lives on)."""
        super().__init__(aabb, None)
        self.config = config
        self.register_buffer("encoding_box", aabb.detach().clone().float())
        self.register_buffer("reso", torch.tensor([int(r) for r in reso], dtype=torch.long))
        self.view_dependent = view_dependent
        self.recording = False
        self.recorded: Tensor | None = None
        self.noise_generator = noise_generator
        point_width = encoded_width(3, config.position_bands)
        self.direction_width = encoded_width(3, config.direction_bands) if view_dependent else 0
        widths = [point_width] + [config.width] * config.depth
        self.trunk = nn.ModuleList(
            _linear(widths[i] + (point_width if config.skip and i == config.skip + 1 else 0), config.width, generator)
            for i in range(config.depth)
        )
        self.density_head = _linear(config.width, 1, generator)
        self.bottleneck = _linear(config.width, config.width, generator)
        self.view_layer = _linear(config.width + self.direction_width, config.view_width, generator)
        self.rgb_head = _linear(config.view_width, 3, generator)

    # -- the frequency mask -------------------------------------------------------------------------------------
    def filter(self, f_density: float, f_color: float) -> FilteredGrids:
        """The band weights of the positions (at share ``f_density``) and of the directions (``f_color``)."""
        device = self.encoding_box.device
        rendering = not torch.is_grad_enabled()
        positions = FilteredFactors(
            [], [], rendering, {"mask": band_mask(f_density, self.config.position_bands, device)}
        )
        directions = FilteredFactors(
            [], [], rendering, {"mask": band_mask(f_color, self.config.direction_bands, device)}
        )
        return FilteredGrids(positions, directions, (f_density, f_color))

    # -- lookups ------------------------------------------------------------------------------------------------
    def encoded_points(self, xyz: Tensor) -> Tensor:
        """World points [N, 3] -> their masked encoding in the fixed encoding box, at [-1, 1]."""
        box = self.encoding_box
        unit = (xyz - box[0]) * (2.0 / (box[1] - box[0])) - 1.0
        return encode(unit, self.filtered.density.cache["mask"])

    def trunk_features(self, xyz: Tensor) -> Tensor:
        """The trunk's output [N, width] at world points."""
        inputs = self.encoded_points(xyz)
        x = inputs
        for i, layer in enumerate(self.trunk):
            if self.config.skip and i == self.config.skip + 1:
                x = torch.cat([x, inputs], dim=-1)
            x = F.relu(layer(x))
        return x

    def density(self, xyz: Tensor) -> Tensor:
        """σ ≥ 0 at world points [N, 3] -> [N]; while ``recording``, the trunk's output is kept in ``recorded`` for
        the colour of the same points (one pass through the trunk per sample, as NeRF's)."""
        trunk = self.trunk_features(xyz)
        if self.recording:
            self.recorded = trunk
        return self.density_from_trunk(trunk)

    def density_from_trunk(self, trunk: Tensor) -> Tensor:
        """σ ≥ 0 from the trunk's output [N, width] at the points (with the training noise on the raw value)."""
        raw = self.density_head(trunk).squeeze(-1)
        if self.training and self.config.density_noise > 0:
            noise = torch.randn(raw.shape, generator=self.noise_generator, device=raw.device, dtype=raw.dtype)
            raw = raw + self.config.density_noise * noise
        return F.softplus(raw + self.config.density_bias)

    def radiance(self, xyz: Tensor, directions: Tensor | None) -> tuple[Tensor, Tensor]:
        """σ [N] and colour [N, 3] at world points [N, 3] from one pass through the trunk (NeRF's network)."""
        trunk = self.trunk_features(xyz)
        return self.density_from_trunk(trunk), self.rgb_from_trunk(trunk, directions)

    def rgb(self, xyz: Tensor, directions: Tensor | None) -> Tensor:
        """Colour in [0, 1] (padded) at world points [N, 3]; ``directions`` unit [N, 3], read when view-dependent."""
        return self.rgb_from_trunk(self.trunk_features(xyz), directions)

    def rgb_from_trunk(self, trunk: Tensor, directions: Tensor | None) -> Tensor:
        """Colour from the trunk's output [N, width] at the points (``rgb`` without the trunk)."""
        x = self.bottleneck(trunk)
        if self.view_dependent:
            if directions is None:
                raise ValueError("a view-dependent MLP field needs the view directions")
            x = torch.cat([x, encode(directions, self.filtered.appearance.cache["mask"])], dim=-1)
        x = F.relu(self.view_layer(x))
        pad = self.config.rgb_padding
        return torch.sigmoid(self.rgb_head(x)) * (1 + 2 * pad) - pad

    # -- structure ----------------------------------------------------------------------------------------------
    @property
    def resolution(self) -> list[int]:
        return [int(r) for r in self.reso.tolist()]

    def crop(self, lo: Sequence[int], hi: Sequence[int], box: Tensor) -> None:
        """Sample only ``box`` from now on (vertices [lo, hi) of the sampling grid); the encoding keeps its box."""
        self.reso.copy_(torch.tensor([h - low for low, h in zip(lo, hi, strict=True)]))
        self.aabb.copy_(box)

    def upsample(self, reso: Sequence[int]) -> None:
        """Step the sampler and the occupancy grid at ``reso`` vertices per axis."""
        self.reso.copy_(torch.tensor([int(r) for r in reso]))

    def param_groups(self) -> dict[str, list[nn.Parameter]]:
        """One group, the networks', as FreeNeRF trains its MLP with one Adam."""
        return {"networks": list(self.parameters())}


def parameter_count(config: MLPFieldConfig, view_dependent: bool = True) -> int:
    """Weights and biases of an MLP field of ``config`` (each is one multiply-add per sample in a forward pass)."""
    point = encoded_width(3, config.position_bands)
    direction = encoded_width(3, config.direction_bands) if view_dependent else 0
    inputs = [point] + [config.width] * (config.depth - 1)
    if config.skip and config.skip + 1 < config.depth:
        inputs[config.skip + 1] += point
    layers = [(n, config.width) for n in inputs]
    layers += [(config.width, 1), (config.width, config.width), (config.width + direction, config.view_width)]
    layers.append((config.view_width, 3))
    return sum(n_in * n_out + n_out for n_in, n_out in layers)
