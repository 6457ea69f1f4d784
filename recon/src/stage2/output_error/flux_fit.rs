//! Fits at a fixed shape: the fluxes of every video, and optionally the global physics
//! $\lambda = (h + R)/C$ (1/s) and $c = 1/C$ (m^2 K/J) with them.
//!
//! **Preconditioning.** A flux pattern of decay rate kappa (an eigenvalue of
//! $K = \lambda I + \alpha M^{-1} L$, 1/s) raises the temperature by about
//! $b\,\min(t, 1/\kappa)$: conduction damps the fine patterns, and the loss's Hessian in b spans
//! $(1 + \kappa T)^2$ (T the fitted duration; ~10^3 for a pixel-scale pattern at level 1), too
//! ill-conditioned for a few iterations. The fit runs in $u = S^{-1} b$ with
//! $S = I + \tau K$, $\tau = T/\sqrt{3}$, which undoes that damping to first order; $S^{-1}$
//! is a solve with the step matrix's structure, $(1 + \tau\lambda) M + \tau\alpha L$, times M.
//!
//! **Globals.** Stage 1 estimates lambda and c from the equation error, whose noise they
//! inherit; with the true values the output-error fit's size drift is smaller (README, "What
//! drives the size drift"). With [`fit_flux_and_globals`] they join the same L-BFGS as
//! $\lambda = \lambda_0 e^{q_\lambda/\kappa_\lambda}$, $c = c_0 + q_c/\kappa_c$, the fluxes
//! scaled along with lambda, $b = (\lambda/\lambda_0) S u$: a change of lambda then changes the
//! rise's time constant and not its steady level $b/\lambda$, which the fluxes would otherwise
//! have to undo. The gradients are the adjoint sums of [`loss`],
//! $\partial J/\partial q_\lambda = (\lambda\,\partial J/\partial\lambda +
//! \sum_v b_v \cdot \partial J/\partial b_v)/\kappa_\lambda$. The scales $\kappa$ give the two
//! the loss's curvature along the fluxes' own direction, measured by second differences at
//! the start, so that one L-BFGS step length suits all unknowns. c stays in $[0, \lambda/R]$,
//! $R = 4\varepsilon\sigma T_a^3$: a non-negative convection coefficient $h = \lambda/c - R$.
//! Radiation beyond Eq. 5 is c's only effect, small at a few kelvin: where the loss's
//! curvature in c vanishes, c stays.

use super::{loss, minimise_fallible, OeData, OeGrad, OeMesh, StepMatrix};
use crate::error::ReconError;
use crate::stage1::SIGMA;
use heatsim::surface::operators::{lumped_area, AreaMass, CotanLaplacian};

/// lambda and c of [`OeData`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Globals {
    /// lambda = (h + R)/C, 1/s.
    pub lambda: f64,
    /// c = 1/C, m^2 K/J.
    pub c_inv: f64,
}

impl Globals {
    /// The globals of `d`.
    pub fn of(d: &OeData) -> Globals {
        Globals { lambda: d.lambda, c_inv: d.c_inv }
    }

    /// `d` with these globals.
    pub fn apply<'a>(self, d: &OeData<'a>) -> OeData<'a> {
        OeData { lambda: self.lambda, c_inv: self.c_inv, ..*d }
    }
}

/// Minimises [`loss`] over the fluxes at fixed depths `z`, from `b` (updated in place), by
/// L-BFGS (`iterations`, preconditioned: module doc); returns the loss.
///
/// # Errors
/// As [`loss`].
pub fn fit_flux(om: &OeMesh, d: &OeData, z: &[f64], b: &mut [Vec<f64>], iterations: usize) -> Result<f64, ReconError> {
    fit(om, d, z, b, iterations, false).map(|(_, j)| j)
}

/// As [`fit_flux`], with lambda and c fitted alongside from `d`'s values (module doc,
/// "Globals"); returns them and the loss.
///
/// # Errors
/// As [`loss`].
pub fn fit_flux_and_globals(
    om: &OeMesh,
    d: &OeData,
    z: &[f64],
    b: &mut [Vec<f64>],
    iterations: usize,
) -> Result<(Globals, f64), ReconError> {
    fit(om, d, z, b, iterations, true)
}

/// Second difference of `f` at 0 with step `h`, per unit squared.
fn curvature(f: &mut impl FnMut(f64) -> Result<f64, ReconError>, f0: f64, h: f64) -> Result<f64, ReconError> {
    Ok((f(h)? - 2.0 * f0 + f(-h)?) / (h * h))
}

