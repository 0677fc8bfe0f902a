"""The suite's report: the few-shot quality, equal-time and equal-iterations sections of BENCHMARKS.md and the
equal-time figure, pure functions of the committed rows (nothing is trained here).

    python benchmarks/report.py        # reads benchmarks/results/{quality,equal_time,equal_iterations}/*.jsonl
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from xml.sax.saxutils import escape

import harness
import numpy as np

SUITE = harness.load_suite()
F, T = "fourierf-vm", "tensorf-vm"


# -- few-shot quality: each method at its own val-chosen setting per scene and protocol ----------------------------
def val_cell(rows: list[dict], seeds: Sequence[int]) -> str:
    """A setting's val PSNR: the first seed's, and the mean over the seeds run (named where not all were)."""
    vals = harness.val_by_seed(rows, seeds)
    first = f"{vals[seeds[0]]:.2f}" if seeds[0] in vals else "—"
    mean = float(np.mean(list(vals.values()))) if vals else 0.0
    if len(vals) == len(seeds):
        return f"{first} (seeds: {mean:.2f})"
    if len(vals) > 1:
        return f"{first} (seeds {', '.join(map(str, vals))}: {mean:.2f})"
    return first


def val_test(row: dict) -> str:
    """A row's val and test PSNR, as the tables below set them side by side."""
    return f"{row['val_psnr']:.2f} / {row['psnr']:.2f}"


def curve_table(results: dict[str, dict], suite: harness.Suite = SUITE) -> list[str]:
    """Val and test PSNR along each curve run, next to the 800-iteration run of its setting (the rule's at 800)."""
    pairs = {(m, r["at_3000"]): r["at_800"] for m, r in suite.rule_along_the_budget.items()}
    pairs[(F, "lr0.08-tvconst-ramp0.2667-tv4")] = "lr0.08-tvconst-tv4"  # the band open by step 800 of 3000
    lines = []
    for r in sorted((r for r in results.values() if "curve" in r), key=lambda r: r["key"]):
        groups = harness.rows_by(results, r["scene"], suite.protocols[r["protocol"]].curve_of, r["method"])
        setting = r["setting"] if r["setting"] in groups else pairs.get((r["method"], r["setting"]), "")
        short = [x for x in groups.get(setting, []) if x["seed"] == r["seed"]]
        steps = " · ".join(f"{int(step)}: {val:.2f} / {test:.2f}" for step, val, test in r["curve"])
        against = val_test(short[0]) if short else "—"
        if short and setting != r["setting"]:
            against += f" (`{setting}`)"
        lines.append(f"| {r['scene']} | {r['method']} | `{r['setting']}` | {against} | {steps} |")
    return harness.titled_table(
        "Along the budget (`run.py curve`): one run of 3000 iterations, its checkpoints every "
        f"{suite.curve_every} iterations evaluated on val and test, against a run of 800 iterations with the same "
        "sizes and setting (its schedules are fractions of its own length, so step 800 of the long run is not the "
        "short run). Val / test PSNR:",
        ["scene", "method", "setting", "800-iteration run", "3000-iteration run, step: val / test"],
        lines,
    )


def first_seed(results: dict[str, dict], protocol: str, method: str, setting: str, suite: harness.Suite) -> dict | None:
    rows = harness.rows_by(results, "fern", protocol, method).get(setting, [])
    return next((r for r in rows if r["seed"] == suite.seeds[0]), None)


