#!/usr/bin/env bash
# Installs everything dispmvs needs to build and test on Debian 12, from
# Debian's own packages. Run as root (or with sudo available).
set -euo pipefail
export DEBIAN_FRONTEND=noninteractive
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO=sudo; fi
packages=(
  build-essential cmake ninja-build pkg-config
  libtorch-dev            # the network (LibTorch 1.13, CPU)
  libeigen3-dev           # geometry in colmap_io and test references
  libopencv-dev           # image I/O and resizing
  libtiff-dev libwebp-dev # image headers read before decoding (colmap_io/image_header.h)
  libboost-program-options-dev
  libnanoflann-dev         # k-d trees of the point-cloud evaluation (eval/)
  libgtest-dev libgmock-dev
  libbenchmark-dev        # microbenchmarks in bench/
  colmap                  # the real peer in the interop tests
  dpkg-dev file           # `cpack -G DEB`: dpkg-shlibdeps computes the package's Depends, CPack
                          # finds the binaries with file (cmake/packaging.cmake, tests/package/)
  unzip                   # bench/motorcycle_check.sh: the disparity inside scikit-image's .npz
  chromium                # the report_in_browser test: a real browser loads the run report
  munge slurmctld slurmd slurm-client  # the slurm_one_node test starts a one-node Slurm cluster
  clang libclang-rt-14-dev  # the fuzz ctest (tests/fuzz/): libFuzzer targets need clang and its
                            # libFuzzer and sanitizer runtimes (Debian 12: clang 14)
)
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq "${packages[@]}"