fn fit(
    om: &OeMesh,
    d: &OeData,
    z: &[f64],
    b: &mut [Vec<f64>],
    iterations: usize,
    globals: bool,
) -> Result<(Globals, f64), ReconError> {
    use super::super::optimize::{LargeSteps, OptimOptions, Optimizer};
    let n = om.mesh.len();
    let nvid = b.len();
    let dt = d.dt()?;
    let g0 = Globals::of(d);
    let tau = dt * (d.frames() - 1 - d.first) as f64 / 3f64.sqrt();
    let x = om.mesh.positions(z);
    let lap = CotanLaplacian::new(&x, &om.mesh.tris);
    let m = lumped_area(&x, &om.mesh.tris, AreaMass::Barycentric);
    let Some(sm) = StepMatrix::new(&om.pattern, &lap, &m, 1.0 + tau * d.lambda, tau * d.alpha) else {
        return Ok((g0, f64::INFINITY)); // a folded shape
    };
    // b = S u = u + tau (lambda u + alpha M^-1 L u); dJ/du = S^T dJ/db. (`CotanLaplacian::apply`
    // gives -L v in this module's sign.)
    let lap_apply = |v: &[f64]| -> Vec<f64> {
        let mut out = vec![0.0; n];
        lap.apply(v, &mut out);
        out.iter_mut().for_each(|o| *o = -*o);
        out
    };
    let s_apply = |u: &[f64]| -> Vec<f64> {
        let lu = lap_apply(u);
        (0..n).map(|i| u[i] * (1.0 + tau * d.lambda) + tau * d.alpha * lu[i] / m[i]).collect()
    };
    let st_apply = |g: &[f64]| -> Vec<f64> {
        let gm: Vec<f64> = (0..n).map(|i| g[i] / m[i]).collect();
        let lg = lap_apply(&gm);
        (0..n).map(|i| g[i] * (1.0 + tau * d.lambda) + tau * d.alpha * lg[i]).collect()
    };
    let mut flat: Vec<f64> = Vec::with_capacity(nvid * n + 2);
    for bv in b.iter() {
        let mut u: Vec<f64> = (0..n).map(|i| m[i] * bv[i]).collect();
        sm.solve(&mut u);
        flat.extend(u);
    }
    let nu = flat.len();
    let r = 4.0 * d.emissivity * SIGMA * d.ambient.powi(3);
    // Scales of the globals' unknowns (module doc); kappa_c = None: c stays.
    let (kappa_l, kappa_c) = if globals {
        let j0 = loss(om, d, z, b, OeGrad::default())?;
        let scaled = |s: f64| -> Vec<Vec<f64>> { b.iter().map(|v| v.iter().map(|x| x * s).collect()).collect() };
        let flux_norm2 = flat.iter().map(|v| v * v).sum::<f64>();
        let eps = 1e-3;
        let c_flux =
            curvature(&mut |e| loss(om, d, z, &scaled(1.0 + e), OeGrad::default()), j0, eps)? / flux_norm2.max(1e-300);
        let c_lambda = curvature(
            &mut |e| loss(om, &Globals { lambda: g0.lambda * e.exp(), ..g0 }.apply(d), z, &scaled(e.exp()), OeGrad::default()),
            j0,
            eps,
        )?;
        let hc = eps * g0.lambda / r;
        let c_c = curvature(&mut |e| loss(om, &Globals { c_inv: g0.c_inv + e, ..g0 }.apply(d), z, b, OeGrad::default()), j0, hc)?;
        if !(c_flux > 0.0 && c_lambda > 0.0) {
            return Err(ReconError::Input(format!(
                "output-error globals fit: the loss is not convex at the start (curvatures {c_flux:e}, {c_lambda:e})"
            )));
        }
        // c fitted where its whole range moves the loss by more than 1e-9 of doubling the fluxes.
        let kappa_c = (c_c * (g0.lambda / r).powi(2) > 1e-9 * c_flux * flux_norm2).then(|| (c_c / c_flux).sqrt());
        flat.extend([0.0, 0.0]);
        (Some((c_lambda / c_flux).sqrt()), kappa_c)
    } else {
        (None, None)
    };
    // The globals at the unknowns' values, c clamped to [0, lambda / R].
    let globals_at = |f: &[f64]| -> Globals {
        match kappa_l {
            None => g0,
            Some(kl) => {
                let lambda = g0.lambda * (f[nu] / kl).exp();
                let c_inv = kappa_c.map_or(g0.c_inv, |kc| g0.c_inv + f[nu + 1] / kc).clamp(0.0, lambda / r);
                Globals { lambda, c_inv }
            }
        }
    };
    let fluxes = |f: &[f64]| -> Vec<Vec<f64>> {
        let s = globals_at(f).lambda / g0.lambda;
        (0..nvid).map(|v| s_apply(&f[v * n..(v + 1) * n]).into_iter().map(|x| x * s).collect()).collect()
    };
    let mean_b = b.iter().flatten().map(|v| v.abs()).sum::<f64>() / (nvid * n).max(1) as f64;
    let ident = LargeSteps::new(flat.len(), &[], 0.0)?;
    let opts = OptimOptions {
        optimizer: Optimizer::Lbfgs,
        iterations,
        learning_rate: 0.05 * mean_b.max(1e-12),
        large_steps_lambda: 0.0,
        min_depth: f64::NEG_INFINITY,
    };
    minimise_fallible(
        &mut flat,
        &ident,
        &opts,
        |f, g| {
            let gl = globals_at(f);
            let bf = fluxes(f);
            let mut gb = vec![vec![0.0; n]; nvid];
            let mut gg = [0.0; 2];
            let grad = OeGrad { b: Some(&mut gb), globals: kappa_l.map(|_| &mut gg), ..Default::default() };
            let j = loss(om, &gl.apply(d), z, &bf, grad)?;
            let s = gl.lambda / g0.lambda;
            for (v, gv) in gb.iter().enumerate() {
                let gu = st_apply(gv);
                g[v * n..(v + 1) * n].iter_mut().zip(gu).for_each(|(o, x)| *o = x * s);
            }
            if let Some(kl) = kappa_l {
                let flux_part: f64 = gb.iter().flatten().zip(bf.iter().flatten()).map(|(gi, bi)| gi * bi).sum();
                g[nu] = (gl.lambda * gg[0] + flux_part) / kl;
                // At a bound of c, a gradient pushing out of it is dropped (the step would be
                // clamped away and the line search fail).
                let at_bound = (gl.c_inv <= 0.0 && gg[1] > 0.0) || (gl.c_inv >= gl.lambda / r && gg[1] < 0.0);
                g[nu + 1] = kappa_c.filter(|_| !at_bound).map_or(0.0, |kc| gg[1] / kc);
            }
            Ok(j)
        },
        |f| {
            // Keep c's unknown inside its bounds, so the optimiser sees where c is.
            if let (Some(kl), Some(kc)) = (kappa_l, kappa_c) {
                let lambda = g0.lambda * (f[nu] / kl).exp();
                f[nu + 1] = ((g0.c_inv + f[nu + 1] / kc).clamp(0.0, lambda / r) - g0.c_inv) * kc;
            }
        },
    )?;
    let gl = globals_at(&flat);
    for (o, v) in b.iter_mut().zip(fluxes(&flat)) {
        *o = v;
    }
    Ok((gl, loss(om, &gl.apply(d), z, b, OeGrad::default())?))
}

