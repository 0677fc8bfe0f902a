"""An object in a textured room as a synthetic phone capture (``fourierf-synth --kind room``): fourierf-vm and
tensorf-vm from 8 views and from every photo, test metrics and the exported mesh's Chamfer distance to the object.

    python benchmarks/room_capture.py [--threads 2] [--shared ../shared]
"""

from __future__ import annotations

import json
import subprocess
import sys
from functools import partial
from pathlib import Path

import harness
import imageio.v3 as iio
import numpy as np
import trimesh

from fourierf_plugin.method_configs.sizing import CPU_ITERATIONS
from fourierf_plugin.utils.geometry import chamfer_distance, mesh_surface_points

METHODS = ("fourierf-vm", "tensorf-vm")
VIEWS = ("8", "all")
FEW_SHOT_COUNT = CPU_ITERATIONS  # every photo is also trained at the few-shot count, beside the trainer's own
TARGETS = {"8": 22.0, "all": 28.0}  # test PSNR each view count should reach
CROP_PADDING = 0.1  # the mesh is scored inside the true object's box grown by this share of its size on each side
PICTURE_VIEWS = 2
PICTURE = Path("docs/room_capture.png")
RESULTS = harness.RESULTS / "room_capture" / "results.jsonl"
NO_MESH = {"chamfer": None, "mesh_to_truth": None, "truth_to_mesh": None}


def crop(mesh: trimesh.Trimesh, bounds: np.ndarray) -> trimesh.Trimesh:
    """The faces whose centroid lies in ``bounds`` grown by ``CROP_PADDING`` of its size."""
    pad = CROP_PADDING * (bounds[1] - bounds[0])
    centres = mesh.triangles_center
    keep = ((centres >= bounds[0] - pad) & (centres <= bounds[1] + pad)).all(axis=1)
    return mesh.submesh([np.flatnonzero(keep)], append=True) if keep.any() else trimesh.Trimesh()


def mesh_scores(run_dir: Path, work: Path, key: str, room: Path) -> dict:
    """The exported mesh, cropped to the object's box (capture frame), against points on the true object's surface."""
    path = work / f"{key}.ply"
    cmd = [
        str(harness.BIN / "fourierf-export"), "marching-cubes", "--load-config", str(run_dir / "config.json"),
        "--output-path", str(path), "--resolution", "192", "--overwrite",
    ]  # fmt: skip
    if harness.run_timed(cmd, work / f"{key}.export.log")[2] != 0:
        return NO_MESH
    bounds = np.asarray(json.loads((room / "geometry.json").read_text())["object"]["bounds"], dtype=np.float64)
    mesh = crop(trimesh.load(path, force="mesh"), bounds)
    if len(mesh.faces) == 0:
        return NO_MESH
    truth = np.asarray(trimesh.load(room / "object_surface.ply").vertices, dtype=np.float64)
    cd = chamfer_distance(mesh_surface_points(mesh, 50_000, seed=0), truth)
    return {"chamfer": cd["chamfer"], "mesh_to_truth": cd["a_to_b_mean"], "truth_to_mesh": cd["b_to_a_mean"]}


def execute(run: harness.Run, room: Path, work: Path, lpips: Path, threads: int | None) -> dict:
    out_dir = work / "runs"
    run_dir = out_dir / room.name / run.method / run.key
    views = [] if run.views == "all" else ["--num-views", run.views]
    count = ["--max-num-iterations", str(run.iters)] if run.iters else []
    done = harness.done_record(harness.read_jsonl(run_dir / "metrics.jsonl", torn=True))
    if done is None:
        cmd = harness.train_cmd(run.method, room, out_dir, run.key, "--seed", str(run.seed), *count,
                                *harness.thread_flags(threads), "nerfstudio-data", *views)  # fmt: skip
        seconds, rss = harness.run_checked(cmd, work / f"{run.key}.train.log", "training")
    else:  # trained by an earlier invocation that stopped before its row was written
        seconds, rss = float(done["train_seconds"]), None
    config = json.loads((run_dir / "config.json").read_text())["config"]
    row = {
        "key": run.key, "method": run.method, "views": run.views, "seed": run.seed,
        "iterations": config["max_num_iterations"], "train_seconds": seconds, "train_peak_rss_gb": rss,
        "train_views": len(json.loads((run_dir / "views.json").read_text())["train_view_ids"]),
        "run_dir": str(run_dir),
    }  # fmt: skip
    row |= harness.evaluate(run_dir, run.key, work, lpips, threads=threads)
    return row | mesh_scores(run_dir, work, run.key, room)


