//! Analytic derivatives of the per-triangle quantities of [`super::operators`] with respect to
//! the triangle's vertex positions, and a vector-Jacobian product (VJP) over a whole mesh, for
//! the shape stage of the reconstruction (an energy of the cotangent weights and lumped area
//! masses of the current vertex positions).
//!
//! Conventions: a triangle is `p: [[f64; 3]; 3]` (m); a per-corner quantity q_c has the
//! Jacobian `J[c][v][k] = d q_c / d p_v[k]` (c = quantity's corner, v = vertex moved, k = axis).
//! Corners are cyclic: for corner c, a = c+1 and b = c+2 (mod 3).
//!
//! **Half cotangents** (dimensionless; gradient in 1/m). With the edge vectors
//! u = p_a - p_c, v = p_b - p_c, d = u.v, n = u x v and s = |n| (twice the area),
//! cot = d / s, and by the quotient rule with ds/du = (v x n)/s, ds/dv = (n x u)/s:
//!
//! ```text
//! d cot/du = v/s - d (v x n)/s^3 = |v|^2 (|u|^2 v - d u) / s^3
//! d cot/dv = u/s - d (n x u)/s^3 = |u|^2 (|v|^2 u - d v) / s^3
//! ```
//!
//! (the second forms use v x (u x v) = u|v|^2 - v d and Lagrange's identity
//! s^2 + d^2 = |u|^2 |v|^2). Then d cot/dp_a = d cot/du, d cot/dp_b = d cot/dv and
//! d cot/dp_c = -(d cot/du + d cot/dv) (translation invariance); the half cotangent
//! w_c = cot_c / 2 has half these gradients.
//!
//! **Area** (m^2; gradient in m): A = |n|/2 with n = (p_1 - p_0) x (p_2 - p_0), unit normal
//! n^ = n/|n|; dA/dp_v = n^ x (p_{v+2} - p_{v+1}) / 2, i.e. half the opposite edge rotated
//! by 90 degrees in the triangle's plane, pointing away from the triangle.
//!
//! **Corner areas** (m^2; gradient in m). Barycentric: A/3 each, gradient dA/3. Mixed Voronoi
//! (Meyer et al. 2003), the same branches as [`super::operators::corner_areas`]:
//! - no obtuse corner (every (p_a - p_c).(p_b - p_c) >= 0): the Voronoi share
//!   a_c = (|p_c - p_a|^2 cot_b + |p_c - p_b|^2 cot_a) / 8, whose gradient follows by the
//!   product rule from d|p_c - p_a|^2/dp_c = 2 (p_c - p_a) = -d|p_c - p_a|^2/dp_a and the
//!   cotangent gradients above;
//! - an obtuse corner o: a_o = A/2, the others A/4, gradients dA/2 and dA/4.
//!
//! The mixed Voronoi shares are continuous but **not differentiable where a corner is a right
//! angle**: as the angle at c reaches 90 degrees, the Voronoi shares tend to A/2 at c and A/4
//! elsewhere (the circumcentre reaches the hypotenuse), so the values match, but the one-sided
//! gradients differ. Exactly at a right angle (dot product exactly 0) the non-obtuse branch is
//! used, as in the operator, so the returned gradient is the one-sided derivative from the
//! acute side. An optimiser crossing right angles sees a kink; barycentric masses are smooth.
//!
//! **Mesh VJP.** For a scalar E(w, a) of the edge weights w_e of the
//! [`super::operators::CotanLaplacian`] (its edge order) and the lumped masses a_i,
//! [`LaplacianVjp::accumulate`] adds
//! `dE/dx_v = sum_t sum_c [ dE/dw_{e(t,c)} dw^t_c/dx_v + dE/da_{t[c]} da^t_c/dx_v ]`
//! to a gradient buffer, where w^t_c is triangle t's half cotangent at corner c (contributing
//! to the opposite edge e(t,c)) and a^t_c its corner area. Cost: O(#triangles), no Jacobian
//! is formed: area-proportional shares contribute (dE/dA_t) dA_t/dx, and the Voronoi shares of
//! a non-obtuse triangle, sum_c m_c a_c = sum_k (m_{k+1} + m_{k+2}) |e_k|^2 w_k / 4 with e_k
//! the edge opposite corner k, fold into the cotangent adjoints plus an edge-length term. Units: with E in units `[E]`, dE/dw in `[E]`, dE/da in `[E]/m^2`, the output in `[E]/m`.
//!
//! Degenerate (zero-area) triangles give non-finite values and gradients, as in the operators.

