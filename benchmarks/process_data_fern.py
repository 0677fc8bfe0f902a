"""``fourierf-process-data images`` on real photos nobody here wrote: fern's 20 images_8 photos (504x378).

The recovered cameras are aligned to fern's ``poses_bounds.npy`` (LLFF's own COLMAP run on the full-size photos) by
the similarity that best maps their centres (Umeyama); reported: images registered (target >= 18 of 20), the median
rotation error after alignment (target <= 1 degree), the median camera-centre error as a percentage of the scene
extent, here the largest distance between two reference camera centres (target <= 2 %), and the wall time of the
whole command (copies, SIFT, matching, mapping, transforms.json, downscaled folders) on this machine.

    python benchmarks/process_data_fern.py                       # ../shared/data/llff/fern
    python benchmarks/process_data_fern.py --shared PATH --work outputs/bench_process_data_fern
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np
from harness import REPO, markers, section_head, update_benchmarks_md

from fourierf_plugin.data.nerfstudio_writer import capture_from_llff
from fourierf_plugin.scripts.process_data import main as process_data
from fourierf_plugin.sfm.alignment import pose_errors

TARGETS = {"registered": 18, "rotation_deg": 1.0, "centre_percent": 2.0}
BEGIN, END = markers("process-data-fern", "process_data_fern.py")


def recovered_poses(scene: Path) -> dict[str, np.ndarray]:
    """Camera-to-world (OpenGL axes) of each registered photo, by file name, from the written transforms.json."""
    content = json.loads((scene / "transforms.json").read_text())
    return {Path(f["file_path"]).name: np.asarray(f["transform_matrix"]) for f in content["frames"]}


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shared", type=Path, default=REPO.parent / "shared")
    ap.add_argument("--work", type=Path, default=REPO / "outputs" / "bench_process_data_fern")
    ap.add_argument("--markdown", type=Path, default=REPO / "BENCHMARKS.md")
    args = ap.parse_args()
    fern = args.shared / "data" / "llff" / "fern"
    scene = args.work / "scene"

    started = time.perf_counter()
    report = process_data(["images", "--data", str(fern / "images_8"), "--output-dir", str(scene), "--overwrite"])
    wall = time.perf_counter() - started

    reference = {f.image_path.name: f.camera_to_world for f in capture_from_llff(fern, "images_8").frames}
    estimated = recovered_poses(scene)
    names = [n for n in reference if n in estimated]
    errors = pose_errors(np.stack([estimated[n] for n in names]), np.stack([reference[n] for n in names]))
    result = {
        "registered": len(report.registered),
        "total": report.total,
        "unregistered": report.unregistered,
        "mean_reprojection_error_px": report.mean_reprojection_error,
        "rotation_deg_median": float(np.median(errors.rotation_deg)),
        "rotation_deg_max": float(np.max(errors.rotation_deg)),
        "centre_percent_median": float(np.median(errors.centre_error_percent)),
        "centre_percent_max": float(np.max(errors.centre_error_percent)),
        "reference_extent": errors.reference_extent,
        "wall_seconds": wall,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
    }
    passed = {
        "registered": result["registered"] >= TARGETS["registered"],
        "rotation_deg": result["rotation_deg_median"] <= TARGETS["rotation_deg"],
        "centre_percent": result["centre_percent_median"] <= TARGETS["centre_percent"],
    }
    result["passed"] = passed
    (args.work / "result.json").write_text(json.dumps(result, indent=2))
    mark = {True: "ok", False: "MISSED"}
    print(
        f"registered        {result['registered']} / {result['total']}   (target >= 18)  {mark[passed['registered']]}"
    )
    print(
        f"rotation error    median {result['rotation_deg_median']:.3f} deg, max {result['rotation_deg_max']:.3f}"
        f"   (target median <= 1)  {mark[passed['rotation_deg']]}"
    )
    print(
        f"centre error      median {result['centre_percent_median']:.3f} %, max {result['centre_percent_max']:.3f} %"
        f" of the camera extent   (target median <= 2 %)  {mark[passed['centre_percent']]}"
    )
    print(f"reprojection      mean {result['mean_reprojection_error_px']:.3f} px")
    print(f"wall time         {wall:.1f} s on {result['machine']}")
    body = [
        *section_head(
            "Structure from motion on fern's 20 photos (fourierf-process-data images)",
            "python benchmarks/process_data_fern.py",
            "COLMAP's SIFT, exhaustive matching and incremental mapping through pycolmap on the CPU, on fern's "
            "images_8 (504×378); the recovered cameras aligned to fern's poses_bounds.npy by a similarity "
            "(Umeyama); extent = the largest distance between two reference camera centres.",
        ),
        "| registered | rotation error median (max) | centre error median (max) | reprojection | wall time |",
        "|---|---|---|---|---|",
        f"| {result['registered']} / {result['total']} | {result['rotation_deg_median']:.2f}° "
        f"({result['rotation_deg_max']:.2f}°) | {result['centre_percent_median']:.2f} % "
        f"({result['centre_percent_max']:.2f} %) | {result['mean_reprojection_error_px']:.2f} px | {wall:.0f} s |",
    ]
    update_benchmarks_md(args.markdown, BEGIN, END, body)
    return result


if __name__ == "__main__":
    main()
