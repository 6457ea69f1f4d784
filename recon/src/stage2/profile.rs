//! The profiled unknowns of the data term (`super::energy`, module doc): per vertex i, its
//! squared residual summed over its rows is a quadratic in u = (alpha, dlambda, dc),
//! `e_i(u) = Y_i - 2 b_i . u + u^T H_i u` (K^2/s^2; a [`Part`]), and the data term is
//! `sum_i e_i` (L2) or `sum_i rho(e_i / n)` (robust: `rho(v) = sqrt(s(v) + delta^2)`,
//! `s(v) = (v + sqrt(v^2 + delta^4)) / 2` a smooth `max(0, v)`, n the rows per vertex). The
//! profile minimises it over the free components of u at every evaluation of the energy.
//!
//! Every pass over the vertices gives the same bits at any thread count and on any processor:
//! per-vertex values are computed in parallel blocks (the loss compiled for AVX2 where the
//! processor has it, [`pulp::Arch`]; IEEE square roots and divisions are correctly rounded at
//! any vector width and Rust fuses no multiply-add), and summed in vertex order.

use rayon::prelude::*;

/// One vertex's quadratic: (Y, b, H with H packed as [00, 01, 02, 11, 12, 22]).
pub(super) type Part = (f64, [f64; 3], [f64; 6]);

/// Vertices per parallel task.
const BLOCK: usize = 4096;

/// For a block of at most 1024 vertices, the first and second derivatives of `rho(e_i(u) / n)`
/// with respect to its argument, vectorised (module doc).
fn loss_derivatives(block: &[Part], u: [f64; 3], n: f64, delta2: f64) -> ([f64; 1024], [f64; 1024]) {
    let (mut d1, mut d2) = ([0.0; 1024], [0.0; 1024]);
    pulp::Arch::new().dispatch(|| {
        for (x, (y, b, h)) in d1.iter_mut().zip(block) {
            *x = profile_value(*y, b, h, u) / n;
        }
        for (x1, x2) in d1[..block.len()].iter_mut().zip(&mut d2) {
            (_, *x1, *x2) = robust_rho2(*x1, delta2);
        }
    });
    (d1, d2)
}

/// Per vertex, `f(e_i(u) / n)` into `out`, in parallel blocks, `f` vectorised (module doc).
fn per_vertex(parts: &[Part], u: [f64; 3], n: f64, out: &mut Vec<f64>, f: impl Fn(f64) -> f64 + Sync) {
    out.resize(parts.len(), 0.0);
    let arch = pulp::Arch::new();
    out.par_chunks_mut(BLOCK).zip(parts.par_chunks(BLOCK)).for_each(|(o, p)| {
        arch.dispatch(|| {
            for (x, (y, b, h)) in o.iter_mut().zip(p) {
                *x = profile_value(*y, b, h, u) / n;
            }
            o.iter_mut().for_each(|x| *x = f(*x));
        });
    });
}

/// e_i(u) of a vertex's [`Part`].
#[inline(always)]
pub(super) fn profile_value(y: f64, b: &[f64; 3], h: &[f64; 6], u: [f64; 3]) -> f64 {
    y - 2.0 * (b[0] * u[0] + b[1] * u[1] + b[2] * u[2])
        + h[0] * u[0] * u[0]
        + h[3] * u[1] * u[1]
        + h[5] * u[2] * u[2]
        + 2.0 * (h[1] * u[0] * u[1] + h[2] * u[0] * u[2] + h[4] * u[1] * u[2])
}

/// The robust loss of one vertex, `ρ = sqrt(s(v) + δ^2)` with the smooth clamp
/// `s(v) = (v + sqrt(v^2 + δ^4))/2` of its mean squared residual `v` (module doc), and
/// `dρ/dv = s'(v) / (2ρ)`.
#[inline(always)]
pub(super) fn robust_rho(v: f64, delta2: f64) -> (f64, f64) {
    let (rho, d, _) = robust_rho2(v, delta2);
    (rho, d)
}

/// [`robust_rho`] with the second derivative, `ρ'' = s''/(2ρ) - s'^2/(4ρ^3)`.
#[inline(always)]
fn robust_rho2(v: f64, delta2: f64) -> (f64, f64, f64) {
    let q = (v * v + delta2 * delta2).sqrt();
    let rho = (0.5 * (v + q) + delta2).sqrt();
    let (s1, s2) = (0.5 * (1.0 + v / q), 0.5 * delta2 * delta2 / (q * q * q));
    (rho, s1 / (2.0 * rho), s2 / (2.0 * rho) - s1 * s1 / (4.0 * rho * rho * rho))
}

