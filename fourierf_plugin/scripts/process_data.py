"""``fourierf-process-data``: from a folder of photos, a video or an LLFF scene to a scene folder to train on.

    fourierf-process-data images --data PHOTOS --output-dir SCENE     # structure-from-motion through pycolmap
    fourierf-process-data video --data clip.mp4 --num-frames 100 --output-dir SCENE
    fourierf-process-data llff --data LLFF_SCENE --output-dir SCENE   # the LLFF poses, no structure-from-motion

SCENE then holds ``transforms.json`` (nerfstudio's format: intrinsics, camera model, distortion, frames,
``applied_transform``), ``images/`` (copies of the inputs) with ``images_2/4/8/`` beside it, and after
structure-from-motion ``colmap/sparse/0`` (the model, for ``colmap-data``) and ``sparse_pc.ply`` (its points).
Why in this package: nerfstudio's own route needs the COLMAP binary installed separately; ``pycolmap`` (the optional
``[colmap]`` extra) brings COLMAP's SIFT, matching and mapping with nothing to compile.
"""

from __future__ import annotations

import math
import shlex
import shutil
import sys
import time
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Annotated

import tyro
from rich.markup import escape

from fourierf_plugin.data.capture import Capture
from fourierf_plugin.data.colmap_model import capture_from_model, read_model
from fourierf_plugin.data.nerfstudio_writer import capture_from_llff, write_transforms
from fourierf_plugin.scripts.cli import run_cli, strip_verbose
from fourierf_plugin.sfm.colmap_library import import_pycolmap
from fourierf_plugin.sfm.features import SfmCameraModel
from fourierf_plugin.sfm.matching import MatchingMode
from fourierf_plugin.sfm.photos import check_photo_count, copy_photos, list_photos, write_downscaled
from fourierf_plugin.sfm.pipeline import OVERLAP_ADVICE, SfmOptions, run_sfm
from fourierf_plugin.sfm.progress import StageDisplay
from fourierf_plugin.sfm.video import extract_frames
from fourierf_plugin.utils.console import get_console, warn
from fourierf_plugin.utils.errors import fail
from fourierf_plugin.utils.files import check_writable_dir

OUTPUTS = ("images", "images_2", "images_4", "images_8", "colmap", "transforms.json", "sparse_pc.ply")
"""What this script writes in --output-dir (and all that --overwrite removes there)."""


@dataclass(kw_only=True)
class _Output:
    output_dir: Path
    """The scene folder to write (created if missing)."""
    overwrite: bool = False
    """Allow an existing, non-empty --output-dir: this script's earlier outputs there are replaced."""


@dataclass(kw_only=True)
class _Sfm:
    matching: MatchingMode = "auto"
    """exhaustive (every pair; small unordered sets), sequential (neighbours; videos), auto (chooses)."""
    camera_model: SfmCameraModel = "OPENCV"
    """Lens model COLMAP fits: OPENCV (phones, most lenses), PINHOLE, SIMPLE_RADIAL, OPENCV_FISHEYE (fisheye)."""
    max_image_size: int = 1600
    """SIFT sees photos shrunk to this longer side (faster on CPU); poses stay full-resolution. 0: full size."""
    threads: int | None = None
    """CPU threads for SIFT extraction, matching, mapping and the downscaled copies. Default: all cores."""


@dataclass(kw_only=True)
class ImagesCommand(_Sfm, _Output):
    """Structure-from-motion on a folder of photos."""

    data: Path
    """Folder of photos (.jpg, .jpeg, .png directly in it), at least 3 of one scene with plenty of overlap."""


@dataclass(kw_only=True)
class VideoCommand(_Sfm, _Output):
    """Structure-from-motion on evenly spaced frames of a video."""

    data: Path
    """Video file (MP4, MOV, ... through imageio's ffmpeg plugin: pip install '.[video]'; GIF needs nothing)."""
    num_frames: int = 150
    """Frames to take, evenly spaced over the whole clip."""


@dataclass(kw_only=True)
class LLFFCommand(_Output):
    """An LLFF scene (poses_bounds.npy) written as transforms.json, no structure-from-motion."""

    data: Path
    """LLFF scene folder: poses_bounds.npy and images/ or images_<k>/."""
    image_folder: str | None = None
    """Photo folder of the scene to copy (e.g. images_8); default: the highest-resolution one present."""


