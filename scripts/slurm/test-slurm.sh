#!/usr/bin/env bash
# CI test of the Slurm scripts: sets up a single-node Slurm cluster (scripts/slurm/setup-slurm.sh;
# needs root), builds a tiny suite, scores it with the plane method as a 2-task job array
# (scripts/slurm/run-suite-array.sh) and checks that the merged run reports every case.
#
#   scripts/slurm/test-slurm.sh [SPEC]     (SPEC: the suite spec, default suites/tiny.json)
#
# Uses SIMBENCH (default: target/release/simbench in the repository; build it first) and a
# fresh temporary directory, removed on success and kept on failure.
set -euo pipefail

say() { echo "test-slurm: $*"; }
die() { echo "test-slurm: error: $*" >&2; exit 1; }

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
spec=${1:-$root/suites/tiny.json}
[[ -f $spec ]] || die "suite spec '$spec' not found"
export SIMBENCH=${SIMBENCH:-$root/target/release/simbench}
[[ -x $SIMBENCH ]] || die "simbench binary '$SIMBENCH' not found (cargo build --release -p simbench)"

"$root/scripts/slurm/setup-slurm.sh"

tmp=$(mktemp -d "${TMPDIR:-/tmp}/test-slurm.XXXXXX")
trap 'if (($? != 0)); then echo "test-slurm: FAILED; files kept in $tmp" >&2; fi' EXIT
say "working in $tmp"

say "building the suite from $spec"
"$SIMBENCH" suite build --spec "$spec" --out "$tmp/suite"

"$root/scripts/slurm/run-suite-array.sh" "$tmp/suite" "$tmp/run" 2 --method plane

# Both shards must have run as tasks of one array on this cluster.
for k in 1 2; do
    grep -q "^suite-array: job [0-9]*_$k on " "$tmp/run/logs/shard-$k.out" ||
        die "task $k's log $tmp/run/logs/shard-$k.out does not show it ran under Slurm"
done

# `suite report` fails unless the run holds a record for every case of the suite.
say "checking the merged run: $SIMBENCH suite report $tmp/run/merged"
"$SIMBENCH" suite report "$tmp/run/merged"

trap - EXIT
rm -rf "$tmp"
say "OK"
