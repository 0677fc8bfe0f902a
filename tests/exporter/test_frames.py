"""The frame of an exported mesh: the parser's normalisation recovered from the poses and undone, NDC mapped back to
metric, and each parser's outputs carrying the map from its capture's frame (checked against the cameras)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch
import trimesh

from fourierf_plugin.cameras.ndc import ndc_rays
from fourierf_plugin.data.dataparser_transforms import (
    FILE_NAME,
    NDC_FAR_MARGIN,
    DataparserTransform,
    NdcFrame,
    RunFrame,
    fit_transform,
    read_dataparser_transforms,
    write_dataparser_transforms,
    write_run_frame,
)
from fourierf_plugin.data.parsers.blender import BlenderDataParserConfig
from fourierf_plugin.data.parsers.colmap import ColmapDataParserConfig
from fourierf_plugin.data.parsers.llff import LLFFDataParserConfig, load_poses_bounds, to_opengl
from fourierf_plugin.data.parsers.nerfstudio import NerfstudioDataParserConfig
from fourierf_plugin.exporter.frames import (
    NDC_NOTE,
    NORMALISED_NOTE,
    MeshFrame,
    field_frame,
    map_mesh,
    resolve_frame,
)
from tests.data.colmap_fixtures import make_model as make_colmap_model
from tests.data.colmap_fixtures import write_scene as write_colmap_scene
from tests.data.transforms_scenes import rig_c2w, ring_c2w, write_scene
from tests.helpers import TINY_SCENE
from tests.scenes import write_llff_scene


def _rotation(seed: int) -> np.ndarray:
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def _similarity(seed: int = 0) -> DataparserTransform:
    rng = np.random.default_rng(seed)
    return DataparserTransform(np.concatenate([_rotation(seed), rng.normal(size=(3, 1))], axis=1), 0.37)


def _apply(transform: DataparserTransform, c2w: np.ndarray) -> np.ndarray:
    """Camera-to-worlds moved as a parser normalises them: rotation parts turned, centres mapped."""
    linear = transform.transform[:, :3]
    return np.concatenate([linear @ c2w[:, :3, :3], transform.to_normalised(c2w[:, :3, 3])[:, :, None]], axis=2)


def _sphere(centre=(0.0, 0.0, 0.0), radius: float = 1.0) -> trimesh.Trimesh:
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=radius)
    mesh.apply_translation(centre)
    return mesh


# -- the transform ---------------------------------------------------------------------------------------------------
def test_the_transform_maps_both_ways_and_as_one_matrix() -> None:
    transform = _similarity()
    points = np.random.default_rng(1).normal(size=(20, 3))
    moved = transform.to_normalised(points)
    np.testing.assert_allclose(transform.to_capture(moved), points, atol=1e-12)
    homogeneous = np.concatenate([points, np.ones((20, 1))], axis=1) @ transform.matrix.T
    np.testing.assert_allclose(homogeneous[:, :3], moved, atol=1e-12)
    identity = DataparserTransform.identity()
    np.testing.assert_array_equal(identity.to_capture(points), points)


def test_fit_recovers_a_normalisation_from_the_poses_exactly() -> None:
    c2w = ring_c2w(7)[:, :3, :4]
    transform = _similarity(3)
    fitted = fit_transform(c2w, _apply(transform, c2w))
    assert fitted is not None
    np.testing.assert_allclose(fitted.transform, transform.transform, atol=1e-12)
    assert fitted.scale == pytest.approx(transform.scale, rel=1e-12)


def test_fit_refuses_what_the_poses_do_not_determine() -> None:
    c2w = ring_c2w(5)[:, :3, :4]
    same_place = c2w.copy()
    same_place[:, :, 3] = 1.0
    assert fit_transform(same_place, _apply(_similarity(), same_place)) is None, "every camera in one place"
    moved = _apply(_similarity(), c2w)
    moved[2, :, 3] += 0.1
    assert fit_transform(c2w, moved) is None, "one camera moved on its own: no single transform"
    turned = _apply(_similarity(), c2w)
    turned[1, :, :3] = _rotation(9) @ turned[1, :, :3]
    assert fit_transform(c2w, turned) is None, "one camera turned on its own"


def test_the_file_round_trips_and_a_broken_one_is_named(tmp_path: Path) -> None:
    transform = _similarity()
    ndc = NdcFrame(400.0, 504, 378, 1.0, 20.0)
    path = write_dataparser_transforms(tmp_path, transform, ndc)
    assert path == tmp_path / FILE_NAME and [p.name for p in tmp_path.iterdir()] == [FILE_NAME]
    record = json.loads(path.read_text())
    assert set(record) == {"transform", "scale", "ndc"} and np.asarray(record["transform"]).shape == (3, 4)
    read = read_dataparser_transforms(tmp_path)
    assert read is not None and read.ndc == ndc and read.path == path
    np.testing.assert_array_equal(read.transform.transform, transform.transform)
    assert read_dataparser_transforms(tmp_path / "elsewhere") is None
    path.write_text(json.dumps({"transform": [[1, 0, 0]], "scale": 1}))
    with pytest.raises(ValueError, match=FILE_NAME):
        read_dataparser_transforms(tmp_path)


# -- NDC ------------------------------------------------------------------------------------------------------------
def test_ndc_points_map_back_to_where_the_rays_went() -> None:
    """A point seen by a camera lies, in NDC, on that ray's NDC line; ``to_metric`` undoes ``to_ndc``."""
    ndc = NdcFrame(focal=50.0, width=80, height=60)
    points = np.array([[0.3, -0.2, -2.0], [-1.0, 0.5, -7.5], [0.0, 0.0, -1.5]])
    np.testing.assert_allclose(ndc.to_metric(ndc.to_ndc(points)), points, rtol=1e-12)
    origins = torch.tensor([[0.1, 0.2, 0.0]], dtype=torch.float64).expand(3, 3)
    directions = torch.from_numpy(points) - origins
    o_ndc, d_ndc = ndc_rays(origins, directions, ndc.focal, ndc.width, ndc.height, near=1.0)
    offsets = torch.from_numpy(ndc.to_ndc(points)) - o_ndc
    assert torch.linalg.cross(offsets, d_ndc).norm(dim=-1).max() < 1e-9, "on the ray's NDC line"


