#!/usr/bin/env bash
# Scores a training run's checkpoints on the selection set, to choose the one
# that goes on to the published tables (docs/training.md, step 3):
#   train/score_checkpoints.sh BUILD_DIR CHECKPOINT_DIR [dispmvs_train options...]
# Every weights-<step>.safetensors (kept by --keep_weights_every) and the
# latest checkpoint-<step>.safetensors of the folder is evaluated with
#   --evaluate FILE --height 512 --width 640 --sources 5 --val_scenes 20
#   --val_seed_base 2000000000 --widenings 1 --precision bf16 --threads 2
# (20 generated scenes that are not the published 20-scene table's; later
# options override these), and a Markdown table goes to stdout, one row per
# step, the best <2 % marked. The scores are also appended to
# CHECKPOINT_DIR/selection.txt, and a file already scored there with the same
# options is not evaluated again, so the script can run while training goes
# on and be re-run as new checkpoints arrive.
#
# With DISPMVS_REALVAL_DIR set to a folder of real two-view workspaces with
# ground truth (such as ../shared/data/realval: validation and selection
# only, never training), every checkpoint is also run on its mvs_* pairs
# (bench/realval_eval.sh, photometric maps, --threads 2 and the device of the
# options) and the table gains a column, the mean over those pairs of the
# share of GT pixels within 2 %; the best row is then the one with the best
# mean of the two <2 % columns, so that a checkpoint is chosen on both the
# generated and the real images. Those scores go to CHECKPOINT_DIR/
# selection_realval.txt, with the same re-use.
set -euo pipefail

