"""Marching-cubes export: analytic surfaces land where they should, files round-trip, bad input fails cleanly.

On a trained tiny run: the CLI writes a mesh inside the model's box, a frequency cap of 0 leaves a flat density, and
an export between training iterations (``field.filtered_at``) gives the trainer back its own autograd filtering,
even when the export fails.
"""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import torch
import trimesh

from fourierf_plugin.data.dataparser_transforms import FILE_NAME, DataparserTransform, write_dataparser_transforms
from fourierf_plugin.engine.loading import load_run
from fourierf_plugin.exporter.marching_cubes import (
    AUTO_OPACITIES,
    NDC_NOTE,
    auto_levels,
    component_labels,
    describe,
    export_field_mesh,
    extract_mesh,
    largest_piece_share,
    remove_small_components,
    sample_grid,
    solid_level,
    vertex_colors,
    write_mesh,
)
from fourierf_plugin.method_configs import config_registry
from fourierf_plugin.model_components.rendering import opacity_from_density
from fourierf_plugin.scripts import export as export_script
from fourierf_plugin.scripts.cli import EXIT_USER_ERROR
from fourierf_plugin.utils.errors import UserError
from tests.helpers import cli_exit_code, train_tiny

CUBE = ((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0))


def sphere_sdf(center: tuple[float, float, float], radius: float):
    """Density r − |x − c|: positive inside, the surface at level 0 is the sphere."""
    c = torch.tensor(center)
    return lambda x: radius - (x - c).norm(dim=-1)


def box_sdf(lo: tuple[float, float, float], hi: tuple[float, float, float]):
    """Density min over axes of the distance inside the slab: the surface at level 0 is the box."""
    lo_t, hi_t = torch.tensor(lo), torch.tensor(hi)
    return lambda x: torch.minimum(x - lo_t, hi_t - x).amin(dim=-1)


def voxel(bbox: tuple, reso: int | tuple[int, int, int]) -> float:
    r = np.asarray([reso] * 3 if isinstance(reso, int) else reso)
    return float(np.max((np.asarray(bbox[1]) - np.asarray(bbox[0])) / (r - 1)))


# -- analytic surfaces -------------------------------------------------------------------------------------------
def test_sphere_vertices_lie_on_the_sphere_and_the_mesh_is_closed_and_outward() -> None:
    reso, radius = 33, 0.6
    volume = sample_grid(sphere_sdf((0.0, 0.0, 0.0), radius), *CUBE, reso)
    assert volume.shape == (reso, reso, reso) and volume.dtype == np.float32
    mesh = extract_mesh(volume, 0.0, *CUBE)
    dist = np.linalg.norm(mesh.vertices, axis=1)
    assert np.abs(dist - radius).max() < voxel(CUBE, reso)
    assert mesh.is_watertight
    assert np.mean(np.sum(mesh.face_normals * mesh.triangles_center, axis=1)) > 0, "normals point outwards"
    assert mesh.volume == pytest.approx(4 / 3 * math.pi * radius**3, rel=0.05), "positive volume: outward winding"
    assert np.mean(np.sum(mesh.vertex_normals * mesh.vertices, axis=1)) > 0


def test_box_bounds_within_one_voxel() -> None:
    reso, lo, hi = 41, (-0.5, -0.3, -0.7), (0.4, 0.6, 0.2)
    mesh = extract_mesh(sample_grid(box_sdf(lo, hi), *CUBE, reso), 0.0, *CUBE)
    assert mesh.is_watertight
    np.testing.assert_allclose(mesh.bounds, [lo, hi], atol=voxel(CUBE, reso))


