#!/usr/bin/env bash
# The geometric filter's and fusion's settings against the fused cloud: on
# workspaces whose photometric maps already exist (the x<X> folder of a
# depth_range_robustness.sh run), reruns `dispmvs_colmap --mode fuse` with
# each setting, scores the geometric maps and fused.ply with dispmvs_eval
# against the exact ground truth, and prints one table row per setting.
# Only the filter and fusion run (about a second per scene), never the
# network, so a sweep of many settings takes minutes.
#
#   bench/filter_sweep.sh BUILD_DIR WS_ROOT [--sources N] SETTING...
#     WS_ROOT     a folder of generated workspaces (scene_*) with photometric
#                 maps and ground truth, e.g. OUT_DIR/x1 of
#                 depth_range_robustness.sh
#     --sources N the --max_num_src_images the maps were made with (default 5,
#                 depth_range_robustness.sh's): the filter's sources must be
#                 the network's
#     SETTING     "REPROJ DEPTH CONSISTENT CONFIDENCE", the values of
#                 --max_reproj_error --max_depth_error --min_num_consistent
#                 --min_confidence, e.g. "1 0.01 2 0.1" (fusion's defaults);
#                 the geometric filter gets the same thresholds without its
#                 support rule (--filter_max_reproj_error REPROJ
#                 --filter_max_depth_error DEPTH --filter_min_support 0), the
#                 one rule for both that this sweep was made for
#                 (bench/filter_curve.sh sweeps the filter's own)
#
# Each setting leaves its logs and scores in each scene as fuse_<K>.log and
# eval_<K>.{tsv,json} (K = the setting's position, from 1), and the geometric
# maps and fused.ply of the last setting. Columns: those of
# depth_range_robustness.sh's tables, pooled the same way
# (bench/eval_pooling.sh): the geometric maps over all views of all scenes,
# the clouds as means over scenes (F-score at dispmvs_eval's default tau).
set -euo pipefail

die() { echo "filter_sweep: $*" >&2; exit 1; }
# shellcheck source=eval_pooling.sh
source "$(dirname "$0")/eval_pooling.sh"

[ $# -ge 3 ] || die "usage: $0 BUILD_DIR WS_ROOT [--sources N] \"REPROJ DEPTH CONSISTENT CONFIDENCE\"..."
build=$(cd "$1" && pwd) || die "no build directory $1"
root=$(cd "$2" && pwd) || die "no folder $2"
shift 2
sources=5
if [ "${1:-}" = "--sources" ]; then
  [ $# -ge 2 ] || die "--sources needs a value"
  sources=$2
  shift 2
fi
[ $# -ge 1 ] || die "no setting given"
for program in src/dispmvs_colmap src/dispmvs_eval; do
  [ -x "$build/$program" ] || die "$build/$program is missing: build the project first"
done
workspaces=("$root"/scene_*)
[ -d "${workspaces[0]}" ] || die "no scene_* workspace in $root"

echo "| max_reproj_error | max_depth_error | min_num_consistent | min_confidence | geometric coverage | AbsRel | <1 % | <2 % | <5 % | fused points (mean) | accuracy / diag | completeness / diag | overall / diag | precision | recall | F-score |"
echo "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
k=0
for setting in "$@"; do
  k=$((k + 1))
  read -r reproj depth consistent confidence extra <<< "$setting"
  [ -n "$confidence" ] && [ -z "${extra:-}" ] || die "setting '$setting' is not four numbers"
  for ws in "${workspaces[@]}"; do
    "$build/src/dispmvs_colmap" --workspace_path "$ws" --mode fuse --max_num_src_images "$sources" \
      --max_reproj_error "$reproj" --max_depth_error "$depth" --min_num_consistent "$consistent" \
      --filter_max_reproj_error "$reproj" --filter_max_depth_error "$depth" --filter_min_support 0 \
      --min_confidence "$confidence" > "$ws/fuse_$k.log" 2>&1 ||
      die "dispmvs_colmap failed on $ws (see $ws/fuse_$k.log)"
    "$build/src/dispmvs_eval" --workspace_path "$ws" --types dispmvs.geometric \
      --ply "$ws/fused.ply" --json "$ws/eval_$k.json" --tsv "$ws/eval_$k.tsv" > /dev/null ||
      die "dispmvs_eval failed on $ws"
  done
  maps=$(for ws in "${workspaces[@]}"; do cat "$ws/eval_$k.tsv"; done |
    pooled_depth_columns dispmvs.geometric)
  clouds=$(mean_cloud_columns "eval_$k.tsv" "eval_$k.json" "${workspaces[@]}") ||
    die "a scene has no cloud scores"
  echo "| $reproj | $depth | $consistent | $confidence | $maps | $clouds |"
done
