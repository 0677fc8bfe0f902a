"""The capture core (``CaptureParser``): the forward-facing/object call, both normalisations, splits and few-shot
views, and how the decision is declared and pinned. Most cases run on captures built in memory (no images needed);
the LLFF comparison writes a tiny LLFF scene and its transforms.json."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from fourierf_plugin.data.capture import Capture, Frame, Intrinsics
from fourierf_plugin.data.parsers.capture_parser import CaptureParser, CaptureParserConfig
from fourierf_plugin.data.parsers.capture_scene import (
    OBJECT_NEAR,
    decide_scene_kind,
    frame_depth_bounds,
    normalise_object,
)
from fourierf_plugin.data.parsers.llff import LLFF_DECLARATION, LLFFDataParserConfig
from fourierf_plugin.data.parsers.nerfstudio import NerfstudioDataParserConfig
from fourierf_plugin.data.poses import focus_point, orientation_rotation, rotation_between
from fourierf_plugin.data.scene_effects import SceneEffects
from fourierf_plugin.data.view_selection import kmeans_views
from fourierf_plugin.method_configs.finalize import finalize
from fourierf_plugin.scripts.train import parse_args
from fourierf_plugin.utils.errors import UserError
from tests.data.transforms_scenes import homogeneous, rig_c2w, ring_c2w, write_scene
from tests.scenes import FULL_FOCAL, FULL_H, FULL_W, default_bounds, opengl_poses, write_llff_scene

WIDTH, HEIGHT, FOCAL = 8, 6, 6.0


class MemoryParser(CaptureParser):
    """A capture parser whose capture is handed in (the format-independent core, without a file)."""

    def __init__(self, config: CaptureParserConfig, capture: Capture) -> None:
        super().__init__(config)
        self._given = capture

    def read_capture(self) -> Capture:
        return self._given


def capture_of(
    c2w: np.ndarray,
    points: np.ndarray | None = None,
    bounds: np.ndarray | None = None,
    focal: float = FOCAL,
    models: list[str] | None = None,
) -> Capture:
    frames = [
        Frame(
            Path(f"/capture/images/f{i:03d}.png"),
            homogeneous(c2w[i : i + 1])[0],
            Intrinsics(focal, focal, WIDTH / 2, HEIGHT / 2, WIDTH, HEIGHT, (models or ["PINHOLE"] * len(c2w))[i]),  # type: ignore[arg-type]
            depth_bounds=None if bounds is None else (float(bounds[i, 0]), float(bounds[i, 1])),
        )
        for i in range(len(c2w))
    ]
    return Capture(frames, Path("/capture/transforms.json"), np.zeros((0, 3)) if points is None else points)


def parser_of(capture: Capture, **kwargs) -> MemoryParser:
    return MemoryParser(CaptureParserConfig(data=Path("/capture"), **kwargs), capture)


def _axis_angle(angle: float, axis: list[float]) -> np.ndarray:
    a = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def moved(c2w: np.ndarray, turn: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """The same capture in another world frame: every pose turned by ``turn`` and shifted."""
    out = homogeneous(c2w).copy()
    out[:, :3, :3] = turn @ out[:, :3, :3]
    out[:, :3, 3] = out[:, :3, 3] @ turn.T + shift
    return out


# -- pose geometry --------------------------------------------------------------------------------------------------


def test_rotation_between_takes_a_onto_b() -> None:
    rng = np.random.default_rng(0)
    for a, b in [*(rng.normal(size=(2, 3)) for _ in range(5)), (np.array([0, 0, 1.0]), np.array([0, 0, -1.0]))]:
        r = rotation_between(a, b)
        np.testing.assert_allclose(r @ (a / np.linalg.norm(a)), b / np.linalg.norm(b), atol=1e-12)
        np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
        assert np.linalg.det(r) == pytest.approx(1.0)


def test_focus_of_a_ring_is_its_centre_and_a_rig_has_none() -> None:
    np.testing.assert_allclose(focus_point(ring_c2w(12, centre=(5, -2, 3))), [5, -2, 3], atol=1e-6)
    parallel = homogeneous(opengl_poses(9))
    parallel[:, :3, :3] = np.eye(3)
    assert focus_point(parallel) is None


def test_pca_orientation_puts_the_plane_of_the_cameras_flat() -> None:
    turn = _axis_angle(0.7, [1, 1, 0])
    c2w = moved(ring_c2w(12, height=0.0), turn, np.zeros(3))
    r = orientation_rotation(c2w, "pca")
    centres = c2w[:, :3, 3] @ r.T
    assert np.ptp(centres[:, 2]) < 1e-9, "the ring's plane becomes horizontal"
    assert (r @ c2w[:, :3, 1].mean(axis=0))[2] > 0, "on the side of the cameras' up"
    assert np.linalg.det(r) == pytest.approx(1.0)


# -- forward-facing or object -----------------------------------------------------------------------------------------


def test_a_ring_looking_inward_is_an_object() -> None:
    decision = decide_scene_kind(capture_of(ring_c2w(12)))
    assert decision.kind == "object" and "a capture around the scene" in decision.reason


def test_a_dome_looking_down_surrounds_the_scene() -> None:
    """Cameras 45° above the horizon all look within 45° of straight down, but surround the object."""
    decision = decide_scene_kind(capture_of(ring_c2w(12, radius=4.0, height=4.0)))
    assert decision.kind == "object" and "surround" in decision.reason


@pytest.mark.parametrize("evidence", ["points", "bounds"])
def test_a_fronto_parallel_rig_is_forward_facing(evidence: str) -> None:
    c2w = rig_c2w(12)
    points = np.random.default_rng(0).uniform([-2, -6, -30], [8, 4, -10], size=(200, 3))  # in front of the rig
    capture = capture_of(c2w, points=points) if evidence == "points" else capture_of(c2w, bounds=default_bounds(12))
    parser = parser_of(capture)
    assert parser.scene_kind().kind == "forward-facing"
    declared = parser.declaration()
    assert SceneEffects(**{k: getattr(declared, k) for k in SceneEffects.__dataclass_fields__}) == SceneEffects(
        **{k: getattr(LLFF_DECLARATION, k) for k in SceneEffects.__dataclass_fields__}
    )
    assert declared.bounded is False and declared.reason.startswith("auto: every camera looks within")


def test_a_rig_without_points_or_bounds_needs_them() -> None:
    parser = parser_of(capture_of(rig_c2w(12)))
    assert parser.scene_kind().kind == "forward-facing" and "parallel" in parser.scene_kind().reason
    with pytest.raises(UserError, match="needs the depth range") as info:
        parser.normalised()
    assert "--scene-kind object" in str(info.value.fix)


def test_the_flag_overrides_the_decision_and_pin_records_auto() -> None:
    capture = capture_of(rig_c2w(12), bounds=default_bounds(12))
    forced = parser_of(capture, scene_kind="object").declaration()
    assert forced.bounded and forced.ray_space == "euclidean" and forced.reason == "set by --scene-kind"
    config = CaptureParserConfig(data=Path("/capture"))
    declared = MemoryParser(config, capture).declaration()
    config.pin(declared)
    assert (config.scene_kind, config.scene_kind_reason) == ("forward-facing", declared.reason)
    again = MemoryParser(config, capture_of(ring_c2w(12))).declaration()  # pinned: never decided again
    assert not again.bounded and again.reason == declared.reason
    config.pin(forced)  # a pinned (or user-given) kind stays
    assert config.scene_kind == "forward-facing"


def test_finalize_prints_and_pins_the_decision(tmp_path: Path) -> None:
    scene = write_scene(tmp_path / "ring", ring_c2w(10))
    config, notes = finalize(parse_args(["fourierf-vm", "--data", str(scene), "nerfstudio-data"]))
    parser = config.pipeline.datamanager.dataparser
    assert isinstance(parser, NerfstudioDataParserConfig) and parser.scene_kind == "unbounded"  # photos, no alpha
    assert parser.scene_kind_reason.startswith("auto: ")
    assert [n for n in notes if n.startswith("scene kind: ")] == [
        f"scene kind: unbounded (contracted) ({parser.scene_kind_reason})"
    ]
    assert config.scene_preset == "synthetic"
    given, _ = finalize(parse_args(["fourierf-vm", "--data", str(scene), "nerfstudio-data", "--scene-kind", "object"]))
    assert given.pipeline.datamanager.dataparser.scene_kind_reason == ""


# -- forward-facing normalisation = the LLFF parser's -----------------------------------------------------------------


def llff_and_transforms(root: Path, turn: np.ndarray | None = None) -> tuple[Path, Path]:
    """A tiny LLFF scene and the same capture as a transforms.json (full-size intrinsics, images_8/ copies), the
    latter optionally in a turned and shifted world frame."""
    llff = write_llff_scene(root / "llff")
    c2w = homogeneous(opengl_poses(20))
    if turn is not None:
        c2w = moved(c2w, turn, np.array([4.0, -3.0, 8.0]))
    bounds = default_bounds(20)
    frames = [
        {"file_path": f"images/image{i:03d}.png", "transform_matrix": c2w[i].tolist(), "depth_bounds": list(bounds[i])}
        for i in range(20)
    ]
    meta = {"fl_x": FULL_FOCAL, "fl_y": FULL_FOCAL, "cx": FULL_W / 2, "cy": FULL_H / 2, "w": FULL_W, "h": FULL_H}
    (llff / "transforms.json").write_text(json.dumps(meta | {"frames": frames}))
    return llff, llff / "transforms.json"


@pytest.mark.parametrize("turned", [False, True])
def test_forward_facing_cameras_equal_the_llff_parsers(tmp_path: Path, turned: bool) -> None:
    llff, transforms = llff_and_transforms(tmp_path, _axis_angle(2.5, [0.3, -1, 2]) if turned else None)
    for split in ("train", "test", "val"):
        ours = NerfstudioDataParserConfig(data=transforms, downscale=8, view_ids=(1, 10, 19)).setup().get_outputs(split)
        theirs = LLFFDataParserConfig(data=llff, view_ids=(1, 10, 19)).setup().get_outputs(split)
        assert ours.view_ids == theirs.view_ids
        for name in ("camera_to_worlds", "fx", "fy", "cx", "cy"):
            torch.testing.assert_close(getattr(ours.cameras, name), getattr(theirs.cameras, name), rtol=0, atol=1e-5)
        assert ours.depth_bounds == pytest.approx(theirs.depth_bounds)
        assert (ours.near, ours.far, ours.scene_box.tolist()) == (theirs.near, theirs.far, theirs.scene_box.tolist())
        torch.testing.assert_close(ours.images, theirs.images, rtol=0, atol=0)


def test_depth_bounds_from_the_points_each_camera_sees() -> None:
    c2w = homogeneous(np.concatenate([np.eye(3), np.zeros((3, 1))], axis=1)[None].repeat(3, axis=0))
    c2w[:, 0, 3] = [0.0, 0.5, 1.0]
    c2w[2, :3, :3] = _axis_angle(math.pi, [0, 1, 0])  # the third camera looks away from every point
    depths = np.repeat([3.0, 5.0, 7.0], 4)
    points = np.stack([np.tile([0.1, 0.2, 0.3, 0.4], 3), np.zeros(12), -depths], axis=1)
    bounds = frame_depth_bounds(capture_of(c2w, points=points))
    expected = np.percentile(depths, [0.1, 99.9])
    np.testing.assert_allclose(bounds[0], expected)
    np.testing.assert_allclose(bounds[1], expected)
    np.testing.assert_allclose(bounds[2], expected)  # sees nothing: the others' nearest and farthest


# -- object normalisation ---------------------------------------------------------------------------------------------


def test_object_poses_are_upright_centred_on_the_focus_and_fit_the_unit_box() -> None:
    turn = _axis_angle(1.1, [1, 2, -0.5])
    c2w = moved(ring_c2w(12, radius=4.0, height=1.0), turn, np.array([5.0, -2.0, 3.0]))
    scene = normalise_object(capture_of(c2w), "up", 1.0)
    poses = scene.camera_to_worlds
    up = poses[:, :, 1].mean(axis=0)
    np.testing.assert_allclose(up / np.linalg.norm(up), [0, 0, 1], atol=1e-9)
    assert np.abs(poses[:, :, 3]).max() == pytest.approx(1.0)
    np.testing.assert_allclose(focus_point(poses), 0.0, atol=1e-9)
    for pose in poses:  # still cameras: rotations, and looking at the focus
        np.testing.assert_allclose(pose[:, :3].T @ pose[:, :3], np.eye(3), atol=1e-6)  # look_at is float32
        view = -pose[:, 2]
        np.testing.assert_allclose(view, -pose[:, 3] / np.linalg.norm(pose[:, 3]), atol=1e-6)
    kept = normalise_object(capture_of(c2w), "none", 1.0).camera_to_worlds
    np.testing.assert_allclose(kept[:, :, :3], c2w[:, :3, :3], atol=1e-12)


def test_without_points_the_box_is_what_the_cameras_see_whole() -> None:
    """Blender's lego rig: radius 4 with a 40° field of view sees a cube of half-size 4 tan 20° ≈ 1.46 whole."""
    fov = math.radians(40)
    focal = HEIGHT / 2 / math.tan(fov / 2)  # the narrower (vertical) field of view is 40°
    scene = normalise_object(capture_of(ring_c2w(12, radius=4.0, height=0.0), focal=focal), "up", 1.0)
    half = 4 * math.tan(fov / 2) / 4  # in the normalised units (the ring's radius becomes 1)
    np.testing.assert_allclose(scene.scene_box, [[-half] * 3, [half] * 3], atol=1e-9)
    doubled = normalise_object(capture_of(ring_c2w(12, radius=4.0, height=0.0), focal=focal), "up", 2.0)
    np.testing.assert_allclose(doubled.scene_box, 2 * scene.scene_box, atol=1e-9)


