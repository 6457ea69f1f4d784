//! Cramér–Rao bounds: how well any unbiased estimator can determine the shape from the videos
//! (product code beside the method; the benchmark prints it beside every error).
//!
//! - [`output_error`]: the forward model the bound is built on, the video predicted by the
//!   surface heat equation on a shape, with its adjoint gradient; [`flux_fit`]: the fluxes (and
//!   globals) that fit a video at a fixed shape.
//! - [`shape`]: the bound on a few shape modes (size, relief, image polynomials) with the fluxes
//!   and globals known or unknown, reported as the expected surface error after a rigid
//!   alignment. [`shape_bound_at_truth`] evaluates it on simulated datasets at their true
//!   depth, fluxes and globals ([`oracle_stage1`]), without running a reconstruction.
//! - The bound on stage 1's globals lambda, C and h is `crate::stage1::bound`.

pub mod flux_fit;
pub mod output_error;
mod rim;
pub mod shape;
mod tie;

use std::path::Path;

use crate::dataset::{check_compatible, Dataset, LoadOptions};
use crate::error::ReconError;
use crate::halfspace::halfspace;
use crate::pyramid::Level;
use crate::stage1::{Stage1Input, SIGMA};
use crate::stage2::coarse_to_fine::{ray_dirs, Stage1Params};
use crate::stage2::energy::RayMesh;
use crate::validate::Truth;
use output_error::{FrameSet, OeData, OeMesh};
use shape::{default_modes, shape_bound, BoundOptions, ShapeBound};

/// 0 for the vertices within `rings` rings of the mask boundary (partly covered pixels), else 1.
pub(crate) fn rim_weights(mesh: &RayMesh, rings: usize) -> Vec<f64> {
    mesh.boundary_distance().iter().map(|&k| if k < rings { 0.0 } else { 1.0 }).collect()
}

/// The output-error physics of a level: its raw `series` and frame times, the globals of
/// `params`, the diffusivity `alpha` (m^2/s), the vertex `weight`s; one substep, no offsets, the
/// noise variance unknown, every frame.
pub(crate) fn oe_data<'a>(
    series: &'a [Vec<f64>],
    input: &'a Stage1Input,
    params: &Stage1Params,
    alpha: f64,
    weight: &'a [f64],
) -> OeData<'a> {
    OeData {
        series,
        times: &input.times,
        first: input.times.iter().position(|&t| t >= -1e-9).unwrap_or(0),
        alpha,
        lambda: params.lambda,
        c_inv: params.c_inv,
        ambient: input.ambient,
        emissivity: input.emissivity,
        weight,
        substeps: 1,
        noise_var: 0.0,
        offsets: false,
        frame_set: FrameSet::All,
    }
}

/// The shape bound ([`shape::shape_bound`]) of the simulated datasets in `dirs` (read as `load`
/// says) at pyramid `level`, at their true depth with the true fluxes and globals, the
/// diffusivity `alpha` (m^2/s) known, the vertices within `boundary_rings` of the mask boundary
/// left out, the modes of [`shape::default_modes`] of `opts.degree`, the noise measured on the
/// frames at t <= 0. `threshold` is Eq. 9's (it does not enter the bound).
///
/// # Errors
/// Missing or incompatible datasets or ground truth, a truth that misses a vertex, videos
/// without noise.
pub fn shape_bound_at_truth(
    dirs: &[&Path],
    load: &LoadOptions,
    level: usize,
    alpha: f64,
    boundary_rings: usize,
    threshold: f64,
    opts: BoundOptions,
) -> Result<ShapeBound, ReconError> {
    let sets = dirs.iter().map(|d| Dataset::load(d, load)).collect::<Result<Vec<_>, _>>()?;
    check_compatible(&sets)?;
    let lvl = Level::build(&sets, level);
    let input = Stage1Input::from_level(&lvl, sets[0].ambient, sets[0].emissivity)?;
    let mesh = RayMesh::new(ray_dirs(&lvl.camera, &input.grid), input.grid.tris.clone())?;
    let truth = Truth::load(dirs[0], level)?;
    let zt: Vec<f64> = input.grid.pixels.iter().map(|&p| truth.depth[p]).collect();
    if !zt.iter().all(|z| z.is_finite()) {
        return Err(ReconError::Input(format!("the true depth misses vertices of level {level}")));
    }
    at_truth(&mesh, &input, &input.series, &zt, dirs, level, alpha, boundary_rings, threshold, opts)
}

