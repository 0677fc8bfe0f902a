"""LLFF parser on synthetic ``poses_bounds.npy`` scenes written in tmp_path, plus the shared fern when present.

The synthetic poses are known OpenGL camera-to-worlds converted back to LLFF's (down, right, back) columns, so
every step of the parser (axis order, scaling, recentring, splits, the RegNeRF rule) is checked against ground
truth rather than against itself.
"""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from fourierf_plugin.cameras.camera_paths import average_pose as _average_pose_torch
from fourierf_plugin.data.parsers.llff import LLFF_DECLARATION, LLFFDataParserConfig, recenter_poses, to_opengl
from fourierf_plugin.data.view_selection import regnerf_views
from fourierf_plugin.utils.errors import UserError
from tests.conftest import require_shared
from tests.helpers import TINY_SCENE
from tests.scenes import (
    FULL_FOCAL,
    FULL_H,
    FULL_W,
    SMALL_H,
    SMALL_W,
    default_bounds,
    image_pixels,
    opengl_poses,
    to_llff_columns,
    write_llff_scene,
)


def parse(data: Path, split: str = "train", **kwargs):
    return LLFFDataParserConfig(data=data, **kwargs).setup().get_outputs(split)


def all_parsed_poses(data: Path) -> np.ndarray:
    """Every camera's parsed c2w [N, 3, 4], in file order (test split + train split, merged by view id)."""
    train, test = parse(data, "train"), parse(data, "test")
    poses = {}
    for out in (train, test):
        for vid, c2w in zip(out.view_ids, out.cameras.camera_to_worlds.numpy(), strict=True):
            poses[vid] = c2w.astype(np.float64)
    return np.stack([poses[i] for i in sorted(poses)])


def average_pose(c2w: np.ndarray) -> np.ndarray:
    return _average_pose_torch(torch.from_numpy(c2w)).double().numpy()


def _homogeneous(c2w: np.ndarray) -> np.ndarray:
    out = np.zeros((c2w.shape[0], 4, 4))
    out[:, :3] = c2w
    out[:, 3, 3] = 1.0
    return out


@pytest.fixture
def scene(tmp_path: Path) -> Path:
    return write_llff_scene(tmp_path / "scene")


# -- pose processing ------------------------------------------------------------------------------------------------


def test_to_opengl_undoes_the_llff_column_order() -> None:
    c2w = opengl_poses(5)
    np.testing.assert_allclose(to_opengl(to_llff_columns(c2w)), c2w, atol=0)


def test_to_opengl_maps_down_right_back_to_right_up_back() -> None:
    """A camera whose LLFF columns are the world axes: its OpenGL right is LLFF's 'right', its up is -'down'."""
    llff = np.concatenate([np.eye(3), np.zeros((3, 1))], axis=1)[None]  # down=x, right=y, back=z
    gl = to_opengl(llff)[0]
    np.testing.assert_array_equal(gl[:, 0], [0, 1, 0])  # right
    np.testing.assert_array_equal(gl[:, 1], [-1, 0, 0])  # up = -down
    np.testing.assert_array_equal(gl[:, 2], [0, 0, 1])  # back


def test_average_pose_is_a_proper_rotation() -> None:
    avg = average_pose(opengl_poses(20, seed=3))
    r = avg[:, :3]
    np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-6)
    assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-6)


def test_recentred_average_pose_is_the_identity() -> None:
    out = recenter_poses(opengl_poses(20, seed=4))
    np.testing.assert_allclose(average_pose(out), np.concatenate([np.eye(3), np.zeros((3, 1))], axis=1), atol=1e-6)


def test_parsed_poses_are_a_rigid_motion_of_the_scaled_input(scene: Path) -> None:
    """One world transform M (a rotation with det +1, plus a translation) maps every scaled input pose to its output."""
    truth = opengl_poses(20)
    scale = 1.0 / (0.75 * default_bounds(20)[:, 0].min())
    scaled = truth.copy()
    scaled[:, :, 3] *= scale
    parsed = all_parsed_poses(scene)
    m = _homogeneous(parsed[:1])[0] @ np.linalg.inv(_homogeneous(scaled[:1])[0])
    np.testing.assert_allclose(m[:3, :3].T @ m[:3, :3], np.eye(3), atol=1e-5)
    assert np.linalg.det(m[:3, :3]) == pytest.approx(1.0, abs=1e-5)
    np.testing.assert_allclose(m @ _homogeneous(scaled), _homogeneous(parsed), atol=1e-5)
    # every camera keeps a proper rotation, and the recentred rig is centred on the identity pose
    assert np.allclose(np.linalg.det(parsed[:, :, :3]), 1.0, atol=1e-5)
    np.testing.assert_allclose(average_pose(parsed), np.concatenate([np.eye(3), np.zeros((3, 1))], 1), atol=1e-5)


