"""The ground-truth scene generator: exact intersections, a dataset the Blender parser reads, the true surface."""

from __future__ import annotations

import json
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from fourierf_plugin.data.parsers.blender import BlenderDataParserConfig
from fourierf_plugin.scripts import synth
from fourierf_plugin.scripts.cli import EXIT_USER_ERROR
from fourierf_plugin.synthetic import (
    Box,
    GroundPlane,
    SceneSpec,
    Sphere,
    default_scene,
    intersect_scene,
    load_scene,
    sample_surface,
    save_scene,
    split_cameras,
    surface_distance,
    write_blender_dataset,
)
from fourierf_plugin.utils.errors import UserError
from tests.helpers import cli_exit_code

RED, GREEN, BLUE = (0.8, 0.2, 0.2), (0.2, 0.8, 0.2), (0.2, 0.4, 0.8)


def _ray(origin, direction) -> tuple[np.ndarray, np.ndarray]:
    return np.array([origin], dtype=np.float64), np.array([direction], dtype=np.float64)


# -- intersections -----------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("origin", "direction", "t", "normal"),
    [
        ((0, 0, -5), (0, 0, 1), 4.0, (0, 0, -1)),  # head-on
        ((0, 0, -5), (0, 0, 2), 2.0, (0, 0, -1)),  # t is in units of the direction's length
        ((0, 0, 0), (1, 0, 0), 1.0, (1, 0, 0)),  # starts inside: the exit, normal still outward
        ((0, 0.6, -5), (0, 0, 1), 5.0 - 0.8, (0, 0.6, -0.8)),  # off-centre: the chord's near end
        ((0, 2, -5), (0, 0, 1), np.inf, (0, 0, 0)),  # passes beside
        ((0, 0, 5), (0, 0, 1), np.inf, (0, 0, 0)),  # sphere behind the ray
    ],
)
def test_ray_sphere_hand_cases(origin, direction, t, normal) -> None:
    got_t, got_n = Sphere((0, 0, 0), 1.0, RED).intersect(*_ray(origin, direction))
    np.testing.assert_allclose(got_t, [t], atol=1e-12)
    np.testing.assert_allclose(got_n, [normal], atol=1e-12)


@pytest.mark.parametrize(
    ("origin", "direction", "t", "normal"),
    [
        ((-5, 0.5, 0.5), (1, 0, 0), 4.0, (-1, 0, 0)),  # axis-parallel ray into the -x face
        ((0.2, 0.3, 10), (0, 0, -1), 7.0, (0, 0, 1)),  # from above onto the top face
        ((0, 0, 0), (0, 1, 0), 2.0, (0, 1, 0)),  # starts inside: the exit face
        ((-5, 3, 0), (1, 0, 0), np.inf, (0, 0, 0)),  # parallel to the y slab and outside it
        ((-5, 0, 0), (-1, 0, 0), np.inf, (0, 0, 0)),  # box behind the ray
        ((-1.5, -3, 0), (1, 1, 0), 1.0, (0, -1, 0)),  # diagonal, enters through the -y face at (-0.5, -2, 0)
        ((-3, 3.5, 0), (1, -0.2, 0), np.inf, (0, 0, 0)),  # diagonal: leaves the x slab before entering the y one
    ],
)
def test_ray_box_hand_cases(origin, direction, t, normal) -> None:
    got_t, got_n = Box((0, 0, 0), (1, 2, 3), BLUE).intersect(*_ray(origin, direction))
    np.testing.assert_allclose(got_t, [t], atol=1e-12)
    np.testing.assert_allclose(got_n, [normal], atol=1e-12)


def test_ray_ground_plane_hand_cases() -> None:
    plane = GroundPlane(height=-0.5, color=GREEN, half_extent=1.0)
    t, n = plane.intersect(
        np.array([[0, 0, 2.0], [3, 0, 2.0], [0, 0, 2.0]]), np.array([[0, 0, -1.0]] * 2 + [[1, 0, 0]])
    )
    np.testing.assert_allclose(t, [2.5, np.inf, np.inf])  # hit; off the square; parallel to it
    np.testing.assert_allclose(n[0], [0, 0, 1])


