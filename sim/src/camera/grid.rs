//! [`PixelGrid`]: the triangle mesh with one vertex per masked pixel (paper Sec. 5, "we create a
//! flat triangular mesh within the mask where every pixel is associated to a vertex").
//!
//! The simulator (surface solver on the camera grid) and the reconstruction share this exact
//! connectivity, so that an operator estimated from a video can be compared entry by entry
//! with the true one.
//!
//! **Construction.** Every masked pixel is a candidate vertex. Every 2 x 2 block of pixels
//! with corners `p00 = (u, v)`, `p10 = (u+1, v)`, `p01 = (u, v+1)`, `p11 = (u+1, v+1)`
//! (`(u, v)` = (column, row)) contributes
//! - all four in the mask: two triangles split along the **main diagonal** `p00`-`p11`
//!   (top-left to bottom-right in the image): `(p00, p01, p11)` and `(p00, p11, p10)`;
//! - exactly three in the mask: the one triangle of those three;
//! - fewer: nothing.
//!
//! Candidate pixels that end up in no triangle (isolated pixels, one-pixel-wide lines) are
//! **dropped**: they are not vertices, and `vertex_of_pixel` is [`NOT_A_VERTEX`] there. The
//! vertices are numbered in row-major pixel order (`pixels` is increasing).
//!
//! **Orientation.** With the OpenCV camera (x right, y down, z forward) and pixel `(u, v)`
//! seeing the direction `((u - c_x)/f_x, (v - c_y)/f_y, 1)`, every triangle is listed so that
//! its image-plane signed area `(b - a) x (c - a)` (with `x = u`, `y = v`) is negative, i.e.
//! counter-clockwise as the picture is displayed (v downwards). Back-projecting the pixels onto
//! any surface the camera sees (depth single-valued and the surface in front of the camera),
//! the triangle normals `(p_b - p_a) x (p_c - p_a)` then point towards the camera (their dot
//! product with the viewing ray is negative). For a fronto-parallel plane the normal is
//! exactly `-z`.
//!
//! Checkerboard-like masks (two blocks touching only at a corner) give non-manifold vertices
//! shared by two fans; the mesh is still a valid triangle list.
//!
//! **Pyramid.** [`downsample_mask`] halves a mask: coarse pixel `(U, V)` covers fine pixels
//! `(2U..2U+2, 2V..2V+2)` and is in the mask only if all four are (so that block averages of
//! images never mix in background); an odd last row or column is dropped. Coarse pixel centres
//! sit at fine coordinates `2U + 1/2`, so the coarse intrinsics are `f' = f/2`,
//! `c' = (c - 1/2)/2`.

/// Value of [`PixelGrid::vertex_of_pixel`] at pixels that are not vertices.
pub const NOT_A_VERTEX: u32 = u32::MAX;

/// The pixel-grid triangle mesh of a mask (see the module doc for the rules).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PixelGrid {
    /// Image width W, in pixels.
    pub width: usize,
    /// Image height H, in pixels.
    pub height: usize,
    /// Vertex k is pixel `pixels[k] = v * W + u` (row-major, increasing).
    pub pixels: Vec<usize>,
    /// For each of the `W * H` pixels, its vertex index, or [`NOT_A_VERTEX`].
    pub vertex_of_pixel: Vec<u32>,
    /// Triangles as vertex indices, oriented towards the camera (module doc).
    pub tris: Vec<[usize; 3]>,
}

/// Errors from [`PixelGrid::try_new`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum GridError {
    /// The mask length is not `width * height`.
    #[error("mask has {len} pixels, expected width {width} x height {height} = {}", width * height)]
    MaskSize {
        /// Mask length.
        len: usize,
        /// Width.
        width: usize,
        /// Height.
        height: usize,
    },
    /// Too many pixels for `u32` vertex indices.
    #[error("image of {0} pixels is too large for u32 vertex indices")]
    TooLarge(usize),
}

impl PixelGrid {
    /// The pixel-grid mesh of `mask` (`width * height`, row-major).
    ///
    /// # Panics
    /// If `mask.len() != width * height` (use [`PixelGrid::try_new`] for an error instead).
    pub fn new(mask: &[bool], width: usize, height: usize) -> PixelGrid {
        match PixelGrid::try_new(mask, width, height) {
            Ok(g) => g,
            Err(e) => panic!("PixelGrid::new: {e}"),
        }
    }

