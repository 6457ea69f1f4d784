"""Tetrahedralise a closed surface with fTetWild (PyPI `pytetwild`): the independent mesher of
`simbench mesh-independence`.

Usage: tetwild_mesh.py SURFACE.obj OUT_DIR --edge H [--epsilon E]

Reads a closed triangle surface (OBJ, metres), runs fTetWild with ideal edge length H (m) and
envelope E (relative to the bounding-box diagonal), and writes OUT_DIR/nodes.npy (float64
[N, 3], m) and OUT_DIR/tets.npy (int64 [T, 4]); prints one JSON line with the counts, the
volume and the time. fTetWild's output surface lies within the envelope of the input, not on
it: it is a different mesh of (nearly) the same solid, which is the point.
"""

import argparse
import json
import pathlib
import sys
import time

import numpy as np


def read_obj(path):
    verts, faces = [], []
    for line in open(path, encoding="utf-8"):
        s = line.split()
        if not s:
            continue
        if s[0] == "v":
            verts.append([float(x) for x in s[1:4]])
        elif s[0] == "f":
            if len(s) != 4:
                sys.exit(f"{path}: only triangles are supported, got a face with {len(s) - 1} vertices")
            faces.append([int(x.split("/")[0]) - 1 for x in s[1:4]])
    return np.asarray(verts, dtype=np.float64), np.asarray(faces, dtype=np.int32)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("surface")
    ap.add_argument("out")
    ap.add_argument("--edge", type=float, required=True, help="ideal edge length (m)")
    ap.add_argument("--epsilon", type=float, default=1e-3, help="envelope, relative to the bbox diagonal")
    args = ap.parse_args()
    import pytetwild

    verts, faces = read_obj(args.surface)
    if len(faces) == 0:
        sys.exit(f"{args.surface}: no faces")
    t0 = time.perf_counter()
    # Fewer optimisation passes than fTetWild's defaults (stop energy 10, 80 iterations):
    # the meshes are used for heat conduction, where quality beyond this changes nothing
    # measurable, and the defaults take minutes.
    nodes, tets = pytetwild.tetrahedralize(
        verts, faces, edge_length_abs=args.edge, epsilon=args.epsilon, stop_energy=10.0, num_opt_iter=20, quiet=True
    )
    seconds = time.perf_counter() - t0
    a, b, c, d = (nodes[tets[:, i]] for i in range(4))
    volume = float(np.abs(np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a))).sum() / 6.0)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    np.save(out / "nodes.npy", np.asarray(nodes, dtype=np.float64))
    np.save(out / "tets.npy", np.asarray(tets, dtype=np.int64))
    print(json.dumps({"nodes": int(len(nodes)), "tets": int(len(tets)), "volume_m3": volume, "seconds": seconds,
                      "edge_m": args.edge, "epsilon": args.epsilon, "pytetwild": pytetwild.__version__}))


if __name__ == "__main__":
    main()
