//! The shape energy of stage 2 (paper Eq. 11) as a function of one depth per vertex, with its
//! analytic gradient.
//!
//! **Unknowns.** Vertex i sits on its pixel's ray, `x_i = z_i d_i` in camera coordinates (m),
//! `d_i = K^-1(u_i, v_i, 1)^T`, `z_i` its depth along the optical axis (m).
//!
//! **Data term.** With `L(x)` the cotangent Laplacian (weights `w_ij`) and `m_i(x)` the
//! barycentric lumped areas of the current vertices, the heat residual divided by C (K/s), per
//! vertex i, frame pair k and video v, is
//! `r = dot(θ)_i - Σ_j a_ij (bar(θ)_j - bar(θ)_i) + λ bar(θ)_i
//!        + c N(bar(θ)_i) - b_(v,i), a_ij = α w_ij/m_i,`
//! with `bar(θ)` the time rule's mix of frames k and k+1 (as stage 1), `λ=(h+R)/C`,
//! `c = 1/C` (0 when unknown), `N` the radiation beyond Eq. 5 and `b = q/C`. All but the
//! Laplacian are fixed by the data, so `r = y - a_i · g` with `g_j = bar(θ)_j -
//! bar(θ)_i`, and the L2 data term is a quadratic form in each vertex's row `a_i`:
//! `Σ_(k,v) r^2 = a_i^T G_i a_i - 2 a_i^T f_i + Y_i`, the per-vertex Gram matrix built once
//! (cost per evaluation O(vertices), independent of the frame count). The data energy is
//! `E_d = Σ_i (…) / (n_rows bar(b)^2)`: the mean squared residual relative to the
//! squared mean flux `bar(b)` (dimensionless). Minimising it is fitting the shape's operator to
//! the stage-1 rows in the metric of the data (`E_i = (a_i-hat(a)_i)^T G_i (a_i - hat(a)_i)` +
//! const).
//!
//! **Profiled flux** (`HeatData::profile_flux`): minimising over a constant `b` per vertex and
//! video replaces each row by its deviation from its mean over frame pairs (per video), so
//! that the fit uses the time-varying part of conduction only and a biased flux image (from
//! stage 1, whose rows are uncertain) cannot bias the shape. The flux images still give the
//! half-space term.
//!
//! **Boundary rings** (`HeatData::boundary_rings`): the vertices within k rings of the mask's
//! boundary carry no data term. Their pixels are partly covered (and at coarse levels block
//! averages of partly covered blocks), so their temperatures are not those of the surface
//! point on their ray, and their rows see a truncated neighbourhood; their depths follow from
//! the regularisers and their neighbours.
//!
//! **Profiled globals** (`HeatData::profile_globals`, robust loss only): lambda and c enter
//! the residual linearly, `r = y + δ_λ bar(θ)_i + δ_c N(bar(θ)_i) - a_i ·
//! g`, so each row gains two columns and each vertex's squared residual is a quadratic in the
//! corrections `δ`. They are minimised at every evaluation by iteratively reweighted least
//! squares and Newton steps, and the shape gradient is taken at the optimum (envelope
//! theorem). The robust loss is convex in `δ` only while no vertex's noise-corrected
//! `e_i` is negative; at NETD 50 mK many are, the clamp bends them sharply, and the minimiser
//! found jumps with the shape (docs/notes/reconstruction-stage2.md, "The profiled globals made
//! the 50 mK energy discontinuous": L-BFGS's line search then stops early). The shape then no
//! longer inherits stage 1's error in lambda, which at coarse levels sets a wrong size
//! (measured: docs/notes/code-comments.md). [`energy_at_globals`] takes the corrections as given instead, with
//! their gradient `∂ E/∂ δ = Σ_i ∂ E/∂ e_i 2(H_i u - b_i)`:
//! a smooth function of depths and globals together, for their joint minimisation
//! (`super::coarse_to_fine`).
//!
//! **Noise** (`HeatData::noise_cov`): noise in the temperatures enters both the neighbour
//! differences and the rest of each row, so each Gram matrix carries the expected outer
//! product of the row noise (errors in variables). Left in, it penalises large Laplacian
//! weights `w/m`, i.e. it pushes the shape away from the camera (a larger surface has smaller
//! `w/m`): on the 50 mK hemisphere the true depth scored twice the data energy of a shape
//! blown up to metres. With the noise's temporal covariance given, that expectation is
//! subtracted from every Gram matrix ([`super::noise`]), so the data energy is an unbiased
//! estimate of the noise-free one (corrected least squares).
//!
//! **Scale.** Cotangent weights are scale invariant and areas scale as `s^2`: `α` fixes the
//! metric size. [`Scale::Diffusivity`] uses the material's `α` (m^2/s, metric result);
//! [`Scale::Profiled`] minimises over `α` at every evaluation (L2: in closed form,
//! `α^* = Σ tilde(a)^T f / Σ tilde(a)^T G tilde(a)` with `tilde(a) = w/m`; robust:
//! jointly with the profiled globals, since each vertex's squared residual is a quadratic in
//! `(α, δ_λ, δ_c)`, by the same reweighted least squares; the gradient at
//! the optimum by the envelope theorem), leaving the shape's size free: the caller fixes it
//! with a nominal distance, or scales the shape to the known diffusivity afterwards
//! (`super::coarse_to_fine`).
//!
//! **Robust variant** ([`DataTerm::robust`]): the mean over
//! vertices of each vertex's RMS residual, `E_d = 1/(V bar(b))Σ_i sqrt(s(e_i) + δ^2)`
//! (`e_i` its mean squared residual over pairs and videos, `δ = 10^-3 bar(b)`): an L1 norm
//! across vertices (as the authors' L1 mean) that keeps the Gram form, so that a few vertices
//! whose coarse operator is poor (the grazing rim) cannot dominate the fit. With the noise
//! correction a vertex's `e_i` can be negative; `s(e) = (e + sqrt(e^2 + δ^4))/2` is a
//! smooth `max(0, e)` (`robust_rho`). A hard clamp made the energy non-smooth where `e_i`
//! crosses 0, and its gradient had been taken as if unclamped: on the 50 mK bunny L-BFGS's
//! line search failed after 14 iterations of 600 with the predicted decrease of the
//! direction 500 times the actual rise.
//!
//! **Normal consistency** (dimensionless): mean over interior edges of `1 - n_f · n_g` for
//! the unit normals of the two faces sharing it.
//!
//! **Half space** (paper Eq. 10, dimensionless): `1/V Σ_i max(-N_i n_i · e, 0)`
//! with `n_i` the area-weighted unit vertex normal, `N_i ∈ {-1,0,1}` stage 1's half-space
//! image and `e` the unit lamp axis in camera coordinates (pointing from video 2's lamp towards
//! video 1's).
//!
//! **Mirror symmetry** (optional, dimensionless, [`super::symmetry`]): the mean squared
//! difference between each depth and its mirror's about the mask's centre column, relative to
//! a reference depth.
//!
//! Total: `E = E_d + w_sm E_sm + w_hs E_hs (+ w_sy E_sy)`; gradients through
//! `heatsim::surface::derivatives` (weights and areas) and by hand for the normals, then
//! `∂ E/∂ z_i = d_i · ∂ E/∂ x_i`.

