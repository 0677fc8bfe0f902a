"""An unbounded capture's object box: what the photos aim at (the sparse points in the central part of nearly every
photo, about the cameras' focus), not the table it stands on; the points nearly every camera sees, else None, when too
few points are aimed at."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from fourierf_plugin.data.capture import Capture, Frame, Intrinsics
from fourierf_plugin.data.parsers.capture_scene import (
    MIN_BOX_POINTS,
    _box_aimed_at,
    _box_seen_by_most,
    _object_box,
    normalise_unbounded,
)
from fourierf_plugin.synthetic.cameras import look_at

WIDTH, HEIGHT = 160, 120
FOCAL = WIDTH / 2 / math.tan(math.radians(65.0) / 2)  # a phone's 65° across
TABLE_Z = -0.2


def arc_c2w(n: int = 24, arc_deg: float = 110.0) -> np.ndarray:
    """[n, 4, 4] cameras on an arc on the -y side at unit distance, a little above the origin, looking at it: their
    focus is the origin and they fit [-1, 1]³ as they are, so the normalised frame is this one."""
    azimuths = np.radians(-90.0 + arc_deg * (np.linspace(0.0, 1.0, n) - 0.5))
    eyes = np.stack([np.cos(azimuths), np.sin(azimuths), np.full(n, 0.2)], axis=1)
    return np.stack([look_at(eye) for eye in eyes])


def capture_of(c2w: np.ndarray, points: np.ndarray) -> Capture:
    k = Intrinsics(FOCAL, FOCAL, WIDTH / 2, HEIGHT / 2, WIDTH, HEIGHT)
    frames = [Frame(Path(f"/capture/images/f{i:03d}.png"), pose, k) for i, pose in enumerate(c2w)]
    return Capture(frames, Path("/capture/transforms.json"), points)


def object_points(n: int = 600, seed: int = 0) -> np.ndarray:
    """A compact object at the focus: a sphere of radius 0.15 standing on the table."""
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return 0.15 * d / np.linalg.norm(d, axis=1, keepdims=True) + np.array([0.0, 0.0, TABLE_Z + 0.15])


def table_points(n: int = 1500, half: float = 0.9, seed: int = 1) -> np.ndarray:
    """A wide flat table top under the object, reaching nearly as far as the cameras."""
    xy = np.random.default_rng(seed).uniform(-half, half, size=(n, 2))
    return np.concatenate([xy, np.full((n, 1), TABLE_Z)], axis=1)


def inside(points: np.ndarray, box: np.ndarray) -> np.ndarray:
    return ((points >= box[0] - 1e-9) & (points <= box[1] + 1e-9)).all(axis=1)


def test_the_box_holds_the_object_and_leaves_out_most_of_the_table() -> None:
    c2w = arc_c2w()
    obj, table = object_points(), table_points()
    box = normalise_unbounded(capture_of(c2w, np.concatenate([obj, table])), "none").object_box
    assert box is not None
    assert inside(obj, box).all()
    assert inside(table, box).mean() < 0.2
    table_area = (2 * 0.9) ** 2
    assert np.prod(box[1, :2] - box[0, :2]) < 0.25 * table_area
    seen_by_most = _box_seen_by_most(c2w[:, :3, :4], capture_of(c2w, table), table)
    assert seen_by_most is not None and inside(table, seen_by_most).mean() > inside(table, box).mean()


def test_a_far_wall_straight_behind_the_object_stays_out_on_a_narrow_arc() -> None:
    c2w = arc_c2w(arc_deg=40.0)
    obj = object_points()
    wall = np.random.default_rng(2).uniform(-0.3, 0.3, size=(400, 3)) * np.array([1.0, 0.0, 1.0]) + [0.0, 2.5, 0.0]
    box = normalise_unbounded(capture_of(c2w, np.concatenate([obj, wall])), "none").object_box
    assert box is not None and inside(obj, box).all() and not inside(wall, box).any()


def test_the_side_no_photo_sees_is_held_behind_the_focus() -> None:
    c2w = arc_c2w()
    obj = object_points()
    front = obj[obj[:, 1] < 0]  # only the side facing the cameras has sparse points
    box = _box_aimed_at(c2w[:, :3, :4], capture_of(c2w, front), front)
    assert box is not None and inside(obj, box).all()


def test_too_few_aimed_points_fall_back_to_what_most_cameras_see_then_to_none() -> None:
    c2w = arc_c2w()
    poses = c2w[:, :3, :4]
    rim = table_points(seed=3)
    rim = rim[np.abs(rim[:, :2]).max(axis=1) > 0.5]  # the table's rim: at the frames' edges, never aimed at
    capture = capture_of(c2w, rim)
    assert _box_aimed_at(poses, capture, rim) is None
    fallback = _box_seen_by_most(poses, capture, rim)
    assert fallback is not None
    assert np.array_equal(_object_box(poses, capture, rim, converge=True), fallback)
    few = object_points(MIN_BOX_POINTS - 1)
    assert _object_box(poses, capture_of(c2w, few), few, converge=True) is None
    obj = object_points()
    assert np.array_equal(
        _object_box(poses, capture_of(c2w, obj), obj, converge=False),
        _box_seen_by_most(poses, capture_of(c2w, obj), obj),
    )
