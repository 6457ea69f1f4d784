//! The output-error fit of a few shape modes with lambda: the depths restricted to
//! `z = z_0 + Σ_j β_j v_j` (the bound's modes, [`default_modes`] at the start `z_0`: size,
//! relief and the image monomials u^p v^q up to a degree) and lambda = λ_0 exp(x_0), fitted by
//! L-BFGS on the output-error loss profiled over the fluxes,
//! `J*(x, β) = min_b J(z(β), b, λ(x))` (K^2).
//!
//! The gradient is the envelope theorem's: after the flux fit at `(x, β)` the partial
//! derivatives at fixed fluxes, `∂J*/∂β_j = Σ_i (∂J/∂z_i) v_j[i]` and
//! `∂J*/∂x_0 = λ ∂J/∂λ` ([`crate::bound::output_error::loss`]'s adjoint). Each evaluation warm
//! starts its flux fit from the fluxes of the lowest point so far.
//!
//! With [`OeOptions::mode_gauss_newton`] the fit instead takes damped Gauss–Newton steps of
//! variable projection: the videos' derivatives in `(x, β)` projected away from the fluxes'
//! directions, `A`, and the whitened residual `r` at the exact flux fit
//! ([`crate::bound::shape::mode_system`]) give the step `(Â + μ I)^-1 r̂` (`Â = A^T A` scaled
//! to unit diagonal, `r̂ = A^T r` alike), `μ` (from 1e-4) divided by 100 after a step that
//! lowers the profiled loss (down to 1e-10: relief and the quadratic monomials are nearly one
//! direction, which a larger `μ` holds back) and multiplied by 10 until one does (at most 8
//! times). `A^T A` is also the Fisher information at the fit: the coefficients' standard
//! deviations are reported, and the fit stops when a step moves every coefficient by less than
//! 0.05 of its own or 1e-4 (or the loss by less than 1e-12 of itself).
//!
//! With [`OeOptions::mode_starts`] the fit runs from several sizes of the start (its depths
//! scaled) and keeps the lowest loss: the loss along the size has more than one basin at
//! camera noise.
//!
//! Why: along a fixed form the output-error size moves by more than 10 % for any millimetre
//! error of that form, and per-vertex forms fitted at 50 mK carry fitted noise
//! (docs/notes/reconstruction-stage2.md, "The output-error size at the full tier's level 1").
//! With a handful of modes the fit cannot follow the noise, and the size is fitted with the
//! form and lambda, as in the bound. Measured on the ball, it holds the size from the true form
//! at 20 and 50 mK, but from the method's forms it walks 15 to 55 % away (notes, "The mode fit
//! by Gauss–Newton" and "The size rule spoils the form at camera noise").

use std::cell::RefCell;

use faer::linalg::solvers::{DenseSolveCore, Solve};
use faer::{Mat, Side};

use crate::bound::output_error::{loss, minimise_fallible, OeData, OeGrad, OeMesh};
use crate::bound::shape::{default_modes, mode_system, ShapeMode};
use crate::error::ReconError;
use crate::experimental::output_error::{profile_fluxes, OeOptions, EXACT_FLUX_FIT};
use crate::stage2::optimize::{LargeSteps, OptimOptions, Optimizer};

/// Depth change of a monomial mode per unit coefficient, m (so that every coefficient of the
/// fit is of order one where the form is centimetres off).
const MONOMIAL_SCALE_M: f64 = 0.01;

/// A Gauss–Newton step that moves no coefficient (nor ln lambda) by more than this ends the
/// fit, whatever the noise (noise-free data give standard deviations of 0).
const NEGLIGIBLE_STEP: f64 = 1e-4;

/// A mode whose depth changes' rms is below this fraction of the depths' is left out.
const NEGLIGIBLE_MODE: f64 = 1e-9;

/// The result of [`fit_modes`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ModeFit {
    /// The modes' names, as in the bound ("size", "relief", "u^p v^q").
    pub modes: Vec<String>,
    /// Their fitted coefficients (size and relief: factors less one; monomials: cm), at the
    /// kept start's depths.
    pub coefficients: Vec<f64>,
    /// The fitted lambda, 1/s.
    pub lambda: f64,
    /// The loss at the kept start, K^2.
    pub loss_start_k2: f64,
    /// The loss at the end, K^2.
    pub loss_k2: f64,
    /// Loss evaluations (each one flux fit), of every start.
    pub evaluations: usize,
    /// Gauss–Newton: the standard deviations at the last system, from the noise variance: of ln
    /// lambda first, then of each coefficient; empty for L-BFGS.
    pub std: Vec<f64>,
    /// The mean depth of the fit over that of the given depths.
    pub size_factor: f64,
    /// Every start ([`OeOptions::mode_starts`]), in order; the fit is the lowest's.
    pub starts: Vec<ModeStart>,
}