use heatsim::surface::derivatives::LaplacianVjp;
use heatsim::surface::operators::{lumped_area, AreaMass, CotanLaplacian};
use heatsim::vec3::{add, cross, dot, norm, scale, sub};
use rayon::prelude::*;

use super::lamp_shading::LampShading;
use super::noise::RowNoise;
use super::profile::{profile_unknowns, profile_value, robust_rho, Part};
use super::symmetry::MirrorSymmetry;
use crate::error::ReconError;
#[cfg(feature = "experimental")]
use crate::experimental::lamp_ratio::LampRatio;
use crate::stage1::radiation_remainder;

/// How the diffusivity factor of the Laplacian is fixed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scale {
    /// Known diffusivity alpha = k/(rho c_p), m^2/s: metric shape.
    Diffusivity(f64),
    /// alpha minimised in closed form at every evaluation; the size of the shape is set by the
    /// caller (nominal distance).
    Profiled,
}

/// The pixel mesh with its rays and the connectivity the energy needs.
#[derive(Clone, Debug)]
pub struct RayMesh {
    /// Ray direction per vertex, camera frame, z component 1.
    pub dirs: Vec<[f64; 3]>,
    /// Triangles (towards the camera).
    pub tris: Vec<[usize; 3]>,
    /// Undirected edges (i < j), sorted (the Laplacian's and the VJP's order).
    pub edges: Vec<[usize; 2]>,
    /// Per vertex, (neighbour, edge index), neighbours increasing.
    pub nbrs: Vec<Vec<(usize, usize)>>,
    /// Pairs of triangles sharing an edge.
    pub face_pairs: Vec<[usize; 2]>,
    vjp: LaplacianVjp,
}

impl RayMesh {
    /// From ray directions and triangles.
    ///
    /// # Errors
    /// Bad triangles (out of range, repeated vertex).
    pub fn new(dirs: Vec<[f64; 3]>, tris: Vec<[usize; 3]>) -> Result<RayMesh, ReconError> {
        let n = dirs.len();
        let vjp = LaplacianVjp::new(n, &tris).map_err(|e| ReconError::Input(format!("stage 2 mesh: {e}")))?;
        let edges = vjp.edges().to_vec();
        let mut nbrs = vec![Vec::new(); n];
        for (e, &[i, j]) in edges.iter().enumerate() {
            nbrs[i].push((j, e));
            nbrs[j].push((i, e));
        }
        for l in &mut nbrs {
            l.sort_unstable();
        }
        let mut by_edge: Vec<([usize; 2], usize)> = Vec::with_capacity(3 * tris.len());
        for (t, tri) in tris.iter().enumerate() {
            for c in 0..3 {
                let (a, b) = (tri[c], tri[(c + 1) % 3]);
                by_edge.push(([a.min(b), a.max(b)], t));
            }
        }
        by_edge.sort_unstable();
        let face_pairs = by_edge.windows(2).filter(|w| w[0].0 == w[1].0).map(|w| [w[0].1, w[1].1]).collect();
        Ok(RayMesh { dirs, tris, edges, nbrs, face_pairs, vjp })
    }

