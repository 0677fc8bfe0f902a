"""The accuracy–time report: tables (markdown) and plots (PNG, when matplotlib is installed) from the results files.

Everything here is a pure function of the measurement rows and run records, so the maths is tested on made-up
numbers and the report can be rebuilt at any time from a finished bench folder (``fourierf-bench --report-only``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from fourierf_plugin.bench import phases as ph
from fourierf_plugin.bench.sweep import KNOBS, REPORT_FRACTIONS, voxels_label

BASELINE = "tensorf-vm"
WITHIN_DB = 0.5
PAPER_TIME_RATIOS = {"tensorf-vm": 1.0, "fourierf-vm": 0.93, "zerorf-vm": 5.18}
"""Training time relative to TensoRF in the FourieRF paper (Table 3; FreeNeRF's 35.7× has no preset here)."""
MATCH_KNOBS = ("iters", "downscale", "grid_voxels", "step_ratio", "batch_size", "seed")
"""What a run must share with a baseline run to be compared with it (f0 and Δ do not exist for the baseline)."""
PLOTS_MISSING = "plots skipped: matplotlib is not installed (pip install 'fourierf[bench]')"


@dataclass
class Curve:
    """One run's measurements along its budget (rows sorted by step) and its run record."""

    key: str
    rows: list[dict]
    record: dict = field(default_factory=dict)

    @property
    def method(self) -> str:
        return self.rows[0]["method"]

    @property
    def iters(self) -> int:
        return int(self.rows[0]["iters"])

    @property
    def final(self) -> dict:
        return self.rows[-1]

    def knob(self, name: str) -> object:
        return self.rows[0].get(name)

    @property
    def train_seconds(self) -> float | None:
        return self.final.get("train_seconds_total")


def curves(rows: Sequence[dict], records: dict[str, dict] | None = None) -> list[Curve]:
    """Rows grouped by run, in the order runs first appear."""
    grouped: dict[str, list[dict]] = {}
    for row in rows:
        grouped.setdefault(row["key"], []).append(row)
    records = records or {}
    return [Curve(k, sorted(v, key=lambda r: r["step"]), records.get(k, {})) for k, v in grouped.items()]


def at_fraction(curve: Curve, fraction: float) -> dict | None:
    """The measurement taken exactly at this fraction of the budget (None when that step was not evaluated)."""
    step = max(1, round(fraction * curve.iters))
    return next((r for r in curve.rows if r["step"] == step), None)


def seconds_to_within(curve: Curve, tolerance: float = WITHIN_DB) -> tuple[float | None, int] | None:
    """(training seconds, step) of the first evaluated checkpoint within ``tolerance`` dB of the final PSNR."""
    final = curve.final["psnr"]
    if final is None:
        return None
    for row in curve.rows:
        if row["psnr"] is not None and row["psnr"] >= final - tolerance:
            return row["train_seconds_at_step"], row["step"]
    return None


def pareto_front(points: Sequence[tuple[float, float]]) -> list[int]:
    """Indices of the points no other point beats (no more seconds and no less PSNR, one strictly), by seconds."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], -points[i][1]))
    front: list[int] = []
    best = -math.inf
    for i in order:
        if points[i][1] > best:
            front.append(i)
            best = points[i][1]
    return front


def matching_baseline(
    curve: Curve, all_curves: Sequence[Curve], baseline: str = BASELINE, match: Sequence[str] = MATCH_KNOBS
) -> Curve | None:
    """The baseline run with the same budget, images, grid, sampling, batch and seed (None when not run)."""
    return next(
        (c for c in all_curves if c.method == baseline and all(c.knob(k) == curve.knob(k) for k in match)), None
    )


def per_iteration_ratio(curve: Curve, all_curves: Sequence[Curve], baseline: str = BASELINE) -> float | None:
    """Seconds per iteration over the baseline's, for runs whose budget no baseline run shares (e.g. CP, cut short).

    Rough: a run's cost per iteration changes along its schedule (upsampling, box shrink), so equal budgets compare
    better; this is the fallback when only a different budget was run.
    """
    others = [k for k in MATCH_KNOBS if k != "iters"]
    candidates = [c for c in all_curves if c.method == baseline and all(c.knob(k) == curve.knob(k) for k in others)]
    base = min(candidates, key=lambda c: abs(c.iters - curve.iters), default=None)  # the nearest budget
    if base is None or not base.train_seconds or curve.train_seconds is None:
        return None
    return (curve.train_seconds / curve.iters) / (base.train_seconds / base.iters)


def baseline_ratio(curve: Curve, all_curves: Sequence[Curve], baseline: str = BASELINE) -> float | None:
    """The run's training seconds over those of the matching baseline run."""
    base = matching_baseline(curve, all_curves, baseline)
    if base is None or not base.train_seconds or curve.train_seconds is None:
        return None
    return curve.train_seconds / base.train_seconds


def varying_knobs(all_curves: Sequence[Curve]) -> list[str]:
    """The knobs that take more than one value across the runs (the others are stated once)."""
    return [k for k in (*KNOBS, "seed") if len({c.knob(k) for c in all_curves}) > 1]


def delta_groups(all_curves: Sequence[Curve]) -> list[list[Curve]]:
    """Runs that differ only in ramp_fraction (≥ 2 values): the Δ ablations, each sorted by ramp fraction."""
    groups: dict[tuple, list[Curve]] = {}
    for c in all_curves:
        if c.knob("ramp_fraction") is None:
            continue
        ident = (c.method, *(c.knob(k) for k in KNOBS if k != "ramp_fraction"), c.knob("seed"))
        groups.setdefault(ident, []).append(c)
    return [sorted(g, key=lambda c: c.knob("ramp_fraction")) for g in groups.values() if len(g) >= 2]


def label(curve: Curve, knobs: Sequence[str]) -> str:
    """The method and the run's values of the varying knobs (f0 and Δ left out where the method has none)."""
    shown = [k for k in knobs if not (k in ("f0", "ramp_fraction") and curve.knob(k) is None)]
    return " ".join([curve.method] + [f"{k}={_knob_text(k, curve.knob(k))}" for k in shown])


def _knob_text(name: str, value: object) -> str:
    if value is None:
        return "default" if name == "downscale" else "—"
    if name == "grid_voxels":
        side = voxels_label(int(value))  # type: ignore[arg-type]
        return f"{side}³" if side.isdigit() else side
    return f"{value:g}" if isinstance(value, float) else str(value)


def _g(value: float | None) -> str:
    return "—" if value is None else f"{value:.3g}"


def _secs(value: float | None) -> str:
    """Seconds: whole above 100 s, tenths below (tiny runs stay readable)."""
    return _f(value, 0 if value is not None and value >= 100 else 1)


def _f(value: float | None, digits: int, suffix: str = "") -> str:
    return "—" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:.{digits}f}{suffix}"


