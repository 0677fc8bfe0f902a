"""``--time-budget`` (``method_configs/time_budget.py``): parsing, the plan as a pure function, the error cases, and
that the count a budget picks feeds the short-run rules as a typed ``--max-num-iterations`` would."""

from __future__ import annotations

import pytest

from fourierf_plugin.method_configs import finalize, time_budget
from fourierf_plugin.method_configs.time_budget import (
    MARGIN,
    MIN_ITERATIONS,
    StepCost,
    parse_duration,
    plan_iterations,
)
from fourierf_plugin.scripts.train import build_config, given_options, parse_args
from fourierf_plugin.utils.errors import UserError
from tests.helpers import TINY_SCENE


@pytest.mark.parametrize(
    ("text", "seconds"),
    [("90s", 90), ("5m", 300), ("1.5h", 5400), ("1h30m", 5400), ("1m30s", 90), ("2h5m10s", 7510), (" 3M ", 180)],
)
def test_durations_parse(text, seconds):
    assert parse_duration(text) == pytest.approx(seconds)


@pytest.mark.parametrize("text", ["", "5", "m", "5 m", "-5m", "0s", "0h0m", "5d", "30m1h", "1.5.2h", "five minutes"])
def test_bad_durations_name_the_flag(text):
    with pytest.raises(UserError, match="--time-budget"):
        parse_duration(text)


def test_plan_fills_the_budget_less_the_margin():
    cost = StepCost(seconds_per_iteration=0.1)
    n = plan_iterations(100.0, cost)
    assert cost.seconds(n) <= 100.0 * (1 - MARGIN) < cost.seconds(n + 1)


def test_plan_counts_the_checkpoint_saves():
    plain, saving = StepCost(0.1), StepCost(0.1, seconds_per_save=5.0, steps_per_save=100)
    assert plan_iterations(300.0, saving) < plan_iterations(300.0, plain)
    assert saving.seconds(200) == pytest.approx(20.0 + 2 * 5.0)
    assert saving.seconds(201) == pytest.approx(20.1 + 3 * 5.0)  # and one at the end


def test_plan_is_monotone_in_the_budget():
    cost = StepCost(0.037, seconds_per_save=0.4, steps_per_save=250)
    counts = [plan_iterations(float(b), cost) for b in range(10, 2000, 7)]
    assert counts == sorted(counts)
    assert counts[-1] > 10 * counts[0]


def test_a_budget_too_small_for_the_minimum_is_an_error():
    cost = StepCost(1.0)
    assert plan_iterations(MIN_ITERATIONS / (1 - MARGIN) + 1, cost) == MIN_ITERATIONS
    with pytest.raises(UserError, match="too short") as err:
        plan_iterations(MIN_ITERATIONS * 0.5, cost)
    assert "--time-budget" in err.value.fix


def build(*flags: str):
    args = ["fourierf-vm", "--data", str(TINY_SCENE), "--device", "cpu", *flags]
    return build_config(parse_args(args), given_options(args))


def test_both_length_flags_are_one_error():
    with pytest.raises(UserError, match="--max-num-iterations") as err:
        build("--time-budget", "5m", "--max-num-iterations", "800")
    assert "--time-budget" in err.value.problem


def test_no_time_budget_on_resume(tmp_path):
    with pytest.raises(UserError, match="resumed run") as err:
        build("--time-budget", "5m", "--load-dir", str(tmp_path))
    assert "--time-budget" in err.value.problem


def test_a_bad_budget_fails_before_the_scene_is_read():
    args = ["fourierf-vm", "--data", "/nonexistent/scene", "--time-budget", "soon"]
    with pytest.raises(UserError, match="--time-budget 'soon' is not a duration"):
        build_config(parse_args(args), given_options(args))


def per_iteration_for(iterations: int, budget_s: float) -> float:
    """A measured cost per iteration at which ``budget_s`` plans ``iterations`` exactly (checkpoint saves aside)."""
    return budget_s * (1 - MARGIN) / (iterations + 0.5)


@pytest.mark.parametrize("iterations", [800, 300])
def test_the_budgets_count_feeds_the_rules_like_a_typed_one(monkeypatch, iterations):
    """With a mocked cost, a budget that gives N iterations sets what ``--max-num-iterations N`` sets, the budget's
    own fields aside."""
    monkeypatch.setattr(time_budget, "save_seconds", lambda size: 0.0)
    monkeypatch.setattr(time_budget, "run_shape", lambda config: 1.0)
    timed = []

    def measure(config):
        timed.append(config.max_num_iterations)
        return per_iteration_for(iterations, 600.0)

    monkeypatch.setattr(time_budget, "measure_first_steps", measure)
    args = ["fourierf-vm", "--data", str(TINY_SCENE), "--device", "cpu"]
    budgeted, notes = finalize(parse_args([*args, "--time-budget", "10m"]), given_options([*args, "--time-budget"]))
    typed_args = [*args, "--max-num-iterations", str(iterations)]
    typed, typed_notes = finalize(parse_args(typed_args), given_options(typed_args))
    assert budgeted.max_num_iterations == iterations
    assert budgeted.planned_train_seconds == pytest.approx(iterations * per_iteration_for(iterations, 600.0))
    budgeted.time_budget, budgeted.planned_train_seconds, budgeted.train_deadline_seconds = None, None, None
    budgeted.length_plan = None
    assert budgeted == typed
    rest = [n for n in notes if not n.startswith(("time budget ", "run size "))]
    assert rest == [n for n in typed_notes if not n.startswith("run size ")]
    plan = next(n for n in notes if n.startswith("time budget 10m"))
    assert f"max_num_iterations={iterations}" in plan and "not included" in plan
    assert timed[-1] == iterations or len(timed) == 1  # the last timing ran under the rules of the count it gave


