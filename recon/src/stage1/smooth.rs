//! Graph-regularised estimate of the rows of Δ_s, with the globals fixed (module doc of
//! [`super`], "Why per-vertex rows are not enough").
//!
//! With fixed globals `u`, vertex `i`'s least-squares problem in its weights `w_i` (one per
//! weight group) and fluxes `b_i` is `‖A_i w_i + F_i b_i - (y_i - B_i u)‖^2`. Eliminating the
//! fluxes (unconstrained) leaves the Schur complement `S_i = A_i^T (I - P_F_i) A_i` and
//! `r_i = A_i^T (I - P_F_i) (y_i - B_i u)`. Every weight group has a direction class (pixel
//! offset up to sign: horizontal, vertical, main diagonal; with the free stencil the signed
//! offset), and neighbouring vertices' weights of the same class are tied:
//! `min_w Σ_i (w_i^T S_i w_i - 2 r_i^T w_i) +
//!    μ Σ_((i,j) ∈ E) Σ_c (w_ic - w_jc)^2,
//!    μ = κ bar(tr(S_i)/n_i),`
//! a sparse SPD system solved by conjugate gradients with a block-Jacobi preconditioner (the
//! per-vertex blocks `S_i + μ °`). `κ` is dimensionless ([`super::Stage1Options::smoothing`]).
//! The fluxes then follow per vertex by NNLS given `w_i`.

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

