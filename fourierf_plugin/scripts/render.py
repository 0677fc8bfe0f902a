"""``fourierf-render dataset|orbit|spiral --load-config RUN/config.json``: novel views as PNG frames and animations.

``dataset`` renders a split's own cameras (named after the views), ``orbit`` a Blender-style turntable around the
object and ``spiral`` the LLFF spiral of forward-facing captures. Every requested output (rgb, depth coloured by a
perceptual colormap, accumulation) is written as ``DIR/<output>/<frame>.png`` plus ``DIR/<output>.gif`` (and
``.mp4`` when the optional imageio-ffmpeg plugin is installed).
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import imageio.v3 as iio
import numpy as np
import tyro
from rich.markup import escape

from fourierf_plugin.cameras.camera_paths import orbit_from_cameras, scale_cameras, spiral_path
from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.data.datamanager import camera_rays
from fourierf_plugin.engine.loading import LoadedRun
from fourierf_plugin.engine.run_dir import unique_safe_name
from fourierf_plugin.scripts.cli import run_cli, strip_verbose
from fourierf_plugin.scripts.run_options import RunOptions
from fourierf_plugin.utils.colormaps import Colormap, colorize_accumulation, colorize_depth, depth_range, to_uint8
from fourierf_plugin.utils.console import TaskProgress, format_duration, get_console, warn
from fourierf_plugin.utils.errors import UserError, fail
from fourierf_plugin.utils.memory import available_memory, check_fits

OUTPUT_NAMES = ("rgb", "depth", "accumulation")


@dataclass
class RenderConfig(RunOptions):
    """Options shared by every render mode."""

    output_dir: Path | None = None
    """Where to write frames and animations (default: RUN/renders/<mode>-step<N>/)."""
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
class RenderOrbit(RenderConfig):
    """A turntable around the z axis at the training cameras' mean distance from the origin (object scenes)."""

    n_frames: int = 60
    """Frames in one full turn."""
    elevation_deg: float | None = None
    """Camera elevation above the xy plane in degrees (default: the training cameras' mean elevation)."""

    @property
    def mode(self) -> str:
        return "orbit"


@dataclass
class RenderSpiral(RenderConfig):
    """The LLFF spiral around the training cameras' average pose (forward-facing scenes; works for any scene)."""

    n_frames: int = 60
    """Frames along the whole spiral."""
    n_rotations: float = 2.0
    """Turns of the spiral."""
    zrate: float = 0.5
    """Forward/backward oscillations per turn."""
    radius_scale: float = 1.0
    """Scale of the spiral's radii (from the 90th percentile of the training cameras' spread)."""
    near: float | None = None
    """Near bound for the focus depth, world units (default: the dataset's; LLFF: 0.9 x its nearest depth)."""
    far: float | None = None
    """Far bound for the focus depth, world units (default: the dataset's; LLFF: 5 x its farthest depth)."""

    @property
    def mode(self) -> str:
        return "spiral"


_MISSING = tyro.MISSING
if TYPE_CHECKING:
    RenderCommand = RenderConfig