def test_scene_picks_the_nearest_primitive_and_normals_are_unit_and_outward() -> None:
    spec = default_scene(ground_plane=True)
    rng = np.random.default_rng(0)
    origins = rng.normal(size=(4000, 3)) * 3
    targets = rng.uniform(-0.8, 0.8, size=(4000, 3))
    dirs = targets - origins
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    hits = intersect_scene(spec, origins, dirs)
    assert 0.2 < hits.hit.mean() < 1.0
    per_prim = np.stack([p.intersect(origins, dirs)[0] for p in spec.primitives], axis=1)
    np.testing.assert_array_equal(hits.t, per_prim.min(axis=1))
    h = hits.hit
    np.testing.assert_allclose(np.linalg.norm(hits.normal[h], axis=1), 1.0, atol=1e-12)
    points = origins[h] + hits.t[h, None] * dirs[h]
    for i, prim in enumerate(spec.primitives):
        mine = hits.index[h] == i
        assert prim.surface_distance(points[mine]).max() < 1e-9
        if isinstance(prim, GroundPlane):
            assert (hits.normal[h][mine] == [0, 0, 1]).all()
        else:  # outward: along the offset from the centre
            offset = points[mine] - np.asarray(prim.center)
            assert (np.einsum("ij,ij->i", hits.normal[h][mine], offset) > 0).all()


# -- cameras -----------------------------------------------------------------------------------------------------
def test_cameras_look_at_the_origin_from_the_upper_hemisphere_and_splits_differ() -> None:
    cams = split_cameras(4, 4, 8, radius=4.0, seed=3)
    assert {s: len(c) for s, c in cams.items()} == {"train": 4, "val": 4, "test": 8}
    for c2w in np.concatenate(list(cams.values())):
        rot, eye = c2w[:3, :3], c2w[:3, 3]
        np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(rot) == pytest.approx(1.0)
        assert np.linalg.norm(eye) == pytest.approx(4.0)
        assert eye[2] > 0
        np.testing.assert_allclose(-rot[:, 2], -eye / 4.0, atol=1e-12)  # looking down -z at the origin
        assert rot[2, 1] > 0  # image up points up in the world
    train = cams["train"][:, :3, 3]
    for split in ("val", "test"):
        gaps = np.linalg.norm(train[:, None] - cams[split][None, :, :3, 3], axis=-1)
        assert gaps.min() > 0.05
    again = split_cameras(4, 4, 8, radius=4.0, seed=3)
    assert all(np.array_equal(cams[s], again[s]) for s in cams)
    assert not np.array_equal(cams["train"], split_cameras(4, 4, 8, seed=4)["train"])


# -- datasets ----------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sphere_scene() -> SceneSpec:
    # The box lies below z = 0, so it is never between an upper-hemisphere camera and the origin.
    return SceneSpec((Sphere((0, 0, 0), 0.5, RED), Box((0.6, 0.6, -0.6), (0.2, 0.2, 0.2), BLUE)))


@pytest.fixture(scope="module")
def dataset(tmp_path_factory, sphere_scene: SceneSpec) -> Path:
    return write_blender_dataset(sphere_scene, tmp_path_factory.mktemp("synth") / "scene", 32, 32, 4, 2, 3, seed=1)


def _pngs(folder: Path) -> list[np.ndarray]:
    return [iio.imread(p) for p in sorted(folder.glob("*/r_*.png"))]


def test_dataset_parses_with_the_blender_parser(dataset: Path, sphere_scene: SceneSpec) -> None:
    parser = BlenderDataParserConfig(data=dataset).setup()
    counts = {}
    for split in ("train", "val", "test"):
        out = parser.get_outputs(split)
        counts[split] = len(out.images)
        assert out.images.shape[1:] == (32, 32, 4)
        assert out.image_names[0] == "r_0"
        # Every camera looks at the sphere at the origin: the pixel by the image centre is opaque sphere colour.
        centre = out.images[:, 16, 16].numpy()
        np.testing.assert_allclose(centre, np.tile([*RED, 1.0], (len(centre), 1)), atol=1 / 255)
        assert (out.images[:, 0, 0, 3] == 0).all()  # the corner ray misses everything
        # The parser's own rays see exactly the rendered coverage.
        origins, dirs = out.cameras.generate_rays(0)
        hits = intersect_scene(sphere_scene, origins.double().numpy(), dirs.double().numpy())
        alpha = out.images[0, ..., 3].numpy().reshape(-1)
        assert (hits.hit != (alpha > 0.5)).mean() < 0.01
    assert counts == {"train": 4, "val": 2, "test": 3}
    meta = json.loads((dataset / "transforms_train.json").read_text())
    assert meta["frames"][1]["file_path"] == "./train/r_1"
    assert np.asarray(meta["frames"][1]["transform_matrix"]).shape == (4, 4)


