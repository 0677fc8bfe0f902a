"""A training step on the GPU paths waits for the device at most twice: one compaction of the shaded samples, and
one read of the step's metrics when it logs. Checked on the CPU with the GPU paths forced (``SyncCounter``); the
forms it uses compute what the CPU forms compute."""

from __future__ import annotations

from pathlib import Path

import torch

from fourierf_plugin.accel.ops import AcceleratedOps
from fourierf_plugin.engine.optimizers import build_optimizer
from fourierf_plugin.engine.trainer import Trainer
from fourierf_plugin.model_components.marching import densities, densities_everywhere
from fourierf_plugin.scripts.train import build_config, parse_args
from tests.engine.sync_counter import SyncCounter
from tests.helpers import TINY_FLAGS, TINY_SCENE

ITERS = 100
LATE_STRUCTURE = ["--pipeline.model.occupancy-update-fractions", "0.6", "0.8"]
GPU_PATHS = ["--pipeline.model.accel.gpu-paths", "True", "--pipeline.model.fourier.ramp-fraction", "0.5"]


def _trainer(data: Path, out: Path, flags: list[str]) -> Trainer:
    parser = ["llff-data", "--num-views", "3"] if (data / "poses_bounds.npy").exists() else []
    args = ["fourierf-vm", "--data", str(data), "--output-dir", str(out), "--max-num-iterations", str(ITERS)]
    config, _ = build_config(parse_args([*args, *TINY_FLAGS, *flags, *parser]))
    return Trainer(config)


def _step(trainer: Trainer, optimizer: torch.optim.Optimizer, step: int) -> dict[str, torch.Tensor]:
    pipeline = trainer.pipeline
    loss, metrics = pipeline.train_step(step)
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    optimizer.step()
    pipeline.after_step(step)
    return metrics


def test_one_training_step_waits_for_the_device_at_most_twice(tmp_path: Path, either_scene: Path) -> None:
    trainer = _trainer(either_scene, tmp_path, GPU_PATHS)
    model = trainer.pipeline.model
    assert isinstance(model.field.ops, AcceleratedOps) and not model.field.ops.gather  # grid_sample, FFT filters
    assert trainer.pipeline.step_generator is not model.generator  # per-step draws on the device's generator
    optimizer = build_optimizer(trainer.config.optimizer, model.param_groups())
    reset = set(model.reset_steps())
    for step in range(45):  # past both occupancy updates (steps 20, 40), inside the cutoff ramp (50 steps)
        _step(trainer, optimizer, step)
        if step in reset:
            optimizer = build_optimizer(trainer.config.optimizer, model.param_groups())
    assert model.occupancy.active and model.cutoffs(45)[0] < 1.0
    with SyncCounter(trainer.pipeline.step_generator) as counter:
        metrics = _step(trainer, optimizer, 45)
        values = trainer.pipeline.read_metrics(metrics)
    assert counter.total <= 2, dict(counter.calls)
    assert counter.calls["nonzero"] == 1 and counter.calls["tolist"] == 1  # the shaded samples; the metrics
    assert all(torch.isfinite(torch.tensor(v)) for v in values.values())


def test_the_counter_sees_what_the_cpu_paths_wait_for(tmp_path: Path) -> None:
    """The same step on the CPU forms compacts densities and reads the longest ray: the counter must say so."""
    trainer = _trainer(TINY_SCENE, tmp_path, ["--pipeline.model.accel.gpu-paths", "False"])
    optimizer = build_optimizer(trainer.config.optimizer, trainer.pipeline.model.param_groups())
    with SyncCounter(trainer.pipeline.step_generator) as counter:
        _step(trainer, optimizer, 0)
    assert counter.calls["__float__"] >= 1 and counter.calls["nonzero"] >= 2, dict(counter.calls)


def test_density_at_every_sample_equals_the_compacted_density(tmp_path: Path) -> None:
    trainer = _trainer(TINY_SCENE, tmp_path, GPU_PATHS[2:])
    model = trainer.pipeline.model
    optimizer = build_optimizer(trainer.config.optimizer, model.param_groups())
    for step in range(41):  # through the occupancy updates: the occupancy grid masks samples too
        _step(trainer, optimizer, step)
        if step in model.reset_steps():
            optimizer = build_optimizer(trainer.config.optimizer, model.param_groups())
    assert model.occupancy.active
    batch = trainer.pipeline.datamanager.next_batch()
    model.prepare(41)
    samples = model.sample(batch.origins, batch.directions)
    compact = densities(model.field.density, samples, model.occupancy)
    everywhere = densities_everywhere(model.field.density, samples, model.occupancy)
    torch.testing.assert_close(everywhere, compact, rtol=1e-6, atol=1e-9)  # the same lookups, other batch sizes
    assert (compact == 0).any() and (compact > 0).any()


def test_gpu_paths_train_like_the_cpu_paths(tmp_path: Path) -> None:
    """The same initial grids, other forms and random streams, the same method: over the last 10 of 40 steps both
    fit the views alike. (Before any occupancy update: on a 16³ grid the first update's box is at the mercy of the
    random stream, which would compare luck, not forms.)"""
    psnr = {}
    for forced in ("False", "True"):
        flags = ["--pipeline.model.accel.gpu-paths", forced, *LATE_STRUCTURE]
        trainer = _trainer(TINY_SCENE, tmp_path / forced, flags)
        model = trainer.pipeline.model
        optimizer = build_optimizer(trainer.config.optimizer, model.param_groups())
        last = []
        for step in range(40):
            metrics = _step(trainer, optimizer, step)
            if step in model.reset_steps():
                optimizer = build_optimizer(trainer.config.optimizer, model.param_groups())
            last.append(trainer.pipeline.read_metrics(metrics)["psnr"])
        psnr[forced] = sum(last[-10:]) / 10
    assert abs(psnr["True"] - psnr["False"]) < 1.0, psnr
    assert min(psnr.values()) > 13.0, psnr