def test_translations_and_bounds_share_one_scale(scene: Path) -> None:
    """Distances between cameras scale by 1 / (0.75 min near); the nearest bound becomes 1 / 0.75."""
    bounds = default_bounds(20)
    scale = 1.0 / (0.75 * bounds[:, 0].min())
    truth = opengl_poses(20)[:, :, 3]
    parsed = all_parsed_poses(scene)[:, :, 3]
    dist = lambda p: np.linalg.norm(p[:, None] - p[None], axis=-1)  # noqa: E731
    np.testing.assert_allclose(dist(parsed), scale * dist(truth), rtol=1e-5, atol=1e-5)
    near, far = parse(scene).depth_bounds
    assert near == pytest.approx(1.0 / 0.75)
    assert far == pytest.approx(bounds[:, 1].max() * scale)


def test_bd_factor_option_changes_the_scale(scene: Path) -> None:
    near, _ = parse(scene, bd_factor=0.5).depth_bounds
    assert near == pytest.approx(2.0)


# -- splits and the few-shot rule -----------------------------------------------------------------------------------


def test_hold_out_is_every_eighth_image(scene: Path) -> None:
    test = parse(scene, "test")
    assert test.view_ids == [0, 8, 16]
    assert test.image_names == ["image000", "image008", "image016"]
    train = parse(scene, "train")
    assert train.view_ids == [i for i in range(20) if i % 8]
    assert len(train.cameras) == 17 and train.images.shape[0] == 17


def test_few_shot_val_is_unused_training_images_evenly_spaced(scene: Path) -> None:
    """Tuning on val must never see a test view nor a training view: fern's 3-view val is 2, 9, 18."""
    val = parse(scene, "val", num_views=3)
    assert val.view_ids == [2, 9, 18]
    assert not set(val.view_ids) & ({0, 8, 16} | {1, 10, 19})
    assert parse(scene, "val", num_views=3, val_views=5).view_ids == [2, 5, 9, 14, 18]
    assert parse(scene, "val", view_ids=(1, 2), val_views=1).view_ids == [3]


def test_val_falls_back_to_the_hold_out_set_when_every_training_image_is_used(scene: Path) -> None:
    assert parse(scene, "val").view_ids == [0, 8, 16]
    assert parse(scene, "val", num_views=17).view_ids == [0, 8, 16]


# Spec §2.1: RegNeRF/FreeNeRF training views per scene size, for 3, 6 and 9 views.
REGNERF_TABLE: dict[str, tuple[int, dict[int, list[int]]]] = {
    "fern": (20, {3: [1, 10, 19], 6: [1, 4, 7, 12, 15, 19], 9: [1, 3, 5, 7, 10, 12, 14, 17, 19]}),
    "flower": (34, {3: [1, 17, 33], 6: [1, 7, 13, 20, 26, 33], 9: [1, 5, 9, 12, 17, 21, 25, 28, 33]}),
    "fortress": (42, {3: [1, 21, 41], 6: [1, 9, 17, 25, 33, 41], 9: [1, 5, 11, 15, 21, 26, 30, 36, 41]}),
    "horns": (62, {3: [1, 30, 61], 6: [1, 13, 25, 37, 49, 61], 9: [1, 9, 15, 23, 30, 38, 46, 53, 61]}),
    "leaves": (26, {3: [1, 12, 25], 6: [1, 5, 10, 15, 20, 25], 9: [1, 4, 6, 10, 12, 15, 19, 21, 25]}),
    "orchids": (25, {3: [1, 12, 23], 6: [1, 5, 10, 14, 19, 23], 9: [1, 3, 6, 10, 12, 14, 18, 21, 23]}),
    "room": (41, {3: [1, 20, 39], 6: [1, 9, 17, 23, 31, 39], 9: [1, 5, 10, 15, 20, 25, 30, 35, 39]}),
    "trex": (55, {3: [1, 28, 54], 6: [1, 11, 22, 33, 44, 54], 9: [1, 7, 14, 21, 28, 34, 41, 47, 54]}),
}
TABLE_CASES = [(name, n, views, ids) for name, (n, row) in REGNERF_TABLE.items() for views, ids in row.items()]


