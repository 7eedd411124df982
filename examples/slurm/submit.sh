#!/bin/bash
# Runs dispmvs_colmap on a Slurm cluster: a job array of photometric shards
# (photometric_array.sbatch), then one fusion job (fuse.sbatch) that starts
# only when every shard has succeeded.
#
#   submit.sh --workspace_path WS --shards N [--cpus_per_task C]
#             [--log_dir DIR] [--program PATH] [--wait [--give_up_after S]]
#             [-- dispmvs_colmap options]
#
# Options after `--` go to both jobs (e.g. --max_image_size 1600 --model_path F).
# Partition, account, time limit and the like come from sbatch's own
# environment variables (SBATCH_PARTITION, SBATCH_ACCOUNT, SBATCH_TIMELIMIT).
# Prints the two job ids. With --wait it returns when the fusion job ends:
# 0 when it completed, 1 when it failed or was cancelled (Slurm cancels it
# when a shard fails), or when scontrol has reported no state for the job
# for S seconds (default 600: the controller is down, or forgot the job).
# Submitting again resumes: finished views are kept.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
usage() {
  sed -n '2,17p' "$0" | sed 's/^# \{0,1\}//' >&2
  exit 2
}
workspace="" shards="" cpus=4 log_dir="" program="" wait=0 give_up_after=600
while [ $# -gt 0 ]; do
  case $1 in
    --workspace_path) workspace=${2:?}; shift 2 ;;
    --shards) shards=${2:?}; shift 2 ;;
    --cpus_per_task) cpus=${2:?}; shift 2 ;;
    --log_dir) log_dir=${2:?}; shift 2 ;;
    --program) program=${2:?}; shift 2 ;;
    --wait) wait=1; shift ;;
    --give_up_after) give_up_after=${2:?}; shift 2 ;;
    --) shift; break ;;
    -h|--help) usage ;;
    *) echo "submit.sh: unknown option $1 (dispmvs_colmap options go after --)" >&2; usage ;;
  esac
done
if [ -z "$workspace" ] || [ -z "$shards" ]; then usage; fi
if ! [[ $shards =~ ^[1-9][0-9]*$ ]] || ! [[ $cpus =~ ^[1-9][0-9]*$ ]] ||
   ! [[ $give_up_after =~ ^[1-9][0-9]*$ ]]; then
  echo "submit.sh: --shards, --cpus_per_task and --give_up_after must be positive integers" >&2
  exit 2
fi
if [ ! -d "$workspace/images" ] || [ ! -d "$workspace/sparse" ]; then
  echo "submit.sh: $workspace is not a COLMAP dense workspace (no images/ or sparse/)" >&2
  exit 1
fi
workspace=$(cd "$workspace" && pwd)  # the jobs may start in another directory
program=${program:-$(command -v dispmvs_colmap || true)}
if [ -z "$program" ] || [ ! -x "$program" ]; then
  echo "submit.sh: dispmvs_colmap not found: put it on PATH or pass --program" >&2
  exit 1
fi
program=$(cd "$(dirname "$program")" && pwd)/$(basename "$program")
log_dir=${log_dir:-$workspace/dispmvs_slurm_logs}
mkdir -p "$log_dir"

# Check the workspace and options once, here, before anything is queued.
"$program" --workspace_path "$workspace" --mode plan "$@" > "$log_dir/plan.txt"

array_job=$(sbatch --parsable --array="0-$((shards - 1))" --cpus-per-task="$cpus" \
  --output="$log_dir/%x-%A_%a.out" --export=ALL,DISPMVS_COLMAP="$program" \
  "$here/photometric_array.sbatch" "$workspace" "$@")
array_job=${array_job%%;*}  # --parsable prints ID or ID;CLUSTER
echo "photometric array: job $array_job ($shards tasks)"
fuse_args=(--parsable --dependency="afterok:$array_job" --kill-on-invalid-dep=yes
  --output="$log_dir/%x-%j.out" --export=ALL,DISPMVS_COLMAP="$program")
fuse_job=$(sbatch "${fuse_args[@]}" "$here/fuse.sbatch" "$workspace" "$@")
fuse_job=${fuse_job%%;*}
echo "fusion: job $fuse_job (after the array)"
[ "$wait" = 1 ] || exit 0

# Wait for the fusion job. `sbatch --wait` is not used: it returns 0 for a
# job cancelled before it started, which is what Slurm does to the fusion job
# when a shard fails (--kill-on-invalid-dep). The job's final state decides.
# scontrol reports nothing while the controller is unreachable, and forgets
# a job some minutes after it ends (MinJobAge): after --give_up_after seconds
# of that, stop waiting rather than wait forever.
echo "fusion: waiting for job $fuse_job"
last_answer=$SECONDS
while :; do
  info=$(scontrol show job -o "$fuse_job" 2> /dev/null || true)
  state=$(grep -o 'JobState=[A-Z_]*' <<< "$info" | cut -d= -f2 || true)
  case $state in
    "")
      if (( SECONDS - last_answer >= give_up_after )); then
        echo "submit.sh: scontrol has not reported job $fuse_job for ${give_up_after} s;" \
          "stopped waiting (the jobs themselves are not touched): ask the cluster" \
          "(sacct -j $fuse_job), see the logs in $log_dir" >&2
        exit 1
      fi
      sleep 2 ;;
    PENDING|CONFIGURING|RUNNING|COMPLETING|REQUEUED|RESIZING|SUSPENDED)
      last_answer=$SECONDS; sleep 2 ;;
    COMPLETED) echo "fusion: job $fuse_job completed"; exit 0 ;;
    *)
      reason=$(grep -o 'Reason=[^ ]*' <<< "$info" | cut -d= -f2 || true)
      echo "submit.sh: fusion job $fuse_job ended $state (reason: ${reason:-none});" \
        "a failed shard cancels it: see the logs in $log_dir, then submit again" \
        "(finished views are kept)" >&2
      exit 1 ;;
  esac
done
