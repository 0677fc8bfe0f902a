"""Reading COLMAP sparse models (text and binary) and turning them into a Capture in nerfstudio's world frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fourierf_plugin.data.colmap_model import (
    ColmapCamera,
    capture_from_model,
    depth_bounds,
    intrinsics_of,
    qvec_to_rotation,
    read_model,
)
from fourierf_plugin.utils.errors import UserError
from tests.conftest import require_module
from tests.data.colmap_fixtures import (
    Camera,
    make_model,
    rotation_to_qvec,
    write_binary,
    write_photos,
    write_text,
)

TWO_CAMERAS = [
    Camera(1, "OPENCV", 64, 48, (60.0, 62.0, 32.5, 23.5, 0.01, -0.002, 1e-4, -2e-4)),
    Camera(7, "SIMPLE_RADIAL", 80, 60, (70.0, 40.0, 30.0, -0.03)),
]


def _nerfstudio_c2w(rot: np.ndarray, t: np.ndarray) -> np.ndarray:
    """nerfstudio's colmap_to_json, restated: invert, flip camera y/z, swap world y/z rows, negate world z."""
    w2c = np.eye(4)
    w2c[:3, :3], w2c[:3, 3] = rot, t
    c2w = np.linalg.inv(w2c)
    c2w[0:3, 1:3] *= -1
    c2w = c2w[np.array([0, 2, 1, 3]), :]
    c2w[2, :] *= -1
    return c2w


def test_text_and_binary_readers_agree_with_what_was_written(tmp_path: Path) -> None:
    model = make_model(cameras=TWO_CAMERAS)
    text = read_model(write_text(model, tmp_path / "txt"))
    binary = read_model(write_binary(model, tmp_path / "bin"))
    for read in (text, binary):
        assert set(read.cameras) == {1, 7}
        assert read.cameras[7].model == "SIMPLE_RADIAL" and read.cameras[7].params == (70.0, 40.0, 30.0, -0.03)
        assert [read.images[i].name for i in sorted(read.images)] == [im.name for im in model.images]
        for im in model.images:
            np.testing.assert_allclose(qvec_to_rotation(read.images[im.image_id].qvec), im.rotation, atol=1e-12)
            np.testing.assert_allclose(read.images[im.image_id].tvec, im.translation, atol=1e-12)
        np.testing.assert_allclose(read.points, model.points, atol=1e-12)
        np.testing.assert_array_equal(read.colors, model.colors)
        assert len(read.observation_points) == len(model.points) * len(model.images)
    np.testing.assert_array_equal(text.observation_images, binary.observation_images)
    np.testing.assert_array_equal(text.observation_points, binary.observation_points)
    assert text.mean_reprojection_error() == pytest.approx(model.errors.mean())


def test_binary_reader_reads_what_colmap_itself_writes(tmp_path: Path) -> None:
    pycolmap = require_module("pycolmap", "pycolmap (the [colmap] extra) writes the reference files")
    model = make_model(cameras=TWO_CAMERAS)
    model.tracks = [track[j % 3 :] for j, track in enumerate(model.tracks)]  # not every image sees every point
    ours = read_model(write_text(model, tmp_path / "txt"))
    reconstruction = pycolmap.Reconstruction(str(tmp_path / "txt"))
    (tmp_path / "colmap_bin").mkdir()
    reconstruction.write_binary(str(tmp_path / "colmap_bin"))
    theirs = read_model(tmp_path / "colmap_bin")
    assert {k: (c.model, c.width, c.height) for k, c in theirs.cameras.items()} == {
        k: (c.model, c.width, c.height) for k, c in ours.cameras.items()
    }
    for k, c in ours.cameras.items():
        np.testing.assert_allclose(theirs.cameras[k].params, c.params)
    for k, im in ours.images.items():
        np.testing.assert_allclose(qvec_to_rotation(theirs.images[k].qvec), qvec_to_rotation(im.qvec), atol=1e-12)
        np.testing.assert_allclose(theirs.images[k].tvec, im.tvec, atol=1e-12)
        assert theirs.images[k].name == im.name
    order = np.lexsort((ours.observation_images, ours.observation_points))
    order_theirs = np.lexsort((theirs.observation_images, theirs.observation_points))
    np.testing.assert_allclose(theirs.points, ours.points)
    np.testing.assert_array_equal(theirs.observation_images[order_theirs], ours.observation_images[order])