/// A tie of weight `a` of a vertex to weight `b` of its neighbour `j`.
#[derive(Clone, Copy)]
struct Tie {
    j: u32,
    a: u8,
    b: u8,
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

/// The ties of the regularisation: for each edge, the pairs of (local index at i, vertex j,
/// local index at j) of equal class, stored compactly (CG is bound by memory traffic, not
/// arithmetic) as one array: vertex i's ties at `ties[start[i]..start[i + 1]]`.
fn equal_class_ties(blocks: &[Block], edges: &[[usize; 2]]) -> (Vec<usize>, Vec<Tie>) {
    let mut adj: Vec<Vec<Tie>> = vec![Vec::new(); blocks.len()];
    for &[i, j] in edges {
        for (a, ca) in blocks[i].class.iter().enumerate() {
            if let Some(b) = blocks[j].class.iter().position(|cb| cb == ca) {
                // A vertex has at most 8 weights and a mesh far fewer than 2^32 vertices.
                let (a8, b8) = (
                    u8::try_from(a).expect("weights per vertex < 256"),
                    u8::try_from(b).expect("weights per vertex < 256"),
                );
                let (i32_, j32) =
                    (u32::try_from(i).expect("vertices < 2^32"), u32::try_from(j).expect("vertices < 2^32"));
                adj[i].push(Tie { a: a8, j: j32, b: b8 });
                adj[j].push(Tie { a: b8, j: i32_, b: a8 });
            }
        }
    }
    let start: Vec<usize> = std::iter::once(0)
        .chain(adj.iter().scan(0, |acc, t| {
            *acc += t.len();
            Some(*acc)
        }))
        .collect();
    (start, adj.into_iter().flatten().collect())
}

/// Block-Jacobi preconditioner: (S_i + mu deg) per vertex, factorised once (its diagonal
/// where that fails); `scale` is the mean diagonal of the blocks (the ridge's reference).
fn block_jacobi<'a>(
    blocks: &[Block],
    ties_of: &(dyn Fn(usize) -> &'a [Tie] + Sync),
    mu: f64,
    scale: f64,
) -> Vec<Result<Vec<f64>, Vec<f64>>> {
    (0..blocks.len())
        .into_par_iter()
        .map(|i| {
            let b = &blocks[i];
            let n = b.r.len();
            let mut m = b.s.clone();
            for t in ties_of(i) {
                let a = usize::from(t.a);
                m[a * n + a] += mu;
            }
            // Small ridge for vertices without information.
            let tr = (0..n).map(|a| m[a * n + a]).sum::<f64>().max(scale * 1e-12) / n.max(1) as f64;
            for a in 0..n {
                m[a * n + a] += 1e-10 * tr;
            }
            lsq::chol_factor(&m, n).ok_or_else(|| (0..n).map(|a| m[a * n + a].max(f64::MIN_POSITIVE)).collect())
        })
        .collect()
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
    let (start, ties) = equal_class_ties(blocks, edges);
    let ties_of = |i: usize| &ties[start[i]..start[i + 1]];
    // Vectors are flat, vertex i's weights at `i * stride ..` (padded with zeros to the widest
    // block), so every CG iteration works in place.
    let stride = blocks.iter().map(|b| b.r.len()).max().unwrap_or(0).max(1);
    let apply = |x: &[f64], y: &mut [f64]| {
        y.par_chunks_mut(stride).enumerate().for_each(|(i, yi)| {
            let b = &blocks[i];
            let n = b.r.len();
            let xi = &x[i * stride..i * stride + n];
            for (ya, srow) in yi.iter_mut().zip(b.s.chunks_exact(n.max(1))) {
                *ya = srow.iter().zip(xi).map(|(s, v)| s * v).sum();
            }
            for t in ties_of(i) {
                let (a, j, bb) = (usize::from(t.a), t.j as usize, usize::from(t.b));
                yi[a] += mu * (xi[a] - x[j * stride + bb]);
            }
        });
    };
    let precond = block_jacobi(blocks, &ties_of, mu, scale);
    let prec = |r: &[f64], z: &mut [f64]| {
        z.par_chunks_mut(stride).zip(r.par_chunks(stride)).enumerate().for_each(|(i, (zi, ri))| {
            let n = blocks[i].r.len();
            zi[..n].copy_from_slice(&ri[..n]);
            match &precond[i] {
                Ok(l) => lsq::chol_apply(l, n, &mut zi[..n]),
                Err(diag) => zi.iter_mut().zip(diag).for_each(|(v, d)| *v /= d),
            }
        });
    };
    let mut parts = vec![0.0; nv];
    let mut dot = |a: &[f64], b: &[f64]| -> f64 {
        // Per-block products in parallel, summed in order: the same bits on every run.
        parts.par_iter_mut().zip(a.par_chunks(stride).zip(b.par_chunks(stride))).enumerate().for_each(
            |(i, (d, (x, y)))| {
                let n = blocks[i].r.len();
                *d = x[..n].iter().zip(&y[..n]).map(|(p, q)| p * q).sum::<f64>();
            },
        );
        parts.iter().sum()
    };
    let axpy = |y: &mut [f64], s: f64, x: &[f64]| {
        y.par_chunks_mut(4096)
            .zip(x.par_chunks(4096))
            .for_each(|(a, b)| a.iter_mut().zip(b).for_each(|(p, q)| *p += s * q));
    };
    let flat = |v: &mut [f64], i: usize, src: &[f64]| v[i * stride..i * stride + src.len()].copy_from_slice(src);
    let mut rhs = vec![0.0; nv * stride];
    let mut x = vec![0.0; nv * stride];
    for (i, (b, w)) in blocks.iter().zip(warm).enumerate() {
        flat(&mut rhs, i, &b.r);
        flat(&mut x, i, w);
    }
    let bnorm = dot(&rhs, &rhs).sqrt().max(f64::MIN_POSITIVE);
    let mut ap = vec![0.0; nv * stride];
    apply(&x, &mut ap);
    let mut r: Vec<f64> = rhs.iter().zip(&ap).map(|(a, b)| a - b).collect();
    let mut z = vec![0.0; nv * stride];
    prec(&r, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let mut iterations = 0;
    let mut rel = dot(&r, &r).sqrt() / bnorm;
    while iterations < 5000 && rel > 1e-10 {
        apply(&p, &mut ap);
        let pap = dot(&p, &ap);
        if pap <= 0.0 {
            break;
        }
        let alpha = rz / pap;
        axpy(&mut x, alpha, &p);
        axpy(&mut r, -alpha, &ap);
        prec(&r, &mut z);
        let rz2 = dot(&r, &z);
        let beta = rz2 / rz;
        rz = rz2;
        p.par_chunks_mut(4096)
            .zip(z.par_chunks(4096))
            .for_each(|(pp, zz)| pp.iter_mut().zip(zz).for_each(|(a, b)| *a = b + beta * *a));
        iterations += 1;
        rel = dot(&r, &r).sqrt() / bnorm;
    }
    let w = blocks.iter().enumerate().map(|(i, b)| x[i * stride..i * stride + b.r.len()].to_vec()).collect();
    Solution { w, mu, iterations, rel_residual: rel }
}
