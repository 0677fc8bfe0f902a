"""The nerfstudio-format capture of an analytic scene: its transforms.json, and images seen through a known lens."""

from __future__ import annotations

import json
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from fourierf_plugin.cameras.cameras import Cameras
from fourierf_plugin.cameras.distortion import DISTORTION_KEYS, undistort
from fourierf_plugin.synthetic import SceneSpec, Sphere, default_scene, intersect_scene, write_blender_dataset
from fourierf_plugin.synthetic.cameras import hemisphere_cameras
from fourierf_plugin.synthetic.nerfstudio_capture import (
    PHONE_LENS,
    capture_cameras,
    render_camera,
    write_nerfstudio_capture,
)
from fourierf_plugin.utils.errors import UserError

SIZE = 32
OPTIONS = {"n_train": 2, "n_val": 1, "n_test": 2, "shading": "lambert"}  # shaded: the lens shows inside objects too
STRONG_LENS = {"k1": -0.3, "k2": 0.05, "p1": 2e-3, "p2": -1e-3}  # corners move by pixels even at 32 px


@pytest.fixture(scope="module")
def captures(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("captures")
    spec = default_scene()
    return {
        "pinhole": write_nerfstudio_capture(spec, root / "pinhole", SIZE, SIZE, **OPTIONS, seed=3),
        "lens": write_nerfstudio_capture(spec, root / "lens", SIZE, SIZE, **OPTIONS, seed=3, distortion=STRONG_LENS),
    }


def load(capture: Path) -> tuple[dict, list[np.ndarray]]:
    meta = json.loads((capture / "transforms.json").read_text())
    return meta, [iio.imread(capture / frame["file_path"]) for frame in meta["frames"]]


def cameras_from_json(meta: dict) -> Cameras:
    """The cameras transforms.json describes, read the way nerfstudio reads its shared-intrinsics keys."""
    n = len(meta["frames"])
    c2w = torch.tensor([frame["transform_matrix"] for frame in meta["frames"]], dtype=torch.float64)[:, :3]

    def full(key: str) -> torch.Tensor:
        return torch.full((n,), float(meta[key]), dtype=torch.float64)

    coeffs = torch.tensor([[meta.get(k, 0.0) for k in DISTORTION_KEYS]] * n, dtype=torch.float64)
    return Cameras(
        c2w, full("fl_x"), full("fl_y"), full("cx"), full("cy"), meta["w"], meta["h"], meta["camera_model"], coeffs
    )


@pytest.mark.parametrize("kind", ["pinhole", "lens"])
def test_transforms_json_has_nerfstudios_schema(captures: dict[str, Path], kind: str) -> None:
    meta, images = load(captures[kind])
    intrinsics = {"camera_model": str, "fl_x": float, "fl_y": float, "cx": float, "cy": float, "w": int, "h": int}
    for key, kind_of in intrinsics.items():
        assert isinstance(meta[key], kind_of), key
    assert (meta["w"], meta["h"], meta["cx"], meta["cy"]) == (SIZE, SIZE, SIZE / 2, SIZE / 2)
    if kind == "lens":
        assert meta["camera_model"] == "OPENCV"
        assert {k: meta[k] for k in DISTORTION_KEYS if k in meta} == STRONG_LENS  # k1 k2 p1 p2; zero k3 k4 left out
    else:
        assert meta["camera_model"] == "PINHOLE" and not set(DISTORTION_KEYS) & set(meta)
    assert len(meta["frames"]) == OPTIONS["n_train"] + OPTIONS["n_val"] + OPTIONS["n_test"]
    for frame, image in zip(meta["frames"], images, strict=True):
        assert set(frame) == {"file_path", "transform_matrix"}
        assert frame["file_path"].startswith("images/") and frame["file_path"].endswith(".png")
        assert image.shape == (SIZE, SIZE, 4) and image.dtype == np.uint8
        c2w = np.asarray(frame["transform_matrix"])
        assert c2w.shape == (4, 4)
        np.testing.assert_allclose(c2w[3], [0, 0, 0, 1])
        np.testing.assert_allclose(c2w[:3, :3] @ c2w[:3, :3].T, np.eye(3), atol=1e-12)  # a rotation
        assert np.linalg.det(c2w[:3, :3]) > 0
        assert c2w[:3, 2] @ c2w[:3, 3] > 0  # OpenGL: the camera looks down -z, towards the scene at the origin
    splits = [meta[f"{s}_filenames"] for s in ("train", "val", "test")]
    assert [len(s) for s in splits] == [OPTIONS["n_train"], OPTIONS["n_val"], OPTIONS["n_test"]]
    assert sorted(name for split in splits for name in split) == sorted(
        f["file_path"] for f in meta["frames"]
    )  # a partition of the frames
    render = json.loads((captures[kind] / "geometry.json").read_text())["render"]
    assert render["camera_model"] == meta["camera_model"] and render["distortion"] == (
        {} if kind == "pinhole" else STRONG_LENS
    )


def test_without_a_lens_the_images_are_the_blender_writers(tmp_path: Path, captures: dict[str, Path]) -> None:
    blender = write_blender_dataset(default_scene(), tmp_path / "blender", SIZE, SIZE, **OPTIONS, seed=3)
    meta, images = load(captures["pinhole"])
    for frame, image in zip(meta["frames"], images, strict=True):
        split, i = Path(frame["file_path"]).stem.split("_")
        reference = iio.imread(blender / split / f"r_{int(i)}.png")
        np.testing.assert_array_equal(image, reference)  # the same rays, so the same bytes


def test_the_lens_changes_the_images(captures: dict[str, Path]) -> None:
    _, pinhole = load(captures["pinhole"])
    _, lens = load(captures["lens"])
    changed = np.mean([(a != b).any(axis=-1).mean() for a, b in zip(pinhole, lens, strict=True)])
    assert changed > 0.02


@pytest.mark.parametrize("kind", ["pinhole", "lens"])
def test_the_json_describes_the_images(captures: dict[str, Path], kind: str) -> None:
    """Coverage seen through the cameras read back from transforms.json is exactly the images' alpha."""
    meta, images = load(captures[kind])
    cameras = cameras_from_json(meta)
    spec = default_scene()
    for i, image in enumerate(images):
        origins, dirs = cameras.generate_rays(i)
        hits = intersect_scene(spec, origins.numpy(), dirs.numpy()).hit.reshape(SIZE, SIZE)
        assert (hits != (image[..., 3] > 127)).mean() < 0.002


def test_a_distorted_pixel_shows_the_undistorted_render_at_its_undistorted_place() -> None:
    """A smooth (Lambert-shaded) sphere filling the view: the distorted image at pixel p equals the pinhole image
    sampled bilinearly at undistort(p), to interpolation accuracy, and not at p itself (the lens moves it by pixels)."""
    spec = SceneSpec((Sphere((0.0, 0.0, 0.0), 1.45, (0.8, 0.6, 0.4)),))
    size, c2w = 64, hemisphere_cameras(1)
    lens_cams = capture_cameras(c2w, size, size, 0.69, STRONG_LENS)
    distorted = np.round(render_camera(spec, lens_cams, 0, "lambert") * 255) / 255
    pinhole = np.round(render_camera(spec, capture_cameras(c2w, size, size, 0.69), 0, "lambert") * 255) / 255
    f = float(lens_cams.fx[0])
    v, u = np.meshgrid(np.arange(size) + 0.5, np.arange(size) + 0.5, indexing="ij")
    x, y = undistort(
        torch.tensor((u - size / 2) / f), torch.tensor((v - size / 2) / f), lens_cams.distortion[0], "OPENCV"
    )
    su, sv = x.numpy() * f + size / 2 - 0.5, y.numpy() * f + size / 2 - 0.5  # pixel-index coordinates
    assert np.hypot(su - (u - 0.5), sv - (v - 0.5)).max() > 3.0
    sampled, inside = bilinear(pinhole, su, sv)
    mask = inside & (distorted[..., 3] == 1.0)
    assert mask.mean() > 0.5
    mapped = np.abs(sampled[..., :3] - distorted[..., :3]).max(axis=-1)[mask]
    in_place = np.abs(pinhole[..., :3] - distorted[..., :3]).max(axis=-1)[mask & (pinhole[..., 3] == 1.0)]
    assert mapped.max() < 3.5 / 255 and mapped.mean() < 1.0 / 255
    assert in_place.max() > 8 / 255 and in_place.mean() > 3 * mapped.mean()


def bilinear(image: np.ndarray, su: np.ndarray, sv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``image`` sampled at fractional pixel indices, and where all four neighbours are inside and opaque."""
    h, w = image.shape[:2]
    u0, v0 = np.floor(su).astype(int), np.floor(sv).astype(int)
    inside = (u0 >= 0) & (v0 >= 0) & (u0 < w - 1) & (v0 < h - 1)
    u0, v0 = np.clip(u0, 0, w - 2), np.clip(v0, 0, h - 2)
    a, b = (su - u0)[..., None], (sv - v0)[..., None]
    corners = [image[v0, u0], image[v0, u0 + 1], image[v0 + 1, u0], image[v0 + 1, u0 + 1]]
    sampled = corners[0] * (1 - a) * (1 - b) + corners[1] * a * (1 - b) + corners[2] * (1 - a) * b + corners[3] * a * b
    opaque = np.all([c[..., 3] == 1.0 for c in corners], axis=0)
    return sampled, inside & opaque


def test_supersampling_samples_the_lens_at_sub_pixel_centres() -> None:
    """3 x 3 samples per pixel see what a 3x larger image with the same lens sees (its pixel centres are exactly the
    sub-pixel samples, since the coefficients act on normalised coordinates), averaged over each 3 x 3 block."""
    spec, c2w = default_scene(), hemisphere_cameras(1)
    smooth = render_camera(spec, capture_cameras(c2w, SIZE, SIZE, 0.69, PHONE_LENS), 0, samples_per_pixel=3)
    fine = capture_cameras(c2w, 3 * SIZE, 3 * SIZE, 0.69, PHONE_LENS)
    fine_alpha = render_camera(spec, fine, 0)[..., 3].reshape(SIZE, 3, SIZE, 3).mean(axis=(1, 3))
    np.testing.assert_allclose(smooth[..., 3], fine_alpha, atol=1e-12)
    assert ((smooth[..., 3] > 0) & (smooth[..., 3] < 1)).any()  # fractional coverage on silhouettes


@pytest.mark.parametrize(
    ("lens", "message"),
    [
        ({"k5": 0.1}, r"unknown distortion coefficients \['k5'\]"),
        ({"k1": float("nan")}, "must be finite"),
        ({"k1": -3.0}, "cannot be undistorted over a 32x32 image"),
    ],
)
def test_a_bad_lens_is_a_user_error_before_anything_is_written(tmp_path: Path, lens: dict, message: str) -> None:
    with pytest.raises(UserError, match=message):
        write_nerfstudio_capture(default_scene(), tmp_path / "cap", SIZE, SIZE, **OPTIONS, distortion=lens)
    assert not (tmp_path / "cap").exists()


def test_regenerating_removes_stale_images(tmp_path: Path) -> None:
    out = write_nerfstudio_capture(default_scene(), tmp_path / "cap", SIZE, SIZE, n_train=3, n_val=1, n_test=1)
    write_nerfstudio_capture(default_scene(), out, SIZE, SIZE, **OPTIONS)
    assert sorted(p.name for p in (out / "images").glob("*.png")) == sorted(
        Path(f["file_path"]).name for f in json.loads((out / "transforms.json").read_text())["frames"]
    )
