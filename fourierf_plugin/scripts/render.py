"""``fourierf-render [auto|interpolate|arc|orbit|spiral|dataset|camera-path] --load-config RUN/config.json``: novel
views as PNG frames and animations.

``interpolate`` moves through the training cameras, ``arc`` sweeps the angular range they cover about the scene's
centre, ``orbit`` is a Blender-style turntable and ``spiral`` the LLFF spiral, both aimed at the scene's centre;
``dataset`` renders a split's own cameras (named after the views), ``camera-path`` a camera_path.json (nerfstudio's
format, as the viewer saves it). ``auto`` (also what runs when no mode is named)
picks an orbit when the training cameras surround the scene and the interpolated path otherwise, so a partial capture
is only shown from where it was photographed. Every requested output (rgb, depth coloured by a perceptual colormap,
accumulation) is written as ``DIR/<output>/<frame>.png`` plus ``DIR/<output>.gif`` (and ``.mp4`` when the optional
imageio-ffmpeg plugin is installed). Nothing already in a named ``--output-dir`` is replaced without
``--overwrite``, outputs are written beside their final names first and renamed into place when complete, and a
folder another live render is writing is refused (``render_lock``).
"""

from __future__ import annotations

import dataclasses
import math
import os
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import imageio.v3 as iio
import numpy as np
import tyro
from rich.markup import escape
from torch import Tensor

from fourierf_plugin.cameras.camera_path import read_camera_path
from fourierf_plugin.cameras.camera_paths import (
    arc_path,
    captured_range,
    interpolate_path,
    llff_focus,
    orbit_from_cameras,
    scale_cameras,
    scene_up,
    spiral_path,
    surrounds,
)
from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.data.datamanager import camera_rays
from fourierf_plugin.data.dataparser_base import DataparserOutputs
from fourierf_plugin.engine.loading import LoadedRun
from fourierf_plugin.engine.run_dir import RunLock, hold_lock, unique_safe_name
from fourierf_plugin.scripts.cli import run_cli, strip_verbose
from fourierf_plugin.scripts.run_options import RunOptions
from fourierf_plugin.utils.colormaps import Colormap, colorize_accumulation, colorize_depth, depth_range, to_uint8
from fourierf_plugin.utils.console import TaskProgress, format_duration, get_console, warn
from fourierf_plugin.utils.errors import UserError, fail
from fourierf_plugin.utils.files import run_renders_dir
from fourierf_plugin.utils.interrupt import note_kept, stop_cleanly
from fourierf_plugin.utils.memory import available_memory, check_fits
from fourierf_plugin.utils.new_dirs import NewDirs
from fourierf_plugin.utils.os_errors import user_error_for

OUTPUT_NAMES = ("rgb", "depth", "accumulation")


@dataclass
class RenderConfig(RunOptions):
    """Options shared by every render mode."""

    output_dir: Path | None = None
    """Where to write frames and animations (default: RUN/renders/<mode>-step<N>/, or a fresh -1, -2 ... beside it
    when that exists)."""
    overwrite: bool = False
    """Replace outputs already in --output-dir (the <output>/ folders and animations of the same names)."""
    outputs: tuple[str, ...] = OUTPUT_NAMES
    """Which images to write: any of rgb, depth, accumulation."""
    resolution_scale: float = 1.0
    """Image size relative to the dataset's cameras (0.5 renders at half width and height, 4x faster)."""
    fps: float = 24.0
    """Frame rate of the animations."""
    no_video: bool = False
    """Write only the PNG frames, no GIF/MP4."""
    depth_near: float | None = None
    """Depth shown at the colormap's low end (default: the 1st percentile of the first frame's opaque pixels)."""
    depth_far: float | None = None
    """Depth shown at the colormap's high end (default: the 99th percentile of the first frame's opaque pixels)."""
    colormap: Colormap = "turbo"
    """Colormap of the depth images."""

    @property
    def mode(self) -> str:
        return "render"


@dataclass
class RenderDataset(RenderConfig):
    """Render the cameras of a dataset split; frames are named after the views."""

    split: Literal["test", "train", "val"] = "test"
    """Which split's cameras to render."""

    @property
    def mode(self) -> str:
        return f"dataset-{self.split}"


