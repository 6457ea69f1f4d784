//! The output-error model: the video predicted by the surface heat equation on a shape,
//! compared with the observed one. The Cramér–Rao shape bound ([`super::shape`]) is built on it;
//! the experimental refinement (`crate::experimental::output_error`) fits it.
//!
//! The equation-error data term ([`crate::stage2::energy`]) puts the measured temperatures into the
//! regressors, so their noise biases the shape (errors in variables) and the low-rank denoiser
//! that tames it removes the shape's information (docs: "Why 50 mK fails"). Here the
//! temperatures are *predicted*: per video, from `θ^0 = 0` at the first frame at t = 0
//! (lamps on), implicit Euler over each frame interval `Δ t`,
//! `((1 + Δ t λ) M + Δ t α L) θ^(k+1) =
//!    M(θ^k + Δ t (b - c N(θ^k))),`
//! with `L` the cotangent Laplacian (weights `w_ij`, `(Lθ)_i = Σ_j w_ij(θ_i -
//! θ_j)`), `M` the barycentric lumped areas of the current vertices (m^2), `α` the
//! diffusivity (m^2/s), `λ = (h+R)/C` (1/s), `c = 1/C`, `N` the radiation beyond Eq. 5
//! (W/m^2), `b = q/C` (K/s). The loss is the mean squared difference to the observed rises
//! (K^2): for white noise, the negative log-likelihood up to constants.
//!
//! **Offsets** ([`OeData::offsets`]): the observed rise is the video less a fixed pattern
//! estimated from the frames at t <= 0, so each pixel carries a constant error of the noise's
//! size over the square root of their number (10 frames: 0.32 sigma), the same in every frame.
//! With offsets on, each video and vertex gets a free constant `o_i` and the loss runs over all
//! F frames, the prediction 0 up to t = 0: `Σ_k (θ^k_i + o_i - y^k_i)^2`, minimised
//! in closed form by `o_i` = the mean of `y_i - θ_i` over the frames (count F - 1 per
//! vertex). This is the likelihood of the raw video with an unknown pattern per pixel.
//!
//! **Gradient** by the adjoint of the time stepping: with `A` the (symmetric) matrix above,
//! `g^k` the total derivative of the loss in `θ^k` and `p^(k+1) = A^-1 g^(k+1)`,
//! `g^k = ∂ J/∂θ^k + (1 - Δ t c N'(θ^k)) M p^(k+1)`, and
//! `∂ J/∂ b = Δ t Σ_k M p^(k+1)`,
//! `∂ J/∂ m_i = Σ_k p^(k+1)_i (u^k_i - (1+Δ tλ)θ^(k+1)_i)` with
//! `u^k = θ^k + Δ t(b - cN(θ^k))`,
//! `∂ J/∂ w_ij = -Δ t α Σ_k (p_i - p_j)(θ_i - θ_j)^(k+1)`;
//! `∂ J/∂λ = -Δ t Σ_k p^(k+1T) M θ^(k+1)`,
//! `∂ J/∂ c = -Δ t Σ_k p^(k+1T) M N(θ^k)`;
//! the weights' and areas' derivatives map these to the depths
//! (`heatsim::surface::derivatives`); finite-difference checked in the tests.
//!
//! An evaluation is a forward and an adjoint solve per frame and video (the step matrix's
//! pattern and symbolic factorisation are computed once per mesh, [`OeMesh`]). At the coarsest
//! level (4 x 4 block averages) its own model error dominates: with the rim rings left out, the
//! noise-free loss is lowest for the plane.

use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::Side;
use heatsim::surface::operators::{lumped_area, AreaMass, CotanLaplacian};
use rayon::prelude::*;

use crate::error::ReconError;
// Sequential Cholesky: faer's parallel one changes its bits with the thread count.
use crate::faer_seq::{Llt, SymbolicLlt};
use crate::stage1::SIGMA;
use crate::stage2::energy::RayMesh;