def picture(rows: dict[str, dict], room: Path, work: Path, threads: int | None, path: Path) -> None:
    """Test views, one row each: the photo, then each method's RGB and depth (``rows``: its 8-view run's row)."""
    missing = [row["run_dir"] for row in rows.values() if not (Path(row["run_dir"]) / "config.json").is_file()]
    if missing and path.is_file():
        print(f"kept {path}: the recorded runs it shows are not on this machine ({', '.join(missing)})")
        return
    if missing:
        sys.exit(f"error: the recorded runs {', '.join(missing)} are not on this machine, so their views cannot be "
                 f"pictured; move {RESULTS} aside to train the runs again")  # fmt: skip
    folders = {}
    for method, row in rows.items():
        folders[method] = work / f"{row['key']}_renders"
        if not folders[method].is_dir():
            cmd = [
                str(harness.BIN / "fourierf-render"), "dataset", "--load-config",
                str(Path(row["run_dir"]) / "config.json"), "--output-dir", str(folders[method]), "--outputs", "rgb",
                "depth", "--no-video", *harness.thread_flags(threads),
            ]  # fmt: skip
            subprocess.run(cmd, check=True, capture_output=True)
    names = sorted(p.stem for p in (folders[METHODS[0]] / "rgb").glob("*.png"))[::3][:PICTURE_VIEWS]
    columns = [room / "images", *(folders[method] / kind for method in METHODS for kind in ("rgb", "depth"))]
    lines = [np.concatenate([iio.imread(c / f"{name}.png")[..., :3] for c in columns], axis=1) for name in names]
    iio.imwrite(path, np.concatenate(lines, axis=0))


def section(rows: list[tuple[harness.Run, dict]], seed: int, picture_link: Path) -> list[str]:
    lines = [
        *harness.section_head(
            "Object in a room: a synthetic phone capture (unbounded scene)",
            "python benchmarks/room_capture.py",
            "`fourierf-synth --kind room` (160×120 RGB, no alpha, 30 training photos on a 110° arc, 8 test views "
            "between them); each method at the size the trainer picks for the machine, and every photo also at the "
            f"few-shot count ({FEW_SHOT_COUNT} iterations), seed {seed}; 8 views picked by k-means on the camera "
            "centres. The mesh is `fourierf-export marching-cubes --resolution 192` (the object's box, capture frame), "
            f"scored inside the true object's box grown by {CROP_PADDING:.0%} a side against 20k points on the true "
            "object's surface (scene units; the object is about 0.5 wide). Train seconds are wall time with other work "
            "on the machine: not a speed measurement (BENCHMARKS.md's speed sections are).",
        ),
        "| method | views | iterations | test PSNR | target | SSIM | LPIPS | Chamfer | mesh → object | object → mesh "
        "| train s |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for run, r in rows:
        target = TARGETS[run.views]
        met = "met" if r["psnr"] >= target else f"missed by {target - r['psnr']:.2f}"
        goal = "— (the few-shot count)" if run.iters else f"≥ {target:.0f} ({met})"
        mesh = [f"{r[k]:.4f}" if r[k] is not None else "—" for k in NO_MESH]
        lines.append(
            f"| {run.method} | {r['train_views']} | {r['iterations']} | {r['psnr']:.2f} | {goal} | {r['ssim']:.3f} "
            f"| {r['lpips']:.3f} | {' | '.join(mesh)} | {r['train_seconds']:.0f} |"
        )
    alt = "test views: photo, fourierf-vm RGB and depth, tensorf-vm RGB and depth (8 views)"
    return [*lines, "", f"![{alt}]({picture_link})"]


def main() -> None:
    ap = harness.arguments(__doc__, "bench_room_capture")
    ap.add_argument("--seed", type=int, default=20211202)
    ap.add_argument("--threads", type=int, default=None)
    args = ap.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    room = args.work / "room"
    if not (room / "transforms.json").is_file():
        subprocess.run([str(harness.BIN / "fourierf-synth"), "--output-dir", str(room), "--kind", "room"], check=True)
    lpips = args.shared / harness.LPIPS
    plan = [harness.Run(m, 0, args.seed, v) for v in VIEWS for m in METHODS]
    plan += [harness.Run(m, FEW_SHOT_COUNT, args.seed, "all") for m in METHODS]
    run = partial(execute, room=room, work=args.work, lpips=lpips, threads=args.threads)
    harness.run_all([harness.Job(r.key, args.work / r.key, partial(run, r)) for r in plan], RESULTS)
    results = harness.load_results(RESULTS)
    if failed := [r.key for r in plan if r.key not in results]:
        sys.exit(f"error: {len(failed)} runs failed (their logs are under {args.work}); run again")
    eight = {m: results[harness.Run(m, 0, args.seed, "8").key] for m in METHODS}
    picture(eight, room, args.work, args.threads, harness.REPO / PICTURE)
    rows = [(r, results[r.key]) for r in plan]
    harness.write_section(args.markdown, "room-capture", "room_capture.py", section(rows, args.seed, PICTURE))


if __name__ == "__main__":
    main()
