"""The suite's runner: trains and evaluates points of ``suite.toml`` (the budget rule off, so each run has exactly
its setting's values) and appends one JSONL row each; a recorded point is skipped unless run ``--again NOTE``.

    python benchmarks/run.py sweep  --protocol cpu-800 mid-3000 --scene lego fern  # every setting, first seed
    python benchmarks/run.py seeds  --protocol mid-3000 --scene lego --seeds 1     # the val choice, later seeds
    python benchmarks/run.py curve  --scene fern     # cpu-3000, a checkpoint every 500 iterations evaluated
    python benchmarks/run.py sweep  --only S --again "threads not recorded"  # the earlier row to repeats.jsonl
    python benchmarks/run.py merge  --rows lane2/results.jsonl               # rows run elsewhere
    python benchmarks/run.py equal-time --scene lego fern --budget 1m 3m --jobs 2  # wall-time budgets
    python benchmarks/run.py equal-iterations --scene lego fern --jobs 2   # the same, at the suite's iterations
    python benchmarks/report.py                                              # the BENCHMARKS.md sections
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
import uuid
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import harness

from fourierf_plugin.method_configs.time_budget import parse_duration
from fourierf_plugin.utils.errors import UserError

SUITE = harness.load_suite()
Point = tuple[str, str, str, harness.Run]  # (scene, protocol, setting, run)


def execute(point: Point, args: argparse.Namespace, suite: harness.Suite = SUITE) -> dict:
    scene, protocol, setting, run = point
    extra = [*suite.protocols[protocol].flags(), "--device", args.device, "--budget-rule", "False",
             *harness.setting_flags(setting)]  # fmt: skip
    every = suite.curve_every
    if args.stage == "curve":  # keep a checkpoint every ``curve_every`` iterations (the later flag wins)
        extra += ["--steps-per-save", str(every), "--keep-checkpoints", str(run.iters // every + 1)]
    data, lpips, work = args.data / suite.scenes[scene]["path"], args.lpips, args.work / scene
    row = harness.train_and_eval(run, data, suite.parser_args(scene, protocol), work, lpips, extra, args.threads)
    run_dir = Path(row["run_dir"])
    row |= harness.evaluate(run_dir, run.key, work, lpips, split="val", threads=args.threads)
    if args.stage == "curve":  # [step, val PSNR, test PSNR] of every checkpoint before the last, then the row's own
        row["curve"] = []
        for ckpt in sorted((run_dir / "checkpoints").glob("step-*.ckpt")):
            step = int(ckpt.stem.split("-")[-1])
            if step < run.iters:
                key, at = f"{run.key}.step{step}", ("--checkpoint", str(ckpt))
                val = harness.evaluate(run_dir, key, work, lpips, *at, split="val", threads=args.threads)
                test = harness.evaluate(run_dir, key, work, lpips, *at, threads=args.threads)
                row["curve"].append([step, val["val_psnr"], test["psnr"]])
        row["curve"].append([run.iters, row["val_psnr"], row["psnr"]])
    return row | {"scene": scene, "protocol": protocol, "setting": setting, "device": args.device}


def quality_job(point: Point, args: argparse.Namespace) -> harness.Job:
    scene, run = point[0], point[3]
    return harness.Job(f"{scene}/{run.key}", args.work / scene / run.key, lambda: execute(point, args))


# -- equal time and equal iterations: each method given the same wall time (``--time-budget``) or iterations ("800it")
# on each scene, as a user would run it with no size flag; a budget too short for a method's fewest iterations is a
# row that says so, not a failure.
THREADS = 1  # a CPU run is then bit-reproducible, and two run side by side on two cores
TOO_SHORT = re.compile(r"--time-budget \S+ is too short[^\n]*")
TrainArgs = tuple[harness.Run, Path, list[str], Path, list[str]]  # ``train_and_eval``'s first arguments


def budget_iterations(budget: str) -> int | None:
    """The iterations of a budget such as "800it", or None (a wall-time budget such as "3m")."""
    found = re.fullmatch(r"([1-9][0-9]*)it", budget)
    return int(found.group(1)) if found else None


@dataclass(frozen=True)
class TimedPoint:
    scene: str
    method: str  # a method, or an equal-iterations variant: a method with flags of its own
    budget: str

    @property
    def key(self) -> str:
        return f"{self.scene}/{self.method}/{self.budget}"

    def variant(self, suite: harness.Suite) -> dict:
        return suite.equal_time["iterations"].get("variants", {}).get(self.method, {})

    def run(self, suite: harness.Suite) -> harness.Run:
        iterations, method = budget_iterations(self.budget), self.variant(suite).get("method", self.method)
        views = "equal-time" if iterations is None else "equal-iterations"
        return harness.Run(method, iterations or 0, suite.equal_time["seed"], views, self.budget, name=self.method)

    def train_args(self, suite: harness.Suite, data: Path, work: Path) -> TrainArgs:
        """``train_and_eval``'s run, data, parser flags, work folder and extra flags (a variant's own)."""
        parser = suite.parser_args(self.scene, suite.equal_time["protocol"])
        flags = list(self.variant(suite).get("flags", []))
        return self.run(suite), data / suite.scenes[self.scene]["path"], parser, work / self.scene, flags


def timed_plan(
    suite: harness.Suite, scenes: Sequence[str], budgets: Sequence[str], only: Sequence[str] | None = None
) -> list:
    """The equal-time points, longest budget first (two jobs at once end on short runs)."""
    longest_first = sorted(budgets, key=parse_duration, reverse=True)
    return [TimedPoint(s, m, b) for b in longest_first for s in scenes for m in only or suite.equal_time["methods"]]


def iteration_plan(
    suite: harness.Suite, scenes: Sequence[str], only: Sequence[str] | None = None, budget: str | None = None
) -> list[TimedPoint]:
    """The equal-iterations points in the suite's method order (slowest first), a variant only on its scenes."""
    stage = suite.equal_time["iterations"]
    points = [TimedPoint(s, m, budget or stage["budget"]) for m in only or stage["methods"] for s in scenes]
    return [p for p in points if p.scene in p.variant(suite).get("scenes", scenes)]