@pytest.mark.parametrize(("scene_name", "num_images", "num_views", "expected"), TABLE_CASES)
def test_regnerf_rule_reproduces_the_spec_table(
    scene_name: str, num_images: int, num_views: int, expected: list[int]
) -> None:
    train = [i for i in range(num_images) if i % 8]
    assert [train[j] for j in regnerf_views(len(train), num_views)] == expected


@pytest.fixture(scope="module")
def sized_scenes(tmp_path_factory) -> dict[int, Path]:
    """One tiny scene per table size (8x6 images), shared by the parametrised parser cases."""
    root = tmp_path_factory.mktemp("sizes")
    return {n: write_llff_scene(root / f"n{n}", n=n) for n, _ in REGNERF_TABLE.values()}


@pytest.mark.parametrize(("scene_name", "num_images", "num_views", "expected"), TABLE_CASES)
def test_parser_num_views_reproduces_the_spec_table(
    sized_scenes: dict[int, Path], scene_name: str, num_images: int, num_views: int, expected: list[int]
) -> None:
    out = parse(sized_scenes[num_images], num_views=num_views)
    assert out.view_ids == expected
    assert out.image_names == [f"image{i:03d}" for i in expected]
    assert out.images.shape[0] == num_views


def test_explicit_view_ids_are_used(scene: Path) -> None:
    assert parse(scene, view_ids=(2, 5)).view_ids == [2, 5]


# -- images and intrinsics ------------------------------------------------------------------------------------------


def test_images_and_focal_follow_the_image_folder(scene: Path) -> None:
    out = parse(scene, num_views=3)
    assert tuple(out.images.shape) == (3, SMALL_H, SMALL_W, 4)
    cams = out.cameras
    assert (cams.width, cams.height) == (SMALL_W, SMALL_H)
    np.testing.assert_allclose(cams.fx.numpy(), FULL_FOCAL * SMALL_W / FULL_W)
    np.testing.assert_allclose(cams.fy.numpy(), FULL_FOCAL * SMALL_W / FULL_W)
    np.testing.assert_allclose(cams.cx.numpy(), SMALL_W / 2)
    np.testing.assert_allclose(cams.cy.numpy(), SMALL_H / 2)
    np.testing.assert_allclose(out.images[0, :, :, :3].numpy(), image_pixels(1, SMALL_W, SMALL_H) / 255.0, atol=1e-6)
    assert bool((out.images[..., 3] == 1).all()), "photos are opaque"


def test_ndc_scene_box_and_declaration(scene: Path) -> None:
    parser = LLFFDataParserConfig(data=scene).setup()
    out = parser.get_outputs("train")
    np.testing.assert_allclose(out.scene_box.numpy(), [[-1.5, -1.67, -1.0], [1.5, 1.67, 1.0]])
    assert (out.near, out.far) == (0.0, 1.0)
    d = parser.declaration()
    assert d == LLFF_DECLARATION
    assert (d.background, d.ray_space, d.bounded, d.view_dependent, d.occlusion_regularization) == (
        "none",
        "ndc",
        False,
        False,
        True,
    )


