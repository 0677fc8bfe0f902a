"""A ``--time-budget`` run plans its length again once it trains (``Trainer._replan``): before every count-dependent
event and once more after the last, from its own speed, inside the short-run rules' span, every schedule following,
and a resume equal to an uninterrupted run."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from fourierf_plugin.configs.base import load_config
from fourierf_plugin.data.scene_effects import RaySpace
from fourierf_plugin.engine.checkpoint import list_checkpoints, load_latest_checkpoint
from fourierf_plugin.engine.estimates import REST_TO_GROWTH, cost_kind, rest_seconds
from fourierf_plugin.engine.trainer import (
    MIN_TIMED_STEPS,
    START_STEPS,
    LengthPlan,
    Trainer,
    TrainerConfig,
    set_run_length,
)
from fourierf_plugin.method_configs import all_methods, config_registry
from fourierf_plugin.method_configs.time_budget import pinned_steps
from fourierf_plugin.pipelines.base import Pipeline
from fourierf_plugin.scripts.train import build_config, parse_args
from tests.helpers import assert_same_model_state, tiny_trainer_config

FAST = ["--log-every", "1000"]


def planned(config: TrainerConfig, low: int = 1, high: int = 10_000, seconds: float = 60.0) -> TrainerConfig:
    config.time_budget = "1m"
    config.length_plan = LengthPlan(seconds, 0.0, low, high, pinned_steps(config, "white"))
    return config


def pipeline_of(config: TrainerConfig) -> Pipeline:
    return config.pipeline.setup(
        device=torch.device("cpu"), max_iters=config.max_num_iterations, generator=torch.Generator().manual_seed(0)
    )


def schedules(pipeline: Pipeline, steps: range) -> dict:
    """Everything of a built pipeline that follows the run's length."""
    model, manager = pipeline.model, pipeline.datamanager
    return {
        "length": (model.max_iters, manager.max_iters),
        "events": (model.upsample_steps, model.voxel_targets, model.occupancy_steps, model.after_first_update),
        "background": model.random_background_step,
        "regularisers": model.regularisers,
        "cutoffs": [model.cutoffs(s) for s in steps],
        "tv": [model.tv_scale(s) for s in steps],
        "rays": [manager.rays_at(s) for s in steps],
        "stages": manager.stage_steps(),
    }


@pytest.mark.parametrize(
    "extra",
    [
        [],
        ["--pipeline.model.occupancy-update-fractions", "0.5"],
        ["--pipeline.datamanager.rays-per-batch-schedule", "0.1", "2"],
        ["--pipeline.datamanager.rays-per-batch-schedule", "0.005", "2", "0.01", "4"],  # stages at steps 1 and 2
        [
            "--pipeline.model.floaters-gradient-scaling",
            "True",
            "--pipeline.model.floaters-gradient-scaling-from",
            "0.15",
        ],
    ],
)
def test_the_replan_falls_before_every_event_after_enough_timed_steps(tmp_path, extra):
    trainer = Trainer(planned(tiny_trainer_config(tmp_path, iters=200, extra=extra)))
    start, at, last = trainer._replan_window()
    events = [s for s in trainer.pipeline.model.event_steps() + trainer.pipeline.datamanager.stage_steps() if s > 0]
    warm_up = [s + 1 for s in events if s < START_STEPS]  # the iterations that run an event among the first steps
    assert start == START_STEPS + max(warm_up, default=0) and at - start >= MIN_TIMED_STEPS and not last
    assert at <= min(s for s in events if s >= start) - 1, "the re-plan comes before the next event"
    start, at, last = trainer._last_window()
    assert start >= max(events) + 1 + START_STEPS and at - start >= MIN_TIMED_STEPS and at < 200 and last


def test_no_replan_without_a_plan_too_few_steps_or_on_resume(tmp_path):
    unplanned = Trainer(tiny_trainer_config(tmp_path / "a", iters=200))
    assert unplanned._replan_window() is None and unplanned._last_window() is None
    early = ["--pipeline.model.occupancy-update-fractions", "0.05"]  # step 10: no room for the timed steps
    assert Trainer(planned(tiny_trainer_config(tmp_path / "b", iters=200, extra=early)))._replan_window() is None
    late = ["--pipeline.model.field.upsample-fractions", "0.3", "0.95"]  # step 190: no room after the last event
    assert Trainer(planned(tiny_trainer_config(tmp_path / "c", iters=200, extra=late)))._last_window() is None


