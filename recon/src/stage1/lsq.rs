//! Small dense least squares in square-root (orthogonal) form, for the per-vertex problems.
//!
//! A vertex's equations are a tall matrix `D = [A | y]` (one row per frame pair and video).
//! Instead of its Gram matrix `D^T D`, we keep the upper-triangular `R` with `R^T R = D^T D`,
//! built row by row with Givens rotations ([`SqrtInfo::add_row`]); then
//! `‖D z‖ = ‖R z‖` for every `z`, so any least-squares problem over the vertex's columns can be
//! solved on the few rows of `R` instead of the data. Why: under lamps that stay on, a vertex's
//! columns are nearly collinear, the Gram matrix squares their condition number beyond f64,
//! and its Cholesky solves returned rows of Δ_s far off where the same equations solved
//! orthogonally were accurate (`recon/tests/stage1_synthetic.rs`; the figures:
//! docs/notes/code-comments.md).
//!
//! [`triangularize`] re-triangularises chosen columns (the square root of a Schur complement is
//! the trailing block), [`nnls`] is Lawson and Hanson's active-set NNLS (1974) with every
//! subproblem solved by [`triangularize`] and back substitution. [`chol_solve`] is left for the
//! small, well-conditioned systems (the globals' 2 x 2, block preconditioners).

/// Solves `g x = f` in place for a symmetric positive (semi)definite `n x n` row-major `g`
/// (a copy is factorised); a tiny diagonal shift (1e-13 relative) keeps it well posed.
/// Returns `false` if the matrix is not positive definite even after the shift.
pub fn chol_solve(g: &[f64], n: usize, f: &mut [f64]) -> bool {
    match chol_factor(g, n) {
        Some(l) => {
            chol_apply(&l, n, f);
            true
        }
        None => false,
    }
}

/// The Cholesky factor L (row-major, lower) of `g` with the shift of [`chol_solve`], or `None`
/// if not positive definite.
pub fn chol_factor(g: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = g.to_vec();
    let shift = 1e-13 * (0..n).map(|i| g[i * n + i].abs()).fold(0.0, f64::max);
    for j in 0..n {
        let mut d = l[j * n + j] + shift;
        for k in 0..j {
            d -= l[j * n + k] * l[j * n + k];
        }
        if d <= 0.0 || !d.is_finite() {
            return None;
        }
        let d = d.sqrt();
        l[j * n + j] = d;
        for i in j + 1..n {
            let mut s = l[i * n + j];
            for k in 0..j {
                s -= l[i * n + k] * l[j * n + k];
            }
            l[i * n + j] = s / d;
        }
    }
    Some(l)
}