def too_short(log: Path) -> str | None:
    """The train CLI's "--time-budget ... is too short" line in a failed run's log, or None (another failure)."""
    found = TOO_SHORT.search(log.read_text(errors="replace")) if log.is_file() else None
    return found.group(0) if found else None


def execute_timed(
    point: TimedPoint, suite: harness.Suite, data: Path, work: Path, lpips: Path, jobs: int, invocation: str
) -> dict:
    """Train and evaluate one point; its row (planned and actual training seconds from the run's metrics).
    ``invocation`` names the run.py call the point ran in: only its rows shared one machine and one load."""
    started, (run, scene_data, parser, scene_work, flags) = time.perf_counter(), point.train_args(suite, data, work)
    iterations = budget_iterations(point.budget)
    size = {"budget_iterations": iterations} if iterations else {"budget_seconds": parse_duration(point.budget)}
    row = {
        "scene": point.scene, "method": point.method, "budget": point.budget, **size, "flags": flags,
        "threads": THREADS, "jobs": jobs, "machine": harness.cpu_and_cores(), "invocation": invocation,
    }  # fmt: skip
    try:
        trained = harness.train_and_eval(run, scene_data, parser, scene_work, lpips, flags, threads=THREADS)
    except RuntimeError:
        if (message := too_short(scene_work / f"{run.key}.train.log")) is None:
            raise
        return row | {"too_short": message, "seconds": time.perf_counter() - started}
    done = harness.done_record(harness.read_jsonl(Path(trained["run_dir"]) / "metrics.jsonl", torn=True)) or {}
    iterations, seconds = int(done["step"]), float(done["train_seconds"])
    return row | {
        "planned_seconds": done.get("planned_train_seconds"), "trained_seconds": seconds, "iterations": iterations,
        "planned_iterations": done.get("planned_iterations", iterations), "seconds_per_iteration": seconds / iterations,
        **{k: trained[k] for k in ("psnr", "ssim", "lpips", "train_threads", "train_view_ids", "run_dir")},
        "seconds": time.perf_counter() - started,
    }  # fmt: skip


def timed_job(point: TimedPoint, args: argparse.Namespace) -> harness.Job:
    execute = lambda: execute_timed(point, SUITE, args.data, args.work, args.lpips, args.jobs, args.invocation)  # noqa: E731
    return harness.Job(point.key, args.work / point.scene / point.run(SUITE).key, execute)


ROW_FIELDS = ("key", "scene", "protocol", "method", "setting", "seed", "val_psnr", "psnr")  # what the report reads


