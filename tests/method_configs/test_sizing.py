"""Run sizes that fit the scene and the machine (``method_configs.sizing``), applied where the user set nothing, and
the cost printed before training (``engine.estimates``)."""

from __future__ import annotations

import copy
import sys

import pytest
import torch

from fourierf_plugin.data.parsers.llff import NDC_BOX
from fourierf_plugin.engine.estimates import checkpoint_bytes, describe_cost, estimate_seconds
from fourierf_plugin.field_components.schedules import n_to_reso
from fourierf_plugin.method_configs import all_methods, finalize
from fourierf_plugin.method_configs.sizing import CPU_SIDE, DENSE_FACTOR, FEW_SHOT_VIEWS, GPU, run_size
from fourierf_plugin.scripts.train import parse_args
from tests.helpers import TINY_SCENE
from tests.scenes import write_llff_scene

CPU, CUDA = torch.device("cpu"), torch.device("cuda")


def test_the_bundled_scene_on_a_cpu_gets_the_demo_sizes() -> None:
    size = run_size(4, 100, 100, CPU)
    assert (size.iterations, size.rays_per_batch, size.n_voxels_init, size.n_voxels_final) == (800, 1024, 64**3, 128**3)


@pytest.mark.parametrize(("side", "expected"), [(20, CPU_SIDE[0]), (150, 192), (800, CPU_SIDE[1])])
def test_the_cpu_grid_follows_the_larger_image_side_within_bounds(side: int, expected: int) -> None:
    size = run_size(3, side // 2, side, CPU)
    assert size.n_voxels_final == expected**3 and size.n_voxels_init == (expected // 2) ** 3


def test_a_gpu_gets_the_papers_settings() -> None:
    size = run_size(4, 800, 800, CUDA)
    assert (size.iterations, size.rays_per_batch) == (GPU["iterations"], GPU["rays_per_batch"])
    assert (size.n_voxels_init, size.n_voxels_final) == (128**3, 300**3)
    assert "the paper's settings" in size.reason


def test_finalize_sizes_what_the_user_left_and_keeps_what_they_set() -> None:
    config, notes = finalize(parse_args(["fourierf-vm", "--data", str(TINY_SCENE), "--max-num-iterations", "50"]))
    assert config.max_num_iterations == 50, "a flag always wins"
    assert config.pipeline.datamanager.rays_per_batch == 1024
    assert config.pipeline.model.field.n_voxels_final == 128**3
    assert "run size for 4 view(s) of 100x100 on cpu" in notes[0] and "kept your max_num_iterations" in notes[0]


def test_cost_estimates_scale_with_the_run() -> None:
    config = copy.deepcopy(all_methods["fourierf-vm"])
    one = estimate_seconds(config, threads=2)
    config.max_num_iterations *= 2
    assert estimate_seconds(config, threads=2) == pytest.approx(2 * one)
    assert estimate_seconds(config, threads=4) == pytest.approx(one)
    model, rays = config.pipeline.model, config.pipeline.datamanager.rays_per_batch
    model.depth_smoothness_weight = 0.1  # 4 unseen-view patches of 8×8 pixels: 256 more rays an iteration
    assert estimate_seconds(config, threads=4) == pytest.approx(one * (rays + 256) / rays)
    assert 150 * 2**20 < checkpoint_bytes(config, rays=40000) < 300 * 2**20, "the paper's grid: ~209 MB"
    line = describe_cost(config, 40000, threads=2, cpu=True)
    assert "MB each, the last 3 kept" in line and "estimated training time" in line
    assert "estimated" not in describe_cost(config, 40000, threads=2, cpu=False)


def test_a_forward_facing_scene_on_a_gpu_gets_tensorfs_llff_grid() -> None:
    """TensoRF's LLFF config: N_voxel_init 2097156 ≈ 128³, which on the NDC box is its 141×157×94, and 640³ final."""
    size = run_size(3, 378, 504, CUDA, forward_facing=True)
    assert (size.iterations, size.rays_per_batch) == (GPU["iterations"], GPU["rays_per_batch"])
    assert (size.n_voxels_init, size.n_voxels_final) == (128**3, 640**3)
    assert n_to_reso(size.n_voxels_init, [b - a for a, b in zip(*NDC_BOX, strict=True)]) == [141, 157, 94]
    assert "TensoRF's LLFF final grid 640³" in size.reason
    assert run_size(3, 378, 504, CPU, forward_facing=True) == run_size(3, 378, 504, CPU), "CPU: the pixel rule"


def test_finalize_gives_a_forward_facing_scene_on_a_gpu_the_llff_grid(monkeypatch, tmp_path) -> None:
    monkeypatch.setattr(sys.modules["fourierf_plugin.method_configs.finalize"], "pick_device", lambda _: CUDA)
    scene = write_llff_scene(tmp_path / "scene")
    given = parse_args(["fourierf-vm", "--data", str(scene), "llff-data", "--num-views", "3"])
    config, notes = finalize(given)
    assert config.pipeline.model.field.n_voxels_final == 640**3 and config.pipeline.model.field.n_voxels_init == 128**3
    assert any("TensoRF's LLFF final grid 640³" in n and "n_voxels_final=262144000" in n for n in notes)
    flags = ["--pipeline.model.field.n-voxels-final", str(200**3), "llff-data", "--num-views", "3"]
    config, _ = finalize(parse_args(["fourierf-vm", "--data", str(scene), *flags]))
    assert config.pipeline.model.field.n_voxels_final == 200**3, "a flag always wins"
    blender, _ = finalize(parse_args(["fourierf-vm", "--data", str(TINY_SCENE)]))
    assert blender.pipeline.model.field.n_voxels_final == 300**3, "a bounded scene keeps the paper's grid"


@pytest.mark.parametrize("device", [CPU, CUDA])
def test_a_few_shot_capture_gets_the_few_shot_count_and_a_dense_one_grows_to_tensorfs(device) -> None:
    few_shot = run_size(FEW_SHOT_VIEWS, 100, 100, device).iterations
    assert all(run_size(views, 100, 100, device).iterations == few_shot for views in range(1, FEW_SHOT_VIEWS + 1))
    counts = [run_size(views, 100, 100, device).iterations for views in range(FEW_SHOT_VIEWS, 60)]
    assert counts == sorted(counts), "never fewer iterations for more views"
    assert run_size(2 * FEW_SHOT_VIEWS, 100, 100, device).iterations == 2 * few_shot, "in proportion to the views"
    assert run_size(1000, 100, 100, device).iterations == DENSE_FACTOR * few_shot, "capped"
    assert "dense capture: 2x the few-shot count" in run_size(2 * FEW_SHOT_VIEWS, 100, 100, device).reason
    assert "dense" not in run_size(FEW_SHOT_VIEWS, 100, 100, device).reason


def test_a_full_blender_scene_on_a_gpu_gets_tensorfs_count() -> None:
    """TensoRF's Blender config trains its 100 views 30000 iterations."""
    assert run_size(100, 800, 800, CUDA).iterations == 30000