use rayon::prelude::*;

use super::operators::{corner_areas, half_cotangents, AreaMass};
use crate::vec3::{add, cross, dot, norm, scale, sub};

/// Jacobian of three per-corner quantities: `J[c][v][k] = d q_c / d p_v[k]`.
pub type CornerJacobian = [[[f64; 3]; 3]; 3];

/// Bad arguments to the mesh-level VJP.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DerivativeError {
    #[error("triangle {tri} refers to vertex {vertex}, but the mesh has {n} vertices")]
    VertexOutOfRange { tri: usize, vertex: usize, n: usize },
    #[error("triangle {tri} repeats vertex {vertex}")]
    RepeatedVertex { tri: usize, vertex: usize },
    #[error("{what} has {got} entries, expected {expected}")]
    Length { what: &'static str, got: usize, expected: usize },
}

/// Half cotangents w_c = cot(angle at c)/2 (as [`super::operators::half_cotangents`]) and their
/// gradients `J[c][v][k] = d w_c / d p_v[k]` (1/m). See the module doc for the formulas.
pub fn half_cotangents_grad(p: &[[f64; 3]; 3]) -> ([f64; 3], CornerJacobian) {
    let mut w = [0.0; 3];
    let mut jac = [[[0.0; 3]; 3]; 3];
    for c in 0..3 {
        let (a, b) = ((c + 1) % 3, (c + 2) % 3);
        let u = sub(p[a], p[c]);
        let v = sub(p[b], p[c]);
        let d = dot(u, v);
        let s = norm(cross(u, v));
        let (uu, vv) = (dot(u, u), dot(v, v));
        w[c] = 0.5 * d / s;
        // Half of d cot/du = |v|^2 (|u|^2 v - d u) / s^3, and likewise for v.
        let k = 0.5 / (s * s * s);
        let gu = scale(sub(scale(v, uu), scale(u, d)), k * vv);
        let gv = scale(sub(scale(u, vv), scale(v, d)), k * uu);
        jac[c][a] = gu;
        jac[c][b] = gv;
        jac[c][c] = scale(add(gu, gv), -1.0);
    }
    (w, jac)
}

/// Triangle area A (m^2, as [`super::operators::triangle_area`]) and its gradient
/// `g[v][k] = dA / d p_v[k]` (m): n^ x (p_{v+2} - p_{v+1}) / 2.
pub fn triangle_area_grad(p: &[[f64; 3]; 3]) -> (f64, [[f64; 3]; 3]) {
    let n = cross(sub(p[1], p[0]), sub(p[2], p[0]));
    let len = norm(n);
    let nh = scale(n, 1.0 / len);
    let g = std::array::from_fn(|v| scale(cross(nh, sub(p[(v + 2) % 3], p[(v + 1) % 3])), 0.5));
    (0.5 * len, g)
}

/// Corner areas (m^2, as [`super::operators::corner_areas`]) and their gradients
/// `J[c][v][k] = d a_c / d p_v[k]` (m). The mixed Voronoi case is piecewise smooth, with a kink
/// where a corner is a right angle (see the module doc).
pub fn corner_areas_grad(p: &[[f64; 3]; 3], kind: AreaMass) -> ([f64; 3], CornerJacobian) {
    match kind {
        AreaMass::Barycentric => {
            let (area, g) = triangle_area_grad(p);
            ([area / 3.0; 3], [g.map(|x| scale(x, 1.0 / 3.0)); 3])
        }
        AreaMass::MixedVoronoi => match obtuse_corner(p) {
            Some(o) => {
                let (area, g) = triangle_area_grad(p);
                let f = |c: usize| if c == o { 0.5 } else { 0.25 };
                (std::array::from_fn(|c| area * f(c)), std::array::from_fn(|c| g.map(|x| scale(x, f(c)))))
            }
            None => {
                let (w, wg) = half_cotangents_grad(p);
                voronoi_from_cot(p, &w, &wg)
            }
        },
    }
}

