#!/usr/bin/env bash
# Creates the Python virtual environment .venv for the oracle checks (idempotent).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
venv="$root/.venv"
stamp="$venv/.requirements.sha256"
want=$(sha256sum "$root/scripts/oracle/requirements.txt" | cut -d' ' -f1)
if [ -x "$venv/bin/python" ] && [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
  exit 0
fi
python3 -m venv "$venv"
"$venv/bin/python" -m pip install -q --disable-pip-version-check -r "$root/scripts/oracle/requirements.txt"
echo "$want" > "$stamp"
echo "oracles: virtual environment ready at $venv"
