"""transforms.json as nerfstudio writes it, from a Capture; LLFF scenes read as a Capture."""

from __future__ import annotations

import json
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from fourierf_plugin.data.capture import Capture, Frame, Intrinsics
from fourierf_plugin.data.colmap_model import capture_from_model, read_model
from fourierf_plugin.data.nerfstudio_writer import capture_from_llff, write_transforms
from fourierf_plugin.data.parsers.llff import load_poses_bounds, to_opengl
from fourierf_plugin.utils.errors import UserError
from tests.conftest import require_shared
from tests.data.colmap_fixtures import make_model, write_binary, write_photos

OPENCV = Intrinsics(60.0, 61.0, 32.0, 24.0, 64, 48, "OPENCV", (0.01, -0.02, 0.003, 0.0, 1e-4, -2e-4))


def _frame(folder: Path, name: str, intr: Intrinsics = OPENCV, **extra) -> Frame:
    pose = np.eye(4)
    pose[:3, 3] = [len(name), 2.0, 3.0]
    return Frame(folder / "images" / name, pose, intr, **extra)


def test_shared_intrinsics_go_to_the_top_and_paths_are_relative(tmp_path: Path) -> None:
    frames = [_frame(tmp_path, "a.jpg", depth_bounds=(1.5, 9.0)), _frame(tmp_path, "bb.png")]
    capture = Capture(frames, source=tmp_path / "model", applied_transform=np.eye(4)[[0, 2, 1]])
    path = write_transforms(capture, tmp_path / "transforms.json")
    content = json.loads(path.read_text())
    assert {k: content[k] for k in ("w", "h", "fl_x", "fl_y", "cx", "cy", "camera_model")} == {
        "w": 64, "h": 48, "fl_x": 60.0, "fl_y": 61.0, "cx": 32.0, "cy": 24.0, "camera_model": "OPENCV"
    }  # fmt: skip
    assert {k: content[k] for k in ("k1", "k2", "k3", "p1", "p2")} == pytest.approx(
        {"k1": 0.01, "k2": -0.02, "k3": 0.003, "p1": 1e-4, "p2": -2e-4}
    )
    assert "k4" not in content
    assert [f["file_path"] for f in content["frames"]] == ["images/a.jpg", "images/bb.png"]
    np.testing.assert_allclose(content["frames"][1]["transform_matrix"], frames[1].camera_to_world)
    assert content["frames"][0]["depth_bounds"] == [1.5, 9.0]
    assert "depth_bounds" not in content["frames"][1]
    assert "fl_x" not in content["frames"][0]
    np.testing.assert_allclose(content["applied_transform"], np.eye(4)[[0, 2, 1]])
    assert "ply_file_path" not in content  # no points, no point cloud
    assert not (tmp_path / "sparse_pc.ply").exists()


def test_differing_intrinsics_are_written_per_frame(tmp_path: Path) -> None:
    fisheye = Intrinsics(40.0, 40.0, 20.0, 15.0, 40, 30, "OPENCV_FISHEYE", (0.1, -0.01, 0.002, -0.001, 0.0, 0.0))
    pinhole = Intrinsics(40.0, 41.0, 20.0, 15.0, 40, 30, "PINHOLE")
    capture = Capture([_frame(tmp_path, "a.png", fisheye), _frame(tmp_path, "b.png", pinhole)], source=tmp_path)
    content = json.loads(write_transforms(capture, tmp_path / "out" / "transforms.json").read_text())
    assert "fl_x" not in content and "camera_model" not in content
    first, second = content["frames"]
    assert first["camera_model"] == "OPENCV_FISHEYE" and second["camera_model"] == "PINHOLE"
    assert [first[k] for k in ("k1", "k2", "k3", "k4")] == pytest.approx([0.1, -0.01, 0.002, -0.001])
    assert not any(k in second for k in ("k1", "k2", "k3", "k4", "p1", "p2"))
    assert (second["fl_x"], second["fl_y"], second["w"], second["h"]) == (40.0, 41.0, 40, 30)
    assert first["file_path"] == "../images/a.png"  # relative to the json's own folder


