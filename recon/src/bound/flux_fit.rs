//! Fits at a fixed shape: the fluxes of every video, and optionally the global physics
//! `λ = (h + R)/C` (1/s) and `c = 1/C` (m^2 K/J) with them.
//!
//! **Preconditioning.** A flux pattern of decay rate kappa (an eigenvalue of
//! `K = λ I + α M^-1 L`, 1/s) raises the temperature by about
//! `b min(t, 1/κ)`: conduction damps the fine patterns, and the loss's Hessian in b spans
//! `(1 + κ T)^2` (T the fitted duration; ~10^3 for a pixel-scale pattern at level 1), too
//! ill-conditioned for a few iterations. The fit runs in `u = S^-1 b` with
//! `S = I + τ K`, `τ = T/sqrt(3)`, which undoes that damping to first order; `S^-1`
//! is a solve with the step matrix's structure, `(1 + τλ) M + τα L`, times M.
//!
//! **Globals.** Stage 1 estimates lambda and c from the equation error, whose noise they
//! inherit; with the true values the output-error fit's size drift is smaller
//! (docs/notes/reconstruction-stage2.md, "What drives the size drift"). With [`fit_flux_and_globals`] they join the same L-BFGS as
//! `λ = λ_0 e^(q_λ/κ_λ)`, `c = c_0 + q_c/κ_c`, the fluxes
//! scaled along with lambda, `b = (λ/λ_0) S u`: a change of lambda then changes the
//! rise's time constant and not its steady level `b/λ`, which the fluxes would otherwise
//! have to undo. The gradients are the adjoint sums of [`loss`],
//! `∂ J/∂ q_λ = (λ ∂ J/∂λ +
//! Σ_v b_v · ∂ J/∂ b_v)/κ_λ`. The scales `κ` give the two
//! the loss's curvature along the fluxes' own direction, measured by second differences at
//! the start, so that one L-BFGS step length suits all unknowns. c stays in `[0, λ/R]`,
//! `R = 4εσ T_a^3`: a non-negative convection coefficient `h = λ/c - R`.
//! Radiation beyond Eq. 5 is c's only effect, small at a few kelvin: where the loss's
//! curvature in c vanishes, c stays.

use super::output_error::{loss, minimise_fallible, OeData, OeGrad, OeMesh, StepMatrix};
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

/// L-BFGS's first step in the fluxes (K/s): the largest unknown moves by 5 % of the mean
/// absolute flux of `b`.
pub(crate) fn flux_learning_rate(b: &[Vec<f64>]) -> f64 {
    let count = b.iter().map(|v| v.len()).sum::<usize>().max(1);
    (0.05 * b.iter().flatten().map(|v| v.abs()).sum::<f64>() / count as f64).max(0.05 * 1e-12)
}

/// Second difference of `f` at 0 with step `h`, per unit squared.
pub(crate) fn curvature(
    f: &mut impl FnMut(f64) -> Result<f64, ReconError>,
    f0: f64,
    h: f64,
) -> Result<f64, ReconError> {
    Ok((f(h)? - 2.0 * f0 + f(-h)?) / (h * h))
}

/// The unknowns of the fits at a fixed shape, flattened for L-BFGS (module doc): per video the
/// preconditioned fluxes u, then (with the globals) `q_λ` and `q_c`.
pub(crate) struct FluxParams {
    n: usize,
    nvid: usize,
    tau: f64,
    alpha: f64,
    lap: CotanLaplacian,
    m: Vec<f64>,
    /// The step-structured matrix (1 + tau lambda) M + tau alpha L of S^-1.
    sm: StepMatrix,
    /// The globals at q = 0.
    g0: Globals,
    /// R = 4 eps sigma T_a^3, W/(m^2 K).
    r: f64,
    /// Scales of q_lambda and q_c (`None`: not fitted).
    kappa_l: Option<f64>,
    kappa_c: Option<f64>,
}

