//! Discrete differential operators of a triangle mesh (paper Eq. 3), shared by the surface
//! solver and the reconstruction.
//!
//! - Cotangent Laplacian: (L f)_i = sum_{j in N(i)} w_ij (f_j - f_i) with
//!   w_ij = (cot alpha_ij + cot beta_ij) / 2, the angles opposite edge ij (one of them on a
//!   boundary edge). Units 1 (dimensionless): L f has the units of f times area / length^2.
//!   -L is the P1 stiffness matrix of the piecewise-linear hat functions: sum over triangles
//!   of A_t grad phi_i . grad phi_j.
//! - Lumped area mass (m^2): barycentric, a_i = sum_{t at i} A_t / 3, or mixed Voronoi
//!   (Meyer et al. 2003): the Voronoi area of i inside each non-obtuse triangle, A_t / 2 at the
//!   obtuse corner of an obtuse triangle and A_t / 4 at its other corners. Both sum to the
//!   mesh's area. M^{-1} L f approximates the Laplace-Beltrami operator of f (1/m^2 x f).
//! - Area-weighted vertex normals, and boundary vertices (ends of edges with one triangle).

use crate::vec3::{cross, dot, norm, sub};

/// The three corners' half cotangents of a triangle: entry c is cot(angle at corner c) / 2,
/// the weight it contributes to the opposite edge (corners c+1, c+2).
pub fn half_cotangents(p: &[[f64; 3]; 3]) -> [f64; 3] {
    let mut out = [0.0; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let a = sub(p[(c + 1) % 3], p[c]);
        let b = sub(p[(c + 2) % 3], p[c]);
        // cot = cos / sin = (a . b) / |a x b|; zero area gives an infinite weight, refused by
        // callers that validate meshes and left to surface as a non-finite number otherwise.
        *o = 0.5 * dot(a, b) / norm(cross(a, b));
    }
    out
}

/// Area of a triangle (m^2).
pub fn triangle_area(p: &[[f64; 3]; 3]) -> f64 {
    0.5 * norm(cross(sub(p[1], p[0]), sub(p[2], p[0])))
}

/// The cotangent Laplacian of a triangle mesh as its list of undirected edges and weights.
#[derive(Clone, Debug, PartialEq)]
pub struct CotanLaplacian {
    /// Number of vertices.
    pub n: usize,
    /// Undirected edges (i < j), sorted.
    pub edges: Vec<[usize; 2]>,
    /// w_ij of each edge (dimensionless); negative across obtuse angles.
    pub weights: Vec<f64>,
}

impl CotanLaplacian {
    /// Assembles the weights of every edge of `tris` over `n` vertices at `verts`.
    pub fn new(verts: &[[f64; 3]], tris: &[[usize; 3]]) -> CotanLaplacian {
        let mut entries: Vec<([usize; 2], f64)> = Vec::with_capacity(3 * tris.len());
        for t in tris {
            let w = half_cotangents(&t.map(|i| verts[i]));
            for c in 0..3 {
                let (a, b) = (t[(c + 1) % 3], t[(c + 2) % 3]);
                entries.push(([a.min(b), a.max(b)], w[c]));
            }
        }
        entries.sort_unstable_by(|x, y| x.0.cmp(&y.0));
        let mut edges: Vec<[usize; 2]> = Vec::with_capacity(entries.len() / 2 + 1);
        let mut weights: Vec<f64> = Vec::with_capacity(entries.len() / 2 + 1);
        for (e, w) in entries {
            if edges.last() == Some(&e) {
                *weights.last_mut().expect("edges and weights grow together") += w;
            } else {
                edges.push(e);
                weights.push(w);
            }
        }
        CotanLaplacian { n: verts.len(), edges, weights }
    }

    /// y = L x: y_i = sum_j w_ij (x_j - x_i).
    pub fn apply(&self, x: &[f64], y: &mut [f64]) {
        y.iter_mut().for_each(|v| *v = 0.0);
        for (&[i, j], &w) in self.edges.iter().zip(&self.weights) {
            let d = w * (x[j] - x[i]);
            y[i] += d;
            y[j] -= d;
        }
    }

    /// The diagonal of L: -sum_j w_ij.
    pub fn diagonal(&self) -> Vec<f64> {
        let mut d = vec![0.0; self.n];
        for (&[i, j], &w) in self.edges.iter().zip(&self.weights) {
            d[i] -= w;
            d[j] -= w;
        }
        d
    }

    /// L as a dense row-major n x n matrix (for tests and small meshes).
    pub fn to_dense(&self) -> Vec<f64> {
        let n = self.n;
        let mut a = vec![0.0; n * n];
        for (&[i, j], &w) in self.edges.iter().zip(&self.weights) {
            a[i * n + j] += w;
            a[j * n + i] += w;
            a[i * n + i] -= w;
            a[j * n + j] -= w;
        }
        a
    }
}

