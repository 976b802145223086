#!/usr/bin/env bash
# Builds raycut and runs every test. GPU and OptiX tests skip (and say why) where there is no
# GPU or no OptiX headers.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/configure.sh
ctest --test-dir "${BUILD_DIR:-build}" --output-on-failure -j"$(nproc)"