def test_a_new_length_moves_every_schedule_as_a_run_of_that_length_has_them(tmp_path):
    """A forward-facing run of 1337 iterations set to 1100 has the config (its pinned steps included: band open by
    800, one occupancy update at 200) and the schedules of a run configured for 1100."""

    def finished(iters: int) -> TrainerConfig:
        extra = ["--scene-preset", "real", "--pipeline.datamanager.rays-per-batch-schedule", "0.3", "2"]
        return tiny_trainer_config(tmp_path, iters=iters, extra=extra)

    config = planned(finished(1337))
    assert {(path.rsplit(".", 1)[-1], step) for path, _, step in config.length_plan.pinned} == {
        ("ramp_fraction", 800),
        ("occupancy_update_fractions", 200),
    }
    pipeline = pipeline_of(config)
    set_run_length(config, pipeline.model, pipeline.datamanager, 1100)
    typed = finished(1100)
    config.time_budget, config.length_plan = None, None
    assert config == typed
    steps = range(0, 1100, 7)
    assert schedules(pipeline, steps) == schedules(pipeline_of(typed), steps)
    assert pipeline.model.occupancy_steps == [200]


def replanned(
    tmp_path: Path, speed: float, low: int = 1, high: int = 10_000, extra: tuple[str, ...] = ()
) -> tuple[Trainer, int, float]:
    """A run of 200 planned again after its window, its iterations timed at ``speed`` times the cost at which 200 fill
    its 60 s exactly (2 s spent): the trainer, the iterations done and the seconds per iteration timed."""
    trainer = Trainer(planned(tiny_trainer_config(tmp_path, iters=200, extra=list(extra)), low, high))
    start, at, _ = trainer._replan_window()
    per_iteration = speed * 58.0 / rest_seconds(trainer.config, 200, at, 1.0)
    trainer._replan(at, [2.0 - per_iteration * (at - done) for done in range(start, at + 1)], last=False)
    return trainer, at, per_iteration


@pytest.mark.parametrize(("speed", "longer"), [(1.3, False), (0.9, True), (0.5, True)])
def test_the_last_replan_fits_the_rest_at_its_timed_speed_with_every_event_behind(tmp_path, speed, longer):
    """Planned again after its last event (40 s spent), a run times what each further iteration costs: the longest
    count whose rest fits the plan's 60 s at that cost and keeps every event behind it."""
    trainer = Trainer(planned(tiny_trainer_config(tmp_path, iters=200)))
    start, at, _ = trainer._last_window()
    per_iteration = speed * 20.0 / (200 - at)
    trainer._replan(at, [40.0 - per_iteration * (at - done) for done in range(start, at + 1)], last=True)
    n = trainer.config.max_num_iterations

    def allowed(count: int) -> bool:
        return 40.0 + (count - at) * per_iteration <= 60.0 and max(trainer._event_steps(count)) < at

    assert (n > 200) == longer and allowed(n) and not allowed(n + 1)
    assert trainer.pipeline.model.max_iters == trainer.pipeline.datamanager.max_iters == n
    assert trainer.config.planned_train_seconds == pytest.approx(40.0 + (n - at) * per_iteration)


@pytest.mark.parametrize(("speed", "longer"), [(1.3, False), (0.8, True)])
def test_a_slow_run_shrinks_and_a_fast_one_grows(tmp_path, speed, longer):
    trainer, at, per_iteration = replanned(tmp_path, speed)
    c = trainer.config
    n = c.max_num_iterations
    assert (n > 200) == longer and n != 200
    assert [2.0 + rest_seconds(c, k, at, per_iteration) <= 60.0 for k in (n, n + 1)] == [True, False], "the longest"
    assert trainer.pipeline.model.max_iters == trainer.pipeline.datamanager.max_iters == n
    assert c.planned_train_seconds == pytest.approx(2.0 + rest_seconds(c, n, at, per_iteration))
    saved = load_config(trainer.run_dir / "config.json", TrainerConfig, config_registry())
    assert saved.max_num_iterations == n and saved.length_plan == c.length_plan
    record = [json.loads(line) for line in (trainer.run_dir / "metrics.jsonl").read_text().splitlines()][-1]
    assert record["event"] == "replan" and (record["from"], record["to"]) == (200, n)