impl FluxParams {
    /// The parameterisation at depths `z` and `d`'s globals and the unknowns' start for fluxes
    /// `b`; `None` for a folded shape. With `globals`, the globals are unknowns too, their
    /// scales set by second differences (module doc).
    pub(crate) fn new(
        om: &OeMesh,
        d: &OeData,
        z: &[f64],
        b: &[Vec<f64>],
        globals: bool,
    ) -> Result<Option<(FluxParams, Vec<f64>)>, ReconError> {
        let n = om.mesh.len();
        let dt = d.dt()?;
        let tau = dt * (d.frames() - 1 - d.first) as f64 / 3f64.sqrt();
        let x = om.mesh.positions(z);
        let lap = CotanLaplacian::new(&x, &om.mesh.tris);
        let m = lumped_area(&x, &om.mesh.tris, AreaMass::Barycentric);
        let Some(sm) = StepMatrix::new(&om.pattern, &lap, &m, 1.0 + tau * d.lambda, tau * d.alpha) else {
            return Ok(None);
        };
        let r = 4.0 * d.emissivity * SIGMA * d.ambient.powi(3);
        let g0 = Globals::of(d);
        let mut fp =
            FluxParams { n, nvid: b.len(), tau, alpha: d.alpha, lap, m, sm, g0, r, kappa_l: None, kappa_c: None };
        let mut flat: Vec<f64> = Vec::with_capacity(fp.nvid * n + 2);
        for bv in b {
            let mut u: Vec<f64> = (0..n).map(|i| fp.m[i] * bv[i]).collect();
            fp.sm.solve(&mut u);
            flat.extend(u);
        }
        if !globals {
            return Ok(Some((fp, flat)));
        }
        let j0 = loss(om, d, z, b, OeGrad::default())?;
        let scaled = |s: f64| -> Vec<Vec<f64>> { b.iter().map(|v| v.iter().map(|x| x * s).collect()).collect() };
        let flux_norm2 = flat.iter().map(|v| v * v).sum::<f64>();
        let eps = 1e-3;
        let c_flux =
            curvature(&mut |e| loss(om, d, z, &scaled(1.0 + e), OeGrad::default()), j0, eps)? / flux_norm2.max(1e-300);
        let at_lambda = |e: f64| Globals { lambda: g0.lambda * e.exp(), ..g0 }.apply(d);
        let c_lambda = curvature(&mut |e| loss(om, &at_lambda(e), z, &scaled(e.exp()), OeGrad::default()), j0, eps)?;
        let hc = eps * g0.lambda / r;
        let at_c = |e: f64| Globals { c_inv: g0.c_inv + e, ..g0 }.apply(d);
        let c_c = curvature(&mut |e| loss(om, &at_c(e), z, b, OeGrad::default()), j0, hc)?;
        if !(c_flux > 0.0 && c_lambda > 0.0) {
            return Err(ReconError::Input(format!(
                "output-error globals fit: the loss is not convex at the start (curvatures {c_flux:e}, {c_lambda:e})"
            )));
        }
        fp.kappa_l = Some((c_lambda / c_flux).sqrt());
        // c fitted where its whole range moves the loss by more than 1e-9 of doubling the
        // fluxes.
        fp.kappa_c = (c_c * (g0.lambda / r).powi(2) > 1e-9 * c_flux * flux_norm2).then(|| (c_c / c_flux).sqrt());
        flat.extend([0.0, 0.0]);
        Ok(Some((fp, flat)))
    }

    /// -L v (`CotanLaplacian::apply`'s sign).
    fn lap_apply(&self, v: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.n];
        self.lap.apply(v, &mut out);
        out.iter_mut().for_each(|o| *o = -*o);
        out
    }

    /// The globals at the unknowns `f`, c clamped to [0, lambda / R].
    pub(crate) fn globals(&self, f: &[f64]) -> Globals {
        let nu = self.nvid * self.n;
        match self.kappa_l {
            None => self.g0,
            Some(kl) => {
                let lambda = self.g0.lambda * (f[nu] / kl).exp();
                let c_inv =
                    self.kappa_c.map_or(self.g0.c_inv, |kc| self.g0.c_inv + f[nu + 1] / kc).clamp(0.0, lambda / self.r);
                Globals { lambda, c_inv }
            }
        }
    }

    /// The fluxes b = (lambda / lambda_0) S u at the unknowns `f`, K/s.
    pub(crate) fn fluxes(&self, f: &[f64]) -> Vec<Vec<f64>> {
        let (n, tau, l0) = (self.n, self.tau, self.g0.lambda);
        let s = self.globals(f).lambda / l0;
        (0..self.nvid)
            .map(|v| {
                let u = &f[v * n..(v + 1) * n];
                let lu = self.lap_apply(u);
                (0..n).map(|i| s * (u[i] * (1.0 + tau * l0) + tau * self.alpha * lu[i] / self.m[i])).collect()
            })
            .collect()
    }

    /// The gradient in the unknowns `f` (into `g`) from [`loss`]'s gradients in the fluxes `gb`
    /// and the globals `gg` at `f`, whose fluxes ([`FluxParams::fluxes`]) are `bf`.
    pub(crate) fn gradient(&self, f: &[f64], bf: &[Vec<f64>], gb: &[Vec<f64>], gg: [f64; 2], g: &mut [f64]) {
        let (n, tau, l0) = (self.n, self.tau, self.g0.lambda);
        let gl = self.globals(f);
        let s = gl.lambda / l0;
        for (v, gv) in gb.iter().enumerate() {
            // dJ/du = s S^T dJ/db.
            let gm: Vec<f64> = (0..n).map(|i| gv[i] / self.m[i]).collect();
            let lg = self.lap_apply(&gm);
            for i in 0..n {
                g[v * n + i] = s * (gv[i] * (1.0 + tau * l0) + tau * self.alpha * lg[i]);
            }
        }
        if let Some(kl) = self.kappa_l {
            let nu = self.nvid * n;
            let flux_part: f64 = gb.iter().flatten().zip(bf.iter().flatten()).map(|(gi, bi)| gi * bi).sum();
            g[nu] = (gl.lambda * gg[0] + flux_part) / kl;
            // At a bound of c, a gradient pushing out of it is dropped (the step would be
            // clamped away and the line search fail).
            let at_bound = (gl.c_inv <= 0.0 && gg[1] > 0.0) || (gl.c_inv >= gl.lambda / self.r && gg[1] < 0.0);
            g[nu + 1] = self.kappa_c.filter(|_| !at_bound).map_or(0.0, |kc| gg[1] / kc);
        }
    }

    /// Keeps c's unknown inside its bounds, so the optimiser sees where c is.
    pub(crate) fn project(&self, f: &mut [f64]) {
        if let (Some(kl), Some(kc)) = (self.kappa_l, self.kappa_c) {
            let nu = self.nvid * self.n;
            let lambda = self.g0.lambda * (f[nu] / kl).exp();
            f[nu + 1] = ((self.g0.c_inv + f[nu + 1] / kc).clamp(0.0, lambda / self.r) - self.g0.c_inv) * kc;
        }
    }

    /// Whether the globals are unknowns.
    pub(crate) fn fits_globals(&self) -> bool {
        self.kappa_l.is_some()
    }
}

