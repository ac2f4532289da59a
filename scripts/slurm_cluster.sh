#!/usr/bin/env bash
# A throw-away single-node SLURM cluster on this machine, to try `hydra/launcher=slurm` before a real cluster and
# for the tests marked `slurm` (tests/test_slurm.py; .ci/run starts it before the test suite).
#
#   scripts/slurm_cluster.sh start    # install Debian's slurm-wlm and munge if missing, start munged, slurmctld and
#                                     # slurmd, wait until the node is idle (a no-op when the cluster is already up)
#   scripts/slurm_cluster.sh status   # sinfo and squeue; exit 0 when the node takes jobs, 1 otherwise
#   scripts/slurm_cluster.sh stop     # cancel every job, stop the daemons, remove the config and the state folder
#
# One node (this host, under its short host name, at 127.0.0.1) with the CPUs this process may use (nproc) and the
# memory slurmd measures (slurmd -C), one partition `debug` (the default), no cgroups (ProctrackType=proctrack/
# linuxproc, TaskPlugin=task/none), no accounting database, jobs run as the submitting user. Daemons are started
# directly (containers rarely run systemd). Needs root (apt-get, /etc/slurm/slurm.conf, slurmd); re-runs itself
# through sudo when not root. A machine that already has a /etc/slurm/slurm.conf not written by this script (a real
# cluster's) is left alone: start refuses.
#
# Environment: STUDY_SLURM_STATE (state, spool and log folder; default /tmp/study-slurm),
#              STUDY_SLURM_WAIT (seconds to wait for the node; default 60).
# Sources: Slurm 22.05 slurm.conf(5), slurmctld(8), slurmd(8); MUNGE munged(8), mungekey(8).
set -euo pipefail

STATE="${STUDY_SLURM_STATE:-/tmp/study-slurm}"
WAIT="${STUDY_SLURM_WAIT:-60}"
CONF=/etc/slurm/slurm.conf
MARK="# Written by study's scripts/slurm_cluster.sh: a throw-away single-node cluster ('stop' removes it)."
NODE="$(hostname -s)"
PARTITION=debug

say() { echo "slurm_cluster: $*" >&2; }
die() { say "error: $*"; exit 1; }

if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null 2>&1 || die "needs root (apt-get, $CONF, slurmd) and sudo is not installed"
    exec sudo -E "$0" "$@"
fi

ours() { [ -f "$CONF" ] && head -n 1 "$CONF" | grep -qF "$MARK"; }

alive() {  # alive PIDFILE: the pid in PIDFILE is a running process
    [ -s "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null
}

stop_pidfile() {  # stop_pidfile PIDFILE NAME: TERM, then KILL after 10 s; removes the pid file
    local pf="$1" name="$2" pid i
    if alive "$pf"; then
        pid="$(cat "$pf")"
        kill -TERM "$pid" 2>/dev/null || true
        for i in $(seq 1 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.2; done
        if kill -0 "$pid" 2>/dev/null; then say "$name did not stop on TERM, killing"; kill -KILL "$pid" 2>/dev/null || true; fi
    fi
    rm -f "$pf"
}

node_state() {  # the node's state as sinfo prints it (idle, mix, alloc, down*, unk*, ...), empty when unreachable
    ours || return 0
    timeout 10 sinfo -h -n "$NODE" -o %t 2>/dev/null | head -n 1 || true
}

up() {  # both daemons of this script alive, munge answering and the node taking jobs
    alive "$STATE/slurmctld.pid" && alive "$STATE/slurmd.pid" || return 1
    munge -n 2>/dev/null | unmunge >/dev/null 2>&1 || return 1
    case "$(node_state)" in idle|mix|mixed|alloc|allocated|comp|completing) return 0;; *) return 1;; esac
}

install_packages() {
    local missing=""
    for c in munged munge unmunge slurmctld slurmd sinfo sbatch; do command -v "$c" >/dev/null 2>&1 || missing="$missing $c"; done
    [ -z "$missing" ] && return 0
    command -v apt-get >/dev/null 2>&1 || die "missing:$missing, and no apt-get to install Debian's slurm-wlm and munge"
    say "installing slurm-wlm and munge (missing:$missing)"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends slurm-wlm munge >/dev/null
}

