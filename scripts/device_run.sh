#!/usr/bin/env bash
# One call on a GPU machine: build (Release, sm_90), the GPU tests, then the benchmarks, with
# every result in one tarball (for machines that hand back few files). What this project's device
# sessions ran, in one place.
#
#   [PREBUILT=ARCHIVE] scripts/device_run.sh [gtest FILTER] [tests REGEX] [bench] [lists]
#                         [periodic] [sph] [python] [python-bench] [mpi] [mpi-scaling]
#                         [reused-plans] [memcheck] [grid-suites] [latency] [compiled] [knn]
#                         [roofline]
#                         results: ${OUT:-/tmp/raycut-out}/results.tgz
#
#   gtest FILTER the gtest binaries with --gtest_filter=FILTER (also with PREBUILT, below)
#   tests REGEX  ctest -R REGEX (e.g. "GridVariants|grid_|Sph"; "." for everything, ~6 min),
#                less those matching $TESTS_EXCLUDE; ctest-K.log for the K-th tests step
#   bench        both suites, every GPU method, plus the paper's grid when its source is in
#                .deps/paper/Cuda-version/cudaLJ.cu (docs/benchmarks.md; never committed)
#   lists        neighbour lists vs fused kernels (bench/neighbour_bench: uniform beta 16 and 32,
#                and the LJ liquid; cold and prepared), lists.csv/.md/.png (docs/benchmarks.md)
#   periodic     bench/neighbour_bench --periodic: the LJ liquid in a periodic cube
#                (2^20) and batches of 512 x 128 and 64 x 4096 periodic cubes; lists with shifts,
#                lj_forces; cold and prepared; PERIODIC_METHODS (default grid) picks the methods.
#                periodic.csv/.md (with lists.csv's tables too when the lists step ran before)
#   baseline-periodic
#                the periodic workloads (as in periodic) on an earlier revision and on this
#                tree, alternately, $ROUNDS times each (default 2), on the same GPU:
#                BASELINE_SRC is that revision's source (git archive REV | tar -x -C
#                .scratch/baseline, carried); its neighbour_bench is built there, unless the
#                PREBUILT archive has it. baseline-periodic-K.csv, current-periodic-K.csv
#   sph          the article's SPH run with every GPU method, and the validation scenarios
#   grid-suites  both suites with grid and grid-paper beside the paper's grid (no regression)
#   latency      call latency of small systems and batches (docs/benchmarks.md, "Latency of small
#                systems"): build/bench/raycut_latency_bench --crossover (static pair list eager
#                and from a CUDA graph, the engine), bench/python_latency.py --crossover
#                (pyraycut.neighbor_list on torch CUDA tensors, the Python package built first;
#                the profiler's table of each case in profiles/),
#                bench/plot_latency.py: latency-cpp.csv, latency-python.csv, latency.png
#   compiled     bench/python_compiled.py: an LJ step eager, under torch.compile(fullgraph) and
#                replayed as a CUDA graph (mode="reduce-overhead"), and the operator alone, beside
#                raycut_latency_bench's C++ rows, at COMPILED_SIZES (default 1000,10000,1048576):
#                compiled-python.csv, compiled-cpp.csv
#   knn          bench/python_knn.py: pyraycut.torch.knn (k = 16 and 64) beside radius_graph of
#                the same mean degree, 10^6 uniform points on CUDA (knn.csv; docs/compatibility.md)
#   roofline     ncu (Nsight Compute) metrics of the periodic workloads', the uniform suite's and
#                the small pass's kernels, a run per operation: ncu-*.csv, and roofline.csv/.png
#                by bench/roofline_table.py (docs/benchmarks.md's roofline)
#   reused-plans the grid's builds that reuse their plan (Engine::set_reuse_plan): their tests
#                (C++, memcheck, python/tests/test_torch_static.py), then the C++ engine rows
#                and bench/python_latency.py at 10^4 and 10^5 particles with
#                RAYCUT_REUSE_PLAN=0 and =1, $ROUNDS alternated rounds (default 2), profiler
#                tables in profiles-reuse{0,1}-K/ (docs/streams.md)
#   memcheck     compute-sanitizer on the functor, list, grid-variant and periodic GPU tests;
#                racecheck on the small-system pass
#   python       the Python package built with the device's Python (the PyTorch operators with
#                their CUDA kernel: RAYCUT_TORCH_CUDA=ON), and its tests: a pytest process per
#                file ($PYTEST_FILES, or every file), each killed after $PYTEST_FILE_TIMEOUT seconds
#                when set (not PYTEST_TIMEOUT, which pytest-timeout takes as its per-test
#                limit); a file that crashes runs again to its first failure with native
#                frames printed (scripts/segv_backtrace.c): pytest-FILE-native.log
#   python-bench bench/python_lists.py (beside neighbour_bench's periodic list rows, run first)
#                and bench/python_overhead.py: python-lists.csv/.md, python-overhead.csv
#                (docs/python.md)
#   mpi          the MPI tests (ctest -R mpi, the device-resident ones among them) and
#                `mpirun -np 1 raycut bench --distributed` at 2^20 and 2^22 with host positions
#                (distributed-np1.csv), then --device at 2^20, 2^22, 2^24 (MPI_DEVICE_SIZES)
#                beside the plain engine (distributed-device-np1.csv; docs/distributed.md), and
#                with --halo-images (a rank's own images as halo records), host-staged and by
#                NCCL (distributed-halo-images-np1-{mpi-host,nccl}.csv)
#   mpi-scaling  the MPI tests, then weak (2^24 per GPU) and strong (2^25) scaling of the
#                device-resident engine with NCCL at 1, 2, 4 and all visible GPUs (kinds
#                nvidia-h200-x2/x4/x8): weak-npK.csv, strong-npK.csv, scaling.md/.png
#                (bench/plot_distributed.py); then the distributed SPH solver
#                on the GPUs (the article's drop and 524,288 particles): sph-scaling.csv
set -uo pipefail
cd "$(dirname "$0")/.." || exit 1
out="${OUT:-/tmp/raycut-out}"
# The results are packed into $out/results.tgz after every step, so that a run stopped by a time
# limit still hands back what it measured, in one file (the device tool hands back a limited
# number of files). RAYCUT_RESULTS_DIR: also keep them there as loose files.
res="${RAYCUT_RESULTS_DIR:-$(mktemp -d)}"
mkdir -p "$out" "$res"
pack() { tar czf "$out/results.tgz.part" -C "$res" --exclude cudaLJ --exclude 'results.tgz*' . &&
  mv "$out/results.tgz.part" "$out/results.tgz"; }
