//! Jacobi-preconditioned conjugate gradients for the symmetric positive definite step matrix
//! `A + D0` of the volumetric stepper (`super::volumetric`), an alternative to its sparse
//! Cholesky factor.
//!
//! The step matrix is mass dominated (`M/dt` against `K`), so after Jacobi scaling its
//! condition number is small (about 4.5 on the cuboid scene) and CG from a warm start (the
//! previous iterate) converges in a few iterations. Each iteration is one product with the
//! full symmetric matrix (compressed rows, rows in parallel) and three inner products.
//!
//! **Stopping.** Iterations stop when the Jacobi-scaled residual `max_i |r_i| / A_ii` (K) is at
//! most the tolerance: the temperature change node i alone would need to balance its residual.
//! With the scaled condition number kappa, the error is at most about kappa times that.
//!
//! **Determinism.** Every row's product is summed in the row's fixed order, and inner products
//! are summed over fixed blocks of `BLOCK` entries, the blocks' sums then in order: the bits
//! are the same for any thread count.

use rayon::prelude::*;

use super::assembly::Pattern;

/// Entries per block of the inner products (fixed, so the sums do not depend on threads).
const BLOCK: usize = 4096;

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
        let inv_diag = base_diag.iter().map(|d| 1.0 / d).collect();
        let mut a = Csr { row_ptr, col, val, inv_diag, diag_pos, base_diag };
        a.set_diagonal_additions(diag_add).then_some(a)
    }

    /// Sets the diagonal of the listed rows to their entry without additions plus the given
    /// value (the other rows keep theirs); false when a diagonal entry is not positive.
    pub fn set_diagonal_additions(&mut self, add: &[(usize, f64)]) -> bool {
        for &(i, d) in add {
            let v = self.base_diag[i] + d;
            self.val[self.diag_pos[i]] = v;
            self.inv_diag[i] = 1.0 / v;
        }
        self.inv_diag.iter().all(|&d| d > 0.0 && d.is_finite())
    }

    /// Order of the matrix.
    pub fn len(&self) -> usize {
        self.inv_diag.len()
    }

    /// Whether the matrix is empty.
    pub fn is_empty(&self) -> bool {
        self.inv_diag.is_empty()
    }

    /// y = A x, rows in parallel.
    pub fn matvec(&self, x: &[f64], y: &mut [f64]) {
        y.par_iter_mut().with_min_len(1024).enumerate().for_each(|(i, yi)| {
            let range = self.row_ptr[i]..self.row_ptr[i + 1];
            *yi = self.col[range.clone()].iter().zip(&self.val[range]).map(|(&c, &a)| a * x[c as usize]).sum();
        });
    }

    /// Solves `A x = b` from the start `x` (a warm start: the previous iterate) until the
    /// Jacobi-scaled residual is at most `tolerance` (K) or after `max_iterations`.
    pub fn solve(&self, b: &[f64], x: &mut [f64], tolerance: f64, max_iterations: u32) -> PcgReport {
        let n = self.len();
        let mut r = vec![0.0; n];
        self.matvec(x, &mut r);
        r.par_iter_mut().zip(b).for_each(|(ri, bi)| *ri = bi - *ri);
        let scaled = |r: &[f64]| r.iter().zip(&self.inv_diag).fold(0.0_f64, |m, (ri, d)| m.max((ri * d).abs()));
        let mut report = PcgReport { iterations: 0, scaled_residual: scaled(&r) };
        if report.scaled_residual <= tolerance {
            return report;
        }
        let mut z: Vec<f64> = r.iter().zip(&self.inv_diag).map(|(ri, d)| ri * d).collect();
        let mut p = z.clone();
        let mut q = vec![0.0; n];
        let mut rz = dot(&r, &z);
        while report.iterations < max_iterations {
            report.iterations += 1;
            self.matvec(&p, &mut q);
            let alpha = rz / dot(&p, &q);
            x.par_iter_mut().zip(&p).for_each(|(xi, pi)| *xi += alpha * pi);
            r.par_iter_mut().zip(&q).for_each(|(ri, qi)| *ri -= alpha * qi);
            report.scaled_residual = scaled(&r);
            if report.scaled_residual <= tolerance {
                break;
            }
            z.par_iter_mut().zip(&r).zip(&self.inv_diag).for_each(|((zi, ri), d)| *zi = ri * d);
            let rz_next = dot(&r, &z);
            let beta = rz_next / rz;
            rz = rz_next;
            p.par_iter_mut().zip(&z).for_each(|(pi, zi)| *pi = zi + beta * *pi);
        }
        report
    }
}

/// Inner product summed over fixed blocks, then the blocks in order (module doc).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let partial: Vec<f64> = a
        .par_chunks(BLOCK)
        .zip(b.par_chunks(BLOCK))
        .map(|(x, y)| x.iter().zip(y).map(|(u, v)| u * v).sum::<f64>())
        .collect();
    partial.iter().sum()
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

    #[test]
    fn full_matrix_product_matches_the_lower_triangle_product() {
        let (p, v) = chain(50);
        let a = Csr::from_lower(&p, &v, &[(3, 0.25)]).unwrap();
        let x: Vec<f64> = (0..50).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut y = vec![0.0; 50];
        a.matvec(&x, &mut y);
        let mut shifted = v.clone();
        shifted[p.diag[3]] += 0.25;
        // Setting the addition again (to another value, and back) gives the same matrix.
        let mut b = a.clone();
        assert!(b.set_diagonal_additions(&[(3, 1.0)]) && b.set_diagonal_additions(&[(3, 0.25)]));
        let mut yb = vec![0.0; 50];
        b.matvec(&x, &mut yb);
        assert_eq!(y, yb);
        let mut z = vec![0.0; 50];
        sym_matvec(&p, &shifted, &x, &mut z);
        for (u, w) in y.iter().zip(&z) {
            assert!((u - w).abs() < 1e-14, "{u} vs {w}");
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
        let rep = a.solve(&b, &mut x, 1e-12, 200);
        assert!(rep.scaled_residual <= 1e-12, "{rep:?}");
        assert!(rep.iterations > 3 && rep.iterations < 60, "{rep:?}");
        let err = x.iter().zip(&truth).fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(err < 1e-11, "error {err:e}");
        // Started at the solution: no iteration.
        let mut y = truth.clone();
        assert_eq!(a.solve(&b, &mut y, 1e-9, 200).iterations, 0);
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
                let rep = a.solve(&b, &mut x, 1e-13, 500);
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
