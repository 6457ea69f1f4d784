//! Graph-regularised estimate of the rows of Δ_s, with the globals fixed (module doc of
//! [`super`], "Why per-vertex rows are not enough").
//!
//! With fixed globals $u$, vertex $i$'s least-squares problem in its weights $w_i$ (one per
//! weight group) and fluxes $b_i$ is $\|A_i w_i + F_i b_i - (y_i - B_i u)\|^2$. Eliminating the
//! fluxes (unconstrained) leaves the Schur complement $S_i = A_i^T (I - P_{F_i}) A_i$ and
//! $r_i = A_i^T (I - P_{F_i}) (y_i - B_i u)$. Every weight group has a direction class (pixel
//! offset up to sign: horizontal, vertical, main diagonal; with the free stencil the signed
//! offset), and neighbouring vertices' weights of the same class are tied:
//! $$ \min_w \sum_i \left(w_i^T S_i w_i - 2 r_i^T w_i\right) +
//!    \mu \sum_{(i,j)\in E} \sum_{c} (w_{ic} - w_{jc})^2, \qquad
//!    \mu = \kappa\,\overline{\mathrm{tr}(S_i)/n_i}, $$
//! a sparse SPD system solved by conjugate gradients with a block-Jacobi preconditioner (the
//! per-vertex blocks $S_i + \mu\,\deg$). $\kappa$ is dimensionless ([`super::Stage1Options::smoothing`]).
//! The fluxes then follow per vertex by NNLS given $w_i$.

use rayon::prelude::*;

use super::lsq;

/// Per-vertex input of [`solve`]: Schur complement `s` (n x n), right-hand side `r`, and the
/// class of each of the `n` weights.
pub struct Block {
    /// Row-major n x n.
    pub s: Vec<f64>,
    /// Length n.
    pub r: Vec<f64>,
    /// Class of each weight.
    pub class: Vec<u8>,
}

/// Result of [`solve`].
pub struct Solution {
    /// Per vertex, its weights.
    pub w: Vec<Vec<f64>>,
    /// μ used.
    pub mu: f64,
    /// CG iterations.
    pub iterations: usize,
    /// Final relative residual of the linear system.
    pub rel_residual: f64,
}

/// Solves the regularised system (module doc) for `blocks` on the vertex graph `edges`.
pub fn solve(blocks: &[Block], edges: &[[usize; 2]], kappa: f64, warm: &[Vec<f64>]) -> Solution {
    let nv = blocks.len();
    let scale: f64 = blocks
        .iter()
        .filter(|b| !b.r.is_empty())
        .map(|b| (0..b.r.len()).map(|a| b.s[a * b.r.len() + a]).sum::<f64>() / b.r.len() as f64)
        .sum::<f64>()
        / nv.max(1) as f64;
    let mu = kappa * scale;
    // Ties: for each edge, the pairs of (local index at i, local index at j) of equal class.
    let mut adj: Vec<Vec<(usize, usize, usize)>> = vec![Vec::new(); nv]; // (local a, vertex j, local b)
    for &[i, j] in edges {
        for (a, ca) in blocks[i].class.iter().enumerate() {
            if let Some(b) = blocks[j].class.iter().position(|cb| cb == ca) {
                adj[i].push((a, j, b));
                adj[j].push((b, i, a));
            }
        }
    }
    let apply = |x: &[Vec<f64>]| -> Vec<Vec<f64>> {
        (0..nv)
            .into_par_iter()
            .map(|i| {
                let b = &blocks[i];
                let n = b.r.len();
                let mut y: Vec<f64> = (0..n).map(|a| (0..n).map(|c| b.s[a * n + c] * x[i][c]).sum()).collect();
                for &(a, j, bb) in &adj[i] {
                    y[a] += mu * (x[i][a] - x[j][bb]);
                }
                y
            })
            .collect()
    };
    // Block-Jacobi preconditioner: (S_i + mu deg) per vertex, factorised once (its diagonal
    // where that fails).
    let precond: Vec<Result<Vec<f64>, Vec<f64>>> = (0..nv)
        .map(|i| {
            let b = &blocks[i];
            let n = b.r.len();
            let mut m = b.s.clone();
            for &(a, _, _) in &adj[i] {
                m[a * n + a] += mu;
            }
            // Small ridge for vertices without information.
            let tr = (0..n).map(|a| m[a * n + a]).sum::<f64>().max(scale * 1e-12) / n.max(1) as f64;
            for a in 0..n {
                m[a * n + a] += 1e-10 * tr;
            }
            lsq::chol_factor(&m, n).ok_or_else(|| (0..n).map(|a| m[a * n + a].max(f64::MIN_POSITIVE)).collect())
        })
        .collect();
    let prec = |r: &[Vec<f64>]| -> Vec<Vec<f64>> {
        (0..nv)
            .into_par_iter()
            .map(|i| {
                let n = r[i].len();
                let mut z = r[i].clone();
                match &precond[i] {
                    Ok(l) => lsq::chol_apply(l, n, &mut z),
                    Err(diag) => z.iter_mut().zip(diag).for_each(|(v, d)| *v /= d),
                }
                z
            })
            .collect()
    };
    let dot = |a: &[Vec<f64>], b: &[Vec<f64>]| -> f64 {
        // Per-block products in parallel, summed in order: the same bits on every run.
        let parts: Vec<f64> =
            a.par_iter().zip(b).map(|(x, y)| x.iter().zip(y).map(|(p, q)| p * q).sum::<f64>()).collect();
        parts.iter().sum()
    };
    let axpy = |y: &mut [Vec<f64>], s: f64, x: &[Vec<f64>]| {
        y.par_iter_mut().zip(x).for_each(|(a, b)| a.iter_mut().zip(b).for_each(|(p, q)| *p += s * q));
    };
    let rhs: Vec<Vec<f64>> = blocks.iter().map(|b| b.r.clone()).collect();
    let bnorm = dot(&rhs, &rhs).sqrt().max(f64::MIN_POSITIVE);
    let mut x: Vec<Vec<f64>> = warm.to_vec();
    let ax = apply(&x);
    let mut r: Vec<Vec<f64>> =
        rhs.iter().zip(&ax).map(|(a, b)| a.iter().zip(b).map(|(p, q)| p - q).collect()).collect();
    let mut z = prec(&r);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let mut iterations = 0;
    let mut rel = dot(&r, &r).sqrt() / bnorm;
    while iterations < 5000 && rel > 1e-10 {
        let ap = apply(&p);
        let pap = dot(&p, &ap);
        if pap <= 0.0 {
            break;
        }
        let alpha = rz / pap;
        axpy(&mut x, alpha, &p);
        axpy(&mut r, -alpha, &ap);
        z = prec(&r);
        let rz2 = dot(&r, &z);
        let beta = rz2 / rz;
        rz = rz2;
        p.par_iter_mut().zip(&z).for_each(|(pp, zz)| pp.iter_mut().zip(zz).for_each(|(a, b)| *a = b + beta * *a));
        iterations += 1;
        rel = dot(&r, &r).sqrt() / bnorm;
    }
    Solution { w: x, mu, iterations, rel_residual: rel }
}
