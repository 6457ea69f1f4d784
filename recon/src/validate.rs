//! Figures of merit for stage 1 against ground truth (simulated data only). This module, and
//! only this one, reads ground-truth files (`gt_depth.npy`, `gt_flux.npy`, `gt_normals.npy`,
//! `material.json`, `meta.json`, `lamps.json`, `environment.json`'s `convection_coefficient`);
//! the estimator never calls it.
//!
//! - **True operator:** `Δ_s = α M^-1 L` on the pixel mesh with each vertex at its
//!   pixel centre back-projected to depth `gt_depth` (`z_c`) through the level's camera,
//!   `α = k/(ρ c_p)`, `L` the cotangent Laplacian and `M` the barycentric lumped area
//!   (`heatsim::surface::operators`). Error: `‖hat(Δ)_s - Δ_s‖_F / ‖Δ_s‖_F` over
//!   all entries (diagonal included).
//! - **Flux:** Pearson correlation over the mesh vertices between the estimate and `gt_flux`
//!   (the flux is estimated as q/C, so scale does not matter). On the camera grid with
//!   `solver.surface_flux: "vertex"` (the validation scenes) `gt_flux` at a vertex's pixel is
//!   the flux the surface solver applies there (Eq. 6); with the default triangle means the
//!   applied flux is [`model_vertex_flux`], reported beside it.
//! - **C, h:** relative errors against `C = ρ c_p d` (`material.json`, thickness from
//!   `meta.json`'s `scene.object`) and `h` (`environment.json`); also
//!   `λ = (h + R)/C`, the combination the data determine.
//! - **Bound:** the Cramér–Rao bound on λ, C and h at the data's noise, from the noise-free
//!   video ([`globals_bound`], [`crate::stage1::bound`]): what any unbiased estimator could reach.
//! - **Half-space:** fraction of assigned pixels (`N ≠ 0`) whose sign equals the sign of the
//!   true normal's x component towards lamp 1, i.e. `sign(n_x (x_(lamp,1) - x_(lamp,2)))`
//!   with world-frame normals and lamp positions (`lamps.json`).

use std::path::Path;

use heatsim::dataset_format::{self as format, ENVIRONMENT_FILE, META_FILE};
use heatsim::scene::{LampSpec, SurfaceFlux};
use heatsim::surface::operators::{lumped_area, AreaMass, CotanLaplacian};
use heatsim::vec3::{cross, norm, sub};
use ndarray::{Array2, Array3};

use crate::dataset::CameraInfo;
use crate::error::ReconError;
use crate::stage1::bound::{self, BoundModel, GlobalsBound};
use crate::stage1::{weight_groups, Stage1Input, Stage1Result, Stencil};

/// Pearson correlation of two equally long samples.
pub fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    sab / (saa * sbb).sqrt()
}

/// Relative Frobenius error of an operator given as triplets (every (i, j) at most once)
/// against the true α M^-1 L of the mesh `(verts, tris)`.
pub fn operator_error(est: &[(usize, usize, f64)], verts: &[[f64; 3]], tris: &[[usize; 3]], alpha: f64) -> f64 {
    let truth = true_operator(verts, tris, alpha);
    let mut t: std::collections::BTreeMap<(usize, usize), f64> = truth.iter().map(|&(i, j, v)| ((i, j), v)).collect();
    let norm2: f64 = truth.iter().map(|x| x.2 * x.2).sum();
    let mut err2 = 0.0;
    for &(i, j, v) in est {
        let tv = t.remove(&(i, j)).unwrap_or(0.0);
        err2 += (v - tv) * (v - tv);
    }
    err2 += t.values().map(|v| v * v).sum::<f64>();
    (err2 / norm2).sqrt()
}