def along_the_budget(results: dict[str, dict], suite: harness.Suite = SUITE) -> list[str]:
    """Fern, first seed, 800 against 3000 iterations: each method at mid sizes and `lr0.08` (mid-800's only seed), then
    at the budget rule's settings at cpu sizes (does a user's run under the rule get better as the budget grows?)."""
    runs = {m: [first_seed(results, p, m, "lr0.08", suite) for p in ("mid-800", "mid-3000")] for m in suite.methods}
    lines = [
        f"- fern, {m}, mid sizes, `lr0.08`, 800 → 3000 iterations: val {short['val_psnr']:.2f} → "
        f"{long['val_psnr']:.2f}, test {short['psnr']:.2f} → {long['psnr']:.2f}"
        for m, (short, long) in runs.items()
        if short and long
    ]
    for method, rule in suite.rule_along_the_budget.items():
        a, b = (first_seed(results, f"cpu-{n}", method, rule[f"at_{n}"], suite) for n in (800, 3000))
        if a and b:
            lines.append(
                f"- fern, {method}, the budget rule's settings at cpu sizes: `{rule['at_800']}` at 800 iterations val "
                f"{a['val_psnr']:.2f}, test {a['psnr']:.2f} → `{rule['at_3000']}` at 3000 val {b['val_psnr']:.2f}, "
                f"test {b['psnr']:.2f}"
            )
    return lines


def targets_table(results: dict[str, dict], suite: harness.Suite = SUITE) -> list[str]:
    """Each target as measured: both methods' choices, the lead in test PSNR and by how much it is met or missed."""
    lines = []
    for t in suite.targets:
        picked, test = {}, {}
        for method, allowed in ((F, t.get("fourierf", ())), (T, t.get("tensorf", ()))):
            groups = harness.rows_by(results, t["scene"], t["protocol"], method)
            groups = {s: r for s, r in groups.items() if not allowed or s in allowed}
            picked[method] = harness.chosen_setting(groups, suite.seeds)
            test[method] = {r["seed"]: r["psnr"] for r in groups.get(picked[method], [])}
        if not all(test.values()):
            continue
        own, baseline = (float(np.mean(list(test[m].values()))) for m in (F, T))
        lead = own - baseline
        per_seed = ", ".join(f"{test[F][s] - test[T][s]:+.2f}" for s in suite.seeds if s in test[F] and s in test[T])
        floor = t.get("floor")
        short = [f"lead by {t['lead'] - lead:.2f}"] if lead < t["lead"] else []
        if floor is not None and own < floor:
            short.append(f"PSNR by {floor - own:.2f}")
        at_least = f"≥ {floor:.1f} dB and " if floor is not None else ""
        cells = [f"`{picked[m]}`, {harness.fmt(list(test[m].values()), 2)} ({len(test[m])})" for m in (F, T)]
        status = "missed: " + ", ".join(short) if short else "met"
        target = f"{t['scene']}, {t['protocol']}: fourierf-vm {at_least}≥ +{t['lead']:.1f} dB; {t['against']}"
        lines.append(harness.md_row([target, *cells, f"**{lead:+.2f}** ({per_seed})", status]))
    return harness.titled_table(
        "The quality targets, measured (test PSNR, mean ± std over the seeds; the lead per seed in brackets, seeds "
        f"{', '.join(map(str, suite.seeds))}; each choice made on val among the settings the baseline allows):",
        ["target", *(f"{m}: setting, test PSNR (seeds)" for m in (F, T)), "lead", "status"],
        lines,
    )


def later_seeds_table(results: dict[str, dict], repeats: Sequence[dict], suite: harness.Suite = SUITE) -> list[str]:
    """Every setting run on each later seed on a GPU, beside its repeats (GPU training is not bit-reproducible)."""
    later = suite.seeds[1:]
    groups: dict[tuple[str, str, str, str, str], dict[int, dict]] = {}
    for r in [*results.values(), *repeats]:
        if r.get("device") == "cuda" and r["seed"] in later:
            group = (r["scene"], r["protocol"], r["method"], r["setting"], r.get("repeat", ""))
            groups.setdefault(group, {})[r["seed"]] = r
    lines = []
    for (scene, protocol, method, setting, note), by_seed in sorted(groups.items()):
        if set(by_seed) == set(later):
            rows = [by_seed[seed] for seed in later]
            mean = {k: np.mean([r[k] for r in rows]) for k in ("val_psnr", "psnr")}
            named = f"`{setting}`" + (f" ({note})" if note else "")
            lines.append(harness.md_row([scene, protocol, method, named, *map(val_test, [*rows, mean])]))
    return harness.titled_table(
        f"Settings run on seeds {', '.join(map(str, later))} on a GPU (an H100, several runs at once), beside "
        "their other runs: `-plain` is TensoRF's ReLU for the density, `-revive1` revives every dark batch (the "
        "budget rule's for a forward-facing run over 800 iterations), no suffix the field's default, which revives "
        "a field only when it is dead. GPU training is not bit-reproducible (grid_sample's CUDA backward accumulates "
        "with atomics), so a repeat of one setting and seed is the spread a difference must clear.",
        ["scene", "protocol", "method", "setting", *(f"seed {seed}: val / test" for seed in later), "mean val / test"],
        lines,
    )