def test_poses_follow_nerfstudio_and_points_move_with_the_world(tmp_path: Path) -> None:
    model = make_model(names=["b.png", "a.png", "c.png"])
    folder = write_binary(model, tmp_path / "sparse" / "0")
    capture = capture_from_model(read_model(folder), write_photos(model, tmp_path / "images"))
    by_name = {im.name: im for im in model.images}
    assert [f.image_path.name for f in capture.frames] == ["a.png", "b.png", "c.png"]
    applied = np.asarray(capture.applied_transform)
    np.testing.assert_allclose(applied, [[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0]])
    np.testing.assert_allclose(capture.points, model.points @ applied[:, :3].T)
    for frame in capture.frames:
        im = by_name[frame.image_path.name]
        np.testing.assert_allclose(frame.camera_to_world, _nerfstudio_c2w(im.rotation, im.translation), atol=1e-12)
        # a world point seen by the OpenCV camera at (x, y, z) is at (x, -y, -z) for the OpenGL one
        opencv = model.points @ im.rotation.T + im.translation
        opengl = (np.linalg.inv(frame.camera_to_world) @ np.c_[capture.points, np.ones(len(capture.points))].T).T
        np.testing.assert_allclose(opengl[:, :3], opencv * [1, -1, -1], atol=1e-9)


def test_depth_bounds_are_percentiles_of_the_observed_depths(tmp_path: Path) -> None:
    model = make_model(n_points=200)
    model.tracks = [track if j % 3 else track[:1] for j, track in enumerate(model.tracks)]  # some seen by image 1 only
    read = read_model(write_text(model, tmp_path / "m"))
    bounds = depth_bounds(read, min_track_length=1)
    for im in model.images:
        seen = [j for j, track in enumerate(model.tracks) if im.image_id in track]
        depths = (model.points[seen] @ im.rotation.T + im.translation)[:, 2]
        assert bounds[im.image_id] == pytest.approx(tuple(np.percentile(depths, [0.1, 99.9])))


def test_depth_bounds_leave_out_points_seen_in_two_photos_only(tmp_path: Path) -> None:
    model = make_model(n_points=200)
    clean = depth_bounds(read_model(write_text(model, tmp_path / "clean")))
    first, second = model.images[:2]
    stray = 0.9 * (-first.rotation.T @ first.translation)  # close before the first camera's lens
    model.points = np.concatenate([model.points, stray[None]])
    model.colors = np.concatenate([model.colors, model.colors[:1]])
    model.errors = np.concatenate([model.errors, model.errors[:1]])
    model.tracks = [*model.tracks, [first.image_id, second.image_id]]  # a false match of two photos
    read = read_model(write_text(model, tmp_path / "stray"))
    assert depth_bounds(read, min_track_length=1)[first.image_id][0] < 0.5 * clean[first.image_id][0]
    assert depth_bounds(read) == clean


def test_an_image_with_only_short_tracks_keeps_its_bounds(tmp_path: Path) -> None:
    model = make_model(n_points=200)
    model.tracks = [track[:2] for track in model.tracks]  # every point seen in two photos at most
    read = read_model(write_text(model, tmp_path / "m"))
    assert depth_bounds(read) == depth_bounds(read, min_track_length=1)


def test_images_that_observe_no_point_have_no_depth_bounds(tmp_path: Path) -> None:
    model = make_model()
    model.tracks = [[t for t in track if t != 3] for track in model.tracks]
    capture = capture_from_model(read_model(write_text(model, tmp_path / "m")), write_photos(model, tmp_path / "i"))
    assert [f.depth_bounds is None for f in capture.frames] == [False, False, True, False, False]