/// The obtuse corner, by the same test as [`super::operators::corner_areas`].
fn obtuse_corner(p: &[[f64; 3]; 3]) -> Option<usize> {
    (0..3).find(|&c| dot(sub(p[(c + 1) % 3], p[c]), sub(p[(c + 2) % 3], p[c])) < 0.0)
}

/// Voronoi shares a_c = (|p_c - p_a|^2 cot_b + |p_c - p_b|^2 cot_a)/8 and their gradients from
/// the half cotangents w (cot = 2 w) and their gradients.
fn voronoi_from_cot(p: &[[f64; 3]; 3], w: &[f64; 3], wg: &CornerJacobian) -> ([f64; 3], CornerJacobian) {
    let mut val = [0.0; 3];
    let mut jac = [[[0.0; 3]; 3]; 3];
    for c in 0..3 {
        let (a, b) = ((c + 1) % 3, (c + 2) % 3);
        let (ea, eb) = (sub(p[c], p[a]), sub(p[c], p[b]));
        let (la, lb) = (dot(ea, ea), dot(eb, eb));
        // a_c = (la * 2 w_b + lb * 2 w_a) / 8 = (la w_b + lb w_a) / 4.
        val[c] = 0.25 * (la * w[b] + lb * w[a]);
        for v in 0..3 {
            let mut g = scale(add(scale(wg[b][v], la), scale(wg[a][v], lb)), 0.25);
            // d la/dp_c = 2 ea = -d la/dp_a; d lb/dp_c = 2 eb = -d lb/dp_b.
            if v == c {
                g = add(g, scale(add(scale(ea, w[b]), scale(eb, w[a])), 0.5));
            } else if v == a {
                g = sub(g, scale(ea, 0.5 * w[b]));
            } else {
                g = sub(g, scale(eb, 0.5 * w[a]));
            }
            jac[c][v] = g;
        }
    }
    (val, jac)
}

/// One triangle's contribution to dE/dp_v given dE/dw_c for its three half cotangents (`ge`)
/// and dE/da_c for its three corner areas (`gm`), without forming Jacobians. For the mixed
/// Voronoi shares of a non-obtuse triangle, sum_c m_c a_c = sum_k (m_{k+1} + m_{k+2}) |e_k|^2 w_k / 4
/// (e_k = p_{k+1} - p_{k+2}, the edge opposite k), which folds into the cotangent adjoints plus
/// an edge-length term.
fn triangle_vjp(p: &[[f64; 3]; 3], ge: Option<[f64; 3]>, gm: Option<[f64; 3]>, kind: AreaMass) -> [[f64; 3]; 3] {
    let mut out = [[0.0; 3]; 3];
    // dE/dA of the area-proportional masses, or the Voronoi case.
    let (area_adjoint, voronoi) = match (gm, kind) {
        (None, _) => (0.0, None),
        (Some(m), AreaMass::Barycentric) => ((m[0] + m[1] + m[2]) / 3.0, None),
        (Some(m), AreaMass::MixedVoronoi) => match obtuse_corner(p) {
            Some(o) => ((0..3).map(|c| m[c] * if c == o { 0.5 } else { 0.25 }).sum(), None),
            None => (0.0, Some(m)),
        },
    };
    if area_adjoint != 0.0 {
        let (_, g) = triangle_area_grad(p);
        for v in 0..3 {
            out[v] = add(out[v], scale(g[v], area_adjoint));
        }
    }
    if ge.is_none() && voronoi.is_none() {
        return out;
    }
    let ge = ge.unwrap_or([0.0; 3]);
    for c in 0..3 {
        let (a, b) = ((c + 1) % 3, (c + 2) % 3);
        let u = sub(p[a], p[c]);
        let v = sub(p[b], p[c]);
        let d = dot(u, v);
        let s = norm(cross(u, v));
        let (uu, vv) = (dot(u, u), dot(v, v));
        // Effective adjoint of w_c; the edge opposite c is p_b - p_a = v - u.
        let mut g = ge[c];
        if let Some(m) = voronoi {
            let e = sub(v, u);
            let f = 0.25 * (m[a] + m[b]);
            g += f * dot(e, e);
            // d |e|^2 / dp_b = 2 e = -d |e|^2 / dp_a, times f w_c.
            let t = scale(e, 2.0 * f * 0.5 * d / s);
            out[b] = add(out[b], t);
            out[a] = sub(out[a], t);
        }
        if g != 0.0 {
            let k = 0.5 * g / (s * s * s);
            let gu = scale(sub(scale(v, uu), scale(u, d)), k * vv);
            let gv = scale(sub(scale(u, vv), scale(v, d)), k * uu);
            out[a] = add(out[a], gu);
            out[b] = add(out[b], gv);
            out[c] = sub(out[c], add(gu, gv));
        }
    }
    out
}