def test_an_ndc_mesh_is_mapped_back_to_metric_with_its_winding_kept() -> None:
    ndc = NdcFrame(focal=50.0, width=80, height=60, far=100.0)
    sphere = _sphere((0.2, -0.1, -4.0), 0.5)
    in_ndc = trimesh.Trimesh(ndc.to_ndc(sphere.vertices), sphere.faces[:, ::-1], process=False)  # NDC mirrors
    assert in_ndc.volume > 0, "precondition: outward faces in NDC"
    frame = resolve_frame("normalised", "ndc", _recorded(ndc))
    back, dropped = map_mesh(in_ndc, frame)
    assert dropped == 0 and frame.space == "normalised"
    np.testing.assert_allclose(back.vertices, sphere.vertices, atol=1e-9)
    assert back.volume == pytest.approx(sphere.volume, rel=1e-9), "outward winding"
    assert np.mean(np.sum(back.vertex_normals * (back.vertices - (0.2, -0.1, -4.0)), axis=1)) > 0


def test_geometry_at_infinity_is_left_out() -> None:
    ndc = NdcFrame(focal=50.0, width=80, height=60, far=10.0)
    near = _sphere((0.0, 0.0, -3.0), 0.5)
    wall = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    wall.apply_translation((0.0, 0.0, -40.0))  # beyond the far bound
    both = trimesh.util.concatenate([near, wall])
    in_ndc = trimesh.Trimesh(ndc.to_ndc(both.vertices), both.faces, process=False)
    back, dropped = map_mesh(in_ndc, resolve_frame("normalised", "ndc", _recorded(ndc)))
    assert dropped == len(wall.faces) and len(back.faces) == len(near.faces)
    assert back.vertices[:, 2].min() > -3.6


