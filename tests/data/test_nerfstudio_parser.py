"""The nerfstudio-data parser on tiny ``transforms.json`` scenes written in tmp_path: every field variant, every
error a user can make (one clear UserError naming the file and the frame), a tiny training run through the CLI, and
the shared fern written as a transforms.json giving the llff-data parser's cameras exactly."""

from __future__ import annotations

import json
import math
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from fourierf_plugin.data.parsers import all_dataparsers
from fourierf_plugin.data.parsers.llff import LLFFDataParserConfig, load_poses_bounds, to_opengl
from fourierf_plugin.data.parsers.nerfstudio import NerfstudioDataParserConfig, read_transforms
from fourierf_plugin.scripts import train
from fourierf_plugin.utils.errors import UserError
from tests.conftest import require_shared
from tests.data.transforms_scenes import (
    FOCAL,
    HEIGHT,
    WIDTH,
    edit_transforms,
    homogeneous,
    ring_c2w,
    write_image,
    write_scene,
)
from tests.helpers import TINY_FLAGS, cli_exit_code
from tests.scenes import image_pixels, opengl_poses

N = 10


def parse(data: Path, split: str = "train", **kwargs):
    return NerfstudioDataParserConfig(data=data, **kwargs).setup().get_outputs(split)


def error_of(data: Path, split: str = "train", **kwargs) -> str:
    with pytest.raises(UserError) as info:
        parse(data, split, **kwargs)
    return str(info.value)


@pytest.fixture
def ring(tmp_path: Path) -> Path:
    return write_scene(tmp_path / "ring", ring_c2w(N))


# -- reading the file -----------------------------------------------------------------------------------------------


def test_registered_as_nerfstudio_data() -> None:
    assert isinstance(all_dataparsers["nerfstudio-data"], NerfstudioDataParserConfig)


def test_shared_intrinsics_give_every_camera_the_same(ring: Path) -> None:
    out = parse(ring)
    assert out.view_ids == [i for i in range(N) if i % 8]
    assert out.image_names == [f"frame_{i:05d}" for i in out.view_ids]
    assert tuple(out.images.shape) == (len(out.view_ids), HEIGHT, WIDTH, 4)
    cams = out.cameras
    assert (cams.width, cams.height, cams.camera_model) == (WIDTH, HEIGHT, "PINHOLE")
    for values, expected in ((cams.fx, FOCAL), (cams.fy, FOCAL), (cams.cx, WIDTH / 2), (cams.cy, HEIGHT / 2)):
        torch.testing.assert_close(values, torch.full((len(cams),), expected))
    assert cams.distortion is not None and tuple(cams.distortion.shape) == (len(cams), 6)
    assert not cams.distortion.any()
    expected = torch.from_numpy(image_pixels(1, WIDTH, HEIGHT)).float() / 255
    torch.testing.assert_close(out.images[0, :, :, :3], expected)
    assert bool((out.images[..., 3] == 1).all())


def test_data_may_name_the_json_file(ring: Path) -> None:
    out = parse(ring / "transforms.json")
    assert out.scene_name == "ring" and len(out.view_ids) == N - 2


def test_per_frame_intrinsics_win_over_shared_ones(tmp_path: Path) -> None:
    scene = write_scene(tmp_path / "s", ring_c2w(N), frames={1: {"fl_x": 9.0, "cx": 3.5}})
    cams = parse(scene).cameras
    assert float(cams.fx[0]) == 9.0 and float(cams.cx[0]) == 3.5  # frame 1 is the first training view
    assert float(cams.fx[1]) == FOCAL and float(cams.fy[0]) == FOCAL


def test_missing_fl_y_cx_cy_default_to_fl_x_and_the_image_centre(tmp_path: Path) -> None:
    scene = write_scene(tmp_path / "s", ring_c2w(N))
    edit_transforms(scene, lambda d: [d.pop(k) for k in ("fl_y", "cx", "cy")])
    cams = parse(scene).cameras
    assert float(cams.fy[0]) == FOCAL and float(cams.cx[0]) == WIDTH / 2 and float(cams.cy[0]) == HEIGHT / 2