def test_the_box_holds_the_sparse_points() -> None:
    rng = np.random.default_rng(0)
    points = rng.uniform(-1.0, 1.0, size=(2000, 3)) * [1.0, 0.5, 0.25]
    strays = rng.uniform(30, 40, size=(5, 3))
    scene = normalise_object(capture_of(ring_c2w(12, radius=8.0), points=np.concatenate([points, strays])), "none", 1)
    box = scene.scene_box * 8.0  # back to capture units (the ring's radius 8 becomes 1); the focus is the origin
    size = box[1] - box[0]
    np.testing.assert_allclose(size, [2.0, 1.0, 0.5] * np.array(1 + 2 * 0.05), rtol=0.05)
    inside = ((points >= box[0]) & (points <= box[1])).all(axis=1)
    assert inside.mean() > 0.97 and (box[1] < 30).all(), "stray points are left out"


def test_near_and_far_span_the_box_from_every_camera() -> None:
    scene = normalise_object(capture_of(ring_c2w(12)), "up", 1.5)
    corners = np.stack(np.meshgrid(*scene.scene_box.T, indexing="ij"), axis=-1).reshape(-1, 3)
    distances = np.linalg.norm(corners[None] - scene.camera_to_worlds[:, None, :, 3], axis=-1)
    assert distances.max() == pytest.approx(scene.far) and scene.near == OBJECT_NEAR
    assert scene.depth_bounds is None


