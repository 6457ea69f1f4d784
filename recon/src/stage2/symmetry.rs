//! Mirror symmetry of the depth (paper Eq. 11's `L_sy`): the authors' left/right
//! symmetry about the mask's centre, used at the coarsest level as a regulariser.
//!
//! The mirror axis is the image column `u_c` (pixels) through the mask's centroid. Pixel
//! `(u, v)` mirrors to `(2u_c - u, v)`, generally between two pixels `a` (column
//! `⌊ 2u_c - u⌋`) and `b` (the next); its mirror depth is their linear interpolation
//! `tilde(z)_i = (1 - t) z_a + t z_b`. Vertices whose mirror is not inside the mask (both
//! pixels vertices) carry no term. With `P` such vertices and a reference depth `z_ref` (m)
//! that makes the term dimensionless,
//! `E_sy = 1/P Σ_i ((z_i - tilde(z)_i)/z_ref)^2,
//!    (∂ E_sy)/(∂ z_i) += (2 r_i)/(P z_ref^2),
//!    (∂ E_sy)/(∂ z_a) -= (1 - t)(2 r_i)/(P z_ref^2),
//!    (∂ E_sy)/(∂ z_b) -= t (2 r_i)/(P z_ref^2),`
//! `r_i = z_i - tilde(z)_i`. Every mirrored pair appears twice (i's mirror and the mirror's),
//! which keeps the term symmetric in the two sides.
//!
//! Depth is along the optical axis, so the term is exact for an object symmetric about the
//! plane through the camera centre and the image column `u_c`; an object whose symmetry plane
//! is off the optical axis sees a small perspective bias. It holds for the ball, the can, the
//! bottles and the hemisphere of the shape-error table, not for the bunny.

use heatsim::camera::grid::NOT_A_VERTEX;
use heatsim::camera::PixelGrid;

/// The mirror pairs of a pixel mesh and the term's normalisation (module doc).
#[derive(Clone, Debug)]
pub struct MirrorSymmetry {
    /// `(i, a, b, t)`: vertex i's mirror depth is `(1 - t) z[a] + t z[b]`.
    pairs: Vec<(usize, usize, usize, f64)>,
    /// Reference depth z_ref, m.
    z_ref: f64,
    /// Mirror axis, image column (pixels).
    pub axis_u: f64,
}

impl MirrorSymmetry {
    /// Mirror about the column through the centroid of `grid`'s pixels, normalised by `z_ref`
    /// (m, > 0; e.g. the level's starting mean depth).
    pub fn new(grid: &PixelGrid, z_ref: f64) -> MirrorSymmetry {
        let n = grid.vertex_count().max(1) as f64;
        let axis_u = (0..grid.vertex_count()).map(|k| grid.pixel_uv(k).0 as f64).sum::<f64>() / n;
        MirrorSymmetry::with_axis(grid, axis_u, z_ref)
    }

    /// Mirror about image column `axis_u` (pixels).
    pub fn with_axis(grid: &PixelGrid, axis_u: f64, z_ref: f64) -> MirrorSymmetry {
        let vertex = |u: i64, v: usize| -> Option<usize> {
            if u < 0 || u as usize >= grid.width {
                return None;
            }
            let k = grid.vertex_of_pixel[v * grid.width + u as usize];
            (k != NOT_A_VERTEX).then_some(k as usize)
        };
        let pairs = (0..grid.vertex_count())
            .filter_map(|i| {
                let (u, v) = grid.pixel_uv(i);
                let m = 2.0 * axis_u - u as f64;
                let a = m.floor();
                let t = m - a;
                let ia = vertex(a as i64, v)?;
                // On a pixel centre (t = 0) the neighbour is not needed.
                let ib = if t > 0.0 { vertex(a as i64 + 1, v)? } else { ia };
                Some((i, ia, ib, t))
            })
            .collect();
        MirrorSymmetry { pairs, z_ref, axis_u }
    }

    /// Number of vertices that carry the term.
    pub fn len(&self) -> usize {
        self.pairs.len()
    }

    /// Whether no vertex carries the term.
    pub fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }

    /// `E_sy` at depths `z` (m; unweighted, dimensionless); `weight` times its gradient
    /// (1/m) is added to `grad`.
    pub fn term(&self, z: &[f64], weight: f64, grad: Option<&mut [f64]>) -> f64 {
        if self.pairs.is_empty() {
            return 0.0;
        }
        let k = 1.0 / (self.pairs.len() as f64 * self.z_ref * self.z_ref);
        let residual = |&(i, a, b, t): &(usize, usize, usize, f64)| z[i] - (1.0 - t) * z[a] - t * z[b];
        let e = self.pairs.iter().map(|p| residual(p).powi(2)).sum::<f64>() * k;
        if let Some(g) = grad {
            for p in &self.pairs {
                let &(i, a, b, t) = p;
                let d = 2.0 * weight * k * residual(p);
                g[i] += d;
                g[a] -= (1.0 - t) * d;
                g[b] -= t * d;
            }
        }
        e
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 7 x 4 mask whose columns 1..=5 are vertices (centroid column 3) and one extra pixel at
    /// (6, 0), which moves the axis off a pixel centre.
    fn grid(extra: bool) -> PixelGrid {
        let (w, h) = (7, 4);
        let mut mask = vec![false; w * h];
        for v in 0..h {
            for u in 1..=5 {
                mask[v * w + u] = true;
            }
        }
        if extra {
            mask[6] = true;
        }
        PixelGrid::new(&mask, w, h)
    }

    #[test]
    fn symmetric_depths_score_zero_and_asymmetric_ones_do_not() {
        let g = grid(false);
        let s = MirrorSymmetry::new(&g, 0.5);
        assert_eq!(s.axis_u, 3.0);
        assert_eq!(s.len(), g.vertex_count());
        let z: Vec<f64> = (0..g.vertex_count()).map(|k| 0.5 + 0.01 * (g.pixel_uv(k).0 as f64 - 3.0).powi(2)).collect();
        assert!(s.term(&z, 1.0, None).abs() < 1e-30);
        let tilted: Vec<f64> = (0..g.vertex_count()).map(|k| 0.5 + 0.01 * g.pixel_uv(k).0 as f64).collect();
        // z_u - z_{6-u} = 0.02 (u - 3): mean of (0.02 (u-3) / 0.5)^2 over u = 1..5 is 0.0016 * 2.
        let e = s.term(&tilted, 1.0, None);
        assert!((e - 0.0016 * 2.0).abs() < 1e-15, "{e}");
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let g = grid(true);
        let s = MirrorSymmetry::new(&g, 0.4);
        assert!(s.axis_u.fract() != 0.0, "the extra pixel moves the axis between pixel centres");
        assert!(!s.is_empty() && s.len() < g.vertex_count(), "{}", s.len());
        let z: Vec<f64> = (0..g.vertex_count()).map(|k| 0.4 + 1e-3 * ((7 * k) % 5) as f64).collect();
        let w = 3.0;
        let mut grad = vec![0.0; z.len()];
        s.term(&z, w, Some(&mut grad));
        let h = 1e-6;
        for i in 0..z.len() {
            let (mut zp, mut zm) = (z.clone(), z.clone());
            zp[i] += h;
            zm[i] -= h;
            let fd = w * (s.term(&zp, 1.0, None) - s.term(&zm, 1.0, None)) / (2.0 * h);
            assert!((fd - grad[i]).abs() <= 1e-7 * (1.0 + grad[i].abs()), "vertex {i}: fd {fd} analytic {}", grad[i]);
        }
        assert!(grad.iter().any(|g| g.abs() > 1e-3), "the test point is asymmetric");
    }
}
