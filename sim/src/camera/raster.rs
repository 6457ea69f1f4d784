//! [`rasterize`]: renders a triangle mesh through a [`Camera`] into a [`Render`] (per pixel: the
//! nearest triangle, perspective-correct barycentric coordinates and depth), and the per-frame
//! gathers [`Render::interpolate`] and [`Render::interpolate_face`].
//!
//! # Method
//! Each pixel is sampled once, at its centre `(u, v)`, along the camera-frame ray
//! `d = K^-1 (u, v, 1)^T` (so `d_z = 1`). For a triangle with camera-frame corners
//! `p_0, p_1, p_2` the homogeneous edge functions (Olano and Greer 1997)
//! `λ_i(d) = d · (p_(i+1) × p_(i+2)) (indices mod 3)`
//! are linear in `(u, v)`, and if the ray meets the triangle's plane at `s d` then
//! `λ_i = b_i V / s` with `b_i` the barycentric coordinates of the hit point in the
//! triangle itself (not in its projection) and `V = p_0 · (p_1 × p_2)`. Hence:
//! - the pixel sees the triangle iff all `λ_i sign(V) ≥ 0` (this also
//!   rejects hits behind the camera, where `s < 0`);
//! - the perspective-correct barycentrics are `b_i = λ_i / Σ_j λ_j`, so a field
//!   that is linear on the triangle in 3D is reproduced exactly at the pixel centre;
//! - the depth is `z_c = Σ_i b_i z_i` (m), the camera-frame z of the hit point.
//!
//! No perspective division of the corners is needed, so triangles crossing the plane of the
//! camera are handled; only hits closer than [`NEAR_PLANE`] are dropped. Triangles are not
//! culled by orientation: back faces are rendered too, and the depth test picks the nearest
//! surface (equal depths: the lower triangle index wins, because each band of rows processes
//! triangles in index order and replaces only on strictly smaller depth).
//!
//! # Fill rule
//! A pixel centre lying exactly on an edge (`λ_i = 0`) belongs to the triangle whose
//! sign-normalised edge normal `n_i = sign(V) p_(i+1) × p_(i+2)` is
//! lexicographically positive (`n_x > 0`, or `n_x = 0` and `n_y > 0`, ...). This is a symbolic
//! perturbation: the tie is decided as if the ray were nudged by `(ε, ε^2, 0)`
//! in the camera frame, i.e. towards +u and, on horizontal edges, +v; without skew it is the
//! usual top-left rule (left and top edges in, right and bottom edges out). The neighbour
//! across a shared edge computes exactly `-n_i` (the cross product of the same two corners in
//! the other order rounds to the exact negation, and so do the dot products), so for
//! triangles that face the same way exactly one of them owns each pixel centre on a shared
//! edge: no gaps, no double coverage. Where the edge functions are exact (e.g. dyadic
//! coordinates) the perturbation argument also gives exactly-once coverage at shared
//! vertices; otherwise a pixel centre within rounding error (~1e-16 relative) of a shared
//! vertex may be missed or doubled, which the depth test resolves.
//!
//! # Parallelism and determinism
//! Triangles are binned into bands of [`BAND_ROWS`] rows in index order; bands are rendered in
//! parallel with rayon, each band serially. The result does not depend on the thread count.

use rayon::prelude::*;

use crate::vec3::{cross, dot, sub, unit};

use super::Camera;

/// Triangle index of a pixel that sees no triangle.
pub const EMPTY: u32 = u32::MAX;

/// Hits closer to the centre of projection than this depth (`z_c`, m) are ignored: 1 mm, far
/// inside any thermal camera's minimum focus distance, and a bound on the size of the
/// bounding box of a triangle that crosses the camera plane.
pub const NEAR_PLANE: f64 = 1e-3;

/// Rows per band of the parallel rasteriser and of the per-frame gathers. 8 rows of a 640-wide
/// image are ~5000 pixels: enough work per task, and 64 bands for a 512-row image balance well.
pub const BAND_ROWS: usize = 8;

