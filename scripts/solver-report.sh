#!/usr/bin/env bash
# Measures the volumetric solver: phase timings and the step/substitution ratio with the
# direct and the conjugate-gradient linear solver (`simbench bench-solver`) on the default cuboid, a cuboid of about 1e5 tetrahedra and the
# bunny at 1 cm, and the side-by-side comparison with the scikit-fem peer
# (`simbench peer volumetric`). Writes JSON to results/solver/ and prints a summary.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q -p simbench
scripts/setup-oracles.sh
out=results/solver; mkdir -p "$out"
sb=./target/release/simbench
$sb bench-solver scenes/cuboid.json > "$out/bench_cuboid.json"
$sb bench-solver scenes/cuboid.json --element-size 0.0014 > "$out/bench_cuboid_1e5.json"
$sb bench-solver scenes/bunny.json --thickness 0.01 --repeat 15 > "$out/bench_bunny_1cm.json"
$sb peer volumetric scenes/cuboid.json > "$out/peer_cuboid.json"
$sb peer volumetric bench/peers/cuboid_1e5.json > "$out/peer_cuboid_1e5.json"
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
for name in ["peer_cuboid", "peer_cuboid_1e5"]:
    r = json.loads((d / f"{name}.json").read_text())
    print(f"{name}: {r['nodes']} nodes, {r['steps']} steps; ours {r['ours_s']:.2f} s, scikit-fem {r['peer_s']:.2f} s, "
          f"speedup {r['speedup']:.2f}x, max difference {r['max_rel_diff']:.1e} of the rise")
PY