@pytest.mark.parametrize(
    ("model", "params", "expected_model", "expected"),
    [
        ("SIMPLE_PINHOLE", (50.0, 31.0, 24.0), "SIMPLE_PINHOLE", (50, 50, 31, 24, (0, 0, 0, 0, 0, 0))),
        ("PINHOLE", (50.0, 51.0, 31.0, 24.0), "PINHOLE", (50, 51, 31, 24, (0, 0, 0, 0, 0, 0))),
        ("SIMPLE_RADIAL", (50.0, 31.0, 24.0, 0.1), "OPENCV", (50, 50, 31, 24, (0.1, 0, 0, 0, 0, 0))),
        ("RADIAL", (50.0, 31.0, 24.0, 0.1, -0.2), "OPENCV", (50, 50, 31, 24, (0.1, -0.2, 0, 0, 0, 0))),
        ("OPENCV", (50, 51, 31, 24, 0.1, -0.2, 0.01, 0.02), "OPENCV", (50, 51, 31, 24, (0.1, -0.2, 0, 0, 0.01, 0.02))),
        ("FULL_OPENCV", (50, 51, 31, 24, 0.1, -0.2, 0.01, 0.02, 0.3, 0, 0, 0), "OPENCV",
         (50, 51, 31, 24, (0.1, -0.2, 0.3, 0, 0.01, 0.02))),
        ("OPENCV_FISHEYE", (50, 51, 31, 24, 0.1, -0.2, 0.3, -0.4), "OPENCV_FISHEYE",
         (50, 51, 31, 24, (0.1, -0.2, 0.3, -0.4, 0, 0))),
        ("RADIAL_FISHEYE", (50, 31, 24, 0.1, -0.2), "OPENCV_FISHEYE", (50, 50, 31, 24, (0.1, -0.2, 0, 0, 0, 0))),
        ("FISHEYE", (50, 51, 31, 24), "OPENCV_FISHEYE", (50, 51, 31, 24, (0, 0, 0, 0, 0, 0))),
    ],
)  # fmt: skip
def test_camera_models_map_to_ours(model: str, params: tuple, expected_model: str, expected: tuple) -> None:
    intr = intrinsics_of(ColmapCamera(3, model, 62, 48, tuple(float(p) for p in params)), "cameras.bin")
    assert intr.camera_model == expected_model
    assert (intr.fx, intr.fy, intr.cx, intr.cy) == pytest.approx(expected[:4])
    assert intr.distortion == pytest.approx(expected[4])
    assert (intr.width, intr.height) == (62, 48)


def _project(intr, cam_points: np.ndarray) -> np.ndarray:
    """Our models' projection in closed form: OPENCV radial-tangential, OPENCV_FISHEYE equidistant."""
    k1, k2, k3, k4, p1, p2 = intr.distortion
    x, y = cam_points[:, 0] / cam_points[:, 2], cam_points[:, 1] / cam_points[:, 2]
    if intr.camera_model == "OPENCV_FISHEYE":
        r = np.hypot(x, y)
        theta = np.arctan(r)
        theta_d = theta * (1 + k1 * theta**2 + k2 * theta**4 + k3 * theta**6 + k4 * theta**8)
        scale = np.where(r > 0, theta_d / np.maximum(r, 1e-12), 1.0)
        xd, yd = x * scale, y * scale
    else:
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([intr.fx * xd + intr.cx, intr.fy * yd + intr.cy], axis=1)


@pytest.mark.parametrize(
    ("model", "params"),
    [
        ("SIMPLE_RADIAL", (50.0, 31.0, 24.0, 0.08)),
        ("RADIAL", (50.0, 31.0, 24.0, 0.08, -0.03)),
        ("OPENCV", (50.0, 52.0, 31.0, 24.0, 0.08, -0.03, 0.002, -0.001)),
        ("FULL_OPENCV", (50.0, 52.0, 31.0, 24.0, 0.08, -0.03, 0.002, -0.001, 0.01, 0.0, 0.0, 0.0)),
        ("OPENCV_FISHEYE", (50.0, 52.0, 31.0, 24.0, 0.05, -0.02, 0.01, -0.004)),
        ("SIMPLE_RADIAL_FISHEYE", (50.0, 31.0, 24.0, 0.05)),
        ("RADIAL_FISHEYE", (50.0, 31.0, 24.0, 0.05, -0.02)),
        ("SIMPLE_FISHEYE", (50.0, 31.0, 24.0)),
        ("FISHEYE", (50.0, 52.0, 31.0, 24.0)),
    ],
)
def test_mapped_models_project_exactly_as_colmap_does(model: str, params: tuple) -> None:
    pycolmap = require_module("pycolmap", "pycolmap (the [colmap] extra) gives COLMAP's projections")
    camera = pycolmap.Camera.create_from_model_name(1, model, 50.0, 62, 48)
    camera.params = list(params)
    cam_points = np.random.default_rng(0).uniform([-0.5, -0.4, 1.0], [0.5, 0.4, 2.0], (50, 3))
    intr = intrinsics_of(ColmapCamera(1, model, 62, 48, params), "cameras.bin")
    np.testing.assert_allclose(_project(intr, cam_points), camera.img_from_cam(cam_points), atol=1e-9)