export PATH="/usr/local/cuda/bin:$PATH"
start=$(date +%s)
step() { echo "[$(($(date +%s) - start)) s] $*"; }
# The Python package in the same build tree, with the device's Python (torch, cupy, jax there);
# once per run.
py="${RAYCUT_PYTHON:-/opt/torch/.venv/bin/python}"
# PREBUILT=ARCHIVE: the binaries and the Python package built on a machine like this one
# (scripts/device_prebuild.sh), carried as one archive and unpacked into build/ here: no build, a
# call of seconds instead of minutes. Its tests run as gtest binaries (build/tests/*; ctest's
# files name the other machine's paths), its Python steps on the package in build/python.
if [ -n "${PREBUILT:-}" ]; then
  tar -xJf "$PREBUILT" || { echo "PREBUILT=$PREBUILT: cannot unpack"; exit 1; }
  export LD_LIBRARY_PATH="/usr/local/cuda/lib64:${LD_LIBRARY_PATH:-}"
  SKIP_MAIN_BUILD=1
  python_built=1
  step "unpacked $PREBUILT"
fi
build_python() {
  [ -n "${python_built:-}" ] && return
  python_built=1
  BUILD_DIR=build scripts/configure.sh -DRAYCUT_BUILD_PYTHON=ON -DPython_EXECUTABLE="$py" \
    -DRAYCUT_TORCH_CUDA=ON -DCMAKE_CUDA_ARCHITECTURES=90 \
    > "$res/python-build.log" 2>&1 || tail -20 "$res/python-build.log"
  step "python built"
  # A module with its own static libstdc++ breaks number formatting (cmake/shared_libstdcxx.cmake).
  for m in build/python/pyraycut/*.so; do
    nm -C --defined-only "$m" 2>/dev/null | grep -q "std::ostream::_M_insert<long>" &&
      echo "warning: $m holds a static libstdc++"
  done
}

# SKIP_MAIN_BUILD=1: no build of every target first (a call of Python steps alone, with
# BUILD_TARGETS="raycut_python_modules raycut_python_package": the Python build makes those).
if [ -z "${SKIP_MAIN_BUILD:-}" ]; then
  BUILD_DIR=build scripts/configure.sh -DCMAKE_CUDA_ARCHITECTURES=90 > "$res/build.log" 2>&1 ||
    { tail -40 "$res/build.log"; exit 1; }
  step "built"
fi
raycut=build/apps/raycut
paper=()
if [ -f .deps/paper/Cuda-version/cudaLJ.cu ] &&
  nvcc -O3 -std=c++17 -DSTANDALONE -arch=sm_90 -include tuple -include list \
    .deps/paper/Cuda-version/cudaLJ.cu -o "$res/cudaLJ" > "$res/paper-build.log" 2>&1; then
  paper=(--paper-binary "$res/cudaLJ")
fi

while [ $# -gt 0 ]; do
  case "$1" in
    tests)
      runs=$((${runs:-0} + 1))
      (cd build && ctest -R "$2" -E "${TESTS_EXCLUDE:-^$}" -j12 --output-on-failure \
        > "$res/ctest-$runs.log" 2>&1)
      grep -E "tests passed|tests failed" "$res/ctest-$runs.log"
      grep -E "\(Failed\)|\(Timeout\)" "$res/ctest-$runs.log" | head -20
      shift
      ;;
    gtest)
      # The gtest binaries ($GTEST_BINARIES, default below) with --gtest_filter=FILTER, a process
      # each: no ctest files needed, so PREBUILT runs them too. gtest-BINARY.log each.
      for name in ${GTEST_BINARIES:-raycut_tests raycut_grid_variant_tests \
        raycut_functor_cuda_tests raycut_device_pairs_tests}; do
        [ -x "build/tests/$name" ] || { echo "$name: not built"; continue; }
        timeout "${GTEST_TIMEOUT:-300}" "build/tests/$name" --gtest_filter="$2" \
          > "$res/gtest-$name.log" 2>&1
        echo "$name exit $?: $(grep -E '^\[  PASSED  \]' "$res/gtest-$name.log")"
        grep -E '^\[  FAILED  \] [A-Za-z]' "$res/gtest-$name.log" | head -10
      done
      shift
      ;;
    bench)
      methods=grid,grid-paper,optix-aabb,optix-aabb-sorted,optix-spheres,optix-triangles
      "$raycut" bench -s uniform -m "$methods" -o "$res/bench-uniform.csv" "${paper[@]}" \
        > "$res/bench-uniform.log" 2>&1
      "$raycut" bench -s surface --param 8,16,32,64,128 -m "$methods" --large-n 4000000 \
        --large-reps 2 -o "$res/bench-surface.csv" "${paper[@]}" > "$res/bench-surface.log" 2>&1
      python3 bench/auto_table.py "$res/bench-uniform.csv" "$res/bench-surface.csv" \
        --md "$res/auto-vs-best.md"
      ;;
    lists)
      if [ -x build/bench/neighbour_bench ]; then
        build/bench/neighbour_bench --methods "${LISTS_METHODS:-grid,grid-paper}" --lj-liquid \
          --out "$res/lists.csv" > "$res/lists.log" 2>&1
        echo "neighbour_bench exit $?"
        grep -E "list_full |count |lj " "$res/lists.log" | grep -E "^uniform +32 +32|^lj-liquid" | head -20
        csv="$res/lists.csv"
        [ -f "$csv" ] || csv="$res/lists.csv.tmp"  # a run that stopped: the rows it wrote
        [ -f "$csv" ] && python3 bench/plot_lists.py "$csv" --md "$res/lists.md" \
          --png "$res/lists.png" > "$res/lists-plot.log" 2>&1
        [ -f "$res/lists.md" ] && awk '/### Targets/{f=1} /### Every/{f=0} f' "$res/lists.md"
      else
        echo "build/bench/neighbour_bench was not built (needs CUDA and CLI11)"
      fi
      ;;
    periodic)
      if [ -x build/bench/neighbour_bench ]; then
        build/bench/neighbour_bench --methods "${PERIODIC_METHODS:-grid}" --no-suite --periodic \
          --out "$res/periodic.csv" > "$res/periodic.log" 2>&1
        echo "neighbour_bench --periodic exit $?"
        grep -E "^(lj-liquid-pbc|batch-pbc) |skipped|failed" "$res/periodic.log" | head -30
        csv="$res/periodic.csv"
        [ -f "$csv" ] || csv="$res/periodic.csv.tmp"  # a run that stopped: the rows it wrote
        csvs=()
        [ -f "$res/lists.csv" ] && csvs+=("$res/lists.csv")  # one markdown with both
        [ -f "$csv" ] && python3 bench/plot_lists.py "${csvs[@]}" "$csv" --md "$res/periodic.md" \
          > "$res/periodic-plot.log" 2>&1
        [ -f "$res/periodic.md" ] && awk '/### Periodic workloads/{f=1} f' "$res/periodic.md"
      else
        echo "build/bench/neighbour_bench was not built (needs CUDA and CLI11)"
      fi
      ;;
    latency)
      if [ -x build/bench/raycut_latency_bench ]; then
        build/bench/raycut_latency_bench --crossover --output "$res/latency-cpp.csv" \
          > "$res/latency-cpp.log" 2>&1
        echo "raycut_latency_bench exit $?"
        awk '/^workload /{f=1} f' "$res/latency-cpp.log"
      else
        echo "build/bench/raycut_latency_bench was not built (needs CUDA)"
      fi
      build_python
      mkdir -p "$res/profiles"
      PYTHONPATH="$PWD/build/python" "$py" bench/python_latency.py --crossover \
        --output "$res/latency-python.csv" --profile-tables "$res/profiles" \
        > "$res/latency-python.log" 2>&1
      echo "python_latency exit $?"
      grep -E "^lj-pbc|python_latency" "$res/latency-python.log" | head -30
      csvs=()
      for csv in "$res/latency-cpp.csv" "$res/latency-python.csv"; do
        [ -f "$csv" ] && csvs+=("$csv")
      done
      [ ${#csvs[@]} -gt 0 ] && "$py" bench/plot_latency.py "${csvs[@]}" --png "$res/latency.png"
      ;;
    compiled)
      # The operator's cost over the C++ call, and a compiled LJ step against eager (#31's
      # performance): the C++ rows at the same sizes first, in the same run.
      sizes="${COMPILED_SIZES:-1000,10000,1048576}"
      [ -x build/bench/raycut_latency_bench ] &&
        build/bench/raycut_latency_bench --sizes "$sizes" --batches none \
          --output "$res/compiled-cpp.csv" > "$res/compiled-cpp.log" 2>&1
      echo "raycut_latency_bench exit $?"
      awk '/^workload /{f=1} f' "$res/compiled-cpp.log"
      build_python
      PYTHONPATH="$PWD/build/python" "$py" bench/python_compiled.py --sizes "$sizes" \
        --output "$res/compiled-python.csv" > "$res/compiled-python.log" 2>&1
      echo "python_compiled exit $?"
      grep -E "^lj-pbc|python_compiled" "$res/compiled-python.log" | head -20
      ;;
    reused-plans)
      # Engine::set_reuse_plan on the GPU: its tests (memcheck too, and the PyTorch operator's
      # static lists), the C++ engine rows at 10,000 and 100,000 particles, then
      # bench/python_latency.py there with the operators planning (RAYCUT_REUSE_PLAN=0) and
      # reusing (=1), alternated $ROUNDS times (default 2), each with the profiler's tables:
      # reused-gtest.log, reused-memcheck.log, reused-pytest.log, reused-cpp-K.csv,
      # reused-python-{0,1}-K.csv, profiles-reuse{0,1}-K/
      timeout 300 build/tests/raycut_tests --gtest_filter='*Reused*:*StaticLists*/grid' \
        > "$res/reused-gtest.log" 2>&1
      echo "reused-plans gtest exit $?: $(grep -E '^\[  PASSED  \]' "$res/reused-gtest.log")"
      grep -E '^\[  FAILED  \] [A-Za-z]' "$res/reused-gtest.log" | head -10
      compute-sanitizer --tool memcheck --error-exitcode 9 build/tests/raycut_tests \
        --gtest_filter='*Reused*' > "$res/reused-memcheck.log" 2>&1
      echo "reused-plans memcheck exit $? ($(grep -E "ERROR SUMMARY" "$res/reused-memcheck.log"))"
      build_python
      PYTHONPATH="$PWD/build/python" timeout 300 "$py" -m pytest -q \
        python/tests/test_torch_static.py > "$res/reused-pytest.log" 2>&1
      echo "reused-plans pytest exit $?: $(tail -1 "$res/reused-pytest.log")"
      grep -E "^FAILED|^E " "$res/reused-pytest.log" | head -10
      for round in $(seq 1 "${ROUNDS:-2}"); do
        build/bench/raycut_latency_bench --sizes 10000,100000 --batches none \
          --output "$res/reused-cpp-$round.csv" > "$res/reused-cpp-$round.log" 2>&1
        grep -E "engine|host enqueue" "$res/reused-cpp-$round.log"
        for reuse in 0 1; do
          mkdir -p "$res/profiles-reuse$reuse-$round"
          RAYCUT_REUSE_PLAN=$reuse PYTHONPATH="$PWD/build/python" "$py" bench/python_latency.py \
            --sizes 10000,100000 --batches none --profile-tables "$res/profiles-reuse$reuse-$round" \
            --output "$res/reused-python-$reuse-$round.csv" \
            > "$res/reused-python-$reuse-$round.log" 2>&1
          echo "RAYCUT_REUSE_PLAN=$reuse, round $round:"
          grep -E "^lj-pbc" "$res/reused-python-$reuse-$round.log" | grep -v verlet
        done
      done
      ;;
    memcheck)
      # compute-sanitizer on the pair-pass paths: user functors, lists, the grid's variants.
      for t in "raycut_functor_cuda_tests" \
        "raycut_tests --gtest_filter=Methods/Lists.*:Methods/Conformance.*grid_uniform_n4000*:Methods/Conformance.*grid_paper_lattice_k1_n1000*:Methods/Conformance.*brute_force_gpu_coincident_n1000*" \
        "raycut_grid_variant_tests --gtest_filter=*uniform*:*coincident*" \
        "raycut_tests --gtest_filter=*Periodic*/grid:*Periodic*/brute_force_gpu:*Periodic*/grid_*:*Periodic*/brute_force_gpu_*" \
        "raycut_tests --gtest_filter=*Coulomb*:*Functor*" \
        "raycut_device_pairs_tests"; do
        name="${t%% *}"
        [[ "$t" == *Periodic* ]] && name="$name-periodic"
        [[ "$t" == *Coulomb* ]] && name="$name-coulomb-functors"
        # shellcheck disable=SC2086
        compute-sanitizer --tool memcheck --error-exitcode 9 build/tests/$t \
          > "$res/memcheck-$name.log" 2>&1
        echo "memcheck $name: exit $? ($(grep -E "ERROR SUMMARY" "$res/memcheck-$name.log"))"
      done
      # The small-system pass shares its block scan through shared memory: racecheck too.
      compute-sanitizer --tool racecheck --error-exitcode 9 build/tests/raycut_device_pairs_tests \
        --gtest_filter='Where/*:Families/*uniform*' > "$res/racecheck-device-pairs.log" 2>&1
      echo "racecheck device-pairs: exit $? ($(grep -E "ERROR SUMMARY|RACECHECK SUMMARY" \
        "$res/racecheck-device-pairs.log" | tail -1))"
      # The distributed engine's device-resident path, one rank (MPI singleton). NCCL probes its
      # kernels' attributes with calls that fail by design: API errors are not reported here.
      if [ -x build/tests/raycut_mpi_tests ]; then
        compute-sanitizer --tool memcheck --report-api-errors no --error-exitcode 9 \
          build/tests/raycut_mpi_tests --gtest_filter='DistributedDevice*' \
          > "$res/memcheck-mpi-device.log" 2>&1
        echo "memcheck mpi-device: exit $? ($(grep -E "ERROR SUMMARY" "$res/memcheck-mpi-device.log"))"
      fi
      ;;
    roofline)
      # Nsight Compute over the periodic workloads (2^20 LJ liquid, the 512 x 128 and 64 x 4096
      # batches) and the uniform suite's beta 32 p 32, one run per operation, and the small-system
      # pass at 1,000 particles: each launch's time, DRAM and L2 bytes, instructions, achieved
      # throughput and registers. bench/roofline_table.py then gives each traversal kernel its
      # workload and its instructions and bytes per pair: roofline.csv/.png (docs/benchmarks.md's
      # roofline). --clock-control none: the clocks stay as the machine runs them.
      metrics=gpu__time_duration.sum,dram__bytes_read.sum,dram__bytes_write.sum,lts__t_bytes.sum
      metrics=$metrics,sm__inst_executed.sum,sm__throughput.avg.pct_of_peak_sustained_elapsed
      metrics=$metrics,gpu__compute_memory_throughput.avg.pct_of_peak_sustained_elapsed
      metrics=$metrics,sm__warps_active.avg.pct_of_peak_sustained_active,launch__registers_per_thread
      ncu=(ncu --clock-control none --csv --metrics "$metrics")
      specs=()
      # One operation of one suite (periodic or uniform) under ncu, then its launches.
      ncu_operation() {
        local suite=$1 op=$2
        shift 2
        timeout 150 "${ncu[@]}" build/bench/neighbour_bench --methods grid "$@" --ops "$op" \
          --modes prepared --reps 1 > "$res/ncu-$suite-$op.csv" 2> "$res/ncu-$suite-$op.log"
        echo "ncu $suite $op exit $? ($(wc -l < "$res/ncu-$suite-$op.csv") lines)"
        python3 bench/summarise_ncu.py "$res/ncu-$suite-$op.csv" --launches \
          --out "$res/launches-$suite-$op.csv" && specs+=(--"$suite" "$op=$res/launches-$suite-$op.csv")
      }
      for op in count list_full_s list_half_s list_half_any_s lj_forces; do
        ncu_operation periodic "$op" --no-suite --periodic
      done
      for op in lj list_full; do ncu_operation uniform "$op" --betas 32 --ps 32; done
      python3 bench/roofline_table.py "${specs[@]}" --out "$res/roofline.csv" \
        --png "$res/roofline.png" > "$res/roofline.log" 2>&1
      echo "roofline table exit $?"
      timeout 120 "${ncu[@]}" build/bench/raycut_latency_bench --sizes 1000 --batches none \
        --reps 1 --min-loop-ms 0.001 > "$res/ncu-small.csv" 2> "$res/ncu-small.log"
      echo "ncu small pass exit $? ($(wc -l < "$res/ncu-small.csv") lines)"
      ;;
    python)
      # One process per test file, so that a crash (a segfault in one framework's runtime) hides
      # nothing else: pytest-FILE.log each, and a line per file here.
      build_python
      # AOTInductor (test_example_model) compiles the model with $CXX, else g++. A g++ without a
      # shared libstdc++ gives the package a static copy of its own (cmake/shared_libstdcxx.cmake
      # says what that breaks): then the system's compiler, where it has one.
      echo "g++: $(command -v g++), libstdc++.so: $(g++ -print-file-name=libstdc++.so)"
      if [ -z "${CXX:-}" ] && [[ "$(g++ -print-file-name=libstdc++.so)" != /* ]] &&
        [[ "$(/usr/bin/g++ -print-file-name=libstdc++.so 2>/dev/null)" == /* ]]; then
        export CXX=/usr/bin/g++
        echo "CXX=$CXX for AOTInductor"
      fi
      files="${PYTEST_FILES:-$(ls python/tests/test_*.py)}"
      for f in $files; do
        name=$(basename "$f" .py)
        PYTHONPATH="$PWD/build/python" timeout "${PYTEST_FILE_TIMEOUT:-0}" \
          "$py" -m pytest -v -rfEs -p no:cacheprovider "$f" > "$res/pytest-$name.log" 2>&1
        rc=$?
        echo "pytest $name exit $rc: $(tail -1 "$res/pytest-$name.log")"
        grep -E "^(FAILED|ERROR) |Fatal Python" "$res/pytest-$name.log" | head -10
        [ $rc -ge 124 ] && grep -B1 -m1 "Fatal Python" "$res/pytest-$name.log"
        # A crash (no gdb here): the file again up to its first failure, with the native frames
        # (scripts/segv_backtrace.c) in pytest-FILE-native.log; -s, as pytest's capture of fd 2 would
        # drop the frames with the process.
        if [ $rc -eq 139 ] || [ $rc -eq 134 ] || [ $rc -eq 135 ]; then
          [ -f build/segv_backtrace.so ] ||
            cc -shared -fPIC -O1 -o build/segv_backtrace.so scripts/segv_backtrace.c
          LD_PRELOAD="$PWD/build/segv_backtrace.so" PYTHONPATH="$PWD/build/python" \
            timeout "${PYTEST_FILE_TIMEOUT:-0}" "$py" -m pytest -x -s -v -p no:cacheprovider "$f" \
            > "$res/pytest-$name-native.log" 2>&1
          grep -A24 -m1 "native backtrace" "$res/pytest-$name-native.log" | cut -c1-160
        fi
      done
      ;;
    knn)
      build_python
      PYTHONPATH="$PWD/build/python" "$py" bench/python_knn.py --device cuda --n 1000000 \
        --k 16 --k 64 --out "$res/knn.csv" > "$res/knn.log" 2>&1
      echo "python_knn exit $?"
      tail -5 "$res/knn.log"
      ;;
    python-bench)
      build_python
      build/bench/neighbour_bench --methods grid --periodic --betas 32 --ps 32 \
        --ops list_full,list_full_s,list_half_s --reps 10 --out "$res/nb-lists.csv" \
        > "$res/nb-lists.log" 2>&1
      PYTHONPATH="$PWD/build/python" "$py" bench/python_lists.py --native "$res/nb-lists.csv" \
        --out "$res/python-lists.csv" --md "$res/python-lists.md" > "$res/python-lists.log" 2>&1
      echo "python_lists exit $?"
      tail -5 "$res/python-lists.md"
      PYTHONPATH="$PWD/build/python" "$py" bench/python_overhead.py \
        --out "$res/python-overhead.csv" > "$res/python-overhead.log" 2>&1
      echo "python_overhead exit $?"
      tail -13 "$res/python-overhead.log" | head -11
      ;;
    mpi)
      export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
      (cd build && ctest -R mpi --output-on-failure > "$res/ctest-mpi.log" 2>&1)
      grep -E "tests passed|tests failed" "$res/ctest-mpi.log"
      grep -E "DistributedDevice|SKIPPED|FAILED" "$res/ctest-mpi.log" | sort | uniq -c | head -20
      mpirun --allow-run-as-root -np 1 "$raycut" bench --distributed --n 1048576 4194304 \
        -m grid -o "$res/distributed-np1.csv" > "$res/distributed-np1.log" 2>&1
      echo "distributed np1 exit $?"
      tail -4 "$res/distributed-np1.log"
      # The device-resident path against the plain engine in the same run (plain_step_ms).
      mpirun --allow-run-as-root -np 1 "$raycut" bench --distributed --device \
        --n "${MPI_DEVICE_SIZES:-1048576,4194304,16777216}" -m grid -r 10 \
        -o "$res/distributed-device-np1.csv" > "$res/distributed-device-np1.log" 2>&1
      echo "distributed --device np1 exit $?"
      grep -E "step|plain" "$res/distributed-device-np1.log"
      # The same with 5 steps per exchange: steps after steps, as between an MD run's exchanges
      # (does the step right after an exchange carry the fixed excess over plain?).
      mpirun --allow-run-as-root -np 1 "$raycut" bench --distributed --device --steps 5 \
        --n 1048576,4194304 -m grid -r 10 -o "$res/distributed-device-np1-steps5.csv" \
        > "$res/distributed-device-np1-steps5.log" 2>&1
      echo "distributed --device --steps 5 np1 exit $?"
      grep -E "step|plain" "$res/distributed-device-np1-steps5.log"
      # Halo records at one rank: every periodic axis imaged by halos, the rank's own images
      # exchanged with itself (the records and refreshes of a slab split, on one GPU).
      for transport in mpi-host nccl; do
        flag=()
        [ "$transport" = nccl ] && flag=(--nccl)
        mpirun --allow-run-as-root -np 1 "$raycut" bench --distributed --device "${flag[@]}" \
          --halo-images --n 4194304,16777216 -m grid -r 10 \
          -o "$res/distributed-halo-images-np1-$transport.csv" \
          > "$res/distributed-halo-images-np1-$transport.log" 2>&1
        echo "distributed --device --halo-images ($transport) np1 exit $?"
        grep -E "step|plain" "$res/distributed-halo-images-np1-$transport.log"
      done
      ;;
    mpi-scaling)
      # 2, 4 or 8 GPUs: weak (MPI_WEAK_N per GPU, default 2^24) and strong
      # (MPI_STRONG_N in total, default 2^25) scaling of the device-resident engine, halo
      # refreshes by NCCL, one rank per GPU, from 1 rank to every visible GPU; the MPI tests
      # first (the NCCL twin runs at np > 1 only with a GPU per rank).
      export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
      gpus=$(nvidia-smi -L | wc -l)
      (cd build && ctest -R mpi --output-on-failure > "$res/ctest-mpi.log" 2>&1)
      grep -E "tests passed|tests failed" "$res/ctest-mpi.log"
      csvs=()
      for np in $(seq 1 "$gpus"); do
        [ "$np" -eq 1 ] || [ "$np" -eq 2 ] || [ "$np" -eq 4 ] || [ "$np" -eq "$gpus" ] || continue
        for kind in weak strong; do
          if [ "$kind" = weak ]; then size=(--n-per-rank "${MPI_WEAK_N:-16777216}"); else
            size=(--n "${MPI_STRONG_N:-33554432}"); fi
          mpirun --allow-run-as-root --bind-to none -np "$np" "$raycut" bench --distributed \
            --device --nccl --steps 5 "${size[@]}" -m grid -r 10 -o "$res/$kind-np$np.csv" \
            > "$res/$kind-np$np.log" 2>&1
          echo "$kind np$np exit $?"
          grep -E "step|plain" "$res/$kind-np$np.log"
          [ -f "$res/$kind-np$np.csv" ] && csvs+=("$res/$kind-np$np.csv")
        done
      done
      [ ${#csvs[@]} -gt 0 ] && "$py" bench/plot_distributed.py "${csvs[@]}" \
        --md "$res/scaling.md" --png "$res/scaling.png" && cat "$res/scaling.md"
      # The distributed SPH solver on the GPUs ("hiprt-drop and a scaled-up one"),
      # beside the single-process solver: sph-single.csv and sph-scaling.csv, a row per run.
      sph_summary() { grep -E "steps/s|distributed:"; }
      "$raycut" sph --scenario hiprt-drop -m grid -q --csv "$res/sph-single.csv" | sph_summary
      "$raycut" sph --scenario small -n 524288 --frames 100 -m grid -q \
        --csv "$res/sph-single.csv" | sph_summary
      for np in $(seq 1 "$gpus"); do
        [ "$np" -eq 1 ] || [ "$np" -eq 2 ] || [ "$np" -eq 4 ] || [ "$np" -eq "$gpus" ] || continue
        mpirun --allow-run-as-root --bind-to none -np "$np" "$raycut" sph --distributed --nccl \
          --scenario hiprt-drop -m grid -q --csv "$res/sph-scaling.csv" | sph_summary
        mpirun --allow-run-as-root --bind-to none -np "$np" "$raycut" sph --distributed --nccl \
          --scenario small -n 524288 --frames 100 -m grid -q --csv "$res/sph-scaling.csv" |
          sph_summary
      done
      ;;
    grid-suites)
      # Both suites, the grids beside the paper's own grid: the no-regression check.
      "$raycut" bench -s uniform -m grid,grid-paper -o "$res/bench-uniform-grids.csv" \
        "${paper[@]}" > "$res/bench-uniform-grids.log" 2>&1
      "$raycut" bench -s surface --param 8,16,32,64,128 -m grid,grid-paper --large-n 4000000 \
        --large-reps 2 -o "$res/bench-surface-grids.csv" "${paper[@]}" \
        > "$res/bench-surface-grids.log" 2>&1
      grep -E "grid " "$res/bench-uniform-grids.log" | tail -8
      ;;
    baseline-periodic)
      # A prebuilt archive may carry the baseline's binary (scripts/device_prebuild.sh with
      # BASELINE_SRC): then nothing is built here.
      baseline_bin=build/bench/neighbour_bench_baseline
      if [ ! -x "$baseline_bin" ]; then
        src="${BASELINE_SRC:?BASELINE_SRC: an earlier revision, as a source tree}"
        baseline_bin="$src/build/bench/neighbour_bench"
        # cmake itself, not that revision's configure.sh (which may build every target).
        { cmake -S "$src" -B "$src/build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
          -DCMAKE_CUDA_ARCHITECTURES=90 && cmake --build "$src/build" -j"$(nproc)" \
          --target neighbour_bench; } > "$res/baseline-build.log" 2>&1 ||
          { tail -20 "$res/baseline-build.log"; baseline_bin=""; }
        step "baseline built"
      fi
      for k in $(seq "${ROUNDS:-2}"); do
        [ -n "$baseline_bin" ] || break
        for tree in baseline current; do
          bin=build/bench/neighbour_bench
          [ "$tree" = baseline ] && bin="$baseline_bin"
          "$bin" --methods grid --no-suite --periodic --out "$res/$tree-periodic-$k.csv" \
            > "$res/$tree-periodic-$k.log" 2>&1
          echo "$tree $k: exit $?"
          grep -E "^(lj-liquid-pbc|batch-pbc) " "$res/$tree-periodic-$k.log" | head -12
        done
      done
      ;;
    sph)
      for m in grid grid-paper optix-aabb-sorted optix-aabb optix-spheres optix-triangles; do
        "$raycut" sph --scenario hiprt-drop -m "$m" --csv "$res/sph-hiprt-drop.csv" -q | tail -1
      done
      for r in 10 20 40; do
        "$raycut" sph --scenario dam-break -m grid --resolution $r -q \
          --result-csv "$res/sph-dam-break-r$r.csv" --csv "$res/sph-validation-runs.csv" | tail -1
        "$raycut" sph --scenario hydrostatic -m grid --resolution $r -q \
          --result-csv "$res/sph-hydrostatic-r$r.csv" --csv "$res/sph-validation-runs.csv" | tail -1
      done
      ;;
    *)
      echo "unknown step '$1'" >&2
      exit 2
      ;;
  esac
  step "$1 done"
  pack
  shift
done
pack
step "results: $out/results.tgz"
