#!/usr/bin/env bash
# Dry run of bench/gpu_bench.sh on the CPU at a tiny size (the ctest
# bench_gpu_script_dry_run): the script's steps run here as on a device.
#   gpu_bench_dry_run_test.sh SCRIPT BUILD_DIR WORK_DIR
set -euo pipefail
script=$1 build=$2 work=$3
rm -rf "$work" && mkdir -p "$work"
fail() { echo "FAIL: $*" >&2; exit 1; }
"$script" --device cpu --sizes 64x48,96x64 --reps 1 --warmup 0 --build "$build" --out "$work/out" \
  --work "$work/scratch" > "$work/run.out" 2>&1 || { cat "$work/run.out"; fail "the run"; }
cat "$work/run.out"
md=$work/out/gpu_bench.md
[ -s "$md" ] || fail "no gpu_bench.md"
# One table row per configuration, precision and size.
for config in small_v2 small paper_v2 paper; do
  for precision in fp32 bf16; do
    for size in 64x48 96x64; do
      grep -q "^| $config | $precision | [0-9.]*M | [0-9]*+[0-9]* | $size | " "$md" ||
        fail "no row for $config in $precision at $size"
    done
  done
done
# The refinement's two tables: small_v2 in fp32 at the first size, with the
# refinement's share of the time.
[ "$(grep -c "^With the photometric refinement" "$md")" = 2 ] || fail "no refinement tables"
[ "$(grep -c "^| small_v2 | fp32 | [0-9.]*M | [0-9]*+[0-9]* | 64x48 | " "$md")" = 3 ] ||
  fail "no refinement rows for small_v2 in fp32 at 64x48"
# The refinement took time in those rows: their 'refine' share (the 16th
# '|' field) is not 0.
sed -n '/^With the photometric refinement/,$p' "$md" |
  awk -F'|' '/^\| small_v2 \| fp32 / { rows++; if ($16 + 0 > 0) timed++ } END { exit !(rows == 2 && timed == 2) }' ||
  fail "the refinement rows show no refine time"
echo "PASS"