/// One start of [`fit_modes`] and where its fit ended.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ModeStart {
    /// The factor on the given depths.
    pub factor: f64,
    /// The loss at the start, K^2.
    pub loss_start_k2: f64,
    /// The loss at the end, K^2.
    pub loss_k2: f64,
    /// The mean depth at the end over that of the given depths.
    pub size_factor: f64,
}

/// Fits lambda and the coefficients of the modes of degree [`OeOptions::mode_degree`] at the
/// depths `z` (module doc) by [`OeOptions::mode_iterations`] of L-BFGS, each evaluation the
/// fluxes' fit ([`profile_fluxes`]) from the lowest point's fluxes so far, or of Gauss–Newton
/// with [`OeOptions::mode_gauss_newton`]; from `z` scaled by each of
/// [`OeOptions::mode_starts`] (or `z` alone), the lowest loss kept. `z` and `b` get the lowest
/// point evaluated. `d`'s lambda is the start.
///
/// # Errors
/// As [`loss`]; Gauss–Newton without [`OeOptions::exact_profile`]; a start factor that is not
/// positive.
pub fn fit_modes(
    om: &OeMesh,
    d: &OeData,
    z: &mut [f64],
    b: &mut [Vec<f64>],
    opts: &OeOptions,
    observer: &mut dyn crate::Observer,
) -> Result<ModeFit, ReconError> {
    let factors = if opts.mode_starts.is_empty() { vec![1.0] } else { opts.mode_starts.clone() };
    if let Some(f) = factors.iter().find(|f| !(f.is_finite() && **f > 0.0)) {
        return Err(ReconError::Input(format!("mode_starts: {f} is not a positive factor")));
    }
    let (mut starts, mut evaluations) = (Vec::with_capacity(factors.len()), 0);
    let mut best: Option<(ModeFit, Vec<f64>, Vec<Vec<f64>>)> = None;
    for (k, &factor) in factors.iter().enumerate() {
        if factors.len() > 1 {
            observer.message(&format!("mode fit, start {} of {}: the depths x {factor}", k + 1, factors.len()));
        }
        let (mut zs, mut bs): (Vec<f64>, _) = (z.iter().map(|v| v * factor).collect(), b.to_vec());
        let fit = fit_from(om, d, &mut zs, &mut bs, opts, factor, observer)?;
        evaluations += fit.evaluations;
        starts.push(ModeStart {
            factor,
            loss_start_k2: fit.loss_start_k2,
            loss_k2: fit.loss_k2,
            size_factor: fit.size_factor,
        });
        if best.as_ref().is_none_or(|(kept, ..)| fit.loss_k2 < kept.loss_k2) {
            best = Some((fit, zs, bs));
        }
    }
    let (mut fit, zs, bs) = best.expect("at least one start");
    z.copy_from_slice(&zs);
    b.iter_mut().zip(bs).for_each(|(o, v)| *o = v);
    fit.evaluations = evaluations;
    fit.starts = starts;
    Ok(fit)
}

/// [`fit_modes`] from the depths `z` (the given depths times `factor`, for the messages).
fn fit_from(
    om: &OeMesh,
    d: &OeData,
    z: &mut [f64],
    b: &mut [Vec<f64>],
    opts: &OeOptions,
    factor: f64,
    observer: &mut dyn crate::Observer,
) -> Result<ModeFit, ReconError> {
    let z0 = z.to_vec();
    let mut modes = default_modes(om, &z0, opts.mode_degree);
    for m in modes.iter_mut().skip(2) {
        m.dz.iter_mut().for_each(|v| *v *= MONOMIAL_SCALE_M);
    }
    // A mode that does not move the depths (the relief of a plane) is left out: its
    // coefficient would scale rounding.
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    let size_rms = rms(&z0);
    modes.retain(|m| rms(&m.dz) > NEGLIGIBLE_MODE * size_rms);
    let p = Problem { om, d, opts, z0, modes, factor };
    let fit = if opts.mode_gauss_newton {
        if !opts.exact_profile {
            return Err(ReconError::Input("the Gauss-Newton mode fit needs exact_profile".into()));
        }
        gauss_newton(&p, b, observer)?
    } else {
        lbfgs(&p, b)?
    };
    z.copy_from_slice(&p.depths(&fit.x));
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    Ok(ModeFit {
        modes: p.modes.iter().map(|m| m.name.clone()).collect(),
        coefficients: fit.x[1..].to_vec(),
        lambda: d.lambda * fit.x[0].exp(),
        loss_start_k2: fit.loss_start,
        loss_k2: fit.loss,
        evaluations: fit.evaluations,
        std: fit.std,
        size_factor: factor * mean(z) / mean(&p.z0),
        starts: Vec::new(),
    })
}

