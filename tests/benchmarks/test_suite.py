"""benchmarks/run.py and report.py on made-up rows: settings are chosen on val alone, the plans skip what a method
cannot vary, and an unknown ``--only`` name or a misplaced ``--seeds`` is one clear error."""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import harness
import pytest
from harness import chosen_setting, load_results, read_jsonl, rows_by, setting_flags

from tests.helpers import load_benchmark

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "run.py"
SUITE = harness.load_suite()
SEEDS = SUITE.seeds
RULE = SUITE.rule_along_the_budget


runner = load_benchmark("run")
rep = load_benchmark("report")


def _target(scene: str, protocol: str, lead: float, floor: float | None = None, **more) -> dict:
    return {"scene": scene, "protocol": protocol, "lead": lead, "against": "each method at its val choice", **more} | (
        {"floor": floor} if floor is not None else {}
    )


def _row(setting: str, seed: int, val: float, test: float) -> dict:
    return {
        "key": f"lego/fourierf-vm_cpu-800_{setting}_800_s{seed}", "scene": "lego", "protocol": "cpu-800",
        "method": "fourierf-vm", "setting": setting, "seed": seed, "val_psnr": val, "psnr": test,
    }  # fmt: skip


def test_a_settings_name_is_its_flags() -> None:
    flags = setting_flags("wd0-nodecay-lr0.04-tv4-comp8-f0d0.1")
    assert flags == [
        "--optimizer.weight-decay", "0", "--optimizer.lr-decay-ratio", "1.0", "--optimizer.lr-grids", "0.04",
        "--pipeline.model.tv-weight-density", "4", "--pipeline.model.tv-weight-appearance", "4",
        "--pipeline.model.field.density-components", "8", "8", "8",
        "--pipeline.model.field.appearance-components", "24", "24", "24",
        "--pipeline.model.fourier.f0-density", "0.1",
    ]  # fmt: skip
    assert setting_flags("preset") == []
    for scene, names in SUITE.settings.items():
        assert len(set(names)) == len(names), f"{scene}: a setting listed twice"
        for name in names:
            setting_flags(name)  # every listed setting parses
    with pytest.raises(ValueError, match="no such token 'tvx'"):
        setting_flags("lr0.08-tvx")


def test_the_choice_reads_validation_only() -> None:
    first = SEEDS[0]
    rows = [
        _row("preset", first, val=21.0, test=30.0),  # best on test: must not be picked
        _row("wd0", first, val=22.0, test=20.0),
        _row("wd0", 1, val=10.0, test=10.0),  # later seeds do not take part in the choice
    ]
    groups = rows_by({r["key"]: r for r in rows}, "lego", "cpu-800", "fourierf-vm")
    assert chosen_setting(groups, SEEDS) == "wd0"
    assert chosen_setting({}, SEEDS) is None


def test_settings_run_on_every_seed_are_chosen_by_their_mean_val() -> None:
    first, *later = SEEDS
    rows = [
        _row("lucky", first, val=22.6, test=30.0),  # best first seed, worst mean: the mean decides
        *[_row("lucky", seed, val=22.0, test=30.0) for seed in later],
        _row("steady", first, val=22.4, test=10.0),
        *[_row("steady", seed, val=22.4, test=10.0) for seed in later],
        _row("one-seed", first, val=23.0, test=30.0),  # not run on every seed: out of the mean's race
        _row("two-seeds", first, val=23.0, test=30.0),
        _row("two-seeds", later[0], val=24.0, test=30.0),  # best mean of those run, but not on every seed
    ]
    groups = rows_by({r["key"]: r for r in rows}, "lego", "cpu-800", "fourierf-vm")
    assert chosen_setting(groups, SEEDS) == "steady"
    assert rep.val_cell(groups["lucky"], SEEDS) == "22.60 (seeds: 22.20)"
    assert rep.val_cell(groups["one-seed"], SEEDS) == "23.00"
    assert rep.val_cell(groups["two-seeds"], SEEDS) == f"23.00 (seeds {first}, {later[0]}: 23.50)"


