"""Run sizes that fit the scene and the machine (``method_configs.sizing``), applied where the user set nothing, and
the cost printed before training (``engine.estimates``)."""

from __future__ import annotations

import copy

import pytest
import torch

from fourierf_plugin.engine.estimates import checkpoint_bytes, describe_cost, estimate_seconds
from fourierf_plugin.method_configs import all_methods, finalize
from fourierf_plugin.method_configs.sizing import CPU_SIDE, GPU, run_size
from fourierf_plugin.scripts.train import parse_args
from tests.helpers import TINY_SCENE

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
    assert 150 * 2**20 < checkpoint_bytes(config, rays=40000) < 300 * 2**20, "the paper's grid: ~209 MB"
    line = describe_cost(config, 40000, threads=2, cpu=True)
    assert "MB each, the last 3 kept" in line and "estimated training time" in line
    assert "estimated" not in describe_cost(config, 40000, threads=2, cpu=False)
