# A one-node Slurm cluster on localhost for dsm-farm's test and benchmark,
# sourced by tests/tools/check_dsm_farm_slurm.sh and bench/farm/slurm_farm.sh.
#
#   start_slurm_cluster CPUS    starts munged, slurmctld and slurmd under a fresh
#                               temporary directory $root (every file the daemons
#                               write is in it; ports chosen free; traffic on
#                               127.0.0.1), exports SLURM_CONF, and sets a trap
#                               that stops the daemons by PID and removes $root.
# Needs: munged, slurmctld, slurmd, sinfo (scripts/install-deps).

slurm_cluster_pids=()

stop_slurm_cluster() {
  local status=$?
  for ((i = ${#slurm_cluster_pids[@]} - 1; i >= 0; i--)); do kill "${slurm_cluster_pids[i]}" 2>/dev/null || true; done
  for pid in "${slurm_cluster_pids[@]}"; do
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

free_port() { /usr/bin/python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }

start_slurm_cluster() {
  local cpus=$1 ctl_port node_port socket state
  root=$(mktemp -d "${TMPDIR:-/tmp}/dsm-farm-slurm.XXXXXX")
  trap stop_slurm_cluster EXIT

  # munge: its socket directory must be mode 0711; --force because /tmp is
  # writable by all (sticky).
  mkdir -p "$root/munge" "$root/state" "$root/spool" "$root/tmp"
  chmod 0711 "$root" "$root/munge"
  dd if=/dev/urandom of="$root/munge.key" bs=1024 count=1 status=none
  chmod 0400 "$root/munge.key"
  socket=$root/munge/munge.socket
  munged --foreground --force --socket="$socket" --key-file="$root/munge.key" --log-file="$root/munged.log" \
    --pid-file="$root/munged.pid" --seed-file="$root/munge.seed" >"$root/munged.out" 2>&1 &
  slurm_cluster_pids+=($!)

  ctl_port=$(free_port)
  node_port=$(free_port)
  while [ "$node_port" = "$ctl_port" ]; do node_port=$(free_port); done
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
  [ -S "$socket" ] || { echo "munged did not start"; return 1; }
  slurmctld -D -i -f "$SLURM_CONF" >"$root/slurmctld.out" 2>&1 &
  slurm_cluster_pids+=($!)
  slurmd -D -N localhost -f "$SLURM_CONF" >"$root/slurmd.out" 2>&1 &
  slurm_cluster_pids+=($!)
  for _ in $(seq 150); do
    state=$(sinfo -h -o %T 2>/dev/null || true)
    [ "$state" = idle ] && break
    sleep 0.2
  done
  [ "$state" = idle ] || { echo "the node did not come up (state '$state')"; return 1; }
  echo "cluster up: slurmctld :$ctl_port, slurmd :$node_port, $cpus CPUs"
}
