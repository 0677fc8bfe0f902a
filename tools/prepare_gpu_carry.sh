#!/usr/bin/env bash
# Prepare what a lent GPU machine (no network; python3 there has torch, rich, imageio, scikit-image) needs to run
# benchmarks/run.py: wheels of the pure-Python dependencies it lacks (.whl/), a clean export of this project's
# committed files (.gpu/src), and the scene files the cpu-800 and mid-3000 protocols read (.gpu/data, about 22 MB: lego's
# four training views and every 8th val/test view, fern's images_8). Both folders are git-ignored via
# .git/info/exclude. On the GPU machine, carry ".gpu" and ".whl" and run:
#   source .gpu/setup.sh && python3 .gpu/src/benchmarks/run.py sweep --protocol mid-3000 --device cuda --jobs 4 \
#       --threads 2 --data .gpu/data --lpips .gpu/lpips/lpips_alex_v0.1.pth --work /tmp/work
# and copy /tmp/work/results.jsonl to $OUT. Four trainings at once suit one H100; sixteen time-slice it to a crawl.
set -euo pipefail
cd "$(dirname "$0")/.."
shared=${1:-../shared}
mkdir -p .git/info
for p in /.whl/ /.gpu/; do grep -qx "$p" .git/info/exclude 2>/dev/null || echo "$p" >> .git/info/exclude; done
rm -rf .whl .gpu
for pkg in tyro docstring-parser typeguard trimesh; do
    python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
        --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 -d .whl "$pkg"
done
mkdir -p .gpu/src .gpu/lpips .gpu/data/blender/lego/{train,val,test} .gpu/data/llff/fern
git archive HEAD | tar -x -C .gpu/src
rm -rf .gpu/src/demo .gpu/src/docs .gpu/src/tests
lego="$shared/data/blender/lego"
cp "$lego"/transforms_*.json .gpu/data/blender/lego/
for i in 27 76 97 99; do cp "$lego/train/r_$i.png" .gpu/data/blender/lego/train/; done
for i in $(seq 0 8 99); do cp "$lego/val/r_$i.png" .gpu/data/blender/lego/val/; done
for i in $(seq 0 8 199); do cp "$lego/test/r_$i.png" .gpu/data/blender/lego/test/; done
cp -r "$shared/data/llff/fern/images_8" "$shared/data/llff/fern/poses_bounds.npy" .gpu/data/llff/fern/
cp "$shared/lpips/lpips_alex_v0.1.pth" .gpu/lpips/
cat > .gpu/setup.sh <<'EOF'
# On the GPU machine: install the carried wheels and the exported project into its python3.
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir .whl/*.whl
python3 -m pip install -q --no-index --no-deps --no-build-isolation ./.gpu/src
export PYTHONUNBUFFERED=1
nvidia-smi -L
EOF
du -sh .gpu .whl