#[cfg(test)]
mod tests {
    use super::super::tests::{physics, problem};
    use super::super::predict;
    use super::*;

    #[test]
    fn flux_fit_recovers_the_fluxes_of_model_data() {
        let (mesh, z, b, _, times) = problem();
        let om = OeMesh::new(&mesh).expect("pattern");
        let mut d = OeData { substeps: 1, ..physics(&[], &times) };
        let series = predict(&om, &d, &z, &b).expect("prediction");
        d.series = &series;
        let n = mesh.len();
        let mean_b = b.iter().flatten().sum::<f64>() / (2 * n) as f64;
        let mut bs = vec![vec![mean_b; n]; 2];
        fit_flux(&om, &d, &z, &mut bs, 40).expect("flux fit");
        let err = b.iter().flatten().zip(bs.iter().flatten()).fold(0.0f64, |a, (t, e)| a.max((t - e).abs()));
        assert!(err < 1e-4 * mean_b, "largest flux error {err:e} of mean {mean_b:e}");
    }

    /// Model data from known globals: the joint fit from lambda 15 % and c 40 % off, fluxes
    /// flat, recovers both. (lambda T ~ 1 over the 5.5 s: the rise's curvature in time is what
    /// tells lambda from the fluxes.)
    #[test]
    fn globals_fit_recovers_lambda_of_model_data() {
        let (mesh, z, b, _, times) = problem();
        let om = OeMesh::new(&mesh).expect("pattern");
        let truth = OeData { substeps: 1, lambda: 0.2, ..physics(&[], &times) };
        let series = predict(&om, &truth, &z, &b).expect("prediction");
        let start = Globals { lambda: truth.lambda * 1.15, c_inv: truth.c_inv * 0.6 };
        let d = start.apply(&OeData { series: &series, ..truth });
        let mean_b = b.iter().flatten().sum::<f64>() / (2 * mesh.len()) as f64;
        let mut bs = vec![vec![mean_b; mesh.len()]; 2];
        let (g, j) = fit_flux_and_globals(&om, &d, &z, &mut bs, 80).expect("globals fit");
        let rel = g.lambda / truth.lambda - 1.0;
        assert!(rel.abs() < 2e-3, "lambda {:e} vs {:e} ({rel:+e}), loss {j:e}", g.lambda, truth.lambda);
        let rel_c = g.c_inv / truth.c_inv - 1.0;
        assert!(rel_c.abs() < 1e-2, "c {:e} vs {:e} ({rel_c:+e}), loss {j:e}", g.c_inv, truth.c_inv);
    }
}
