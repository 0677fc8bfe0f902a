"""An object in a room, photographed over a partial arc: a phone-like capture whose answer is known exactly.

Why: a real capture shows its object in front of walls and furniture, from one side, without alpha or masks. This
scene has all of that (a textured object on a table, textured walls, floor and ceiling in every photo, cameras on
an arc at the object's height with a phone's field of view) and ground truth beside it: per-test-view depth, the
scene's and the object's analytic geometry, and samples of the object's surface for Chamfer distances.

World frame: z up, units of about a metre; the table top lies at z = -0.3 and the object stands on it near the
origin. The capture is written in the nerfstudio format (``transforms.json`` with sparse points and split lists).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import imageio.v3 as iio
import numpy as np

from fourierf_plugin.synthetic.cameras import look_at
from fourierf_plugin.synthetic.nerfstudio_capture import (
    _check_distortion,
    _intrinsics_json,
    capture_cameras,
    render_camera,
)
from fourierf_plugin.synthetic.primitives import Box, Primitive, Sphere, room_panels
from fourierf_plugin.synthetic.render import Shading, intersect_scene, shade
from fourierf_plugin.synthetic.scene import SceneSpec, save_scene
from fourierf_plugin.synthetic.surface import sample_surface
from fourierf_plugin.synthetic.textures import Texture
from fourierf_plugin.utils.colormaps import to_uint8
from fourierf_plugin.utils.errors import fail

ROOM_LOW = (-2.2, -2.0, -1.05)
ROOM_HIGH = (2.6, 2.4, 1.45)
"""The room's corners: the floor at z = -1.05, the ceiling at 1.45; off-centre, so no two walls look alike."""
TABLE_TOP_Z = -0.3
TABLE_HALF = (0.6, 0.45)
"""The table top's half extent in x and y (a 1.2 x 0.9 table, 4 cm thick, on four legs)."""
EMBED = 0.005
"""Each part of the object sinks this far into what it stands on, so faces resting on a support are buried (not part
of the object's exposed surface) rather than coincident with it."""

AIM = (0.0, 0.0, -0.12)
"""Where the cameras look: near the middle of the object's bounds and inside its largest box (by more than the hand
jitter), so every optical axis meets the object."""
DEFAULT_ARC_DEG = 110.0
DEFAULT_RADIUS = 1.0
"""Horizontal distance of the cameras from the aim point: the object fills much of each photo, the room the rest."""
DEFAULT_FOV_DEG = 65.0
"""A phone's main camera: about 65° across the longer side."""
ARC_CENTRE_DEG = -90.0
"""Azimuth (about z, from +x) of the arc's middle: the cameras stand on the -y side, looking towards +y."""
HEIGHT_ABOVE_AIM = 0.2
HEIGHT_SWAY = 0.06
"""Camera heights: ``HEIGHT_ABOVE_AIM`` above the aim point, swaying by ± ``HEIGHT_SWAY`` along the arc."""
HAND_JITTER = 0.01
"""Seeded hand-held jitter: up to this much in camera height and in each coordinate of the aim point ..."""
ROLL_JITTER_DEG = 1.0
"""... and up to this roll about the optical axis."""

POINTS_FILE = "points.ply"
OBJECT_FILE = "object.json"
OBJECT_SURFACE_FILE = "object_surface.ply"
DEPTH_DIR = "depth"


@dataclass(frozen=True)
class RoomScene:
    """The room scene: every primitive in ``spec``, and which of them make up the object, the table and the room."""

    spec: SceneSpec
    object_indices: tuple[int, ...]
    table_indices: tuple[int, ...]
    room_indices: tuple[int, ...]

    @property
    def object_spec(self) -> SceneSpec:
        """The object alone (what an exported mesh of the object's box is scored against)."""
        return SceneSpec(tuple(self.spec.primitives[i] for i in self.object_indices))

    @property
    def table_top(self) -> Primitive:
        return self.spec.primitives[self.table_indices[0]]

    def object_bounds(self) -> np.ndarray:
        """[2, 3] (min, max) of the object's primitives."""
        return np.stack(self.object_spec.bounds())

    def aim_point(self) -> np.ndarray:
        """Where the cameras look (:data:`AIM`)."""
        return np.asarray(AIM, dtype=np.float64)


def _rgb(*values: float) -> tuple[float, float, float]:
    return (values[0], values[1], values[2])


def _standing_box(xy: tuple[float, float], half_xy: tuple[float, float], low: float, high: float, tex: Texture) -> Box:
    return Box((xy[0], xy[1], (low + high) / 2), (half_xy[0], half_xy[1], (high - low) / 2), tex.colors[0], tex)


