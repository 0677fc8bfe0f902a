"""``fourierf-train fourierf-vm --time-budget B`` on the bundled lego and on fern, three budgets each, one at a time:
planned against actual iterations and seconds (training should end within ``TOLERANCE`` of the budget).

    python benchmarks/time_budget.py [--shared PATH] [--work outputs/bench_time_budget]
"""

from __future__ import annotations

import json
from pathlib import Path

import harness

from fourierf_plugin.method_configs.time_budget import parse_duration

TOLERANCE = 0.10  # training may end this share of the budget early or late
SCENES = {  # its data (the repository's, or under --shared), budgets and parser flags
    "lego_tiny": (Path("demo/lego_tiny"), ("1m", "2m", "3m"), ()),
    "fern, 3 views": (Path("data/llff/fern"), ("2m", "3m", "4m"), ("llff-data", "--num-views", "3")),
}


def measure(data: Path, budget: str, parser: tuple[str, ...], work: Path, name: str) -> dict:
    _, records, wall, _ = harness.train_run(data, work, name, "--time-budget", budget, *parser)
    done = harness.done_record(records) or {}
    replans = [r for r in records if r.get("event") == "replan"]
    return {
        "budget": budget, "budget_seconds": parse_duration(budget), "iterations": done.get("step"),
        "planned_iterations": done.get("planned_iterations", done.get("step")),
        "plans": [r["from"] for r in replans[:1]] + [r["to"] for r in replans],
        "planned_seconds": done.get("planned_train_seconds"), "train_seconds": done.get("train_seconds"),
        "wall_seconds": wall,
    }  # fmt: skip


def within(row: dict) -> bool:
    """Whether a run's training ended within ``TOLERANCE`` of its budget."""
    return abs(row["train_seconds"] / row["budget_seconds"] - 1) <= TOLERANCE


def planned(row: dict) -> str:
    """The count planned before training and each new one the run planned from its own speed."""
    plans = row.get("plans", [])
    counts = [n for i, n in enumerate(plans) if not i or n != plans[i - 1]]
    return " → ".join(map(str, counts or [row["planned_iterations"]]))


def section(rows: dict[str, list[dict]]) -> list[str]:
    runs = [r for scene in rows.values() for r in scene]
    return [
        *harness.section_head(
            "Time budgets: planned against actual (fourierf-train --time-budget)",
            "python benchmarks/time_budget.py",
            "`fourierf-train fourierf-vm --data DATA --time-budget B` with every other value at its default, one run "
            "at a time. The budget covers training; setup, the opening timing and the final save are in the wall "
            "time beside it. Planned iterations: timed before training → planned again from the run's own "
            "speed after its first steps → and after its last event.",
        ),
        "| scene | budget | planned iterations | iterations run | planned training | training | whole command |",
        "|---|---|---|---|---|---|---|",
        *(
            f"| {scene} | {r['budget']} | {planned(r)} | {r['iterations']} | "
            f"{r['planned_seconds']:.0f} s | {r['train_seconds']:.0f} s "
            f"({r['train_seconds'] / r['budget_seconds'] - 1:+.0%}) | {r['wall_seconds']:.0f} s |"
            for scene, scene_rows in rows.items()
            for r in scene_rows
        ),
        "",
        f"Training ended within {TOLERANCE:.0%} of its budget in {sum(map(within, runs))} of {len(runs)} runs.",
    ]


def main() -> dict:
    args = harness.arguments(__doc__, "bench_time_budget").parse_args()
    rows: dict[str, list[dict]] = {}
    for scene, (data, budgets, parser) in SCENES.items():
        root = harness.REPO if (harness.REPO / data).exists() else args.shared
        rows[scene] = [measure(root / data, b, parser, args.work, f"{scene.split(',')[0]}_{b}") for b in budgets]
        for r in rows[scene]:
            print(f"{scene} {r['budget']}: trained {r['train_seconds']:.1f} s of {r['budget_seconds']:.0f} s")
    (args.work / "results.json").write_text(json.dumps(rows, indent=2))
    harness.write_section(args.markdown, "time-budget", "time_budget.py", section(rows))
    return rows


if __name__ == "__main__":
    main()
