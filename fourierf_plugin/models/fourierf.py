"""FourieRF model: fixed-step sampler over the occupancy grid, the Fourier-filtered field, compositing, losses.

All schedules (cutoffs, L1 weight, upsample and occupancy-update steps) are functions of the step and the run
length; the model changes its own structure in ``after_step`` and tells the caller when parameters were replaced
so the optimiser can be rebuilt. It never reaches into the trainer.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import ClassVar, Literal

import torch
from torch import Tensor, nn
from torch.utils.checkpoint import checkpoint

from fourierf_plugin.configs.base import InstantiateConfig
from fourierf_plugin.data.dataparser_base import Background, SceneDeclaration
from fourierf_plugin.field_components import schedules
from fourierf_plugin.fields.fourier_tensorf_field import FieldConfig, FourierTensoRFField
from fourierf_plugin.model_components import losses
from fourierf_plugin.model_components.gradient_scaling import floaters_scale, scale_gradient
from fourierf_plugin.model_components.occupancy import (
    OccupancyGrid,
    occupancy_from_alpha,
    occupied_aabb,
    shrink_bounds,
    vertex_grid,
)
from fourierf_plugin.model_components.ray_sampling import ray_box_span, sample_deltas, step_samples
from fourierf_plugin.model_components.rendering import (
    accumulate,
    background_color,
    blend_background,
    composite_target,
    composite_weights,
    expected_depth,
)
from fourierf_plugin.utils.console import get_console
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.utils.phases import phase


@dataclass
class FourierConfig:
    """The frequency curriculum: the kept share of the spectrum grows linearly from f0 to 1."""

    enabled: bool = True
    """False gives plain TensoRF (masks off) with the identical pipeline."""
    f0_density: float = 0.3
    """Initial cutoff for the density grids (paper, synthetic: 0.3; real: 0.01)."""
    f0_color: float = 0.3
    """Initial cutoff for the appearance grids."""
    ramp_fraction: float = 0.2
    """Fraction of the run after which the cutoff is fully open (paper, synthetic: 2000 of 10k iterations)."""
    plane_leakage: float = 0.0
    """Weight kept on out-of-band plane coefficients; the paper zeroes them, the official code keeps 1e-6."""
    app_planes_follow_density: bool = False
    """Official-code behaviour: appearance planes use the density cutoff instead of the colour cutoff."""


def resolve_effects(declared: SceneDeclaration, config: FourieRFModelConfig) -> SceneDeclaration:
    """The scene's declaration with the model config's explicit overrides (None = as declared) applied."""
    overrides = {
        "background": config.background,
        "ray_space": config.ray_space,
        "view_dependent": config.view_dependent,
        "occlusion_regularization": config.occlusion_regularization,
    }
    return dataclasses.replace(declared, **{k: v for k, v in overrides.items() if v is not None})


def occlusion_penalty(sigma: Tensor, fraction: float) -> Tensor:
    """FreeNeRF's occlusion term: mean over rays and all K samples of σ_k · 1[k < M], M = round(fraction · K).

    It penalises density right in front of the cameras, where few-shot training likes to paint floaters.
    """
    k = sigma.shape[-1]
    if sigma.shape[0] == 0 or k == 0:
        return sigma.sum()  # no rays: 0 with a graph, not the NaN of an empty mean
    m = max(1, round(fraction * k))
    return sigma[:, :m].sum(dim=-1).mean() / k


def _event_steps(fractions: tuple[float, ...], max_iters: int, flag: str) -> list[int]:
    """Steps of scheduled events; a schedule that does not fit the run is the user's to fix."""
    if not fractions:
        return []
    try:
        return schedules.steps_from_fractions(fractions, max_iters)
    except ValueError as err:
        fail(
            f"{flag} {' '.join(map(str, fractions))} does not fit a run of {max_iters} iterations ({err})",
            f"use fractions strictly between 0 and 1 and a --max-num-iterations long enough to place them "
            f"(at least {max(2, math.ceil(1 / min(fractions)))} here), or pass {flag} with no value to disable them",
        )


@dataclass
class Changes:
    """What ``after_step`` did, so the pipeline and trainer can follow."""

    params_replaced: bool = False
    filter_rays: bool = False