/// The result of rasterising a mesh: for each of the W * H pixels (row-major, pixel `(u, v)` at
/// index `v * W + u`) the triangle seen at the pixel centre, its barycentric coordinates there
/// and the depth.
#[derive(Clone, Debug, PartialEq)]
pub struct Render {
    /// Image width W, in pixels.
    pub width: u32,
    /// Image height H, in pixels.
    pub height: u32,
    /// #H*W index into `tris` of the nearest triangle, [`EMPTY`] where no triangle is seen.
    pub face: Vec<u32>,
    /// #H*W x 3 perspective-correct barycentric coordinates of the point seen, in the corner
    /// order of its triangle (non-negative, summing to 1 up to rounding); `[0, 0, 0]` where
    /// empty.
    pub bary: Vec<[f64; 3]>,
    /// #H*W depth `z_c` of the point seen (distance along the optical axis, m); NaN where
    /// empty.
    pub z: Vec<f64>,
}

/// Per-triangle set-up: sign-normalised edge normals, corner depths and pixel bounding box.
struct Setup {
    id: u32,
    /// Edge normals n_i = sign(V) p_{i+1} x p_{i+2} (camera frame).
    n: [[f64; 3]; 3],
    /// Tie rule per edge: a pixel centre with lambda_i == 0 is inside iff `tie[i]`.
    tie: [bool; 3],
    /// Corner depths z_c, m.
    z: [f64; 3],
    /// Inclusive pixel ranges of the bounding box, clamped to the image.
    u0: usize,
    u1: usize,
    v0: usize,
    v1: usize,
}

/// Renders the triangles `tris` (#F x 3 indices into `verts`) of `verts` (#V x 3 world
/// coordinates, m) through `camera`: nearest surface per pixel centre, perspective-correct
/// barycentrics, depth (see the module documentation for the method and fill rule).
///
/// Triangles of zero area, seen exactly edge-on, or with a non-finite corner cover no pixel.
///
/// # Panics
/// If a triangle index is out of range for `verts`, or if `tris.len() >= u32::MAX` (pixel
/// triangle ids are `u32`, with [`EMPTY`] reserved). Validated meshes
/// ([`TriMesh::try_new`](crate::mesh::trimesh::TriMesh::try_new)) satisfy the first.
pub fn rasterize(camera: &Camera, verts: &[[f64; 3]], tris: &[[usize; 3]]) -> Render {
    assert!(tris.len() < EMPTY as usize, "rasterize: {} triangles, at most {} supported", tris.len(), EMPTY - 1);
    let (w, h) = (camera.width as usize, camera.height as usize);
    let pc: Vec<[f64; 3]> = verts.par_iter().map(|&p| camera.to_camera(p)).collect();

    let setups: Vec<Setup> =
        tris.par_iter().enumerate().filter_map(|(f, t)| setup(camera, f as u32, t.map(|i| pc[i]))).collect();

    let bands = h.div_ceil(BAND_ROWS);
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (k, s) in setups.iter().enumerate() {
        for bin in &mut bins[s.v0 / BAND_ROWS..=s.v1 / BAND_ROWS] {
            bin.push(k as u32);
        }
    }

    // Ray directions d = K^-1 (u, v, 1): y depends on v only; x = xs[u] - skew * y / fx.
    let k = &camera.k;
    let xs: Vec<f64> = (0..w).map(|u| (u as f64 - k[0][2]) / k[0][0]).collect();
    let skew_over_fx = k[0][1] / k[0][0];

    let mut face = vec![EMPTY; w * h];
    let mut bary = vec![[0.0; 3]; w * h];
    let mut z = vec![f64::INFINITY; w * h];
    let band_len = w * BAND_ROWS;
    face.par_chunks_mut(band_len)
        .zip(bary.par_chunks_mut(band_len))
        .zip(z.par_chunks_mut(band_len))
        .zip(bins.par_iter())
        .enumerate()
        .for_each(|(band, (((face, bary), z), bin))| {
            let row0 = band * BAND_ROWS;
            let row_end = row0 + face.len() / w; // exclusive
            for &k_setup in bin {
                let s = &setups[k_setup as usize];
                for v in s.v0.max(row0)..=s.v1.min(row_end - 1) {
                    let y = (v as f64 - k[1][2]) / k[1][1];
                    let shift = -skew_over_fx * y;
                    let row = (v - row0) * w;
                    for (u, &xu) in xs.iter().enumerate().take(s.u1 + 1).skip(s.u0) {
                        let d = [xu + shift, y, 1.0];
                        let l = [dot(s.n[0], d), dot(s.n[1], d), dot(s.n[2], d)];
                        let inside = (0..3).all(|i| l[i] > 0.0 || (l[i] == 0.0 && s.tie[i]));
                        let sum = l[0] + l[1] + l[2];
                        // Inside implies no NaN, so sum <= 0 means all three are zero.
                        if !inside || sum <= 0.0 {
                            continue;
                        }
                        let b = [l[0] / sum, l[1] / sum, l[2] / sum];
                        let depth = b[0] * s.z[0] + b[1] * s.z[1] + b[2] * s.z[2];
                        let p = row + u;
                        if depth >= NEAR_PLANE && depth < z[p] {
                            z[p] = depth;
                            face[p] = s.id;
                            bary[p] = b;
                        }
                    }
                }
            }
        });
    for d in &mut z {
        if *d == f64::INFINITY {
            *d = f64::NAN;
        }
    }
    Render { width: camera.width, height: camera.height, face, bary, z }
}