def room_scene() -> RoomScene:
    """A textured object (two boxes stacked, two spheres) on a wooden table in a room with textured walls."""
    top = TABLE_TOP_Z
    checker = Texture("checker", (_rgb(0.92, 0.86, 0.7), _rgb(0.15, 0.25, 0.6)), 0.05)
    beach = Texture("stripes", (_rgb(0.85, 0.2, 0.15), _rgb(0.95, 0.93, 0.88), _rgb(0.2, 0.55, 0.3)), 0.04)
    tiles = Texture("tiles", (_rgb(0.95, 0.8, 0.2), _rgb(0.3, 0.7, 0.35), _rgb(0.9, 0.45, 0.15)), 0.03, seed=1)
    moss = Texture("noise", (_rgb(0.1, 0.3, 0.15), _rgb(0.45, 0.7, 0.3), _rgb(0.85, 0.9, 0.5)), 0.04, seed=2)
    box_top = 0.02
    obj: list[Primitive] = [
        _standing_box((-0.08, 0.08), (0.14, 0.12), top - EMBED, box_top, checker),
        _standing_box((-0.06, 0.08), (0.06, 0.06), box_top - EMBED, 0.1, tiles),
        Sphere((0.2, -0.02, top + 0.13 - EMBED), 0.13, beach.colors[0], beach),
        Sphere((-0.12, -0.16, top + 0.08 - EMBED), 0.08, moss.colors[1], moss),
    ]
    wood = Texture("stripes", (_rgb(0.55, 0.35, 0.2), _rgb(0.62, 0.42, 0.25), _rgb(0.48, 0.3, 0.17)), 0.03, 90.0)
    hx, hy = TABLE_HALF
    leg_half_height = (top - 0.04 - ROOM_LOW[2]) / 2
    table: list[Primitive] = [Box((0.0, 0.0, top - 0.02), (hx, hy, 0.02), wood.colors[0], wood)]
    for sx in (-1, 1):
        for sy in (-1, 1):
            centre = (sx * (hx - 0.05), sy * (hy - 0.05), ROOM_LOW[2] + leg_half_height)
            table.append(Box(centre, (0.03, 0.03, leg_half_height), _rgb(0.3, 0.2, 0.12)))
    planks = Texture("stripes", (_rgb(0.7, 0.6, 0.45), _rgb(0.6, 0.5, 0.38), _rgb(0.76, 0.66, 0.52)), 0.15)
    ceiling = Texture("noise", (_rgb(0.8, 0.8, 0.78), _rgb(0.95, 0.95, 0.93)), 0.4, seed=3)
    walls = (
        Texture("tiles", (_rgb(0.6, 0.75, 0.85), _rgb(0.85, 0.7, 0.6), _rgb(0.7, 0.8, 0.6), _rgb(0.9, 0.9, 0.8)), 0.3),
        Texture("stripes", (_rgb(0.85, 0.75, 0.55), _rgb(0.6, 0.4, 0.35)), 0.12),
        Texture("noise", (_rgb(0.35, 0.4, 0.55), _rgb(0.75, 0.75, 0.8)), 0.5, seed=4),
        Texture("tiles", (_rgb(0.3, 0.45, 0.6), _rgb(0.9, 0.85, 0.7), _rgb(0.75, 0.3, 0.3), _rgb(0.5, 0.6, 0.4)), 0.25),
    )
    room = list(room_panels(ROOM_LOW, ROOM_HIGH, planks, ceiling, walls))
    spec = SceneSpec(tuple(obj + table + room), light_direction=(0.35, -0.5, 0.8), ambient=0.45)
    n_obj, n_table = len(obj), len(table)
    return RoomScene(
        spec,
        tuple(range(n_obj)),
        tuple(range(n_obj, n_obj + n_table)),
        tuple(range(n_obj + n_table, len(spec.primitives))),
    )


@dataclass(frozen=True)
class ArcCameras:
    """Cameras on the arc in capture order, and which are training candidates and which held-out test views."""

    c2ws: np.ndarray  # [N, 4, 4] OpenGL camera-to-worlds
    arc_position: np.ndarray  # [N] in [0, 1]: 0 and 1 are the arc's ends
    azimuth_deg: np.ndarray  # [N] about the aim point, from +x
    is_test: np.ndarray  # [N] bool