    /// As [`PixelGrid::new`], with an error for a mask of the wrong size.
    ///
    /// # Errors
    /// [`GridError::MaskSize`], [`GridError::TooLarge`].
    pub fn try_new(mask: &[bool], width: usize, height: usize) -> Result<PixelGrid, GridError> {
        let n = width.checked_mul(height).ok_or(GridError::TooLarge(usize::MAX))?;
        if mask.len() != n {
            return Err(GridError::MaskSize { len: mask.len(), width, height });
        }
        if n >= NOT_A_VERTEX as usize {
            return Err(GridError::TooLarge(n));
        }
        // Triangles in pixel indices first.
        let mut pix_tris: Vec<[usize; 3]> = Vec::new();
        for v in 0..height.saturating_sub(1) {
            for u in 0..width.saturating_sub(1) {
                let p00 = v * width + u;
                let p10 = p00 + 1;
                let p01 = p00 + width;
                let p11 = p01 + 1;
                let inside = [mask[p00], mask[p10], mask[p01], mask[p11]];
                match inside.iter().filter(|&&b| b).count() {
                    4 => {
                        pix_tris.push([p00, p01, p11]);
                        pix_tris.push([p00, p11, p10]);
                    }
                    3 => {
                        let t: Vec<usize> =
                            [p00, p10, p01, p11].into_iter().zip(inside).filter(|&(_, b)| b).map(|(p, _)| p).collect();
                        pix_tris.push(orient([t[0], t[1], t[2]], width));
                    }
                    _ => {}
                }
            }
        }
        let mut used = vec![false; n];
        for t in &pix_tris {
            for &p in t {
                used[p] = true;
            }
        }
        let mut vertex_of_pixel = vec![NOT_A_VERTEX; n];
        let mut pixels = Vec::new();
        for (p, &u) in used.iter().enumerate() {
            if u {
                vertex_of_pixel[p] = pixels.len() as u32;
                pixels.push(p);
            }
        }
        let tris = pix_tris.iter().map(|t| t.map(|p| vertex_of_pixel[p] as usize)).collect();
        Ok(PixelGrid { width, height, pixels, vertex_of_pixel, tris })
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.pixels.len()
    }

    /// Pixel coordinates `(u, v)` = (column, row) of vertex `k`.
    pub fn pixel_uv(&self, k: usize) -> (usize, usize) {
        (self.pixels[k] % self.width, self.pixels[k] / self.width)
    }

    /// The mask of the vertices (pixels that are vertices), `W * H`.
    pub fn vertex_mask(&self) -> Vec<bool> {
        self.vertex_of_pixel.iter().map(|&k| k != NOT_A_VERTEX).collect()
    }

    /// The undirected edges `(i, j)` with `i < j`, sorted, each once.
    pub fn edges(&self) -> Vec<[usize; 2]> {
        let mut e: Vec<[usize; 2]> = Vec::with_capacity(self.tris.len() * 3);
        for t in &self.tris {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                e.push([a.min(b), a.max(b)]);
            }
        }
        e.sort_unstable();
        e.dedup();
        e
    }
}

/// Order three pixels so that the image-plane signed area (u right, v down) is negative.
fn orient(t: [usize; 3], width: usize) -> [usize; 3] {
    let uv = |p: usize| ((p % width) as i64, (p / width) as i64);
    let (a, b, c) = (uv(t[0]), uv(t[1]), uv(t[2]));
    let cross = (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0);
    if cross > 0 {
        [t[0], t[2], t[1]]
    } else {
        t
    }
}