/// Set-up of triangle `id` with camera-frame corners `p`, or `None` if it can cover no pixel.
fn setup(camera: &Camera, id: u32, p: [[f64; 3]; 3]) -> Option<Setup> {
    let mut n = [cross(p[1], p[2]), cross(p[2], p[0]), cross(p[0], p[1])];
    let vol = dot(p[0], n[0]);
    // V = 0: zero area, or the triangle's plane contains the centre of projection (seen
    // edge-on); NaN: a non-finite corner. Neither covers any pixel.
    if !(vol != 0.0 && vol.is_finite()) {
        return None;
    }
    if vol < 0.0 {
        for ni in &mut n {
            *ni = [-ni[0], -ni[1], -ni[2]];
        }
    }
    let tie = n.map(|ni| ni[0] > 0.0 || (ni[0] == 0.0 && (ni[1] > 0.0 || (ni[1] == 0.0 && ni[2] > 0.0))));

    // Bounding box of the part of the triangle in front of the near plane: clip the polygon
    // against z >= NEAR_PLANE (Sutherland-Hodgman, one plane) and project what remains.
    let (mut umin, mut umax, mut vmin, mut vmax) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    let mut include = |q: [f64; 3]| {
        if let Some([u, v]) = camera.project_camera(q) {
            umin = umin.min(u);
            umax = umax.max(u);
            vmin = vmin.min(v);
            vmax = vmax.max(v);
        }
    };
    for i in 0..3 {
        let (a, b) = (p[i], p[(i + 1) % 3]);
        if a[2] >= NEAR_PLANE {
            include(a);
        }
        if (a[2] >= NEAR_PLANE) != (b[2] >= NEAR_PLANE) {
            let s = (NEAR_PLANE - a[2]) / (b[2] - a[2]);
            let e = sub(b, a);
            include([a[0] + s * e[0], a[1] + s * e[1], NEAR_PLANE]);
        }
    }
    let (w, h) = (f64::from(camera.width), f64::from(camera.height));
    // floor/ceil include every pixel centre in the closed box (and at most one more column or
    // row, which the edge functions reject): the box comes from divisions that round
    // differently from the edge functions, so it must not be tight.
    let (u_lo, u_hi) = (umin.floor().max(0.0), umax.ceil().min(w - 1.0));
    let (v_lo, v_hi) = (vmin.floor().max(0.0), vmax.ceil().min(h - 1.0));
    // Also false when nothing was included (infinite bounds) or a bound is NaN.
    if !(u_lo <= u_hi && v_lo <= v_hi) {
        return None;
    }
    Some(Setup {
        id,
        n,
        tie,
        z: [p[0][2], p[1][2], p[2][2]],
        u0: u_lo as usize,
        u1: u_hi as usize,
        v0: v_lo as usize,
        v1: v_hi as usize,
    })
}

impl Render {
    /// Number of pixels W * H.
    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// #H*W: whether the pixel sees a triangle.
    pub fn mask(&self) -> Vec<bool> {
        self.face.iter().map(|&f| f != EMPTY).collect()
    }

