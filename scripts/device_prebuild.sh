#!/usr/bin/env bash
# Builds on this machine what a device call runs, for the device's CPU, GPU (sm_90) and Python,
# and packs it into one archive to carry (a device call then unpacks instead of building:
# scripts/device_run.sh with PREBUILT=ARCHIVE). A full build there takes 5-8 minutes of the
# device's time; carried, a call takes seconds.
#
#   scripts/device_prebuild.sh [TARGET...]     default: the GPU tests, the benchmarks and the
#                                              Python package
#   DEVICE_PYTHON: a Python of the device's version with the device's torch, required (the
#                  device has 3.12 and torch 2.11.0+cu130: a 3.12 venv with `pip install
#                  torch==2.11.0 nanobind numpy jax`; pyenv provides a 3.12)
#   BUILD_DIR: the build tree (default build-device)
#   ARCHIVE: where the archive goes (default .scratch/prebuilt.tar.xz; carry it)
#   BASELINE_SRC: an earlier revision's source tree (git archive REV | tar -x -C DIR): its
#                 neighbour_bench goes in as build/bench/neighbour_bench_baseline, for
#                 device_run.sh's baseline-periodic step
#
# Binaries are stripped; the archive must stay under the device tool's carry limit with the
# working tree (64 MiB). The device's libstdc++ and glibc run binaries built here (Debian 12).
set -euo pipefail
cd "$(dirname "$0")/.."
py="${DEVICE_PYTHON:?DEVICE_PYTHON: a Python of the device version with its torch (see above)}"
archive="${ARCHIVE:-.scratch/prebuilt.tar.xz}"
build="${BUILD_DIR:-build-device}"
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(raycut_tests raycut_grid_variant_tests raycut_functor_cuda_tests
  raycut_device_pairs_tests neighbour_bench raycut_latency_bench raycut_python_modules
  raycut_python_package)
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CUDA_ARCHITECTURES=90 \
  -DRAYCUT_BUILD_PYTHON=ON -DPython_EXECUTABLE="$py" -DRAYCUT_TORCH_CUDA=ON > /dev/null
cmake --build "$build" -j"$(nproc)" --target "${targets[@]}"
stage=$(mktemp -d)
mkdir -p "$stage/build/bench" "$stage/build/tests"
for f in "$build"/bench/* "$build"/tests/*; do
  [ -f "$f" ] && [ -x "$f" ] || continue
  dir=$(basename "$(dirname "$f")")
  cp "$f" "$stage/build/$dir/" && strip "$stage/build/$dir/$(basename "$f")"
done
if [ -n "${BASELINE_SRC:-}" ]; then
  cmake -S "$BASELINE_SRC" -B "$BASELINE_SRC/build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
    -DCMAKE_CUDA_ARCHITECTURES=90 > /dev/null
  cmake --build "$BASELINE_SRC/build" -j"$(nproc)" --target neighbour_bench
  cp "$BASELINE_SRC/build/bench/neighbour_bench" "$stage/build/bench/neighbour_bench_baseline"
  strip "$stage/build/bench/neighbour_bench_baseline"
fi
[ -d "$build/python" ] && cp -r "$build/python" "$stage/build/python" &&
  find "$stage/build/python" -name '*.so' -exec strip --strip-unneeded {} +
mkdir -p "$(dirname "$archive")"
tar -C "$stage" -cf - build | xz -T"$(nproc)" -9 > "$archive"
rm -rf "$stage"
echo "$archive: $(du -h "$archive" | cut -f1)"