def budget_table(all_curves: Sequence[Curve], knobs: Sequence[str]) -> list[str]:
    """PSNR at 25/50/100% of each run's budget, time to within 0.5 dB of the final PSNR, and time vs the baseline."""
    head = " | ".join(f"PSNR @{round(f * 100)}%" for f in REPORT_FRACTIONS)
    lines = [
        f"| run | {head} | SSIM | LPIPS | s to within {WITHIN_DB} dB of final (step) | train s | "
        f"× {BASELINE} | peak RSS GB |",
        "|---|" + "---|" * (len(REPORT_FRACTIONS) + 6),
    ]
    footnote = False
    for c in all_curves:
        if len(c.rows) < 2:
            continue
        psnrs = " | ".join(_f((at_fraction(c, f) or {}).get("psnr"), 2) for f in REPORT_FRACTIONS)
        within = seconds_to_within(c)
        within_text = "—" if within is None else f"{_secs(within[0])} ({within[1]})"
        ratio = baseline_ratio(c, all_curves)
        ratio_text = _f(ratio, 2, "×")
        if ratio is None and (per_it := per_iteration_ratio(c, all_curves)) is not None:
            ratio_text = f"{per_it:.2f}× per it.¹"
            footnote = True
        lines.append(
            f"| {label(c, knobs)} | {psnrs} | {_f(c.final['ssim'], 3)} | {_f(c.final['lpips'], 3)} | {within_text} | "
            f"{_secs(c.train_seconds)} | {ratio_text} | {_f(c.final['peak_rss_gb'], 2)} |"
        )
    if footnote:
        lines += ["", f"¹ No {BASELINE} run has this budget: seconds per iteration compared with {BASELINE}'s at its "
                      "budget (rough: the cost per iteration changes along a run's schedule)."]  # fmt: skip
    return lines


