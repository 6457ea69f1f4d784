//! Stage 1 (paper Sec. 5, Eq. 7): the scaled surface Laplacian, the absorbed flux of each video
//! and the global heat-exchange parameters, from thermal videos alone, by structured least
//! squares.
//!
//! # Model
//! Per unit area, with `θ = T - T_s` the rise above ambient, `C = ρ c_p d` (J/(m^2 K)),
//! the surface solver's equation divided by `C` is
//! `dot(θ)_i = Σ_(j ~ i) a_ij (θ_j - θ_i) + b_i -
//!    λ θ_i - c N(θ_i),`
//! with `a_ij = α w_ij / m_i` the off-diagonal of `Δ_s = α M^-1 L` (1/s),
//! `b_i = q_i / C` (K/s, one image per video), `λ = (h + R)/C` (1/s) where
//! `R = 4 ε σ T_s^3` is radiation's known linear coefficient (Eq. 5), `c = 1/C`,
//! and `N(θ) = εσ((T_s+θ)^4 - T_s^4 - 4 T_s^3 θ)` the
//! part of `T^4` radiation beyond Eq. 5. A time rule ([`time_rule`]) turns the frames into one
//! equation per vertex, instant and video,
//! `dot(θ)_i = Σ_j a_ij(bar(θ)_j - bar(θ)_i) + b_i - λ bar(θ)_i - c bar(N)_i,`
//! with `bar(x)` and `dot(x)` fixed combinations of a few frames: backward Euler on frame pairs
//! (Eq. 7 exactly), the trapezoid on pairs, or (the default) the state at frame k with a
//! five-point derivative (fourth order for the continuous-time heating a camera films).
//!
//! # Identifiability (read this before using C and h)
//! With Eq. 5's linearised radiation, `h` and radiation multiply the same regressor `θ`, and
//! `(C, α M^-1L C, q, h) → (sC, s α M^-1L C, s q, s h + (s-1) R)` leaves
//! Eq. 7 unchanged (times `s`): **only `λ = (h+R)/C` is identifiable, not `C` and `h`
//! separately.** `Δ_s`, `q/C` and `λ` are; they are also exactly what the shape stage
//! needs. With full `T^4` radiation the curvature `N(θ) ≈ 6εσ T_s^2
//! θ^2` separates them, but its relative size is about `1.5 θ/T_s` (1e-4 for a rise of
//! 0.05 K): [`Stage1Options::radiation`] = [`Radiation::Full`] fits `c` as a second global and
//! reports its uncertainty, which tells whether `C` was determined. A known `h` or `C`
//! ([`Stage1Options::known`]) gives the other from `λ`.
//!
//! **Uncertainty and the "not identifiable" verdict.** Besides the formal standard deviation
//! (below), the globals are refitted on the first and on the second half of the frame pairs;
//! half the difference is a floor on each σ. C and h are reported only if c = 1/C is at least
//! 1/[`Stage1Options::identifiable_rel_sigma`] (default 3) σ from zero; otherwise the split says
//! "not identifiable" and λ, q/C and Δ_s are the identified quantities.
//!
//! # Why a vertex's row is (almost) not identifiable from its own data
//! Under lamps that switch on once and stay on, conduction is a small correction (about 0.5 %
//! of the heating for PLA), so each video is close to separable, θ(x, t) ≈ β(x) g(t) with one
//! temporal profile g. Then every neighbour difference of vertex i is ≈ (Δβ) g(t), collinear with
//! θ_i(t) ≈ β_i g(t): per video, the data fix only one combination `Σ_j a_ij(β_j - β_i)`
//! of the row, i.e. **V videos give V constraints on a row of 3 (paired) or 6 (free) weights**.
//! The rest comes from the small departures from separability: a vertex's columns are
//! collinear to 1e-10 (condition numbers to 1e11), so the rows are solved orthogonally
//! ([`lsq`]) and the data must be exact to many digits (a float32 video at 300 K is not). On data
//! that follow the model the rows come out (0.02 % on exact synthetic data); noise, the time
//! rule's error and, at coarse pyramid levels, block averaging are amplified by the same
//! conditioning. Hence neighbouring rows tied by a graph regulariser ([`smooth`], strength
//! [`Stage1Options::smoothing`]: weak on noise-free data, strong on noisy data) and, for the
//! globals on noisy data, rows with fewer unknowns ([`Stencil::Paired`], exact for locally
//! affine surfaces; its floor against the true operator is printed by `--check` as
//! `operator_error_paired_floor`).
//!
//! # Stencils
//! [`weight_groups`] gives, per vertex, the weight unknowns: [`Stencil::Free`] one per
//! neighbour; [`Stencil::Paired`] one per pixel direction (horizontal, vertical, main
//! diagonal) shared by the two opposite neighbours (second difference regressor), a lone
//! neighbour on its own. The globals are fitted with [`Stage1Options::globals_stencil`] rows
//! (free rows are unbiased without noise, paired rows are robust to noise), then the rows are
//! re-estimated with [`Stage1Options::stencil`] and the graph regulariser, globals fixed, and
//! the fluxes follow by NNLS.
//!
//! # Solver
//! All unknowns enter linearly. Per vertex `i` the unknowns `x_i = (a_ij)_j, (b^v_i)_v ≥ 0`
//! form a tiny block (6 to 8 neighbours plus one flux per video) coupled to the others only
//! through the globals `u = (λ[, c])`. One pass over the data compresses, per vertex, its
//! equations `[A_i | B_i | y_i]` (regressors, `(-bar(θ)_i, -bar(N)_i)`, `dot(θ)_i`) into
//! the triangular square root `R_i` of their Gram matrix by Givens rotations ([`lsq`]), then
//! everything works on these small matrices, by orthogonal factorisations only (the columns of
//! a vertex are collinear to 1e-10 under lamps that stay on: normal equations square that and
//! lost the rows, [`lsq`] module doc):
//! 1. the profiled cost `φ(u) = Σ_i min_(x_i ≥ 0) ‖A_i x_i + B_i u - y_i‖^2` is convex
//!    and piecewise quadratic; for given `u` each vertex solves its NNLS (Lawson–Hanson);
//! 2. with the free sets fixed, `φ` is quadratic and its minimiser solves the 1 x 1 or
//!    2 x 2 system `Σ_i B_i^T (I - P_i) B_i u = Σ_i B_i^T (I-P_i) y_i` (variable
//!    projection; `P_i` the projector on vertex `i`'s free columns; each term from the trailing
//!    block of a QR of `[A_(i,F) | B_i | y_i]`); a backtracking line search keeps `φ`
//!    decreasing. Converges when the free sets stop changing (a handful of iterations).
//!
//! Edge weights are estimated **per row** (the row-scaled operator `a_ij`, fully decoupled),
//! then symmetrised ([`symmetrise()`]): masses from `m_i a_ij = m_j a_ji` in log space by
//! least squares over the edges, and `α w_ij = sqrt(m_i a_ij m_j a_ji)`. Both the
//! raw rows and the symmetrised operator are returned.
//!
//! **Uncertainty of the globals:** `cov(u) = hat(σ)^2 H^-1` with `H` the matrix of
//! step 2 (the Gauss–Newton Hessian of the profiled cost, accounting for the per-vertex
//! unknowns) and `hat(σ)^2` = residual sum of squares / (rows - unknowns); this assumes
//! independent errors in `dot(θ)` only (noise in the regressors is not accounted for).
//! `C = 1/c` and `h = λ/c - R` get theirs by first-order propagation.

