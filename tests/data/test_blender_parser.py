"""The Blender DataParser on tiny synthetic scenes, the bundled demo scene and the shared lego."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from fourierf_plugin.data.parsers.blender import BLENDER_DECLARATION, BlenderDataParserConfig
from fourierf_plugin.utils.errors import UserError
from tests.helpers import TINY_SCENE

ANGLE = 0.7


def _c2w(i: int, n: int) -> list[list[float]]:
    """A camera on a circle of radius 4 (distinct per frame); the parser uses the matrix as is."""
    theta = 2 * math.pi * i / n
    c, s = math.cos(theta), math.sin(theta)
    return [[c, 0.0, s, 4 * s], [s, 0.0, -c, -4 * c], [0.0, 1.0, 0.0, 0.5], [0.0, 0.0, 0.0, 1.0]]


def _image(i: int, size: int) -> np.ndarray:
    rng = np.random.default_rng(i)
    img = rng.integers(0, 256, (size, size, 4), dtype=np.uint8)
    img[0, 0] = (255, 0, 0, 128)  # red at half alpha
    return img


def make_scene(root: Path, counts: dict[str, int] | None = None, size: int = 16) -> Path:
    """A NeRF-synthetic-shaped scene: transforms_{split}.json and RGBA PNGs named r_<i>."""
    counts = counts or {"train": 5, "val": 2, "test": 5}
    root.mkdir(parents=True, exist_ok=True)
    for split, n in counts.items():
        (root / split).mkdir(exist_ok=True)
        frames = []
        for i in range(n):
            iio.imwrite(root / split / f"r_{i}.png", _image(100 * len(split) + i, size))
            frames.append({"file_path": f"./{split}/r_{i}", "rotation": 0.0, "transform_matrix": _c2w(i, n)})
        meta = {"camera_angle_x": ANGLE, "frames": frames}
        (root / f"transforms_{split}.json").write_text(json.dumps(meta, indent=2))
    return root


def parse(data: Path, split: str = "train", **kw: Any):
    return BlenderDataParserConfig(data=data, **kw).setup().get_outputs(split)


@pytest.fixture
def scene(tmp_path: Path) -> Path:
    return make_scene(tmp_path / "toy")


def test_outputs_shapes_cameras_and_declaration(scene: Path) -> None:
    parser = BlenderDataParserConfig(data=scene).setup()
    out = parser.get_outputs("train")
    assert out.images.shape == (5, 16, 16, 4) and out.images.dtype == torch.float32
    assert out.view_ids == [0, 1, 2, 3, 4] and out.image_names == [f"r_{i}" for i in range(5)]
    cams = out.cameras
    assert len(cams) == 5 and (cams.width, cams.height) == (16, 16)
    focal = 8 / math.tan(ANGLE / 2)
    torch.testing.assert_close(cams.fx, torch.full((5,), focal))
    torch.testing.assert_close(cams.fy, cams.fx)
    torch.testing.assert_close(cams.cx, torch.full((5,), 8.0))
    torch.testing.assert_close(cams.cy, torch.full((5,), 8.0))
    torch.testing.assert_close(cams.camera_to_worlds[2], torch.tensor(_c2w(2, 5))[:3])
    assert parser.declaration() == BLENDER_DECLARATION  # its values: tests/data/test_scene_effects.py
    torch.testing.assert_close(out.scene_box, torch.tensor([[-1.5] * 3, [1.5] * 3]))
    assert (out.near, out.far) == (2.0, 6.0)
    assert out.scene_name == "toy"
    assert out.source_files == [scene / "train" / f"r_{i}.png" for i in range(5)]


def test_images_are_premultiplied(scene: Path) -> None:
    img = parse(scene).images[0]
    a = 128 / 255
    torch.testing.assert_close(img[0, 0], torch.tensor([a, 0.0, 0.0, a]))
    raw = torch.from_numpy(_image(100 * 5, 16).astype(np.float32) / 255)
    torch.testing.assert_close(img[..., :3], raw[..., :3] * raw[..., 3:])


def test_downscale_is_an_exact_area_average_and_scales_focal(scene: Path) -> None:
    full = parse(scene).images
    out = parse(scene, downscale=4)
    assert out.images.shape == (5, 4, 4, 4)
    torch.testing.assert_close(out.images[1, 2, 3], full[1, 8:12, 12:16].mean(dim=(0, 1)))
    assert out.cameras.width == 4
    torch.testing.assert_close(out.cameras.fx[0], torch.tensor(2 / math.tan(ANGLE / 2)))
    torch.testing.assert_close(out.cameras.cx[0], torch.tensor(2.0))


def test_view_ids_keep_their_order(scene: Path) -> None:
    full = parse(scene)
    out = parse(scene, view_ids=(3, 0, 2), num_views=1)  # explicit ids override num_views
    assert out.view_ids == [3, 0, 2] and out.image_names == ["r_3", "r_0", "r_2"]
    torch.testing.assert_close(out.images, full.images[[3, 0, 2]])
    torch.testing.assert_close(out.cameras.camera_to_worlds, full.cameras.camera_to_worlds[[3, 0, 2]])


def test_num_views_picks_distinct_sorted_ids_on_train_only(scene: Path) -> None:
    out = parse(scene, num_views=3)
    assert len(out.view_ids) == 3 == len(set(out.view_ids)) and out.view_ids == sorted(out.view_ids)
    assert out.image_names == [f"r_{i}" for i in out.view_ids]
    assert parse(scene, num_views=3).view_ids == out.view_ids
    assert parse(scene, "test", num_views=2).view_ids == [0, 1, 2, 3, 4]


def test_test_every_subsamples_test_and_val(scene: Path) -> None:
    out = parse(scene, "test", test_every=2)
    assert out.view_ids == [0, 2, 4] and out.image_names == ["r_0", "r_2", "r_4"]
    assert out.images.shape[0] == 3
    assert parse(scene, "val", test_every=2).view_ids == [0]
    assert parse(scene, test_every=2).view_ids == [0, 1, 2, 3, 4]  # train keeps every view


def test_file_path_with_suffix(scene: Path) -> None:
    meta = json.loads((scene / "transforms_test.json").read_text())
    meta["frames"][0]["file_path"] = "./test/r_0.png"
    (scene / "transforms_test.json").write_text(json.dumps(meta))
    assert parse(scene, "test").image_names[0] == "r_0"


def test_bundled_demo_scene() -> None:
    demo = TINY_SCENE
    train = parse(demo)
    assert train.images.shape == (4, 100, 100, 4)
    assert train.image_names == ["r_27", "r_76", "r_97", "r_99"] and train.view_ids == [0, 1, 2, 3]
    assert 0.0 < train.images[..., 3].mean() < 1.0  # an object on a transparent background
    test = parse(demo, "test")
    assert test.images.shape == (8, 100, 100, 4)
    assert test.image_names == [f"r_{25 * k}" for k in range(8)]
    assert parse(demo, "val").images.shape[0] == 4
    size = sum(p.stat().st_size for p in demo.rglob("*") if p.is_file())
    assert size < 1_000_000


@pytest.mark.shared
def test_shared_lego_few_shot_is_deterministic(shared_dir: Path) -> None:
    lego = shared_dir / "data" / "blender" / "lego"
    out = parse(lego, num_views=4, downscale=4)
    assert out.images.shape == (4, 100, 100, 4) and len(set(out.view_ids)) == 4
    assert out.image_names == [f"r_{i}" for i in out.view_ids]  # official files: frame i is r_i
    again = parse(lego, num_views=4, downscale=4)
    assert again.view_ids == out.view_ids and torch.equal(again.images, out.images)
    torch.testing.assert_close(out.cameras.fx[0], torch.tensor(50 / math.tan(0.6911112070083618 / 2)))
    test = parse(lego, "test", downscale=4)
    assert test.images.shape == (200, 100, 100, 4)


# --- bad inputs: each one a UserError whose problem names the file and whose fix says what to do ---------------


def _edit_json(split: str, edit: Callable[[dict], Any]) -> Callable[[Path], None]:
    def apply(root: Path) -> None:
        path = root / f"transforms_{split}.json"
        meta = json.loads(path.read_text())
        edit(meta)
        path.write_text(json.dumps(meta))

    return apply


def _mixed_sizes(root: Path) -> None:
    iio.imwrite(root / "train" / "r_3.png", np.zeros((12, 16, 4), dtype=np.uint8))


BAD_INPUTS: dict[str, tuple[Callable[[Path], None], dict[str, Any], str]] = {
    # name: (break the scene, config overrides, text the problem must contain)
    "malformed json": (
        lambda r: (r / "transforms_train.json").write_text('{"camera_angle_x": 0.7,\n "frames": [}'),
        {},
        "transforms_train.json",
    ),
    "missing camera_angle_x": (_edit_json("train", lambda m: m.pop("camera_angle_x")), {}, "camera_angle_x"),
    "empty frames": (_edit_json("train", lambda m: m.update(frames=[])), {}, "transforms_train.json"),
    "matrix not 4x4": (
        _edit_json("train", lambda m: m["frames"][1].update(transform_matrix=[[1, 0, 0, 0]] * 3)),
        {},
        "frame 1",
    ),
    "non-finite matrix": (
        lambda r: (r / "transforms_train.json").write_text(
            (r / "transforms_train.json").read_text().replace("0.5", "NaN", 1)
        ),
        {},
        "non-finite",
    ),
    "all-zero matrix": (
        _edit_json("train", lambda m: m["frames"][2].update(transform_matrix=[[0.0] * 4] * 4)),
        {},
        "frame 2: transform_matrix is not a camera pose: its rotation is singular",
    ),
    "scaled rotation": (
        _edit_json("train", lambda m: m["frames"][3].update(transform_matrix=(2 * np.eye(4)).tolist())),
        {},
        "frame 3: transform_matrix is not a camera pose: its rotation is not orthonormal",
    ),
    "mirrored rotation": (
        _edit_json("train", lambda m: m["frames"][0].update(transform_matrix=np.diag([-1.0, 1, 1, 1]).tolist())),
        {},
        "frame 0: transform_matrix is not a camera pose: its rotation mirrors",
    ),
    "missing image": (lambda r: (r / "train" / "r_2.png").unlink(), {}, "r_2.png"),
    "mixed sizes": (_mixed_sizes, {}, "r_3.png"),
    "num_views > split": (lambda r: None, {"num_views": 6}, "transforms_train.json"),
    "num_views < 1": (lambda r: None, {"num_views": 0}, "--num-views"),
    "view id out of range": (lambda r: None, {"view_ids": (1, 5)}, "transforms_train.json"),
    "view id duplicated": (lambda r: None, {"view_ids": (1, 1)}, "[1]"),
    "downscale < 1": (lambda r: None, {"downscale": 0}, "--downscale"),
    "downscale > image": (lambda r: None, {"downscale": 17}, "r_0.png"),
    "test_every < 1": (lambda r: None, {"test_every": 0}, "--test-every"),
}


@pytest.mark.parametrize("case", list(BAD_INPUTS))
def test_bad_inputs_raise_user_errors(tmp_path: Path, case: str) -> None:
    root = make_scene(tmp_path / "toy", {"train": 5})
    breaker, overrides, expected = BAD_INPUTS[case]
    breaker(root)
    with pytest.raises(UserError) as info:
        parse(root, **overrides)
    assert expected in info.value.problem, info.value.problem
    assert info.value.fix


def test_malformed_json_reports_the_line(tmp_path: Path) -> None:
    root = make_scene(tmp_path / "toy", {"train": 2})
    (root / "transforms_train.json").write_text('{"camera_angle_x": 0.7,\n "frames": [}')
    with pytest.raises(UserError, match="line 2"):
        parse(root)


def test_missing_or_foreign_folders(tmp_path: Path) -> None:
    with pytest.raises(UserError) as info:
        parse(tmp_path / "nowhere")
    assert "nowhere" in info.value.problem

    (tmp_path / "empty").mkdir()
    with pytest.raises(UserError) as info:
        parse(tmp_path / "empty")
    assert "empty" in info.value.problem and "transforms_" in info.value.problem

    (tmp_path / "fern").mkdir()
    np.save(tmp_path / "fern" / "poses_bounds.npy", np.zeros((3, 17)))
    with pytest.raises(UserError) as info:
        parse(tmp_path / "fern")
    assert "fern" in info.value.problem and "poses_bounds.npy" in info.value.problem
    assert "llff-data" in info.value.fix

    root = make_scene(tmp_path / "toy", {"train": 2})
    with pytest.raises(UserError) as info:
        parse(root, "test")
    assert "transforms_test.json" in info.value.problem
