//! Small dense linear algebra for the per-vertex problems: Cholesky solves and non-negative
//! least squares on a Gram matrix (Lawson and Hanson 1974, active-set method).
//!
//! NNLS solves $\min_{x \ge 0} \tfrac12 x^T G x - f^T x$ (the normal-equation form of
//! $\min_{x\ge0} \|A x - b\|^2$ with $G = A^T A$, $f = A^T b$). Columns are scaled to unit
//! diagonal first; columns with a zero diagonal (a regressor that is identically zero) are
//! fixed at 0.

/// Solves `g x = f` in place for a symmetric positive (semi)definite `n x n` row-major `g`
/// (a copy is factorised); a tiny diagonal shift (1e-13 relative) keeps it well posed.
/// Returns `false` if the matrix is not positive definite even after the shift.
pub fn chol_solve(g: &[f64], n: usize, f: &mut [f64]) -> bool {
    let mut l = g.to_vec();
    let shift = 1e-13 * (0..n).map(|i| g[i * n + i].abs()).fold(0.0, f64::max);
    for j in 0..n {
        let mut d = l[j * n + j] + shift;
        for k in 0..j {
            d -= l[j * n + k] * l[j * n + k];
        }
        if d <= 0.0 || !d.is_finite() {
            return false;
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
    true
}

/// Solves the sub-system `g[s, s] x_s = f[s]` for the index set `s`; returns `None` if singular.
fn solve_subset(g: &[f64], n: usize, f: &[f64], s: &[usize]) -> Option<Vec<f64>> {
    let m = s.len();
    let mut sub = vec![0.0; m * m];
    for (a, &i) in s.iter().enumerate() {
        for (b, &j) in s.iter().enumerate() {
            sub[a * m + b] = g[i * n + j];
        }
    }
    let mut x: Vec<f64> = s.iter().map(|&i| f[i]).collect();
    chol_solve(&sub, m, &mut x).then_some(x)
}

/// Non-negative least squares on the Gram matrix `g` (`n x n`, row-major) with `f = A^T b`.
/// Returns `x >= 0`; `free[j]` tells whether `x_j` is in the passive (unconstrained) set.
pub fn nnls_gram(g: &[f64], n: usize, f: &[f64]) -> (Vec<f64>, Vec<bool>) {
    nnls_gram_signed(g, n, f, &vec![false; n])
}

/// As [`nnls_gram`], with the variables where `signed[j]` unconstrained (any sign).
pub fn nnls_gram_signed(g: &[f64], n: usize, f: &[f64], signed: &[bool]) -> (Vec<f64>, Vec<bool>) {
    // Unit-diagonal scaling.
    let scale: Vec<f64> = (0..n).map(|j| if g[j * n + j] > 0.0 { 1.0 / g[j * n + j].sqrt() } else { 0.0 }).collect();
    let mut gs = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            gs[i * n + j] = g[i * n + j] * scale[i] * scale[j];
        }
    }
    let fs: Vec<f64> = (0..n).map(|i| f[i] * scale[i]).collect();
    let usable: Vec<bool> = scale.iter().map(|&s| s > 0.0).collect();
    let fmax = fs.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
    let tol = 1e-12 * fmax.max(f64::MIN_POSITIVE);

    let mut x = vec![0.0; n];
    let mut passive: Vec<bool> = (0..n).map(|j| signed[j] && usable[j]).collect();
    if passive.iter().any(|&b| b) {
        let s: Vec<usize> = (0..n).filter(|&i| passive[i]).collect();
        match solve_subset(&gs, n, &fs, &s) {
            Some(z) => s.iter().zip(z).for_each(|(&i, v)| x[i] = v),
            None => s.iter().for_each(|&i| passive[i] = false),
        }
    }
    let grad =
        |x: &[f64]| -> Vec<f64> { (0..n).map(|i| fs[i] - (0..n).map(|j| gs[i * n + j] * x[j]).sum::<f64>()).collect() };
    for _outer in 0..3 * n + 3 {
        let w = grad(&x);
        let cand = (0..n)
            .filter(|&j| usable[j] && !passive[j] && w[j] > tol)
            .max_by(|&a, &b| w[a].partial_cmp(&w[b]).unwrap_or(std::cmp::Ordering::Equal));
        let Some(j) = cand else { break };
        passive[j] = true;
        for _inner in 0..3 * n + 3 {
            let s: Vec<usize> = (0..n).filter(|&i| passive[i]).collect();
            let Some(z) = solve_subset(&gs, n, &fs, &s) else {
                passive[j] = false;
                break;
            };
            if s.iter().zip(&z).all(|(&i, &v)| v > 0.0 || signed[i]) {
                for (k, &i) in s.iter().enumerate() {
                    x[i] = z[k];
                }
                break;
            }
            let mut alpha = 1.0f64;
            for (k, &i) in s.iter().enumerate() {
                if z[k] <= 0.0 && !signed[i] {
                    let a = x[i] / (x[i] - z[k]);
                    alpha = alpha.min(a);
                }
            }
            for (k, &i) in s.iter().enumerate() {
                x[i] += alpha * (z[k] - x[i]);
                if !signed[i] && x[i] <= 1e-15 * (1.0 + z[k].abs()) {
                    x[i] = 0.0;
                    passive[i] = false;
                }
            }
        }
    }
    let out: Vec<f64> = (0..n).map(|i| x[i] * scale[i]).collect();
    (out, passive)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nnls_matches_kkt() {
        // A 6 x 3 problem whose unconstrained solution has a negative entry.
        let a = [[1.0, 0.2, 0.1], [0.3, 1.0, 0.0], [0.0, 0.5, 1.0], [1.0, 1.0, 1.0], [0.2, 0.1, 0.9], [0.7, 0.0, 0.3]];
        let b = [1.0, 2.0, -1.0, 1.0, -0.5, 0.4];
        let n = 3;
        let mut g = vec![0.0; 9];
        let mut f = vec![0.0; 3];
        for (r, &bi) in a.iter().zip(&b) {
            for i in 0..n {
                f[i] += r[i] * bi;
                for j in 0..n {
                    g[i * n + j] += r[i] * r[j];
                }
            }
        }
        let (x, _) = nnls_gram(&g, n, &f);
        // KKT: x >= 0, w = f - G x <= 0, x_i w_i = 0.
        for i in 0..n {
            let w: f64 = f[i] - (0..n).map(|j| g[i * n + j] * x[j]).sum::<f64>();
            assert!(x[i] >= 0.0);
            assert!(w <= 1e-12, "w {w}");
            assert!((x[i] * w).abs() < 1e-12);
        }
        assert!(x.contains(&0.0), "the constraint should be active: {x:?}");
    }

    #[test]
    fn chol_solves() {
        let g = [4.0, 1.0, 1.0, 3.0];
        let mut f = [1.0, 2.0];
        assert!(chol_solve(&g, 2, &mut f));
        assert!((4.0 * f[0] + f[1] - 1.0).abs() < 1e-12 && (f[0] + 3.0 * f[1] - 2.0).abs() < 1e-12);
    }
}