class FourieRFModel(nn.Module):
    config: FourieRFModelConfig

    def __init__(
        self,
        config: FourieRFModelConfig,
        scene_box: Tensor,
        near: float,
        far: float,
        declaration: SceneDeclaration,
        max_iters: int,
        generator: torch.Generator,
    ) -> None:
        super().__init__()
        self.config = config
        self.near, self.far = float(near), float(far)
        self.max_iters = int(max_iters)
        self.generator = generator
        self.effects = resolve_effects(declaration, config)
        self.background: Background = self.effects.background
        self.view_dependent = self.effects.view_dependent
        self.ray_space = self.effects.ray_space
        fc = config.field
        self.upsample_steps = _event_steps(
            fc.upsample_fractions, max_iters, "--pipeline.model.field.upsample-fractions"
        )
        self.voxel_targets = schedules.voxel_counts(fc.n_voxels_init, fc.n_voxels_final, len(self.upsample_steps))
        frac = config.occupancy_update_fractions
        self.occupancy_steps = _event_steps(frac, max_iters, "--pipeline.model.occupancy-update-fractions")
        reso = schedules.n_to_reso(fc.n_voxels_init, (scene_box[1] - scene_box[0]).tolist())
        self.field = FourierTensoRFField(fc, scene_box, reso, self.view_dependent, generator)
        self.occupancy = OccupancyGrid()

    # -- schedules (pure functions of the step) ---------------------------------------------------------------
    def cutoffs(self, step: int) -> tuple[float, float]:
        fc = self.config.fourier
        if not fc.enabled:
            return 1.0, 1.0
        ramp = round(fc.ramp_fraction * self.max_iters)
        return schedules.cutoff_at(step, fc.f0_density, ramp), schedules.cutoff_at(step, fc.f0_color, ramp)

    def reset_steps(self) -> list[int]:
        """Steps after which parameters are replaced (and the optimiser restarts at the initial lr)."""
        return sorted(set(self.upsample_steps) | set(self.occupancy_steps))

    def l1_weight(self, step: int) -> float:
        # The switch happens after the first update's own step, i.e. from the next step on.
        first = self.occupancy_steps[0] + 1 if self.occupancy_steps else None
        return schedules.l1_weight_at(step, first, self.config.l1_weight_initial, self.config.l1_weight_rest)

    # -- derived sampling parameters (from the current box and resolution) ------------------------------------
    @property
    def aabb(self) -> Tensor:
        return self.field.aabb

    def _box_size(self) -> list[float]:
        return (self.aabb[1] - self.aabb[0]).tolist()

    @property
    def step_size(self) -> float:
        return schedules.step_size(self._box_size(), self.field.resolution, self.config.step_ratio)

    def samples_per_ray(self, training: bool) -> int:
        if training:
            return schedules.train_samples_per_ray(self.field.resolution, self.config.step_ratio)
        return schedules.eval_samples_per_ray(self._box_size(), self.step_size)

    # -- forward ----------------------------------------------------------------------------------------------
    def prepare(self, step: int) -> None:
        """Filter the grids at this step's cutoffs once; call before ``forward`` (under no_grad for eval)."""
        f_d, f_c = self.cutoffs(step)
        fc = self.config.fourier
        with phase("fourier_filter"):
            self.field.prepare(f_d, f_c, fc.plane_leakage, fc.app_planes_follow_density)

    def forward(self, origins: Tensor, directions: Tensor, training: bool, background: Tensor | None = None) -> dict:
        """Render rays [R, 3] (unit directions; NDC directions as made). Returns rgb [R, 3], accumulation, depth [R]."""
        num_rays = origins.shape[0]
        device = origins.device
        if background is None:
            background = background_color(
                self.background if training else self._eval_background(), num_rays, device, self.generator
            )
        with phase("sampling"):
            if self.ray_space == "ndc":
                t, deltas = self._ndc_samples(origins, directions, training)
            else:
                t, deltas, t_exit = self._box_samples(origins, directions, training)
            num_samples = t.shape[1]
            xyz = torch.addcmul(origins.unsqueeze(1), directions.unsqueeze(1), t.unsqueeze(-1))
            if self.ray_space == "ndc":
                inside = ((xyz >= self.aabb[0]) & (xyz <= self.aabb[1])).all(dim=-1)
                directions = directions / directions.norm(dim=-1, keepdim=True)
            else:
                inside = t < t_exit.unsqueeze(-1)
            march_to_opacity = not training and self.config.eval_stop_transmittance > 0
            # Samples are addressed by flat indices into [R·N] from here on: boolean masks would run a nonzero
            # pass at every use (indexing, index_put and their backward), ~3x the cost of one index_select each.
            points = xyz.view(-1, 3)
            if not march_to_opacity:  # (the early-terminated march checks occupancy itself, for live rays only)
                valid, valid_points = self._occupied(points, inside.view(-1).nonzero().squeeze(1))
        with phase("density"):
            if march_to_opacity:
                sigma = self._density_until_opaque(xyz, inside, deltas)
            else:
                sigma = points.new_zeros(num_rays * num_samples)
                if valid.numel():
                    sigma = sigma.index_put((valid,), self.field.density(valid_points))
                sigma = sigma.view(num_rays, num_samples)
        grad_scale = floaters_scale(t) if self.config.floaters_gradient_scaling and training else None
        if grad_scale is not None:
            sigma = scale_gradient(sigma, grad_scale)
        with phase("compositing"):
            weights = composite_weights(sigma, deltas, self.config.distance_scale)
        with phase("appearance"):
            shade = (weights.detach().view(-1) > self.config.weight_threshold).nonzero().squeeze(1)
            rgb = weights.new_zeros(num_rays, 3)
            if shade.numel():
                ray_of = shade.div(num_samples, rounding_mode="floor")
                dirs = directions.index_select(0, ray_of) if self.view_dependent else None
                colors = self._colors(points.index_select(0, shade), dirs)
                if grad_scale is not None:
                    colors = scale_gradient(colors, grad_scale.view(-1, 1).index_select(0, shade))
                rgb = accumulate(weights.view(-1).index_select(0, shade), colors, ray_of, num_rays)
        with phase("compositing"):
            acc = weights.sum(dim=-1)
            rgb = blend_background(rgb, acc, background)
            if not training:
                rgb = rgb.clamp(0.0, 1.0)
            depth = expected_depth(weights, t, torch.full_like(acc, self.far))
        out = {"rgb": rgb, "accumulation": acc, "depth": depth, "background": background}
        if training and self.effects.occlusion_regularization:
            out["occlusion"] = occlusion_penalty(sigma, self.config.occlusion_fraction)
        return out

    def _colors(self, xyz: Tensor, directions: Tensor | None) -> Tensor:
        """The field's colour at [N, 3] points; in training with many points, in checkpointed chunks
        (``checkpoint_above``)."""
        above, chunk = self.config.checkpoint_above, self.config.checkpoint_chunk
        if not torch.is_grad_enabled() or above <= 0 or xyz.shape[0] <= above:
            return self.field.rgb(xyz, directions)
        parts = []
        for i in range(0, xyz.shape[0], chunk):
            dirs = directions[i : i + chunk] if directions is not None else None
            part = checkpoint(self.field.rgb, xyz[i : i + chunk], dirs, use_reentrant=False, preserve_rng_state=False)
            parts.append(part)
        return torch.cat(parts)

    def _occupied(self, points: Tensor, index: Tensor) -> tuple[Tensor, Tensor]:
        """The listed samples (flat ``index`` into ``points``) that lie in occupied cells: their indices and points."""
        selected = points.index_select(0, index)
        if not self.occupancy.active or not index.numel():
            return index, selected
        with phase("sampling"):
            keep = self.occupancy.query(selected).nonzero().squeeze(1)
        return index.index_select(0, keep), selected.index_select(0, keep)

    def _density_until_opaque(self, xyz: Tensor, inside: Tensor, deltas: Tensor) -> Tensor:
        """σ [R, N] marched in segments; a ray stops being queried once its transmittance falls below
        ``eval_stop_transmittance`` (early ray termination: what lies behind an opaque surface cannot show). Samples
        ``inside`` the box are checked against the occupancy grid segment by segment, for live rays only."""
        num_rays, num_samples = inside.shape
        sigma = xyz.new_zeros(num_rays, num_samples)
        points = xyz.view(-1, 3)
        depth = xyz.new_zeros(num_rays)
        max_depth = -math.log(self.config.eval_stop_transmittance)
        segment = self.config.eval_segment_samples
        for start in range(0, num_samples, segment):
            cols = slice(start, start + segment)
            alive = depth < max_depth
            if not alive.any():
                break
            live = (inside[:, cols] & alive.unsqueeze(-1)).view(-1).nonzero().squeeze(1)  # flat in [R, width]
            width = min(segment, num_samples - start)
            index = live.div(width, rounding_mode="floor") * num_samples + (live % width + start)  # flat in [R, N]
            index, selected = self._occupied(points, index)
            if not index.numel():
                continue
            sigma.view(-1).index_put_((index,), self.field.density(selected))
            depth = depth + (sigma[:, cols] * deltas[:, cols]).sum(dim=-1) * self.config.distance_scale
        return sigma

    def _box_samples(self, origins: Tensor, directions: Tensor, training: bool) -> tuple[Tensor, Tensor, Tensor]:
        """Fixed-step marching from the box entry (unit directions, metric t), per-ray jitter in training.

        Returns t and δ [R, N] and where each ray leaves the box [R].
        """
        num_rays = origins.shape[0]
        start, t_exit = ray_box_span(origins, directions, self.aabb, self.near, self.far)
        step = self.step_size
        span = ((t_exit - start) / step).clamp(min=0)
        needed = math.ceil(float(span.max())) + 1 if num_rays else 0
        num_samples = max(1, min(self.samples_per_ray(training), needed))
        jitter = torch.rand(num_rays, generator=self.generator).to(origins.device) if training else None
        t = step_samples(start, step, num_samples, jitter)
        return t, sample_deltas(t), t_exit

    def _ndc_samples(self, origins: Tensor, directions: Tensor, training: bool) -> tuple[Tensor, Tensor]:
        """NDC rays: t evenly spaced in [near, far] (= [0, 1]) with per-sample jitter in training; δ scaled by |d|."""
        num_rays, device = origins.shape[0], origins.device
        n = self.samples_per_ray(training)
        t = torch.linspace(self.near, self.far, n, device=device).expand(num_rays, n)
        if training:
            t = t + torch.rand(num_rays, n, generator=self.generator).to(device) * ((self.far - self.near) / n)
        return t, sample_deltas(t) * directions.norm(dim=-1, keepdim=True)

    def _eval_background(self) -> Background:
        """Renders for evaluation: random → white, none (photos) → black."""
        return {"random": "white", "none": "black"}.get(self.background, self.background)

    def loss_dict(self, outputs: dict, target_rgba: Tensor, step: int) -> dict[str, Tensor]:
        """Photometric MSE plus the regularisers, all on this iteration's filtered grids."""
        target = composite_target(target_rgba, outputs["background"])
        g = self.field.filtered
        c = self.config
        out = {"mse": losses.mse(outputs["rgb"], target)}
        if c.tv_weight_density > 0:
            out["tv_density"] = c.tv_weight_density * losses.grid_tv(g.density_planes, g.density_lines)
        if c.tv_weight_appearance > 0:
            out["tv_appearance"] = c.tv_weight_appearance * losses.grid_tv(g.appearance_planes, g.appearance_lines)
        l1 = self.l1_weight(step)
        if l1 > 0:
            out["l1_density"] = l1 * losses.density_l1(g.density_planes, g.density_lines)
        if "occlusion" in outputs and c.occlusion_weight > 0:
            out["occlusion"] = c.occlusion_weight * outputs["occlusion"]
        return out

    @torch.no_grad()
    def render_rays(
        self, origins: Tensor, directions: Tensor, step: int, chunk: int | None = None
    ) -> dict[str, Tensor]:
        """Evaluation render in chunks (no jitter, clamped colour) at the cutoffs of ``step``."""
        self.prepare(step)
        chunk = chunk or self.config.eval_chunk_rays
        parts = [
            self.forward(origins[i : i + chunk], directions[i : i + chunk], training=False)
            for i in range(0, origins.shape[0], chunk)
        ]
        return {k: torch.cat([p[k] for p in parts]) for k in ("rgb", "accumulation", "depth")}

    # -- structure changes --------------------------------------------------------------------------------------
    @torch.no_grad()
    def after_step(self, step: int) -> Changes:
        """Occupancy updates (the first shrinks the box, the second asks for ray filtering) and upsamples."""
        changes = Changes()
        if step in self.occupancy_steps:
            self.prepare(step + 1)
            first = step == self.occupancy_steps[0]
            self._update_occupancy(shrink=first)
            changes.params_replaced = True
            # Ray filtering needs metric rays through a box; NDC rays all cross the frustum (TensoRF skips it too).
            second = len(self.occupancy_steps) > 1 and step == self.occupancy_steps[1]
            changes.filter_rays = second and self.ray_space == "euclidean"
        if step in self.upsample_steps:
            self.prepare(step + 1)
            target = self.voxel_targets[self.upsample_steps.index(step)]
            self._upsample(schedules.n_to_reso(target, self._box_size()))
            changes.params_replaced = True
        if changes.params_replaced:
            self.field.invalidate()
        return changes

    def _dense_alpha(self, reso: list[int], chunk: int = 65536) -> Tensor:
        """Alpha 1 - exp(-σ step) at the grid vertices (TensoRF's mask criterion, no distance scale)."""
        xyz = vertex_grid(self.aabb, reso).reshape(-1, 3)
        alpha = torch.zeros(xyz.shape[0], device=xyz.device)
        step = self.step_size
        for i in range(0, xyz.shape[0], chunk):
            pts = xyz[i : i + chunk]
            keep = self.occupancy.query(pts)
            if keep.any():
                sigma = self.field.density(pts[keep])
                alpha[i : i + chunk][keep] = -torch.expm1(-sigma * step)
        return alpha.view(*reso)

    def _update_occupancy(self, shrink: bool) -> None:
        reso = self.field.resolution
        vertices = occupancy_from_alpha(self._dense_alpha(reso), self.config.occupancy_threshold)
        box = occupied_aabb(vertices, self.aabb)
        if box is None:
            get_console().print(
                "[yellow]warning:[/yellow] the occupancy grid is empty (no density above the threshold); "
                "keeping the previous box and sampling everywhere"
            )
            return
        self.occupancy.set(vertices, self.aabb)
        if shrink:
            lo, hi, new_box = shrink_bounds(box, self.aabb, reso)
            for grid in (self.field.density_grid, self.field.appearance_grid):
                grid.replace(*grid.cropped(lo, hi))
            self.field.aabb = new_box

    def _upsample(self, reso: list[int]) -> None:
        """Replace each raw factor by the bilinear upsample of its *filtered* version (out-of-band is dropped)."""
        g = self.field.filtered
        for grid, planes, lines in (
            (self.field.density_grid, g.density_planes, g.density_lines),
            (self.field.appearance_grid, g.appearance_planes, g.appearance_lines),
        ):
            grid.replace(*grid.upsampled(planes, lines, reso))

    @torch.no_grad()
    def rays_hit_occupancy(
        self, origins: Tensor, directions: Tensor, num_samples: int = 256, chunk: int = 8192
    ) -> Tensor:
        """Bool [R]: the ray passes through an occupied cell at any of ``num_samples`` evenly spaced points."""
        keep = torch.zeros(origins.shape[0], dtype=torch.bool, device=origins.device)
        for i in range(0, origins.shape[0], chunk):
            o, d = origins[i : i + chunk], directions[i : i + chunk]
            start, t_exit = ray_box_span(o, d, self.aabb, self.near, self.far)
            frac = torch.linspace(0.0, 1.0, num_samples, device=o.device)
            t = start.unsqueeze(-1) + (t_exit - start).clamp(min=0).unsqueeze(-1) * frac
            xyz = o.unsqueeze(1) + d.unsqueeze(1) * t.unsqueeze(-1)
            hit = self.occupancy.query(xyz.reshape(-1, 3)).view(-1, num_samples).any(dim=-1)
            keep[i : i + chunk] = hit & (t_exit > start)
        return keep

    # -- parameters and checkpoints -----------------------------------------------------------------------------
    def param_groups(self) -> dict[str, list[nn.Parameter]]:
        grids = list(self.field.density_grid.parameters()) + list(self.field.appearance_grid.parameters())
        networks = list(self.field.basis.parameters()) + list(self.field.decoder.parameters())
        return {"grids": grids, "networks": networks}

    def load_state_dict(self, state_dict, strict: bool = True, assign: bool = False):  # type: ignore[override]
        """Load a checkpoint taken after any number of upsamples/shrinks: tensors are resized to the saved shapes."""
        own = dict(self.named_parameters()) | dict(self.named_buffers())
        for name, value in state_dict.items():
            if name in own and own[name].shape != value.shape:
                module_name, _, attr = name.rpartition(".")
                module = self.get_submodule(module_name)
                blank = torch.empty_like(value, device=own[name].device)
                setattr(module, attr, nn.Parameter(blank) if isinstance(own[name], nn.Parameter) else blank)
        self.field.invalidate()
        return super().load_state_dict(state_dict, strict=strict, assign=assign)


