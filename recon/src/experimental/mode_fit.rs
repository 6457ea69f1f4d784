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
//! Why: along a fixed form the output-error size moves by more than 10 % for any millimetre
//! error of that form, and per-vertex forms fitted at 50 mK carry fitted noise
//! (docs/notes/reconstruction-stage2.md, "The output-error size at the full tier's level 1").
//! With a handful of modes the fit cannot follow the noise, and the size is fitted with the
//! form and lambda, as in the bound. Measured, it does not find the form yet (notes, "The
//! ball's output-error size was lambda").

use std::cell::RefCell;

use crate::bound::output_error::{loss, minimise_fallible, OeData, OeGrad, OeMesh};
use crate::bound::shape::default_modes;
use crate::error::ReconError;
use crate::experimental::output_error::{profile_fluxes, OeOptions};
use crate::stage2::optimize::{LargeSteps, OptimOptions, Optimizer};

/// Depth change of a monomial mode per unit coefficient, m (so that every coefficient of the
/// fit is of order one where the form is centimetres off).
const MONOMIAL_SCALE_M: f64 = 0.01;

/// The result of [`fit_modes`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ModeFit {
    /// The modes' names, as in the bound ("size", "relief", "u^p v^q").
    pub modes: Vec<String>,
    /// Their fitted coefficients (size and relief: factors less one; monomials: cm).
    pub coefficients: Vec<f64>,
    /// The fitted lambda, 1/s.
    pub lambda: f64,
    /// The loss at the start, K^2.
    pub loss_start_k2: f64,
    /// The loss at the end, K^2.
    pub loss_k2: f64,
    /// Loss evaluations (each one flux fit).
    pub evaluations: usize,
}

/// Fits lambda and the coefficients of the modes of degree [`OeOptions::mode_degree`] at the
/// depths `z` (module doc) by [`OeOptions::mode_iterations`] of L-BFGS, each evaluation the
/// fluxes' fit ([`profile_fluxes`]) from the lowest point's fluxes so far; `z` and `b` get
/// the lowest point evaluated. `d`'s lambda is the start.
///
/// # Errors
/// As [`loss`].
pub fn fit_modes(
    om: &OeMesh,
    d: &OeData,
    z: &mut [f64],
    b: &mut [Vec<f64>],
    opts: &OeOptions,
) -> Result<ModeFit, ReconError> {
    let z0 = z.to_vec();
    let mut modes = default_modes(om, &z0, opts.mode_degree);
    for m in modes.iter_mut().skip(2) {
        m.dz.iter_mut().for_each(|v| *v *= MONOMIAL_SCALE_M);
    }
    let depths = |x: &[f64]| -> Vec<f64> {
        let mut zz = z0.clone();
        for (m, &beta) in modes.iter().zip(&x[1..]) {
            zz.iter_mut().zip(&m.dz).for_each(|(o, v)| *o += beta * v);
        }
        zz
    };
    // The lowest point so far: (loss, coefficients, fluxes). Every evaluation starts its flux
    // fit from its fluxes, so that a wild line-search trial does not spoil the next start.
    let best = RefCell::new((f64::INFINITY, Vec::new(), b.to_vec()));
    let evaluations = RefCell::new(0usize);
    let objective = |x: &[f64], g: &mut [f64]| -> Result<f64, ReconError> {
        let dl = OeData { lambda: d.lambda * x[0].exp(), ..d.clone() };
        let zz = depths(x);
        let mut bx = best.borrow().2.clone();
        profile_fluxes(om, &dl, &zz, &mut bx, opts)?;
        let (mut gz, mut gg) = (vec![0.0; zz.len()], [0.0; 2]);
        let j = loss(om, &dl, &zz, &bx, OeGrad { z: Some(&mut gz), b: None, globals: Some(&mut gg) })?;
        g[0] = gg[0] * dl.lambda;
        for (gk, m) in g[1..].iter_mut().zip(&modes) {
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
    let loss_start_k2 = objective(&x, &mut g0)?;
    let lbfgs = OptimOptions {
        optimizer: Optimizer::Lbfgs,
        iterations: opts.mode_iterations,
        learning_rate: 0.02,
        large_steps_lambda: 0.0,
        min_depth: f64::NEG_INFINITY,
        blocks: (1..n).collect(),
    };
    let identity = LargeSteps::new(n, &[], 0.0)?;
    minimise_fallible(&mut x, &identity, &lbfgs, objective, |_| {})?;
    let (loss_k2, x, fitted) = best.into_inner();
    z.copy_from_slice(&depths(&x));
    b.iter_mut().zip(fitted).for_each(|(o, v)| *o = v);
    Ok(ModeFit {
        modes: modes.iter().map(|m| m.name.clone()).collect(),
        coefficients: x[1..].to_vec(),
        lambda: d.lambda * x[0].exp(),
        loss_start_k2,
        loss_k2,
        evaluations: evaluations.into_inner(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bound::output_error::tests::{lambda_problem, physics, LAMBDA_TRUE};

    /// Model data; the start 12 % too far, with a relief 30 % too small and a tilt, lambda 12 %
    /// off: the fit of degree 1 recovers the depths and lambda.
    #[test]
    fn mode_fit_recovers_size_relief_tilt_and_lambda() {
        let (mesh, z, mut bs, series, times) = lambda_problem(2);
        let om = OeMesh::new(&mesh).expect("pattern");
        let d = OeData { lambda: LAMBDA_TRUE * 1.12, ..physics(&series, &times) };
        let zm = z.iter().sum::<f64>() / z.len() as f64;
        let mut zs: Vec<f64> =
            z.iter().zip(&mesh.dirs).map(|(v, dir)| 1.12 * (zm + 0.7 * (v - zm)) + 0.002 * dir[0] / 0.05).collect();
        let opts = OeOptions { mode_degree: 1, flux_iterations: 60, mode_iterations: 40, ..OeOptions::new(0) };
        let fit = fit_modes(&om, &d, &mut zs, &mut bs, &opts).expect("mode fit");
        let err = zs.iter().zip(&z).map(|(a, t)| (a - t).abs()).fold(0.0f64, f64::max);
        let rel = fit.lambda / LAMBDA_TRUE - 1.0;
        assert!(fit.loss_k2 < 1e-3 * fit.loss_start_k2, "loss {:e} -> {:e}", fit.loss_start_k2, fit.loss_k2);
        assert!(err < 2e-4 && rel.abs() < 0.01, "largest depth error {err:e} m, lambda {rel:+e}: {fit:?}");
    }
}
