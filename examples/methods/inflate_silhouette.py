#!/usr/bin/env python3
"""Balloon inflation of the silhouette: an example external reconstruction method.

This is a *contract example* and a silhouette-only baseline, not a heat method: it reads only
LEFT's mask and camera and ignores every temperature (video.npy, times.npy) and the
environment and material files; it checks that they are there and well-formed, as a real
method would need them.

Contract (how `simbench suite run --method-cmd 'CMD {left} {right} {out}'` calls a method)
-----------------------------------------------------------------------------------------
    python3 examples/methods/inflate_silhouette.py LEFT RIGHT OUT

LEFT and RIGHT are dataset directories of the same object and camera under two lamp
configurations (they may be the same directory when a scene has a single configuration).
Each holds:
  video.npy         float32 [frames, H, W]: apparent temperature, K
  times.npy         float64 [frames]: frame times, s
  mask.npy          bool [H, W]: the object's pixels
  camera.json       K (3x3 intrinsics, pixels), R (3x3 world->camera rotation), t ([3]
                    world->camera translation, m), width, height, frame_interval_s (s).
                    OpenCV convention: x_cam = R x_world + t, x right, y down, the camera
                    looks along +z_cam; pixel (u, v) = (K x_cam / z_cam)[:2]; the image is
                    row-major with v the row; pixel centres at integer (u, v), i.e. the
                    centre of pixel [row v, column u] is (u, v) (heatsim's camera/pinhole.rs).
  environment.json  ambient_temperature (K), emissivity
  material.json     the object's material
The method writes OUT/recon_world.obj (creating OUT if needed): a triangle mesh in the WORLD
frame, in metres. It exits 0 on success; on invalid input it prints the reason to stderr and
exits 1.

The method
----------
d0 is the distance from the camera centre C = -R^T t to the world origin, at which the camera
looks. Every mask pixel p gets the camera depth z_cam(p) = d0 - h(p) with

    h(p) = c * sqrt(dist(p)),

dist(p) the Euclidean distance (m, measured in the plane z_cam = d0, i.e. pixel offsets scaled
by d0/fx and d0/fy) from p's centre to the silhouette boundary, taken half a pixel inside the
centres of the nearest background pixels (pixels outside the image count as background). The
constant c is chosen so that the bulge's height max h equals half the silhouette's half-width,
the half-width being the largest dist (the inradius: the radius for a disc, half the width
for a strip): c = sqrt(max dist) / 2, so max h = max dist / 2. The silhouette's rim stays on
the plane z_cam = d0 through the origin, the middle bulges towards the camera.

Each mask pixel centre (u, v) is back-projected to x_cam = z_cam K^-1 (u, v, 1) and taken to
the world frame, X = R^T (x_cam - t); every 2 x 2 block of mask pixels gives two triangles,
wound so that their normals face the camera. Only numpy and the standard library are used.

On scenes/hemisphere.json (`simbench simulate --solver surface`, 640 x 512, radius 50 mm) it
takes about 5 s and `simbench eval --align none` gives mae_mm 13.3 (the bulge is 25 mm high
where the hemisphere is 50 mm; 12.6 mm analytically); eval's default rigid ICP gives 5.4 mm
only by tilting the flat dome about 55 degrees against the hemisphere's side.
"""

import json
import os
import sys

try:
    import numpy as np
except ImportError:
    print("inflate_silhouette: error: numpy is not installed for this Python (pip install numpy)", file=sys.stderr)
    sys.exit(1)

# Mask pixels against boundary pixels per distance block (memory ~ 8 * CHUNK * boundary bytes).
CHUNK = 4096


class InputError(Exception):
    """Invalid input: reported on stderr, exit code 1."""


def fail(msg):
    print(f"inflate_silhouette: error: {msg}", file=sys.stderr)
    sys.exit(1)


def load_json(path):
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except FileNotFoundError:
        raise InputError(f"{path} not found") from None
    except (OSError, ValueError) as e:
        raise InputError(f"cannot read {path}: {e}") from None


def load_npy(path, mmap=False):
    try:
        return np.load(path, mmap_mode="r" if mmap else None, allow_pickle=False)
    except FileNotFoundError:
        raise InputError(f"{path} not found") from None
    except (OSError, ValueError) as e:
        raise InputError(f"cannot read {path}: {e}") from None


def matrix(cam, key, shape, path):
    try:
        a = np.array(cam[key], dtype=np.float64)
    except KeyError:
        raise InputError(f"{path}: missing key '{key}'") from None
    except (TypeError, ValueError):
        raise InputError(f"{path}: '{key}' is not a numeric array") from None
    if a.shape != shape or not np.all(np.isfinite(a)):
        raise InputError(f"{path}: '{key}' must be a finite array of shape {list(shape)}, got {cam[key]}")
    return a


