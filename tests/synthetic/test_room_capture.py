"""The object-in-a-room capture: textured surfaces, cameras on a partial arc, a nerfstudio capture the parser reads,
and ground truth (depth of the test views, the object's geometry and surface) that agrees with the photos."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import trimesh

from fourierf_plugin.data.parsers.nerfstudio import NerfstudioDataParserConfig, read_transforms
from fourierf_plugin.scripts import synth
from fourierf_plugin.scripts.cli import EXIT_USER_ERROR
from fourierf_plugin.synthetic import (
    SceneSpec,
    Sphere,
    default_scene,
    intersect_scene,
    load_scene,
    save_scene,
    surface_distance,
    write_blender_dataset,
)
from fourierf_plugin.synthetic.nerfstudio_capture import capture_cameras, render_camera
from fourierf_plugin.synthetic.primitives import Box, Panel, room_panels
from fourierf_plugin.synthetic.room import (
    ARC_CENTRE_DEG,
    HAND_JITTER,
    HEIGHT_ABOVE_AIM,
    HEIGHT_SWAY,
    TABLE_TOP_Z,
    room_scene,
    write_room_capture,
)
from fourierf_plugin.synthetic.textures import Texture
from fourierf_plugin.utils.errors import UserError
from tests.helpers import cli_exit_code

W, H = 48, 36
N_TRAIN, N_TEST = 9, 3
SMALL = {"width": W, "height": H, "n_train": N_TRAIN, "n_test": N_TEST, "samples_per_pixel": 1}
CHECKER = Texture("checker", ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)), 0.5)


@pytest.fixture(scope="module")
def capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_room_capture(tmp_path_factory.mktemp("room") / "cap", **SMALL)


def transforms(capture: Path) -> dict:
    return json.loads((capture / "transforms.json").read_text())


def geometry(capture: Path) -> dict:
    return json.loads((capture / "geometry.json").read_text())


def pinhole_rays(meta: dict, c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit rays [H*W, 3] through the pixel centres, from transforms.json's intrinsics (OpenGL, looking down -z)."""
    v, u = np.meshgrid(np.arange(meta["h"]) + 0.5, np.arange(meta["w"]) + 0.5, indexing="ij")
    local = np.stack([(u - meta["cx"]) / meta["fl_x"], -(v - meta["cy"]) / meta["fl_y"], -np.ones_like(u)], axis=-1)
    dirs = local.reshape(-1, 3) @ c2w[:3, :3].T
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    return np.broadcast_to(c2w[:3, 3], dirs.shape), dirs


def frame_ids(meta: dict, split: str) -> list[int]:
    paths = [f["file_path"] for f in meta["frames"]]
    return [paths.index(name) for name in meta[f"{split}_filenames"]]


# -- layout ---------------------------------------------------------------------------------------------------------
def test_the_capture_has_the_stated_layout(capture: Path) -> None:
    meta = transforms(capture)
    assert (meta["camera_model"], meta["w"], meta["h"], meta["cx"], meta["cy"]) == ("PINHOLE", W, H, W / 2, H / 2)
    assert meta["ply_file_path"] == "points.ply" and (capture / "points.ply").is_file()
    names = [f["file_path"] for f in meta["frames"]]
    assert names == [f"images/frame_{i:05d}.png" for i in range(N_TRAIN + N_TEST)]  # arc order
    assert (len(meta["train_filenames"]), len(meta["test_filenames"])) == (N_TRAIN, N_TEST)
    assert sorted(meta["train_filenames"] + meta["test_filenames"]) == names and "val_filenames" not in meta
    for name in names:
        image = iio.imread(capture / name)
        assert image.shape == (H, W, 3) and image.dtype == np.uint8  # RGB: no alpha, as a phone photo
    depth_files = sorted(p.name for p in (capture / "depth").iterdir())
    assert depth_files == sorted(Path(n).stem + ".npy" for n in meta["test_filenames"])
    geo = geometry(capture)
    assert geo["depth"]["files"] == [f"depth/{Path(n).stem}.npy" for n in meta["test_filenames"]]
    scene = room_scene()
    assert load_scene(capture / "geometry.json") == scene.spec
    assert load_scene(capture / "object.json") == scene.object_spec
    np.testing.assert_allclose(geo["object"]["bounds"], scene.object_bounds())
    assert [scene.spec.primitives[i] for i in geo["object"]["primitives"]] == list(scene.object_spec.primitives)