def delta_table(group: Sequence[Curve], all_curves: Sequence[Curve]) -> list[str]:
    c0 = group[0]
    lines = [
        f"{c0.method}, {c0.iters} iterations, f0 = {_knob_text('f0', c0.knob('f0'))}: the band opens fully after "
        "`ramp fraction × iterations`; Δ = (1 − f0) / that length is the paper's per-iteration increment.",
        "",
        "| ramp fraction | Δ per iteration | PSNR | SSIM | LPIPS | train s |",
        "|---|---|---|---|---|---|",
    ]
    for c in group:
        delta = c.knob("delta_per_iter")
        delta_text = "∞ (open at once)" if delta is not None and math.isinf(delta) else _g(delta)
        lines.append(
            f"| {c.knob('ramp_fraction'):g} | {delta_text} | {_f(c.final['psnr'], 2)} | {_f(c.final['ssim'], 3)} | "
            f"{_f(c.final['lpips'], 3)} | {_secs(c.train_seconds)} |"
        )
    base = matching_baseline(c0, all_curves)
    if base is not None:
        lines.append(f"| {BASELINE} (no curriculum) | — | {_f(base.final['psnr'], 2)} | {_f(base.final['ssim'], 3)} | "
                     f"{_f(base.final['lpips'], 3)} | {_secs(base.train_seconds)} |")  # fmt: skip
    return lines


def phase_section(all_curves: Sequence[Curve]) -> list[str]:
    """Where an iteration's time goes, per profiled run: whole run and its last 20% (full grid, band open)."""
    profiled = [c for c in all_curves if c.record.get("phases_total") or c.record.get("phases_final")]
    if not profiled:
        return [
            "No per-phase breakdown: no run was trained with `--profile-phases` (the trainer may not support it, "
            "or `--profile-phases none` was given)."
        ]
    methods = [c.method for c in profiled]
    names = {c.key: c.method if methods.count(c.method) == 1 else c.key for c in profiled}
    columns: list[tuple[str, dict[str, float]]] = []
    for c in profiled:
        for part, phases in (("run", c.record.get("phases_total")), ("last 20%", c.record.get("phases_final"))):
            if phases:
                columns.append((f"{names[c.key]} ({part})", phases))
    share_cols = [ph.shares(p) for _, p in columns]
    order: list[str] = []
    for s in share_cols:
        order += [n for n in s if n not in order]
    lines = [
        "Share of iteration time per phase (seconds from the trainer's `--profile-phases`):",
        "",
        "| phase | " + " | ".join(title for title, _ in columns) + " |",
        "|---|" + "---|" * len(columns),
    ]
    for name in order:
        cells = [_f(100 * s[name], 1, "%") if name in s else "—" for s in share_cols]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines.append("| total s | " + " | ".join(_f(sum(p.values()), 1) for _, p in columns) + " |")
    lines.append("")
    for c in profiled:
        whole, tail = ph.fourier_share(c.record.get("phases_total")), ph.fourier_share(c.record.get("phases_final"))
        if whole is None and tail is None:
            continue
        lines.append(
            f"- Fourier filtering share ({names[c.key]}): {_pct(whole)} of iteration time over the run, "
            f"{_pct(tail)} over its last 20%."
        )
    return lines


def pareto_points(all_curves: Sequence[Curve]) -> tuple[list[tuple[float, float]], list[tuple[Curve, dict]]]:
    points, owners = [], []
    for c in all_curves:
        for r in c.rows:
            if r["train_seconds_at_step"] is not None and r["psnr"] is not None:
                points.append((float(r["train_seconds_at_step"]), float(r["psnr"])))
                owners.append((c, r))
    return points, owners


def pareto_table(all_curves: Sequence[Curve], knobs: Sequence[str]) -> list[str]:
    points, owners = pareto_points(all_curves)
    lines = ["| training s | PSNR | run | step |", "|---|---|---|---|"]
    for i in pareto_front(points):
        c, r = owners[i]
        lines.append(f"| {_secs(points[i][0])} | {points[i][1]:.2f} | {label(c, knobs)} | {r['step']}/{c.iters} |")
    return lines


def headline(all_curves: Sequence[Curve]) -> list[str]:
    """The acceptance questions answered in one place."""
    lines = []
    for c in all_curves:
        if c.method == BASELINE or len(c.rows) < 2:
            continue
        ratio = baseline_ratio(c, all_curves)
        if ratio is not None:
            paper = PAPER_TIME_RATIOS.get(c.method)
            quoted = f" (paper: {paper:g}×)" if paper is not None else ""
            lines.append(f"- {c.method} ({c.iters} it.): training time {ratio:.2f}× {BASELINE}'s{quoted}.")
    for c in all_curves:
        whole, tail = ph.fourier_share(c.record.get("phases_total")), ph.fourier_share(c.record.get("phases_final"))
        if c.knob("f0") is not None and (whole is not None or tail is not None):
            lines.append(
                f"- Fourier filtering share of iteration time ({c.method}, forward + backward): {_pct(whole)} over "
                f"the run, {_pct(tail)} over its last 20% (target below 3%)."
            )
    return lines


def _pct(share: float | None) -> str:
    return _f(None if share is None else 100 * share, 2, "%")


