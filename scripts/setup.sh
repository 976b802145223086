#!/usr/bin/env bash
# Installs everything raycut needs on a fresh Debian 12 machine, from Debian's packages, then the
# Python package's build and test requirements (python/requirements.txt, from PyPI) and PyTorch and
# JAX (python/requirements-frameworks.txt, about 6 GB, for the operators and the custom call:
# scripts/python_env.sh) into a virtual environment in
# the repository, .venv (ignored by git; Debian's own Python refuses `pip install` outside one,
# PEP 668). scripts/test.sh uses it.
# doxygen and sphinx build the API reference (scripts/docs.sh).
# Open MPI builds raycut::mpi, the distributed engine, and its tests (mpirun, 1 to 4 ranks).
# The CUDA toolkit is optional and not a Debian package here: when nvcc is on the machine
# (/usr/local/cuda), the CUDA methods are built; otherwise the CPU methods only.
set -euo pipefail
cd "$(dirname "$0")/.."
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends \
  cmake ninja-build g++ make git \
  libgtest-dev libgmock-dev libcli11-dev libpng-dev \
  clang-format python3 python3-dev python3-venv python3-numpy python3-matplotlib \
  openmpi-bin libopenmpi-dev doxygen \
  clang libclang-rt-14-dev  # the readers' fuzz test (tests/fuzz: libFuzzer, sanitizers)
scripts/python_env.sh
echo "raycut: dependencies installed (Python: $PWD/.venv)"