/// Per row i: `‖hat(Δ)_(i ·) - Δ_(i ·)‖ / ‖Δ_(i ·)‖` (both given as triplets).
pub fn row_errors(est: &[(usize, usize, f64)], truth: &[(usize, usize, f64)], nv: usize) -> Vec<f64> {
    let mut t: std::collections::BTreeMap<(usize, usize), f64> = truth.iter().map(|&(i, j, v)| ((i, j), v)).collect();
    let mut norm2 = vec![0.0; nv];
    for &(i, _, v) in truth {
        norm2[i] += v * v;
    }
    let mut err2 = vec![0.0; nv];
    for &(i, j, v) in est {
        let tv = t.remove(&(i, j)).unwrap_or(0.0);
        err2[i] += (v - tv) * (v - tv);
    }
    for (&(i, _), v) in &t {
        err2[i] += v * v;
    }
    err2.iter().zip(&norm2).map(|(e, n)| (e / n).sqrt()).collect()
}

/// The true operator restricted to a stencil: in each row, the weights of a group (see
/// [`crate::stage1::weight_groups`]) replaced by their mean, the diagonal by minus the row sum.
/// Its error against the truth is the floor any estimate with that stencil has.
pub fn stencil_projection(truth: &[(usize, usize, f64)], groups: &[Vec<Vec<usize>>]) -> Vec<(usize, usize, f64)> {
    let t: std::collections::BTreeMap<(usize, usize), f64> = truth.iter().map(|&(i, j, v)| ((i, j), v)).collect();
    let mut out = Vec::new();
    for (i, gs) in groups.iter().enumerate() {
        let mut diag = 0.0;
        for g in gs {
            let mean = g.iter().map(|&j| t.get(&(i, j)).copied().unwrap_or(0.0)).sum::<f64>() / g.len() as f64;
            for &j in g {
                out.push((i, j, mean));
                diag -= mean;
            }
        }
        out.push((i, i, diag));
    }
    out
}

/// The absorbed flux the camera-grid surface model applies at each vertex with its default
/// triangle means (`solver.surface_flux: "triangle_mean"`), from the per-vertex flux
/// `vertex_flux` (`gt_flux` at the vertices' pixels): each triangle carries the mean of its
/// corners' fluxes, the load of vertex i is the sum of q_f A_f / 3 over its triangles and its
/// barycentric area the sum of A_f / 3 (`heatsim::surface::system`), so the flux per area is
/// the area-weighted mean of its triangles' fluxes (W/m^2 or any unit of `vertex_flux`; NaN for
/// a vertex in no triangle).
pub fn model_vertex_flux(verts: &[[f64; 3]], tris: &[[usize; 3]], vertex_flux: &[f64]) -> Vec<f64> {
    let (mut load, mut area) = (vec![0.0; verts.len()], vec![0.0; verts.len()]);
    for t in tris {
        let [a, b, c] = t.map(|i| verts[i]);
        let af = 0.5 * norm(cross(sub(b, a), sub(c, a)));
        let qf = t.iter().map(|&i| vertex_flux[i]).sum::<f64>() / 3.0;
        for &i in t {
            load[i] += qf * af;
            area[i] += af;
        }
    }
    load.iter().zip(&area).map(|(l, a)| if *a > 0.0 { l / a } else { f64::NAN }).collect()
}

/// α M^-1 L as triplets, diagonal included.
pub fn true_operator(verts: &[[f64; 3]], tris: &[[usize; 3]], alpha: f64) -> Vec<(usize, usize, f64)> {
    let lap = CotanLaplacian::new(verts, tris);
    let m = lumped_area(verts, tris, AreaMass::Barycentric);
    let diag = lap.diagonal();
    let mut out = Vec::new();
    for (&[i, j], &w) in lap.edges.iter().zip(&lap.weights) {
        out.push((i, j, alpha * w / m[i]));
        out.push((j, i, alpha * w / m[j]));
    }
    out.extend(diag.iter().enumerate().map(|(i, &d)| (i, i, alpha * d / m[i])));
    out
}

/// Back-projects pixel centres `(u, v)` at camera depth `z` to camera-frame points (m).
pub fn back_project(camera: &CameraInfo, u: f64, v: f64, z: f64) -> [f64; 3] {
    let k = &camera.k;
    let y = (v - k[1][2]) / k[1][1];
    let x = (u - k[0][2] - k[0][1] * y) / k[0][0];
    [x * z, y * z, z]
}