start_munge() {
    local pf=/run/munge/munged.pid
    if [ ! -s /etc/munge/munge.key ]; then
        say "creating the munge key /etc/munge/munge.key"
        mkdir -p /etc/munge
        mungekey --create --keyfile=/etc/munge/munge.key
    fi
    chown munge:munge /etc/munge /etc/munge/munge.key
    chmod 0700 /etc/munge
    chmod 0400 /etc/munge/munge.key
    if munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then return 0; fi  # already serving
    mkdir -p /run/munge /var/lib/munge /var/log/munge
    chown munge:munge /run/munge /var/lib/munge /var/log/munge
    chmod 0755 /run/munge
    if ! alive "$pf"; then rm -f "$pf" /run/munge/munge.socket.2 /run/munge/munge.socket.2.lock; fi
    runuser -u munge -- /usr/sbin/munged
    touch "$STATE/munged.ours"  # stop stops munged only when start started it
    local i
    for i in $(seq 1 50); do
        if munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then return 0; fi
        sleep 0.2
    done
    die "munged does not answer (see /var/log/munge/munged.log)"
}

write_conf() {
    local cpus mem
    cpus="$(nproc)"
    mem="$(slurmd -C | sed -n 's/.*RealMemory=\([0-9]*\).*/\1/p' | head -n 1)"
    [ -n "$mem" ] || die "slurmd -C did not report RealMemory"
    mkdir -p /etc/slurm "$STATE/ctld" "$STATE/d"
    cat > "$CONF.tmp" <<EOF
$MARK
# One node: $NODE, $cpus CPUs (nproc), ${mem} MB (slurmd -C). State and logs in $STATE.
ClusterName=study
SlurmctldHost=$NODE(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$STATE/ctld
SlurmdSpoolDir=$STATE/d
SlurmctldPidFile=$STATE/slurmctld.pid
SlurmdPidFile=$STATE/slurmd.pid
SlurmctldLogFile=$STATE/slurmctld.log
SlurmdLogFile=$STATE/slurmd.log
# no cgroups: processes tracked through /proc, no task binding
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
MpiDefault=none
ReturnToService=2
# the node's hardware as configured here, whatever slurmd detects inside a container
SlurmdParameters=config_overrides
# finished jobs stay visible to squeue/scontrol for 5 minutes
MinJobAge=300
KillWait=5
InactiveLimit=0
NodeName=$NODE NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=$PARTITION Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF
    mv "$CONF.tmp" "$CONF"
}

stop_daemons() {
    stop_pidfile "$STATE/slurmd.pid" slurmd
    stop_pidfile "$STATE/slurmctld.pid" slurmctld
}

start() {
    if [ -f "$CONF" ] && ! ours; then
        die "$CONF exists and was not written by this script (a real cluster's?); not touching it"
    fi
    install_packages
    if up; then say "already running: node $NODE $(node_state)"; return 0; fi
    stop_daemons  # leftovers of an earlier start (a daemon that died, stale pid files)
    mkdir -p "$STATE"
    start_munge
    write_conf
    slurmctld
    slurmd -N "$NODE"
    local i st=""
    for i in $(seq 1 "$WAIT"); do
        st="$(node_state)"
        case "$st" in
            idle) say "up: node $NODE idle, partition $PARTITION ($(nproc) CPUs); logs in $STATE"; return 0;;
            down*|drain*|unk*) [ "$i" -gt 5 ] && scontrol update nodename="$NODE" state=resume >/dev/null 2>&1 || true;;
        esac
        sleep 1
    done
    say "node $NODE not idle after ${WAIT} s (state: '${st:-unreachable}'); last lines of the logs:"
    tail -n 20 "$STATE/slurmctld.log" "$STATE/slurmd.log" >&2 2>/dev/null || true
    exit 1
}

stop() {
    if ours; then
        if up; then
            timeout 10 squeue -h -o %A 2>/dev/null | sort -u | xargs -r timeout 10 scancel 2>/dev/null || true
            sleep 1
        fi
    elif [ -f "$CONF" ]; then
        die "$CONF was not written by this script; not touching it"
    fi
    stop_daemons
    if [ -f "$STATE/munged.ours" ]; then stop_pidfile /run/munge/munged.pid munged; fi
    if ours; then rm -f "$CONF"; fi
    rm -rf "$STATE"
    say "stopped"
}

status() {
    if ! ours; then say "not running (no $CONF written by this script)"; return 1; fi
    timeout 10 sinfo 2>&1 || true
    timeout 10 squeue 2>&1 || true
    if up; then return 0; fi
    local d
    for d in slurmctld slurmd; do alive "$STATE/$d.pid" || say "$d is not running"; done
    munge -n 2>/dev/null | unmunge >/dev/null 2>&1 || say "munged does not answer"
    say "node $NODE not taking jobs (state: '$(node_state)')"
    return 1
}

case "${1:-}" in
    start) start;;
    stop) stop;;
    status) status;;
    *) echo "usage: $0 start|stop|status" >&2; exit 2;;
esac