@dataclass
class RenderInterpolate(RenderConfig):
    """A path through the training cameras, in the order they were taken (nerfstudio's ``interpolate``)."""

    steps_per_transition: int = 10
    """Frames from one camera to the next (the cameras themselves are frames 0, k, 2k, ...)."""
    order_poses: bool = True
    """Sort the cameras along the capture first (the shortest nearest-neighbour path); else the split's order."""
    split: Literal["train", "val", "test"] = "train"
    """Whose cameras the path runs through."""

    @property
    def mode(self) -> str:
        return "interpolate"


@dataclass
class RenderArc(RenderConfig):
    """An arc about the scene's centre over the angular range the training cameras cover, at their mean distance
    and height (a capture over part of a circle has seen nothing of the rest)."""

    n_frames: int = 60
    """Frames from one end of the arc to the other."""
    span_scale: float = 1.0
    """Shrink (or widen) the arc about its middle: 1 sweeps exactly the cameras' range."""

    @property
    def mode(self) -> str:
        return "arc"


@dataclass
class RenderAuto(RenderConfig):
    """An orbit when the training cameras surround the scene, else the path through them (interpolate)."""

    n_frames: int = 60
    """Frames of an orbit."""
    steps_per_transition: int = 10
    """Frames between consecutive cameras of an interpolated path."""

    @property
    def mode(self) -> str:
        return "auto"


@dataclass
class RenderOrbit(RenderConfig):
    """A turntable about the scene's up axis through its centre, at the training cameras' mean distance from it."""

    n_frames: int = 60
    """Frames in one full turn."""
    elevation_deg: float | None = None
    """Camera elevation above the scene's ground plane in degrees (default: the training cameras' mean elevation)."""

    @property
    def mode(self) -> str:
        return "orbit"


@dataclass
class RenderSpiral(RenderConfig):
    """The LLFF spiral around the training cameras' average pose, looking at the scene's centre (forward-facing
    scenes; works for any scene)."""

    n_frames: int = 60
    """Frames along the whole spiral."""
    n_rotations: float = 2.0
    """Turns of the spiral."""
    zrate: float = 0.5
    """Forward/backward oscillations per turn."""
    radius_scale: float = 1.0
    """Scale of the spiral's radii (from the 90th percentile of the training cameras' spread)."""
    near: float | None = None
    """With --far: look at LLFF's focus depth between these bounds in front of the average camera instead of the
    scene's centre (world units; forward-facing scenes default to 0.9 x the nearest content depth)."""
    far: float | None = None
    """With --near: see --near (forward-facing scenes default to 5 x the farthest content depth)."""

    @property
    def mode(self) -> str:
        return "spiral"


@dataclass
class RenderCameraPath(RenderConfig):
    """A camera path saved by the viewer's render button, or by nerfstudio's viewer (its camera_path.json format):
    its frames, image size and frame rate."""

    camera_path_filename: Path | None = None
    """The camera_path.json to render (the viewer writes them to RUN/camera_paths/)."""
    fps: float | None = None  # type: ignore[assignment]
    """Frame rate of the animations (default: the path's own)."""

    @property
    def mode(self) -> str:
        return "camera-path"


_MISSING = tyro.MISSING
if TYPE_CHECKING:
    RenderCommand = RenderConfig
else:
    RenderCommand = tyro.extras.subcommand_type_from_defaults(
        {
            "auto": RenderAuto(load_config=_MISSING),
            "interpolate": RenderInterpolate(load_config=_MISSING),
            "arc": RenderArc(load_config=_MISSING),
            "orbit": RenderOrbit(load_config=_MISSING),
            "spiral": RenderSpiral(load_config=_MISSING),
            "dataset": RenderDataset(load_config=_MISSING),
            "camera-path": RenderCameraPath(load_config=_MISSING, camera_path_filename=_MISSING),
        },
        {
            "auto": "The path that fits the capture: orbit when the cameras surround it, else interpolate "
            "(the default when no mode is named).",
            "interpolate": "Move through the training cameras (nerfstudio's interpolate).",
            "arc": "Sweep the angular range the training cameras cover about the scene's centre.",
            "orbit": "Render a turntable around the scene's centre (captures all around an object).",
            "spiral": "Render the LLFF spiral, aimed at the scene's centre (forward-facing scenes).",
            "dataset": "Render the cameras of a dataset split (test by default).",
            "camera-path": "Render a camera_path.json saved by the viewer (nerfstudio's format).",
        },
        prefix_names=False,
        sort_subcommands=False,
    )