def test_world_coordinates_in_a_non_cubic_offset_box() -> None:
    bbox = ((2.0, -3.0, 0.5), (3.0, -1.0, 1.0))
    reso = (24, 40, 12)
    center, radius = (2.5, -2.0, 0.75), 0.2
    volume = sample_grid(sphere_sdf(center, radius), *bbox, reso)
    assert volume.shape == reso
    mesh = extract_mesh(volume, 0.0, *bbox)
    dist = np.linalg.norm(mesh.vertices - np.asarray(center), axis=1)
    assert np.abs(dist - radius).max() < voxel(bbox, reso)
    np.testing.assert_allclose(mesh.bounds, [np.subtract(center, radius), np.add(center, radius)], atol=0.05)
    # Grid vertex (i, j, k) sits at bbox_min + index * spacing: the box corners are samples.
    corner_values = sample_grid(lambda x: x[:, 0] * 100 + x[:, 1] * 10 + x[:, 2], *bbox, reso)
    assert corner_values[0, 0, 0] == pytest.approx(2.0 * 100 - 30 + 0.5, abs=1e-4)
    assert corner_values[-1, -1, -1] == pytest.approx(3.0 * 100 - 10 + 1.0, abs=1e-4)


def test_chunking_does_not_change_the_volume() -> None:
    fn = sphere_sdf((0.1, -0.2, 0.05), 0.5)
    small = sample_grid(fn, *CUBE, (33, 30, 31), chunk=1000)
    large = sample_grid(fn, *CUBE, (33, 30, 31), chunk=2**18)
    assert np.array_equal(small, large)


def test_opacity_and_auto_level() -> None:
    sigma = torch.tensor([0.0, 1e-8, 1.0, 1e4])
    alpha = opacity_from_density(sigma, 0.01, 25.0)
    np.testing.assert_allclose(alpha.numpy(), -np.expm1(-sigma.double().numpy() * 0.25), rtol=1e-6)
    assert alpha[1] > 0, "small densities are not rounded to zero"
    assert auto_levels("opacity", 0.01, 25.0) == list(AUTO_OPACITIES)
    densities = torch.tensor(auto_levels("density", 0.01, 25.0))
    np.testing.assert_allclose(opacity_from_density(densities, 0.01, 25.0).numpy(), AUTO_OPACITIES, rtol=1e-6)


def blobs_in_a_shell(x: torch.Tensor) -> torch.Tensor:
    """A solid ball of opacity 0.25 with four dense blobs (0.8) inside it: high levels cut the blobs apart."""
    ball = (sphere_sdf((0.0, 0.0, 0.0), 0.6)(x) > 0).float() * 0.25
    blobs = sum((sphere_sdf(c, 0.1)(x) > 0).float() for c in ((0.3, 0, 0), (-0.3, 0, 0), (0, 0.3, 0), (0, -0.3, 0)))
    return torch.maximum(ball, 0.8 * blobs.clamp(max=1.0))


def test_the_automatic_level_is_the_highest_that_makes_one_solid_piece() -> None:
    volume = sample_grid(blobs_in_a_shell, *CUBE, 41)
    assert largest_piece_share(volume, 0.5) == pytest.approx(0.25, abs=0.02), "four equal blobs above 0.5"
    level, reason = solid_level(volume, AUTO_OPACITIES)
    assert level == 0.2 and "100%" in reason, "0.3 still cuts the blobs apart; 0.2 is the ball"
    mesh = extract_mesh(volume, level, *CUBE)
    assert len(np.unique(component_labels(mesh))) == 1


def test_without_a_solid_level_the_most_solid_one_is_taken_and_an_unreachable_field_is_an_error() -> None:
    volume = sample_grid(blobs_in_a_shell, *CUBE, 41)
    level, reason = solid_level(volume, (0.5,))
    assert level == 0.5 and "no tried level" in reason and "25%" in reason
    with pytest.raises(UserError, match="no automatic level fits"):
        solid_level(np.zeros((4, 4, 4), dtype=np.float32), AUTO_OPACITIES)


def test_small_pieces_are_dropped_by_default() -> None:
    def ball_and_speck(x: torch.Tensor) -> torch.Tensor:
        return torch.maximum(sphere_sdf((-0.3, 0.0, 0.0), 0.5)(x), sphere_sdf((0.7, 0.0, 0.0), 0.045)(x))

    mesh = extract_mesh(sample_grid(ball_and_speck, *CUBE, 81), 0.0, *CUBE)
    assert len(np.unique(component_labels(mesh))) == 2
    cleaned, kept, removed = remove_small_components(mesh, None)
    assert (kept, removed) == (1, 1) and cleaned.bounds[1, 0] < 0.5, "the speck on the +x side is gone"