    /// Number of vertices.
    pub fn len(&self) -> usize {
        self.dirs.len()
    }

    /// The VJP connectivity of the cotangent weights and areas of this mesh.
    pub(crate) fn vjp(&self) -> &LaplacianVjp {
        &self.vjp
    }

    /// Whether there is no vertex.
    pub fn is_empty(&self) -> bool {
        self.dirs.is_empty()
    }

    /// Per vertex, its distance in edges from the mesh boundary (0 on the boundary).
    pub fn boundary_distance(&self) -> Vec<usize> {
        let on = heatsim::surface::operators::boundary_vertices(self.len(), &self.tris);
        let mut dist: Vec<usize> = on.iter().map(|&b| if b { 0 } else { usize::MAX }).collect();
        let mut front: Vec<usize> = (0..self.len()).filter(|&i| on[i]).collect();
        let mut k = 0;
        while !front.is_empty() {
            k += 1;
            let mut next = Vec::new();
            for &i in &front {
                for &(j, _) in &self.nbrs[i] {
                    if dist[j] == usize::MAX {
                        dist[j] = k;
                        next.push(j);
                    }
                }
            }
            front = next;
        }
        dist
    }

    /// Vertex positions (m, camera frame) for depths `z` (m).
    pub fn positions(&self, z: &[f64]) -> Vec<[f64; 3]> {
        self.dirs.iter().zip(z).map(|(d, &z)| scale(*d, z)).collect()
    }

    /// Area-weighted unit vertex normals (towards the camera) at depths `z`.
    pub fn normals(&self, z: &[f64]) -> Vec<[f64; 3]> {
        heatsim::surface::operators::vertex_normals(&self.positions(z), &self.tris)
    }
}

/// The data term's per-vertex Gram matrices (module doc).
#[derive(Clone, Debug)]
pub struct DataTerm {
    /// Per vertex, row-major (p+1) x (p+1): [G f; f^T Y] with p = its neighbour count.
    grams: Vec<Vec<f64>>,
    /// Equations in all (vertices x pairs x videos).
    pub rows: usize,
    /// 1 / (rows * mean(b)^2): the normalisation of the data energy.
    pub norm: f64,
    /// Mean flux |b| (K/s).
    pub mean_b: f64,
    /// Robust per-vertex loss (see [`DataTerm::robust`]).
    pub robust: bool,
    /// Extra columns per row: 2 (theta, N(theta)) when lambda and c are profiled, else 0.
    pub extra: usize,
    /// Stage 1's lambda (1/s) and c (m^2 K/J), the values the profiled corrections start from.
    pub lambda0: f64,
    /// See `lambda0`.
    pub c0: f64,
}

/// What the data term needs besides the mesh: the videos and stage 1's parameters.
#[derive(Clone, Debug)]
pub struct HeatData<'a> {
    /// Per video, rise theta (K) as `[vertex * frames + frame]`.
    pub series: &'a [Vec<f64>],
    /// Frame times, s.
    pub times: &'a [f64],
    /// Frame pairs (k, k+1) used, by k.
    pub pairs: &'a [usize],
    /// Weight of frame k+1 in the mix (1 backward Euler, 1/2 trapezoid).
    pub time_weight: f64,
    /// lambda = (h + R)/C, 1/s.
    pub lambda: f64,
    /// c = 1/C (m^2 K/J), 0 to leave out the radiation remainder.
    pub c_inv: f64,
    /// Per video and vertex, b = q/C (K/s).
    pub flux_over_c: &'a [Vec<f64>],
    /// Ambient temperature, K.
    pub ambient: f64,
    /// Emissivity.
    pub emissivity: f64,
    /// Minimise over a constant flux per vertex and video instead of using `flux_over_c`
    /// (module doc): the data term then sees only the time-varying part of the heat equation.
    pub profile_flux: bool,
    /// Leave out of the data term the vertices within this many rings of the mesh boundary
    /// (module doc; 0 keeps all).
    pub boundary_rings: usize,
    /// Minimise over lambda and c as well (module doc; robust loss only).
    pub profile_globals: bool,
    /// Per video, the temporal covariance of the noise in `series` (K^2, frames x frames,
    /// row-major; the same for every vertex, independent between vertices), whose expected
    /// contribution is removed from the Gram matrices (module doc, [`super::noise`]); empty for
    /// no correction.
    pub noise_cov: &'a [Vec<f64>],
}

