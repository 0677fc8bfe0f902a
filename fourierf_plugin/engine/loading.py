"""Rebuild a trained pipeline from a run's config.json and a checkpoint (eval, render and export share this)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch

from fourierf_plugin.configs.base import Registry, load_config
from fourierf_plugin.engine.checkpoint import load_checkpoint, load_latest_checkpoint
from fourierf_plugin.engine.machine import pick_device, seed_everything
from fourierf_plugin.engine.trainer import TrainerConfig
from fourierf_plugin.pipelines.base import Pipeline


@dataclass
class LoadedRun:
    config: TrainerConfig
    pipeline: Pipeline
    step: int
    checkpoint: Path
    run_dir: Path
    device: torch.device


def run_dir_of(config_path: Path) -> Path:
    """The run directory for a path to its config.json (or the directory itself)."""
    return config_path.parent if config_path.suffix == ".json" else config_path


def locate_data(config: TrainerConfig, run_dir: Path, override: Path | None = None) -> Path:
    """The scene folder of a saved run: ``override`` if given, else the recorded (absolute) folder, else the one at
    the recorded place relative to the run folder (the run was moved together with its data)."""
    if override is not None:
        return Path(override).expanduser().resolve()
    recorded = Path(config.pipeline.datamanager.dataparser.data)
    if not recorded.exists() and config.data_from_run_dir is not None:
        beside = (Path(run_dir) / config.data_from_run_dir).resolve()
        if beside.exists():
            return beside
    return recorded


def load_run(
    config_path: Path,
    registry: Registry,
    checkpoint: Path | None = None,
    device: str = "auto",
    data: Path | None = None,
) -> LoadedRun:
    """Config, pipeline with the checkpoint's weights (grid shapes restored), and the step it was taken at.

    ``registry`` names the config classes the run may use (``method_configs.config_registry()``); ``data``
    overrides the scene folder recorded in the config (a run made on another machine).
    """
    config = load_config(config_path, TrainerConfig, registry)
    run_dir = run_dir_of(config_path)
    config.pipeline.datamanager.dataparser.data = locate_data(config, run_dir, data)
    if checkpoint is not None:
        ckpt_path, state = checkpoint, load_checkpoint(checkpoint)
    else:
        ckpt_path, state = load_latest_checkpoint(run_dir / "checkpoints")
    dev = pick_device(device)
    generator = seed_everything(config.seed)
    pipeline: Pipeline = config.pipeline.setup(
        device=dev, max_iters=config.max_num_iterations, generator=generator, load_train=False
    )
    pipeline.load_state_dict(state["pipeline"])
    pipeline.model.eval()
    return LoadedRun(config, pipeline, int(state["step"]), Path(ckpt_path), run_dir, dev)
