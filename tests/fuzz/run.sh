#!/usr/bin/env bash
# Builds the position readers' fuzz target (fuzz_positions.cpp + src/tools/positions_io.cpp) with clang++ and
# -fsanitize=fuzzer,address,undefined, and runs it for a bounded time on the committed seed
# corpus (corpus/; new inputs go to a working copy, never into the repository).
#   tests/fuzz/run.sh [WORK_DIR]        FUZZ_SECONDS (default 60), CXX_FUZZ (default clang++)
#   tests/fuzz/run.sh WORK_DIR FILE...  replays FILEs (e.g. a crash-* artifact) instead
# Exits 77 (ctest: skipped) when clang++ or libFuzzer (Debian: clang, libclang-rt-14-dev) is not
# available; otherwise 0, or non-zero with the crashing input saved in WORK_DIR/crash-*.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
work="${1:-${TMPDIR:-/tmp}/raycut-fuzz}"
shift || true
seconds="${FUZZ_SECONDS:-60}"
cxx="${CXX_FUZZ:-clang++}"
mkdir -p "$work"

if ! command -v "$cxx" >/dev/null 2>&1; then
  echo "fuzz: skipped: $cxx not found (Debian: apt-get install clang libclang-rt-14-dev)"
  exit 77
fi
probe="$work/probe.cpp"
printf 'extern "C" int LLVMFuzzerTestOneInput(const unsigned char*, unsigned long) { return 0; }\n' >"$probe"
if ! "$cxx" -fsanitize=fuzzer,address,undefined "$probe" -o "$work/probe" >"$work/probe.log" 2>&1; then
  echo "fuzz: skipped: $cxx cannot link -fsanitize=fuzzer (Debian: libclang-rt-14-dev):"
  tail -3 "$work/probe.log"
  exit 77
fi

binary="$work/fuzz_positions"
"$cxx" -std=c++20 -O1 -g -fno-omit-frame-pointer -fsanitize=fuzzer,address,undefined \
  -fno-sanitize-recover=all -I"$root/include" -I"$root/src" \
  "$here/fuzz_positions.cpp" "$root/src/tools/positions_io.cpp" "$root/src/core/box.cpp" -o "$binary"

# Every input is written to a file and read back: on tmpfs when there is one (a disk is ~50x
# slower), in a folder of this run's own.
scratch_root="$work"
[ -d /dev/shm ] && [ -w /dev/shm ] && scratch_root=/dev/shm
RAYCUT_FUZZ_SCRATCH="$(mktemp -d "$scratch_root/raycut-fuzz.XXXXXX")"
export RAYCUT_FUZZ_SCRATCH
trap 'rm -rf "$RAYCUT_FUZZ_SCRATCH"' EXIT
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
if [ "$#" -gt 0 ]; then
  "$binary" "$@"
  exit
fi
mkdir -p "$work/corpus"
# Lines are capped at 1 MiB (tests/test_io.cpp covers that); short inputs explore the parsers.
# libFuzzer logs every new input; a failure's report (and the crash-* path) comes last.
"$binary" -max_total_time="$seconds" -rss_limit_mb=2048 -max_len=8192 -timeout=10 \
  -artifact_prefix="$work/" -print_final_stats=1 "$work/corpus" "$here/corpus" 2>&1 | tail -n 100
