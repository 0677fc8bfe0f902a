"""Bad-input catalogue (issue 6): every user mistake at train, eval, render and export ends in exit code 2 with one
message naming the problem and the fix, and no traceback unless ``--verbose``.

The cases are driven through each console script's real ``main`` under ``run_cli`` (what ``entrypoint`` does), plus
two through the installed scripts themselves. Cases already in scripts/test_cli.py, scripts/test_render.py and
exporter/test_export.py (missing scene folder, zero iterations, missing config, missing checkpoint, bad render/export
options) are not repeated; the parser-level checks of the Blender and LLFF parser tests are repeated here end to end,
through the CLI, because what the user sees (exit code, one message, no traceback) is what is tested.
"""

from __future__ import annotations

import copy
import json
import os
import shutil
import struct
import subprocess
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from fourierf_plugin.data.parsers.blender import BlenderDataParserConfig
from fourierf_plugin.data.parsers.llff import LLFFDataParserConfig
from fourierf_plugin.engine.option_checks import check_training_options
from fourierf_plugin.method_configs import all_methods, finalize
from fourierf_plugin.method_configs.scene_presets import apply_real_scene_preset
from fourierf_plugin.scripts import eval as eval_script
from fourierf_plugin.scripts import export as export_script
from fourierf_plugin.scripts import render as render_script
from fourierf_plugin.scripts import train as train_script
from fourierf_plugin.scripts.cli import EXIT_USER_ERROR, run_cli
from tests.data.transforms_scenes import edit_transforms as edit_capture
from tests.data.transforms_scenes import ring_c2w, write_image, write_scene
from tests.helpers import REPO_ROOT, TINY_SCENE, tiny_args, train_tiny, venv_script
from tests.scenes import write_llff_scene

ENTRIES = {
    "train": train_script.main,
    "eval": eval_script.main,
    "render": render_script.main,
    "export": export_script.main,
}


@dataclass(frozen=True)
class Case:
    entry: str
    args: Callable[[Path, Path], list[str]]
    """Builds the command line from a scratch folder and the config.json of a tiny trained run."""
    expected: tuple[str, ...]
    """Text the message must contain (the problem names the file or flag; the fix says what to do)."""


# -- scenes and runs to break ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def trained_config(tmp_path_factory: pytest.TempPathFactory) -> Path:
    _, run_dir = train_tiny(tmp_path_factory.mktemp("run"), iters=12, extra=["--steps-per-save", "6"])
    return run_dir / "config.json"


def blender(tmp: Path) -> Path:
    return Path(shutil.copytree(TINY_SCENE, tmp / "lego"))


def llff(tmp: Path) -> Path:
    return write_llff_scene(tmp / "fern", n=10)


def write(path: Path, content: str | bytes) -> Path:
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    return path


def edit_transforms(scene: Path, split: str, edit: Callable[[dict], None]) -> Path:
    path = scene / f"transforms_{split}.json"
    meta = json.loads(path.read_text())
    edit(meta)
    path.write_text(json.dumps(meta))
    return scene


def copy_run(config: Path, tmp: Path) -> Path:
    """A private copy of the trained run directory (its config.json path) that a case may break."""
    return Path(shutil.copytree(config.parent, tmp / "run")) / "config.json"


def with_config(config: Path, tmp: Path, edit: Callable[[dict], None]) -> Path:
    copied = copy_run(config, tmp)
    payload = json.loads(copied.read_text())
    edit(payload)
    copied.write_text(json.dumps(payload))
    return copied


