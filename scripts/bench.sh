#!/usr/bin/env bash
# The main job: builds raycut and runs the uniform benchmark suite of the paper with the best
# methods available here (CPU without a GPU, CUDA grids with one, OptiX with its headers).
# Extra arguments go to `raycut bench` (e.g. --suite surface --methods grid,grid-paper).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/configure.sh >/dev/null
mkdir -p bench/results/local
out="bench/results/local/bench-$(date +%Y%m%d-%H%M%S).csv"
"${BUILD_DIR:-build}/apps/raycut" bench --suite uniform --out "$out" "$@"
echo "results: $out"
