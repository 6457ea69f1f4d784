#!/usr/bin/env python3
"""Mitsuba 3 oracle of a dataset's absorbed flux (`gt_flux.npy`) and shadows.

Usage: mitsuba_flux.py DATASET_DIR [--spp N] [--scale S] [--json] [--save FILE.npy]

Renders the object of a dataset written by `simbench simulate` with Mitsuba 3 (variant
`scalar_rgb`, CPU only) and compares it with the dataset's ground truth:

- geometry: `boundary.vtu` (the whole boundary surface: what is seen and what casts shadows),
  flat-shaded with face normals;
- material: a one-sided diffuse BSDF whose (grey) reflectance is the absorptivity beta, so the
  reflected radiance is L = beta/pi * E, and pi * L = beta * E is the absorbed flux;
- lamps: each point lamp an isotropic `point` emitter of radiant intensity
  I = radiant_fraction * power / (4 pi) W/sr (times --scale, 1 by default: a deliberately wrong
  value shows that the check can fail);
- integrator: `direct` (direct light only, no interreflection, like the simulator), wrapped in
  an `aov` integrator that also returns the distance to the surface (a check of the camera);
  one rendering per lamp, summed (with several emitters `direct` samples one at random);
- sensor: a `perspective` camera equal to the OpenCV camera of camera.json, with an hdrfilm of
  the same size, a `box` filter and a `stratified` sampler without jitter: with the default
  --spp 1 every pixel is sampled once, exactly at its centre, as gt_flux.npy is (the flux of
  the face seen at the pixel centre). A pixel mean (--spp 4, 9, ...: a regular grid) differs
  from it wherever a pixel straddles two flat-shaded faces: on the 4 mm mesh of the test that
  alone is a mean relative error of ~1.8 %, against ~0.2 % at the pixel centres.

Comparison: over pixels seen in both renderings and at least 2 px from a silhouette and from a
shadow edge (a pixel whose 5 x 5 neighbourhood mixes lit and shadowed pixels in either image,
or, with several lamps, in Mitsuba's rendering of one lamp alone),
the mean relative error |ours - mitsuba| / mitsuba over lit pixels (ours > 0 and
mitsuba > 1e-3 max) and the fraction of pixels where both agree on the shadow
((ours == 0) == (mitsuba < 1e-6 max)). Prints a JSON report; exits 1 when the mean relative
error exceeds 2 % or the shadow agreement is below 99 %, and 2 on unusable input (e.g. a
uniform lamp, which has no Mitsuba counterpart). The report also compares the silhouettes
(mask_iou) and the depth (our z_c times the ray length against Mitsuba's ray distance).

Expected differences (not errors): the simulator evaluates each face's flux at its centroid
and its shadow from the centroid, Mitsuba at the pixel's point; so the flux differs by the
variation of cos(theta)/r^2 across a face (first order in face size / lamp distance, ~0.1 %),
and a face straddling a shadow edge is all lit or all dark in gt_flux (disagreements within
about half a face of the edge).

Camera conventions (OpenCV -> Mitsuba): OpenCV's camera has x right, y down, z forward; a
Mitsuba camera looks along its local +z with +y up and +x to the LEFT of the image
(`ScalarTransform4f.look_at` builds the columns [left, up, forward, origin]). So the Mitsuba
camera-to-world matrix has columns (-x_cv, -y_cv, +z_cv) expressed in world coordinates (rows
of R, negated for the first two) and the origin C = -R^T t. OpenCV pixel centres are at integer
u with cx = (W - 1)/2 on the optical axis; Mitsuba's film spans [0, W] with pixel centres at
u + 0.5, so the same image plane has a horizontal field of view 2 atan(W / (2 fx)) (fov_axis
"x"), and a principal point off the image centre is not supported (refused).

Spectra pitfall: in `scalar_rgb` an emitter given as {"type": "spectrum", "value": I} is an
equal-energy illuminant converted to sRGB (not grey: R, G, B = 1.20, 0.95, 0.91 of I); a plain
float (or an "rgb" triple) is the grey RGB value intended here.
"""

import argparse
import json
import math
import os
import sys
import tempfile
import time

import numpy as np

# Near clipping distance of the Mitsuba camera (m): far below any working distance.
NEAR_CLIP = 1e-4


class InputError(Exception):
    """The dataset cannot be compared (missing file, unsupported lamp or camera)."""