def test_missing_exact_folder_resizes_the_next_larger_one(tmp_path: Path) -> None:
    """images_8 absent, images_4 (16x12) present: read images_4 and halve it (exact 2x2 block means)."""
    data = write_llff_scene(tmp_path / "s", folders={"images_4": 4})
    out = parse(data, num_views=3)
    assert tuple(out.images.shape) == (3, SMALL_H, SMALL_W, 4)
    big = image_pixels(1, FULL_W // 4, FULL_H // 4) / 255.0
    halved = big.reshape(SMALL_H, 2, SMALL_W, 2, 3).mean(axis=(1, 3))
    np.testing.assert_allclose(out.images[0, :, :, :3].numpy(), halved, atol=1e-6)
    np.testing.assert_allclose(out.cameras.fx.numpy(), FULL_FOCAL * SMALL_W / FULL_W)


def test_downscale_four_reads_images_4(tmp_path: Path) -> None:
    data = write_llff_scene(tmp_path / "s", folders={"images_4": 4, "images_8": 8})
    out = parse(data, downscale=4, num_views=3)
    assert (out.cameras.width, out.cameras.height) == (FULL_W // 4, FULL_H // 4)
    np.testing.assert_allclose(out.cameras.fx.numpy(), FULL_FOCAL / 4)


# -- bad inputs: each a UserError naming the file or option ---------------------------------------------------------


def _user_error(data: Path, **kwargs) -> UserError:
    with pytest.raises(UserError) as info:
        parse(data, **kwargs)
    return info.value


def test_no_usable_image_folder_for_the_downscale(tmp_path: Path) -> None:
    data = write_llff_scene(tmp_path / "s", folders={"images_3": 3})
    err = _user_error(data)
    assert "images_8" in err.problem and "images_3" in err.problem
    assert err.fix


def test_wrong_column_count(scene: Path) -> None:
    np.save(scene / "poses_bounds.npy", np.zeros((20, 15)))
    err = _user_error(scene)
    assert "poses_bounds.npy" in err.problem and "17" in err.problem and "(20, 15)" in err.problem


def test_pose_count_differs_from_image_count(scene: Path) -> None:
    (scene / "images_8" / "image019.png").unlink()
    err = _user_error(scene)
    assert "poses_bounds.npy" in err.problem and "20" in err.problem and "19" in err.problem


def test_missing_image_folder(scene: Path) -> None:
    for f in (scene / "images_8").iterdir():
        f.unlink()
    (scene / "images_8").rmdir()
    err = _user_error(scene)
    assert "images_8" in err.problem and str(scene) in err.problem


def test_missing_poses_bounds(scene: Path) -> None:
    (scene / "poses_bounds.npy").unlink()
    assert "poses_bounds.npy" in _user_error(scene).problem


def test_mixed_image_sizes(scene: Path) -> None:
    iio.imwrite(scene / "images_8" / "image003.png", image_pixels(3, SMALL_W + 2, SMALL_H))
    err = _user_error(scene)
    assert "image003.png" in err.problem and "same size" in err.problem


def test_nan_in_poses(scene: Path) -> None:
    arr = np.load(scene / "poses_bounds.npy")
    arr[4, 3] = np.nan
    np.save(scene / "poses_bounds.npy", arr)
    err = _user_error(scene)
    assert "poses_bounds.npy" in err.problem and "NaN" in err.problem and "[4]" in err.problem


@pytest.mark.parametrize(
    ("rotation", "expected"),
    [(np.zeros((3, 3)), "singular"), (3.0 * np.eye(3), "not orthonormal"), (np.diag([1.0, 1.0, -1.0]), "mirrors")],
)
def test_degenerate_poses_are_refused_naming_the_camera(scene: Path, rotation: np.ndarray, expected: str) -> None:
    arr = np.load(scene / "poses_bounds.npy")
    pose = arr[6, :15].reshape(3, 5)
    pose[:, :3] = rotation
    arr[6, :15] = pose.reshape(-1)
    np.save(scene / "poses_bounds.npy", arr)
    err = _user_error(scene)
    assert "poses_bounds.npy, row 6 (camera 6): not a camera pose" in err.problem and expected in err.problem


def test_num_views_larger_than_the_training_split(scene: Path) -> None:
    err = _user_error(scene, num_views=18)
    assert "--num-views 18" in err.problem and "17" in err.problem and "17" in (err.fix or "")


def test_view_ids_naming_a_hold_out_image(scene: Path) -> None:
    err = _user_error(scene, view_ids=(1, 8))
    assert "--view-ids" in err.problem and "[8]" in err.problem


def test_view_ids_out_of_range(scene: Path) -> None:
    assert "20" in _user_error(scene, view_ids=(1, 25)).problem


def test_blender_folder_given_to_llff(tmp_path: Path) -> None:
    err = _user_error(TINY_SCENE)
    assert "Blender" in err.problem and "blender-data" in (err.fix or "")


def test_missing_data_folder(tmp_path: Path) -> None:
    assert str(tmp_path / "nowhere") in _user_error(tmp_path / "nowhere").problem


@pytest.mark.parametrize(
    "option", [{"downscale": 0}, {"num_views": 0}, {"hold_every": 1}, {"bd_factor": 0.0}, {"val_views": 0}]
)
def test_bad_options(scene: Path, option: dict) -> None:
    flag = "--" + next(iter(option)).replace("_", "-")
    assert flag in _user_error(scene, **option).problem


# -- the shared fern ------------------------------------------------------------------------------------------------


def test_fern_three_views() -> None:
    fern = require_shared("data", "llff", "fern")
    train = parse(fern, num_views=3)
    assert train.view_ids == [1, 10, 19]
    assert (train.cameras.width, train.cameras.height) == (504, 378)
    assert tuple(train.images.shape) == (3, 378, 504, 4)
    assert train.scene_name == "fern"
    test = parse(fern, "test")
    assert test.view_ids == [0, 8, 16]
    assert tuple(test.images.shape) == (3, 378, 504, 4)
