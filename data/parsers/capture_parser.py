"""One road from a photo capture (nerfstudio ``transforms.json`` or a COLMAP model) to a scene.

Subclasses only read their files into a :class:`~fourierf_plugin.data.capture.Capture` (``read_capture``); this base
decides whether the scene is forward-facing or an object, normalises the poses for it (``capture_scene``), picks the
splits and the few-shot views, loads the photos at one size (``capture_images``) and declares the scene's effects.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import torch
import tyro

from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.cameras.distortion import has_distortion, undistorted_directions
from fourierf_plugin.data.capture import Capture
from fourierf_plugin.data.dataparser_base import DataParser, DataParserConfig, DataparserOutputs, Split
from fourierf_plugin.data.dataparser_transforms import DataparserTransform, fit_transform
from fourierf_plugin.data.parsers.capture_images import (
    auto_downscale,
    has_alpha,
    load_frames,
    most_common_size,
    target_size,
    variants,
)
from fourierf_plugin.data.parsers.capture_scene import (
    KindDecision,
    NormalisedScene,
    camera_to_worlds,
    decide_scene_kind,
    normalise_forward_facing,
    normalise_object,
    normalise_unbounded,
    share_beyond_cameras,
)
from fourierf_plugin.data.parsers.llff import LLFF_DECLARATION
from fourierf_plugin.data.poses import Orientation
from fourierf_plugin.data.scene_effects import SceneDeclaration
from fourierf_plugin.data.view_selection import check_view_counts, explicit_views, kmeans_views, validation_views
from fourierf_plugin.utils.console import warn
from fourierf_plugin.utils.errors import fail

SPLIT_KEYS = ("train", "val", "test")
_SPLIT_FIX = "list the frames of each split in train_filenames/val_filenames/test_filenames, or change --test-every"


def object_declaration(background_known: bool, reason: str) -> SceneDeclaration:
    """An object (360°) capture: euclidean rays in a bounded box, no view dependence (too few views); a white
    background when the photos say where the background is (alpha or masks), else none (photos)."""
    return SceneDeclaration(
        background="white" if background_known else "none",
        ray_space="euclidean",
        view_dependent=False,
        occlusion_regularization=False,
        bounded=True,
        reason=reason,
    )


def unbounded_declaration(reason: str) -> SceneDeclaration:
    """An object photographed with its surroundings: contracted rays (the object's region kept, the rest of the
    world squeezed into a shell around it), photos' own background learnt as scene, no view dependence."""
    return SceneDeclaration(
        background="none",
        ray_space="contracted",
        view_dependent=False,
        occlusion_regularization=False,
        bounded=True,
        reason=reason,
    )


def check_lenses(cameras: Cameras, names: list[str], source: Path) -> None:
    """A clear error, before training, for a calibration whose distortion cannot be undone over the whole image
    (rays are formed by undoing it; the border is where it folds over first)."""
    if cameras.distortion is None or not has_distortion(cameras.distortion, cameras.camera_model):
        return
    w, h = cameras.width, cameras.height
    u = torch.cat([torch.arange(w) + 0.5, torch.full((h,), w - 0.5), torch.arange(w) + 0.5, torch.full((h,), 0.5)])
    v = torch.cat([torch.full((w,), 0.5), torch.arange(h) + 0.5, torch.full((w,), h - 0.5), torch.arange(h) + 0.5])
    for i, name in enumerate(names):
        x = (u.double() - float(cameras.cx[i])) / float(cameras.fx[i])
        y = (v.double() - float(cameras.cy[i])) / float(cameras.fy[i])
        try:
            undistorted_directions(x, y, cameras.distortion[i].double(), cameras.camera_model)
        except ValueError as err:
            fail(
                f"{source}, frame {name}: its lens distortion cannot be undone over the image ({err})",
                "check the calibration (k1 k2 k3 k4 p1 p2 and camera_model), or undistort the photos first",
            )


_WARNED: set[str] = set()