def bench_cost(all_curves: Sequence[Curve]) -> str:
    """What the whole bench cost: training processes (start-up included) plus every evaluation."""
    train = sum(c.final.get("wall_seconds") or 0.0 for c in all_curves)
    evals = sum(r.get("eval_seconds") or 0.0 for c in all_curves for r in c.rows)
    n_evals = sum(len(c.rows) for c in all_curves)
    runs = f"{len(all_curves)} run" + ("s" if len(all_curves) != 1 else "")
    return (
        f"Bench cost: {runs}, {train / 60:.1f} min in training processes and {evals / 60:.1f} min in {n_evals} "
        f"evaluations ({(train + evals) / 60:.1f} min in all)."
    )


def fixed_settings(all_curves: Sequence[Curve], knobs: Sequence[str]) -> str:
    c = all_curves[0]
    fixed = [k for k in (*KNOBS, "seed") if k not in knobs and k not in ("f0", "ramp_fraction")]
    return ", ".join(f"{k} {_knob_text(k, c.knob(k))}" for k in fixed)


def markdown(
    rows: Sequence[dict],
    records: dict[str, dict],
    *,
    title: str,
    preamble: Sequence[str] = (),
    image_dir: str | None = None,
    plots: Sequence[str] = (),
    plots_note: str | None = None,
) -> list[str]:
    """The report body: headline answers, budget table, Δ ablation, phase breakdown, Pareto front, plots."""
    all_curves = curves(rows, records)
    if not all_curves:
        return [f"## {title}", "", "No finished runs yet."]
    knobs = varying_knobs(all_curves)
    test_views = all_curves[0].final.get("test_views")
    lines = [f"## {title}", "", *preamble]
    lines += [
        f"Fixed for every run: {fixed_settings(all_curves, knobs)}; {test_views} test views. Seconds are training "
        "wall seconds measured by the trainer (process start-up and evaluation excluded).",
        bench_cost(all_curves),
        "",
        *headline(all_curves),
        "",
        "### PSNR along the budget",
        "",
        *budget_table(all_curves, knobs),
    ]
    for group in delta_groups(all_curves):
        lines += ["", "### Δ ablation (growth length of the frequency band)", "", *delta_table(group, all_curves)]
    lines += ["", "### Where an iteration's time goes", "", *phase_section(all_curves)]
    lines += ["", "### Pareto front (no run is both faster and more accurate)", "", *pareto_table(all_curves, knobs)]
    lines += [""]
    if plots:
        prefix = f"{image_dir}/" if image_dir else ""
        lines += [f"![{Path(p).stem}]({prefix}{Path(p).name})" for p in plots]
    if plots_note:
        lines += [plots_note]
    return lines


def make_plots(rows: Sequence[dict], records: dict[str, dict], out_dir: Path) -> tuple[list[Path], str | None]:
    """PSNR vs training seconds (with the Pareto front) and PSNR vs growth length; ([], why) without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return [], PLOTS_MISSING
    all_curves = curves(rows, records)
    if not all_curves:
        return [], "plots skipped: no finished runs"
    knobs = varying_knobs(all_curves)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for c in all_curves:
        timed = [r for r in c.rows if r["train_seconds_at_step"] is not None]
        ax.plot([r["train_seconds_at_step"] for r in timed], [r["psnr"] for r in timed], marker="o", markersize=3,
                label=label(c, knobs))  # fmt: skip
    points, _ = pareto_points(all_curves)
    front = [points[i] for i in pareto_front(points)]
    if front:
        ax.step([p[0] for p in front], [p[1] for p in front], where="post", color="black", linestyle="--",
                linewidth=1, label="Pareto front")  # fmt: skip
    paths = [_save(plt, fig, ax, "training seconds", out_dir / "psnr_vs_seconds.png")]
    groups = delta_groups(all_curves)
    if groups:
        fig, ax = plt.subplots(figsize=(6, 4))
        for group in groups:
            xs = [c.knob("ramp_fraction") for c in group]
            ax.plot(xs, [c.final["psnr"] for c in group], marker="o", label=f"{group[0].method}, {group[0].iters} it.")
            base = matching_baseline(group[0], all_curves)
            if base is not None:
                ax.axhline(base.final["psnr"], color="red", linestyle=":", label=f"{BASELINE} (no curriculum)")
        xlabel = "growth length (fraction of the run until the band is fully open; Δ ∝ 1 / this)"
        paths.append(_save(plt, fig, ax, xlabel, out_dir / "psnr_vs_delta.png"))
    return paths, None


def _save(plt, fig, ax, xlabel: str, path: Path) -> Path:
    ax.set_xlabel(xlabel)
    ax.set_ylabel("test PSNR (dB)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