def _recorded(ndc: NdcFrame | None = None, transform: DataparserTransform | None = None) -> RunFrame:
    return RunFrame(transform or DataparserTransform.identity(), ndc, Path("RUN") / FILE_NAME)


# -- which frame an export gets ---------------------------------------------------------------------------------------
def test_a_mesh_goes_back_to_the_capture_frame() -> None:
    transform = _similarity(5)
    sphere = _sphere((1.0, 2.0, -0.5), 0.8)
    normalised = trimesh.Trimesh(transform.to_normalised(sphere.vertices), sphere.faces, process=False)
    frame = resolve_frame("capture", "euclidean", _recorded(transform=transform))
    assert frame.space == "capture" and str(Path("RUN") / FILE_NAME) in frame.note
    back, dropped = map_mesh(normalised, frame)
    assert dropped == 0
    np.testing.assert_allclose(back.vertices, sphere.vertices, atol=1e-9)
    assert back.volume == pytest.approx(sphere.volume, rel=1e-9)
    kept, _ = map_mesh(normalised, resolve_frame("normalised", "euclidean", _recorded(transform=transform)))
    np.testing.assert_array_equal(kept.vertices, normalised.vertices)


def test_without_the_file_the_mesh_stays_normalised_and_says_why() -> None:
    frame = resolve_frame("capture", "euclidean", None)
    assert frame.space == "normalised" and frame.note.startswith(NORMALISED_NOTE) and FILE_NAME in frame.note
    ndc = resolve_frame("capture", "ndc", None)
    assert ndc.space == "ndc" and ndc.note.startswith(NDC_NOTE) and "cannot be undone" in ndc.note
    assert field_frame("ndc").space == "ndc" and field_frame("euclidean").space == "normalised"
    assert resolve_frame("field", "contracted", _recorded()).space == "contracted"


def test_contracted_coordinates_are_uncontracted() -> None:
    inner = _sphere((0.1, 0.0, 0.0), 0.3)  # inside the inner cube the contraction is the identity
    outer_points = np.array([[1.5, 0.0, 0.0], [0.0, -1.75, 0.0], [1.99999, 0.0, 0.0]])
    mesh = trimesh.Trimesh(np.concatenate([inner.vertices, outer_points]), inner.faces, process=False)
    mesh = trimesh.Trimesh(mesh.vertices, np.concatenate([mesh.faces, [[len(inner.vertices) + i for i in range(3)]]]))
    back, dropped = map_mesh(mesh, MeshFrame("normalised", "", "contracted", far=1000.0))
    assert dropped == 1, "the face reaching the grid's outer face (infinitely far) is left out"
    np.testing.assert_allclose(back.vertices[: len(inner.vertices)], inner.vertices, atol=1e-12)


# -- the parsers' outputs -------------------------------------------------------------------------------------------
def _centres_match(outputs, capture_c2w: np.ndarray) -> None:
    transform = outputs.dataparser_transform
    assert transform is not None
    got = transform.to_normalised(capture_c2w[outputs.view_ids, :3, 3])
    np.testing.assert_allclose(got, outputs.cameras.centers.double().numpy(), atol=1e-5)
    normalised_centres = outputs.cameras.centers.double().numpy()
    np.testing.assert_allclose(
        transform.to_capture(normalised_centres), capture_c2w[outputs.view_ids, :3, 3], atol=1e-4
    )


def test_blender_poses_are_the_capture_frame() -> None:
    outputs = BlenderDataParserConfig(data=TINY_SCENE).setup().get_outputs("train")
    transform = outputs.dataparser_transform
    assert transform is not None and transform.scale == 1.0
    np.testing.assert_array_equal(transform.matrix, np.eye(4))