def load_json(path):
    try:
        with open(path) as f:
            return json.load(f)
    except (OSError, ValueError) as e:
        raise InputError(f"{path}: {e}") from e


def read_boundary(path):
    """Boundary triangles of the dataset: (vertices #V x 3 float64, faces #F x 3 int)."""
    import meshio

    try:
        mesh = meshio.read(path)
    except Exception as e:  # meshio raises many kinds
        raise InputError(f"{path}: {e}") from e
    tris = [c.data for c in mesh.cells if c.type == "triangle"]
    if not tris:
        raise InputError(f"{path}: no triangles")
    faces = np.concatenate(tris).astype(np.int64)
    verts = np.asarray(mesh.points, dtype=np.float64)
    # Keep only the vertices in use (the file holds every node of the tetrahedral mesh).
    used, inverse = np.unique(faces.ravel(), return_inverse=True)
    return verts[used], inverse.reshape(-1, 3)


def orient_outward(verts, faces):
    """The faces wound so that their normals point out of the (closed) surface; Mitsuba's diffuse
    BSDF is one-sided. Returns (faces, signed volume before any flip)."""
    a, b, c = (verts[faces[:, k]] for k in range(3))
    volume = float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)
    if volume < 0:
        faces = faces[:, [0, 2, 1]]
    return faces, volume


def write_ply(path, verts, faces):
    """Binary little-endian PLY: float32 positions, uchar-counted int32 index lists."""
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(verts)}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    face_rec = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    face_rec["n"] = 3
    face_rec["i"] = faces
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(np.ascontiguousarray(verts, dtype="<f4").tobytes())
        f.write(face_rec.tobytes())


def camera_to_mitsuba(cam):
    """(camera-to-world 4x4 for Mitsuba, horizontal fov in degrees, width, height) of an OpenCV
    camera.json."""
    K = np.asarray(cam["K"], dtype=np.float64)
    R = np.asarray(cam["R"], dtype=np.float64)
    t = np.asarray(cam["t"], dtype=np.float64)
    W, H = int(cam["width"]), int(cam["height"])
    fx, fy, cx, cy, skew = K[0, 0], K[1, 1], K[0, 2], K[1, 2], K[0, 1]
    if abs(fx - fy) > 1e-9 * fx or abs(skew) > 1e-9 * fx:
        raise InputError(f"camera.json: non-square pixels or skew (fx {fx}, fy {fy}, skew {skew}) are not supported")
    if abs(cx - (W - 1) / 2) > 1e-6 or abs(cy - (H - 1) / 2) > 1e-6:
        raise InputError(f"camera.json: principal point ({cx}, {cy}) is not the image centre ({(W - 1) / 2}, {(H - 1) / 2})")
    if np.abs(R @ R.T - np.eye(3)).max() > 1e-9 or np.linalg.det(R) < 0:
        raise InputError("camera.json: R is not a rotation")
    centre = -R.T @ t
    to_world = np.eye(4)
    to_world[:3, 0] = -R[0]  # Mitsuba +x: image left
    to_world[:3, 1] = -R[1]  # Mitsuba +y: image up
    to_world[:3, 2] = R[2]  # forward
    to_world[:3, 3] = centre
    fov = math.degrees(2.0 * math.atan(W / (2.0 * fx)))
    return to_world, fov, W, H


def ray_lengths(cam):
    """Length of each pixel-centre ray per unit depth z_c (dimensionless, [H, W])."""
    K = np.asarray(cam["K"], dtype=np.float64)
    v, u = np.mgrid[0 : int(cam["height"]), 0 : int(cam["width"])]
    return np.sqrt(((u - K[0, 2]) / K[0, 0]) ** 2 + ((v - K[1, 2]) / K[1, 1]) ** 2 + 1.0)


def point_lamps(lamps):
    out = []
    for i, lamp in enumerate(lamps):
        kind = lamp.get("kind")
        if kind != "point":
            raise InputError(f"lamps.json: lamps[{i}] is a {kind!r} lamp; only point lamps have a Mitsuba counterpart")
        eta = float(lamp.get("radiant_fraction", 0.85))
        out.append((np.asarray(lamp["position"], dtype=np.float64), eta * float(lamp["power"]) / (4.0 * math.pi)))
    if not out:
        raise InputError("lamps.json: no lamp")
    return out