def test_events_of_the_first_steps_stay_behind_wherever_the_new_length_places_them(tmp_path):
    """A ray batch's stages at steps 1 and 2 of 200 (ZeroRF's schedule at its fractions) happened before the window:
    a fast run grows past the counts that keep them at those very steps, and they stay behind the re-plan."""
    stages = ("--pipeline.datamanager.rays-per-batch-schedule", "0.005", "2", "0.01", "4")
    trainer, at, _ = replanned(tmp_path, 0.4, extra=stages)
    n = trainer.config.max_num_iterations
    assert trainer.pipeline.datamanager.stage_steps() != [1, 2] and max(trainer.pipeline.datamanager.stage_steps()) < at
    assert trainer._events_behind(n, at) == 2 and min(trainer.pipeline.model.event_steps()) >= at


def test_the_span_and_the_events_bound_the_new_length(tmp_path):
    assert replanned(tmp_path / "capped", 0.01, high=230)[0].config.max_num_iterations == 229, "the rules' span"
    assert replanned(tmp_path / "low", 50.0, low=180)[0].config.max_num_iterations == 180
    starved, at, _ = replanned(tmp_path / "starved", 50.0)
    n = starved.config.max_num_iterations
    assert n < 180 and min(starved.pipeline.model.event_steps()) >= at, "no event falls before the re-plan"
    fewer = starved._event_steps(n - 1)
    assert fewer is None or min(fewer) < at, "the fewest iterations that keep every event ahead"


def test_a_resumed_replanned_run_equals_an_uninterrupted_one(tmp_path, monkeypatch):
    """Timed at no cost a step, a run of 100 grows to its span's end (129) at the re-plan; resumed from a checkpoint
    after it, it continues with the new length (its config.json) and ends as the uninterrupted run does."""
    monkeypatch.setattr(Trainer, "_clock", lambda self, started: 1.0)
    flags = [*FAST, "--steps-per-save", "60", "--keep-checkpoints", "10"]
    a, b = (Trainer(planned(tiny_trainer_config(tmp_path / name, iters=100, extra=flags), 100, 130)) for name in "ab")
    for trainer in (a, b):
        trainer.train()
        assert trainer.config.max_num_iterations == 129
    for ckpt in list_checkpoints(b.run_dir / "checkpoints"):
        if int(ckpt.stem.split("-")[1]) > 60:
            ckpt.unlink()
    config, _ = build_config(parse_args(["fourierf-vm", "--load-dir", str(b.run_dir)]))
    resumed = Trainer(config)
    assert resumed.start_step == 60 and resumed.config.max_num_iterations == 129
    assert resumed._replan_window() is None, "a resumed run keeps its length"
    resumed.train()
    assert load_latest_checkpoint(b.run_dir / "checkpoints")[1]["step"] == 129
    assert_same_model_state(a, resumed)


def test_a_value_the_user_typed_is_not_pinned(tmp_path):
    extra = ["--scene-preset", "real", "--pipeline.model.fourier.ramp-fraction", "0.5"]
    config = tiny_trainer_config(tmp_path, iters=1337, extra=extra)
    assert [path.rsplit(".", 1)[-1] for path, _, _ in pinned_steps(config, "white")] == ["occupancy_update_fractions"]


def test_every_model_has_a_rest_ratio_for_every_ray_space_and_a_decoder_culls_more_of_an_object():
    """Each preset's cost kind has a ratio for every ray space; a decoder at every sample (zerorf-vm, freenerf) is
    most of its iteration, so skipping an object's empty box cuts its rest more than a grid model's."""
    kinds = {name: cost_kind(config.pipeline.model) for name, config in all_methods.items()}
    assert {kinds["zerorf-vm"], kinds["freenerf"]} == {"decoder"}
    assert {kinds["fourierf-vm"], kinds["fourierf-cp"], kinds["tensorf-vm"]} == {"grid"}
    assert all(set(REST_TO_GROWTH[kind]) == set(RaySpace.__args__) for kind in kinds.values())
    assert REST_TO_GROWTH["decoder"]["euclidean"] < REST_TO_GROWTH["grid"]["euclidean"]