impl DataTerm {
    /// Accumulates the Gram matrices.
    ///
    /// # Errors
    /// Sizes that do not match the mesh, no frame pair.
    pub fn new(mesh: &RayMesh, d: &HeatData) -> Result<DataTerm, ReconError> {
        let nv = mesh.len();
        let frames = d.times.len();
        if d.series.is_empty() || d.series.len() != d.flux_over_c.len() {
            return Err(ReconError::Input(format!(
                "stage 2: {} videos but {} flux images",
                d.series.len(),
                d.flux_over_c.len()
            )));
        }
        for (s, b) in d.series.iter().zip(d.flux_over_c) {
            if s.len() != nv * frames || b.len() != nv {
                return Err(ReconError::Input(format!(
                    "stage 2: series of {} values / flux of {} for {nv} vertices x {frames} frames",
                    s.len(),
                    b.len()
                )));
            }
        }
        if d.pairs.is_empty() {
            return Err(ReconError::Input("stage 2: no frame pair to fit".into()));
        }
        let w = d.time_weight;
        if !d.noise_cov.is_empty() && d.noise_cov.len() != d.series.len() {
            return Err(ReconError::Input(format!(
                "stage 2: {} noise covariances for {} videos",
                d.noise_cov.len(),
                d.series.len()
            )));
        }
        let row_noise = d
            .noise_cov
            .iter()
            .map(|cov| RowNoise::new(cov, d.times, d.pairs, w, d.lambda, d.profile_flux))
            .collect::<Result<Vec<_>, _>>()?;
        let ring = mesh.boundary_distance();
        let extra = if d.profile_globals { 2 } else { 0 };
        let grams: Vec<Vec<f64>> = (0..nv)
            .into_par_iter()
            .map(|i| {
                let nb = &mesh.nbrs[i];
                let p = nb.len();
                let m = p + 1 + extra;
                let mut g = vec![0.0; m * m];
                if ring[i] < d.boundary_rings {
                    return g;
                }
                let mut rows = vec![0.0; d.pairs.len() * m];
                for (v, (s, b)) in d.series.iter().zip(d.flux_over_c).enumerate() {
                    let at = |v: usize, k: usize| s[v * frames + k];
                    for (row, &k) in rows.chunks_exact_mut(m).zip(d.pairs) {
                        let dt = d.times[k + 1] - d.times[k];
                        let bar = |v: usize| w * at(v, k + 1) + (1.0 - w) * at(v, k);
                        let ti = bar(i);
                        for (c, &(j, _)) in nb.iter().enumerate() {
                            row[c] = bar(j) - ti;
                        }
                        row[p] = (at(i, k + 1) - at(i, k)) / dt
                            + d.lambda * ti
                            + d.c_inv * radiation_remainder(ti, d.ambient, d.emissivity)
                            - b[i];
                        if extra == 2 {
                            row[p + 1] = ti;
                            row[p + 2] = radiation_remainder(ti, d.ambient, d.emissivity);
                        }
                    }
                    if d.profile_flux {
                        // Minimising over a constant b per vertex and video centres the rows.
                        let mut mean = vec![0.0; m];
                        for row in rows.chunks_exact(m) {
                            mean.iter_mut().zip(row).for_each(|(a, r)| *a += r / d.pairs.len() as f64);
                        }
                        for row in rows.chunks_exact_mut(m) {
                            row.iter_mut().zip(&mean).for_each(|(r, a)| *r -= a);
                        }
                    }
                    for row in rows.chunks_exact(m) {
                        for r in 0..m {
                            for c in 0..m {
                                g[r * m + c] += row[r] * row[c];
                            }
                        }
                    }
                    if let Some(rn) = row_noise.get(v) {
                        rn.subtract_from(&mut g, p, extra);
                    }
                }
                g
            })
            .collect();
        let rows = nv * d.pairs.len() * d.series.len();
        let nb_total = (nv * d.series.len()) as f64;
        let mean_b = d.flux_over_c.iter().flatten().sum::<f64>() / nb_total;
        let mean_b = if mean_b.abs() > 0.0 { mean_b } else { 1.0 };
        Ok(DataTerm {
            grams,
            rows,
            norm: 1.0 / (rows as f64 * mean_b * mean_b),
            mean_b: mean_b.abs(),
            robust: false,
            extra,
            lambda0: d.lambda,
            c0: d.c_inv,
        })
    }
}

/// Weights of the regularisers and the half-space data.
#[derive(Clone, Debug)]
pub struct Regularisers {
    /// Normal-consistency weight.
    pub normal_consistency: f64,
    /// Half-space hinge weight.
    pub halfspace: f64,
    /// Per vertex, N in {-1, 0, 1} (empty: no half-space term).
    pub halfspace_sign: Vec<i8>,
    /// Unit lamp axis e, camera frame.
    pub lamp_axis: [f64; 3],
    /// The two-light flux ratio (`crate::experimental::lamp_ratio`) and its weight; `None`: no
    /// such term.
    #[cfg(feature = "experimental")]
    pub lamp_ratio: Option<(LampRatio, f64)>,
    /// Shading by calibrated lamps ([`super::lamp_shading`]) and its weight; `None`: no such term.
    pub lamp_shading: Option<(LampShading, f64)>,
    /// Mirror symmetry of the depth ([`super::symmetry`]) and its weight; `None`: no such term.
    pub symmetry: Option<(MirrorSymmetry, f64)>,
}

impl Regularisers {
    /// Normal consistency of weight `w` alone (no half-space term).
    pub fn normal_only(w: f64) -> Regularisers {
        Regularisers {
            normal_consistency: w,
            halfspace: 0.0,
            halfspace_sign: Vec::new(),
            lamp_axis: [1.0, 0.0, 0.0],
            #[cfg(feature = "experimental")]
            lamp_ratio: None,
            lamp_shading: None,
            symmetry: None,
        }
    }
}

