"""Rebuild a trained pipeline from a run's config.json and a checkpoint (eval, render and export share this)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from fourierf_plugin.configs.base import Registry, load_config
from fourierf_plugin.data.dataparser_base import DataparserOutputs
from fourierf_plugin.engine.checkpoint import load_checkpoint, load_latest_checkpoint, restore_pipeline
from fourierf_plugin.engine.machine import pick_device, seed_everything
from fourierf_plugin.engine.option_checks import check_saved_config
from fourierf_plugin.engine.run_dir import views_record
from fourierf_plugin.engine.trainer import TrainerConfig
from fourierf_plugin.pipelines.base import Pipeline
from fourierf_plugin.utils.errors import fail


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
    check_saved_config(config, Path(config_path))
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
    restore_pipeline(pipeline, state, Path(ckpt_path))
    pipeline.model.eval()
    return LoadedRun(config, pipeline, int(state["step"]), Path(ckpt_path), run_dir, dev)


CENTRE_TOLERANCE = 1e-4
"""Largest difference of a training camera's centre (scene units after normalisation) still taken as the same."""


def scene_differences(recorded: dict[str, Any], scene: DataparserOutputs) -> list[str]:
    """How the training views of ``scene`` differ from those ``views.json`` recorded (empty: the same scene); a
    record without sizes or centres is compared on what it has."""
    now = views_record(scene)
    found: list[str] = []
    names = recorded.get("train_image_names")
    if names is not None and list(names) != now["train_image_names"]:
        missing = [n for n in names if n not in now["train_image_names"]]
        shown = f"{', '.join(map(str, missing[:3]))} missing" if missing else "another selection or order"
        found.append(f"training images {', '.join(map(str, names[:3]))}... ({shown})")
    size = recorded.get("train_image_size")
    if size is not None and list(size) != now["train_image_size"]:
        found.append(f"images of {size[0]}x{size[1]}, not {now['train_image_size'][0]}x{now['train_image_size'][1]}")
    centres = recorded.get("train_camera_centres")
    if not found and centres is not None:
        moved = len(centres) != len(now["train_camera_centres"]) or any(
            abs(a - b) > CENTRE_TOLERANCE
            for old, new in zip(centres, now["train_camera_centres"], strict=False)
            for a, b in zip(old, new, strict=False)
        )
        if moved:
            found.append("training cameras at other positions")
    return found


def check_same_scene(run_dir: Path, data: Path, scene: DataparserOutputs) -> None:
    """A UserError when ``scene`` (read from ``data``) is not the scene the run in ``run_dir`` trained on, by
    the training views its ``views.json`` records; nothing to check where the run has none."""
    path = Path(run_dir) / "views.json"
    try:
        recorded = json.loads(path.read_text())
    except FileNotFoundError:
        return
    except (OSError, ValueError) as err:
        fail(f"cannot read {path} to check that --data {data} holds the run's scene: {err}", "restore views.json")
    if not isinstance(recorded, dict):
        fail(f"{path} is not a views record (expected a JSON object)", "restore views.json")
    differences = scene_differences(recorded, scene)
    if differences:
        fail(
            f"--data {data} is not the scene the run in {run_dir} was trained on: the run recorded "
            f"{'; '.join(differences)}",
            f"pass the run's own scene folder (moved or copied, not another scene), or start a new run on {data}",
        )