/// Observed videos and the fixed physics of the output-error loss.
#[derive(Clone)]
pub struct OeData<'a> {
    /// Per video, observed rise (K) as `[vertex * frames + frame]`.
    pub series: &'a [Vec<f64>],
    /// Frame times, s (uniform from `first` on).
    pub times: &'a [f64],
    /// Index of the frame at t = 0 (the lamps switch on; the rise is 0 there).
    pub first: usize,
    /// Diffusivity alpha, m^2/s.
    pub alpha: f64,
    /// lambda = (h + R)/C, 1/s.
    pub lambda: f64,
    /// c = 1/C, m^2 K/J.
    pub c_inv: f64,
    /// Ambient temperature, K.
    pub ambient: f64,
    /// Emissivity.
    pub emissivity: f64,
    /// Per vertex, its weight in the loss (0 leaves it out, e.g. partly covered rim pixels);
    /// empty: all 1.
    pub weight: &'a [f64],
    /// Implicit Euler steps per frame interval (>= 1).
    pub substeps: usize,
    /// Variance of the temperature noise, K^2 (the loss's value at the truth for white
    /// noise): the unit of the regularisers' weights in the experimental refinement; 0 when not known.
    pub noise_var: f64,
    /// Fit a constant offset per video and vertex (profiled in closed form) over all frames,
    /// those before t = 0 included (module doc, "Offsets").
    pub offsets: bool,
    /// The frames whose residuals the loss sums (the rest can serve as held-out data).
    pub frame_set: FrameSet,
}

/// A subset of the frames, by index in the video.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum FrameSet {
    /// Every frame.
    All,
    /// Frames 0, 2, 4, ...
    Even,
    /// Frames 1, 3, 5, ...
    Odd,
}

impl FrameSet {
    /// Whether frame `k` belongs to the set.
    pub fn contains(self, k: usize) -> bool {
        match self {
            FrameSet::All => true,
            FrameSet::Even => k.is_multiple_of(2),
            FrameSet::Odd => !k.is_multiple_of(2),
        }
    }
}

impl OeData<'_> {
    pub(crate) fn frames(&self) -> usize {
        self.times.len()
    }

    pub(crate) fn dt(&self) -> Result<f64, ReconError> {
        let f = self.frames();
        if f < self.first + 2 {
            return Err(ReconError::Input("output-error loss: fewer than two frames after t = 0".into()));
        }
        let dt = self.times[self.first + 1] - self.times[self.first];
        let uniform = (self.first..f - 1).all(|k| ((self.times[k + 1] - self.times[k]) - dt).abs() <= 1e-9 * dt.abs());
        if !(dt > 0.0 && uniform) {
            return Err(ReconError::Input("output-error loss: frames after t = 0 must be uniform in time".into()));
        }
        Ok(dt)
    }

    /// Vertex `i`'s weight in the loss.
    pub(crate) fn weight(&self, i: usize) -> f64 {
        if self.weight.is_empty() {
            1.0
        } else {
            self.weight[i]
        }
    }

    /// The frames whose residuals count: of the frame set, those after t = 0 without offsets,
    /// all with them (the fitted offset takes one per vertex); `n` vertices.
    pub(crate) fn fit_frames(&self, n: usize) -> FitFrames {
        let frames = self.frames();
        let in_fit: Vec<bool> =
            (0..frames).map(|k| self.frame_set.contains(k) && (self.offsets || k > self.first)).collect();
        let used: Vec<usize> = (0..frames).filter(|&k| in_fit[k]).collect();
        let per_vertex = used.len().saturating_sub(usize::from(self.offsets));
        let count =
            (per_vertex as f64 * (0..n).map(|i| self.weight(i)).sum::<f64>() * self.series.len() as f64).max(1.0);
        FitFrames { in_fit, used, count }
    }

    /// N(theta), W/m^2, and its derivative, W/(m^2 K).
    pub(crate) fn radiation(&self, theta: f64) -> (f64, f64) {
        let (ts, es) = (self.ambient, self.emissivity * SIGMA);
        let t = ts + theta;
        (es * (t.powi(4) - ts.powi(4) - 4.0 * ts.powi(3) * theta), es * 4.0 * (t.powi(3) - ts.powi(3)))
    }
}

