"""fourierf-render on one tiny run: frames, animations, progress output and the errors of every mode.

The colormaps it uses are tested in tests/utils/test_colormaps.py, its progress display in tests/utils/test_console.py.
"""

from __future__ import annotations

import importlib.util
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
from PIL import Image, ImageSequence

from fourierf_plugin.scripts import render as render_script
from fourierf_plugin.scripts.cli import EXIT_USER_ERROR
from fourierf_plugin.scripts.render import OUTPUT_NAMES, RenderOrbit, main, render_lock, spiral_bounds
from fourierf_plugin.utils.interrupt import Interrupted
from tests.helpers import (
    REPO_ROOT,
    TINY_IMAGE_SIZE,
    TINY_TEST_VIEWS,
    TINY_TRAIN_NAMES,
    cli_exit_code,
    train_tiny,
    venv_script,
)

ITERS = 20


# -- fourierf-render on one tiny run ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def run_config(tmp_path_factory) -> Path:
    """config.json of one tiny fourierf-vm run on the bundled scene (16³ -> 24³, 20 iterations)."""
    _, run_dir = train_tiny(tmp_path_factory.mktemp("runs"), iters=ITERS)
    return run_dir / "config.json"


def _check_gif(path: Path, n_frames: int, height: int, width: int, fps: float = 24.0) -> None:
    """A GIF of frames of the given size lasting ``n_frames / fps`` seconds.

    The frame count itself is not checked: Pillow merges identical consecutive frames (an untrained model renders
    every view blank) into one frame with the summed duration, which plays the same.
    """
    with Image.open(path) as gif:
        durations = []
        for frame in ImageSequence.Iterator(gif):
            assert frame.size == (width, height)
            durations.append(frame.info["duration"])
    assert 1 <= len(durations) <= n_frames
    assert sum(durations) == pytest.approx(n_frames * 1000.0 / fps, abs=10 * n_frames), "GIF delays are 10 ms units"


def test_dataset_mode_writes_every_test_view(run_config: Path, tmp_path: Path) -> None:
    out = tmp_path / "dataset"
    result = main(["dataset", "--load-config", str(run_config), "--output-dir", str(out), "--resolution-scale", "0.3"])
    height, width = (round(s * 0.3) for s in TINY_IMAGE_SIZE)
    assert (result.height, result.width, result.step) == (height, width, ITERS)
    for name in OUTPUT_NAMES:
        frames = sorted((out / name).glob("*.png"))
        assert len(frames) == TINY_TEST_VIEWS
        assert {p.stem for p in frames} == {f"r_{25 * i}" for i in range(TINY_TEST_VIEWS)}, "named after the views"
        image = iio.imread(frames[0])
        assert image.shape == (height, width, 3) and image.dtype == np.uint8
        _check_gif(out / f"{name}.gif", TINY_TEST_VIEWS, height, width)
    assert result.seconds_per_frame > 0


