"""fourierf-process-data: photos, a video or an LLFF scene to a scene folder; and every bad input ends in exit 2."""

from __future__ import annotations

import contextlib
import io
import json
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from fourierf_plugin.data.colmap_model import read_model
from fourierf_plugin.data.nerfstudio_writer import capture_from_llff
from fourierf_plugin.data.parsers.colmap import ColmapDataParserConfig
from fourierf_plugin.data.parsers.nerfstudio import NerfstudioDataParserConfig
from fourierf_plugin.scripts import process_data
from fourierf_plugin.scripts.cli import EXIT_USER_ERROR
from fourierf_plugin.sfm.alignment import pose_errors
from fourierf_plugin.utils.errors import UserError
from tests.helpers import REPO_ROOT, cli_exit_code
from tests.scenes import opengl_poses, write_llff_scene
from tests.sfm.textured_scene import opengl, write_photos

needs_pycolmap = pytest.mark.usefixtures("pycolmap_installed")  # skipped without it, a failure in CI


@pytest.fixture(scope="module")
def photos(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray]:
    folder = tmp_path_factory.mktemp("photos") / "photos"
    return folder, opengl(write_photos(folder, n=8))


@dataclass(frozen=True)
class Processed:
    report: process_data.ProcessReport
    stdout: str
    stderr: str


@pytest.fixture(scope="module")
def processed(photos: tuple[Path, np.ndarray], tmp_path_factory: pytest.TempPathFactory) -> Processed:
    """The 8 photos and one of noise, which cannot register, through fourierf-process-data images."""
    inputs = tmp_path_factory.mktemp("inputs") / "photos"
    shutil.copytree(photos[0], inputs)
    noise = np.random.default_rng(0).integers(0, 256, (120, 160, 3)).astype(np.uint8)
    iio.imwrite(inputs / "zz_noise.png", noise)
    scene = tmp_path_factory.mktemp("scene") / "scene"
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        report = process_data.main(["images", "--data", str(inputs), "--output-dir", str(scene)])
    return Processed(report, out.getvalue(), err.getvalue())


@needs_pycolmap
def test_images_writes_a_complete_scene(processed: Processed, photos: tuple[Path, np.ndarray]) -> None:
    report, scene = processed.report, processed.report.scene
    views = [f"view_{i:02d}.png" for i in range(8)]
    assert report.registered == views and report.unregistered == ["zz_noise.png"] and report.total == 9
    assert 0 < report.mean_reprojection_error < 1.0
    assert "registered 8 of 9 images, mean reprojection error" in processed.stdout
    assert "1 image(s) could not be registered" in processed.stderr and "zz_noise.png" in processed.stderr
    content = json.loads((scene / "transforms.json").read_text())
    assert content["camera_model"] == "OPENCV" and (content["w"], content["h"]) == (160, 120)
    assert [f["file_path"] for f in content["frames"]] == [f"images/{name}" for name in views]
    assert all(0 < f["depth_bounds"][0] < f["depth_bounds"][1] for f in content["frames"])
    np.testing.assert_allclose(content["applied_transform"], [[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0]])
    errors = pose_errors(np.stack([np.array(f["transform_matrix"]) for f in content["frames"]]), photos[1])
    assert np.median(errors.rotation_deg) < 1.0 and np.median(errors.centre_error_percent) < 2.0
    for folder, size in (
        ("images", (120, 160)),
        ("images_2", (60, 80)),
        ("images_4", (30, 40)),
        ("images_8", (15, 20)),
    ):
        files = sorted((scene / folder).iterdir())
        assert [p.name for p in files] == [*views, "zz_noise.png"]  # every input is copied, registered or not
        assert iio.imread(files[0]).shape[:2] == size
    np.testing.assert_array_equal(iio.imread(scene / "images" / "view_03.png"), iio.imread(photos[0] / "view_03.png"))
    model = read_model(scene / "colmap" / "sparse" / "0")
    assert len(model.images) == 8
    import trimesh

    assert content["ply_file_path"] == "sparse_pc.ply"
    assert len(trimesh.load(scene / "sparse_pc.ply").vertices) == len(model.points) > 50