@dataclass
class FourieRFModelConfig(InstantiateConfig):
    """Sampler, field, renderer and losses of FourieRF (and of TensoRF with ``fourier.enabled False``)."""

    _target: ClassVar[type] = FourieRFModel
    field: FieldConfig = dataclasses.field(default_factory=FieldConfig)
    fourier: FourierConfig = dataclasses.field(default_factory=FourierConfig)
    occupancy_update_fractions: tuple[float, ...] = (0.2, 0.4)
    """When to rebuild the occupancy grid (fractions of the run); the first shrinks the box, the second filters rays."""
    occupancy_threshold: float = 1e-4
    """Alpha (after a 3³ dilation) above which a grid vertex counts as occupied."""
    step_ratio: float = 0.5
    """Sampling step in voxels."""
    distance_scale: float = 25.0
    """Multiplies σδ in compositing (TensoRF's distance_scale)."""
    weight_threshold: float = 1e-4
    """Colour is evaluated only at samples whose weight exceeds this."""
    tv_weight_density: float = 1.0
    """Total-variation weight on the (filtered) density planes."""
    tv_weight_appearance: float = 1.0
    """Total-variation weight on the (filtered) appearance planes."""
    l1_weight_initial: float = 8e-5
    """Density L1 weight before the first occupancy update."""
    l1_weight_rest: float = 4e-5
    """Density L1 weight from the first occupancy update on."""
    background: Literal["white", "black", "random", "none"] | None = None
    """Override the background the scene declares (None: as declared; Blender white, LLFF none = photos)."""
    view_dependent: bool | None = None
    """Override whether colour depends on the view direction (None: as declared; off for few-shot scenes)."""
    ray_space: Literal["euclidean", "ndc"] | None = None
    """Override the ray space (None: as declared; LLFF scenes declare NDC)."""
    occlusion_regularization: bool | None = None
    """Override FreeNeRF's occlusion regulariser (None: as declared; on for forward-facing scenes)."""
    occlusion_weight: float = 0.01
    """Weight of the occlusion regulariser (FreeNeRF: 0.01)."""
    occlusion_fraction: float = 20 / 128
    """Share of each ray, from its start, whose densities the occlusion term penalises (FreeNeRF: 20 of 128)."""
    floaters_gradient_scaling: bool = False
    """'Floaters No More': scale density and colour gradients by clamp(t², 0, 1) (t: the ray parameter)."""
    checkpoint_above: int = 65536
    """With more shaded samples than this in a training batch, colour is computed in checkpointed chunks: their
    activations are recomputed in the backward pass instead of kept. Early in a run nearly every sample is shaded;
    P-CPU's early peak RSS fell from 1.13 to 0.77 GB at no cost there, while checkpointing the final phase's ~50k
    samples would cost ~45 ms per iteration, hence the threshold. 0 = never."""
    checkpoint_chunk: int = 32768
    """Shaded samples per checkpointed chunk (see ``checkpoint_above``)."""
    eval_chunk_rays: int = 2048
    """Rays per chunk when rendering whole images: small enough that the temporaries stay in the recycled heap
    (under glibc's 32 MB mmap ceiling), large enough to amortise the per-chunk work (P-CPU renders: 512 rays 1.90 s,
    1024 1.69 s, 2048 1.44 s, 4096 1.76 s for the same 60k rays)."""
    eval_stop_transmittance: float = 1e-4
    """Evaluation renders stop querying a ray once its transmittance is below this (0 = march every sample)."""
    eval_segment_samples: int = 128
    """Samples per ray marched between early-termination checks at evaluation."""