/// The terms of the energy at one point.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Terms {
    /// Total.
    pub total: f64,
    /// Data term (relative mean squared residual).
    pub data: f64,
    /// Normal consistency (unweighted).
    pub normal: f64,
    /// Half-space hinge (unweighted).
    pub halfspace: f64,
    /// Two-light flux ratio term (unweighted; 0 without one).
    pub lamp_ratio: f64,
    /// Lamp-shading term (unweighted; 0 without one).
    pub lamp_shading: f64,
    /// Its profiled beta = absorptivity / (4 pi C), m^2 K/J (0 without the term).
    pub lamp_beta: f64,
    /// Mirror-symmetry term (unweighted; 0 without one).
    pub symmetry: f64,
    /// The diffusivity used (given, or the profiled optimum), m^2/s.
    pub alpha: f64,
    /// RMS heat residual, K/s.
    pub rms_residual: f64,
    /// lambda = (h + R)/C used (stage 1's, or profiled), 1/s.
    pub lambda: f64,
    /// c = 1/C used (stage 1's, or profiled), m^2 K/J.
    pub c_inv: f64,
}

/// Per vertex, the data term's quadratic in alpha, (q, l, Y) with ã = w/m:
/// the squared residual summed over its rows is alpha² q - 2 alpha l + Y (K²/s²).
fn vertex_quadratics(mesh: &RayMesh, data: &DataTerm, weights: &[f64], m: &[f64]) -> Vec<(f64, f64, f64)> {
    (0..mesh.len())
        .into_par_iter()
        .with_min_len(512)
        .map(|i| {
            let nb = &mesh.nbrs[i];
            let p = nb.len();
            let mm = p + 1 + data.extra;
            let g = &data.grams[i];
            let at: Vec<f64> = nb.iter().map(|&(_, e)| weights[e] / m[i]).collect();
            let (mut q, mut l) = (0.0, 0.0);
            for r in 0..p {
                let mut s = 0.0;
                for c in 0..p {
                    s += g[r * mm + c] * at[c];
                }
                q += at[r] * s;
                l += at[r] * g[r * mm + p];
            }
            (q, l, g[p * mm + p])
        })
        .collect()
}

/// Per vertex, its squared residual summed over its rows as a quadratic in the profiled
/// unknowns u = (alpha, dlambda, dc): e_i(u) = Y_i - 2 b_i.u + u^T H_i u (H packed as
/// [00, 01, 02, 11, 12, 22]); the last two are zero without the globals' columns.
fn vertex_profiles(mesh: &RayMesh, data: &DataTerm, weights: &[f64], m: &[f64]) -> Vec<Part> {
    vertex_quadratics(mesh, data, weights, m)
        .into_par_iter()
        .enumerate()
        .with_min_len(512)
        .map(|(i, (q, l, y))| {
            let (mut b, mut h) = ([l, 0.0, 0.0], [q, 0.0, 0.0, 0.0, 0.0, 0.0]);
            if data.extra == 2 {
                let nb = &mesh.nbrs[i];
                let p = nb.len();
                let mm = p + 3;
                let g = &data.grams[i];
                for t in 0..2 {
                    let row = &g[(p + 1 + t) * mm..(p + 2 + t) * mm];
                    // residual r = y + d_t col_t - alpha a.g: the cross term with alpha is
                    // -alpha d_t (col_t . a.g), with y +d_t (col_t . y).
                    b[1 + t] = -row[p];
                    h[1 + t] = -nb.iter().enumerate().map(|(c, &(_, e))| row[c] * weights[e] / m[i]).sum::<f64>();
                }
                let at = |r: usize, c: usize| g[(p + 1 + r) * mm + p + 1 + c];
                h[3] = at(0, 0);
                h[4] = at(0, 1);
                h[5] = at(1, 1);
            }
            (y, b, h)
        })
        .collect()
}

/// Per vertex, the RMS heat residual (K/s) over its frame pairs and videos at depths `z` with
/// diffusivity `alpha` (m^2/s): the stage-2 residual map.
pub fn vertex_rms_residual(mesh: &RayMesh, data: &DataTerm, terms: &Terms, z: &[f64]) -> Vec<f64> {
    let x = mesh.positions(z);
    let lap = CotanLaplacian::new(&x, &mesh.tris);
    let m = lumped_area(&x, &mesh.tris, AreaMass::Barycentric);
    let per_vertex_rows = (data.rows / mesh.len().max(1)).max(1) as f64;
    let u = [terms.alpha, terms.lambda - data.lambda0, terms.c_inv - data.c0];
    let e: Vec<f64> =
        vertex_profiles(mesh, data, &lap.weights, &m).iter().map(|(y, b, h)| profile_value(*y, b, h, u)).collect();
    e.into_iter().map(|e| (e.max(0.0) / per_vertex_rows).sqrt()).collect()
}

