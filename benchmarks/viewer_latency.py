"""The viewer's latency (camera move to preview, to final picture) on P-CPU lego in a headless chromium, and the
training slowdown of ``--viewer`` (``ARMS`` interleaved).

    python benchmarks/viewer_latency.py [--run RUN/config.json] [--rounds 2]   # trains P-CPU first without --run
    python benchmarks/viewer_latency.py --run RUN/config.json --screenshots-only   # docs/viewer_lego_f1.png, f005.png
"""

from __future__ import annotations

import math
import os
import re
import socket
import statistics
import subprocess
import sys
import time
import urllib.request
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import harness
import numpy as np
from scipy.spatial.transform import Rotation

from fourierf_plugin.engine.trainer import TrainerConfig
from fourierf_plugin.scripts.viewer import ViewerConfig, ViewerHandle, serve
from fourierf_plugin.viewer.headless import CHROMIUM, CHROMIUM_ARGS
from fourierf_plugin.viewer.render_service import camera_from_dataset, render_view
from fourierf_plugin.viewer.scene_view import scene_layout

SQUARE_WINDOW = {"width": 704, "height": 704}  # a square page, so the preview is 256×256
LATENCY_TARGET_S = 0.5
SLOWDOWN_TARGET = 0.10
BUDGET = TrainerConfig.viewer_max_slowdown  # the viewer arm's: --viewer-max-slowdown's default
STEADY_FROM = 200  # the steady state's first step: the browser has loaded the page (its largest one-off cost)
ARMS = {"plain": None, "browser": ["--viewer-max-slowdown", "0.001"], "viewer": []}
"""The slowdown's arms: no viewer; the browser on a viewer that draws almost nothing; the viewer at its budget."""
VIEWER_SHARE = re.compile(r"live viewer: .*?([0-9.]+) s of the training's time")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextmanager
def headless_page(url: str | None, viewport: dict[str, int] = SQUARE_WINDOW) -> Iterator[object]:
    """One headless chromium page (Debian's, through playwright) open at ``url`` (None: a blank page)."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=str(CHROMIUM), args=list(CHROMIUM_ARGS))
        try:
            page = browser.new_page(viewport=viewport)
            if url is not None:
                page.goto(url, wait_until="load", timeout=60_000)
            yield page
        finally:
            browser.close()


@contextmanager
def served(config: Path, viewport: dict[str, int] = SQUARE_WINDOW, **sizes: int) -> Iterator[tuple]:
    """A run served by ``fourierf-viewer`` with one headless page on it: the handle and the page."""
    handle = serve(ViewerConfig(load_config=config, port=free_port(), host="127.0.0.1", **sizes))
    try:
        with headless_page(handle.url, viewport) as page:
            yield handle, page
    finally:
        handle.stop()


def wait_for(condition: Callable[[], bool], seconds: float, what: str) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError(f"timed out after {seconds:.0f} s waiting for {what}")
        time.sleep(0.01)


def pcpu_train(data: Path, out: Path, stamp: str, iters: int, *extra: str) -> list:
    flags = ["--max-num-iterations", str(iters), *harness.GRID_FLAGS, *extra, *harness.PCPU_LEGO_PARSER]
    return harness.train_cmd("fourierf-vm", data, out, stamp, *flags)


def browser_cpu_seconds() -> float:
    """CPU seconds (user + system) used so far by every running chromium process (the headless browser's)."""
    tick, total = os.sysconf("SC_CLK_TCK"), 0.0
    for proc in Path("/proc").glob("[0-9]*"):
        try:
            if CHROMIUM.name not in (proc / "cmdline").read_text():
                continue
            fields = (proc / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue  # a process that ended meanwhile
        total += (int(fields[11]) + int(fields[12])) / tick
    return total


def orbit_moves(handle: ViewerHandle, n: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Camera positions turning about the scene's up axis through the object, 360/n degrees apart, and the target."""
    cameras = handle.run.pipeline.datamanager.reference_outputs.cameras
    layout = scene_layout(cameras)
    start = camera_from_dataset(cameras, 0).camera_to_world[:, 3] - layout.target
    turns = Rotation.from_rotvec([layout.up * 2 * math.pi * i / n for i in range(1, n + 1)])
    return [(layout.target + offset, layout.target) for offset in turns.apply(start)]


def timed_moves(handle: ViewerHandle, moves: int, final: bool, settle: float) -> Iterator[tuple[object, float]]:
    """Turn the browser's camera ``moves`` times from the server: each first preview (``final``: picture), its delay."""
    view = handle.view
    wait_for(lambda: view.client_count > 0, 60, "the browser to connect")
    wait_for(lambda: view.final_renders > 0, 120, "the first final render")
    client = next(iter(view.server.get_clients().values()))
    for position, target in orbit_moves(handle, moves):
        time.sleep(settle)
        wait_for(lambda: not view.busy, 120, "the renderer to finish")
        count, started = len(view.log), time.perf_counter()
        with client.atomic():
            client.camera.position = position
            client.camera.look_at = target
        try:
            wait_for(lambda c=count: any(r.final == final for r in list(view.log)[c:]), 120 if final else 60,
                     "the final picture after a move" if final else "a preview after a move")  # fmt: skip
        except TimeoutError:
            if final:
                raise
            yield None, 0.0  # reported: a move the page never answered with a preview
            continue
        record = next(r for r in list(view.log)[count:] if r.final == final)
        yield record, record.sent_at - started


def latency_on(config: Path, moves: int) -> dict:
    """Seconds from each camera command to its first preview, what they rendered, and a full-quality 256×256 render."""
    with served(config, preview_side=256, final_side=512) as (handle, _):
        answered = [(r, s) for r, s in timed_moves(handle, moves, final=False, settle=1.0) if r is not None]
        if not answered:
            raise RuntimeError(f"none of the {moves} camera moves got a preview within 60 s")
        model, view = handle.run.pipeline.model, handle.view
        camera = camera_from_dataset(handle.run.pipeline.datamanager.reference_outputs.cameras, 0).resized(256, 256)
        with view.viewed.lock:  # the page's render thread shares the model
            render_only = [render_view(model, camera, model.cutoffs(handle.run.step)).seconds for _ in range(5)]
    latencies = [s for _, s in answered]
    return {
        "latencies": latencies, "median": statistics.median(latencies),
        "sizes": sorted({f"{r.width}×{r.height}" for r, _ in answered}),
        "rendered_sides": [r.render_width for r, _ in answered],
        "preview_seconds": [r.render_seconds for r, _ in answered],
        "render_only_median": statistics.median(render_only), "missed": moves - len(answered),
    }  # fmt: skip


def final_on(config: Path, moves: int) -> dict:
    """Seconds from a camera command to the full final picture, on a page at ``fourierf-viewer``'s default sizes."""
    with served(config) as (handle, _):
        answered = list(timed_moves(handle, moves, final=True, settle=0.0))
    seconds = [s for _, s in answered]
    return {"seconds": seconds, "median": statistics.median(seconds),
            "sizes": sorted({f"{r.width}×{r.height}" for r, _ in answered})}  # fmt: skip


def train_with_browser(cmd: list[str], port: int, log: Path) -> float:
    """A ``--viewer`` training with a headless browser (opened first, as a user's) on its page; the browser's CPU s."""
    with headless_page(None) as page:
        time.sleep(2.0)  # the browser's own start-up settles
        cpu_before = browser_cpu_seconds()
        with log.open("w") as fh:
            # No terminal on stdin: the run closes its page when it ends instead of serving the finished run.
            proc = subprocess.Popen(
                cmd, stdin=subprocess.DEVNULL, stdout=fh, stderr=subprocess.STDOUT, cwd=harness.REPO
            )
        try:
            url = f"http://127.0.0.1:{port}/"
            wait_for(lambda: proc.poll() is not None or page_up(url), 300, "the training's viewer page")
            if proc.poll() is None:
                page.goto(url, wait_until="load", timeout=60_000)  # type: ignore[attr-defined]
            if proc.wait() != 0:
                raise RuntimeError(f"training failed; see {log}")
            return browser_cpu_seconds() - cpu_before
        finally:
            if proc.poll() is None:
                proc.kill()


def page_up(url: str) -> bool:
    try:
        urllib.request.urlopen(url, timeout=1).close()
    except OSError:
        return False
    return True


def measure_slowdown(data: Path, work: Path, rounds: int, iters: int) -> dict:
    """Interleaved rounds of the arms, the order rotating; training seconds of each, whole and from ``STEADY_FROM``."""
    runs: dict[str, list[dict[str, float]]] = {arm: [] for arm in ARMS}  # per arm, one row a training
    out = work / "ab" / time.strftime("%Y%m%d-%H%M%S")  # this invocation's own runs, never an earlier one's
    for i, arm in harness.interleaved(rounds, list(ARMS)):
        stamp, port, flags = f"{arm}-{i}", free_port(), ARMS[arm]
        extra = [] if flags is None else ["--viewer", "True", "--viewer-port", str(port), *flags]
        cmd, log = pcpu_train(data, out, stamp, iters, *extra), work / f"{stamp}.log"
        print(f"training {stamp} ...", flush=True)
        run: dict[str, float] = {}
        if flags is None:
            harness.run_checked(cmd, log, "training")
        else:
            run["browser_cpu"] = train_with_browser(cmd, port, log)
        records = harness.read_jsonl(harness.run_dir_in(out, "fourierf-vm", stamp) / "metrics.jsonl", torn=True)
        run["seconds"] = float(harness.done_record(records)["train_seconds"])  # type: ignore[index]
        if arm == "viewer":  # its snapshots, pictures and meshes: the seconds its last report in the log gives
            if not (reported := VIEWER_SHARE.findall(log.read_text())):
                raise RuntimeError(f"{log} has no 'live viewer: ...' line")
            run["own_share"] = float(reported[-1]) / run["seconds"]
        elapsed = harness.elapsed_by_step(records)
        if STEADY_FROM not in elapsed:
            raise RuntimeError(f"{stamp}: metrics.jsonl logs no step {STEADY_FROM}; log every 50 steps")
        run["steady"] = elapsed[max(elapsed)] - elapsed[STEADY_FROM]
        runs[arm].append(run)
        print(f"  {run['seconds']:.1f} s", flush=True)

    def column(arm: str, key: str) -> list[float]:
        return [run[key] for run in runs[arm]]

    def ratio(arm: str, base: str, key: str = "seconds") -> float:
        return statistics.median(column(arm, key)) / statistics.median(column(base, key)) - 1.0

    return {
        "seconds": {arm: column(arm, "seconds") for arm in ARMS}, "slowdown": ratio("viewer", "plain"),
        "browser_slowdown": ratio("browser", "plain"), "viewer_over_browser": ratio("viewer", "browser"),
        "own_share": statistics.median(column("viewer", "own_share")),
        "browser_cpu": {arm: column(arm, "browser_cpu") for arm in ARMS if ARMS[arm] is not None},
        "steady_slowdown": ratio("viewer", "plain", "steady"),
        "steady_browser_slowdown": ratio("browser", "plain", "steady"),
    }  # fmt: skip


SCREENSHOT_CUTOFFS = {"viewer_lego_f1.png": 1.0, "viewer_lego_f005.png": 0.05}


def screenshots(config: Path, docs: Path) -> list[Path]:
    """The viewer page with both cutoffs at 1.0 and at 0.05 (capped at the run's own), saved under ``docs``."""
    written = []
    with served(config, {"width": 1200, "height": 760}, preview_side=128, final_side=640) as (handle, page):
        view = handle.view
        time.sleep(2.0)  # dismiss the page's notices (viser's note on software WebGL) before a picture
        for button in page.locator(".mantine-Notification-closeButton").all():  # type: ignore[attr-defined]
            try:
                button.click(timeout=2000)
            except Exception as err:  # cosmetic: a notice left open only covers a corner of the picture
                print(f"note: could not close a notice on the page ({err})")
        wait_for(lambda: view.final_renders > 0, 300, "the first final render")
        for name, value in SCREENSHOT_CUTOFFS.items():
            count, before = view.final_renders, view.cutoffs()
            view.density_slider.value = min(value, view.density_slider.max)
            view.color_slider.value = min(value, view.color_slider.max)
            if view.cutoffs() != before:  # else the picture on screen is already the one at these cutoffs
                wait_for(lambda c=count: view.final_renders > c, 300, f"the final render at {value}")
            time.sleep(2.0)
            page.screenshot(path=str(docs / name))  # type: ignore[attr-defined]
            written.append(docs / name)
    return written


def section(latency: dict, final: dict, ab: dict, command: str, iters: int, rounds: int) -> list[str]:
    lats, sides, seconds = latency["latencies"], latency["rendered_sides"], ab["seconds"]
    side_range = f"{min(sides)}" if min(sides) == max(sides) else f"{min(sides)}–{max(sides)}"
    ok_latency = "meets" if latency["median"] <= LATENCY_TARGET_S else "misses"

    def verdict(value: float) -> str:
        return f"{100 * value:+.1f} % ({'meets' if value <= SLOWDOWN_TARGET else 'misses'} the target)"

    def listed(values: list[float], digits: int = 0) -> str:
        return ", ".join(f"{v:.{digits}f}" for v in values)

    settings = (
        f"P-CPU lego (fourierf-vm, views {' '.join('r_' + v for v in harness.LEGO_VIEWS)}, 100×100, 64³ → 128³, "
        f"{iters} iterations). Latency: one headless chromium (704×704 window), the camera turned from the server; "
        "time from the command to the first preview handed to the page's connection. Slowdown: training seconds "
        f"(metrics.jsonl) of three arms, {rounds} interleaved rounds (order rotating), same flags: no viewer; "
        "`--viewer True --viewer-max-slowdown 0.001` with one headless browser on the page (the viewer draws its first "
        "picture and then almost nothing: the browser's own cost on these cores); `--viewer True` at its default "
        f"budget ({BUDGET}) with the browser. The browser starts before the training and opens the page when the "
        "server answers; it draws WebGL in software (SwiftShader) on the training's two cores. The viewer makes its "
        "snapshots and pictures on the training thread between steps (`fourierf_plugin/viewer/live.py`)."
    )
    missed = f" Moves without a preview within 60 s: {latency['missed']}." if latency["missed"] else ""
    return [
        *harness.section_head("Web viewer: latency and training slowdown", command, settings),
        *harness.table(["measure", "value", "target"], []),
        f"| camera move → preview ({', '.join(latency['sizes'])} shown), median (range) of {len(lats)} moves | "
        f"{latency['median']:.2f} s ({min(lats):.2f}–{max(lats):.2f}; {ok_latency} the target) "
        f"| ≤ {LATENCY_TARGET_S} s |",
        f"| of which the preview's render: pixels rendered per side (scaled up to the shown size), seconds (median) "
        f"| {side_range} px, {statistics.median(latency['preview_seconds']):.2f} s | |",
        "| for comparison: full-quality render of a 256×256 view (the final picture's path; median of 5, browser"
        f" connected) | {latency['render_only_median']:.2f} s | |",
        f"| camera move → full final picture at the default size ({', '.join(final['sizes'])}), median (range) of "
        f"{len(final['seconds'])} moves | {final['median']:.2f} s ({min(final['seconds']):.2f}–"
        f"{max(final['seconds']):.2f}) | |",
        f"| training seconds: no viewer / browser on the page / viewer + browser | {listed(seconds['plain'])} / "
        f"{listed(seconds['browser'])} / {listed(seconds['viewer'])} | |",
        f"| slowdown with the viewer and the browser, whole run (median / median - 1) | {verdict(ab['slowdown'])} "
        "| ≤ 10 % |",
        f"| the same, steps {STEADY_FROM}-{iters} (after the page load) | {verdict(ab['steady_slowdown'])} | ≤ 10 % |",
        f"| of which the browser on the page alone, whole run (steps {STEADY_FROM}-{iters}) | "
        f"{100 * ab['browser_slowdown']:+.1f} % ({100 * ab['steady_browser_slowdown']:+.1f} %) | |",
        f"| the viewer over the browser alone (median / median - 1) | {100 * ab['viewer_over_browser']:+.1f} % | |",
        f"| the viewer's own snapshots and pictures, as it reports them (median share of the run) "
        f"| {100 * ab['own_share']:.1f} % | budget {100 * BUDGET:g} % |",
        "| the browser's CPU seconds per run (page load included): page alone / with the viewer | "
        f"{listed(ab['browser_cpu']['browser'], 1)} / {listed(ab['browser_cpu']['viewer'], 1)} | |",
        "",
        f"Latencies per move (s): {listed(lats, 2)}.{missed}",
    ]


def main() -> None:
    ap = harness.arguments(__doc__, "bench_viewer")
    ap.add_argument("--run", type=Path, help="config.json of a finished P-CPU run (default: train one)")
    ap.add_argument("--moves", type=int, default=8)
    ap.add_argument("--rounds", type=int, default=2, help="rounds of the three slowdown arms")
    ap.add_argument("--iters", type=int, default=800)
    ap.add_argument("--screenshots-only", action="store_true", help="only write the docs/ screenshots (needs --run)")
    args = ap.parse_args()
    data = args.shared / "data" / "blender" / "lego"
    if not data.exists():
        sys.exit(f"error: {data} not found; pass --shared PATH_TO_SHARED")
    args.work.mkdir(parents=True, exist_ok=True)
    config = args.run
    if config is None:
        out, stamp = args.work / "final", f"pcpu-{args.iters}"
        existing = list(out.glob(f"*/fourierf-vm/{stamp}/config.json"))
        if existing and list(existing[0].parent.glob("checkpoints/*.ckpt")):
            config = existing[0]
        else:
            print("training the P-CPU run ...", flush=True)
            harness.run_checked(pcpu_train(data, out, stamp, args.iters), args.work / "final.log", "training")
            config = harness.run_dir_in(out, "fourierf-vm", stamp) / "config.json"
    if args.screenshots_only:
        for path in screenshots(config, harness.REPO / "docs"):
            print(f"wrote {path}")
        return
    latency = latency_on(config, args.moves)
    print(f"latency median {latency['median']:.2f} s ({latency['sizes']})", flush=True)
    final = final_on(config, args.moves)
    print(f"final picture median {final['median']:.2f} s ({final['sizes']})", flush=True)
    ab = measure_slowdown(data, args.work, args.rounds, args.iters)
    command = " ".join(["python benchmarks/viewer_latency.py", *sys.argv[1:]])
    body = section(latency, final, ab, command, args.iters, args.rounds)
    harness.write_section(args.markdown, "viewer", "viewer_latency.py", body)


if __name__ == "__main__":
    main()
