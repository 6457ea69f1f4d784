#!/usr/bin/env bash
# Runs every test of the project on a fresh machine: installs what the tests need
# (the bunny asset, the Python oracle environment), then the whole Cargo test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/fetch-bunny.sh
scripts/setup-oracles.sh
# Oracle and asset tests fail (instead of skipping) when their prerequisites are missing.
export HEATSIM_REQUIRE_ASSETS=1
cargo test --workspace --release "$@"
