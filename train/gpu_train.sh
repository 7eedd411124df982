#!/usr/bin/env bash
# Fine-tune the shipped weights on a GPU machine that has a CUDA PyTorch and
# nothing else (no Debian -dev packages, no network), within a fixed lease:
#
#   1. builds the LibTorch-only targets (model/, synth/, train/) against that
#      PyTorch's LibTorch (skipped when the build folder is already built);
#   2. converts photographs for photo textures to PPM, which every build reads
#      (by default the photos of the machine's scikit-image data folder, never
#      motorcycle_*, which bench/motorcycle_check.sh evaluates on);
#   3. times a few steps (a probe in a scratch folder), then sizes the run to
#      --minutes: the steps that fit, a learning-rate warm-up (the optimiser's
#      moments start empty), 4 halvings of the rate over the run and 8 kept
#      checkpoints; a rerun on the same machine resumes the checkpoint folder;
#   4. trains from --init (the shipped weights) with the shipped weights'
#      objective (log-depth loss, flow loss 0.3, 1, 2 and N sources mixed;
#      models/README.md, stage 28), scenes generated on the device, and any
#      trainer options after `--` (e.g. -- --jpeg_quality 40,95);
#   5. scores the kept checkpoints of the run's second half on the selection
#      set (train/score_checkpoints.sh) and keeps the best;
#   6. evaluates it and the starting weights on the 20 validation scenes
#      (640x512, N = 5, hint widened x = 1, 3, 10 and none);
#   7. leaves in --out (default $OUT, else out/gpu_train): the chosen weights,
#      the training log, the selection table, both validation tables and
#      summary.md (the commands and numbers to paste into models/README.md).
#      At most 8 files, each under 16 MiB, as the device tool brings back.
#
# On the device (10 minutes per command, 15 per loan, start-up included):
#   call 1:  train/gpu_train.sh --build_only          (a few minutes)
#   call 2:  train/gpu_train.sh --minutes 6           (probe + training; the
#            selection and evaluation add about 2-3 minutes)
# One call with a shorter --minutes also works: the build is skipped when done.
# Here, on a CPU, the same script runs at a tiny size as the ctest
# train_gpu_script_dry_run (train/CMakeLists.txt), so that a device's lent
# minutes go to training, not debugging.
set -euo pipefail

usage() {
  sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'
  cat <<'EOF'
Options (default):
  --minutes M              wall-clock minutes of the probe and the training (6)
  --height H --width W     training image size (480 640: the CPU stages' size)
  --batch B                samples per step (8)
  --sources N              source views per training sample (5)
  --lr LR                  peak learning rate, after the warm-up; it halves 4
                           times over the run (1e-4)
  --warmup K               learning-rate warm-up steps, at most a tenth of the
                           run (100)
  --seed S                 run seed (derived from --init's checksum, so each new
                           set of weights trains on new scenes)
  --init FILE              starting weights (models/dispmvs_small.safetensors)
  --config NAME            network config, must fit --init (small_v2)
  --device D               cuda | cuda:I | cpu (cuda)
  --photos DIR             photographs for textures (the scikit-image data folder
                           found by python3; none if there is none)
  --val_scenes K           evaluation scenes (20)
  --eval_height H --eval_width W   evaluation size (512 640)
  --build DIR              build folder (build-gpu)
  --out DIR                results ($OUT, else out/gpu_train)
  --work DIR               checkpoints and converted photos (BUILD/gpu_train: kept
                           between device calls, like the build)
  -- OPTIONS               the rest goes to dispmvs_train as it is (generator
                           knobs such as --jpeg_quality, --specular_probability,
                           --photometry); the objective's options come first, so
                           a later --depth_loss or --source_counts here wins
  --build_only             configure and build, then stop
  --configure_only         configure the build folder, then stop (a check of the
                           LibTorch-only CMake flavour)
EOF
}

root=$(cd "$(dirname "$0")/.." && pwd)
minutes=6 height=480 width=640 batch=8 sources=5 lr=1e-4 warmup=100 seed=""
init="$root/models/dispmvs_small.safetensors" config=small_v2 device=cuda photos=""
val_scenes=20 eval_height=512 eval_width=640 build="$root/build-gpu"
out=${OUT:-$root/out/gpu_train} work="" build_only=0 configure_only=0
extra_train_options=()
while [ $# -gt 0 ]; do
  case "$1" in
    --minutes) minutes=$2; shift 2 ;;
    --height) height=$2; shift 2 ;;
    --width) width=$2; shift 2 ;;
    --batch) batch=$2; shift 2 ;;
    --sources) sources=$2; shift 2 ;;
    --lr) lr=$2; shift 2 ;;
    --warmup) warmup=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --init) init=$2; shift 2 ;;
    --config) config=$2; shift 2 ;;
    --device) device=$2; shift 2 ;;
    --photos) photos=$2; shift 2 ;;
    --val_scenes) val_scenes=$2; shift 2 ;;
    --eval_height) eval_height=$2; shift 2 ;;
    --eval_width) eval_width=$2; shift 2 ;;
    --build) build=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    --build_only) build_only=1; shift ;;
    --configure_only) configure_only=1; shift ;;
    -h|--help) usage; exit 0 ;;
    --) shift; extra_train_options=("$@"); break ;;
    *) echo "error: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done