def test_plans_skip_curriculum_settings_for_tensorf_and_keep_only() -> None:
    args = argparse.Namespace(
        stage="sweep", protocol=["cpu-800"], scene=["lego"], only=["wd0", "wd0-ramp0.5"], methods=None
    )
    plan = {(r.method, r.views) for *_, r in runner.plan(args)}
    assert plan == {
        ("fourierf-vm", "cpu-800_wd0"), ("tensorf-vm", "cpu-800_wd0"), ("fourierf-vm", "cpu-800_wd0-ramp0.5")
    }  # fmt: skip
    args.only = ["wd0-nodecay-ffinal0.7", "wd0-nodecay-occ"]
    plan = {(r.method, r.views) for *_, r in runner.plan(args)}
    assert ("tensorf-vm", "cpu-800_wd0-nodecay-ffinal0.7") not in plan, "a final cutoff is a curriculum setting"
    assert ("tensorf-vm", "cpu-800_wd0-nodecay-occ") in plan
    args.methods = ["fourierf-vm"]
    assert {r.method for *_, r in runner.plan(args)} == {"fourierf-vm"}, "--methods keeps the others out"
    args = argparse.Namespace(stage="sweep", protocol=["mid-800"], scene=["lego", "fern"], only=None, methods=None)
    assert {p[0] for p in runner.plan(args)} == {"fern"}, "mid-800 is fern's check"
    for single_scene in ("high-3000", "mid-grid300-3000"):
        args = argparse.Namespace(
            stage="sweep", protocol=[single_scene], scene=["lego", "fern"], only=None, methods=None
        )
        assert {p[0] for p in runner.plan(args)} == {"lego"}, f"{single_scene} measures lego only"


def test_an_unknown_setting_is_one_clear_error(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "sweep", "--scene", "lego", "--only", "wd9", "--work", str(tmp_path)],
        capture_output=True,
        text=True,
    )
    assert done.returncode != 0
    assert "--only wd9: no such setting for lego" in done.stderr and "wd0-nodecay" in done.stderr
    assert "Traceback" not in done.stderr
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "sweep", "--methods", "nerf", "--work", str(tmp_path)],
        capture_output=True,
        text=True,
    )
    assert done.returncode != 0 and "Traceback" not in done.stderr
    assert "--methods" in done.stderr and "invalid choice: 'nerf'" in done.stderr and "fourierf-vm" in done.stderr
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "seeds", "--seeds", "7", "--work", str(tmp_path)], capture_output=True, text=True
    )
    assert done.returncode != 0 and "Traceback" not in done.stderr
    assert "--seeds" in done.stderr and "invalid choice: 7" in done.stderr
    done = subprocess.run(
        [sys.executable, str(SCRIPT), "sweep", "--seeds", "1", "--work", str(tmp_path)], capture_output=True, text=True
    )
    assert done.returncode != 0 and "Traceback" not in done.stderr
    assert "--seeds picks the later seeds of the seeds stage; drop it for the sweep stage" in done.stderr


def test_a_curve_trains_the_800_iteration_choice_unless_told(tmp_path: Path) -> None:
    results = tmp_path / "results.jsonl"
    rows = [_row("wd0", SEEDS[0], val=22.0, test=20.0), _row("preset", SEEDS[0], val=21.0, test=21.0)]
    tensorf = _row("wd0-nodecay", SEEDS[0], val=21.5, test=21.0) | {"method": "tensorf-vm"}
    tensorf["key"] = "lego/tensorf-vm_cpu-800_wd0-nodecay_800_s20211202"
    results.write_text("".join(json.dumps(r) + "\n" for r in [*rows, tensorf]))
    args = argparse.Namespace(
        stage="curve", protocol=["cpu-3000"], scene=["lego"], only=None, results=results, methods=None
    )
    plan = {(r.method, r.views, r.iters) for *_, r in runner.plan(args)}
    assert plan == {("fourierf-vm", "cpu-3000_wd0", 3000), ("tensorf-vm", "cpu-3000_wd0-nodecay", 3000)}
    args.methods = ["tensorf-vm"]
    assert {(r.method, r.views) for *_, r in runner.plan(args)} == {("tensorf-vm", "cpu-3000_wd0-nodecay")}
    args.methods = None
    args.only = ["wd0-ramp0.5", "preset"]
    plan = {(r.method, r.views) for *_, r in runner.plan(args)}
    assert plan == {("fourierf-vm", "cpu-3000_wd0-ramp0.5"), ("fourierf-vm", "cpu-3000_preset"),
                    ("tensorf-vm", "cpu-3000_preset")}  # fmt: skip
    args.only = ["wd0-ramp0.5"]  # curriculum settings alone: tensorf-vm has nothing to run, and that is no error
    assert {(r.method, r.views) for *_, r in runner.plan(args)} == {("fourierf-vm", "cpu-3000_wd0-ramp0.5")}
    args.protocol = ["cpu-800"]
    with pytest.raises(SystemExit, match="the curve stage runs"):
        runner.plan(args)