fn fit(
    om: &OeMesh,
    d: &OeData,
    z: &[f64],
    b: &mut [Vec<f64>],
    iterations: usize,
    globals: bool,
) -> Result<(Globals, f64), ReconError> {
    use crate::stage2::optimize::{LargeSteps, OptimOptions, Optimizer};
    let nvid = b.len();
    let n = om.mesh.len();
    let Some((fp, mut flat)) = FluxParams::new(om, d, z, b, globals)? else {
        return Ok((Globals::of(d), f64::INFINITY)); // a folded shape
    };
    let ident = LargeSteps::new(flat.len(), &[], 0.0)?;
    let opts = OptimOptions {
        optimizer: Optimizer::Lbfgs,
        iterations,
        learning_rate: flux_learning_rate(b),
        large_steps_lambda: 0.0,
        min_depth: f64::NEG_INFINITY,
        blocks: Vec::new(),
    };
    minimise_fallible(
        &mut flat,
        &ident,
        &opts,
        |f, g| {
            let gl = fp.globals(f);
            let mut gb = vec![vec![0.0; n]; nvid];
            let mut gg = [0.0; 2];
            let grad = OeGrad { b: Some(&mut gb), globals: fp.fits_globals().then_some(&mut gg), ..Default::default() };
            let bf = fp.fluxes(f);
            let j = loss(om, &gl.apply(d), z, &bf, grad)?;
            fp.gradient(f, &bf, &gb, gg, g);
            Ok(j)
        },
        |f| fp.project(f),
    )?;
    let gl = fp.globals(&flat);
    for (o, v) in b.iter_mut().zip(fp.fluxes(&flat)) {
        *o = v;
    }
    Ok((gl, loss(om, &gl.apply(d), z, b, OeGrad::default())?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bound::output_error::predict;
    use crate::bound::output_error::tests::{lambda_problem, physics, problem, LAMBDA_TRUE};

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

    /// Model data from known globals: the fit of fluxes and globals from lambda 15 % and c
    /// 40 % off, fluxes flat, recovers both. (lambda T ~ 1 over the 5.5 s: the rise's curvature in time is what
    /// tells lambda from the fluxes.)
    #[test]
    fn globals_fit_recovers_lambda_of_model_data() {
        let (mesh, z, mut bs, series, times) = lambda_problem(1);
        let om = OeMesh::new(&mesh).expect("pattern");
        let truth = OeData { substeps: 1, lambda: LAMBDA_TRUE, ..physics(&series, &times) };
        let d = Globals { lambda: truth.lambda * 1.15, c_inv: truth.c_inv * 0.6 }.apply(&truth);
        let (g, j) = fit_flux_and_globals(&om, &d, &z, &mut bs, 80).expect("globals fit");
        let rel = g.lambda / truth.lambda - 1.0;
        assert!(rel.abs() < 2e-3, "lambda {:e} vs {:e} ({rel:+e}), loss {j:e}", g.lambda, truth.lambda);
        let rel_c = g.c_inv / truth.c_inv - 1.0;
        assert!(rel_c.abs() < 1e-2, "c {:e} vs {:e} ({rel_c:+e}), loss {j:e}", g.c_inv, truth.c_inv);
    }
}
