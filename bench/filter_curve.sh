#!/usr/bin/env bash
# The geometric filter's precision against its completeness: on workspaces
# whose photometric maps already exist, reruns `dispmvs_colmap --mode fuse`
# with each filter setting and scores the geometric maps against the ground
# truth. One point per setting and set: x = the share of ALL ground-truth
# pixels kept and within 2 % (a filtered-out pixel counts as a miss, as
# realval's figures count), y = the share of the kept pixels within 2 %.
# Only the filter and fusion run, never the network; fusion keeps its
# defaults (bench/filter_sweep.sh scores the clouds).
#
#   bench/filter_curve.sh BUILD_DIR OUT_DIR [--realval DIR] [--generated DIR]
#                         [--sources N] SETTING...
#     --realval DIR    two-view workspaces with maps and ground truth, e.g. the
#                      OUT_DIR of bench/realval_eval.sh (validation only: read
#                      the rules in its README); scored as realval's figures
#                      are, the mean over the pairs of each set (mvs_*,
#                      scenes11_*)
#     --generated DIR  generated workspaces (scene_*), e.g. OUT_DIR/x1 of
#                      bench/depth_range_robustness.sh; pixels pooled over all
#                      views of all scenes
#     --sources N      the --max_num_src_images the generated maps were made
#                      with (default 5, depth_range_robustness.sh's)
#     SETTING          "LABEL REPROJ DEPTH SUPPORT RADIUS": a curve's name and
#                      the values of --filter_max_reproj_error
#                      --filter_max_depth_error --filter_min_support
#                      --filter_support_radius, e.g. "colmap 1 0.01 0 2"
#                      (the filter before the support rule) or
#                      "support 2 0.02 0.6 2"; a LABEL ending in '*' marks the
#                      default in the plot
#
# Writes OUT_DIR/filter_curve.tsv (set, label, the four values, within_2_all,
# precision), OUT_DIR/filter_curve.md (the same as tables) and, where
# python3 is found, OUT_DIR/filter_curve.svg (bench/plot_filter_curve.py).
# Every workspace is left with the geometric maps and fused.ply of the last
# setting.
set -euo pipefail

die() { echo "filter_curve: $*" >&2; exit 1; }
[ $# -ge 3 ] || die "usage: $0 BUILD_DIR OUT_DIR [--realval DIR] [--generated DIR] [--sources N] SETTING..."
build=$(cd "$1" && pwd) || die "no build directory $1"
mkdir -p "$2"
out=$(cd "$2" && pwd)
shift 2
realval="" generated="" sources=5
while [ $# -gt 0 ]; do
  case "$1" in
    --realval) [ $# -ge 2 ] || die "--realval needs a folder"; realval=$(cd "$2" && pwd) || die "no folder $2"; shift 2 ;;
    --generated) [ $# -ge 2 ] || die "--generated needs a folder"; generated=$(cd "$2" && pwd) || die "no folder $2"; shift 2 ;;
    --sources) [ $# -ge 2 ] || die "--sources needs a value"; sources=$2; shift 2 ;;
    --*) die "unknown option $1" ;;
    *) break ;;
  esac
