# Sourced by the device scripts (train/gpu_train.sh, bench/gpu_bench.sh):
# configures and builds the LibTorch-only flavour on a machine that has a
# CUDA PyTorch and nothing else (no Debian -dev packages, no network).
#
#   build_torch_only ROOT BUILD_DIR LOG_DIR CONFIGURE_ONLY(0|1) TARGET...
#
# A PyTorch install carries its LibTorch (found through the Python module);
# Debian's libtorch-dev has no Python module and is found by CMake's default
# search. An already configured BUILD_DIR is built as it is.
build_torch_only() {
  local root=$1 build=$2 logs=$3 configure_only=$4
  shift 4
  mkdir -p "$logs"
  if [ ! -f "$build/CMakeCache.txt" ]; then
    local prefix=() generator=() torch_cmake
    if torch_cmake=$(python3 -c 'import torch; print(torch.utils.cmake_prefix_path)' 2>/dev/null); then
      prefix=(-DCMAKE_PREFIX_PATH="$torch_cmake")
      # Hopper (H100/H200): steers the CUDA checks of LibTorch's CMake files;
      # the network's kernels come with LibTorch.
      export TORCH_CUDA_ARCH_LIST=${TORCH_CUDA_ARCH_LIST:-9.0}
    fi
    command -v ninja > /dev/null && generator=(-G Ninja)
    echo "configuring $build (LibTorch only)"
    cmake -S "$root" -B "$build" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release -DDISPMVS_TORCH_ONLY=ON \
      "${prefix[@]}" > "$logs/configure.log" 2>&1 || { cat "$logs/configure.log"; return 1; }
  fi
  [ "$configure_only" = 1 ] && return 0
  echo "building $* in $build"
  cmake --build "$build" --target "$@" -j "$(nproc)" > "$logs/build.log" 2>&1 ||
    { tail -50 "$logs/build.log"; return 1; }
}
