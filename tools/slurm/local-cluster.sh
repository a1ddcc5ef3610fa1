#!/usr/bin/env bash
# A one-node Slurm cluster on this machine, for the sweep's tests and for trying a sweep
# (docs/cluster.md): Debian's slurmctld, slurmd, slurm-client and munge, on 127.0.0.1, as root.
#
#   tools/slurm/local-cluster.sh start   # installs what is missing, starts, waits for the node
#   tools/slurm/local-cluster.sh stop    # stops only the daemons this script started
#   tools/slurm/local-cluster.sh status
#
# Its files (slurm.conf, state, logs, pids) live in $CELLFLIP_SLURM_DIR (default
# /tmp/cellflip-slurm); clients find the cluster through SLURM_CONF=$CELLFLIP_SLURM_DIR/slurm.conf,
# which `start` prints. Nothing under /etc/slurm is written. Debian's packages do not start
# their services on install here, so the daemons are started by hand; munged runs as user munge.
set -euo pipefail
dir=${CELLFLIP_SLURM_DIR:-/tmp/cellflip-slurm}
conf=$dir/slurm.conf
export SLURM_CONF=$conf

say() { echo "local-cluster: $*" >&2; }

install() {
    local missing=()
    for bin in slurmctld slurmd sbatch munged; do
        command -v "$bin" >/dev/null 2>&1 || missing+=("$bin")
    done
    [ ${#missing[@]} -eq 0 ] && return 0
    say "installing slurmctld slurmd slurm-client munge (missing: ${missing[*]})"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends slurmctld slurmd slurm-client munge >/dev/null
}

write_conf() {
    local host node
    host=$(hostname -s)
    # The node as slurmd sees it (CPUs, memory), named after this host, reached on loopback.
    node=$(slurmd -C | head -n 1 | sed "s/^NodeName=[^ ]*/NodeName=$host NodeAddr=127.0.0.1/")
    mkdir -p "$dir/ctld" "$dir/d"
    cat >"$conf" <<EOF
ClusterName=cellflip
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
# A requeued job waits for its old credential to expire before it runs again (120 s by
# default); a local cluster for tests waits 10.
AuthInfo=cred_expire=10
SlurmctldPort=6817
SlurmdPort=6818
StateSaveLocation=$dir/ctld
SlurmdSpoolDir=$dir/d
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
# Without a default, a job takes the whole node's memory and jobs run one at a time.
DefMemPerCPU=1000
SchedulerType=sched/backfill
SchedulerParameters=sched_interval=2
ReturnToService=2
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
# Between the SIGTERM of a time limit, a cancel or a requeue and the SIGKILL (30 s by default).
# A task stopped by its limit must write its checkpoint and requeue itself within it: half the
# default here shows that this takes seconds (6 s at most seen, on 2 cores four times
# oversubscribed), not the whole half minute.
KillWait=15
MinJobAge=600
$node State=UNKNOWN
PartitionName=local Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
}

alive() { [ -f "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null; }

start_munge() {
    if [ -S /run/munge/munge.socket.2 ] && munge -n </dev/null >/dev/null 2>&1; then
        return 0 # a munged is already serving; not ours to start or stop
    fi
    mkdir -p /run/munge "$dir"
    chown munge:munge /run/munge
    [ -f /etc/munge/munge.key ] || { mungekey --create 2>/dev/null || /usr/sbin/create-munge-key -f; }
    runuser -u munge -- /usr/sbin/munged --pid-file=/run/munge/munged.pid
    cp /run/munge/munged.pid "$dir/munged.pid"
}

start() {
    install
    write_conf
    start_munge
    alive "$dir/slurmctld.pid" || slurmctld -f "$conf"
    alive "$dir/slurmd.pid" || slurmd -f "$conf" -N "$(hostname -s)"
    for _ in $(seq 1 60); do
        if sinfo -h -o '%t' 2>/dev/null | grep -qE '^(idle|mix|alloc)'; then
            say "up: $(sinfo -h -o '%N %c CPUs %m MB %t')"
            echo "export SLURM_CONF=$conf"
            return 0
        fi
        scontrol update nodename="$(hostname -s)" state=resume >/dev/null 2>&1 || true
        sleep 0.5
    done
    say "the node did not come up; see $dir/slurmctld.log and $dir/slurmd.log"
    return 1
}

stop() {
    for d in slurmd slurmctld munged; do
        if alive "$dir/$d.pid"; then
            kill "$(cat "$dir/$d.pid")" || true
            say "stopped $d"
        fi
        rm -f "$dir/$d.pid"
    done
}

case "${1:-}" in
start) start ;;
stop) stop ;;
status) sinfo && squeue ;;
*)
    echo "usage: $0 start|stop|status" >&2
    exit 2
    ;;
esac
