//! Cramér–Rao bound on the shape from the heat videos: how well any unbiased estimator can
//! determine a few shape modes from the videos of [`super::output_error::loss`]'s model, whatever its method.
//!
//! The videos are `y = θ(z, b, g) + o + ε`: the surface heat equation's rise
//! ([`super::output_error::predict`]) at depths `z` (m), per-video fluxes `b` (K/s) and globals
//! `g = (λ, c)`, a constant offset `o` per video and vertex when [`super::output_error::OeData::offsets`]
//! (the fixed pattern), and white noise of variance `σ^2` (K^2). The depths are restricted
//! to `z = z_0 + Σ_j β_j v_j` for the modes `v_j` ([`ShapeMode`], m per unit
//! coefficient). The Fisher information in `β` with the nuisances unknown is
//! `F = σ^-2 (P^(⊥) J_β)^T W (P^(⊥) J_β),`
//! `J_β` the videos' derivative in the coefficients, `W` the loss's vertex weights, and
//! `P^(⊥)` the `W`-orthogonal projection away from every direction the nuisances can move the
//! videos in. Any unbiased estimate has covariance at least `F^-1`.
//!
//! **Columns.** `J_β` and the globals' columns are central differences of
//! [`super::output_error::predict`] (relative step 1e-6). The fluxes' directions are applied exactly: the
//! tangent of the time stepping, `δθ^(j+1) = A^-1 M((1 - h c N'(θ^j))
//! δθ^j + h δ b)`, and its transpose, the adjoint recursion of
//! [`super::output_error::loss`].
//!
//! **Projection.** Offsets are profiled exactly (each vertex's mean over the fitted frames is
//! removed). The fluxes, one per vertex and video, are projected out per video by CGLS on
//! `min_b ‖y - C J_b b‖` (`C` the offsets' centring), preconditioned by the flux fit's
//! `b = S u` ([`super::flux_fit`]): a flux pattern of decay rate `κ` raises the rise by
//! about `b min(t, 1/κ)`, which `S = I + τ K` undoes to first order. The residual of a
//! CGLS run that stopped early still contains flux directions, so it overstates `F`: the bound
//! is then optimistic (by a few per cent at 400 iterations: docs/notes/code-comments.md).
//!
//! **What it does not cover.** The model is taken as exact and the diffusivity known; the
//! modes restrict the shape to a few degrees of freedom, so the bound on the full shape is
//! looser still. A biased estimator (a regulariser) can beat it. As a lower bound it answers
//! one question: whether the videos can determine these modes to a given accuracy at all.
//!
//! Its values on the shape-error table's 50 mK datasets (`scripts/shape-bound.sh`,
//! `results/shape_bound/`) are in docs/notes/reconstruction-stage2.md, "How much the videos say
//! about the shape".

use super::output_error::{OeData, OeMesh, Stepping};
use super::rim;
use super::tie::Tie;
use crate::error::ReconError;
use faer::linalg::solvers::DenseSolveCore;
use faer::{Mat, Side};
use rayon::prelude::*;

/// A direction of the depths, m per unit coefficient, with its name.
#[derive(Clone, Debug)]
pub struct ShapeMode {
    /// Name in the report (e.g. "size").
    pub name: String,
    /// Per vertex, the change of depth per unit coefficient, m.
    pub dz: Vec<f64>,
}

/// Which nuisances a row of [`ShapeBound`] treats as unknown.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Nuisances {
    /// Per-vertex fluxes of every video unknown (the paper's setting); false: known (calibrated
    /// lamps and absorptivity, the most lamp knowledge can give).
    pub fluxes: bool,
    /// lambda and c unknown.
    pub globals: bool,
}

/// One row of [`ShapeBound`].
#[derive(Clone, Debug, serde::Serialize)]
pub struct BoundRow {
    /// The unknown nuisances.
    pub nuisances: Nuisances,
    /// Per mode, the standard deviation bound of its coefficient (unit of the coefficient).
    pub std: Vec<f64>,
    /// Per mode, the expected mean unsigned surface error (m) of that mode's error alone at
    /// its bound, after the best rigid motion ([`aligned_displacements`]).
    pub mode_mae_m: Vec<f64>,
    /// The expected mean unsigned surface error (m) of all modes' errors together (Gaussian
    /// at the bound's covariance), after the best rigid motion.
    pub joint_mae_m: f64,
}

/// The bound for every combination of known and unknown nuisances.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ShapeBound {
    /// The modes' names.
    pub modes: Vec<String>,
    /// Noise standard deviation used, K.
    pub sigma: f64,
    /// Rows: fluxes unknown / known x globals known / unknown.
    pub rows: Vec<BoundRow>,
    /// The largest relative gradient at which a flux projection stopped (CGLS); the bound's
    /// optimism is of this order.
    pub projection_residual: f64,
    /// CGLS iterations of the slowest projection.
    pub projection_iterations: usize,
}

/// Settings of the bound.
#[derive(Clone, Copy, Debug)]
pub struct BoundOptions {
    /// Degree of the polynomial modes of [`default_modes`] (for callers that use them).
    pub degree: usize,
    /// CGLS iterations at most per projection.
    pub max_iterations: usize,
    /// CGLS stops when the normal equations' residual falls below this fraction of the start's.
    pub tolerance: f64,
}

impl Default for BoundOptions {
    fn default() -> BoundOptions {
        BoundOptions { degree: 2, max_iterations: 400, tolerance: 1e-5 }
    }
}

/// The default modes at depths `z` (m) on `om`: "size" (all depths scaled: z), "relief"
/// (z - mean z, the truth scan's line), and the monomials u^p v^q of the normalised image
/// coordinates with 1 <= p + q <= `degree` (m each: a smooth deformation).
pub fn default_modes(om: &OeMesh, z: &[f64], degree: usize) -> Vec<ShapeMode> {
    let dirs = &om.mesh.dirs;
    let zm = z.iter().sum::<f64>() / z.len().max(1) as f64;
    let mut modes = vec![
        ShapeMode { name: "size".into(), dz: z.to_vec() },
        ShapeMode { name: "relief".into(), dz: z.iter().map(|v| v - zm).collect() },
    ];
    let range = |k: usize| {
        let (lo, hi) = dirs.iter().fold((f64::MAX, f64::MIN), |(a, b), d| (a.min(d[k]), b.max(d[k])));
        ((hi + lo) / 2.0, ((hi - lo) / 2.0).max(1e-12))
    };
    let ((cu, su), (cv, sv)) = (range(0), range(1));
    for total in 1..=degree {
        for p in (0..=total).rev() {
            let q = total - p;
            let dz =
                dirs.iter().map(|d| ((d[0] - cu) / su).powi(p as i32) * ((d[1] - cv) / sv).powi(q as i32)).collect();
            modes.push(ShapeMode { name: format!("u^{p} v^{q}"), dz });
        }
    }
    modes
}