/// Energy and gradient with respect to the depths (module doc). `grad` gets dE/dz (1/m).
///
/// Non-finite geometry (a degenerate triangle, a depth <= 0) gives a non-finite energy.
pub fn energy(
    mesh: &RayMesh,
    data: &DataTerm,
    reg: &Regularisers,
    scale_: Scale,
    z: &[f64],
    grad: Option<&mut [f64]>,
) -> Terms {
    energy_core(mesh, data, reg, scale_, z, None, grad, None)
}

/// [`energy`] with the globals' corrections `d` = (dlambda (1/s), dc (m^2 K/J)) from stage 1's
/// values given instead of profiled: the energy is then a smooth function of the depths and
/// `d` together, for a joint minimisation (the profile's minimiser jumps with the depths at
/// 50 mK, module doc). `grad_globals` gets dE/dd. Needs the globals' columns
/// ([`HeatData::profile_globals`]); without them `d` is ignored and its gradient is 0.
#[allow(clippy::too_many_arguments)]
pub fn energy_at_globals(
    mesh: &RayMesh,
    data: &DataTerm,
    reg: &Regularisers,
    scale_: Scale,
    z: &[f64],
    d: [f64; 2],
    grad: Option<&mut [f64]>,
    grad_globals: Option<&mut [f64; 2]>,
) -> Terms {
    energy_core(mesh, data, reg, scale_, z, Some(d), grad, grad_globals)
}

#[allow(clippy::too_many_arguments)]
fn energy_core(
    mesh: &RayMesh,
    data: &DataTerm,
    reg: &Regularisers,
    scale_: Scale,
    z: &[f64],
    given: Option<[f64; 2]>,
    grad: Option<&mut [f64]>,
    grad_globals: Option<&mut [f64; 2]>,
) -> Terms {
    let x = mesh.positions(z);
    let (weights, m) = mesh.vjp.weights_and_masses(&x, AreaMass::Barycentric);
    let nv = mesh.len();
    let per_vertex_rows = (data.rows / nv.max(1)) as f64;
    let delta2 = (1e-3 * data.mean_b).powi(2);
    // Robust: E_d = mean_i sqrt(e_i + delta^2) / mean(b), e_i the vertex's mean squared residual.
    let robust = data.robust;
    let parts = vertex_profiles(mesh, data, &weights, &m);
    // The profiled unknowns: alpha when profiled, the globals' corrections with their columns.
    let (alpha0, free_alpha) = match scale_ {
        Scale::Diffusivity(a) => (a, false),
        Scale::Profiled => (0.0, true),
    };
    // Profiled globals: robust loss only (module doc), and not when given.
    let globals = data.extra == 2 && robust && given.is_none();
    let d0 = given.filter(|_| data.extra == 2).unwrap_or([0.0; 2]);
    let mut u = profile_unknowns(&parts, [alpha0, d0[0], d0[1]], [free_alpha, false, false], false, 1.0, 0.0);
    if robust {
        u = profile_unknowns(&parts, u, [free_alpha, globals, globals], robust, per_vertex_rows, delta2);
    }
    let (alpha, d) = (u[0], [u[1], u[2]]);
    let e: Vec<f64> = parts.par_iter().with_min_len(4096).map(|(y, b, h)| profile_value(*y, b, h, u)).collect();
    let sse: f64 = e.iter().sum();
    // Per vertex, rho and d rho / d e.
    let (rho, drho): (Vec<f64>, Vec<f64>) = if robust {
        e.par_iter()
            .with_min_len(4096)
            .map(|&e| {
                let (r, d) = robust_rho(e / per_vertex_rows, delta2);
                (r, d / per_vertex_rows)
            })
            .unzip()
    } else {
        (Vec::new(), Vec::new())
    };
    let data_e = if robust { rho.iter().sum::<f64>() / (nv as f64 * data.mean_b) } else { sse * data.norm };
    let mut terms = Terms {
        data: data_e,
        alpha,
        rms_residual: (sse.max(0.0) / data.rows as f64).sqrt(),
        lambda: data.lambda0 + d[0],
        c_inv: data.c0 + d[1],
        ..Default::default()
    };

    if let Some(gg) = grad_globals {
        // dE/du = sum_i dE/de_i * 2 (H_i u - b_i), components 1 and 2 (alpha, when profiled,
        // is optimal given d: envelope theorem).
        *gg = [0.0; 2];
        if data.extra == 2 {
            for (i, (_, b, h)) in parts.iter().enumerate() {
                let k = if robust { drho[i] / (nv as f64 * data.mean_b) } else { data.norm };
                gg[0] += k * 2.0 * (h[1] * u[0] + h[3] * u[1] + h[4] * u[2] - b[1]);
                gg[1] += k * 2.0 * (h[2] * u[0] + h[4] * u[1] + h[5] * u[2] - b[2]);
            }
        }
    }
    let mut gx = grad.as_ref().map(|_| vec![[0.0; 3]; nv]);
    if let Some(gx) = gx.as_mut() {
        // dE/dã_ij = norm * (2 α² (Gã)_j - 2 α f_j); ã_ij = w_e/m_i.
        // Per vertex (in parallel), each neighbour edge's adjoint and the mass adjoint; the edge
        // adjoints are then summed in vertex order (the same bits at any thread count).
        let per_vertex: Vec<(Vec<f64>, f64)> = (0..nv)
            .into_par_iter()
            .with_min_len(512)
            .map(|i| {
                let nb = &mesh.nbrs[i];
                let p = nb.len();
                let mm = p + 1 + data.extra;
                let g = &data.grams[i];
                let at: Vec<f64> = nb.iter().map(|&(_, e)| weights[e] / m[i]).collect();
                let mut dm = 0.0;
                let mut de = Vec::with_capacity(p);
                for r in 0..p {
                    let mut s = 0.0;
                    for c in 0..p {
                        s += g[r * mm + c] * at[c];
                    }
                    let k = if robust { drho[i] / (nv as f64 * data.mean_b) } else { data.norm };
                    // With profiled globals, the corrections' columns join f (envelope theorem:
                    // d is optimal, so its own variation does not enter).
                    let f = g[r * mm + p] + (0..data.extra).map(|t| d[t] * g[r * mm + p + 1 + t]).sum::<f64>();
                    let da = k * (2.0 * alpha * alpha * s - 2.0 * alpha * f);
                    de.push(da / m[i]);
                    dm -= da * at[r] / m[i];
                }
                (de, dm)
            })
            .collect();
        let mut edge_adj = vec![0.0; mesh.edges.len()];
        let mut mass_adj = vec![0.0; nv];
        for (i, (de, dm)) in per_vertex.iter().enumerate() {
            for (&(_, e), &v) in mesh.nbrs[i].iter().zip(de) {
                edge_adj[e] += v;
            }
            mass_adj[i] = *dm;
        }
        mesh.vjp
            .accumulate(&x, Some(&edge_adj), Some(&mass_adj), AreaMass::Barycentric, gx)
            .expect("sizes are consistent by construction");
    }

    let rt = regulariser_terms(mesh, reg, &x, gx.as_deref_mut());
    terms.normal = rt.normal;
    terms.halfspace = rt.halfspace;
    terms.lamp_ratio = rt.lamp_ratio;
    terms.lamp_shading = rt.lamp_shading;
    terms.lamp_beta = rt.lamp_beta;
    let mut grad = grad;
    if let (Some(grad), Some(gx)) = (grad.as_deref_mut(), gx) {
        for i in 0..nv {
            grad[i] = dot(gx[i], mesh.dirs[i]);
        }
    }
    terms.total = terms.data + reg.normal_consistency * terms.normal + reg.halfspace * terms.halfspace;
    #[cfg(feature = "experimental")]
    if let Some((_, w)) = &reg.lamp_ratio {
        terms.total += w * terms.lamp_ratio;
    }
    if let Some((_, w)) = &reg.lamp_shading {
        terms.total += w * terms.lamp_shading;
    }
    // The symmetry term is a function of the depths themselves, not of the positions.
    if let Some((sym, w)) = reg.symmetry.as_ref().filter(|(_, w)| *w > 0.0) {
        terms.symmetry = sym.term(z, *w, grad);
        terms.total += w * terms.symmetry;
    }
    terms
}