def test_masks_splits_and_the_point_cloud(tmp_path: Path) -> None:
    import trimesh

    frames = [_frame(tmp_path, "a.png", mask_path=tmp_path / "masks" / "a.png"), _frame(tmp_path, "b.png")]
    points = np.random.default_rng(0).normal(size=(30, 3))
    colors = np.random.default_rng(1).integers(0, 256, (30, 3)).astype(np.uint8)
    capture = Capture(
        frames, source=tmp_path, points=points, splits={"train": ["images/a.png"], "val": ["images/b.png"]}
    )
    content = json.loads(write_transforms(capture, tmp_path / "transforms.json", point_colors=colors).read_text())
    assert content["frames"][0]["mask_path"] == "masks/a.png"
    assert "mask_path" not in content["frames"][1]
    assert content["train_filenames"] == ["images/a.png"] and content["val_filenames"] == ["images/b.png"]
    assert content["ply_file_path"] == "sparse_pc.ply"
    cloud = trimesh.load(tmp_path / "sparse_pc.ply")
    np.testing.assert_allclose(np.asarray(cloud.vertices), points, rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(np.asarray(cloud.colors)[:, :3], colors)


def test_a_colmap_capture_round_trips_through_the_json(tmp_path: Path) -> None:
    model = make_model()
    capture = capture_from_model(
        read_model(write_binary(model, tmp_path / "sparse")), write_photos(model, tmp_path / "images")
    )
    content = json.loads(write_transforms(capture, tmp_path / "transforms.json").read_text())
    assert len(content["frames"]) == len(capture.frames) == 5
    for frame, entry in zip(capture.frames, content["frames"], strict=True):
        assert (tmp_path / entry["file_path"]).resolve() == frame.image_path.resolve()
        np.testing.assert_allclose(entry["transform_matrix"], frame.camera_to_world, atol=0)
        assert entry["depth_bounds"] == pytest.approx(list(frame.depth_bounds))
    np.testing.assert_allclose(content["applied_transform"], [[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0]])
    assert (content["fl_x"], content["fl_y"], content["cx"], content["cy"]) == (60.0, 62.0, 32.5, 23.5)


def test_writing_an_empty_capture_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="no frames"):
        write_transforms(Capture([], source=tmp_path / "x"), tmp_path / "transforms.json")


# -- LLFF -> Capture ------------------------------------------------------------------------------------------------


def _llff_scene(root: Path, n: int = 4, size: tuple[int, int] = (32, 24), full: tuple[int, int] = (256, 192)) -> Path:
    """poses_bounds.npy for ``full``-size photos, with ``images_8`` holding ``size``-d ones."""
    rng = np.random.default_rng(0)
    rows = []
    for i in range(n):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        q *= np.sign(np.linalg.det(q))
        pose = np.c_[q, rng.normal(size=3), [full[1], full[0], 200.0 + i]]
        rows.append(np.r_[pose.ravel(), 1.0 + i, 10.0 + i])
    root.mkdir(parents=True)
    np.save(root / "poses_bounds.npy", np.array(rows))
    folder = root / "images_8"
    folder.mkdir()
    for i in range(n):
        iio.imwrite(folder / f"IMG_{i:04d}.png", np.full((size[1], size[0], 3), 40 * i, dtype=np.uint8))
    return root


def test_llff_scene_as_a_capture(tmp_path: Path) -> None:
    scene = _llff_scene(tmp_path / "scene")
    raw, _, bounds = load_poses_bounds(scene / "poses_bounds.npy")
    capture = capture_from_llff(scene)
    assert [f.image_path.name for f in capture.frames] == [f"IMG_{i:04d}.png" for i in range(4)]
    for i, frame in enumerate(capture.frames):
        # LLFF's columns are (down, right, back): OpenGL's (right, up, back) is (c1, -c0, c2)
        np.testing.assert_allclose(frame.camera_to_world[:3, 0], raw[i, :, 1])
        np.testing.assert_allclose(frame.camera_to_world[:3, 1], -raw[i, :, 0])
        np.testing.assert_allclose(frame.camera_to_world[:3, 2:4], raw[i, :, 2:4])
        np.testing.assert_allclose(frame.camera_to_world[3], [0, 0, 0, 1])
        intr = frame.intrinsics
        assert (intr.width, intr.height, intr.cx, intr.cy) == (32, 24, 16.0, 12.0)
        assert intr.fx == intr.fy == pytest.approx((200.0 + i) / 8)
        assert intr.camera_model == "PINHOLE"
        assert frame.depth_bounds == tuple(bounds[i])
    assert capture.applied_transform is None and len(capture.points) == 0


def test_llff_mismatches_are_clear_errors(tmp_path: Path) -> None:
    scene = _llff_scene(tmp_path / "a")
    (scene / "images_8" / "IMG_0002.png").unlink()
    with pytest.raises(UserError, match=r"has 4 poses but .* has 3 images"):
        capture_from_llff(scene)
    scene = _llff_scene(tmp_path / "b", size=(32, 32))
    with pytest.raises(UserError, match="different aspect ratio"):
        capture_from_llff(scene)
    with pytest.raises(UserError, match="images_2 not found"):
        capture_from_llff(_llff_scene(tmp_path / "c"), "images_2")


def test_fern_as_a_capture_matches_the_llff_parser_poses() -> None:
    fern = require_shared("data", "llff", "fern")
    capture = capture_from_llff(fern, "images_8")
    raw, hwf, bounds = load_poses_bounds(fern / "poses_bounds.npy")
    assert len(capture.frames) == 20
    np.testing.assert_allclose(np.stack([f.camera_to_world[:3] for f in capture.frames]), to_opengl(raw))
    intr = capture.frames[0].intrinsics
    assert (intr.width, intr.height) == (504, 378)
    assert intr.fx == pytest.approx(hwf[0, 2] * 504 / hwf[0, 1])
    assert capture.frames[5].depth_bounds == tuple(bounds[5])