pub mod bound;
pub mod denoise;
pub mod lsq;
pub mod smooth;
pub mod symmetrise;
pub mod synthetic;
pub mod time_rule;

pub use symmetrise::symmetrise;
pub use time_rule::{FrameRule, TimeRule};

use heatsim::camera::PixelGrid;
use rayon::prelude::*;

use crate::error::ReconError;
use crate::pyramid::Level;

/// Stefan–Boltzmann constant, W/(m^2 K^4).
pub const SIGMA: f64 = 5.670_374_419e-8;

/// Radiation model of the estimator.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Radiation {
    /// Eq. 5: only λ = (h + R)/C is estimated.
    Linearized,
    /// Full T^4: λ and c = 1/C are estimated.
    Full,
}

/// How a vertex's row of Δ_s is parameterised (the module doc of `heatrecon::stage1`, "Stencils").
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Stencil {
    /// One free weight per neighbour (6 for an interior vertex of the pixel mesh).
    Free,
    /// Opposite neighbours along the same pixel direction (horizontal, vertical, main
    /// diagonal) share one weight (3 for an interior vertex): exact for locally affine
    /// surfaces, where the cotangent weights of the two opposite edges are equal.
    Paired,
}

/// A known global parameter that fixes the split of λ into C and h.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Known {
    /// Nothing known: C and h from c (only with [`Radiation::Full`]).
    None,
    /// The convection coefficient h, W/(m^2 K).
    Convection(f64),
    /// The heat capacity per area C, J/(m^2 K).
    HeatCapacity(f64),
}

/// Options of stage 1.
#[derive(Clone, Debug)]
pub struct Stage1Options {
    /// Time rule of the equations (default [`TimeRule::Central`], chosen on the validation
    /// scenes: docs/notes/reconstruction-stage1.md and docs/notes/code-comments.md).
    pub time_rule: TimeRule,
    /// Radiation model.
    pub radiation: Radiation,
    /// Known parameter, if any.
    pub known: Known,
    /// Use equations whose frames are all at t >= `t_start` (s; lamps switch on at 0) ...
    pub t_start: f64,
    /// ... and at t <= `t_end` (s).
    pub t_end: f64,
    /// Maximum outer iterations (variable projection).
    pub max_iterations: usize,
    /// Constrain the edge weights to be non-negative (as the paper); cotangent weights of
    /// obtuse triangles are negative, so `false` lets them take any sign (fluxes stay >= 0).
    pub nonnegative_weights: bool,
    /// Parameterisation of the rows of Δ_s.
    pub stencil: Stencil,
    /// C and h are reported only when the relative standard deviation of c = 1/C is below this
    /// (default 1/3, i.e. c at least 3 σ from zero); otherwise "not identifiable".
    pub identifiable_rel_sigma: f64,
    /// Graph regularisation of the rows ([`smooth`]): `Some(kappa)` ties the weights of the same
    /// direction at neighbouring vertices with strength μ = κ · mean diagonal of the per-vertex
    /// Schur complements; `None` (or 0) leaves every row to its own data (ill-posed: the rows are
    /// nearly collinear, so any model error is amplified). [`Stage1Options::for_noise`] picks
    /// [`SMOOTHING_NOISE_FREE`] (scaled per pyramid level) or [`SMOOTHING_NOISY`], measured on
    /// the validation scenes (docs/notes/reconstruction-stage1.md), not by a data-driven rule.
    pub smoothing: Option<f64>,
    /// Stencil of the per-vertex fit that determines the globals (λ, c). `Free` is unbiased on
    /// noise-free data, where `Paired` biases C, but its six first-difference regressors fit
    /// noise, where `Paired` does far less (measured: docs/notes/code-comments.md).
    /// [`Stage1Options::for_noise`] picks `Free` below [`NOISE_FREE_BELOW`], else `Paired`.
    pub globals_stencil: Stencil,
}

/// Temporal noise (K) below which [`Stage1Options::for_noise`] treats data as noise-free.
pub const NOISE_FREE_BELOW: f64 = 1e-3;

