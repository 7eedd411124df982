#!/usr/bin/env bash
# Depth-range robustness on generated scenes, the protocol of the paper's
# Table 5: every image's depth-range hint [d_min, d_max] (from the sparse
# points, as for a user's workspace) is widened to [d_min / x, d_max * x] for
# x = 1, 2, 3, and the whole dense step (network, geometric filter, fusion) is
# scored against the exact ground truth, for the depth maps and for the fused
# point cloud.
#
#   bench/depth_range_robustness.sh BUILD_DIR OUT_DIR [options]
#     --scenes K        generated scenes (default 10)
#     --seed S          dispmvs_synth's base seed (default 2027; training never
#                       uses dispmvs_synth's workspaces)
#     --width W --height H   image size (default 640 x 512)
#     --views V         views per scene (default 6; every view is a reference)
#     --sources N       sources per reference (default 5, the paper's N = 5
#                       setting; must be < V)
#     --widenings "1 2 3"
#     --model PATH      weights (default: dispmvs_colmap's, the shipped model)
#     -- ARGS...        passed on to dispmvs_colmap (e.g. --threads 2)
#
# Writes OUT_DIR/scenes (the generated workspaces), OUT_DIR/x<X>/scene_NNN
# (one workspace per scene and widening, sharing the scene's images, sparse
# model and ground truth through symbolic links), each scene's
# dispmvs_eval output (eval.tsv, eval.json), and OUT_DIR/table.md. Reruns
# resume: scenes, maps and evaluations already present are kept.
#
# Numbers: depth maps are pooled over all views of all scenes (pixel
# counts added up, as dispmvs_eval does over views): coverage, AbsRel over
# the predicted pixels, and the fractions of ALL ground-truth pixels under
# 1 / 2 / 5 % relative error. Point clouds: accuracy, completeness and
# overall are means over scenes of each scene's value divided by its
# ground-truth cloud's bounding-box diagonal (scenes have random metric
# scales), precision / recall / F-score at tau = 0.2 % of the diagonal
# (dispmvs_eval's default), averaged over scenes.
set -euo pipefail

die() { echo "depth_range_robustness: $*" >&2; exit 1; }
# shellcheck source=eval_pooling.sh
source "$(dirname "$0")/eval_pooling.sh"
types="dispmvs.photometric dispmvs.geometric"

[ $# -ge 2 ] || die "usage: $0 BUILD_DIR OUT_DIR [--scenes K] [--seed S] [--width W] [--height H] [--views V] [--sources N] [--widenings \"1 2 3\"] [--model PATH] [-- dispmvs_colmap args]"
build=$(cd "$1" && pwd) || die "no build directory $1"
mkdir -p "$2"
out=$(cd "$2" && pwd)
shift 2

scenes=10 seed=2027 width=640 height=512 views=6 sources=5 widenings="1 2 3" model=""
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --scenes) scenes=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --width) width=$2; shift 2 ;;
    --height) height=$2; shift 2 ;;
    --views) views=$2; shift 2 ;;
    --sources) sources=$2; shift 2 ;;
    --widenings) widenings=$2; shift 2 ;;
    --model) model=$2; shift 2 ;;
    --) shift; extra=("$@"); break ;;
    *) die "unknown option $1" ;;
  esac
done
for program in src/dispmvs_synth src/dispmvs_colmap src/dispmvs_eval; do
  [ -x "$build/$program" ] || die "$build/$program is missing: build the project first"
done
[ "$sources" -lt "$views" ] || die "--sources must be smaller than --views"
model_args=()
if [ -n "$model" ]; then
  [ -f "$model" ] || die "no weights file $model"
  model_args=(--model_path "$model")
fi

start=$(date +%s)
echo "== generating $scenes scenes (${width}x${height}, $views views, seed $seed)"
"$build/src/dispmvs_synth" --output_path "$out/scenes" --num_scenes "$scenes" --seed "$seed" \
  --width "$width" --height "$height" --num_views "$views" > "$out/synth.log"
tail -n 1 "$out/synth.log"

for x in $widenings; do
  for ((i = 0; i < scenes; ++i)); do
    name=$(printf "scene_%03d" "$i")
    src="$out/scenes/$name"
    ws="$out/x$x/$name"
    [ -d "$src/sparse" ] || die "$src was not generated"
    mkdir -p "$ws/stereo"
    for part in images sparse ground_truth; do
      [ -e "$ws/$part" ] || ln -s "$src/$part" "$ws/$part"
    done
    cp "$src/stereo/patch-match.cfg" "$ws/stereo/patch-match.cfg"
    if [ ! -f "$ws/eval.tsv" ]; then
      echo "== x = $x, $name"
      "$build/src/dispmvs_colmap" --workspace_path "$ws" --depth_range_widening "$x" \
        --max_num_src_images "$sources" ${model_args[@]+"${model_args[@]}"} \
        ${extra[@]+"${extra[@]}"} > "$ws/dispmvs_colmap.log" 2>&1 ||
        die "dispmvs_colmap failed on $ws (see $ws/dispmvs_colmap.log)"
      tail -n 3 "$ws/dispmvs_colmap.log"
      "$build/src/dispmvs_eval" --workspace_path "$ws" \
        --types "${types// /,}" --ply "$ws/fused.ply" \
        --json "$ws/eval.json" --tsv "$ws/eval.tsv.tmp" > "$ws/eval.txt" ||
        die "dispmvs_eval failed on $ws"
      mv "$ws/eval.tsv.tmp" "$ws/eval.tsv"
    fi
  done
done

# One table row per widening and map type, then one per widening for the
# clouds (bench/eval_pooling.sh).
{
  echo "Depth-range robustness: $scenes generated scenes (seed $seed), ${width}x${height}, N = $sources sources, hint [d_min / x, d_max * x]"
  echo
  echo "| x | maps | coverage | AbsRel | <1 % | <2 % | <5 % |"
  echo "|---|---|---|---|---|---|---|"
  for x in $widenings; do
    for type in $types; do
      echo "| $x | $type | $(cat "$out/x$x"/scene_*/eval.tsv | pooled_depth_columns "$type") |"
    done
  done
  echo
  echo "| x | fused points (mean) | accuracy / diag | completeness / diag | overall / diag | precision | recall | F-score |"
  echo "|---|---|---|---|---|---|---|---|"
  for x in $widenings; do
    clouds=$(mean_cloud_columns eval.tsv eval.json "$out/x$x"/scene_*) || die "a scene has no cloud scores"
    [ -z "$clouds" ] || echo "| $x | $clouds |"
  done
  echo
  echo "(this run: $(( $(date +%s) - start )) s on $(nproc) cores; per-scene numbers in OUT_DIR/x*/scene_*/eval.txt)"
} > "$out/table.md.tmp"
mv "$out/table.md.tmp" "$out/table.md"
cat "$out/table.md"