/// The fit's unknowns `x = (ln lambda factor, β)` and what they set.
struct Problem<'a, 'd> {
    om: &'a OeMesh<'a>,
    d: &'a OeData<'d>,
    opts: &'a OeOptions,
    /// The start depths, m.
    z0: Vec<f64>,
    modes: Vec<ShapeMode>,
    /// The start depths over the given ones (for the messages).
    factor: f64,
}

impl<'d> Problem<'_, 'd> {
    /// `z_0 + Σ_j β_j v_j`, m.
    fn depths(&self, x: &[f64]) -> Vec<f64> {
        let mut zz = self.z0.clone();
        for (m, &beta) in self.modes.iter().zip(&x[1..]) {
            zz.iter_mut().zip(&m.dz).for_each(|(o, v)| *o += beta * v);
        }
        zz
    }

    /// The data with lambda = λ_0 exp(x_0).
    fn at(&self, x: &[f64]) -> OeData<'d> {
        OeData { lambda: self.d.lambda * x[0].exp(), ..self.d.clone() }
    }

    /// The loss at `x` profiled over the fluxes from `b` ([`profile_fluxes`]); `b` gets them.
    fn profile(&self, x: &[f64], b: &mut [Vec<f64>]) -> Result<f64, ReconError> {
        profile_fluxes(self.om, &self.at(x), &self.depths(x), b, self.opts)
    }
}

/// A solver's result: `x = (ln lambda factor, β)` at the lowest loss (`b` has its fluxes).
struct Solved {
    x: Vec<f64>,
    loss_start: f64,
    loss: f64,
    evaluations: usize,
    std: Vec<f64>,
}

/// L-BFGS on `(x_0, β)` with the envelope theorem's gradient (module doc).
fn lbfgs(p: &Problem, b: &mut [Vec<f64>]) -> Result<Solved, ReconError> {
    let (om, modes) = (p.om, &p.modes);
    // The lowest point so far: (loss, coefficients, fluxes). Every evaluation starts its flux
    // fit from its fluxes, so that a wild line-search trial does not spoil the next start.
    let best = RefCell::new((f64::INFINITY, Vec::new(), b.to_vec()));
    let evaluations = RefCell::new(0usize);
    let objective = |x: &[f64], g: &mut [f64]| -> Result<f64, ReconError> {
        let (dl, zz) = (p.at(x), p.depths(x));
        let mut bx = best.borrow().2.clone();
        profile_fluxes(om, &dl, &zz, &mut bx, p.opts)?;
        let (mut gz, mut gg) = (vec![0.0; zz.len()], [0.0; 2]);
        let j = loss(om, &dl, &zz, &bx, OeGrad { z: Some(&mut gz), b: None, globals: Some(&mut gg) })?;
        g[0] = gg[0] * dl.lambda;
        for (gk, m) in g[1..].iter_mut().zip(modes) {
            *gk = m.dz.iter().zip(&gz).map(|(v, gi)| v * gi).sum();
        }
        *evaluations.borrow_mut() += 1;
        if j < best.borrow().0 {
            *best.borrow_mut() = (j, x.to_vec(), bx);
        }
        Ok(j)
    };
    let n = modes.len() + 1;
    let mut x = vec![0.0; n];
    let mut g0 = vec![0.0; n];
    let loss_start = objective(&x, &mut g0)?;
    let lbfgs = OptimOptions {
        optimizer: Optimizer::Lbfgs,
        iterations: p.opts.mode_iterations,
        learning_rate: 0.02,
        large_steps_lambda: 0.0,
        min_depth: f64::NEG_INFINITY,
        blocks: (1..n).collect(),
    };
    let identity = LargeSteps::new(n, &[], 0.0)?;
    minimise_fallible(&mut x, &identity, &lbfgs, objective, |_| {})?;
    let (loss, x, fitted) = best.into_inner();
    b.iter_mut().zip(fitted).for_each(|(o, v)| *o = v);
    Ok(Solved { x, loss_start, loss, evaluations: evaluations.into_inner(), std: Vec::new() })
}