log() { echo "[gpu_train $(date -u +%H:%M:%S)] $*"; }
[ -n "$work" ] || work="$build/gpu_train"
mkdir -p "$out" "$work"

# --- 1. Build (cmake/build_torch_only.sh).
source "$root/cmake/build_torch_only.sh"
if [ "$configure_only" = 1 ]; then
  build_torch_only "$root" "$build" "$work" 1
  log "configured $build"
  exit 0
fi
# dispmvs_bench too, so that bench/gpu_bench.sh finds it built.
build_torch_only "$root" "$build" "$work" 0 dispmvs_train dispmvs_bench
train="$build/src/dispmvs_train"
[ -x "$train" ] || { echo "error: $train was not built" >&2; exit 1; }
if [ "$build_only" = 1 ]; then
  log "built $train"
  exit 0
fi
[ -f "$init" ] || { echo "error: --init $init: no such file" >&2; exit 1; }
[ -n "$seed" ] || seed=$(cksum < "$init" | cut -d' ' -f1)

# --- 2. Photos as PPM (the LibTorch-only build decodes no other format).
if [ -z "$photos" ]; then
  photos=$(python3 -c 'import os, skimage.data as d; print(os.path.dirname(d.__file__))' 2>/dev/null || true)
fi
photo_options=()
if [ -n "$photos" ] && [ -d "$photos" ]; then
  rm -rf "$work/photos" && mkdir -p "$work/photos"
  for f in "$photos"/*; do
    name=$(basename "$f")
    case "$name" in
      motorcycle*) continue ;;  # evaluation data (bench/motorcycle_check.sh)
      *.ppm|*.pgm|*.PPM|*.PGM) cp "$f" "$work/photos/" ;;
      *.png|*.jpg|*.jpeg|*.bmp|*.tif|*.tiff|*.PNG|*.JPG|*.JPEG)
        python3 - "$f" "$work/photos/${name%.*}.ppm" <<'EOF' 2>/dev/null || true
import sys
try:
    from PIL import Image
    Image.open(sys.argv[1]).convert("RGB").save(sys.argv[2])
except ImportError:
    import cv2  # opencv-python, where Pillow is missing
    image = cv2.imread(sys.argv[1], cv2.IMREAD_COLOR)
    if image is None or not cv2.imwrite(sys.argv[2], image):
        sys.exit(1)
EOF
        ;;
    esac
  done
  count=$(find "$work/photos" -maxdepth 1 -name '*.p?m' | wc -l)
  if [ "$count" -gt 0 ]; then
    log "$count photos from $photos"
    photo_options=(--texture_dir "$work/photos" --photo_probability 0.3)
  else
    log "no usable photos in $photos: procedural textures only"
  fi
else
  log "no photo folder: procedural textures only"
fi

# --- 3. Size the run. No step time on this device was ever measured here, so
# a short probe (in a scratch folder, thrown away) times a few steps first;
# then the run's steps are what fits the minutes left, and the learning rate
# halves 4 times over them (a warm restart that anneals, as the CPU stages that
# shipped did) while 8 checkpoints are kept for the selection in step 4. A
# rerun on the same machine reuses the schedule, so the checkpoint folder resumes.
budget_start=$(date +%s)
seconds_left() { awk -v m="$minutes" -v t0="$budget_start" -v now="$(date +%s)" 'BEGIN { print int(60 * m - (now - t0)) }'; }
# The shipped weights' objective (stages 24-28): the L1 of log depth, the
# flow loss at every fine iteration, and steps with 1, 2 and N sources mixed
# (two-view workspaces are common). Without it a run would train them
# towards the paper's inverse-depth loss instead.
if (( sources >= 2 )); then source_counts="1,2,$sources,$sources"; else source_counts=1; fi
objective=(--depth_loss log --source_counts "$source_counts")
[[ "$config" != *_v2 ]] || objective+=(--flow_loss_weight 0.3)  # the paper's design has no flow loss
common=(--config "$config" --device "$device" --height "$height" --width "$width" --sources "$sources"
        --batch "$batch" --lr "$lr" --train_widening_max 3 --seed "$seed" --scene_reuse 4
        --validate_every 0 --init_weights "$init" "${photo_options[@]}" "${objective[@]}"
        "${extra_train_options[@]}")
schedule=$work/schedule.env
if [ -f "$schedule" ]; then
  source "$schedule"
  log "resuming the schedule of $schedule"
else
  probe_steps=6
  rm -rf "$work/probe"
  "$train" --checkpoint_dir "$work/probe" "${common[@]}" --steps "$probe_steps" \
    --checkpoint_every "$probe_steps" --val_scenes 1 --max_minutes 2 > "$work/probe.log" 2>&1 ||
    { cat "$work/probe.log"; echo "error: the timing probe failed" >&2; exit 1; }
  rm -rf "$work/probe"
  # The mean s/step after the first two steps (start-up, kernel autotuning).
  step_seconds=$(awk '/^step / { if (++n > 2) for (i = 2; i <= NF; i++) if ($i == "s/step") { sum += $(i - 1); k++ } }
                      END { printf "%.4f", (k && sum > 0) ? sum / k : 0.01 }' "$work/probe.log")
  # 0.85: checkpoints and the end-of-run validation come on top of the steps.
  total_steps=$(awk -v left="$(seconds_left)" -v s="$step_seconds" 'BEGIN { n = int(0.85 * left / s); print n < 16 ? 16 : n }')
  halve_every=$(( (total_steps + 3) / 4 ))
  keep_every=$(( total_steps / 8 ))
  (( warmup <= total_steps / 10 )) || warmup=$(( total_steps / 10 ))
  printf 'step_seconds=%s\ntotal_steps=%s\nhalve_every=%s\nkeep_every=%s\nwarmup=%s\n' \
    "$step_seconds" "$total_steps" "$halve_every" "$keep_every" "$warmup" > "$schedule.tmp"
  mv "$schedule.tmp" "$schedule"
fi
log "schedule: $step_seconds s/step probed, $total_steps steps, lr $lr after $warmup warm-up steps, halved every $halve_every, weights kept every $keep_every"

# --- 4. Train (resumes from $work/ckpt when rerun on the same machine).
train_minutes=$(awk -v s="$(seconds_left)" 'BEGIN { m = s / 60; printf "%.2f", m < 0.5 ? 0.5 : m }')
command=("$train" --checkpoint_dir "$work/ckpt" "${common[@]}" --steps "$total_steps"
         --lr_warmup_steps "$warmup" --lr_halve_every "$halve_every" --checkpoint_every "$keep_every"
         --keep_weights_every "$keep_every" --val_scenes "$(( val_scenes < 8 ? val_scenes : 8 ))"
         --max_minutes "$train_minutes")
log "training: ${command[*]}"
# Every 50th step line and all other lines on the terminal, everything in the log.
set +o pipefail
"${command[@]}" 2>&1 | tee "$out/train.log" | awk '!/^step / || NR % 50 == 1'
status=${PIPESTATUS[0]}
set -o pipefail
[ "$status" = 0 ] || { echo "error: training failed with status $status (see $out/train.log)" >&2; exit 1; }

# --- 5. Choose the weights: the kept weights of the run's second half and its
# last checkpoint, scored on the selection set (train/score_checkpoints.sh:
# generated scenes that are not the validation table's), the best < 2 % wins.
# One checkpoint is a noisy choice; the CPU stages chose this way too.
selection=$work/selection
rm -rf "$selection" && mkdir -p "$selection"
latest=$(ls "$work/ckpt"/checkpoint-*.safetensors 2>/dev/null | grep -v '\.optim\.' | sort | tail -1 || true)
for f in "$work/ckpt"/weights-*.safetensors $latest; do
  [ -e "$f" ] || continue
  name=$(basename "$f" .safetensors)
  (( 10#${name##*-} * 2 >= total_steps )) || [ "$f" = "$latest" ] || continue
  ln -s "$f" "$selection/"
done
log "scoring $(ls "$selection" | wc -l) checkpoints on the selection set"
"$root/train/score_checkpoints.sh" "$build" "$selection" --device "$device" --precision fp32 \
  --height "$eval_height" --width "$eval_width" --val_scenes "$val_scenes" > "$out/selection.md" 2> "$work/selection.log" ||
  { cat "$work/selection.log"; echo "error: scoring the checkpoints failed" >&2; exit 1; }
# score_checkpoints.sh marks the best < 2 % in bold: its choice is the one taken.
best_step=$(sed -n 's/^| \([0-9]*\) | [0-9.]* | \*\*.*/\1/p' "$out/selection.md" | head -1)
[ -n "$best_step" ] || { cat "$out/selection.md"; echo "error: no best row in the selection table" >&2; exit 1; }
best=""
for f in "$selection"/*.safetensors; do
  name=$(basename "$f" .safetensors)
  (( 10#${name##*-} == best_step )) && { best=$f; break; }
done
[ -n "$best" ] || { echo "error: no checkpoint of step $best_step in $selection" >&2; exit 1; }
weights="$out/dispmvs_$config.safetensors"
cp "$best" "$weights"
log "chose step $best_step ($(basename "$(readlink -f "$best")"))"

# --- 6. Evaluate both the chosen and the starting weights on the same scenes.
widenings=1,3,10,none
[[ "$config" == *_v2 ]] || widenings=1,3,10
evaluate() {
  "$train" --evaluate "$1" --device "$device" --height "$eval_height" --width "$eval_width" \
    --sources 5 --val_scenes "$val_scenes" --widenings "$widenings" > "$2" 2>&1 ||
    { cat "$2"; echo "error: evaluation of $1 failed" >&2; exit 1; }
}
log "evaluating the new weights"
evaluate "$weights" "$out/eval_new.txt"
log "evaluating the starting weights"
evaluate "$init" "$out/eval_init.txt"

# --- 7. Summary.
steps=$(grep -c '^step ' "$out/train.log" || true)
{
  echo "# GPU fine-tuning, $(date -u +%Y-%m-%d)"
  echo
  echo "Device: $device ($(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1 || echo n/a))."
  echo "Steps this run: $steps of $total_steps ($step_seconds s/step probed); $minutes min in all."
  echo "Chosen on the selection set: step $best_step."
  echo
  echo '```sh'
  echo "${command[*]}" | sed "s|$root/||g; s|$work|WORK|g"
  echo '```'
  echo
  echo "## Selection set (< 2 % at x = 1, $val_scenes scenes)"
  cat "$out/selection.md"
  echo
  echo "## New weights (step $best_step)"
  echo '```'; cat "$out/eval_new.txt"; echo '```'
  echo
  echo "## Starting weights"
  echo '```'; cat "$out/eval_init.txt"; echo '```'
} > "$out/summary.md"
log "done: $weights, $out/summary.md"