def test_the_curve_table_sets_each_step_beside_the_short_run() -> None:
    short = _row("wd0", SEEDS[0], val=19.5, test=19.0)
    long = _row("wd0", SEEDS[0], val=20.25, test=19.75) | {
        "key": "lego/fourierf-vm_cpu-3000_wd0_3000_s20211202", "protocol": "cpu-3000",
        "curve": [[500, 18.0, 17.5], [3000, 20.25, 19.75]],
    }  # fmt: skip
    table = rep.curve_table({r["key"]: r for r in (short, long)})
    row = next(line for line in table if line.startswith("| lego"))
    assert row == "| lego | fourierf-vm | `wd0` | 19.50 / 19.00 | 500: 18.00 / 17.50 · 3000: 20.25 / 19.75 |"
    assert rep.curve_table({short["key"]: short}) == []


def test_the_curve_table_sets_the_rules_3000_iteration_setting_beside_its_800() -> None:
    p_short, p_long = "cpu-800", "cpu-3000"
    short, long = RULE["fourierf-vm"]["at_800"], RULE["fourierf-vm"]["at_3000"]
    fern = {"scene": "fern", "method": "fourierf-vm"}
    rows = [
        _row(short, SEEDS[0], val=19.5, test=19.0) | fern | {"protocol": p_short, "key": "short"},
        _row(long, SEEDS[0], val=21.0, test=20.5) | fern | {
            "protocol": p_long, "key": "long", "curve": [[3000, 21.0, 20.5]],
        },
    ]  # fmt: skip
    row = next(line for line in rep.curve_table({r["key"]: r for r in rows}) if line.startswith("| fern"))
    assert f"| 19.50 / 19.00 (`{short}`) |" in row, "the rule's 800-iteration run stands beside its 3000"


def test_the_rule_line_sets_each_methods_800_iteration_run_beside_its_3000() -> None:
    rows = []
    p_short, p_long = "cpu-800", "cpu-3000"
    for method, rule in RULE.items():
        short, long = rule["at_800"], rule["at_3000"]
        base = {"scene": "fern", "method": method}
        rows += [
            _row(short, SEEDS[0], val=19.5, test=19.0) | base | {"protocol": p_short, "key": f"{method}/short"},
            # a later seed recorded first: the line sets the first seed's runs side by side, never a later one's
            _row(long, SEEDS[1], val=25.0, test=25.0) | base | {"protocol": p_long, "key": f"{method}/long1"},
            _row(long, SEEDS[0], val=21.0, test=20.5) | base | {"protocol": p_long, "key": f"{method}/long"},
        ]
    lines = rep.along_the_budget({r["key"]: r for r in rows})
    assert lines == [
        f"- fern, {method}, the budget rule's settings at cpu sizes: `{rule['at_800']}` at 800 iterations val "
        f"19.50, test 19.00 → `{rule['at_3000']}` at 3000 val 21.00, test 20.50"
        for method, rule in RULE.items()
    ]
    assert rep.along_the_budget({r["key"]: r for r in rows[:1]}) == [], "no 3000-iteration run: no line"
    assert rep.along_the_budget({r["key"]: r for r in rows[:2]}) == [], "a later seed's alone: no line"