def test_orbit_writes_frames_at_the_scaled_size(run_config: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "orbit"
    args = ["orbit", "--load-config", str(run_config), "--output-dir", str(out)]
    result = main([*args, "--n-frames", "3", "--resolution-scale", "0.25", "--outputs", "rgb", "depth", "--fps", "10"])
    written = sorted(p.name for p in out.iterdir() if p.suffix != ".mp4")  # MP4 only with the video extra
    assert written == ["depth", "depth.gif", "rgb", "rgb.gif"]
    for name in ("rgb", "depth"):
        frames = sorted((out / name).glob("*.png"))
        assert [p.name for p in frames] == [f"frame_{i:05d}.png" for i in range(3)]
        for p in frames:
            image = iio.imread(p)
            assert image.shape == (25, 25, 3) and image.dtype == np.uint8
        _check_gif(out / f"{name}.gif", 3, 25, 25, fps=10.0)
    gifs = [p for p in result.animations if p.suffix == ".gif"]
    assert gifs == [out / "rgb.gif", out / "depth.gif"]
    printed = capsys.readouterr().out
    # Plain progress off a TTY; the rate reads frames/s or s/frame depending on the machine's speed.
    assert re.search(r"^frame 3/3 \(100%\) \| ([\d.]+ frames/s|[\d.]+ s/frame), eta ", printed, re.MULTILINE)
    assert "\x1b" not in printed
    if importlib.util.find_spec("imageio_ffmpeg") is None:
        assert "no MP4" in printed, "says why there is no video"


def test_mp4_when_the_ffmpeg_plugin_is_installed(run_config: Path, tmp_path: Path) -> None:
    pytest.importorskip("imageio_ffmpeg", reason="the optional video extra (imageio-ffmpeg) is not installed")
    import imageio.v2 as iio2

    args = ["orbit", "--load-config", str(run_config), "--output-dir", str(tmp_path), "--outputs", "rgb"]
    result = main([*args, "--n-frames", "2", "--resolution-scale", "0.25"])
    assert tmp_path / "rgb.mp4" in result.animations
    with iio2.get_reader(tmp_path / "rgb.mp4") as reader:
        assert reader.count_frames() == 2
        assert reader.get_meta_data()["size"] == (26, 26), "25 px padded to even for H.264"


def test_spiral_defaults_to_the_run_directory_and_no_video_skips_gifs(run_config: Path) -> None:
    args = ["spiral", "--load-config", str(run_config), "--n-frames", "3", "--resolution-scale", "0.2", "--no-video"]
    result = main(args)
    assert result.output_dir == run_config.parent / "renders" / f"spiral-step{ITERS:06d}"
    assert result.animations == [] and not list(result.output_dir.glob("*.gif"))
    for name in OUTPUT_NAMES:
        frames = sorted((result.output_dir / name).glob("frame_*.png"))
        assert len(frames) == 3 and iio.imread(frames[-1]).shape == (20, 20, 3)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["orbit", "--n-frames", "0"], "--n-frames"),
        (["spiral", "--n-frames", "-2"], "--n-frames"),
        (["orbit", "--resolution-scale", "0"], "--resolution-scale"),
        (["dataset", "--resolution-scale", "-0.5"], "--resolution-scale"),
        (["orbit", "--outputs", "rgb", "normals"], "normals"),
        (["orbit", "--elevation-deg", "120"], "--elevation-deg"),
        (["orbit", "--fps", "0"], "--fps"),
        (["spiral", "--near", "0", "--far", "1", "--n-frames", "1"], "spiral"),
        (["interpolate", "--steps-per-transition", "0"], "--steps-per-transition"),
        (["arc", "--span-scale", "-1"], "--span-scale"),
        (["arc", "--n-frames", "0"], "--n-frames"),
    ],
)
def test_bad_options_exit_2_with_a_message(run_config: Path, tmp_path: Path, capsys, extra, message) -> None:
    args = [extra[0], "--load-config", str(run_config), "--output-dir", str(tmp_path / "out"), *extra[1:]]
    assert cli_exit_code(main, args) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert "error:" in err and message in err and "Traceback" not in err


def test_bad_paths_exit_2(run_config: Path, tmp_path: Path, capsys) -> None:
    a_file = tmp_path / "taken"
    a_file.write_text("not a directory")
    cases = [
        (["orbit", "--load-config", str(run_config), "--output-dir", str(a_file)], "existing file"),
        (["orbit", "--load-config", str(tmp_path / "nope" / "config.json")], "config file not found"),
        (["orbit", "--load-config", str(run_config), "--checkpoint", str(tmp_path / "x.ckpt")], "does not exist"),
    ]
    for args, message in cases:
        assert cli_exit_code(main, args) == EXIT_USER_ERROR
        assert message in capsys.readouterr().err