/// Damped Gauss–Newton on `(x_0, β)` (module doc).
fn gauss_newton(p: &Problem, b: &mut [Vec<f64>], observer: &mut dyn crate::Observer) -> Result<Solved, ReconError> {
    let n = p.modes.len() + 1;
    let mut x = vec![0.0; n];
    let mut j = p.profile(&x, b)?;
    let (loss_start, mut evaluations, mut std, mut mu) = (j, 1, Vec::new(), 1e-4);
    for it in 0..p.opts.mode_iterations {
        let dl = p.at(&x);
        let (gram, rhs) = mode_system(p.om, &dl, &p.depths(&x), b, &p.modes, EXACT_FLUX_FIT)?;
        std = covariance_diagonal(&gram).iter().map(|c| (dl.noise_var * c).sqrt()).collect();
        let (mut taken, mut converged) = (false, false);
        for _ in 0..8 {
            let Some(step) = damped_step(&gram, &rhs, mu) else { break };
            // The system's order is (β, ln lambda); x's is (ln lambda, β).
            let mut trial = x.clone();
            trial[0] += step[n - 1];
            trial[1..].iter_mut().zip(&step).for_each(|(t, s)| *t += s);
            let mut bt = b.to_vec();
            let jt = p.profile(&trial, &mut bt)?;
            evaluations += 1;
            if jt < j {
                // Converged: the loss no longer falls, or the step is well within the
                // coefficients' noise.
                converged = j - jt <= 1e-12 * j
                    || step.iter().zip(&std).all(|(s, sd)| s.abs() <= (0.05 * sd).max(NEGLIGIBLE_STEP));
                (x, j, taken) = (trial, jt, true);
                b.iter_mut().zip(bt).for_each(|(o, v)| *o = v);
                mu = (mu / 100.0).max(1e-10);
                break;
            }
            mu *= 10.0;
        }
        observer.message(&format!(
            "mode fit, Gauss-Newton step {}: loss {j:.6e} K^2, size factor {:.5}, lambda {:.5e} 1/s{}",
            it + 1,
            p.factor * (1.0 + x[1]),
            p.at(&x).lambda,
            if taken { "" } else { " (no step lowered the loss)" }
        ));
        if !taken || converged {
            break;
        }
    }
    // Back to x's order.
    if !std.is_empty() {
        std.rotate_right(1);
    }
    Ok(Solved { x, loss_start, loss: j, evaluations, std })
}

/// The solution of `(Â + μ I) ŝ = r̂`, `Â` the Gram scaled to unit diagonal (a coefficient
/// with a zero diagonal, a mode that does not move the videos, stays); `None` when that system
/// is not positive definite.
fn damped_step(gram: &Mat<f64>, rhs: &[f64], mu: f64) -> Option<Vec<f64>> {
    let k = rhs.len();
    let s: Vec<f64> = (0..k).map(|a| if gram[(a, a)] > 0.0 { 1.0 / gram[(a, a)].sqrt() } else { 0.0 }).collect();
    let a = Mat::from_fn(k, k, |p, q| gram[(p, q)] * s[p] * s[q] + if p == q { mu } else { 0.0 });
    let r = Mat::from_fn(k, 1, |p, _| rhs[p] * s[p]);
    let sol = a.llt(Side::Lower).ok()?.solve(&r);
    let step: Vec<f64> = (0..k).map(|p| sol[(p, 0)] * s[p]).collect();
    step.iter().all(|v| v.is_finite()).then_some(step)
}