/// Row smoothing κ for noise-free data at full resolution (pyramid level 0), multiplied by
/// [`SMOOTHING_LEVEL_FACTOR`] per coarser level. Chosen from sweeps of κ on backward-Euler
/// simulations of the validation scenes (central time rule,
/// `simbench reconstruct --stage 1 --check --clean --smoothing K`; the figures are in
/// docs/notes/reconstruction-stage1.md, "Noise-free smoothing per level", and
/// docs/notes/code-comments.md): at level 0 the error of Delta_s falls with κ down to 1e-7, and
/// 1e-6 beat 1e-5 on each of the six noise-free datasets of the shape-error table (not used to
/// choose it). 1e-6 rather than less keeps a margin from κ = 0, where the rows are ill-posed.
pub const SMOOTHING_NOISE_FREE: f64 = 1e-6;

/// Factor of the noise-free κ per pyramid level above 0: block averaging adds a model error
/// that more smoothing suppresses (level 1: 1e-5 beat 1e-6 on five of the six table datasets
/// and on both validation scenes; an earlier sweep, docs/notes/reconstruction-stage1.md: 1e-3
/// best at levels 2 and 3).
pub const SMOOTHING_LEVEL_FACTOR: f64 = 10.0;

/// Row smoothing κ for noisy data (NETD 50 mK, 640 x 512 hemisphere / bunny at full
/// resolution: flux correlation 0.993 / 0.979 at κ = 1, 0.930 / 0.906 at 0.1).
pub const SMOOTHING_NOISY: f64 = 1.0;

impl Stage1Options {
    /// The defaults for data at pyramid `level` (0: full resolution) whose temporal noise is
    /// `sigma` (K; `None`: unknown, treated as noisy): below [`NOISE_FREE_BELOW`], free rows for
    /// the globals and [`SMOOTHING_NOISE_FREE`] times [`SMOOTHING_LEVEL_FACTOR`]^level;
    /// otherwise paired rows for the globals and [`SMOOTHING_NOISY`].
    pub fn for_noise(sigma: Option<f64>, level: usize) -> Stage1Options {
        let noise_free = sigma.is_some_and(|s| s < NOISE_FREE_BELOW);
        let kappa_free = SMOOTHING_NOISE_FREE * SMOOTHING_LEVEL_FACTOR.powi(level.min(16) as i32);
        Stage1Options {
            time_rule: TimeRule::Central,
            radiation: Radiation::Full,
            known: Known::None,
            t_start: 0.0,
            t_end: f64::INFINITY,
            max_iterations: 50,
            nonnegative_weights: false,
            stencil: Stencil::Free,
            identifiable_rel_sigma: 1.0 / 3.0,
            smoothing: Some(if noise_free { kappa_free } else { SMOOTHING_NOISY }),
            globals_stencil: if noise_free { Stencil::Free } else { Stencil::Paired },
        }
    }
}

impl Default for Stage1Options {
    /// The noise-free defaults at full resolution ([`Stage1Options::for_noise`] with no noise).
    fn default() -> Self {
        Stage1Options::for_noise(Some(0.0), 0)
    }
}

/// Input of the estimator: the mesh and, per video, the rise per vertex and frame.
#[derive(Clone, Debug)]
pub struct Stage1Input {
    /// The pixel mesh.
    pub grid: PixelGrid,
    /// Per video: rise θ (K), layout `[vertex * frames + frame]`.
    pub series: Vec<Vec<f64>>,
    /// Frame times, s.
    pub times: Vec<f64>,
    /// Ambient temperature T_s, K.
    pub ambient: f64,
    /// Emissivity.
    pub emissivity: f64,
}

impl Stage1Input {
    /// From a pyramid level: the pixel mesh of its mask and the rise of its vertices.
    ///
    /// # Errors
    /// An empty mesh (mask without any 2 x 2 block of three pixels at this level).
    pub fn from_level(level: &Level, ambient: f64, emissivity: f64) -> Result<Stage1Input, ReconError> {
        let (w, h) = (level.camera.width, level.camera.height);
        let grid = PixelGrid::new(&level.mask, w, h);
        if grid.vertex_count() == 0 {
            return Err(ReconError::Input(format!(
                "the mask at pyramid level {} ({w} x {h}) has no triangle (no 2 x 2 block with 3 object pixels)",
                level.level
            )));
        }
        let frames = level.times.len();
        let series = level
            .rises
            .iter()
            .map(|r| {
                let mut s = vec![0.0; grid.vertex_count() * frames];
                for (i, &p) in grid.pixels.iter().enumerate() {
                    for k in 0..frames {
                        s[i * frames + k] = r[[k, p / w, p % w]];
                    }
                }
                s
            })
            .collect();
        Ok(Stage1Input { grid, series, times: level.times.clone(), ambient, emissivity })
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.times.len()
    }
}

/// A global estimate with its standard deviation (`None` where not determined).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Estimate {
    /// Value.
    pub value: f64,
    /// One standard deviation (see the module doc for how it is estimated).
    pub sigma: f64,
}

/// Everything stage 1 estimates.
#[derive(Clone, Debug)]
pub struct Stage1Result {
    /// The pixel mesh.
    pub grid: PixelGrid,
    /// Undirected edges (i < j), as [`PixelGrid::edges`].
    pub edges: Vec<[usize; 2]>,
    /// Per edge, the raw row estimates `[a_ij, a_ji]` (1/s): `a_ij = Δ_s[i, j]` from vertex i's row.
    pub row_weights: Vec<[f64; 2]>,
    /// Per edge, the symmetrised α w_ij in 1/s for masses normalised to mean 1:
    /// `Δ_s[i, j] = weights / masses[i]`.
    pub weights: Vec<f64>,
    /// Relative lumped masses (mean 1).
    pub masses: Vec<f64>,
    /// Per video and vertex, b = q / C (K/s).
    pub flux_over_c: Vec<Vec<f64>>,
    /// λ = (h + R)/C (1/s).
    pub lambda: Estimate,
    /// c = 1/C (m^2 K/J), if fitted.
    pub c: Option<Estimate>,
    /// R = 4 ε σ T_s^3 (W/(m^2 K)).
    pub radiation_coefficient: f64,
    /// C (J/(m^2 K)), when determined.
    pub heat_capacity: Option<Estimate>,
    /// h (W/(m^2 K)), when determined.
    pub convection: Option<Estimate>,
    /// How C and h were obtained.
    pub split: String,
    /// Per video and vertex, RMS residual of the equations (K/s).
    pub residual_rms: Vec<Vec<f64>>,
    /// Frame pairs used `(k, k + 1)`.
    pub pairs: Vec<usize>,
    /// Rows (equations) in all.
    pub rows: usize,
    /// Outer iterations done.
    pub iterations: usize,
    /// Final cost (sum of squared residuals, (K/s)^2).
    pub cost: f64,
    /// The graph regularisation, when used: `(kappa, mu, CG iterations, relative residual)`.
    pub smoothing: Option<(f64, f64, usize, f64)>,
}

