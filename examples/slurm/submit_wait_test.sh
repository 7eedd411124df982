#!/bin/bash
# submit.sh --wait against stand-in sbatch / scontrol / dispmvs_colmap
# programs (no cluster): the fusion job's final state decides the exit
# status, and a controller that reports nothing makes it give up after
# --give_up_after seconds instead of waiting forever. Bad options exit 2.
#
#   submit_wait_test.sh WORK_DIR
set -euo pipefail
[ $# -eq 1 ] || { echo "usage: $0 WORK_DIR" >&2; exit 2; }
here=$(cd "$(dirname "$0")" && pwd)
work=$1
rm -rf "$work"
mkdir -p "$work/bin" "$work/ws/images" "$work/ws/sparse"
work=$(cd "$work" && pwd)

# sbatch prints a job id; scontrol prints the line in $work/scontrol_says,
# or fails like an unreachable controller when that file is empty.
cat > "$work/bin/sbatch" <<'SH'
#!/bin/bash
echo 4242
SH
cat > "$work/bin/scontrol" <<SH
#!/bin/bash
line=\$(cat "$work/scontrol_says")
[ -n "\$line" ] || { echo "slurm_load_jobs error: Unable to contact slurm controller" >&2; exit 1; }
echo "\$line"
SH
cat > "$work/bin/dispmvs_colmap" <<'SH'
#!/bin/bash
echo "plan: ok"
SH
chmod +x "$work/bin/"*

failures=0
expect() {  # expect NAME STATUS NEEDLE SCONTROL_LINE [submit.sh options]
  local name=$1 want=$2 needle=$3 says=$4
  shift 4
  printf '%s\n' "$says" > "$work/scontrol_says"
  local status=0
  PATH="$work/bin:$PATH" "$here/submit.sh" --workspace_path "$work/ws" --shards 2 \
    --program "$work/bin/dispmvs_colmap" "$@" > "$work/$name.out" 2>&1 || status=$?
  if [ "$status" != "$want" ] || ! grep -q -- "$needle" "$work/$name.out"; then
    echo "FAIL $name: exit $status (want $want), output:" >&2
    cat "$work/$name.out" >&2
    failures=$((failures + 1))
  else
    echo "ok   $name: exit $status, '$needle'"
  fi
}

expect completed 0 "job 4242 completed" "JobId=4242 JobState=COMPLETED Reason=None" --wait
expect cancelled 1 "ended CANCELLED (reason: DependencyNeverSatisfied)" \
  "JobId=4242 JobState=CANCELLED Reason=DependencyNeverSatisfied" --wait
start=$SECONDS
expect silent 1 "has not reported job 4242 for 3 s" "" --wait --give_up_after 3
elapsed=$((SECONDS - start))
if [ "$elapsed" -gt 20 ]; then
  echo "FAIL silent: gave up after $elapsed s, not about 3" >&2
  failures=$((failures + 1))
fi
expect no_wait 0 "fusion: job 4242" "" # without --wait it never asks scontrol
expect bad_limit 2 "must be positive integers" "" --wait --give_up_after soon

if [ "$failures" -gt 0 ]; then
  echo "$failures case(s) failed" >&2
  exit 1
fi
echo "all cases passed"