def test_spiral_bounds_use_metric_depths_of_ndc_scenes() -> None:
    assert spiral_bounds(2.0, 6.0, None) == (2.0, 6.0), "euclidean scenes: their own near/far"
    near, far = spiral_bounds(0.0, 1.0, (1.0 / 0.75, 10.0))  # LLFF: NDC near/far, metric content depths
    assert near == pytest.approx(1.2) and far == pytest.approx(50.0), "LLFF's 0.9 x closest and 5 x farthest"


def test_subcommands_have_help(capsys) -> None:
    for mode in ("auto", "interpolate", "arc", "orbit", "spiral", "dataset"):
        with pytest.raises(SystemExit) as info:
            main([mode, "--help"])
        assert info.value.code == 0
        assert "--load-config" in capsys.readouterr().out
    assert RenderOrbit(load_config=Path("c.json")).mode == "orbit"


def test_console_script_reports_a_missing_config_cleanly(tmp_path: Path) -> None:
    script = venv_script("fourierf-render")
    if not script.exists():
        pytest.skip(f"{script} is not installed (pip install -e .)")
    proc = subprocess.run(
        [str(script), "orbit", "--load-config", str(tmp_path / "missing.json")],
        capture_output=True,
        text=True,
        cwd=REPO_ROOT,
        timeout=120,
    )
    assert proc.returncode == EXIT_USER_ERROR
    assert "config file not found" in proc.stderr and "Traceback" not in proc.stderr


# -- paths that fit the capture, and what is already on disk ---------------------------------------------------------
def _quick(run_config: Path, *args: str) -> list[str]:
    return [*args, "--load-config", str(run_config), "--resolution-scale", "0.2", "--outputs", "rgb"]


def test_interpolate_renders_a_frame_per_step_through_the_training_views(run_config: Path, tmp_path: Path) -> None:
    out = tmp_path / "interpolate"
    result = main([*_quick(run_config, "interpolate"), "--steps-per-transition", "2", "--output-dir", str(out)])
    frames = sorted((out / "rgb").glob("*.png"))
    assert len(frames) == (len(TINY_TRAIN_NAMES) - 1) * 2 + 1 and result.frames["rgb"] == frames
    assert (out / "rgb.gif").is_file()
    assert not [p for p in out.iterdir() if p.name.startswith(".")], "no staging folder or file left"


