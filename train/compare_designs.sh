#!/usr/bin/env bash
# Controlled comparison of the paper's design (config small: random start
# inside the depth-range hint, depth loss only) and model v2 (small_v2:
# start from the best match along each epipolar segment, segment volume,
# matching loss) at EQUAL CPU TIME: both trained from scratch, same seed,
# same generated scenes, same validation scenes, one thread each, run side
# by side and stopped by --max_cpu_minutes (process CPU time, so a busy
# machine slows both alike without changing the budget).
#
#   train/compare_designs.sh BUILD_DIR OUT_DIR [CPU_MINUTES] [extra dispmvs_train options]
#   train/compare_designs.sh --summary OUT_DIR     only (re)write OUT_DIR/curves.md
#
# Resumes: rerunning continues both runs from their checkpoints (the CPU
# budget counts from each restart). Writes OUT_DIR/{paper,v2}/train.log and
# OUT_DIR/curves.md (the validation lines: step, CPU seconds, < 2 %, coarse
# top-1, for both arms).
set -euo pipefail

# One row per validation: design, step, CPU seconds, depth metrics, coarse top-1.
summarise() {
  local out=$1
  {
    echo "| design | step | CPU s | <1 % | <2 % | <5 % | AbsRel | coverage | coarse top-1 |"
    echo "|---|---|---|---|---|---|---|---|---|"
    for arm in paper v2; do
      awk -v arm="$arm" '/^validate step/ {
          step=$3; cpu=$5;
          for (i = 1; i <= NF; i++) {
            if ($i == "<1%:") a=$(i+1); if ($i == "<2%:") b=$(i+1); if ($i == "<5%:") c=$(i+1);
            if ($i == "AbsRel:") r=$(i+1); if ($i == "coverage:") v=$(i+1); if ($i == "top-1:") t=$(i+1);
          }
          printf "| %s | %s | %s | %s | %s | %s | %s | %s | %s |\n", arm, step, cpu, a, b, c, r, v, t
        }' "$out/$arm/train.log"
    done
  } > "$out/curves.md"
  cat "$out/curves.md"
}

if [ "${1:-}" = "--summary" ]; then
  summarise "${2:?usage: compare_designs.sh --summary OUT_DIR}"
  exit 0
fi
build=${1:?usage: compare_designs.sh BUILD_DIR OUT_DIR [CPU_MINUTES] [options]}
out=${2:?usage: compare_designs.sh BUILD_DIR OUT_DIR [CPU_MINUTES] [options]}
minutes=${3:-45}
shift $(( $# >= 3 ? 3 : $# ))
train="$build/src/dispmvs_train"
[ -x "$train" ] || { echo "error: $train not found (build first)" >&2; exit 1; }
mkdir -p "$out"
common=(--height 192 --width 256 --sources 4 --batch 2 --steps 1000000 --lr 3e-4
        --train_widening_max 3 --seed 1 --threads 1 --scene_reuse 4
        --checkpoint_every 100 --validate_every 100 --val_scenes 8
        --max_cpu_minutes "$minutes" "$@")
"$train" --checkpoint_dir "$out/paper" --config small "${common[@]}" > "$out/paper.out" 2>&1 &
paper=$!
"$train" --checkpoint_dir "$out/v2" --config small_v2 --matching_warmup_steps 50 "${common[@]}" \
  > "$out/v2.out" 2>&1 &
v2=$!
status=0
wait "$paper" || status=$?
wait "$v2" || status=$?
[ "$status" = 0 ] || { echo "error: a run failed; see $out/paper.out, $out/v2.out" >&2; exit "$status"; }

summarise "$out"