def test_the_targets_table_reads_each_target_against_the_baseline_it_names() -> None:
    first, one, two = SEEDS
    tensorf = {"method": "tensorf-vm"}
    rows = [
        *[_row("tv4", seed, val=23.0, test=test) for seed, test in ((first, 23.0), (one, 23.2), (two, 23.4))],
        _row("tuned", first, val=22.9, test=22.0) | tensorf | {"key": "t1"},
        _row("published", first, val=20.0, test=20.5) | tensorf | {"key": "t2"},  # lower on val: only if named
        _row("best-on-test", first, val=19.0, test=30.0) | tensorf | {"key": "t3"},  # never chosen on test
    ]
    results = {r["key"]: r for r in rows}
    targets = (
        _target("lego", "cpu-800", 0.5, 22.0),
        _target("lego", "cpu-800", 2.5, 23.5, tensorf=("published", "best-on-test"), against="a weak baseline"),
        _target("lego", "mid-3000", 1.0),  # nothing run: no line
    )
    table = rep.targets_table(results, dataclasses.replace(SUITE, targets=targets))
    lines = [line for line in table if line.startswith("| lego")]
    assert len(lines) == 2
    assert "`tuned`, 22.00 (1) | **+1.20** (+1.00) | met |" in lines[0], "the lead is the mean over each one's seeds"
    assert "≥ 22.0 dB and ≥ +0.5 dB; each method at its val choice" in lines[0]
    assert "`published`, 20.50 (1) | **+2.70** (+2.50) | missed: PSNR by 0.30 |" in lines[1]
    assert "23.20 ± 0.16 (3)" in lines[1]
    short = (_target("lego", "cpu-800", 1.5),)
    assert rep.targets_table(results, dataclasses.replace(SUITE, targets=short))[4].endswith("| missed: lead by 0.30 |")
    assert rep.targets_table({}, dataclasses.replace(SUITE, targets=targets)) == []


def test_the_p_mid_line_sets_the_first_seeds_800_iteration_run_beside_its_3000() -> None:
    fern = {"scene": "fern", "method": "tensorf-vm", "setting": "lr0.08"}
    rows = [
        fern | {"protocol": "mid-800", "seed": SEEDS[0], "val_psnr": 16.5, "psnr": 15.5, "key": "short"},
        # a later seed recorded before the first seed's (a rerun goes to the end): the first seed's is the line's
        fern | {"protocol": "mid-3000", "seed": SEEDS[2], "val_psnr": 30.0, "psnr": 30.0, "key": "later"},
        fern | {"protocol": "mid-3000", "seed": SEEDS[0], "val_psnr": 19.0, "psnr": 18.0, "key": "long"},
    ]
    assert rep.along_the_budget({r["key"]: r for r in rows}) == [
        "- fern, tensorf-vm, mid sizes, `lr0.08`, 800 → 3000 iterations: val 16.50 → 19.00, test 15.50 → 18.00"
    ]
    assert rep.along_the_budget({r["key"]: r for r in rows[:2]}) == [], "no first-seed 3000 run: no line"


def test_seeds_run_the_val_choice_on_the_later_seeds(tmp_path: Path) -> None:
    results = tmp_path / "results.jsonl"
    rows = [_row("wd0", SEEDS[0], val=22.0, test=20.0), _row("preset", SEEDS[0], val=21.0, test=23.0)]
    results.write_text("".join(json.dumps(r) + "\n" for r in rows))
    args = argparse.Namespace(
        stage="seeds",
        protocol=["cpu-800"],
        scene=["lego"],
        results=results,
        methods=["fourierf-vm"],
        only=None,
        seeds=None,
    )
    plan = [(r.method, r.views, r.seed) for *_, r in runner.plan(args)]
    assert plan == [("fourierf-vm", "cpu-800_wd0", seed) for seed in SEEDS[1:]]
    args.methods = None  # tensorf-vm has no sweep row: one clear error
    with pytest.raises(SystemExit, match="no sweep result for lego cpu-800 tensorf-vm"):
        runner.plan(args)