/// Ground truth of one simulated dataset, at a pyramid level.
#[derive(Clone, Debug)]
pub struct Truth {
    /// C = ρ c_p d, J/(m^2 K).
    pub heat_capacity: f64,
    /// h, W/(m^2 K).
    pub convection: f64,
    /// α = k / (ρ c_p), m^2/s.
    pub diffusivity: f64,
    /// Depth z_c per pixel at the level (NaN off the object), m.
    pub depth: Vec<f64>,
    /// Absorbed flux per pixel at the level, W/m^2.
    pub flux: Vec<f64>,
    /// World-frame normal x component per pixel at the level.
    pub normal_x: Vec<f64>,
    /// x coordinate of the (first) lamp, m, if known.
    pub lamp_x: Option<f64>,
    /// The simulation applied each vertex's flux (`solver.surface_flux: "vertex"` in
    /// `meta.json`'s scene), so `gt_flux` is the applied flux itself.
    pub flux_per_vertex: bool,
    /// Warnings met while reading, each naming its file (`lamps.json` in the legacy layout);
    /// the caller shows them.
    pub warnings: Vec<String>,
}

/// The thickness d of `meta.json`'s object (m), for C = ρ c_p d.
///
/// # Errors
/// [`ReconError::Format`] naming `meta.json` for an object without one (a closed solid).
pub(crate) fn object_thickness(dir: &Path, meta: &format::MetaFile) -> Result<f64, ReconError> {
    meta.scene.object.thickness().ok_or_else(|| {
        ReconError::format(
            dir.join(META_FILE),
            "scene.object: no thickness (a closed solid has no layer thickness d for C = rho c_p d)",
        )
    })
}

/// The convection coefficient h of `environment.json` (W/(m^2 K)).
///
/// # Errors
/// [`ReconError::Format`] naming `environment.json` when it is absent (not a simulated
/// dataset).
pub(crate) fn true_convection(dir: &Path, env: &format::EnvironmentFile) -> Result<f64, ReconError> {
    env.convection_coefficient.ok_or_else(|| {
        ReconError::format(dir.join(ENVIRONMENT_FILE), "no `convection_coefficient`: not a simulated dataset")
    })
}

fn block_average(img: &[f64], w: usize, h: usize, level: usize) -> (Vec<f64>, usize, usize) {
    let (mut img, mut w, mut h) = (img.to_vec(), w, h);
    for _ in 0..level {
        let (w2, h2) = (w / 2, h / 2);
        let mut out = vec![f64::NAN; w2 * h2];
        for v in 0..h2 {
            for u in 0..w2 {
                let p = 2 * v * w + 2 * u;
                out[v * w2 + u] = (img[p] + img[p + 1] + img[p + w] + img[p + w + 1]) / 4.0;
            }
        }
        (img, w, h) = (out, w2, h2);
    }
    (img, w, h)
}

