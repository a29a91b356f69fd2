#!/usr/bin/env bash
# Runs dsm-farm through a real Slurm (docs/dsm-farm.md): starts munged,
# slurmctld and slurmd on localhost under a fresh temporary directory (every
# file the daemons write is in it; ports chosen free; traffic on loopback),
# runs the checks, and stops the daemons by PID.
#
#   check_dsm_farm_slurm.sh DSM_FARM DSM_BUILD SCENE
#
# Checks (one cluster for all, to keep the time small):
#   identical  a 4x4 farm build equals the one-machine build byte for byte;
#   failure    a part made to fail (its output path is a directory) gives a
#              non-zero --wait naming it and no output; resubmitting that part
#              alone, then the stitch, completes the same map.
# Exit 77 (skipped) when Slurm or munge is not installed (scripts/install-deps).
set -euo pipefail
farm=$1 build=$2 scene=$3
for daemon in munged slurmctld slurmd sbatch scontrol sinfo; do
  command -v "$daemon" >/dev/null || PATH=$PATH:/usr/sbin
  command -v "$daemon" >/dev/null || { echo "SKIP: $daemon is not installed"; exit 77; }
done

root=$(mktemp -d "${TMPDIR:-/tmp}/dsm-farm-slurm.XXXXXX")
pids=()
stop() {
  local status=$?
  for ((i = ${#pids[@]} - 1; i >= 0; i--)); do kill "${pids[i]}" 2>/dev/null || true; done
  for pid in "${pids[@]}"; do
    for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -9 "$pid" 2>/dev/null || true
  done
  if [ "$status" -ne 0 ]; then
    echo "--- daemon logs (failure) ---"
    tail -n 30 "$root"/*.log "$root"/*.out 2>/dev/null || true
  fi
  rm -rf "$root"
  exit "$status"
}
trap stop EXIT
fail() { echo "FAIL: $*"; exit 1; }

free_port() { /usr/bin/python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }

# munge: its socket directory must be mode 0711; --force because /tmp is
# writable by all (sticky).
mkdir -p "$root/munge" "$root/state" "$root/spool" "$root/tmp"
chmod 0711 "$root" "$root/munge"
dd if=/dev/urandom of="$root/munge.key" bs=1024 count=1 status=none
chmod 0400 "$root/munge.key"
socket=$root/munge/munge.socket
munged --foreground --force --socket="$socket" --key-file="$root/munge.key" --log-file="$root/munged.log" \
  --pid-file="$root/munged.pid" --seed-file="$root/munge.seed" >"$root/munged.out" 2>&1 &
pids+=($!)

ctl_port=$(free_port)
node_port=$(free_port)
while [ "$node_port" = "$ctl_port" ]; do node_port=$(free_port); done
# 16 slots, more than the cores (config_overrides): the parts of the test map
# are small, and a scheduling cycle takes longer than one of them.
cpus=16
export SLURM_CONF=$root/slurm.conf
cat >"$SLURM_CONF" <<CONF
ClusterName=dsmfarm
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort=$ctl_port
SlurmdPort=$node_port
SlurmUser=$(id -un)
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$socket
CredType=cred/munge
StateSaveLocation=$root/state
SlurmdSpoolDir=$root/spool
TmpFS=$root/tmp
SlurmctldPidFile=$root/slurmctld.pid
SlurmdPidFile=$root/slurmd.pid
SlurmctldLogFile=$root/slurmctld.log
SlurmdLogFile=$root/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/builtin
SlurmdParameters=config_overrides
MpiDefault=none
ReturnToService=2
MinJobAge=3600
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
SwitchType=switch/none
NodeName=localhost NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=farm Nodes=localhost Default=YES MaxTime=INFINITE State=UP
CONF

for _ in $(seq 50); do [ -S "$socket" ] && break; sleep 0.1; done
[ -S "$socket" ] || fail "munged did not start"
slurmctld -D -i -f "$SLURM_CONF" >"$root/slurmctld.out" 2>&1 &
pids+=($!)
slurmd -D -N localhost -f "$SLURM_CONF" >"$root/slurmd.out" 2>&1 &
pids+=($!)
for _ in $(seq 150); do
  state=$(sinfo -h -o %T 2>/dev/null || true)
  [ "$state" = idle ] && break
  sleep 0.2
done
[ "$state" = idle ] || fail "the node did not come up (state '$state')"
echo "cluster up: slurmctld :$ctl_port, slurmd :$node_port, $cpus CPUs"

options=(-r 128 -t 16 -s 4)
"$build" "$scene" -o "$root/one.dsm" "${options[@]}" -q

# identical
start=$SECONDS
"$farm" submit --engine slurm "$scene" -o "$root/farm.dsm" --tiles 16 "${options[@]}" --cpus-per-task 1 --wait \
  >"$root/identical.out" 2>&1 || { cat "$root/identical.out"; fail "identical: the farm build failed"; }
cmp "$root/one.dsm" "$root/farm.dsm" || fail "identical: the farm build differs from the one-machine build"
grep -q "submitted parts job [0-9]*, stitch job [0-9]*" "$root/identical.out" || fail "identical: no job ids printed"
echo "identical: passed ($((SECONDS - start)) s)"

# failure
start=$SECONDS
mkdir -p "$root/failing.parts/part-0005.dsm"  # part 5 cannot be written
status=0
"$farm" submit --engine slurm "$scene" -o "$root/failing.dsm" --parts "$root/failing.parts" --tiles 16 \
  "${options[@]}" --cpus-per-task 1 --wait >"$root/failure.out" 2>&1 || status=$?
cat "$root/failure.out"
[ "$status" -ne 0 ] || fail "failure: --wait exited 0 with a failed part"
grep -q "parts failed: 5 " "$root/failure.out" || fail "failure: the failed part is not named"
grep -q "stitch CANCELLED" "$root/failure.out" || fail "failure: the stitch was not reported cancelled"
[ ! -e "$root/failing.dsm" ] || fail "failure: an output was written"
grep -q "is a directory\|directory" "$root/failing.parts/logs/part-0005.log" || fail "failure: part 5's log lacks the cause"
rmdir "$root/failing.parts/part-0005.dsm"
"$farm" submit --engine slurm "$scene" -o "$root/failing.dsm" --parts "$root/failing.parts" --tiles 16 \
  "${options[@]}" --cpus-per-task 1 --indices 5 --wait >"$root/resubmit.out" 2>&1 ||
  { cat "$root/resubmit.out"; fail "failure: the resubmission failed"; }
cmp "$root/one.dsm" "$root/failing.dsm" || fail "failure: the completed build differs from the one-machine build"
built=$(grep -l "wrote part" "$root"/failing.parts/logs/part-*.log | wc -l)
[ "$built" -eq 16 ] || fail "failure: $built part logs say built, expected 16 (15 first, then part 5)"
echo "failure: passed ($((SECONDS - start)) s)"
