//! Joint fit (experimental): depths, fluxes and, optionally, lambda and c in one L-BFGS, in
//! place of [`super::refine`]'s alternation of a shape fit at fixed fluxes and a flux fit at
//! fixed depths, which moves slowly along the directions where shape and fluxes trade off
//! (the size above all).
//!
//! Unknowns: the depths in large-steps coordinates `u_z = (I + λ_ls L_u) z`, scaled
//! by `κ_z`; the fluxes and globals as [`crate::bound::flux_fit`] parameterises them. `κ_z`
//! makes L-BFGS's first step (the largest unknown moved by the flux fits' learning rate, K/s)
//! the shape fits' first step in the depths (their learning rate, m); after it, L-BFGS scales
//! the depths' block and the rest each by their own curvature pair
//! ([`crate::stage2::optimize::OptimOptions::blocks`]; with one scale for all the depths barely
//! moved). The objective is `shape_loss`: the output-error loss plus the shape fits' normal
//! consistency. [`OeOptions::hold_mean_depth`] does not apply.

use super::output_error::{shape_loss, OeOptions};
use crate::bound::flux_fit::{flux_learning_rate, FluxParams, Globals};
use crate::bound::output_error::{minimise_fallible, OeData, OeGrad, OeMesh};
use crate::error::ReconError;
use crate::stage2::energy::Regularisers;
use crate::stage2::optimize::{LargeSteps, OptimOptions, Optimizer};

/// Minimises `shape_loss` (normal consistency weighted as in [`super::refine`]) over
/// the depths `z` (m), the fluxes `b` (K/s) and, with [`OeOptions::globals`], lambda and c from
/// `d`'s, by [`OeOptions::shape_iterations`] of L-BFGS (module doc), the depths in the
/// coordinates of `steps` and their first step `lr_shape` (m); `z` and `b` are updated in
/// place. Returns the globals and the output-error loss (without the regulariser), K^2.
///
/// # Errors
/// As [`crate::bound::output_error::loss`]; a folded start.
pub fn fit_joint(
    om: &OeMesh,
    d: &OeData,
    opts: &OeOptions,
    lr_shape: f64,
    steps: &LargeSteps,
    z: &mut [f64],
    b: &mut [Vec<f64>],
) -> Result<(Globals, f64), ReconError> {
    let (n, nvid) = (om.mesh.len(), b.len());
    let (iterations, globals) = (opts.shape_iterations, opts.globals);
    let reg = &Regularisers::normal_only(opts.normal_consistency * d.noise_var);
    let Some((fp, fstart)) = FluxParams::new(om, d, z, b, globals)? else {
        return Err(ReconError::Input("output-error joint fit: the start is folded".into()));
    };
    // The depths' scale: the first L-BFGS step moves the largest unknown by the fluxes'
    // learning rate, which in the depths' block is to be the shape fits' (`lr_shape`, m).
    let lr = flux_learning_rate(b);
    let kappa_z = lr / lr_shape;
    let uz0 = steps.apply(z);
    let mut x: Vec<f64> = uz0.iter().map(|u| kappa_z * u).chain(fstart.iter().copied()).collect();
    let depths = |x: &[f64]| -> Vec<f64> {
        let mut zz: Vec<f64> = x[..n].iter().map(|v| v / kappa_z).collect();
        steps.solve(&mut zz);
        zz
    };
    let opts = OptimOptions {
        optimizer: Optimizer::Lbfgs,
        iterations,
        learning_rate: lr,
        large_steps_lambda: 0.0,
        min_depth: f64::NEG_INFINITY,
        blocks: vec![n],
    };
    let ident = LargeSteps::new(x.len(), &[], 0.0)?;
    minimise_fallible(
        &mut x,
        &ident,
        &opts,
        |x, g| {
            let zz = depths(x);
            let f = &x[n..];
            let (mut gz, mut gb, mut gg) = (vec![0.0; n], vec![vec![0.0; n]; nvid], [0.0; 2]);
            let bf = fp.fluxes(f);
            let grad = OeGrad { z: Some(&mut gz), b: Some(&mut gb), globals: globals.then_some(&mut gg) };
            let j = shape_loss(om, &fp.globals(f).apply(d), reg, &zz, &bf, grad)?;
            steps.solve(&mut gz);
            g[..n].iter_mut().zip(&gz).for_each(|(o, v)| *o = v / kappa_z);
            fp.gradient(f, &bf, &gb, gg, &mut g[n..]);
            Ok(j)
        },
        |x| fp.project(&mut x[n..]),
    )?;
    z.copy_from_slice(&depths(&x));
    let gl = fp.globals(&x[n..]);
    for (o, v) in b.iter_mut().zip(fp.fluxes(&x[n..])) {
        *o = v;
    }
    Ok((gl, crate::bound::output_error::loss(om, &gl.apply(d), z, b, OeGrad::default())?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bound::output_error::loss;
    use crate::bound::output_error::tests::{lambda_problem, physics, LAMBDA_TRUE};

    /// Model data, noise-free: from depths 10 % too far with flat fluxes and lambda 15 % off,
    /// the joint fit lowers the loss by orders of magnitude and recovers the size.
    #[test]
    fn joint_fit_recovers_size_and_lambda_of_model_data() {
        let (mesh, z, mut bs, series, times) = lambda_problem(2);
        let om = OeMesh::new(&mesh).expect("pattern");
        let d = OeData { lambda: LAMBDA_TRUE * 1.15, ..physics(&series, &times) };
        let mut zs: Vec<f64> = z.iter().map(|v| v * 1.1).collect();
        let j_start = loss(&om, &d, &zs, &bs, OeGrad::default()).expect("loss");
        let steps = LargeSteps::new(mesh.len(), &mesh.edges, 10.0).expect("large steps");
        let opts = OeOptions { shape_iterations: 400, globals: true, ..OeOptions::new(1) };
        let (g, j) = fit_joint(&om, &d, &opts, 1e-3, &steps, &mut zs, &mut bs).expect("joint fit");
        let s = zs.iter().sum::<f64>() / z.iter().sum::<f64>();
        let rel = g.lambda / LAMBDA_TRUE - 1.0;
        assert!(j < 1e-4 * j_start, "loss {j_start:e} -> {j:e}");
        assert!((s - 1.0).abs() < 0.02 && rel.abs() < 0.01, "size factor {s}, lambda {rel:+e} (loss {j:e})");
    }
}
