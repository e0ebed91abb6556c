#!/bin/bash
# A one-node Slurm cluster for the study tests (tests/tests/study_slurm.rs) on Debian 12, as root,
# without systemd: munged, slurmctld and slurmd started by hand and stopped by PID.
# Usage: single-node.sh start|stop|status. Idempotent. Adapted from a recipe tested on this kind of machine:
# fresh StateSaveLocation (a warm restart reports idle before slurmd registered), batch_sched_delay=0,
# MinJobAge=3600, proctrack/pgid (linuxproc left a SIGKILLed task's children running), no accounting database.
# Idempotent: start skips daemons that are already up; stop is a no-op when nothing runs.
set -eu
D=${SLURM_CI_DIR:-/var/spool/slurm-ci}          # state, logs, pid files
H=$(hostname -s)
PROCTRACK=${SLURM_CI_PROCTRACK:-proctrack/pgid}   # pgid also kills orphans of a SIGKILLed task
CPUS=${SLURM_CI_CPUS:-$(nproc)}                    # job slots; may exceed nproc (config_overrides)

pid_of() {  # pid_of PIDFILE NAME -> prints the pid if that daemon is alive (zombies don't count)
  local p; p=$(cat "$1" 2>/dev/null) && [ -n "$p" ] || return 1
  grep -qx "Name:[[:space:]]*$2" /proc/$p/status 2>/dev/null &&
    ! grep -q '^State:[[:space:]]*Z' /proc/$p/status 2>/dev/null && echo "$p"
}

write_conf() {
  mkdir -p "$D/ctld" "$D/d"
  cat > /etc/slurm/slurm.conf <<CONF
ClusterName=ci
SlurmctldHost=$H
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$D/ctld
SlurmdSpoolDir=$D/d
SlurmctldPidFile=$D/slurmctld.pid
SlurmdPidFile=$D/slurmd.pid
SlurmctldLogFile=$D/slurmctld.log
SlurmdLogFile=$D/slurmd.log
ProctrackType=$PROCTRACK
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc=$D/jobcomp.txt
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MpiDefault=none
SchedulerParameters=batch_sched_delay=0
MinJobAge=3600
SlurmdParameters=config_overrides
NodeName=$H CPUs=$CPUS State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
}

start() {
  command -v slurmctld >/dev/null 2>&1 || DEBIAN_FRONTEND=noninteractive \
    apt-get install -y -q --no-install-recommends slurmctld slurmd slurm-client munge
  [ -s /etc/munge/munge.key ] || mungekey --create
  chown munge:munge /etc/munge/munge.key && chmod 0400 /etc/munge/munge.key
  install -d -o munge -g munge -m 0755 /run/munge
  munge -n </dev/null >/dev/null 2>&1 || runuser -u munge -- /usr/sbin/munged
  if ! pid_of "$D/slurmctld.pid" slurmctld >/dev/null; then
    rm -rf "$D/ctld" "$D/jobcomp.txt"   # fresh state: job ids restart at 1; node UNKNOWN until slurmd registers
    write_conf
    /usr/sbin/slurmctld
  fi
  pid_of "$D/slurmd.pid" slurmd >/dev/null || /usr/sbin/slurmd
  timeout 60 bash -c "until sinfo -h -n $H -o %T 2>/dev/null | grep -qxE 'idle|mixed|allocated|completing'; do sleep 0.5; done" \
    || { echo "slurm not ready; see $D/*.log" >&2; sinfo >&2 || true; return 1; }
}

stop() {
  if pid_of "$D/slurmctld.pid" slurmctld >/dev/null; then
    scancel -u root 2>/dev/null || true       # kill running/pending jobs first
    timeout 40 bash -c 'while [ -n "$(squeue -h 2>/dev/null)" ]; do sleep 0.5; done' || true
  fi
  local p i
  for x in "$D/slurmd.pid slurmd" "$D/slurmctld.pid slurmctld" "/run/munge/munged.pid munged"; do
    set -- $x
    p=$(pid_of "$1" "$2") || continue
    kill -TERM "$p"
    for i in $(seq 100); do pid_of "$1" "$2" >/dev/null || break; sleep 0.2; done
    pid_of "$1" "$2" >/dev/null && kill -KILL "$p"
  done
  return 0
}

status() { for x in slurmctld slurmd; do echo "$x: $(pid_of "$D/$x.pid" $x || echo down)"; done
           echo "munged: $(pid_of /run/munge/munged.pid munged || echo down)"; sinfo 2>/dev/null || true; }

"${1:?usage: $0 start|stop|status}"
