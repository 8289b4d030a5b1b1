#!/usr/bin/env bash
# A real one-node Slurm cluster on this machine (Debian's slurm-wlm and munge), for the `cluster`
# tests and for trying `plenopiv slurm` without a cluster. Needs root (munged runs as `munge`).
#   bash scripts/slurm-local.sh start DIR   # writes DIR/slurm.conf, starts munged, slurmctld, slurmd;
#                                           # prints `export SLURM_CONF=...` for the clients
#   bash scripts/slurm-local.sh stop DIR    # stops them by their pid files
# Everything (config, state, spool, logs, the munge socket) lives in DIR; a failure says why and
# shows the daemon's log.
set -euo pipefail

usage() { echo "usage: $0 start|stop DIR" >&2; exit 2; }
[ $# -eq 2 ] || usage
action=$1
dir=$(realpath -m "$2")

fail() {
  echo "slurm-local: $*" >&2
  for log in "$dir"/log/*.log; do
    [ -s "$log" ] && { echo "--- $log (last lines)" >&2; tail -n 15 "$log" >&2; }
  done
  exit 1
}

stop_pid_file() {
  local file=$1
  [ -f "$file" ] || return 0
  local pid
  pid=$(cat "$file")
  if kill -0 "$pid" 2>/dev/null; then
    kill "$pid" 2>/dev/null || true
    for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -9 "$pid" 2>/dev/null || true
  fi
  rm -f "$file"
}

if [ "$action" = stop ]; then
  stop_pid_file "$dir/run/slurmd.pid"
  stop_pid_file "$dir/run/slurmctld.pid"
  stop_pid_file "$dir/munge/munged.pid"
  echo "slurm-local: stopped ($dir)"
  exit 0
fi
[ "$action" = start ] || usage

[ "$(id -u)" -eq 0 ] || fail "needs root (munged runs as the munge user, slurmd starts jobs as their user)"
for tool in munged mungekey slurmctld slurmd sinfo; do
  command -v "$tool" >/dev/null || fail "$tool is not installed: bash scripts/setup.sh installs slurm-wlm and munge"
done
id munge >/dev/null 2>&1 || fail "no munge user: the munge package's install did not finish"

host=$(hostname -s)
cpus=$(nproc)
memory_mb=$(( $(awk '/MemTotal/ {print int($2 / 1024)}' /proc/meminfo) * 9 / 10 ))
mkdir -p "$dir"/{run,log,state,spool,munge}

# munge: its own key, socket and files in DIR, owned by munge.
chown munge: "$dir/munge"
chmod 0755 "$dir/munge"  # clients reach the socket; the key itself is 0600
if [ ! -f "$dir/munge/munge.key" ]; then
  runuser -u munge -- mungekey --create --keyfile="$dir/munge/munge.key" ||
    fail "mungekey --create failed"
fi
# munged refuses a socket folder others can write to; DIR's parents may be /tmp (sticky, allowed).
runuser -u munge -- munged --socket="$dir/munge/munge.socket" --key-file="$dir/munge/munge.key" \
  --pid-file="$dir/munge/munged.pid" --log-file="$dir/munge/munged.log" \
  --seed-file="$dir/munge/munged.seed" ||
  fail "munged did not start: $(tail -n 3 "$dir/munge/munged.log" 2>/dev/null)"

cat > "$dir/slurm.conf" <<EOF
# One node: this machine. Written by scripts/slurm-local.sh.
ClusterName=plenopiv-local
SlurmctldHost=$host
SlurmUser=root
AuthType=auth/munge
AuthInfo=socket=$dir/munge/munge.socket
CredType=cred/munge
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/run/slurmctld.pid
SlurmdPidFile=$dir/run/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
SlurmctldPort=6917
SlurmdPort=6918
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
ReturnToService=2
MpiDefault=none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/backfill
MinJobAge=3600
DefMemPerCPU=1024
NodeName=$host CPUs=$cpus RealMemory=$memory_mb State=UNKNOWN
PartitionName=local Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF

export SLURM_CONF="$dir/slurm.conf"
slurmctld -f "$SLURM_CONF" || fail "slurmctld did not start"
slurmd -f "$SLURM_CONF" || fail "slurmd did not start"
for _ in $(seq 100); do
  state=$(sinfo --noheader --format=%t 2>/dev/null | head -n 1 || true)
  case "$state" in idle|mix|alloc) echo "export SLURM_CONF=$SLURM_CONF"; exit 0 ;; esac
  sleep 0.2
done
fail "the node did not become idle within 20 s (sinfo says '${state:-nothing}')"