/// A vertex's equations, compressed: the square root of their Gram matrix ([`lsq`]) for the
/// columns `[weight groups | fluxes | B (1 or 2) | y]`.
struct VertexData {
    /// Weight unknowns of the row: each multiplies `sum_{j in group} (θ_j - θ_i)`.
    nbrs: Vec<Vec<usize>>,
    /// Number of per-vertex unknowns p = neighbours + videos.
    p: usize,
    /// R (m x m, m = p + globals + 1) with R^T R = the Gram matrix of the columns.
    r: lsq::SqrtInfo,
}

impl VertexData {
    /// Column j of R.
    fn col(&self, j: usize) -> Vec<f64> {
        self.r.column(j)
    }

    /// The right-hand side of the per-vertex unknowns at globals `u`: R (y - B u).
    fn rhs(&self, u: &[f64]) -> Vec<f64> {
        let m = self.r.cols();
        let mut b = self.col(m - 1);
        for (q, &uq) in u.iter().enumerate() {
            let c = self.col(self.p + q);
            b.iter_mut().zip(&c).for_each(|(x, y)| *x -= uq * y);
        }
        b
    }
}

fn neighbours(grid: &PixelGrid) -> Vec<Vec<usize>> {
    let mut nb = vec![Vec::new(); grid.vertex_count()];
    for [i, j] in grid.edges() {
        nb[i].push(j);
        nb[j].push(i);
    }
    nb
}

/// The weight groups of every vertex under `stencil`: for [`Stencil::Free`] each neighbour
/// alone; for [`Stencil::Paired`] the neighbours at pixel offsets `+d` and `-d` together when
/// both are mesh neighbours (d = (1,0), (0,1), (1,1)), any other neighbour alone.
pub fn weight_groups(grid: &PixelGrid, stencil: Stencil) -> Vec<Vec<Vec<usize>>> {
    let nb = neighbours(grid);
    nb.iter()
        .enumerate()
        .map(|(i, list)| match stencil {
            Stencil::Free => list.iter().map(|&j| vec![j]).collect(),
            Stencil::Paired => {
                let (ui, vi) = grid.pixel_uv(i);
                let off = |j: usize| {
                    let (u, v) = grid.pixel_uv(j);
                    (u as i64 - ui as i64, v as i64 - vi as i64)
                };
                let mut used = vec![false; list.len()];
                let mut groups = Vec::new();
                for (a, &ja) in list.iter().enumerate() {
                    if used[a] {
                        continue;
                    }
                    used[a] = true;
                    let (du, dv) = off(ja);
                    let partner = list.iter().enumerate().position(|(b, &jb)| !used[b] && off(jb) == (-du, -dv));
                    match partner {
                        Some(b) => {
                            used[b] = true;
                            groups.push(vec![ja, list[b]]);
                        }
                        None => groups.push(vec![ja]),
                    }
                }
                groups
            }
        })
        .collect()
}

/// Radiation remainder N(θ) = εσ((T_s+θ)^4 - T_s^4 - 4 T_s^3 θ), W/m^2.
pub fn radiation_remainder(theta: f64, ts: f64, eps: f64) -> f64 {
    eps * SIGMA * theta * theta * (6.0 * ts * ts + 4.0 * ts * theta + theta * theta)
}

