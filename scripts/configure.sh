#!/usr/bin/env bash
# Configures and builds raycut (Release) into ${BUILD_DIR:-build}. OptiX is used when its headers
# are found: OptiX_ROOT in the environment, or the ignored folder .deps/optix. BUILD_TARGETS (a
# space-separated list) builds only those targets.
set -euo pipefail
cd "$(dirname "$0")/.."
build="${BUILD_DIR:-build}"
optix="${OptiX_ROOT:-${OPTIX_ROOT:-${OptiX_INSTALL_DIR:-}}}"
[ -z "$optix" ] && [ -f .deps/optix/include/optix.h ] && optix="$PWD/.deps/optix"
generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
cmake -S . -B "$build" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release ${optix:+-DOptiX_ROOT="$optix"} "$@"
# shellcheck disable=SC2086
cmake --build "$build" -j"$(nproc)" ${BUILD_TARGETS:+--target $BUILD_TARGETS}