def test_seeds_of_named_settings_skip_what_tensorf_cannot_vary(tmp_path: Path) -> None:
    results = tmp_path / "results.jsonl"
    results.write_text("")
    args = argparse.Namespace(
        stage="seeds",
        protocol=["cpu-800"],
        scene=["lego"],
        results=results,
        methods=None,
        only=["wd0-ramp0.5"],
        seeds=None,
    )
    plan = [(r.method, r.views, r.seed) for *_, r in runner.plan(args)]
    assert plan == [("fourierf-vm", "cpu-800_wd0-ramp0.5", seed) for seed in SEEDS[1:]]
    args.seeds = [SEEDS[2]]  # one of the later seeds, when a run is long
    assert [r.seed for *_, r in runner.plan(args)] == [SEEDS[2]]


def test_the_later_seeds_table_holds_gpu_settings_run_on_every_later_seed_beside_their_repeats() -> None:
    one, two = SEEDS[1:]
    gpu = {"device": "cuda"}
    rows = [
        _row("tv4", one, val=21.0, test=20.0) | gpu,
        _row("tv4", two, val=22.0, test=21.0) | gpu,
        _row("tv6", one, val=20.0, test=19.0) | gpu,  # seed 2 missing: no line
        _row("tv8", one, val=20.0, test=19.0) | {"device": "cpu"},  # a CPU run: not a GPU side by side
        _row("tv8", two, val=20.0, test=19.0) | {"device": "cpu"},
    ]
    repeats = [
        r | {"val_psnr": r["val_psnr"] + 0.5, "repeat": "an older tree"} for r in rows[:2]
    ]  # the same keys, run before
    table = rep.later_seeds_table({r["key"]: r for r in rows}, repeats)
    lines = [line for line in table if line.startswith("| lego")]
    assert lines == [
        "| lego | cpu-800 | fourierf-vm | `tv4` | 21.00 / 20.00 | 22.00 / 21.00 | 21.50 / 20.50 |",
        "| lego | cpu-800 | fourierf-vm | `tv4` (an older tree) | 21.50 / 20.00 | 22.50 / 21.00 | 22.00 / 20.50 |",
    ]
    assert rep.later_seeds_table({r["key"]: r for r in rows[2:]}, []) == []


def test_training_seconds_are_compared_on_one_device_both_methods_ran_on() -> None:
    def run(device: str, seconds: float) -> dict:
        return {"device": device, "train_seconds": seconds}

    rows = {  # fourierf-vm all on a GPU; tensorf-vm's first seed on the CPU, its later two on the GPU
        "fourierf-vm": [run("cuda", 210.0), run("cuda", 212.0), run("cuda", 214.0)],
        "tensorf-vm": [run("cpu", 2986.0), run("cuda", 230.0), run("cuda", 234.0)],
    }
    assert rep.comparable_seconds(rows) == "212 / 232 (cuda)"
    rows["tensorf-vm"] = [run("cpu", 2986.0)]
    assert rep.comparable_seconds(rows) == "— (no shared device)"  # no mixed mean


def test_the_machine_line_names_the_rows_machines_not_the_reporters() -> None:
    rows = [_row("wd0", 1, 22.0, 22.0), _row("wd0", 2, 22.0, 22.0) | {"machine": "CPU A, 2 cores"}]
    rows.append(_row("wd0", 3, 22.0, 22.0) | {"machine": "CPU A, 2 cores"})
    line = rep.recording_machines(rows)
    assert line.count("CPU A, 2 cores") == 1 and "2-core CPUs" in line
    assert "record theirs" not in rep.recording_machines(rows[:1])


def test_threads_below_one_is_one_clear_error(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, str(SCRIPT), "sweep", "--threads", "0", "--work", str(tmp_path)],
                          capture_output=True, text=True)  # fmt: skip
    assert done.returncode != 0 and "--threads 0 must be at least 1" in done.stderr
    assert "Traceback" not in done.stderr


