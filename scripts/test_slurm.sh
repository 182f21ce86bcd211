#!/bin/bash
# evio sweep --engine slurm on a one-node Slurm on this machine: writes a munge key and a
# slurm.conf (this host as the only node, ports that are free, state and logs in a temp folder),
# starts munged, slurmctld and slurmd in the background (torn down at exit), runs the same sweep
# with --engine local and --engine slurm and checks that results.jsonl has the same rows (cell,
# exit code, params, metrics; times and per-event timings aside), then cancels a task mid-run and
# checks that it is recorded (from scontrol) and rerun by --resume. Exit 77 (skipped) when slurm-wlm
# or munge is missing, or when not run as root (slurmd needs it).
# Usage: scripts/test_slurm.sh EVIO [SPEC] [PYTHON]   (as root or the user the daemons may run as)
set -u
evio=${1:?usage: test_slurm.sh EVIO [SPEC] [PYTHON]}
here=$(cd "$(dirname "$0")" && pwd)
spec=${2:-$here/../tests/apps/data/sweep/hosts.yaml}
python=${3:-/usr/bin/python3}
for need in slurmctld slurmd sbatch squeue scontrol scancel; do
  command -v $need > /dev/null || [ -x /usr/sbin/$need ] || { echo "SKIP: $need is not installed (Debian package slurm-wlm)"; exit 77; }
done
command -v munged > /dev/null || [ -x /usr/sbin/munged ] || { echo "SKIP: munged is not installed (Debian package munge)"; exit 77; }
[ "$(id -u)" = 0 ] || { echo "SKIP: slurmd runs jobs as their user and needs root"; exit 77; }
export PATH=$PATH:/usr/sbin

t=$(mktemp -d /tmp/evio_sweep_slurm.XXXXXX)
chmod 755 "$t"
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2> /dev/null; done
  [ -f "$t/munged.pid" ] && kill "$(cat "$t/munged.pid")" 2> /dev/null
  sleep 0.5
  rm -rf "$t"
}
trap cleanup EXIT
fail() { echo "FAIL: $*"; for f in "$t"/slurmctld.log "$t"/slurmd.log; do [ -f "$f" ] && tail -5 "$f"; done; exit 1; }
free_port() { $python -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }

# munge: its own key and socket.
mkdir -p "$t/munge"
chmod 700 "$t/munge"
dd if=/dev/urandom of="$t/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$t/munge/munge.key"
munged --force --key-file="$t/munge/munge.key" --socket="$t/munge/munge.sock" --pid-file="$t/munged.pid" \
  --log-file="$t/munged.log" --seed-file="$t/munge/seed" || fail "munged did not start: $(cat "$t/munged.log")"

host=$(hostname -s)
user=$(id -un)
mkdir -p "$t/state" "$t/spool"
cat > "$t/slurm.conf" << EOF
ClusterName=evio
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$(free_port)
SlurmdPort=$(free_port)
SlurmUser=$user
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$t/munge/munge.sock
CredType=cred/munge
StateSaveLocation=$t/state
SlurmdSpoolDir=$t/spool
SlurmctldPidFile=$t/slurmctld.pid
SlurmdPidFile=$t/slurmd.pid
SlurmctldLogFile=$t/slurmctld.log
SlurmdLogFile=$t/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
MinJobAge=600
NodeName=$host NodeAddr=127.0.0.1 CPUs=$(nproc) State=UNKNOWN
PartitionName=evio Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF=$t/slurm.conf
slurmctld -D -i -f "$t/slurm.conf" > "$t/slurmctld.out" 2>&1 &
pids+=($!)
slurmd -D -f "$t/slurm.conf" > "$t/slurmd.out" 2>&1 &
pids+=($!)
for i in $(seq 100); do
  state=$(sinfo -h -o %t 2> /dev/null)
  [ "$state" = idle ] && break
  sleep 0.2
done
[ "$state" = idle ] || fail "the node is not idle: '$state' $(cat "$t/slurmctld.out" "$t/slurmd.out")"
echo "Slurm on $host is up (slurm.conf: $t/slurm.conf)"

start=$(date +%s.%N)
"$evio" sweep "$spec" --out "$t/local" -q --no-report -j 2 || fail "the local sweep failed"
mid=$(date +%s.%N)
"$evio" sweep "$spec" --out "$t/slurm" -q --no-report --engine slurm --slurm-partition evio -j 2 || fail "the slurm sweep failed: $(cat "$t"/slurm/slurm/*.err)"
end=$(date +%s.%N)
echo "local: $($python -c "print(round($mid - $start, 1))") s, slurm: $($python -c "print(round($end - $mid, 1))") s"

$python "$here/../tests/apps/compare_sweep_rows.py" "$t/local" "$t/slurm" slurm || fail "the rows differ"
grep -q '^#SBATCH --array=0-5%2$' "$t/slurm/slurm/run1.sh" || fail "unexpected array script: $(cat "$t/slurm/slurm/run1.sh")"

# A task cancelled mid-run (scancel: its runner dies with it and leaves no outcome file) is recorded
# with what `scontrol show job` says (a negative exit code: the signal) and rerun by --resume.
cat > "$t/slow.yaml" << EOF
name: slow
datasets:
  - {name: wall, scene: $here/../datasets/poster_6dof.yaml, duration: 2}
algorithms:
  - {algorithm: reconstruct, datasets: [wall], grid: {method: [cf]}}
EOF
"$evio" sweep "$t/slow.yaml" --out "$t/cancel" -q --no-report --engine slurm &
sweep=$!
for i in $(seq 1200); do
  pgrep -f "evio-reconstruct $t/cancel/" > /dev/null && break
  sleep 0.05
done
pgrep -f "evio-reconstruct $t/cancel/" > /dev/null || fail "the slow cell never ran"
scancel "$(cat "$t/cancel/slurm/run1.jobid")"
wait $sweep
rc=$?
[ $rc = 1 ] || fail "the sweep with a cancelled task exited $rc, not 1"
grep -q '"exit_code": -[0-9]' "$t/cancel/results.jsonl" || fail "the cancelled cell is not recorded with a signal: $(cat "$t/cancel/results.jsonl")"
grep -q "left no .*outcome.json: Slurm task" "$t"/cancel/cells/*/stderr.log || fail "the cell's stderr.log does not say why"
"$evio" sweep "$t/slow.yaml" --out "$t/cancel" -q --no-report --engine slurm --resume || fail "--resume failed"
[ "$(grep -c '"exit_code": 0' "$t/cancel/results.jsonl")" = 1 ] || fail "--resume did not rerun the cancelled cell"
echo "a task cancelled mid-run was recorded with $(grep -o '"exit_code": -[0-9]*' "$t/cancel/results.jsonl") and rerun by --resume"
