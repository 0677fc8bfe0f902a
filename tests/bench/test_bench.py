"""fourierf-bench: sweep expansion, the report's maths on made-up measurements, executors, and a tiny real bench."""

from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

import pytest

from fourierf_plugin.bench import phases as ph
from fourierf_plugin.bench import report, results
from fourierf_plugin.bench.executors import LocalExecutor, RayExecutor, probe, threads_per_worker
from fourierf_plugin.bench.runner import RunTask, Scene, train_command
from fourierf_plugin.bench.sweep import RunSpec, SweepSpec, designate_profiled, eval_steps, expand
from fourierf_plugin.scripts.bench import BenchConfig, detect_scene
from fourierf_plugin.scripts.bench import main as bench_main
from fourierf_plugin.scripts.cli import run_cli
from fourierf_plugin.utils.errors import UserError
from tests.conftest import SHARED_DIR
from tests.helpers import TINY_SCENE

# -- sweep ------------------------------------------------------------------------------------------------------------


def test_sweep_is_methods_times_knob_values_and_baselines_ignore_the_curriculum() -> None:
    spec = SweepSpec(
        methods=("fourierf-vm", "tensorf-vm"), iters=(100, 200), batch_size=(256, 1024), ramp_fraction=(0.1, 0.5)
    )
    runs = expand(spec)
    fourier = [r for r in runs if r.method == "fourierf-vm"]
    baseline = [r for r in runs if r.method == "tensorf-vm"]
    assert len(fourier) == 2 * 2 * 2  # iters × batch × ramp
    assert len(baseline) == 2 * 2  # ramp means nothing without the curriculum: collapsed, not repeated
    assert {r.ramp_fraction for r in fourier} == {0.1, 0.5} and {r.f0 for r in fourier} == {0.3}  # preset f0
    assert all(r.f0 is None and r.ramp_fraction is None for r in baseline)
    assert len({r.key for r in runs}) == len(runs)


def test_eval_steps_cover_tenths_and_the_quoted_fractions_with_one_checkpoint_interval() -> None:
    assert eval_steps(800, 10) == (80, 160, 200, 240, 320, 400, 480, 560, 640, 720, 800)
    run = expand(SweepSpec(methods=("fourierf-vm",), iters=(800,)))[0]
    assert run.steps_per_save() == 40 and all(s % 40 == 0 for s in run.eval_steps())
    assert eval_steps(400, 1) == (400,)
    assert eval_steps(20, 2) == (10, 20)
    short = expand(SweepSpec(methods=("fourierf-vm",), iters=(160,), eval_points=4))[0]
    assert short.steps_per_save() == 40 and short.log_every() == 8  # 128 = 80% of the run starts the final window


def test_run_spec_becomes_train_flags() -> None:
    run = expand(SweepSpec(methods=("fourierf-vm",), iters=(400,), downscale=(2,), f0=(0.1,), step_ratio=(0.25,)))[0]
    scene = Scene(Path("/scene"), "blender", ("--test-every", "8"))
    cmd = train_command(RunTask(designate_profiled([run], "all")[0], scene, Path("/out"), threads=1))
    text = " ".join(cmd)
    for flag in (
        "fourierf-vm --max-num-iterations 400",
        "--steps-per-save 20 --log-every 20 --keep-checkpoints 0",  # 80% = step 320: on a checkpoint
        "--pipeline.model.step-ratio 0.25",
        "--pipeline.model.fourier.f0-density 0.1 --pipeline.model.fourier.f0-color 0.1",
        "--pipeline.model.fourier.ramp-fraction 0.2",
        "--threads 1",
        "--profile-phases True",
        f"--timestamp {run.key}",
    ):
        assert flag in text
    assert cmd[-5:] == ["blender-data", "--downscale", "2", "--test-every", "8"]  # the parser comes last


def test_one_profiled_run_per_method_and_duplicates_merge() -> None:
    runs = expand(SweepSpec(methods=("fourierf-vm", "tensorf-vm"), iters=(100, 200)))
    marked = designate_profiled(runs, "first")
    assert [r.profile_phases for r in marked] == [True, False, True, False]
    twice = expand(SweepSpec(methods=("fourierf-vm", "fourierf-vm"), ramp_fraction=(0.2, None)))
    assert len(twice) == 1  # None is the preset's 0.2: the same training