impl Truth {
    /// Reads the ground truth of the simulated dataset `dir`, block-averaged to `level`.
    ///
    /// # Errors
    /// Missing or malformed ground-truth files, `lamps.json` included (in no known layout or
    /// with a bad lamp; a missing `lamps.json` only leaves `lamp_x` unknown).
    pub fn load(dir: &Path, level: usize) -> Result<Truth, ReconError> {
        let mat = format::read_material(dir)?;
        let meta = format::read_meta(dir)?;
        let env = format::read_environment(dir)?;
        let (rho, cp, k) = (mat.density, mat.specific_heat, mat.conductivity);
        let d = object_thickness(dir, &meta)?;
        let h = true_convection(dir, &env)?;
        let read2 = |name: &str| -> Result<(Vec<f64>, usize, usize), ReconError> {
            let p = dir.join(name);
            let a: Array2<f32> = ndarray_npy::read_npy(&p).map_err(|e| ReconError::format(&p, e.to_string()))?;
            let (hh, ww) = a.dim();
            Ok((a.iter().map(|&x| x as f64).collect(), ww, hh))
        };
        let (depth, w, hgt) = read2("gt_depth.npy")?;
        let (flux, _, _) = read2("gt_flux.npy")?;
        let np = dir.join("gt_normals.npy");
        let n3: Array3<f32> = ndarray_npy::read_npy(&np).map_err(|e| ReconError::format(&np, e.to_string()))?;
        let nx: Vec<f64> =
            n3.outer_iter().flat_map(|row| row.outer_iter().map(|p| p[0] as f64).collect::<Vec<_>>()).collect();
        // The first lamp's x if it is a point lamp; no lamps.json: unknown.
        let (lamp_x, warnings) = match format::read_lamps(dir) {
            Ok(f) => {
                let x = match f.lamps.first() {
                    Some(LampSpec::Point(l)) => Some(l.position[0]),
                    _ => None,
                };
                (x, f.warnings)
            }
            Err(e) if e.is_not_found() => (None, Vec::new()),
            Err(e) => return Err(e.into()),
        };
        Ok(Truth {
            heat_capacity: rho * cp * d,
            convection: h,
            diffusivity: k / (rho * cp),
            depth: block_average(&depth, w, hgt, level).0,
            flux: block_average(&flux, w, hgt, level).0,
            normal_x: block_average(&nx, w, hgt, level).0,
            lamp_x,
            flux_per_vertex: meta.scene.solver.surface_flux == SurfaceFlux::Vertex,
            warnings,
        })
    }
}

/// Stage-1 figures against the truth of each video's dataset.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Stage1Check {
    /// Relative error of C (None if not estimated).
    pub heat_capacity_rel_error: Option<f64>,
    /// Relative error of h (None if not estimated).
    pub convection_rel_error: Option<f64>,
    /// Relative error of λ = (h + R)/C.
    pub lambda_rel_error: f64,
    /// Flux correlation per video.
    pub flux_correlation: Vec<f64>,
    /// Flux correlation per video against the flux the camera-grid surface model applies at
    /// each vertex: `gt_flux` itself with `solver.surface_flux: "vertex"`, else the
    /// triangle means' [`model_vertex_flux`], which differs from the per-pixel `gt_flux` where
    /// the flux jumps (shadow and facet edges).
    pub flux_correlation_model: Vec<f64>,
    /// Δ_s relative Frobenius error of the raw rows.
    pub operator_error_rows: f64,
    /// Δ_s relative Frobenius error after symmetrisation.
    pub operator_error_symmetric: f64,
    /// Half-space sign agreement (videos 1 and 2), fraction of assigned vertices.
    pub halfspace_agreement: Option<f64>,
    /// Vertices assigned a half-space.
    pub halfspace_assigned: usize,
    /// The same agreement for Eq. 9 applied to the true flux images (`gt_flux`) at the same
    /// threshold: the ceiling of any flux estimate under this rule (its misses are vertices
    /// where the lamps' distance falloff outweighs a small normal x component).
    pub halfspace_agreement_true_flux: Option<f64>,
    /// Vertices in the mesh.
    pub vertices: usize,
    /// Vertices with a finite true depth (others are excluded from the operator check).
    pub operator_vertices: usize,
    /// Median over vertices of the relative error of their raw row of Δ_s.
    pub operator_row_error_median: f64,
    /// Relative Frobenius error of the raw rows over the vertices with a full ring of six
    /// neighbours only (away from the mask's edge).
    pub operator_error_rows_interior: f64,
    /// The error of the true operator projected onto the paired stencil (the floor of
    /// `Stencil::Paired`).
    pub operator_error_paired_floor: f64,
    /// Cramér–Rao bound on the globals at the data's noise (`--check` fills it from the
    /// noise-free video when the noise level is known; [`globals_bound`]).
    pub bound: Option<Stage1Bound>,
    /// Per vertex, relative error of its raw row (not serialised; for images).
    #[serde(skip)]
    pub row_error: Vec<f64>,
}