def render(dataset, spp, scale, seed=0):
    """Mitsuba's absorbed flux pi * L of each lamp (float64 [lamps, H, W]), coverage alpha and distance to the
    surface along each pixel's rays (m), and the render time in s."""
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    cam = load_json(os.path.join(dataset, "camera.json"))
    lamps = point_lamps(load_json(os.path.join(dataset, "lamps.json")))
    absorptivity = float(load_json(os.path.join(dataset, "material.json"))["absorptivity"])
    verts, faces = read_boundary(os.path.join(dataset, "boundary.vtu"))
    faces, volume = orient_outward(verts, faces)
    to_world, fov, W, H = camera_to_mitsuba(cam)
    with tempfile.TemporaryDirectory() as tmp:
        ply = os.path.join(tmp, "boundary.ply")
        write_ply(ply, verts, faces)
        scene = {
            "type": "scene",
            "integrator": {"type": "aov", "aovs": "dist:depth", "light": {"type": "direct"}},
            "sensor": {
                "type": "perspective",
                "fov_axis": "x",
                "fov": fov,
                "near_clip": NEAR_CLIP,
                "far_clip": 1e4,
                "to_world": mi.ScalarTransform4f(to_world.tolist()),
                "film": {
                    "type": "hdrfilm",
                    "width": W,
                    "height": H,
                    "pixel_format": "rgba",
                    "rfilter": {"type": "box"},
                },
                "sampler": {"type": "stratified", "sample_count": spp, "jitter": False, "seed": seed},
            },
            "object": {
                "type": "ply",
                "filename": ply,
                "face_normals": True,
                "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [absorptivity] * 3}},
            },
        }
        # One rendering per lamp, summed: with several emitters, `direct` picks one at random
        # per emitter sample (weighted by their count), which is exact only on average.
        started = time.perf_counter()
        per_lamp = []
        for position, intensity in lamps:
            # A plain float is a grey RGB value (a "spectrum" would be an illuminant, see above).
            scene["lamp"] = {"type": "point", "position": position.tolist(), "intensity": float(intensity * scale)}
            image = np.array(mi.render(mi.load_dict(scene)), dtype=np.float64)
            # Channels of the aov integrator's image: the inner integrator's R, G, B, then the
            # alpha (coverage), then the AOV "dist" (premultiplied by the coverage).
            if image.ndim != 3 or image.shape != (H, W, 5):
                raise RuntimeError(f"unexpected Mitsuba image of shape {image.shape}, expected ({H}, {W}, 5)")
            per_lamp.append(math.pi * image[:, :, :3].mean(axis=2))
        seconds = time.perf_counter() - started
    alpha = image[:, :, 3]
    # Rays start on the near plane (z_c = NEAR_CLIP): the distance from the centre of
    # projection is t + NEAR_CLIP times the ray's length per unit z_c.
    dist = np.where(alpha > 0, image[:, :, 4] / np.maximum(alpha, 1e-12), np.nan)
    dist = dist + NEAR_CLIP * ray_lengths(cam)
    return np.stack(per_lamp), alpha, dist, seconds, volume


