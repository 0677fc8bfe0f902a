"""Run sizes that fit the scene and the machine: iterations, batch and grid from the training images and the device.

Why: the method presets carry the paper's GPU settings (10k iterations, batch 4096, 128³ → 300³), about three hours
on two CPU cores for the bundled 100×100 scene. The rule, applied to every size the user leaves at the preset's
value (a flag always wins):

* on a GPU: the paper's settings; a forward-facing scene gets TensoRF's LLFF final grid, 640³ (the paper gives
  no real-scene grid, and 300³ is its synthetic one). The initial grid is 128³ either way: TensoRF's LLFF
  ``N_voxel_init`` is 2097156 ≈ 128³, which on the NDC box is the 141×157×94 of its table;
* on a CPU: 800 iterations of 1024 rays (protocol P-CPU, a few minutes), and a final grid of 1.28 voxels per pixel of
  the training images' larger side, between 64³ and 192³, upsampled from half that side (100×100 images:
  64³ → 128³).

Either way the count is the few-shot one for up to ``FEW_SHOT_VIEWS`` views and grows with the views beyond, so every
view is visited as often as in a nine-view run, up to ``DENSE_FACTOR`` times it: TensoRF trains a full capture 30k
iterations, three times the paper's few-shot 10k (a 100-view scene on a GPU gets TensoRF's 30k).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

CPU_ITERATIONS = 800
CPU_RAYS_PER_BATCH = 1024
CPU_VOXELS_PER_PIXEL = 1.28
CPU_SIDE = (64, 192)
"""The final grid's side on a CPU, at least and at most."""
GPU = {"iterations": 10000, "rays_per_batch": 4096, "init_side": 128, "final_side": 300}
"""The paper's settings."""
FEW_SHOT_VIEWS = 9
"""The paper's few-shot regime is 3 to 9 views; up to this many, a run gets the few-shot count."""
DENSE_FACTOR = 3
"""TensoRF's full-capture count over the paper's few-shot one (30k / 10k): the most a dense capture's count grows."""
GPU_FORWARD_FACING_FINAL_SIDE = 640
"""TensoRF's LLFF final grid (``configs/flower.txt``: N_voxel_final 262144000 = 640³)."""


@dataclass(frozen=True)
class RunSize:
    iterations: int
    rays_per_batch: int
    n_voxels_init: int
    n_voxels_final: int
    reason: str

    def settings(self) -> dict[str, int]:
        """As config paths (what ``scene_presets.apply_settings`` takes)."""
        values = (self.iterations, self.rays_per_batch, self.n_voxels_init, self.n_voxels_final)
        return dict(zip(SIZED_PATHS, values, strict=True))


SIZED_PATHS = (
    "max_num_iterations",
    "pipeline.datamanager.rays_per_batch",
    "pipeline.model.field.n_voxels_init",
    "pipeline.model.field.n_voxels_final",
)
"""The config paths a run size sets (``--help`` shows them as sized)."""


def count_factor(views: int) -> float:
    """How many times the few-shot count ``views`` training views get: 1 up to ``FEW_SHOT_VIEWS``, in proportion to
    the views beyond, at most ``DENSE_FACTOR``."""
    return min(DENSE_FACTOR, max(1.0, views / FEW_SHOT_VIEWS))


def run_size(views: int, height: int, width: int, device: torch.device, forward_facing: bool = False) -> RunSize:
    """The sizes the rule gives for ``views`` training images of ``height`` × ``width`` on ``device`` (of a
    forward-facing scene if ``forward_facing``)."""
    scene = f"{views} view(s) of {width}x{height} on {device.type}"
    factor = count_factor(views)
    dense = f", a dense capture: {factor:.3g}x the few-shot count" if factor > 1 else ""
    if device.type != "cpu":
        final, grid = GPU["final_side"], ""
        if forward_facing:
            final, grid = GPU_FORWARD_FACING_FINAL_SIDE, f", TensoRF's LLFF final grid {GPU_FORWARD_FACING_FINAL_SIDE}³"
        return RunSize(
            round(factor * GPU["iterations"]), GPU["rays_per_batch"], GPU["init_side"] ** 3, final**3,
            f"{scene}: the paper's settings{grid}{dense}",
        )  # fmt: skip
    low, high = CPU_SIDE
    side = min(high, max(low, round(CPU_VOXELS_PER_PIXEL * max(height, width))))
    return RunSize(
        round(factor * CPU_ITERATIONS), CPU_RAYS_PER_BATCH, (side // 2) ** 3, side**3,
        f"{scene}: sized for a CPU (see README){dense}",
    )  # fmt: skip
