#!/usr/bin/env bash
# Measures the volumetric solver: phase timings and the step/substitution ratio with the
# direct and the conjugate-gradient linear solver (`simbench bench-solver`) on the default
# cuboid, a cuboid of about 1e5 tetrahedra and the bunny at 1 cm; both of ours against every
# peer configuration (`simbench peer volumetric`: SuperLU, PARDISO, SciPy CG) on every shipped
# scene and on the cuboid from 2 to 0.5 mm elements (about 60 minutes on 2 cores). Writes
# JSON to results/solver/ and prints a summary.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q -p simbench
scripts/setup-peers.sh
out=results/solver; mkdir -p "$out/peers"
sb=./target/release/simbench
$sb bench-solver scenes/cuboid.json > "$out/bench_cuboid.json"
$sb bench-solver scenes/cuboid.json --element-size 0.0014 > "$out/bench_cuboid_1e5.json"
$sb bench-solver scenes/bunny.json --thickness 0.01 --repeat 15 > "$out/bench_bunny_1cm.json"
for s in cuboid box hemisphere bunny bunny-uniform tour; do
  repeat=3; case $s in bunny|bunny-uniform) repeat=2;; cuboid|box|tour) repeat=5;; esac
  $sb peer volumetric "scenes/$s.json" --repeat "$repeat" > "$out/peers/$s.json"
done
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
$sb peer volumetric scenes/cuboid.json --repeat 2 --duration 3 \
  --element-sizes 0.002,0.0014,0.001,0.0008,0.0006,0.0005 --out "$work" > /dev/null
cp "$work"/peer_scaling.{json,csv,png} "$out/"
python3 - "$out" <<'PY'
import json, sys, pathlib
d = pathlib.Path(sys.argv[1])
for name in ["bench_cuboid", "bench_cuboid_1e5", "bench_bunny_1cm"]:
    r = json.loads((d / f"{name}.json").read_text())
    print(f"{name}: {r['nodes']} nodes, {r['tetrahedra']} tets; assembly {r['assembly_s']*1e3:.1f} ms; "
          f"direct step over CG step {r['direct_step_over_cg_step']:.2f}, solvers differ by {r['max_difference_after_steps_k']:.1e} K")
    for s in r["solvers"]:
        print(f"  {s['solver']}: set-up {s['setup_s']*1e3:.1f} ms, solve {s['substitution_s']*1e3:.2f} ms, "
              f"step {s['step_s']*1e3:.2f} ms, step/solve {s['step_over_substitution']:.2f}, "
              f"CG iterations per solve {s['cg_iterations_per_solve_mean']:.1f}")
reports = [json.loads(p.read_text()) for p in sorted((d / "peers").glob("*.json"))]
reports += json.loads((d / "peer_scaling.json").read_text())
for r in reports:
    cg = {s["peer"]: s["stepping"] for s in r["speedups"] if s["ours"] == "conjugate_gradients"}
    print(f"peer {r['scene']}: {r['nodes']} nodes, {r['steps']} steps; our CG over SuperLU {cg['superlu']:.2f}x, "
          f"PARDISO {cg['pardiso']:.2f}x, SciPy CG {cg['cg']:.2f}x; max difference {r['max_rel_diff']:.1e} of the rise")
PY
