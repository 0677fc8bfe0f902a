"""The ray-batch schedule: a function of the step, the batches the datamanager draws at each step, the unchanged
constant batch without one, resume, and bad schedules."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import torch

from fourierf_plugin.data.datamanager import DataManager, invalid_schedule, rays_per_batch_at
from fourierf_plugin.method_configs import all_methods
from fourierf_plugin.utils.errors import UserError
from tests.helpers import tiny_trainer_config

ZERORF = ((0.0051, 4.0), (0.0101, 16.0))


def _manager(tmp_path: Path, schedule: object = None, rays: int = 64, max_iters: int = 20, seed: int = 0):
    """The tiny scene's training rays, ``rays`` a batch, with ``schedule``, for a run of ``max_iters``."""
    config = tiny_trainer_config(tmp_path).pipeline.datamanager
    config = dataclasses.replace(config, rays_per_batch=rays, rays_per_batch_schedule=schedule)
    generator = torch.Generator().manual_seed(seed)
    manager = config.setup(device=torch.device("cpu"), generator=generator, ray_space="euclidean", max_iters=max_iters)
    return manager, generator


# -- the schedule ---------------------------------------------------------------------------------------------------
def test_zerorfs_schedule_at_its_own_10k_iterations_is_4096_16384_65536() -> None:
    """ZeroRF: 4096 rays for iterations 0-50, 16384 for 51-100, 65536 from 101."""
    at = [rays_per_batch_at(step, 4096, ZERORF, 10000) for step in (0, 50, 51, 100, 101, 5000, 9999)]
    assert at == [4096, 4096, 16384, 16384, 65536, 65536, 65536]


def test_a_cpu_run_keeps_the_shape_at_its_own_base_batch() -> None:
    """800 iterations of 1024: the stages start at steps 4 and 8 (0.51% and 1.01% of the run, rounded)."""
    at = [rays_per_batch_at(step, 1024, ZERORF, 800) for step in (0, 3, 4, 7, 8, 799)]
    assert at == [1024, 1024, 4096, 4096, 16384, 16384]


def test_without_a_schedule_the_batch_is_constant() -> None:
    for schedule in (None, ()):
        assert {rays_per_batch_at(step, 777, schedule, 100) for step in range(100)} == {777}


def test_stages_start_at_their_rounded_fraction_and_may_shrink() -> None:
    schedule = ((0.25, 2.0), (0.5, 0.5))
    assert [rays_per_batch_at(s, 100, schedule, 10) for s in (0, 1, 2, 3, 4, 5, 9)] == [100, 100, 100, 200, 200, 50, 50]
    assert rays_per_batch_at(0, 3, ((0.0, 0.1),), 10) == 1, "never fewer than one ray"


@pytest.mark.parametrize(
    ("schedule", "why"),
    [
        (((0.5, 2.0), (0.25, 4.0)), "increasing fractions"),
        (((1.5, 2.0),), "increasing fractions"),
        (((0.5, 0.0),), "multipliers > 0"),
        (((0.5, float("nan")),), "multipliers > 0"),
        (((0.5,),), "pairs"),
    ],
)
def test_bad_schedules_are_named(schedule: tuple, why: str) -> None:
    reason = invalid_schedule(schedule)
    assert reason is not None and why in reason
    assert invalid_schedule(None) is None and invalid_schedule(ZERORF) is None


def test_a_bad_schedule_is_one_clear_error_naming_the_flag(tmp_path: Path) -> None:
    with pytest.raises(UserError, match=r"--pipeline\.datamanager\.rays-per-batch-schedule 0\.5 0"):
        _manager(tmp_path, ((0.5, 0.0),))


# -- the datamanager ------------------------------------------------------------------------------------------------
def test_the_datamanager_draws_the_scheduled_rays_at_each_step(tmp_path: Path) -> None:
    manager, _ = _manager(tmp_path, ((0.25, 2.0), (0.5, 4.0)), rays=64, max_iters=8)
    sizes = [manager.next_batch(step).origins.shape[0] for step in range(8)]
    assert sizes == [64, 64, 128, 128, 256, 256, 256, 256]
    assert [manager.rays_at(step) for step in range(8)] == sizes


def test_without_a_schedule_the_batches_are_the_constant_permutation_walk(tmp_path: Path) -> None:
    """The default draws exactly the constant batch's rays: one permutation of the active rays per epoch
    from the run's generator, walked ``rays_per_batch`` at a time, the tail of an epoch dropped."""
    rays = 4000
    manager, generator = _manager(tmp_path, None, rays=rays, max_iters=20, seed=3)
    assert isinstance(manager, DataManager) and manager.config.rays_per_batch_schedule is None
    reference = torch.Generator().manual_seed(3)
    active = manager.active.clone()
    n = int(active.numel())
    per_epoch = n // rays
    train = manager.train_rays
    assert train is not None
    order = torch.zeros(0, dtype=torch.long)
    for step in range(per_epoch + 2):  # across an epoch's end
        if step % per_epoch == 0:
            order = active[torch.randperm(n, generator=reference)]
        idx = order[(step % per_epoch) * rays : (step % per_epoch + 1) * rays]
        batch = manager.next_batch(step)
        assert torch.equal(batch.rgba, train.rgba[idx]) and torch.equal(batch.origins, train.origins[idx])
    assert torch.equal(generator.get_state(), reference.get_state())


def test_a_resumed_datamanager_draws_what_the_uninterrupted_one_draws(tmp_path: Path) -> None:
    schedule = ((0.2, 3.0), (0.6, 5.0))
    whole, _ = _manager(tmp_path / "a", schedule, rays=100, max_iters=10, seed=1)
    first = [whole.next_batch(step).rgba for step in range(10)]
    part, gen = _manager(tmp_path / "b", schedule, rays=100, max_iters=10, seed=1)
    for step in range(4):
        part.next_batch(step)
    state, rng = part.state_dict(), gen.get_state()
    resumed, gen2 = _manager(tmp_path / "c", schedule, rays=100, max_iters=10, seed=7)
    resumed.load_state_dict(state)
    gen2.set_state(rng)
    for step in range(4, 10):
        assert torch.equal(resumed.next_batch(step).rgba, first[step])


def test_only_zerorf_vm_has_a_schedule() -> None:
    for name, preset in all_methods.items():
        schedule = preset.pipeline.datamanager.rays_per_batch_schedule
        assert schedule == (ZERORF if name == "zerorf-vm" else None), name
