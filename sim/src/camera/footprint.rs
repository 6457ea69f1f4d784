//! [`Footprint`]: the supersampled rasterisation of a mesh (once per run) and, every frame, the
//! film it gives: the radiance temperature each pixel integrates over its footprint through
//! the lens ([`optics`](super::optics) states the model).
//!
//! # Method
//! The mesh is rasterised through [`supersampled_camera`], the camera with `s` times the
//! focal length and `s (W + 2 m) x s (H + 2 m)` pixels, whose pixel centres are the
//! sub-samples of the image extended by the kernel's margin `m` ([`PixelKernel::margin`]).
//! The rasteriser ([`rasterize`]) runs on strips of [`STRIP_SUB_SAMPLES`] sub-samples, so its
//! depth buffer stays small, and only the sub-samples that see the object are kept: their
//! column, triangle and perspective-correct barycentrics (32 bytes each), row by row.
//!
//! A frame is then a gather and a sparse separable sum: for a per-vertex temperature `T`
//! (K) and the background's `T_b` (K), every kept sub-sample `i` contributes
//! `d_i = T_i^4 - T_b^4` with `T_i = Σ_k b_k T_(t_k)`, and the pixel integrates
//! `D(u, v) = Σ_i c[t_u(i)] c[t_v(i)] d_i` (each sub-sample is scattered along its row to the
//! ≈ `1 + 2R/s` pixels whose kernel covers it, and each row's result to the pixel rows that
//! cover it). Background sub-samples contribute nothing, so the cost is proportional to the
//! sub-samples on the object. The film is
//! `T_eq(u, v) = (T_b^4 + D(u, v))^(1/4)`:
//! the `T^4` mean of the true temperatures over the weighted footprint, with the background
//! counted at `T_b` (why this is the film the sensor needs: [`optics`](super::optics),
//! "Radiance mixing"). Pixels whose kernel covers no sub-sample on the object are NaN (pure
//! background; the sensor reports `T_b` there), except under the mask (the pixel centre
//! sees the object, but no sub-sample does: a sliver thinner than a sub-sample), which get
//! `T_b`. Pixels just outside the mask are finite when blurred or partly covered radiance
//! reaches them.
//!
//! # Determinism
//! Output rows are computed in parallel bands of [`BAND_ROWS`] rows; each row sums its
//! sub-samples in one fixed order, so the result does not depend on the thread count.

use rayon::prelude::*;

use super::optics::PixelKernel;
use super::raster::{rasterize, EMPTY};
use super::Camera;

/// Sub-samples per rasterisation strip: 2^22, a temporary depth buffer of 150 MB at most
/// (36 bytes per sub-sample), whatever the supersampling.
pub const STRIP_SUB_SAMPLES: usize = 1 << 22;

/// Output rows per parallel band of the per-frame sum. Each band re-scatters the `2R` fine
/// rows it shares with its neighbours; 32 rows of a 512-row image keep that below 10 % at
/// s = 4 with the default PSF (R = 6) and still give 16 tasks.
pub const BAND_ROWS: usize = 32;

/// A sub-sample that sees the object: its column in the supersampled image, the triangle and
/// the perspective-correct barycentrics there (corner order of the triangle).
#[derive(Clone, Copy, Debug, PartialEq)]
struct SubSample {
    col: u32,
    face: u32,
    bary: [f64; 3],
}

/// The supersampled rasterisation of a mesh and the optics' kernel (module documentation).
#[derive(Clone, Debug)]
pub struct Footprint {
    width: usize,
    height: usize,
    kernel: PixelKernel,
    fine_width: usize,
    fine_height: usize,
    /// `fine_height + 1` offsets into `samples`: row r holds `samples[row_start[r]..row_start[r + 1]]`.
    row_start: Vec<usize>,
    samples: Vec<SubSample>,
    /// #H*W weighted fraction of each pixel's footprint that sees the object, in [0, 1].
    coverage: Vec<f64>,
    /// Per fine column, the pixels its sub-samples reach ([`Reach`]).
    col_reach: Vec<Reach>,
    /// Per fine row, the pixel rows it reaches.
    row_reach: Vec<Reach>,
}