def test_unshaded_pixels_are_exactly_the_albedos(dataset: Path) -> None:
    images = _pngs(dataset)
    assert all(img.dtype == np.uint8 and img.shape == (32, 32, 4) for img in images)
    pixels = np.concatenate([img.reshape(-1, 4) for img in images])
    assert set(np.unique(pixels[:, 3]).tolist()) == {0, 255}  # hard edges without supersampling
    opaque = {tuple(c) for c in pixels[pixels[:, 3] == 255, :3].tolist()}
    assert opaque == {tuple(round(255 * c) for c in RED), tuple(round(255 * c) for c in BLUE)}


def test_lambert_shading_and_supersampling_change_only_what_they_should(tmp_path: Path, dataset: Path) -> None:
    spec = default_scene()
    shaded = write_blender_dataset(spec, tmp_path / "lit", 32, 32, 2, 1, 1, seed=1, shading="lambert")
    flat = write_blender_dataset(spec, tmp_path / "flat", 32, 32, 2, 1, 1, seed=1)
    lit_px, flat_px = np.stack(_pngs(shaded)), np.stack(_pngs(flat))
    np.testing.assert_array_equal(lit_px[..., 3], flat_px[..., 3])  # shading never changes coverage
    lit_colours = {tuple(c) for c in lit_px[lit_px[..., 3] == 255][:, :3].tolist()}
    albedos = {tuple(round(255 * c) for c in p.color) for p in spec.primitives}
    assert len(lit_colours) > 3 * len(albedos)
    assert not lit_colours <= albedos
    smooth = np.stack(_pngs(write_blender_dataset(spec, tmp_path / "aa", 32, 32, 2, 1, 1, seed=1, samples_per_pixel=3)))
    edge_alpha = smooth[..., 3][(smooth[..., 3] > 0) & (smooth[..., 3] < 255)]
    assert edge_alpha.size > 0  # fractional coverage on silhouettes
    assert abs(int((smooth[..., 3] > 127).sum()) - int((flat_px[..., 3] > 0).sum())) < 0.05 * flat_px[..., 3].size


def test_geometry_json_round_trip(tmp_path: Path, dataset: Path, sphere_scene: SceneSpec) -> None:
    assert load_scene(dataset / "geometry.json") == sphere_scene
    render = json.loads((dataset / "geometry.json").read_text())["render"]
    assert render["views"] == {"train": 4, "val": 2, "test": 3} and render["shading"] == "none"
    spec = SceneSpec(default_scene(ground_plane=True).primitives, light_direction=(0, 1, 1), ambient=0.5)
    assert load_scene(save_scene(spec, tmp_path / "g.json")) == spec


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("{not json", "not valid JSON"),
        ('{"primitives": [{"type": "cone"}]}', "primitive 0: type must be one of"),
        ('{"primitives": [{"type": "sphere", "center": [0, 0], "radius": 1, "color": [1, 0, 0]}]}', "center"),
        ('{"primitives": [{"type": "sphere", "center": [0, 0, 0], "radius": -1, "color": [1, 0, 0]}]}', "radius"),
        ('{"primitives": []}', "at least one primitive"),
    ],
)
def test_bad_geometry_json_is_a_user_error(tmp_path: Path, content: str, message: str) -> None:
    path = tmp_path / "geometry.json"
    path.write_text(content)
    with pytest.raises(UserError, match=message) as info:
        load_scene(path)
    assert str(path) in info.value.problem


def test_a_scene_outside_the_parser_box_is_refused(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="outside the Blender parser's box"):
        write_blender_dataset(SceneSpec((Sphere((1.4, 0, 0), 0.3, RED),)), tmp_path / "x", 16, 16, 1, 1, 1)
    with pytest.raises(UserError, match="near/far"):
        write_blender_dataset(default_scene(), tmp_path / "y", 16, 16, 1, 1, 1, radius=2.5)