def test_the_photos_are_what_the_json_files_describe(capture: Path) -> None:
    """Rendering geometry.json through the cameras of transforms.json gives the photos' exact bytes."""
    meta, spec = transforms(capture), load_scene(capture / "geometry.json")
    c2ws = np.array([f["transform_matrix"] for f in meta["frames"]])
    cameras = capture_cameras(c2ws, W, H, 2 * math.atan(W / 2 / meta["fl_x"]))
    for i in (0, len(c2ws) // 2, len(c2ws) - 1):
        rgba = render_camera(spec, cameras, i, geometry(capture)["render"]["shading"])
        expected = np.round(np.clip(rgba[..., :3], 0, 1) * 255).astype(np.uint8)
        np.testing.assert_array_equal(iio.imread(capture / meta["frames"][i]["file_path"]), expected)


# -- the parser -----------------------------------------------------------------------------------------------------
def test_the_nerfstudio_parser_reads_the_splits_few_shot_views_and_points(capture: Path) -> None:
    meta = transforms(capture)
    parser = NerfstudioDataParserConfig(data=capture, num_views=4).setup()
    train, test = parser.get_outputs("train"), parser.get_outputs("test")
    assert len(train.view_ids) == 4 and set(train.view_ids) <= set(frame_ids(meta, "train"))
    assert test.view_ids == frame_ids(meta, "test")
    assert tuple(train.images.shape[1:3]) == (H, W)
    for ids, out in ((train.view_ids, train), (test.view_ids, test)):
        for k, i in enumerate(ids):
            photo = iio.imread(capture / meta["frames"][i]["file_path"]).astype(np.float32) / 255
            np.testing.assert_allclose(out.images[k, ..., :3].numpy(), photo, atol=1e-6)
            if out.images.shape[-1] == 4:
                assert bool((out.images[k, ..., 3] == 1).all())  # no alpha: every pixel is content
    assert parser.declaration().background != "white"  # photos without alpha have no known background
    points = read_transforms(capture / "transforms.json").points
    assert len(points) == geometry(capture)["render"]["sparse_points"]["count"] == 4000
    # The robust box of the points (the parser's 1st-99th percentiles) holds the object and reaches into the room.
    low, high = np.percentile(points, (1.0, 99.0), axis=0)
    bounds = room_scene().object_bounds()
    assert (low < bounds[0]).all() and (high > bounds[1]).all()
    assert (high - low).max() > 3 * (bounds[1] - bounds[0]).max()


# -- ground truth ---------------------------------------------------------------------------------------------------
def test_the_centre_ray_of_every_camera_hits_the_object_unobstructed(capture: Path) -> None:
    meta, scene = transforms(capture), room_scene()
    test_ids = set(frame_ids(meta, "test"))
    for i, frame in enumerate(meta["frames"]):
        c2w = np.asarray(frame["transform_matrix"])
        origin, direction = c2w[None, :3, 3], -c2w[None, :3, 2]
        hits = intersect_scene(scene.spec, origin, direction)
        assert int(hits.index[0]) in scene.object_indices
        t_object = intersect_scene(scene.object_spec, origin, direction).t[0]
        assert hits.t[0] == t_object  # nothing in the room lies in front of the object
        assert surface_distance(scene.object_spec, origin + t_object * direction)[0] < 1e-9
        if i in test_ids:  # the pixel below-right of the image centre: its own ray, through the object too
            depth = np.load(capture / "depth" / f"frame_{i:05d}.npy")
            origins, dirs = pinhole_rays(meta, c2w)
            k = (H // 2) * W + W // 2
            pixel = intersect_scene(scene.spec, origins[k : k + 1], dirs[k : k + 1])
            assert int(pixel.index[0]) in scene.object_indices
            assert depth[H // 2, W // 2] == pytest.approx(pixel.t[0], rel=1e-6)


def test_test_view_depth_is_the_ray_distance_to_the_first_surface(capture: Path) -> None:
    meta, spec = transforms(capture), room_scene().spec
    for i in frame_ids(meta, "test"):
        depth = np.load(capture / "depth" / f"frame_{i:05d}.npy")
        assert depth.shape == (H, W) and depth.dtype == np.float32 and np.isfinite(depth).all()
        origins, dirs = pinhole_rays(meta, np.asarray(meta["frames"][i]["transform_matrix"]))
        hits = intersect_scene(spec, origins, dirs)
        np.testing.assert_allclose(depth.reshape(-1), hits.t, rtol=1e-6)
        points = origins + depth.reshape(-1, 1).astype(np.float64) * dirs
        assert surface_distance(spec, points).max() < 1e-5


def test_the_background_is_textured_everywhere_and_fills_most_of_each_photo(capture: Path) -> None:
    meta, scene = transforms(capture), room_scene()
    for frame in meta["frames"]:
        image = iio.imread(capture / frame["file_path"]).reshape(-1, 3)
        hits = intersect_scene(scene.spec, *pinhole_rays(meta, np.asarray(frame["transform_matrix"])))
        assert hits.hit.all()  # the room is closed: every pixel sees a surface
        on_object = np.isin(hits.index, scene.object_indices)
        assert 0.05 < on_object.mean() < 0.5
        background = image[~on_object]
        assert len(np.unique(background, axis=0)) >= 8 and background.astype(float).std(axis=0).max() > 10
        for i in (*scene.table_indices[:1], *scene.room_indices):  # the table top, walls, floor: each textured
            if (hits.index == i).sum() >= 20:
                assert len(np.unique(image[hits.index == i], axis=0)) >= 2
    walls_seen = {
        int(i)
        for f in meta["frames"]
        for i in np.unique(intersect_scene(scene.spec, *pinhole_rays(meta, np.asarray(f["transform_matrix"]))).index)
    } & set(scene.room_indices)
    assert len(walls_seen) >= 3  # floor and two walls or more


def test_sparse_points_lie_on_the_seen_surfaces_object_table_and_walls(capture: Path) -> None:
    scene = room_scene()
    cloud = trimesh.load(capture / "points.ply", process=False)
    points = np.asarray(cloud.vertices, dtype=np.float64)
    assert len(points) == 4000 and np.asarray(cloud.colors).shape[0] == 4000
    per_part = {
        name: np.min([scene.spec.primitives[i].surface_distance(points) for i in ids], axis=0) < 1e-6
        for name, ids in (
            ("object", scene.object_indices),
            ("table", scene.table_indices),
            ("room", scene.room_indices),
        )
    }
    assert np.any(list(per_part.values()), axis=0).all()
    assert per_part["object"].mean() == pytest.approx(0.4, abs=0.01)
    assert per_part["table"].sum() > 100 and per_part["room"].sum() > 500


def test_the_object_surface_samples_lie_on_the_object_and_not_inside_the_table(capture: Path) -> None:
    scene = room_scene()
    samples = np.asarray(trimesh.load(capture / "object_surface.ply", process=False).vertices, dtype=np.float64)
    assert len(samples) == geometry(capture)["object"]["surface_points"]
    assert surface_distance(scene.object_spec, samples).max() < 1e-6
    assert samples[:, 2].min() >= TABLE_TOP_Z - 1e-9  # faces resting in the table are not exposed
    assert not scene.table_top.contains(samples).any()


# -- the arc --------------------------------------------------------------------------------------------------------
def test_the_cli_arc_spans_its_stated_degrees_with_a_phone_field_of_view(tmp_path: Path, capsys) -> None:
    small = ["--width", "32", "--height", "24", "--n-train", "7", "--n-test", "3", "--samples-per-pixel", "1"]
    out = synth.main(["--output-dir", str(tmp_path / "r"), "--kind", "room", *small])
    assert "7 train candidates and 3 test views on a 110° arc at 32x24" in capsys.readouterr().out
    meta, geo = transforms(out), geometry(out)
    assert math.degrees(2 * math.atan(meta["w"] / 2 / meta["fl_x"])) == pytest.approx(65.0)
    assert iio.imread(out / meta["frames"][0]["file_path"]).shape == (24, 32, 3)
    aim = np.asarray(geo["arc"]["aim"])
    np.testing.assert_allclose(aim, room_scene().aim_point())
    eyes = np.array([f["transform_matrix"] for f in meta["frames"]])[:, :3, 3]
    azimuth = np.degrees(np.arctan2(eyes[:, 1] - aim[1], eyes[:, 0] - aim[0]))
    train, test = azimuth[frame_ids(meta, "train")], azimuth[frame_ids(meta, "test")]
    assert train.max() - train.min() == pytest.approx(110.0)
    assert (train.min() + train.max()) / 2 == pytest.approx(ARC_CENTRE_DEG)
    assert geo["arc"]["span_deg"] == 110.0 and geo["arc"]["azimuth_deg"] == pytest.approx([train.min(), train.max()])
    np.testing.assert_allclose(np.hypot(*(eyes[:, :2] - aim[:2]).T), 1.0)
    gaps = np.searchsorted(np.sort(train), test)
    assert len(set(gaps)) == len(test) and ((gaps > 0) & (gaps < len(train))).all()  # each in its own gap
    heights = eyes[:, 2] - aim[2]
    assert (np.abs(heights - HEIGHT_ABOVE_AIM) <= HEIGHT_SWAY + HAND_JITTER + 1e-12).all()
    assert heights.max() - heights.min() > HEIGHT_SWAY  # the height varies a little
    assert (eyes[:, 2] > room_scene().object_bounds()[0, 2]).all()  # at the object's height, above the table


@pytest.mark.parametrize("arc", [60.0, 200.0])
def test_arc_deg_sets_the_span(tmp_path: Path, arc: float) -> None:
    out = write_room_capture(tmp_path / "r", 16, 12, 5, 2, arc_deg=arc, samples_per_pixel=1, n_points=50)
    meta, aim = transforms(out), room_scene().aim_point()
    eyes = np.array([f["transform_matrix"] for f in meta["frames"]])[frame_ids(meta, "train"), :3, 3] - aim
    azimuth = np.unwrap(np.arctan2(eyes[:, 1], eyes[:, 0]))
    assert math.degrees(azimuth.max() - azimuth.min()) == pytest.approx(arc)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--kind", "room", "--n-val", "2"], "--n-val does not apply to --kind room"),
        (["--kind", "room", "--ground-plane"], "--ground-plane does not apply"),
        (["--kind", "room", "--n-train", "4", "--n-test", "4"], "--n-test must be between 1 and"),
        (["--kind", "room", "--radius", "0.3"], "over the table or outside the room"),
        (["--kind", "room", "--radius", "3"], "over the table or outside the room"),
        (["--kind", "room", "--arc-deg", "0"], "--arc-deg must lie in"),
        (["--kind", "room", "--arc-deg", "360"], "--arc-deg must lie in"),
        (["--arc-deg", "90"], "--arc-deg only applies to --kind room"),
    ],
)
def test_cli_bad_room_options_exit_2_before_writing(tmp_path: Path, capsys, args: list[str], message: str) -> None:
    assert cli_exit_code(synth.main, ["--output-dir", str(tmp_path / "s"), "--width", "16", *args]) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert message in err and "fix:" in err
    assert not (tmp_path / "s").exists()


# -- primitives and textures ----------------------------------------------------------------------------------------
def test_textures_give_their_patterns() -> None:
    red, green, blue = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
    uv = np.array([[0.25, 0.25], [0.75, 0.25], [0.25, 0.75], [-0.25, 0.25], [1.25, 1.25]])
    np.testing.assert_array_equal(CHECKER.color_at(uv)[:, 0], [0, 1, 1, 1, 0])
    stripes = Texture("stripes", (red, green, blue), 0.5)
    np.testing.assert_array_equal(stripes.color_at(uv), [red, green, red, blue, blue])
    across = Texture("stripes", (red, green), 0.5, angle=90.0)  # bands along u
    np.testing.assert_array_equal(across.color_at(uv), [red, red, green, red, red])
    grid = np.stack(np.meshgrid(np.arange(40) + 0.5, np.arange(40) + 0.5), -1).reshape(-1, 2)
    tiles = Texture("tiles", (red, green, blue), 1.0, seed=5).color_at(grid)
    counts = np.unique(tiles, axis=0, return_counts=True)[1]
    assert len(counts) == 3 and counts.min() > 400  # every colour, in about equal shares
    np.testing.assert_array_equal(tiles, Texture("tiles", (red, green, blue), 1.0, seed=5).color_at(grid))
    assert not np.array_equal(tiles, Texture("tiles", (red, green, blue), 1.0, seed=6).color_at(grid))
    noise = Texture("noise", ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)), 1.0)
    fine = noise.color_at(np.stack([np.linspace(0, 4, 4001), np.zeros(4001)], -1))[:, 0]
    assert fine.min() >= 0 and fine.max() <= 1 and fine.std() > 0.05
    assert np.abs(np.diff(fine)).max() < 0.01  # smooth: no jumps between neighbouring points


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"kind": "plaid"}, "texture kind"),
        ({"colors": ((0.1, 0.2, 0.3),)}, "2 or more RGB"),
        ({"colors": ((0.1, 0.2, 0.3), (0.4, 1.5, 0.0))}, r"in \[0, 1\]"),
        ({"scale": 0.0}, "scale must be a positive"),
    ],
)
def test_bad_textures_are_refused(kwargs: dict, message: str) -> None:
    base = {"kind": "checker", "colors": ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)), "scale": 0.1} | kwargs
    with pytest.raises(ValueError, match=message):
        Texture(**base)