/// Runs stage 1 on `input`.
///
/// # Errors
/// Too few frame pairs for the unknowns of a vertex (paper Sec. 5), no usable pair, a
/// [`Known`] value that is not positive and finite.
pub fn estimate(input: &Stage1Input, opts: &Stage1Options) -> Result<Stage1Result, ReconError> {
    let (nv, videos) = (input.grid.vertex_count(), input.series.len());
    if videos == 0 {
        return Err(ReconError::Input("no video given".into()));
    }
    let eqs: Vec<(usize, FrameRule)> = opts.time_rule.equations(&input.times, opts.t_start, opts.t_end);
    let pairs: Vec<usize> = eqs.iter().map(|e| e.0).collect();
    // The globals are fitted with `globals_stencil` rows (free on noise-free data: the paired
    // stencil's small bias on curved surfaces leaks into them, C off by 18 % instead of 0.15 %
    // on the noise-free 160 x 128 hemisphere); the rows are then re-estimated with the chosen
    // stencil, globals fixed.
    let nb_free = weight_groups(&input.grid, opts.globals_stencil);
    let nb_list = weight_groups(&input.grid, opts.stencil);
    let max_p = nb_free.iter().map(Vec::len).max().unwrap_or(0) + videos;
    let nglob = match opts.radiation {
        Radiation::Linearized => 1,
        Radiation::Full => 2,
    };
    check_equations(pairs.len(), videos, max_p, nglob, opts)?;
    let rows_per_vertex = pairs.len() * videos;

    // 1. Per-vertex equations in square-root form, in parallel over vertices.
    // The split-sample check (step 3) needs the globals' rows of each half of the equations;
    // the full set is their merge (the same Gram matrix), so the data are passed once.
    let half = pairs.len() / 2;
    let halves = (half > max_p + nglob && videos * half > max_p + nglob).then(|| {
        (vertex_rows(input, &nb_free, &eqs[..half], nglob), vertex_rows(input, &nb_free, &eqs[half..], nglob))
    });
    let rows_free = match &halves {
        Some((first, second)) => first
            .par_iter()
            .zip(second)
            .map(|(a, b)| {
                let mut r = a.r.clone();
                r.merge(&b.r);
                VertexData { nbrs: a.nbrs.clone(), p: a.p, r }
            })
            .collect(),
        None => vertex_rows(input, &nb_free, &eqs, nglob),
    };

    // 2-3. The globals by variable projection, then the rows.
    let (u, mut sols, mut cost, iterations, h) = fit_globals(&rows_free, nglob, opts);
    let free_sets = sols.clone();
    let vertices =
        if opts.stencil == opts.globals_stencil { rows_free } else { vertex_rows(input, &nb_list, &eqs, nglob) };
    // 3b. Optional graph-regularised rows with the globals fixed.
    let mut smoothing_report = None;
    let kappa = opts.smoothing.filter(|&k| k > 0.0).unwrap_or(0.0);
    let refit_rows = kappa > 0.0 || opts.stencil != opts.globals_stencil;
    if refit_rows {
        let (regularised, report) = regularised_rows(input, opts, &vertices, &sols, &u, kappa);
        sols = regularised;
        smoothing_report = report;
    }

    let n_unknowns: usize = sols.iter().map(|s| s.1.iter().filter(|&&f| f).count()).sum::<usize>() + nglob;
    let rows = rows_per_vertex * nv;
    let mut cov = globals_covariance(&h, nglob, cost / (rows.saturating_sub(n_unknowns).max(1)) as f64);
    let (ts, eps) = (input.ambient, input.emissivity);
    let r_coef = 4.0 * eps * SIGMA * ts.powi(3);
    // Split-sample check of the globals: refit on the first and on the second half of the
    // frame pairs; half their difference is a floor on the standard deviations (it also
    // catches model error and regressor noise, which the formal one ignores).
    // Each half's globals by one variable-projection step with the full fit's free sets (the
    // exact minimiser when the sets do not change; a full refit tripled stage 1's time).
    let split_u: Option<(Vec<f64>, Vec<f64>)> = halves.map(|(first, second)| {
        let refit = |rows: &[VertexData]| {
            let (h, mut g) = newton_system(rows, nglob, &free_sets);
            if !lsq::chol_solve(&h, nglob, &mut g) {
                g.iter_mut().for_each(|x| *x = f64::NAN);
            }
            g
        };
        (refit(&first), refit(&second))
    });
    let spread = |q: usize| split_u.as_ref().map_or(0.0, |(a, b)| (a[q] - b[q]).abs() / 2.0);
    let lambda = Estimate { value: u[0], sigma: cov[0].sqrt().max(spread(0)) };
    let c = (nglob == 2).then(|| Estimate { value: u[1], sigma: cov[3].sqrt().max(spread(1)) });
    if nglob == 2 {
        cov[3] = cov[3].max(spread(1).powi(2));
    }
    cov[0] = cov[0].max(spread(0).powi(2));
    let (heat_capacity, convection, split) = split_lambda(opts, lambda, c, &u, &cov, r_coef);

    // 4. Unpack per-vertex unknowns.
    let edges = input.grid.edges();
    let (row_weights, flux_over_c) = unpack(&edges, &vertices, &sols, nv, videos);
    let (weights, masses) = symmetrise(nv, &edges, &row_weights);

    // 5. Residual per vertex and video (second pass over the data).
    let residual_rms = residuals(input, &vertices, &sols, &eqs, &u, nglob);
    if refit_rows {
        cost = residual_rms.iter().flatten().map(|r| r * r * pairs.len() as f64).sum();
    }
    Ok(Stage1Result {
        grid: input.grid.clone(),
        edges,
        row_weights,
        weights,
        masses,
        flux_over_c,
        lambda,
        c,
        radiation_coefficient: r_coef,
        heat_capacity,
        convection,
        split,
        residual_rms,
        pairs,
        rows,
        iterations,
        cost,
        smoothing: smoothing_report,
    })
}

/// Refuses too few equations per vertex (`pairs` frame pairs per video) for its up to `max_p`
/// unknowns and the `nglob` shared globals, and a known parameter that is not finite and >= 0.
fn check_equations(
    pairs: usize,
    videos: usize,
    max_p: usize,
    nglob: usize,
    opts: &Stage1Options,
) -> Result<(), ReconError> {
    let rows_per_vertex = pairs * videos;
    // Each vertex needs more equations than its own unknowns, plus a share of the globals.
    if rows_per_vertex < max_p + nglob + 1 {
        return Err(ReconError::Input(format!(
            "too few frames: {pairs} frame pairs x {videos} videos = {rows_per_vertex} equations per vertex, \
             but a vertex has up to {max_p} unknowns (edge weights and one flux per video) and \
             {nglob} global(s) are shared: need at least {} equations per vertex (paper Sec. 5); \
             frames from t = {} s to {} s were usable",
            max_p + nglob + 1,
            opts.t_start,
            opts.t_end
        )));
    }
    match opts.known {
        Known::Convection(x) | Known::HeatCapacity(x) if !(x.is_finite() && x >= 0.0) => {
            Err(ReconError::Input(format!("known parameter must be finite and >= 0, got {x}")))
        }
        _ => Ok(()),
    }
}