# -- the true surface --------------------------------------------------------------------------------------------
def test_sample_surface_lies_on_the_exposed_surfaces() -> None:
    spec = default_scene(ground_plane=True)
    points = sample_surface(spec, 20000, seed=0)
    assert points.shape == (20000, 3)
    assert surface_distance(spec, points).max() < 1e-6
    for prim in spec.primitives:
        assert not prim.contains(points).any()  # nothing buried inside a solid
    np.testing.assert_array_equal(points, sample_surface(spec, 20000, seed=0))
    # The default box cuts into the big sphere, so some of each surface is buried and must be missing.
    big, box = spec.primitives[0], spec.primitives[2]
    assert box.contains(big.sample(2000, np.random.default_rng(1))).any()


def test_sample_surface_is_area_weighted() -> None:
    spec = SceneSpec((Sphere((-0.5, 0, 0), 0.2, RED), Sphere((0.5, 0, 0), 0.4, GREEN)))  # disjoint, areas 1 : 4
    points = sample_surface(spec, 20000, seed=2)
    assert (points[:, 0] > 0).mean() == pytest.approx(0.8, abs=0.015)
    # A sphere half inside a box keeps only its outer half: the rejected half is not resampled onto it.
    spec = SceneSpec((Sphere((0, 0, 0), 0.5, RED), Box((0, 0, -0.5), (0.6, 0.6, 0.5), BLUE)))
    on_sphere = sample_surface(spec, 4000, seed=0)
    on_sphere = on_sphere[spec.primitives[0].surface_distance(on_sphere) < 1e-9]
    assert (on_sphere[:, 2] >= 0).all()


# -- the command line --------------------------------------------------------------------------------------------
def test_cli_writes_the_default_scene(tmp_path: Path, capsys) -> None:
    out = synth.main(["--output-dir", str(tmp_path / "s"), "--width", "16", "--height", "12", "--n-test", "2"])
    assert "4 train, 4 val, 2 test" in capsys.readouterr().out
    assert load_scene(out / "geometry.json") == default_scene()
    assert iio.imread(out / "test" / "r_1.png").shape == (12, 16, 4)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--width", "4"], "too small"),
        (["--height", "7"], "too small"),
        (["--n-train", "0"], "--n-train must be >= 1"),
        (["--samples-per-pixel", "0"], "--samples-per-pixel"),
        (["--camera-angle-x", "4"], "--camera-angle-x"),
        (["--shading", "phong"], None),  # tyro rejects the choice itself, also with exit 2
    ],
)
def test_cli_bad_options_exit_2(tmp_path: Path, capsys, args: list[str], message: str | None) -> None:
    assert cli_exit_code(synth.main, ["--output-dir", str(tmp_path / "s"), *args]) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    if message is not None:
        assert message in err and "fix:" in err
    assert not (tmp_path / "s").exists()


def test_cli_refuses_a_non_empty_folder_without_overwrite(tmp_path: Path, capsys) -> None:
    (tmp_path / "notes.txt").write_text("mine")
    args = ["--output-dir", str(tmp_path), "--width", "8", "--height", "8", "--n-val", "1", "--n-test", "1"]
    assert cli_exit_code(synth.main, args) == EXIT_USER_ERROR
    assert "--overwrite" in capsys.readouterr().err
    synth.main([*args, "--overwrite"])
    assert (tmp_path / "notes.txt").read_text() == "mine"
    assert (tmp_path / "transforms_train.json").is_file()


def test_cli_renders_a_given_geometry_json(tmp_path: Path, capsys) -> None:
    spec = SceneSpec((Box((0, 0, 0), (0.4, 0.3, 0.2), GREEN), GroundPlane(-0.5, (0.4, 0.4, 0.4), 0.9)))
    small = ["--width", "8", "--height", "8", "--n-val", "1", "--n-test", "1"]
    scene = save_scene(spec, tmp_path / "g.json")
    out = synth.main(["--output-dir", str(tmp_path / "s"), "--scene", str(scene), *small])
    assert load_scene(out / "geometry.json") == spec
    missing = ["--output-dir", str(tmp_path / "t"), "--scene", str(tmp_path / "missing.json"), *small]
    assert cli_exit_code(synth.main, missing) == EXIT_USER_ERROR
    assert "scene file not found" in capsys.readouterr().err