/// How the area of the mesh is shared among its vertices.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum AreaMass {
    /// A_t / 3 to each corner.
    #[default]
    Barycentric,
    /// Mixed Voronoi areas (Meyer, Desbrun, Schroeder and Barr 2003).
    MixedVoronoi,
}

/// The lumped (diagonal) area mass of each vertex (m^2).
pub fn lumped_area(verts: &[[f64; 3]], tris: &[[usize; 3]], kind: AreaMass) -> Vec<f64> {
    let mut a = vec![0.0; verts.len()];
    for t in tris {
        let p = t.map(|i| verts[i]);
        for (c, share) in corner_areas(&p, kind).into_iter().enumerate() {
            a[t[c]] += share;
        }
    }
    a
}

/// The share of a triangle's area given to each corner (m^2); the shares sum to its area.
pub fn corner_areas(p: &[[f64; 3]; 3], kind: AreaMass) -> [f64; 3] {
    let area = triangle_area(p);
    match kind {
        AreaMass::Barycentric => [area / 3.0; 3],
        AreaMass::MixedVoronoi => {
            let dots: [f64; 3] = std::array::from_fn(|c| dot(sub(p[(c + 1) % 3], p[c]), sub(p[(c + 2) % 3], p[c])));
            if let Some(obtuse) = dots.iter().position(|&d| d < 0.0) {
                std::array::from_fn(|c| if c == obtuse { area / 2.0 } else { area / 4.0 })
            } else {
                // Voronoi area of corner c: (|e_b|^2 cot(angle at b) + |e_a|^2 cot(angle at a)) / 8
                // over the two edges at c, each weighted by the cotangent of its opposite angle.
                let cot = half_cotangents(p).map(|h| 2.0 * h);
                std::array::from_fn(|c| {
                    let (a, b) = ((c + 1) % 3, (c + 2) % 3);
                    let len2 = |x: usize, y: usize| {
                        let d = sub(p[x], p[y]);
                        dot(d, d)
                    };
                    (len2(c, a) * cot[b] + len2(c, b) * cot[a]) / 8.0
                })
            }
        }
    }
}

/// Area-weighted unit vertex normals (the normalised sum of the faces' area vectors);
/// [0, 0, 0] for a vertex with no face of non-zero area.
pub fn vertex_normals(verts: &[[f64; 3]], tris: &[[usize; 3]]) -> Vec<[f64; 3]> {
    let mut nrm = vec![[0.0; 3]; verts.len()];
    for t in tris {
        let c = cross(sub(verts[t[1]], verts[t[0]]), sub(verts[t[2]], verts[t[0]]));
        for &i in t {
            for k in 0..3 {
                nrm[i][k] += c[k];
            }
        }
    }
    for v in &mut nrm {
        let l = norm(*v);
        if l > 0.0 {
            *v = v.map(|x| x / l);
        }
    }
    nrm
}

/// Whether each vertex lies on the boundary (on an edge used by exactly one triangle).
pub fn boundary_vertices(n: usize, tris: &[[usize; 3]]) -> Vec<bool> {
    let mut edges: Vec<[usize; 2]> =
        tris.iter().flat_map(|t| (0..3).map(move |c| [t[c].min(t[(c + 1) % 3]), t[c].max(t[(c + 1) % 3])])).collect();
    edges.sort_unstable();
    let mut on = vec![false; n];
    let mut k = 0;
    while k < edges.len() {
        let mut m = k + 1;
        while m < edges.len() && edges[m] == edges[k] {
            m += 1;
        }
        if m - k == 1 {
            on[edges[k][0]] = true;
            on[edges[k][1]] = true;
        }
        k = m;
    }
    on
}

#[cfg(test)]
mod tests {
    use super::*;

    fn right_triangle() -> [[f64; 3]; 3] {
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    }

    #[test]
    fn half_cotangents_of_a_right_triangle() {
        let w = half_cotangents(&right_triangle());
        assert!(w[0].abs() < 1e-15); // right angle
        assert!((w[1] - 0.5).abs() < 1e-15 && (w[2] - 0.5).abs() < 1e-15); // 45 degrees
    }

    #[test]
    fn mixed_voronoi_shares_sum_to_the_area() {
        for p in [
            right_triangle(),
            [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 0.8, 0.1]],
            [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, 0.1, 0.0]],
        ] {
            let s: f64 = corner_areas(&p, AreaMass::MixedVoronoi).iter().sum();
            assert!((s - triangle_area(&p)).abs() < 1e-15 * triangle_area(&p).max(1.0), "{s}");
        }
    }

    #[test]
    fn boundary_of_two_triangles() {
        let on = boundary_vertices(5, &[[0, 1, 2], [0, 2, 3]]);
        assert_eq!(on, vec![true, true, true, true, false]);
    }
}