/// The Cramér–Rao bound (module doc) on the coefficients of `modes` at depths `z` (m), fluxes
/// `b` (per video, K/s) and `d`'s globals, for white noise of standard deviation `sigma` (K).
///
/// # Errors
/// A folded shape, sizes that do not match, no mode, a singular information matrix (modes that
/// the videos cannot tell apart at all).
pub fn shape_bound(
    om: &OeMesh,
    d: &OeData,
    z: &[f64],
    b: &[Vec<f64>],
    sigma: f64,
    modes: &[ShapeMode],
    opts: BoundOptions,
) -> Result<ShapeBound, ReconError> {
    let n = om.mesh.len();
    if modes.is_empty() || modes.iter().any(|m| m.dz.len() != n) || z.len() != n {
        return Err(ReconError::Input("shape bound: one depth change per vertex in every mode".into()));
    }
    if sigma.is_nan() || sigma <= 0.0 {
        return Err(ReconError::Input(format!("shape bound: the noise sigma must be positive (got {sigma} K)")));
    }
    let lin = Linearised::new(om, d, z, b)?;
    let columns = columns(om, d, z, b, modes)?;
    // Whitened and centred (the offsets profiled), per column and video.
    let known: Vec<Vec<Vec<f64>>> = columns.iter().map(|c| c.iter().map(|v| lin.whiten(v)).collect()).collect();
    let (free, projection_residual, projection_iterations) = lin.project_all(&known, opts);
    let aligned = aligned_displacements(om, z, modes);
    let k = modes.len();
    let mut rows = Vec::new();
    for (fluxes, cols) in [(true, &free), (false, &known)] {
        let gram = |a: usize, c: usize| -> f64 {
            cols[a].iter().zip(&cols[c]).map(|(x, y)| x.iter().zip(y).map(|(p, q)| p * q).sum::<f64>()).sum::<f64>()
                / (sigma * sigma)
        };
        for globals in [false, true] {
            let dim = if globals { k + 2 } else { k };
            let f = Mat::from_fn(dim, dim, &gram);
            let cov = invert(&f).ok_or_else(|| {
                ReconError::Input(format!(
                    "shape bound: the information matrix is singular (fluxes {}, globals {}): the videos do not tell \
                     the modes apart",
                    if fluxes { "unknown" } else { "known" },
                    if globals { "unknown" } else { "known" }
                ))
            })?;
            let cov = cov.submatrix(0, 0, k, k).to_owned();
            let std: Vec<f64> = (0..k).map(|j| cov[(j, j)].max(0.0).sqrt()).collect();
            let expected_abs = (2.0 / std::f64::consts::PI).sqrt();
            let mean = |f: &dyn Fn(usize) -> f64| (0..n).map(f).sum::<f64>() / n as f64;
            let mode_mae_m = (0..k).map(|j| expected_abs * std[j] * mean(&|i| aligned[j][i].abs())).collect();
            let joint_mae_m = expected_abs
                * mean(&|i| {
                    let quad: f64 = (0..k)
                        .flat_map(|a| (0..k).map(move |c| (a, c)))
                        .map(|(a, c)| aligned[a][i] * cov[(a, c)] * aligned[c][i])
                        .sum();
                    quad.max(0.0).sqrt()
                });
            rows.push(BoundRow { nuisances: Nuisances { fluxes, globals }, std, mode_mae_m, joint_mae_m });
        }
    }
    Ok(ShapeBound {
        modes: modes.iter().map(|m| m.name.clone()).collect(),
        sigma,
        rows,
        projection_residual,
        projection_iterations,
    })
}

/// Fits the fluxes `b` exactly at depths `z`: the residual of the prediction at `b` (whitened
/// as the loss weighs it, the offsets profiled) is fitted by every video's flux directions by
/// CGLS (the bound's projection, the time stepping linearised at `b`, `opts`' iterations and
/// tolerance), `b` moved by that fit (the step halved while it does not lower the loss, at
/// most 8 times, and not taken if none does), and the loss there returned (K^2). From fluxes near the
/// fit (an L-BFGS flux fit) this removes what the fit left unconverged: loss differences of
/// 1e-4 of the loss, the size of a 25 % size change on the ball at 50 mK
/// (docs/notes/reconstruction-stage2.md), are below what 15 L-BFGS iterations resolve.
///
/// The fluxes of vertices left out of the loss (weight 0) reach it only through conduction
/// and are weakly determined: CGLS over all fluxes crawls (on the ball at level 1, 400
/// iterations left the normal equations' residual at 0.1 to 0.4 of the start's). So they are
/// eliminated exactly: their columns are computed a colour at a time (vertices far enough
/// apart for conduction not to carry between them share a tangent run) and CGLS runs on the
/// fitted vertices' fluxes with the residual projected away from those columns. With
/// `tie_left_out` each instead takes the mean of its neighbours one ring nearer the fitted
/// vertices: about 20 iterations, but a different model, whose size on noise-free data is 23
/// to 29 % off where the free one's is within 0.4 % (notes, "The rim's fluxes carry the size").
///
/// # Errors
/// As [`super::output_error::loss`]; a folded shape.
pub fn fit_flux_exactly(
    om: &OeMesh,
    d: &OeData,
    z: &[f64],
    b: &mut [Vec<f64>],
    opts: BoundOptions,
    tie_left_out: bool,
) -> Result<f64, ReconError> {
    let tie = if tie_left_out { Tie::of_weights(&om.mesh.nbrs, d.weight) } else { None };
    if let Some(tie) = &tie {
        b.iter_mut().for_each(|bv| *bv = tie.extend(bv));
    }
    let lin = Linearised { tie, ..Linearised::new(om, d, z, b)? };
    let pred = super::output_error::predict(om, d, z, b)?;
    let left_out = left_out(om, d);
    let groups = lin.rim_groups(om, &left_out);
    let steps: Vec<Vec<f64>> = d
        .series
        .par_iter()
        .zip(&pred)
        .enumerate()
        .map(|(v, (y, p))| {
            let r = lin.whiten(&y.iter().zip(p).map(|(a, c)| a - c).collect::<Vec<f64>>());
            let rc = groups.as_ref().and_then(|g| lin.rim_columns(v, g));
            lin.fit_step(v, &r, rc.as_ref(), &left_out, opts)
        })
        .collect();
    if steps.iter().flatten().any(|v| !v.is_finite()) {
        return Err(ReconError::Input("exact flux fit: the flux step is not finite".into()));
    }
    // The step is the linearised model's; radiation makes the loss not quite quadratic, so a
    // step that does not lower the loss is halved (at most 8 times) and otherwise not taken.
    let loss_at = |bb: &[Vec<f64>]| super::output_error::loss(om, d, z, bb, super::output_error::OeGrad::default());
    let j0 = loss_at(b)?;
    let mut scale = 1.0;
    for _ in 0..=8 {
        let trial: Vec<Vec<f64>> =
            b.iter().zip(&steps).map(|(bv, db)| bv.iter().zip(db).map(|(x, e)| x + scale * e).collect()).collect();
        let j = loss_at(&trial)?;
        if j <= j0 {
            b.iter_mut().zip(trial).for_each(|(o, t)| *o = t);
            return Ok(j);
        }
        scale /= 2.0;
    }
    Ok(j0)
}