# -- splits and few-shot views ----------------------------------------------------------------------------------------


def test_hold_out_every_kth_frame_with_index_0() -> None:
    parser = parser_of(capture_of(ring_c2w(20)), test_every=8)
    assert parser.split_ids("test") == [0, 8, 16]
    assert parser.split_ids("train") == [i for i in range(20) if i % 8]
    assert parser_of(capture_of(ring_c2w(20)), test_every=5).split_ids("test") == [0, 5, 10, 15]


def test_few_shot_views_are_kmeans_on_the_training_centres() -> None:
    parser = parser_of(capture_of(ring_c2w(20)), num_views=4, kmeans_seed=3)
    train = [i for i in range(20) if i % 8]
    centres = parser.normalised().camera_to_worlds[train, :, 3]
    assert parser.split_ids("train") == [train[j] for j in kmeans_views(centres, 4, seed=3)]


def test_view_ids_index_all_frames_and_refuse_test_views() -> None:
    assert parser_of(capture_of(ring_c2w(20)), view_ids=(3, 1)).split_ids("train") == [3, 1]
    with pytest.raises(UserError, match="hold-out test images"):
        parser_of(capture_of(ring_c2w(20)), view_ids=(1, 8)).split_ids("train")
    with pytest.raises(UserError, match="more than the 17 training images"):
        parser_of(capture_of(ring_c2w(20)), num_views=18).split_ids("train")