def threads_cell(rows: Iterable[dict]) -> str:
    """The CPU threads the rows trained on (``?``: not recorded; ``—``: none ran on a CPU)."""
    threads = sorted({str(r.get("train_threads") or "?") for r in rows if r.get("device") == "cpu"})
    return " / ".join(threads) or "—"


def cpu_reruns_table(results: dict[str, dict], repeats: Sequence[dict]) -> list[str]:
    """Every CPU run of a key that ran twice, beside the row the report reads: the spread a difference must clear."""
    lines = []
    others = [r for r in repeats if r.get("device") == "cpu" and r["key"] in results]
    for other in sorted(others, key=lambda r: r["key"]):
        kept = results[other["key"]]
        cells = [f"{val_test(r)} ({threads_cell([r])})" for r in (kept, other)]
        named = [kept["scene"], kept["protocol"], kept["method"], f"`{kept['setting']}`", kept["seed"]]
        lines.append(harness.md_row([*named, *cells, other["repeat"]]))
    return harness.titled_table(
        "CPU runs of one setting and seed run twice: the row the tables above read and the other run (`repeats.jsonl`"
        "), val / test PSNR (CPU threads; ? = not recorded). Only a one-thread CPU run is bit-reproducible.",
        ["scene", "protocol", "method", "setting", "seed", "read above", "other run", "what the other run was"],
        lines,
    )


def comparable_seconds(rows: dict[str, list[dict]]) -> str:
    """Each method's mean training seconds on the one device both ran most of their runs on."""
    shared = sorted(set.intersection(*({r["device"] for r in rows[m]} for m in rows)))
    if not shared:
        return "— (no shared device)"
    device = max(shared, key=lambda d: sum(r["device"] == d for m in rows for r in rows[m]))
    secs = [np.mean([r["train_seconds"] for r in rows[m] if r["device"] == device]) for m in rows]
    return " / ".join(f"{t:.0f}" for t in secs) + f" ({device})"


def recording_machines(rows: Iterable[dict]) -> str:
    """Where the rows ran (many machines; those that record their CPU named), not the machine writing the report."""
    named = sorted({r["machine"] for r in rows if "machine" in r})
    those = f"; rows that record theirs: {'; '.join(named)}" if named else ""
    return f"several machines (2-core CPUs, torch 2.13.0+cpu; an H100 where the device is cuda){those}"