    /// Number of pixels that see a triangle.
    pub fn covered(&self) -> usize {
        self.face.iter().filter(|&&f| f != EMPTY).count()
    }

    /// #H*W depth `z_c` (m) as `f32`, NaN where empty.
    pub fn depth(&self) -> Vec<f32> {
        self.z.iter().map(|&d| d as f32).collect()
    }

    /// #H*W world-frame unit normals of the faces seen: the flat (per-face) normal
    /// `(b - a) × (c - a) / | · |` of the triangle as stored, not interpolated vertex
    /// normals and not flipped towards the camera (for an outward-oriented surface seen from
    /// outside it points to the camera's side). NaN where empty.
    ///
    /// `verts`, `tris` must be the arrays passed to [`rasterize`].
    ///
    /// # Panics
    /// If a face index or vertex index is out of range (other arrays than the rasterised ones).
    pub fn normals(&self, verts: &[[f64; 3]], tris: &[[usize; 3]]) -> Vec<[f32; 3]> {
        let face_normal = |f: u32| -> [f32; 3] {
            let [a, b, c] = tris[f as usize].map(|i| verts[i]);
            match unit(cross(sub(b, a), sub(c, a))) {
                Some(n) => n.map(|x| x as f32),
                None => [f32::NAN; 3],
            }
        };
        self.face.par_iter().map(|&f| if f == EMPTY { [f32::NAN; 3] } else { face_normal(f) }).collect()
    }

    /// Interpolates per-vertex values into `out` (#H*W): at each pixel
    /// `Σ_i b_i x_t_i` with `b` the perspective-correct barycentrics and `t` the
    /// triangle's corners, computed in f64 and rounded to the output's type `T`; NaN where empty. A field linear
    /// on a triangle in 3D is reproduced exactly (up to rounding) at the pixel centres.
    ///
    /// `tris` must be the array passed to [`rasterize`]; `vertex_values` has #V entries (any
    /// unit, e.g. K).
    ///
    /// # Panics
    /// If `out.len() != W * H`, or an index is out of range for `tris` or `vertex_values`.
    pub fn interpolate<T: Sample>(&self, tris: &[[usize; 3]], vertex_values: &[f64], out: &mut [T]) {
        self.gather(out, |f, b| {
            let t = tris[f as usize];
            b[0] * vertex_values[t[0]] + b[1] * vertex_values[t[1]] + b[2] * vertex_values[t[2]]
        });
    }

    /// Writes per-face values into `out` (#H*W): the value of the triangle seen at each pixel
    /// (e.g. an absorbed flux, W m^-2), rounded to f32; NaN where empty.
    ///
    /// # Panics
    /// If `out.len() != W * H`, or a face index is out of range for `face_values`.
    pub fn interpolate_face(&self, face_values: &[f64], out: &mut [f32]) {
        self.gather(out, |f, _| face_values[f as usize]);
    }

    fn gather<T: Sample>(&self, out: &mut [T], value: impl Fn(u32, &[f64; 3]) -> f64 + Sync) {
        assert_eq!(out.len(), self.pixel_count(), "output image has the wrong number of pixels");
        let band_len = self.width as usize * BAND_ROWS;
        out.par_chunks_mut(band_len).zip(self.face.par_chunks(band_len)).zip(self.bary.par_chunks(band_len)).for_each(
            |((out, face), bary)| {
                for ((o, &f), b) in out.iter_mut().zip(face).zip(bary) {
                    *o = if f == EMPTY { T::NAN } else { T::from_f64(value(f, b)) };
                }
            },
        );
    }
}

/// The float type of an output image: f32 for what a camera stores, f64 for ground truth that
/// must keep float32's lost digits.
pub trait Sample: Copy + Send + Sync {
    /// Not a number (empty pixels).
    const NAN: Self;
    /// `x` rounded to this type.
    fn from_f64(x: f64) -> Self;
}

impl Sample for f32 {
    const NAN: f32 = f32::NAN;
    fn from_f64(x: f64) -> f32 {
        x as f32
    }
}

impl Sample for f64 {
    const NAN: f64 = f64::NAN;
    fn from_f64(x: f64) -> f64 {
        x
    }
}