/// The Gauss–Newton system of the coefficients of `modes` and of ln lambda (last) at depths
/// `z` and fluxes `b` fitted there ([`fit_flux_exactly`]): with `A` the whitened videos'
/// derivatives in the coefficients projected away from every video's flux directions (the
/// bound's columns and projection, the left-out fluxes eliminated as in the exact fit) and `r`
/// the whitened residual, `(A^T A, A^T r)`. The step `(A^T A)^-1 A^T r` lowers the loss
/// profiled over the fluxes to first order (variable projection); `noise_var (A^T A)^-1` is
/// the coefficients' covariance at the fit (the bound there, lambda unknown, c known).
///
/// # Errors
/// As [`super::output_error::loss`]; a folded shape; a mode without one depth change per
/// vertex.
pub fn mode_system(
    om: &OeMesh,
    d: &OeData,
    z: &[f64],
    b: &[Vec<f64>],
    modes: &[ShapeMode],
    opts: BoundOptions,
) -> Result<(Mat<f64>, Vec<f64>), ReconError> {
    let n = om.mesh.len();
    if modes.iter().any(|m| m.dz.len() != n) || z.len() != n {
        return Err(ReconError::Input("mode system: one depth change per vertex in every mode".into()));
    }
    let lin = Linearised::new(om, d, z, b)?;
    let mut cols = columns(om, d, z, b, modes)?;
    cols.truncate(modes.len() + 1);
    cols[modes.len()].iter_mut().flatten().for_each(|v| *v *= d.lambda);
    let pred = super::output_error::predict(om, d, z, b)?;
    let left_out = left_out(om, d);
    let groups = lin.rim_groups(om, &left_out);
    let rims: Vec<Option<rim::RimColumns>> =
        (0..b.len()).into_par_iter().map(|v| groups.as_ref().and_then(|g| lin.rim_columns(v, g))).collect();
    let jobs: Vec<(usize, usize)> = (0..cols.len()).flat_map(|c| (0..b.len()).map(move |v| (c, v))).collect();
    let projected: Vec<Vec<f64>> = jobs
        .par_iter()
        .map(|&(c, v)| {
            let y = lin.whiten(&cols[c][v]);
            let fitted = lin.whiten(&lin.tangent(v, &lin.fit_step(v, &y, rims[v].as_ref(), &left_out, opts)));
            y.iter().zip(&fitted).map(|(a, f)| a - f).collect()
        })
        .collect();
    let residual: Vec<Vec<f64>> = d
        .series
        .iter()
        .zip(&pred)
        .map(|(y, p)| lin.whiten(&y.iter().zip(p).map(|(a, c)| a - c).collect::<Vec<f64>>()))
        .collect();
    let k = cols.len();
    let nv = b.len();
    let dot = |a: &[f64], c: &[f64]| a.iter().zip(c).map(|(x, y)| x * y).sum::<f64>();
    let gram = Mat::from_fn(k, k, |a, c| (0..nv).map(|v| dot(&projected[a * nv + v], &projected[c * nv + v])).sum());
    let rhs = (0..k).map(|a| (0..nv).map(|v| dot(&projected[a * nv + v], &residual[v])).sum()).collect();
    Ok((gram, rhs))
}

/// The videos' derivatives (video-shaped, per video) in each mode's coefficient and in lambda
/// and c, by central differences of [`super::output_error::predict`] (relative step 1e-6).
fn columns(
    om: &OeMesh,
    d: &OeData,
    z: &[f64],
    b: &[Vec<f64>],
    modes: &[ShapeMode],
) -> Result<Vec<Vec<Vec<f64>>>, ReconError> {
    let fd = |f: &dyn Fn(f64) -> Result<Vec<Vec<f64>>, ReconError>, step: f64| -> Result<Vec<Vec<f64>>, ReconError> {
        let (p, m) = (f(step)?, f(-step)?);
        Ok(p.iter().zip(&m).map(|(p, m)| p.iter().zip(m).map(|(a, b)| (a - b) / (2.0 * step)).collect()).collect())
    };
    let mut columns = Vec::with_capacity(modes.len() + 2);
    let zmax = z.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    for mode in modes {
        let scale = mode.dz.iter().fold(0.0f64, |a, v| a.max(v.abs())).max(1e-300);
        let at = |e: f64| {
            let ze: Vec<f64> = z.iter().zip(&mode.dz).map(|(z, v)| z + e * v).collect();
            super::output_error::predict(om, d, &ze, b)
        };
        columns.push(fd(&at, 1e-6 * zmax / scale)?);
    }
    let at_lambda = |e: f64| super::output_error::predict(om, &OeData { lambda: d.lambda + e, ..*d }, z, b);
    columns.push(fd(&at_lambda, 1e-6 * d.lambda.abs().max(1e-12))?);
    let at_c = |e: f64| super::output_error::predict(om, &OeData { c_inv: d.c_inv + e, ..*d }, z, b);
    columns.push(fd(&at_c, 1e-6 * d.c_inv.abs().max(1e-9))?);
    Ok(columns)
}

/// The inverse of a symmetric positive definite matrix, scaled to unit diagonal first;
/// `None` when it is not (numerically) positive definite.
fn invert(f: &Mat<f64>) -> Option<Mat<f64>> {
    let s: Vec<f64> = (0..f.nrows()).map(|i| f[(i, i)].sqrt()).collect();
    if s.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
        return None;
    }
    let scaled = Mat::from_fn(f.nrows(), f.ncols(), |a, c| f[(a, c)] / (s[a] * s[c]));
    let inv = scaled.llt(Side::Lower).ok()?.inverse();
    Some(Mat::from_fn(f.nrows(), f.ncols(), |a, c| inv[(a, c)] / (s[a] * s[c])))
}