def test_llff_outputs_carry_the_scale_and_recentring(tmp_path: Path) -> None:
    scene = write_llff_scene(tmp_path / "llff", n=9)
    outputs = LLFFDataParserConfig(data=scene).setup().get_outputs("train")
    raw, _, _ = load_poses_bounds(scene / "poses_bounds.npy")
    _centres_match(outputs, to_opengl(raw))
    assert outputs.dataparser_transform.scale != pytest.approx(1.0)


@pytest.mark.parametrize(
    ("kind", "c2w"),
    [("object", ring_c2w(8, centre=(3.0, -1.0, 2.0))), ("forward-facing", rig_c2w(8))],
)
def test_capture_outputs_carry_their_normalisation(tmp_path: Path, kind: str, c2w: np.ndarray) -> None:
    points = np.random.default_rng(0).normal(size=(50, 3)) * 0.3 + np.array([3.0, -1.0, 2.0])
    if kind == "forward-facing":
        points = np.random.default_rng(0).normal(size=(50, 3)) * 0.5 + np.array([0.0, 0.0, -6.0])
    scene = write_scene(tmp_path / kind, c2w, points=points)
    cfg = NerfstudioDataParserConfig(data=scene, scene_kind=kind)  # type: ignore[arg-type]
    outputs = cfg.setup().get_outputs("train")
    _centres_match(outputs, c2w)
    transform = outputs.dataparser_transform
    if kind == "object":  # turned upright and centred: the ring's centre goes near the origin
        assert np.linalg.norm(transform.to_normalised(np.array([[3.0, -1.0, 2.0]]))) < 0.5 + math.sqrt(3)


def test_a_forward_facing_run_records_its_ndc_mapping(tmp_path: Path) -> None:
    """What the trainer writes: the parser's transform, and for NDC rays the reference camera's mapping with the
    content's far bound widened."""
    outputs = SimpleNamespace(
        dataparser_transform=_similarity(),
        cameras=SimpleNamespace(fx=torch.tensor([400.0, 410.0]), width=504, height=378),
        depth_bounds=(1.2, 11.0),
    )
    (tmp_path / "ndc").mkdir()
    write_run_frame(tmp_path / "ndc", outputs, "ndc")
    recorded = read_dataparser_transforms(tmp_path / "ndc")
    assert recorded is not None and recorded.ndc == NdcFrame(400.0, 504, 378, 1.0, NDC_FAR_MARGIN * 11.0)
    (tmp_path / "box").mkdir()
    write_run_frame(tmp_path / "box", outputs, "euclidean")
    assert read_dataparser_transforms(tmp_path / "box").ndc is None
    (tmp_path / "unknown").mkdir()
    assert write_run_frame(tmp_path / "unknown", SimpleNamespace(dataparser_transform=None), "euclidean") is None
    assert not any((tmp_path / "unknown").iterdir())


def test_colmap_outputs_map_from_the_models_own_world_frame(tmp_path: Path) -> None:
    """colmap-data: the transform starts in COLMAP's world (where points3D live), not in the turned frame the poses
    are read into, so COLMAP's camera centres land on the normalised ones."""
    model = make_colmap_model(names=[f"img_{i:02d}.png" for i in range(8)])
    scene = write_colmap_scene(model, tmp_path / "scene")
    outputs = ColmapDataParserConfig(data=scene).setup().get_outputs("train")
    centres = np.stack([-im.rotation.T @ im.translation for im in model.images])  # COLMAP's world frame
    _centres_match(outputs, np.concatenate([np.tile(np.eye(3), (8, 1, 1)), centres[:, :, None]], axis=2))


def test_composing_with_a_first_map() -> None:
    first = np.concatenate([_rotation(4), np.array([[1.0], [2.0], [3.0]])], axis=1)
    transform = _similarity(6)
    points = np.random.default_rng(2).normal(size=(5, 3))
    direct = transform.to_normalised(points @ first[:, :3].T + first[:, 3])
    np.testing.assert_allclose(transform.after(first).to_normalised(points), direct, atol=1e-12)
