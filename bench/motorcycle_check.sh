#!/usr/bin/env bash
# A real two-view check: DispMVS on the Middlebury 2014 Motorcycle pair
# (quarter size, 741x500) that Debian's python3-skimage package ships with its
# ground-truth disparity, scored in depth and in disparity by dispmvs_eval.
#
#   1. apt-get download python3-skimage (into OUT_DIR/download; a .deb already
#      there is reused), dpkg-deb -x, unzip -p motorcycle_disp.npz arr_0.npy
#   2. dispmvs_stereo_pair_workspace -> OUT_DIR/workspace (cameras, poses,
#      sparse points and GT depth from the Middlebury calibration)
#   3. dispmvs_colmap --mode photometric (one source view each; a pair needs
#      no geometric pass)
#   4. dispmvs_eval -> OUT_DIR/eval.txt, eval.json, eval.tsv, png/
#
# usage: bench/motorcycle_check.sh BUILD_DIR OUT_DIR [dispmvs_colmap options]
# e.g. bench/motorcycle_check.sh build out/motorcycle --device cuda
# Needs apt-get, dpkg-deb and unzip (.ci/install_deps.sh installs unzip).
set -euo pipefail

if [ $# -lt 2 ]; then
  echo "usage: $0 BUILD_DIR OUT_DIR [dispmvs_colmap options]" >&2
  exit 2
fi
[ -d "$1" ] || { echo "error: BUILD_DIR $1 is not a directory" >&2; exit 1; }
build=$(cd "$1" && pwd)
mkdir -p "$2"
out=$(cd "$2" && pwd)
shift 2

# Quarter-size Motorcycle calibration (Middlebury's calib.txt divided by 4).
focal=994.978
cx=311.193
cy=254.877
doffs=31.086
baseline=193.001  # mm: depths come out in mm
expected_version=0.19.3-8

step() { echo "== $*"; }
fail() { echo "error: $*" >&2; exit 1; }

converter=$build/bench/dispmvs_stereo_pair_workspace
colmap_dense=$build/src/dispmvs_colmap
evaluate=$build/src/dispmvs_eval
for program in "$converter" "$colmap_dense" "$evaluate"; do
  [ -x "$program" ] || fail "$program is missing: cmake --build $build --target $(basename "$program")"
done
for tool in apt-get dpkg-deb; do
  command -v "$tool" > /dev/null || fail "$tool is not on PATH (this script needs Debian's package tools)"
done
command -v unzip > /dev/null || fail "unzip is not on PATH: apt-get install unzip (.ci/install_deps.sh installs it)"

start=$(date +%s)

step "fetching python3-skimage"
mkdir -p "$out/download"
if ! ls "$out"/download/python3-skimage_*.deb > /dev/null 2>&1; then
  # apt-get download needs no root, only package lists that know the package.
  if ! (cd "$out/download" && apt-get download python3-skimage); then
    echo "warning: apt-get download python3-skimage failed." >&2
    echo "  Update the package lists (as root: apt-get update) and rerun, or put" >&2
    echo "  python3-skimage_${expected_version}_all.deb into $out/download yourself." >&2
    exit 1
  fi
fi
debs=("$out"/download/python3-skimage_*.deb)
[ ${#debs[@]} -eq 1 ] || fail "several python3-skimage packages in $out/download: keep one"
deb=${debs[0]}
version=$(dpkg-deb -f "$deb" Version)
if [ "$version" != "$expected_version" ]; then
  echo "warning: $deb is version $version, this check was set up with $expected_version" >&2
fi

step "extracting the Motorcycle pair from $(basename "$deb")"
rm -rf "$out/skimage"
dpkg-deb -x "$deb" "$out/skimage"
data=$out/skimage/usr/lib/python3/dist-packages/skimage/data
for file in motorcycle_left.png motorcycle_right.png motorcycle_disp.npz; do
  [ -f "$data/$file" ] || fail "$deb has no $file under usr/lib/python3/dist-packages/skimage/data"
done
# Written under a temporary name so that a failed extraction leaves no
# truncated .npy behind.
unzip -p "$data/motorcycle_disp.npz" arr_0.npy > "$out/motorcycle_disp.npy.tmp"
mv "$out/motorcycle_disp.npy.tmp" "$out/motorcycle_disp.npy"

step "writing the workspace $out/workspace"
ws=$out/workspace
"$converter" --left "$data/motorcycle_left.png" --right "$data/motorcycle_right.png" \
  --disparity "$out/motorcycle_disp.npy" --focal $focal --cx $cx --cy $cy --doffs $doffs \
  --baseline $baseline --output_path "$ws"

step "dispmvs_colmap --mode photometric (log: $out/dispmvs_colmap.log)"
# --overwrite: maps of an earlier run with other weights or options must not
# be scored as this run's.
network_start=$(date +%s)
"$colmap_dense" --workspace_path "$ws" --mode photometric --overwrite "$@" \
  > "$out/dispmvs_colmap.log" 2>&1 || { tail -n 20 "$out/dispmvs_colmap.log" >&2; fail "dispmvs_colmap failed (see $out/dispmvs_colmap.log)"; }
network_seconds=$(( $(date +%s) - network_start ))

step "dispmvs_eval"
"$evaluate" --workspace_path "$ws" --types dispmvs.photometric --per_view \
  --json "$out/eval.json" --tsv "$out/eval.tsv" --png_dir "$out/png" > "$out/eval.txt.tmp"
mv "$out/eval.txt.tmp" "$out/eval.txt"
cat "$out/eval.txt"
echo "time: $(( $(date +%s) - start )) s in all, ${network_seconds} s in dispmvs_colmap"