def test_small_pieces_are_removed() -> None:
    def two_spheres(x: torch.Tensor) -> torch.Tensor:
        return torch.maximum(sphere_sdf((-0.4, 0.0, 0.0), 0.4)(x), sphere_sdf((0.6, 0.0, 0.0), 0.15)(x))

    mesh = extract_mesh(sample_grid(two_spheres, *CUBE, 41), 0.0, *CUBE)
    same, kept, removed = remove_small_components(mesh)
    assert (kept, removed) == (2, 0) and same is mesh
    big, kept, removed = remove_small_components(mesh, keep_largest=1)
    assert (kept, removed) == (1, 1) and big.is_watertight
    assert big.bounds[1, 0] < 0.1, "the small sphere on the +x side is gone"
    small_faces = len(mesh.faces) - len(big.faces)
    by_size, kept, removed = remove_small_components(mesh, min_faces=small_faces + 1)
    assert (kept, removed, len(by_size.faces)) == (1, 1, len(big.faces))
    with pytest.raises(UserError, match="min-component-faces"):
        remove_small_components(mesh, min_faces=10**9)


def test_vertex_colours_are_rgba_and_view_from_outside() -> None:
    mesh = extract_mesh(sample_grid(sphere_sdf((0.0, 0.0, 0.0), 0.5), *CUBE, 17), 0.0, *CUBE)
    seen: list[torch.Tensor] = []

    def rgb(x: torch.Tensor, d: torch.Tensor | None) -> torch.Tensor:
        assert d is not None
        seen.append((d * x).sum(dim=-1))
        return (x + 1) / 2

    colors = vertex_colors(rgb, mesh.vertices, mesh.vertex_normals, view_dependent=True, chunk=100)
    assert colors.shape == (len(mesh.vertices), 4) and colors.dtype == np.uint8
    assert (colors[:, 3] == 255).all()
    np.testing.assert_allclose(colors[:, :3], (mesh.vertices + 1) / 2 * 255, atol=1.0)
    assert (torch.cat(seen) < 0).all(), "view directions look at the surface from outside"
    flat = vertex_colors(lambda x, d: torch.full_like(x, 0.5 if d is None else 0.0), mesh.vertices, None, False)
    assert (flat[:, :3] == 128).all()


@pytest.mark.parametrize("suffix", [".ply", ".obj", ".glb"])
def test_formats_round_trip(tmp_path: Path, suffix: str) -> None:
    mesh = extract_mesh(sample_grid(sphere_sdf((0.2, 0.0, -0.1), 0.5), *CUBE, 21), 0.0, *CUBE)
    mesh.visual.vertex_colors = np.tile(np.array([[200, 100, 50, 255]], dtype=np.uint8), (len(mesh.vertices), 1))
    path = tmp_path / "nested" / f"mesh{suffix}"
    write_mesh(mesh, path)
    loaded = trimesh.load(path, force="mesh", process=False)
    np.testing.assert_allclose(loaded.bounds, mesh.bounds, atol=1e-5)
    if suffix != ".glb":  # glTF may re-index vertices; bounds are compared above
        assert (len(loaded.vertices), len(loaded.faces)) == (len(mesh.vertices), len(mesh.faces))
    if suffix == ".ply":
        assert (np.asarray(loaded.visual.vertex_colors)[:, :3] == [200, 100, 50]).all()


# -- bad input ---------------------------------------------------------------------------------------------------
def test_empty_iso_surface_names_the_range() -> None:
    volume = sample_grid(sphere_sdf((0.0, 0.0, 0.0), 0.5), *CUBE, 9)
    with pytest.raises(UserError, match="empty iso-surface") as info:
        extract_mesh(volume, 5.0, *CUBE)
    assert "--level" in info.value.fix and "--bbox" in info.value.fix