/// Each vertex's equations `eqs` in square-root form, with the weight groups `nb_list` and
/// `nglob` globals, in parallel over vertices.
fn vertex_rows(
    input: &Stage1Input,
    nb_list: &[Vec<Vec<usize>>],
    eqs: &[(usize, FrameRule)],
    nglob: usize,
) -> Vec<VertexData> {
    let (frames, nv, videos) = (input.frames(), input.grid.vertex_count(), input.series.len());
    let (ts, eps) = (input.ambient, input.emissivity);
    (0..nv)
        .into_par_iter()
        .map(|i| {
            let nbrs = nb_list[i].clone();
            let p = nbrs.len() + videos;
            let m = p + nglob + 1;
            let mut r = lsq::SqrtInfo::new(m);
            let mut row = vec![0.0; m];
            for (v, s) in input.series.iter().enumerate() {
                let at = |vert: usize, k: usize| s[vert * frames + k];
                for (_, rule) in eqs {
                    let bar = |vert: usize| FrameRule::apply(&rule.mix, |f| at(vert, f));
                    let ti = bar(i);
                    row.iter_mut().for_each(|x| *x = 0.0);
                    for (c, g) in nbrs.iter().enumerate() {
                        row[c] = g.iter().map(|&j| bar(j) - ti).sum();
                    }
                    row[nbrs.len() + v] = 1.0;
                    row[p] = -ti;
                    if nglob == 2 {
                        row[p + 1] = -FrameRule::apply(&rule.mix, |f| radiation_remainder(at(i, f), ts, eps));
                    }
                    row[m - 1] = FrameRule::apply(&rule.deriv, |f| at(i, f));
                    r.add_row(&mut row);
                }
            }
            VertexData { nbrs, p, r }
        })
        .collect()
}

/// A per-vertex solution: the unknowns, which are free (not at an NNLS bound), the cost.
type VertexSolution = (Vec<f64>, Vec<bool>, f64);

/// Step 3b: the rows re-estimated with the globals `u` fixed, graph-regularised with strength
/// `kappa` (`smooth`), warm-started from `sols`; the fluxes then by NNLS. Returns the new
/// solutions and the smoothing's report (kappa, mu, iterations, relative residual).
#[allow(clippy::type_complexity)]
fn regularised_rows(
    input: &Stage1Input,
    opts: &Stage1Options,
    vertices: &[VertexData],
    sols: &[VertexSolution],
    u: &[f64],
    kappa: f64,
) -> (Vec<VertexSolution>, Option<(f64, f64, usize, f64)>) {
    let class_of = |i: usize, j: usize| -> u8 {
        let (ui, vi) = input.grid.pixel_uv(i);
        let (uj, vj) = input.grid.pixel_uv(j);
        let (mut du, mut dv) = (uj as i64 - ui as i64, vj as i64 - vi as i64);
        if opts.stencil == Stencil::Paired && (du < 0 || (du == 0 && dv < 0)) {
            (du, dv) = (-du, -dv);
        }
        ((du + 1) * 3 + (dv + 1)) as u8
    };
    let blocks: Vec<smooth::Block> = vertices
        .par_iter()
        .enumerate()
        .map(|(i, vg)| {
            let (p, kw) = (vg.p, vg.nbrs.len());
            // Fluxes eliminated orthogonally: QR of [fluxes | weights | rhs]; the trailing
            // block T (weights and rhs) gives S = T_ww^T T_ww and r = T_ww^T t_wr.
            let nb = p - kw;
            let mut cols: Vec<Vec<f64>> = (kw..p).chain(0..kw).map(|j| vg.col(j)).collect();
            cols.push(vg.rhs(u));
            let (s_mat, r) = lsq::schur(&cols, nb);
            let class = vg.nbrs.iter().map(|g| class_of(i, g[0])).collect();
            smooth::Block { s: s_mat, r, class }
        })
        .collect();
    let warm: Vec<Vec<f64>> = vertices
        .iter()
        .zip(sols)
        .map(|(vg, s)| {
            if opts.stencil == opts.globals_stencil {
                s.0[..vg.nbrs.len()].to_vec()
            } else {
                vec![0.0; vg.nbrs.len()]
            }
        })
        .collect();
    let sol = smooth::solve(&blocks, &input.grid.edges(), kappa, &warm);
    let report = (kappa > 0.0).then_some((kappa, sol.mu, sol.iterations, sol.rel_residual));
    // Fluxes per vertex by NNLS given the weights; the globals stay those of the per-vertex
    // fit (refitting them with the regularised weights fixed was measured to be worse: C off
    // by 19 % instead of 0.4 % on the noise-free hemisphere at level 3).
    let sols = vertices
        .par_iter()
        .zip(&sol.w)
        .map(|(vg, w)| {
            let (p, kw) = (vg.p, vg.nbrs.len());
            let mut rhs = vg.rhs(u);
            for (c, &wc) in w.iter().enumerate() {
                let col = vg.col(c);
                rhs.iter_mut().zip(&col).for_each(|(x, y)| *x -= wc * y);
            }
            let flux_cols: Vec<Vec<f64>> = (kw..p).map(|j| vg.col(j)).collect();
            let (b, free) = lsq::nnls(&flux_cols, &rhs, &vec![false; p - kw]);
            let mut x = w.clone();
            x.extend(b);
            let mut f = vec![true; kw];
            f.extend(free);
            (x, f, 0.0)
        })
        .collect();
    (sols, report)
}

/// The formal covariance of the `nglob` globals, `sigma2` H^-1 (row-major; infinite where the
/// Gauss-Newton matrix `h` is singular).
fn globals_covariance(h: &[f64], nglob: usize, sigma2: f64) -> Vec<f64> {
    let mut cov = vec![0.0; nglob * nglob];
    for q in 0..nglob {
        let mut e = vec![0.0; nglob];
        e[q] = 1.0;
        if lsq::chol_solve(h, nglob, &mut e) {
            for s in 0..nglob {
                cov[s * nglob + q] = sigma2 * e[s];
            }
        } else {
            for s in 0..nglob {
                cov[s * nglob + q] = f64::INFINITY;
            }
        }
    }
    cov
}