def arc_cameras(aim: np.ndarray, n_train: int, n_test: int, arc_deg: float, radius: float, seed: int = 0) -> ArcCameras:
    """``n_train`` cameras evenly spaced over ``arc_deg`` of azimuth (both ends included) and ``n_test`` halfway
    between two neighbours, the gaps spread evenly along the arc; all at ``radius`` from the aim point horizontally,
    a little above it with a gentle sway in height, looking at it, with seeded hand-held jitter."""
    train_s = np.linspace(0.0, 1.0, n_train)
    gaps = ((np.arange(n_test) + 0.5) * (n_train - 1) / n_test).astype(int)
    test_s = (gaps + 0.5) / (n_train - 1)
    s = np.concatenate([train_s, test_s])
    is_test = np.concatenate([np.zeros(n_train, bool), np.ones(n_test, bool)])
    order = np.argsort(s, kind="stable")
    s, is_test = s[order], is_test[order]
    rng = np.random.default_rng(seed)
    jitter = rng.uniform(-1.0, 1.0, size=(len(s), 5)) * np.array([HAND_JITTER] * 4 + [ROLL_JITTER_DEG])
    azimuth = ARC_CENTRE_DEG + arc_deg * (s - 0.5)
    phi = np.radians(azimuth)
    heights = aim[2] + HEIGHT_ABOVE_AIM + HEIGHT_SWAY * np.sin(3.0 * math.pi * s) + jitter[:, 0]
    c2ws = []
    for i in range(len(s)):
        eye = np.array([aim[0] + radius * math.cos(phi[i]), aim[1] + radius * math.sin(phi[i]), heights[i]])
        c2w = look_at(eye, tuple(aim + jitter[i, 1:4]))
        roll = math.radians(jitter[i, 4])
        turn = np.array([[math.cos(roll), -math.sin(roll), 0], [math.sin(roll), math.cos(roll), 0], [0, 0, 1]])
        c2w[:3, :3] = c2w[:3, :3] @ turn  # about the optical axis
        c2ws.append(c2w)
    return ArcCameras(np.stack(c2ws), s, azimuth, is_test)


def _check_room_options(
    width: int, height: int, n_train: int, n_test: int, fov: float, radius: float, arc: float, spp: int
) -> None:
    if width < 8 or height < 8:
        fail(f"image size {width}x{height} is too small", "use --width and --height of at least 8 pixels")
    if n_train < 2:
        fail(f"--n-train must be >= 2 for the room, got {n_train}", "the arc needs a camera at each end")
    if not 1 <= n_test <= n_train - 1:
        fail(
            f"--n-test must be between 1 and n_train - 1 = {n_train - 1}, got {n_test}",
            "each test view sits in its own gap between two training views",
        )
    if not 0 < fov < math.pi:
        fail(f"--camera-angle-x must lie in (0, pi) radians, got {fov}", f"the room's default is {DEFAULT_FOV_DEG}°")
    if not 0 < arc < 360:
        fail(f"--arc-deg must lie in (0, 360), got {arc}", f"the default is {DEFAULT_ARC_DEG:g} (a partial arc)")
    if not radius > 0:
        fail(f"--radius must be > 0, got {radius}", f"the room's default is {DEFAULT_RADIUS:g}")
    if not 1 <= spp <= 16:
        fail(f"--samples-per-pixel must be in 1..16, got {spp}", "use 2-4 for antialiased edges and textures")


def _check_camera_places(c2ws: np.ndarray) -> None:
    """Every camera inside the room (10 cm from its walls) and beside the table, not over it."""
    eyes = c2ws[:, :3, 3]
    inside = ((eyes > np.asarray(ROOM_LOW) + 0.1) & (eyes < np.asarray(ROOM_HIGH) - 0.1)).all(axis=1)
    over_table = (np.abs(eyes[:, :2]) < np.asarray(TABLE_HALF) + 0.1).all(axis=1)
    if not (inside & ~over_table).all():
        fail(
            "--radius puts cameras over the table or outside the room",
            f"use a radius between about {np.hypot(*TABLE_HALF) + 0.1:.1f} and 1.8 (the default is {DEFAULT_RADIUS:g})",
        )