def test_the_budget_is_recorded_and_the_estimate_line_shows_the_plan(monkeypatch):
    from fourierf_plugin.engine.estimates import describe_cost

    monkeypatch.setattr(time_budget, "measure_first_steps", lambda config: 0.05)
    args = ["fourierf-vm", "--data", str(TINY_SCENE), "--device", "cpu", "--time-budget", "90s"]
    config, _ = finalize(parse_args(args), given_options(args))
    assert config.time_budget == "90s" and 0 < config.planned_train_seconds <= 90 * (1 - MARGIN)
    assert "planned training time" in describe_cost(config, 1000, 2, cpu=True)


def test_a_count_is_planned_only_from_a_cost_timed_under_its_own_rules(monkeypatch):
    """When the rules of a long run make it dear enough to plan a short one, and the short one's rules make it cheap
    enough to plan a long one, the plan is the longest count that fits under rules that were timed, at their cost."""
    from fourierf_plugin.method_configs.budget import Run, rule_span

    monkeypatch.setattr(time_budget, "save_seconds", lambda size: 0.0)
    monkeypatch.setattr(time_budget, "run_shape", lambda config: 1.0)
    args = ["fourierf-vm", "--data", str(TINY_SCENE), "--device", "cpu"]
    short = finalize(parse_args([*args, "--max-num-iterations", "500"]), given_options(args))[0]
    boundary = rule_span(Run.of(short, "white"))[1]  # the first count under the longer runs' rules
    assert boundary < 10_000
    dear, cheap = per_iteration_for(boundary // 2, 600.0), per_iteration_for(boundary * 2, 600.0)

    def measure(config):
        return dear if config.max_num_iterations >= boundary else cheap

    monkeypatch.setattr(time_budget, "measure_first_steps", measure)
    budgeted, _ = finalize(parse_args([*args, "--time-budget", "10m"]), given_options([*args, "--time-budget"]))
    assert budgeted.max_num_iterations == boundary - 1
    assert budgeted.planned_train_seconds == pytest.approx((boundary - 1) * cheap)


def test_a_growing_batch_is_timed_at_its_mean_and_a_fixed_one_as_it_is():
    from fourierf_plugin.engine.estimates import mean_rays_per_batch

    def finished(method: str):
        args = [method, "--data", str(TINY_SCENE), "--device", "cpu"]
        return finalize(parse_args(args), given_options(args))[0]

    zerorf = finished("zerorf-vm")
    timed = time_budget.at_mean_batch(zerorf)
    assert zerorf.pipeline.datamanager.rays_per_batch_schedule
    assert timed.pipeline.datamanager.rays_per_batch_schedule is None
    assert timed.pipeline.datamanager.rays_per_batch == round(mean_rays_per_batch(zerorf))
    assert timed.pipeline.datamanager.rays_per_batch > zerorf.pipeline.datamanager.rays_per_batch
    fourierf = finished("fourierf-vm")
    assert time_budget.at_mean_batch(fourierf) is fourierf


def test_a_run_past_its_deadline_stops_saves_and_says_so(tmp_path, capsys):
    """The budget is a promise: a run whose iterations cost more than planned stops at its deadline, keeps a
    checkpoint of that step and ends as a success that names the iterations it did not run."""
    import json

    from fourierf_plugin.engine.checkpoint import checkpoint_name, list_checkpoints
    from fourierf_plugin.engine.trainer import Trainer
    from tests.helpers import tiny_trainer_config

    config = tiny_trainer_config(tmp_path, iters=30)
    config.time_budget, config.train_deadline_seconds = "1s", 0.0  # past due after the first iteration
    run_dir = Trainer(config).train()
    done = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()][-1]
    assert done["event"] == "done" and done["step"] == 1 and done["planned_iterations"] == 30
    assert done["fitting_iterations"] == 1, "no time left: the fewest iterations"
    assert list_checkpoints(run_dir / "checkpoints")[-1].name == checkpoint_name(1)
    said = " ".join(capsys.readouterr().out.split())  # the console wraps long lines
    assert "reached after 1 of the 30 planned iterations" in said and "--max-num-iterations 1 (from this run's" in said


def test_the_count_that_fits_follows_the_measured_cost_and_the_upsamples_still_to_come():
    import copy

    from fourierf_plugin.engine.estimates import fitting_iterations, grid_growth
    from fourierf_plugin.method_configs import all_methods

    config = copy.deepcopy(all_methods["fourierf-vm"])
    config.max_num_iterations = 1000
    config.pipeline.model.field.upsample_fractions = ()
    assert fitting_iterations(config, 100, 10.0, 60.0) == 600, "one grid: the measured rate"
    config.pipeline.model.field.upsample_fractions = (0.5,)
    before = fitting_iterations(config, 100, 10.0, 60.0)
    assert before == int(600 / grid_growth(config)) < 600, "cut before its upsample: a whole run costs more a step"
    assert fitting_iterations(config, 1000, 100.0, 60.0) == 600, "a whole run's rate is the rate of a whole run"
    assert grid_growth(config, 500) == 1.0 < grid_growth(config, 750) < grid_growth(config)


def test_a_run_within_its_deadline_runs_every_iteration(tmp_path):
    import json

    from fourierf_plugin.engine.trainer import Trainer
    from tests.helpers import tiny_trainer_config

    config = tiny_trainer_config(tmp_path, iters=12)
    config.time_budget, config.train_deadline_seconds = "1h", 3600.0
    run_dir = Trainer(config).train()
    done = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()][-1]
    assert done["step"] == 12 and "planned_iterations" not in done
