#!/bin/bash
# Interleaved A/B of a fern P-CPU training run (fourierf-vm, 3 views, 64³ -> 128³, 1024 rays, 800 iterations, two
# threads): the occupancy update at TensoRF's 10 % (step 80, side A, by flag) against the budget rule's step 200
# (side B, the default since session 28). Pairs alternate which side goes first; keep the machine quiet.
#   bash benchmarks/ab_fern_occupancy.sh [SHARED_DIR]     (default ../shared)
set -euo pipefail
cd "$(dirname "$0")/.."
shared=${1:-../shared}
work=$(mktemp -d)
run() {  # side seed
    local flag=()
    [ "$1" = A ] && flag=(--pipeline.model.occupancy-update-fractions 0.1)
    local start end
    start=$(date +%s.%N)
    .venv/bin/fourierf-train fourierf-vm --data "$shared/data/llff/fern" --output-dir "$work" --timestamp "$1_$2" \
        --seed "$2" --pipeline.datamanager.rays-per-batch 1024 --pipeline.model.field.n-voxels-init 262144 \
        --pipeline.model.field.n-voxels-final 2097152 --steps-per-save 100000 --device cpu --threads 2 "${flag[@]}" \
        llff-data --num-views 3 >"$work/$1_$2.log" 2>&1
    end=$(date +%s.%N)
    printf '%s seed %s: %.1f s\n' "$1" "$2" "$(echo "$end - $start" | bc)"
}
run A 20211202
run B 20211202
run B 1
run A 1
rm -rf "$work"