/// The diagonal of the Gram's inverse over the coefficients that move the videos (scaled to
/// unit diagonal first); infinite for the others and where that is not positive definite.
fn covariance_diagonal(gram: &Mat<f64>) -> Vec<f64> {
    let k = gram.nrows();
    let live: Vec<usize> = (0..k).filter(|&a| gram[(a, a)] > 0.0 && gram[(a, a)].is_finite()).collect();
    let s: Vec<f64> = live.iter().map(|&a| gram[(a, a)].sqrt()).collect();
    let scaled = Mat::from_fn(live.len(), live.len(), |p, q| gram[(live[p], live[q])] / (s[p] * s[q]));
    let mut out = vec![f64::INFINITY; k];
    if let Ok(llt) = scaled.llt(Side::Lower) {
        let inv = llt.inverse();
        live.iter().enumerate().for_each(|(p, &a)| out[a] = inv[(p, p)] / (s[p] * s[p]));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bound::output_error::tests::{lambda_problem, physics, LAMBDA_TRUE};

    /// Model data; the start 12 % too far, with a relief 30 % too small and a tilt, lambda 12 %
    /// off: the fit of degree 1 recovers the depths and lambda, by L-BFGS and by Gauss–Newton.
    #[test]
    fn mode_fit_recovers_size_relief_tilt_and_lambda() {
        let (mesh, z, bs, series, times) = lambda_problem(2);
        let om = OeMesh::new(&mesh).expect("pattern");
        let d = OeData { lambda: LAMBDA_TRUE * 1.12, ..physics(&series, &times) };
        let zm = z.iter().sum::<f64>() / z.len() as f64;
        let start: Vec<f64> =
            z.iter().zip(&mesh.dirs).map(|(v, dir)| 1.12 * (zm + 0.7 * (v - zm)) + 0.002 * dir[0] / 0.05).collect();
        let lbfgs = OeOptions { mode_degree: 1, flux_iterations: 60, mode_iterations: 40, ..OeOptions::new(0) };
        let gauss_newton = OeOptions {
            flux_iterations: 3,
            exact_profile: true,
            mode_gauss_newton: true,
            mode_iterations: 10,
            ..lbfgs.clone()
        };
        for opts in [lbfgs, gauss_newton] {
            let (mut zs, mut b) = (start.clone(), bs.clone());
            let fit = fit_modes(&om, &d, &mut zs, &mut b, &opts, &mut crate::observer::Silent).expect("mode fit");
            let err = zs.iter().zip(&z).map(|(a, t)| (a - t).abs()).fold(0.0f64, f64::max);
            let rel = fit.lambda / LAMBDA_TRUE - 1.0;
            assert!(fit.loss_k2 < 1e-3 * fit.loss_start_k2, "loss {:e} -> {:e}", fit.loss_start_k2, fit.loss_k2);
            assert!(err < 2e-4 && rel.abs() < 0.01, "largest depth error {err:e} m, lambda {rel:+e}: {fit:?}");
            assert_eq!(fit.std.len(), if opts.mode_gauss_newton { fit.coefficients.len() + 1 } else { 0 });
        }
    }

    /// Two starts (the depths as given and 30 % farther): the fit kept is the one of the lower
    /// loss, its depths are the ones returned, and a factor that is not positive is refused.
    #[test]
    fn mode_starts_keep_the_lowest_fit() {
        let (mesh, z, bs, series, times) = lambda_problem(2);
        let om = OeMesh::new(&mesh).expect("pattern");
        let d = OeData { lambda: LAMBDA_TRUE * 1.12, ..physics(&series, &times) };
        let start: Vec<f64> = z.iter().map(|v| 1.12 * v).collect();
        let opts = OeOptions {
            mode_degree: 1,
            flux_iterations: 3,
            exact_profile: true,
            mode_gauss_newton: true,
            mode_iterations: 3,
            mode_starts: vec![1.0, 1.3],
            ..OeOptions::new(0)
        };
        let (mut zs, mut b) = (start.clone(), bs.clone());
        let fit = fit_modes(&om, &d, &mut zs, &mut b, &opts, &mut crate::observer::Silent).expect("mode fit");
        assert_eq!(fit.starts.len(), 2);
        let lowest = fit.starts.iter().min_by(|a, c| a.loss_k2.total_cmp(&c.loss_k2)).expect("two starts");
        assert_eq!((fit.loss_k2, fit.size_factor), (lowest.loss_k2, lowest.size_factor));
        assert!(fit.starts.iter().any(|s| s.loss_k2 > fit.loss_k2), "the starts ended alike: {:?}", fit.starts);
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        assert!((mean(&zs) / mean(&start) - fit.size_factor).abs() < 1e-12);
        let bad = OeOptions { mode_starts: vec![1.0, 0.0], ..opts };
        let err = fit_modes(&om, &d, &mut start.clone(), &mut bs.clone(), &bad, &mut crate::observer::Silent);
        assert!(matches!(err, Err(ReconError::Input(m)) if m.contains("mode_starts")));
    }
}
