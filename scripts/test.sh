#!/usr/bin/env bash
# Runs every test of the project on a fresh machine: installs what the tests need
# (the bunny asset, the Python oracle environment), then the whole Cargo test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/fetch-bunny.sh
scripts/setup-oracles.sh
# Oracle and asset tests fail (instead of skipping) when their prerequisites are missing.
export HEATSIM_REQUIRE_ASSETS=1
# The suite builds the reconstruction's experiments too (feature `experimental`); the binary
# users get (default features) must build as well.
cargo test --workspace --release --features simbench/experimental "$@"
cargo build --release -p simbench
# The API documentation builds without warnings (broken links, unescaped brackets, bare URLs).
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps --workspace
# The cluster path of the benchmark suite on a real single-node Slurm (installed and started
# by the script): a small suite scored as a two-task job array and merged.
scripts/slurm/test-slurm.sh
