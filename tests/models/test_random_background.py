"""A random training background starts after the first occupancy update (``random_background_from``): white before,
so the density L1 clears the fog a fresh field starts with and the field lights, random after, so density outside
the object's silhouette costs the training views something."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from tests.helpers import TINY_SCENE
from tests.models.test_scene_effects import ITERS, pipeline_for

RANDOM = ["--pipeline.effects.background", "random"]


def backgrounds(model, step: int, rays) -> torch.Tensor:
    model.train()
    model.prepare(step)
    with torch.no_grad():
        return model(rays.origins[:64], rays.directions[:64])["background"]


def test_random_after_the_first_occupancy_update_white_before(tmp_path: Path) -> None:
    pipeline = pipeline_for(TINY_SCENE, tmp_path, *RANDOM)
    model, rays = pipeline.model, pipeline.datamanager.train_rays
    first_update = model.occupancy_steps[0]
    assert 0 < first_update < ITERS
    assert model.random_background_step == first_update + 1, "the step after the update, as the L1's switch"
    for step in (0, first_update):
        assert model.training_background(step) == "white"
        assert bool((backgrounds(model, step, rays) == 1).all())
    assert model.training_background(first_update + 1) == "random"
    after = backgrounds(model, first_update + 1, rays)
    assert after.shape == (64, 3) and float(after.std()) > 0.1, "a colour per ray"
    model.eval()
    with torch.no_grad():
        shown = model(rays.origins[:8], rays.directions[:8])["background"]
    assert bool((shown == 1).all()), "renders and scores stay on white"


@pytest.mark.parametrize(("start", "step"), [("0", 0), ("0.5", ITERS // 2)])
def test_a_given_start_is_a_fraction_of_the_run(tmp_path: Path, start: str, step: int) -> None:
    pipeline = pipeline_for(TINY_SCENE, tmp_path, *RANDOM, "--pipeline.model.random-background-from", start)
    model = pipeline.model
    assert model.random_background_step == step
    assert model.training_background(step) == "random"
    assert step == 0 or model.training_background(step - 1) == "white"


def test_without_an_occupancy_update_it_is_random_from_the_start(tmp_path: Path) -> None:
    pipeline = pipeline_for(TINY_SCENE, tmp_path, *RANDOM, "--pipeline.model.occupancy-update-fractions")
    assert pipeline.model.occupancy_steps == [] and pipeline.model.training_background(0) == "random"


def test_other_backgrounds_ignore_the_start(tmp_path: Path) -> None:
    pipeline = pipeline_for(TINY_SCENE, tmp_path, "--pipeline.model.random-background-from", "0.5")
    assert all(pipeline.model.training_background(s) == "white" for s in (0, ITERS - 1))