/// The frames of [`OeData::fit_frames`].
pub(crate) struct FitFrames {
    /// Per frame, whether its residuals count.
    pub(crate) in_fit: Vec<bool>,
    /// The frames that count, in order.
    pub(crate) used: Vec<usize>,
    /// The loss's divisor: residuals that count less one per offset, weighted, all videos.
    pub(crate) count: f64,
}

/// The sparsity pattern of the step matrix and its symbolic Cholesky factorisation (fill-
/// reducing ordering): fixed per mesh, computed once and reused by every evaluation.
pub(crate) struct StepPattern {
    pub(crate) col_ptr: Vec<usize>,
    pub(crate) row_idx: Vec<usize>,
    /// Per stored entry, the edge whose weight it carries (`None` on the diagonal).
    pub(crate) entry_edge: Vec<Option<usize>>,
    pub(crate) symbolic: SymbolicLlt,
}

impl StepPattern {
    /// The lower triangle in CSC of a matrix with the mesh's vertex adjacency: column j holds
    /// (j, j) and (i, j) for neighbours i > j.
    pub(crate) fn new(mesh: &RayMesh) -> Result<StepPattern, ReconError> {
        let n = mesh.len();
        let mut col_ptr = vec![0usize; n + 1];
        let mut row_idx = Vec::with_capacity(n + mesh.edges.len());
        let mut entry_edge = Vec::with_capacity(n + mesh.edges.len());
        for j in 0..n {
            row_idx.push(j);
            entry_edge.push(None);
            let mut below: Vec<(usize, usize)> = mesh.nbrs[j].iter().copied().filter(|&(i, _)| i > j).collect();
            below.sort_unstable();
            for (i, e) in below {
                row_idx.push(i);
                entry_edge.push(Some(e));
            }
            col_ptr[j + 1] = row_idx.len();
        }
        let sym = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
        let symbolic = SymbolicLlt::try_new(sym, Side::Lower)
            .map_err(|e| ReconError::Input(format!("output-error loss: symbolic factorisation failed: {e:?}")))?;
        Ok(StepPattern { col_ptr, row_idx, entry_edge, symbolic })
    }
}

/// The ray mesh of the output-error loss with its step matrix's sparsity pattern and symbolic factorisation.
pub struct OeMesh<'a> {
    /// The mesh whose depths are fitted.
    pub mesh: &'a RayMesh,
    pub(crate) pattern: StepPattern,
}

impl<'a> OeMesh<'a> {
    /// Analyses the step matrix's pattern of `mesh` (once per mesh).
    ///
    /// # Errors
    /// A pattern faer cannot analyse (does not happen for a valid mesh).
    pub fn new(mesh: &'a RayMesh) -> Result<OeMesh<'a>, ReconError> {
        Ok(OeMesh { mesh, pattern: StepPattern::new(mesh)? })
    }
}

/// The factorised step matrix A = (1 + dt lambda) M + dt alpha L.
pub(crate) struct StepMatrix {
    pub(crate) llt: Llt,
}

impl StepMatrix {
    pub(crate) fn new(
        pat: &StepPattern,
        lap: &CotanLaplacian,
        m: &[f64],
        diag_scale: f64,
        off_scale: f64,
    ) -> Option<StepMatrix> {
        let n = m.len();
        let mut diag: Vec<f64> = m.iter().map(|&mi| diag_scale * mi).collect();
        for (&[i, j], &w) in lap.edges.iter().zip(&lap.weights) {
            diag[i] += off_scale * w;
            diag[j] += off_scale * w;
        }
        let values: Vec<f64> = pat
            .entry_edge
            .iter()
            .zip(&pat.row_idx)
            .map(|(e, &i)| match e {
                Some(e) => -off_scale * lap.weights[*e],
                None => diag[i],
            })
            .collect();
        let sym = SymbolicSparseColMatRef::new_checked(n, n, &pat.col_ptr, None, &pat.row_idx);
        let mat = SparseColMatRef::new(sym, &values);
        let llt = Llt::try_new_with_symbolic(pat.symbolic.clone(), mat, Side::Lower, faer::Par::Seq).ok()?;
        Some(StepMatrix { llt })
    }

