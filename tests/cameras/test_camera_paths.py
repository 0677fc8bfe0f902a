"""Camera paths: look-at poses, the turntable orbit, the LLFF spiral, the arc over the captured range, the path
through the training cameras and resolution scaling, checked geometrically."""

from __future__ import annotations

import math

import pytest
import torch

from fourierf_plugin.cameras.camera_paths import (
    arc_path,
    average_pose,
    azimuths,
    capture_order,
    captured_range,
    focus_depth,
    interpolate_path,
    llff_focus,
    look_at,
    orbit_from_cameras,
    orbit_path,
    scale_cameras,
    scene_up,
    spiral_path,
    surrounds,
)
from fourierf_plugin.cameras.cameras import Cameras

ATOL = 1e-5


def _assert_rotations_valid(c2w: torch.Tensor) -> None:
    """Every [3, 3] block is orthonormal with determinant +1 (a rotation, no reflection or scale)."""
    rot = c2w[..., :3].reshape(-1, 3, 3)
    eye = torch.eye(3).expand_as(rot)
    assert torch.allclose(rot.transpose(1, 2) @ rot, eye, atol=ATOL)
    assert torch.allclose(torch.linalg.det(rot), torch.ones(rot.shape[0]), atol=ATOL)


def _viewing_direction(c2w: torch.Tensor) -> torch.Tensor:
    """World direction of the camera's optical axis (OpenGL: the camera looks down its -z)."""
    return -c2w[..., :3, 2]


def _unit(v: torch.Tensor) -> torch.Tensor:
    return v / v.norm(dim=-1, keepdim=True)


