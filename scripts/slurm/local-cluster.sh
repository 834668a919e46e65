#!/usr/bin/env bash
# local-cluster.sh: run the gpustar Slurm job array end to end on a one-node Slurm cluster
# started here, on localhost, for real (munged + slurmctld + slurmd), then stop it again.
#
#   scripts/slurm/local-cluster.sh
#
# Steps: install slurm-wlm and munge if missing (apt-get, as root); build gpustar (cargo build
# --release) unless GPUSTAR names a binary; start munged, slurmctld and slurmd from a generated
# minimal configuration in a new temporary directory; simulate an archive; submit
# scripts/slurm/gpustar-array.sbatch with sbatch --array=0-(NTASKS-1); wait for it (squeue
# polling, with a timeout); rerun one task to show that --resume skips finished work; merge
# the parts with `gpustar merge --dir` (every input exactly once), and check that a missing
# part is caught; score the merged records with `gpustar evaluate`; print a summary. The
# cluster is shut down on every exit (trap), success or failure.
#
# Everything lives in one temporary directory (/tmp/gpustar-slurm.XXXXXX): configuration, munge
# key and socket, daemon state, spool and logs, the archive, the outputs and gpustar's table
# cache. It is removed after a successful run (KEEP=1 keeps it) and kept after a failure, for
# its logs. The daemons listen on free ports found at start (from 16817 up), and all traffic
# is to 127.0.0.1, so the script can be rerun, or run beside a real Slurm installation. Besides
# installing the packages, nothing outside the temporary directory is written, except the
# repository's own target/ by the cargo build.
#
# Environment (all optional):
#   NTASKS=4          array tasks = shards
#   NFRAMES=400       simulated frames
#   SIZE=512x512      frame size
#   FOV_DEG=18        simulated field of view, degrees
#   TIMEOUT=600       seconds to wait for the cluster and for the array job
#   GPUSTAR=PATH      use this gpustar binary instead of building one
#   KEEP=1            keep the temporary directory after a successful run
set -euo pipefail

NTASKS="${NTASKS:-4}"
NFRAMES="${NFRAMES:-400}"
SIZE="${SIZE:-512x512}"
SIM_FOV_DEG="${FOV_DEG:-18}"
TIMEOUT="${TIMEOUT:-600}"
KEEP="${KEEP:-0}"

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/../.." && pwd)"
SBATCH_SCRIPT="$HERE/gpustar-array.sbatch"

say() { printf '==> %s\n' "$*"; }
info() { printf '    %s\n' "$*"; }
die() {
    printf 'local-cluster: FAILED: %s\n' "$*" >&2
    exit 1
}

[[ "$NTASKS" =~ ^[1-9][0-9]*$ ]] || die "NTASKS must be a positive integer, not '$NTASKS'"
[[ -f "$SBATCH_SCRIPT" ]] || die "missing $SBATCH_SCRIPT"

# --- 1. Packages ---------------------------------------------------------------------------
say "Packages: slurm-wlm, munge"
missing=()
for cmd in munged mungekey munge unmunge slurmctld slurmd sbatch squeue scontrol sinfo scancel; do
    command -v "$cmd" >/dev/null 2>&1 || missing+=("$cmd")