else:
    RenderCommand = tyro.extras.subcommand_type_from_defaults(
        {
            "dataset": RenderDataset(load_config=_MISSING),
            "orbit": RenderOrbit(load_config=_MISSING),
            "spiral": RenderSpiral(load_config=_MISSING),
        },
        {
            "dataset": "Render the cameras of a dataset split (test by default).",
            "orbit": "Render a turntable around the object (Blender-style scenes).",
            "spiral": "Render the LLFF spiral (forward-facing scenes).",
        },
        prefix_names=False,
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


def validate(cfg: RenderConfig) -> list[str]:
    """Every check that needs no trained run, so a typo fails in a second instead of after loading the model."""
    outputs = _outputs(cfg)
    if not (math.isfinite(cfg.resolution_scale) and cfg.resolution_scale > 0):
        fail(f"--resolution-scale must be > 0, got {cfg.resolution_scale}", "use e.g. 0.5 for half size")
    if not (math.isfinite(cfg.fps) and cfg.fps > 0):
        fail(f"--fps must be > 0, got {cfg.fps}", "use e.g. 24")
    n_frames = getattr(cfg, "n_frames", 1)
    if n_frames < 1:
        fail(f"--n-frames must be >= 1, got {n_frames}", "use e.g. 60")
    if cfg.depth_near is not None and cfg.depth_far is not None and not cfg.depth_near < cfg.depth_far:
        fail(f"need --depth-near < --depth-far, got {cfg.depth_near} and {cfg.depth_far}", "swap or fix them")
    if isinstance(cfg, RenderOrbit) and cfg.elevation_deg is not None and not -90 <= cfg.elevation_deg <= 90:
        fail(f"--elevation-deg must be within [-90, 90], got {cfg.elevation_deg}", "use e.g. 30")
    if isinstance(cfg, RenderSpiral) and not cfg.radius_scale >= 0:
        fail(f"--radius-scale must be >= 0, got {cfg.radius_scale}", "use 1 for the cameras' own spread")
    if cfg.output_dir is not None and cfg.output_dir.exists() and not cfg.output_dir.is_dir():
        fail(f"--output-dir {cfg.output_dir} is an existing file", "choose a directory path")
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


def build_cameras(cfg: RenderConfig, run: LoadedRun) -> tuple[Cameras, list[str]]:
    """The cameras of the chosen mode (before resolution scaling) and a file stem per frame."""
    datamanager = run.pipeline.datamanager
    if isinstance(cfg, RenderDataset):
        outputs = datamanager.parser.get_outputs(cfg.split)
        if len(outputs.cameras) == 0:
            fail(
                f"the {cfg.split} split of {datamanager.config.dataparser.data} has no views", "render another --split"
            )
        return outputs.cameras, _unique_stems(outputs.image_names)
    reference = datamanager.reference_outputs
    if isinstance(cfg, RenderOrbit):
        if run.pipeline.effects.ray_space == "ndc":
            warn("this scene uses NDC rays (forward-facing): an orbit leaves the captured frustum; try `spiral`")
        cameras = orbit_from_cameras(reference.cameras, cfg.n_frames, cfg.elevation_deg)
    elif isinstance(cfg, RenderSpiral):
        near, far = spiral_bounds(reference.near, reference.far, reference.depth_bounds)
        near = near if cfg.near is None else cfg.near
        far = far if cfg.far is None else cfg.far
        try:
            cameras = spiral_path(
                reference.cameras, cfg.n_frames, near, far, cfg.n_rotations, cfg.zrate, cfg.radius_scale
            )
        except ValueError as err:
            fail(f"cannot build the spiral: {err}", "pass --near and --far with 0 < near < far (scene units)")
    else:  # pragma: no cover - tyro only builds the three modes
        raise TypeError(f"unknown render mode {type(cfg).__name__}")
    return cameras, [f"frame_{i:05d}" for i in range(len(cameras))]


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
    iio.imwrite(gif, np.stack(frames), duration=1000.0 / fps, loop=0)
    written = [gif]
    if mp4:
        import imageio.v2 as iio2

        video = output_dir / f"{name}.mp4"
        try:
            with iio2.get_writer(video, format="FFMPEG", fps=fps, codec="libx264", macro_block_size=1) as writer:
                for frame in frames:
                    writer.append_data(_even(frame))
            written.append(video)
        except Exception as err:  # the video is an extra: the frames and the GIF are already written
            warn(f"could not write {video}: {err}")
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
    cameras, stems = build_cameras(cfg, run)
    cameras = scale_cameras(cameras, cfg.resolution_scale)
    check_frame_fits(cameras.width, cameras.height, cfg.resolution_scale)
    output_dir = cfg.output_dir or run.run_dir / "renders" / f"{cfg.mode}-step{run.step:06d}"
    for name in outputs:
        _mkdir(output_dir / name)

    model = run.pipeline.model
    model.eval()
    ray_space = run.pipeline.datamanager.ray_space  # NDC for forward-facing scenes, as in training
    result = RenderResult(output_dir, {name: [] for name in outputs}, [], 0.0, cameras.width, cameras.height, run.step)
    limits: list[float | None] = [cfg.depth_near, cfg.depth_far]
    console.print(
        f"rendering {len(cameras)} frames of {cameras.width}x{cameras.height} ({cfg.mode}, step {run.step}) "
        f"on {run.device}"
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
                path = output_dir / name / f"{stem}.png"
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

    for name in outputs:
        console.print(f"  {name}: {len(result.frames[name])} frames in {escape(str(output_dir / name))}/")
    for path in result.animations:
        console.print(f"  {escape(str(path))}")
    console.print(
        f"[bold]rendered {len(cameras)} frames[/bold] in {format_duration(render_seconds)} "
        f"({result.seconds_per_frame:.3f} s/frame)"
    )
    return result


def main(args: list[str] | None = None) -> RenderResult:
    cfg = tyro.cli(RenderCommand, args=strip_verbose(sys.argv[1:] if args is None else args))
    return render(cfg)


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