# -- look_at --------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("eye", "target", "up"),
    [
        ((4.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
        ((1.0, -2.0, 3.0), (0.5, 0.5, -0.5), (0.0, 0.0, 1.0)),
        ((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
        ((-3.0, 2.0, 1.0), (1.0, 1.0, 1.0), (0.0, 1.0, 0.0)),
    ],
)
def test_look_at_points_the_optical_axis_at_the_target(eye, target, up) -> None:
    c2w = look_at(eye, target, up)
    assert c2w.shape == (3, 4)
    _assert_rotations_valid(c2w)
    assert torch.allclose(c2w[:, 3], torch.tensor(eye))
    expected = _unit(torch.tensor(target) - torch.tensor(eye))
    assert torch.allclose(c2w[:, :3] @ torch.tensor([0.0, 0.0, -1.0]), expected, atol=ATOL)
    # no roll: the image's x axis is horizontal (perpendicular to up) and its y axis leans towards up
    assert abs(float(c2w[:, 0] @ torch.tensor(up))) < ATOL
    assert float(c2w[:, 1] @ torch.tensor(up)) > 0


def test_look_at_straight_along_up_still_gives_a_rotation() -> None:
    c2w = look_at((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    _assert_rotations_valid(c2w)
    assert torch.allclose(_viewing_direction(c2w), torch.tensor([0.0, 0.0, -1.0]), atol=ATOL)


def test_look_at_rejects_eye_at_target() -> None:
    with pytest.raises(ValueError, match="eye != target"):
        look_at((1.0, 1.0, 1.0), (1.0, 1.0, 1.0))


# -- orbit ----------------------------------------------------------------------------------------------------------
def test_orbit_cameras_sit_on_the_circle_and_look_at_the_centre() -> None:
    center = torch.tensor([0.1, -0.2, 0.3])
    cams = orbit_path(center, 2.5, 30.0, 8, fx=50.0, fy=60.0, width=100, height=80)
    assert len(cams) == 8 and (cams.width, cams.height) == (100, 80)
    assert torch.allclose(cams.cx, torch.full((8,), 50.0)) and torch.allclose(cams.cy, torch.full((8,), 40.0))
    assert torch.allclose(cams.fx, torch.full((8,), 50.0)) and torch.allclose(cams.fy, torch.full((8,), 60.0))
    _assert_rotations_valid(cams.camera_to_worlds)
    offsets = cams.centers - center
    assert torch.allclose(offsets.norm(dim=-1), torch.full((8,), 2.5), atol=ATOL)
    elevation = torch.rad2deg(torch.asin(offsets[:, 2] / offsets.norm(dim=-1)))
    assert torch.allclose(elevation, torch.full((8,), 30.0), atol=1e-3)
    assert torch.allclose(_viewing_direction(cams.camera_to_worlds), _unit(-offsets), atol=ATOL)
    # z-up turntable: no roll, and the frames are distinct, evenly spaced in azimuth, not repeating the first
    assert torch.allclose(cams.camera_to_worlds[:, 2, 0], torch.zeros(8), atol=ATOL)
    azimuth = torch.atan2(offsets[:, 1], offsets[:, 0])
    steps = torch.remainder(azimuth.roll(-1) - azimuth, 2 * math.pi)
    assert torch.allclose(steps, torch.full((8,), 2 * math.pi / 8), atol=1e-4)
    assert torch.cdist(cams.centers, cams.centers).add(torch.eye(8) * 10).min() > 0.1


def test_orbit_centre_pixel_ray_hits_the_centre() -> None:
    """Through Cameras.generate_rays: the single pixel of a 1x1 image sees the orbit centre."""
    center = torch.tensor([0.5, 0.0, -0.2])
    cams = orbit_path(center, 3.0, -20.0, 5, fx=1.0, fy=1.0, width=1, height=1)
    for i in range(len(cams)):
        origin, direction = cams.generate_rays(i)
        to_center = _unit(center - origin[0])
        assert torch.allclose(direction[0], to_center, atol=ATOL)


@pytest.mark.parametrize("elevation", [90.0, -90.0])
def test_orbit_at_the_poles_has_valid_poses(elevation: float) -> None:
    cams = orbit_path((0.0, 0.0, 0.0), 1.0, elevation, 3, 10.0, 10.0, 8, 8)
    _assert_rotations_valid(cams.camera_to_worlds)
    assert torch.isfinite(cams.camera_to_worlds).all()


def test_orbit_rejects_bad_arguments() -> None:
    with pytest.raises(ValueError, match="n_frames"):
        orbit_path((0, 0, 0), 1.0, 0.0, 0, 1.0, 1.0, 4, 4)
    with pytest.raises(ValueError, match="radius"):
        orbit_path((0, 0, 0), 0.0, 0.0, 3, 1.0, 1.0, 4, 4)


def test_orbit_from_cameras_matches_their_distance_elevation_and_intrinsics() -> None:
    source = orbit_path((0.0, 0.0, 0.0), 4.0, 30.0, 5, fx=111.0, fy=112.0, width=64, height=48, cx=30.0, cy=25.0)
    cams = orbit_from_cameras(source, 7)
    assert len(cams) == 7 and (cams.width, cams.height) == (64, 48)
    assert torch.allclose(cams.centers.norm(dim=-1), torch.full((7,), 4.0), atol=1e-4)
    assert torch.allclose(cams.centers[:, 2], torch.full((7,), 4.0 * math.sin(math.radians(30.0))), atol=1e-4)
    for got, want in ((cams.fx, 111.0), (cams.fy, 112.0), (cams.cx, 30.0), (cams.cy, 25.0)):
        assert torch.allclose(got, torch.full((7,), want))
    low = orbit_from_cameras(source, 3, elevation_deg=10.0)
    assert torch.allclose(low.centers[:, 2], torch.full((3,), 4.0 * math.sin(math.radians(10.0))), atol=1e-4)


# -- spiral ---------------------------------------------------------------------------------------------------------
def _forward_facing_cameras() -> Cameras:
    """Five cameras on a small grid in the z=0 plane, all looking down -z (an LLFF-like capture)."""
    positions = torch.tensor([[0.0, 0.0, 0.0], [-0.4, -0.3, 0.05], [0.4, -0.3, 0.0], [-0.4, 0.3, -0.05], [0.4, 0.3, 0]])
    c2w = torch.cat([torch.eye(3).expand(5, 3, 3), positions.unsqueeze(-1)], dim=-1)
    full = torch.full((5,), 40.0)
    return Cameras(c2w, full, full, torch.full((5,), 32.0), torch.full((5,), 24.0), 64, 48)


def test_focus_depth_is_llffs_weighted_harmonic_mean() -> None:
    assert focus_depth(2.0, 6.0) == pytest.approx(4.0)
    assert focus_depth(1.0, 100.0) == pytest.approx(1.0 / (0.25 / 1.0 + 0.75 / 100.0))
    for near, far in ((0.0, 1.0), (2.0, 1.0), (-1.0, 1.0)):
        with pytest.raises(ValueError, match="near"):
            focus_depth(near, far)


def test_average_pose_of_forward_facing_cameras() -> None:
    cams = _forward_facing_cameras()
    avg = average_pose(cams.camera_to_worlds)
    _assert_rotations_valid(avg)
    assert torch.allclose(avg[:, :3], torch.eye(3), atol=ATOL)
    assert torch.allclose(avg[:, 3], cams.centers.mean(dim=0), atol=ATOL)


def test_spiral_stays_forward_within_the_radii_and_looks_at_the_focus() -> None:
    cams = _forward_facing_cameras()
    near, far = 1.0, 10.0
    path = spiral_path(cams, 12, llff_focus(cams, near, far))
    assert len(path) == 12 and (path.width, path.height) == (64, 48)
    assert torch.allclose(path.fx, torch.full((12,), 40.0)) and torch.allclose(path.cx, torch.full((12,), 32.0))
    _assert_rotations_valid(path.camera_to_worlds)
    avg = average_pose(cams.camera_to_worlds)
    views = _viewing_direction(path.camera_to_worlds)
    assert (views @ -avg[:, 2]).min() > 0.9, "every frame looks roughly along the average viewing axis"
    radii = torch.quantile((cams.centers - avg[:, 3]).abs(), 0.9, dim=0)
    local = (path.centers - avg[:, 3]) @ avg[:, :3]
    assert (local.abs() <= radii + ATOL).all(), "the path stays inside the cameras' spread"
    assert local[:, 0].abs().max() > 0.5 * radii[0], "and actually moves"
    focus = avg[:, 3] - focus_depth(near, far) * avg[:, 2]
    assert torch.allclose(views, _unit(focus - path.centers), atol=ATOL)
    # LLFF's path (2 turns, zrate 0.5) passes its start again halfway, so only consecutive frames must differ
    assert (path.centers.roll(-1, dims=0) - path.centers).norm(dim=-1).min() > 1e-3


def test_spiral_radius_scale_and_rotations() -> None:
    cams = _forward_facing_cameras()
    avg = average_pose(cams.camera_to_worlds)
    focus = llff_focus(cams, 1.0, 10.0)
    base = (spiral_path(cams, 8, focus).centers - avg[:, 3]).norm(dim=-1)
    half = (spiral_path(cams, 8, focus, radius_scale=0.5).centers - avg[:, 3]).norm(dim=-1)
    assert torch.allclose(half, 0.5 * base, atol=ATOL)
    still = spiral_path(cams, 4, focus, radius_scale=0.0)
    assert torch.allclose(still.centers, avg[:, 3].expand(4, 3), atol=ATOL)


def test_spiral_on_a_360_ring_of_cameras_is_valid() -> None:
    """Blender-style cameras facing every way: the spiral degrades gracefully (valid, finite poses)."""
    ring = orbit_path((0.0, 0.0, 0.0), 4.0, 30.0, 6, 100.0, 100.0, 50, 50)
    path = spiral_path(ring, 5, llff_focus(ring, 2.0, 6.0))
    assert torch.isfinite(path.camera_to_worlds).all()
    _assert_rotations_valid(path.camera_to_worlds)
    flat = orbit_path((0.0, 0.0, 0.0), 4.0, 0.0, 4, 100.0, 100.0, 50, 50)  # viewing axes sum to zero
    _assert_rotations_valid(spiral_path(flat, 3, llff_focus(flat, 2.0, 6.0)).camera_to_worlds)


def test_spiral_looks_at_the_scene_centre_it_is_given() -> None:
    """An object capture's spiral aims at the object (the scene's centre), not at a depth in front of the cameras."""
    arc = _arc_capture(span_deg=100.0, n=6)
    centre = torch.tensor([0.2, -0.1, 0.3])
    path = spiral_path(arc, 9, centre)
    _assert_rotations_valid(path.camera_to_worlds)
    assert torch.allclose(_viewing_direction(path.camera_to_worlds), _unit(centre - path.centers), atol=ATOL)
    with pytest.raises(ValueError, match="target"):
        spiral_path(arc, 3, average_pose(arc.camera_to_worlds)[:, 3])


def test_orbit_from_cameras_circles_the_scene_centre_about_its_up_axis() -> None:
    centre = torch.tensor([1.0, 2.0, -0.5])
    source = orbit_path(centre, 3.0, 20.0, 7, 50.0, 50.0, 32, 32)
    cams = orbit_from_cameras(source, 5, center=centre)
    offsets = cams.centers - centre
    assert torch.allclose(offsets.norm(dim=-1), torch.full((5,), 3.0), atol=1e-4)
    assert torch.allclose(offsets[:, 2], torch.full((5,), 3.0 * math.sin(math.radians(20.0))), atol=1e-4)
    assert torch.allclose(_viewing_direction(cams.camera_to_worlds), _unit(-offsets), atol=ATOL)


# -- the scene's up, the captured range and the arc -----------------------------------------------------------------
def _arc_capture(span_deg: float, n: int, centre=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0), start_deg: float = 30.0):
    """``n`` cameras looking at ``centre`` from azimuths spread over ``span_deg`` (a partial-arc phone capture), at
    uneven heights and distances; azimuth 0 is +x when ``up`` is +z."""
    c, up_t = torch.tensor(centre), _unit(torch.tensor(up))
    e1 = torch.tensor([1.0, 0.0, 0.0]) if abs(float(up_t[0])) < 0.9 else torch.tensor([0.0, 1.0, 0.0])
    e1 = _unit(e1 - (e1 @ up_t) * up_t)
    e2 = torch.linalg.cross(up_t, e1)
    poses = []
    for k in range(n):
        angle = math.radians(start_deg + span_deg * k / (n - 1))
        eye = c + (2.0 + 0.3 * (k % 2)) * (math.cos(angle) * e1 + math.sin(angle) * e2) + (0.4 + 0.1 * k) * up_t
        poses.append(look_at(eye, c, up_t))
    full = torch.full((n,), 60.0)
    return Cameras(torch.stack(poses), full, full, torch.full((n,), 20.0), torch.full((n,), 15.0), 40, 30)


def test_scene_up_snaps_to_the_nearest_axis_only_when_close() -> None:
    z_up = _arc_capture(100.0, 5)
    assert torch.equal(scene_up(z_up.camera_to_worlds), torch.tensor([0.0, 0.0, 1.0]))
    y_up = _arc_capture(100.0, 5, up=(0.0, 1.0, 0.0))
    assert torch.equal(scene_up(y_up.camera_to_worlds), torch.tensor([0.0, 1.0, 0.0]))
    tilted = torch.tensor([1.0, 0.0, 1.0]) / math.sqrt(2.0)  # 45° from the axes nearest it: kept as it is
    level = orbit_path((0.0, 0.0, 0.0), 2.0, 0.0, 4, 50.0, 50.0, 8, 8, up=tilted)  # each camera's up is ``tilted``
    assert torch.allclose(scene_up(level.camera_to_worlds), tilted, atol=ATOL)


@pytest.mark.parametrize(("span", "start"), [(100.0, 30.0), (60.0, 170.0), (200.0, -120.0)])
def test_captured_range_is_the_cameras_angular_span(span: float, start: float) -> None:
    cams = _arc_capture(span, 6, start_deg=start)
    got_start, got_span = captured_range(cams.centers, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    assert math.degrees(got_span) == pytest.approx(span, abs=1e-3)
    assert math.degrees(got_start) % 360 == pytest.approx(start % 360, abs=1e-3)
    assert surrounds(cams.centers, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)) == (span > 180.0)


def test_a_ring_of_cameras_surrounds_the_scene() -> None:
    ring = orbit_path((0.0, 0.0, 0.0), 4.0, 30.0, 3, 100.0, 100.0, 50, 50)
    assert surrounds(ring.centers, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    assert math.degrees(captured_range(ring.centers, (0.0, 0.0, 0.0), (0.0, 0.0, 1.0))[1]) == pytest.approx(240.0)


@pytest.mark.parametrize("up", [(0.0, 0.0, 1.0), (0.0, 1.0, 0.0)])
def test_arc_spans_exactly_the_training_cameras_range_and_looks_at_the_centre(up) -> None:
    centre = (0.3, -0.2, 0.1)
    cams = _arc_capture(100.0, 6, centre=centre, up=up)
    arc = arc_path(cams, centre, 11)
    assert len(arc) == 11 and (arc.width, arc.height) == (40, 30)
    _assert_rotations_valid(arc.camera_to_worlds)
    c = torch.tensor(centre)
    assert torch.allclose(_viewing_direction(arc.camera_to_worlds), _unit(c - arc.centers), atol=ATOL)
    theirs = captured_range(cams.centers, c, up)
    ours = captured_range(arc.centers, c, up)
    assert math.degrees(ours[1]) == pytest.approx(math.degrees(theirs[1]), abs=1e-3), "the same angular span"
    assert math.degrees(ours[1]) == pytest.approx(100.0, abs=1e-3)
    ends = azimuths(arc.centers[[0, -1]], c, up).double()
    want = torch.tensor([theirs[0], theirs[0] + theirs[1]], dtype=torch.float64)
    assert torch.allclose(
        torch.remainder(ends - want + math.pi, 2 * math.pi), torch.full((2,), math.pi, dtype=torch.float64), atol=1e-4
    )
    steps = torch.remainder(azimuths(arc.centers, c, up).diff(), 2 * math.pi)
    assert torch.allclose(steps, torch.full((10,), math.radians(10.0)), atol=1e-4), "evenly spaced, one way"
    offsets = arc.centers - c
    height = offsets @ torch.tensor(up)
    cam_height = (cams.centers - c) @ torch.tensor(up)
    assert torch.allclose(height, cam_height.mean().expand(11), atol=1e-4), "at the cameras' mean height"
    half = arc_path(cams, centre, 5, span_scale=0.5)
    assert math.degrees(captured_range(half.centers, c, up)[1]) == pytest.approx(50.0, abs=1e-3)


def test_arc_rejects_cameras_on_its_axis() -> None:
    above = Cameras(look_at((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0))[None], *[torch.ones(1)] * 4, 4, 4)
    with pytest.raises(ValueError, match="axis"):
        arc_path(above, (0.0, 0.0, 0.0), 5, up=(0.0, 0.0, 1.0))


# -- interpolate ----------------------------------------------------------------------------------------------------
def _shuffled_capture() -> tuple[Cameras, list[int]]:
    """Six cameras of a 120° arc, stored out of the order they were taken in; and that order."""
    cams = _arc_capture(120.0, 6)
    walk = [3, 0, 5, 1, 4, 2]  # storage position of the k-th camera along the arc
    stored = [walk.index(i) for i in range(6)]
    c2w = cams.camera_to_worlds[stored]
    fx = torch.linspace(50.0, 70.0, 6)[stored]
    return Cameras(c2w, fx, fx + 1.0, cams.cx, cams.cy, cams.width, cams.height), walk


def test_capture_order_walks_the_arc_from_one_end() -> None:
    cams, walk = _shuffled_capture()
    order = capture_order(cams.centers)
    assert order in (walk, walk[::-1])
    assert capture_order(cams.centers[:2]) == [0, 1]


def test_interpolate_passes_exactly_through_the_cameras_at_the_keyframes() -> None:
    cams, _ = _shuffled_capture()
    steps = 7
    path = interpolate_path(cams, steps)
    order = capture_order(cams.centers)
    assert len(path) == (len(cams) - 1) * steps + 1
    for k, i in enumerate(order):
        assert torch.equal(path.camera_to_worlds[k * steps], cams.camera_to_worlds[i])
        for got, want in ((path.fx, cams.fx), (path.fy, cams.fy), (path.cx, cams.cx), (path.cy, cams.cy)):
            assert got[k * steps] == want[i]
    _assert_rotations_valid(path.camera_to_worlds)
    moves = (path.centers.diff(dim=0)).norm(dim=-1)
    assert moves.max() < 3 * moves.mean(), "no jumps: consecutive frames move evenly"
    between = path.fx[1:steps]
    assert (between.diff() * (path.fx[steps] - path.fx[0]) > 0).all(), "intrinsics move monotonically"


def test_interpolate_rotates_by_slerp_at_constant_speed() -> None:
    a = look_at((3.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    b = look_at((0.0, 3.0, 0.0), (0.0, 0.0, 0.0))
    ones = torch.ones(2)
    cams = Cameras(torch.stack([a, b]), ones, ones, ones, ones, 4, 4)
    path = interpolate_path(cams, 4, order=False)
    _assert_rotations_valid(path.camera_to_worlds)
    views = _viewing_direction(path.camera_to_worlds)
    angles = torch.rad2deg(torch.acos((views[:-1] * views[1:]).sum(dim=-1).clamp(-1, 1)))
    assert torch.allclose(angles, torch.full((4,), 22.5), atol=1e-3), "90° in four equal turns"
    assert torch.allclose(path.camera_to_worlds[:, 2, 0], torch.zeros(5), atol=ATOL), "no roll about the way"


def test_interpolate_of_one_camera_is_that_camera() -> None:
    cams = _arc_capture(100.0, 3)
    single = Cameras(cams.camera_to_worlds[:1], cams.fx[:1], cams.fy[:1], cams.cx[:1], cams.cy[:1], 40, 30)
    path = interpolate_path(single, 5)
    assert len(path) == 1 and torch.equal(path.camera_to_worlds[0], single.camera_to_worlds[0])
    with pytest.raises(ValueError, match="steps_per_transition"):
        interpolate_path(cams, 0)


# -- resolution scale ------------------------------------------------------------------------------------------------
def test_scale_cameras_halves_sizes_and_focal_lengths() -> None:
    cams = _forward_facing_cameras()
    half = scale_cameras(cams, 0.5)
    assert (half.width, half.height) == (32, 24)
    for got, want in ((half.fx, cams.fx), (half.fy, cams.fy), (half.cx, cams.cx), (half.cy, cams.cy)):
        assert torch.allclose(got, 0.5 * want)
    assert torch.equal(half.camera_to_worlds, cams.camera_to_worlds)


def test_scale_cameras_rounds_and_keeps_the_field_of_view() -> None:
    cams = _forward_facing_cameras()  # 64 x 48
    scaled = scale_cameras(cams, 0.3)  # 19.2 -> 19, 14.4 -> 14
    assert (scaled.width, scaled.height) == (19, 14)
    assert torch.allclose(scaled.width / (2 * scaled.fx), cams.width / (2 * cams.fx))
    assert torch.allclose(scaled.height / (2 * scaled.fy), cams.height / (2 * cams.fy))
    tiny = scale_cameras(cams, 1e-4)
    assert (tiny.width, tiny.height) == (1, 1)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="resolution scale"):
            scale_cameras(cams, bad)