@pytest.mark.parametrize(
    ("spec", "needle"),
    [
        (SweepSpec(methods=()), "--methods"),
        (SweepSpec(methods=("nerfacto",)), "nerfacto"),
        (SweepSpec(methods=("fourierf-vm",), iters=()), "--iters"),
        (SweepSpec(methods=("fourierf-vm",), batch_size=()), "--batch-size"),
        (SweepSpec(methods=("fourierf-vm",), iters=(9,)), "--iters"),
        (SweepSpec(methods=("fourierf-vm",), ramp_fraction=(1.5,)), "ramp-fraction"),
        (SweepSpec(methods=("fourierf-vm",), step_ratio=(0.0,)), "--step-ratio"),
    ],
)
def test_bad_sweeps_are_user_errors(spec: SweepSpec, needle: str) -> None:
    with pytest.raises(UserError) as err:
        expand(spec)
    assert needle in err.value.problem and err.value.fix


def test_bad_cli_input_exits_2(tmp_path: Path, capsys) -> None:
    cases = [
        ["--data", str(tmp_path / "missing")],
        ["--data", str(tmp_path)],  # no scene files
        ["--data", str(TINY_SCENE), "--methods", "fourierf-xx"],
        ["--data", str(TINY_SCENE), "--iters", "5"],
        ["--data", str(TINY_SCENE), "--delta-values", "0.1", "--delta-methods", "tensorf-vm"],
        ["--data", str(TINY_SCENE), "--workers", "999"],
        ["--data", str(TINY_SCENE), "--scene-kind", "llff"],
    ]
    for args in cases:
        with pytest.raises(SystemExit) as exit_info:
            run_cli(lambda args=args: bench_main([*args, "--output-dir", str(tmp_path / "out")]), argv=[])
        assert exit_info.value.code == 2, args
        assert "error:" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()  # nothing is created before the input is known to be good


# -- report maths on made-up measurements ----------------------------------------------------------------------------


def _rows(method: str, iters: int, psnrs: list[float], seconds: list[float], **knobs) -> list[dict]:
    steps = [round(iters * (i + 1) / len(psnrs)) for i in range(len(psnrs))]
    base = {"method": method, "iters": iters, "downscale": 4, "grid_voxels": 128**3, "step_ratio": 0.5,
            "batch_size": 1024, "seed": 1, "f0": 0.3, "ramp_fraction": 0.2, "ssim": 0.8, "lpips": 0.1,
            "peak_rss_gb": 1.0, "train_seconds_total": seconds[-1] + 1, "test_views": 25} | knobs  # fmt: skip
    key = f"{method}-{iters}-{base['ramp_fraction']}"
    return [
        base | {"key": key, "step": s, "psnr": p, "train_seconds_at_step": t}
        for s, p, t in zip(steps, psnrs, seconds, strict=True)
    ]


def test_within_half_a_db_and_budget_fractions() -> None:
    rows = _rows("fourierf-vm", 800, [15, 18, 20.6, 20.9, 21.0, 21.2, 21.3, 21.3], [10, 20, 30, 40, 50, 60, 70, 80])
    (curve,) = report.curves(rows)
    assert report.seconds_to_within(curve) == (40, 400)  # the first checkpoint at or above 21.3 - 0.5 dB
    assert report.at_fraction(curve, 0.25)["psnr"] == 18
    assert report.at_fraction(curve, 0.5)["psnr"] == 20.9
    assert report.at_fraction(curve, 1.0)["psnr"] == 21.3
    assert report.at_fraction(curve, 0.3) is None  # not evaluated: no made-up number


def test_pareto_front_keeps_only_undominated_points() -> None:
    points = [(10, 20.0), (20, 19.0), (30, 22.0), (30, 21.0), (5, 18.0), (40, 22.0), (50, 23.0)]
    assert report.pareto_front(points) == [4, 0, 2, 6]
    assert report.pareto_front([]) == []


def test_time_relative_to_the_matching_baseline_and_the_delta_table() -> None:
    rows = _rows("tensorf-vm", 800, [20, 21], [50, 99], f0=None, ramp_fraction=None)
    rows += _rows("fourierf-vm", 800, [20, 21.5], [60, 109])
    rows += _rows("tensorf-vm", 400, [19, 20], [25, 49], f0=None, ramp_fraction=None)  # another budget: not matched
    for ramp, psnr in ((0.05, 19.0), (0.5, 20.5), (0.1, 20.0)):
        rows += _rows("fourierf-vm", 400, [psnr], [40], ramp_fraction=ramp)
    all_curves = report.curves(rows)
    by_key = {c.key: c for c in all_curves}
    assert report.baseline_ratio(by_key["fourierf-vm-800-0.2"], all_curves) == pytest.approx(110 / 100)
    (group,) = report.delta_groups(all_curves)
    assert [c.knob("ramp_fraction") for c in group] == [0.05, 0.1, 0.5]
    table = report.delta_table(group, all_curves)
    assert any(line.startswith("| 0.5 |") and "20.50" in line for line in table)
    assert any(line.startswith("| tensorf-vm") and "20.00" in line for line in table)  # the 400-it baseline
    cp = report.curves(_rows("fourierf-cp", 200, [18, 19], [30, 59]))[0]  # no tensorf-vm run at 200 iterations
    assert report.baseline_ratio(cp, all_curves) is None
    assert report.per_iteration_ratio(cp, all_curves) == pytest.approx((60 / 200) / (50 / 400))  # nearest budget
    md = "\n".join(report.markdown(rows, {}, title="t"))
    assert "1.10×" in md and "Δ ablation" in md and "No per-phase breakdown" in md