@pytest.mark.parametrize(
    ("bbox", "reso", "match"),
    [
        (((0, 0, 0), (1, 0, 1)), 8, "axis y"),
        (((0, 2, 0), (1, 1, 1)), 8, "min >= max"),
        ((CUBE[0], (1.0, float("nan"), 1.0)), 8, "finite"),
        (CUBE, 1, "resolution"),
        (CUBE, 2000, "resolution"),
    ],
)
def test_bad_box_or_resolution(bbox: tuple, reso: int, match: str) -> None:
    with pytest.raises(UserError, match=match):
        sample_grid(sphere_sdf((0.0, 0.0, 0.0), 0.5), *bbox, reso)


def test_unknown_suffix(tmp_path: Path) -> None:
    mesh = extract_mesh(sample_grid(sphere_sdf((0.0, 0.0, 0.0), 0.5), *CUBE, 9), 0.0, *CUBE)
    for name in ("mesh.txt", "mesh.stl", "mesh"):
        with pytest.raises(UserError, match=r"\.ply, \.obj, \.glb"):
            write_mesh(mesh, tmp_path / name)
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (["--output-path", "mesh.xyz"], "unsupported mesh format"),
        (["--frequency-cap", "1.5"], "frequency-cap"),
        (["--resolution", "1"], "resolution"),
        (["--resolution", "4096"], "resolution"),
        (["--bbox-min", "0", "0", "0", "--bbox-max", "1", "1", "0"], "min >= max"),
        (["--level-kind", "opacity", "--level", "2"], "not an opacity"),
        ([], "config"),  # the config file itself is missing
    ],
)
def test_cli_bad_input_exits_2_before_loading(tmp_path: Path, capsys, extra: list[str], expected: str) -> None:
    args = ["marching-cubes", "--load-config", str(tmp_path / "missing" / "config.json"), *extra]
    if "--output-path" not in extra:
        args += ["--output-path", str(tmp_path / "mesh.ply")]
    assert cli_exit_code(export_script.main, args) == EXIT_USER_ERROR
    assert expected in capsys.readouterr().err
    assert not (tmp_path / "mesh.ply").exists()


# -- a trained run -----------------------------------------------------------------------------------------------
@dataclass
class TinyRun:
    config: Path
    model: torch.nn.Module
    step: int


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> TinyRun:
    _, run_dir = train_tiny(tmp_path_factory.mktemp("out"), iters=20)
    run = load_run(run_dir / "config.json", config_registry(), device="cpu")
    return TinyRun(run_dir / "config.json", run.pipeline.model, run.step)


def _density(model, step: int, reso: int, cap: float | None = None) -> np.ndarray:
    with torch.no_grad():
        if cap is None:
            model.prepare(step)
        else:
            model.field.prepare(cap, cap)
    aabb = model.aabb.tolist()
    return sample_grid(model.field.density, aabb[0], aabb[1], reso)


@pytest.mark.slow
def test_cli_exports_a_trained_run(tiny: TinyRun, tmp_path: Path, capsys) -> None:
    volume = _density(tiny.model, tiny.step, 32)
    level = float(np.median(volume))
    assert volume.min() < level < volume.max()
    out = tmp_path / "meshes" / "tiny.ply"
    args = ["marching-cubes", "--load-config", str(tiny.config), "--output-path", str(out), "--resolution", "32"]
    args += ["--level-kind", "density", "--level", repr(level), "--vertex-colors", "--device", "cpu"]
    report = export_script.main(args)
    assert out.is_file() and report.faces > 0 and report.vertices > 0
    loaded = trimesh.load(out, force="mesh", process=False)
    assert (len(loaded.vertices), len(loaded.faces)) == (report.vertices, report.faces)
    aabb = tiny.model.aabb.numpy()
    voxel_size = (aabb[1] - aabb[0]).max() / 31
    assert (loaded.bounds[0] >= aabb[0] - voxel_size).all() and (loaded.bounds[1] <= aabb[1] + voxel_size).all()
    assert np.asarray(loaded.visual.vertex_colors).shape == (report.vertices, 4)
    assert report.space == "capture" and report.level == pytest.approx(level), "Blender poses: the capture's frame"
    printed = capsys.readouterr().out
    assert f"{report.vertices} vertices, {report.faces} faces" in printed and "watertight" in printed
    assert "took" in printed and str(out) in printed