    pub(crate) fn solve(&self, b: &mut [f64]) {
        self.llt.solve_in_place(b);
    }
}

/// Gradients of [`loss`].
#[derive(Default)]
pub struct OeGrad<'a> {
    /// dJ/dz (K^2/m), one per vertex.
    pub z: Option<&'a mut [f64]>,
    /// Per video, dJ/db (K^2 / (K/s)).
    pub b: Option<&'a mut [Vec<f64>]>,
    /// (dJ/dlambda, K^2 s; dJ/dc, K^2 J/(m^2 K)).
    pub globals: Option<&'a mut [f64; 2]>,
}

/// The time stepping of [`loss`] at one shape: the positions, operators and factorised step
/// matrix, with the step h = dt / substeps.
pub(crate) struct Stepping {
    pub(crate) x: Vec<[f64; 3]>,
    pub(crate) lap: CotanLaplacian,
    pub(crate) m: Vec<f64>,
    pub(crate) a: StepMatrix,
    pub(crate) h: f64,
    pub(crate) sub: usize,
    pub(crate) dlam: f64,
    pub(crate) frames_fit: usize,
    pub(crate) steps: usize,
}

impl Stepping {
    /// `None` when the step matrix is not positive definite (a folded shape).
    pub(crate) fn new(om: &OeMesh, d: &OeData, z: &[f64], b: &[Vec<f64>]) -> Result<Option<Stepping>, ReconError> {
        let mesh = om.mesh;
        let n = mesh.len();
        if z.len() != n || b.iter().any(|v| v.len() != n) {
            return Err(ReconError::Input("output-error loss: depths or fluxes of the wrong size".into()));
        }
        let dt = d.dt()?;
        let x = mesh.positions(z);
        let lap = CotanLaplacian::new(&x, &mesh.tris);
        let m = lumped_area(&x, &mesh.tris, AreaMass::Barycentric);
        let sub = d.substeps.max(1);
        let h = dt / sub as f64;
        let dlam = 1.0 + h * d.lambda;
        let Some(a) = StepMatrix::new(&om.pattern, &lap, &m, dlam, h * d.alpha) else {
            return Ok(None);
        };
        let frames_fit = d.frames() - 1 - d.first;
        Ok(Some(Stepping { x, lap, m, a, h, sub, dlam, frames_fit, steps: frames_fit * sub }))
    }

    /// Forward: theta[j] (K) for j = 0..=steps (time t_first + j h; frame first + j / sub) under
    /// the flux `bv` (K/s).
    pub(crate) fn forward(&self, d: &OeData, bv: &[f64]) -> Vec<Vec<f64>> {
        let (n, h) = (self.m.len(), self.h);
        let mut theta = vec![vec![0.0; n]; self.steps + 1];
        for j in 0..self.steps {
            let mut rhs: Vec<f64> = (0..n)
                .map(|i| {
                    let t = theta[j][i];
                    self.m[i] * (t + h * (bv[i] - d.c_inv * d.radiation(t).0))
                })
                .collect();
            self.a.solve(&mut rhs);
            theta[j + 1] = rhs;
        }
        theta
    }
}

/// The videos [`loss`] predicts at depths `z` (m) and fluxes `b` (K/s), laid out as
/// [`OeData::series`] (`[vertex * frames + frame]`, K; 0 up to the frame at t = 0).
///
/// # Errors
/// As [`loss`]; a folded shape (step matrix not positive definite).
pub fn predict(om: &OeMesh, d: &OeData, z: &[f64], b: &[Vec<f64>]) -> Result<Vec<Vec<f64>>, ReconError> {
    let st = Stepping::new(om, d, z, b)?
        .ok_or_else(|| ReconError::Input("output-error prediction: the shape is folded".into()))?;
    let (n, frames) = (om.mesh.len(), d.frames());
    Ok(b.iter()
        .map(|bv| {
            let theta = st.forward(d, bv);
            let mut out = vec![0.0; n * frames];
            for k in 0..=st.frames_fit {
                for i in 0..n {
                    out[i * frames + d.first + k] = theta[k * st.sub][i];
                }
            }
            out
        })
        .collect())
}

