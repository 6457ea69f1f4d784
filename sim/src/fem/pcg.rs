//! Jacobi-preconditioned conjugate gradients for the symmetric positive definite step matrix
//! `A + D0` of the volumetric stepper (`super::volumetric`), an alternative to its sparse
//! Cholesky factor.
//!
//! The step matrix is mass dominated (`M/dt` against `K`), so after Jacobi scaling its
//! condition number is small (about 4.5 on the cuboid scene) and CG from a warm start (the
//! previous iterate) converges in a few iterations. An iteration is three parallel passes over
//! blocks of rows (the product fused with its inner product, the updates fused with the
//! residual's norms, the new direction), bound by reading the matrix once; the work vectors
//! live in a [`CgWorkspace`] kept by the caller.
//!
//! **Stopping.** Iterations stop when the Jacobi-scaled residual `max_i |r_i| / A_ii` (K) is at
//! most the tolerance: the temperature change node i alone would need to balance its residual.
//! With the scaled condition number kappa, the error is at most about kappa times that.
//!
//! **Determinism.** Every row's product is summed in a fixed order (`Csr::row_dot`), and inner
//! products are summed over fixed blocks of `BLOCK` rows, the blocks' sums then in order: the
//! bits are the same for any thread count.

use rayon::prelude::*;

use super::assembly::Pattern;

/// Rows per block of each pass and of the inner products' partial sums (fixed, so the sums do not
/// depend on threads).
const BLOCK: usize = 1024;

/// A symmetric matrix in compressed sparse rows, both triangles stored, with its inverted
/// diagonal (the Jacobi preconditioner).
#[derive(Clone, Debug)]
pub struct Csr {
    row_ptr: Vec<usize>,
    /// Column of each entry (u32: the product is bound by memory traffic).
    col: Vec<u32>,
    val: Vec<f64>,
    inv_diag: Vec<f64>,
    /// Per row, the position of its diagonal entry and that entry without any addition.
    diag_pos: Vec<usize>,
    base_diag: Vec<f64>,
}

/// What one solve did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PcgReport {
    /// CG iterations (matrix products beyond the initial residual).
    pub iterations: u32,
    /// The final Jacobi-scaled residual `max_i |r_i| / A_ii` (K).
    pub scaled_residual: f64,
}

impl Csr {
    /// The full matrix of the lower triangle `lower` (values in `pattern` order) plus `diag_add`
    /// on the diagonal of the listed nodes. `None` when a diagonal entry is not positive or the
    /// order exceeds `u32`.
    pub fn from_lower(pattern: &Pattern, lower: &[f64], diag_add: &[(usize, f64)]) -> Option<Csr> {
        let n = pattern.n;
        let mut count = vec![0usize; n + 1];
        for c in 0..n {
            for &r in &pattern.row_idx[pattern.col_ptr[c]..pattern.col_ptr[c + 1]] {
                count[r + 1] += 1;
                if r != c {
                    count[c + 1] += 1;
                }
            }
        }
        for i in 0..n {
            count[i + 1] += count[i];
        }
        let row_ptr = count.clone();
        let mut next = count;
        let nnz = row_ptr[n];
        u32::try_from(n).ok()?;
        let (mut col, mut val) = (vec![0u32; nnz], vec![0.0; nnz]);
        for c in 0..n {
            let range = pattern.col_ptr[c]..pattern.col_ptr[c + 1];
            for (&r, &a) in pattern.row_idx[range.clone()].iter().zip(&lower[range]) {
                col[next[r]] = c as u32;
                val[next[r]] = a;
                next[r] += 1;
                if r != c {
                    col[next[c]] = r as u32;
                    val[next[c]] = a;
                    next[c] += 1;
                }
            }
        }
        let base_diag: Vec<f64> = (0..n).map(|i| lower[pattern.diag[i]]).collect();
        let diag_pos: Vec<usize> = (0..n)
            .map(|i| (row_ptr[i]..row_ptr[i + 1]).find(|&k| col[k] as usize == i).expect("a stored diagonal"))
            .collect();
        let mut add = vec![0.0; n];
        for &(i, d) in diag_add {
            add[i] = d;
        }
        let mut a = Csr { row_ptr, col, val, inv_diag: vec![0.0; n], diag_pos, base_diag };
        a.set_diagonal_additions(&add).then_some(a)
    }