def _prepare_as_the_trainer_does(model, step: int):
    """The filtering of a training iteration (with autograd), as the trainer leaves it between two steps."""
    model.prepare(step)
    prepared = model.field.filtered
    assert prepared.density.planes[0].requires_grad, "precondition: the trainer's filtering carries a graph"
    return prepared


def _still_trains(model, prepared) -> None:
    """The restored filtering is the trainer's: a density read through it back-propagates into the parameters."""
    assert model.field.filtered is prepared
    model.zero_grad()
    model.field.density(model.aabb.mean(dim=0, keepdim=True) + torch.zeros(4, 3)).sum().backward()
    grads = [p.grad for p in model.field.density_grid.planes]
    assert all(g is not None and torch.isfinite(g).all() for g in grads)


@pytest.mark.slow
def test_frequency_cap_zero_gives_a_constant_field(tiny: TinyRun) -> None:
    full, dc_only = _density(tiny.model, tiny.step, 16, cap=1.0), _density(tiny.model, tiny.step, 16, cap=0.0)
    assert full.std() > 0
    assert dc_only.std() < 1e-3 * full.std() + 1e-7, "f = 0 keeps one constant per factor: a flat density"
    prepared = _prepare_as_the_trainer_does(tiny.model, tiny.step)
    with pytest.raises(UserError, match="no automatic level fits"):  # a flat field crosses no level
        export_field_mesh(tiny.model, tiny.step, None, resolution=16, level_kind="density", frequency_cap=0.0)
    _still_trains(tiny.model, prepared)  # a failed export restores the filtering too


@pytest.mark.slow
def test_export_restores_the_trainers_filtering(tiny: TinyRun) -> None:
    model = tiny.model
    volume = _density(model, tiny.step, 12)
    level = float(np.median(volume))
    prepared = _prepare_as_the_trainer_does(model, tiny.step)
    report = export_field_mesh(
        model, tiny.step, None, resolution=12, level=level, level_kind="density", frequency_cap=0.5
    )
    _still_trains(model, prepared)
    assert report.frequency_cap == 0.5 and report.path is None
    assert report.faces > 0


@pytest.mark.slow
def test_ndc_runs_say_which_space_the_mesh_is_in(tiny: TinyRun, monkeypatch) -> None:
    volume = _density(tiny.model, tiny.step, 12)
    monkeypatch.setattr(tiny.model, "effects", dataclasses.replace(tiny.model.effects, ray_space="ndc"))
    report = export_field_mesh(
        tiny.model, tiny.step, None, resolution=12, level=float(np.median(volume)), level_kind="density"
    )
    assert report.space == "ndc"
    assert NDC_NOTE in describe(report)


@pytest.mark.slow
def test_the_default_export_of_a_trained_demo_run_is_one_dominant_piece(tmp_path: Path) -> None:
    """``--level auto`` and the default small-piece removal give the object, not a cloud of blobs (issue 22): the
    bundled lego trained long enough to hold an object (200 iterations on the tiny grid)."""
    _, run_dir = train_tiny(tmp_path, iters=200, extra=["--pipeline.datamanager.rays-per-batch", "512"])
    run = load_run(run_dir / "config.json", config_registry(), device="cpu")
    report = export_field_mesh(run.pipeline.model, run.step, tmp_path / "mesh.ply", resolution=64)
    assert report.level_reason.startswith("auto: the highest tried level"), describe(report)
    faces = np.bincount(component_labels(trimesh.load(tmp_path / "mesh.ply")))
    assert faces.max() >= 0.9 * faces.sum() and faces.sum() > 1000, describe(report)