/// The shape bound on `mesh` at the true depths `zt` (m) of the datasets `dirs` at `level`,
/// from the raw `series` on `input`'s grid and frames (module doc).
#[allow(clippy::too_many_arguments)]
pub(crate) fn at_truth(
    mesh: &RayMesh,
    input: &Stage1Input,
    series: &[Vec<f64>],
    zt: &[f64],
    dirs: &[&Path],
    level: usize,
    alpha: f64,
    boundary_rings: usize,
    threshold: f64,
    opts: BoundOptions,
) -> Result<ShapeBound, ReconError> {
    let raw = Stage1Input { series: series.to_vec(), ..input.clone() };
    let sigma = crate::stage1::denoise::noise_sigma(&raw).ok_or_else(|| {
        ReconError::Input("the shape bound needs noisy videos (the noise is measured before t = 0)".into())
    })?;
    let params = oracle_stage1(dirs, level, &input.grid, input.ambient, input.emissivity, threshold)?;
    let weight = rim_weights(mesh, boundary_rings);
    // The fixed pattern is a free offset per pixel, as in the datasets.
    let d = OeData { noise_var: sigma * sigma, offsets: true, ..oe_data(series, input, &params, alpha, &weight) };
    let om = OeMesh::new(mesh)?;
    let modes = default_modes(&om, zt, opts.degree);
    shape_bound(&om, &d, zt, &params.flux_over_c, sigma, &modes, opts)
}

/// Ground-truth physics of a simulated dataset: C (J/(m^2 K)) with the layer thickness the
/// simulation used, h (W/(m^2 K)) and alpha (m^2/s).
pub fn true_physics(dir: &Path) -> Result<(f64, f64, f64), ReconError> {
    use heatsim::dataset_format as format;
    let (mat, meta, env) = (format::read_material(dir)?, format::read_meta(dir)?, format::read_environment(dir)?);
    let (rho, cp, k) = (mat.density, mat.specific_heat, mat.conductivity);
    let d = match meta.simulation.layer_thickness_m {
        Some(d) => d,
        None => crate::validate::object_thickness(dir, &meta)?,
    };
    let h = crate::validate::true_convection(dir, &env)?;
    Ok((rho * cp * d, h, k / (rho * cp)))
}

/// Stage 1's parameters from the ground truth of the simulated datasets `dirs` at pyramid
/// `level`, on the vertices of `grid`: the true lambda, 1/C and q/C, what the bound assumes
/// known or takes as its point.
pub fn oracle_stage1(
    dirs: &[&Path],
    level: usize,
    grid: &heatsim::camera::PixelGrid,
    ambient: f64,
    emissivity: f64,
    threshold: f64,
) -> Result<Stage1Params, ReconError> {
    let (c, h, _) = true_physics(dirs[0])?;
    let r = 4.0 * emissivity * SIGMA * ambient.powi(3);
    let mut flux = Vec::new();
    for d in dirs {
        let t = Truth::load(d, level)?;
        flux.push(grid.pixels.iter().map(|&p| t.flux[p] / c).collect::<Vec<f64>>());
    }
    let hs = (flux.len() >= 2).then(|| halfspace(&flux[0], &flux[1], threshold));
    Ok(Stage1Params {
        lambda: (h + r) / c,
        c_inv: 1.0 / c,
        flux_over_c: flux,
        halfspace: hs,
        noise_cov: Vec::new(),
        source: "oracle: ground truth C, h and gt_flux".into(),
    })
}