def test_camera_angle_x_stands_in_for_fl_x(tmp_path: Path) -> None:
    scene = write_scene(tmp_path / "s", ring_c2w(N))
    edit_transforms(scene, lambda d: [d.pop("fl_x"), d.pop("fl_y"), d.update(camera_angle_x=1.2)])
    cams = parse(scene).cameras
    assert float(cams.fx[0]) == pytest.approx(0.5 * WIDTH / math.tan(0.6)) == pytest.approx(float(cams.fy[0]))
    edit_transforms(scene, lambda d: d.update(camera_angle_x=0.0))
    assert "camera_angle_x must be in (0, pi)" in error_of(scene)


@pytest.mark.parametrize(
    ("meta", "model", "row"),
    [
        (
            {"camera_model": "OPENCV", "k1": 0.1, "k2": -0.02, "p1": 0.001, "p2": -0.002},
            "OPENCV",
            [0.1, -0.02, 0, 0, 0.001, -0.002],
        ),
        (
            {"camera_model": "OPENCV_FISHEYE", "k1": 0.1, "k2": 0.01, "k3": -0.01, "k4": 0.002},
            "OPENCV_FISHEYE",
            [0.1, 0.01, -0.01, 0.002, 0, 0],
        ),
        ({"camera_model": "SIMPLE_PINHOLE"}, "SIMPLE_PINHOLE", [0.0] * 6),
        ({"k1": 0.05}, "OPENCV", [0.05, 0, 0, 0, 0, 0]),  # no camera_model, distortion given: nerfstudio's OPENCV
    ],
)
def test_camera_models_and_distortion(tmp_path: Path, meta: dict, model: str, row: list[float]) -> None:
    cams = parse(write_scene(tmp_path / "s", ring_c2w(N), meta=meta)).cameras
    assert cams.camera_model == model
    assert cams.distortion is not None
    torch.testing.assert_close(cams.distortion, torch.tensor([row] * len(cams), dtype=torch.float32))


def test_per_frame_distortion(tmp_path: Path) -> None:
    scene = write_scene(tmp_path / "s", ring_c2w(N), meta={"camera_model": "OPENCV"}, frames={2: {"k1": 0.2}})
    cams = parse(scene).cameras
    assert cams.distortion is not None
    assert cams.distortion[:, 0].tolist() == pytest.approx([0.0, 0.2, 0, 0, 0, 0, 0, 0])


def test_frames_are_taken_in_file_name_order(tmp_path: Path) -> None:
    names = [f"img{i}.png" for i in (10, 2, 1, 0, 3, 4, 5, 6, 7, 8)]  # natural order: 0 1 2 3 ... 10
    capture = read_transforms(write_scene(tmp_path / "s", ring_c2w(N), image_names=names) / "transforms.json")
    assert [f.image_path.name for f in capture.frames] == [f"img{i}.png" for i in (0, 1, 2, 3, 4, 5, 6, 7, 8, 10)]
    np.testing.assert_array_equal(capture.frames[0].camera_to_world, ring_c2w(N)[3])


def test_points_applied_transform_and_depth_bounds_are_read(tmp_path: Path) -> None:
    points = np.random.default_rng(0).normal(size=(20, 3))
    applied = [[0, 1, 0, 0], [1, 0, 0, 0], [0, 0, -1, 0]]
    scene = write_scene(
        tmp_path / "s",
        ring_c2w(N),
        meta={"applied_transform": applied},
        frames={0: {"depth_bounds": [1, 9]}},
        points=points,
    )
    capture = read_transforms(scene / "transforms.json")
    np.testing.assert_allclose(capture.points, points, atol=1e-7)
    np.testing.assert_array_equal(capture.applied_transform, applied)
    assert capture.frames[0].depth_bounds == (1.0, 9.0) and capture.frames[1].depth_bounds is None


def test_listed_splits_are_used(tmp_path: Path) -> None:
    meta = {
        "train_filenames": [f"images/frame_{i:05d}.png" for i in (0, 1, 2, 3, 4, 5)],
        "val_filenames": ["images/frame_00006.png"],
        "test_filenames": ["images/frame_00007.png", "images/frame_00009.png"],
    }
    scene = write_scene(tmp_path / "s", ring_c2w(N), meta=meta)
    assert parse(scene).view_ids == [0, 1, 2, 3, 4, 5]
    assert parse(scene, "val").view_ids == [6]
    assert parse(scene, "test").view_ids == [7, 9]