def truncate_all_checkpoints(config: Path, tmp: Path) -> Path:
    copied = copy_run(config, tmp)
    for ckpt in (copied.parent / "checkpoints").glob("step-*.ckpt"):
        data = ckpt.read_bytes()
        ckpt.write_bytes(data[: len(data) // 2])
    return copied


def truncated_checkpoint(config: Path, tmp: Path) -> Path:
    newest = sorted((config.parent / "checkpoints").glob("step-*.ckpt"))[-1]
    return write(tmp / "cut.ckpt", newest.read_bytes()[:4096])


def other_version(payload: dict) -> None:
    payload.update(config_format=99, fourierf_version="9.0.0")


def newer_field(payload: dict) -> None:
    payload["config"]["pipeline"]["model"]["new_option_of_a_later_version"] = 1


def np_saved(path: Path, array: np.ndarray) -> Path:
    """``np.save`` to exactly ``path`` (no .npy appended); returns the scene folder for poses_bounds.npy."""
    with path.open("wb") as fh:
        np.save(fh, array)
    return path.parent if path.name == "poses_bounds.npy" else path


def no_frames(meta: dict) -> None:
    meta["frames"] = []


def zero_pose(meta: dict) -> None:
    meta["frames"][1]["transform_matrix"] = [[0.0] * 4] * 4


def foreign_checkpoint(config: Path, tmp: Path) -> Path:
    """A good checkpoint of the run, copied out of its checkpoints folder (as another run's would be)."""
    newest = sorted((config.parent / "checkpoints").glob("step-*.ckpt"))[-1]
    return Path(shutil.copy(newest, tmp / "foreign.ckpt"))


def plain_file(tmp: Path, _: Path) -> list[str]:
    """Puts a plain file where a case's output folder should be; adds no arguments."""
    write(tmp / "file.txt", "not a folder")
    return []


def existing_report(tmp: Path) -> list[str]:
    """Puts a file where the eval report goes; adds no arguments."""
    write(tmp / "eval.json", "{}")
    return []


def folder_of_notes(tmp: Path) -> list[str]:
    """Puts a user's folder with a note in it where the renders go; adds no arguments."""
    (tmp / "mine").mkdir()
    write(tmp / "mine" / "notes.txt", "keep me")
    return []


def moved_scene(payload: dict, where: Path) -> None:
    payload["config"]["pipeline"]["datamanager"]["dataparser"]["data"] = str(where)


def mixed_blender_sizes(tmp: Path) -> Path:
    scene = blender(tmp)
    iio.imwrite(scene / "train" / "r_76.png", np.zeros((50, 60, 4), dtype=np.uint8))
    return scene


def mixed_llff_sizes(tmp: Path) -> Path:
    scene = llff(tmp)
    iio.imwrite(scene / "images_8" / "image003.png", np.zeros((5, 7, 3), dtype=np.uint8))
    return scene


NS = ("nerfstudio-data",)


def capture(tmp: Path, damage: Callable[[Path], object]) -> Path:
    """A small object capture (nerfstudio transforms.json, 8x6 images), then ``damage(root)``."""
    root = write_scene(tmp / "capture", ring_c2w(10))
    damage(root)
    return root


def set_keys(**keys: object) -> Callable[[Path], None]:
    return lambda root: edit_capture(root, lambda doc: doc.update(keys))


def frame_keys(index: int, **keys: object) -> Callable[[Path], None]:
    return lambda root: edit_capture(root, lambda doc: doc["frames"][index].update(keys))


def empty_colmap_model(tmp: Path) -> Path:
    """A COLMAP text model whose images.txt lists nothing."""
    model = tmp / "colmap_scene" / "colmap" / "sparse" / "0"
    model.mkdir(parents=True)
    write(model / "cameras.txt", "1 PINHOLE 8 6 6 6 4 3\n")
    write(model / "images.txt", "# no images\n")
    write(model / "points3D.txt", "")
    (tmp / "colmap_scene" / "images").mkdir()
    return tmp / "colmap_scene"


# -- issue 85: resume, memory and decode guards, tracebacks made errors ---------------------------------------------
def shifted_scene(tmp: Path) -> Path:
    """The bundled scene's files under the same names and sizes, every camera moved: another scene to a run."""

    def shift(meta: dict) -> None:
        for frame in meta["frames"]:
            frame["transform_matrix"][0][3] += 0.5

    return edit_transforms(blender(tmp), "train", shift)


def deeply_nested(depth: int = 100_000) -> str:
    return "[" * depth + "]" * depth


def llff_with(tmp: Path, edit: Callable[[np.ndarray], np.ndarray]) -> Path:
    """An LLFF scene whose poses_bounds.npy array is replaced by ``edit(array)``."""
    scene = llff(tmp)
    return np_saved(scene / "poses_bounds.npy", edit(np.load(scene / "poses_bounds.npy")))


def with_column(column: int, value: float) -> Callable[[np.ndarray], np.ndarray]:
    def edit(array: np.ndarray) -> np.ndarray:
        array[:, column] = value
        return array

    return edit


def png16_header_only(path: Path, width: int, height: int) -> Path:
    """A 16-bit RGBA PNG whose header declares ``width`` x ``height`` pixels over a few bytes of pixel data."""

    def chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    header = struct.pack(">IIBBBBB", width, height, 16, 6, 0, 0, 0)
    data = (
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(bytes(1000))) + chunk(b"IEND", b"")
    )
    return write(path, data)


def bomb_scene(tmp: Path) -> Path:
    scene = blender(tmp)
    png16_header_only(scene / "train" / "r_27.png", 40_000, 40_000)
    return scene


def edited_checkpoint(edit: Callable[[dict], object]) -> Callable[[Path, Path], list[str]]:
    """``--checkpoint`` of a copy of the run's newest checkpoint after ``edit(state)`` (``--force-checkpoint``)."""

    def build(tmp: Path, cfg: Path) -> list[str]:
        newest = sorted((cfg.parent / "checkpoints").glob("step-*.ckpt"))[-1]
        state = torch.load(newest, map_location="cpu", weights_only=True)
        edit(state)
        torch.save(state, tmp / "edited.ckpt")
        return ["--checkpoint", str(tmp / "edited.ckpt"), "--force-checkpoint"]

    return build


def drop_a_weight(state: dict) -> None:
    model = state["pipeline"]["model"]
    del model[sorted(model)[0]]


def add_a_weight(state: dict) -> None:
    state["pipeline"]["model"]["foreign.weight"] = torch.zeros(3)


def config_value(path: str, value: object) -> Callable[[dict], None]:
    """Sets ``path`` (dotted, inside the saved config) in a config.json payload."""

    def edit(payload: dict) -> None:
        node = payload["config"]
        *parents, last = path.split(".")
        for part in parents:
            node = node[part]
        node[last] = value

    return edit


# -- command lines --------------------------------------------------------------------------------------------------
def train_on(data: Path, tmp: Path, *extra: str, iters: int = 10) -> list[str]:
    args = tiny_args(tmp / "out", iters=iters, extra=list(extra))
    args[args.index(str(TINY_SCENE))] = str(data)
    return args


def train_with(*extra: str, iters: int = 10) -> Callable[[Path, Path], list[str]]:
    return lambda tmp, _: train_on(TINY_SCENE, tmp, *extra, iters=iters)


def out_of_range(flag: str, value: str, needs: str) -> Case:
    """A training flag given a value outside its range: the message repeats the flag with the value and says the
    range it needs."""
    return Case("train", train_with(flag, value), (f"{flag} {value}", needs))


def resume(make_config: Callable[[Path, Path], Path]) -> Callable[[Path, Path], list[str]]:
    return lambda tmp, cfg: ["fourierf-vm", "--load-dir", str(make_config(cfg, tmp).parent)]


def intact(cfg: Path, tmp: Path) -> Path:
    return cfg


EVAL = ["--load-config", "{config}", "--output-path", "{tmp}/eval.json", "--render-dir", "none"]
RENDER = ["dataset", "--load-config", "{config}", "--output-dir", "{tmp}/r"]
EXPORT = ["marching-cubes", "--load-config", "{config}", "--resolution", "8", "--output-path", "{tmp}/mesh.ply"]


def on_run(
    template: list[str],
    make_config: Callable[[Path, Path], Path] = intact,
    extra: Callable[[Path, Path], list[str]] = lambda tmp, cfg: [],
) -> Callable[[Path, Path], list[str]]:
    """A command line on a run: ``{config}`` becomes the (possibly broken) config.json, ``{tmp}`` the scratch folder,
    and ``extra(tmp, cfg)`` is appended."""

    def build(tmp: Path, cfg: Path) -> list[str]:
        config = str(make_config(cfg, tmp))
        return [w.format(config=config, tmp=tmp) for w in template] + extra(tmp, cfg)

    return build


MODEL = "--pipeline.model"
ACCEL = f"{MODEL}.accel"
CASES: dict[str, Case] = {
    # -- train: scenes --------------------------------------------------------------------------------------------
    "train: --data is a file": Case(
        "train", lambda tmp, _: train_on(write(tmp / "scene.txt", "x"), tmp), ("scene.txt", "is a file", "--data")
    ),
    "train: LLFF folder given to blender-data": Case(
        "train", lambda tmp, _: train_on(llff(tmp), tmp, "blender-data"), ("poses_bounds.npy", "llff-data")
    ),
    "train: Blender folder given to llff-data": Case(
        "train", lambda tmp, _: train_on(blender(tmp), tmp, "llff-data"), ("transforms_", "blender-data")
    ),
    "train: malformed transforms JSON": Case(
        "train",
        lambda tmp, _: train_on(write(blender(tmp) / "transforms_train.json", '{"frames": [').parent, tmp),
        ("transforms_train.json", "not valid JSON", "line 1"),
    ),
    "train: malformed poses_bounds.npy": Case(
        "train",
        lambda tmp, _: train_on(write(llff(tmp) / "poses_bounds.npy", b"\x93NUMPY garbage").parent, tmp, "llff-data"),
        ("poses_bounds.npy", "not a readable .npy", "re-export"),
    ),
    "train: poses_bounds.npy of the wrong shape": Case(
        "train",
        lambda tmp, _: train_on(np_saved(llff(tmp) / "poses_bounds.npy", np.zeros((10, 5))), tmp, "llff-data"),
        ("poses_bounds.npy", "N x 17", "imgs2poses"),
    ),
    "train: Blender images of mixed sizes": Case(
        "train", lambda tmp, _: train_on(mixed_blender_sizes(tmp), tmp), ("r_76.png", "60x50")
    ),
    "train: LLFF images of mixed sizes": Case(
        "train", lambda tmp, _: train_on(mixed_llff_sizes(tmp), tmp, "llff-data"), ("image003.png",)
    ),
    "train: zero training views (Blender)": Case(
        "train",
        lambda tmp, _: train_on(edit_transforms(blender(tmp), "train", no_frames), tmp),
        ("transforms_train.json", "non-empty", "add at least one frame"),
    ),
    "train: zero cameras (LLFF)": Case(
        "train",
        lambda tmp, _: train_on(np_saved(llff(tmp) / "poses_bounds.npy", np.zeros((0, 17))), tmp, "llff-data"),
        ("poses_bounds.npy", "no cameras"),
    ),
    "train: view id out of range": Case(
        "train", train_with("blender-data", "--view-ids", "0", "99"), ("[99]", "out of range", "0..3")
    ),
    "train: --num-views 0": Case("train", train_with("blender-data", "--num-views", "0"), ("--num-views", ">= 1")),
    # -- train: nonsense option values -----------------------------------------------------------------------------
    "train: negative iterations": Case("train", train_with(iters=-5), ("--max-num-iterations", "-5", "positive")),
    "train: f0 > 1": Case(
        "train", train_with(f"{MODEL}.fourier.f0-density", "1.5"), (f"{MODEL}.fourier.f0-density 1.5", "[0, 1]")
    ),
    "train: f0 < 0": Case(
        "train", train_with(f"{MODEL}.fourier.f0-color", "-0.1"), (f"{MODEL}.fourier.f0-color -0.1", "[0, 1]")
    ),
    "train: f0 NaN": Case("train", train_with(f"{MODEL}.fourier.f0-density", "nan"), ("f0-density nan",)),
    "train: f0 above the final cutoff": Case(
        "train",
        train_with(f"{MODEL}.fourier.f0-density", "0.6", f"{MODEL}.fourier.f-final", "0.5"),
        ("f0-density 0.6 is above", "f-final 0.5", "cutoff only grows"),
    ),
    "train: colour f0 above the colour's final cutoff": Case(
        "train",
        train_with(f"{MODEL}.fourier.f0-color", "0.6", f"{MODEL}.fourier.f-final-color", "0.5"),
        ("f0-color 0.6 is above", "f-final-color 0.5", "cutoff only grows"),
    ),
    "train: colour final cutoff above 1": Case(
        "train", train_with(f"{MODEL}.fourier.f-final-color", "2"), ("f-final-color 2", "(0, 1]")
    ),
    "train: mirror boundaries of a band that is off": Case(
        "train",
        train_with(f"{MODEL}.fourier.boundary", "mirror", f"{MODEL}.fourier.enabled", "False"),
        ("boundary mirror", "curriculum", "off", "nothing is filtered", "drop"),
    ),
    "train: density axes of a band that is off": Case(
        "train",
        train_with(f"{MODEL}.fourier.density-axes", "0", "1", f"{MODEL}.fourier.enabled", "False"),
        ("density-axes 0 1", "curriculum", "off", "nothing is filtered", "drop"),
    ),
    "train: density axes beyond z": Case(
        "train", train_with(f"{MODEL}.fourier.density-axes", "0", "3"), ("density-axes 0 3", "0 1 2")
    ),
    "train: density axes twice": Case(
        "train", train_with(f"{MODEL}.fourier.density-axes", "1", "1"), ("density-axes 1 1", "distinct")
    ),
    "train: final cutoff 0": Case("train", train_with(f"{MODEL}.fourier.f-final", "0"), ("f-final 0", "(0, 1]")),
    "train: negative ramp": Case("train", train_with(f"{MODEL}.fourier.ramp-fraction", "-1"), ("ramp-fraction -1",)),
    "train: negative plane leakage": Case(
        "train", train_with(f"{MODEL}.fourier.plane-leakage", "-1"), ("plane-leakage -1", ">= 0")
    ),
    "train: negative depth-smoothness weight": out_of_range(f"{MODEL}.depth-smoothness-weight", "-1", ">= 0"),
    "train: negative distortion weight": out_of_range(f"{MODEL}.distortion-weight", "-0.01", ">= 0"),
    "train: zero depth-smoothness patches": out_of_range(f"{MODEL}.depth-smoothness-patches", "0", ">= 1"),
    "train: negative entropy weight": out_of_range(f"{MODEL}.entropy-weight", "-0.001", ">= 0"),
    "train: negative feature frequencies": out_of_range(f"{MODEL}.field.feature-frequencies", "-1", ">= 0"),
    "train: negative view frequencies": out_of_range(f"{MODEL}.field.view-frequencies", "-2", ">= 0"),
    "train: an entropy threshold past full opacity": out_of_range(f"{MODEL}.entropy-threshold", "1.5", "[0, 1]"),
    "train: negative unseen rays for the entropy": out_of_range(f"{MODEL}.entropy-unseen-rays", "-3", ">= 0"),
    "train: floaters scaling from past the run": out_of_range(
        f"{MODEL}.floaters-gradient-scaling-from", "1.5", "[0, 1]"
    ),
    "train: a random background from past the run": out_of_range(f"{MODEL}.random-background-from", "1.5", "[0, 1]"),
    "train: a start for floaters scaling that is off": Case(
        "train",
        train_with(f"{MODEL}.floaters-gradient-scaling-from", "0.5"),
        ("floaters-gradient-scaling-from 0.5", "off", "floaters-gradient-scaling True"),
    ),
    "train: a depth-smoothness patch of one pixel": out_of_range(f"{MODEL}.depth-smoothness-patch-size", "1", ">= 2"),
    "train: a depth-smoothness patch larger than the images": Case(
        "train",
        train_with(f"{MODEL}.depth-smoothness-weight", "0.1", f"{MODEL}.depth-smoothness-patch-size", "101"),
        ("depth-smoothness-patch-size 101 does not fit the 100×100", "at most 100"),
    ),
    "train: --steps-per-save 0": Case("train", train_with("--steps-per-save", "0"), ("--steps-per-save 0", ">= 1")),
    "train: --log-every 0": Case("train", train_with("--log-every", "0"), ("--log-every 0", ">= 1")),
    "train: step ratio 0": Case("train", train_with(f"{MODEL}.step-ratio", "0"), ("step-ratio 0", "> 0")),
    "train: negative distance scale": Case(
        "train", train_with(f"{MODEL}.distance-scale", "-25"), ("distance-scale -25", "> 0")
    ),
    "train: zero rays per batch": Case(
        "train", train_with("--pipeline.datamanager.rays-per-batch", "0"), ("rays-per-batch 0", ">= 1")
    ),
    "train: zero components": Case(
        "train", train_with(f"{MODEL}.field.density-components", "0", "0", "0"), ("density-components 0 0 0",)
    ),
    "train: zero threads": Case("train", train_with("--threads", "0"), ("--threads 0",)),
    "train: early-stop transmittance above 0.5": out_of_range(f"{ACCEL}.early-stop-transmittance", "1", "[0, 0.5]"),
    "train: zero early-stop segment": out_of_range(f"{ACCEL}.early-stop-segment", "0", ">= 1"),
    "train: zero render chunk": out_of_range(f"{ACCEL}.render-chunk-rays", "0", ">= 1"),
    "train: negative checkpoint threshold": out_of_range(f"{ACCEL}.checkpoint-above", "-1", ">= 0"),
    "train: zero checkpoint chunk": out_of_range(f"{ACCEL}.checkpoint-chunk", "0", ">= 1"),
    "train: negative dense training size": out_of_range(f"{ACCEL}.dense-train-max-vertices", "-1", ">= 0"),
    "train: negative dense render budget": out_of_range(f"{ACCEL}.dense-render-max-mb", "-1", ">= 0"),
    "train: an event fraction outside the run": Case(
        "train",
        train_with(f"{MODEL}.occupancy-update-fractions", "0.5", "1.5"),
        (f"{MODEL}.occupancy-update-fractions 0.5 1.5", "does not fit a run of 10 iterations", "strictly between"),
    ),
    "train: upsamples too dense for a short run": Case(
        "train",
        train_with(f"{MODEL}.field.upsample-fractions", "0.01", "0.02", iters=10),
        (f"{MODEL}.field.upsample-fractions 0.01 0.02", "at least 100 here"),
    ),
    "train: AdamW beta >= 1": Case("train", train_with("--optimizer.betas", "1.5", "0.9"), ("--optimizer.betas 1.5",)),
    "train: AdamW beta after a reset >= 1": Case(
        "train", train_with("--optimizer.betas-after-reset", "0.9", "1.0"), ("--optimizer.betas-after-reset 0.9 1.0",)
    ),
    "train: TV decay ratio <= 0": out_of_range(f"{MODEL}.tv-decay-ratio", "0", "> 0"),
    "train: revive patience 0": out_of_range(f"{MODEL}.field.revive-patience", "0", ">= 1"),
    # -- train: resuming ---------------------------------------------------------------------------------------------
    "train: resume a config from another version": Case(
        "train",
        resume(lambda cfg, tmp: with_config(cfg, tmp, other_version)),
        ("config format 99", "9.0.0", "retrain"),
    ),
    "train: resume with every checkpoint truncated": Case(
        "train", resume(truncate_all_checkpoints), ("none of the", "checkpoints", "is readable")
    ),
    "train: resume a folder that is no run": Case(
        "train", lambda tmp, _: ["fourierf-vm", "--load-dir", str(tmp)], ("config file not found", "config.json")
    ),
    # -- eval --------------------------------------------------------------------------------------------------------
    "eval: config from another version": Case(
        "eval", on_run(EVAL, lambda cfg, tmp: with_config(cfg, tmp, other_version)), ("config format 99", "install")
    ),
    "eval: config with a field this version lacks": Case(
        "eval",
        on_run(EVAL, lambda cfg, tmp: with_config(cfg, tmp, newer_field)),
        ("new_option_of_a_later_version", "does not match this fourierf version"),
    ),
    "eval: malformed config JSON": Case(
        "eval", on_run(EVAL, lambda cfg, tmp: write(copy_run(cfg, tmp), "{not json")), ("config.json", "not valid JSON")
    ),
    "eval: a checkpoint given as the config": Case(
        "eval", on_run(EVAL, truncated_checkpoint), ("cut.ckpt", "not valid JSON")
    ),
    "eval: truncated checkpoint": Case(
        "eval",
        on_run(
            EVAL, extra=lambda tmp, cfg: ["--checkpoint", str(truncated_checkpoint(cfg, tmp)), "--force-checkpoint"]
        ),
        ("cut.ckpt", "unreadable", "truncated"),
    ),
    "eval: every checkpoint truncated": Case("eval", on_run(EVAL, truncate_all_checkpoints), ("none of the",)),
    "eval: a .npy given as the checkpoint": Case(
        "eval",
        on_run(
            EVAL,
            extra=lambda tmp, _: ["--checkpoint", str(np_saved(tmp / "poses.ckpt", np.zeros(3))), "--force-checkpoint"],
        ),
        ("poses.ckpt", "unreadable"),
    ),
    "eval: --data of the wrong dataset kind": Case(
        "eval", on_run(EVAL, extra=lambda tmp, _: ["--data", str(llff(tmp))]), ("poses_bounds.npy", "llff-data")
    ),
    "eval: --data with zero test views": Case(
        "eval",
        on_run(EVAL, extra=lambda tmp, _: ["--data", str(edit_transforms(blender(tmp), "test", no_frames))]),
        ("transforms_test.json", "non-empty"),
    ),
    "eval: the run's scene folder was moved": Case(
        "eval",
        on_run(EVAL, lambda cfg, tmp: with_config(cfg, tmp, lambda p: moved_scene(p, tmp / "gone"))),
        ("data folder not found", "gone", "--data"),
    ),
    # -- render ------------------------------------------------------------------------------------------------------
    "render: config from another version": Case(
        "render", on_run(RENDER, lambda cfg, tmp: with_config(cfg, tmp, other_version)), ("config format 99",)
    ),
    "render: every checkpoint truncated": Case("render", on_run(RENDER, truncate_all_checkpoints), ("none of the",)),
    "render: --data with mixed image sizes": Case(
        "render",
        on_run(RENDER, extra=lambda tmp, _: ["--split", "train", "--data", str(mixed_blender_sizes(tmp))]),
        ("r_76.png",),
    ),
    # -- export ------------------------------------------------------------------------------------------------------
    "export: config from another version": Case(
        "export", on_run(EXPORT, lambda cfg, tmp: with_config(cfg, tmp, other_version)), ("config format 99",)
    ),
    "export: truncated checkpoint": Case(
        "export",
        on_run(
            EXPORT, extra=lambda tmp, cfg: ["--checkpoint", str(truncated_checkpoint(cfg, tmp)), "--force-checkpoint"]
        ),
        ("cut.ckpt", "unreadable"),
    ),
    "export: malformed config JSON": Case(
        "export", on_run(EXPORT, lambda cfg, tmp: write(copy_run(cfg, tmp), "[1, 2")), ("not valid JSON",)
    ),
    # -- a new user's first hour (issue 22) ---------------------------------------------------------------------------
    "train: an all-zero transform_matrix": Case(
        "train",
        lambda tmp, _: train_on(edit_transforms(blender(tmp), "train", zero_pose), tmp),
        ("transforms_train.json, frame 1", "not a camera pose", "singular", "fix or remove that frame"),
    ),
    "train: a final grid larger than the memory": Case(
        "train",
        train_with(f"{MODEL}.field.n-voxels-final", "1000000000000"),
        (f"{MODEL}.field.n-voxels-final 1000000000000", "GiB", "pass at most"),
    ),
    "train: --data twice, different folders": Case(
        "train",
        lambda tmp, _: train_on(TINY_SCENE, tmp, "blender-data", "--data", str(blender(tmp))),
        ("two scene folders", "--data once"),
    ),
    "train: resume with a flag it would ignore": Case(
        "train",
        lambda tmp, cfg: [*resume(intact)(tmp, cfg), "--max-num-iterations", "999"],
        ("--max-num-iterations would be ignored", "its own saved config", "--load-dir"),
    ),
    "eval: another run's checkpoint": Case(
        "eval",
        on_run(EVAL, extra=lambda tmp, cfg: ["--checkpoint", str(foreign_checkpoint(cfg, tmp))]),
        ("foreign.ckpt", "not one of this run's checkpoints", "--force-checkpoint"),
    ),
    "eval: an output path that cannot be written": Case(
        "eval",
        on_run(["--load-config", "{config}", "--output-path", "{tmp}/file.txt/eval.json"], extra=plain_file),
        ("cannot write to", "file.txt", "--output-path"),
    ),
    "eval: an output path that is a folder": Case(
        "eval",
        on_run(["--load-config", "{config}", "--output-path", "{tmp}", "--render-dir", "none"]),
        ("--output-path", "is a folder", "eval.json"),
    ),
    "eval: an existing output path": Case(
        "eval",
        on_run(EVAL, extra=lambda tmp, _: existing_report(tmp)),
        ("--output-path", "already exists", "--overwrite"),
    ),
    "eval: a render dir holding files": Case(
        "eval",
        on_run(
            ["--load-config", "{config}", "--output-path", "{tmp}/eval.json", "--render-dir", "{tmp}/mine"],
            extra=lambda tmp, _: folder_of_notes(tmp),
        ),
        ("--render-dir", "not empty", "--overwrite"),
    ),
    "eval: a render dir of other files even with --overwrite": Case(
        "eval",
        on_run(
            ["--load-config", "{config}", "--output-path", "{tmp}/eval.json", "--render-dir", "{tmp}/mine"],
            extra=lambda tmp, _: [*folder_of_notes(tmp), "--overwrite"],
        ),
        ("--render-dir", "notes.txt", "only a folder of renders"),
    ),
    "eval: zero threads": Case("eval", on_run(EVAL, extra=lambda tmp, _: ["--threads", "0"]), ("--threads 0",)),
    "export: zero threads": Case("export", on_run(EXPORT, extra=lambda tmp, _: ["--threads", "0"]), ("--threads 0",)),
    "render: a frame larger than the memory": Case(
        "render",
        on_run(RENDER, extra=lambda tmp, _: ["--resolution-scale", "3000"]),
        ("--resolution-scale 3000", "GiB"),
    ),
    "export: an output path that cannot be written": Case(
        "export",
        on_run(
            ["marching-cubes", "--load-config", "{config}", "--output-path", "{tmp}/file.txt/m.ply"], extra=plain_file
        ),
        ("cannot write to", "file.txt", "--output-path"),
    ),
    # -- train: captures (nerfstudio transforms.json, COLMAP models) ------------------------------------------------
    "train: transforms.json frame whose image is missing": Case(
        "train",
        lambda tmp, _: train_on(capture(tmp, lambda root: (root / "images" / "frame_00002.png").unlink()), tmp, *NS),
        ("transforms.json, frame 2", "not found"),
    ),
    "train: several transforms.json images missing": Case(
        "train",
        lambda tmp, _: train_on(
            capture(tmp, lambda root: [(root / "images" / f"frame_{i:05d}.png").unlink() for i in (2, 5, 7)]), tmp, *NS
        ),
        ("3 of 10 frames", "frame 2 (images/frame_00002.png)", "frame 7", "--skip-missing-images True"),
    ),
    "train: one photo named by two frames with different cameras": Case(
        "train",
        lambda tmp, _: train_on(capture(tmp, frame_keys(4, file_path="images/frame_00003.png")), tmp, *NS),
        ("frames 3 and 4 (images/frame_00003.png)", "different cameras", "keep one frame per photo"),
    ),
    "train: unknown camera_model": Case(
        "train",
        lambda tmp, _: train_on(capture(tmp, set_keys(camera_model="EQUIRECTANGULAR")), tmp, *NS),
        ("'EQUIRECTANGULAR'", "OPENCV_FISHEYE"),
    ),
    "train: non-finite pose in transforms.json": Case(
        "train",
        lambda tmp, _: train_on(capture(tmp, frame_keys(1, transform_matrix=[[float("nan")] * 4] * 4)), tmp, *NS),
        ("transforms.json", "frame 1"),
    ),
    "train: mixed image sizes without per-frame intrinsics": Case(
        "train",
        lambda tmp, _: train_on(
            capture(tmp, lambda root: write_image(root / "images" / "frame_00003.png", 3, 4, 3)), tmp, *NS
        ),
        ("frame_00003.png",),
    ),
    "train: a COLMAP model with no images": Case(
        "train",
        lambda tmp, _: train_on(empty_colmap_model(tmp), tmp, "colmap-data"),
        ("colmap/sparse/0", "no registered images"),
    ),
    # -- issue 85 ----------------------------------------------------------------------------------------------------
    "train: --seed -1": out_of_range("--seed", "-1", "0..2^63-1"),
    "train: --seed 1e23 written out": out_of_range("--seed", "100000000000000000000000", "0..2^63-1"),
    "train: an initial grid larger than the memory": Case(
        "train",
        train_with(f"{MODEL}.field.n-voxels-init", "1000000000000"),
        (f"{MODEL}.field.n-voxels-init 1000000000000", "initial grid", "GiB", "pass at most"),
    ),
    "train: resume with a flag equal to the preset's default": Case(
        "train",
        lambda tmp, cfg: [*resume(intact)(tmp, cfg), "--max-num-iterations", "10000"],
        ("--max-num-iterations would be ignored", "its own saved config"),
    ),
    "train: resume with --data of another scene": Case(
        "train",
        lambda tmp, cfg: [*resume(intact)(tmp, cfg), "--data", str(shifted_scene(tmp))],
        ("is not the scene the run", "training cameras at other positions", "start a new run"),
    ),
    "train: deeply nested transforms JSON": Case(
        "train",
        lambda tmp, _: train_on(write(blender(tmp) / "transforms_train.json", deeply_nested()).parent, tmp),
        ("transforms_train.json", "nests its JSON too deeply"),
    ),
    "train: an LLFF pose array of strings": Case(
        "train",
        lambda tmp, _: train_on(np_saved(llff(tmp) / "poses_bounds.npy", np.full((10, 17), "a")), tmp, "llff-data"),
        ("poses_bounds.npy", "<U1 values, not real numbers"),
    ),
    "train: a zero focal length in poses_bounds.npy": Case(
        "train",
        lambda tmp, _: train_on(llff_with(tmp, with_column(14, 0.0)), tmp, "llff-data"),
        ("poses_bounds.npy", "focal length of 0 or below", "re-run pose estimation"),
    ),
    "train: a 16-bit PNG declaring 40000x40000 pixels": Case(
        "train", lambda tmp, _: train_on(bomb_scene(tmp), tmp), ("r_27.png", "40000x40000", "decompression bomb")
    ),
    "eval: deeply nested config JSON": Case(
        "eval",
        on_run(EVAL, lambda cfg, tmp: write(copy_run(cfg, tmp), deeply_nested())),
        ("nests its JSON too deeply",),
    ),
    "train: resume a config.json with a value out of range": Case(
        "train",
        resume(lambda cfg, tmp: with_config(cfg, tmp, config_value("pipeline.model.step_ratio", 0))),
        ("config.json holds a value out of range", "step-ratio 0"),
    ),
    "eval: a config.json value out of range": Case(
        "eval",
        on_run(EVAL, lambda cfg, tmp: with_config(cfg, tmp, config_value("seed", -1))),
        ("config.json holds a value out of range", "--seed -1", "restore the value"),
    ),
    "render: a config.json grid larger than the memory": Case(
        "render",
        on_run(
            RENDER, lambda cfg, tmp: with_config(cfg, tmp, config_value("pipeline.model.field.n_voxels_final", 10**15))
        ),
        ("config.json", "GiB", "more memory"),
    ),
    "eval: a checkpoint with a negative step": Case(
        "eval", on_run(EVAL, extra=edited_checkpoint(lambda state: state.update(step=-5))), ("edited.ckpt", "below 0")
    ),
    "eval: a checkpoint missing a weight": Case(
        "eval", on_run(EVAL, extra=edited_checkpoint(drop_a_weight)), ("does not hold this run's model", "missing")
    ),
    "eval: a checkpoint with a foreign weight": Case(
        "eval", on_run(EVAL, extra=edited_checkpoint(add_a_weight)), ("unknown foreign.weight",)
    ),
    "export: a checkpoint without model weights": Case(
        "export",
        on_run(EXPORT, extra=edited_checkpoint(lambda state: state.pop("pipeline"))),
        ("edited.ckpt", "holds no model weights"),
    ),
    "render: --n-frames of a billion": Case(
        "render",
        on_run(["orbit", "--load-config", "{config}", "--output-dir", "{tmp}/r", "--n-frames", "1000000000"]),
        ("--n-frames must be in 1..100000", "1000000000"),
    ),
}


def run_entry(entry: str, args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """Run an entry point's ``main(args)`` the way its console script does; returns exit code and stderr."""
    with pytest.raises(SystemExit) as info:
        run_cli(lambda: ENTRIES[entry](args), args)
    return info.value.code, capsys.readouterr().err


def run_dirs(root: Path) -> list[Path]:
    return [p.parent for p in root.rglob("config.json")]


@pytest.mark.parametrize("name", list(CASES))
def test_bad_input_exits_2_with_one_message_and_its_fix(
    name: str, tmp_path: Path, trained_config: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    case = CASES[name]
    args = case.args(tmp_path, trained_config)
    code, err = run_entry(case.entry, args, capsys)
    flat = " ".join(err.split())  # paths are never wrapped, but keep the checks immune to wrapping anyway
    assert code == EXIT_USER_ERROR, err
    assert flat.count("error:") == 1 and flat.count("fix:") == 1, err
    for text in case.expected:
        assert text in flat, f"{text!r} missing from:\n{err}"
    assert "Traceback" not in err
    if case.entry == "train" and "--load-dir" not in args:
        assert not run_dirs(tmp_path / "out"), "a rejected run must not leave a run directory behind"


def test_option_checks_run_before_any_data_is_read(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A bad option is reported even when the scene is broken too: the cheapest check comes first."""
    args = train_on(tmp_path / "no_scene", tmp_path, f"{MODEL}.fourier.f0-density", "2")
    code, err = run_entry("train", args, capsys)
    assert code == EXIT_USER_ERROR and "f0-density 2" in err


def test_verbose_shows_the_traceback_and_still_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = [*train_on(TINY_SCENE, tmp_path, f"{MODEL}.fourier.f0-density", "1.5"), "--verbose"]
    code, err = run_entry("train", args, capsys)
    assert code == EXIT_USER_ERROR
    assert "Traceback" in err and "UserError" in err
    assert " ".join(err.split()).count("error:") == 1


@pytest.mark.parametrize("name", ["train: f0 > 1", "export: truncated checkpoint"])
def test_installed_scripts_exit_2_without_a_traceback(name: str, tmp_path: Path, trained_config: Path) -> None:
    """The same cases through the real console scripts (a fresh interpreter, the installed entry points)."""
    case = CASES[name]
    script = venv_script(f"fourierf-{case.entry}")
    if not script.exists():
        pytest.skip(f"{script} is not installed (pip install -e . first)")
    proc = subprocess.run(
        [str(script), *case.args(tmp_path, trained_config)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=REPO_ROOT,
        env={**os.environ, "COLUMNS": "200", "OMP_NUM_THREADS": "1"},
    )
    flat = " ".join(proc.stderr.split())
    assert proc.returncode == EXIT_USER_ERROR, proc.stderr
    assert all(text in flat for text in case.expected), proc.stderr
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize("method", sorted(all_methods))
def test_every_preset_passes_the_option_checks_also_with_the_real_scene_settings(method: str) -> None:
    """The range checks must never reject a shipped setting (synthetic preset, or the real-scene values on top)."""
    config = copy.deepcopy(all_methods[method])
    check_training_options(config)
    apply_real_scene_preset(config, all_methods[method])
    check_training_options(config)


def test_16bit_and_grayscale_images_are_accepted(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Not every odd image is bad input: 16-bit and grayscale PNGs train like 8-bit RGBA ones (exit 0)."""
    scene = blender(tmp_path)
    rgba = iio.imread(scene / "train" / "r_27.png")
    gray = rgba[..., :3].mean(axis=-1)
    iio.imwrite(scene / "train" / "r_27.png", (gray * 257).astype(np.uint16))  # 16-bit grayscale
    iio.imwrite(scene / "train" / "r_76.png", gray.astype(np.uint8))  # 8-bit grayscale
    run_cli(lambda: train_script.main(train_on(scene, tmp_path, iters=6)), [])
    assert len(run_dirs(tmp_path / "out")) == 1
    assert "error:" not in capsys.readouterr().err


# -- accepted, with a warning (issue 85, item 7) ----------------------------------------------------------------------
def set_pose(index: int, edit: Callable[[list], None]) -> Callable[[dict], None]:
    return lambda meta: edit(meta["frames"][index]["transform_matrix"])


def far_camera(matrix: list) -> None:
    matrix[0][3] = 1e30


def skewed_bottom_row(matrix: list) -> None:
    matrix[3] = [0.0, 0.0, 0.1, 1.0]


def duplicate_frame(meta: dict) -> None:
    meta["frames"].append(copy.deepcopy(meta["frames"][0]))


def parse_blender(scene: Path) -> None:
    BlenderDataParserConfig(data=scene).setup().get_outputs("train")


def parse_llff(scene: Path) -> None:
    LLFFDataParserConfig(data=scene).setup().get_outputs("train")


def band_flag_without_band(tmp: Path) -> None:
    args = [*train_on(TINY_SCENE, tmp, f"{MODEL}.fourier.f0-density", "0.5")]
    args[0] = "tensorf-vm"
    finalize(train_script.parse_args(args), train_script.given_options(args))


WARNED: dict[str, tuple[Callable[[Path], None], tuple[str, ...]]] = {
    "a camera at 1e30": (
        lambda tmp: parse_blender(edit_transforms(blender(tmp), "train", set_pose(1, far_camera))),
        ("frame 1", "1e+30", "farther from the cameras' centre"),
    ),
    "a transform whose bottom row is not (0, 0, 0, 1)": (
        lambda tmp: parse_blender(edit_transforms(blender(tmp), "train", set_pose(2, skewed_bottom_row))),
        ("frame 2", "bottom row is not (0, 0, 0, 1)", "top 3x4"),
    ),
    "a negative focal in poses_bounds.npy": (
        lambda tmp: parse_llff(llff_with(tmp, with_column(14, -400.0))),
        ("negative focal length", "mirrored"),
    ),
    "duplicate Blender frames": (
        lambda tmp: parse_blender(edit_transforms(blender(tmp), "train", duplicate_frame)),
        ("frames 0 and 4 both name", "counts twice"),
    ),
    "tensorf-vm with an initial Fourier cutoff": (
        band_flag_without_band,
        (f"{MODEL}.fourier.f0-density", "curriculum, which is off", "tensorf-vm", "ignored"),
    ),
}


@pytest.mark.parametrize("name", list(WARNED))
def test_a_likely_mistake_is_accepted_with_a_warning(
    name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    accept, expected = WARNED[name]
    accept(tmp_path)
    flat = " ".join(capsys.readouterr().err.split())
    assert "warning:" in flat
    for text in expected:
        assert text in flat, f"{text!r} missing from:\n{flat}"