def _metrics_records(iters: int, every: int) -> list[dict]:
    """A fake metrics.jsonl of a profiled run: each interval costs 1 s of which the filter takes a fixed part."""
    records = []
    for step in range(every, iters + 1, every):
        late = step > 0.8 * iters
        phases = {"fourier_filter": 0.01, "fourier_filter_backward": 0.01 if late else 0.03, "backward": 0.5}
        phases["field"] = 1.0 - sum(phases.values())
        records.append({"step": step, "elapsed_s": step / 10, "psnr": 20.0, "phases": phases})
    total = {"fourier_filter": 0.1, "fourier_filter_backward": 0.26, "backward": 5.0, "field": 4.64}
    records.append({"event": "done", "step": iters, "train_seconds": iters / 10, "phases_total": total})
    return records


def test_phase_shares_whole_run_and_final_fifth(tmp_path: Path) -> None:
    path = tmp_path / "metrics.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in _metrics_records(100, 10)) + '{"step": 10')  # torn tail
    records = ph.read_metrics(path)
    assert ph.elapsed_by_step(records)[50] == 5.0
    total, final = ph.phases_total(records), ph.phases_final(records, 100)
    assert ph.fourier_share(total) == pytest.approx(0.036)
    assert final is not None and final["backward"] == pytest.approx(1.0)  # intervals (80, 90] and (90, 100]
    assert ph.fourier_share(final) == pytest.approx(0.02)
    shares = ph.shares(total)
    assert next(iter(shares)) == "backward" and sum(shares.values()) == pytest.approx(1.0)
    assert ph.fourier_share(None) is None and ph.fourier_share({"backward": 1.0}) is None
    assert ph.phases_final(_metrics_records(100, 10)[:3], 100) is None  # nothing logged in the last fifth
    md = report.phase_section(report.curves(_rows("fourierf-vm", 100, [20], [9]), {
        "fourierf-vm-100-0.2": {"phases_total": total, "phases_final": final}}))  # fmt: skip
    text = "\n".join(md)
    assert "| backward | 50.0% | 50.0% |" in text and "3.60%" in text and "2.00%" in text


def test_csv_round_trip_keeps_types(tmp_path: Path) -> None:
    rows = _rows("tensorf-vm", 100, [20.5], [9.0], f0=None, ramp_fraction=None)
    rows[0] |= {"delta_per_iter": math.inf, "profiled": True}
    results.append_rows(tmp_path / "m.csv", rows)
    results.append_rows(tmp_path / "m.csv", rows)
    back = results.read_rows(tmp_path / "m.csv")
    assert len(back) == 2 and back[0]["step"] == 100 and back[0]["psnr"] == 20.5 and back[0]["f0"] is None
    assert back[0]["profiled"] is True and math.isinf(back[0]["delta_per_iter"])


