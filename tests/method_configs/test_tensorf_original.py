"""``tensorf-vm-published``: TensoRF's published configuration (apchenstu/TensoRF ``configs/lego.txt``,
``configs/flower.txt``, ``opt.py``) in this pipeline, at any budget.

Its values, its schedules (TensoRF's steps over its 30000 Blender / 25000 LLFF iterations, as fractions of the run),
Adam (AdamW without weight decay takes Adam's steps), that no short-run rule touches it, and that a forward-facing
scene gives it TensoRF's LLFF configuration rather than the paper's real-scene values.
"""

from __future__ import annotations

import copy
from pathlib import Path

import pytest
import torch

from fourierf_plugin.engine.optimizers import build_optimizer
from fourierf_plugin.field_components.schedules import lr_scale_at, steps_from_fractions
from fourierf_plugin.field_components.tensorf_decoder import TensoRFDecoder
from fourierf_plugin.method_configs import all_methods, finalize
from fourierf_plugin.method_configs.budget import apply_budget_rule
from fourierf_plugin.method_configs.scene_presets import (
    PUBLISHED_TENSORF_REAL_SCENE_SETTINGS,
    REAL_SCENE_SETTINGS,
    apply_real_scene_preset,
)
from fourierf_plugin.method_configs.sizing import CPU_ITERATIONS
from fourierf_plugin.scripts.train import given_options, parse_args
from tests.helpers import TINY_SCENE, train_tiny

NAME = "tensorf-vm-published"
PRESET = all_methods[NAME]
LEGO_ITERATIONS, FLOWER_ITERATIONS = 30000, 25000
LEGO_UPSAMPLES, LEGO_MASK_UPDATES = [2000, 3000, 4000, 5500, 7000], [2000, 4000]
FLOWER_UPSAMPLES, FLOWER_MASK_UPDATES = [2000, 3000, 4000, 5500], [2500]


def finished(scene: Path, *flags: str):
    parser = ["llff-data", "--num-views", "3"] if (scene / "poses_bounds.npy").exists() else []
    args = [NAME, "--data", str(scene), "--device", "cpu", *flags, *parser]
    return finalize(parse_args(args), given_options(args))


def test_the_blender_values_are_tensorfs() -> None:
    model, field = PRESET.pipeline.model, PRESET.pipeline.model.field
    assert (field.decomposition, field.density_components, field.appearance_components) == (
        "vm",
        (16, 16, 16),
        (48, 48, 48),
    )
    assert (field.decoder, field.feature_frequencies, field.view_frequencies) == ("tensorf", 2, 2)
    assert (field.appearance_dim, field.hidden_dim) == (27, 128)
    assert (field.density_activation, field.density_shift, model.distance_scale) == ("softplus", -10.0, 25.0)
    assert (field.n_voxels_init, field.n_voxels_final) == (128**3, 300**3)
    assert (model.tv_weight_density, model.tv_weight_appearance) == (0.0, 0.0)
    assert (model.l1_weight_initial, model.l1_weight_rest) == (8e-5, 4e-5)
    assert (model.step_ratio, model.weight_threshold) == (0.5, 1e-4)
    assert not model.fourier.enabled, "the Fourier masks are off"
    effects = PRESET.pipeline.effects
    assert effects.view_dependent is True and effects.occlusion_regularization is False
    assert effects.background is None and effects.ray_space is None, "the rest as the scene declares"


def test_the_optimiser_is_tensorfs_adam() -> None:
    opt = PRESET.optimizer
    assert (opt.lr_grids, opt.lr_networks, opt.betas, opt.weight_decay) == (0.02, 1e-3, (0.9, 0.99), 0.0)
    assert opt.betas_after_reset is None and opt.lr_decay_ratio == 0.1
    assert lr_scale_at(LEGO_ITERATIONS, [], opt.lr_decay_ratio, LEGO_ITERATIONS) == pytest.approx(0.1)


def test_its_optimiser_takes_adams_steps() -> None:
    """AdamW without weight decay is Adam: five steps on the same gradients land on the same parameters."""
    start = torch.randn(4, 5, generator=torch.Generator().manual_seed(0))
    ours, theirs = torch.nn.Parameter(start.clone()), torch.nn.Parameter(start.clone())
    optimizer = build_optimizer(PRESET.optimizer, {"grids": [ours]})
    adam = torch.optim.Adam([theirs], lr=0.02, betas=(0.9, 0.99))
    g = torch.Generator().manual_seed(1)
    for _ in range(5):
        grad = torch.randn(4, 5, generator=g)
        ours.grad, theirs.grad = grad.clone(), grad.clone()
        optimizer.step()
        adam.step()
    assert torch.allclose(ours, theirs, rtol=0, atol=1e-6)


