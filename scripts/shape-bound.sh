#!/usr/bin/env bash
# The Cramér–Rao bound on the shape from the videos (heatrecon::bound) on the full suite tier's
# hemisphere and bunny at 50 mK, at several levels and degrees (the suite itself computes one
# level and degree at build, SUITE/bounds.json): re-simulates the two datasets from the scenes
# stored in the suite (SUITE/objects/ID/scene.json, default SUITE: a full-tier build in
# suites-build/full) with the camera at 50 mK, runs `simbench reconstruct --shape-bound DEGREE` at the true depth,
# fluxes and globals for each (level, degree) below, and writes each level's bound to
# results/shape_bound/OBJECT-LLEVEL-dDEGREE.json and a summary to results/shape_bound/summary.csv.
# About 40 minutes on 2 cores. Rerunning skips the files that exist (delete them to redo).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q -p simbench
scripts/fetch-bunny.sh >&2
out=results/shape_bound; mkdir -p "$out"
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
bin=./target/release/simbench
# object, level, degree, CGLS iterations
runs="hemisphere 2 2 400
hemisphere 2 4 400
hemisphere 2 6 400
hemisphere 1 2 400
hemisphere 1 4 200
bunny 2 2 400
bunny 2 4 400
bunny 2 6 400
bunny 1 2 400"
suite=${1:-suites-build/full}
declare -A row=([hemisphere]=hemisphere-surface-d0.001 [bunny]=bunny-surface-d0.002)
while read -r obj level degree iters; do
  file="$out/$obj-L$level-d$degree.json"
  [ -s "$file" ] && continue
  data="$tmp/${row[$obj]}"
  if [ ! -d "$data" ]; then
    echo "simulating ${row[$obj]}" >&2
    # The suite's noise-free scene with the camera at 50 mK (fixed pattern 25 mK, 10 mK steps).
    python3 -c 'import json, sys; s = json.load(open(sys.argv[1])); s["camera"].update(netd=0.05, fixed_pattern_sigma=0.025, quantization=0.01); print(json.dumps(s, indent=1))' \
      "$suite/objects/${row[$obj]}/scene.json" > "$tmp/${row[$obj]}.json"
    cp "$suite/objects/${row[$obj]}"/*.obj "$tmp/" 2>/dev/null || true
    $bin simulate "$tmp/${row[$obj]}.json" --out "$data" --vtu-frames 0 >"$tmp/simulate.log" 2>&1 || { cat "$tmp/simulate.log" >&2; exit 1; }
  fi
  echo "bound: $obj, level $level, degree $degree" >&2
  # The bound is taken at the true depth with the true fluxes and globals (--check), whatever
  # the reconstruction gives: one iteration of it is enough.
  $bin reconstruct "$data/left" "$data/right" --out "$tmp/run" --diffusivity material --check \
    --set shape.iterations=1 --level "$level" --set shape.extra_levels=0 --shape-bound "$degree" \
    --shape-bound-iterations "$iters" >/dev/null 2>"$tmp/log" || { cat "$tmp/log" >&2; exit 1; }
  python3 - "$tmp/run/check.json" "$file.part" "$obj" "$level" "$degree" "$tmp/run/stage2.json" <<'PY'
import json, sys
c = json.load(open(sys.argv[1]))
s = json.load(open(sys.argv[6]))
b = c["levels"][0]["shape_bound"]
b.update(object=sys.argv[3], level=int(sys.argv[4]), degree=int(sys.argv[5]), vertices=s["levels"][0]["vertices"])
json.dump(b, open(sys.argv[2], "w"), indent=1)
PY
  mv "$file.part" "$file"
  rm -rf "$tmp/run"
done <<< "$runs"
python3 - "$out" <<'PY'
import glob, json, sys
lines = ["object,level,vertices,degree,modes,fluxes,globals,expected_mae_mm,size_std,relief_std,cgls_iterations"]
for f in sorted(glob.glob(sys.argv[1] + "/*-L*-d*.json")):
    b = json.load(open(f))
    for r in b["rows"]:
        n = r["nuisances"]
        lines.append(",".join(str(x) for x in [b["object"], b["level"], b["vertices"], b["degree"], len(b["modes"]),
            "unknown" if n["fluxes"] else "known", "unknown" if n["globals"] else "known",
            "%.3f" % (1e3 * r["joint_mae_m"]), "%.4g" % r["std"][0], "%.4g" % r["std"][1], b["projection_iterations"]]))
open(sys.argv[1] + "/summary.csv", "w").write("\n".join(lines) + "\n")
print("\n".join(lines))
PY