def quality_section(results: dict[str, dict], repeats: Sequence[dict], suite: harness.Suite = SUITE) -> list[str]:
    seeds = suite.seeds
    views = "; ".join(f"{scene}: {s['views']}" for scene, s in suite.scenes.items())
    body = harness.section_head(
        "Few-shot quality: fourierf-vm against tensorf-vm, settings chosen on val",
        "python benchmarks/run.py sweep|seeds|curve, then python benchmarks/report.py",
        "Protocols, scenes and settings: `benchmarks/suite.toml` (a protocol is named by its sizes and iterations: "
        "cpu, what a CPU run gets by default (P-CPU in the speed sections); mid, the largest that trains in about 20 "
        f"minutes on 2 cores). {views}. Each method at its own val-chosen setting (best mean val PSNR over seeds "
        f"{', '.join(map(str, seeds))} among the settings run on all of them, else best val PSNR of seed {seeds[0]}); "
        "test PSNR of that setting only, mean ± std over the seeds run. PSNRs agree across devices up to float "
        "rounding and random streams. Training seconds are the device's and were taken while other work shared the "
        "machine: they are no speed measurement (the speed benchmarks are the interleaved ones).",
        machine=recording_machines(results.values()),
    )
    protocols = []
    for p in suite.protocols.values():
        images = {"lego": f"{400 // p.lego_downscale}×{400 // p.lego_downscale}", "fern": "504×378"}
        sizes = [image if scene in p.scenes else "—" for scene, image in images.items()]
        protocols.append(harness.md_row([p.name, p.iters, p.rays, f"{p.grid[0]}³ → {p.grid[1]}³", *sizes]))
    body += [*harness.table(["protocol", "iterations", "rays", "grid", "lego image", "fern image"], protocols), ""]
    chosen: list[str] = []
    sweeps: list[str] = []
    for scene in suite.settings:
        for p in suite.protocols:
            tables = {m: harness.rows_by(results, scene, p, m) for m in (F, T)}
            if not all(tables.values()):
                continue
            picked = {m: harness.chosen_setting(tables[m], seeds) for m in (F, T)}
            rows = {m: tables[m][picked[m]] for m in (F, T)}
            test = {m: [r["psnr"] for r in rows[m]] for m in (F, T)}
            both = rows[F] + rows[T]
            device = "/".join(sorted({r["device"] for r in both}))
            cells = [f"`{picked[m]}`, {harness.fmt(test[m], 2)} ({len(test[m])})" for m in (F, T)]
            gap = f"**{np.mean(test[F]) - np.mean(test[T]):+.2f}**"
            chosen.append(harness.md_row([scene, p, device, *cells, gap, threads_cell(both), comparable_seconds(rows)]))
            for s in suite.settings[scene]:
                vals = [val_cell(tables[m][s], seeds) if s in tables[m] else "—" for m in (F, T)]
                if vals != ["—", "—"]:
                    sweeps.append(harness.md_row([scene, p, s, *vals]))
    picks = [f"{m}: setting, test PSNR (seeds)" for m in (F, T)]
    head = ["scene", "protocol", "device", *picks, "gap", "CPU threads", "train s (f / t)"]
    body += [*harness.table(head, chosen), ""]
    body += targets_table(results, suite)
    body += along_the_budget(results, suite)
    body += ["", *curve_table(results, suite)]
    body += later_seeds_table(results, repeats, suite)
    body += cpu_reruns_table(results, repeats)
    body += [
        f"Validation PSNR of every setting tried, seed {seeds[0]}, and the mean over all {len(seeds)} seeds where "
        "they were run, or over the seeds named where only some were (the choice above is the best all-seed mean of "
        "each column, else its best first seed):",
        "",
        *harness.table(["scene", "protocol", "setting", f"{F} val", f"{T} val"], sweeps),
        "",
    ]
    for grid in suite.grids:
        if (harness.REPO / grid["path"]).is_file():
            columns = ", ".join(("ground truth", *grid["columns"]))
            body += [
                f"{grid['heading']}: `{grid['path']}` (`python benchmarks/picture_grid.py`, {grid['runs']}; "
                f"{grid['views']}). Columns: {columns.replace(', ', ' | ')}; rows: RGB, depth (turbo, dark = near, "
                "one range per view), accumulation.",
                "",
                f"![{grid['scene']}: {columns}; rgb, depth, accumulation]({grid['path']})",
                "",
                f"What the grid shows (read by eye, not measured): {grid['reading']}",
                "",
            ]
    return body


