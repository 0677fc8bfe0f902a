"""Build demo/lego_tiny: a 100 px, 4-train-view cut of NeRF-synthetic lego small enough to ship in the repo.

Run from the repo root: ``.venv/bin/python tools/make_demo_scene.py [--source PATH] [--out PATH]``.
Cameras (camera_angle_x, transform_matrix) are copied unchanged; images are area-averaged on premultiplied
colour, then stored as straight-alpha 8-bit PNGs, so the parser reads back what it would compute itself.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT))  # run as a script without installing the package

from fourierf_plugin.data.images import downscale_rgba, load_image_rgba  # noqa: E402

TRAIN_VIEWS = ("r_27", "r_76", "r_97", "r_99")  # FourieRF's 4-view lego pick (reference spec, section 2.2)
EVERY = 25  # val/test keep every 25th frame: 4 of 100 val, 8 of 200 test
FACTOR = 4

README = """# lego_tiny

A tiny demo scene cut from the NeRF-synthetic **lego** scene (Mildenhall et al., "NeRF", ECCV 2020), licensed
CC BY 3.0 (https://creativecommons.org/licenses/by/3.0/). Changes: only a few frames are kept and the images
are downscaled.

- `train`: frames r_27, r_76, r_97, r_99 (FourieRF's 4-view k-means pick for lego).
- `val`: every 25th val frame (4); `test`: every 25th test frame (8: r_0, r_25, ..., r_175).
- Images: the project's 400 px copy (`shared/data/blender/lego`) area-averaged by {factor} on premultiplied colour
  to {size} px, stored as straight-alpha 8-bit RGBA PNGs. `camera_angle_x` and every `transform_matrix` are copied
  unchanged.

Regenerate with `.venv/bin/python tools/make_demo_scene.py`.
"""


def to_straight_rgba8(premultiplied: np.ndarray) -> np.ndarray:
    """Premultiplied float RGBA -> straight-alpha uint8, dividing by the *quantised* alpha.

    Dividing by the alpha that will be stored makes the reloaded premultiplied colour match to within half a
    level of that alpha; fully transparent pixels get black.
    """
    alpha8 = np.round(np.clip(premultiplied[..., 3], 0.0, 1.0) * 255.0).astype(np.uint8)
    alpha = alpha8.astype(np.float64)[..., None] / 255.0
    rgb = np.divide(premultiplied[..., :3], alpha, out=np.zeros(premultiplied[..., :3].shape), where=alpha > 0)
    rgb8 = np.round(np.clip(rgb, 0.0, 1.0) * 255.0).astype(np.uint8)
    return np.concatenate([rgb8, alpha8[..., None]], axis=-1)


def pick_frames(frames: list[dict], split: str) -> list[dict]:
    if split == "train":
        by_name = {Path(f["file_path"]).stem: f for f in frames}
        missing = [name for name in TRAIN_VIEWS if name not in by_name]
        if missing:
            raise SystemExit(f"error: the source's transforms_train.json lacks frames {missing}")
        return [by_name[name] for name in TRAIN_VIEWS]
    return frames[::EVERY]


def build(source: Path, out: Path) -> None:
    if not (source / "transforms_train.json").is_file():
        raise SystemExit(f"error: {source} is not a NeRF-synthetic scene (no transforms_train.json); pass --source")
    size = None
    for split in ("train", "val", "test"):
        meta = json.loads((source / f"transforms_{split}.json").read_text())
        frames = pick_frames(meta["frames"], split)
        for stale in (out / split).glob("*.png"):  # the tool owns this folder: drop frames of an older cut
            stale.unlink()
        for frame in frames:
            rel = frame["file_path"] if Path(frame["file_path"]).suffix else frame["file_path"] + ".png"
            small = downscale_rgba(load_image_rgba(source / rel), FACTOR)
            size = small.shape[0]
            target = out / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            iio.imwrite(target, to_straight_rgba8(small), extension=".png", optimize=True)
        meta = {**meta, "frames": frames}
        (out / f"transforms_{split}.json").write_text(json.dumps(meta, indent=4) + "\n")
        print(f"{split}: {len(frames)} frames")
    (out / "README.md").write_text(README.format(factor=FACTOR, size=size))
    total = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    print(f"wrote {out} ({total / 1e6:.2f} MB)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--source", type=Path, default=REPO_ROOT.parent / "shared/data/blender/lego")
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "demo/lego_tiny")
    args = parser.parse_args()
    build(args.source, args.out)


if __name__ == "__main__":
    main()