/// One video's share of [`loss`]: its sum of squared residuals and, when asked, its
/// adjoint sums (module doc).
struct VideoPass {
    pub(crate) sum_sq: f64,
    pub(crate) edge_adj: Vec<f64>,
    pub(crate) mass_adj: Vec<f64>,
    pub(crate) b_grad: Vec<f64>,
    pub(crate) globals_grad: [f64; 2],
}

/// The output-error loss (module doc) at depths `z` (m) and fluxes `b` (per video and vertex,
/// K/s) on `om`; the gradients requested in `grad`. A step matrix that is not positive
/// definite (a folded shape) gives an infinite loss. The videos run in parallel; their sums
/// are added in order (deterministic).
///
/// # Errors
/// Frame times that are not uniform after t = 0, sizes that do not match.
pub fn loss(om: &OeMesh, d: &OeData, z: &[f64], b: &[Vec<f64>], grad: OeGrad) -> Result<f64, ReconError> {
    let n = om.mesh.len();
    let frames = d.frames();
    if b.len() != d.series.len() || d.series.iter().any(|v| v.len() != n * frames) {
        return Err(ReconError::Input("output-error loss: one flux image per video, videos of n x frames".into()));
    }
    let Some(st) = Stepping::new(om, d, z, b)? else {
        return Ok(f64::INFINITY);
    };
    let (mesh, x, lap, m, a) = (om.mesh, &st.x, &st.lap, &st.m, &st.a);
    let (h, sub, dlam, steps) = (st.h, st.sub, st.dlam, st.steps);
    let wt = |i: usize| d.weight(i);
    let FitFrames { in_fit, used, count } = d.fit_frames(n);
    let want_grad = grad.z.is_some() || grad.b.is_some() || grad.globals.is_some();
    let pass = |(obs, bv): (&Vec<f64>, &Vec<f64>)| -> VideoPass {
        let theta = st.forward(d, bv);
        // Predicted rise at frame k (0 up to the frame at t = 0).
        let pred = |k: usize, i: usize| if k <= d.first { 0.0 } else { theta[(k - d.first) * sub][i] };
        let offset: Vec<f64> = (0..n)
            .map(|i| {
                if d.offsets {
                    used.iter().map(|&k| obs[i * frames + k] - pred(k, i)).sum::<f64>() / used.len().max(1) as f64
                } else {
                    0.0
                }
            })
            .collect();
        let sum_sq = used
            .iter()
            .map(|&k| (0..n).map(|i| wt(i) * (pred(k, i) + offset[i] - obs[i * frames + k]).powi(2)).sum::<f64>())
            .sum::<f64>();
        let mut out = VideoPass {
            sum_sq,
            edge_adj: Vec::new(),
            mass_adj: Vec::new(),
            b_grad: Vec::new(),
            globals_grad: [0.0; 2],
        };
        if !want_grad {
            return out;
        }
        // Residual at substep j when it is a frame (j a multiple of sub), else 0. The profiled
        // offset adds nothing: its own derivative, the residuals' sum, is zero.
        let resid = |j: usize, i: usize| {
            if j.is_multiple_of(sub) && in_fit[d.first + j / sub] {
                wt(i) * (theta[j][i] + offset[i] - obs[i * frames + d.first + j / sub])
            } else {
                0.0
            }
        };
        // Adjoint, backwards: g^j then p^j = A^{-1} g^j.
        let (mut edge_adj, mut mass_adj, mut gb) = (vec![0.0; lap.edges.len()], vec![0.0; n], vec![0.0; n]);
        let mut gg = [0.0; 2];
        let mut p_next: Vec<f64> = vec![0.0; n]; // p^{j+1}
        for j in (1..=steps).rev() {
            let mut g: Vec<f64> = (0..n)
                .map(|i| {
                    let dn = d.radiation(theta[j][i]).1;
                    2.0 * resid(j, i) / count + (1.0 - h * d.c_inv * dn) * m[i] * p_next[i]
                })
                .collect();
            a.solve(&mut g);
            let p = g; // p^j, the adjoint of the step j-1 -> j
            let (tk, tprev) = (&theta[j], &theta[j - 1]);
            for i in 0..n {
                gb[i] += h * m[i] * p[i];
                let nr = d.radiation(tprev[i]).0;
                let u = tprev[i] + h * (bv[i] - d.c_inv * nr);
                mass_adj[i] += p[i] * (u - dlam * tk[i]);
                gg[0] -= h * m[i] * p[i] * tk[i];
                gg[1] -= h * m[i] * p[i] * nr;
            }
            for (e, &[i, k]) in lap.edges.iter().enumerate() {
                edge_adj[e] -= h * d.alpha * (p[i] - p[k]) * (tk[i] - tk[k]);
            }
            p_next = p;
        }
        out.edge_adj = edge_adj;
        out.mass_adj = mass_adj;
        out.b_grad = gb;
        out.globals_grad = gg;
        out
    };
    let passes: Vec<VideoPass> = d.series.par_iter().zip(b.par_iter()).map(pass).collect();
    let total: f64 = passes.iter().map(|p| p.sum_sq).sum();
    if let Some(gz) = grad.z {
        let (mut edge_adj, mut mass_adj) = (vec![0.0; lap.edges.len()], vec![0.0; n]);
        for p in &passes {
            edge_adj.iter_mut().zip(&p.edge_adj).for_each(|(o, v)| *o += v);
            mass_adj.iter_mut().zip(&p.mass_adj).for_each(|(o, v)| *o += v);
        }
        let mut gx = vec![[0.0; 3]; n];
        mesh.vjp()
            .accumulate(x, Some(&edge_adj), Some(&mass_adj), AreaMass::Barycentric, &mut gx)
            .expect("sizes are consistent by construction");
        gz.par_iter_mut().zip(&gx).zip(&mesh.dirs).for_each(|((g, gxi), di)| {
            *g = gxi[0] * di[0] + gxi[1] * di[1] + gxi[2] * di[2];
        });
    }
    if let Some(gg) = grad.globals {
        *gg = passes.iter().fold([0.0; 2], |a, p| [a[0] + p.globals_grad[0], a[1] + p.globals_grad[1]]);
    }
    if let Some(gbo) = grad.b {
        for (o, p) in gbo.iter_mut().zip(passes) {
            *o = p.b_grad;
        }
    }
    Ok(total / count)
}