/// The profiled unknowns minimising the data term: u starts at `u0`, the components with
/// `free[c]` are minimised (alpha kept >= 0). L2: one weighted least-squares solve;
/// robust (sum_i rho(e_i/n), [`robust_rho`]): iteratively reweighted least squares with the
/// weights rho'(e_i/n), whose fixed point is the stationary point the envelope-theorem gradient
/// needs, then Newton steps to reach it to rounding (IRLS converges linearly, and slowly along
/// the barely determined c: stopped short, its optimum moved with the shape by more than the
/// gradient accounts for, and L-BFGS's line search failed after 41 iterations on the 50 mK
/// bunny).
pub(super) fn profile_unknowns(
    parts: &[Part],
    u0: [f64; 3],
    free: [bool; 3],
    robust: bool,
    n: f64,
    delta2: f64,
) -> [f64; 3] {
    let idx: Vec<usize> = (0..3).filter(|&c| free[c]).collect();
    if idx.is_empty() {
        return u0;
    }
    let full = |h: &[f64; 6], r: usize, c: usize| {
        h[match (r.min(c), r.max(c)) {
            (0, 0) => 0,
            (0, 1) => 1,
            (0, 2) => 2,
            (1, 1) => 3,
            (1, 2) => 4,
            _ => 5,
        }]
    };
    // One weighted least-squares step over the components `idx`, the others held at `u`. The
    // pass-independent part, per vertex the right side with the held components moved over (k)
    // and the matrix (k x k), is computed once per `idx` and held values (`cache`); a pass
    // computes the weights in parallel and sums the weighted terms in vertex order (the same
    // bits at any thread count).
    let mut cache: Option<(Vec<usize>, [u64; 3], Vec<f64>)> = None;
    let mut weights: Vec<f64> = Vec::new();
    let mut step = |u: [f64; 3], idx: &[usize]| -> Option<[f64; 3]> {
        let k = idx.len();
        let width = k + k * k;
        let held: Vec<usize> = (0..3).filter(|c| !idx.contains(c)).collect();
        let held_bits = [0, 1, 2].map(|c| if held.contains(&c) { u[c].to_bits() } else { 0 });
        if !matches!(&cache, Some((i, b, _)) if i.as_slice() == idx && *b == held_bits) {
            let mut terms = vec![0.0; parts.len() * width];
            terms.par_chunks_mut(width * 1024).enumerate().for_each(|(chunk, out)| {
                for (t, (_, b, h)) in out.chunks_exact_mut(width).zip(&parts[chunk * 1024..]) {
                    for (r, &ir) in idx.iter().enumerate() {
                        // d e/d u_ir = 2 (H u - b)_ir; the fixed components move to the right side.
                        let mut fixed = b[ir];
                        for &c in &held {
                            fixed -= full(h, ir, c) * u[c];
                        }
                        t[r] = fixed;
                        for (c, &ic) in idx.iter().enumerate() {
                            t[k + r * k + c] = full(h, ir, ic);
                        }
                    }
                }
            });
            cache = Some((idx.to_vec(), held_bits, terms));
        }
        let terms = &cache.as_ref().expect("just filled").2;
        if robust {
            per_vertex(parts, u, n, &mut weights, |v| robust_rho(v, delta2).1);
        }
        let (mut a, mut rhs) = (vec![0.0; k * k], vec![0.0; k]);
        for (i, t) in terms.chunks_exact(width).enumerate() {
            let w = if robust { weights[i] } else { 1.0 };
            for r in 0..k {
                rhs[r] += w * t[r];
                for c in 0..k {
                    a[r * k + c] += w * t[k + r * k + c];
                }
            }
        }
        // A tiny ridge only when singular: c may be barely identifiable (docs/reconstruction.md, stage 1). It is
        // not in the energy, so where it acts the gradient is off by its size (envelope theorem).
        let sol = solve_small(&a, &rhs, k).or_else(|| {
            let tr: f64 = (0..k).map(|r| a[r * k + r]).sum();
            let mut ar = a.clone();
            (0..k).for_each(|r| ar[r * k + r] += 1e-12 * tr);
            solve_small(&ar, &rhs, k)
        })?;
        let mut next = u;
        for (r, &ir) in idx.iter().enumerate() {
            next[ir] = sol[r];
        }
        Some(next)
    };
    let mut u = u0;
    for _ in 0..if robust { 50 } else { 1 } {
        let Some(mut next) = step(u, &idx) else {
            break;
        };
        // alpha >= 0: where the joint step leaves it negative, the constrained minimiser has
        // alpha = 0 and the other components re-solved with it (clamping alone left them at
        // values that belong to the negative alpha, an energy above that of any alpha >= 0).
        if free[0] && next[0] < 0.0 {
            let rest: Vec<usize> = idx.iter().copied().filter(|&c| c != 0).collect();
            let at_zero = [0.0, u[1], u[2]];
            next = if rest.is_empty() { at_zero } else { step(at_zero, &rest).unwrap_or(at_zero) };
        }
        let change: f64 = (0..3).map(|c| (next[c] - u[c]).abs() / (next[c].abs() + 1e-300)).sum();
        u = next;
        if change < 1e-10 {
            break;
        }
    }
    if robust {
        // Newton on the components not held at a bound (alpha = 0 stays there).
        let idx: Vec<usize> = idx.iter().copied().filter(|&c| !(c == 0 && u[0] == 0.0)).collect();
        let mut rho: Vec<f64> = Vec::new();
        let mut total = |u: [f64; 3]| {
            per_vertex(parts, u, n, &mut rho, |v| robust_rho(v, delta2).0);
            rho.iter().sum::<f64>()
        };
        let mut f0 = total(u);
        let mut buf = Vec::new();
        for _ in 0..20 {
            let k = idx.len();
            if k == 0 {
                break; // every component at its bound: nothing to step
            }
            // Per vertex, its terms of the gradient (k) and Hessian (k x k), in parallel, then
            // summed in vertex order.
            let width = k + k * k;
            buf.resize(parts.len() * width, 0.0);
            let terms = &mut buf[..];
            terms.par_chunks_mut(width * 1024).enumerate().for_each(|(chunk, out)| {
                let block = &parts[chunk * 1024..(chunk * 1024 + out.len() / width)];
                let (d1s, d2s) = loss_derivatives(block, u, n, delta2);
                for (j, t) in out.chunks_exact_mut(width).enumerate() {
                    let (_, b, h) = &block[j];
                    let (d1, d2) = (d1s[j], d2s[j]);
                    // d e / d u = 2 (H u - b), d2 e / du2 = 2 H.
                    let mut ge = [0.0; 3];
                    for (g, &r) in ge.iter_mut().zip(&idx) {
                        *g = 2.0 * ((0..3).map(|c| full(h, r, c) * u[c]).sum::<f64>() - b[r]);
                    }
                    for r in 0..k {
                        t[r] = d1 / n * ge[r];
                        for c in 0..k {
                            t[k + r * k + c] = d1 / n * 2.0 * full(h, idx[r], idx[c]) + d2 / (n * n) * ge[r] * ge[c];
                        }
                    }
                }
            });
            let (mut hess, mut grad) = (vec![0.0; k * k], vec![0.0; k]);
            for t in terms.chunks_exact(width) {
                for r in 0..k {
                    grad[r] += t[r];
                    for c in 0..k {
                        hess[r * k + c] += t[k + r * k + c];
                    }
                }
            }
            // Damped where the Hessian is not positive definite or the full step rises (the
            // loss is not convex where the clamp bends): H + mu diag(H), mu = 0, 1e-3, 1e-2, ...
            let mut accepted = None;
            for mu in [0.0, 1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3] {
                let mut hd = hess.clone();
                (0..k).for_each(|r| hd[r * k + r] += mu * hess[r * k + r].abs().max(1e-300));
                let Some(step) = solve_small(&hd, &grad, k) else { continue };
                let mut next = u;
                for (r, &c) in idx.iter().enumerate() {
                    next[c] -= step[r];
                }
                if idx.contains(&0) && next[0] < 0.0 {
                    continue;
                }
                let f1 = total(next);
                if f1 <= f0 {
                    accepted = Some((next, f1));
                    break;
                }
            }
            let Some((next, f1)) = accepted else { break };
            u = next;
            if f0 - f1 <= 1e-15 * f0.abs() {
                break;
            }
            f0 = f1;
        }
    }
    u
}

