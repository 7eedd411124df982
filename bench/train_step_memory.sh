#!/usr/bin/env bash
# Training step time against resident memory: dispmvs_train's default (every
# freed block kept in the C heap for the next step) and --low_memory 1 (freed
# blocks above 32 MiB returned to the system, glibc's default), run
# alternately in one sitting so that both see the same machine.
#
#   bench/train_step_memory.sh BUILD_DIR OUT_DIR [options] [-- TRAIN_OPTIONS...]
#     --rounds R        alternations (default 2: default, low, default, low)
#     --steps K         training steps per run (default 5; the first, which
#                       also generates its scenes, is left out of the medians)
#     --height H --width W --sources N --batch B
#                       the step's size (default 480 x 640, 5 sources, batch 2:
#                       the shipped model's training steps)
#     --init_weights F  start from these weights (default models/dispmvs_small.safetensors)
#     -- TRAIN_OPTIONS  passed on to dispmvs_train (e.g. --precision bf16)
#
# Each run trains from scratch into OUT_DIR/<setting>-<round> (a fresh
# folder: a resumed run would skip its steps). Prints a Markdown table: per
# setting, the median over runs of the median seconds per step (wall) and
# of the CPU seconds per step that dispmvs_train logs, the system (kernel)
# CPU time per run, and the peak resident memory (the largest VmHWM seen in
# /proc while the run lasted).
set -euo pipefail

die() { echo "train_step_memory: $*" >&2; exit 1; }
usage() { sed -n '2,23p' "$0" | sed 's/^# \{0,1\}//' >&2; exit 2; }

[ $# -ge 2 ] || usage
build=$1 out=$2
shift 2
rounds=2 steps=5 height=480 width=640 sources=5 batch=2
init=$(cd "$(dirname "$0")/.." && pwd)/models/dispmvs_small.safetensors
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --rounds) rounds=$2; shift 2 ;;
    --steps) steps=$2; shift 2 ;;
    --height) height=$2; shift 2 ;;
    --width) width=$2; shift 2 ;;
    --sources) sources=$2; shift 2 ;;
    --batch) batch=$2; shift 2 ;;
    --init_weights) init=$2; shift 2 ;;
    --) shift; extra=("$@"); break ;;
    -h|--help) usage ;;
    *) die "unknown option $1 (see --help)" ;;
  esac
done
train=$build/src/dispmvs_train
[ -x "$train" ] || die "$train not found: build the project first"
[ -f "$init" ] || die "$init not found"
[[ $steps =~ ^[0-9]+$ ]] && [ "$steps" -ge 2 ] || die "--steps must be an integer >= 2, got $steps"
[[ $rounds =~ ^[0-9]+$ ]] && [ "$rounds" -ge 1 ] || die "--rounds must be an integer >= 1, got $rounds"
mkdir -p "$out"

median() { sort -g | awk '{ v[NR] = $1 } END { if (NR == 0) print "nan"; else if (NR % 2) print v[(NR + 1) / 2]; else print (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }

# Sets children_sys to the system CPU seconds of this shell's finished
# children so far: the second line of `times`, which must run in this shell
# (in a command substitution it would count the subshell's children only).
read_children_sys() {
  times > "$out/.times"
  children_sys=$(sed -n 2p "$out/.times" | awk '{ split($2, t, /[ms]/); print t[1] * 60 + t[2] }')
}

# One run: OUT/<name>/ (checkpoints, train.log), OUT/<name>.log and
# OUT/<name>.tsv: wall and CPU seconds per step after the first, then
# "sys SECONDS" and "peak KB".
run() {
  local name=$1 low=$2 dir=$out/$1
  rm -rf "$dir"
  local sys_before peak=0 kb
  read_children_sys
  sys_before=$children_sys
  "$train" --checkpoint_dir "$dir" --config small_v2 --height "$height" --width "$width" \
    --sources "$sources" --batch "$batch" --steps "$steps" --lr 1e-7 --seed 1 \
    --scene_reuse 4 --checkpoint_every 1000000 --val_scenes 1 --init_weights "$init" \
    --low_memory "$low" "${extra[@]}" > "$out/$name.log" 2>&1 &
  local pid=$!
  while kill -0 "$pid" 2> /dev/null; do
    kb=$(awk '/^VmHWM:/ { print $2 }' "/proc/$pid/status" 2> /dev/null || true)
    if [ -n "$kb" ] && [ "$kb" -gt "$peak" ]; then peak=$kb; fi
    sleep 1
  done
  wait "$pid" || die "$name failed: see $out/$name.log"
  read_children_sys
  local sys
  sys=$(awk -v a="$sys_before" -v b="$children_sys" 'BEGIN { printf "%.2f", b - a }')
  sed -n 's|^step \([0-9]*\)/.* \([0-9.]*\) s/step .*cpu \([0-9.]*\) s).*|\1 \2 \3|p' "$out/$name.log" |
    awk '$1 >= 2 { print $2 "\t" $3 }' > "$out/$name.tsv"
  [ -s "$out/$name.tsv" ] || die "$name: no step lines in $out/$name.log"
  printf 'sys\t%s\npeak\t%s\n' "$sys" "$peak" >> "$out/$name.tsv"
  echo "$name: $(grep -c '^[0-9.]' "$out/$name.tsv") steps timed, system CPU $sys s, peak $((peak / 1024)) MiB" >&2
}

for ((r = 1; r <= rounds; ++r)); do
  run "default-$r" 0
  run "low_memory-$r" 1
done

echo "Training steps, ${width}x${height}, $sources sources, batch $batch, $steps steps per run (the first left out), $rounds run(s) per setting, alternated; $(nproc) cores"
echo
echo "| setting | s/step (wall) | CPU s/step | system CPU s per run | peak resident memory |"
echo "|---|---|---|---|---|"
for setting in default low_memory; do
  per_run_wall=() per_run_cpu=() sys=() peak=()
  for ((r = 1; r <= rounds; ++r)); do
    f=$out/$setting-$r.tsv
    per_run_wall+=("$(awk -F'\t' '$1 ~ /^[0-9.]+$/ { print $1 }' "$f" | median)")
    per_run_cpu+=("$(awk -F'\t' '$1 ~ /^[0-9.]+$/ { print $2 }' "$f" | median)")
    sys+=("$(awk -F'\t' '$1 == "sys" { print $2 }' "$f")")
    peak+=("$(awk -F'\t' '$1 == "peak" { print $2 }' "$f")")
  done
  wall=$(printf '%s\n' "${per_run_wall[@]}" | median)
  cpu=$(printf '%s\n' "${per_run_cpu[@]}" | median)
  s=$(printf '%s\n' "${sys[@]}" | median)
  p=$(printf '%s\n' "${peak[@]}" | sort -n | tail -1)
  label=$setting; [ "$setting" = low_memory ] && label="--low_memory 1"
  printf '| %s | %.2f | %.2f | %.1f | %d MiB |\n' "$label" "$wall" "$cpu" "$s" $((p / 1024))
done
