#!/usr/bin/env bash
# Scores a benchmark suite as a Slurm job array of N shards and merges the shards:
#
#   scripts/slurm/run-suite-array.sh SUITE RUN N [METHOD ARGS...]
#   e.g. scripts/slurm/run-suite-array.sh suite runs/plane 4 --method plane --timeout 600
#
# Submits scripts/slurm/suite-array.sbatch with `sbatch --wait --array=1-N`, so that task K
# writes RUN/shard-K (`simbench suite run SUITE --out RUN/shard-K --shard K/N METHOD ARGS...`)
# and its log RUN/logs/shard-K.out; waits for the whole array; fails, showing the log tails of
# the failed tasks, if any task failed; else runs `simbench suite merge RUN/shard-1 ...
# RUN/shard-N --out RUN/merged`.
#
# Environment: SIMBENCH, the simbench binary (default: target/release/simbench in the
# repository); sbatch's own variables (SBATCH_PARTITION, SBATCH_TIMELIMIT, ...) apply too.
set -euo pipefail

say() { echo "run-suite-array: $*"; }
die() { echo "run-suite-array: error: $*" >&2; exit 1; }

(($# >= 3)) || die "usage: $0 SUITE RUN N [METHOD ARGS...]"
suite=$1
run=$2
n=$3
shift 3
[[ $n =~ ^[1-9][0-9]*$ ]] || die "N must be a positive integer, got '$n'"

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
sbatch_script=$root/scripts/slurm/suite-array.sbatch
simbench=${SIMBENCH:-$root/target/release/simbench}
# The job runs in this directory too, but an absolute path does not depend on that.
[[ $simbench == /* ]] || simbench=$PWD/$simbench
[[ -x $simbench ]] || die "simbench binary '$simbench' not found (build it: cargo build --release -p simbench; or set SIMBENCH)"
export SIMBENCH=$simbench
export SIMBENCH_SHARDS=$n
command -v sbatch >/dev/null || die "sbatch not found; set up Slurm first (scripts/slurm/setup-slurm.sh)"
[[ -e $suite ]] || die "suite '$suite' not found"

logs=$run/logs
mkdir -p "$logs"
# Stale exit codes of an earlier submission must not count for tasks that never start now.
for ((k = 1; k <= n; k++)); do rm -f "$run/shard-$k.exit"; done
say "submitting $n array tasks: $simbench suite run $suite --out $run/shard-K --shard K/$n $*"
say "task logs: $logs/shard-K.out (K = 1..$n)"
start=$SECONDS
rc=0
# --wait: returns when every task has ended, with the highest exit code of the tasks.
jobid=$(sbatch --parsable --wait --array="1-$n" --job-name="simbench-suite" \
    --output="$logs/shard-%a.out" "$sbatch_script" "$suite" "$run" "$@") || rc=$?
jobid=${jobid%%;*}
say "job array ${jobid:-?} finished in $((SECONDS - start)) s (sbatch exit code $rc)"

failed=()
for ((k = 1; k <= n; k++)); do
    status=$(cat "$run/shard-$k.exit" 2>/dev/null || echo "none")
    if [[ $status != 0 ]]; then
        failed+=("$k")
        if [[ $status == none ]]; then
            echo "run-suite-array: task $k did not finish (killed, timed out or never started)" >&2
        else
            echo "run-suite-array: task $k exited with $status" >&2
        fi
        echo "---- last lines of $logs/shard-$k.out ----" >&2
        tail -n 20 "$logs/shard-$k.out" >&2 2>/dev/null || echo "(no log)" >&2
        echo "----" >&2
    fi
done
if ((${#failed[@]})); then
    die "${#failed[@]} of $n tasks failed (${failed[*]}) in job ${jobid:-?}; logs in $logs"
fi
((rc == 0)) || die "sbatch exited with $rc although every task reported success; logs in $logs"

shards=()
for ((k = 1; k <= n; k++)); do shards+=("$run/shard-$k"); done
say "merging: $simbench suite merge ${shards[*]} --out $run/merged"
"$simbench" suite merge "${shards[@]}" --out "$run/merged" || die "suite merge failed"
say "done: merged run in $run/merged (shards in $run/shard-K, logs in $logs)"