def _sparse_points(
    spec: SceneSpec,
    object_indices: tuple[int, ...],
    c2ws: np.ndarray,
    fx: float,
    width: int,
    height: int,
    n_points: int,
    object_share: float,
    shading: Shading,
    seed: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Points [n, 3] and uint8 colours [n, 3] where random pixel rays of the given cameras first hit a surface:
    ``object_share`` of them on the object, the rest wherever the rays land (table, walls, floor)."""
    rng = np.random.default_rng(seed)
    want_object = round(n_points * object_share)
    want_rest = n_points - want_object
    on_object: list[np.ndarray] = []
    rest: list[np.ndarray] = []
    got_object = got_rest = 0
    for _ in range(100):
        if got_object >= want_object and got_rest >= want_rest:
            break
        m = 4 * n_points
        cam = rng.integers(0, len(c2ws), size=m)
        u, v = rng.uniform(0, width, size=m), rng.uniform(0, height, size=m)
        local = np.stack([(u - width / 2) / fx, -(v - height / 2) / fx, -np.ones(m)], axis=1)
        dirs = np.einsum("nij,nj->ni", c2ws[cam, :3, :3], local)
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        origins = c2ws[cam, :3, 3]
        hits = intersect_scene(spec, origins, dirs)
        colors = shade(spec, hits, dirs, shading)
        rows = np.concatenate([hits.point, colors], axis=1)[hits.hit]
        mine = np.isin(hits.index[hits.hit], object_indices)
        on_object.append(rows[mine])
        rest.append(rows[~mine])
        got_object += int(mine.sum())
        got_rest += int((~mine).sum())
    if got_object < want_object or got_rest < want_rest:
        fail("the cameras see too little of the scene to place its sparse points", "check --radius and --arc-deg")
    rows = np.concatenate([np.concatenate(on_object)[:want_object], np.concatenate(rest)[:want_rest]])
    rows = rows[rng.permutation(len(rows))]
    return rows[:, :3], np.round(np.clip(rows[:, 3:], 0, 1) * 255).astype(np.uint8)


def write_room_capture(
    out_dir: Path,
    width: int = 160,
    height: int = 120,
    n_train: int = 30,
    n_test: int = 8,
    seed: int = 0,
    camera_angle_x: float = math.radians(DEFAULT_FOV_DEG),
    radius: float = DEFAULT_RADIUS,
    arc_deg: float = DEFAULT_ARC_DEG,
    shading: Shading = "lambert",
    samples_per_pixel: int = 3,
    n_points: int = 4000,
    object_share: float = 0.4,
    object_surface_points: int = 20000,
    distortion: dict[str, float] | None = None,
) -> Path:
    """Render the room scene as a nerfstudio capture in ``out_dir`` and return it.

    Layout: ``images/frame_<i>.png`` (8-bit RGB, frames in arc order), ``transforms.json`` (shared intrinsics,
    ``train_filenames`` and ``test_filenames``, ``ply_file_path``), ``points.ply`` (sparse points with colours, on
    the surfaces the training cameras see), ``depth/frame_<i>.npy`` for the test views, ``geometry.json`` (the whole
    scene, plus the object's, table's and room's primitives, the object's bounds, the arc and the depth convention),
    ``object.json`` (the object alone, loadable with ``load_scene``) and ``object_surface.ply`` (points uniform over
    the object's exposed surface). Stale PNGs and depth files from an earlier generation are removed.
    """
    _check_room_options(width, height, n_train, n_test, camera_angle_x, radius, arc_deg, samples_per_pixel)
    if shading not in ("none", "lambert"):
        fail(f"shading must be 'none' or 'lambert', got {shading!r}", "pick one of: none, lambert")
    if n_points < 1 or not 0 <= object_share <= 1 or object_surface_points < 1:
        fail("the point counts must be >= 1 and the object share in [0, 1]", "use the defaults")
    lens = _check_distortion(distortion)
    scene = room_scene()
    aim = scene.aim_point()
    arc = arc_cameras(aim, n_train, n_test, arc_deg, radius, seed)
    _check_camera_places(arc.c2ws)
    cameras = capture_cameras(arc.c2ws, width, height, camera_angle_x, lens)
    try:
        cameras.generate_rays(0)
    except ValueError as err:
        fail(f"the distortion {lens} cannot be undistorted over a {width}x{height} image: {err}", "use a milder lens")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        fail(f"output path {out} is a file", "choose a folder path for the capture")
    images, depths = out / "images", out / DEPTH_DIR
    images.mkdir(parents=True, exist_ok=True)
    depths.mkdir(exist_ok=True)
    for stale in [*images.glob("*.png"), *depths.glob("*.npy")]:
        stale.unlink()

    frames, names = [], {"train": [], "test": []}
    for i, c2w in enumerate(arc.c2ws):
        name = f"images/frame_{i:05d}.png"
        rgba = render_camera(scene.spec, cameras, i, shading, samples_per_pixel)
        if (rgba[..., 3] < 1).any():
            fail("a camera sees past the room's walls", "keep the cameras inside the room (check --radius)")
        iio.imwrite(out / name, to_uint8(rgba[..., :3]))
        frames.append({"file_path": name, "transform_matrix": c2w.tolist()})
        split = "test" if arc.is_test[i] else "train"
        names[split].append(name)
        if split == "test":
            origins, dirs = (t.double().numpy() for t in cameras.generate_rays(i))
            depth = intersect_scene(scene.spec, origins, dirs).t.reshape(height, width)
            np.save(depths / f"frame_{i:05d}.npy", depth.astype(np.float32))

    train_c2ws = arc.c2ws[~arc.is_test]
    fx = float(cameras.fx[0])
    points, colors = _sparse_points(
        scene.spec, scene.object_indices, train_c2ws, fx, width, height, n_points, object_share, shading, seed
    )
    write_point_cloud(points, out / POINTS_FILE, colors)
    surface = sample_surface(scene.object_spec, object_surface_points, seed=seed, occluders=(scene.table_top,))
    write_point_cloud(surface, out / OBJECT_SURFACE_FILE)

    meta = _intrinsics_json(cameras, lens) | {"frames": frames, "ply_file_path": POINTS_FILE}
    meta |= {f"{s}_filenames": n for s, n in names.items()}
    (out / "transforms.json").write_text(json.dumps(meta, indent=2) + "\n", encoding="utf-8")
    object_bounds = scene.object_bounds()
    save_scene(scene.object_spec, out / OBJECT_FILE, extra={"bounds": object_bounds.tolist()})
    extra = _geometry_extra(scene, arc, aim, radius, arc_deg, names, object_surface_points)
    extra["render"] = {
        "format": "nerfstudio",
        "kind": "room",
        "width": width,
        "height": height,
        "seed": seed,
        "camera_angle_x": camera_angle_x,
        "shading": shading,
        "samples_per_pixel": samples_per_pixel,
        "camera_model": cameras.camera_model,
        "distortion": lens,
        "views": {s: len(n) for s, n in names.items()},
        "sparse_points": {"file": POINTS_FILE, "count": len(points), "object_share": object_share},
    }
    save_scene(scene.spec, out / "geometry.json", extra=extra)
    return out


def write_point_cloud(points: np.ndarray, path: Path, colors: np.ndarray | None = None) -> Path:
    """A binary PLY of vertices (float64 x y z, with uint8 red green blue when ``colors`` [N, 3] is given)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    if colors is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    rows = np.empty(len(points), dtype=fields)
    rows["x"], rows["y"], rows["z"] = points.T
    if colors is not None:
        rows["red"], rows["green"], rows["blue"] = np.asarray(colors, dtype=np.uint8).reshape(-1, 3).T
    names = {"<f8": "double", "u1": "uchar"}
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(points)}"]
    header += [f"property {names[kind]} {name}" for name, kind in fields] + ["end_header"]
    path.write_bytes(("\n".join(header) + "\n").encode("ascii") + rows.tobytes())
    return path


def _geometry_extra(
    scene: RoomScene,
    arc: ArcCameras,
    aim: np.ndarray,
    radius: float,
    arc_deg: float,
    names: dict[str, list[str]],
    surface_points: int,
) -> dict[str, Any]:
    heights = arc.c2ws[:, 2, 3]
    return {
        "object": {
            "primitives": list(scene.object_indices),
            "bounds": scene.object_bounds().tolist(),
            "scene_file": OBJECT_FILE,
            "surface_file": OBJECT_SURFACE_FILE,
            "surface_points": surface_points,
            "buried_by": [scene.table_indices[0]],
        },
        "table": {"primitives": list(scene.table_indices)},
        "room": {"primitives": list(scene.room_indices), "bounds": [list(ROOM_LOW), list(ROOM_HIGH)]},
        "arc": {
            "aim": aim.tolist(),
            "radius": radius,
            "span_deg": arc_deg,
            "azimuth_deg": [float(arc.azimuth_deg.min()), float(arc.azimuth_deg.max())],
            "height": [float(heights.min()), float(heights.max())],
        },
        "depth": {
            "folder": DEPTH_DIR,
            "files": [f"{DEPTH_DIR}/{Path(n).stem}.npy" for n in names["test"]],
            "quantity": "distance along the unit ray from the camera centre to the first surface (not z-depth)",
            "units": "transforms.json world units",
            "dtype": "float32 [h, w], one ray per pixel centre",
        },
    }