def test_a_grid_over_the_available_memory_is_refused_before_sampling(
    tiny: TinyRun, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The export estimates its memory first (12 bytes a vertex): over what is available, the flag and a value that
    fits are named, and nothing is sampled."""
    monkeypatch.setattr("fourierf_plugin.exporter.marching_cubes.available_memory", lambda: 12 * 40**3)
    monkeypatch.setattr("fourierf_plugin.exporter.marching_cubes.sample_grid", lambda *a, **k: pytest.fail("sampled"))
    with pytest.raises(UserError) as info:
        export_field_mesh(tiny.model, tiny.step, None, resolution=64)
    assert "64x64x64 marching-cubes grid (--resolution)" in info.value.problem
    assert info.value.fix == "pass at most --resolution 40 on this machine"


# -- the frame of the mesh, and what is already there ----------------------------------------------------------------
def _copy_run(tiny: TinyRun, where: Path) -> Path:
    """A copy of the tiny run's folder (its config, checkpoints and recorded frame) to change safely."""
    return Path(shutil.copytree(tiny.config.parent, where / "run")) / "config.json"


def _export(config: Path, out: Path, *extra: str) -> object:
    args = ["marching-cubes", "--load-config", str(config), "--output-path", str(out), "--resolution", "16"]
    return export_script.main([*args, "--device", "cpu", *extra])


@pytest.mark.slow
def test_the_trainer_records_the_runs_frame(tiny: TinyRun) -> None:
    record = json.loads((tiny.config.parent / FILE_NAME).read_text())
    assert np.allclose(record["transform"], np.eye(4)[:3]) and record["scale"] == 1.0, "Blender: used as given"
    assert "ndc" not in record


@pytest.mark.slow
def test_meshes_go_back_to_the_capture_frame_unless_asked_to_stay(tiny: TinyRun, tmp_path: Path, capsys) -> None:
    config = _copy_run(tiny, tmp_path)
    angle = math.radians(30.0)
    rotation = np.array([[math.cos(angle), -math.sin(angle), 0], [math.sin(angle), math.cos(angle), 0], [0, 0, 1]])
    transform = DataparserTransform(np.concatenate([rotation, [[0.5], [-1.0], [2.0]]], axis=1), 0.25)
    write_dataparser_transforms(config.parent, transform)
    normalised = _export(config, tmp_path / "normalised.ply", "--frame", "normalised")
    assert normalised.space == "normalised" and "normalised frame" in capsys.readouterr().out
    captured = _export(config, tmp_path / "capture.ply")
    printed = capsys.readouterr().out
    assert captured.space == "capture" and "capture's frame" in printed and FILE_NAME in printed
    a = trimesh.load(tmp_path / "normalised.ply", process=False)
    b = trimesh.load(tmp_path / "capture.ply", process=False)
    np.testing.assert_allclose(b.vertices, transform.to_capture(a.vertices), atol=1e-4)
    np.testing.assert_array_equal(a.faces, b.faces)
    assert b.volume * a.volume > 0 and abs(b.volume) == pytest.approx(abs(a.volume) / 0.25**3, rel=1e-3)


@pytest.mark.slow
def test_a_run_without_its_frame_exports_normalised_and_says_so(tiny: TinyRun, tmp_path: Path, capsys) -> None:
    config = _copy_run(tiny, tmp_path)
    (config.parent / FILE_NAME).unlink()
    report = _export(config, tmp_path / "mesh.ply")
    assert report.space == "normalised"
    assert f"has no {FILE_NAME}" in capsys.readouterr().out


@pytest.mark.slow
def test_an_existing_mesh_is_replaced_only_with_overwrite(tiny: TinyRun, tmp_path: Path, capsys) -> None:
    out = tmp_path / "mesh.ply"
    out.write_text("mine")
    args = ["marching-cubes", "--load-config", str(tiny.config), "--output-path", str(out), "--resolution", "16"]
    assert cli_exit_code(export_script.main, args) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert "already exists" in err and "--overwrite" in err
    assert out.read_text() == "mine"
    _export(tiny.config, out, "--overwrite")
    assert len(trimesh.load(out, process=False).faces) > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mesh.ply"], "no temporary file left beside it"
