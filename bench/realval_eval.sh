#!/usr/bin/env bash
# dispmvs on the real-photograph validation pairs (a folder of two-view COLMAP
# dense workspaces with ground-truth depth, e.g. ../shared/data/realval; read
# only, never committed, never trained on), one table per set: per pair the
# share of all ground-truth pixels within 1 / 2 / 5 % (<X%all of dispmvs_eval,
# a missing prediction counting as wrong), photometric and geometric, and the
# mean over the pairs of each set (pairs named SET_NNN: mvs_001 -> set mvs);
# then where the pixels lie (dispmvs_eval --regions: seen by the pair's other
# view, hidden there, outside it; the seen ones by distance to a depth edge),
# pooled over each set's pixels.
#
#   bench/realval_eval.sh BUILD_DIR REALVAL_DIR OUT_DIR [options] [-- dispmvs_colmap options]
#
# options:
#   --pairs GLOB               which pairs (default: every folder of REALVAL_DIR)
#   --principal_point_shift D  add D to cx and cy of every camera of the copies
#                              (the pixel-centre convention of the cameras: D =
#                              0.5 turns "pixel centre at (0, 0)" into COLMAP's
#                              "(0.5, 0.5)"; the ground truth stays as it is)
#   --jpeg_quality Q           replace the copies' photographs by their JPEG
#                              round trip at quality Q (libjpeg through
#                              BUILD_DIR/bench/dispmvs_jpeg_recompress), each
#                              view on its own, as photographs that reach a
#                              workspace as JPEGs: what compression costs
#
# Writes OUT_DIR/PAIR/ (the workspace copy, its maps and eval.tsv) and
# OUT_DIR/summary.tsv (pair, type, within_1, within_2, within_5 as shares of
# the GT pixels), and prints the tables. Reruns keep finished pairs (delete
# OUT_DIR/PAIR to recompute one).
set -euo pipefail

usage() {
  echo "usage: $0 BUILD_DIR REALVAL_DIR OUT_DIR [--pairs GLOB] [--principal_point_shift D] [--jpeg_quality Q]" \
    "[-- dispmvs_colmap options]" >&2
  exit 2
}
[ $# -ge 3 ] || usage
[ -d "$1" ] || { echo "error: BUILD_DIR $1 is not a directory" >&2; exit 1; }
[ -d "$2" ] || { echo "error: REALVAL_DIR $2 is not a directory" >&2; exit 1; }
build=$(cd "$1" && pwd)
realval=$(cd "$2" && pwd)
mkdir -p "$3"
out=$(cd "$3" && pwd)
shift 3
pairs_glob="*"
shift_pp=""
jpeg_quality=""
while [ $# -gt 0 ]; do
  case "$1" in
    --pairs) pairs_glob="$2"; shift 2 ;;
    --principal_point_shift) shift_pp="$2"; shift 2 ;;
    --jpeg_quality) jpeg_quality="$2"; shift 2 ;;
    --) shift; break ;;
    *) usage ;;
  esac
done
colmap_options=("$@")

