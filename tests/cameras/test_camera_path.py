"""nerfstudio's camera_path.json: written from keyframes, read back, rendered by ``fourierf-render camera-path``
(a path written by hand from nerfstudio's documented format included), and its bad files are clear errors."""

from __future__ import annotations

import json
import math
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from fourierf_plugin.cameras.camera_path import (
    Keyframe,
    camera_path_json,
    fresh_path,
    read_camera_path,
    write_camera_path,
)
from fourierf_plugin.cameras.camera_paths import look_at
from fourierf_plugin.engine.loading import load_run
from fourierf_plugin.method_configs import config_registry
from fourierf_plugin.scripts.cli import EXIT_USER_ERROR
from fourierf_plugin.scripts.render import main
from fourierf_plugin.utils.errors import UserError
from tests.helpers import cli_exit_code, train_tiny


def _keyframes() -> list[Keyframe]:
    eyes = [(4.0, 0.0, 1.0), (0.0, 4.0, 1.5), (-4.0, 0.0, 1.0)]
    return [Keyframe(look_at(eye, (0, 0, 0)).double().numpy(), 40.0 + 5 * i, 1.5) for i, eye in enumerate(eyes)]


def test_a_written_path_reads_back_with_its_frames_size_and_rate(tmp_path: Path) -> None:
    keys = _keyframes()
    content = camera_path_json(keys, width=60, height=40, fps=10.0, seconds=2.0)
    path = write_camera_path(tmp_path, content)
    read = read_camera_path(path)
    assert (read.width, read.height, read.fps, len(read.cameras)) == (60, 40, 10.0, 20)
    c2w = read.cameras.camera_to_worlds.double().numpy()
    np.testing.assert_allclose(c2w[0], keys[0].camera_to_world, atol=1e-5)  # starts and ends on the keyframes
    np.testing.assert_allclose(c2w[-1], keys[-1].camera_to_world, atol=1e-5)
    fov = [math.degrees(2 * math.atan(20 / float(f))) for f in read.cameras.fy]
    assert fov[0] == pytest.approx(40.0, abs=1e-3) and fov[-1] == pytest.approx(50.0, abs=1e-3)
    rotations = c2w[:, :, :3]
    np.testing.assert_allclose(rotations @ rotations.transpose(0, 2, 1), np.broadcast_to(np.eye(3), rotations.shape),
                               atol=1e-5)  # fmt: skip
    steps = np.linalg.norm(np.diff(c2w[:, :, 3], axis=0), axis=1)
    assert steps.max() < 3 * steps.mean(), "the frames move along the path without jumps"
    saved = json.loads(path.read_text())
    assert len(saved["keyframes"]) == 3 and len(saved["camera_path"][0]["camera_to_world"]) == 16


def test_paths_are_never_overwritten(tmp_path: Path) -> None:
    content = camera_path_json(_keyframes(), 8, 8, 4.0, 1.0)
    first = write_camera_path(tmp_path, content)
    first_text = first.read_text()
    second = write_camera_path(tmp_path, content)
    assert (first.name, second.name) == ("camera_path.json", "camera_path-2.json")
    assert first.read_text() == first_text
    assert fresh_path(tmp_path).name == "camera_path-3.json"


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"camera_path": "x"}, "no camera_path list"),
        ({"camera_path": []}, "holds 0 frames"),
        ({"camera_type": "fisheye"}, "only perspective"),
        ({"render_height": -3}, "render_height must be a number"),
        ({"fps": "fast"}, "fps must be a number"),
        ({"camera_path": [{"camera_to_world": [1.0] * 15, "fov": 50}]}, "16 finite numbers"),
        ({"camera_path": [{"camera_to_world": [0.0] * 16, "fov": 50}]}, "singular"),
        ({"camera_path": [{"camera_to_world": np.eye(4).ravel().tolist(), "fov": 190}]}, "below 180"),
    ],
)
def test_bad_paths_are_one_clear_error(tmp_path: Path, change: dict, message: str) -> None:
    content = {**camera_path_json(_keyframes(), 8, 8, 4.0, 1.0), **change}
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(content))
    with pytest.raises(UserError, match=message) as info:
        read_camera_path(path)
    assert str(path) in info.value.problem


# -- fourierf-render camera-path ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def run_config(tmp_path_factory) -> Path:
    _, run_dir = train_tiny(tmp_path_factory.mktemp("runs"), iters=20)
    return run_dir / "config.json"


def _nerfstudio_path(run_config: Path) -> dict:
    """A camera_path.json as nerfstudio's viewer writes it, by hand: its first frame is training view 0 (its pose as
    16 row-major floats in the run's world frame, its vertical fov in degrees, its image size), the second a turned
    view."""
    run = load_run(run_config, config_registry())
    cameras = run.pipeline.datamanager.reference_outputs.cameras
    height, width = cameras.height, cameras.width
    fov = math.degrees(2 * math.atan(0.5 * height / float(cameras.fy[0])))
    first = np.eye(4)
    first[:3] = cameras.camera_to_worlds[0].double().numpy()
    turned = np.eye(4)
    turned[:3] = look_at(first[:3, 3] * 1.1, (0.0, 0.0, 0.0)).double().numpy()
    frames = [first, turned]
    return {
        "keyframes": [{"matrix": m.ravel().tolist(), "fov": fov, "aspect": width / height} for m in frames],
        "camera_type": "perspective",
        "render_height": height,
        "render_width": width,
        "fps": 2,
        "seconds": 1.0,
        "smoothness_value": 0.5,
        "is_cycle": False,
        "crop": None,
        "camera_path": [{"camera_to_world": m.ravel().tolist(), "fov": fov, "aspect": width / height} for m in frames],
    }


def test_a_nerfstudio_camera_path_renders_its_frames(run_config: Path, tmp_path: Path) -> None:
    path = tmp_path / "camera_path.json"
    path.write_text(json.dumps(_nerfstudio_path(run_config)))
    out = tmp_path / "path"
    result = main(["camera-path", "--load-config", str(run_config), "--camera-path-filename", str(path),
                   "--output-dir", str(out), "--outputs", "rgb"])  # fmt: skip
    assert len(result.frames["rgb"]) == 2 and (out / "rgb.gif").exists()
    train = main(["dataset", "--split", "train", "--load-config", str(run_config), "--output-dir",
                  str(tmp_path / "train"), "--outputs", "rgb", "--no-video"])  # fmt: skip
    first, view0, turned = (iio.imread(p).astype(float) for p in
                            (result.frames["rgb"][0], train.frames["rgb"][0], result.frames["rgb"][1]))  # fmt: skip
    assert first.shape == view0.shape
    assert np.abs(first - view0).mean() < 1.0, "the path's first frame is training view 0"
    assert np.abs(turned - view0).mean() > 1.0, "the second frame is another view"


def test_camera_path_errors_name_the_file(run_config: Path, tmp_path: Path) -> None:
    missing = tmp_path / "none.json"
    args = ["camera-path", "--load-config", str(run_config), "--camera-path-filename", str(missing)]
    assert cli_exit_code(main, args) == EXIT_USER_ERROR
