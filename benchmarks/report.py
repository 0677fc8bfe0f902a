"""The suite's report: regenerates the few-shot quality, the equal-time and the equal-iterations sections of
BENCHMARKS.md (and the equal-time figure) from the committed rows.

    python benchmarks/report.py        # reads benchmarks/results/{quality,equal_time,equal_iterations}/*.jsonl

Each method at its own val-chosen setting per scene and protocol; the test PSNR of that setting only. Nothing is
trained here: a section is a pure function of the rows, so it is regenerated at any time.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable, Sequence
from pathlib import Path

import equal_iterations_report as ei
import equal_time_report as et
import numpy as np
from equal_time import EQUAL_ITERATIONS_RESULTS
from harness import (
    EQUAL_TIME_RESULTS,
    QUALITY_RESULTS,
    REPEATS,
    REPO,
    Suite,
    chosen_setting,
    fmt,
    load_results,
    load_suite,
    markers,
    read_repeats,
    rows_by,
    section_head,
    update_benchmarks_md,
    val_by_seed,
)

SUITE = load_suite()
BEGIN, END = markers("quality", "report.py")
F, T = "fourierf-vm", "tensorf-vm"


def val_cell(rows: list[dict], seeds: Sequence[int]) -> str:
    """A setting's val PSNR for the sweep table: the first seed's, and the mean over every seed where all were run,
    else over the seeds that were (named, as such a mean does not take part in the choice)."""
    vals = val_by_seed(rows, seeds)
    first = f"{vals[seeds[0]]:.2f}" if seeds[0] in vals else "—"
    mean = float(np.mean(list(vals.values()))) if vals else 0.0
    if len(vals) == len(seeds):
        return f"{first} (seeds: {mean:.2f})"
    if len(vals) > 1:
        return f"{first} (seeds {', '.join(map(str, vals))}: {mean:.2f})"
    return first


def rule_at_800(suite: Suite) -> dict[tuple[str, str], str]:
    """(method, the rule's 3000-iteration setting) -> its 800-iteration setting, where the two are named apart."""
    pairs = {(m, r["at_3000"]): r["at_800"] for m, r in suite.rule_along_the_budget.items()}
    return pairs | {(F, "lr0.08-tvconst-ramp0.2667-tv4"): "lr0.08-tvconst-tv4"}  # the band open by step 800 of 3000


def curve_table(results: dict[str, dict], suite: Suite = SUITE) -> list[str]:
    """Val and test PSNR along each curve run's training, next to the 800-iteration run of the same sizes and setting,
    or the budget rule's setting at 800 where the rule names them apart (does quality hold as the budget grows?)."""
    lines, pairs = [], rule_at_800(suite)
    for r in sorted(results.values(), key=lambda r: r["key"]):
        if "curve" not in r:
            continue
        groups = rows_by(results, r["scene"], suite.protocols[r["protocol"]].curve_of, r["method"])
        setting = r["setting"] if r["setting"] in groups else pairs.get((r["method"], r["setting"]), "")
        short = [x for x in groups.get(setting, []) if x["seed"] == r["seed"]]
        steps = " · ".join(f"{int(step)}: {val:.2f} / {test:.2f}" for step, val, test in r["curve"])
        against = f"{short[0]['val_psnr']:.2f} / {short[0]['psnr']:.2f}" if short else "—"
        if short and setting != r["setting"]:
            against += f" (`{setting}`)"
        lines.append(f"| {r['scene']} | {r['method']} | `{r['setting']}` | {against} | {steps} |")
    if not lines:
        return []
    return [
        "Along the budget (`run.py curve`): one run of 3000 iterations, its checkpoints every "
        f"{suite.curve_every} iterations evaluated on val and test, against a run of 800 iterations with the same "
        "sizes and setting (its schedules are fractions of its own length, so step 800 of the long run is not the "
        "short run). Val / test PSNR:",
        "",
        "| scene | method | setting | 800-iteration run | 3000-iteration run, step: val / test |",
        "|---|---|---|---|---|",
        *lines,
        "",
    ]


def first_seed_row(results: dict[str, dict], protocol: str, method: str, setting: str, suite: Suite) -> dict | None:
    rows = [r for r in rows_by(results, "fern", protocol, method).get(setting, []) if r["seed"] == suite.seeds[0]]
    return rows[0] if rows else None


def mid_along_the_budget(results: dict[str, dict], suite: Suite = SUITE) -> list[str]:
    """Does quality hold as the budget grows? Fern at mid sizes and `lr0.08`, 800 against 3000 iterations, for each
    method: the first seed's runs, the only seed mid-800 ran."""
    lines = []
    for m in suite.methods:
        short, long = (first_seed_row(results, p, m, "lr0.08", suite) for p in ("mid-800", "mid-3000"))
        if short and long:
            lines.append(
                f"- fern, {m}, mid sizes, `lr0.08`, 800 → 3000 iterations: val {short['val_psnr']:.2f} → "
                f"{long['val_psnr']:.2f}, test {short['psnr']:.2f} → {long['psnr']:.2f}"
            )
    return lines


def rule_along_the_budget(results: dict[str, dict], suite: Suite = SUITE) -> list[str]:
    """Does a user's run under the budget rule get better as the budget grows from 800 to 3000 iterations?"""
    lines = []
    for method, rule in suite.rule_along_the_budget.items():
        a = first_seed_row(results, "cpu-800", method, rule["at_800"], suite)
        b = first_seed_row(results, "cpu-3000", method, rule["at_3000"], suite)
        if a and b:
            lines.append(
                f"- fern, {method}, the budget rule's settings at cpu sizes: `{rule['at_800']}` at 800 iterations val "
                f"{a['val_psnr']:.2f}, test {a['psnr']:.2f} → `{rule['at_3000']}` at 3000 val {b['val_psnr']:.2f}, "
                f"test {b['psnr']:.2f}"
            )
    return lines


def targets_table(results: dict[str, dict], suite: Suite = SUITE) -> list[str]:
    """Each target as measured: both methods' choices, the lead in test PSNR (per seed where both ran the same
    seeds) and by how much it is met or missed."""
    lines = []
    for t in suite.targets:
        picked, rows = {}, {}
        for method, allowed in ((F, t.get("fourierf", ())), (T, t.get("tensorf", ()))):
            groups = rows_by(results, t["scene"], t["protocol"], method)
            groups = {s: r for s, r in groups.items() if not allowed or s in allowed}
            picked[method] = chosen_setting(groups, suite.seeds)
            rows[method] = groups.get(picked[method], [])
        if not all(rows.values()):
            continue
        test = {m: {r["seed"]: r["psnr"] for r in rows[m]} for m in (F, T)}
        own, baseline = (float(np.mean(list(test[m].values()))) for m in (F, T))
        lead = own - baseline
        shared = [seed for seed in suite.seeds if seed in test[F] and seed in test[T]]
        per_seed = ", ".join(f"{test[F][s] - test[T][s]:+.2f}" for s in shared)
        floor = t.get("floor")
        short = [f"lead by {t['lead'] - lead:.2f}"] if lead < t["lead"] else []
        if floor is not None and own < floor:
            short.append(f"PSNR by {floor - own:.2f}")
        at_least = f"≥ {floor:.1f} dB and " if floor is not None else ""
        cells = [f"`{picked[m]}`, {fmt(list(test[m].values()), 2)} ({len(test[m])})" for m in (F, T)]
        status = "missed: " + ", ".join(short) if short else "met"
        lines.append(
            f"| {t['scene']}, {t['protocol']}: fourierf-vm {at_least}≥ +{t['lead']:.1f} dB; {t['against']} | "
            f"{cells[0]} | {cells[1]} | **{lead:+.2f}** ({per_seed}) | {status} |"
        )
    if not lines:
        return []
    return [
        "The quality targets, measured (test PSNR, mean ± std over the seeds; the lead per seed in brackets, seeds "
        f"{', '.join(map(str, suite.seeds))}; each choice made on val among the settings the baseline allows):",
        "",
        "| target | fourierf-vm: setting, test PSNR (seeds) | tensorf-vm: setting, test PSNR (seeds) | lead | status |",
        "|---|---|---|---|---|",
        *lines,
        "",
    ]


def later_seeds_table(results: dict[str, dict], repeats: Sequence[dict], suite: Suite = SUITE) -> list[str]:
    """Every setting run on each later seed on a GPU, with its other runs: settings compared where they ran side by
    side, read against the spread between repeats (GPU training is not bit-reproducible)."""
    later = suite.seeds[1:]
    groups: dict[tuple[str, str, str, str, str], dict[int, dict]] = {}
    for r in [*results.values(), *repeats]:
        if r.get("device") == "cuda" and r["seed"] in later:
            group = (r["scene"], r["protocol"], r["method"], r["setting"], r.get("repeat", ""))
            groups.setdefault(group, {})[r["seed"]] = r
    lines = []
    for (scene, protocol, method, setting, note), by_seed in sorted(groups.items()):
        if set(by_seed) != set(later):
            continue
        rows = [by_seed[seed] for seed in later]
        cells = " | ".join(f"{r['val_psnr']:.2f} / {r['psnr']:.2f}" for r in rows)
        val, test = (np.mean([r[k] for r in rows]) for k in ("val_psnr", "psnr"))
        lines.append(
            f"| {scene} | {protocol} | {method} | `{setting}`{f' ({note})' if note else ''} | {cells} "
            f"| {val:.2f} / {test:.2f} |"
        )
    if not lines:
        return []
    seeds = " | ".join(f"seed {seed}: val / test" for seed in later)
    return [
        f"Settings run on seeds {', '.join(map(str, later))} on a GPU (an H100, several runs at once), beside "
        "their other runs: `-plain` is TensoRF's ReLU for the density, `-revive1` revives every dark batch (the "
        "budget rule's for a forward-facing run over 800 iterations), no suffix the field's default, which revives "
        "a field only when it is dead. GPU training is not bit-reproducible "
        "(grid_sample's CUDA backward accumulates with atomics), so a repeat of one setting and seed is the spread "
        "a difference must clear.",
        "",
        f"| scene | protocol | method | setting | {seeds} | mean val / test |",
        "|---|---|---|---|" + "---|" * len(later) + "---|",
        *lines,
        "",
    ]


def threads_cell(rows: Iterable[dict]) -> str:
    """The CPU threads the rows trained on, as one cell: ``1`` where every CPU row says one (bit-reproducible), ``?``
    for rows that do not record it, ``—`` where none ran on a CPU."""
    cpu = [r for r in rows if r.get("device") == "cpu"]
    if not cpu:
        return "—"
    return " / ".join(sorted({str(r.get("train_threads") or "?") for r in cpu}))


def cpu_reruns_table(results: dict[str, dict], repeats: Sequence[dict]) -> list[str]:
    """Every CPU run of a key that ran twice, beside the row the report reads: how far one setting and seed moved
    between two CPU runs (on more than one thread, or across a change of code) is the spread a difference must clear."""
    lines = []
    for other in sorted((r for r in repeats if r.get("device") == "cpu" and r["key"] in results),
                        key=lambda r: r["key"]):  # fmt: skip
        kept = results[other["key"]]
        cells = [f"{r['val_psnr']:.2f} / {r['psnr']:.2f} ({threads_cell([r])})" for r in (kept, other)]
        lines.append(
            f"| {kept['scene']} | {kept['protocol']} | {kept['method']} | `{kept['setting']}` | "
            f"{kept['seed']} | {cells[0]} | {cells[1]} | {other['repeat']} |"
        )
    if not lines:
        return []
    return [
        "CPU runs of one setting and seed run twice: the row the tables above read and the other run (`repeats.jsonl`"
        "), val / test PSNR (CPU threads; ? = not recorded). Only a one-thread CPU run is bit-reproducible.",
        "",
        "| scene | protocol | method | setting | seed | read above | other run | what the other run was |",
        "|---|---|---|---|---|---|---|---|",
        *lines,
        "",
    ]


def comparable_seconds(rows: dict[str, list[dict]]) -> str:
    """Each method's mean training seconds over its runs on one device both methods ran on (the one holding most of
    their runs), as the summary's cell: a mean over a CPU run and two GPU runs set beside three CPU runs would read as
    a speed gap."""
    shared = sorted(set.intersection(*({r["device"] for r in rows[m]} for m in rows)))
    if not shared:
        return "— (no shared device)"
    device = max(shared, key=lambda d: sum(r["device"] == d for m in rows for r in rows[m]))
    secs = [np.mean([r["train_seconds"] for r in rows[m] if r["device"] == device]) for m in rows]
    return " / ".join(f"{t:.0f}" for t in secs) + f" ({device})"


def recording_machines(rows: Iterable[dict]) -> str:
    """Where the rows ran: they span many machines, so the machine that writes the report says nothing of them.
    Rows that record their CPU are named; the others are not."""
    named = sorted({r["machine"] for r in rows if "machine" in r})
    those = f"; rows that record theirs: {'; '.join(named)}" if named else ""
    return f"several machines (2-core CPUs, torch 2.13.0+cpu; an H100 where the device is cuda){those}"


def protocols_table(suite: Suite) -> list[str]:
    scenes = {"lego": lambda p: f"{400 // p.lego_downscale}×{400 // p.lego_downscale}", "fern": lambda p: "504×378"}
    lines = ["| protocol | iterations | rays | grid | lego image | fern image |", "|---|---|---|---|---|---|"]
    for p in suite.protocols.values():
        cells = [scenes[s](p) if s in p.scenes else "—" for s in ("lego", "fern")]
        lines.append(f"| {p.name} | {p.iters} | {p.rays} | {p.grid[0]}³ → {p.grid[1]}³ | {' | '.join(cells)} |")
    return [*lines, ""]


def report(results: dict[str, dict], repeats: Sequence[dict], suite: Suite = SUITE) -> list[str]:
    seeds = suite.seeds
    views = "; ".join(f"{scene}: {s['views']}" for scene, s in suite.scenes.items())
    body = section_head(
        "Few-shot quality: fourierf-vm against tensorf-vm, settings chosen on val",
        "python benchmarks/run.py sweep|seeds|curve, then python benchmarks/report.py",
        "Protocols, scenes and settings: `benchmarks/suite.toml` (a protocol is named by its sizes and iterations: "
        "cpu, what a CPU run gets by default (P-CPU in the speed sections); mid, the largest that trains in about 20 "
        f"minutes on 2 cores). {views}. "
        f"Each method at its own val-chosen setting (best mean val PSNR over seeds {', '.join(map(str, seeds))} "
        f"among the settings run on all of them, else best val PSNR of seed {seeds[0]}); test PSNR of that setting "
        "only, mean ± std over the seeds run. PSNRs agree across devices up to float rounding and random streams. "
        "Training seconds are the device's and were taken while other work shared the machine: they are no speed "
        "measurement (the speed benchmarks are the interleaved ones).",
        machine=recording_machines(results.values()),
    )
    body += protocols_table(suite)
    summary = [
        "| scene | protocol | device | fourierf-vm: setting, test PSNR (seeds) | tensorf-vm: setting, test PSNR (seeds)"
        " | gap | CPU threads | train s (f / t) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    sweeps: list[str] = []
    for scene in suite.settings:
        for p in suite.protocols:
            tables = {m: rows_by(results, scene, p, m) for m in (F, T)}
            if not all(tables.values()):
                continue
            picked = {m: chosen_setting(tables[m], seeds) for m in (F, T)}
            rows = {m: tables[m][picked[m]] for m in (F, T)}
            test = {m: [r["psnr"] for r in rows[m]] for m in (F, T)}
            device = "/".join(sorted({r["device"] for m in (F, T) for r in rows[m]}))
            cells = [f"`{picked[m]}`, {fmt(test[m], 2)} ({len(test[m])})" for m in (F, T)]
            gap = np.mean(test[F]) - np.mean(test[T])
            summary.append(
                f"| {scene} | {p} | {device} | {cells[0]} | {cells[1]} | **{gap:+.2f}** | "
                f"{threads_cell(r for m in (F, T) for r in rows[m])} | {comparable_seconds(rows)} |"
            )
            for s in suite.settings[scene]:
                vals = [val_cell(tables[m][s], seeds) if s in tables[m] else "—" for m in (F, T)]
                if vals != ["—", "—"]:
                    sweeps.append(f"| {scene} | {p} | {s} | " + " | ".join(vals) + " |")
    body += [*summary, ""]
    body += targets_table(results, suite)
    body += mid_along_the_budget(results, suite)
    body += rule_along_the_budget(results, suite)
    body += ["", *curve_table(results, suite)]
    body += later_seeds_table(results, repeats, suite)
    body += cpu_reruns_table(results, repeats)
    body += [
        f"Validation PSNR of every setting tried, seed {seeds[0]}, and the mean over all {len(seeds)} seeds where "
        "they were run, or over the seeds named where only some were (the choice above is the best all-seed mean of "
        "each column, else its best first seed):",
        "",
        "| scene | protocol | setting | fourierf-vm val | tensorf-vm val |",
        "|---|---|---|---|---|",
        *sweeps,
        "",
    ]
    for grid in suite.grids:
        if (REPO / grid["path"]).is_file():
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--results", type=Path, default=QUALITY_RESULTS, help="the rows run.py recorded")
    ap.add_argument("--equal-time", type=Path, default=EQUAL_TIME_RESULTS, help="the equal-time stage's rows")
    ap.add_argument("--equal-iterations", type=Path, default=EQUAL_ITERATIONS_RESULTS, help="that stage's rows")
    ap.add_argument("--markdown", type=Path, default=REPO / "BENCHMARKS.md")
    ap.add_argument("--figure", type=Path, default=REPO / et.FIGURE, help="the equal-time figure (SVG)")
    args = ap.parse_args()
    body = report(load_results(args.results), read_repeats(args.results.with_name(REPEATS)))
    print(update_benchmarks_md(args.markdown, BEGIN, END, body))
    timed = list(load_results(args.equal_time).values())
    print(update_benchmarks_md(args.markdown, et.BEGIN, et.END, et.section(timed, SUITE)))
    args.figure.write_text(et.figure(timed, SUITE))
    counted = list(load_results(args.equal_iterations).values())
    print(update_benchmarks_md(args.markdown, ei.BEGIN, ei.END, ei.section(counted, SUITE)))


if __name__ == "__main__":
    main()