def warn_principal_points(capture: Capture) -> None:
    """A warning (once per file) naming the frames whose principal point (cx, cy) lies outside their image: a
    calibration in other units or of another image size, whose rays would all leave the cameras far off-axis."""
    off = [
        f
        for f in capture.frames
        if not (0 <= f.intrinsics.cx <= f.intrinsics.width and 0 <= f.intrinsics.cy <= f.intrinsics.height)
    ]
    if not off or str(capture.source) in _WARNED:
        return
    _WARNED.add(str(capture.source))
    k = off[0].intrinsics
    more = f" (and {len(off) - 1} more frames)" if len(off) > 1 else ""
    warn(
        f"{capture.source}: the principal point of {off[0].image_path.name}{more} lies outside its image (cx {k.cx:g}, "
        f"cy {k.cy:g} for a {k.width}x{k.height} image); check that cx and cy are in pixels of that image size"
    )


class CaptureParser(DataParser):
    """Base of the capture parsers; ``read_capture`` is the only format-specific part."""

    config: CaptureParserConfig

    def __init__(self, config: CaptureParserConfig) -> None:
        super().__init__(config)
        self._capture: Capture | None = None
        self._scene: NormalisedScene | None = None
        self._target: tuple[int, int] | None = None

    def read_capture(self) -> Capture:  # pragma: no cover - interface
        raise NotImplementedError

    # -- what the scene is ------------------------------------------------------------------------------------------
    def capture(self) -> Capture:
        """The capture, read once per parser."""
        if self._capture is None:
            capture = self.read_capture()
            if not capture.frames:
                fail(f"{capture.source} holds no registered images", "re-run structure from motion on more photos")
            models = sorted({f.intrinsics.camera_model for f in capture.frames})
            if len(models) > 1:
                fail(
                    f"{capture.source} mixes camera models {models}; a scene uses one",
                    "undistort the photos into one model, or split the capture by camera",
                )
            warn_principal_points(capture)
            self._capture = capture
        return self._capture

    def scene_kind(self) -> KindDecision:
        """The user's --scene-kind (or the one a saved run pinned, with its reason), else the decision from the poses
        (``capture_scene.decide_scene_kind``)."""
        cfg = self.config
        if cfg.scene_kind != "auto":
            return KindDecision(cfg.scene_kind, cfg.scene_kind_reason or "set by --scene-kind")
        decision = decide_scene_kind(self.capture())
        if decision.kind == "object" and not self._background_known():
            decision = KindDecision("unbounded", self._unbounded_reason(decision.reason))
        return KindDecision(decision.kind, f"auto: {decision.reason}")

    def _unbounded_reason(self, cameras: str) -> str:
        share = share_beyond_cameras(self.capture(), self.config.orientation)
        points = "" if share is None else f"; {share:.0%} of the sparse points lie beyond the cameras"
        return (
            f"{cameras}, and the photos carry no alpha or masks{points}: the object is modelled with its "
            "surroundings (space beyond the cameras contracted)"
        )

    def declaration(self) -> SceneDeclaration:
        decision = self.scene_kind()
        if decision.kind == "forward-facing":
            return dataclasses.replace(LLFF_DECLARATION, reason=decision.reason)
        if decision.kind == "unbounded":
            return unbounded_declaration(decision.reason)
        return object_declaration(self._background_known(), decision.reason)

    def _background_known(self) -> bool:
        """Masks, or an alpha channel in the first photo (its header only: declarations read no images)."""
        capture = self.capture()
        if any(f.mask_path is not None for f in capture.frames):
            return True
        present = variants(capture.frames[0].image_path)
        return bool(present) and has_alpha(next(iter(present.values())))

    def normalised(self) -> NormalisedScene:
        if self._scene is None:
            cfg, capture = self.config, self.capture()
            kind = self.scene_kind().kind
            if kind == "forward-facing":
                self._scene = normalise_forward_facing(capture, cfg.bd_factor)
            elif kind == "unbounded":
                self._scene = normalise_unbounded(capture, cfg.orientation)
            else:
                self._scene = normalise_object(capture, cfg.orientation, cfg.scene_scale)
        return self._scene

    # -- splits -----------------------------------------------------------------------------------------------------
    def _listed(self, capture: Capture) -> dict[str, list[int]]:
        """The file's own splits (``train_filenames`` ...) as frame indices; every name must be a frame's file."""
        index = {os.path.normpath(f.image_path): i for i, f in enumerate(capture.frames)}
        listed: dict[str, list[int]] = {}
        for key, names in (capture.splits or {}).items():
            ids = set()
            for name in names:
                i = index.get(os.path.normpath(capture.source.parent / name))
                if i is None:
                    fail(
                        f"{capture.source}: {key}_filenames names {name}, which is not the file_path of any frame",
                        f"list only file paths of frames (as written in their file_path) in {key}_filenames",
                    )
                ids.add(i)
            listed[key] = sorted(ids)
        return listed

    def base_splits(self) -> tuple[list[int], list[int], list[int] | None]:
        """(train, test, val as listed or None): the file's lists when it has them, else every ``test_every``-th
        frame (index 0 included, as LLFF's llffhold) held out for test."""
        capture = self.capture()
        n, every = len(capture.frames), self.config.test_every
        listed = self._listed(capture)
        if not listed:
            test = list(range(0, n, every))
            return [i for i in range(n) if i % every], test, None
        val = listed.get("val")
        if "test" in listed:
            test = listed["test"]
        elif val is not None:
            test = val
        else:
            test = [i for i in range(n) if i not in set(listed["train"])]
        held = set(test) | set(val or [])
        train = listed["train"] if "train" in listed else [i for i in range(n) if i not in held]
        return train, test, val

    def train_ids(self) -> list[int]:
        cfg, capture = self.config, self.capture()
        train, test, _ = self.base_splits()
        source = str(capture.source)
        if not train:
            fail(f"{source} leaves no training images (all {len(capture.frames)} are held out)", _SPLIT_FIX)
        if cfg.view_ids is not None:
            chosen = explicit_views(cfg.view_ids, len(capture.frames), source)
            outside = [i for i in chosen if i not in set(train)]
            if outside:
                why = "hold-out test images" if set(outside) <= set(test) else "not training images"
                fail(
                    f"--view-ids {outside} are {why} of {source} (the test split is {test})",
                    f"choose training ids (frame indices in file-name order) among {train}",
                )
            return chosen
        if cfg.num_views is not None:
            if cfg.num_views > len(train):
                fail(
                    f"--num-views {cfg.num_views} is more than the {len(train)} training images of {source}",
                    f"use at most {len(train)} views",
                )
            centres = self.normalised().camera_to_worlds[train, :, 3]
            return [train[j] for j in kmeans_views(centres, cfg.num_views, seed=cfg.kmeans_seed)]
        return train

    def split_ids(self, split: Split) -> list[int]:
        """Frame indices (file-name order) of ``split``. Val: the file's list, else ``val_views`` training images
        the run does not train on, evenly spaced (as LLFF); the test images when every training image is in use."""
        train, test, val = self.base_splits()
        if split == "test":
            ids = test
        elif split == "train":
            ids = self.train_ids()
        elif val is not None:
            ids = val
        else:
            ids = validation_views(train, self.train_ids(), test, self.config.val_views)
        if not ids:
            fail(f"the {split} split of {self.capture().source} is empty", _SPLIT_FIX)
        return ids

    # -- outputs ----------------------------------------------------------------------------------------------------
    def downscale(self) -> int:
        if self.config.downscale is not None:
            return self.config.downscale
        return auto_downscale(*most_common_size(self.capture().frames))

    def _check_config(self) -> None:
        cfg = self.config
        if cfg.downscale is not None and cfg.downscale < 1:
            fail(f"--downscale must be >= 1, got {cfg.downscale}", "use 1 for full resolution, 2 for half, ...")
        if cfg.test_every < 2:
            fail(f"--test-every must be >= 2, got {cfg.test_every}", "8 holds out every 8th image, as LLFF")
        check_view_counts(cfg.num_views, cfg.val_views)
        if not cfg.bd_factor > 0:
            fail(f"--bd-factor must be > 0, got {cfg.bd_factor}", "the LLFF default is 0.75")
        if not (np.isfinite(cfg.scene_scale) and cfg.scene_scale > 0):
            fail(f"--scene-scale must be > 0, got {cfg.scene_scale}", "1 keeps the box the points or cameras give")

    def get_outputs(self, split: Split) -> DataparserOutputs:
        self._check_config()
        capture, scene = self.capture(), self.normalised()
        ids = self.split_ids(split)
        frames = [capture.frames[i] for i in ids]
        downscale = self.downscale()
        if self._target is None:
            self._target = target_size(capture.frames, downscale, capture.source)
        width, height = self._target
        images = load_frames(frames, downscale, self._target, capture.source)
        sx = np.array([width / f.intrinsics.width for f in frames])
        sy = np.array([height / f.intrinsics.height for f in frames])

        def column(values: list[float], scale: np.ndarray) -> torch.Tensor:
            return torch.from_numpy((np.asarray(values, dtype=np.float64) * scale).astype(np.float32))

        cameras = Cameras(
            camera_to_worlds=torch.from_numpy(scene.camera_to_worlds[ids].astype(np.float32)),
            fx=column([f.intrinsics.fx for f in frames], sx),
            fy=column([f.intrinsics.fy for f in frames], sy),
            cx=column([f.intrinsics.cx for f in frames], sx),
            cy=column([f.intrinsics.cy for f in frames], sy),
            width=int(width),
            height=int(height),
            camera_model=frames[0].intrinsics.camera_model,
            distortion=torch.tensor([f.intrinsics.distortion for f in frames], dtype=torch.float32),
        )
        check_lenses(cameras, [f.image_path.name for f in frames], capture.source)
        return DataparserOutputs(
            images=torch.from_numpy(images),
            cameras=cameras,
            image_names=[f.image_path.stem for f in frames],
            view_ids=ids,
            scene_box=torch.from_numpy(scene.scene_box.astype(np.float32)),
            near=scene.near,
            far=scene.far,
            scene_name=self.scene_name(),
            source_files=[f.image_path for f in frames],
            depth_bounds=scene.depth_bounds,
            object_box=None if scene.object_box is None else (tuple(scene.object_box[0]), tuple(scene.object_box[1])),
            dataparser_transform=self.dataparser_transform(),
        )

    def dataparser_transform(self) -> DataparserTransform | None:
        """The map from the capture's world frame to the normalised one, recovered from the poses before and after
        (``fit_transform``); None when they do not pin it down (every camera in one place)."""
        return fit_transform(camera_to_worlds(self.capture()), self.normalised().camera_to_worlds)

    def scene_name(self) -> str:
        data = Path(self.config.data)
        return (data.parent if data.suffix.lower() == ".json" else data).resolve().name