def test_arc_says_the_range_it_sweeps(run_config: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "arc"
    main([*_quick(run_config, "arc"), "--n-frames", "3", "--no-video", "--output-dir", str(out)])
    assert len(list((out / "rgb").glob("*.png"))) == 3
    assert re.search(r"arc over the \d+° the training cameras cover", capsys.readouterr().out)


def test_no_mode_renders_the_path_that_fits_the_capture(run_config: Path, capsys) -> None:
    result = main([*_quick(run_config), "--n-frames", "2", "--steps-per-transition", "1", "--no-video"])
    printed = capsys.readouterr().out
    chosen = re.search(r"auto: the training cameras .*: rendering `(orbit|interpolate)`", printed)
    assert chosen, printed
    assert result.output_dir.name.startswith(f"{chosen.group(1)}-step")


def test_a_second_render_never_replaces_the_first_without_overwrite(run_config: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "mine"
    args = [*_quick(run_config, "arc"), "--n-frames", "2", "--output-dir", str(out)]
    main(args)
    first = {p: p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()}
    assert cli_exit_code(main, [*args, "--n-frames", "3"]) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert "already holds rgb, rgb.gif" in err and "--overwrite" in err
    assert {p: p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file()} == first, "left as it was"
    main([*args, "--n-frames", "3", "--overwrite"])
    assert len(list((out / "rgb").glob("*.png"))) == 3
    assert not [p for p in out.iterdir() if p.name.startswith(".")]
    # the run's own renders folder: a second render of the same mode goes beside the first
    default = [*_quick(run_config, "arc"), "--n-frames", "1", "--no-video"]
    one, two = main(default), main(default)
    assert two.output_dir == one.output_dir.with_name(one.output_dir.name + "-1")
    assert (one.output_dir / "rgb" / "frame_00000.png").is_file()


# -- two renders into one folder, and a stop mid-render ---------------------------------------------------------------
def every_path(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


def hold_render_lock(out: Path, output: str = "rgb") -> subprocess.Popen[str]:
    """Another live process holding the lock of ``output`` in ``out`` the way a render does (an ``flock``, its PID
    inside)."""
    out.mkdir(parents=True, exist_ok=True)
    code = (
        "import fcntl, os, sys, time; fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT); "
        "fcntl.flock(fd, fcntl.LOCK_EX); os.write(fd, f'{os.getpid()}\\n'.encode()); print('held', flush=True); "
        "time.sleep(60)"
    )
    holder = subprocess.Popen([sys.executable, "-c", code, str(out / render_lock(output))], stdout=subprocess.PIPE,
                              text=True)  # fmt: skip
    assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
    return holder


def test_a_folder_another_live_render_is_writing_is_refused_naming_its_pid(
    run_config: Path, tmp_path: Path, capsys
) -> None:
    out = tmp_path / "out"
    holder = hold_render_lock(out)
    try:
        code = cli_exit_code(main, [*_quick(run_config, "arc"), "--n-frames", "1", "--output-dir", str(out)])
    finally:
        holder.kill()
        holder.wait()
    err = " ".join(capsys.readouterr().err.split())
    assert code == EXIT_USER_ERROR and "Traceback" not in err, err
    assert f"--output-dir {out}: rgb is being written there by process {holder.pid}" in err, err
    assert f"kill {holder.pid}" in err and "choose another --output-dir" in err
    assert every_path(out) == {render_lock("rgb")}, "nothing written beside the other render's work"


def test_a_render_of_other_outputs_shares_the_folder_of_a_live_render(run_config: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    holder = hold_render_lock(out, "rgb")
    try:
        main([*_quick(run_config, "arc"), "--n-frames", "1", "--no-video", "--outputs", "depth", "--output-dir",
              str(out)])  # fmt: skip
    finally:
        holder.kill()
        holder.wait()
    assert every_path(out) == {render_lock("rgb"), "depth", "depth/frame_00000.png"}, "the other render's lock stays"


def test_the_lock_of_a_render_that_is_gone_is_taken_over(run_config: Path, tmp_path: Path) -> None:
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    out = tmp_path / "out"
    out.mkdir()
    (out / render_lock("rgb")).write_text(gone.stdout)  # what a render killed with SIGKILL leaves
    main([*_quick(run_config, "arc"), "--n-frames", "1", "--no-video", "--output-dir", str(out)])
    assert every_path(out) == {"rgb", "rgb/frame_00000.png"}, "the lock is released with the render"


@pytest.mark.parametrize("where", ["default", "default --overwrite", "--output-dir"])
def test_a_first_render_stopped_mid_frames_leaves_no_folder_it_made(
    run_config: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, where: str
) -> None:
    """A run never rendered (no RUN/renders/), stopped after its first frame: the folders it made go, a user's
    empty folder stays."""
    run = Path(shutil.copytree(run_config.parent, tmp_path / "run", ignore=shutil.ignore_patterns("renders")))
    (tmp_path / "mine").mkdir()
    args = [*_quick(run / "config.json", "arc"), "--n-frames", "3"]
    args += {
        "default": [],
        "default --overwrite": ["--overwrite"],
        "--output-dir": ["--output-dir", str(tmp_path / "mine" / "new" / "deeper")],
    }[where]
    before = every_path(tmp_path)
    real = render_script.iio.imwrite
    written: list[object] = []

    def write_then_stop(path: object, *rest: object, **kwargs: object) -> object:
        written.append(path)
        if len(written) == 2:
            raise Interrupted(signal.SIGTERM)  # what the stop-signal handler raises mid-work
        return real(path, *rest, **kwargs)

    monkeypatch.setattr(render_script.iio, "imwrite", write_then_stop)
    with pytest.raises(KeyboardInterrupt):
        main(args)
    assert every_path(tmp_path) == before