def test_rotation_and_quaternion_round_trip() -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        q = rng.normal(size=4)
        q *= np.sign(q[0]) / np.linalg.norm(q)
        rot = qvec_to_rotation(q)
        np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(rot) == pytest.approx(1.0)
        np.testing.assert_allclose(rotation_to_qvec(rot), q, atol=1e-9)


# -- errors ---------------------------------------------------------------------------------------------------------


def test_missing_folder_and_missing_files_are_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="model folder not found"):
        read_model(tmp_path / "nope")
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "cameras.bin").write_bytes(b"")
    with pytest.raises(UserError, match=r"no COLMAP model.*cameras.bin \+ images.bin"):
        read_model(tmp_path / "empty")


def test_a_model_with_no_images_is_a_clear_error(tmp_path: Path) -> None:
    model = make_model()
    model.images, model.tracks = [], [[] for _ in model.tracks]
    read = read_model(write_binary(model, tmp_path / "m"))
    with pytest.raises(UserError, match="has no registered images") as info:
        capture_from_model(read, tmp_path)
    assert "more overlapping photos" in info.value.fix


def test_unsupported_camera_models_are_named(tmp_path: Path) -> None:
    model = make_model(cameras=[Camera(1, "FOV", 64, 48, (60.0, 60.0, 32.0, 24.0, 0.9))])
    read = read_model(write_text(model, tmp_path / "m"))
    with pytest.raises(UserError, match="camera 1 uses the COLMAP camera model FOV") as info:
        capture_from_model(read, write_photos(model, tmp_path / "images"))
    assert "OPENCV" in info.value.fix
    with pytest.raises(UserError, match="FULL_OPENCV with the rational terms"):
        intrinsics_of(ColmapCamera(1, "FULL_OPENCV", 8, 8, (5, 5, 4, 4, 0, 0, 0, 0, 0, 0.1, 0, 0)), "cameras.txt")


def test_images_missing_on_disk_are_listed(tmp_path: Path) -> None:
    model = make_model()
    images = write_photos(model, tmp_path / "images")
    (images / "img_01.png").unlink()
    (images / "img_03.png").unlink()
    with pytest.raises(UserError, match=r"2 of the 5 images .* are not in .*: img_01.png, img_03.png"):
        capture_from_model(read_model(write_binary(model, tmp_path / "m")), images)
    with pytest.raises(UserError, match="image folder not found"):
        capture_from_model(read_model(tmp_path / "m"), tmp_path / "elsewhere")


def test_truncated_binary_and_malformed_text_are_clear_errors(tmp_path: Path) -> None:
    model = make_model()
    folder = write_binary(model, tmp_path / "bin")
    data = (folder / "images.bin").read_bytes()
    (folder / "images.bin").write_bytes(data[: len(data) // 2])
    with pytest.raises(UserError, match=r"images.bin ends early"):
        read_model(folder)
    folder = write_text(model, tmp_path / "txt")
    lines = (folder / "cameras.txt").read_text().splitlines()
    (folder / "cameras.txt").write_text("\n".join([*lines, "2 PINHOLE 64 48 60.0 60.0"]) + "\n")
    with pytest.raises(UserError, match=r"cameras.txt, line 3: camera model PINHOLE takes 4 parameters, found 2"):
        read_model(folder)


def test_a_non_finite_pose_is_named(tmp_path: Path) -> None:
    model = make_model()
    model.images[2].translation = np.array([np.nan, 0.0, 1.0])
    read = read_model(write_text(model, tmp_path / "m"))
    with pytest.raises(UserError, match=r"image 'img_02\.png' .* non-finite pose"):
        capture_from_model(read, write_photos(model, tmp_path / "images"))
