#!/usr/bin/env bash
# Installs everything raycut needs on a fresh Debian 12 machine, from Debian's packages.
# The CUDA toolkit is optional and not a Debian package here: when nvcc is on the machine
# (/usr/local/cuda), the CUDA methods are built; otherwise the CPU methods only.
set -euo pipefail
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends \
  cmake ninja-build g++ make git \
  libgtest-dev libgmock-dev libcli11-dev libpng-dev \
  clang-format python3 python3-numpy python3-matplotlib \
  clang libclang-rt-14-dev  # the readers' fuzz test (tests/fuzz: libFuzzer, sanitizers)
echo "raycut: dependencies installed"