/// The Cramér–Rao bound on lambda, C and h ([`crate::stage1::bound`]) for three models of the
/// rows, from the least to the most unknown.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Stage1Bound {
    /// The temperature noise per frame and vertex the bound assumes, K.
    pub sigma: f64,
    /// Rows known (the true shape).
    pub rows_known: Option<GlobalsBound>,
    /// One unknown weight per pair of opposite neighbours (`Stencil::Paired`).
    pub rows_paired: Option<GlobalsBound>,
    /// One unknown weight per neighbour (`Stencil::Free`).
    pub rows_free: Option<GlobalsBound>,
}

/// The bound of [`crate::stage1::bound`] on `clean` (the noise-free rises of the level stage 1
/// ran on) for noise `sigma` (K), linearised about the truth of `t0`; `radiation_coefficient`
/// is R = 4 eps sigma_SB T_s^3 (W/(m^2 K)).
pub fn globals_bound(clean: &Stage1Input, t0: &Truth, radiation_coefficient: f64, sigma: f64) -> Stage1Bound {
    let model = BoundModel {
        lambda: (t0.convection + radiation_coefficient) / t0.heat_capacity,
        c: 1.0 / t0.heat_capacity,
        ambient: clean.ambient,
        emissivity: clean.emissivity,
        sigma,
    };
    let run = |groups: Option<&[Vec<Vec<usize>>]>| bound::globals_bound(&clean.series, &clean.times, groups, &model);
    let paired = weight_groups(&clean.grid, Stencil::Paired);
    let free = weight_groups(&clean.grid, Stencil::Free);
    Stage1Bound { sigma, rows_known: run(None), rows_paired: run(Some(&paired)), rows_free: run(Some(&free)) }
}

