#!/usr/bin/env bash
# Sets up a single-node Slurm cluster on this machine (Debian 12), for running benchmark
# suites as job arrays (scripts/slurm/run-suite-array.sh) and for CI (scripts/slurm/test-slurm.sh).
#
#   sudo scripts/slurm/setup-slurm.sh
#
# What it does, each step skipped when already done (a second run is a fast no-op):
#   1. apt-get installs Debian's slurm-wlm (slurmctld, slurmd, client tools) and munge;
#   2. creates the munge key /etc/munge/munge.key if missing;
#   3. writes /etc/slurm/slurm.conf: this host (short hostname, address 127.0.0.1) is both the
#      controller and the only compute node, with the CPUs and memory `slurmd -C` reports;
#      select/cons_tres (CR_Core), proctrack/linuxproc and task/none (no cgroups needed), no
#      accounting; state under /var/lib/slurm, logs under /var/log/slurm;
#   4. starts munged, slurmctld and slurmd directly (no systemd: this also works in a
#      container), restarting the Slurm daemons if the configuration changed;
#   5. waits (up to SLURM_SETUP_TIMEOUT seconds, default 60) until `sinfo` shows the node up.
#
# Needs root. Writes only system files (/etc/slurm, /etc/munge, /var/lib/slurm, /var/log/slurm,
# /run/munge) and, while apt runs, a temporary /usr/sbin/policy-rc.d so that package scripts do
# not try to start the daemons themselves.
set -euo pipefail

TIMEOUT=${SLURM_SETUP_TIMEOUT:-60}
CONF_DIR=/etc/slurm
CONF=$CONF_DIR/slurm.conf
STATE_DIR=/var/lib/slurm
LOG_DIR=/var/log/slurm

say() { echo "setup-slurm: $*"; }
die() { echo "setup-slurm: error: $*" >&2; exit 1; }

[[ $(id -u) -eq 0 ]] || die "must run as root (it installs packages and starts system daemons)"
start_time=$SECONDS

# --- 1. packages -------------------------------------------------------------------------
PACKAGES=(slurm-wlm slurmctld slurmd slurm-client munge)
missing=()
for p in "${PACKAGES[@]}"; do
    if [[ $(dpkg-query -W -f='${Status}' "$p" 2>/dev/null) != "install ok installed" ]]; then
        missing+=("$p")
    fi