# -- equal time and equal iterations: each point a user's run (run.py equal-time / equal-iterations) ---------------
FIGURE = "docs/equal_time.svg"
ITERATIONS_TITLE = "Equal iterations: the paper's systems at the default CPU run"
PAPER, BASELINE = "fourierf-vm-paper", "tensorf-vm-published"
ALPHA, NO_ALPHA = "zerorf-vm", "zerorf-vm-no-alpha"
COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#17becf", "#7f7f7f")


def stage_head(rows: Sequence[dict], title: str, command: str, settings: str) -> list[str]:
    """An equal-time or equal-iterations section's opening lines, naming the machines its rows ran on."""
    machines = "; ".join(sorted({r["machine"] for r in rows})) or "none yet"
    return harness.section_head(title, command, settings, machine=f"{machines}, one thread a run")


def lego_side(suite: harness.Suite) -> int:
    return 400 // suite.protocols[suite.equal_time["protocol"]].lego_downscale


def timed(rows: Sequence[dict], scene: str, method: str) -> list[dict]:
    """The rows of a method (or variant) on a scene that trained (not too short), by training time."""
    found = [r for r in rows if (r["scene"], r["method"]) == (scene, method) and "too_short" not in r]
    return sorted(found, key=lambda r: r["trained_seconds"])


def time_to_psnr(points: Sequence[tuple[float, float]], target: float) -> tuple[float, bool] | None:
    """(Seconds, whether an upper bound) to reach ``target`` along (seconds, PSNR) points, linear in log time."""
    for i, (seconds, psnr) in enumerate(points):
        if psnr < target:
            continue
        if i == 0:
            return seconds, True
        (t0, p0), (t1, p1) = points[i - 1], points[i]
        share = (target - p0) / (p1 - p0)
        return math.exp(math.log(t0) + share * (math.log(t1) - math.log(t0))), False
    return None


def duration(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.1f} min" if seconds < 5400 else f"{seconds / 3600:.1f} h"


def time_cell(points: Sequence[tuple[float, float]], target: float) -> str:
    found = time_to_psnr(points, target)
    return "not reached" if found is None else ("≤ " if found[1] else "") + duration(found[0])


def methods_of(rows: Sequence[dict], suite: harness.Suite) -> list[str]:
    """The suite's methods that have rows, in the suite's order, then any others the rows hold."""
    listed = [m for m in suite.equal_time["methods"] if any(r["method"] == m for r in rows)]
    return listed + sorted({r["method"] for r in rows} - set(listed))


def scene_tables(rows: Sequence[dict], scene: str, suite: harness.Suite) -> list[str]:
    here = {(r["method"], r["budget"]): r for r in rows if r["scene"] == scene}
    seconds = {budget: r["budget_seconds"] for (_, budget), r in here.items()}
    budgets, methods = sorted(seconds, key=seconds.__getitem__), methods_of(list(here.values()), suite)
    targets = suite.equal_time["psnr_targets"].get(scene, [])

    def cell(row: dict | None) -> str:
        if row is None:
            return "—"
        return "too short" if "too_short" in row else f"{row['psnr']:.2f} / {row['ssim']:.3f} / {row['lpips']:.3f}"

    lines = [
        f"### {scene}",
        "",
        *harness.titled_table(
            "Test PSNR / SSIM / LPIPS at each budget (too short: the budget does not fit the method's fewest "
            "iterations; —: not run at that budget):",
            ["method", *budgets],
            [harness.md_row([m, *(cell(here.get((m, b))) for b in budgets)]) for m in methods],
        ),
    ]
    points = {m: [(r["trained_seconds"], r["psnr"]) for r in timed(rows, scene, m)] for m in methods}
    return lines + harness.titled_table(
        "Training time to reach a test PSNR (interpolated on log time between budgets; ≤: reached at the first):",
        ["method", *(f"{t:.1f} dB" for t in targets)],
        [harness.md_row([m, *(time_cell(points[m], t) for t in targets)]) for m in methods] if targets else [],
    )


