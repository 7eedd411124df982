# Shared by package_test.sh and package_install_test.sh (sourced, not run).

fail() {
  echo "FAIL: $*" >&2
  exit 1
}

# build_deb CPACK BUILD_DIR OUT_DIR: `cpack -G DEB` with the build folder's
# CPack configuration, its output (and CPack's staging folder) in the scratch
# folder OUT_DIR instead of the build folder; prints the path of the .deb.
build_deb() {
  local cpack=$1 build_dir=$2 out=$3 debs
  rm -rf "$out"
  mkdir -p "$out"
  if ! "$cpack" -G DEB --config "$build_dir/CPackConfig.cmake" -B "$out" \
      >"$out/cpack.log" 2>&1; then
    cat "$out/cpack.log" >&2
    fail "cpack -G DEB failed"
  fi
  debs=("$out"/dispmvs_*.deb)
  if [ "${#debs[@]}" != 1 ] || [ ! -f "${debs[0]}" ]; then
    cat "$out/cpack.log" >&2
    fail "cpack made no single dispmvs_*.deb in $out: ${debs[*]}"
  fi
  echo "${debs[0]}"
}

# run_example MAKE_EXAMPLE COLMAP WS WEIGHTS: generates the embedded example in
# WS, runs dispmvs_colmap on it without --model_path, and checks its exit
# status, WS/fused.ply, the fused points and that it used the weights WEIGHTS.
run_example() {
  local make_example=$1 colmap=$2 ws=$3 weights=$4 out rc
  rm -rf "$ws"
  if ! out=$("$make_example" --output_path "$ws" --ground_truth_sampling colmap-dense 2>&1); then
    echo "$out" >&2
    fail "$make_example failed"
  fi
  rc=0
  out=$("$colmap" --workspace_path "$ws" --max_image_size 64 --threads 2 2>&1) || rc=$?
  echo "$out"
  [ "$rc" = 0 ] || fail "$colmap exited with status $rc"
  [ -s "$ws/fused.ply" ] || fail "no $ws/fused.ply"
  [[ $'\n'"$out"$'\n' == *" weights $weights"$'\n'* ]] ||
    fail "$colmap did not use the weights $weights"
  [[ "$out" =~ summary:\ fusion:\ [1-9][0-9]*\ points ]] || fail "no fused points"
}
