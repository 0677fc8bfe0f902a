"""Runs are not tied to the working directory: config.json stores absolute paths, a run moved together with its
scene still finds it, and ``--data`` points a saved run at a scene that moved on its own (eval and resume)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from fourierf_plugin.engine.loading import load_run
from fourierf_plugin.engine.trainer import Trainer
from fourierf_plugin.method_configs import config_registry, resume_config
from tests.helpers import TINY_SCENE, tiny_trainer_config


@pytest.fixture(scope="module")
def project(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A project folder holding a scene and a run trained on it, written with relative paths from inside it."""
    root = tmp_path_factory.mktemp("moved") / "project"
    scene = Path(shutil.copytree(TINY_SCENE, root / "scene"))
    config = tiny_trainer_config(root / "out", iters=4)
    config.pipeline.datamanager.dataparser.data = scene
    Trainer(config).train()
    return root


def run_config(root: Path) -> Path:
    (config,) = root.glob("out/*/*/*/config.json")
    return config


def test_config_json_records_absolute_paths(project: Path) -> None:
    saved = json.loads(run_config(project).read_text())["config"]
    data = Path(saved["pipeline"]["datamanager"]["dataparser"]["data"])
    assert data.is_absolute() and data == (project / "scene").resolve()
    assert Path(saved["output_dir"]).is_absolute()


def test_a_run_moved_with_its_scene_still_loads(project: Path, tmp_path: Path) -> None:
    """The recorded absolute folder is gone (the project was moved): the scene beside the moved run is found."""
    moved = Path(shutil.copytree(project, tmp_path / "elsewhere"))
    (project / "scene").rename(project / "scene.gone")
    try:
        run = load_run(run_config(moved), config_registry())
        assert run.config.pipeline.datamanager.dataparser.data == (moved / "scene").resolve()
    finally:
        (project / "scene.gone").rename(project / "scene")


def test_data_overrides_a_moved_scene_for_eval_and_resume(project: Path, tmp_path: Path) -> None:
    other = Path(shutil.copytree(project / "scene", tmp_path / "copy"))
    run = load_run(run_config(project), config_registry(), data=other)
    assert run.config.pipeline.datamanager.dataparser.data == other.resolve()
    resumed = resume_config("fourierf-vm", run_config(project).parent, data=other)
    assert resumed.pipeline.datamanager.dataparser.data == other.resolve()