def read_rows(source: Path, suite: harness.Suite = SUITE) -> list[dict]:
    """The rows of a results file written elsewhere, checked for what the report reads (ValueError names the line)."""
    if not source.is_file():
        raise ValueError(f"{source}: no such results file; pass the --results path a sweep, seeds or curve stage wrote")
    rows = []
    for number, line in enumerate(source.read_text().splitlines(), start=1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError as err:
            raise ValueError(f"{source}:{number}: not a JSON row ({err.msg}); one finished run a line") from None
        if missing := [f for f in ROW_FIELDS if not isinstance(row, dict) or f not in row]:
            raise ValueError(f"{source}:{number}: a row without {', '.join(missing)}; merge only rows run.py wrote")
        if row["protocol"] not in suite.protocols or row["method"] not in suite.methods:
            what = f"protocol {row['protocol']!r} or method {row['method']!r}"
            known = f"{', '.join(suite.protocols)}; {', '.join(suite.methods)}"
            raise ValueError(f"{source}:{number}: {what} is not the suite's ({known})")
        rows.append(row)
    return rows


def merge(path: Path, sources: Sequence[Path], again: str | None) -> list[str]:
    """Record the rows of ``sources`` (runs trained elsewhere) as ``run_all`` would, all checked before any is."""
    if any(source.resolve() == path.resolve() for source in sources):
        raise ValueError(f"{path}: the results cannot be merged into themselves; pass the other run's --results file")
    rows, held, lines = [row for source in sources for row in read_rows(source)], set(harness.load_results(path)), []
    for row in rows:
        if row["key"] in held and again is None:
            lines.append(f"{row['key']}: recorded, skipped (--again NOTE keeps this row, the earlier to the repeats)")
            continue
        harness.record(path, row, again)
        held.add(row["key"])
        threads = row.get("train_threads", "?")
        lines.append(f"{row['key']}: val {row['val_psnr']:.2f}  test {row['psnr']:.2f}  (threads {threads})")
    return lines


def plan(args: argparse.Namespace, suite: harness.Suite = SUITE) -> list[Point]:
    """The stage's points: a sweep's every setting at the first seed; seeds and curve, --only's or the val choice."""
    sweep, results = args.stage == "sweep", {} if args.stage == "sweep" else harness.load_results(args.results)
    seeds = (args.seeds or suite.seeds[1:]) if args.stage == "seeds" else suite.seeds[:1]
    points = []
    for p in args.protocol:
        if (chosen_of := suite.protocols[p].curve_of if args.stage == "curve" else p) is None:
            curves = [name for name, protocol in suite.protocols.items() if protocol.curve_of]
            sys.exit(f"error: the curve stage runs {' or '.join(curves)}, not {p}")
        iters = suite.protocols[p].iters
        for scene in [s for s in args.scene if not sweep or s in suite.protocols[p].scenes]:
            for method in args.methods or suite.methods:
                if sweep:
                    settings = [s for s in suite.settings[scene] if not args.only or s in args.only]
                elif args.only:
                    settings = args.only
                else:
                    best = harness.chosen_setting(harness.rows_by(results, scene, chosen_of, method), suite.seeds)
                    if best is None:
                        sys.exit(f"error: no sweep result for {scene} {chosen_of} {method}; run the sweep stage "
                                 "first or pass --only")  # fmt: skip
                    settings = [best]
                runs = [(s, seed) for s in settings if harness.applies(method, s) for seed in seeds]
                points += [(scene, p, s, harness.Run(method, iters, seed, f"{p}_{s}")) for s, seed in runs]
    return points


def parse_args(argv: Sequence[str] | None = None, suite: harness.Suite = SUITE) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("stage", choices=("sweep", "seeds", "curve", "merge", "equal-time", "equal-iterations"))
    ap.add_argument("--protocol", nargs="+", choices=tuple(suite.protocols), help="default: cpu-800 mid-3000 mid-800; "
                    "curve: cpu-3000")  # fmt: skip
    ap.add_argument("--scene", nargs="+", choices=tuple(suite.settings), default=list(suite.settings))
    shared = harness.REPO.parent / "shared"
    ap.add_argument("--data", type=Path, default=shared / "data", help="holds blender/lego, llff/fern")
    ap.add_argument("--lpips", type=Path, default=shared / harness.LPIPS)
    ap.add_argument("--work", type=Path, help="run folders and logs (default: outputs/bench_STAGE)")
    ap.add_argument("--results", type=Path, help="one row a finished run (default: the stage's, benchmarks/results/)")
    ap.add_argument("--budget", nargs="+", help="equal-time: each point's --time-budget; equal-iterations: one count "
                    "such as 200it (default: the suite's)")  # fmt: skip
    ap.add_argument("--device", default="cpu", choices=("cpu", "cuda"))
    ap.add_argument("--only", nargs="+", help="sweep only these settings (names from suite.toml)")
    equal_time = suite.equal_time
    stage_methods = {"equal-time": equal_time["methods"], "equal-iterations": equal_time["iterations"]["methods"]}
    every_method = dict.fromkeys([*suite.methods, *(m for ms in stage_methods.values() for m in ms)])
    ap.add_argument("--methods", nargs="+", choices=tuple(every_method), help="run only these methods")
    ap.add_argument("--seeds", nargs="+", type=int, choices=suite.seeds[1:], help="the seeds stage's later seeds")
    ap.add_argument("--jobs", type=int, default=1, help="trainings at once")
    ap.add_argument("--threads", type=int, default=1, help="CPU threads a run (1: a CPU run is bit-reproducible)")
    ap.add_argument("--again", metavar="NOTE", help="run recorded runs again too, each earlier row to repeats.jsonl "
                    "with NOTE (what differed then)")  # fmt: skip
    ap.add_argument("--rows", nargs="+", type=Path, metavar="FILE", help="merge: results files written elsewhere")
    args = ap.parse_args(argv)
    stage, timed, counted = args.stage, args.stage == "equal-time", args.stage == "equal-iterations"
    family = stage.replace("-", "_") if timed or counted else "quality"  # the stage's results and work folders
    args.work = args.work or harness.REPO / "outputs" / f"bench_{family}"
    args.results = args.results or harness.RESULTS / family / "results.jsonl"
    if args.budget is not None and not (timed or counted):
        sys.exit(f"error: --budget sets the equal-time stage's budgets; drop it for the {stage} stage")
    if counted and args.budget and (len(args.budget) != 1 or not budget_iterations(args.budget[0])):
        sys.exit(f"error: --budget {' '.join(args.budget)}: the equal-iterations stage takes one count, e.g. 200it")
    args.budget = args.budget or ([equal_time["iterations"]["budget"]] if counted else list(equal_time["budgets"]))
    allowed = stage_methods.get(stage, suite.methods)
    if set(args.methods or ()) - set(allowed):
        sys.exit(f"error: --methods: the {stage} stage runs {', '.join(allowed)}; pass some of those")
    args.protocol = args.protocol or (["cpu-3000"] if stage == "curve" else ["cpu-800", "mid-3000", "mid-800"])
    if args.threads < 1:
        sys.exit(f"error: --threads {args.threads} must be at least 1; pass e.g. --threads 2, or omit it for 1")
    if args.again is not None and not args.again.strip():
        sys.exit("error: --again NOTE reruns recorded runs (or merges rows of recorded keys) and needs a note saying "
                 "what differed then, e.g. --again 'threads not recorded'")  # fmt: skip
    if (args.rows is None) != (stage != "merge"):
        sys.exit("error: --rows FILE ... goes with the merge stage, and the merge stage needs it: "
                 "run.py merge --rows other/results.jsonl")  # fmt: skip
    if args.seeds and stage != "seeds":
        sys.exit(f"error: --seeds picks the later seeds of the seeds stage; drop it for the {stage} stage")
    known = {name for scene in args.scene for name in suite.settings[scene]}
    if unknown := sorted(set(args.only or ()) - known):
        sys.exit(f"error: --only {' '.join(unknown)}: no such setting for {' '.join(args.scene)}; known: "
                 f"{sorted(known)}")  # fmt: skip
    return args


def main() -> None:
    args = parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    args.results.parent.mkdir(parents=True, exist_ok=True)
    if args.stage == "merge":
        try:
            print("\n".join(merge(args.results, args.rows, args.again)))
        except ValueError as err:
            sys.exit(f"error: {err}")
        return
    for scene in args.scene:
        if not (args.data / SUITE.scenes[scene]["path"]).exists():
            sys.exit(f"error: {scene} not found under {args.data}; pass --data FOLDER")
    if args.stage in ("equal-time", "equal-iterations"):
        try:
            if args.stage == "equal-time":
                points = timed_plan(SUITE, args.scene, args.budget, args.methods)
            else:
                points = iteration_plan(SUITE, args.scene, args.methods, args.budget[0])
        except UserError as err:  # a --budget that is no duration
            sys.exit(f"error: --budget: {err}")
        args.invocation = uuid.uuid4().hex[:12]
        return harness.run_all([timed_job(p, args) for p in points], args.results, args.jobs, args.again)
    points = sorted(plan(args), key=lambda p: (-p[3].iters, p[0] != "fern"))  # longest first: the pool ends on short
    harness.run_all([quality_job(p, args) for p in points], args.results, args.jobs, args.again)


if __name__ == "__main__":
    main()