/// [`crate::stage2::optimize::minimise`] of a loss that can fail: the first error ends the run and is
/// returned (the optimiser sees a non-finite value).
pub(crate) fn minimise_fallible(
    x: &mut [f64],
    steps: &crate::stage2::optimize::LargeSteps,
    opts: &crate::stage2::optimize::OptimOptions,
    mut f: impl FnMut(&[f64], &mut [f64]) -> Result<f64, ReconError>,
    project: impl FnMut(&mut [f64]),
) -> Result<(), ReconError> {
    let mut err = None;
    let run = crate::stage2::optimize::minimise(
        x,
        steps,
        opts,
        |v, g| match f(v, g) {
            Ok(j) => j,
            Err(e) => {
                err.get_or_insert(e);
                f64::NAN
            }
        },
        project,
        |_, _, _, _| {},
    );
    // The loss's own error first: the optimiser's (a non-finite start) would hide it.
    err.map_or(run, Err)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use heatsim::camera::PixelGrid;

    /// The test problem: mesh, depths (m), fluxes (K/s), videos (K) and frame times (s).
    pub(crate) type Problem = (RayMesh, Vec<f64>, Vec<Vec<f64>>, Vec<Vec<f64>>, Vec<f64>);

    /// A 7 x 6 pixel patch of a dome seen along +z, two videos of 12 frames.
    pub(crate) fn problem() -> Problem {
        let (w, h) = (7, 6);
        let grid = PixelGrid::new(&vec![true; w * h], w, h);
        let f = 0.01; // rays: (u - 3) f, (v - 2.5) f, 1
        let dirs: Vec<[f64; 3]> = (0..grid.vertex_count())
            .map(|k| {
                let (u, v) = grid.pixel_uv(k);
                [(u as f64 - 3.0) * f, (v as f64 - 2.5) * f, 1.0]
            })
            .collect();
        let z: Vec<f64> = dirs.iter().map(|d| 0.3 - 0.5 * (d[0] * d[0] + d[1] * d[1])).collect();
        let mesh = RayMesh::new(dirs, grid.tris.clone()).expect("mesh");
        let n = mesh.len();
        let frames = 12;
        let times: Vec<f64> = (0..frames).map(|k| (k as f64 - 1.0) * 0.5).collect();
        let b: Vec<Vec<f64>> =
            (0..2).map(|v| (0..n).map(|i| 0.05 + 0.01 * ((i * (v + 3)) % 7) as f64).collect()).collect();
        let series: Vec<Vec<f64>> = (0..2)
            .map(|v| {
                (0..n * frames)
                    .map(|q| 0.02 * (q % frames) as f64 * (1.0 + 0.1 * ((q / frames + v) % 5) as f64))
                    .collect()
            })
            .collect();
        (mesh, z, b, series, times)
    }

    /// lambda of [`lambda_problem`], 1/s: lambda T ~ 1 over the 5.5 s, so that the rise's
    /// curvature in time tells lambda from the fluxes.
    pub(crate) const LAMBDA_TRUE: f64 = 0.2;

    /// [`problem`] with the videos this model predicts at [`LAMBDA_TRUE`] (`substeps` per
    /// frame) and, in place of the true fluxes, a flat start at their mean.
    pub(crate) fn lambda_problem(substeps: usize) -> Problem {
        let (mesh, z, b, _, times) = problem();
        let om = OeMesh::new(&mesh).expect("pattern");
        let truth = OeData { lambda: LAMBDA_TRUE, substeps, ..physics(&[], &times) };
        let series = predict(&om, &truth, &z, &b).expect("prediction");
        let mean_b = b.iter().flatten().sum::<f64>() / (2 * mesh.len()) as f64;
        let flat = vec![vec![mean_b; mesh.len()]; 2];
        (mesh, z, flat, series, times)
    }

    /// The problem's physics: a large diffusivity, so that conduction matters on this coarse
    /// patch; two substeps, no offsets, every frame.
    pub(crate) fn physics<'a>(series: &'a [Vec<f64>], times: &'a [f64]) -> OeData<'a> {
        OeData {
            series,
            times,
            first: 1,
            alpha: 2e-5,
            lambda: 0.005,
            c_inv: 5e-4,
            ambient: 295.0,
            emissivity: 0.9,
            weight: &[],
            substeps: 2,
            noise_var: 0.0,
            offsets: false,
            frame_set: FrameSet::All,
        }
    }

    #[test]
    pub(crate) fn gradient_matches_finite_differences() {
        check_gradients(false, FrameSet::All);
    }

    #[test]
    pub(crate) fn gradient_with_offsets_and_a_frame_set_matches_finite_differences() {
        check_gradients(true, FrameSet::All);
        check_gradients(false, FrameSet::Odd);
        check_gradients(true, FrameSet::Even);
    }

    pub(crate) fn check_gradients(offsets: bool, frame_set: FrameSet) {
        let (mesh, z, b, series, times) = problem();
        let weight: Vec<f64> = (0..mesh.len()).map(|i| if i % 5 == 0 { 0.0 } else { 1.0 }).collect();
        let d = OeData { weight: &weight, substeps: 3, offsets, frame_set, ..physics(&series, &times) };
        let n = mesh.len();
        let om = OeMesh::new(&mesh).expect("pattern");
        let mut gz = vec![0.0; n];
        let mut gb = vec![vec![0.0; n]; 2];
        let mut gg = [0.0; 2];
        let grad = OeGrad { z: Some(&mut gz), b: Some(&mut gb), globals: Some(&mut gg) };
        let j0 = loss(&om, &d, &z, &b, grad).expect("loss");
        assert!(j0.is_finite() && j0 > 0.0);
        let eval = |z: &[f64], b: &[Vec<f64>]| loss(&om, &d, z, b, OeGrad::default()).expect("loss");
        for (q, step) in [(0, 1e-6 * d.lambda), (1, 1e-4 * d.c_inv)] {
            let at = |x: f64| {
                let dq = if q == 0 { OeData { lambda: x, ..d } } else { OeData { c_inv: x, ..d } };
                loss(&om, &dq, &z, &b, OeGrad::default()).expect("loss")
            };
            let x0 = if q == 0 { d.lambda } else { d.c_inv };
            let fd = (at(x0 + step) - at(x0 - step)) / (2.0 * step);
            assert!(gg[q] != 0.0 && (fd - gg[q]).abs() <= 1e-5 * gg[q].abs(), "global {q}: analytic {} fd {fd}", gg[q]);
        }
        let scale_z = gz.iter().fold(0.0f64, |a, g| a.max(g.abs()));
        for i in [0, 9, 17, 24, n - 1] {
            let hz = 1e-6;
            let (mut zp, mut zm) = (z.clone(), z.clone());
            zp[i] += hz;
            zm[i] -= hz;
            let fd = (eval(&zp, &b) - eval(&zm, &b)) / (2.0 * hz);
            assert!((fd - gz[i]).abs() <= 1e-5 * scale_z, "dJ/dz[{i}]: analytic {} fd {fd}", gz[i]);
        }
        let scale_b = gb.iter().flatten().fold(0.0f64, |a, g| a.max(g.abs()));
        for (v, i) in [(0, 3), (1, 20), (1, n - 2)] {
            let hb = 1e-6;
            let (mut bp, mut bm) = (b.clone(), b.clone());
            bp[v][i] += hb;
            bm[v][i] -= hb;
            let fd = (eval(&z, &bp) - eval(&z, &bm)) / (2.0 * hb);
            assert!((fd - gb[v][i]).abs() <= 1e-6 * scale_b, "dJ/db[{v}][{i}]: analytic {} fd {fd}", gb[v][i]);
        }
    }

    #[test]
    pub(crate) fn frame_sets_split_the_loss() {
        let (mesh, z, b, series, times) = problem();
        let om = OeMesh::new(&mesh).expect("pattern");
        let mut d = physics(&series, &times);
        let mut at = |fs: FrameSet| {
            d.frame_set = fs;
            loss(&om, &d, &z, &b, OeGrad::default()).expect("loss")
        };
        // Frames 2..=11 after t = 0: five even, five odd.
        let (all, even, odd) = (at(FrameSet::All), at(FrameSet::Even), at(FrameSet::Odd));
        assert!(even > 0.0 && odd > 0.0 && (even - odd).abs() > 1e-6 * all, "{even} {odd}");
        assert!((all - 0.5 * (even + odd)).abs() <= 1e-12 * all, "all {all}, even {even}, odd {odd}");
    }

    /// [`problem`] with the model's own videos (offsets fitted, every frame) plus a constant
    /// error per video and vertex, of the size of the rise's first steps.
    pub(crate) fn offset_problem() -> Problem {
        let (mesh, z, b, _, times) = problem();
        let om = OeMesh::new(&mesh).expect("pattern");
        let (n, frames) = (mesh.len(), times.len());
        let d = OeData { offsets: true, ..physics(&[], &times) };
        let mut series = predict(&om, &d, &z, &b).expect("prediction");
        for (v, s) in series.iter_mut().enumerate() {
            for i in 0..n {
                let o = 0.01 * (((i * 7 + v * 3) % 11) as f64 - 5.0);
                s[i * frames..(i + 1) * frames].iter_mut().for_each(|y| *y += o);
            }
        }
        (mesh, z, b, series, times)
    }

    #[test]
    fn offsets_absorb_an_error_of_the_fixed_pattern() {
        let (mesh, z, b, series, times) = offset_problem();
        let om = OeMesh::new(&mesh).expect("pattern");
        let mut d = OeData { offsets: true, ..physics(&series, &times) };
        assert!(loss(&om, &d, &z, &b, OeGrad::default()).expect("loss") < 1e-20);
        d.offsets = false;
        let without = loss(&om, &d, &z, &b, OeGrad::default()).expect("loss");
        assert!(without > 1e-5, "the offsets should show without their fit: {without:e}");
    }
}