def test_a_textured_scene_round_trips_through_geometry_json(tmp_path: Path) -> None:
    spec = room_scene().spec
    assert load_scene(save_scene(spec, tmp_path / "g.json")) == spec
    data = json.loads((tmp_path / "g.json").read_text())
    data["primitives"][0]["texture"]["kind"] = "plaid"
    (tmp_path / "bad.json").write_text(json.dumps(data))
    with pytest.raises(UserError, match=r"primitive 0 \(box\): texture kind"):
        load_scene(tmp_path / "bad.json")


def test_panel_hits_from_both_sides_and_room_panels_close_the_room() -> None:
    wall = Panel((0.0, 2.0, 0.0), (1.0, 0.0, 0.5), (0.5, 0.5, 0.5))
    origins = np.array([[0.0, 0.0, 0.0], [0.0, 4.0, 0.2], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    dirs = np.array([[0.0, 1.0, 0.0], [0.0, -2.0, 0.0], [0.0, -1.0, 0.0], [0.0, 1.0, 0.3]])
    t, normals = wall.intersect(origins, dirs)
    np.testing.assert_allclose(t, [2.0, 1.0, np.inf, np.inf])  # the last passes over its top edge (z = 0.6 > 0.5)
    np.testing.assert_array_equal(normals[:2], [[0, -1, 0], [0, 1, 0]])  # facing each ray's origin
    assert wall.area() == pytest.approx(2.0) and not wall.contains(origins).any()
    np.testing.assert_allclose(wall.surface_distance(np.array([[0.0, 2.5, 0.0], [1.5, 2.0, 0.0]])), [0.5, 0.5])
    with pytest.raises(ValueError, match="exactly one zero"):
        Panel((0, 0, 0), (1.0, 1.0, 1.0), (0.5, 0.5, 0.5))
    room = SceneSpec(room_panels((-1, -2, -1), (3, 2, 1), CHECKER, CHECKER, (CHECKER,) * 4))
    rng = np.random.default_rng(0)
    dirs = rng.standard_normal((20000, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    hits = intersect_scene(room, np.zeros_like(dirs), dirs)
    assert hits.hit.all()  # closed: no ray from inside escapes, not even along the edges
    corner = intersect_scene(room, np.zeros((1, 3)), np.array([[-1.0, -2.0, -1.0]]) / math.sqrt(6))
    assert corner.t[0] == pytest.approx(math.sqrt(6))


def test_a_textured_box_shows_its_texture_on_each_face() -> None:
    box = Box((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), (0.5, 0.5, 0.5), CHECKER)
    points = np.array([[1.0, 0.25, 0.25], [1.0, 0.75, 0.25], [0.25, 0.25, 1.0], [0.75, 0.25, -1.0]])
    normals = np.array([[1.0, 0, 0], [1.0, 0, 0], [0, 0, 1.0], [0, 0, -1.0]])
    np.testing.assert_array_equal(box.color_at(points, normals)[:, 0], [0, 1, 0, 1])
    sphere = Sphere((0.0, 0.0, 0.0), 1.0, (0.5, 0.5, 0.5))
    np.testing.assert_array_equal(sphere.color_at(points[:1], normals[:1]), [[0.5, 0.5, 0.5]])  # untextured: flat


# -- the other scenes are untouched ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("ground_plane", "shading", "spp", "pixels", "geometry_json"),
    [
        (False, "none", 1, "57a474b91858b293", "379a53fa72e4e28b"),
        (True, "lambert", 2, "7a997608b2cec9d8", "fc452932af915b58"),
    ],
)
def test_the_objects_scenes_are_bit_identical(
    tmp_path: Path, ground_plane, shading, spp, pixels, geometry_json
) -> None:
    """Pinned pixel and geometry.json hashes of the Blender-format default scene: textures and panels change nothing."""
    out = write_blender_dataset(
        default_scene(ground_plane), tmp_path / "b", 32, 24, 2, 1, 1, shading=shading, samples_per_pixel=spp
    )
    digest = hashlib.sha256()
    for split in ("train", "val", "test"):
        for frame in json.loads((out / f"transforms_{split}.json").read_text())["frames"]:
            digest.update(np.ascontiguousarray(iio.imread(out / (frame["file_path"][2:] + ".png"))).tobytes())
    assert digest.hexdigest()[:16] == pixels
    assert hashlib.sha256((out / "geometry.json").read_bytes()).hexdigest()[:16] == geometry_json
    assert "texture" not in (out / "geometry.json").read_text()