/// Per mode and vertex, the surface error a unit coefficient makes (m): the displacement
/// along the vertex's ray, projected on its normal, less the best rigid motion (linearised
/// point-to-plane ICP: least squares over a small rotation and a translation), which an
/// evaluation after alignment does not see.
pub fn aligned_displacements(om: &OeMesh, z: &[f64], modes: &[ShapeMode]) -> Vec<Vec<f64>> {
    let mesh = om.mesh;
    let x = mesh.positions(z);
    let normals = mesh.normals(z);
    let n = x.len();
    let c: [f64; 3] = std::array::from_fn(|k| x.iter().map(|p| p[k]).sum::<f64>() / n.max(1) as f64);
    // Rigid basis per vertex: (r x n, n) with r = x - c, the normal displacement of rotation and
    // translation.
    let basis: Vec<[f64; 6]> = x
        .iter()
        .zip(&normals)
        .map(|(p, nv)| {
            let r = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
            [r[1] * nv[2] - r[2] * nv[1], r[2] * nv[0] - r[0] * nv[2], r[0] * nv[1] - r[1] * nv[0], nv[0], nv[1], nv[2]]
        })
        .collect();
    let g = Mat::from_fn(6, 6, |a, b| basis.iter().map(|r| r[a] * r[b]).sum::<f64>());
    let g_inv = invert(&g);
    modes
        .iter()
        .map(|mode| {
            let e: Vec<f64> = (0..n)
                .map(|i| {
                    let d = mesh.dirs[i];
                    mode.dz[i] * (d[0] * normals[i][0] + d[1] * normals[i][1] + d[2] * normals[i][2])
                })
                .collect();
            let Some(g_inv) = g_inv.as_ref() else { return e };
            let rhs: Vec<f64> = (0..6).map(|a| basis.iter().zip(&e).map(|(r, v)| r[a] * v).sum()).collect();
            let coef: Vec<f64> = (0..6).map(|a| (0..6).map(|c| g_inv[(a, c)] * rhs[c]).sum()).collect();
            e.iter().zip(&basis).map(|(v, r)| v - (0..6).map(|a| coef[a] * r[a]).sum::<f64>()).collect()
        })
        .collect()
}

/// The model linearised at one point: the time stepping with its trajectories, and the
/// fluxes' exact tangent and adjoint.
struct Linearised<'a> {
    d: &'a OeData<'a>,
    st: Stepping,
    /// Per video, theta at every substep.
    theta: Vec<Vec<Vec<f64>>>,
    /// Per frame, whether its residuals count.
    in_fit: Vec<bool>,
    /// sqrt of each vertex's weight.
    sqrt_w: Vec<f64>,
    /// The preconditioner's tau, s.
    tau: f64,
    /// The left-out vertices' fluxes tied to the fitted ones (the exact flux fit); `None`: all
    /// free (the bound).
    tie: Option<Tie>,
}