/// Solves the symmetric k x k system `a x = b` (k <= 3) by Gaussian elimination with partial
/// pivoting; `None` when singular. Not `stage1::lsq::chol_solve`: its fixed diagonal shift
/// moves the optimum off the energy's stationary point, which the envelope-theorem gradient
/// needs (a 1e-12 shift gave a 2.4e-5 gradient error with alpha profiled).
fn solve_small(a: &[f64], b: &[f64], k: usize) -> Option<Vec<f64>> {
    let mut m: Vec<Vec<f64>> = (0..k).map(|r| (0..k).map(|c| a[r * k + c]).chain([b[r]]).collect()).collect();
    for col in 0..k {
        let piv = (col..k).max_by(|&x, &y| m[x][col].abs().total_cmp(&m[y][col].abs()))?;
        m.swap(col, piv);
        let pivot = m[col].clone();
        if pivot[col] == 0.0 || !pivot[col].is_finite() {
            return None;
        }
        for row in m.iter_mut().skip(col + 1) {
            let f = row[col] / pivot[col];
            row.iter_mut().zip(&pivot).skip(col).for_each(|(x, p)| *x -= f * p);
        }
    }
    let mut x = vec![0.0; k];
    for r in (0..k).rev() {
        x[r] = (m[r][k] - (r + 1..k).map(|c| m[r][c] * x[c]).sum::<f64>()) / m[r][r];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The vectorised per-vertex pass gives the bits of one vertex at a time, over values that
    /// cross the clamp (negative, zero, tiny and large e).
    #[test]
    fn vectorised_pass_matches_scalar_bits() {
        let mut s = 0x9e37_79b9_7f4a_7c15_u64;
        let mut r = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.3
        };
        let parts: Vec<Part> = (0..10_007)
            .map(|i| {
                let scale = 10f64.powi((i % 13) as i32 - 6);
                (scale * r(), [r(), r(), r()], [1.0 + r(), r(), r(), 1.0 + r(), r(), 1.0 + r()])
            })
            .collect();
        let (u, n, delta2) = ([0.3, -0.2, 0.7], 202.0, 1e-8);
        for (k, f) in [|v: f64, d: f64| robust_rho(v, d).0, |v: f64, d: f64| robust_rho(v, d).1].iter().enumerate() {
            let mut out = Vec::new();
            per_vertex(&parts, u, n, &mut out, |v| f(v, delta2));
            for (i, (y, b, h)) in parts.iter().enumerate() {
                let one = f(profile_value(*y, b, h, u) / n, delta2);
                assert_eq!(out[i].to_bits(), one.to_bits(), "output {k}, vertex {i}: {} against {one}", out[i]);
            }
        }
        for block in parts.chunks(1024) {
            let (d1, d2) = loss_derivatives(block, u, n, delta2);
            for (j, (y, b, h)) in block.iter().enumerate() {
                let (_, e1, e2) = robust_rho2(profile_value(*y, b, h, u) / n, delta2);
                assert_eq!((d1[j].to_bits(), d2[j].to_bits()), (e1.to_bits(), e2.to_bits()), "vertex {j}");
            }
        }
    }

    /// With the unconstrained alpha negative, the profile returns the constrained minimiser
    /// (alpha = 0, the globals re-solved), whose value is below that of the clamped joint
    /// solution, for the L2 and the robust loss; a small grid over alpha >= 0 finds nothing lower.
    #[test]
    fn profile_keeps_alpha_nonnegative_and_minimal() {
        // e(u) = y - 2 b.u + u^T H u, H = [[2, 1, 0], [1, 2, 0.5], [0, 0.5, 1]] packed.
        let h = [2.0, 1.0, 0.0, 2.0, 0.5, 1.0];
        let parts = vec![(10.0, [-1.0, 1.0, 0.3], h), (8.0, [-0.5, 0.8, 0.1], h)];
        let total = |u: [f64; 3]| parts.iter().map(|(y, b, h)| profile_value(*y, b, h, u)).sum::<f64>();
        let robust_total =
            |u: [f64; 3]| parts.iter().map(|(y, b, h)| robust_rho(profile_value(*y, b, h, u), 0.01).0).sum::<f64>();
        for robust in [false, true] {
            let f = |u: [f64; 3]| if robust { robust_total(u) } else { total(u) };
            let u = profile_unknowns(&parts, [0.0; 3], [true; 3], robust, 1.0, 0.01);
            assert_eq!(u[0], 0.0, "alpha should sit on its bound: {u:?}");
            // The clamped joint solution for comparison (L2): H u = sum b / 2 parts.
            let bsum = [-1.5 / 2.0, 1.8 / 2.0, 0.4 / 2.0];
            let g = [2.0, 1.0, 0.0, 1.0, 2.0, 0.5, 0.0, 0.5, 1.0];
            let mut x = bsum;
            assert!(crate::stage1::lsq::chol_solve(&g, 3, &mut x));
            assert!(x[0] < 0.0, "the unconstrained alpha must be negative for this test: {x:?}");
            let clamped = [0.0, x[1], x[2]];
            assert!(f(u) < f(clamped) - 1e-9, "robust {robust}: {} vs clamped {}", f(u), f(clamped));
            for k in 0..20 {
                for d1 in [-0.1, 0.0, 0.1] {
                    for d2 in [-0.1, 0.0, 0.1] {
                        let v = [0.05 * k as f64, u[1] + d1, u[2] + d2];
                        assert!(f(v) >= f(u) - 1e-9, "robust {robust}: {v:?} gives {} < {}", f(v), f(u));
                    }
                }
            }
        }
    }
}
