//! Symmetrising the row-scaled operator: given per-row estimates `a_ij ≈ α w_ij/m_i`
//! and `a_ji ≈ α w_ij/m_j` of a symmetric `W` and a diagonal mass `M`, find
//! masses with `m_i a_ij = m_j a_ji` by least squares on `ℓ = log m` over the edges where
//! both are positive,
//! `min_ℓ Σ_((i,j)) (ℓ_i - ℓ_j - loga_ji/a_ij)^2 +
//!    ε Σ_i ℓ_i^2, ε = 10^-6,`
//! (the small ridge fixes the free constant of each connected component; solved by a sparse
//! Cholesky factorisation, conjugate gradients where it fails), then
//! `α w_ij = sqrt(m_i a_ij m_j a_ji)` (the arithmetic mean where one of them is 0). Masses are
//! normalised to mean 1: `Δ_s` is invariant to a common scale of `W` and `M`.

/// Returns `(weights per edge, masses per vertex)` (see the module doc).
pub fn symmetrise(n: usize, edges: &[[usize; 2]], rows: &[[f64; 2]]) -> (Vec<f64>, Vec<f64>) {
    let eps = 1e-6;
    let valid: Vec<bool> = rows.iter().map(|r| r[0] > 0.0 && r[1] > 0.0).collect();
    let mut rhs = vec![0.0; n];
    let mut deg = vec![0.0; n];
    for ((&[i, j], r), &ok) in edges.iter().zip(rows).zip(&valid) {
        if ok {
            let d = (r[1] / r[0]).ln();
            rhs[i] += d;
            rhs[j] -= d;
            deg[i] += 1.0;
            deg[j] += 1.0;
        }
    }
    let l =
        solve_direct(n, edges, &valid, &deg, eps, &rhs).unwrap_or_else(|| solve_cg(n, edges, &valid, &deg, eps, &rhs));
    let mut m: Vec<f64> = l.iter().map(|x| x.exp()).collect();
    let mean = m.iter().sum::<f64>() / n.max(1) as f64;
    m.iter_mut().for_each(|x| *x /= mean);
    let w = edges
        .iter()
        .zip(rows)
        .zip(&valid)
        .map(
            |((&[i, j], r), &ok)| {
                if ok {
                    (m[i] * r[0] * m[j] * r[1]).sqrt()
                } else {
                    0.5 * (m[i] * r[0] + m[j] * r[1])
                }
            },
        )
        .collect();
    (w, m)
}

/// Solves `(D + eps I - A) l = rhs` (D the valid degrees, A the valid adjacency) by a sparse
/// Cholesky factorisation; `None` if it fails.
fn solve_direct(
    n: usize,
    edges: &[[usize; 2]],
    valid: &[bool],
    deg: &[f64],
    eps: f64,
    rhs: &[f64],
) -> Option<Vec<f64>> {
    use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
    let mut lower: Vec<Vec<usize>> = vec![Vec::new(); n];
    for (&[i, j], &ok) in edges.iter().zip(valid) {
        if ok && i != j {
            lower[i.min(j)].push(i.max(j));
        }
    }
    let mut col_ptr = vec![0usize; n + 1];
    let mut row_idx = Vec::with_capacity(n + edges.len());
    let mut values = Vec::with_capacity(n + edges.len());
    for (j, below) in lower.iter_mut().enumerate() {
        below.sort_unstable();
        below.dedup();
        row_idx.push(j);
        values.push(deg[j] + eps);
        for &i in below.iter() {
            row_idx.push(i);
            values.push(-1.0);
        }
        col_ptr[j + 1] = row_idx.len();
    }
    let sym = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
    let symbolic = crate::faer_seq::SymbolicLlt::try_new(sym, faer::Side::Lower).ok()?;
    let llt = crate::faer_seq::Llt::try_new_with_symbolic(
        symbolic,
        SparseColMatRef::new(sym, &values),
        faer::Side::Lower,
        faer::Par::Seq,
    )
    .ok()?;
    let mut l = rhs.to_vec();
    llt.solve_in_place(&mut l);
    l.iter().all(|v| v.is_finite()).then_some(l)
}