@dataclass
class RenderResult:
    output_dir: Path
    frames: dict[str, list[Path]] = field(default_factory=dict)
    animations: list[Path] = field(default_factory=list)
    seconds_per_frame: float = 0.0
    width: int = 0
    height: int = 0
    step: int = 0


# -- validation -----------------------------------------------------------------------------------------------------
def _outputs(cfg: RenderConfig) -> list[str]:
    """The requested outputs in order, duplicates dropped; unknown names are a UserError."""
    unknown = [name for name in cfg.outputs if name not in OUTPUT_NAMES]
    if unknown:
        fail(f"unknown --outputs {' '.join(unknown)}", f"choose from {' '.join(OUTPUT_NAMES)}")
    chosen = list(dict.fromkeys(cfg.outputs))
    if not chosen:
        fail("--outputs is empty", f"name at least one of {' '.join(OUTPUT_NAMES)}")
    return chosen


MAX_FRAMES = 100_000
"""The most frames one render may ask for (over an hour of video at 24 fps): a count beyond it is a typo, and its
camera path alone would fill the memory before the first frame."""


def validate(cfg: RenderConfig) -> list[str]:
    """Every check that needs no trained run, so a typo fails in a second instead of after loading the model."""
    outputs = _outputs(cfg)
    if isinstance(cfg, RenderCameraPath):
        if cfg.camera_path_filename is None:
            fail("camera-path needs --camera-path-filename", "pass the camera_path.json the viewer wrote")
        if cfg.fps is None:
            cfg.fps = read_camera_path(cfg.camera_path_filename, MAX_FRAMES).fps  # the path's own frame rate
    if not (math.isfinite(cfg.resolution_scale) and cfg.resolution_scale > 0):
        fail(f"--resolution-scale must be > 0, got {cfg.resolution_scale}", "use e.g. 0.5 for half size")
    if not (math.isfinite(cfg.fps) and cfg.fps > 0):
        fail(f"--fps must be > 0, got {cfg.fps}", "use e.g. 24")
    n_frames = getattr(cfg, "n_frames", 1)
    if not 1 <= n_frames <= MAX_FRAMES:
        fail(f"--n-frames must be in 1..{MAX_FRAMES}, got {n_frames}", "use e.g. 60 (2.5 s at 24 fps)")
    steps = getattr(cfg, "steps_per_transition", 1)
    if not 1 <= steps <= MAX_FRAMES:
        fail(f"--steps-per-transition must be in 1..{MAX_FRAMES}, got {steps}", "use e.g. 10")
    if isinstance(cfg, RenderArc) and not (math.isfinite(cfg.span_scale) and cfg.span_scale >= 0):
        fail(f"--span-scale must be >= 0, got {cfg.span_scale}", "use 1 for the cameras' own range")
    if cfg.depth_near is not None and cfg.depth_far is not None and not cfg.depth_near < cfg.depth_far:
        fail(f"need --depth-near < --depth-far, got {cfg.depth_near} and {cfg.depth_far}", "swap or fix them")
    if isinstance(cfg, RenderOrbit) and cfg.elevation_deg is not None and not -90 <= cfg.elevation_deg <= 90:
        fail(f"--elevation-deg must be within [-90, 90], got {cfg.elevation_deg}", "use e.g. 30")
    if isinstance(cfg, RenderSpiral) and not cfg.radius_scale >= 0:
        fail(f"--radius-scale must be >= 0, got {cfg.radius_scale}", "use 1 for the cameras' own spread")
    if cfg.output_dir is not None and cfg.output_dir.exists() and not cfg.output_dir.is_dir():
        fail(f"--output-dir {cfg.output_dir} is an existing file", "choose a directory path")
    if cfg.output_dir is not None and not cfg.overwrite:
        _refuse_taken(cfg.output_dir, outputs)
    if not Path(cfg.load_config).exists():
        fail(
            f"config file not found: {cfg.load_config}",
            "pass the config.json written in a run directory (outputs/<scene>/<method>/<timestamp>/config.json)",
        )
    return outputs


# -- cameras ------------------------------------------------------------------------------------------------------
def _unique_stems(names: list[str]) -> list[str]:
    """Safe file stems for view names; a name that sanitises onto an earlier one gets its index appended."""
    taken: set[str] = set()
    return [unique_safe_name(name, i, taken) for i, name in enumerate(names)]


