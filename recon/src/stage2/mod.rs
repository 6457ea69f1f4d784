//! Stage 2 (paper Sec. 6): shape from the Laplacian. One depth per pixel-vertex along its
//! camera ray; the heat residual re-evaluated with the cotangent Laplacian and area mass of the
//! current vertices ([`energy`]), normal consistency, the half-space hinge of Eq. 10 and an
//! optional mirror symmetry ([`symmetry`]); with calibrated lamps, the opt-in two-light ratio
//! ([`lamp_ratio`]) and lamp shading ([`lamp_shading`]); large-steps AdamUniform or L-BFGS
//! ([`optimize`]); coarse to fine over the image pyramid ([`coarse_to_fine`]); files
//! ([`export`]).
//!
//! [`oracle_stage1`] builds stage 1's parameters from a simulated dataset's ground truth
//! (`material.json`, `environment.json`, `meta.json`, `gt_flux.npy`): a test-only mode that
//! measures stage 2's accuracy separately from stage 1's.

pub mod coarse_to_fine;
pub mod energy;
pub mod export;
pub mod lamp_ratio;
pub mod lamp_shading;
pub mod noise;
pub mod optimize;
pub mod output_error;
pub mod symmetry;

use std::path::Path;

use heatsim::dataset_format as format;

use crate::error::ReconError;
use crate::halfspace::halfspace;
use crate::stage1::SIGMA;
use crate::validate::Truth;

pub use coarse_to_fine::{reconstruct, Stage1Params, Stage2Options, Stage2Result};
pub use energy::Scale;
pub use optimize::{OptimOptions, Optimizer};

/// Ground-truth physics of a simulated dataset: C (J/(m^2 K)) with the layer thickness the
/// simulation used, h (W/(m^2 K)) and alpha (m^2/s).
pub fn true_physics(dir: &Path) -> Result<(f64, f64, f64), ReconError> {
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
/// `level`, on the vertices of `grid` (test-only oracle mode, see the module doc).
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
        source: "oracle: ground truth C, h and gt_flux (test-only mode)".into(),
    })
}
