#!/usr/bin/env bash
# Builds raycut and runs every test: ctest, then pytest on the Python package (python/tests),
# whose extension is built in the same tree (build/python/pyraycut: no second build of the
# library). GPU and OptiX tests skip (and say why) where there is no GPU or no OptiX headers.
#
# The Python used: $RAYCUT_PYTHON, else .venv/bin/python (scripts/setup.sh), else python3; it
# needs nanobind, numpy and pytest (python/requirements.txt); without them and without .venv,
# .venv is created by scripts/python_env.sh, as scripts/setup.sh does, but with PyTorch and JAX
# only where the disk has room for them (--frameworks-optional). RAYCUT_PYTHON_TESTS=OFF
# skips the Python package. RAYCUT_TEST_WHEEL=1 also runs `pip install --no-build-isolation .`
# into that Python (a second, full build of the library) and the tests on the installed package.
# With torch and jax importable by that Python, the PyTorch operators and pyraycut.jax's custom
# call are built and tested too; without them their tests are skipped, saying why.
set -euo pipefail
cd "$(dirname "$0")/.."
build="${BUILD_DIR:-build}"
python_tests="${RAYCUT_PYTHON_TESTS:-ON}"
python="${RAYCUT_PYTHON:-}"
[ -z "$python" ] && [ -x .venv/bin/python ] && python="$PWD/.venv/bin/python"
[ -z "$python" ] && python="$(command -v python3 || echo python3)"
python_args=(-DRAYCUT_BUILD_PYTHON=OFF)
if [ "$python_tests" != OFF ]; then
  if [ -z "${RAYCUT_PYTHON:-}" ] && [ ! -e .venv ] &&
     ! "$python" -c "import nanobind, numpy, pytest" 2>/dev/null; then
    echo "raycut: no .venv: creating it (python/requirements*.txt, from PyPI)" >&2
    if scripts/python_env.sh --frameworks-optional; then
      python="$PWD/.venv/bin/python"
    fi
  fi
  if ! "$python" -c "import nanobind, numpy, pytest" 2>/dev/null; then
    echo "raycut: $python lacks nanobind, numpy or pytest: run scripts/setup.sh (it creates" \
         ".venv), or set RAYCUT_PYTHON to a Python that has them (RAYCUT_PYTHON_TESTS=OFF" \
         "skips the Python tests)" >&2
    exit 1
  fi
  python_args=(-DRAYCUT_BUILD_PYTHON=ON -DPython_EXECUTABLE="$python")
fi
scripts/configure.sh "${python_args[@]}"
ctest --test-dir "$build" --output-on-failure -j"$(nproc)"
if [ "$python_tests" != OFF ]; then
  case "$build" in /*) build_path="$build" ;; *) build_path="$PWD/$build" ;; esac
  PYTHONPATH="$build_path/python" "$python" -m pytest -q -rs -p no:cacheprovider python/tests
  if [ "${RAYCUT_TEST_WHEEL:-0}" = 1 ]; then
    "$python" -m pip install -q --no-build-isolation --no-index .
    (cd python/tests && "$python" -m pytest -q -rs -p no:cacheprovider .)
  fi
fi
