#!/usr/bin/env bash
# Meshes the shipped cuboid, hemisphere and bunny scenes at thicknesses from 1 mm to 1 m with
# `simbench mesh --thickness` and collects the statistics in results/mesh/thickness_table.csv.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q -p simbench
out=results/mesh; mkdir -p "$out"
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
csv="$tmp/table.csv"
echo "scene,thickness_m,nodes,tetrahedra,boundary_faces,visible_faces,min_dihedral_deg,max_radius_edge_ratio,volume_m3,volume_rel_error_vs_analytic,tetgen_seconds" > "$csv"
for scene in cuboid hemisphere bunny; do
  for d in 0.001 0.003 0.01 0.03 0.1 0.2 0.5 1.0; do
    echo "meshing $scene at $d m" >&2
    ./target/release/simbench mesh "scenes/$scene.json" --thickness "$d" --out "$tmp/$scene-$d" 2>/dev/null \
      | python3 -c "
import json, sys
s = json.load(sys.stdin)
e = s['volume_rel_error_vs_analytic']
print(','.join(str(x) for x in ['$scene', $d, s['nodes'], s['tetrahedra'], s['boundary_faces'], s['visible_faces'],
      round(s['min_dihedral_deg'], 2), round(s['max_radius_edge_ratio'], 2), '%.6e' % s['volume_m3'],
      '' if e is None else '%.2e' % e, round(s['tetgen_seconds'], 2)]))" >> "$csv"
  done
done
mv "$csv" "$out/thickness_table.csv"
column -s, -t "$out/thickness_table.csv"
