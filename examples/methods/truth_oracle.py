#!/usr/bin/env python3
"""The oracle: a case's visible ground truth handed back as its reconstruction.

Not a method: it reads the truth that the suite never gives a method, to check the scoring.
A reconstruction that is the truth must score (almost) zero on every case of a tier; if it
does not, the tier's scoring has drifted from its truth (bench/tests/suite.rs runs it).

Contract
--------
    python truth_oracle.py SUITE CASE OUT [CHECKER_M]

run by `simbench suite run SUITE --method-cmd 'python truth_oracle.py SUITE {case} {out}'`.
SUITE is the built suite's folder (given in the template: the method's inputs {left} and
{right} hold no truth), CASE the case id ({case}). The case's object is looked up in
SUITE/suite.json, and its truth read from SUITE/objects/<object>/left/, the view the suite
scores against:
  gt_depth.npy  float32 [H, W]: depth z_c along the optical axis, m, NaN off the object
  camera.json   K (OpenCV intrinsics, pixels), R and t (world -> camera: x_c = R x_w + t, m)
Writes OUT/recon_world.obj: a triangle mesh in the world frame, in metres.

Every pixel centre with a finite depth is un-projected. Pixel (u, v) = (column, row) has its
centre at integer (u, v) (sim/src/camera/pinhole.rs), so with K = [[fx, s, cx], [0, fy, cy],
[0, 0, 1]] and z = gt_depth[v, u]:

    y_c = (v - cy) z / fy,   x_c = (u - cx - s y_c / z) z / fx,   z_c = z,
    x_w = R^T (x_c - t).

Each 2 x 2 block of such pixels gives two triangles split along the main diagonal, oriented
as heatsim's PixelGrid (normals towards the camera): (p00, p01, p11) and (p00, p11, p10),
p10 being (u + 1, v) and p01 (u, v + 1). Vertices in no triangle are dropped.

CHECKER_M (optional, m, default 0) is added to the depth of every pixel with u + v odd: a
checkerboard no rigid motion undoes, to see that the check fails. numpy only.
"""

import json
import os
import sys

import numpy as np


def main(argv):
    if len(argv) not in (4, 5):
        sys.exit(__doc__)
    suite, case_id, out = argv[1:4]
    checker = float(argv[4]) if len(argv) == 5 else 0.0
    with open(os.path.join(suite, "suite.json"), encoding="utf-8") as f:
        cases = [c for c in json.load(f)["cases"] if c["id"] == case_id]
    if len(cases) != 1:
        sys.exit(f"truth_oracle: error: case {case_id!r} is not in {suite}/suite.json")
    truth = os.path.join(suite, "objects", cases[0]["object"], "left")
    depth = np.load(os.path.join(truth, "gt_depth.npy")).astype(np.float64)
    with open(os.path.join(truth, "camera.json"), encoding="utf-8") as f:
        cam = json.load(f)
    k, r, t = (np.array(cam[key], dtype=np.float64) for key in ("K", "R", "t"))
    fx, s, cx, fy, cy = k[0, 0], k[0, 1], k[0, 2], k[1, 1], k[1, 2]

    seen = np.isfinite(depth)
    rows, cols = np.nonzero(seen)
    z = depth[rows, cols] + checker * ((rows + cols) % 2)
    y_c = (rows - cy) * z / fy
    x_c = (cols - cx - s * y_c / z) * z / fx
    verts = (np.stack([x_c, y_c, z], axis=1) - t) @ r  # row vectors: R^T (x_c - t)

    index = np.full(depth.shape, -1, dtype=np.int64)
    index[rows, cols] = np.arange(rows.size)
    bv, bu = np.nonzero(seen[:-1, :-1] & seen[:-1, 1:] & seen[1:, :-1] & seen[1:, 1:])
    p00, p10, p01, p11 = index[bv, bu], index[bv, bu + 1], index[bv + 1, bu], index[bv + 1, bu + 1]
    tris = np.concatenate([np.stack([p00, p01, p11], axis=1), np.stack([p00, p11, p10], axis=1)])
    if tris.size == 0:
        sys.exit(f"truth_oracle: error: {truth}/gt_depth.npy holds no 2 x 2 block of pixels")
    used = np.zeros(rows.size, dtype=bool)
    used[tris.ravel()] = True
    renumber = np.cumsum(used) - 1

    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "recon_world.obj"), "w", encoding="ascii") as f:
        f.write(f"# truth_oracle.py: the visible truth of {case_id} (checker {checker} m); world frame, m\n")
        np.savetxt(f, verts[used], fmt="v %.10g %.10g %.10g")
        np.savetxt(f, renumber[tris] + 1, fmt="f %d %d %d")


if __name__ == "__main__":
    main(sys.argv)
