#!/usr/bin/env bash
# Dry run of train/gpu_train.sh on the CPU at a tiny size (the ctest
# train_gpu_script_dry_run): every step of the GPU script runs here as it will
# on a device machine, so that a lent GPU's minutes go to training.
#   gpu_train_dry_run_test.sh SCRIPT BUILD_DIR WORK_DIR
set -euo pipefail
script=$1 build=$2 work=$3
rm -rf "$work" && mkdir -p "$work/photos"
fail() { echo "FAIL: $*" >&2; exit 1; }

# The LibTorch-only CMake flavour configures (a GPU machine builds it).
"$script" --configure_only --build "$work/torch_only" --out "$work/out" --work "$work/scratch" \
  > "$work/configure.out" 2>&1 || { cat "$work/configure.out" "$work/scratch/configure.log"; fail "configure"; }
grep -q "full build = OFF" "$work/scratch/configure.log" || fail "not the LibTorch-only flavour"

# Two photos as PPM: a 32x24 colour ramp, and a motorcycle_* one (evaluation
# data: it must be left out).
ramp() {
  printf 'P6\n32 24\n255\n'
  for ((y = 0; y < 24; y++)); do for ((x = 0; x < 32; x++)); do printf "\\$(printf %o $((x * 8)))\\$(printf %o $((y * 10)))\\100"; done; done
}
ramp > "$work/photos/ramp.ppm"
cp "$work/photos/ramp.ppm" "$work/photos/motorcycle_left.ppm"

"$script" --device cpu --minutes 1 --height 64 --width 96 --batch 1 --val_scenes 1 \
  --eval_height 64 --eval_width 96 --photos "$work/photos" --build "$build" \
  --out "$work/out" --work "$work/scratch" -- --jpeg_quality 60,90 > "$work/run.out" 2>&1 ||
  { cat "$work/run.out"; fail "the run"; }
cat "$work/run.out"

out=$work/out
grep -q "1 photos from" "$work/run.out" || fail "photos: motorcycle_* not left out, or the ramp not used"
grep -q -- "--texture_dir" "$out/train.log" "$out/summary.md" || fail "photos not passed to training"
# The shipped weights' objective, and the options after -- on top of it.
for option in "--depth_loss log" "--flow_loss_weight 0.3" "--source_counts 1,2,5,5" "--jpeg_quality 60,90"; do
  grep -q -- "$option" "$out/summary.md" || fail "summary.md: training without $option"
done
grep -q "JPEG compression: quality 60-90" "$out/train.log" || fail "the option after -- did not reach the trainer"
# The probe sized the run: the schedule line names the steps, and training
# ran that schedule (its step lines count to the probed total, with the rate
# halving every quarter) or stopped at the minutes left.
schedule=$(grep -o "schedule: .*" "$work/run.out") || fail "no schedule line"
total=$(sed 's/.* s\/step probed, \([0-9]*\) steps,.*/\1/' <<< "$schedule")
halve=$(sed 's/.*halved every \([0-9]*\),.*/\1/' <<< "$schedule")
[[ "$total" =~ ^[0-9]+$ && "$total" -ge 16 ]] || fail "schedule: $schedule"
[ "$halve" = $(( (total + 3) / 4 )) ] || fail "the rate does not halve every quarter of the run: $schedule"
grep -q "^step [0-9]*/$total " "$out/train.log" || fail "training did not run the probed schedule"
grep -q -- "--lr_halve_every $halve" "$out/summary.md" || fail "summary.md lacks the halving"
[ ! -e "$work/scratch/probe" ] || fail "the probe's scratch folder was left behind"
# The selection: every kept checkpoint of the run's second half and the last
# one, each scored once (how many there are depends on how many steps this
# machine managed in the minute), and the chosen one is the best < 2 %.
expected=$( (for f in "$work/scratch/ckpt"/weights-*.safetensors; do
               [ -e "$f" ] || continue
               step=$(basename "$f" .safetensors); step=$((10#${step##*-}))
               (( step * 2 >= total )) && echo "$step"
             done
             last=$(ls "$work/scratch/ckpt"/checkpoint-*.safetensors | grep -v '\.optim\.' | sort | tail -1)
             last=$(basename "$last" .safetensors); echo $((10#${last##*-}))) | sort -n -u | tr '\n' ' ')
scored=$(grep -o '^| [0-9]* ' "$out/selection.md" | tr -d '| ' | sort -n -u | tr '\n' ' ')
[ -n "$scored" ] && [ "$scored" = "$expected" ] ||
  fail "selection.md scored steps '$scored', not the second half's kept ones and the last: '$expected'"
chosen=$(grep -o "chose step [0-9]*" "$work/run.out" | grep -o '[0-9]*$') || fail "no chosen step"
# Independently of the table's bold mark: the chosen row holds the column's maximum.
best=$(awk -F' *\\| *' '/^\| [0-9]/ { v = $4; gsub(/\*/, "", v); if (v + 0 > max + 0) max = v } END { print max }' "$out/selection.md")
chosen_value=$(awk -F' *\\| *' -v s="$chosen" '$2 == s { v = $4; gsub(/\*/, "", v); print v }' "$out/selection.md")
[ -n "$chosen_value" ] && awk -v a="$chosen_value" -v b="$best" 'BEGIN { exit !(a + 0 == b + 0) }' ||
  fail "step $chosen (< 2 % '$chosen_value') is not the best of selection.md ($best)"
grep -q "^## New weights (step $chosen)" "$out/summary.md" || fail "summary.md does not name step $chosen"
[ -s "$out/dispmvs_small_v2.safetensors" ] || fail "no weights"
for table in eval_new eval_init; do
  for x in 1.000 3.000 10.00 none; do
    grep -q "^x=$x  <1%: " "$out/$table.txt" || fail "$table.txt lacks the row x=$x"
  done
done
grep -q "^## New weights" "$out/summary.md" && grep -q "^## Starting weights" "$out/summary.md" || fail "summary.md"
# The new weights differ from the starting ones (they trained) and load.
! cmp -s "$out/dispmvs_small_v2.safetensors" "$(dirname "$script")/../models/dispmvs_small.safetensors" ||
  fail "the weights did not change"
[ "$(find "$out" -type f | wc -l)" -le 8 ] || fail "more than 8 files in the output (the device brings back 8)"
echo "PASS"