    /// Sets every row's diagonal to its entry without additions plus `add[i]` (one value per
    /// row, 0 for none), over blocks of rows in parallel; false when a diagonal entry is not
    /// positive.
    pub fn set_diagonal_additions(&mut self, add: &[f64]) -> bool {
        assert_eq!(add.len(), self.len(), "one addition per row");
        let (n, blocks) = (self.len(), self.len().div_ceil(BLOCK));
        // The entries of each block of rows, a slice of its own.
        let mut rows: Vec<&mut [f64]> = Vec::with_capacity(blocks);
        let mut rest = &mut self.val[..];
        for k in 0..blocks {
            let (start, end) = (self.row_ptr[k * BLOCK], self.row_ptr[((k + 1) * BLOCK).min(n)]);
            let (block, tail) = std::mem::take(&mut rest).split_at_mut(end - start);
            rows.push(block);
            rest = tail;
        }
        let (row_ptr, diag_pos, base_diag) = (&self.row_ptr, &self.diag_pos, &self.base_diag);
        rows.into_par_iter().zip(self.inv_diag.par_chunks_mut(BLOCK)).enumerate().all(|(k, (val, inv))| {
            let first = row_ptr[k * BLOCK];
            let mut positive = true;
            for (j, inv_j) in inv.iter_mut().enumerate() {
                let i = k * BLOCK + j;
                let v = base_diag[i] + add[i];
                val[diag_pos[i] - first] = v;
                *inv_j = 1.0 / v;
                positive &= *inv_j > 0.0 && inv_j.is_finite();
            }
            positive
        })
    }

    /// Order of the matrix.
    pub fn len(&self) -> usize {
        self.inv_diag.len()
    }

    /// Whether the matrix is empty.
    pub fn is_empty(&self) -> bool {
        self.inv_diag.is_empty()
    }

    /// y = A x, rows in parallel (on a worker thread: [`Csr::solve`]).
    pub fn matvec(&self, x: &[f64], y: &mut [f64]) {
        self.matvec_plus(x, |_| 0.0, y);
    }

    /// y_i = (A x)_i + add(i), rows in parallel (on a worker thread: [`Csr::solve`]).
    pub fn matvec_plus(&self, x: &[f64], add: impl Fn(usize) -> f64 + Sync, y: &mut [f64]) {
        rayon::scope(|_| {
            y.par_chunks_mut(BLOCK).enumerate().for_each(|(k, yb)| {
                for (j, yi) in yb.iter_mut().enumerate() {
                    let i = k * BLOCK + j;
                    *yi = self.row_dot(i, x) + add(i);
                }
            })
        });
    }

    /// The matrix with every value multiplied by `factor`.
    pub fn scaled(mut self, factor: f64) -> Csr {
        self.val.iter_mut().for_each(|v| *v *= factor);
        self.base_diag.iter_mut().for_each(|v| *v *= factor);
        self.inv_diag.iter_mut().for_each(|v| *v /= factor);
        self
    }

    /// Row i of A times x: four running sums over the row's entries in order (entry k into
    /// sum k mod 4, so that the additions do not wait on each other), then combined as
    /// (s0 + s1) + (s2 + s3).
    #[inline]
    fn row_dot(&self, i: usize, x: &[f64]) -> f64 {
        let range = self.row_ptr[i]..self.row_ptr[i + 1];
        let (col, val) = (&self.col[range.clone()], &self.val[range]);
        let mut s = [0.0; 4];
        let (col4, val4) = (col.chunks_exact(4), val.chunks_exact(4));
        let (col_rest, val_rest) = (col4.remainder(), val4.remainder());
        for (c, a) in col4.zip(val4) {
            for k in 0..4 {
                s[k] += a[k] * x[c[k] as usize];
            }
        }
        for (k, (&c, &a)) in col_rest.iter().zip(val_rest).enumerate() {
            s[k] += a * x[c as usize];
        }
        (s[0] + s[1]) + (s[2] + s[3])
    }

    /// Solves `A x = b` from the start `x` (a warm start: the previous iterate) until the
    /// Jacobi-scaled residual is at most `tolerance` (K) or after `max_iterations`, with the
    /// work vectors of `work`.
    ///
    /// An iteration is three passes over blocks of rows: q = A p with p.q; then
    /// x += alpha p, r -= alpha q with r.z and max |z| (z = D^-1 r, not stored); then
    /// p = z + beta p.
    ///
    /// The solve runs on one of rayon's worker threads (`rayon::scope`): called from outside the
    /// pool, each pass would otherwise hand its work to the pool and wait for it, two context
    /// switches per pass.
    pub fn solve(
        &self,
        b: &[f64],
        x: &mut [f64],
        tolerance: f64,
        max_iterations: u32,
        work: &mut CgWorkspace,
    ) -> PcgReport {
        rayon::scope(|_| self.solve_in_pool(b, x, tolerance, max_iterations, work))
    }