done
if ((${#missing[@]})); then
    say "installing ${missing[*]} (apt-get)"
    export DEBIAN_FRONTEND=noninteractive
    # Package scripts would try to start the daemons (through invoke-rc.d) before the
    # configuration exists; forbid that while apt runs, as container images usually do.
    policy=/usr/sbin/policy-rc.d
    created_policy=0
    if [[ ! -e $policy ]]; then
        printf '#!/bin/sh\nexit 101\n' >"$policy"
        chmod 755 "$policy"
        created_policy=1
        trap 'if [[ $created_policy -eq 1 ]]; then rm -f "$policy"; fi' EXIT
    fi
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends slurm-wlm munge >/dev/null
    if [[ $created_policy -eq 1 ]]; then
        rm -f "$policy"
        created_policy=0
    fi
    say "installed: $(dpkg-query -W -f='${Package} ${Version}, ' "${PACKAGES[@]}" | sed 's/, $//')"
else
    say "packages already installed ($(dpkg-query -W -f='${Version}' slurm-wlm))"
fi
for cmd in munged munge unmunge slurmctld slurmd sinfo sbatch squeue scontrol; do
    command -v "$cmd" >/dev/null || die "'$cmd' not found after installing slurm-wlm and munge"
done
id munge >/dev/null 2>&1 || die "the munge package did not create the user 'munge'"
id slurm >/dev/null 2>&1 || die "the slurm packages did not create the user 'slurm'"

# --- 2. munge key ------------------------------------------------------------------------
KEY=/etc/munge/munge.key
if [[ ! -s $KEY ]]; then
    say "creating the munge key $KEY"
    install -d -o munge -g munge -m 0700 /etc/munge
    if command -v mungekey >/dev/null; then
        mungekey --create --keyfile="$KEY" --force
    else
        dd if=/dev/urandom of="$KEY" bs=1024 count=1 status=none
    fi
    chown munge:munge "$KEY"
    chmod 0400 "$KEY"
fi

# --- 3. slurm.conf -----------------------------------------------------------------------
NODE=$(hostname -s)
[[ -n $NODE ]] || die "hostname -s printed nothing"
# `slurmd -C` prints e.g. "NodeName=h CPUs=2 Boards=1 SocketsPerBoard=1 CoresPerSocket=2
# ThreadsPerCore=1 RealMemory=24105" and an "UpTime=..." line; keep the node line.
hw=$(slurmd -C 2>/dev/null | grep '^NodeName=' | head -n 1) ||
    die "'slurmd -C' did not report this machine's hardware"
hw=${hw#NodeName=* }   # the fields after the node name
for field in CPUs RealMemory; do
    [[ " $hw " == *" $field="* ]] || die "'slurmd -C' output lacks $field: $hw"
done

conf_new=$(mktemp)
trap 'rm -f "$conf_new"' EXIT
cat >"$conf_new" <<EOF
# Single-node Slurm cluster written by scripts/slurm/setup-slurm.sh (rerun it to regenerate).
ClusterName=simbench
SlurmctldHost=$NODE(127.0.0.1)
SlurmUser=slurm
SlurmctldPort=6817
SlurmdPort=6818
AuthType=auth/munge
StateSaveLocation=$STATE_DIR/slurmctld
SlurmdSpoolDir=$STATE_DIR/slurmd
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
SlurmctldLogFile=$LOG_DIR/slurmctld.log
SlurmdLogFile=$LOG_DIR/slurmd.log
# No cgroups (containers often lack a writable cgroup hierarchy): track processes by their
# parent ids and bind no tasks.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
MpiDefault=none
# No mail server: job mail would only log errors.
MailProg=/bin/true
SwitchType=switch/none
# No accounting database: sacct does not work, squeue/scontrol do.
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
# A node that was down (e.g. the daemons restarted) comes back as soon as it registers.
ReturnToService=2
SlurmdTimeout=300
InactiveLimit=0
KillWait=30
MinJobAge=300
Waittime=0
NodeName=$NODE NodeAddr=127.0.0.1 $hw State=UNKNOWN
PartitionName=main Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF

conf_changed=0
if [[ -f $CONF ]] && cmp -s "$conf_new" "$CONF"; then
    say "$CONF is up to date (node $NODE: $hw)"
else
    [[ -f $CONF ]] && cp "$CONF" "$CONF.bak" && say "previous configuration saved as $CONF.bak"
    install -d -m 0755 "$CONF_DIR"
    install -m 0644 "$conf_new" "$CONF"
    conf_changed=1
    say "wrote $CONF (node $NODE: $hw)"
fi
install -d -o slurm -g slurm -m 0755 "$STATE_DIR" "$STATE_DIR/slurmctld" "$LOG_DIR"
install -d -o root -g root -m 0755 "$STATE_DIR/slurmd"

# --- 4. daemons --------------------------------------------------------------------------
# Waits up to $2 seconds for a process named $1.
wait_pid() {
    local name=$1 secs=$2 i
    for ((i = 0; i < secs * 10; i++)); do
        pidof "$name" >/dev/null && return 0
        sleep 0.1
    done
    return 1
}
# Stops the daemon named $1 (only the pids pidof reports for that exact executable).
stop_daemon() {
    local name=$1 pids i
    pids=$(pidof "$name") || return 0
    say "stopping $name (pid $pids)"
    # shellcheck disable=SC2086 # one word per pid
    kill $pids
    for ((i = 0; i < 100; i++)); do
        pidof "$name" >/dev/null || return 0
        sleep 0.1
    done
    die "$name (pid $pids) did not stop within 10 s"
}

if pidof munged >/dev/null; then
    say "munged already running (pid $(pidof munged))"
else
    install -d -o munge -g munge -m 0755 /run/munge
    install -d -o munge -g munge -m 0700 /var/lib/munge /var/log/munge
    say "starting munged"
    runuser -u munge -- munged || die "munged failed to start; see /var/log/munge/munged.log"
    wait_pid munged 10 || die "munged is not running; see /var/log/munge/munged.log"
fi
munge -n | unmunge >/dev/null || die "munge credentials do not round-trip (munge -n | unmunge)"

if ((conf_changed)); then
    stop_daemon slurmd
    stop_daemon slurmctld
fi
if pidof slurmctld >/dev/null; then
    say "slurmctld already running (pid $(pidof slurmctld))"
else
    say "starting slurmctld"
    slurmctld || die "slurmctld failed to start; see $LOG_DIR/slurmctld.log"
    wait_pid slurmctld 10 || die "slurmctld exited; last lines of $LOG_DIR/slurmctld.log:
$(tail -n 20 "$LOG_DIR/slurmctld.log" 2>/dev/null)"
fi
if pidof slurmd >/dev/null; then
    say "slurmd already running (pid $(pidof slurmd))"
else
    say "starting slurmd"
    slurmd || die "slurmd failed to start; see $LOG_DIR/slurmd.log"
    wait_pid slurmd 10 || die "slurmd exited; last lines of $LOG_DIR/slurmd.log:
$(tail -n 20 "$LOG_DIR/slurmd.log" 2>/dev/null)"
fi

# --- 5. wait for the node --------------------------------------------------------------
state=""
resumed=0
for ((i = 0; i < TIMEOUT * 2; i++)); do
    state=$(sinfo -h -N -n "$NODE" -o %t 2>/dev/null | head -n 1 || true)
    case $state in
        idle | mix | alloc | comp) break ;;
        down* | drain* | drng*)
            # E.g. left down by an earlier run whose slurmd was stopped; it is registered now.
            if ((!resumed)) && pidof slurmd >/dev/null; then
                say "node $NODE is $state; resuming it"
                scontrol update NodeName="$NODE" State=RESUME >/dev/null 2>&1 || true
                resumed=1
            fi
            ;;
    esac
    sleep 0.5
done
case $state in
    idle | mix | alloc | comp) ;;
    *)
        die "node $NODE is not up after ${TIMEOUT} s (sinfo state: '${state:-none}').
$(scontrol show node "$NODE" 2>&1 | grep -E 'State=|Reason=' || true)
last lines of $LOG_DIR/slurmctld.log:
$(tail -n 10 "$LOG_DIR/slurmctld.log" 2>/dev/null)
last lines of $LOG_DIR/slurmd.log:
$(tail -n 10 "$LOG_DIR/slurmd.log" 2>/dev/null)"
        ;;
esac
say "node $NODE is $state; Slurm is ready ($((SECONDS - start_time)) s)"
sinfo