/// Compares `res` (estimated on `camera` at some level) with the truths of its videos.
/// `halfspace` is stage 1's half-space image with the threshold it was made with.
pub fn check(
    res: &Stage1Result,
    camera: &CameraInfo,
    truths: &[Truth],
    halfspace: Option<(&[i8], f64)>,
) -> Stage1Check {
    let t0 = &truths[0];
    let grid = &res.grid;
    let w = grid.width;
    // Mesh with true depth; vertices without a depth (should not happen) are dropped.
    let verts: Vec<[f64; 3]> =
        grid.pixels.iter().map(|&p| back_project(camera, (p % w) as f64, (p / w) as f64, t0.depth[p])).collect();
    let ok: Vec<bool> = verts.iter().map(|v| v[2].is_finite()).collect();
    let tris: Vec<[usize; 3]> = grid.tris.iter().copied().filter(|t| t.iter().all(|&i| ok[i])).collect();
    let keep = |ops: Vec<(usize, usize, f64)>| -> Vec<(usize, usize, f64)> {
        ops.into_iter().filter(|&(i, j, _)| ok[i] && ok[j]).collect()
    };
    let op_rows = operator_error(&keep(res.operator_rows()), &verts, &tris, t0.diffusivity);
    let op_sym = operator_error(&keep(res.operator_symmetric()), &verts, &tris, t0.diffusivity);
    let truth_op = true_operator(&verts, &tris, t0.diffusivity);
    let nv = grid.vertex_count();
    let row_error = row_errors(&keep(res.operator_rows()), &truth_op, nv);
    let mut sorted: Vec<f64> = row_error.iter().copied().filter(|x| x.is_finite()).collect();
    sorted.sort_by(f64::total_cmp);
    let operator_row_error_median = sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN);
    let groups = weight_groups(grid, Stencil::Paired);
    let floor = stencil_projection(&truth_op, &groups);
    let operator_error_paired_floor = operator_error(&floor, &verts, &tris, t0.diffusivity);
    let interior: Vec<bool> = (0..nv).map(|i| groups[i].len() == 3 && groups[i].iter().all(|g| g.len() == 2)).collect();
    let frob = |ops: &[(usize, usize, f64)]| -> f64 {
        let t: std::collections::BTreeMap<(usize, usize), f64> =
            truth_op.iter().filter(|x| interior[x.0]).map(|&(i, j, v)| ((i, j), v)).collect();
        let n2: f64 = t.values().map(|v| v * v).sum();
        let e2: f64 = ops
            .iter()
            .filter(|x| interior[x.0])
            .map(|&(i, j, v)| (v - t.get(&(i, j)).copied().unwrap_or(0.0)).powi(2))
            .sum();
        (e2 / n2).sqrt()
    };
    let operator_error_rows_interior = frob(&keep(res.operator_rows()));
    // Per video, gt_flux at the vertices' pixels.
    let gt_flux: Vec<Vec<f64>> = truths.iter().map(|t| grid.pixels.iter().map(|&p| t.flux[p]).collect()).collect();
    let (flux_correlation, flux_correlation_model): (Vec<f64>, Vec<f64>) = res
        .flux_over_c
        .iter()
        .zip(&gt_flux)
        .map(|(f, gt)| {
            let model = if t0.flux_per_vertex { gt.clone() } else { model_vertex_flux(&verts, &tris, gt) };
            let (a, b): (Vec<f64>, Vec<f64>) = f.iter().zip(&model).filter(|(_, m)| m.is_finite()).unzip();
            (correlation(f, gt), correlation(&a, &b))
        })
        .unzip();
    let r = res.radiation_coefficient;
    let lambda_true = (t0.convection + r) / t0.heat_capacity;
    let (mut agreement, mut assigned, mut agreement_true) = (None, 0, None);
    if let (Some((hs, threshold)), true) = (halfspace, truths.len() >= 2) {
        let side = match (truths[0].lamp_x, truths[1].lamp_x) {
            (Some(a), Some(b)) => (a - b).signum(),
            _ => 1.0,
        };
        // (agreeing, assigned) vertices of a half-space image against the true normals.
        let score = |hs: &[i8]| -> (usize, usize) {
            let (mut agree, mut assigned) = (0, 0);
            for (k, &p) in grid.pixels.iter().enumerate() {
                if hs[k] != 0 && t0.normal_x[p].is_finite() {
                    assigned += 1;
                    if (hs[k] as f64) * side * t0.normal_x[p] > 0.0 {
                        agree += 1;
                    }
                }
            }
            (agree, assigned)
        };
        let fraction = |(a, n): (usize, usize)| a as f64 / n.max(1) as f64;
        let (a, n) = score(hs);
        (agreement, assigned) = (Some(fraction((a, n))), n);
        let hs_true = crate::halfspace::halfspace(&gt_flux[0], &gt_flux[1], threshold);
        agreement_true = Some(fraction(score(&hs_true)));
    }
    Stage1Check {
        heat_capacity_rel_error: res.heat_capacity.map(|c| c.value / t0.heat_capacity - 1.0),
        convection_rel_error: res.convection.map(|h| h.value / t0.convection - 1.0),
        lambda_rel_error: res.lambda.value / lambda_true - 1.0,
        flux_correlation,
        flux_correlation_model,
        operator_error_rows: op_rows,
        operator_error_symmetric: op_sym,
        halfspace_agreement: agreement,
        halfspace_assigned: assigned,
        halfspace_agreement_true_flux: agreement_true,
        vertices: grid.vertex_count(),
        operator_vertices: ok.iter().filter(|&&b| b).count(),
        operator_row_error_median,
        operator_error_rows_interior,
        operator_error_paired_floor,
        bound: None,
        row_error,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two unit right triangles sharing the diagonal of a unit square, corner fluxes 0, 0, 1, 1:
    /// the model's flux at a vertex is the area-weighted mean of its triangles' corner means.
    #[test]
    fn model_vertex_flux_averages_the_triangles_of_a_vertex() {
        let verts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        let tris = [[0, 1, 2], [0, 2, 3]];
        let q = model_vertex_flux(&verts, &tris, &[0.0, 0.0, 1.0, 1.0]);
        // Triangle fluxes 1/3 and 2/3 with equal areas.
        let expected = [0.5, 1.0 / 3.0, 0.5, 2.0 / 3.0];
        for (a, b) in q.iter().zip(expected) {
            assert!((a - b).abs() < 1e-15, "{q:?}");
        }
        let constant = model_vertex_flux(&verts, &tris, &[2.0; 4]);
        assert!(constant.iter().all(|&v| (v - 2.0).abs() < 1e-15), "{constant:?}");
    }
}
