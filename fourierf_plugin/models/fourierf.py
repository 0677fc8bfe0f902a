"""FourieRF model: sample rays → march the occupancy grid → the Fourier-filtered field → composite; and its losses.

All schedules (cutoffs, L1 weight, upsample and occupancy-update steps) are functions of the step and the run
length; the model changes its own structure in ``after_step`` and tells the caller when parameters were replaced
so the optimiser can be rebuilt. It never reaches into the trainer.
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Collection
from dataclasses import dataclass
from typing import ClassVar, Literal

import torch
from torch import Tensor, nn

from fourierf_plugin.accel import AccelConfig, build_ops
from fourierf_plugin.accel.config import uses_gpu_paths
from fourierf_plugin.configs.base import InstantiateConfig
from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.field_components import schedules
from fourierf_plugin.fields.fourier_tensorf_field import ALL_AXES, FieldConfig, FourierTensoRFField
from fourierf_plugin.fields.prepared_field import PreparedField
from fourierf_plugin.model_components import losses, regularisers
from fourierf_plugin.model_components.gradient_scaling import scale_gradient
from fourierf_plugin.model_components.marching import (
    densities,
    densities_everywhere,
    densities_that_show,
    densities_until_opaque,
    shade,
)
from fourierf_plugin.model_components.occupancy import (
    OccupancyGrid,
    occupancy_from_alpha,
    occupied_aabb,
    shrink_bounds,
    vertex_grid,
)
from fourierf_plugin.model_components.ray_sampling import (
    RaySamples,
    box_samples,
    contracted_samples,
    ndc_samples,
    ray_box_span,
)
from fourierf_plugin.model_components.regularisers import Regulariser, TrainingRays
from fourierf_plugin.model_components.rendering import (
    background_color,
    blend_background,
    composite_target,
    composite_weights,
    expected_depth,
    opacity_from_density,
)
from fourierf_plugin.utils.console import get_console
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
    f_final: float = 1.0
    """Cutoff the ramp ends at and keeps (paper: 1, the whole spectrum). Below 1 the field stays band-limited, so it
    cannot drift to the masks-off solution once the ramp is over (the paper: for large Δ it converges to TensoRF)."""
    f_final_color: float | None = None
    """Final cutoff of the appearance grids; None: ``f_final``. With ``f_final`` < 1 and this 1, only the geometry
    stays band-limited, and the field filters a quarter of the channels once the ramp is over (16 of 64 per plane)."""
    plane_leakage: float = 0.0
    """Weight kept on out-of-band plane coefficients; the paper zeroes them, the official code keeps 1e-6."""
    boundary: Literal["periodic", "mirror"] = "periodic"
    """How the filters treat the box's faces: periodic (the paper and the official code: what lies at one face leaks
    to the opposite one while the band is narrow, e.g. NDC's far wall onto the near plane) or mirror (each factor
    filtered with its mirror image appended, so nothing wraps)."""
    app_planes_follow_density: bool = False
    """Official-code behaviour: appearance planes use the density cutoff instead of the colour cutoff."""
    density_axes: tuple[int, ...] = ALL_AXES
    """World axes (0 x, 1 y, 2 z) along which the density factors are low-passed; the paper filters all three. On a
    forward-facing scene ``0 1`` keeps the curriculum on the image plane and leaves NDC depth (z) unfiltered, so the
    coarse field is smooth across the view but can place a surface at a sharp depth from the first step."""


def final_color_cutoff(fourier: FourierConfig) -> float:
    """The cutoff the appearance grids' ramp ends at: their own final cutoff where set, else the shared one."""
    return fourier.f_final if fourier.f_final_color is None else fourier.f_final_color


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
        effects: SceneEffects,
        max_iters: int,
        generator: torch.Generator,
        device: torch.device | str = "cpu",
        step_generator: torch.Generator | None = None,
    ) -> None:
        """``generator`` draws the initial grids and the host's coin tosses; ``step_generator`` (default: the same)
        the per-step random numbers, on the device it lives on."""
        super().__init__()
        self.config = config
        self.near, self.far = float(near), float(far)
        self.generator = generator
        self.step_generator = step_generator if step_generator is not None else generator
        self.gpu_paths = uses_gpu_paths(config.accel, device)
        self._box: tuple[tuple, list[float]] | None = None
        self.effects = effects
        self.set_run_length(max_iters)
        self._scaling_now = self.gradient_scalers_at(0)  # ``prepare`` sets them for each step
        self._background_now = self.training_background(0)  # ``prepare`` sets it for each step
        self.field = self._build_field(scene_box, effects, generator, device)
        self.occupancy = OccupancyGrid()
        self.empty_at_last_update = False  # the latest occupancy update found no density: a dead field, late in a run

    def set_run_length(self, max_iters: int) -> None:
        """Place every schedule that is a fraction of the run at a run of ``max_iters`` iterations (at construction,
        and when a ``--time-budget`` run plans its length again before the first of its events)."""
        config, fc = self.config, self.config.field
        self.max_iters = int(max_iters)
        self.upsample_steps = schedules.steps_from_fractions(fc.upsample_fractions, max_iters)
        self.voxel_targets = schedules.voxel_counts(fc.n_voxels_init, fc.n_voxels_final, len(self.upsample_steps))
        self.occupancy_steps = schedules.steps_from_fractions(config.occupancy_update_fractions, max_iters)
        # the first step after the first occupancy update's own step (the L1's switch; the random background's start)
        self.after_first_update = self.occupancy_steps[0] + 1 if self.occupancy_steps else None
        self.regularisers: list[Regulariser] = config.regularisers(self.effects, max_iters)
        self.random_background_step = self._random_background_step()

    def event_steps(self) -> list[int]:
        """The steps of the run's count-dependent events: upsamples, occupancy updates (and the L1's switch after the
        first), the random background's start and the regularisers' switches."""
        switches = [r.from_step for r in self.regularisers if hasattr(r, "from_step")]
        after = [self.after_first_update] if self.after_first_update is not None else []
        return sorted([*self.upsample_steps, *self.occupancy_steps, *after, self.random_background_step, *switches])

    def _build_field(
        self, scene_box: Tensor, effects: SceneEffects, generator: torch.Generator, device: torch.device | str
    ) -> PreparedField:
        """The FourieRF/TensoRF field of free factors (``models.zerorf`` builds ZeroRF's generated ones)."""
        config, fc = self.config, self.config.field
        size = (scene_box[1] - scene_box[0]).tolist()
        reso = schedules.n_to_reso(fc.n_voxels_init, size)
        ops = build_ops(config.accel, device)
        return FourierTensoRFField(
            fc,
            scene_box,
            reso,
            effects.view_dependent,
            generator,
            ops=ops,
            plane_leakage=config.fourier.plane_leakage,
            app_planes_follow_density=config.fourier.app_planes_follow_density,
            mirror_boundary=config.fourier.boundary == "mirror",
            density_axes=config.fourier.density_axes,
        )

    # -- schedules (pure functions of the step) ---------------------------------------------------------------
    def cutoffs(self, step: int) -> tuple[float, float]:
        fc = self.config.fourier
        if not fc.enabled:
            return 1.0, 1.0
        ramp = round(fc.ramp_fraction * self.max_iters)
        return (
            schedules.cutoff_at(step, fc.f0_density, ramp, fc.f_final),
            schedules.cutoff_at(step, fc.f0_color, ramp, final_color_cutoff(fc)),
        )

    def reset_steps(self) -> list[int]:
        """Steps after which parameters are replaced (and the optimiser restarts at the initial lr); none for a field
        whose resizes keep its parameters (ZeroRF's generators)."""
        if not self.field.replaces_parameters:
            return []
        return sorted(set(self.upsample_steps) | set(self.occupancy_steps))

    def tv_scale(self, step: int) -> float:
        """Multiplier of both TV weights at ``step`` (TensoRF's per-iteration decay; no decay when unset)."""
        ratio = self.config.tv_decay_ratio
        return 1.0 if ratio is None else schedules.tv_weight_at(step, 1.0, ratio, self.max_iters)

    def gradient_scalers_at(self, step: int) -> list[Regulariser]:
        """The regularisers that scale this step's density and colour gradients (Floaters-No-More)."""
        return [r for r in self.regularisers if r.scales_gradients_at(step)]

    def _random_background_step(self) -> int:
        if self.config.random_background_from is not None:
            return round(self.config.random_background_from * self.max_iters)
        return self.after_first_update or 0

    def training_background(self, step: int) -> str:
        """The background this step trains on: a random one only from ``random_background_step`` on, the evaluation
        background (white) before it (``random_background_from``)."""
        kind = self.effects.background
        if kind == "random" and step < self.random_background_step:
            return self.effects.eval_background
        return kind

    def l1_weight(self, step: int) -> float:
        c = self.config
        return schedules.l1_weight_at(step, self.after_first_update, c.l1_weight_initial, c.l1_weight_rest)

    # -- derived sampling parameters (from the current box and resolution) ------------------------------------
    @property
    def aabb(self) -> Tensor:
        return self.field.aabb

    def _box_size(self) -> list[float]:
        """The box's extent on the host, read from the device once per box (not once per step)."""
        key = (id(self.aabb), self.aabb._version)
        if self._box is None or self._box[0] != key:
            self._box = (key, (self.aabb[1] - self.aabb[0]).tolist())
        return self._box[1]

    @property
    def step_size(self) -> float:
        return schedules.step_size(self._box_size(), self.field.resolution, self.config.step_ratio)

    def samples_per_ray(self, training: bool) -> int:
        if training:
            return schedules.train_samples_per_ray(self.field.resolution, self.config.step_ratio)
        return schedules.eval_samples_per_ray(self._box_size(), self.step_size)

    # -- forward ----------------------------------------------------------------------------------------------
    def prepare(self, step: int) -> None:
        """Filter the grids at this step's cutoffs once; call before ``forward`` (under no_grad for renders)."""
        with phase("fourier_filter"):
            self.field.prepare(*self.cutoffs(step))
        self._scaling_now = self.gradient_scalers_at(step)
        self._background_now = self.training_background(step)

    def forward(
        self,
        origins: Tensor,
        directions: Tensor,
        background: Tensor | None = None,
        jitter: torch.Generator | None = None,
        colour: bool = True,
        terms: Collection[str] | None = None,
    ) -> dict:
        """Render rays [R, 3] (unit directions; NDC directions as made): rgb [R, 3], accumulation and depth [R].

        In training mode samples are jittered (from ``jitter``, default the step generator) and each regulariser's
        ray term is returned under its name (only those named in ``terms`` when given); in eval mode colours are
        clamped and, if the accel config says so, rays stop marching once they are opaque. ``colour`` False renders
        geometry only (rgb is the background): the unseen-view terms score depth and opacity, so decoding colours
        there would be wasted.
        """
        if background is None:
            background = self.draw_background(origins.shape[0], origins.device)
        with phase("sampling"):
            samples = self.sample(origins, directions, jitter)
        with phase("density"):
            sigma = self.march(samples)
        scale = self._gradient_scale(samples.t) if self.training else None
        if scale is not None:
            sigma = scale_gradient(sigma, scale)
        with phase("compositing"):
            weights = composite_weights(sigma, samples.deltas, self.config.distance_scale)
        with phase("appearance"):
            rgb = weights.new_zeros(weights.shape[0], 3)
            if colour:
                rgb = self.colours(samples, weights, scale)
        with phase("compositing"):
            out = self.composite(rgb, weights, samples.t, background)
        if self.training:
            rays = TrainingRays(
                sigma, samples.t, samples.deltas, weights, out["accumulation"], self.near, self.far,
                self.config.distance_scale,
            )  # fmt: skip
            out |= self.ray_terms(rays, terms)
        return out

    def composite(self, rgb: Tensor, weights: Tensor, t: Tensor, background: Tensor) -> dict[str, Tensor]:
        """A render's outputs from its weighted colour [R, 3] and weights [R, N] at ``t``: the colour on
        ``background`` (clamped in renders), the opacity, the expected depth (misses at far) and the background."""
        acc = weights.sum(dim=-1)
        rgb = blend_background(rgb, acc, background)
        if not self.training:
            rgb = rgb.clamp(0.0, 1.0)
        depth = expected_depth(weights, t, torch.full_like(acc, self.far))
        return {"rgb": rgb, "accumulation": acc, "depth": depth, "background": background}

    def ray_terms(self, rays: TrainingRays, terms: Collection[str] | None) -> dict[str, Tensor]:
        """Each regulariser's term on a training render's rays, by name (only those named in ``terms`` when given)."""
        found = {}
        for regulariser in self.regularisers:
            if terms is None or regulariser.name in terms:
                term = regulariser.ray_term(rays)
                if term is not None:
                    found[regulariser.name] = term
        return found

    def draw_background(self, num_rays: int, device: torch.device | str) -> Tensor:
        """The background of a batch of ``num_rays`` rays: this step's training one (one coin per batch, or a colour
        per ray) in training mode, the scene's evaluation one otherwise."""
        kind = self._background_now if self.training else self.effects.eval_background
        return background_color(kind, num_rays, device, self.generator, self.step_generator)

    def colours(self, samples: RaySamples, weights: Tensor, scale: Tensor | None) -> Tensor:
        """Ray colours [R, 3] from the samples that show (``marching.shade``; a model whose density pass already
        computed what the colour reads may reuse it)."""
        return shade(self.field.rgb, samples, weights, self.config.weight_threshold, self.effects.view_dependent, scale)

    def _gradient_scale(self, t: Tensor) -> Tensor | None:
        """The product of this step's gradient scales at ray parameters ``t`` [R, N]; None where none acts."""
        scale = None
        for regulariser in self._scaling_now:
            factor = regulariser.gradient_scale(t)
            scale = factor if scale is None else scale * factor
        return scale

    def sample(self, origins: Tensor, directions: Tensor, jitter: torch.Generator | None = None) -> RaySamples:
        """Fixed steps through the box (euclidean rays), even steps along NDC rays, or fixed steps of the contracted
        coordinate (unbounded scenes); jittered in training (from ``jitter``, default the step generator)."""
        generator = (jitter or self.step_generator) if self.training else None
        num = self.samples_per_ray(self.training)
        if self.effects.ray_space == "ndc":
            return ndc_samples(origins, directions, self.aabb, self.near, self.far, num, generator)
        if self.effects.ray_space == "contracted":
            return contracted_samples(
                origins, directions, self.aabb, self.near, self.far, self.step_size, num, generator
            )
        fixed = self.gpu_paths and self.training
        return box_samples(origins, directions, self.aabb, self.near, self.far, self.step_size, num, generator, fixed)

    def march(self, samples: RaySamples) -> Tensor:
        """σ [R, N] at the samples in occupied cells; renders may stop each ray once it is opaque."""
        accel = self.config.accel
        cull = self.config.cull_weight_threshold
        if self.training and cull > 0 and not self.gpu_paths:  # the GPU paths keep data-independent shapes
            return densities_that_show(self.field.density, samples, self.occupancy, self.config.distance_scale, cull)
        if self.training and self.gpu_paths:
            return densities_everywhere(self.field.density, samples, self.occupancy)
        if self.training or accel.early_stop_transmittance <= 0:
            return densities(self.field.density, samples, self.occupancy)
        return densities_until_opaque(
            self.field.density,
            samples,
            self.occupancy,
            self.config.distance_scale,
            accel.early_stop_transmittance,
            accel.early_stop_segment,
        )

    def unseen_views(self) -> list[Regulariser]:
        """The regularisers that render rays from unseen poses each step, in the order their terms are taken."""
        return [r for r in self.regularisers if r.unseen is not None]

    def unseen_loss(
        self, regulariser: Regulariser, origins: Tensor, directions: Tensor, jitter: torch.Generator | None = None
    ) -> Tensor:
        """``regulariser``'s weighted term on its rays [R, 3] from unseen poses, rendered as geometry only (no colour
        is scored there: no coin is drawn for a background). ``jitter``: where the samples' jitter comes from (the
        pipeline keeps these draws off the training batches' stream)."""
        background = torch.zeros(3, device=origins.device)
        outputs = self.forward(origins, directions, background, jitter, colour=False, terms=(regulariser.name,))
        return regulariser.unseen_loss(outputs)

    def loss_dict(self, outputs: dict, target_rgba: Tensor, step: int) -> dict[str, Tensor]:
        """Photometric MSE plus the regularisers, all on this iteration's filtered grids."""
        target = composite_target(target_rgba, outputs["background"])
        g = self.field.filtered
        c = self.config
        tv_terms = self.field.ops.squared_differences
        out = {"mse": losses.mse(outputs["rgb"], target)}
        tv_scale = self.tv_scale(step)
        if c.tv_weight_density > 0:
            tv = losses.grid_tv(g.density.planes, g.density.lines, sq=tv_terms)
            out["tv_density"] = c.tv_weight_density * tv_scale * tv
        if c.tv_weight_appearance > 0:
            tv = losses.grid_tv(g.appearance.planes, g.appearance.lines, sq=tv_terms)
            out["tv_appearance"] = c.tv_weight_appearance * tv_scale * tv
        l1 = self.l1_weight(step)
        if l1 > 0:
            out["l1_density"] = l1 * losses.density_l1(g.density.planes, g.density.lines)
        for regulariser in self.regularisers:
            term = regulariser.loss(outputs)
            if term is not None:
                out[regulariser.name] = term
        return out

    @torch.no_grad()
    def render_rays(
        self,
        origins: Tensor,
        directions: Tensor,
        step: int,
        chunk: int | None = None,
        cutoffs: tuple[float, float] | None = None,
    ) -> dict[str, Tensor]:
        """Render whole images in eval mode, in chunks (no jitter, clamped colour), at the cutoffs of ``step``.

        ``cutoffs`` (f_density, f_color) renders the field low-passed there instead (the viewer's sliders); the
        filtering prepared before is restored afterwards (``field.filtered_at``)."""
        was_training = self.training
        self.eval()
        filtering = contextlib.nullcontext() if cutoffs is None else self.field.filtered_at(*cutoffs)
        try:
            with filtering:
                if cutoffs is None:
                    self.prepare(step)
                chunk = chunk or self.config.accel.render_chunk_rays
                parts = [
                    self.forward(origins[i : i + chunk], directions[i : i + chunk])
                    for i in range(0, max(origins.shape[0], 1), chunk)  # no rays: one empty chunk, empty outputs
                ]
        finally:
            self.train(was_training)
        return {k: torch.cat([p[k] for p in parts]) for k in ("rgb", "accumulation", "depth")}

    # -- structure changes --------------------------------------------------------------------------------------
    @torch.no_grad()
    def after_step(self, step: int) -> Changes:
        """Occupancy updates (the first shrinks the box, the second asks for ray filtering) and upsamples."""
        changes = Changes()
        structure_changed = False
        if step in self.occupancy_steps:
            self.prepare(step + 1)
            first = step == self.occupancy_steps[0]
            self._update_occupancy(shrink=first, step=step)
            structure_changed = True
            # Ray filtering needs metric rays through a box; NDC rays all cross the frustum (TensoRF skips it too).
            second = len(self.occupancy_steps) > 1 and step == self.occupancy_steps[1]
            changes.filter_rays = second and self.effects.ray_space == "euclidean"
        if step in self.upsample_steps:
            self.prepare(step + 1)
            target = self.voxel_targets[self.upsample_steps.index(step)]
            self._upsample(schedules.n_to_reso(target, self._box_size()))
            structure_changed = True
        if structure_changed:
            changes.params_replaced = self.field.replaces_parameters
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
                alpha[i : i + chunk][keep] = opacity_from_density(sigma, step)
        return alpha.view(*reso)

    def _update_occupancy(self, shrink: bool, step: int) -> None:
        reso = self.field.resolution
        vertices = occupancy_from_alpha(self._dense_alpha(reso), self.config.occupancy_threshold)
        box = occupied_aabb(vertices, self.aabb)
        if box is None:
            self.empty_at_last_update = True
            get_console().print(
                "[yellow]warning:[/yellow] the occupancy grid is empty (no density above the threshold); "
                "keeping the previous box and sampling everywhere"
            )
            return
        self.empty_at_last_update = False
        self.occupancy.set(vertices, self.aabb)
        # Said at every update because what it prunes is never sampled again: a run that stalls after an update that
        # kept little of a forward-facing scene's grid was pruned while still dark (README, budget rule).
        kept = self.occupancy.cells.float().mean().item()
        get_console().print(f"occupancy update after step {step}: {kept:.0%} of the grid kept")
        if shrink:
            self.field.crop(*shrink_bounds(box, self.aabb, reso))

    def _upsample(self, reso: list[int]) -> None:
        """Resize the field to ``reso`` vertices per axis (after ``prepare``: free grids upsample what it filtered)."""
        self.field.upsample(reso)

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
        """The field's parameters by optimiser group (``engine.optimizers`` gives each group its learning rate)."""
        return self.field.param_groups()

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
    """Sampler, field, renderer and losses of FourieRF (and of TensoRF with ``fourier.enabled False``); ZeroRF's is
    ``models.zerorf.ZeroRFModelConfig``."""

    _target: ClassVar[type] = FourieRFModel
    field: FieldConfig = dataclasses.field(default_factory=FieldConfig)
    fourier: FourierConfig = dataclasses.field(default_factory=FourierConfig)
    accel: AccelConfig = dataclasses.field(default_factory=AccelConfig)
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
    tv_decay_ratio: float | None = None
    """Both TV weights at the end of the run relative to the start, decayed every iteration and never restarted
    (TensoRF). None: the optimiser's ``lr_decay_ratio``, set when the run is configured; a model built from a config
    that still says None does not decay."""
    l1_weight_initial: float = 8e-5
    """Density L1 weight before the first occupancy update."""
    l1_weight_rest: float = 4e-5
    """Density L1 weight from the first occupancy update on."""
    occlusion_weight: float = 0.01
    """Weight of the occlusion regulariser (FreeNeRF: 0.01)."""
    occlusion_fraction: float = 20 / 128
    """Share of each ray, from its start, whose densities the occlusion term penalises (FreeNeRF: 20 of 128)."""
    random_background_from: float | None = None
    """Where the scene trains on a random background: the fraction of the run from which it does, the evaluation
    background (white) before it; None = from the step after the first occupancy update (0 without one). Why not
    from the start: a random background charges density only on rays that cross the background in some training
    view, so the fog a fresh field starts with stays wherever none does, keeps the occupancy grid's box from
    shrinking and shows as coloured floaters at the box's edges; and under it TensoRF's density L1 can empty a field
    that has not lit yet.
    On white first the L1 clears the fog and the field lights; the random background then charges what white cannot,
    density outside the object's silhouette (README, "Scene effects")."""
    floaters_gradient_scaling: bool = False
    """'Floaters No More': scale density and colour gradients by clamp(t², 0, 1) (t: the ray parameter). It acts
    where samples lie within 1 of the camera (NDC, forward-facing); past Blender's near plane 2 it does nothing."""
    floaters_gradient_scaling_from: float = 0.0
    """Fraction of the run from which Floaters-No-More scales gradients (0: the whole run, as in its paper). While
    the band is narrow FourieRF paints no near floaters and the scaling only slows the near geometry; once the band
    is open the field trains like TensoRF's, which the scaling helps (set it to the ramp fraction for that)."""
    distortion_weight: float = 0.0
    """Weight of mip-NeRF 360's distortion loss on the training rays (mip-NeRF 360: 0.01), which pulls each ray's
    weight into one short interval against floaters and doubled geometry; 0 = off."""
    depth_smoothness_weight: float = 0.0
    """RegNeRF's depth smoothness on patches seen from poses between the training cameras (RegNeRF: 0.1 on NDC depth,
    8×8 patches); 0 = off, and no extra rays are rendered."""
    depth_smoothness_patches: int = 4
    """Unseen-view patches per iteration (each costs size² extra rays)."""
    depth_smoothness_patch_size: int = 8
    """Side of an unseen-view patch in pixels."""
    entropy_weight: float = 0.0
    """Weight of InfoNeRF's ray entropy (InfoNeRF: 0.001) on the training rays and on ``entropy_unseen_rays`` rays
    from poses between the training cameras, which pulls each ray's opacity into one sample; 0 = off."""
    entropy_threshold: float = 0.1
    """Rays whose accumulation is at most this are left out of the entropy (InfoNeRF: 0.1): they hit nothing."""
    entropy_unseen_rays: int = 1024
    """Rays from unseen poses per iteration for the entropy (InfoNeRF: 1024, as many as its training rays); 0 =
    the training rays only."""
    cull_weight_threshold: float = 0.0
    """Training on a CPU: σ is read without gradients first, then with them only where the compositing weight exceeds
    this; other samples count as empty (ZeroRF's occlusion culling: 1e-4). 0 = off."""

    def regularisers(self, effects: SceneEffects, max_iters: int) -> list[Regulariser]:
        """The few-shot regularisers these options turn on for a scene with ``effects`` (``model_components.
        regularisers``: one module each), in the order their terms are taken."""
        return regularisers.build(self, effects, max_iters)

    def unseen_rays(self) -> int:
        """Rays an iteration renders from unseen poses (depth smoothness's patches, the entropy's rays)."""
        built = self.regularisers(SceneEffects(), 1)
        return sum(r.unseen.rays for r in built if r.unseen is not None)
