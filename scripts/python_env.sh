#!/usr/bin/env bash
# Creates the repository's virtual environment, .venv (ignored by git), if it is missing, and
# installs into it from PyPI: python/requirements.txt (building and testing the package), then
# python/requirements-frameworks.txt (PyTorch and JAX, about 6 GB installed with PyTorch's CUDA
# libraries, and as much again while pip holds the downloaded wheels). pip's cache is off: it
# would store every wheel a second time.
#
#   scripts/python_env.sh                        # both, or fail
#   scripts/python_env.sh --frameworks-optional  # the frameworks where the disk has room for them
#
# With --frameworks-optional (scripts/test.sh on a machine without .venv), a disk with less than
# RAYCUT_FRAMEWORKS_MIN_GB (10) free, or a failed install, leaves PyTorch and JAX out with a
# warning: their tests are then skipped, and say so, while everything else is built and tested.
# A half-installed framework is removed, since one that fails to import would fail the tests
# rather than skip them.
set -euo pipefail
cd "$(dirname "$0")/.."
optional=0
[ "${1:-}" = --frameworks-optional ] && optional=1
pip_install() {
  # One retry: a download that breaks off should not fail a fresh machine's setup.
  .venv/bin/python -m pip install -q --no-cache-dir "$@" ||
    { sleep 10; .venv/bin/python -m pip install -q --no-cache-dir "$@"; }
}
[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/python -m pip install -q --no-cache-dir --upgrade pip
pip_install -r python/requirements.txt

frameworks_left_out() {
  echo "raycut: WARNING: PyTorch and JAX not installed ($1); the torch and JAX tests will be" \
       "skipped. scripts/setup.sh installs them." >&2
  .venv/bin/python -m pip uninstall -q -y torch triton jax jaxlib >/dev/null 2>&1 || true
  exit 0
}
min_gb="${RAYCUT_FRAMEWORKS_MIN_GB:-10}"
free_gb=$(($(df -Pk .venv | awk 'NR == 2 { print $4 }') / 1048576))
if [ "$optional" = 1 ] && [ "$free_gb" -lt "$min_gb" ]; then
  frameworks_left_out "${free_gb} GB free on the disk of .venv, ${min_gb} GB needed"
fi
if ! pip_install -r python/requirements-frameworks.txt; then
  [ "$optional" = 1 ] && frameworks_left_out "pip failed"
  echo "raycut: installing python/requirements-frameworks.txt failed (${free_gb} GB were free)" >&2
  exit 1
fi