def test_plots_are_skipped_with_a_reason_without_matplotlib(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    paths, note = report.make_plots(_rows("fourierf-vm", 100, [20, 21], [5, 9]), {}, tmp_path)
    assert paths == [] and note is not None and "fourierf[bench]" in note


# -- executors --------------------------------------------------------------------------------------------------------


def test_local_executor_with_workers_runs_every_item_once_in_a_pool() -> None:
    """What the pool guarantees, whatever the machine's load: every item runs exactly once (results come back in
    completion order, so they are compared as a multiset), in spawned worker processes, never more than ``workers``
    of them. Which worker gets how many items is up to the scheduler and is not asserted."""
    pool = LocalExecutor(workers=2)
    assert sorted(pool.map(abs, [-3, -1, -4, -1, -5])) == [1, 1, 3, 4, 5]
    pids = [pid for _, pid in pool.map(probe, [0.0] * 4)]
    assert len(pids) == 4 and os.getpid() not in pids
    assert 1 <= len(set(pids)) <= 2
    assert list(pool.map(abs, [])) == []


def test_local_executor_with_one_worker_runs_in_order_in_this_process() -> None:
    assert list(LocalExecutor(workers=1).map(abs, [-1, -2, -3])) == [1, 2, 3]
    assert {pid for _, pid in LocalExecutor(workers=1).map(probe, [0.0, 0.0])} == {os.getpid()}


def test_workers_times_threads_fit_the_cores() -> None:
    assert threads_per_worker(2, None, cores=8) == 4
    assert threads_per_worker(1, 2, cores=2) == 2
    with pytest.raises(UserError):
        threads_per_worker(2, 2, cores=2)


def test_ray_executor_without_ray_is_a_user_error(monkeypatch, tmp_path: Path) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray raises ImportError
    with pytest.raises(UserError) as err:
        RayExecutor()
    assert "fourierf[ray]" in (err.value.fix or "")
    args = ["--data", str(TINY_SCENE), "--executor", "ray", "--output-dir", str(tmp_path / "out")]
    with pytest.raises(SystemExit) as exit_info:
        run_cli(lambda: bench_main(args), argv=[])
    assert exit_info.value.code == 2 and not (tmp_path / "out").exists()


@pytest.mark.slow
def test_ray_executor_on_a_local_instance() -> None:
    ray = pytest.importorskip("ray", reason="ray is not installed (pip install 'fourierf[ray]')")
    executor = RayExecutor(None, num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        pids = [pid for _, pid in executor.map(probe, [0.0, 0.0, 0.0])]
        assert len(pids) == 3 and os.getpid() not in pids  # ran in Ray's worker processes
    finally:
        ray.shutdown()


# -- end to end -------------------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_tiny_bench_writes_csv_and_report_and_resumes(tmp_path: Path, capsys) -> None:
    lpips = SHARED_DIR / "lpips" / "lpips_alex_v0.1.pth"
    args = ["--data", str(TINY_SCENE), "--methods", "fourierf-vm", "tensorf-vm", "--iters", "20",
            "--eval-points", "2", "--grid-voxels", "13824", "--init-voxels", "4096", "--batch-size", "256",
            "--output-dir", str(tmp_path), "--threads", "1"]  # fmt: skip
    if lpips.is_file():
        args += ["--lpips-weights", str(lpips)]
    outcome = bench_main(args)
    out = outcome.out_dir
    assert out.parent == tmp_path and sorted(outcome.finished) == sorted(r["key"] for r in _plan(out))
    rows = results.read_rows(out / results.MEASUREMENTS)
    assert len(rows) == 4 and {r["step"] for r in rows} == {10, 20}
    for r in rows:
        assert r["psnr"] > 5 and r["train_seconds_at_step"] > 0 and r["peak_rss_gb"] > 0.05
        assert (r["lpips"] is not None) == lpips.is_file()
    text = (out / "report.md").read_text()
    assert "PSNR along the budget" in text and "× tensorf-vm" in text and "Pareto front" in text
    assert "Fourier filtering share" in text  # the first run of each method records the phase breakdown
    assert ("psnr_vs_seconds.png" in text) == (out / "psnr_vs_seconds.png").is_file()
    final_ckpts = list(out.glob("runs/*/*/*/checkpoints/*.ckpt"))
    assert len(final_ckpts) == 2  # only each run's final checkpoint is kept
    capsys.readouterr()
    again = bench_main([*args, "--resume", str(out)])
    assert again.finished == [] and "0 of 2 runs to do" in capsys.readouterr().out
    assert len(results.read_rows(out / results.MEASUREMENTS)) == 4


def _plan(out: Path) -> list[dict]:
    return json.loads((out / "plan.json").read_text())["runs"]


def test_run_spec_key_is_path_safe() -> None:
    run = RunSpec("fourierf-vm", 800, None, 2_000_000, 64**3, 0.5, 1024, 0.3, 0.2, 1, 10)
    assert run.key == "fourierf-vm_it800_dsdef_g2000000v_sr0.5_b1024_f00.3_r0.2_s1"
    assert run.delta_per_iteration() == pytest.approx(0.7 / 160)


def test_captures_are_detected_and_read_by_their_parser(tmp_path: Path) -> None:
    """A nerfstudio capture (transforms.json) goes to nerfstudio-data, a bare COLMAP model to colmap-data, and a
    process-data output (both) to nerfstudio-data."""
    nerfstudio = tmp_path / "ns"
    nerfstudio.mkdir()
    (nerfstudio / "transforms.json").write_text("{}")
    colmap = tmp_path / "colmap"
    (colmap / "sparse" / "0").mkdir(parents=True)
    both = tmp_path / "both"
    (both / "colmap" / "sparse" / "0").mkdir(parents=True)
    (both / "transforms.json").write_text("{}")
    for data, parser in ((nerfstudio, "nerfstudio-data"), (colmap, "colmap-data"), (both, "nerfstudio-data")):
        scene = detect_scene(BenchConfig(data=data, views=3))
        assert scene.parser_command == parser and scene.parser_args == ("--num-views", "3"), data
    with pytest.raises(UserError, match=r"transforms\.json"):
        detect_scene(BenchConfig(data=colmap, scene_kind="nerfstudio"))