@dataclass
class CaptureParserConfig(DataParserConfig):
    """Options shared by every capture parser (view selection, splits, normalisation)."""

    downscale: int | None = None
    """Image downscale factor: reads <folder>_<k>/ (images_4/ ...) when present, else resizes; unset: the smallest
    power of two that brings the longer side to at most 1600 px (nerfstudio's rule)."""
    num_views: int | None = None
    """Few-shot: train on this many views picked by seeded k-means on the camera centres (as blender-data)."""
    view_ids: tuple[int, ...] | None = None
    """Explicit training frame indices (0-based, in file-name order, over all frames); overrides num_views."""
    kmeans_seed: int = 0
    """Seed of the k-means view selection; the chosen ids are deterministic for a seed."""
    test_every: int = 8
    """Without split lists in the file, every k-th frame (0 included) is a hold-out test view (llffhold 8)."""
    val_views: int = 3
    """Validation views: this many unused training images, evenly spaced; the test views if none are unused."""
    orientation: Orientation = "up"
    """Object scenes: up (the cameras' mean up becomes +z), pca (least camera spread becomes z) or none."""
    scene_scale: float = 1.0
    """Object scenes: scale the scene box (from the sparse points, else the cameras) about its centre."""
    scene_kind: Literal["auto", "object", "forward-facing", "unbounded"] = "auto"
    """auto: forward-facing (NDC rays, the real-scene preset) when every camera looks the same way and they do not
    surround the scene; else object (a bounded box on a known background) when the photos carry alpha or masks, and
    unbounded (the object with its surroundings, space beyond the cameras contracted) when they do not. The run's
    config.json records the decision."""
    scene_kind_reason: tyro.conf.Suppress[str] = ""
    """Why scene_kind has its value, recorded when a run pins the automatic decision (not a flag)."""
    bd_factor: float = 0.75
    """Forward-facing scenes: scale so the nearest depth bound becomes 1 / bd_factor (LLFF)."""

    def pin(self, declared: SceneDeclaration) -> None:
        """Record what ``auto`` decided (and why) in the config, so a saved run never decides again."""
        if self.scene_kind == "auto":
            self.scene_kind = declared.kind  # type: ignore[assignment]
            self.scene_kind_reason = declared.reason
