"""The BENCHMARKS.md sections of the measuring scripts, formatted from fixed measurements: each must match its
golden text byte for byte (a section is only rewritten by measuring again, so its format must not drift)."""

from __future__ import annotations

import json
from pathlib import Path

import harness
import pytest

from tests.helpers import load_benchmark

GOLDEN = Path(__file__).with_name("golden")


@pytest.fixture(autouse=True)
def fixed_machine(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(harness, "machine_description", lambda: "a test machine, 2 cores")


def viewer_inputs(missed: int) -> tuple[dict, dict, dict]:
    latency = {
        "latencies": [0.25, 0.19, 0.31], "median": 0.25, "sizes": ["256×256"], "rendered_sides": [103, 137, 120],
        "preview_seconds": [0.2, 0.23, 0.3], "render_only_median": 1.06, "missed": missed,
    }  # fmt: skip
    final = {"seconds": [1.5, 2.25, 1.75], "median": 1.75, "sizes": ["800×800"]}
    ab = {
        "seconds": {"plain": [67.0, 76.0], "browser": [76.0, 84.0], "viewer": [92.0, 79.0]},
        "slowdown": 0.091, "browser_slowdown": 0.051, "viewer_over_browser": 0.037, "own_share": 0.037,
        "browser_cpu": {"browser": [6.1, 6.6], "viewer": [8.0, 7.7]}, "steady_slowdown": 0.068,
        "steady_browser_slowdown": 0.029,
    }  # fmt: skip
    return latency, final, ab


def pcpu_rows() -> list[dict]:
    def row(seed: int, ref_s: float, ours_s: float, ref_psnr: float, curve: dict) -> dict:
        reference = {"train_wall_s": ref_s, "final_phase_s_per_it": 0.8, "test_psnr": ref_psnr, "peak_rss_gb": 1.27}
        elapsed = {step: ours_s * int(step) / 800 for step in curve}
        ours = {"train_wall_s": ours_s, "final_phase_s_per_it": 0.175, "test_psnr": curve["800"],
                "peak_rss_gb": 0.74, "psnr_curve": curve, "elapsed": elapsed}  # fmt: skip
        return {"seed": seed, "reference": reference, "ours": ours}

    return [
        row(20211202, 673.0, 126.0, 21.3, {"80": 15.0, "240": 21.5, "800": 21.94}),
        row(1, 690.0, 103.0, 22.5, {"80": 15.0, "800": 22.01}),  # never reaches the reference's PSNR
    ]


GPU_ROWS = [
    {"protocol": "lego", "device": "cuda", "tiny": False, "train_seconds": 612.4, "final_s_per_it": 0.0611,
     "peak_gpu_gb": 5.25, "psnr": 22.1, "paper_psnr": 22.41, "ssim": 0.85, "lpips": 0.12},
    {"protocol": "lego", "device": "cpu", "tiny": True, "train_seconds": None, "final_s_per_it": None,
     "peak_gpu_gb": None, "psnr": 9.5, "paper_psnr": None, "ssim": 0.3, "lpips": None},
]  # fmt: skip
SFM_RESULT = {
    "registered": 20, "total": 20, "mean_reprojection_error_px": 0.701, "rotation_deg_median": 0.49,
    "rotation_deg_max": 0.583, "centre_percent_median": 0.38, "centre_percent_max": 0.671, "wall_seconds": 11.2,
    "training": {
        parser: {"scene_kind": kind, "train_view_ids": [1, 10, 19],
                 "runs": [{"seed": seed, "psnr": psnr + i, "ssim": 0.61 - i / 100, "lpips": 0.4 + i / 100}
                          for i, seed in enumerate((20211202, 1, 2))]}
        for parser, kind, psnr in (("llff-data", "forward-facing (llff-data)", 19.5),
                                   ("nerfstudio-data", "forward-facing", 19.25))
    },
    "passed": {"training": True},
}  # fmt: skip


def room_rows() -> list[tuple[object, dict]]:
    run = harness.Run

    def row(method: str, views: str, psnr: float, chamfer: float | None, iterations: int = 800) -> tuple[object, dict]:
        mesh = {
            "chamfer": chamfer,
            "mesh_to_truth": chamfer and chamfer * 1.5,
            "truth_to_mesh": chamfer and chamfer / 3,
        }
        sized = views == "8" or iterations != 800
        return run(method, 0 if sized else 800, 20211202, views), {
            "method": method, "views": views, "train_views": 8 if views == "8" else 30, "iterations": iterations,
            "psnr": psnr, "ssim": 0.8341, "lpips": 0.0696, "train_seconds": 1577.8} | mesh  # fmt: skip

    return [row("fourierf-vm", "8", 23.81, 0.0199), row("tensorf-vm", "8", 21.5, None),
            row("fourierf-vm", "all", 28.3, 0.0217, 2400), row("tensorf-vm", "all", 27.09, 0.0217, 2400),
            row("fourierf-vm", "all", 24.3, 0.0217), row("tensorf-vm", "all", 26.09, 0.0217)]  # fmt: skip


def golden(name: str) -> str:
    return (GOLDEN / f"{name}.md").read_text()


@pytest.mark.parametrize("missed", [0, 2])
def test_the_viewer_section(missed: int) -> None:
    viewer = load_benchmark("viewer_latency")
    body = viewer.section(*viewer_inputs(missed), "python benchmarks/viewer_latency.py --rounds 2", 800, 2)
    assert "\n".join(body) + "\n" == golden(f"viewer_latency_missed{missed}")


def test_the_pcpu_vs_reference_section() -> None:
    assert "\n".join(load_benchmark("pcpu_vs_reference").section(pcpu_rows())) + "\n" == golden("pcpu_vs_reference")


def test_the_gpu_protocol_section() -> None:
    assert "\n".join(load_benchmark("gpu_protocol").section(GPU_ROWS)) + "\n" == golden("gpu_protocol")


def test_the_process_data_fern_section() -> None:
    assert "\n".join(load_benchmark("process_data_fern").section(SFM_RESULT)) + "\n" == golden("process_data_fern")


def budget_row(budget: str, budget_s: float, planned: int, run: int, train_s: float) -> dict:
    return {
        "budget": budget, "budget_seconds": budget_s, "planned_iterations": planned, "iterations": run,
        "planned_seconds": budget_s * 0.95, "train_seconds": train_s, "wall_seconds": train_s + 12.0,
    }  # fmt: skip


def test_the_time_budget_section() -> None:
    rows = {
        "lego_tiny": [budget_row("30s", 30.0, 180, 180, 28.4), budget_row("1m", 60.0, 400, 371, 57.2)],
        "fern, 3 views": [budget_row("3m", 180.0, 900, 812, 154.0)],  # 14 % short: not within
    }
    assert "\n".join(load_benchmark("time_budget").section(rows)) + "\n" == golden("time_budget")


def test_the_room_capture_section() -> None:
    body = load_benchmark("room_capture").section(room_rows(), 20211202, Path("docs/room_capture.png"))
    assert "\n".join(body) + "\n" == golden("room_capture")


def test_the_ab_speed_section(tmp_path: Path) -> None:
    ab_speed = load_benchmark("ab_speed")
    rows = [{"label": f"{side}-{i}", "seed": seed, "side": side, "train_wall_s": wall, "final_s_per_it": wall / 700,
             "render_s": wall / 25, "psnr": 23 + wall / 1000}
            for i, (seed, pair) in enumerate([(1, (175.4, 179.3)), (2, (159.4, 170.3))])
            for side, wall in zip(("old", "new"), pair, strict=True)]  # fmt: skip
    meta = {"describe": "a change", "pairs": 2, "seeds": [1, 2], "scene": "fern", "old_flags": [],
            "new_flags": ["--x", "1"], "command": "python benchmarks/ab_speed.py --old HEAD"}  # fmt: skip
    for name, value in (("results.jsonl", "".join(json.dumps(r) + "\n" for r in rows)),
                        ("iterations.json", json.dumps({"old": [0.2392, 0.25], "new": [0.2331, 0.24]})),
                        ("meta.json", json.dumps(meta))):  # fmt: skip
        (tmp_path / name).write_text(value)
    ab_speed.write_report(tmp_path, tmp_path / "BENCHMARKS.md")
    assert (tmp_path / "BENCHMARKS.md").read_text() == golden("ab_speed")
