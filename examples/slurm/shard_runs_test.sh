#!/bin/bash
# ctests `shards_with_xargs` and `slurm_one_node`: a workspace computed in
# shards must come out byte-identical to one `dispmvs_colmap` process on a
# copy of the same workspace (the example, at 96 px, one thread each).
#
#   shard_runs_test.sh BUILD_DIR WORK_DIR xargs
#     3 shards at once on this machine with `xargs -P` (the command of
#     examples/slurm/README.md), then `--mode fuse`.
#   shard_runs_test.sh BUILD_DIR WORK_DIR slurm
#     starts a one-node Slurm cluster (munged, slurmctld and slurmd from
#     Debian's packages, everything under WORK_DIR, on free ports, stopped
#     at the end) and runs submit.sh (3 photometric shards, then the
#     dependent fusion job) with one shard's task killed as if its node died:
#     the fusion job must not run. Submits again (only that shard's views
#     are computed), then compares.
set -euo pipefail

usage="usage: $0 BUILD_DIR WORK_DIR xargs|slurm"
build=$(cd "${1:?$usage}" && pwd)
work=${2:?$usage}
mode=${3:?$usage}
here=$(cd "$(dirname "$0")" && pwd)
PATH=$PATH:/usr/sbin:/sbin  # munged, slurmctld and slurmd live there
colmap=$build/src/dispmvs_colmap
[ -x "$colmap" ] || { echo "FAIL: $colmap not built"; exit 1; }
rm -rf "$work"
mkdir -p "$work"
work=$(cd "$work" && pwd)

# The same workspace twice: one process, and the shards.
"$build/examples/dispmvs_make_example" --output_path "$work/single" --seed 1 > /dev/null
cp -a "$work/single" "$work/cluster"
options=(--max_image_size 96 --threads 1)
start=$SECONDS
"$colmap" --workspace_path "$work/single" "${options[@]}" > "$work/single.log" 2>&1 \
  || { cat "$work/single.log"; echo "FAIL: the single-process run failed"; exit 1; }
echo "single process: $((SECONDS - start)) s"

# Byte-identical outputs (the report names the command line, the claim
# locks hold pids and the view records times, so they differ by design).
compare_with_single() {
  if ! diff -r --exclude=dispmvs_report.html --exclude=dispmvs_claims \
        --exclude=dispmvs_fusion.lock --exclude=dispmvs_records "$work/single" "$work/cluster"; then
    echo "FAIL: the $mode run's outputs differ from the single process's"
    exit 1
  fi
  maps=$(find "$work/cluster/stereo" -name '*.dispmvs.*.bin' | wc -l)
  [ "$maps" = 42 ] || { echo "FAIL: expected 42 maps, found $maps"; exit 1; }
  [ -s "$work/cluster/fused.ply" ] || { echo "FAIL: no fused cloud"; exit 1; }
}

if [ "$mode" = xargs ]; then
  WS=$work/cluster
  start=$SECONDS
  seq 0 2 | xargs -P 3 -I{} "$colmap" --workspace_path "$WS" --mode photometric --shard {}/3 \
    "${options[@]}" > "$work/shards.log" 2>&1 \
    || { cat "$work/shards.log"; echo "FAIL: a shard failed"; exit 1; }
  "$colmap" --workspace_path "$WS" --mode fuse "${options[@]}" > "$work/fuse.log" 2>&1 \
    || { cat "$work/fuse.log"; echo "FAIL: fusion failed"; exit 1; }
  echo "xargs -P 3 (3 shards) + fuse: $((SECONDS - start)) s"
  computed=$(grep -c '^photometric: \[.*depth at' "$work/shards.log" || true)
  [ "$computed" = 7 ] || { echo "FAIL: the shards computed $computed views, expected 7"; exit 1; }
  compare_with_single
  echo "PASS: 3 shards with xargs -P + --mode fuse == one process (42 maps, fused.ply, .vis)"
  exit 0
fi
[ "$mode" = slurm ] || { echo "$usage"; exit 2; }

for tool in munged munge slurmctld slurmd sbatch sinfo scontrol; do
  command -v "$tool" > /dev/null || { echo "FAIL: $tool not found (apt-get install munge slurmctld slurmd slurm-client)"; exit 1; }
done
# munged refuses a socket or key in a folder others can write to or not
# enter: the key folder is private, the socket folder open to all. --force
# turns its checks of the folders above WORK_DIR (a build tree may sit in a
# group-writable one) into warnings: this daemon lives for one test.
chmod 711 "$work"
mkdir -m 700 "$work/munge" "$work/state" "$work/spool"
mkdir -m 755 "$work/run" "$work/log"
head -c 1024 /dev/urandom > "$work/munge/munge.key"
chmod 400 "$work/munge/munge.key"

pids=()
cleanup() {
  status=$?
  for pid in "${pids[@]}"; do kill "$pid" 2> /dev/null || true; done
  munged --stop --socket="$work/run/munge.socket" 2> /dev/null || true
  if [ $status -ne 0 ]; then
    for f in "$work"/log/*.log "$work"/jobs*/*.out; do
      [ -f "$f" ] && { echo "--- $f (last lines)"; tail -n 30 "$f"; }
    done
  fi
  exit $status
}
trap cleanup EXIT