summary="$out/summary.tsv"
printf 'pair\ttype\twithin_1\twithin_2\twithin_5\n' > "$summary.tmp"
for source in "$realval"/$pairs_glob/; do
  pair=$(basename "$source")
  [ -d "$source/ground_truth/depth_maps" ] || continue
  ws="$out/$pair"
  if [ ! -f "$ws/eval.tsv" ]; then
    rm -rf "$ws"
    cp -r "$source" "$ws"
    chmod -R u+w "$ws"
    if [ -n "$shift_pp" ]; then
      # PINHOLE: fx fy cx cy; SIMPLE_PINHOLE: f cx cy (fields 5.. of a camera line).
      awk -v d="$shift_pp" '
        /^#/ || NF == 0 { print; next }
        $2 == "PINHOLE" { $7 += d; $8 += d; print; next }
        $2 == "SIMPLE_PINHOLE" { $6 += d; $7 += d; print; next }
        { print "error: camera model " $2 " in " FILENAME > "/dev/stderr"; exit 1 }
      ' "$ws/sparse/cameras.txt" > "$ws/sparse/cameras.txt.new"
      mv "$ws/sparse/cameras.txt.new" "$ws/sparse/cameras.txt"
    fi
    if [ -n "$jpeg_quality" ]; then
      "$build/bench/dispmvs_jpeg_recompress" --quality "$jpeg_quality" --images "$ws"/images/* ||
        { echo "error: JPEG recompression failed on $pair" >&2; exit 1; }
    fi
    "$build/src/dispmvs_colmap" --workspace_path "$ws" --no_report "${colmap_options[@]}" \
      > "$ws/dispmvs_colmap.log" 2>&1 ||
      { echo "error: dispmvs_colmap failed on $pair (see $ws/dispmvs_colmap.log)" >&2; exit 1; }
    "$build/src/dispmvs_eval" --workspace_path "$ws" \
      --types dispmvs.photometric,dispmvs.geometric --regions --tsv "$ws/eval.tsv.tmp" > "$ws/eval.txt"
    mv "$ws/eval.tsv.tmp" "$ws/eval.tsv"
  fi
  # depth TYPE views gt_pixels predicted within_1 within_2 within_5 ...
  awk -F'\t' -v pair="$pair" '$1 == "depth" && $4 > 0 {
    printf "%s\t%s\t%.4f\t%.4f\t%.4f\n", pair, $2, $6 / $4, $7 / $4, $8 / $4 }' \
    "$ws/eval.tsv" >> "$summary.tmp"
done
mv "$summary.tmp" "$summary"

# Per set and type: each pair, then the mean over the set's pairs.
awk -F'\t' 'NR > 1 {
    set = $1; sub(/_[^_]*$/, "", set)
    key = set "\t" $2
    if (!(key in n)) order[++keys] = key
    n[key]++; w1[key] += $3; w2[key] += $4; w5[key] += $5
    rows[key] = rows[key] sprintf("  %-16s %.3f / %.3f / %.3f\n", $1, $3, $4, $5)
  }
  END {
    for (k = 1; k <= keys; ++k) {
      key = order[k]; split(key, part, "\t")
      printf "%s, %s: share of GT pixels within 1 / 2 / 5 %%\n%s", part[1], part[2], rows[key]
      printf "  %-16s %.3f / %.3f / %.3f  (%d pairs)\n\n", "mean", w1[key] / n[key],
             w2[key] / n[key], w5[key] / n[key], n[key]
    }
  }' "$summary"

# Per set and type, pooled over the pairs' pixels: each region's share of the
# GT pixels and its pixels within 2 %.
for source in "$realval"/$pairs_glob/; do
  pair=$(basename "$source")
  [ -f "$out/$pair/eval.tsv" ] || continue
  awk -F'\t' -v pair="$pair" '$1 == "depth" || $1 == "region" { print pair "\t" $0 }' "$out/$pair/eval.tsv"
done | awk -F'\t' '
  { set = $1; sub(/_[^_]*$/, "", set) }
  $2 == "depth" { all[set "\t" $3] += $5 }
  $2 == "region" {
    key = set "\t" $3
    if (!((key, $4) in gt)) { names[key, ++count[key]] = $4 }
    gt[key, $4] += $5; w2[key, $4] += $7
    if (!(key in seen_key)) { seen_key[key] = 1; order[++keys] = key }
  }
  END {
    for (k = 1; k <= keys; ++k) {
      key = order[k]; split(key, part, "\t")
      printf "%s, %s: where the GT pixels lie (pooled): share / within 2 %%\n", part[1], part[2]
      for (i = 1; i <= count[key]; ++i) {
        name = names[key, i]
        printf "  %-34s %.3f / %.3f\n", name, gt[key, name] / all[key], w2[key, name] / gt[key, name]
      }
      printf "\n"
    }
  }'
