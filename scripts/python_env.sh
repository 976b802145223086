#!/usr/bin/env bash
# Creates the repository's virtual environment, .venv (ignored by git), if it is missing, and
# installs python/requirements.txt into it from PyPI. PyTorch and JAX with their CUDA libraries
# come to several GB: pip's cache is off, since it would store every wheel a second time and a
# full disk fails the install.
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/python ] || python3 -m venv .venv
.venv/bin/python -m pip install -q --no-cache-dir --upgrade pip
# One retry: a download that breaks off should not fail a fresh machine's setup.
.venv/bin/python -m pip install -q --no-cache-dir -r python/requirements.txt ||
  { sleep 10; .venv/bin/python -m pip install -q --no-cache-dir -r python/requirements.txt; }