    /// [`Csr::solve`]'s iteration.
    fn solve_in_pool(
        &self,
        b: &[f64],
        x: &mut [f64],
        tolerance: f64,
        max_iterations: u32,
        work: &mut CgWorkspace,
    ) -> PcgReport {
        let n = self.len();
        work.resize(n);
        let CgWorkspace { r, p, q } = work;
        // r = b - A x and p = z = D^-1 r.
        let partial: Vec<(f64, f64)> = r
            .par_chunks_mut(BLOCK)
            .zip(p.par_chunks_mut(BLOCK))
            .enumerate()
            .map(|(k, (rb, pb))| {
                let (mut rz, mut zmax) = (0.0, 0.0_f64);
                for (j, (ri, pi)) in rb.iter_mut().zip(pb.iter_mut()).enumerate() {
                    let i = k * BLOCK + j;
                    *ri = b[i] - self.row_dot(i, x);
                    *pi = *ri * self.inv_diag[i];
                    rz += *ri * *pi;
                    zmax = zmax.max(pi.abs());
                }
                (rz, zmax)
            })
            .collect();
        let (mut rz, zmax) = reduce(&partial);
        let mut report = PcgReport { iterations: 0, scaled_residual: zmax };
        while report.scaled_residual > tolerance && report.iterations < max_iterations {
            report.iterations += 1;
            let pq: f64 = q
                .par_chunks_mut(BLOCK)
                .enumerate()
                .map(|(k, qb)| {
                    let mut s = 0.0;
                    for (j, qi) in qb.iter_mut().enumerate() {
                        let i = k * BLOCK + j;
                        *qi = self.row_dot(i, p);
                        s += p[i] * *qi;
                    }
                    s
                })
                .collect::<Vec<f64>>()
                .iter()
                .sum();
            let alpha = rz / pq;
            let partial: Vec<(f64, f64)> = x
                .par_chunks_mut(BLOCK)
                .zip(r.par_chunks_mut(BLOCK))
                .zip(p.par_chunks(BLOCK).zip(q.par_chunks(BLOCK)))
                .zip(self.inv_diag.par_chunks(BLOCK))
                .map(|(((xb, rb), (pb, qb)), db)| {
                    let (mut rz, mut zmax) = (0.0, 0.0_f64);
                    for ((((xi, ri), pi), qi), di) in xb.iter_mut().zip(rb.iter_mut()).zip(pb).zip(qb).zip(db) {
                        *xi += alpha * pi;
                        *ri -= alpha * qi;
                        let z = *ri * di;
                        rz += *ri * z;
                        zmax = zmax.max(z.abs());
                    }
                    (rz, zmax)
                })
                .collect();
            let (rz_next, zmax) = reduce(&partial);
            report.scaled_residual = zmax;
            if zmax <= tolerance {
                break;
            }
            let beta = rz_next / rz;
            rz = rz_next;
            p.par_chunks_mut(BLOCK).zip(r.par_chunks(BLOCK)).zip(self.inv_diag.par_chunks(BLOCK)).for_each(
                |((pb, rb), db)| {
                    for ((pi, ri), di) in pb.iter_mut().zip(rb).zip(db) {
                        *pi = ri * di + beta * *pi;
                    }
                },
            );
        }
        report
    }
}

/// The work vectors of [`Csr::solve`] (residual, search direction, product), kept between
/// solves so that a solve allocates nothing of the matrix's order.
#[derive(Clone, Debug, Default)]
pub struct CgWorkspace {
    r: Vec<f64>,
    p: Vec<f64>,
    q: Vec<f64>,
}

impl CgWorkspace {
    fn resize(&mut self, n: usize) {
        for v in [&mut self.r, &mut self.p, &mut self.q] {
            v.resize(n, 0.0);
        }
    }
}