munged --force --key-file="$work/munge/munge.key" --socket="$work/run/munge.socket" \
  --pid-file="$work/run/munged.pid" --log-file="$work/log/munged.log" \
  --seed-file="$work/munge/munged.seed"

# Two free TCP ports for the controller and the node daemon.
port_in_use() { (exec 3<> "/dev/tcp/127.0.0.1/$1") 2> /dev/null; }
free_port() {
  local port
  for _ in $(seq 100); do
    port=$((20000 + RANDOM % 20000))
    port_in_use "$port" || { echo "$port"; return; }
  done
  echo "FAIL: no free port" >&2
  exit 1
}
ctld_port=$(free_port)
slurmd_port=$(free_port)
while [ "$slurmd_port" = "$ctld_port" ]; do slurmd_port=$(free_port); done

node=$(hostname -s)
user=$(id -un)
# The node line as slurmd measures this machine (a node configured with more
# CPUs than it has would be drained).
node_line=$(slurmd -C | head -n 1)
cat > "$work/slurm.conf" <<CONF
ClusterName=dispmvs-test
SlurmctldHost=$node(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
SlurmUser=$user
SlurmdUser=$user
AuthType=auth/munge
AuthInfo=socket=$work/run/munge.socket
CredType=cred/munge
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/run/slurmctld.pid
SlurmdPidFile=$work/run/slurmd.pid
SlurmctldLogFile=$work/log/slurmctld.log
SlurmdLogFile=$work/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SwitchType=switch/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
$node_line NodeAddr=127.0.0.1 State=UNKNOWN
PartitionName=test Nodes=$node Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF=$work/slurm.conf

slurmctld -D -c -f "$SLURM_CONF" > "$work/log/slurmctld.out" 2>&1 &
pids+=($!)
slurmd -D -f "$SLURM_CONF" -N "$node" > "$work/log/slurmd.out" 2>&1 &
pids+=($!)
for i in $(seq 120); do
  state=$(sinfo -h -n "$node" -o %T 2> /dev/null || true)
  [ "$state" = idle ] && break
  [ "$i" = 120 ] && { echo "FAIL: the node did not come up (state '$state')"; exit 1; }
  sleep 0.5
done
echo "one-node Slurm up: node $node, controller port $ctld_port, slurmd port $slurmd_port"

# Submits the example to the cluster (3 shards, then fusion) with program $2,
# logs in $1.
submit() {
  "$here/submit.sh" --workspace_path "$work/cluster" --shards 3 --cpus_per_task 1 \
    --log_dir "$1" --program "$2" --wait -- "${options[@]}"
}
# Views the array tasks logging into $1 computed, all tasks together.
views_computed() { cat "$1"/dispmvs-photometric-*.out | grep -c '^photometric: \[.*depth at' || true; }

# First submission with a node that dies: the task of shard 1/3 is killed
# (SIGKILL) before it computes anything. The dependent fusion job must not
# run, and the other shards' views are kept.
cat > "$work/dying_node.sh" <<WRAPPER
#!/bin/bash
case " \$* " in *" --shard 1/3 "*) echo "node lost"; kill -9 \$\$ ;; esac
exec "$colmap" "\$@"
WRAPPER
chmod +x "$work/dying_node.sh"
if submit "$work/jobs1" "$work/dying_node.sh"; then
  echo "FAIL: submit.sh --wait succeeded although a shard failed"
  exit 1
fi
[ "$(views_computed "$work/jobs1")" = 5 ] || { echo "FAIL: expected 5 views before the failure, got $(views_computed "$work/jobs1")"; exit 1; }
grep -q "node lost" "$work"/jobs1/dispmvs-photometric-*_1.out || { echo "FAIL: shard 1/3 did not run into the lost node"; exit 1; }
! ls "$work"/jobs1/dispmvs-fuse-*.out > /dev/null 2>&1 || { echo "FAIL: the fusion job ran after a failed shard"; exit 1; }
[ ! -e "$work/cluster/fused.ply" ] || { echo "FAIL: a fused cloud was written after a failed shard"; exit 1; }
echo "a lost shard held the fusion job back; 5 of 7 views kept"

# Submit again with the real program: only the lost shard's 2 views are
# computed.
start=$SECONDS
submit "$work/jobs2" "$colmap" || { echo "FAIL: the Slurm jobs failed"; exit 1; }
echo "Slurm resubmission (3 shards + fusion): $((SECONDS - start)) s"
logs=("$work"/jobs2/dispmvs-photometric-*.out)
[ ${#logs[@]} = 3 ] || { echo "FAIL: expected 3 array task logs, found ${#logs[@]}"; exit 1; }
[ "$(views_computed "$work/jobs2")" = 2 ] || { echo "FAIL: the resubmission computed $(views_computed "$work/jobs2") views, expected 2"; exit 1; }
grep -q "^summary: fusion" "$work"/jobs2/dispmvs-fuse-*.out || { echo "FAIL: no fusion summary"; exit 1; }

compare_with_single
echo "PASS: lost shard held fusion back; resubmitted, 3 shards + fusion under Slurm == one process (42 maps, fused.ply, .vis)"