def test_a_run_again_moves_the_earlier_row_to_the_repeats_with_its_note(tmp_path: Path) -> None:
    path = tmp_path / "results.jsonl"
    first, other = _row("tv4", 1, val=21.0, test=20.0), _row("tv6", 1, val=20.0, test=19.0)
    for row in (first, other):
        harness.record(path, row)
    rerun = first | {"val_psnr": 21.5, "train_threads": 1}
    harness.record(path, rerun, again="threads not recorded")
    results = load_results(path)
    assert results == {first["key"]: rerun, other["key"]: other}  # one row a key, the latest
    assert len(path.read_text().splitlines()) == 2
    repeats = read_jsonl(path.with_name(harness.REPEATS))
    assert repeats == [first | {"repeat": "threads not recorded"}]  # nothing recorded is lost
    harness.record(path, rerun | {"val_psnr": 21.6}, again="a second rerun")
    assert [r["val_psnr"] for r in read_jsonl(path.with_name(harness.REPEATS))] == [21.0, 21.5]
    harness.record(path, _row("tv8", 1, val=19.0, test=18.0), again="nothing earlier")  # a new key: nothing moves
    assert len(read_jsonl(path.with_name(harness.REPEATS))) == 2


def test_the_threads_cell_says_which_cpu_rows_are_reproducible() -> None:
    cpu = {"device": "cpu"}
    assert rep.threads_cell([cpu | {"train_threads": 1}, cpu | {"train_threads": 1}]) == "1"
    assert rep.threads_cell([cpu | {"train_threads": 1}, cpu]) == "1 / ?"  # a row from before rows recorded it
    assert rep.threads_cell([{"device": "cuda"}]) == "—"


def test_the_cpu_reruns_table_sets_a_cpu_repeat_beside_the_row_read() -> None:
    kept = _row("tv4", 1, val=21.5, test=20.5) | {"device": "cpu", "train_threads": 1}
    earlier = _row("tv4", 1, val=21.0, test=20.0) | {"device": "cpu", "repeat": "threads not recorded"}
    gpu = _row("tv6", 1, val=20.0, test=19.0) | {"device": "cuda", "repeat": "a GPU repeat"}  # the later-seeds table's
    stray = _row("tv8", 1, val=20.0, test=19.0) | {"device": "cpu", "repeat": "its key is gone"}
    results = {r["key"]: r for r in (kept, gpu | {"repeat": ""})}
    lines = [line for line in rep.cpu_reruns_table(results, [earlier, gpu, stray]) if line.startswith("| lego")]
    assert lines == [
        "| lego | cpu-800 | fourierf-vm | `tv4` | 1 | 21.50 / 20.50 (1) | 21.00 / 20.00 (?) | threads not recorded |"
    ]
    assert rep.cpu_reruns_table(results, []) == []


@pytest.mark.parametrize("extra", [["seeds", "--again", ""], ["sweep", "--again", " "]])
def test_again_without_a_run_or_a_note_is_one_clear_error(tmp_path: Path, extra: list[str]) -> None:
    done = subprocess.run([sys.executable, str(SCRIPT), *extra, "--work", str(tmp_path)],
                          capture_output=True, text=True)  # fmt: skip
    assert done.returncode != 0 and "--again NOTE" in done.stderr
    assert "Traceback" not in done.stderr


def test_run_all_skips_recorded_runs_unless_run_again(tmp_path: Path, monkeypatch) -> None:
    run = harness.Run("fourierf-vm", 800, 1, "cpu-800_tv4")
    path = tmp_path / "results.jsonl"
    harness.record(path, _row("tv4", 1, val=21.0, test=20.0))
    ran = []

    def execute(point, args):  # a finished training and evaluation, without either
        ran.append(run.key)
        return _row("tv4", 1, val=21.5, test=20.5) | {"train_seconds": 1.0}

    monkeypatch.setattr(runner, "execute", execute)
    args = argparse.Namespace(results=path, jobs=1, again=None, work=tmp_path)
    point = ("lego", "cpu-800", "tv4", run)
    harness.run_all([runner.quality_job(point, args)], path)
    assert ran == [] and load_results(path)[f"lego/{run.key}"]["val_psnr"] == 21.0  # recorded: skipped
    harness.run_all([runner.quality_job(point, args)], path, again="threads not recorded")
    assert ran == [run.key] and load_results(path)[f"lego/{run.key}"]["val_psnr"] == 21.5
    assert [r["repeat"] for r in read_jsonl(path.with_name(harness.REPEATS))] == ["threads not recorded"]


