#!/usr/bin/env bash
# Builds the API reference, every warning an error: the C++ headers with Doxygen
# (docs/api/Doxyfile) and the Python package with Sphinx (docs/api/python). The HTML goes to
# $BUILD_DIR/docs (cpp/html and python). The Python part imports the package built in
# $BUILD_DIR/python (scripts/test.sh builds it).
#   scripts/docs.sh [cpp|python]     (both without an argument)
# Needs doxygen (Debian) and sphinx (python/requirements.txt): scripts/setup.sh installs both.
# Exits 77 (a skip for ctest) when the tool a part needs is missing.
set -euo pipefail
cd "$(dirname "$0")/.."
part="${1:-all}"
build="${BUILD_DIR:-build}"
case "$build" in /*) ;; *) build="$PWD/$build" ;; esac
python="${RAYCUT_PYTHON:-}"
[ -z "$python" ] && [ -x .venv/bin/python ] && python="$PWD/.venv/bin/python"
[ -z "$python" ] && python="$(command -v python3)"
out="$build/docs"
mkdir -p "$out"
if [ "$part" != python ]; then
  command -v doxygen >/dev/null ||
    { echo "raycut docs: doxygen not found (scripts/setup.sh installs it)" >&2; exit 77; }
  RAYCUT_DOCS_OUT="$out" doxygen docs/api/Doxyfile
  echo "raycut: C++ API reference in $out/cpp/html/index.html"
fi
if [ "$part" != cpp ]; then
  "$python" -c "import sphinx" 2>/dev/null ||
    { echo "raycut docs: $python lacks sphinx (python/requirements.txt)" >&2; exit 77; }
  PYTHONPATH="$build/python${PYTHONPATH:+:$PYTHONPATH}" \
    "$python" -m sphinx -W --keep-going -q -b html -d "$out/.doctrees" docs/api/python \
    "$out/python"
  echo "raycut: Python API reference in $out/python/index.html"
fi
