#!/usr/bin/env bash
# Adds the speed peers of `simbench peer` (MKL PARDISO through pypardiso, about 200 MB) to the
# oracle environment .venv (made first by scripts/setup-oracles.sh). Idempotent. The tests do
# not need it: their peer check uses SciPy's SuperLU.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/setup-oracles.sh"
venv="$root/.venv"
stamp="$venv/.peers.sha256"
want=$(sha256sum "$root/scripts/oracle/peers-requirements.txt" | cut -d' ' -f1)
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
  exit 0
fi
"$venv/bin/python" -m pip install -q --disable-pip-version-check -r "$root/scripts/oracle/peers-requirements.txt"
echo "$want" > "$stamp"
echo "peers: PARDISO (pypardiso) ready in $venv"
