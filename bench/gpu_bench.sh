#!/usr/bin/env bash
# Network speed and memory on a GPU machine that has a CUDA PyTorch and
# nothing else: builds the LibTorch-only targets against that PyTorch's
# LibTorch (cmake/build_torch_only.sh; skipped when the build folder is
# already built, e.g. by train/gpu_train.sh --build_only) and runs
# dispmvs_bench --device cuda at 640x512 and 1600x1152, N = 5, for model v2
# and the paper's design in both sizes, with the GRU update in fp32 and in
# bf16 (--precision; dispmvs_colmap's auto keeps fp32 on CUDA until this
# table says otherwise), then model v2 with the photometric refinement
# (--refinement ncc, without and with two rounds of propagation) at the
# first size. Leaves gpu_bench.md (the command, the
# GPU's name and the table for docs/benchmarks.md) in --out ($OUT, else
# out/gpu_bench).
#
# On the device: bench/gpu_bench.sh                 (after a training call, if
# one is due; a minute or two once built). Here the same script runs on the
# CPU at a tiny size as the ctest bench_gpu_script_dry_run.
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
device=cuda sizes=640x512,1600x1152 configs=small_v2,small,paper_v2,paper precisions=fp32,bf16 sources=5 reps=5 warmup=2
build="$root/build-gpu" out=${OUT:-$root/out/gpu_bench} work=""
while [ $# -gt 0 ]; do
  case "$1" in
    --device) device=$2; shift 2 ;;
    --sizes) sizes=$2; shift 2 ;;
    --config) configs=$2; shift 2 ;;
    --precision) precisions=$2; shift 2 ;;
    --sources) sources=$2; shift 2 ;;
    --reps) reps=$2; shift 2 ;;
    --warmup) warmup=$2; shift 2 ;;
    --build) build=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'
      echo "Options: --device D (cuda) --sizes WxH,... ($sizes) --config LIST ($configs) --precision LIST ($precisions)"
      echo "         --sources N (5) --reps N (5) --warmup N (2) --build DIR (build-gpu) --out DIR --work DIR"
      exit 0 ;;
    *) echo "error: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
[ -n "$work" ] || work="$build/gpu_bench"  # logs and the raw table
mkdir -p "$out" "$work"
source "$root/cmake/build_torch_only.sh"
build_torch_only "$root" "$build" "$work" 0 dispmvs_bench
bench="$build/bench/dispmvs_bench"
command=("$bench" --device "$device" --sizes "$sizes" --config "$configs" --precision "$precisions" --sources "$sources"
         --reps "$reps" --warmup "$warmup")
echo "running: ${command[*]}"
"${command[@]}" > "$work/table.txt" 2> "$work/bench.err" || { cat "$work/bench.err" "$work/table.txt"; exit 1; }
# The photometric refinement after the network (dispmvs_colmap's default
# search, then with two rounds of propagation) at the first size: its
# LibTorch path on the device, timed in the 'refine' column.
refine_commands=()
for rounds in 0 2; do
  refine_command=("$bench" --device "$device" --sizes "${sizes%%,*}" --config small_v2 --precision fp32
                  --sources "$sources" --reps "$reps" --warmup "$warmup" --refinement ncc
                  --refine_propagation_rounds "$rounds")
  refine_commands+=("${refine_command[*]}")
  echo "running: ${refine_command[*]}"
  "${refine_command[@]}" > "$work/refine_$rounds.txt" 2>> "$work/bench.err" ||
    { cat "$work/bench.err" "$work/refine_$rounds.txt"; exit 1; }
done
{
  echo "# dispmvs_bench on $(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1 || echo "$device"), $(date -u +%Y-%m-%d)"
  echo
  echo '```sh'
  echo "bench/gpu_bench.sh   # runs: ${command[*]}" | sed "s|$build/||"
  for refine_command in "${refine_commands[@]}"; do
    echo "#   then: $refine_command" | sed "s|$build/||"
  done
  echo '```'
  echo
  cat "$work/table.txt"
  for rounds in 0 2; do
    echo
    echo "With the photometric refinement (--refinement ncc --refine_propagation_rounds $rounds):"
    echo
    cat "$work/refine_$rounds.txt"
  done
} > "$out/gpu_bench.md"
cat "$out/gpu_bench.md"
