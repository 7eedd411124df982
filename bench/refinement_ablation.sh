#!/usr/bin/env bash
# The photometric refinement's steps turned off one at a time: for each
# variant, the share of pixels within 2 % on realval's pairs (photometric
# maps of the MVS and Scenes11 sets, and the MVS set's geometric maps; the
# mean over the pairs, bench/realval_eval.sh) and on the generated validation
# scenes (dispmvs_train --evaluate, the weights' own validation set), and the
# time per view on realval (640x480, one source: the mean of each pair's
# second view, the first carrying the program's start-up).
#
#   bench/refinement_ablation.sh BUILD_DIR REALVAL_DIR OUT_DIR [--scenes K] [--variants "A B ..."]
#     REALVAL_DIR  the validation pairs (../shared/data/realval: validation
#                  only, never trained on; read its README)
#     --scenes K   generated validation scenes (default 20)
#     --variants   which rows, by name (default all): default network sweep
#                  propagation full_resolution trusted_planes axis_anchors
#                  local_planes window_shift unseen
#
# Writes OUT_DIR/NAME/ (realval_eval.sh's output and scenes.txt) per variant
# and OUT_DIR/ablation.md; reruns keep what is there (realval_eval.sh keeps
# finished pairs; delete OUT_DIR/NAME to redo a variant).
set -euo pipefail

die() { echo "refinement_ablation: $*" >&2; exit 1; }
[ $# -ge 3 ] || die "usage: $0 BUILD_DIR REALVAL_DIR OUT_DIR [--scenes K] [--variants \"A B ...\"]"
build=$(cd "$1" && pwd) || die "no build directory $1"
realval=$(cd "$2" && pwd) || die "no folder $2"
mkdir -p "$3"
out=$(cd "$3" && pwd)
shift 3
scenes=20
variants="default network sweep propagation full_resolution trusted_planes axis_anchors local_planes window_shift unseen"
while [ $# -gt 0 ]; do
  case "$1" in
    --scenes) [ $# -ge 2 ] || die "--scenes needs a value"; scenes=$2; shift 2 ;;
    --variants) [ $# -ge 2 ] || die "--variants needs a value"; variants=$2; shift 2 ;;
    *) die "unknown option $1" ;;
  esac
done
for program in src/dispmvs_colmap src/dispmvs_eval src/dispmvs_train; do
  [ -x "$build/$program" ] || die "$build/$program is missing: build the project first"
done
here=$(cd "$(dirname "$0")" && pwd)
weights="$here/../models/dispmvs_small.safetensors"

# NAME -> "what is off|options of both programs"
describe() {
  case "$1" in
    default) echo "nothing (the defaults)|" ;;
    network) echo "the whole refinement (the network alone)|--refinement none" ;;
    sweep) echo "the sweep of constant depths|--refine_sweep_hypotheses 0" ;;
    propagation) echo "propagation, coarse and full-resolution|--refine_propagation_rounds 0 --refine_full_resolution_rounds 0" ;;
    full_resolution) echo "the full-resolution propagation round|--refine_full_resolution_rounds 0" ;;
    trusted_planes) echo "long-range planes|--refine_trusted_plane_ncc 0" ;;
    axis_anchors) echo "long-range planes from the row and column|--refine_trusted_plane_axis_anchors 0" ;;
    local_planes) echo "local planes|--refine_local_plane_radius 0" ;;
    window_shift) echo "shifted windows|--refine_window_shift 0" ;;
    unseen) echo "planes over pixels no source sees|--refine_unseen_slope_radius 0" ;;
    *) die "unknown variant $1" ;;
  esac
}

for name in $variants; do describe "$name" > /dev/null; done  # an unknown name stops here

table="$out/ablation.md"
{
  echo "| turned off | realval MVS, photometric <2 % | realval MVS, geometric <2 % | Scenes11 <2 % | $scenes generated scenes <2 % | s per view (realval) | options |"
  echo "|---|---|---|---|---|---|---|"
} > "$table.tmp"
for name in $variants; do
  IFS='|' read -r what options <<< "$(describe "$name")"
  echo "== $name: $what" >&2
  mkdir -p "$out/$name"
  # shellcheck disable=SC2086  # options are words
  "$here/realval_eval.sh" "$build" "$realval" "$out/$name" -- $options > "$out/$name/realval.txt" ||
    die "realval_eval.sh failed for $name"
  # dispmvs_train spells the same options --eval_refinement, --eval_refine_*.
  train_options=${options//--refine/--eval_refine}
  [ "$options" = "--refinement none" ] || train_options="--eval_refinement ncc $train_options"
  if [ ! -s "$out/$name/scenes.txt" ]; then
    # shellcheck disable=SC2086
    "$build/src/dispmvs_train" --evaluate "$weights" --height 512 --width 640 --sources 5 \
      --val_scenes "$scenes" --widenings 1 $train_options > "$out/$name/scenes.txt.tmp" 2>&1 ||
      die "dispmvs_train --evaluate failed for $name (see $out/$name/scenes.txt.tmp)"
    mv "$out/$name/scenes.txt.tmp" "$out/$name/scenes.txt"
  fi
  realval_cols=$(awk -F'\t' 'NR > 1 {
      set = $1; sub(/_[^_]*$/, "", set); key = set " " $2; n[key]++; w2[key] += $4 }
    END { printf "%.3f | %.3f | %.3f", w2["mvs dispmvs.photometric"] / n["mvs dispmvs.photometric"],
            w2["mvs dispmvs.geometric"] / n["mvs dispmvs.geometric"],
            w2["scenes11 dispmvs.photometric"] / n["scenes11 dispmvs.photometric"] }' "$out/$name/summary.tsv")
  scenes_col=$(grep -o '^x=1.000 .*<2%: [0-9.]*' "$out/$name/scenes.txt" | sed 's/.*<2%: //' | head -n 1)
  seconds=$(cat "$out/$name"/*/dispmvs_colmap.log |
    awk '/^photometric: \[2\/2\]/ { for (i = 1; i <= NF; ++i) if ($i == "s,") { t += $(i - 1); n++ } }
         END { if (n > 0) printf "%.2f", t / n; else printf "n/a" }')
  echo "| $what | $realval_cols | ${scenes_col:-n/a} | $seconds | \`${options:-}\` |" >> "$table.tmp"
done
mv "$table.tmp" "$table"
cat "$table"