if [ $# -lt 2 ]; then
  sed -n '2,24p' "$0" | sed 's/^# \{0,1\}//' >&2
  exit 2
fi
build=$1 dir=$2
shift 2
train=$build/src/dispmvs_train
[ -x "$train" ] || { echo "error: $train not found: build the project first" >&2; exit 1; }
[ -d "$dir" ] || { echo "error: $dir is not a folder" >&2; exit 1; }

options=(--height 512 --width 640 --sources 5 --val_scenes 20 --val_seed_base 2000000000
         --widenings 1 --precision bf16 --threads 2 "$@")
signature="${options[*]}"
scores=$dir/selection.txt
touch "$scores"
realval=${DISPMVS_REALVAL_DIR:-}
realval_scores=$dir/selection_realval.txt
if [ -n "$realval" ]; then
  ls -d "$realval"/mvs_*/ > /dev/null 2>&1 ||
    { echo "error: DISPMVS_REALVAL_DIR=$realval holds no mvs_* workspace" >&2; exit 1; }
  touch "$realval_scores"
  # The device (and nothing else) of the options applies to dispmvs_colmap too.
  device=cpu
  for ((i = 0; i < ${#options[@]} - 1; ++i)); do
    [ "${options[i]}" = --device ] && device=${options[i + 1]}
  done
  realval_signature="mvs_* photometric --threads 2 --device $device"
fi
root=$(cd "$(dirname "$0")/.." && pwd)

files=()
for f in "$dir"/weights-*.safetensors "$dir"/checkpoint-*.safetensors; do
  [ -e "$f" ] || continue
  case "$f" in *.optim.safetensors) continue ;; esac
  files+=("$f")
done
[ ${#files[@]} -gt 0 ] || { echo "error: no weights-*.safetensors or checkpoint-*.safetensors in $dir" >&2; exit 1; }

# Whether FILE has a line STEP<TAB>SIGNATURE<TAB>...
scored() { awk -F'\t' -v s="$2" -v o="$3" '$1 == s && $2 == o { found = 1 } END { exit !found }' "$1"; }

for f in "${files[@]}"; do
  name=$(basename "$f" .safetensors)
  step=$((10#${name##*-}))
  # selection.txt lines: STEP<TAB>OPTIONS<TAB>the x=1 line of --evaluate;
  # selection_realval.txt lines: STEP<TAB>SIGNATURE<TAB>mean <2 % over the mvs_* pairs.
  need_generated=1 need_real=0
  ! scored "$scores" "$step" "$signature" || need_generated=0
  [ -z "$realval" ] || scored "$realval_scores" "$step" "$realval_signature" || need_real=1
  [ $need_generated = 1 ] || [ $need_real = 1 ] || continue
  # A checkpoint can be replaced while it is read (training goes on): copy it
  # first, once, so that both scores are of the same weights.
  copy=$(mktemp "$dir/.scoring-XXXXXX.safetensors")
  if ! cp "$f" "$copy" 2>/dev/null; then rm -f "$copy"; continue; fi
  if [ $need_real = 1 ]; then
    pairs=$(mktemp -d "$dir/.realval-XXXXXX")
    if ! "$root/bench/realval_eval.sh" "$build" "$realval" "$pairs" --pairs 'mvs_*' -- \
        --model_path "$copy" --mode photometric --threads 2 --device "$device" \
        > "$pairs/table.txt" 2>&1; then
      cat "$pairs/table.txt" >&2
      rm -rf "$copy" "$pairs"
      echo "error: running $f on $realval failed" >&2
      exit 1
    fi
    mean=$(awk -F'\t' 'NR > 1 && $2 == "dispmvs.photometric" { s += $4; n++ } END { if (n) printf "%.4f", s / n }' "$pairs/summary.tsv")
    rm -rf "$pairs"
    [ -n "$mean" ] || { rm -f "$copy"; echo "error: no realval score for $f" >&2; exit 1; }
    printf '%s\t%s\t%s\n' "$step" "$realval_signature" "$mean" >> "$realval_scores"
    echo "scored step $step on $realval: $mean" >&2
  fi
  if [ $need_generated = 1 ]; then
    if ! out=$("$train" --evaluate "$copy" "${options[@]}" 2>&1); then
      rm -f "$copy"
      echo "error: evaluating $f failed:" >&2
      echo "$out" >&2
      exit 1
    fi
    line=$(grep '^x=1' <<< "$out" | head -1)
    [ -n "$line" ] || { rm -f "$copy"; echo "error: no x=1 row when evaluating $f:" >&2; echo "$out" >&2; exit 1; }
    printf '%s\t%s\t%s\n' "$step" "$signature" "$line" >> "$scores"
    echo "scored step $step" >&2
  fi
  rm -f "$copy"
done

# The table: every step scored with these options, in step order, the best in
# bold (its <2 %): the best <2 %, or with realval the best mean of both <2 %.
sort -t "$(printf '\t')" -k1,1n "$scores" | awk -F'\t' -v o="$signature" -v rv="$realval" \
    -v ro="${realval_signature:-}" -v rfile="$realval_scores" '
  function field(line, name) { sub(".*" name ": ", "", line); sub(/ .*/, "", line); return line }
  BEGIN {
    if (rv != "") while ((getline line < rfile) > 0) {
      split(line, part, "\t")
      if (part[2] == ro) real[part[1]] = part[3]
    }
  }
  $2 == o {
    rows[++n] = $1; w1[n] = field($3, "<1%"); w2[n] = field($3, "<2%"); ar[n] = field($3, "AbsRel")
    score = w2[n] + 0
    if (rv != "") score = ($1 in real) ? (score + real[$1]) / 2 : -1
    if (best == 0 || score > best_score) { best = n; best_score = score }
  }
  END {
    if (rv != "") {
      print "| step | <1 % | <2 % | AbsRel | realval mvs <2 % |"
      print "|---|---|---|---|---|"
    } else {
      print "| step | <1 % | <2 % | AbsRel |"
      print "|---|---|---|---|"
    }
    for (i = 1; i <= n; i++) {
      mark = (i == best) ? "**" : ""
      printf "| %d | %s | %s%s%s | %s |", rows[i], w1[i], mark, w2[i], mark, ar[i]
      if (rv != "") printf " %s |", (rows[i] in real) ? real[rows[i]] : "-"
      printf "\n"
    }
  }'