/// [`solve_direct`]'s system by Jacobi-preconditioned conjugate gradients (relative residual
/// 1e-12).
fn solve_cg(n: usize, edges: &[[usize; 2]], valid: &[bool], deg: &[f64], eps: f64, rhs: &[f64]) -> Vec<f64> {
    let apply = |x: &[f64], y: &mut [f64]| {
        for i in 0..n {
            y[i] = (deg[i] + eps) * x[i];
        }
        for (&[i, j], &ok) in edges.iter().zip(valid) {
            if ok {
                y[i] -= x[j];
                y[j] -= x[i];
            }
        }
    };
    let mut l = vec![0.0; n];
    let mut r = rhs.to_vec();
    let pre: Vec<f64> = deg.iter().map(|d| 1.0 / (d + eps)).collect();
    let mut z: Vec<f64> = r.iter().zip(&pre).map(|(a, b)| a * b).collect();
    let mut p = z.clone();
    let mut rz: f64 = r.iter().zip(&z).map(|(a, b)| a * b).sum();
    let r0 = rz.abs().sqrt();
    let mut ap = vec![0.0; n];
    for _ in 0..5000 {
        if rz.abs().sqrt() <= 1e-12 * r0.max(f64::MIN_POSITIVE) {
            break;
        }
        apply(&p, &mut ap);
        let pap: f64 = p.iter().zip(&ap).map(|(a, b)| a * b).sum();
        if pap <= 0.0 {
            break;
        }
        let alpha = rz / pap;
        for i in 0..n {
            l[i] += alpha * p[i];
            r[i] -= alpha * ap[i];
            z[i] = r[i] * pre[i];
        }
        let rz2: f64 = r.iter().zip(&z).map(|(a, b)| a * b).sum();
        let beta = rz2 / rz;
        rz = rz2;
        for i in 0..n {
            p[i] = z[i] + beta * p[i];
        }
    }
    l
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_masses_of_a_consistent_operator() {
        // A 4-cycle with a chord; W symmetric, masses arbitrary.
        let edges = [[0, 1], [0, 3], [1, 2], [1, 3], [2, 3]];
        let w = [1.0, 2.0, 0.5, 1.5, 3.0];
        let m = [1.0, 2.0, 0.5, 1.5];
        let rows: Vec<[f64; 2]> = edges.iter().zip(&w).map(|(&[i, j], &w)| [w / m[i], w / m[j]]).collect();
        let (we, me) = symmetrise(4, &edges, &rows);
        for (&[i, j], (&r, &a)) in edges.iter().zip(rows.iter().zip(&we)) {
            assert!((a / me[i] - r[0]).abs() < 1e-6 * r[0], "row {i}");
            assert!((a / me[j] - r[1]).abs() < 1e-6 * r[1], "row {j}");
        }
        let mean_m = m.iter().sum::<f64>() / 4.0;
        for i in 0..4 {
            assert!((me[i] - m[i] / mean_m).abs() < 1e-5);
        }
    }

    #[test]
    fn the_direct_solve_agrees_with_conjugate_gradients() {
        // A 30 x 20 grid with a few invalid edges and pseudo-random log ratios.
        let (w, h) = (30, 20);
        let mut edges = Vec::new();
        for v in 0..h {
            for u in 0..w {
                let i = v * w + u;
                if u + 1 < w {
                    edges.push([i, i + 1]);
                }
                if v + 1 < h {
                    edges.push([i, i + w]);
                }
            }
        }
        let valid: Vec<bool> = (0..edges.len()).map(|e| e % 17 != 3).collect();
        let (mut rhs, mut deg) = (vec![0.0; w * h], vec![0.0; w * h]);
        for (e, (&[i, j], &ok)) in edges.iter().zip(&valid).enumerate() {
            if ok {
                let d = ((e * 7919) % 101) as f64 / 50.0 - 1.0;
                rhs[i] += d;
                rhs[j] -= d;
                deg[i] += 1.0;
                deg[j] += 1.0;
            }
        }
        let direct = solve_direct(w * h, &edges, &valid, &deg, 1e-6, &rhs).expect("factorises");
        let cg = solve_cg(w * h, &edges, &valid, &deg, 1e-6, &rhs);
        let scale = cg.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let worst = direct.iter().zip(&cg).fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
        assert!(scale > 0.1 && worst < 1e-8 * scale, "largest difference {worst} of {scale}");
    }
}