/// C and h from lambda (and c = 1/C when fitted) as `opts.known` allows, with their standard
/// deviations from the globals' covariance `cov`, and how they were obtained.
fn split_lambda(
    opts: &Stage1Options,
    lambda: Estimate,
    c: Option<Estimate>,
    u: &[f64],
    cov: &[f64],
    r_coef: f64,
) -> (Option<Estimate>, Option<Estimate>, String) {
    match (opts.known, c) {
        (Known::Convection(hk), _) => {
            let cc = (hk + r_coef) / lambda.value;
            (
                Some(Estimate { value: cc, sigma: cc * lambda.sigma / lambda.value.abs() }),
                Some(Estimate { value: hk, sigma: 0.0 }),
                "h given; C = (h + R)/lambda".to_string(),
            )
        }
        (Known::HeatCapacity(ck), _) => {
            let hh = lambda.value * ck - r_coef;
            (
                Some(Estimate { value: ck, sigma: 0.0 }),
                Some(Estimate { value: hh, sigma: ck * lambda.sigma }),
                "C given; h = lambda C - R".to_string(),
            )
        }
        (Known::None, Some(c)) if c.value > 0.0 && c.sigma < opts.identifiable_rel_sigma * c.value => {
            let cc = 1.0 / c.value;
            let hh = u[0] / c.value - r_coef;
            // Jacobians: dC/d(lambda, c) = (0, -1/c^2); dh/d(lambda, c) = (1/c, -lambda/c^2).
            let jc = [0.0, -1.0 / (c.value * c.value)];
            let jh = [1.0 / c.value, -u[0] / (c.value * c.value)];
            let var = |j: [f64; 2]| {
                (0..2).flat_map(|a| (0..2).map(move |b| (a, b))).map(|(a, b)| j[a] * cov[a * 2 + b] * j[b]).sum::<f64>()
            };
            (
                Some(Estimate { value: cc, sigma: var(jc).max(0.0).sqrt() }),
                Some(Estimate { value: hh, sigma: var(jh).max(0.0).sqrt() }),
                "from c = 1/C fitted on the T^4 radiation curvature (full radiation model)".to_string(),
            )
        }
        (Known::None, Some(c)) => (
            None,
            None,
            format!(
                "not identifiable: c = 1/C = {:.3e} +- {:.1e} m^2 K/J from the T^4 curvature is not \
                 {:.1} sigma from zero; give h or C to split lambda",
                c.value,
                c.sigma,
                1.0 / opts.identifiable_rel_sigma
            ),
        ),
        (Known::None, None) => (
            None,
            None,
            "linearised radiation: only lambda = (h + R)/C is identifiable; give h or C to split it".to_string(),
        ),
    }
}

/// Each edge's two raw row weights (`edges` sorted) and each video's flux per vertex, from the
/// per-vertex solutions.
fn unpack(
    edges: &[[usize; 2]],
    vertices: &[VertexData],
    sols: &[VertexSolution],
    nv: usize,
    videos: usize,
) -> (Vec<[f64; 2]>, Vec<Vec<f64>>) {
    let mut row_weights = vec![[0.0f64; 2]; edges.len()];
    let mut flux_over_c = vec![vec![0.0; nv]; videos];
    let edge_index = |i: usize, j: usize| edges.binary_search(&[i.min(j), i.max(j)]).expect("edge of the grid");
    for (i, (vg, (x, _, _))) in vertices.iter().zip(sols).enumerate() {
        for (cidx, g) in vg.nbrs.iter().enumerate() {
            for &j in g {
                let e = edge_index(i, j);
                row_weights[e][usize::from(i > j)] = x[cidx];
            }
        }
        for (v, f) in flux_over_c.iter_mut().enumerate() {
            f[i] = x[vg.nbrs.len() + v];
        }
    }
    (row_weights, flux_over_c)
}

/// The RMS residual of the equations `eqs` per video and vertex (K/s) at the globals `u` and
/// the per-vertex solutions.
fn residuals(
    input: &Stage1Input,
    vertices: &[VertexData],
    sols: &[VertexSolution],
    eqs: &[(usize, FrameRule)],
    u: &[f64],
    nglob: usize,
) -> Vec<Vec<f64>> {
    let (frames, nv) = (input.frames(), input.grid.vertex_count());
    let (ts, eps) = (input.ambient, input.emissivity);
    input
        .series
        .iter()
        .enumerate()
        .map(|(v, s)| {
            (0..nv)
                .into_par_iter()
                .map(|i| {
                    let (vg, (x, _, _)) = (&vertices[i], &sols[i]);
                    let at = |vert: usize, k: usize| s[vert * frames + k];
                    let mut r2 = 0.0;
                    for (_, rule) in eqs {
                        let bar = |vert: usize| FrameRule::apply(&rule.mix, |f| at(vert, f));
                        let ti = bar(i);
                        let mut pred = x[vg.nbrs.len() + v] - u[0] * ti;
                        for (cidx, g) in vg.nbrs.iter().enumerate() {
                            pred += x[cidx] * g.iter().map(|&j| bar(j) - ti).sum::<f64>();
                        }
                        if nglob == 2 {
                            pred -= u[1] * FrameRule::apply(&rule.mix, |f| radiation_remainder(at(i, f), ts, eps));
                        }
                        let r = pred - FrameRule::apply(&rule.deriv, |f| at(i, f));
                        r2 += r * r;
                    }
                    (r2 / eqs.len() as f64).sqrt()
                })
                .collect()
        })
        .collect()
}

