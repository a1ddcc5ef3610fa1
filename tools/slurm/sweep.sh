#!/usr/bin/env bash
# `cellflip report` as a Slurm sweep (docs/cluster.md): one array task per job of the plan, with
# --mem from the job's memory estimate and --time from its estimated cost, and a merge job that
# runs after the arrays.
#
#   tools/slurm/sweep.sh --out DIR [--only REGEX] [report's matrix options...]
#   e.g. tools/slurm/sweep.sh --out sweep --scenes dam-2d,dam-3d --res 50,100
#        tools/slurm/sweep.sh --out paper --only '^(dam-3d|[a-z0-9-]*-2d)-' --matrix paper
#
# --only submits only the jobs whose id matches the extended regular expression (e.g. what fits
# a small cluster); the merge lists the others as missing, with their estimates.
# Prints the merge job's id last. Jobs with the same memory and time request share an array.
# Each task runs with --signal=B:USR1@$CELLFLIP_SIGNAL_SECS --requeue: near its time limit it
# stops its run with a checkpoint (SIGTERM to cellflip) and requeues itself, and the requeued
# task goes on from that checkpoint; its log line says SLURM_RESTART_COUNT. A task requeued by
# Slurm (preemption, `scontrol requeue`) gets SIGTERM and does the same. A task that reaches
# its time limit all the same (no warning, or one too late) gets SIGTERM too, writes its
# checkpoint within KillWait and requeues itself: Slurm ends a timed-out task for good.
#
# Environment: CELLFLIP (the binary, default `cellflip` on the PATH), CELLFLIP_CPUS (CPUs per
# task, default 2: the cost model's threads), CELLFLIP_SIGNAL_SECS (default 120; 0: no warning
# signal, the limit's SIGTERM only), CELLFLIP_TIME_MARGIN (time limit over the estimate,
# default 3), CELLFLIP_TIME_MINUTES (every task's time limit in minutes instead of the
# estimate's, e.g. 1, with CELLFLIP_SIGNAL_SECS=0, to see a real limit expire), SBATCH_EXTRA
# (more sbatch options, e.g. a partition or an account). Slurm may send the warning up to a
# minute early, so a limit not above the signal's lead time and a minute is refused: the
# warning could come at once, each time the task ran, and the task would never get far.
set -euo pipefail
cellflip=${CELLFLIP:-cellflip}
cpus=${CELLFLIP_CPUS:-2}
signal_secs=${CELLFLIP_SIGNAL_SECS:-120}
margin=${CELLFLIP_TIME_MARGIN:-3}
time_minutes=${CELLFLIP_TIME_MINUTES:-}
if [ -n "$time_minutes" ] && ! [[ $time_minutes =~ ^[1-9][0-9]*$ ]]; then
    echo "$0: CELLFLIP_TIME_MINUTES must be a whole number of minutes, not '$time_minutes'" >&2
    exit 2
fi

out=
only=
matrix=()
while [ $# -gt 0 ]; do
    case "$1" in
    --out) out=$2; shift 2 ;;
    --out=*) out=${1#--out=}; shift ;;
    --only) only=$2; shift 2 ;;
    --only=*) only=${1#--only=}; shift ;;
    *) matrix+=("$1"); shift ;;
    esac
done
[ -n "$out" ] || { echo "usage: $0 --out DIR [--only REGEX] [report's matrix options...]" >&2; exit 2; }
mkdir -p "$out/slurm/logs"
out=$(cd "$out" && pwd)
cellflip=$(command -v "$cellflip")

"$cellflip" report "${matrix[@]}" --plan >"$out/slurm/plan.txt"