def compare(dataset, per_lamp, alpha, dist, margin=2):
    """The report of the comparison of the dataset with Mitsuba's per-lamp flux [lamps, H, W]."""
    from scipy import ndimage

    flux_mi = per_lamp.sum(axis=0)
    ours = np.load(os.path.join(dataset, "gt_flux.npy")).astype(np.float64)
    mask = np.load(os.path.join(dataset, "mask.npy")).astype(bool)
    if ours.shape != flux_mi.shape or mask.shape != flux_mi.shape:
        raise InputError(f"gt_flux.npy {ours.shape} / mask.npy {mask.shape} do not match the camera {flux_mi.shape}")
    mask_mi = alpha > 0.5
    both = mask & mask_mi
    size = 2 * margin + 1
    box = np.ones((size, size), dtype=bool)
    interior = ndimage.binary_erosion(both, structure=box, border_value=0)
    peak = float(flux_mi[both].max()) if both.any() else 0.0
    shadow_ours = both & (ours == 0)
    shadow_mi = both & (flux_mi < 1e-6 * peak)

    def near_edge(shadow):
        lit = both & ~shadow
        return ndimage.maximum_filter(shadow, size=size) & ndimage.maximum_filter(lit, size=size)

    compared = interior & ~near_edge(shadow_ours) & ~near_edge(shadow_mi)
    # With several lamps, the shadow of one lamp can fall inside the light of another: its
    # edges (seen in Mitsuba's rendering of that lamp alone) are excluded too.
    if len(per_lamp) > 1:
        for f in per_lamp:
            compared &= ~near_edge(both & (f < 1e-6 * f[both].max()))
    lit = compared & (ours > 0) & (flux_mi > 1e-3 * peak)
    rel = np.abs(ours[lit] - flux_mi[lit]) / flux_mi[lit]
    agree = (shadow_ours == shadow_mi)[compared]
    # Camera check: our depth z_c against Mitsuba's distance along the pixel-centre ray.
    depth = np.load(os.path.join(dataset, "gt_depth.npy")).astype(np.float64)
    ray_len = ray_lengths(load_json(os.path.join(dataset, "camera.json")))
    depth_rel = np.abs(depth[interior] * ray_len[interior] - dist[interior]) / dist[interior]
    sil_ours = mask.sum()
    return {
        "mean_rel_err": float(rel.mean()) if rel.size else float("nan"),
        "median_rel_err": float(np.median(rel)) if rel.size else float("nan"),
        "p99_rel_err": float(np.percentile(rel, 99)) if rel.size else float("nan"),
        "mean_ratio_ours_over_mitsuba": float(np.mean(ours[lit] / flux_mi[lit])) if rel.size else float("nan"),
        "shadow_agreement": float(agree.mean()) if agree.size else float("nan"),
        "compared_pixels": int(compared.sum()),
        "lit_pixels": int(lit.sum()),
        "shadow_pixels": int((compared & shadow_ours).sum()),
        "shadow_disagreements": int((~agree).sum()),
        "mask_pixels_ours": int(sil_ours),
        "mask_pixels_mitsuba": int(mask_mi.sum()),
        "mask_iou": float(both.sum() / max(1, (mask | mask_mi).sum())),
        "depth_max_rel_err": float(depth_rel.max()) if depth_rel.size else float("nan"),
        "depth_p99_rel_err": float(np.percentile(depth_rel, 99)) if depth_rel.size else float("nan"),
        # Pixels where Mitsuba sees another surface (e.g. a ray slipping through a float32 edge).
        "depth_mismatched_pixels": int((depth_rel > 1e-4).sum()),
        "peak_flux_mitsuba": peak,
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", help="directory written by `simbench simulate`")
    ap.add_argument(
        "--spp",
        type=int,
        default=1,
        help="samples per pixel on a regular k x k grid (a square; default 1: the pixel centre, where gt_flux is sampled)",
    )
    ap.add_argument("--scale", type=float, default=1.0, help="multiply every lamp's intensity (a deliberate error, to see the check fail)")
    ap.add_argument("--json", action="store_true", help="print only the JSON report")
    ap.add_argument("--save", help="also write Mitsuba's flux (float32 [H, W], W/m^2, NaN off the object) to this .npy")
    args = ap.parse_args(argv)
    if args.spp < 1 or math.isqrt(args.spp) ** 2 != args.spp or not (args.scale > 0 and math.isfinite(args.scale)):
        ap.error("--spp must be a square >= 1 and --scale a positive number")
    started = time.perf_counter()
    try:
        per_lamp, alpha, dist, render_seconds, volume = render(args.dataset, args.spp, args.scale)
        report = compare(args.dataset, per_lamp, alpha, dist)
    except InputError as e:
        print(f"mitsuba_flux: {e}", file=sys.stderr)
        return 2
    report["seconds"] = time.perf_counter() - started
    report["render_seconds"] = render_seconds
    report["spp"] = args.spp
    report["scale"] = args.scale
    report["boundary_volume_m3"] = abs(volume)
    report["boundary_flipped"] = volume < 0
    if args.save:
        np.save(args.save, np.where(alpha > 0.5, per_lamp.sum(axis=0), np.nan).astype(np.float32))
    ok = report["mean_rel_err"] <= 0.02 and report["shadow_agreement"] >= 0.99
    report["pass"] = bool(ok)
    # Strict JSON: NaN (nothing to compare) becomes null.
    report = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in report.items()}
    text = json.dumps(report, indent=None if args.json else 2)
    print(text)
    if not args.json:
        print("mitsuba_flux: " + ("PASS" if ok else "FAIL (mean_rel_err <= 0.02 and shadow_agreement >= 0.99 required)"), file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
