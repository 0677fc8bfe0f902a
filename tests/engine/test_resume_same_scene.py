"""Resuming with ``--data`` points a run at its scene's new place only when it holds the same training views (names,
image size, camera centres as ``views.json`` records them); any flag but ``--load-dir``, ``--data``, ``--threads``
and ``--device`` is refused on resume, a value equal to the preset's included."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from fourierf_plugin.method_configs import resume_config
from fourierf_plugin.method_configs.finalize import ignored_on_resume
from fourierf_plugin.scripts.train import build_config, given_options, parse_args
from fourierf_plugin.utils.errors import UserError
from tests.helpers import TINY_SCENE, TINY_TRAIN_NAMES, train_tiny


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    _, run = train_tiny(tmp_path_factory.mktemp("run"), iters=6)
    return run


def copy_scene(tmp: Path) -> Path:
    return Path(shutil.copytree(TINY_SCENE, tmp / "scene"))


def test_views_json_records_names_size_and_camera_centres(run_dir: Path) -> None:
    views = json.loads((run_dir / "views.json").read_text())
    assert views["train_image_names"] == TINY_TRAIN_NAMES
    assert views["train_image_size"] == [100, 100]
    assert len(views["train_camera_centres"]) == len(TINY_TRAIN_NAMES)


def test_a_moved_copy_of_the_scene_is_accepted(run_dir: Path, tmp_path: Path) -> None:
    scene = copy_scene(tmp_path)
    resumed = resume_config("fourierf-vm", run_dir, data=scene)
    assert resumed.pipeline.datamanager.dataparser.data == scene.resolve()


def test_another_scene_with_the_same_file_names_is_refused(run_dir: Path, tmp_path: Path) -> None:
    scene = copy_scene(tmp_path)
    meta = json.loads((scene / "transforms_train.json").read_text())
    for frame in meta["frames"]:
        frame["transform_matrix"][0][3] += 0.5  # the same names and sizes, cameras elsewhere
    (scene / "transforms_train.json").write_text(json.dumps(meta))
    with pytest.raises(UserError) as info:
        resume_config("fourierf-vm", run_dir, data=scene)
    assert "not the scene the run" in info.value.problem and "other positions" in info.value.problem
    assert "start a new run" in (info.value.fix or "")


def test_a_scene_with_other_image_names_is_refused(run_dir: Path, tmp_path: Path) -> None:
    scene = copy_scene(tmp_path)
    meta = json.loads((scene / "transforms_train.json").read_text())
    meta["frames"][0]["file_path"] = "./train/renamed"
    shutil.copy(scene / "train" / "r_27.png", scene / "train" / "renamed.png")
    (scene / "transforms_train.json").write_text(json.dumps(meta))
    with pytest.raises(UserError, match="r_27 missing"):
        resume_config("fourierf-vm", run_dir, data=scene)


def test_a_scene_with_images_of_another_size_is_refused(run_dir: Path, tmp_path: Path) -> None:
    scene = copy_scene(tmp_path)
    for png in (scene / "train").glob("*.png"):
        iio.imwrite(png, np.zeros((50, 50, 4), dtype=np.uint8))
    with pytest.raises(UserError, match="images of 100x100, not 50x50"):
        resume_config("fourierf-vm", run_dir, data=scene)


def test_a_flag_equal_to_the_preset_default_is_refused_on_resume(run_dir: Path) -> None:
    args = ["fourierf-vm", "--load-dir", str(run_dir), "--max-num-iterations", "10000"]
    assert ignored_on_resume(parse_args(args), given_options(args)) == ["--max-num-iterations"]
    with pytest.raises(UserError, match="--max-num-iterations would be ignored"):
        build_config(parse_args(args), given_options(args))


def test_the_four_flags_of_where_a_run_goes_are_allowed_on_resume(run_dir: Path, tmp_path: Path) -> None:
    args = ["fourierf-vm", "--load-dir", str(run_dir), "--threads", "1", "--device", "cpu"]
    args += ["--data", str(copy_scene(tmp_path))]
    assert ignored_on_resume(parse_args(args), given_options(args)) == []
    config, _ = build_config(parse_args(args), given_options(args))
    assert config.load_dir == run_dir and config.threads == 1