def test_mask_becomes_alpha_and_declares_a_white_background(tmp_path: Path) -> None:
    mask = np.full((HEIGHT, WIDTH), 255, dtype=np.uint8)
    mask[:, : WIDTH // 2] = 0
    frames = {}
    for i in range(N):
        (tmp_path / "s" / "masks").mkdir(parents=True, exist_ok=True)
        iio.imwrite(tmp_path / "s" / "masks" / f"m{i}.png", mask)
        frames[i] = {"mask_path": f"masks/m{i}.png"}
    scene = write_scene(tmp_path / "s", ring_c2w(N), frames=frames)
    out = parse(scene)
    assert bool((out.images[:, :, : WIDTH // 2] == 0).all()), "masked pixels are transparent (premultiplied)"
    assert bool((out.images[:, :, WIDTH // 2 :, 3] == 1).all())
    assert NerfstudioDataParserConfig(data=scene).setup().declaration().background == "white"


def test_photos_without_alpha_declare_no_background_and_rgba_ones_white(tmp_path: Path) -> None:
    plain = write_scene(tmp_path / "plain", ring_c2w(N))
    rgba = write_scene(tmp_path / "rgba", ring_c2w(N), alpha=True)
    assert NerfstudioDataParserConfig(data=plain).setup().declaration().background == "none"
    assert NerfstudioDataParserConfig(data=rgba).setup().declaration().background == "white"
    out = parse(rgba)
    assert float(out.images[0, 0, 0, 3]) == 0.0 and float(out.images[0, 0, 1, 3]) == 1.0


# -- downscaling, as nerfstudio does it -----------------------------------------------------------------------------


def _full_size_scene(root: Path, with_half: bool) -> Path:
    """16x12 photos in images/ (intrinsics for that size); with ``with_half``, flat grey 8x6 copies in images_2/."""
    scene = write_scene(root, ring_c2w(N))
    if with_half:
        (scene / "images_2").mkdir()
    for i in range(N):
        write_image(scene / "images" / f"frame_{i:05d}.png", i, 2 * WIDTH, 2 * HEIGHT)
        if with_half:
            iio.imwrite(scene / "images_2" / f"frame_{i:05d}.png", np.full((HEIGHT, WIDTH, 3), 100, np.uint8))
    edit_transforms(
        scene, lambda d: d.update(w=2 * WIDTH, h=2 * HEIGHT, fl_x=2 * FOCAL, fl_y=2 * FOCAL, cx=WIDTH, cy=HEIGHT)
    )
    return scene


def test_downscale_reads_the_downscaled_folder_when_present(tmp_path: Path) -> None:
    out = parse(_full_size_scene(tmp_path / "s", with_half=True), downscale=2)
    assert (out.cameras.width, out.cameras.height) == (WIDTH, HEIGHT)
    torch.testing.assert_close(out.images[..., :3], torch.full_like(out.images[..., :3], 100 / 255))
    assert float(out.cameras.fx[0]) == FOCAL and float(out.cameras.cx[0]) == WIDTH / 2


def test_downscale_resizes_when_no_folder_has_that_factor(tmp_path: Path) -> None:
    scene = _full_size_scene(tmp_path / "s", with_half=False)
    out = parse(scene, downscale=2)
    full = torch.from_numpy(image_pixels(1, 2 * WIDTH, 2 * HEIGHT)).float() / 255
    block_means = full.reshape(HEIGHT, 2, WIDTH, 2, 3).mean(dim=(1, 3))
    torch.testing.assert_close(out.images[0, :, :, :3], block_means)
    assert float(out.cameras.fy[0]) == FOCAL and float(out.cameras.cy[0]) == HEIGHT / 2
    assert parse(_full_size_scene(tmp_path / "h", with_half=True), downscale=4).cameras.width == WIDTH // 2


def test_auto_downscale_keeps_small_photos_whole(ring: Path) -> None:
    assert parse(ring).cameras.width == WIDTH


def test_mixed_sizes_with_per_frame_intrinsics_are_resized_to_the_most_common(tmp_path: Path) -> None:
    scene = write_scene(tmp_path / "s", ring_c2w(N), shared=False)
    write_image(scene / "images" / "frame_00001.png", 1, 2 * WIDTH, 2 * HEIGHT)
    edit_transforms(scene, lambda d: d["frames"][1].update(w=16, h=12, fl_x=13.0, fl_y=13.0, cx=8.0, cy=6.0))
    out = parse(scene)
    assert tuple(out.images.shape[1:3]) == (HEIGHT, WIDTH)
    assert out.cameras.fx.tolist() == pytest.approx([6.5] + [FOCAL] * 7)
    assert out.cameras.cx.tolist() == pytest.approx([WIDTH / 2] * 8)


# -- errors: one clear UserError naming the file and the frame -----------------------------------------------------


def test_mixed_sizes_with_shared_intrinsics_fail(tmp_path: Path) -> None:
    scene = write_scene(tmp_path / "s", ring_c2w(N))
    write_image(scene / "images" / "frame_00001.png", 1, 2 * WIDTH, 2 * HEIGHT)
    message = error_of(scene)
    assert "frame_00001.png is 16x12" in message and "w x h = 8x6" in message and "own w, h" in message


def test_mixed_aspect_ratios_fail(tmp_path: Path) -> None:
    scene = write_scene(tmp_path / "s", ring_c2w(N), shared=False)
    write_image(scene / "images" / "frame_00001.png", 1, HEIGHT, WIDTH)
    edit_transforms(scene, lambda d: d["frames"][1].update(w=HEIGHT, h=WIDTH))
    assert "aspect ratios differ" in error_of(scene)


def test_missing_image_names_the_frame(ring: Path) -> None:
    (ring / "images" / "frame_00003.png").unlink()
    message = error_of(ring)
    assert "transforms.json, frame 3 (images/frame_00003.png)" in message and "not found" in message


def test_every_missing_image_is_listed_at_once(tmp_path: Path) -> None:
    scene = write_scene(tmp_path / "s", ring_c2w(12))
    for i in range(1, 11):  # 10 of 12 gone: the first 8 named, the rest counted
        (scene / "images" / f"frame_{i:05d}.png").unlink()
    with pytest.raises(UserError) as info:
        parse(scene)
    problem, fix = info.value.problem, info.value.fix or ""
    assert "transforms.json: 10 of 12 frames name images that are not found" in problem
    assert all(f"frame {i} (images/frame_{i:05d}.png)" in problem for i in range(1, 9))
    assert "frame 9 " not in problem and "... and 2 more" in problem
    assert f"looked in {scene / 'images'} (2 images there)" in problem
    assert (
        "nerfstudio-data --skip-missing-images True" in fix and "train on the 2 frames whose images are present" in fix
    )


def test_skip_missing_images_trains_on_the_frames_that_are_present(tmp_path: Path, capsys) -> None:
    meta = {"train_filenames": [f"images/frame_{i:05d}.png" for i in range(8)], "test_filenames": []}
    meta["test_filenames"] = ["images/frame_00008.png", "images/frame_00009.png"]
    scene = write_scene(tmp_path / "s", ring_c2w(N), meta=meta)
    for i in (2, 5):
        (scene / "images" / f"frame_{i:05d}.png").unlink()
    assert "2 of 10 frames" in error_of(scene)
    out = parse(scene, skip_missing_images=True)
    assert out.image_names == [f"frame_{i:05d}" for i in (0, 1, 3, 4, 6, 7)]  # the listed split, less the two
    assert len(parse(scene, "test", skip_missing_images=True).view_ids) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "skipped 2 of 10 frames whose images are missing" in err and "training on the other 8" in err
    assert "frame 2 (images/frame_00002.png), frame 5 (images/frame_00005.png)" in err
    assert err.count("skipped 2 of 10") == 1  # one line however often the scene is read
    capture = read_transforms(scene / "transforms.json", skip_missing_images=True)
    assert len(capture.frames) == 8


def test_skip_missing_images_is_a_flag_of_the_parser(ring: Path, tmp_path: Path) -> None:
    args = ["fourierf-vm", "--data", str(ring), "--output-dir", str(tmp_path / "out"), "nerfstudio-data"]
    assert train.parse_args(
        [*args, "--skip-missing-images", "True"]
    ).pipeline.datamanager.dataparser.skip_missing_images
    assert not train.parse_args(args).pipeline.datamanager.dataparser.skip_missing_images


def test_skip_missing_images_still_fails_when_no_image_is_found(ring: Path) -> None:
    for path in (ring / "images").iterdir():
        path.unlink()
    message = error_of(ring, skip_missing_images=True)
    assert "none of its 10 frames' images is found" in message and "(0 images there)" in message


def test_instant_ngp_file_is_read_and_its_ignored_keys_named_once(tmp_path: Path, capsys) -> None:
    """colmap2nerf's keys: the fields of view and the lens are read; the scene cube and sharpness are named."""
    fy = FOCAL * 1.25
    ngp = {
        "camera_angle_x": 2 * math.atan(WIDTH / (2 * FOCAL)),
        "camera_angle_y": 2 * math.atan(HEIGHT / (2 * fy)),
        "aabb_scale": 16,
        "scale": 0.33,
        "offset": [0.5, 0.5, 0.5],
        "is_fisheye": False,
        "k1": 0.01,
        "k2": -0.002,
        "p1": 0.0,
        "p2": 0.0,
    }
    frames = {i: {"sharpness": 30.0 + i} for i in range(N)}
    scene = write_scene(tmp_path / "s", ring_c2w(N), meta=ngp, frames=frames)
    edit_transforms(scene, lambda d: [d.pop(k) for k in ("fl_x", "fl_y")])
    cams = parse(scene).cameras
    assert float(cams.fx[0]) == pytest.approx(FOCAL) and float(cams.fy[0]) == pytest.approx(fy)
    assert cams.camera_model == "OPENCV"
    parse(scene, "test")
    out = " ".join(capsys.readouterr().out.split())
    assert "instant-ngp keys ignored: aabb_scale, scale, offset, sharpness (per frame)" in out
    assert out.count("instant-ngp keys ignored") == 1


def test_is_fisheye_means_the_fisheye_model(tmp_path: Path) -> None:
    lens = {"is_fisheye": True, "k1": 0.05, "k2": 0.01, "k3": -0.01, "k4": 0.002}
    cams = parse(write_scene(tmp_path / "s", ring_c2w(N), meta=lens)).cameras
    assert cams.camera_model == "OPENCV_FISHEYE"
    scene = write_scene(tmp_path / "t", ring_c2w(N), meta=lens | {"camera_model": "OPENCV"})
    assert "is_fisheye is true (instant-ngp) but camera_model is 'OPENCV'" in error_of(scene)
    scene = write_scene(tmp_path / "u", ring_c2w(N), meta={"is_fisheye": "yes"})
    assert "is_fisheye must be true or false" in error_of(scene)


def test_frames_repeating_a_photo_are_merged_or_named(tmp_path: Path, capsys) -> None:
    c2w = ring_c2w(N)
    scene = write_scene(tmp_path / "s", c2w)
    repeats = [{"file_path": f"images/frame_{i:05d}.png", "transform_matrix": c2w[i].tolist()} for i in (3, 6)]
    edit_transforms(scene, lambda d: d["frames"].extend(repeats))  # 12 frames for 10 photos, same cameras
    capture = read_transforms(scene / "transforms.json")
    assert [f.image_path.name for f in capture.frames] == [f"frame_{i:05d}.png" for i in range(N)]
    err = " ".join(capsys.readouterr().err.split())
    assert "2 frame(s) repeat a photo with the same camera and are used once" in err
    assert "frames 3 and 10 (images/frame_00003.png), frames 6 and 11 (images/frame_00006.png)" in err
    edit_transforms(scene, lambda d: d["frames"][11].update(transform_matrix=c2w[0].tolist()))
    message = error_of(scene)
    assert "1 photo(s) are named by two frames with different cameras: frames 6 and 11" in message
    assert "keep one frame per photo" in message


def test_unknown_camera_model_lists_the_supported_ones(tmp_path: Path) -> None:
    scene = write_scene(tmp_path / "s", ring_c2w(N), frames={0: {"camera_model": "EQUIRECTANGULAR"}})
    message = error_of(scene)
    assert "frame 0" in message and "'EQUIRECTANGULAR'" in message
    assert all(model in message for model in ("OPENCV", "PINHOLE", "SIMPLE_PINHOLE", "OPENCV_FISHEYE"))


def test_distortion_on_a_pinhole_camera_fails(tmp_path: Path) -> None:
    message = error_of(write_scene(tmp_path / "s", ring_c2w(N), meta={"camera_model": "PINHOLE", "k1": 0.1}))
    assert "PINHOLE has no k1" in message


@pytest.mark.parametrize(
    ("matrix", "words"),
    [
        ([[math.nan, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "non-finite"),
        ([[2, 0, 0, 0], [0, 2, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]], "not a camera pose"),
        ([[0, 0, 0, 0]] * 4, "not a camera pose"),
        ([[1, 0, 0], [0, 1, 0]], "4x4 or 3x4"),
    ],
)
def test_bad_poses_name_the_frame(ring: Path, matrix: list, words: str) -> None:
    edit_transforms(ring, lambda d: d["frames"][4].update(transform_matrix=matrix))
    message = error_of(ring)
    assert "frame 4 (images/frame_00004.png)" in message and words in message


def test_missing_and_malformed_json(tmp_path: Path) -> None:
    assert "transforms.json not found" in error_of(tmp_path)
    assert "data folder not found" in error_of(tmp_path / "nowhere")
    (tmp_path / "transforms.json").write_text('{"frames": [')
    assert "is not valid JSON" in error_of(tmp_path) and "line 1" in error_of(tmp_path)
    (tmp_path / "transforms.json").write_text('{"frames": []}')
    assert "non-empty list" in error_of(tmp_path)


def test_other_formats_are_named(tmp_path: Path) -> None:
    np.save(tmp_path / "poses_bounds.npy", np.zeros((1, 17)))
    assert "use the llff-data parser" in error_of(tmp_path)


def test_unknown_split_name_and_empty_split(tmp_path: Path) -> None:
    scene = write_scene(tmp_path / "s", ring_c2w(N), meta={"test_filenames": ["images/nope.png"]})
    assert "test_filenames names images/nope.png" in error_of(scene, "test")
    scene = write_scene(tmp_path / "e", ring_c2w(N), meta={"test_filenames": []})
    assert "test split" in error_of(scene, "test") and "is empty" in error_of(scene, "test")


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"w": 0}, "w must be a positive whole number"),
        ({"fl_x": "six"}, "fl_x must be a finite number"),
        ({"depth_bounds": [5, 1]}, "0 < near < far"),
        ({"mask_path": "masks/none.png"}, "mask_path masks/none.png not found"),
    ],
)
def test_bad_frame_fields_name_the_frame(ring: Path, change: dict, words: str) -> None:
    edit_transforms(ring, lambda d: d["frames"][2].update(change))
    message = error_of(ring)
    assert "frame 2" in message and words in message


def test_missing_ply_file_fails(ring: Path) -> None:
    edit_transforms(ring, lambda d: d.update(ply_file_path="points.ply"))
    assert "ply_file_path 'points.ply' not found" in error_of(ring)


def test_cli_turns_a_bad_scene_into_exit_2(ring: Path, tmp_path: Path, capsys) -> None:
    (ring / "images" / "frame_00003.png").unlink()
    args = ["fourierf-vm", "--data", str(ring), "--output-dir", str(tmp_path / "out"), "nerfstudio-data"]
    assert cli_exit_code(train.main, args) == 2
    err = capsys.readouterr().err
    assert "frame 3" in err and "Traceback" not in err


# -- training through the CLI ---------------------------------------------------------------------------------------


def test_tiny_training_run_records_the_scene_kind(ring: Path, tmp_path: Path) -> None:
    args = ["fourierf-vm", "--data", str(ring), "--output-dir", str(tmp_path / "out"), "--max-num-iterations", "4"]
    config, notes = train.build_config(train.parse_args([*args, *TINY_FLAGS, "nerfstudio-data", "--num-views", "3"]))
    assert any(note.startswith("scene kind: unbounded") for note in notes)  # photos without alpha
    run_dir = train.Trainer(config).train()
    saved = json.loads((run_dir / "config.json").read_text())["config"]
    parser = saved["pipeline"]["datamanager"]["dataparser"]
    assert parser["_type"] == "NerfstudioDataParserConfig" and parser["scene_kind"] == "unbounded"
    assert parser["scene_kind_reason"].startswith("auto: ")
    assert saved["pipeline"]["effects"]["ray_space"] == "contracted"
    assert saved["pipeline"]["effects"]["background"] == "none"
    assert json.loads((run_dir / "views.json").read_text())[
        "train_view_ids"
    ] == config.pipeline.datamanager.dataparser.setup().split_ids("train")
    assert (run_dir / "checkpoints" / "step-000000004.ckpt").is_file()


def test_tiny_forward_facing_run_gets_ndc_and_the_real_scene_preset(tmp_path: Path) -> None:
    """A rig looking one way, with depth bounds: NDC rays, occlusion regularisation, the real-scene preset."""
    rig = homogeneous(opengl_poses(10))
    bounds = {i: {"depth_bounds": [2.0 + 0.1 * i, 20.0]} for i in range(10)}
    scene = write_scene(tmp_path / "rig", rig, frames=bounds)
    args = ["fourierf-vm", "--data", str(scene), "--output-dir", str(tmp_path / "out"), "--max-num-iterations", "20"]
    config, notes = train.build_config(
        train.parse_args([*args, *TINY_FLAGS, "nerfstudio-data", "--view-ids", "1", "2"])
    )
    assert any(note.startswith("scene kind: forward-facing (auto: every camera looks within") for note in notes)
    assert config.scene_preset == "real"
    effects = config.pipeline.effects
    assert (effects.ray_space, effects.background, effects.occlusion_regularization) == ("ndc", "none", True)
    run_dir = train.Trainer(config).train()
    saved = json.loads((run_dir / "config.json").read_text())["config"]
    assert saved["pipeline"]["datamanager"]["dataparser"]["scene_kind"] == "forward-facing"
    assert (run_dir / "checkpoints" / "step-000000020.ckpt").is_file()


# -- the shared fern --------------------------------------------------------------------------------------------------


def fern_transforms(fern: Path, root: Path, world: np.ndarray | None = None) -> Path:
    """fern's poses_bounds.npy as a transforms.json (full-size intrinsics, images/ paths that resolve to fern's
    images_<k>/, per-frame depth_bounds), optionally in another world frame (``world``: a 4x4 rigid motion)."""
    raw, hwf, bounds = load_poses_bounds(fern / "poses_bounds.npy")
    c2w = homogeneous(to_opengl(raw))
    if world is not None:
        c2w = world[None] @ c2w
    height, width, focal = hwf[0]
    frames = [
        {
            "file_path": str(fern / "images" / f"image{i:03d}.png"),
            "transform_matrix": c2w[i].tolist(),
            "depth_bounds": bounds[i].tolist(),
        }
        for i in range(len(c2w))
    ]
    meta = {"fl_x": focal, "fl_y": focal, "cx": width / 2, "cy": height / 2, "w": int(width), "h": int(height)}
    root.mkdir(parents=True, exist_ok=True)
    (root / "transforms.json").write_text(json.dumps(meta | {"camera_model": "PINHOLE", "frames": frames}))
    return root


def _rigid(angle: float, axis: list[float], shift: list[float]) -> np.ndarray:
    axis_v = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    k = np.array([[0, -axis_v[2], axis_v[1]], [axis_v[2], 0, -axis_v[0]], [-axis_v[1], axis_v[0], 0]])
    out = np.eye(4)
    out[:3, :3] = np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k
    out[:3, 3] = shift
    return out


@pytest.mark.parametrize("world", [None, _rigid(2.0, [1, -2, 0.5], [3.0, -7.0, 11.0])], ids=["llff-frame", "moved"])
def test_fern_as_transforms_gives_the_llff_cameras(tmp_path: Path, world: np.ndarray | None) -> None:
    fern = require_shared("data", "llff", "fern")
    scene = fern_transforms(fern, tmp_path / "fern", world)
    parser = NerfstudioDataParserConfig(data=scene, downscale=8, view_ids=(1, 10, 19)).setup()
    declared = parser.declaration()
    assert (declared.ray_space, declared.bounded, declared.occlusion_regularization) == ("ndc", False, True)
    for split in ("train", "test", "val"):
        ours = parser.get_outputs(split)
        llff = LLFFDataParserConfig(data=fern, view_ids=(1, 10, 19)).setup().get_outputs(split)
        assert ours.view_ids == llff.view_ids and ours.image_names == llff.image_names
        for name in ("camera_to_worlds", "fx", "fy", "cx", "cy"):
            torch.testing.assert_close(getattr(ours.cameras, name), getattr(llff.cameras, name), rtol=0, atol=1e-5)
        assert (ours.cameras.width, ours.cameras.height) == (llff.cameras.width, llff.cameras.height)
        assert ours.depth_bounds == pytest.approx(llff.depth_bounds, rel=1e-9)
        assert (ours.near, ours.far) == (llff.near, llff.far)
        torch.testing.assert_close(ours.scene_box, llff.scene_box)
        torch.testing.assert_close(ours.images, llff.images, rtol=0, atol=0)


def test_a_lens_that_folds_over_the_image_fails_before_training(tmp_path: Path) -> None:
    """Strong barrel distortion turns back before the image corners: no ray can be formed there."""
    scene = write_scene(tmp_path / "s", ring_c2w(N), meta={"camera_model": "OPENCV", "k1": -3.0})
    message = error_of(scene)
    assert "transforms.json, frame frame_00001.png" in message and "cannot be undone" in message