# One task script for every array: it picks its job from its array's list of ids.
task=$out/slurm/task.sh
{
    echo '#!/usr/bin/env bash'
    printf 'cellflip=%q\nout=%q\n' "$cellflip" "$out"
    printf 'matrix=('; printf '%q ' "${matrix[@]}"; printf ')\n'
    cat <<'EOF'
id=$(sed -n "${SLURM_ARRAY_TASK_ID}p" "$1")
echo "cellflip job $id: task ${SLURM_ARRAY_JOB_ID}_${SLURM_ARRAY_TASK_ID}, SLURM_RESTART_COUNT=${SLURM_RESTART_COUNT:-0}"
export RAYON_NUM_THREADS=${SLURM_CPUS_PER_TASK:-2}
"$cellflip" report "${matrix[@]}" --out "$out" --job "$id" &
pid=$!
me=${SLURM_ARRAY_JOB_ID}_${SLURM_ARRAY_TASK_ID}
near_limit() {
    echo "cellflip job $id: near the time limit: checkpoint, then requeue"
    kill -TERM "$pid"
    wait "$pid"
    scontrol requeue "$me"
    exit 0
}
# Stopped by Slurm: cellflip has its own SIGTERM (a second one would end it before its
# checkpoint), so wait for it. Cancelled, requeued or preempted, that is all. Stopped by the
# time limit itself (no warning asked for, or it came too late), the task would end TIMEOUT,
# which --requeue does not requeue, and the merge would list its job as missing: requeue it,
# before KillWait runs out (Slurm takes a requeue while the task is completing).
stopped() {
    wait "$pid"
    if scontrol show job "$me" | grep -qw 'Reason=TimeLimit'; then
        echo "cellflip job $id: stopped by the time limit: checkpoint written, requeue"
        scontrol requeue "$me"
        exit 0
    fi
    exit 143
}
trap near_limit USR1
trap stopped TERM
wait "$pid"
EOF
} >"$task"
chmod +x "$task"

# Jobs grouped by their request: memory in 256 MiB steps (the estimate and a quarter, at
# least 512), time in minutes (the estimate times the margin and 5 minutes, a power of two).
declare -A lists
while read -r id rest; do
    read -r -a f <<<"$rest"
    n=${#f[@]}
    mib=${f[$((n - 4))]}
    cpu_s=${f[$((n - 1))]}
    mem=$(awk -v m="$mib" 'BEGIN { r = int(m * 1.25 / 256 + 1) * 256; print (r < 512 ? 512 : r) }')
    # cpu_s is wall seconds on 2 threads times 2: wall seconds on p CPUs are about cpu_s / p.
    minutes=${time_minutes:-$(awk -v c="$cpu_s" -v k="$margin" -v p="$cpus" 'BEGIN {
        t = c / p * k / 60 + 5; m = 8; while (m < t) m *= 2; print m }')}
    key="${mem}M-${minutes}min"
    lists[$key]+="$id"$'\n'
done < <(grep -v '^#' "$out/slurm/plan.txt" | grep -E -- "${only:-.}" || true)
[ -n "${lists[*]+x}" ] || { echo "$0: no job of the plan matches --only '$only'" >&2; exit 2; }
signal=()
if [ "$signal_secs" != 0 ]; then
    signal=(--signal="B:USR1@$signal_secs")
    for key in "${!lists[@]}"; do
        minutes=${key#*-}
        minutes=${minutes%min}
        if [ $((minutes * 60)) -le $((signal_secs + 60)) ]; then
            echo "$0: a time limit of $minutes min leaves no time before the warning" \
                "(CELLFLIP_SIGNAL_SECS=$signal_secs, which Slurm may send up to 60 s early);" \
                "set CELLFLIP_SIGNAL_SECS=0 or a longer limit" >&2
            exit 2
        fi
    done
fi

arrays=()
for key in "${!lists[@]}"; do
    ids=$out/slurm/$key.ids
    printf '%s' "${lists[$key]}" >"$ids"
    n=$(wc -l <"$ids")
    mem=${key%%-*}
    minutes=${key#*-}
    minutes=${minutes%min}
    # shellcheck disable=SC2086
    jid=$(sbatch --parsable --job-name="cellflip-$key" --array="1-$n" --mem="$mem" \
        --time="$minutes" --cpus-per-task="$cpus" ${signal[@]+"${signal[@]}"} --requeue \
        --output="$out/slurm/logs/%A_%a.out" --open-mode=append ${SBATCH_EXTRA:-} "$task" "$ids")
    echo "array $jid: $n jobs, --mem=$mem --time=${minutes} min" >&2
    arrays+=("$jid")
done

deps=$(IFS=:; echo "${arrays[*]}")
# shellcheck disable=SC2086
merge=$(sbatch --parsable --job-name=cellflip-merge --dependency="afterany:$deps" --mem=1G \
    --time=30 --output="$out/slurm/logs/merge-%j.out" ${SBATCH_EXTRA:-} \
    --wrap="$(printf '%q ' "$cellflip" report "${matrix[@]}" --merge "$out")")
echo "merge job $merge runs after the arrays ($deps); the report goes to $out" >&2
echo "$merge"