def test_val_is_unused_training_frames_evenly_spaced_else_the_test_set() -> None:
    """As LLFF: with 3 views [1, 10, 19] of 20 frames, val is 2, 9, 18."""
    assert parser_of(capture_of(ring_c2w(20)), view_ids=(1, 10, 19)).split_ids("val") == [2, 9, 18]
    assert parser_of(capture_of(ring_c2w(20)), view_ids=(1, 10, 19), val_views=1).split_ids("val") == [2]
    assert parser_of(capture_of(ring_c2w(20))).split_ids("val") == [0, 8, 16]


def test_listed_splits_replace_the_hold_out() -> None:
    capture = capture_of(ring_c2w(6))
    capture.splits = {"train": ["images/f000.png", "images/f002.png"], "test": ["images/f005.png"]}
    parser = parser_of(capture)
    assert (parser.split_ids("train"), parser.split_ids("test"), parser.split_ids("val")) == ([0, 2], [5], [5])
    capture.splits = {"val": ["images/f001.png"]}
    parser = parser_of(capture)
    assert (parser.split_ids("train"), parser.split_ids("test"), parser.split_ids("val")) == ([0, 2, 3, 4, 5], [1], [1])


def test_no_training_frame_left_fails() -> None:
    with pytest.raises(UserError, match="leaves no training images"):
        parser_of(capture_of(ring_c2w(1))).split_ids("train")


def test_one_camera_model_per_capture() -> None:
    models = ["PINHOLE"] * 5 + ["OPENCV"]
    with pytest.raises(UserError, match="mixes camera models"):
        parser_of(capture_of(ring_c2w(6), models=models)).capture()


@pytest.mark.parametrize(
    ("option", "value"),
    [("test_every", 1), ("downscale", 0), ("scene_scale", 0.0), ("bd_factor", -1.0), ("val_views", 0)],
)
def test_bad_options_fail_before_any_work(option: str, value: float) -> None:
    with pytest.raises(UserError, match=option.replace("_", "-")):
        parser_of(capture_of(ring_c2w(6)), **{option: value}).get_outputs("train")