def positive_int(cam, key, path):
    v = cam.get(key)
    if not isinstance(v, int) or isinstance(v, bool) or v < 1:
        raise InputError(f"{path}: '{key}' must be a positive integer, got {v!r}")
    return v


def read_camera(directory):
    path = os.path.join(directory, "camera.json")
    cam = load_json(path)
    if not isinstance(cam, dict):
        raise InputError(f"{path}: expected a JSON object")
    k = matrix(cam, "K", (3, 3), path)
    r = matrix(cam, "R", (3, 3), path)
    t = matrix(cam, "t", (3,), path)
    width = positive_int(cam, "width", path)
    height = positive_int(cam, "height", path)
    dt = cam.get("frame_interval_s")
    if not isinstance(dt, (int, float)) or isinstance(dt, bool) or not dt > 0:
        raise InputError(f"{path}: 'frame_interval_s' must be a positive number, got {dt!r}")
    if not (k[0, 0] > 0 and k[1, 1] > 0 and k[1, 0] == 0 and k[2, 0] == 0 and k[2, 1] == 0 and k[2, 2] == 1):
        raise InputError(f"{path}: K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, got {k.tolist()}")
    if not (np.allclose(r @ r.T, np.eye(3), atol=1e-6) and np.linalg.det(r) > 0):
        raise InputError(f"{path}: R must be a rotation (orthonormal, determinant +1), got {r.tolist()}")
    return k, r, t, width, height


def check_dataset(directory, need_mask):
    """Checks the contract's files in one dataset directory; returns (camera, mask or None)."""
    if not os.path.isdir(directory):
        raise InputError(f"dataset directory {directory} not found")
    k, r, t, width, height = read_camera(directory)
    video_path = os.path.join(directory, "video.npy")
    video = load_npy(video_path, mmap=True)  # header only: the temperatures are not used
    if video.dtype != np.float32 or video.ndim != 3 or video.shape[1:] != (height, width):
        raise InputError(
            f"{video_path}: expected float32 [frames, {height}, {width}], got {video.dtype} {list(video.shape)}"
        )
    times_path = os.path.join(directory, "times.npy")
    times = load_npy(times_path)
    if times.dtype != np.float64 or times.shape != (video.shape[0],):
        raise InputError(f"{times_path}: expected float64 [{video.shape[0]}], got {times.dtype} {list(times.shape)}")
    env_path = os.path.join(directory, "environment.json")
    env = load_json(env_path)
    for key in ("ambient_temperature", "emissivity"):
        if not isinstance(env, dict) or not isinstance(env.get(key), (int, float)):
            raise InputError(f"{env_path}: missing numeric '{key}'")
    load_json(os.path.join(directory, "material.json"))
    mask_path = os.path.join(directory, "mask.npy")
    mask = load_npy(mask_path, mmap=not need_mask)
    if mask.dtype != np.bool_ or mask.shape != (height, width):
        raise InputError(f"{mask_path}: expected bool [{height}, {width}], got {mask.dtype} {list(mask.shape)}")
    return (k, r, t), (np.asarray(mask) if need_mask else None)


def boundary_distance(mask, sx, sy):
    """Per mask pixel (in np.nonzero order): Euclidean distance (m) to the silhouette boundary.

    Pixel offsets are scaled by sx (m per column) and sy (m per row). The distance is the one
    to the nearest background pixel centre minus half a pixel, so that pixels on the rim are
    half a pixel from the silhouette's edge. Exact (brute force over the background pixels
    next to the mask, in blocks).
    """
    # The mask and a one-pixel frame of background around the image.
    padded = np.pad(mask, 1, constant_values=False)
    h, w = padded.shape
    grown = padded.copy()  # the mask dilated by one pixel (8-neighbourhood)
    for dv in (-1, 0, 1):
        for du in (-1, 0, 1):
            grown[max(0, dv) : h + min(0, dv), max(0, du) : w + min(0, du)] |= padded[
                max(0, -dv) : h + min(0, -dv), max(0, -du) : w + min(0, -du)
            ]
    # Background pixels touching the mask, in padded coordinates (row 0 is the row above the image).
    bg_rows, bg_cols = np.nonzero(grown & ~padded)
    by = (bg_rows - 1) * sy
    bx = (bg_cols - 1) * sx
    rows, cols = np.nonzero(mask)
    my = rows * sy
    mx = cols * sx
    dist2 = np.empty(rows.size)
    for s in range(0, rows.size, CHUNK):
        dy = my[s : s + CHUNK, None] - by[None, :]
        dx = mx[s : s + CHUNK, None] - bx[None, :]
        dist2[s : s + CHUNK] = np.min(dx * dx + dy * dy, axis=1)
    half_pixel = 0.5 * min(sx, sy)
    return np.maximum(np.sqrt(dist2) - half_pixel, 0.0)