/// The pixels whose kernel covers one fine column (or row): `count` pixels from `first`, with
/// weights `weights[index - s k]` for the k-th of them (a table built once, so the per-frame
/// scatter needs no division).
#[derive(Clone, Copy, Debug)]
struct Reach {
    first: u32,
    index: u32,
    count: u32,
}

fn reach_table(kernel: &PixelKernel, fine: usize, n: usize) -> Vec<Reach> {
    (0..fine)
        .map(|c| {
            let mut pixels = kernel.pixels_of(c, n);
            match pixels.next() {
                None => Reach { first: 0, index: 0, count: 0 },
                Some((u, _)) => Reach {
                    first: u as u32,
                    index: (c - kernel.first_sub_sample(u)) as u32,
                    count: 1 + pixels.count() as u32,
                },
            }
        })
        .collect()
}

/// The camera whose pixel centres are the sub-samples of `camera`'s image extended by `margin`
/// pixels on every side, `supersampling` (s) per pixel and axis: size `s (W + 2 margin) x
/// s (H + 2 margin)`, `K' = [[s f_x, s skew, s (c_x + margin) + (s - 1)/2], [0, s f_y,
/// s (c_y + margin) + (s - 1)/2], [0, 0, 1]]`, same pose. Its pixel `(U, V)` sees image
/// coordinates `((U + 1/2)/s - 1/2 - margin, (V + 1/2)/s - 1/2 - margin)`.
///
/// # Panics
/// If `supersampling` is 0 or the size overflows `u32`.
pub fn supersampled_camera(camera: &Camera, supersampling: usize, margin: usize) -> Camera {
    assert!(supersampling > 0, "supersampling must be >= 1");
    let s = supersampling as f64;
    let side = |n: u32| u32::try_from(supersampling * (n as usize + 2 * margin)).expect("supersampled size fits u32");
    let shift = 0.5 * (s - 1.0);
    let k = &camera.k;
    let k = [
        [s * k[0][0], s * k[0][1], s * (k[0][2] + margin as f64) + shift],
        [0.0, s * k[1][1], s * (k[1][2] + margin as f64) + shift],
        [0.0, 0.0, 1.0],
    ];
    Camera { width: side(camera.width), height: side(camera.height), k, r: camera.r, t: camera.t }
}

impl Footprint {
    /// Rasterises the triangles `tris` (#F x 3) of `verts` (#V x 3, world frame, m) at the
    /// sub-samples of `camera`'s pixels with `kernel` (supersampling and PSF), and the
    /// coverage of every pixel.
    ///
    /// # Panics
    /// As [`rasterize`].
    pub fn new(camera: &Camera, kernel: PixelKernel, verts: &[[f64; 3]], tris: &[[usize; 3]]) -> Footprint {
        let fine = supersampled_camera(camera, kernel.supersampling(), kernel.margin());
        let (fine_width, fine_height) = (fine.width as usize, fine.height as usize);
        let strip_rows = (STRIP_SUB_SAMPLES / fine_width).max(1);
        let mut row_start = vec![0];
        let mut samples = Vec::new();
        for row0 in (0..fine_height).step_by(strip_rows) {
            let rows = strip_rows.min(fine_height - row0);
            let mut strip = fine.clone();
            strip.height = rows as u32;
            strip.k[1][2] -= row0 as f64;
            let render = rasterize(&strip, verts, tris);
            for r in 0..rows {
                let line = r * fine_width..(r + 1) * fine_width;
                for (col, (&face, &bary)) in render.face[line.clone()].iter().zip(&render.bary[line]).enumerate() {
                    if face != EMPTY {
                        samples.push(SubSample { col: col as u32, face, bary });
                    }
                }
                row_start.push(samples.len());
            }
        }
        let col_reach = reach_table(&kernel, fine_width, camera.width as usize);
        let row_reach = reach_table(&kernel, fine_height, camera.height as usize);
        let mut footprint = Footprint {
            width: camera.width as usize,
            height: camera.height as usize,
            kernel,
            col_reach,
            row_reach,
            fine_width,
            fine_height,
            row_start,
            samples,
            coverage: Vec::new(),
        };
        let mut coverage = vec![0.0; footprint.width * footprint.height];
        footprint.integrate_into(|_| 1.0, &mut coverage);
        footprint.coverage = coverage;
        footprint
    }

