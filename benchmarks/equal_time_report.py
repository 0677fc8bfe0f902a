"""The equal-time section of BENCHMARKS.md and its figure, pure functions of the stage's rows (``equal_time.py``).

Per scene: test PSNR / SSIM / LPIPS of each method at each budget; the training time each needs to reach a PSNR
(interpolated on log time between its budgets); its seconds per iteration over the baseline's, beside the paper's
ratios; and test PSNR against training time on a log axis (``docs/equal_time.svg``, written as SVG text).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from xml.sax.saxutils import escape

from harness import Suite, markers, section_head

BEGIN, END = markers("equal-time", "report.py")
FIGURE = "docs/equal_time.svg"
COMMAND = "python benchmarks/run.py equal-time --jobs 2, then python benchmarks/report.py"
COLOURS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#17becf", "#7f7f7f")


def trained(rows: Sequence[dict], scene: str, method: str) -> list[dict]:
    """The rows of a method on a scene that trained (not too short), by training time."""
    found = [r for r in rows if (r["scene"], r["method"]) == (scene, method) and "too_short" not in r]
    return sorted(found, key=lambda r: r["trained_seconds"])


def metrics_cell(rows: Sequence[dict], scene: str, method: str, budget: str) -> str:
    row = next((r for r in rows if (r["scene"], r["method"], r["budget"]) == (scene, method, budget)), None)
    if row is None:
        return "—"
    if "too_short" in row:
        return "too short"
    return f"{row['psnr']:.2f} / {row['ssim']:.3f} / {row['lpips']:.3f}"


def time_to_psnr(points: Sequence[tuple[float, float]], target: float) -> tuple[float, bool] | None:
    """Seconds to reach ``target`` PSNR along (seconds, PSNR) points sorted by time: linear in log time between the
    last point below it and the first at or above it; (the first point's time, True) where that one already reaches it
    (an upper bound), None where none does."""
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
    if found is None:
        return "not reached"
    return ("≤ " if found[1] else "") + duration(found[0])


def seconds_per_iteration(rows: Sequence[dict], scene: str, method: str) -> tuple[float, bool] | None:
    """A method's mean seconds per iteration on a scene over its trained points, else (True) over the trainer's
    estimates in its too-short points; None without either."""
    own = [r["seconds_per_iteration"] for r in trained(rows, scene, method)]
    estimated = [
        r["estimated_seconds_per_iteration"]
        for r in rows
        if (r["scene"], r["method"]) == (scene, method) and "estimated_seconds_per_iteration" in r
    ]
    values = own or estimated
    return (sum(values) / len(values), not own) if values else None


def speed_cell(rows: Sequence[dict], scene: str, method: str, baseline: str) -> str:
    """A method's seconds per iteration over the baseline's on a scene; "est." where either is an estimate."""
    own, base = (seconds_per_iteration(rows, scene, m) for m in (method, baseline))
    if own is None or base is None:
        return "—"
    return f"{own[0] / base[0]:.2f}" + (" (est.)" if own[1] or base[1] else "")


def budgets_of(rows: Sequence[dict], scene: str) -> list[str]:
    found = {r["budget"]: r["budget_seconds"] for r in rows if r["scene"] == scene}
    return sorted(found, key=found.__getitem__)


def methods_of(rows: Sequence[dict], suite: Suite) -> list[str]:
    """The suite's methods that have rows, in the suite's order, then any others the rows hold."""
    listed = [m for m in suite.equal_time["methods"] if any(r["method"] == m for r in rows)]
    return listed + sorted({r["method"] for r in rows} - set(listed))


def scene_tables(rows: Sequence[dict], scene: str, suite: Suite) -> list[str]:
    budgets, methods = budgets_of(rows, scene), methods_of([r for r in rows if r["scene"] == scene], suite)
    targets = suite.equal_time["psnr_targets"].get(scene, [])
    lines = [
        f"### {scene}",
        "",
        "Test PSNR / SSIM / LPIPS at each budget (too short: the budget does not fit the method's fewest iterations):",
        "",
        "| method | " + " | ".join(budgets) + " |",
        "|---|" + "---|" * len(budgets),
    ]
    lines += [f"| {m} | " + " | ".join(metrics_cell(rows, scene, m, b) for b in budgets) + " |" for m in methods]
    if targets:
        lines += [
            "",
            "Training time to reach a test PSNR (interpolated on log time between budgets; ≤: reached at the first):",
            "",
            "| method | " + " | ".join(f"{t:.1f} dB" for t in targets) + " |",
            "|---|" + "---|" * len(targets),
        ]
        for m in methods:
            points = [(r["trained_seconds"], r["psnr"]) for r in trained(rows, scene, m)]
            lines.append(f"| {m} | " + " | ".join(time_cell(points, t) for t in targets) + " |")
    return [*lines, ""]


def speed_table(rows: Sequence[dict], suite: Suite) -> list[str]:
    baseline, paper = suite.equal_time["baseline"], suite.equal_time["paper_time_ratio"]
    scenes = [s for s in suite.equal_time["scenes"] if any(r["scene"] == s for r in rows)]
    lines = [
        f"Seconds per iteration over {baseline}'s (mean over the budgets that trained; est.: from the trainer's "
        "estimate where no budget fitted), beside the paper's Table 3:",
        "",
        "| method | " + " | ".join(scenes) + " | paper |",
        "|---|" + "---|" * (len(scenes) + 1),
    ]
    for m in methods_of(rows, suite):
        cells = [speed_cell(rows, s, m, baseline) for s in scenes]
        lines.append(f"| {m} | " + " | ".join(cells) + f" | {paper.get(m, '—')} |")
    return [*lines, ""]


def stage_time(rows: Sequence[dict]) -> str:
    """How long the stage took: its points' seconds (training, evaluation, start-up) summed, over the jobs at once."""
    total, jobs = sum(r["seconds"] for r in rows), max(r["jobs"] for r in rows)
    return f"The {len(rows)} points took {duration(total)} in all, about {duration(total / jobs)} at {jobs} at a time."


def section(rows: Sequence[dict], suite: Suite) -> list[str]:
    machines = "; ".join(sorted({r["machine"] for r in rows})) or "none yet"
    side = 400 // suite.protocols[suite.equal_time["protocol"]].lego_downscale  # Blender's images are 400×400
    body = section_head(
        "Equal-time comparison",
        COMMAND,
        "Each point is a user's run: `fourierf-train METHOD --time-budget B --threads 1`, sized for the scene and "
        "the machine, the short-run rules applying as they would, then `fourierf-eval` on the test views. Scenes "
        f"and budgets: `[equal_time]` in `benchmarks/suite.toml`; lego at {side}×{side}. Times are training seconds "
        "from each run's metrics (setup and evaluation not included).",
        machine=f"{machines}, one thread a run",
    )
    if not rows:
        return [*body, "No points are recorded yet.", ""]
    for scene in suite.equal_time["scenes"]:
        if any(r["scene"] == scene for r in rows):
            body += scene_tables(rows, scene, suite)
    off = [r["trained_seconds"] / r["planned_seconds"] - 1 for r in rows if r.get("planned_seconds")]
    if off:
        spread = f"{min(off):+.0%}" + (f" to {max(off):+.0%}" if len(off) > 1 else "")
        body += [f"Actual against planned training time: {spread} over the {len(off)} trained points.", ""]
    body += speed_table(rows, suite)
    body += [stage_time(rows), "", f"![test PSNR against training time, log axis]({FIGURE})", ""]
    return body


def figure(rows: Sequence[dict], suite: Suite) -> str:
    """Test PSNR against training time (log axis), one panel a scene, one polyline a method with trained points."""
    scenes, methods = list(suite.equal_time["scenes"]), methods_of(rows, suite)
    width, height, left, top, plot_w, plot_h = 460, 330, 60, 30, 370, 240
    total_w = width * len(scenes)
    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{total_w}" height="{height + 24 * len(methods) + 10}" '
        'font-family="sans-serif" font-size="12">',
        f'<rect width="{total_w}" height="{height + 24 * len(methods) + 10}" fill="white"/>',
    ]
    for k, scene in enumerate(scenes):
        x0, lines = k * width + left, {m: trained(rows, scene, m) for m in methods}
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
                xy = " ".join(f"{x(r['trained_seconds']):.1f},{y(r['psnr']):.1f}" for r in found)
                colour = COLOURS[i % len(COLOURS)]
                out.append(f'<polyline points="{xy}" fill="none" stroke="{colour}" stroke-width="2" '
                           f'data-method="{escape(m)}" data-scene="{escape(scene)}"/>')  # fmt: skip
                out += [f'<circle cx="{v.split(",")[0]}" cy="{v.split(",")[1]}" r="3" fill="{colour}"/>'
                        for v in xy.split()]  # fmt: skip
    for i, m in enumerate(methods):
        y_legend = height + 24 * i
        out.append(f'<line x1="{left}" y1="{y_legend}" x2="{left + 30}" y2="{y_legend}" '
                   f'stroke="{COLOURS[i % len(COLOURS)]}" stroke-width="2"/>')  # fmt: skip
        out.append(f'<text x="{left + 38}" y="{y_legend + 4}">{escape(m)}</text>')
    return "\n".join([*out, "</svg>", ""])