Commands = (
    Annotated[ImagesCommand, tyro.conf.subcommand("images")]
    | Annotated[VideoCommand, tyro.conf.subcommand("video")]
    | Annotated[LLFFCommand, tyro.conf.subcommand("llff")]
)


@dataclass(frozen=True)
class ProcessReport:
    scene: Path
    transforms: Path
    total: int
    registered: list[str]
    unregistered: list[str]
    mean_reprojection_error: float | None  # None without structure-from-motion
    seconds: float


def check_output(cfg: _Output, data: Path) -> None:
    """Everything about --output-dir that can be checked without writing, before any work."""
    out = cfg.output_dir
    if out.exists() and not out.is_dir():
        fail(f"--output-dir {out} is a file", "pass a folder path (it is created if missing)")
    if out.resolve() == data.resolve() or out.resolve() in data.resolve().parents:
        fail(
            f"--data {data} lies inside --output-dir {out}: the outputs would overwrite the inputs",
            "choose an --output-dir outside the input folder",
        )
    if out.is_dir() and any(out.iterdir()) and not cfg.overwrite:
        fail(f"--output-dir {out} already exists and is not empty", "pass --overwrite, or choose a new folder")


def prepare_output(cfg: _Output) -> Path:
    """Create --output-dir (proving it writable) and remove this script's earlier outputs there (--overwrite)."""
    out = cfg.output_dir
    for name in OUTPUTS:
        target = out / name
        if target.is_dir():
            shutil.rmtree(target)
        elif target.exists():
            target.unlink()
    check_writable_dir(out, "--output-dir")
    return out


def _gather_photos(cfg: ImagesCommand | VideoCommand, images_dir: Path, display: StageDisplay) -> list[Path]:
    if isinstance(cfg, VideoCommand):
        written = partial(_count_files, images_dir)  # frames are written one by one as the clip is decoded
        title = f"extracting {cfg.num_frames} frames of {cfg.data.name}"
        with display.stage(title, total=cfg.num_frames, unit="frames", poll=written) as stage:
            frames = extract_frames(cfg.data, images_dir, cfg.num_frames)
            stage.detail = f"{len(frames)} frames"
        return frames
    photos = list_photos(cfg.data)
    check_photo_count(photos, cfg.data)
    with display.stage(f"copying {len(photos)} photos", total=len(photos), unit="photos") as stage:
        copies = copy_photos(photos, images_dir, on_copied=stage.advance)
        stage.detail = str(images_dir)
    return copies


def _count_files(folder: Path) -> int | None:
    return sum(1 for _ in folder.iterdir()) if folder.is_dir() else None


def _write_downscaled(images_dir: Path, photos: list[Path], display: StageDisplay, threads: int | None) -> None:
    with display.stage("writing images_2, images_4, images_8", total=len(photos), unit="photos") as stage:
        write_downscaled(images_dir, photos, threads=threads, on_photo=stage.advance)
        stage.detail = f"{len(photos)} photos each"


def check_threads(threads: int | None) -> None:
    if threads is not None and threads < 1:
        fail(f"--threads must be at least 1, got {threads}", "leave it out to use every core, or pass e.g. 4")


def process_sfm(cfg: ImagesCommand | VideoCommand, verbose: bool = False) -> ProcessReport:
    """Photos or video frames -> structure-from-motion -> transforms.json, downscaled folders, sparse points."""
    started = time.perf_counter()
    if isinstance(cfg, ImagesCommand):
        check_photo_count(list_photos(cfg.data), cfg.data)  # before anything is written
    elif not cfg.data.is_file():
        fail(f"video not found: {cfg.data}", "pass --data pointing at a video file (e.g. clip.mp4)")
    if cfg.max_image_size < 0:
        fail(f"--max-image-size must be >= 0, got {cfg.max_image_size}", "use 1600 (the default), or 0 for full size")
    check_threads(cfg.threads)
    check_output(cfg, cfg.data)
    import_pycolmap(verbose)  # a missing extra is reported before anything is written
    out = prepare_output(cfg)
    console = get_console()
    display = StageDisplay(console)
    images_dir = out / "images"
    photos = _gather_photos(cfg, images_dir, display)
    names = [p.name for p in photos]
    options = SfmOptions(
        camera_model=cfg.camera_model,
        matching=cfg.matching,
        max_image_size=cfg.max_image_size,
        ordered=isinstance(cfg, VideoCommand),
        verbose=verbose,
        threads=cfg.threads,
    )
    outcome = run_sfm(images_dir, names, out / "colmap", options, display)
    model = read_model(outcome.model_dir)
    capture = capture_from_model(model, images_dir)
    transforms = write_transforms(capture, out / "transforms.json", ply_name="sparse_pc.ply", point_colors=model.colors)
    _write_downscaled(images_dir, photos, display, cfg.threads)
    report = ProcessReport(
        scene=out,
        transforms=transforms,
        total=len(names),
        registered=outcome.registered,
        unregistered=outcome.unregistered,
        mean_reprojection_error=outcome.mean_reprojection_error,
        seconds=time.perf_counter() - started,
    )
    _print_summary(report, capture)
    return report