/// Reusable mesh connectivity for the VJP of the cotangent weights and lumped areas: the
/// Laplacian edge opposite each triangle corner, and the triangle corners at each vertex.
/// Built once per topology; [`LaplacianVjp::accumulate`] then costs O(#triangles).
#[derive(Clone, Debug)]
pub struct LaplacianVjp {
    n: usize,
    tris: Vec<[usize; 3]>,
    /// Undirected edges (i < j), sorted: the order of [`super::operators::CotanLaplacian`].
    edges: Vec<[usize; 2]>,
    /// Index in `edges` of the edge opposite each corner.
    opposite: Vec<[usize; 3]>,
    /// CSR: the corners (3 t + c) at vertex i are `corners[start[i]..start[i + 1]]`.
    start: Vec<usize>,
    corners: Vec<usize>,
}

impl LaplacianVjp {
    /// Connectivity of `tris` over `n` vertices. The edge order equals that of
    /// `CotanLaplacian::new(verts, tris).edges` (distinct undirected edges, sorted).
    pub fn new(n: usize, tris: &[[usize; 3]]) -> Result<LaplacianVjp, DerivativeError> {
        for (t, tri) in tris.iter().enumerate() {
            for c in 0..3 {
                if tri[c] >= n {
                    return Err(DerivativeError::VertexOutOfRange { tri: t, vertex: tri[c], n });
                }
                if tri[c] == tri[(c + 1) % 3] {
                    return Err(DerivativeError::RepeatedVertex { tri: t, vertex: tri[c] });
                }
            }
        }
        let mut entries: Vec<([usize; 2], usize)> = Vec::with_capacity(3 * tris.len());
        for (t, tri) in tris.iter().enumerate() {
            for c in 0..3 {
                let (a, b) = (tri[(c + 1) % 3], tri[(c + 2) % 3]);
                entries.push(([a.min(b), a.max(b)], 3 * t + c));
            }
        }
        entries.par_sort_unstable();
        let mut edges: Vec<[usize; 2]> = Vec::with_capacity(entries.len() / 2 + 1);
        let mut opposite = vec![[0usize; 3]; tris.len()];
        for (e, tc) in entries {
            if edges.last() != Some(&e) {
                edges.push(e);
            }
            opposite[tc / 3][tc % 3] = edges.len() - 1;
        }
        let mut start = vec![0usize; n + 1];
        for tri in tris {
            for &i in tri {
                start[i + 1] += 1;
            }
        }
        for i in 0..n {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut corners = vec![0usize; 3 * tris.len()];
        for (t, tri) in tris.iter().enumerate() {
            for (c, &i) in tri.iter().enumerate() {
                corners[fill[i]] = 3 * t + c;
                fill[i] += 1;
            }
        }
        Ok(LaplacianVjp { n, tris: tris.to_vec(), edges, opposite, start, corners })
    }

    /// The Laplacian's undirected edges (i < j), sorted: the order of `edge_adjoint`.
    pub fn edges(&self) -> &[[usize; 2]] {
        &self.edges
    }

    /// The cotangent weights (in the order of [`Self::edges`]) and lumped masses of `kind` (m^2)
    /// at `verts` (m): the same values as `CotanLaplacian::new(verts, tris).weights` and
    /// `lumped_area(verts, tris, kind)`, with the connectivity reused. Each triangle's share is
    /// computed in parallel and the shares are summed in triangle order, so the result does not
    /// depend on the number of threads.
    pub fn weights_and_masses(&self, verts: &[[f64; 3]], kind: AreaMass) -> (Vec<f64>, Vec<f64>) {
        let shares: Vec<([f64; 3], [f64; 3])> = self
            .tris
            .par_iter()
            .with_min_len(1024)
            .map(|t| {
                let p = t.map(|i| verts[i]);
                (half_cotangents(&p), corner_areas(&p, kind))
            })
            .collect();
        // -0.0 + w is w for every w, as the first share that CotanLaplacian::new takes as is.
        let mut weights = vec![-0.0; self.edges.len()];
        let mut masses = vec![0.0; self.n];
        for ((t, opp), (w, a)) in self.tris.iter().zip(&self.opposite).zip(&shares) {
            for c in 0..3 {
                weights[opp[c]] += w[c];
                masses[t[c]] += a[c];
            }
        }
        (weights, masses)
    }

    /// Adds dE/dx (units `[E]/m`) to `grad_out` (one entry per vertex) for an energy E of the
    /// cotangent weights and lumped masses at `verts` (m): `edge_adjoint[e]` = dE/dw_e in the
    /// order of [`Self::edges`], `mass_adjoint[i]` = dE/da_i (`[E]/m^2`) for the masses of
    /// `kind`; `None` for an energy independent of one of them. Runs in parallel over
    /// triangles, then over vertices; the result does not depend on the number of threads.
    pub fn accumulate(
        &self,
        verts: &[[f64; 3]],
        edge_adjoint: Option<&[f64]>,
        mass_adjoint: Option<&[f64]>,
        kind: AreaMass,
        grad_out: &mut [[f64; 3]],
    ) -> Result<(), DerivativeError> {
        let check = |what, got, expected| {
            if got == expected {
                Ok(())
            } else {
                Err(DerivativeError::Length { what, got, expected })
            }
        };
        check("verts", verts.len(), self.n)?;
        check("grad_out", grad_out.len(), self.n)?;
        if let Some(g) = edge_adjoint {
            check("edge_adjoint", g.len(), self.edges.len())?;
        }
        if let Some(m) = mass_adjoint {
            check("mass_adjoint", m.len(), self.n)?;
        }
        let contrib: Vec<[[f64; 3]; 3]> = self
            .tris
            .par_iter()
            .zip(self.opposite.par_iter())
            .with_min_len(1024)
            .map(|(t, opp)| {
                let p = t.map(|i| verts[i]);
                let ge = edge_adjoint.map(|g| opp.map(|e| g[e]));
                let gm = mass_adjoint.map(|m| t.map(|i| m[i]));
                triangle_vjp(&p, ge, gm, kind)
            })
            .collect();
        grad_out.par_iter_mut().enumerate().with_min_len(1024).for_each(|(i, g)| {
            for &tc in &self.corners[self.start[i]..self.start[i + 1]] {
                *g = add(*g, contrib[tc / 3][tc % 3]);
            }
        });
        Ok(())
    }
}

/// One-shot [`LaplacianVjp::accumulate`]: builds the connectivity of `tris` and adds dE/dx to
/// `grad_out`. `edge_adjoint` is in the edge order of `CotanLaplacian::new(verts, tris)`.
/// For repeated calls on one topology, keep a [`LaplacianVjp`].
pub fn laplacian_vjp(
    verts: &[[f64; 3]],
    tris: &[[usize; 3]],
    edge_adjoint: Option<&[f64]>,
    mass_adjoint: Option<&[f64]>,
    kind: AreaMass,
    grad_out: &mut [[f64; 3]],
) -> Result<(), DerivativeError> {
    LaplacianVjp::new(verts.len(), tris)?.accumulate(verts, edge_adjoint, mass_adjoint, kind, grad_out)
}

#[cfg(test)]
mod tests {
    use super::super::operators::{corner_areas, half_cotangents, triangle_area, CotanLaplacian};
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Central-difference step (m) for triangles of size ~1 m: truncation error ~ h^2 |q'''|
    /// ~ 1e-10, roundoff ~ 1e-16 |q| / h ~ 1e-11, far below the 1e-6 tolerance.
    const H: f64 = 1e-5;

    fn random_triangle(rng: &mut ChaCha8Rng, obtuse: bool) -> [[f64; 3]; 3] {
        loop {
            let p: [[f64; 3]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)));
            let cos: [f64; 3] = std::array::from_fn(|c| {
                let (u, v) = (sub(p[(c + 1) % 3], p[c]), sub(p[(c + 2) % 3], p[c]));
                dot(u, v) / (norm(u) * norm(v))
            });
            let min_cos = cos.iter().cloned().fold(f64::INFINITY, f64::min);
            let max_cos = cos.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
            // Keep away from right angles (the Voronoi kink) and from slivers (angles > 10 deg).
            let ok_shape = max_cos < 10f64.to_radians().cos() && cos.iter().all(|c| c.abs() > 0.05);
            if ok_shape && (obtuse == (min_cos < 0.0)) && (!obtuse || min_cos < -0.3) {
                return p;
            }
        }
    }

    /// Max-norm error of `jac` against central differences of `f`, relative to max |jac|.
    fn fd_rel_error(p: &[[f64; 3]; 3], jac: &CornerJacobian, f: impl Fn(&[[f64; 3]; 3]) -> [f64; 3]) -> f64 {
        let (mut err, mut scale_) = (0.0f64, 0.0f64);
        for v in 0..3 {
            for k in 0..3 {
                let (mut pp, mut pm) = (*p, *p);
                pp[v][k] += H;
                pm[v][k] -= H;
                let (fp, fm) = (f(&pp), f(&pm));
                for c in 0..3 {
                    let fd = (fp[c] - fm[c]) / (2.0 * H);
                    err = err.max((fd - jac[c][v][k]).abs());
                    scale_ = scale_.max(jac[c][v][k].abs());
                }
            }
        }
        err / scale_
    }

    #[test]
    fn triangle_gradients_match_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut worst = [0.0f64; 5];
        for trial in 0..200 {
            let obtuse = trial % 2 == 1;
            let p = random_triangle(&mut rng, obtuse);
            let (w, jw) = half_cotangents_grad(&p);
            assert_eq!(w, half_cotangents(&p));
            worst[0] = worst[0].max(fd_rel_error(&p, &jw, half_cotangents));
            let (a, ga) = triangle_area_grad(&p);
            assert!((a - triangle_area(&p)).abs() <= 1e-15 * a);
            worst[1] = worst[1].max(fd_rel_error(&p, &[ga; 3], |q| [triangle_area(q); 3]));
            for (slot, kind) in [(2, AreaMass::Barycentric), (3, AreaMass::MixedVoronoi)] {
                let (ca, jca) = corner_areas_grad(&p, kind);
                let reference = corner_areas(&p, kind);
                for c in 0..3 {
                    assert!((ca[c] - reference[c]).abs() <= 1e-14 * a, "{kind:?} {ca:?} {reference:?}");
                }
                let e = fd_rel_error(&p, &jca, |q| corner_areas(q, kind));
                worst[slot] = worst[slot].max(e);
                if kind == AreaMass::MixedVoronoi && !obtuse {
                    worst[4] = worst[4].max(e); // the Voronoi (non-obtuse) branch alone
                }
            }
        }
        println!("max relative FD error over 200 triangles (100 acute, 100 obtuse), h = {H:e}:");
        println!(
            "  half cotangents {:.2e}, area {:.2e}, barycentric {:.2e}, mixed Voronoi {:.2e} (acute only {:.2e})",
            worst[0], worst[1], worst[2], worst[3], worst[4]
        );
        assert!(worst.iter().all(|&e| e < 1e-6), "{worst:?}");
    }

    /// At a right angle the mixed Voronoi shares are continuous (A/2 at the right angle, A/4
    /// elsewhere) but the one-sided gradients differ: the documented kink.
    #[test]
    fn mixed_voronoi_is_continuous_but_kinked_at_a_right_angle() {
        let right = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.7, 0.0]];
        let eps = 1e-9;
        let acute = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [eps, 0.7, 0.0]];
        let obtuse = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [-eps, 0.7, 0.0]];
        let a = triangle_area(&right);
        let (v0, _) = corner_areas_grad(&right, AreaMass::MixedVoronoi);
        assert!((v0[0] - a / 2.0).abs() < 1e-15 && (v0[1] - a / 4.0).abs() < 1e-15 && (v0[2] - a / 4.0).abs() < 1e-15);
        let (va, ja) = corner_areas_grad(&acute, AreaMass::MixedVoronoi);
        let (vo, jo) = corner_areas_grad(&obtuse, AreaMass::MixedVoronoi);
        for c in 0..3 {
            assert!((va[c] - vo[c]).abs() < 1e-8, "values jump: {va:?} {vo:?}");
        }
        let jump = (0..3).flat_map(|c| (0..3).flat_map(move |v| (0..3).map(move |k| (c, v, k))));
        let max_jump = jump.map(|(c, v, k)| (ja[c][v][k] - jo[c][v][k]).abs()).fold(0.0, f64::max);
        assert!(max_jump > 0.01, "expected a gradient jump, got {max_jump}");
    }

    /// A (nx+1) x (ny+1) grid over [0,1]^2 with jittered vertices and a random height field,
    /// each square split along a random diagonal.
    fn jittered_grid(nx: usize, ny: usize, rng: &mut ChaCha8Rng) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
        let mut verts = Vec::new();
        for j in 0..=ny {
            for i in 0..=nx {
                let jit = |r: &mut ChaCha8Rng| r.random_range(-0.25..0.25);
                let x = (i as f64 + jit(rng)) / nx as f64;
                let y = (j as f64 + jit(rng)) / ny as f64;
                verts.push([x, y, 0.3 * rng.random_range(-1.0..1.0) / nx as f64]);
            }
        }
        let id = |i: usize, j: usize| i + (nx + 1) * j;
        let mut tris = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                if rng.random_bool(0.5) {
                    tris.extend([[a, b, c], [a, c, d]]);
                } else {
                    tris.extend([[a, b, d], [b, c, d]]);
                }
            }
        }
        (verts, tris)
    }

    fn min_abs_cos(verts: &[[f64; 3]], tris: &[[usize; 3]]) -> f64 {
        let mut m = f64::INFINITY;
        for t in tris {
            for c in 0..3 {
                let (u, v) = (sub(verts[t[(c + 1) % 3]], verts[t[c]]), sub(verts[t[(c + 2) % 3]], verts[t[c]]));
                m = m.min((dot(u, v) / (norm(u) * norm(v))).abs());
            }
        }
        m
    }

    #[test]
    fn weights_and_masses_are_the_operators_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (verts, tris) = jittered_grid(9, 7, &mut rng);
        let vjp = LaplacianVjp::new(verts.len(), &tris).unwrap();
        let lap = CotanLaplacian::new(&verts, &tris);
        for kind in [AreaMass::Barycentric, AreaMass::MixedVoronoi] {
            let (w, m) = vjp.weights_and_masses(&verts, kind);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
            assert_eq!(bits(&w), bits(&lap.weights), "{kind:?}");
            assert_eq!(bits(&m), bits(&super::super::operators::lumped_area(&verts, &tris, kind)), "{kind:?}");
        }
    }

    #[test]
    fn mesh_vjp_matches_finite_differences_of_a_scalar_energy() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let (verts, tris) = jittered_grid(6, 5, &mut rng);
        // The FD step h perturbs cosines by ~ h / edge ~ 1e-5; stay clear of the Voronoi kink.
        let h = 1e-6;
        assert!(min_abs_cos(&verts, &tris) > 1e-3, "the random mesh has a near-right angle");
        let n_obtuse = tris.iter().filter(|t| obtuse_corner(&t.map(|i| verts[i])).is_some()).count();
        assert!(n_obtuse > 0 && n_obtuse < tris.len(), "both mixed Voronoi branches are exercised");
        let lap = CotanLaplacian::new(&verts, &tris);
        let g: Vec<f64> = lap.edges.iter().map(|_| rng.random_range(-1.0..1.0)).collect();
        let m: Vec<f64> = verts.iter().map(|_| rng.random_range(-1.0..1.0)).collect();
        let vjp = LaplacianVjp::new(verts.len(), &tris).unwrap();
        assert_eq!(vjp.edges(), &lap.edges[..]);
        for kind in [AreaMass::Barycentric, AreaMass::MixedVoronoi] {
            let energy = |x: &[[f64; 3]]| {
                let l = CotanLaplacian::new(x, &tris);
                let a = super::super::operators::lumped_area(x, &tris, kind);
                l.weights.iter().zip(&g).map(|(w, g)| w * g).sum::<f64>()
                    + a.iter().zip(&m).map(|(a, m)| a * m).sum::<f64>()
            };
            let mut grad = vec![[0.0; 3]; verts.len()];
            vjp.accumulate(&verts, Some(&g), Some(&m), kind, &mut grad).unwrap();
            let (mut err, mut sc) = (0.0f64, 0.0f64);
            for v in 0..verts.len() {
                for k in 0..3 {
                    let (mut xp, mut xm) = (verts.clone(), verts.clone());
                    xp[v][k] += h;
                    xm[v][k] -= h;
                    let fd = (energy(&xp) - energy(&xm)) / (2.0 * h);
                    err = err.max((fd - grad[v][k]).abs());
                    sc = sc.max(grad[v][k].abs());
                }
            }
            println!("mesh VJP ({kind:?}, {} vertices): max |FD - VJP| / max |VJP| = {:.2e}", verts.len(), err / sc);
            assert!(err / sc < 1e-6, "{kind:?}: {}", err / sc);
            // The one-shot function agrees bit for bit, and a second call adds the same again.
            let mut grad2 = vec![[0.0; 3]; verts.len()];
            laplacian_vjp(&verts, &tris, Some(&g), Some(&m), kind, &mut grad2).unwrap();
            assert_eq!(grad2, grad);
            vjp.accumulate(&verts, Some(&g), Some(&m), kind, &mut grad2).unwrap();
            for v in 0..verts.len() {
                for k in 0..3 {
                    assert!((grad2[v][k] - 2.0 * grad[v][k]).abs() <= 1e-14 * sc, "{:?} {:?}", grad2[v], grad[v]);
                }
            }
        }
    }

    #[test]
    fn vjp_rejects_bad_input() {
        assert_eq!(
            LaplacianVjp::new(3, &[[0, 1, 3]]).unwrap_err(),
            DerivativeError::VertexOutOfRange { tri: 0, vertex: 3, n: 3 }
        );
        assert!(matches!(LaplacianVjp::new(3, &[[0, 1, 1]]), Err(DerivativeError::RepeatedVertex { .. })));
        let vjp = LaplacianVjp::new(3, &[[0, 1, 2]]).unwrap();
        let verts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let mut g = vec![[0.0; 3]; 3];
        let e = vjp.accumulate(&verts, Some(&[1.0, 2.0]), None, AreaMass::Barycentric, &mut g).unwrap_err();
        assert_eq!(e, DerivativeError::Length { what: "edge_adjoint", got: 2, expected: 3 });
        assert_eq!(e.to_string(), "edge_adjoint has 2 entries, expected 3");
    }
}
