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
set -euo pipefail

if [ $# -lt 2 ]; then
  sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//' >&2
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

files=()
for f in "$dir"/weights-*.safetensors "$dir"/checkpoint-*.safetensors; do
  [ -e "$f" ] || continue
  case "$f" in *.optim.safetensors) continue ;; esac
  files+=("$f")
done
[ ${#files[@]} -gt 0 ] || { echo "error: no weights-*.safetensors or checkpoint-*.safetensors in $dir" >&2; exit 1; }

for f in "${files[@]}"; do
  name=$(basename "$f" .safetensors)
  step=$((10#${name##*-}))
  # selection.txt lines: STEP<TAB>OPTIONS<TAB>the x=1 line of --evaluate.
  if awk -F'\t' -v s="$step" -v o="$signature" '$1 == s && $2 == o { found = 1 } END { exit !found }' "$scores"; then
    continue
  fi
  # A checkpoint can be replaced while it is read (training goes on): copy it first.
  copy=$(mktemp "$dir/.scoring-XXXXXX.safetensors")
  if ! cp "$f" "$copy" 2>/dev/null; then rm -f "$copy"; continue; fi
  if ! out=$("$train" --evaluate "$copy" "${options[@]}" 2>&1); then
    rm -f "$copy"
    echo "error: evaluating $f failed:" >&2
    echo "$out" >&2
    exit 1
  fi
  rm -f "$copy"
  line=$(grep '^x=1' <<< "$out" | head -1)
  [ -n "$line" ] || { echo "error: no x=1 row when evaluating $f:" >&2; echo "$out" >&2; exit 1; }
  printf '%s\t%s\t%s\n' "$step" "$signature" "$line" >> "$scores"
  echo "scored step $step" >&2
done

# The table: every step scored with these options, in step order, best <2 % in bold.
sort -t "$(printf '\t')" -k1,1n "$scores" | awk -F'\t' -v o="$signature" '
  function field(line, name) { sub(".*" name ": ", "", line); sub(/ .*/, "", line); return line }
  $2 == o {
    rows[++n] = $1; w1[n] = field($3, "<1%"); w2[n] = field($3, "<2%"); ar[n] = field($3, "AbsRel")
    if (best == 0 || w2[n] + 0 > w2[best] + 0) best = n
  }
  END {
    print "| step | <1 % | <2 % | AbsRel |"
    print "|---|---|---|---|"
    for (i = 1; i <= n; i++) {
      mark = (i == best) ? "**" : ""
      printf "| %d | %s | %s%s%s | %s |\n", rows[i], w1[i], mark, w2[i], mark, ar[i]
    }
  }'