    /// The optics' kernel.
    pub fn kernel(&self) -> &PixelKernel {
        &self.kernel
    }

    /// Number of sub-samples that see the object.
    pub fn object_sub_samples(&self) -> usize {
        self.samples.len()
    }

    /// Size of the supersampled image (width, height), in sub-samples.
    pub fn fine_size(&self) -> (usize, usize) {
        (self.fine_width, self.fine_height)
    }

    /// #H*W weighted fraction of each pixel's footprint (through the PSF) that sees the
    /// object, in [0, 1]: 0 for pure background, 1 inside the object's image.
    pub fn coverage(&self) -> &[f64] {
        &self.coverage
    }

    /// The film of one frame into `out` (#H*W, K): `T_eq = (T_b^4 + D)^(1/4)` for the
    /// per-vertex temperatures `vertex_values` (K, indexed by `tris`, the array passed to
    /// [`Footprint::new`]) and the background at `background` (K), NaN for pure background
    /// off `mask` (#H*W, the pixel centres that see the object), `background` for pure
    /// background under it (module documentation).
    ///
    /// # Panics
    /// If `mask` or `out` does not have W * H elements, or an index is out of range for
    /// `tris` or `vertex_values`.
    pub fn film_into(
        &self,
        tris: &[[usize; 3]],
        vertex_values: &[f64],
        background: f64,
        mask: &[bool],
        out: &mut [f64],
    ) {
        assert_eq!(mask.len(), self.coverage.len(), "mask has the wrong number of pixels");
        let (tb, tb2) = (background, background * background);
        self.integrate_into(
            |s| {
                let t = s.face as usize;
                let [a, b, c] = tris[t];
                let temp = s.bary[0] * vertex_values[a] + s.bary[1] * vertex_values[b] + s.bary[2] * vertex_values[c];
                // T^4 - T_b^4 without cancellation: (T - T_b)(T + T_b)(T^2 + T_b^2).
                (temp - tb) * (temp + tb) * (temp * temp + tb2)
            },
            out,
        );
        let tb4 = tb2 * tb2;
        for ((o, &cover), &m) in out.iter_mut().zip(&self.coverage).zip(mask) {
            *o = if cover > 0.0 {
                (tb4 + *o).max(0.0).sqrt().sqrt()
            } else if m {
                tb
            } else {
                f64::NAN
            };
        }
    }

    /// `out[p] = Σ_i c[t_u(i)] c[t_v(i)] value(i)` over the sub-samples `i` on the object.
    fn integrate_into(&self, value: impl Fn(&SubSample) -> f64 + Sync, out: &mut [f64]) {
        let (w, h) = (self.width, self.height);
        assert_eq!(out.len(), w * h, "output image has the wrong number of pixels");
        let k = &self.kernel;
        let len = k.weights().len();
        let (weights, step) = (k.weights(), k.supersampling());
        out.par_chunks_mut(w * BAND_ROWS).enumerate().for_each(|(band, out)| {
            out.fill(0.0);
            let v0 = band * BAND_ROWS;
            let v1 = v0 + out.len() / w; // exclusive
            let mut row = vec![0.0; w];
            for r in k.first_sub_sample(v0)..(k.first_sub_sample(v1 - 1) + len).min(self.fine_height) {
                let samples = &self.samples[self.row_start[r]..self.row_start[r + 1]];
                if samples.is_empty() {
                    continue;
                }
                row.fill(0.0);
                for s in samples {
                    let x = value(s);
                    let reach = self.col_reach[s.col as usize];
                    for i in 0..reach.count as usize {
                        row[reach.first as usize + i] += weights[reach.index as usize - step * i] * x;
                    }
                }
                let reach = self.row_reach[r];
                for i in 0..reach.count as usize {
                    let v = reach.first as usize + i;
                    if v < v0 || v >= v1 {
                        continue;
                    }
                    let c = weights[reach.index as usize - step * i];
                    let line = &mut out[(v - v0) * w..(v - v0 + 1) * w];
                    for (o, &x) in line.iter_mut().zip(&row) {
                        *o += c * x;
                    }
                }
            }
        });
    }
}
