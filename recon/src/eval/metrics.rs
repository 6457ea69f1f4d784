//! Distance statistics and surface samples.
//!
//! - [`DistanceStats`]: mean, root mean square, 95th percentile (nearest rank) and maximum of a
//!   set of unsigned distances (m).
//! - [`surface_samples`]: deterministic area-weighted points on a triangle mesh, stratified:
//!   sample `k` of `N` lies on the face whose cumulative-area interval contains
//!   `(k + 1/2)/N` of the total area, at barycentric coordinates from the `R_2` low-discrepancy
//!   sequence (reflected into the triangle), so each face gets a number of samples
//!   proportional to its area, without a random seed.

// `!(x > 0.0)` is deliberate: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use heatsim::mesh::TriMesh;
use heatsim::vec3::{add, scale, sub};
use serde::Serialize;

/// Statistics of unsigned distances, m.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct DistanceStats {
    /// Number of distances.
    pub count: usize,
    /// Mean, m.
    pub mean: f64,
    /// Root mean square, m.
    pub rmse: f64,
    /// 95th percentile (nearest rank: the smallest value with at least 95 % at or below), m.
    pub p95: f64,
    /// Maximum, m.
    pub max: f64,
}

impl DistanceStats {
    /// Statistics of `d` (m); all NaN for an empty slice.
    pub fn of(d: &[f64]) -> DistanceStats {
        if d.is_empty() {
            return DistanceStats { count: 0, mean: f64::NAN, rmse: f64::NAN, p95: f64::NAN, max: f64::NAN };
        }
        let n = d.len() as f64;
        let mean = d.iter().sum::<f64>() / n;
        let rmse = (d.iter().map(|x| x * x).sum::<f64>() / n).sqrt();
        let mut s = d.to_vec();
        s.sort_by(f64::total_cmp);
        let rank = ((0.95 * n).ceil() as usize).clamp(1, s.len());
        DistanceStats { count: d.len(), mean, rmse, p95: s[rank - 1], max: s[s.len() - 1] }
    }
}

/// `n` area-weighted points on `mesh` (m), each with the index of its face (see the module
/// documentation). Faces of zero area get none.
pub fn surface_samples(mesh: &TriMesh, n: usize) -> Vec<([f64; 3], usize)> {
    let mut cdf = Vec::with_capacity(mesh.tris.len());
    let mut total = 0.0;
    for f in 0..mesh.tris.len() {
        total += mesh.face_area(f);
        cdf.push(total);
    }
    if !(total > 0.0) || n == 0 {
        return Vec::new();
    }
    // R2 sequence constants: 1/phi2 and 1/phi2^2, phi2 the plastic number.
    const A1: f64 = 0.754_877_666_246_692_7;
    const A2: f64 = 0.569_840_290_998_053_3;
    (0..n)
        .map(|k| {
            let target = (k as f64 + 0.5) / n as f64 * total;
            let f = cdf.partition_point(|&c| c < target).min(cdf.len() - 1);
            let mut u = (0.5 + A1 * k as f64).fract();
            let mut v = (0.5 + A2 * k as f64).fract();
            if u + v > 1.0 {
                u = 1.0 - u;
                v = 1.0 - v;
            }
            let [a, b, c] = mesh.tris[f].map(|i| mesh.verts[i]);
            (add(a, add(scale(sub(b, a), u), scale(sub(c, a), v))), f)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_of_known_values() {
        let d: Vec<f64> = (1..=100).map(|i| i as f64).collect();
        let s = DistanceStats::of(&d);
        assert_eq!(s.mean, 50.5);
        assert_eq!(s.p95, 95.0);
        assert_eq!(s.max, 100.0);
        assert!((s.rmse - (338_350.0f64 / 100.0).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn samples_follow_area() {
        // Two triangles, areas 1/2 and 3/2.
        let mesh = TriMesh::try_new(
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [3.0, 0.0, 1.0], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]],
            vec![[0, 1, 2], [5, 3, 4]],
        )
        .unwrap();
        let s = surface_samples(&mesh, 4000);
        let on0 = s.iter().filter(|x| x.1 == 0).count();
        assert_eq!(on0, 1000);
        // Every sample lies in its triangle's plane and inside it.
        for (p, f) in &s {
            let z = if *f == 0 { 0.0 } else { 1.0 };
            assert_eq!(p[2], z);
            let lim = if *f == 0 { 1.0 } else { 3.0 };
            assert!(p[0] >= 0.0 && p[1] >= 0.0 && p[0] / lim + p[1] <= 1.0 + 1e-12);
        }
        // The mean of samples of one triangle approaches its centroid.
        let m: [f64; 3] = s.iter().filter(|x| x.1 == 0).fold([0.0; 3], |a, x| add(a, scale(x.0, 1e-3)));
        assert!((m[0] - 1.0 / 3.0).abs() < 2e-3 && (m[1] - 1.0 / 3.0).abs() < 2e-3, "{m:?}");
    }
}