def process_llff(cfg: LLFFCommand) -> ProcessReport:
    """An LLFF scene's poses and photos as a nerfstudio scene folder."""
    started = time.perf_counter()
    source = capture_from_llff(cfg.data, cfg.image_folder)  # validates everything before writing
    check_output(cfg, cfg.data)
    out = prepare_output(cfg)
    display = StageDisplay(get_console())
    images_dir = out / "images"
    with display.stage(f"copying {len(source.frames)} photos", total=len(source.frames), unit="photos") as stage:
        copies = copy_photos([f.image_path for f in source.frames], images_dir, on_copied=stage.advance)
        stage.detail = f"from {source.frames[0].image_path.parent}"
    capture = Capture(
        frames=[replace(frame, image_path=copy) for frame, copy in zip(source.frames, copies, strict=True)],
        source=source.source,
    )
    transforms = write_transforms(capture, out / "transforms.json")
    _write_downscaled(images_dir, copies, display, None)
    names = [p.name for p in copies]
    report = ProcessReport(out, transforms, len(names), names, [], None, time.perf_counter() - started)
    _print_summary(report, capture)
    return report


def _print_summary(report: ProcessReport, capture: Capture) -> None:
    console = get_console()
    intr = capture.frames[0].intrinsics
    if report.mean_reprojection_error is None:  # poses from a file, nothing registered
        line = f"{report.total} images with the poses of {capture.source}"
    else:
        line = f"registered {len(report.registered)} of {report.total} images"
        line += f", mean reprojection error {report.mean_reprojection_error:.2f} px"
    console.print(f"[bold]{escape(line)}[/bold] ({report.seconds:.1f} s)", soft_wrap=True)
    console.print(
        f"camera: {intr.camera_model} {intr.width}x{intr.height}, focal {intr.fx:.1f} px; wrote {report.transforms}",
        soft_wrap=True,
        markup=False,
    )
    if report.unregistered:
        names = ", ".join(report.unregistered[:10]) + (" ..." if len(report.unregistered) > 10 else "")
        warn(
            f"{len(report.unregistered)} image(s) could not be registered and are left out of transforms.json: "
            f"{names}. {OVERLAP_ADVICE[0].upper()}{OVERLAP_ADVICE[1:]}."
        )
    for line in train_suggestion(report.scene, len(capture.frames)):
        console.print(line, markup=False, soft_wrap=True)


FEW_SHOT_VIEWS = 8
"""The few-shot view count the closing suggestion proposes (fewer when the capture's training split is smaller)."""


def train_suggestion(scene: Path, views: int, test_every: int = 8) -> list[str]:
    """The closing lines: a complete few-shot training command for the scene (``nerfstudio-data`` holds out every
    ``test_every``-th view for testing, so at most the rest are offered), and how to train on every view."""
    training = views - math.ceil(views / test_every)
    few = max(1, min(FEW_SHOT_VIEWS, training))
    command = f"fourierf-train fourierf-vm --data {shlex.quote(str(scene))} nerfstudio-data --num-views {few}"
    return [
        f"train on {few} of its {views} views (few-shot): {command}",
        f"  on all {training} training views: the same command without --num-views",
    ]


def main(args: list[str] | None = None) -> ProcessReport:
    argv = sys.argv[1:] if args is None else args
    cfg = tyro.cli(Commands, args=strip_verbose(argv))  # type: ignore[call-overload]
    if isinstance(cfg, LLFFCommand):
        return process_llff(cfg)
    return process_sfm(cfg, verbose="--verbose" in argv)


def entrypoint() -> None:
    run_cli(main)


if __name__ == "__main__":
    entrypoint()