done
[ -n "$realval$generated" ] || die "give --realval DIR, --generated DIR or both"
[ $# -ge 1 ] || die "no setting given"
for setting in "$@"; do
  read -r label reproj depth support radius extra <<< "$setting"
  [ -n "${radius:-}" ] && [ -z "${extra:-}" ] || die "setting '$setting' is not LABEL REPROJ DEPTH SUPPORT RADIUS"
done
for program in src/dispmvs_colmap src/dispmvs_eval; do
  [ -x "$build/$program" ] || die "$build/$program is missing: build the project first"
done
realval_ws=() generated_ws=()
if [ -n "$realval" ]; then
  for ws in "$realval"/*/; do
    [ -d "$ws/ground_truth/depth_maps" ] && [ -d "$ws/stereo/depth_maps" ] && realval_ws+=("${ws%/}")
  done
  [ ${#realval_ws[@]} -gt 0 ] || die "no workspace with ground_truth/ and stereo/ maps in $realval"
fi
if [ -n "$generated" ]; then
  for ws in "$generated"/scene_*; do [ -d "$ws" ] && generated_ws+=("$ws"); done
  [ ${#generated_ws[@]} -gt 0 ] || die "no scene_* workspace in $generated"
fi

# fuse WS K SETTING EXTRA...: the filter and fusion with one setting, scored.
fuse() {
  local ws=$1 k=$2 label reproj depth support radius
  read -r label reproj depth support radius <<< "$3"
  shift 3
  "$build/src/dispmvs_colmap" --workspace_path "$ws" --mode fuse --no_report \
    --filter_max_reproj_error "$reproj" --filter_max_depth_error "$depth" \
    --filter_min_support "$support" --filter_support_radius "$radius" "$@" > "$ws/filter_curve_$k.log" 2>&1 ||
    die "dispmvs_colmap failed on $ws (see $ws/filter_curve_$k.log)"
}

tsv="$out/filter_curve.tsv"
printf 'set\tlabel\treproj\tdepth\tsupport\tradius\twithin_2_all\tprecision\n' > "$tsv.tmp"
k=0
for setting in "$@"; do
  k=$((k + 1))
  read -r label reproj depth support radius <<< "$setting"
  values="$label	$reproj	$depth	$support	$radius"
  echo "== $setting" >&2
  for ws in "${realval_ws[@]}"; do
    fuse "$ws" "$k" "$setting"
    "$build/src/dispmvs_eval" --workspace_path "$ws" --types dispmvs.geometric \
      --tsv "$ws/filter_curve_$k.tsv" > /dev/null || die "dispmvs_eval failed on $ws"
  done
  if [ ${#realval_ws[@]} -gt 0 ]; then
    # Per pair the shares, then the mean over each set's pairs.
    for ws in "${realval_ws[@]}"; do
      awk -F'\t' -v pair="$(basename "$ws")" '$1 == "depth" && $4 > 0 {
        printf "%s\t%.6f\t%.6f\n", pair, $7 / $4, ($5 > 0 ? $7 / $5 : 0) }' "$ws/filter_curve_$k.tsv"
    done | awk -F'\t' -v values="$values" '
      { set = $1; sub(/_[^_]*$/, "", set); if (!(set in n)) order[++sets] = set
        n[set]++; all[set] += $2; precision[set] += $3 }
      END { for (i = 1; i <= sets; ++i) { s = order[i]
              printf "realval %s\t%s\t%.4f\t%.4f\n", s, values, all[s] / n[s], precision[s] / n[s] } }' \
      >> "$tsv.tmp"
  fi
  for ws in "${generated_ws[@]}"; do
    fuse "$ws" "$k" "$setting" --max_num_src_images "$sources"
    "$build/src/dispmvs_eval" --workspace_path "$ws" --types dispmvs.geometric \
      --tsv "$ws/filter_curve_$k.tsv" > /dev/null || die "dispmvs_eval failed on $ws"
  done
  if [ ${#generated_ws[@]} -gt 0 ]; then
    for ws in "${generated_ws[@]}"; do cat "$ws/filter_curve_$k.tsv"; done |
      awk -F'\t' -v values="$values" '
        $1 == "depth" && $2 == "dispmvs.geometric" { gt += $4; pred += $5; w2 += $7 }
        END { printf "generated\t%s\t%.4f\t%.4f\n", values, w2 / gt, (pred > 0 ? w2 / pred : 0) }' \
      >> "$tsv.tmp"
  fi
done
mv "$tsv.tmp" "$tsv"

awk -F'\t' 'NR > 1 {
    if (!($1 in seen)) { seen[$1] = 1; order[++sets] = $1 }
    rows[$1] = rows[$1] sprintf("| %s | %s | %s | %s | %s | %s | %s |\n", $2, $3, $4, $5, $6, $7, $8)
  }
  END { for (i = 1; i <= sets; ++i) {
          printf "%s\n\n| setting | reproj px | depth | support | radius | kept and within 2 %% (of all GT) | precision (kept within 2 %%) |\n", order[i]
          printf "|---|---|---|---|---|---|---|\n%s\n", rows[order[i]] } }' "$tsv" > "$out/filter_curve.md"
cat "$out/filter_curve.md"
if command -v python3 > /dev/null; then
  python3 "$(dirname "$0")/plot_filter_curve.py" "$tsv" "$out/filter_curve.svg"
  echo "plot: $out/filter_curve.svg"
fi