/// The blocks' partial (sum, maximum) pairs combined in block order (module doc).
fn reduce(partial: &[(f64, f64)]) -> (f64, f64) {
    partial.iter().fold((0.0, 0.0_f64), |(s, m), &(ps, pm)| (s + ps, m.max(pm)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::assembly::sym_matvec;

    /// A 1-D chain's mass-dominated matrix: 2 + 1/h on the diagonal, -1/(2h) off it.
    fn chain(n: usize) -> (Pattern, Vec<f64>) {
        let tris: Vec<[usize; 3]> = (0..n - 2).map(|i| [i, i + 1, i + 2]).collect();
        let p = Pattern::from_tris(n, &tris);
        let mut v = vec![0.0; p.nnz()];
        for c in 0..n {
            for k in p.col_ptr[c]..p.col_ptr[c + 1] {
                let r = p.row_idx[k];
                v[k] = if r == c {
                    3.0 + c as f64 * 1e-3
                } else if r == c + 1 {
                    -0.5
                } else {
                    -0.2
                };
            }
        }
        (p, v)
    }

    /// The full matrix's product is the lower triangle's, with diagonal additions set at
    /// construction or later, on one block of rows and across several (the additions are set
    /// block by block).
    #[test]
    fn full_matrix_product_matches_the_lower_triangle_product() {
        for n in [50, 2 * BLOCK + 77] {
            let (p, v) = chain(n);
            let added = [3, n / 2, n - 1];
            let a = Csr::from_lower(&p, &v, &added.map(|i| (i, 0.25))).unwrap();
            let x: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
            let mut y = vec![0.0; n];
            a.matvec(&x, &mut y);
            let mut shifted = v.clone();
            added.iter().for_each(|&i| shifted[p.diag[i]] += 0.25);
            // Setting the additions again (to other values, and back) gives the same matrix.
            let mut b = a.clone();
            let mut add = vec![0.0; n];
            added.iter().for_each(|&i| add[i] = 1.0);
            assert!(b.set_diagonal_additions(&add));
            added.iter().for_each(|&i| add[i] = 0.25);
            assert!(b.set_diagonal_additions(&add));
            let mut yb = vec![0.0; n];
            b.matvec(&x, &mut yb);
            assert_eq!(y, yb);
            let mut z = vec![0.0; n];
            sym_matvec(&p, &shifted, &x, &mut z);
            for (u, w) in y.iter().zip(&z) {
                assert!((u - w).abs() < 1e-14, "{u} vs {w}");
            }
            // An addition that leaves a diagonal entry not positive is refused.
            add[n - 1] = -10.0;
            assert!(!b.set_diagonal_additions(&add), "n = {n}");
        }
    }

    /// The solve reaches its scaled-residual tolerance and the solution of a known system.
    #[test]
    fn solves_to_the_tolerance() {
        let (p, v) = chain(300);
        let a = Csr::from_lower(&p, &v, &[]).unwrap();
        let truth: Vec<f64> = (0..300).map(|i| 295.0 + (i as f64 * 0.05).cos()).collect();
        let mut b = vec![0.0; 300];
        a.matvec(&truth, &mut b);
        let mut x = vec![295.0; 300];
        let rep = a.solve(&b, &mut x, 1e-12, 200, &mut CgWorkspace::default());
        assert!(rep.scaled_residual <= 1e-12, "{rep:?}");
        assert!(rep.iterations > 3 && rep.iterations < 60, "{rep:?}");
        let err = x.iter().zip(&truth).fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(err < 1e-11, "error {err:e}");
        // Started at the solution: no iteration.
        let mut y = truth.clone();
        assert_eq!(a.solve(&b, &mut y, 1e-9, 200, &mut CgWorkspace::default()).iterations, 0);
    }

    /// The same bits with one thread and with four (module doc, determinism).
    #[test]
    fn the_same_bits_at_any_thread_count() {
        let (p, v) = chain(20000);
        let a = Csr::from_lower(&p, &v, &[(7, 0.5)]).unwrap();
        let b: Vec<f64> = (0..20000).map(|i| (i as f64 * 0.013).sin()).collect();
        let solve = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| {
                let mut x = vec![0.0; 20000];
                let rep = a.solve(&b, &mut x, 1e-13, 500, &mut CgWorkspace::default());
                (x, rep)
            })
        };
        let (x1, r1) = solve(1);
        let (x4, r4) = solve(4);
        assert!(r1.iterations > 5, "{r1:?}");
        assert_eq!(r1, r4);
        assert!(x1.iter().zip(&x4).all(|(a, b)| a.to_bits() == b.to_bits()));
    }

    #[test]
    fn a_non_positive_diagonal_is_refused() {
        let (p, mut v) = chain(10);
        v[p.diag[4]] = 0.0;
        assert!(Csr::from_lower(&p, &v, &[]).is_none());
    }
}