def test_the_schedules_are_tensorfs_steps_as_fractions_of_its_runs() -> None:
    model = PRESET.pipeline.model
    assert list(model.field.upsample_fractions) == [s / LEGO_ITERATIONS for s in LEGO_UPSAMPLES]
    assert list(model.occupancy_update_fractions) == [s / LEGO_ITERATIONS for s in LEGO_MASK_UPDATES]
    assert steps_from_fractions(model.field.upsample_fractions, LEGO_ITERATIONS) == LEGO_UPSAMPLES
    assert steps_from_fractions(model.occupancy_update_fractions, LEGO_ITERATIONS) == LEGO_MASK_UPDATES
    llff = PUBLISHED_TENSORF_REAL_SCENE_SETTINGS
    assert steps_from_fractions(llff["pipeline.model.field.upsample_fractions"], FLOWER_ITERATIONS) == FLOWER_UPSAMPLES
    assert steps_from_fractions(llff["pipeline.model.occupancy_update_fractions"], FLOWER_ITERATIONS) == [2500]
    # a shorter run keeps the shape: the CPU default's 800 iterations
    assert steps_from_fractions(model.field.upsample_fractions, 800) == [53, 80, 107, 147, 187]


def test_a_forward_facing_scene_takes_tensorfs_llff_configuration_not_the_papers() -> None:
    config = copy.deepcopy(PRESET)
    applied, kept = apply_real_scene_preset(config, PRESET)
    assert not kept and len(applied) == len(PUBLISHED_TENSORF_REAL_SCENE_SETTINGS)
    model, field = config.pipeline.model, config.pipeline.model.field
    assert (field.density_components, field.appearance_components) == ((16, 4, 4), (48, 12, 12))
    assert (field.density_activation, field.feature_frequencies, field.view_frequencies) == ("relu", 0, 0)
    assert (model.tv_weight_density, model.tv_weight_appearance) == (1.0, 1.0)
    assert (model.l1_weight_initial, model.l1_weight_rest) == (0.0, 0.0)
    assert model.fourier == PRESET.pipeline.model.fourier, "none of the paper's curriculum values"
    assert REAL_SCENE_SETTINGS["pipeline.model.l1_weight_initial"] != model.l1_weight_initial


@pytest.mark.parametrize("iterations", [None, "100", "800", "3000"])
def test_no_short_run_rule_touches_it(iterations: str | None, llff_scene: Path) -> None:
    """At the CPU default (800) and at other lengths, on an object and on a forward-facing scene: no rule prints or
    sets anything, and the time budget's planner sees no rule either."""
    length = () if iterations is None else ("--max-num-iterations", iterations)
    for scene, background in ((TINY_SCENE, "white"), (llff_scene, "none")):
        config, notes = finished(scene, *length)
        assert config.max_num_iterations == int(iterations or CPU_ITERATIONS)
        assert not any(note.startswith("short-run defaults") for note in notes), notes
        assert config.budget_rule is False
        assert apply_budget_rule(config, copy.deepcopy(config), frozenset(), background) == []
        assert config.optimizer == PRESET.optimizer
        assert config.pipeline.model.entropy_weight == 0.0
        if scene == TINY_SCENE:
            assert config.pipeline.effects.background == "white", "no random training background"
            assert config.pipeline.model.field.density_components == (16, 16, 16)
            assert config.pipeline.model.tv_weight_density == 0.0
        else:
            assert config.pipeline.model.tv_decay_ratio == 0.1, "TensoRF's TV decays with the lr"
            assert config.pipeline.model.field.density_components == (16, 4, 4)
            assert config.pipeline.effects.occlusion_regularization is False
        assert config.pipeline.effects.view_dependent is True


@pytest.mark.slow
def test_a_tiny_run_trains_through_the_tensorf_decoder(tmp_path: Path) -> None:
    trainer, run_dir = train_tiny(tmp_path, NAME, 12)
    model = trainer.pipeline.model
    assert isinstance(model.field.decoder, TensoRFDecoder) and model.field.decoder.mlp[0].in_features == 150
    assert model.effects.view_dependent and (run_dir / "config.json").exists()
