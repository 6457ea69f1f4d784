#!/usr/bin/env python3
"""Oracle for heatsim's VTK writer: read a .vtu with meshio and print what it holds as JSON.

Usage:
    check_vtu.py FILE.vtu [--expect-points N] [--expect-cells TYPE=N ...]

Prints one JSON object (keys sorted):
    points       number of points
    cells        {meshio cell type ("tetra", "triangle"): count}
    connectivity {cell type: sum of all vertex indices}      (cheap checksum of the cells)
    point_data   {name: [shape...]}
    cell_data    {name: [[shape...] per cell block]}
    sums         {"point:NAME" or "cell:NAME": sum of all values}  (checksum of the data)
    bounds       [[xmin, ymin, zmin], [xmax, ymax, zmax]] in metres, or null
    tetra_volume sum of the signed tetrahedron volumes in m^3 (numpy), or null
    tetra_min_signed_volume  the smallest signed tetrahedron volume, or null

Exits with status 1 if an --expect-* check fails, 2 on usage errors. Needs meshio and numpy
(scripts/oracle/requirements.txt; scripts/setup-oracles.sh creates the .venv).
"""
import argparse
import json
import sys

import meshio
import numpy as np


def signed_volumes(points, tets):
    """det[p1 - p0, p2 - p0, p3 - p0] / 6 for every tetrahedron (m^3)."""
    p = points[np.asarray(tets, dtype=np.int64)]
    return np.linalg.det(np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=-1)) / 6.0


def summarize(mesh):
    cells, connectivity = {}, {}
    for block in mesh.cells:
        cells[block.type] = cells.get(block.type, 0) + int(len(block.data))
        connectivity[block.type] = connectivity.get(block.type, 0) + int(np.sum(block.data, dtype=np.int64))
    sums = {f"point:{k}": float(np.sum(v)) for k, v in mesh.point_data.items()}
    sums.update({f"cell:{k}": float(sum(np.sum(a) for a in v)) for k, v in mesh.cell_data.items()})
    points = np.asarray(mesh.points)
    vols = [signed_volumes(points, b.data) for b in mesh.cells if b.type == "tetra"]
    vols = np.concatenate(vols) if vols else None
    return {
        "tetra_volume": None if vols is None else float(np.sum(vols)),
        "tetra_min_signed_volume": None if vols is None else float(np.min(vols)),
        "points": int(len(points)),
        "cells": cells,
        "connectivity": connectivity,
        "point_data": {k: list(np.shape(v)) for k, v in mesh.point_data.items()},
        "cell_data": {k: [list(np.shape(a)) for a in v] for k, v in mesh.cell_data.items()},
        "sums": sums,
        "bounds": [points.min(axis=0).tolist(), points.max(axis=0).tolist()] if len(points) else None,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("vtu", help="the .vtu file to read")
    ap.add_argument("--expect-points", type=int, help="fail unless the file has N points")
    ap.add_argument("--expect-cells", action="append", default=[], metavar="TYPE=N",
                    help="fail unless there are N cells of meshio type TYPE (repeatable)")
    args = ap.parse_args()

    summary = summarize(meshio.read(args.vtu))
    print(json.dumps(summary, sort_keys=True))

    failures = []
    if args.expect_points is not None and summary["points"] != args.expect_points:
        failures.append(f"expected {args.expect_points} points, found {summary['points']}")
    for spec in args.expect_cells:
        kind, sep, count = spec.partition("=")
        if not sep or not count.isdigit():
            ap.error(f"--expect-cells wants TYPE=N, got {spec!r}")
        found = summary["cells"].get(kind, 0)
        if found != int(count):
            failures.append(f"expected {count} {kind} cells, found {found}")
    for f in failures:
        print(f"check_vtu: {args.vtu}: {f}", file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