def spiral_bounds(near: float, far: float, depth_bounds: tuple[float, float] | None) -> tuple[float, float]:
    """Near/far for the spiral's focus depth, in world units.

    An NDC scene's near/far (0, 1) are NDC units, so its parser's metric ``depth_bounds`` are used instead, widened
    as LLFF does (0.9 x the nearest, 5 x the farthest content depth); other scenes use their own near/far.
    """
    if depth_bounds is not None:
        return 0.9 * depth_bounds[0], 5.0 * depth_bounds[1]
    return near, far


def scene_target(outputs: DataparserOutputs, ray_space: str) -> Tensor:
    """The scene's centre, where orbits, arcs and spirals look: the middle of the scene box (for a capture, the box
    of its sparse points); for an NDC scene, whose box is in NDC units, LLFF's focus point in front of the average
    camera."""
    if ray_space == "ndc":
        near, far = spiral_bounds(outputs.near, outputs.far, outputs.depth_bounds)
        return llff_focus(outputs.cameras, near, far)
    return outputs.scene_box.float().mean(dim=0)


def _frame_stems(cameras: Cameras) -> list[str]:
    return [f"frame_{i:05d}" for i in range(len(cameras))]


def _path_error(mode: str, err: ValueError) -> None:
    fail(f"cannot build the {mode} path: {err}", "render another mode (e.g. dataset), or check the run's cameras")