def equal_time_section(rows: Sequence[dict], suite: harness.Suite) -> list[str]:
    side = lego_side(suite)
    body = stage_head(
        rows,
        "Equal-time comparison",
        "python benchmarks/run.py equal-time --jobs 2, then python benchmarks/report.py",
        "Each point is a user's run: `fourierf-train METHOD --time-budget B --threads 1`, sized for the scene and "
        "the machine, the short-run rules applying as they would, then `fourierf-eval` on the test views. Scenes "
        f"and budgets: `[equal_time]` in `benchmarks/suite.toml`; lego at {side}×{side}. Times are training seconds "
        "from each run's metrics (setup and evaluation not included).",
    )
    if not rows:
        return [*body, "No points are recorded yet.", ""]
    for scene in suite.equal_time["scenes"]:
        if any(r["scene"] == scene for r in rows):
            body += scene_tables(rows, scene, suite)
    if off := [r["trained_seconds"] / r["planned_seconds"] - 1 for r in rows if r.get("planned_seconds")]:
        spread = f"{min(off):+.0%}" + (f" to {max(off):+.0%}" if len(off) > 1 else "")
        body += [f"Actual against planned training time: {spread} over the {len(off)} trained points.", ""]
    stopped = [r for r in rows if r.get("planned_iterations", 0) > r.get("iterations", 0)]
    if cut := [r["iterations"] / r["planned_iterations"] for r in stopped]:
        body += [
            f"Points stopped at their budget before the end of their schedules: {len(cut)}, after {min(cut):.0%} to "
            f"{max(cut):.0%} of their planned iterations (their iterations cost more than the run timed them at).",
            "",
        ]
    total, jobs = sum(r["seconds"] for r in rows), max(r["jobs"] for r in rows)
    return [
        *body,
        f'Training time over {BASELINE}\'s: the last line of "{ITERATIONS_TITLE}" (rows of one invocation only).',
        "",
        f"The {len(rows)} points took {duration(total)} in all, about {duration(total / jobs)} at {jobs} at a time.",
        "",
        f"![test PSNR against training time, log axis]({FIGURE})",
        "",
    ]