/// The regularisers' values at one point (unweighted).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct RegTerms {
    /// Normal consistency.
    pub normal: f64,
    /// Half-space hinge.
    pub halfspace: f64,
    /// Two-light flux ratio term.
    pub lamp_ratio: f64,
    /// Lamp-shading term.
    pub lamp_shading: f64,
    /// Lamp shading's profiled beta, m^2 K/J.
    pub lamp_beta: f64,
}

/// The regularisers of Eq. 11 at positions `x` (m): normal consistency, the mean over adjacent
/// face pairs of 1 - n_f . n_g, the half-space hinge, the mean over vertices of
/// max(0, -N_i n_i . e), the two-light flux ratio term (`crate::experimental::lamp_ratio`) and lamp
/// shading ([`super::lamp_shading`]), all dimensionless and unweighted, the last three with the
/// area-weighted vertex normals; their
/// gradients, weighted by `reg`'s weights, are added to `gx` (per vertex, d/dx).
pub(crate) fn regulariser_terms(
    mesh: &RayMesh,
    reg: &Regularisers,
    x: &[[f64; 3]],
    gx: Option<&mut [[f64; 3]]>,
) -> RegTerms {
    let nv = mesh.len();
    #[cfg_attr(not(feature = "experimental"), allow(unused_mut))]
    let (mut normal, mut halfspace, mut lamp_ratio, mut lamp_shading, mut lamp_beta) = (0.0, 0.0, 0.0, 0.0, 0.0);
    // Face cross products c_t = (p1 - p0) x (p2 - p0), twice the area vector.
    let fc: Vec<[f64; 3]> = mesh.tris.iter().map(|t| cross(sub(x[t[1]], x[t[0]]), sub(x[t[2]], x[t[0]]))).collect();
    // Adjoint of each face cross product.
    let mut gc = vec![[0.0; 3]; if gx.is_some() { fc.len() } else { 0 }];

    if reg.normal_consistency > 0.0 && !mesh.face_pairs.is_empty() {
        let k = 1.0 / mesh.face_pairs.len() as f64;
        let unit: Vec<([f64; 3], f64)> = fc.iter().map(|c| (scale(*c, 1.0 / norm(*c)), norm(*c))).collect();
        let mut e = 0.0;
        for &[f, g] in &mesh.face_pairs {
            let (nf, nn) = (unit[f].0, unit[g].0);
            e += 1.0 - dot(nf, nn);
            if !gc.is_empty() {
                let w = reg.normal_consistency * k;
                // d(-nf.ng)/dc_f = -(I - nf nf^T) ng / |c_f|
                let pf = scale(sub(nn, scale(nf, dot(nf, nn))), -w / unit[f].1);
                let pg = scale(sub(nf, scale(nn, dot(nf, nn))), -w / unit[g].1);
                gc[f] = add(gc[f], pf);
                gc[g] = add(gc[g], pg);
            }
        }
        normal = e * k;
    }

    let use_halfspace = reg.halfspace > 0.0 && reg.halfspace_sign.len() == nv;
    #[cfg(feature = "experimental")]
    let ratio = reg.lamp_ratio.as_ref().filter(|(lr, w)| *w > 0.0 && lr.target.len() == nv);
    #[cfg(not(feature = "experimental"))]
    let ratio: Option<()> = None;
    let shading = reg.lamp_shading.as_ref().filter(|(ls, w)| *w > 0.0 && ls.target.iter().all(|t| t.len() == nv));
    let lamps = ratio.is_some() || shading.is_some();
    // Adjoint of each vertex's summed face cross product vc_i (its normal is vc_i / |vc_i|), and
    // the lamp terms' direct dependence on the positions.
    let mut vadj = vec![[0.0; 3]; if gc.is_empty() || !(use_halfspace || lamps) { 0 } else { nv }];
    let mut gx_direct = vec![[0.0; 3]; if gc.is_empty() || !lamps { 0 } else { nv }];
    let mut vc = vec![[0.0; 3]; if use_halfspace || lamps { nv } else { 0 }];
    if !vc.is_empty() {
        for (t, c) in mesh.tris.iter().zip(&fc) {
            for &i in t {
                vc[i] = add(vc[i], *c);
            }
        }
    }

    if lamps {
        let n: Vec<[f64; 3]> = vc.iter().map(|c| scale(*c, 1.0 / norm(*c))).collect();
        // The lamp terms' weighted gradient with respect to each unit vertex normal.
        let mut dn = vec![[0.0; 3]; if vadj.is_empty() { 0 } else { nv }];
        #[cfg(feature = "experimental")]
        if let Some((lr, w)) = ratio {
            lamp_ratio = if dn.is_empty() {
                lr.term(x, &n, *w, None)
            } else {
                lr.term(x, &n, *w, Some((&mut dn, &mut gx_direct)))
            };
        }
        if let Some((ls, w)) = shading {
            (lamp_shading, lamp_beta) = if dn.is_empty() {
                ls.term(x, &n, *w, None)
            } else {
                ls.term(x, &n, *w, Some((&mut dn, &mut gx_direct)))
            };
        }
        if !dn.is_empty() {
            for i in 0..nv {
                // dn/dvc = (I - n n^T) / |vc|
                let g = scale(sub(dn[i], scale(n[i], dot(n[i], dn[i]))), 1.0 / norm(vc[i]));
                vadj[i] = add(vadj[i], g);
            }
        }
    }

    if use_halfspace {
        let k = 1.0 / nv as f64;
        let ax = reg.lamp_axis;
        let mut e = 0.0;
        for i in 0..nv {
            let s = reg.halfspace_sign[i] as f64;
            if s == 0.0 {
                continue;
            }
            let l = norm(vc[i]);
            let n = scale(vc[i], 1.0 / l);
            let h = -s * dot(n, ax);
            if h > 0.0 {
                e += h;
                if !vadj.is_empty() {
                    // d(-s n.e)/dc = -s (I - n n^T) e / |c|
                    vadj[i] = add(vadj[i], scale(sub(ax, scale(n, dot(n, ax))), -s * reg.halfspace * k / l));
                }
            }
        }
        halfspace = e * k;
    }
    if !vadj.is_empty() {
        for (t, g) in mesh.tris.iter().zip(gc.iter_mut()) {
            for &i in t {
                *g = add(*g, vadj[i]);
            }
        }
    }

    if let Some(gx) = gx {
        for ((t, g), _) in mesh.tris.iter().zip(&gc).zip(&fc) {
            let e1 = sub(x[t[1]], x[t[0]]);
            let e2 = sub(x[t[2]], x[t[0]]);
            // c = e1 x e2: d(c.g) = de1.(e2 x g) + de2.(g x e1)
            let g1 = cross(e2, *g);
            let g2 = cross(*g, e1);
            gx[t[1]] = add(gx[t[1]], g1);
            gx[t[2]] = add(gx[t[2]], g2);
            gx[t[0]] = sub(gx[t[0]], add(g1, g2));
        }
        for (g, d) in gx.iter_mut().zip(&gx_direct) {
            *g = add(*g, *d);
        }
    }
    RegTerms { normal, halfspace, lamp_ratio, lamp_shading, lamp_beta }
}