done
if ((${#missing[@]})); then
    info "missing: ${missing[*]}"
    if [[ $(id -u) != 0 ]] || ! command -v apt-get >/dev/null; then
        die "install them first: sudo apt-get install -y slurm-wlm munge"
    fi
    info "apt-get update && apt-get install -y slurm-wlm munge"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge >/dev/null
fi
[[ $(id -u) == 0 ]] || die "run as root: slurmd runs job steps as the submitting user and must be root"
info "$(slurmctld -V), $(munged -V 2>&1 | head -n1)"

# --- 2. The temporary directory, and shutting everything down on exit -----------------------
WORK="$(mktemp -d /tmp/gpustar-slurm.XXXXXX)"
# munged requires every directory above its socket to be searchable by all, and the key's
# directory writable by its owner only.
chmod 711 "$WORK"
mkdir -p "$WORK"/{bin,munge,slurm/state,slurm/spool,slurm/log,archive,out,logs,cache,xdg}
chmod 711 "$WORK/munge"
CONF="$WORK/slurm/slurm.conf"
MUNGE_SOCK="$WORK/munge/munged.sock"
MUNGED_PID="" CTLD_PID="" SLURMD_PID="" JOBID="" JOBID2=""

# The client commands and the daemons read this configuration, nothing in /etc/slurm.
export SLURM_CONF="$CONF"
# A run inside a Slurm allocation, or with SBATCH_* defaults set, must not leak into ours.
while read -r v; do unset "$v"; done < <(compgen -e | grep -E '^(SLURM_|SBATCH_|SQUEUE_)' | grep -vx SLURM_CONF || true)

stop_pid() { # stop a daemon this script started: TERM, then KILL after 15 s
    local pid="$1" i
    [[ -n "$pid" ]] && kill -0 "$pid" 2>/dev/null || return 0
    kill -TERM "$pid" 2>/dev/null || true
    for ((i = 0; i < 30; i++)); do
        kill -0 "$pid" 2>/dev/null || break
        sleep 0.5
    done
    if kill -0 "$pid" 2>/dev/null; then kill -KILL "$pid" 2>/dev/null; fi
    wait "$pid" 2>/dev/null || true
}

cleanup() {
    local rc=$? i
    set +e
    trap - EXIT INT TERM
    echo "==> Shutting the cluster down"
    # Cancel what is still queued or running, so no job step outlives slurmd.
    if [[ -n "$CTLD_PID" ]] && kill -0 "$CTLD_PID" 2>/dev/null; then
        for j in $JOBID $JOBID2; do scancel "$j" 2>/dev/null; done
        for ((i = 0; i < 30; i++)); do
            [[ -z "$(squeue -h -o %i 2>/dev/null)" ]] && break
            sleep 1
        done
    fi
    stop_pid "$SLURMD_PID"
    stop_pid "$CTLD_PID"
    stop_pid "$MUNGED_PID"
    echo "    slurmd, slurmctld and munged stopped"
    if ((rc != 0)); then
        for f in "$WORK"/slurm/log/*.log "$WORK"/logs/*.log; do
            [[ -s "$f" ]] || continue
            echo "---- last lines of $f"
            tail -n 15 "$f"
        done
        echo "local-cluster: FAILED (exit $rc); logs and outputs kept in $WORK" >&2
    elif [[ "$KEEP" == 1 ]]; then
        echo "    kept $WORK"
    else
        rm -rf "$WORK"
        echo "    removed $WORK"
    fi
    ((rc != 0)) || echo "local-cluster: OK"
    exit "$rc"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

# --- 3. gpustar ----------------------------------------------------------------------------
say "gpustar binary"
if [[ -n "${GPUSTAR:-}" ]]; then
    BIN="$GPUSTAR"
else
    BIN="$REPO/target/release/gpustar"
    if command -v cargo >/dev/null; then
        info "cargo build --release (in $REPO)"
        if ! (cd "$REPO" && cargo build --release --quiet); then
            [[ -x "$BIN" ]] || die "cargo build failed and there is no $BIN"
            info "WARNING: cargo build failed; using the existing $BIN"
        fi
    fi
fi
[[ -x "$BIN" ]] || die "no gpustar binary at $BIN (build it, or set GPUSTAR=/path/to/gpustar)"
# A private copy: a rebuild during the run does not change the binary under the jobs.
cp "$BIN" "$WORK/bin/gpustar"
GS="$WORK/bin/gpustar"
# gpustar's distance-table cache and the Vulkan driver's runtime directory stay in $WORK.
export GPUSTAR_CACHE_DIR="$WORK/cache" XDG_RUNTIME_DIR="$WORK/xdg"
chmod 700 "$XDG_RUNTIME_DIR"
info "$BIN -> $GS"

# --- 4. munge ------------------------------------------------------------------------------
say "munged (key and socket in $WORK/munge)"
mungekey --create --keyfile="$WORK/munge/munge.key"
munged --foreground \
    --key-file="$WORK/munge/munge.key" \
    --socket="$MUNGE_SOCK" \
    --pid-file="$WORK/munge/munged.pid" \
    --log-file="$WORK/munge/munged.log" \
    --seed-file="$WORK/munge/munged.seed" \
    >"$WORK/slurm/log/munged.log" 2>&1 &
MUNGED_PID=$!
for ((i = 0; ; i++)); do
    kill -0 "$MUNGED_PID" 2>/dev/null || die "munged exited (see $WORK/slurm/log/munged.log)"
    [[ -S "$MUNGE_SOCK" ]] && munge -n -S "$MUNGE_SOCK" | unmunge -S "$MUNGE_SOCK" >/dev/null 2>&1 && break
    ((i < 40)) || die "munged did not answer within 20 s"
    sleep 0.5
done
info "munged pid $MUNGED_PID: a credential encodes and decodes"

# --- 5. slurm.conf -------------------------------------------------------------------------
port_busy() { (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null; }
CTLD_PORT=16817
while port_busy "$CTLD_PORT" || port_busy "$((CTLD_PORT + 1))"; do
    CTLD_PORT=$((CTLD_PORT + 2))
    ((CTLD_PORT < 17817)) || die "no free port pair in 16817-17817"
done
SLURMD_PORT=$((CTLD_PORT + 1))
# This machine's CPUs, sockets, cores and memory as slurmd sees them (it refuses a node
# configured with more than it has).
HW="$(slurmd -C | head -n1 | sed -E 's/^NodeName=[^ ]+ //')"
say "slurm.conf: one node 'localhost' ($HW), ports $CTLD_PORT/$SLURMD_PORT"
cat >"$CONF" <<EOF
# Generated by scripts/slurm/local-cluster.sh: a one-node cluster on localhost.
ClusterName=gpustar-local
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
SlurmUser=root
SlurmdUser=root
# munge authentication through our own munged's socket.
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$MUNGE_SOCK
# State, spool, pid and log files in the temporary directory.
StateSaveLocation=$WORK/slurm/state
SlurmdSpoolDir=$WORK/slurm/spool
SlurmctldPidFile=$WORK/slurm/slurmctld.pid
SlurmdPidFile=$WORK/slurm/slurmd.pid
SlurmctldLogFile=$WORK/slurm/log/slurmctld.log
SlurmdLogFile=$WORK/slurm/log/slurmd.log
PlugStackConfig=$WORK/slurm/plugstack.conf
MailProg=/bin/true
# No cgroups, accounting database or MPI: processes are tracked by their parent ids.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
# Schedule individual CPUs, so array tasks of 1 CPU share the node.
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
ReturnToService=2
# Finished jobs stay visible to scontrol for an hour (there is no accounting for sacct).
MinJobAge=3600
KillWait=10
NodeName=localhost NodeAddr=127.0.0.1 $HW State=UNKNOWN
PartitionName=local Nodes=localhost Default=YES MaxTime=INFINITE State=UP
EOF
: >"$WORK/slurm/plugstack.conf"

# --- 6. slurmctld and slurmd ---------------------------------------------------------------
say "slurmctld and slurmd"
slurmctld -D -f "$CONF" >"$WORK/slurm/log/slurmctld.out" 2>&1 &
CTLD_PID=$!
for ((i = 0; ; i++)); do
    kill -0 "$CTLD_PID" 2>/dev/null || die "slurmctld exited (see $WORK/slurm/log/slurmctld.log)"
    scontrol ping 2>/dev/null | grep -q 'is UP' && break
    ((i < 2 * TIMEOUT)) || die "slurmctld did not answer within $TIMEOUT s"
    sleep 0.5
done
info "slurmctld pid $CTLD_PID: $(scontrol ping | head -n1)"
slurmd -D -N localhost -f "$CONF" >"$WORK/slurm/log/slurmd.out" 2>&1 &
SLURMD_PID=$!
for ((i = 0; ; i++)); do
    kill -0 "$SLURMD_PID" 2>/dev/null || die "slurmd exited (see $WORK/slurm/log/slurmd.log)"
    state="$(sinfo -h -N -n localhost -o %T 2>/dev/null || true)"
    [[ "$state" == idle ]] && break
    ((i < 2 * TIMEOUT)) || die "node not idle within $TIMEOUT s (state: $state)"
    sleep 0.5
done
info "slurmd pid $SLURMD_PID"
sinfo | sed 's/^/    /'

# --- 7. The archive ------------------------------------------------------------------------
ARCHIVE_DIR="$WORK/archive"
say "Simulating $NFRAMES frames of $SIZE, ${SIM_FOV_DEG} deg field of view"
"$GS" simulate --out "$ARCHIVE_DIR" -n "$NFRAMES" --fov-deg "$SIM_FOV_DEG" --size "$SIZE" 2>&1 |
    sed 's/^/    /'

# --- 8. The job array ----------------------------------------------------------------------
# The job's parameters (gpustar-array.sbatch reads them; sbatch exports this environment).
unset NSHARDS FOV_DEG MAG_LIMIT RECURSIVE QUIET GPUSTAR_EXTRA_ARGS THREADS
export ARCHIVE="$ARCHIVE_DIR" OUT="$WORK/out" CAMERA="$ARCHIVE_DIR/camera.toml" \
    BACKEND=cpu GPUSTAR="$GS"
SBATCH_OPTS=(--parsable --cpus-per-task=1 --mem=512M --time=00:15:00
    --chdir="$WORK" --output="$WORK/logs/gpustar-%A_%a.log")
say "sbatch --array=0-$((NTASKS - 1)) $(basename "$SBATCH_SCRIPT")"
JOBID="$(sbatch "${SBATCH_OPTS[@]}" --array="0-$((NTASKS - 1))" "$SBATCH_SCRIPT")"
JOBID="${JOBID%%;*}"
info "array job $JOBID: $NTASKS tasks"

say "Waiting for job $JOBID (squeue every 2 s, timeout $TIMEOUT s)"
start=$SECONDS
last=""
while :; do
    now="$(squeue -h -r -j "$JOBID" -o %T 2>/dev/null | sort | uniq -c |
        awk '{s = s (s ? " " : "") $2 "=" $1} END {print s}')"
    if [[ -z "$now" ]]; then
        info "t=$((SECONDS - start))s all tasks left the queue"
        break
    fi
    [[ "$now" != "$last" ]] && info "t=$((SECONDS - start))s $now"
    last="$now"
    ((SECONDS - start < TIMEOUT)) || die "job $JOBID still queued after $TIMEOUT s"
    sleep 2
done

# The final state and exit code of every task, from slurmctld (MinJobAge keeps them).
say "Tasks"
declare -A STATE
while read -r line; do
    [[ "$line" =~ ArrayTaskId=([0-9]+) ]] || continue
    k="${BASH_REMATCH[1]}"
    [[ "$line" =~ JobState=([A-Z_]+) ]] && st="${BASH_REMATCH[1]}"
    [[ "$line" =~ ExitCode=([0-9:]+) ]] && ec="${BASH_REMATCH[1]}"
    STATE[$k]="$st exit $ec"
done < <(scontrol show job -o "$JOBID")
ok_tasks=0
PARTS=()
COUNTS=()
total=0
for ((k = 0; k < NTASKS; k++)); do
    part="$OUT/part-$k.jsonl"
    n=0
    [[ -f "$part" ]] && n=$(wc -l <"$part")
    PARTS+=("$part")
    COUNTS+=("part-$k=$n")
    total=$((total + n))
    info "task $k: ${STATE[$k]:-unknown}, $n records in part-$k.jsonl"
    [[ "${STATE[$k]:-}" == "COMPLETED exit 0:0" ]] && ok_tasks=$((ok_tasks + 1))
done
for k in 0 "$((NTASKS - 1))"; do
    sed 's/^/      | /' "$WORK/logs/gpustar-${JOBID}_$k.log"
    ((NTASKS > 1)) || break
done
((ok_tasks == NTASKS)) || die "$((NTASKS - ok_tasks)) of $NTASKS tasks did not complete with exit 0"

# --- 9. Requeue: --resume continues instead of redoing -------------------------------------
# Task 0 again, as a requeued or resubmitted task would run: its part is complete, so gpustar
# solves nothing and appends nothing. NSHARDS keeps N when only some indices are submitted.
say "Rerunning task 0 alone (NSHARDS=$NTASKS sbatch --array=0 --wait): --resume skips finished inputs"
before=$(wc -l <"$OUT/part-0.jsonl")
JOBID2="$(NSHARDS="$NTASKS" timeout "$TIMEOUT" sbatch "${SBATCH_OPTS[@]}" --wait --array=0 "$SBATCH_SCRIPT")" ||
    die "rerun of task 0 failed"
JOBID2="${JOBID2%%;*}"
after=$(wc -l <"$OUT/part-0.jsonl")
resumed="$(grep -o 'resuming: .*' "$WORK/logs/gpustar-${JOBID2}_0.log" || true)"
info "job $JOBID2: $resumed; part-0.jsonl $before -> $after records"
((before == after)) || die "the rerun changed part-0.jsonl"

# --- 10. Merge and verify ------------------------------------------------------------------
MERGED="$WORK/results.jsonl"
say "gpustar merge part-0..$((NTASKS - 1)).jsonl --dir archive -o results.jsonl"
set +e
merge_msg="$("$GS" merge "${PARTS[@]}" --dir "$ARCHIVE_DIR" -o "$MERGED" 2>&1)"
merge_rc=$?
set -e
info "$merge_msg"
info "exit $merge_rc"
((merge_rc == 0)) || die "gpustar merge did not verify the parts (exit $merge_rc)"
merged=$(wc -l <"$MERGED")
inputs=$(find "$ARCHIVE_DIR" -maxdepth 1 -type f -name '*.png' | wc -l)
((merged == inputs)) || die "merged $merged records for $inputs inputs"

control="skipped (one task)"
if ((NTASKS > 1)); then
    say "Negative control: merge without part-0 must fail with exit 2"
    set +e
    neg_msg="$("$GS" merge "${PARTS[@]:1}" --dir "$ARCHIVE_DIR" -o "$WORK/incomplete.jsonl" 2>&1)"
    neg_rc=$?
    set -e
    info "${neg_msg:0:300}"
    info "exit $neg_rc"
    ((neg_rc == 2)) || die "merge of an incomplete set exited $neg_rc, not 2"
    control="merge without part-0 -> exit 2 (missing inputs detected)"
fi

# --- 11. Score -----------------------------------------------------------------------------
say "gpustar evaluate --truth archive/truth.jsonl results.jsonl"
eval_out="$("$GS" evaluate --truth "$ARCHIVE_DIR/truth.jsonl" "$MERGED" 2>&1)"
while IFS= read -r l; do info "$l"; done <<<"$eval_out"

# --- 12. Summary ---------------------------------------------------------------------------
say "Summary"
info "cluster          : 1 node (localhost), slurmctld :$CTLD_PORT, slurmd :$SLURMD_PORT, munge"
info "array job        : $JOBID, sbatch --array=0-$((NTASKS - 1)): $ok_tasks/$NTASKS tasks COMPLETED, exit 0"
info "records per part : ${COUNTS[*]} (sum $total)"
info "requeue/resume   : task 0 rerun: ${resumed:-?}, part unchanged ($after records)"
info "merged           : $merged records for $inputs inputs -> results.jsonl"
info "verification     : OK: gpustar merge --dir: every input exactly once (exit 0); $control"
# The headline numbers of evaluate's JSON: "key": value -> key=value.
score="$(grep -Eo '"(frames|solved|correct|wrong|unsolved|errors|missing|median_error_arcsec)": [0-9.]+' \
    <<<"$eval_out" | sed -E 's/"([a-z_0-9]+)": ([0-9]+(\.[0-9])?)[0-9]*/\1=\2/' | paste -sd ' ' -)"
info "evaluate         : $score"
