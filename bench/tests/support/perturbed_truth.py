#!/usr/bin/env python3
"""A scripted method for testing `simbench suite compare`: the truth, perturbed.

    perturbed_truth.py SUITE CASE OUT FACTOR DRAW SPREAD

Reads the visible ground truth of CASE from the suite folder SUITE (a test oracle: real methods
never see it) and moves every vertex along its normal by +a or -a (random signs), so that the
rigidly aligned MAE is about a, with

    a = 2 mm * FACTOR * exp(SPREAD * xi),   xi ~ N(0, 1)

drawn from a generator seeded by (CASE, DRAW): the same DRAW gives the same errors, another
DRAW a fresh draw. SPREAD is the standard deviation of ln(MAE) over seeds, to match the
built-in method's. Writes OUT/recon_world.obj (world frame, metres). Standard library only.
"""

import hashlib
import json
import math
import os
import random
import sys


def read_obj(path):
    verts, faces = [], []
    with open(path) as f:
        for line in f:
            p = line.split()
            if not p:
                continue
            if p[0] == "v":
                verts.append([float(x) for x in p[1:4]])
            elif p[0] == "f":
                faces.append([int(x.split("/")[0]) - 1 for x in p[1:4]])
    return verts, faces


def vertex_normals(verts, faces):
    n = [[0.0, 0.0, 0.0] for _ in verts]
    for a, b, c in faces:
        u = [verts[b][k] - verts[a][k] for k in range(3)]
        v = [verts[c][k] - verts[a][k] for k in range(3)]
        w = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
        for i in (a, b, c):
            for k in range(3):
                n[i][k] += w[k]
    out = []
    for x in n:
        length = math.sqrt(sum(c * c for c in x)) or 1.0
        out.append([c / length for c in x])
    return out


def main():
    if len(sys.argv) != 7:
        sys.exit(__doc__)
    suite, case_id, out, factor, draw, spread = sys.argv[1:7]
    manifest = json.load(open(os.path.join(suite, "suite.json")))
    case = next(c for c in manifest["cases"] if c["id"] == case_id)
    verts, faces = read_obj(os.path.join(suite, "objects", case["object"], "left", "gt_mesh.obj"))
    seed = int(hashlib.sha256(f"{case_id}/{draw}".encode()).hexdigest()[:16], 16)
    rng = random.Random(seed)
    a = 2e-3 * float(factor) * math.exp(float(spread) * rng.gauss(0.0, 1.0))
    normals = vertex_normals(verts, faces)
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "recon_world.obj"), "w") as f:
        f.write("# the truth perturbed along its normals (a test method)\n")
        for v, n in zip(verts, normals):
            s = a if rng.random() < 0.5 else -a
            f.write("v {} {} {}\n".format(*(v[k] + s * n[k] for k in range(3))))
        for t in faces:
            f.write("f {} {} {}\n".format(*(i + 1 for i in t)))


if __name__ == "__main__":
    main()
