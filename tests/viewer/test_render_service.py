"""The viewer's pictures: the camera conversions, the cutoff-aware render path, the preview size and the budget."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from fourierf_plugin.data.datamanager import camera_rays
from fourierf_plugin.engine.trainer import Trainer
from fourierf_plugin.viewer.render_budget import PreviewPacer, RenderBudget
from fourierf_plugin.viewer.render_service import (
    OPENCV_TO_OPENGL,
    RAYS_PER_BLOCK,
    PreviewQuality,
    camera_from_dataset,
    camera_from_opencv_pose,
    fit_size,
    high_frequency_energy,
    preview_size,
    render_view,
)
from fourierf_plugin.viewer.scene_view import nearest_point_to_axes, scene_layout, wxyz_from_rotation
from fourierf_plugin.viewer.server import unique_mesh_path
from tests.helpers import FakeClock


def _test_cameras(trainer: Trainer):
    return trainer.pipeline.datamanager.parser.get_outputs("test").cameras


# -- the model's cutoff keyword ---------------------------------------------------------------------------------------
def test_render_rays_at_cutoffs_matches_the_step_with_those_cutoffs_and_restores_the_filtering(trained_run) -> None:
    trainer, _ = trained_run
    model = trainer.pipeline.model
    origins, directions = camera_rays(_test_cameras(trainer), 0, model.effects.ray_space)
    end = model.max_iters
    assert model.cutoffs(end) == (1.0, 1.0)
    model.prepare(0)  # a different filtering is prepared before the render ...
    before = model.field.filtered
    at_cutoffs = model.render_rays(origins, directions, step=0, cutoffs=(1.0, 1.0))
    assert model.field.filtered is before  # ... and is what remains prepared afterwards
    at_step = model.render_rays(origins, directions, step=end)
    for key in ("rgb", "depth", "accumulation"):
        torch.testing.assert_close(at_cutoffs[key], at_step[key])


# -- cameras -----------------------------------------------------------------------------------------------------------
def test_a_dataset_camera_renders_as_the_pipeline_renders_it(trained_run) -> None:
    trainer, _ = trained_run
    pipeline, model = trainer.pipeline, trainer.pipeline.model
    step = model.max_iters
    view = next(pipeline.render_views("test", step))
    rendered = render_view(model, camera_from_dataset(_test_cameras(trainer), 0), model.cutoffs(step))
    expected = np.clip(view.rgb.numpy() * 255 + 0.5, 0, 255).astype(np.uint8)
    assert rendered.rgb.shape == expected.shape
    assert np.abs(rendered.rgb.astype(int) - expected.astype(int)).max() <= 1


def test_blocks_of_rays_render_as_one_call_and_an_abort_stops_the_render(trained_run) -> None:
    trainer, _ = trained_run
    model = trainer.pipeline.model
    camera = camera_from_dataset(_test_cameras(trainer), 1).resized(160, 160)  # 25600 rays: two blocks
    assert camera.width * camera.height > RAYS_PER_BLOCK
    rendered = render_view(model, camera, (0.6, 0.4))
    origins, directions = camera_rays(camera.as_cameras(), 0, model.effects.ray_space)
    whole = model.render_rays(origins, directions, step=0, cutoffs=(0.6, 0.4))
    expected = np.clip(whole["rgb"].view(160, 160, 3).numpy() * 255 + 0.5, 0, 255).astype(np.uint8)
    assert np.array_equal(rendered.rgb, expected)
    asked = []
    assert render_view(model, camera, (0.6, 0.4), abort=lambda: asked.append(1) or len(asked) > 1) is None
    assert len(asked) == 2  # the first block was rendered, the second never started


def test_a_browser_pose_converts_back_to_the_camera_it_came_from(trained_run) -> None:
    trainer, _ = trained_run
    camera = camera_from_dataset(_test_cameras(trainer), 3)
    rotation_cv = camera.camera_to_world[:, :3] @ OPENCV_TO_OPENGL
    back = camera_from_opencv_pose(
        wxyz_from_rotation(rotation_cv), camera.camera_to_world[:, 3], camera.fov_y, 1.0, camera.width
    )
    np.testing.assert_allclose(back.camera_to_world, camera.camera_to_world, atol=1e-6)
    assert (back.width, back.height) == (camera.width, camera.height)
    assert back.focal == pytest.approx(camera.focal)


def test_the_scene_layout_looks_at_the_object_with_z_up(trained_run) -> None:
    trainer, _ = trained_run
    layout = scene_layout(trainer.pipeline.datamanager.reference_outputs.cameras)
    assert layout.up[2] > 0.7  # Blender scenes stand on the xy plane
    assert np.linalg.norm(layout.target) < 0.5  # the cameras circle the object at the origin
    origins = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    directions = np.array([[1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    np.testing.assert_allclose(nearest_point_to_axes(origins, directions), [1.0, 1.0, 0.0], atol=1e-9)


# -- cutoffs change the picture ----------------------------------------------------------------------------------------
def test_a_low_cutoff_renders_a_smoother_picture(trained_run) -> None:
    trainer, _ = trained_run
    model = trainer.pipeline.model
    camera = camera_from_dataset(_test_cameras(trainer), 0)
    full = render_view(model, camera, (1.0, 1.0))
    coarse = render_view(model, camera, (0.0, 0.0))
    assert full.rgb.shape == coarse.rgb.shape == (camera.height, camera.width, 3)
    assert full.depth.shape == full.accumulation.shape == full.rgb.shape
    assert full.rgb.dtype == np.uint8
    assert not np.array_equal(full.rgb, coarse.rgb)
    assert full.rgb.astype(float).var() > 50.0  # an object on the background, not a flat picture
    assert high_frequency_energy(coarse.rgb) < 0.7 * high_frequency_energy(full.rgb)


def test_high_frequency_energy_is_zero_for_a_flat_picture_and_grows_with_detail() -> None:
    flat = np.full((16, 16, 3), 128, dtype=np.uint8)
    checker = (np.indices((16, 16)).sum(axis=0) % 2 * 255).astype(np.uint8)
    ramp = np.tile(np.arange(16, dtype=np.uint8) * 16, (16, 1))
    assert high_frequency_energy(flat) == 0.0
    assert high_frequency_energy(checker) > high_frequency_energy(ramp) > 0.0


# -- sizes -------------------------------------------------------------------------------------------------------------
def test_preview_is_a_quarter_of_each_side_within_bounds() -> None:
    assert preview_size(1024, 576) == (256, 144)
    assert preview_size(100, 50) == (32, 16)  # at least 32 pixels on the longer side
    assert preview_size(20, 10) == (20, 10)  # never larger than the picture itself


def test_fit_size_keeps_the_aspect_on_the_longer_side() -> None:
    assert fit_size(16 / 9, 768) == (768, 432)
    assert fit_size(0.5, 256) == (128, 256)
    assert fit_size(float("nan"), 64) == (64, 64)


# -- budget and mesh names ---------------------------------------------------------------------------------------------
def test_the_budget_spaces_renders_so_their_share_stays_under_the_cap() -> None:
    clock = FakeClock(100.0)
    budget = RenderBudget(0.1, clock=clock)
    assert budget.wait_seconds() == 0.0
    budget.charge(100.0, 0.5)  # 0.5 s of work: the next may start 5 s after this one started
    clock.now = 101.0
    assert budget.wait_seconds() == pytest.approx(4.0)
    clock.now = 105.0
    assert budget.wait_seconds() == 0.0
    unlimited = RenderBudget(None, clock=clock)
    unlimited.charge(105.0, 100.0)
    assert unlimited.wait_seconds() == 0.0
    with pytest.raises(ValueError, match="max_share"):
        RenderBudget(0.0)


def test_mesh_names_never_overwrite_an_earlier_export(tmp_path: Path) -> None:
    first = unique_mesh_path(tmp_path, 0.05)
    assert first.name == "viewer-f0.050.ply"
    first.write_text("x")
    second = unique_mesh_path(tmp_path, 0.05)
    assert second.name == "viewer-f0.050-2.ply"


# -- previews ---------------------------------------------------------------------------------------------------------
def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(((a.astype(float) - b.astype(float)) ** 2).mean())
    return 10 * np.log10(255.0**2 / max(mse, 1e-9))


def test_a_preview_marches_cheaper_scales_up_and_leaves_the_final_render_unchanged(trained_run) -> None:
    trainer, _ = trained_run
    model = trainer.pipeline.model
    camera = camera_from_dataset(_test_cameras(trainer), 0)
    cutoffs = model.cutoffs(model.max_iters)
    own_config = model.config
    final = render_view(model, camera, cutoffs)
    quick = render_view(model, camera, cutoffs, quality=PreviewQuality())
    half = (camera.width // 2, camera.height // 2)
    small = render_view(model, camera, cutoffs, quality=PreviewQuality(), render_size=half)
    assert model.config is own_config  # the preview's marching is undone
    again = render_view(model, camera, cutoffs)
    assert np.array_equal(again.rgb, final.rgb) and np.array_equal(again.depth, final.depth)
    assert final.rendered_size is None and small.rendered_size == half
    for picture in (quick, small):
        assert picture.rgb.shape == picture.depth.shape == picture.accumulation.shape == final.rgb.shape
    assert not np.array_equal(quick.rgb, final.rgb)  # a coarser step changes the picture a little ...
    assert _psnr(quick.rgb, final.rgb) > 30.0  # ... only a little
    assert _psnr(small.rgb, final.rgb) > 20.0  # half the pixels, scaled up: blurrier, the same picture


def test_preview_settings_are_restored_when_the_render_is_abandoned(trained_run) -> None:
    trainer, _ = trained_run
    model = trainer.pipeline.model
    own_config = model.config
    camera = camera_from_dataset(_test_cameras(trainer), 0)
    assert render_view(model, camera, (1.0, 1.0), abort=lambda: True, quality=PreviewQuality()) is None
    assert model.config is own_config


def test_the_pacer_renders_as_many_pixels_as_fit_the_preview_time() -> None:
    pacer = PreviewPacer(0.2, min_scale=0.25, first_scale=0.5)
    assert pacer.render_size(256, 256) == (128, 128)  # nothing learnt yet
    pacer.observe(128 * 128, 0.8)  # four times the target: a quarter of these rays would fit ...
    assert pacer.render_size(256, 256) == (64, 64)  # ... half of each side
    pacer.observe(64 * 64, 0.05)  # now 4x faster per ray (a browser stopped drawing): the mean of the two, ...
    assert pacer.render_size(256, 256) == (81, 81)  # ... 2 s per 256², so sqrt(0.1) of each side
    fast = PreviewPacer(0.2)
    fast.observe(100, 1e-6)
    assert fast.render_size(256, 128) == (256, 128)  # never more than the preview's own pixels
    slow = PreviewPacer(0.2)
    slow.observe(100, 100.0)
    assert slow.render_size(256, 128) == (64, 32)  # never less than min_scale of each side
    with pytest.raises(ValueError, match="target_seconds"):
        PreviewPacer(0.0)


def test_the_pacer_takes_the_work_around_a_picture_off_its_target() -> None:
    pacer = PreviewPacer(0.2, min_scale=0.01)
    pacer.observe(100 * 100, 0.2)  # 100² rays fit the whole target
    assert pacer.render_size(100, 100) == (100, 100)
    pacer.observe_overhead(0.3)  # a snapshot and sending take 0.15 s (the mean with none): 0.05 s left to render
    assert pacer.render_size(100, 100) == (50, 50)
    pacer.observe_overhead(10.0)  # the render keeps at least a quarter of the target
    assert pacer.render_size(100, 100) == (50, 50)


def test_a_render_reports_its_progress_and_its_depth_range(trained_run) -> None:
    trainer, _ = trained_run
    camera = camera_from_dataset(_test_cameras(trainer), 1).resized(160, 160)  # 25600 rays: two blocks
    seen: list[float] = []
    rendered = render_view(trainer.pipeline.model, camera, (1.0, 1.0), progress=seen.append)
    assert rendered is not None and seen == [RAYS_PER_BLOCK / 25600, 1.0]
    near, far = rendered.depth_range
    assert 0 < near < far, "the legend's range: the depths at the colormap's two ends"