def figure(rows: Sequence[dict], suite: harness.Suite) -> str:
    """Test PSNR against training time (log axis), one panel a scene, one polyline a method with trained points."""
    scenes, methods = list(suite.equal_time["scenes"]), methods_of(rows, suite)
    width, height, left, top, plot_w, plot_h = 460, 330, 60, 30, 370, 240
    size = f'width="{width * len(scenes)}" height="{height + 24 * len(methods) + 10}"'
    svg = f'<svg xmlns="http://www.w3.org/2000/svg" {size} font-family="sans-serif" font-size="12">'
    out = [svg, f'<rect {size} fill="white"/>']
    for k, scene in enumerate(scenes):
        x0, lines = k * width + left, {m: timed(rows, scene, m) for m in methods}
        points = [r for found in lines.values() for r in found]
        out.append(f'<text x="{x0 + plot_w / 2}" y="{top - 10}" text-anchor="middle">{escape(scene)}</text>')
        out.append(f'<rect x="{x0}" y="{top}" width="{plot_w}" height="{plot_h}" fill="none" stroke="black"/>')
        out.append(f'<text x="{x0 + plot_w / 2}" y="{top + plot_h + 36}" text-anchor="middle">'
                   "training time (s, log axis)</text>")  # fmt: skip
        out.append(f'<text x="{x0 - 42}" y="{top + plot_h / 2}" text-anchor="middle" '
                   f'transform="rotate(-90 {x0 - 42} {top + plot_h / 2})">test PSNR (dB)</text>')  # fmt: skip
        if not points:
            out.append(f'<text x="{x0 + plot_w / 2}" y="{top + plot_h / 2}" text-anchor="middle">no points</text>')
            continue
        logs = [math.log10(r["trained_seconds"]) for r in points]
        lo_t, hi_t = min(logs) - 0.1, max(logs) + 0.1
        lo_p, hi_p = math.floor(min(r["psnr"] for r in points)) - 0.5, math.ceil(max(r["psnr"] for r in points)) + 0.5

        def x(seconds: float, x0: float = x0, lo: float = lo_t, hi: float = hi_t) -> float:
            return x0 + (math.log10(seconds) - lo) / (hi - lo) * plot_w

        def y(psnr: float, lo: float = lo_p, hi: float = hi_p) -> float:
            return top + (hi - psnr) / (hi - lo) * plot_h

        for tick in (t for t in (10, 30, 60, 120, 300, 600, 1200, 1800, 3600, 7200) if lo_t <= math.log10(t) <= hi_t):
            out.append(f'<text x="{x(tick):.1f}" y="{top + plot_h + 16}" text-anchor="middle">{tick}</text>')
        for tick in range(math.ceil(lo_p), math.floor(hi_p) + 1):
            out.append(f'<text x="{x0 - 6}" y="{y(tick) + 4:.1f}" text-anchor="end">{tick}</text>')
        for i, (m, found) in enumerate(lines.items()):
            if found:
                xy = [(f"{x(r['trained_seconds']):.1f}", f"{y(r['psnr']):.1f}") for r in found]
                colour = COLOURS[i % len(COLOURS)]
                out.append(f'<polyline points="{" ".join(",".join(v) for v in xy)}" fill="none" stroke="{colour}" '
                           f'stroke-width="2" data-method="{escape(m)}" data-scene="{escape(scene)}"/>')  # fmt: skip
                out += [f'<circle cx="{cx}" cy="{cy}" r="3" fill="{colour}"/>' for cx, cy in xy]
    for i, m in enumerate(methods):
        y_legend = height + 24 * i
        out.append(f'<line x1="{left}" y1="{y_legend}" x2="{left + 30}" y2="{y_legend}" '
                   f'stroke="{COLOURS[i % len(COLOURS)]}" stroke-width="2"/>')  # fmt: skip
        out.append(f'<text x="{left + 38}" y="{y_legend + 4}">{escape(m)}</text>')
    return "\n".join([*out, "</svg>", ""])


def counted(rows: Sequence[dict], scene: str, method: str) -> list[dict]:
    """``timed``'s rows of a method (or variant), most iterations first."""
    return sorted(timed(rows, scene, method), key=lambda r: -r["iterations"])


def gap(rows: Sequence[dict], scene: str, ahead: str, behind: str) -> str:
    """Test PSNR of ``ahead`` minus ``behind`` on a scene at the most iterations both ran."""
    for first in counted(rows, scene, ahead):
        second = next((r for r in counted(rows, scene, behind) if r["budget"] == first["budget"]), None)
        if second is not None:
            return f"{first['psnr'] - second['psnr']:+.2f} dB at {first['iterations']} iterations"
    return "not run at equal iterations"


def iterations_table(rows: Sequence[dict], scene: str, methods: Sequence[str]) -> list[str]:
    head = ["method", "test PSNR", "SSIM", "LPIPS", "iterations", "training s", "s/iteration"]
    lines = [f"### {scene}", "", *harness.table(head, [])]
    for method in methods:
        lines += [
            f"| {method} | {row['psnr']:.2f} | {row['ssim']:.3f} | {row['lpips']:.3f} | {row['iterations']} | "
            f"{row['trained_seconds']:.0f} | {row['seconds_per_iteration']:.2f} |"
            for row in counted(rows, scene, method)
        ] or [f"| {method} | not run | | | | | |"]
    return [*lines, ""]