def build_cameras(cfg: RenderConfig, run: LoadedRun) -> tuple[Cameras, list[str], str]:
    """The cameras of the chosen mode (before resolution scaling), a file stem per frame, and the mode rendered
    (``auto`` resolved)."""
    datamanager = run.pipeline.datamanager
    if isinstance(cfg, RenderCameraPath):
        assert cfg.camera_path_filename is not None  # validate() checked it
        cameras = read_camera_path(cfg.camera_path_filename, MAX_FRAMES).cameras
        return cameras, _frame_stems(cameras), cfg.mode
    if isinstance(cfg, RenderDataset):
        outputs = datamanager.parser.get_outputs(cfg.split)
        if len(outputs.cameras) == 0:
            fail(
                f"the {cfg.split} split of {datamanager.config.dataparser.data} has no views", "render another --split"
            )
        return outputs.cameras, _unique_stems(outputs.image_names), cfg.mode
    reference = datamanager.reference_outputs
    ray_space = run.pipeline.effects.ray_space
    target = scene_target(reference, ray_space)
    up = scene_up(reference.cameras.camera_to_worlds)
    console = get_console()
    if isinstance(cfg, RenderAuto):
        around = len(reference.cameras) > 1 and surrounds(reference.cameras.centers, target, up)
        if around or len(reference.cameras) == 1:
            cfg = RenderOrbit(**{**_shared(cfg), "n_frames": cfg.n_frames})
        else:
            cfg = RenderInterpolate(**{**_shared(cfg), "steps_per_transition": cfg.steps_per_transition})
        why = "surround the scene" if around else "cover part of a circle about the scene"
        if len(reference.cameras) == 1:
            why = "are a single view"
        console.print(f"auto: the training cameras {why}: rendering `{cfg.mode}`")
    try:
        if isinstance(cfg, RenderInterpolate):
            source = reference if cfg.split == "train" else datamanager.parser.get_outputs(cfg.split)
            frames = (len(source.cameras) - 1) * cfg.steps_per_transition + 1
            if frames > MAX_FRAMES:
                most = max(1, (MAX_FRAMES - 1) // max(1, len(source.cameras) - 1))
                fail(
                    f"--steps-per-transition {cfg.steps_per_transition} through {len(source.cameras)} cameras makes "
                    f"{frames} frames, over the {MAX_FRAMES} one render may hold",
                    f"pass at most --steps-per-transition {most}",
                )
            cameras = interpolate_path(source.cameras, cfg.steps_per_transition, cfg.order_poses)
        elif isinstance(cfg, RenderArc):
            _, span = captured_range(reference.cameras.centers, target, up)
            console.print(f"arc over the {math.degrees(span) * cfg.span_scale:.0f}° the training cameras cover")
            cameras = arc_path(reference.cameras, target, cfg.n_frames, up, cfg.span_scale)
        elif isinstance(cfg, RenderOrbit):
            if ray_space == "ndc":
                warn("this scene uses NDC rays (forward-facing): an orbit leaves the captured frustum; try `spiral`")
            elif len(reference.cameras) > 1 and not surrounds(reference.cameras.centers, target, up):
                span = math.degrees(captured_range(reference.cameras.centers, target, up)[1])
                warn(
                    f"the training cameras cover {span:.0f}° about the scene's centre: most of an orbit shows what "
                    "no photo saw; try `arc` or `interpolate`"
                )
            cameras = orbit_from_cameras(reference.cameras, cfg.n_frames, cfg.elevation_deg, target, up)
        elif isinstance(cfg, RenderSpiral):
            if cfg.near is not None or cfg.far is not None:
                near, far = spiral_bounds(reference.near, reference.far, reference.depth_bounds)
                near = near if cfg.near is None else cfg.near
                far = far if cfg.far is None else cfg.far
                try:
                    target = llff_focus(reference.cameras, near, far)
                except ValueError as err:
                    fail(f"cannot build the spiral: {err}", "pass --near and --far with 0 < near < far (scene units)")
            cameras = spiral_path(reference.cameras, cfg.n_frames, target, cfg.n_rotations, cfg.zrate, cfg.radius_scale)
        else:  # pragma: no cover - tyro only builds the modes above
            raise TypeError(f"unknown render mode {type(cfg).__name__}")
    except ValueError as err:
        _path_error(cfg.mode, err)
    return cameras, _frame_stems(cameras), cfg.mode


def _shared(cfg: RenderConfig) -> dict:
    """The options every mode shares, to hand ``auto``'s choice the user's settings."""
    return {f.name: getattr(cfg, f.name) for f in dataclasses.fields(RenderConfig)}


BYTES_PER_PIXEL = 100
"""An estimate of a frame's memory per pixel: its rays, the rendered outputs, their concatenation and the images."""


def check_frame_fits(width: int, height: int, scale: float, available: int | None = None) -> None:
    """A UserError before rendering when one frame of this size cannot fit in the memory available now."""
    free = available_memory() if available is None else available
    if free is None:
        return
    largest = scale * (free / (BYTES_PER_PIXEL * width * height)) ** 0.5
    check_fits(
        BYTES_PER_PIXEL * width * height,
        f"a {width}x{height} frame (--resolution-scale {scale:g})",
        f"use at most --resolution-scale {largest:.2g} on this machine",
        free,
    )


# -- writing ------------------------------------------------------------------------------------------------------
ANIMATION_SUFFIXES = (".gif", ".mp4")


def existing_outputs(output_dir: Path, outputs: list[str]) -> list[Path]:
    """What a render of ``outputs`` into ``output_dir`` would replace: non-empty ``<output>/`` folders and
    ``<output>.gif``/``.mp4`` files already there."""
    taken = []
    for name in outputs:
        folder = Path(output_dir) / name
        if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
            taken.append(folder)
        taken += [p for p in (Path(output_dir) / f"{name}{s}" for s in ANIMATION_SUFFIXES) if p.exists()]
    return taken


def _refuse_taken(output_dir: Path, outputs: list[str]) -> None:
    """A UserError when ``output_dir`` already holds one of ``outputs`` (replaced only with --overwrite)."""
    taken = existing_outputs(output_dir, outputs)
    if taken:
        fail(
            f"--output-dir {output_dir} already holds {', '.join(p.name for p in taken)} from an earlier render",
            "choose another --output-dir, or pass --overwrite to replace them",
        )


def _output_dir(cfg: RenderConfig, run: LoadedRun, mode: str, made: NewDirs) -> Path:
    """--output-dir, created if needed; by default a fresh RUN/renders/<mode>-step<N>[-k]/ claimed by creating it (so
    renders started together never share one), or with --overwrite that folder again. Folders made go in ``made``."""
    if cfg.output_dir is not None:
        return made.make(cfg.output_dir, "--output-dir")
    made.make(run.run_dir / "renders", "--output-dir")
    if cfg.overwrite:
        return made.make(run_renders_dir(run.run_dir, mode, run.step, overwrite=True), "--output-dir")
    claimed = run_renders_dir(run.run_dir, mode, run.step, overwrite=False, claim=True)
    made.adopt(claimed)
    return claimed


def render_lock(output: str) -> str:
    """The lock file a render holds inside its output folder while it writes ``output`` there (one per output, so
    renders of other outputs share the folder; inside, not beside: ``.`` and ``/`` have no name to put one beside)."""
    return f".fourierf-render-{output}.lock"


def lock_render_outputs(output_dir: Path, outputs: list[str]) -> list[RunLock]:
    """Take ``render_lock`` of each of ``outputs`` in ``output_dir`` for this process: an output another live render
    is writing there is a clear error naming its PID (two renders would replace each other's frames); the lock of a
    process that is gone is taken over."""

    def busy_with(name: str) -> Callable[[str, int | None], UserError]:
        def busy(who: str, pid: int | None) -> UserError:
            return UserError(
                f"--output-dir {output_dir}: {name} is being written there by {who} (another fourierf-render)",
                fix=f"wait for it to finish{f' (or stop it: kill {pid})' if pid else ''}, or choose another "
                "--output-dir",
            )

        return busy

    locks: list[RunLock] = []
    try:
        for name in sorted(outputs):
            locks.append(hold_lock(Path(output_dir) / render_lock(name), busy_with(name)))
    except UserError:
        for lock in locks:
            for lock in locks:
                lock.release()
        raise
    return locks


def _staging(final: Path) -> Path:
    """A hidden sibling of ``final`` that the work is written to before it is renamed into place."""
    return final.with_name(f".{final.name}.partial-{os.getpid()}{final.suffix}")


def _commit_dir(staged: Path, final: Path) -> None:
    """Put a finished folder in place of ``final`` (an earlier one, allowed by --overwrite, is removed)."""
    old = None
    if final.exists():
        old = final.with_name(f".{final.name}.old-{os.getpid()}")
        final.rename(old)
    staged.rename(final)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _mkdir(path: Path) -> None:
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise UserError(f"cannot create {path}: {err}", fix="choose a writable --output-dir") from err


def _even(frame: np.ndarray) -> np.ndarray:
    """Pad to even width and height by repeating the edge: H.264 in yuv420p needs even sizes."""
    h, w = frame.shape[:2]
    return np.pad(frame, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")


def _ffmpeg_available() -> bool:
    try:
        import imageio_ffmpeg  # noqa: F401
    except ImportError:
        return False
    return True


def write_animations(name: str, paths: list[Path], output_dir: Path, fps: float, mp4: bool) -> list[Path]:
    """``<name>.gif`` (always) and ``<name>.mp4`` (when asked) from the written PNG frames, in order.

    Pillow stores identical consecutive frames once with their summed delay, so a GIF may hold fewer frames than
    were rendered while playing for the same time.
    """
    frames = [iio.imread(p) for p in paths]
    gif = output_dir / f"{name}.gif"
    staged = _staging(gif)
    try:
        iio.imwrite(staged, np.stack(frames), duration=1000.0 / fps, loop=0)
        os.replace(staged, gif)
    finally:
        staged.unlink(missing_ok=True)
    written = [gif]
    if mp4:
        import imageio.v2 as iio2

        video = output_dir / f"{name}.mp4"
        staged = _staging(video)
        try:
            with iio2.get_writer(staged, format="FFMPEG", fps=fps, codec="libx264", macro_block_size=1) as writer:
                for frame in frames:
                    writer.append_data(_even(frame))
            os.replace(staged, video)
            written.append(video)
        except Exception as err:  # the video is an extra: the frames and the GIF are already written
            warn(f"could not write {video}: {err}")
        finally:
            staged.unlink(missing_ok=True)
    return written


def _frame_images(out: dict, height: int, width: int, outputs: list[str], cfg: RenderConfig, limits: list) -> dict:
    images = {}
    if "rgb" in outputs:
        images["rgb"] = to_uint8(out["rgb"].view(height, width, 3).cpu())
    depth = out["depth"].view(height, width).cpu()
    acc = out["accumulation"].view(height, width).cpu()
    if "depth" in outputs:
        if limits[0] is None or limits[1] is None:
            # Fixed from the first frame on, so the colours of an animation do not flicker from frame to frame.
            low, high = depth_range(depth, acc)
            limits[0] = low if limits[0] is None else limits[0]
            limits[1] = high if limits[1] is None else limits[1]
        images["depth"] = colorize_depth(depth, acc, limits[0], limits[1], cmap=cfg.colormap)
    if "accumulation" in outputs:
        images["accumulation"] = colorize_accumulation(acc)
    return images


def render(cfg: RenderConfig) -> RenderResult:
    outputs = validate(cfg)
    console = get_console()
    run = cfg.load_run()
    cameras, stems, mode = build_cameras(cfg, run)
    cameras = scale_cameras(cameras, cfg.resolution_scale)
    check_frame_fits(cameras.width, cameras.height, cfg.resolution_scale)
    with NewDirs() as made:  # a stopped render removes the folders it made and left empty, and only those
        output_dir = _output_dir(cfg, run, mode, made)
        locks = lock_render_outputs(output_dir, outputs)
        staged = {name: _staging(output_dir / name) for name in outputs}
        try:
            if not cfg.overwrite:  # checked again under the lock: a render that just finished may have filled it
                _refuse_taken(output_dir, outputs)
            for folder in staged.values():
                shutil.rmtree(folder, ignore_errors=True)
                _mkdir(folder)
            result = _render_frames(cfg, run, cameras, stems, mode, outputs, staged, output_dir)
            for name in outputs:
                _commit_dir(staged[name], output_dir / name)
                note_kept(output_dir / name)
                result.frames[name] = [output_dir / name / p.name for p in result.frames[name]]
        except OSError as err:
            problem = user_error_for(err, path=output_dir)
            if problem is None:
                raise
            raise problem from err
        finally:
            for folder in staged.values():
                shutil.rmtree(folder, ignore_errors=True)
            for lock in locks:
                lock.release()

    for name in outputs:
        console.print(f"  {name}: {len(result.frames[name])} frames in {escape(str(output_dir / name))}/")
    for path in result.animations:
        console.print(f"  {escape(str(path))}")
    console.print(
        f"[bold]rendered {len(cameras)} frames[/bold] in {format_duration(result.seconds_per_frame * len(cameras))} "
        f"({result.seconds_per_frame:.3f} s/frame)"
    )
    return result


def _render_frames(
    cfg: RenderConfig,
    run: LoadedRun,
    cameras: Cameras,
    stems: list[str],
    mode: str,
    outputs: list[str],
    staged: dict[str, Path],
    output_dir: Path,
) -> RenderResult:
    """Every frame into the ``staged`` folders, then the animations (renamed into place in ``output_dir``)."""
    console = get_console()
    model = run.pipeline.model
    model.eval()
    ray_space = run.pipeline.datamanager.ray_space  # NDC for forward-facing scenes, as in training
    result = RenderResult(output_dir, {name: [] for name in outputs}, [], 0.0, cameras.width, cameras.height, run.step)
    limits: list[float | None] = [cfg.depth_near, cfg.depth_far]
    console.print(
        f"rendering {len(cameras)} frames of {cameras.width}x{cameras.height} ({mode}, step {run.step}) on {run.device}"
    )
    render_seconds = 0.0
    with TaskProgress(len(cameras), unit="frame") as progress:
        for i, stem in enumerate(stems):
            origins, directions = camera_rays(cameras, i, ray_space)
            start = time.perf_counter()
            out = model.render_rays(origins.to(run.device), directions.to(run.device), run.step)
            images = _frame_images(out, cameras.height, cameras.width, outputs, cfg, limits)
            render_seconds += time.perf_counter() - start
            for name, image in images.items():
                path = staged[name] / f"{stem}.png"
                iio.imwrite(path, image)
                result.frames[name].append(path)
            progress.update(i + 1)
    result.seconds_per_frame = render_seconds / len(cameras)

    if not cfg.no_video:
        mp4 = _ffmpeg_available()
        for name in outputs:
            result.animations += write_animations(name, result.frames[name], output_dir, cfg.fps, mp4)
        if not mp4:
            console.print("note: no MP4 (install the video extra, `pip install imageio-ffmpeg`, to get one)")
    return result


def main(args: list[str] | None = None) -> RenderResult:
    argv = strip_verbose(sys.argv[1:] if args is None else args)
    if argv and argv[0].startswith("--") and argv[0] != "--help":
        argv = ["auto", *argv]  # no mode named: the path that fits the capture
    cfg = tyro.cli(RenderCommand, args=argv)
    return render(cfg)


def entrypoint() -> None:
    run_cli(stop_cleanly(main, "fourierf-render"))


if __name__ == "__main__":
    entrypoint()