@needs_pycolmap
def test_the_closing_suggestion_is_a_complete_few_shot_command(processed: Processed) -> None:
    scene = processed.report.scene
    out = " ".join(processed.stdout.split())
    assert f"fourierf-train fourierf-vm --data {scene} nerfstudio-data --num-views 7" in out  # 8 views, 1 held out
    assert "✓ extracting SIFT features of 9 photos" in out and "✓ matching features (exhaustive, 36 pairs)" in out


def test_train_suggestion_offers_only_views_the_training_split_has(tmp_path: Path) -> None:
    lines = process_data.train_suggestion(tmp_path / "my scene", 3)
    assert f"--data '{tmp_path / 'my scene'}' nerfstudio-data --num-views 2" in lines[0]  # frame 0 is a test view
    assert "--num-views 8" in process_data.train_suggestion(tmp_path, 50)[0]
    assert "all 43 training views" in process_data.train_suggestion(tmp_path, 50)[1]


def test_threads_are_forwarded_to_structure_from_motion(
    photos: tuple[Path, np.ndarray], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen = []

    def stop_at_sfm(image_dir, names, colmap_dir, options, display):
        seen.append(options)
        raise UserError("stopped here")

    monkeypatch.setattr(process_data, "import_pycolmap", lambda verbose=False: None)
    monkeypatch.setattr(process_data, "run_sfm", stop_at_sfm)
    args = ["images", "--data", str(photos[0]), "--output-dir", str(tmp_path / "out")]
    for extra, threads in (([], None), (["--threads", "3"], 3)):
        with pytest.raises(UserError, match="stopped here"):
            process_data.main([*args, *extra, "--overwrite"])
        assert seen[-1].threads == threads


@needs_pycolmap
def test_colmap_data_and_nerfstudio_data_read_the_output_alike(processed: Processed) -> None:
    """The same scene through its COLMAP model and through its transforms.json gives the same cameras."""
    scene = processed.report.scene
    from_colmap = ColmapDataParserConfig(data=scene).setup().get_outputs("train")
    from_json = NerfstudioDataParserConfig(data=scene).setup().get_outputs("train")
    assert from_colmap.image_names == from_json.image_names
    np.testing.assert_allclose(from_colmap.cameras.camera_to_worlds, from_json.cameras.camera_to_worlds, atol=1e-5)
    np.testing.assert_allclose(from_colmap.cameras.distortion, from_json.cameras.distortion, atol=1e-7)
    np.testing.assert_allclose(from_colmap.images, from_json.images)


@needs_pycolmap
def test_video_takes_evenly_spaced_frames_and_matches_them_sequentially(
    photos: tuple[Path, np.ndarray], tmp_path: Path
) -> None:
    frames = np.stack([iio.imread(p) for p in sorted(photos[0].iterdir())])
    clip = tmp_path / "clip.gif"
    iio.imwrite(clip, np.repeat(frames, 2, axis=0), duration=40, loop=0)  # 16 frames: every other one is kept
    report = process_data.main(
        ["video", "--data", str(clip), "--num-frames", "8", "--output-dir", str(tmp_path / "scene")]
    )
    assert report.total == 8 and len(report.registered) == 8
    content = json.loads((tmp_path / "scene" / "transforms.json").read_text())
    assert [Path(f["file_path"]).name for f in content["frames"]] == [f"frame_{i:05d}.png" for i in range(1, 9)]


def test_llff_writes_the_file_poses_as_transforms(tmp_path: Path) -> None:
    c2w = opengl_poses(6)
    llff = write_llff_scene(tmp_path / "llff", n=6, c2w=c2w, folders={"images_4": 4, "images_8": 8})
    report = process_data.main(["llff", "--data", str(llff), "--output-dir", str(tmp_path / "scene")])
    scene = report.scene
    content = json.loads((scene / "transforms.json").read_text())
    np.testing.assert_allclose(np.array([f["transform_matrix"] for f in content["frames"]])[:, :3], c2w, atol=1e-12)
    assert (content["w"], content["h"], content["camera_model"]) == (16, 12, "PINHOLE")  # from images_4
    assert content["fl_x"] == pytest.approx(60.0 / 4)
    source = capture_from_llff(llff)
    assert [f["depth_bounds"] for f in content["frames"]] == [list(f.depth_bounds) for f in source.frames]
    for f in content["frames"]:
        np.testing.assert_array_equal(
            iio.imread(scene / f["file_path"]), iio.imread(llff / "images_4" / Path(f["file_path"]).name)
        )
    assert iio.imread(scene / "images_2" / "image000.png").shape[:2] == (6, 8)
    report = process_data.main(
        ["llff", "--data", str(llff), "--output-dir", str(scene), "--image-folder", "images_8", "--overwrite"]
    )
    assert json.loads((scene / "transforms.json").read_text())["w"] == 8
    assert not (scene / "images_8").exists()  # 8x6 photos: an eighth would be under a pixel


# -- bad inputs: exit 2, one message naming the problem and the fix ---------------------------------------------------


def _fails(args: list[str], capsys: pytest.CaptureFixture, *expected: str) -> str:
    assert cli_exit_code(process_data.main, args) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert "Traceback" not in err
    for text in expected:
        assert text in err, err
    return err


def test_fewer_than_three_photos(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    folder = tmp_path / "two"
    folder.mkdir()
    for name in ("a.jpg", "b.jpg"):
        iio.imwrite(folder / name, np.zeros((8, 8, 3), np.uint8))
    out = tmp_path / "out"
    _fails(["images", "--data", str(folder), "--output-dir", str(out)], capsys, "holds 2 photo(s)", "at least 3")
    assert not out.exists()  # nothing was written


def test_threads_below_one(photos: tuple[Path, np.ndarray], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    args = ["images", "--data", str(photos[0]), "--output-dir", str(tmp_path / "out"), "--threads", "0"]
    _fails(args, capsys, "--threads must be at least 1, got 0", "every core")
    assert not (tmp_path / "out").exists()


def test_missing_pycolmap_names_the_extra(
    photos: tuple[Path, np.ndarray], tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "pycolmap", None)  # import pycolmap now raises ImportError
    out = tmp_path / "out"
    args = ["images", "--data", str(photos[0]), "--output-dir", str(out)]
    with pytest.raises(UserError, match="needs pycolmap") as info:
        process_data.main(args)
    assert "pip install '.[colmap]'" in info.value.fix
    _fails(args, capsys, "needs pycolmap", "pip install")
    assert not out.exists()


@needs_pycolmap
def test_photos_that_do_not_register(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    folder = tmp_path / "noise"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(4):
        iio.imwrite(folder / f"n{i}.png", rng.integers(0, 256, (96, 128, 3)).astype(np.uint8))
    _fails(["images", "--data", str(folder), "--output-dir", str(tmp_path / "out")], capsys, "photos", "overlap")
    assert sorted(p.name for p in folder.iterdir()) == [f"n{i}.png" for i in range(4)]  # the inputs are untouched


@needs_pycolmap
def test_unreadable_video(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    (tmp_path / "clip.mp4").write_bytes(b"definitely not a video" * 20)
    args = ["video", "--data", str(tmp_path / "clip.mp4"), "--output-dir", str(tmp_path / "out")]
    with pytest.raises(UserError, match="cannot read the video") as info:
        process_data.main(args)
    assert "pip install '.[video]'" in info.value.fix
    _fails(args, capsys, "cannot read the video", "ffmpeg plugin")
    _fails(["video", "--data", str(tmp_path / "none.mp4"), "--output-dir", str(tmp_path / "o")], capsys, "not found")


def test_output_folder_rules(photos: tuple[Path, np.ndarray], tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    _fails(["images", "--data", str(photos[0]), "--output-dir", str(out)], capsys, "not empty", "--overwrite")
    _fails(["images", "--data", str(photos[0]), "--output-dir", str(photos[0].parent)], capsys, "lies inside")
    _fails(["llff", "--data", str(tmp_path / "nope"), "--output-dir", str(tmp_path / "o2")], capsys, "not found")
    assert (out / "keep.txt").read_text() == "mine"


def test_the_installed_module_prints_no_traceback(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "fourierf_plugin.scripts.process_data", "images", "--data", str(tmp_path / "none"),
         "--output-dir", str(tmp_path / "out")],
        capture_output=True, text=True, cwd=REPO_ROOT, timeout=120,
    )  # fmt: skip
    assert done.returncode == EXIT_USER_ERROR
    assert "photo folder not found" in done.stderr and "Traceback" not in done.stderr