/// Variable projection over the globals (module doc, "Solver"): returns the globals, the
/// per-vertex solutions `(x, free set, cost)`, the total cost, the iterations and the final
/// Gauss-Newton matrix of the globals.
#[allow(clippy::type_complexity)]
fn fit_globals(
    vertices: &[VertexData],
    nglob: usize,
    opts: &Stage1Options,
) -> (Vec<f64>, Vec<VertexSolution>, f64, usize, Vec<f64>) {
    // Per-vertex solve at given globals: returns (x, free, cost_i).
    let solve_vertex = |vg: &VertexData, u: &[f64]| -> (Vec<f64>, Vec<bool>, f64) {
        let p = vg.p;
        let cols: Vec<Vec<f64>> = (0..p).map(|j| vg.col(j)).collect();
        let mut res = vg.rhs(u);
        let signed: Vec<bool> = (0..p).map(|a| a < vg.nbrs.len() && !opts.nonnegative_weights).collect();
        let (x, free) = lsq::nnls(&cols, &res, &signed);
        // ||A x - (y - B u)||^2 = ||R_A x - R (y - B u)||^2
        for (c, &xc) in cols.iter().zip(&x) {
            res.iter_mut().zip(c).for_each(|(r, v)| *r -= xc * v);
        }
        (x, free, res.iter().map(|r| r * r).sum())
    };
    let newton = |sols: &[(Vec<f64>, Vec<bool>, f64)]| newton_system(vertices, nglob, sols);
    let eval = |u: &[f64]| -> (Vec<VertexSolution>, f64) {
        let sols: Vec<_> = vertices.par_iter().map(|vg| solve_vertex(vg, u)).collect();
        let cost = sols.iter().map(|s| s.2).sum();
        (sols, cost)
    };

    // 2. Start from the unconstrained solution (all columns free), then variable projection.
    let all_free: Vec<VertexSolution> = vertices
        .iter()
        .map(|vg| (vec![], (0..vg.p).map(|a| vg.col(a).iter().any(|&x| x != 0.0)).collect(), 0.0))
        .collect();
    let solve_u = |h: &[f64], g: &[f64]| -> Vec<f64> {
        let mut u = g.to_vec();
        if !lsq::chol_solve(h, nglob, &mut u) {
            u.iter_mut().for_each(|x| *x = 0.0);
        }
        u
    };
    let (h0, g0) = newton(&all_free);
    let mut u = solve_u(&h0, &g0);
    let (mut sols, mut cost) = eval(&u);
    let mut iterations = 0;
    for it in 0..opts.max_iterations {
        iterations = it + 1;
        let (h, g) = newton(&sols);
        let target = solve_u(&h, &g);
        let rel_change =
            |a: &[f64]| a.iter().zip(&u).map(|(a, b)| ((a - b) / b.abs().max(1e-300)).abs()).fold(0.0, f64::max);
        // Converged: the free sets reproduce the current globals (no line search over a null step).
        if rel_change(&target) < 1e-12 {
            break;
        }
        let mut step = 1.0;
        let mut accepted = false;
        for _ in 0..30 {
            let trial: Vec<f64> = u.iter().zip(&target).map(|(a, b)| a + step * (b - a)).collect();
            let (s2, c2) = eval(&trial);
            if c2 < cost {
                let change = rel_change(&trial);
                let rel_gain = (cost - c2) / cost.max(f64::MIN_POSITIVE);
                u = trial;
                sols = s2;
                cost = c2;
                accepted = true;
                if change < 1e-12 || rel_gain < 1e-15 {
                    accepted = false;
                }
                break;
            }
            step *= 0.5;
        }
        if !accepted {
            break;
        }
    }

    // 3. Uncertainty from the final Hessian.
    let (h, _) = newton(&sols);
    (u, sols, cost, iterations, h)
}

/// The Newton system H u = g of the globals for the per-vertex free sets of `sols` (module
/// doc, "Solver", step 2).
fn newton_system(vertices: &[VertexData], nglob: usize, sols: &[(Vec<f64>, Vec<bool>, f64)]) -> (Vec<f64>, Vec<f64>) {
    vertices
        .par_iter()
        .zip(sols)
        .map(|(vg, (_, free, _))| {
            let (p, m) = (vg.p, vg.p + nglob + 1);
            // QR of [free columns | B | y]: the trailing block T gives the Schur complement
            // B^T (I - P_F) B = T_BB^T T_BB and B^T (I - P_F) y = T_BB^T t_By.
            let mut cols: Vec<Vec<f64>> = (0..p).filter(|&a| free[a]).map(|a| vg.col(a)).collect();
            let nf = cols.len();
            cols.extend((p..m).map(|j| vg.col(j)));
            lsq::schur(&cols, nf)
        })
        .collect::<Vec<_>>()
        .into_iter()
        // Summed in vertex order (rayon's reduce tree depends on scheduling): the same bits
        // on every run.
        .fold((vec![0.0; nglob * nglob], vec![0.0; nglob]), |(mut h1, mut g1), (h2, g2)| {
            h1.iter_mut().zip(&h2).for_each(|(a, b)| *a += b);
            g1.iter_mut().zip(&g2).for_each(|(a, b)| *a += b);
            (h1, g1)
        })
}

impl Stage1Result {
    /// The raw row-scaled operator Δ_s as `(i, j, value)` triplets, diagonal included
    /// (row i: a_ij off the diagonal, minus their sum on it).
    pub fn operator_rows(&self) -> Vec<(usize, usize, f64)> {
        let mut diag = vec![0.0; self.grid.vertex_count()];
        let mut out = Vec::with_capacity(2 * self.edges.len() + diag.len());
        for (&[i, j], &[aij, aji]) in self.edges.iter().zip(&self.row_weights) {
            out.push((i, j, aij));
            out.push((j, i, aji));
            diag[i] -= aij;
            diag[j] -= aji;
        }
        out.extend(diag.into_iter().enumerate().map(|(i, d)| (i, i, d)));
        out
    }

    /// The symmetrised operator Δ_s = diag(1/masses) W as triplets, diagonal included.
    pub fn operator_symmetric(&self) -> Vec<(usize, usize, f64)> {
        let mut diag = vec![0.0; self.grid.vertex_count()];
        let mut out = Vec::with_capacity(2 * self.edges.len() + diag.len());
        for (&[i, j], &w) in self.edges.iter().zip(&self.weights) {
            out.push((i, j, w / self.masses[i]));
            out.push((j, i, w / self.masses[j]));
            diag[i] -= w / self.masses[i];
            diag[j] -= w / self.masses[j];
        }
        out.extend(diag.into_iter().enumerate().map(|(i, d)| (i, i, d)));
        out
    }
}