impl<'a> Linearised<'a> {
    fn new(om: &OeMesh, d: &'a OeData<'a>, z: &[f64], b: &[Vec<f64>]) -> Result<Linearised<'a>, ReconError> {
        let st =
            Stepping::new(om, d, z, b)?.ok_or_else(|| ReconError::Input("shape bound: the shape is folded".into()))?;
        let theta = b.iter().map(|bv| st.forward(d, bv)).collect();
        let n = om.mesh.len();
        let in_fit = d.fit_frames(n).in_fit;
        let sqrt_w = (0..n).map(|i| d.weight(i).max(0.0).sqrt()).collect();
        let tau = d.dt()? * st.frames_fit as f64 / 3f64.sqrt();
        Ok(Linearised { d, st, theta, in_fit, sqrt_w, tau, tie: None })
    }

    fn frames(&self) -> usize {
        self.d.frames()
    }

    /// A video-shaped vector (`[vertex * frames + frame]`, K) in the whitened space: zero
    /// outside the fitted frames, each vertex's mean over them removed when offsets are fitted,
    /// times sqrt(weight).
    fn whiten(&self, v: &[f64]) -> Vec<f64> {
        let frames = self.frames();
        let used = self.in_fit.iter().filter(|&&u| u).count().max(1) as f64;
        let mut out = vec![0.0; v.len()];
        for (i, sw) in self.sqrt_w.iter().enumerate() {
            let row = &v[i * frames..(i + 1) * frames];
            let mean = if self.d.offsets {
                row.iter().zip(&self.in_fit).filter(|(_, &u)| u).map(|(x, _)| x).sum::<f64>() / used
            } else {
                0.0
            };
            for k in 0..frames {
                if self.in_fit[k] {
                    out[i * frames + k] = sw * (row[k] - mean);
                }
            }
        }
        out
    }

    /// The rise's change in video `v` under a flux change `db` (K/s), video-shaped.
    fn tangent(&self, v: usize, db: &[f64]) -> Vec<f64> {
        let (st, d) = (&self.st, self.d);
        let (n, frames, h) = (db.len(), self.frames(), st.h);
        let mut out = vec![0.0; n * frames];
        let mut dt = vec![0.0; n];
        for j in 0..st.steps {
            let th = &self.theta[v][j];
            let mut rhs: Vec<f64> =
                (0..n).map(|i| st.m[i] * ((1.0 - h * d.c_inv * d.radiation(th[i]).1) * dt[i] + h * db[i])).collect();
            st.a.solve(&mut rhs);
            dt = rhs;
            if (j + 1).is_multiple_of(st.sub) {
                let k = d.first + (j + 1) / st.sub;
                for i in 0..n {
                    out[i * frames + k] = dt[i];
                }
            }
        }
        out
    }

    /// The transpose of [`Linearised::tangent`]: the flux change (K/s) whose inner product with
    /// `db` is that of `r` (video-shaped) with the tangent of `db`.
    fn adjoint(&self, v: usize, r: &[f64]) -> Vec<f64> {
        let (st, d) = (&self.st, self.d);
        let (n, frames, h) = (st.m.len(), self.frames(), st.h);
        let mut grad = vec![0.0; n];
        let mut p_next = vec![0.0; n];
        for j in (1..=st.steps).rev() {
            let th = &self.theta[v][j];
            let frame = j.is_multiple_of(st.sub).then(|| d.first + j / st.sub);
            let mut g: Vec<f64> = (0..n)
                .map(|i| {
                    let ri = frame.map_or(0.0, |k| r[i * frames + k]);
                    ri + (1.0 - h * d.c_inv * d.radiation(th[i]).1) * st.m[i] * p_next[i]
                })
                .collect();
            st.a.solve(&mut g);
            for i in 0..n {
                grad[i] += h * st.m[i] * g[i];
            }
            p_next = g;
        }
        grad
    }

    /// The flux preconditioner b = S u = (1 + tau lambda) u + tau alpha M^-1 L u.
    fn precondition(&self, u: &[f64], transpose: bool) -> Vec<f64> {
        let (st, d, tau) = (&self.st, self.d, self.tau);
        let n = u.len();
        let src: Vec<f64> = if transpose { (0..n).map(|i| u[i] / st.m[i]).collect() } else { u.to_vec() };
        let mut lu = vec![0.0; n];
        st.lap.apply(&src, &mut lu); // -L src
        (0..n)
            .map(|i| {
                let l = -lu[i];
                (1.0 + tau * d.lambda) * u[i] + tau * d.alpha * if transpose { l } else { l / st.m[i] }
            })
            .collect()
    }

    /// The flux change (K/s) of the unknowns `u`: `S u`, or with a tie `E S E u` (`E` the
    /// tie's extension, [`Tie`]); with `transpose` its transpose.
    fn flux_step(&self, u: &[f64], transpose: bool) -> Vec<f64> {
        match &self.tie {
            None => self.precondition(u, transpose),
            Some(tie) if transpose => tie.extend_t(&self.precondition(&tie.extend_t(u), true)),
            Some(tie) => tie.extend(&self.precondition(&tie.extend(u), false)),
        }
    }

    /// B u = whiten(tangent(flux_step(u))).
    fn apply(&self, v: usize, u: &[f64]) -> Vec<f64> {
        self.whiten(&self.tangent(v, &self.flux_step(u, false)))
    }

    /// B^T r = flux_step^T tangent^T whiten^T r (whitening is symmetric: a centring projector
    /// times a diagonal).
    fn apply_t(&self, v: usize, r: &[f64]) -> Vec<f64> {
        self.flux_step(&self.adjoint(v, &self.whiten(r)), true)
    }

    /// [`Linearised::project`] of every column (per video, whitened), in parallel: the projected
    /// columns, the largest final relative residual and the most iterations.
    fn project_all(&self, cols: &[Vec<Vec<f64>>], opts: BoundOptions) -> (Vec<Vec<Vec<f64>>>, f64, usize) {
        let nvid = cols.first().map_or(0, |c| c.len());
        let jobs: Vec<(usize, usize)> = (0..cols.len()).flat_map(|c| (0..nvid).map(move |v| (c, v))).collect();
        let done: Vec<(Vec<f64>, f64, usize)> =
            jobs.par_iter().map(|&(c, v)| self.project(v, &cols[c][v], opts)).collect();
        let residual = done.iter().map(|p| p.1).fold(0.0, f64::max);
        let iterations = done.iter().map(|p| p.2).max().unwrap_or(0);
        let mut it = done.into_iter().map(|p| p.0);
        let projected = (0..cols.len()).map(|_| (0..nvid).map(|_| it.next().expect("one per job")).collect()).collect();
        (projected, residual, iterations)
    }

    /// `y` (whitened, video `v`) less its least-squares fit by the video's fluxes (CGLS):
    /// returns the residual, the final relative normal-equation residual and the iterations.
    fn project(&self, v: usize, y: &[f64], opts: BoundOptions) -> (Vec<f64>, f64, usize) {
        let (r, _, rel, it) = self.solve(v, y, opts);
        (r, rel, it)
    }

    /// [`Linearised::project`] with the fit's coefficients `u` (fluxes `S u`, K/s) second.
    fn solve(&self, v: usize, y: &[f64], opts: BoundOptions) -> (Vec<f64>, Vec<f64>, f64, usize) {
        cgls(|u| self.apply(v, u), |r| self.apply_t(v, r), y, opts)
    }

    /// The left-out vertices' colours ([`rim::colour_left_out`], their separation measured
    /// from one vertex's response in video 0); `None` without a left-out vertex or with a tie.
    fn rim_groups(&self, om: &OeMesh, left_out: &[usize]) -> Option<rim::Colours> {
        (self.tie.is_none() && !left_out.is_empty()).then(|| {
            let p = rim::probe(om.mesh, &self.st.x, left_out);
            let mut unit = vec![0.0; om.mesh.len()];
            unit[p] = 1.0;
            let sep = rim::separation(&om.mesh.nbrs, p, &self.tangent(0, &unit), self.frames());
            rim::colour_left_out(om.mesh, left_out, sep)
        })
    }

    /// The left-out vertices' whitened columns of video `v`, a colour of `groups` at a time.
    fn rim_columns(&self, v: usize, groups: &[Vec<(usize, Vec<usize>)>]) -> Option<rim::RimColumns> {
        let n = self.st.m.len();
        let response = |members: &[usize]| {
            let mut db = vec![0.0; n];
            members.iter().for_each(|&i| db[i] = 1.0);
            self.whiten(&self.tangent(v, &db))
        };
        rim::RimColumns::new(groups, self.frames(), response)
    }

    /// The flux change (K/s) that fits the whitened residual `r` of video `v` best. With the
    /// left-out vertices' columns `rim` ([`Linearised::rim_columns`]) their fluxes are free and
    /// eliminated exactly ([`rim`]): CGLS over the fitted vertices' preconditioned fluxes on
    /// the residual projected away from those columns, then those fluxes' own fit. Without,
    /// CGLS over all fluxes.
    fn fit_step(
        &self,
        v: usize,
        r: &[f64],
        rim: Option<&rim::RimColumns>,
        left_out: &[usize],
        opts: BoundOptions,
    ) -> Vec<f64> {
        let Some(rc) = rim else {
            return self.flux_step(&self.solve(v, r, opts).1, false);
        };
        let zero_left_out = |mut u: Vec<f64>| {
            left_out.iter().for_each(|&i| u[i] = 0.0);
            u
        };
        let apply = |u: &[f64]| {
            let mut q = self.apply(v, &zero_left_out(u.to_vec()));
            rc.project(&mut q);
            q
        };
        let apply_t = |x: &[f64]| {
            let mut px = x.to_vec();
            rc.project(&mut px);
            zero_left_out(self.apply_t(v, &px))
        };
        let mut r_red = r.to_vec();
        rc.project(&mut r_red);
        let u = zero_left_out(cgls(apply, apply_t, &r_red, opts).1);
        let fitted = self.apply(v, &u);
        let rest: Vec<f64> = r.iter().zip(&fitted).map(|(a, c)| a - c).collect();
        let mut db = self.precondition(&u, false);
        for (&i, di) in rc.rim.iter().zip(rc.coefficients(&rest)) {
            db[i] += di;
        }
        db
    }
}

/// The vertices the loss leaves out (weight 0).
fn left_out(om: &OeMesh, d: &OeData) -> Vec<usize> {
    (0..om.mesh.len()).filter(|&i| d.weight(i) <= 0.0).collect()
}

