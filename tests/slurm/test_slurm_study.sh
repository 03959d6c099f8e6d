#!/usr/bin/env bash
# `make test-slurm`: a 4-mission study grid through a real single-node Slurm (Debian's slurmctld, slurmd
# and munge, started here on private sockets, ports and folders, and stopped again), its merged report
# compared with the same grid run locally by `airground-sim study` (tests/slurm/compare_study.py says
# which wall-clock fields are left out). Then the array is submitted again and every task must skip its
# finished mission (resume). About 3-4 minutes on 2 cores; needs root (slurmd) and tools/install-slurm.sh.
#
# Usage: tests/slurm/test_slurm_study.sh [AIRGROUND_SIM]   (default build/native/sim/airground-sim)
# Environment: AG_SLURM_KEEP=1 keeps the work folder; AG_SLURM_PORT (16817) the controller's port, +1 slurmd's;
# AG_SLURM_MAX_DURATION (60) each mission's simulated seconds.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
top=$(cd "$here/../.." && pwd)
sim=$(realpath "${1:-$top/build/native/sim/airground-sim}")
port=${AG_SLURM_PORT:-16817}
max_duration=${AG_SLURM_MAX_DURATION:-60}
say() { echo "test-slurm: $*"; }
die() { echo "test-slurm: FAILED: $*" >&2; exit 1; }

[ -x "$sim" ] || die "$sim is not an executable (build it: make build)"
for tool in munged slurmctld slurmd sbatch squeue sinfo scontrol; do
  command -v "$tool" >/dev/null || die "'$tool' is missing: run tools/install-slurm.sh (Debian's slurmctld slurmd slurm-client munge)"
done
[ "$(id -u)" = 0 ] || die "slurmd runs jobs as their users and needs root"

work=$(mktemp -d /tmp/ag-slurm.XXXXXX)
chmod 755 "$work"
cluster=$work/cluster
mkdir -p "$cluster"/{munge,spool,state,log}
chmod 711 "$cluster/munge"  # the socket needs search permission on its folder; the key stays 0400
pids=()
jobs_submitted=()
stop_cluster() {
  local status=$?
  # A job still running (a failure or ^C) is cancelled first: slurmstepd would outlive slurmd.
  if [ ${#jobs_submitted[@]} -gt 0 ] && [ -n "$(squeue -h 2>/dev/null)" ]; then
    scancel "${jobs_submitted[@]}" 2>/dev/null || true
    for _ in $(seq 30); do [ -z "$(squeue -h 2>/dev/null)" ] && break; sleep 1; done
  fi
  for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
  for pid in "${pids[@]}"; do wait "$pid" 2>/dev/null || true; done
  if [ $status != 0 ]; then
    echo "test-slurm: daemon logs:" >&2
    tail -n 20 "$cluster"/log/*.log >&2 2>/dev/null || true
  fi
  if [ "${AG_SLURM_KEEP:-0}" = 1 ] || [ $status != 0 ]; then say "work folder kept: $work"; else rm -rf "$work"; fi
  exit $status
}
trap stop_cluster EXIT

# --- a private MUNGE: its own key, socket and log
dd if=/dev/urandom of="$cluster/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$cluster/munge/munge.key"
sock=$cluster/munge/munge.sock
munged -F -f --socket="$sock" --key-file="$cluster/munge/munge.key" --pid-file="$cluster/munge/munged.pid" \
  --log-file="$cluster/log/munged.log" --seed-file="$cluster/munge/seed" >"$cluster/log/munged.out" 2>&1 &
pids+=($!)
for _ in $(seq 50); do [ -S "$sock" ] && break; sleep 0.1; done
[ -S "$sock" ] || die "munged did not create $sock"

# --- a single-node Slurm: this host with 2 CPUs, no cgroups, no accounting, everything under $cluster
node=$(hostname -s)
cpus=$(nproc)
export SLURM_CONF=$cluster/slurm.conf
cat > "$SLURM_CONF" <<EOF
ClusterName=airground-test
SlurmctldHost=$node(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$sock
StateSaveLocation=$cluster/state
SlurmdSpoolDir=$cluster/spool
SlurmctldPidFile=$cluster/slurmctld.pid
SlurmdPidFile=$cluster/slurmd.pid
SlurmctldLogFile=$cluster/log/slurmctld.log
SlurmdLogFile=$cluster/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SchedulerType=sched/backfill
ReturnToService=2
MinJobAge=600
NodeName=$node NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=airground Nodes=$node Default=YES MaxTime=INFINITE State=UP
EOF
slurmctld -D -i -f "$SLURM_CONF" >"$cluster/log/slurmctld.out" 2>&1 &
pids+=($!)
slurmd -D -N "$node" -f "$SLURM_CONF" >"$cluster/log/slurmd.out" 2>&1 &
pids+=($!)
for _ in $(seq 60); do
  sinfo -h -o %T 2>/dev/null | grep -qx idle && break
  sleep 0.5
done
sinfo -h -o %T | grep -qx idle || die "the node did not come up idle: $(sinfo 2>&1 | tail -n 2)"
say "Slurm $(sinfo -V | awk '{print $2}') up: node $node, $cpus CPUs, controller port $port"

# --- the grid: 2 team sizes x 2 seeds on a small world, short missions
world=$work/world
"$sim" world generate --seed 3 --size 200 --targets 2 --out "$world" >/dev/null 2>&1 || die "world generate failed"
grid=(--world "$world" --ugvs 1,2 --comm-range 150 --seeds 2 --max-duration "$max_duration" --lidar-columns 512)

t0=$(date +%s)
"$sim" study "${grid[@]}" --out "$work/slurm" --slurm "$work/sbatch" --cpus-per-task 1
wait_array() {  # job id: until squeue no longer lists it (at most 20 minutes)
  for _ in $(seq 1200); do
    [ -z "$(squeue -h -j "$1" 2>/dev/null)" ] && return 0
    sleep 1
  done
  die "job $1 still in the queue after 20 minutes: $(squeue -j "$1")"
}
job=$(sbatch --parsable "$work/sbatch/study.sbatch")
jobs_submitted+=("$job")
say "submitted job array $job"
wait_array "$job"
t_slurm=$(( $(date +%s) - t0 ))
failed=$(scontrol show job "$job" -o | grep -v 'ExitCode=0:0' | grep -o 'ArrayTaskId=[0-9]*' || true)
[ -z "$failed" ] || die "tasks failed: $failed (logs in $work/sbatch/logs)"
for n in 0 1 2 3; do grep -q "task $n: done" "$work/sbatch/logs/task_$n.out" || die "task $n did not finish: $(cat "$work/sbatch/logs/task_$n.out")"; done
say "the array ran 4 missions in ${t_slurm} s"

# --- resume: the same array again; every task finds its metrics.json and runs nothing
job2=$(sbatch --parsable "$work/sbatch/study.sbatch")
jobs_submitted+=("$job2")
wait_array "$job2"
for n in 0 1 2 3; do grep -q "not run again" "$work/sbatch/logs/task_$n.out" || die "task $n of the resubmitted array ran its mission again"; done
say "resubmitted: all 4 tasks skipped their finished missions"

"$sim" study --report-only --out "$work/slurm" >/dev/null

# --- the same grid on this machine, as `study` runs it without Slurm
t0=$(date +%s)
"$sim" study "${grid[@]}" --out "$work/local" --jobs 2 >/dev/null 2>&1 || die "the local study failed"
say "the local study ran 4 missions in $(( $(date +%s) - t0 )) s"

/usr/bin/python3 "$here/compare_study.py" "$work/local" "$work/slurm"
say "passed"