/// Solves L L^T x = f in place with a factor from [`chol_factor`].
pub fn chol_apply(l: &[f64], n: usize, f: &mut [f64]) {
    for i in 0..n {
        let mut s = f[i];
        for k in 0..i {
            s -= l[i * n + k] * f[k];
        }
        f[i] = s / l[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = f[i];
        for k in i + 1..n {
            s -= l[k * n + i] * f[k];
        }
        f[i] = s / l[i * n + i];
    }
}

/// The upper-triangular square root `R` (n x n, row-major) of the Gram matrix of the rows added.
#[derive(Clone, Debug)]
pub struct SqrtInfo {
    n: usize,
    r: Vec<f64>,
}

impl SqrtInfo {
    /// No rows yet (R = 0) for `n` columns.
    pub fn new(n: usize) -> SqrtInfo {
        SqrtInfo { n, r: vec![0.0; n * n] }
    }

    /// Number of columns.
    pub fn cols(&self) -> usize {
        self.n
    }

    /// Entry (i, j) of R (0 below the diagonal).
    pub fn at(&self, i: usize, j: usize) -> f64 {
        self.r[i * self.n + j]
    }

    /// Column j of R (length n).
    pub fn column(&self, j: usize) -> Vec<f64> {
        (0..self.n).map(|i| self.r[i * self.n + j]).collect()
    }

    /// Adds the row `x` (consumed as scratch): R^T R += x x^T, by one Givens rotation per
    /// non-zero entry. The rotation's norm is `sqrt(r^2 + x^2)`, not `hypot` (a fifth of stage
    /// 1's time): entries between 1e-150 and 1e150 in magnitude, as temperatures and their
    /// rates in SI units are, neither overflow nor underflow.
    pub fn add_row(&mut self, x: &mut [f64]) {
        let n = self.n;
        debug_assert_eq!(x.len(), n, "row length (a bug)");
        for j in 0..n {
            let xj = x[j];
            if xj == 0.0 {
                continue;
            }
            let rjj = self.r[j * n + j];
            let h = (rjj * rjj + xj * xj).sqrt();
            let (c, s) = (rjj / h, xj / h);
            self.r[j * n + j] = h;
            x[j] = 0.0;
            let rj = &mut self.r[j * n + j + 1..(j + 1) * n];
            for (a, b) in rj.iter_mut().zip(&mut x[j + 1..]) {
                let (ra, xb) = (*a, *b);
                *a = c * ra + s * xb;
                *b = c * xb - s * ra;
            }
        }
    }
}

impl SqrtInfo {
    /// Adds all rows of which `other` is the square root (same columns): afterwards R^T R is the
    /// Gram matrix of both sets of rows.
    pub fn merge(&mut self, other: &SqrtInfo) {
        debug_assert_eq!(self.n, other.n, "column count (a bug)");
        let n = self.n;
        let mut x = vec![0.0; n];
        for i in 0..n {
            x.copy_from_slice(&other.r[i * n..(i + 1) * n]);
            self.add_row(&mut x);
        }
    }
}

/// The upper-triangular factor (k x k, row-major, k = `cols.len()`) of the QR decomposition of
/// the matrix whose columns are `cols` (all of the same length). Its trailing block for the
/// last columns is the square root of their Schur complement after the leading ones.
pub fn triangularize<C: AsRef<[f64]>>(cols: &[C]) -> SqrtInfo {
    let k = cols.len();
    let rows = cols.first().map_or(0, |c| c.as_ref().len());
    let mut out = SqrtInfo::new(k);
    let mut x = vec![0.0; k];
    for i in 0..rows {
        for (c, col) in cols.iter().enumerate() {
            x[c] = col.as_ref()[i];
        }
        out.add_row(&mut x);
    }
    out
}

/// The Schur complement of the columns `cols[lead..k-1]` after the first `lead`, and its
/// right-hand side for the last column: with T the trailing block of the QR of `cols`,
/// `(T_ww^T T_ww, T_ww^T t_wb)` (row-major (k-lead-1)^2 and length k-lead-1). Eliminating the
/// leading columns orthogonally keeps the conditioning of the data, not of its square.
pub fn schur<C: AsRef<[f64]>>(cols: &[C], lead: usize) -> (Vec<f64>, Vec<f64>) {
    let t = triangularize(cols);
    let kw = cols.len() - lead - 1;
    let mut s = vec![0.0; kw * kw];
    let mut r = vec![0.0; kw];
    for a in 0..kw {
        for c in 0..kw {
            s[a * kw + c] = (lead..lead + kw).map(|k| t.at(k, lead + a) * t.at(k, lead + c)).sum();
        }
        r[a] = (lead..lead + kw).map(|k| t.at(k, lead + a) * t.at(k, lead + kw)).sum();
    }
    (s, r)
}

/// Least squares `min_x ‖[a_j]_(j ∈ s) x - b‖` by QR; `None` when a column of the subset
/// is (to 1e-13 of its norm) a combination of the ones before it.
fn solve_subset(a: &[Vec<f64>], b: &[f64], s: &[usize]) -> Option<Vec<f64>> {
    let mut cols: Vec<&[f64]> = s.iter().map(|&j| a[j].as_slice()).collect();
    cols.push(b);
    let t = triangularize(&cols);
    let m = s.len();
    let mut x = vec![0.0; m];
    for i in (0..m).rev() {
        let d = t.at(i, i);
        let norm = a[s[i]].iter().map(|v| v * v).sum::<f64>().sqrt();
        // Also catches NaN.
        if d.partial_cmp(&(1e-13 * norm)) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        let mut v = t.at(i, m);
        for (k, xk) in x.iter().enumerate().skip(i + 1) {
            v -= t.at(i, k) * xk;
        }
        x[i] = v / d;
    }
    Some(x)
}

/// Non-negative least squares `min ‖A x - b‖` over `x_j ≥ 0` for the columns where
/// `signed[j]` is false (any sign where true), `A` given by its columns `a`. Columns are scaled
/// to unit norm first; a zero column is fixed at 0. Returns `x` and the passive set.
pub fn nnls(a: &[Vec<f64>], b: &[f64], signed: &[bool]) -> (Vec<f64>, Vec<bool>) {
    let n = a.len();
    let norms: Vec<f64> = a.iter().map(|c| c.iter().map(|v| v * v).sum::<f64>().sqrt()).collect();
    let scale: Vec<f64> = norms.iter().map(|&s| if s > 0.0 { 1.0 / s } else { 0.0 }).collect();
    let cols: Vec<Vec<f64>> = a.iter().zip(&scale).map(|(c, &s)| c.iter().map(|v| v * s).collect()).collect();
    let usable: Vec<bool> = scale.iter().map(|&s| s > 0.0).collect();
    let grad = |x: &[f64]| -> Vec<f64> {
        let mut r = b.to_vec();
        for (c, &xc) in cols.iter().zip(x) {
            if xc != 0.0 {
                r.iter_mut().zip(c).for_each(|(ri, ci)| *ri -= xc * ci);
            }
        }
        cols.iter().map(|c| c.iter().zip(&r).map(|(p, q)| p * q).sum()).collect()
    };
    let fmax = grad(&vec![0.0; n]).iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let tol = 1e-12 * fmax.max(f64::MIN_POSITIVE);

    let mut x = vec![0.0; n];
    let mut passive: Vec<bool> = (0..n).map(|j| signed[j] && usable[j]).collect();
    if passive.iter().any(|&p| p) {
        let s: Vec<usize> = (0..n).filter(|&j| passive[j]).collect();
        match solve_subset(&cols, b, &s) {
            Some(z) => s.iter().zip(z).for_each(|(&j, v)| x[j] = v),
            None => s.iter().for_each(|&j| passive[j] = false),
        }
    }
    for _outer in 0..3 * n + 3 {
        let w = grad(&x);
        let cand = (0..n)
            .filter(|&j| usable[j] && !passive[j] && w[j] > tol)
            .max_by(|&p, &q| w[p].partial_cmp(&w[q]).unwrap_or(std::cmp::Ordering::Equal));
        let Some(j) = cand else { break };
        passive[j] = true;
        for _inner in 0..3 * n + 3 {
            let s: Vec<usize> = (0..n).filter(|&i| passive[i]).collect();
            let Some(z) = solve_subset(&cols, b, &s) else {
                passive[j] = false;
                break;
            };
            if s.iter().zip(&z).all(|(&i, &v)| v > 0.0 || signed[i]) {
                s.iter().zip(&z).for_each(|(&i, &v)| x[i] = v);
                break;
            }
            let mut alpha = 1.0f64;
            for (&i, &zi) in s.iter().zip(&z) {
                if zi <= 0.0 && !signed[i] {
                    alpha = alpha.min(x[i] / (x[i] - zi));
                }
            }
            for (&i, &zi) in s.iter().zip(&z) {
                x[i] += alpha * (zi - x[i]);
                if !signed[i] && x[i] <= 1e-15 * (1.0 + zi.abs()) {
                    x[i] = 0.0;
                    passive[i] = false;
                }
            }
        }
    }
    (x.iter().zip(&scale).map(|(v, s)| v * s).collect(), passive)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows() -> Vec<[f64; 4]> {
        vec![
            [1.0, 0.2, 0.1, 1.0],
            [0.3, 1.0, 0.0, 2.0],
            [0.0, 0.5, 1.0, -1.0],
            [1.0, 1.0, 1.0, 1.0],
            [0.2, 0.1, 0.9, -0.5],
            [0.7, 0.0, 0.3, 0.4],
        ]
    }

    #[test]
    fn chol_solves() {
        let g = [4.0, 1.0, 1.0, 3.0];
        let mut f = [1.0, 2.0];
        assert!(chol_solve(&g, 2, &mut f));
        assert!((4.0 * f[0] + f[1] - 1.0).abs() < 1e-12 && (f[0] + 3.0 * f[1] - 2.0).abs() < 1e-12);
    }

    /// R^T R (n x n, row-major).
    fn gram(s: &SqrtInfo) -> Vec<f64> {
        let n = s.cols();
        let mut g = vec![0.0; n * n];
        for a in 0..n {
            for b in 0..n {
                g[a * n + b] = (0..=a.min(b)).map(|k| s.at(k, a) * s.at(k, b)).sum();
            }
        }
        g
    }

    /// R^T R reproduces the Gram matrix of the rows.
    #[test]
    fn sqrt_info_gram() {
        let mut s = SqrtInfo::new(4);
        let mut g = [0.0; 16];
        for r in rows() {
            for a in 0..4 {
                for b in 0..4 {
                    g[a * 4 + b] += r[a] * r[b];
                }
            }
            s.add_row(&mut r.clone());
        }
        for (x, y) in gram(&s).iter().zip(&g) {
            assert!((x - y).abs() < 1e-14 * 10.0, "{x} vs {y}");
        }
        for i in 0..4 {
            for j in 0..i {
                assert_eq!(s.at(i, j), 0.0);
            }
        }
    }

    /// KKT conditions of the NNLS solution, on the square root of the data (4 rows) as on the
    /// data (6 rows): the same answer.
    #[test]
    fn nnls_kkt_on_data_and_on_its_square_root() {
        let data: Vec<Vec<f64>> = (0..4).map(|c| rows().iter().map(|r| r[c]).collect()).collect();
        let (a, b) = (&data[..3], &data[3]);
        let (x, _) = nnls(a, b, &[false; 3]);
        let res: Vec<f64> = (0..6).map(|k| b[k] - (0..3).map(|j| a[j][k] * x[j]).sum::<f64>()).collect();
        for j in 0..3 {
            let w: f64 = a[j].iter().zip(&res).map(|(p, q)| p * q).sum();
            assert!(x[j] >= 0.0 && w <= 1e-12 && (x[j] * w).abs() < 1e-12, "x {x:?} w {w}");
        }
        assert!(x.contains(&0.0), "the constraint should be active: {x:?}");
        let t = triangularize(&data);
        let cols: Vec<Vec<f64>> = (0..4).map(|c| t.column(c)).collect();
        let (x2, _) = nnls(&cols[..3], &cols[3], &[false; 3]);
        for (p, q) in x.iter().zip(&x2) {
            assert!((p - q).abs() < 1e-12, "{x:?} vs {x2:?}");
        }
    }

    /// Columns collinear to 1e-9: the orthogonal solve recovers the coefficients to about
    /// eps x condition, the normal equations (condition squared, 1e18) do not.
    #[test]
    fn nearly_collinear_columns() {
        let m = 40;
        let t: Vec<f64> = (0..m).map(|k| k as f64 / m as f64).collect();
        let c0: Vec<f64> = t.iter().map(|x| x.exp()).collect();
        let c1: Vec<f64> = t.iter().zip(&c0).map(|(x, e)| e + 1e-9 * (7.0 * x).sin()).collect();
        let truth = [2.0, -1.5];
        let b: Vec<f64> = (0..m).map(|k| truth[0] * c0[k] + truth[1] * c1[k]).collect();
        let (x, _) = nnls(&[c0.clone(), c1.clone()], &b, &[true, true]);
        assert!((x[0] - truth[0]).abs() < 1e-4 && (x[1] - truth[1]).abs() < 1e-4, "{x:?}");
        // The Gram route for comparison: Cholesky of the 2 x 2 normal equations.
        let dot = |p: &[f64], q: &[f64]| p.iter().zip(q).map(|(a, b)| a * b).sum::<f64>();
        let g = [dot(&c0, &c0), dot(&c0, &c1), dot(&c1, &c0), dot(&c1, &c1)];
        let mut f = [dot(&c0, &b), dot(&c1, &b)];
        let ok = chol_solve(&g, 2, &mut f);
        assert!(!ok || (f[0] - truth[0]).abs() > 1e-2, "normal equations unexpectedly accurate: {f:?}");
    }
}
