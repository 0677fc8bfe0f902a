"""Photos of an object with its surroundings: the capture is told apart from a white-background box, posed as an
object capture with the space beyond its cameras contracted, and its object's box recorded for the mesh export."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from fourierf_plugin.data.dataparser_transforms import (
    DataparserTransform,
    read_dataparser_transforms,
    write_dataparser_transforms,
)
from fourierf_plugin.data.parsers.capture_scene import CONTRACTED_BOX, UNBOUNDED_FAR
from fourierf_plugin.data.parsers.nerfstudio import NerfstudioDataParserConfig
from fourierf_plugin.scripts.export import default_box
from fourierf_plugin.synthetic.room import TABLE_HALF, TABLE_TOP_Z, write_room_capture

SMALL = {"width": 48, "height": 36, "n_train": 9, "n_test": 3, "samples_per_pixel": 1}


@pytest.fixture(scope="module")
def room(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_room_capture(tmp_path_factory.mktemp("room") / "cap", **SMALL)


def test_a_room_capture_is_unbounded_and_says_why(room: Path) -> None:
    parser = NerfstudioDataParserConfig(data=room).setup()
    declared = parser.declaration()
    assert declared.kind == "unbounded" and declared.ray_space == "contracted" and declared.background == "none"
    assert "no alpha or masks" in declared.reason and "sparse points lie beyond the cameras" in declared.reason
    scene = parser.normalised()
    assert np.array_equal(scene.scene_box, np.asarray(CONTRACTED_BOX)) and scene.far == UNBOUNDED_FAR
    assert np.abs(scene.camera_to_worlds[:, :, 3]).max() == pytest.approx(1.0)  # the cameras fit the inner cube


def test_the_flag_still_gives_a_bounded_object(room: Path) -> None:
    declared = NerfstudioDataParserConfig(data=room, scene_kind="object").setup().declaration()
    assert declared.kind == "object" and declared.ray_space == "euclidean"


def test_the_object_box_holds_the_true_object_not_the_table_inside_the_inner_cube(room: Path) -> None:
    parser = NerfstudioDataParserConfig(data=room).setup()
    box = parser.normalised().object_box
    assert box is not None and (box[0] >= -1).all() and (box[1] <= 1).all() and (box[0] < box[1]).all()
    to_normalised = parser.dataparser_transform().to_normalised
    surface = to_normalised(np.asarray(trimesh.load(room / "object_surface.ply", process=False).vertices))
    assert ((surface >= box[0]) & (surface <= box[1])).all()
    half_x, half_y = TABLE_HALF
    grid = np.stack(np.meshgrid(np.linspace(-half_x, half_x, 25), np.linspace(-half_y, half_y, 19)), axis=-1)
    top = to_normalised(np.concatenate([grid.reshape(-1, 2), np.full((grid[..., 0].size, 1), TABLE_TOP_Z)], axis=1))
    assert ((top >= box[0]) & (top <= box[1])).all(axis=1).mean() < 0.5
    outputs = parser.get_outputs("train")
    assert np.allclose(outputs.object_box, box)


def test_the_object_box_travels_in_dataparser_transforms_and_bounds_the_export(tmp_path: Path) -> None:
    box = ((-0.3, -0.2, -0.1), (0.4, 0.2, 0.3))
    write_dataparser_transforms(tmp_path, DataparserTransform.identity(), object_box=box)
    recorded = read_dataparser_transforms(tmp_path)
    assert recorded is not None and recorded.object_box == box
    model_box = [[-2.0, -0.1, -2.0], [2.0, 2.0, 0.2]]
    assert default_box(model_box, "contracted", box) == ((-0.3, -0.1, -0.1), (0.4, 0.2, 0.2))
    assert default_box(model_box, "contracted") == ((-1.0, -0.1, -1.0), (1.0, 1.0, 0.2))
    assert default_box(model_box, "euclidean", box) == (tuple(model_box[0]), tuple(model_box[1]))
    record = json.loads((tmp_path / "dataparser_transforms.json").read_text())
    record["object_box"] = [[0, 0, 0], [0, 1, 1]]  # empty along x
    (tmp_path / "dataparser_transforms.json").write_text(json.dumps(record))
    with pytest.raises(ValueError, match="object_box"):
        read_dataparser_transforms(tmp_path)