/// Halve a mask (`width * height`, row-major): coarse pixel `(U, V)` is in the mask iff its four
/// fine pixels are. Returns `(mask, width / 2, height / 2)` (odd last row/column dropped).
///
/// # Panics
/// If `mask.len() != width * height`.
pub fn downsample_mask(mask: &[bool], width: usize, height: usize) -> (Vec<bool>, usize, usize) {
    assert_eq!(mask.len(), width * height, "downsample_mask: mask size");
    let (w2, h2) = (width / 2, height / 2);
    let mut out = vec![false; w2 * h2];
    for v in 0..h2 {
        for u in 0..w2 {
            let p = 2 * v * width + 2 * u;
            out[v * w2 + u] = mask[p] && mask[p + 1] && mask[p + width] && mask[p + width + 1];
        }
    }
    (out, w2, h2)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn signed_area(g: &PixelGrid, t: &[usize; 3]) -> i64 {
        let uv = |k: usize| {
            let (u, v) = g.pixel_uv(k);
            (u as i64, v as i64)
        };
        let (a, b, c) = (uv(t[0]), uv(t[1]), uv(t[2]));
        (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0)
    }

    #[test]
    fn full_block_and_counts() {
        // 3 x 2 full mask: 2 blocks, 4 triangles, 6 vertices.
        let g = PixelGrid::new(&[true; 6], 3, 2);
        assert_eq!(g.vertex_count(), 6);
        assert_eq!(g.tris.len(), 4);
        // Main diagonal: (0,0)-(1,1) is an edge, (1,0)-(0,1) is not.
        let e = g.edges();
        assert!(e.contains(&[0, 4]));
        assert!(!e.contains(&[1, 3]));
        assert_eq!(e.len(), 7 + 2); // 7 grid edges + 2 diagonals
        for t in &g.tris {
            assert_eq!(signed_area(&g, t), -1);
        }
    }

    #[test]
    fn three_pixel_blocks_all_orientations() {
        for missing in 0..4 {
            let mut m = [true; 4];
            m[missing] = false;
            let g = PixelGrid::new(&m, 2, 2);
            assert_eq!(g.tris.len(), 1);
            assert_eq!(g.vertex_count(), 3);
            assert_eq!(signed_area(&g, &g.tris[0]), -1, "missing {missing}");
        }
    }

    #[test]
    fn isolated_pixels_dropped() {
        // Pixel (3,0) is isolated; (0,2),(1,2) form a line with no triangle.
        #[rustfmt::skip]
        let m = [
            true, true, false, true,
            true, true, false, false,
            false, false, false, false,
            true, true, false, false,
        ];
        let g = PixelGrid::new(&m, 4, 4);
        assert_eq!(g.pixels, vec![0, 1, 4, 5]);
        assert_eq!(g.vertex_of_pixel[3], NOT_A_VERTEX);
        assert_eq!(g.vertex_of_pixel[12], NOT_A_VERTEX);
        assert_eq!(g.vertex_of_pixel[5], 3);
        let vm = g.vertex_mask();
        assert_eq!(vm.iter().filter(|&&b| b).count(), 4);
    }

    #[test]
    fn wrong_mask_size_is_error() {
        assert!(matches!(PixelGrid::try_new(&[true; 5], 3, 2), Err(GridError::MaskSize { .. })));
        let g = PixelGrid::new(&[], 0, 0);
        assert_eq!(g.vertex_count(), 0);
    }

    /// Back-project a disc of pixels onto a sphere seen from the camera: every triangle normal
    /// points towards the camera.
    #[test]
    fn normals_face_the_camera_on_a_sphere() {
        let (w, h) = (40usize, 30usize);
        let (f, cx, cy) = (50.0, 19.5, 14.5);
        let centre = [0.01, -0.02, 0.5];
        let r = 0.12;
        let mut mask = vec![false; w * h];
        let mut pts = vec![[0.0f64; 3]; w * h];
        for v in 0..h {
            for u in 0..w {
                let d = [(u as f64 - cx) / f, (v as f64 - cy) / f, 1.0];
                // Ray-sphere nearest intersection.
                let dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
                let dc = d[0] * centre[0] + d[1] * centre[1] + d[2] * centre[2];
                let cc = centre.iter().map(|x| x * x).sum::<f64>();
                let disc = dc * dc - dd * (cc - r * r);
                if disc > 0.0 {
                    let s = (dc - disc.sqrt()) / dd;
                    mask[v * w + u] = true;
                    pts[v * w + u] = [s * d[0], s * d[1], s * d[2]];
                }
            }
        }
        let g = PixelGrid::new(&mask, w, h);
        assert!(g.tris.len() > 100);
        for t in &g.tris {
            let p: Vec<[f64; 3]> = t.iter().map(|&k| pts[g.pixels[k]]).collect();
            let e1 = [p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]];
            let e2 = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
            let n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
            // Ray from the camera centre (origin) to the triangle: n . p < 0.
            let dot = n[0] * p[0][0] + n[1] * p[0][1] + n[2] * p[0][2];
            assert!(dot < 0.0, "triangle {t:?} faces away: {dot}");
        }
        // And the fronto-parallel plane gives exactly -z.
        let g = PixelGrid::new(&[true; 4], 2, 2);
        for t in &g.tris {
            let p: Vec<[f64; 3]> = t.iter().map(|&k| [(k % 2) as f64, (k / 2) as f64, 1.0]).collect();
            let e1 = [p[1][0] - p[0][0], p[1][1] - p[0][1]];
            let e2 = [p[2][0] - p[0][0], p[2][1] - p[0][1]];
            assert_eq!(e1[0] * e2[1] - e1[1] * e2[0], -1.0);
        }
    }

    #[test]
    fn downsample_rule() {
        #[rustfmt::skip]
        let m = [
            true, true, true, false, true,
            true, true, true, true, true,
            true, true, true, true, true,
        ];
        let (d, w2, h2) = downsample_mask(&m, 5, 3);
        assert_eq!((w2, h2), (2, 1));
        assert_eq!(d, vec![true, false]);
    }
}
