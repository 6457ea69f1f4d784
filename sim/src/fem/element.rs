//! Element kernels of the P1 heat equation: pure functions on one tetrahedron or one
//! boundary triangle, fixed-size arrays in and out. Units in each doc comment.
//!
//! Local ordering: tetrahedron nodes 0..4 as given (positively oriented, see
//! [`crate::mesh::tetmesh::TetMesh`]); triangle nodes 0..3 as given.

use crate::vec3::{cross, dot, scale, sub};

/// Gradients of the four barycentric (P1 hat) functions of a tetrahedron (1/m) and its
/// volume (m^3). Returns `None` for a degenerate (zero-volume) tetrahedron.
///
/// With edge vectors e1 = p1 - p0, e2 = p2 - p0, e3 = p3 - p0 and 6V = e1 . (e2 x e3):
/// grad phi_1 = (e2 x e3) / 6V, grad phi_2 = (e3 x e1) / 6V, grad phi_3 = (e1 x e2) / 6V,
/// grad phi_0 = -(grad phi_1 + grad phi_2 + grad phi_3).
pub fn tet_gradients(p: &[[f64; 3]; 4]) -> Option<([[f64; 3]; 4], f64)> {
    let e1 = sub(p[1], p[0]);
    let e2 = sub(p[2], p[0]);
    let e3 = sub(p[3], p[0]);
    let c23 = cross(e2, e3);
    let det = dot(e1, c23);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let g1 = scale(c23, 1.0 / det);
    let g2 = scale(cross(e3, e1), 1.0 / det);
    let g3 = scale(cross(e1, e2), 1.0 / det);
    let g0 = [-(g1[0] + g2[0] + g3[0]), -(g1[1] + g2[1] + g3[1]), -(g1[2] + g2[2] + g3[2])];
    Some(([g0, g1, g2, g3], det.abs() / 6.0))
}

/// Conduction stiffness of one tetrahedron (W/K): K_ij = k V grad phi_i . grad phi_j, for
/// conductivity `k` (W/(m K)). Symmetric; rows sum to zero.
#[allow(non_snake_case)]
pub fn tet_stiffness(grads: &[[f64; 3]; 4], volume: f64, k: f64) -> [[f64; 4]; 4] {
    let mut K = [[0.0; 4]; 4];
    for i in 0..4 {
        for j in i..4 {
            let v = k * volume * dot(grads[i], grads[j]);
            K[i][j] = v;
            K[j][i] = v;
        }
    }
    K
}

/// Consistent heat capacity of one tetrahedron (J/K): M_ij = rho c_p V (1 + delta_ij) / 20,
/// for volumetric heat capacity `rho_c` = rho c_p (J/(m^3 K)). Entries sum to rho c_p V.
#[allow(non_snake_case)]
pub fn tet_mass_consistent(volume: f64, rho_c: f64) -> [[f64; 4]; 4] {
    let off = rho_c * volume / 20.0;
    let mut M = [[off; 4]; 4];
    for (i, row) in M.iter_mut().enumerate() {
        row[i] = 2.0 * off;
    }
    M
}

/// Lumped (row-sum) heat capacity of one tetrahedron (J/K): rho c_p V / 4 on each node.
pub fn tet_mass_lumped(volume: f64, rho_c: f64) -> [f64; 4] {
    [rho_c * volume / 4.0; 4]
}

/// Area of a triangle (m^2).
pub fn tri_area(p: &[[f64; 3]; 3]) -> f64 {
    let n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
    0.5 * dot(n, n).sqrt()
}

/// Consistent boundary mass of a triangle times a coefficient `c` (for convection, c = h in
/// W/(m^2 K), giving W/K): B_ij = c A (1 + delta_ij) / 12. Entries sum to c A.
#[allow(non_snake_case)]
pub fn tri_mass(area: f64, c: f64) -> [[f64; 3]; 3] {
    let off = c * area / 12.0;
    let mut B = [[off; 3]; 3];
    for (i, row) in B.iter_mut().enumerate() {
        row[i] = 2.0 * off;
    }
    B
}

/// Load of a flux `q` (W/m^2) constant over a triangle of area `area` (m^2): q A / 3 on each
/// node (W), the exact integral of q phi_i.
pub fn tri_flux_load(area: f64, q: f64) -> [f64; 3] {
    [q * area / 3.0; 3]
}

#[cfg(test)]
mod tests {
    use super::*;

    const UNIT: [[f64; 3]; 4] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

    #[test]
    fn gradients_reproduce_linear_functions() {
        // A skewed tetrahedron; u(x) = 2 + 3x - y + 0.5z has gradient (3, -1, 0.5).
        let p = [[0.1, 0.2, -0.3], [1.3, 0.1, 0.2], [0.2, 0.9, 0.1], [0.4, 0.3, 1.1]];
        let (g, v) = tet_gradients(&p).unwrap();
        let u = |q: [f64; 3]| 2.0 + 3.0 * q[0] - q[1] + 0.5 * q[2];
        let mut grad = [0.0; 3];
        for i in 0..4 {
            for d in 0..3 {
                grad[d] += u(p[i]) * g[i][d];
            }
        }
        assert!((grad[0] - 3.0).abs() < 1e-13 && (grad[1] + 1.0).abs() < 1e-13 && (grad[2] - 0.5).abs() < 1e-13);
        assert!(v > 0.0);
    }

    #[test]
    fn stiffness_rows_sum_to_zero_and_mass_sums_to_capacity() {
        let (g, v) = tet_gradients(&UNIT).unwrap();
        assert!((v - 1.0 / 6.0).abs() < 1e-15);
        let k = tet_stiffness(&g, v, 2.0);
        for row in &k {
            assert!(row.iter().sum::<f64>().abs() < 1e-15);
        }
        // Unit right tetrahedron: K_00 = k V |grad phi_0|^2 = 2 * (1/6) * 3.
        assert!((k[0][0] - 1.0).abs() < 1e-15);
        let m = tet_mass_consistent(v, 3.0);
        let total: f64 = m.iter().flatten().sum();
        assert!((total - 3.0 * v).abs() < 1e-15);
        assert!((tet_mass_lumped(v, 3.0).iter().sum::<f64>() - 3.0 * v).abs() < 1e-15);
    }

    #[test]
    fn stiffness_is_invariant_under_scaling_by_1e6() {
        // K scales like length (V |grad|^2 ~ L^3 / L^2).
        for s in [1e-6, 1e6] {
            let p = UNIT.map(|q| q.map(|c| c * s));
            let (g, v) = tet_gradients(&p).unwrap();
            let k = tet_stiffness(&g, v, 1.0);
            assert!((k[0][0] / s - 1.0 / 2.0).abs() < 1e-12, "{}", k[0][0] / s);
        }
    }

    #[test]
    fn triangle_kernels_integrate_exactly() {
        let p = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let a = tri_area(&p);
        assert_eq!(a, 1.0);
        let b = tri_mass(a, 5.0);
        assert!((b.iter().flatten().sum::<f64>() - 5.0).abs() < 1e-15);
        assert_eq!(tri_flux_load(a, 30.0), [10.0; 3]);
    }
}