def time_ratios(rows: Sequence[dict], scene: str, suite: harness.Suite) -> str:
    """Each method's training time over the baseline's on a scene, from the rows of the baseline's invocation at its
    iterations only (one machine, one load), the paper's Table 3 ratio in brackets where it has one."""
    stage, paper = suite.equal_time["iterations"], suite.equal_time["paper_time_ratio"]
    base = next(iter(counted(rows, scene, BASELINE)), None)
    if base is None or not base.get("invocation"):
        return f"{scene} not timed in one invocation"
    ratios = [
        f"{r['method']} {r['trained_seconds'] / base['trained_seconds']:.2f}"
        + (f" ({paper[r['method']]})" if r["method"] in paper else "")
        for method in stage["methods"]
        if method != BASELINE
        for r in counted(rows, scene, method)
        if (r.get("invocation"), r["budget"]) == (base["invocation"], base["budget"])
    ]
    return f"{scene} at {base['iterations']} iterations: " + (", ".join(ratios) or "no other method in its invocation")


def derived_lines(rows: Sequence[dict], suite: harness.Suite) -> list[str]:
    """FourieRF (paper) over TensoRF (published) on each scene beside the paper's gap; ZeroRF's alpha term on lego;
    each method's training time over TensoRF (published)'s beside the paper's Table 3."""
    scenes, paper_gap = suite.equal_time["scenes"], suite.equal_time["iterations"]["paper_gap"]
    gaps = [
        f"{scene} {gap(rows, scene, PAPER, BASELINE)} (paper at full scale: {paper_gap[scene]:+.1f} dB)"
        for scene in scenes
    ]
    return [
        f"- {PAPER} minus {BASELINE}, test PSNR: " + "; ".join(gaps) + ".",
        f"- {ALPHA} with minus without its alpha term ({NO_ALPHA}) on lego: {gap(rows, 'lego', ALPHA, NO_ALPHA)}.",
        f"- Training time over {BASELINE}'s, rows of one invocation (the paper's Table 3 in brackets): "
        + "; ".join(time_ratios(rows, scene, suite) for scene in scenes)
        + ".",
        "",
    ]


def equal_iterations_section(rows: Sequence[dict], suite: harness.Suite) -> list[str]:
    stage, side = suite.equal_time["iterations"], lego_side(suite)
    body = stage_head(
        rows,
        ITERATIONS_TITLE,
        "python benchmarks/run.py equal-iterations --scene lego fern --jobs 2, then python benchmarks/report.py",
        f"Each point is a user's run at {stage['budget'].removesuffix('it')} iterations: `fourierf-train METHOD "
        "--max-num-iterations N --threads 1` with no size flag (sized as the default CPU run, the short-run rules "
        f"applying as they would), then `fourierf-eval` on the test views; lego at {side}×{side}. {NO_ALPHA} is "
        "zerorf-vm with `--pipeline.model.alpha-weight 0`, on lego only (fern's images carry no alpha). A method "
        "too slow for that budget here runs a shorter one (`--budget Nit`), the iterations column saying which; "
        "each derived line compares rows of equal iterations only. Training seconds compare only within one "
        "invocation of run.py (one machine, one load): the time line takes its rows from the baseline's.",
    )
    if not rows:
        return [*body, "No points are recorded yet.", ""]
    for scene in suite.equal_time["scenes"]:
        variants = stage.get("variants", {})
        methods = [m for m in stage["methods"] if scene in variants.get(m, {}).get("scenes", [scene])]
        body += iterations_table(rows, scene, methods)
    return [*body, *derived_lines(rows, suite)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--markdown", type=Path, default=harness.REPO / "BENCHMARKS.md")
    args = ap.parse_args()
    quality, timed_rows, counted_rows = (
        harness.load_results(harness.RESULTS / family / "results.jsonl")
        for family in ("quality", "equal_time", "equal_iterations")
    )
    repeats = harness.read_jsonl(harness.RESULTS / "quality" / harness.REPEATS)
    for name, body in (
        ("quality", quality_section(quality, repeats)),
        ("equal-time", equal_time_section([*timed_rows.values()], SUITE)),
        ("equal-iterations", equal_iterations_section([*counted_rows.values()], SUITE)),
    ):
        harness.write_section(args.markdown, name, "report.py", body)
    (harness.REPO / FIGURE).write_text(figure([*timed_rows.values()], SUITE))


if __name__ == "__main__":
    main()