def test_merge_records_rows_run_elsewhere_as_a_run_would(tmp_path: Path) -> None:
    path, lane = tmp_path / "results.jsonl", tmp_path / "lane" / "results.jsonl"
    harness.record(path, _row("tv4", 1, val=21.0, test=20.0))
    lane.parent.mkdir()
    rerun, new = _row("tv4", 1, val=21.5, test=20.5) | {"train_threads": 1}, _row("tv6", 2, val=20.0, test=19.0)
    lane.write_text(f"{json.dumps(rerun)}\n\n{json.dumps(new)}\n")
    lines = runner.merge(path, [lane], again=None)
    assert lines[0].endswith("recorded, skipped (--again NOTE keeps this row, the earlier to the repeats)")
    assert load_results(path)[rerun["key"]]["val_psnr"] == 21.0 and new["key"] in load_results(path)
    lines = runner.merge(path, [lane], again="threads not recorded")
    assert lines[0] == f"{rerun['key']}: val 21.50  test 20.50  (threads 1)"
    assert load_results(path)[rerun["key"]] == rerun
    repeats = read_jsonl(path.with_name(harness.REPEATS))
    assert [(r["key"], r["val_psnr"], r["repeat"]) for r in repeats] == [
        (rerun["key"], 21.0, "threads not recorded"),
        (new["key"], 20.0, "threads not recorded"),  # merged twice: the first merge's row is kept, not lost
    ]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (None, "no such results file; pass the --results path"),
        ('{"key": "lego/x"\n', ":1: not a JSON row"),
        ('{"key": "lego/x", "scene": "lego"}\n', ":1: a row without protocol, method, setting, seed, val_psnr, psnr"),
        (json.dumps({**_row("tv4", 1, 21.0, 20.0), "protocol": "p9"}) + "\n", ":1: protocol 'p9' or method"),
    ],
)
def test_merge_refuses_a_bad_file_before_writing_anything(tmp_path: Path, text: str | None, message: str) -> None:
    lane, results = tmp_path / "lane.jsonl", tmp_path / "results.jsonl"
    good = tmp_path / "good.jsonl"
    good.write_text(json.dumps(_row("tv6", 1, 20.0, 19.0)) + "\n")
    if text is not None:
        lane.write_text(text)
    cmd = [sys.executable, str(SCRIPT), "merge", "--rows", str(good), str(lane), "--results", str(results)]
    done = subprocess.run([*cmd, "--work", str(tmp_path / "work")], capture_output=True, text=True)
    assert done.returncode != 0 and "Traceback" not in done.stderr
    assert f"error: {lane}" in done.stderr and message in done.stderr
    assert not results.exists()  # the good file's row waited for the bad one's check


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["merge"], "--rows FILE ... goes with the merge stage"),
        (["sweep", "--rows", "x.jsonl"], "--rows FILE ... goes with the merge stage"),
        (["merge", "--rows", "{results}"], "cannot be merged into themselves"),
    ],
)
def test_merge_without_rows_or_into_itself_is_one_clear_error(tmp_path: Path, extra: list[str], message: str) -> None:
    results = tmp_path / "results.jsonl"
    results.write_text("")
    extra = [e.format(results=results) for e in extra]
    cmd = [sys.executable, str(SCRIPT), *extra, "--results", str(results), "--work", str(tmp_path)]
    done = subprocess.run(cmd, capture_output=True, text=True)
    assert done.returncode != 0 and message in done.stderr
    assert "Traceback" not in done.stderr