/// CGLS on `min_x ‖B x - y‖` with `apply` = B and `apply_t` = B^T, `opts`' iterations and
/// tolerance (on the normal equations' residual, relative to the start's): (the residual, x,
/// the final relative normal residual, iterations).
fn cgls(
    apply: impl Fn(&[f64]) -> Vec<f64>,
    apply_t: impl Fn(&[f64]) -> Vec<f64>,
    y: &[f64],
    opts: BoundOptions,
) -> (Vec<f64>, Vec<f64>, f64, usize) {
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut r = y.to_vec();
    let mut s = apply_t(&r);
    let mut x = vec![0.0; s.len()];
    let mut p = s.clone();
    let mut gamma = dot(&s, &s);
    let gamma0 = gamma;
    if gamma0 == 0.0 {
        return (r, x, 0.0, 0);
    }
    let mut it = 0;
    let mut rr = dot(&r, &r);
    while it < opts.max_iterations && gamma > opts.tolerance * opts.tolerance * gamma0 {
        let q = apply(&p);
        let qq = dot(&q, &q);
        if qq <= 0.0 {
            break;
        }
        let a = gamma / qq;
        let r_next: Vec<f64> = r.iter().zip(&q).map(|(ri, qi)| ri - a * qi).collect();
        // CGLS lowers |r| at every step in exact arithmetic; past the attainable accuracy
        // rounding can make it grow, so a step that raises it ends the iteration.
        let rr_next = dot(&r_next, &r_next);
        if rr_next.is_nan() || rr_next > rr * (1.0 + 1e-9) {
            break;
        }
        (r, rr) = (r_next, rr_next);
        x.iter_mut().zip(&p).for_each(|(xi, pi)| *xi += a * pi);
        s = apply_t(&r);
        let g_new = dot(&s, &s);
        p.iter_mut().zip(&s).for_each(|(pi, si)| *pi = si + (g_new / gamma) * *pi);
        gamma = g_new;
        it += 1;
    }
    (r, x, (gamma / gamma0).sqrt(), it)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bound::output_error::tests::{physics, problem};
    use crate::stage2::energy::RayMesh;

    /// The flux tangent against central differences of `predict`, and the adjoint against the
    /// tangent (dot-product test).
    #[test]
    fn flux_tangent_and_adjoint_are_exact() {
        let (mesh, z, b, series, times) = problem();
        let d = OeData { offsets: true, ..physics(&series, &times) };
        let om = OeMesh::new(&mesh).expect("pattern");
        let lin = Linearised::new(&om, &d, &z, &b).expect("linearised");
        let n = mesh.len();
        let db: Vec<f64> = (0..n).map(|i| 0.01 * ((i * 7) % 5) as f64 - 0.02).collect();
        let h = 1e-4;
        let shifted = |e: f64| {
            let bb: Vec<Vec<f64>> = vec![b[0].iter().zip(&db).map(|(x, y)| x + e * y).collect(), b[1].clone()];
            super::super::output_error::predict(&om, &d, &z, &bb).expect("prediction")
        };
        let (p, m) = (shifted(h), shifted(-h));
        let tan = lin.tangent(0, &db);
        let scale = tan.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        assert!(scale > 0.0);
        for (k, t) in tan.iter().enumerate() {
            let fd = (p[0][k] - m[0][k]) / (2.0 * h);
            assert!((fd - t).abs() <= 1e-7 * scale, "entry {k}: tangent {t}, fd {fd}");
        }
        let r: Vec<f64> = (0..tan.len()).map(|k| ((k * 13) % 11) as f64 - 5.0).collect();
        for v in 0..2 {
            let lhs: f64 = lin.tangent(v, &db).iter().zip(&r).map(|(a, b)| a * b).sum();
            let rhs: f64 = lin.adjoint(v, &r).iter().zip(&db).map(|(a, b)| a * b).sum();
            assert!((lhs - rhs).abs() <= 1e-12 * lhs.abs().max(rhs.abs()), "video {v}: {lhs} vs {rhs}");
            let u: Vec<f64> = (0..n).map(|i| ((i * 3) % 7) as f64).collect();
            let lhs: f64 = lin.apply(v, &u).iter().zip(&r).map(|(a, b)| a * b).sum();
            let rhs: f64 = lin.apply_t(v, &r).iter().zip(&u).map(|(a, b)| a * b).sum();
            assert!((lhs - rhs).abs() <= 1e-12 * lhs.abs().max(rhs.abs()), "preconditioned, video {v}: {lhs} vs {rhs}");
        }
    }

    /// The problem of [`early_flux_fit`]: mesh, depths, data, frame times, the early fluxes,
    /// their loss and the loss of an L-BFGS fit from them run to convergence.
    type EarlyFit = (RayMesh, Vec<f64>, Vec<Vec<f64>>, Vec<f64>, Vec<Vec<f64>>, f64, f64);

    /// Model data with a deterministic disturbance (so the minimum is not 0), offsets, vertex
    /// weights `weight` and a flux fit stopped early ([`EarlyFit`]).
    fn early_flux_fit(weight: &[f64]) -> EarlyFit {
        use crate::bound::flux_fit::fit_flux;
        let (mesh, z, b, series, times) = problem();
        let disturbed: Vec<Vec<f64>> = series
            .iter()
            .map(|v| v.iter().enumerate().map(|(k, x)| x + 0.01 * (1.7 * k as f64).sin()).collect())
            .collect();
        let d = OeData { offsets: true, weight, ..physics(&disturbed, &times) };
        let om = OeMesh::new(&mesh).expect("pattern");
        let mean_b = b.iter().flatten().sum::<f64>() / (2 * mesh.len()) as f64;
        let mut early = vec![vec![mean_b; mesh.len()]; 2];
        let j_early = fit_flux(&om, &d, &z, &mut early, 1).expect("flux fit");
        let mut converged = early.clone();
        let j_conv = fit_flux(&om, &d, &z, &mut converged, 3000).expect("flux fit");
        assert!(j_early > 1.05 * j_conv, "the early fit should be unconverged: {j_early:e} vs {j_conv:e}");
        (mesh, z, disturbed, times, early, j_early, j_conv)
    }

    /// The exact flux fit from a flux fit stopped early reaches the loss of an L-BFGS fit run
    /// to convergence, with every vertex in the loss and with vertices left out (their fluxes
    /// free, eliminated by their columns: [`rim`]).
    #[test]
    fn exact_flux_fit_matches_a_converged_flux_fit() {
        let (mesh, _, _, _, _) = problem();
        let left_out: Vec<f64> = (0..mesh.len()).map(|i| if i == 4 || i % 9 == 0 { 0.0 } else { 1.0 }).collect();
        for weight in [&[][..], &left_out[..]] {
            let (mesh, z, series, times, mut early, j_early, j_conv) = early_flux_fit(weight);
            let d = OeData { offsets: true, weight, ..physics(&series, &times) };
            let om = OeMesh::new(&mesh).expect("pattern");
            let opts = BoundOptions { degree: 0, max_iterations: 2000, tolerance: 1e-12 };
            let exact = fit_flux_exactly(&om, &d, &z, &mut early, opts, false).expect("exact flux fit");
            assert!(
                (exact - j_conv).abs() <= 1e-3 * (j_early - j_conv),
                "{} left out: exact {exact:e}, converged {j_conv:e}, early {j_early:e}",
                weight.iter().filter(|&&w| w == 0.0).count()
            );
            let j_check = crate::bound::output_error::loss(&om, &d, &z, &early, Default::default()).expect("loss");
            assert_eq!(j_check, exact, "the returned loss is the loss at the returned fluxes");
        }
    }

    /// With vertices left out of the loss, the exact flux fit ties their fluxes to the fitted
    /// ones ([`Tie`]) and is stationary in the fitted ones: the loss's gradient through the tie
    /// falls below 1e-5 of the early fit's (one Gauss-Newton step; radiation makes the model
    /// slightly nonlinear).
    #[test]
    fn exact_flux_fit_ties_the_left_out_fluxes() {
        use crate::bound::output_error::{loss, OeGrad};
        let (mesh, _, _, _, _) = problem();
        let weight: Vec<f64> = (0..mesh.len()).map(|i| if i == 4 || i % 9 == 0 { 0.0 } else { 1.0 }).collect();
        let (mesh, z, series, times, mut fit, _, j_conv) = early_flux_fit(&weight);
        let d = OeData { offsets: true, weight: &weight, ..physics(&series, &times) };
        let om = OeMesh::new(&mesh).expect("pattern");
        let tie = Tie::of_weights(&mesh.nbrs, &weight).expect("vertices left out");
        let tied_gradient = |b: &[Vec<f64>]| -> (f64, f64) {
            let mut gb = vec![vec![0.0; mesh.len()]; 2];
            let j = loss(&om, &d, &z, b, OeGrad { b: Some(&mut gb), ..Default::default() }).expect("loss");
            (j, gb.iter().map(|g| tie.extend_t(g).iter().map(|x| x * x).sum::<f64>()).sum::<f64>().sqrt())
        };
        let early_tied: Vec<Vec<f64>> = fit.iter().map(|bv| tie.extend(bv)).collect();
        let (j_start, g_start) = tied_gradient(&early_tied);
        let opts = BoundOptions { degree: 0, max_iterations: 2000, tolerance: 1e-12 };
        let exact = fit_flux_exactly(&om, &d, &z, &mut fit, opts, true).expect("exact flux fit");
        for bv in &fit {
            let off = tie.extend(bv).iter().zip(bv).fold(0.0f64, |m, (a, c)| m.max((a - c).abs()));
            assert!(off <= 1e-14, "the left-out fluxes are the tie's (off by {off:e} K/s)");
        }
        let (j_end, g_end) = tied_gradient(&fit);
        assert_eq!(j_end, exact, "the returned loss is the loss at the returned fluxes");
        assert!(g_end <= 1e-5 * g_start, "gradient through the tie {g_end:e}, at the start {g_start:e}");
        assert!(exact < j_start && exact >= j_conv, "exact {exact:e}, start {j_start:e}, free fit {j_conv:e}");
    }

    /// Per column of `interest` (per video, whitened) its residual after the least-squares fit
    /// by every flux column of its video, each built explicitly (an orthonormal basis by a thin
    /// SVD, directions above 1e-12 of the largest kept).
    fn dense_projection(lin: &Linearised, interest: &[Vec<Vec<f64>>], n: usize) -> Vec<Vec<Vec<f64>>> {
        let mut free = vec![vec![Vec::new(); 2]; interest.len()];
        for v in 0..2 {
            let cols: Vec<Vec<f64>> = (0..n)
                .map(|i| {
                    let mut e = vec![0.0; n];
                    e[i] = 1.0;
                    lin.whiten(&lin.tangent(v, &e))
                })
                .collect();
            let jn = Mat::from_fn(cols[0].len(), n, |q, i| cols[i][q]);
            let svd = jn.thin_svd().expect("svd");
            let s_max = (0..n).map(|i| svd.S()[i]).fold(0.0f64, f64::max);
            let keep: Vec<usize> = (0..n).filter(|&i| svd.S()[i] > 1e-12 * s_max).collect();
            for (c, col) in interest.iter().enumerate() {
                let mut r = col[v].clone();
                for &i in &keep {
                    let u = svd.U().col(i);
                    let a: f64 = (0..r.len()).map(|q| u[q] * col[v][q]).sum();
                    (0..r.len()).for_each(|q| r[q] -= a * u[q]);
                }
                free[c][v] = r;
            }
        }
        free
    }

    /// The Gauss–Newton system with the rim's fluxes eliminated against the dense projection:
    /// the Gram of the projected columns (modes and ln lambda) and their products with the
    /// whitened residual.
    #[test]
    fn mode_system_matches_a_dense_projection() {
        let (mesh, z, b, series, times) = problem();
        let weight = crate::bound::rim_weights(&mesh, 1);
        let disturbed: Vec<Vec<f64>> = series
            .iter()
            .map(|v| v.iter().enumerate().map(|(k, x)| x + 0.01 * (1.7 * k as f64).sin()).collect())
            .collect();
        let d = OeData { offsets: true, weight: &weight, ..physics(&disturbed, &times) };
        let om = OeMesh::new(&mesh).expect("pattern");
        let modes = default_modes(&om, &z, 1);
        let opts = BoundOptions { degree: 1, max_iterations: 2000, tolerance: 1e-12 };
        let (gram, rhs) = mode_system(&om, &d, &z, &b, &modes, opts).expect("mode system");

        let lin = Linearised::new(&om, &d, &z, &b).expect("linearised");
        let k = modes.len() + 1;
        let mut interest: Vec<Vec<Vec<f64>>> = columns(&om, &d, &z, &b, &modes)
            .expect("columns")
            .iter()
            .map(|col| col.iter().map(|c| lin.whiten(c)).collect())
            .collect();
        interest.truncate(k);
        interest[k - 1].iter_mut().flatten().for_each(|v| *v *= d.lambda);
        let free = dense_projection(&lin, &interest, mesh.len());
        let pred = super::super::output_error::predict(&om, &d, &z, &b).expect("prediction");
        let residual: Vec<Vec<f64>> = disturbed
            .iter()
            .zip(&pred)
            .map(|(y, p)| lin.whiten(&y.iter().zip(p).map(|(a, c)| a - c).collect::<Vec<f64>>()))
            .collect();
        let dot = |a: &[f64], c: &[f64]| a.iter().zip(c).map(|(x, y)| x * y).sum::<f64>();
        for a in 0..k {
            let want = (0..2).map(|v| dot(&free[a][v], &residual[v])).sum::<f64>();
            let scale = (gram[(a, a)] * (0..2).map(|v| dot(&residual[v], &residual[v])).sum::<f64>()).sqrt();
            assert!((rhs[a] - want).abs() <= 1e-6 * scale, "rhs {a}: {} vs {want} (scale {scale:e})", rhs[a]);
            for c in 0..k {
                let want = (0..2).map(|v| dot(&free[a][v], &free[c][v])).sum::<f64>();
                let scale = (gram[(a, a)] * gram[(c, c)]).sqrt();
                assert!((gram[(a, c)] - want).abs() <= 1e-6 * scale, "gram ({a}, {c}): {} vs {want}", gram[(a, c)]);
            }
        }
    }

    /// The CGLS projection against a dense one: every flux column built explicitly, the
    /// information in the modes and globals by the Schur complement.
    #[test]
    fn bound_matches_a_dense_schur_complement() {
        let (mesh, z, b, series, times) = problem();
        let weight: Vec<f64> = (0..mesh.len()).map(|i| if i % 6 == 0 { 0.0 } else { 1.0 }).collect();
        let d = OeData { offsets: true, weight: &weight, ..physics(&series, &times) };
        let om = OeMesh::new(&mesh).expect("pattern");
        let modes = default_modes(&om, &z, 1);
        let sigma = 0.01;
        let opts = BoundOptions { degree: 1, max_iterations: 2000, tolerance: 1e-12 };
        let bound = shape_bound(&om, &d, &z, &b, sigma, &modes, opts).expect("bound");
        assert!(bound.projection_residual <= 1e-10, "CGLS stopped at {}", bound.projection_residual);

        // Dense: the whitened columns of modes and globals, and of every flux.
        let lin = Linearised::new(&om, &d, &z, &b).expect("linearised");
        let n = mesh.len();
        let k = modes.len();
        let interest: Vec<Vec<Vec<f64>>> = columns(&om, &d, &z, &b, &modes)
            .expect("columns")
            .iter()
            .map(|col| col.iter().map(|c| lin.whiten(c)).collect())
            .collect();
        let free = dense_projection(&lin, &interest, n);
        for (row, cols) in [(0, &free), (2, &interest)] {
            let gram = Mat::from_fn(k + 2, k + 2, |a, c| {
                (0..2).map(|v| cols[a][v].iter().zip(&cols[c][v]).map(|(x, y)| x * y).sum::<f64>()).sum::<f64>()
                    / (sigma * sigma)
            });
            for globals in [false, true] {
                let dim = if globals { k + 2 } else { k };
                let cov = invert(&gram.submatrix(0, 0, dim, dim).to_owned()).expect("invertible");
                let got = &bound.rows[row + usize::from(globals)];
                assert_eq!(got.nuisances, Nuisances { fluxes: row == 0, globals });
                for j in 0..k {
                    let want = cov[(j, j)].sqrt();
                    assert!(
                        (got.std[j] - want).abs() <= 1e-5 * want,
                        "row {row} globals {globals} mode {j}: {} vs {want}",
                        got.std[j]
                    );
                }
            }
        }
        // More unknowns never tighten the bound.
        for j in 0..k {
            assert!(bound.rows[0].std[j] >= bound.rows[2].std[j] * (1.0 - 1e-9));
            assert!(bound.rows[1].std[j] >= bound.rows[0].std[j] * (1.0 - 1e-9));
        }
    }

    /// The rim's columns computed a colour at a time (a diffusivity small enough that several
    /// left-out vertices share a tangent run) give the left-out fluxes' least-squares fit of
    /// the exact columns, each computed alone.
    #[test]
    fn shared_rim_runs_match_single_vertex_columns() {
        let (mesh, z, b, series, times) = problem();
        let weight = crate::bound::rim_weights(&mesh, 1);
        let d = OeData { alpha: 1e-8, offsets: true, weight: &weight, ..physics(&series, &times) };
        let om = OeMesh::new(&mesh).expect("pattern");
        let lin = Linearised::new(&om, &d, &z, &b).expect("linearised");
        let left_out: Vec<usize> = (0..mesh.len()).filter(|&i| weight[i] == 0.0).collect();
        let p = rim::probe(&mesh, &lin.st.x, &left_out);
        let mut unit = vec![0.0; mesh.len()];
        unit[p] = 1.0;
        let sep = rim::separation(&mesh.nbrs, p, &lin.tangent(0, &unit), times.len());
        let groups = rim::colour_left_out(&mesh, &left_out, sep);
        assert!(groups.len() < left_out.len(), "no colour shared: {} colours", groups.len());
        let unit = |members: &[usize]| {
            let mut db = vec![0.0; mesh.len()];
            members.iter().for_each(|&i| db[i] = 1.0);
            lin.whiten(&lin.tangent(0, &db))
        };
        let rc = rim::RimColumns::new(&groups, times.len(), unit).expect("columns");
        // Dense: each left-out vertex's column alone, and the least-squares coefficients of x.
        let cols: Vec<Vec<f64>> = rc.rim.iter().map(|&i| unit(&[i])).collect();
        let x: Vec<f64> = (0..cols[0].len()).map(|k| ((k * 37) % 23) as f64 / 23.0 - 0.5).collect();
        let m = cols.len();
        let g = Mat::from_fn(m, m, |a, c| cols[a].iter().zip(&cols[c]).map(|(p, q)| p * q).sum::<f64>());
        let rhs = Mat::from_fn(m, 1, |a, _| cols[a].iter().zip(&x).map(|(p, q)| p * q).sum::<f64>());
        let want = faer::linalg::solvers::Solve::solve(&g.llt(Side::Lower).expect("Gram"), &rhs);
        let got = rc.coefficients(&x);
        let scale = (0..m).map(|a| want[(a, 0)].abs()).fold(0.0f64, f64::max);
        for a in 0..m {
            assert!(
                (got[a] - want[(a, 0)]).abs() <= 1e-5 * scale,
                "vertex {}: {} vs {}",
                rc.rim[a],
                got[a],
                want[(a, 0)]
            );
        }
    }

    /// The alignment removes a rigid motion exactly: the depth changes whose surface errors
    /// are those of a translation along the optical axis or a rotation leave none.
    #[test]
    fn rigid_modes_leave_no_aligned_error() {
        let (mesh, z, _, _, _) = problem();
        let om = OeMesh::new(&mesh).expect("pattern");
        let x = mesh.positions(&z);
        let normals = mesh.normals(&z);
        // A motion with velocity field w(x) moves the surface by w . n along its normal; on the
        // ray, a depth change dz moves it by dz (d . n).
        let along_ray = |w: &dyn Fn([f64; 3]) -> [f64; 3]| -> Vec<f64> {
            (0..mesh.len())
                .map(|i| {
                    let (n, d, v) = (normals[i], mesh.dirs[i], w(x[i]));
                    (v[0] * n[0] + v[1] * n[1] + v[2] * n[2]) / (d[0] * n[0] + d[1] * n[1] + d[2] * n[2])
                })
                .collect()
        };
        let shift = ShapeMode { name: "shift".into(), dz: along_ray(&|_| [0.0, 0.0, 1.0]) };
        let turn = ShapeMode { name: "turn".into(), dz: along_ray(&|p| [p[2] - 0.3, 0.0, -p[0]]) };
        let relief = default_modes(&om, &z, 0).swap_remove(1);
        let a = aligned_displacements(&om, &z, &[shift, turn, relief]);
        let max = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(max(&a[0]) <= 1e-12, "translation left {}", max(&a[0]));
        assert!(max(&a[1]) <= 1e-12, "rotation left {}", max(&a[1]));
        assert!(max(&a[2]) > 1e-4, "relief removed entirely: {}", max(&a[2]));
    }
}
