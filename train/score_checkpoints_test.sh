#!/usr/bin/env bash
# Test of train/score_checkpoints.sh (the ctest train_score_checkpoints): a
# tiny run keeps the weights of steps 1 and 2 and its checkpoint of step 3;
# the script scores all three once, marks the best, and scores nothing again
# when re-run.
#   score_checkpoints_test.sh SCRIPT BUILD_DIR WORK_DIR
set -euo pipefail
script=$1 build=$2 work=$3
root=$(cd "$(dirname "$0")/.." && pwd)
fail() { echo "FAIL: $*" >&2; exit 1; }
rm -rf "$work" && mkdir -p "$work"
run=$work/run
"$build/src/dispmvs_train" --checkpoint_dir "$run" --config small_v2 --height 48 --width 64 \
  --sources 2 --steps 3 --checkpoint_every 1 --keep_weights_every 1 --val_scenes 0 --threads 1 \
  > "$work/train.out" 2>&1 || { cat "$work/train.out"; fail "training"; }
ls "$run"
small=(--height 48 --width 64 --sources 2 --val_scenes 1 --threads 1)

"$script" "$build" "$run" "${small[@]}" > "$work/table.md" 2> "$work/first.err" ||
  { cat "$work/first.err"; fail "first scoring"; }
cat "$work/table.md"
[ "$(grep -c '^scored step' "$work/first.err")" = 3 ] || fail "not three files scored"
for step in 1 2 3; do
  grep -Eq "^\| $step \| [0-9.]+ \| (\*\*)?[0-9.]+(\*\*)? \| [0-9.]+ \|$" "$work/table.md" || fail "no row for step $step"
done
[ "$(grep -c '\*\*' "$work/table.md")" = 1 ] || fail "not exactly one best row"
# The best row holds the largest <2 %.
best=$(grep '\*\*' "$work/table.md" | sed 's/.*\*\*\([0-9.]*\)\*\*.*/\1/')
max=$(grep -E '^\| [0-9]+ ' "$work/table.md" | awk -F'|' '{ gsub(/[* ]/, "", $4); if ($4 + 0 > m + 0) m = $4 } END { print m }')
[ "$best" = "$max" ] || fail "best $best is not the maximum $max"

# The score of step 2 is the one --evaluate gives for its weights.
direct=$("$build/src/dispmvs_train" --evaluate "$run/weights-000000002.safetensors" --height 512 --width 640 \
  --sources 5 --val_scenes 20 --val_seed_base 2000000000 --widenings 1 --precision bf16 --threads 2 \
  "${small[@]}" | grep '^x=1' | sed 's/.*<2%: \([0-9.]*\).*/\1/')
grep -Eq "^\| 2 \| [0-9.]+ \| (\*\*)?$direct(\*\*)? \|" "$work/table.md" || fail "step 2's <2 % is not $direct"

# Re-run: nothing is evaluated again, and the table is the same.
"$script" "$build" "$run" "${small[@]}" > "$work/table2.md" 2> "$work/second.err" || fail "second scoring"
! grep -q '^scored step' "$work/second.err" || fail "re-run evaluated again"
cmp -s "$work/table.md" "$work/table2.md" || fail "re-run gave another table"
! ls "$run"/.scoring-* > /dev/null 2>&1 || fail "temporary copies left behind"

# With real pairs (DISPMVS_REALVAL_DIR; here a stand-in: the generated example
# as the one "mvs_001" pair, so that no test reads the real set): a column of
# their mean <2 %, each equal to what bench/realval_eval.sh gives for those
# weights, and the best row is the best mean of the two <2 % columns.
realval=$work/realval
"$build/examples/dispmvs_make_example" --output_path "$realval/mvs_001" \
  --ground_truth_sampling colmap-dense > /dev/null
DISPMVS_REALVAL_DIR=$realval "$script" "$build" "$run" "${small[@]}" > "$work/table3.md" \
  2> "$work/third.err" || { cat "$work/third.err"; fail "scoring with realval"; }
cat "$work/table3.md"
[ "$(grep -c 'on .*realval: ' "$work/third.err")" = 3 ] || fail "not three files run on realval"
! grep -q '^scored step [0-9]*$' "$work/third.err" || fail "the generated scenes were evaluated again"
grep -q '^| step | <1 % | <2 % | AbsRel | realval mvs <2 % |$' "$work/table3.md" || fail "no realval column"
"$root/bench/realval_eval.sh" "$build" "$realval" "$work/direct" --pairs 'mvs_*' -- \
  --model_path "$run/weights-000000002.safetensors" --mode photometric --threads 2 > /dev/null
direct_real=$(awk -F'\t' '$2 == "dispmvs.photometric" { printf "%.4f", $4 }' "$work/direct/summary.tsv")
grep -Eq "^\| 2 \| .* \| $direct_real \|$" "$work/table3.md" || fail "step 2's realval score is not $direct_real"
best=$(grep '\*\*' "$work/table3.md" | sed 's/^| \([0-9]*\) .*/\1/')
expected=$(grep -E '^\| [0-9]+ ' "$work/table3.md" | awk -F'|' '{ gsub(/[* ]/, "", $4); gsub(/ /, "", $6)
  m = ($4 + $6) / 2; if (NR == 1 || m > b) { b = m; s = $2 } } END { gsub(/ /, "", s); print s }')
[ "$best" = "$expected" ] || fail "best step $best is not the best mean, step $expected"
# Again: nothing is run again.
DISPMVS_REALVAL_DIR=$realval "$script" "$build" "$run" "${small[@]}" > "$work/table4.md" 2> "$work/fourth.err"
! grep -q 'scored step' "$work/fourth.err" || fail "re-run with realval evaluated again"
cmp -s "$work/table3.md" "$work/table4.md" || fail "re-run with realval gave another table"
# A realval folder without pairs is refused.
if DISPMVS_REALVAL_DIR=$work/empty_realval "$script" "$build" "$run" > /dev/null 2> "$work/rv.err"; then
  fail "realval folder without pairs accepted"
fi
grep -q "holds no mvs_\* workspace" "$work/rv.err" || fail "realval without pairs: no clear message"

# Bad input: a folder without weights.
mkdir -p "$work/empty"
if "$script" "$build" "$work/empty" > /dev/null 2> "$work/empty.err"; then fail "empty folder accepted"; fi
grep -q "no weights" "$work/empty.err" || fail "empty folder: no clear message"
echo "PASS"