def inflate(mask, k, r, t):
    """The world-frame mesh (vertices [n, 3] in m, triangles [m, 3] 0-based) and a summary."""
    centre = -r.T @ t
    d0 = float(np.linalg.norm(centre))
    if not d0 > 0:
        raise InputError("the camera centre is at the world origin; d0 = |C| must be positive")
    origin_cam = t  # camera coordinates of the world origin
    if origin_cam[2] <= 0:
        raise InputError("the world origin is behind the camera; the camera must look at the scene origin")
    off_axis = np.hypot(origin_cam[0], origin_cam[1]) / origin_cam[2]
    if off_axis > 0.01:
        print(
            f"inflate_silhouette: warning: the optical axis misses the world origin by {off_axis:.3g} rad; "
            "the rim is put at z_cam = |C| anyway",
            file=sys.stderr,
        )
    fx, s, cx, fy, cy = k[0, 0], k[0, 1], k[0, 2], k[1, 1], k[1, 2]
    height, width = mask.shape

    rows, cols = np.nonzero(mask)
    dist = boundary_distance(mask, d0 / fx, d0 / fy)
    half_width = float(dist.max())
    c = np.sqrt(half_width) / 2.0 if half_width > 0 else 0.0
    z = d0 - c * np.sqrt(dist)

    # Back-projection of the pixel centres (u, v) = (column, row), heatsim's pixel_direction.
    u = cols.astype(np.float64)
    v = rows.astype(np.float64)
    y1 = (v - cy) / fy
    x1 = (u - cx - s * y1) / fx
    x_cam = np.stack([x1 * z, y1 * z, z], axis=1)
    verts = (x_cam - t) @ r  # row-vector form of R^T (x_cam - t)

    # Triangles: each 2 x 2 block of mask pixels, wound to face the camera (normal towards -z_cam).
    index = np.full((height, width), -1, dtype=np.int64)
    index[rows, cols] = np.arange(rows.size)
    block = mask[:-1, :-1] & mask[:-1, 1:] & mask[1:, :-1] & mask[1:, 1:]
    bv, bu = np.nonzero(block)
    i00 = index[bv, bu]
    i10 = index[bv, bu + 1]  # u + 1
    i01 = index[bv + 1, bu]  # v + 1
    i11 = index[bv + 1, bu + 1]
    # In the camera frame +u is +x and +v is +y, so (00, 01, 10) turns from +y to +x: normal -z.
    tris = np.concatenate([np.stack([i00, i01, i10], axis=1), np.stack([i10, i01, i11], axis=1)])
    if tris.size == 0:
        raise InputError("the mask holds no 2 x 2 block of pixels: nothing to triangulate")

    # Keep only the vertices of some triangle (isolated pixels and thin lines have none).
    used = np.zeros(rows.size, dtype=bool)
    used[tris.ravel()] = True
    renumber = np.cumsum(used) - 1
    summary = {
        "d0_m": d0,
        "half_width_m": half_width,
        "c_sqrt_m": c,
        "bulge_height_m": c * np.sqrt(half_width),
        "mask_pixels": int(rows.size),
    }
    return verts[used], renumber[tris], summary


def write_obj(path, verts, tris, comment):
    tmp = path + ".tmp"
    with open(tmp, "w", encoding="ascii") as f:
        f.write(f"# {comment}\n# {len(verts)} vertices, {len(tris)} triangles; world frame, metres\n")
        np.savetxt(f, verts, fmt="v %.9g %.9g %.9g")
        np.savetxt(f, tris + 1, fmt="f %d %d %d")
    os.replace(tmp, path)


def main(argv):
    if len(argv) != 4:
        fail(f"usage: {os.path.basename(argv[0])} LEFT RIGHT OUT (dataset directories and an output directory)")
    left, right, out = argv[1:]
    try:
        (k, r, t), mask = check_dataset(left, need_mask=True)
        if os.path.realpath(right) != os.path.realpath(left):
            check_dataset(right, need_mask=False)
        if not mask.any():
            raise InputError(f"{os.path.join(left, 'mask.npy')} is empty: no object pixels")
        verts, tris, summary = inflate(mask, k, r, t)
    except InputError as e:
        fail(str(e))
    try:
        os.makedirs(out, exist_ok=True)
        path = os.path.join(out, "recon_world.obj")
        write_obj(path, verts, tris, "inflate_silhouette.py: balloon inflation of LEFT's silhouette")
    except OSError as e:
        fail(f"cannot write {out}/recon_world.obj: {e}")
    print(
        f"inflate_silhouette: wrote {path}: {len(verts)} vertices, {len(tris)} triangles; "
        f"d0 = {summary['d0_m']:.4f} m, silhouette half-width {summary['half_width_m'] * 1e3:.2f} mm, "
        f"bulge height {summary['bulge_height_m'] * 1e3:.2f} mm",
        file=sys.stderr,
    )


if __name__ == "__main__":
    main(sys.argv)
