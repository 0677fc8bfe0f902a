"""colmap-data: finding the model folder, reading it with its photos, and the errors on the way."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fourierf_plugin.data.colmap_model import capture_from_model, read_model
from fourierf_plugin.data.parsers.colmap import ColmapDataParser, ColmapDataParserConfig
from fourierf_plugin.utils.errors import UserError
from tests.data.colmap_fixtures import make_model, write_photos, write_scene, write_text


def _parser(data: Path, **options) -> ColmapDataParser:
    return ColmapDataParserConfig(data=data, **options).setup()


@pytest.mark.parametrize("model_path", ["colmap/sparse/0", "sparse/0", "sparse"])
def test_the_model_is_found_in_the_usual_places(tmp_path: Path, model_path: str) -> None:
    model = make_model()
    scene = write_scene(model, tmp_path / "scene", model_path, binary=model_path != "sparse")
    parser = _parser(scene)
    assert parser.model_folder() == scene / model_path
    capture = parser.read_capture()
    assert [f.image_path for f in capture.frames] == [scene / "images" / im.name for im in model.images]
    assert capture.source == scene / model_path
    assert len(capture.points) == len(model.points)


def test_nerfstudio_layout_wins_over_colmap_layout(tmp_path: Path) -> None:
    scene = write_scene(make_model(), tmp_path / "scene", "colmap/sparse/0")
    write_text(make_model(names=["other.png"]), scene / "sparse" / "0")
    capture = _parser(scene).read_capture()
    assert len(capture.frames) == 5


def test_explicit_paths(tmp_path: Path) -> None:
    model = make_model()
    scene = tmp_path / "scene"
    write_text(model, scene / "recon" / "3")
    write_photos(model, scene / "photos")
    capture = _parser(scene, colmap_path=Path("recon/3"), images_path=Path("photos")).read_capture()
    expected = capture_from_model(read_model(scene / "recon" / "3"), scene / "photos")
    np.testing.assert_allclose(
        np.stack([f.camera_to_world for f in capture.frames]), np.stack([f.camera_to_world for f in expected.frames])
    )
    with pytest.raises(UserError, match=r"no COLMAP model in .* \(looked in recon/4\)"):
        _parser(scene, colmap_path=Path("recon/4")).read_capture()  # an explicit path has no fallbacks


def test_errors_name_the_problem_and_the_fix(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="data folder not found"):
        _parser(tmp_path / "nowhere").read_capture()
    (tmp_path / "ns").mkdir()
    (tmp_path / "ns" / "transforms.json").write_text("{}")
    with pytest.raises(UserError, match=r"looked in colmap/sparse/0, sparse/0, sparse") as info:
        _parser(tmp_path / "ns").read_capture()
    assert "nerfstudio-data" in info.value.fix
    scene = write_scene(make_model(), tmp_path / "scene")
    with pytest.raises(UserError, match="image folder not found"):
        _parser(scene, images_path=Path("images_missing")).read_capture()


def test_get_outputs_gives_the_registered_photos(tmp_path: Path) -> None:
    """The capture base's get_outputs (normalisation, splits) on a colmap-data scene."""
    model = make_model(names=[f"img_{i:02d}.png" for i in range(10)])
    scene = write_scene(model, tmp_path / "scene")
    outputs = _parser(scene).get_outputs("train")
    assert outputs.images.shape[1:3] == (48, 64)
    assert len(outputs.cameras) == outputs.images.shape[0] >= 1
    assert set(outputs.image_names) <= {Path(im.name).stem for im in model.images} | {im.name for im in model.images}
    assert np.isfinite(outputs.cameras.camera_to_worlds.numpy()).all()
