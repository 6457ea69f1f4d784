//! Opt-in experiments on the shape stage (cargo feature `experimental`): part of neither preset,
//! kept to reproduce the research notes. Configured by [`ExperimentalConfig`], the
//! `experimental` section of [`crate::ReconConfig`] (present only in builds with the feature).
//!
//! - [`output_error`]: the output-error refinement of one level (`experimental.output_error`);
//!   [`joint`]: its joint fit of depths, fluxes and globals.
//! - [`lamp_ratio`]: the two-light flux ratio term of the shape's energy
//!   (`experimental.lamp_ratio`).
//! - `initial_depth` (the first level's start depths from a file) and `min_rank` (a floor on
//!   the denoiser's kept profiles): fields of [`ExperimentalConfig`].

pub mod joint;
pub mod lamp_ratio;
pub mod mode_fit;
pub mod output_error;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::bound::output_error::{OeData, OeMesh};
use crate::bound::{oe_data, rim_weights};
use crate::config::LampTermConfig;
use crate::error::ReconError;
use crate::stage1::Stage1Input;
use crate::stage2::energy::RayMesh;
use crate::stage2::{Stage1Params, Stage2Options};
use output_error::{add_white_noise, fit_lambda_and_size, refine, scan_grid, OeOptions};

/// The experiments of a reconstruction.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct ExperimentalConfig {
    /// The two-light flux ratio term at every level ([`lamp_ratio`]), from the point
    /// lamps of `lamps.json` beside the first two videos; `null`: off.
    pub lamp_ratio: Option<LampTermConfig>,
    /// The output-error refinement at one level ([`output_error::refine`]; needs the
    /// diffusivity); `null`: off.
    pub output_error: Option<OeOptions>,
    /// The first level's start depths from this `.npy` (m, that level's image; NaN or 0
    /// keeps the start's depth) instead of the plane or bulge; `null`: off.
    pub initial_depth: Option<String>,
    /// The low-rank denoiser keeps at least this many temporal profiles per video (`0`: the
    /// threshold's rank).
    pub min_rank: usize,
}

impl ExperimentalConfig {
    /// No experiment is on (the section is then left out of a written configuration).
    pub fn is_off(&self) -> bool {
        *self == ExperimentalConfig::default()
    }
}

/// One round of the output-error refinement as reported in `stage2.json`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct OeRound {
    /// Round (0: after the first flux fit, before any shape fit).
    pub round: usize,
    /// Output-error loss, K^2 (on the fitted frames).
    pub loss_k2: f64,
    /// With the hold-out: the loss on the held-out frames, K^2.
    pub heldout_loss_k2: Option<f64>,
    /// lambda = (h + R)/C of the round, 1/s (stage 1's unless fitted).
    pub lambda: f64,
    /// c = 1/C of the round, m^2 K/J (stage 1's unless fitted).
    pub c_inv: f64,
    /// The round whose depths the refinement returned.
    pub kept: bool,
}

/// Whether an experiment at pyramid `level` fits the series as filmed: the output-error
/// refinement (denoising removes the shape's information).
pub(crate) fn wants_raw_series(opts: &Stage2Options, level: usize) -> bool {
    opts.output_error.as_ref().is_some_and(|o| o.level == level)
}

/// Runs the experiments of pyramid `level` on its depths `z` (m) after the level's fit: the
/// output-error refinement when it is configured there, from the raw `series` with the
/// diffusivity `metric` (or the fixed one of `opts`); `observer` gets their progress. Returns
/// what they report, `None` when none ran.
///
/// # Errors
/// The refinement without the diffusivity or the raw series, or its failures.
#[allow(clippy::too_many_arguments)]
pub(crate) fn after_level(
    opts: &Stage2Options,
    level: usize,
    mesh: &RayMesh,
    series: Option<&[Vec<f64>]>,
    input: &Stage1Input,
    params: &Stage1Params,
    metric: Option<f64>,
    z: &mut [f64],
    observer: &mut dyn crate::Observer,
) -> Result<Option<serde_json::Value>, ReconError> {
    let Some(oe) = opts.output_error.as_ref().filter(|o| o.level == level) else { return Ok(None) };
    let alpha = metric.or(match opts.scale {
        crate::stage2::Scale::Diffusivity(a) => Some(a),
        crate::stage2::Scale::Profiled => None,
    });
    let alpha = alpha.ok_or_else(|| {
        ReconError::Input("the output-error refinement needs the diffusivity (a metric reconstruction)".into())
    })?;
    let raw = series.ok_or_else(|| ReconError::Input("the output-error refinement needs the raw series".into()))?;
    let raw_sigma = crate::stage1::denoise::noise_sigma(&Stage1Input { series: raw.to_vec(), ..input.clone() });
    let weight = rim_weights(mesh, oe.boundary_rings);
    let d = OeData {
        substeps: oe.substeps,
        noise_var: raw_sigma.map_or(0.0, |s| s * s),
        offsets: oe.offsets,
        ..oe_data(raw, input, params, alpha, &weight)
    };
    let om = OeMesh::new(mesh)?;
    let mut b = params.flux_over_c.clone();
    if let Some(path) = &oe.start_depth {
        apply_start_depth(path, &input.grid, z)?;
    }
    // The videos as filmed unless an experiment replaces them or adds noise (then a copy).
    let mut videos = std::borrow::Cow::Borrowed(raw);
    if oe.synthetic_seed != 0 {
        let syn = output_error::Synthetic { seed: oe.synthetic_seed, pattern_error: true };
        videos = std::borrow::Cow::Owned(output_error::synthetic_series(&om, &d, z, &b, syn)?);
    }
    let mut noise_var = d.noise_var;
    if oe.added_noise_k > 0.0 {
        add_white_noise(videos.to_mut(), oe.added_noise_k, oe.synthetic_seed.max(1));
        noise_var += oe.added_noise_k.powi(2);
    }
    let mut d = OeData { series: &videos, noise_var, ..d };
    let mut scan = None;
    if !oe.size_scan.is_empty() {
        let (points, lambda) = scan_grid(&om, &d, oe, z, &mut b)?;
        d.lambda = lambda;
        let mut report = serde_json::json!({ "grid": points });
        if oe.joint_size_rounds > 0 {
            let (lambda, s, j) = fit_lambda_and_size(&om, &d, z, &mut b, oe)?;
            d.lambda = lambda;
            report["joint"] = serde_json::json!({ "lambda": lambda, "size_factor": s, "loss_k2": j });
        }
        scan = Some(report);
    }
    let mut modes = None;
    if oe.mode_degree > 0 {
        let fit = mode_fit::fit_modes(&om, &d, z, &mut b, oe, observer)?;
        d.lambda = fit.lambda;
        modes = Some(fit);
    }
    let mut rounds = Vec::new();
    let kept = refine(&om, &d, &opts.optim, oe, z, &mut b, |r, _| {
        rounds.push(OeRound {
            round: r.round,
            loss_k2: r.loss,
            heldout_loss_k2: r.heldout,
            lambda: r.globals.lambda,
            c_inv: r.globals.c_inv,
            kept: false,
        });
    })?;
    if let Some(r) = rounds.iter_mut().find(|r| r.round == kept.round) {
        r.kept = true;
    }
    Ok(Some(serde_json::json!({ "output_error": rounds, "size_scan": scan, "mode_fit": modes })))
}

/// Replaces the depths `z` of the vertices of `grid` by those of the `.npy` at `path` (the
/// level's image, m, float64 or float32; NaN or 0 keeps a vertex's depth).
///
/// # Errors
/// The file unreadable or not of the level's image size.
pub(crate) fn apply_start_depth(
    path: &str,
    grid: &heatsim::camera::PixelGrid,
    z: &mut [f64],
) -> Result<(), ReconError> {
    // float64, or float32 as `depth.npy` is written.
    let a: ndarray::Array2<f64> = match ndarray_npy::read_npy::<_, ndarray::Array2<f64>>(path) {
        Ok(a) => a,
        Err(e64) => ndarray_npy::read_npy::<_, ndarray::Array2<f32>>(path)
            .map(|a| a.mapv(f64::from))
            .map_err(|_| ReconError::format(path, e64.to_string()))?,
    };
    if a.len() != grid.width * grid.height {
        return Err(ReconError::format(
            path,
            format!("{} values, the level has {} x {} pixels", a.len(), grid.width, grid.height),
        ));
    }
    let flat: Vec<f64> = a.iter().copied().collect();
    for (zk, &p) in z.iter_mut().zip(&grid.pixels) {
        if flat[p].is_finite() && flat[p] > 0.0 {
            *zk = flat[p];
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A start depth read from float64 and from float32 (`depth.npy`), NaN and 0 keeping the
    /// fit's depth; a file of the wrong size is an error naming it.
    #[test]
    fn start_depth_reads_float64_and_float32() {
        let grid = heatsim::camera::PixelGrid::new(&[true, true, false, true, true, true], 3, 2);
        let dir = tempfile::tempdir().expect("temporary directory");
        let image = [0.5, f64::NAN, 0.7, 0.0, 0.9, 1.1];
        let f64_path = dir.path().join("d64.npy");
        let f32_path = dir.path().join("d32.npy");
        let a = ndarray::Array2::from_shape_vec((2, 3), image.to_vec()).expect("shape");
        ndarray_npy::write_npy(&f64_path, &a).expect("write");
        ndarray_npy::write_npy(&f32_path, &a.mapv(|v| v as f32)).expect("write");
        for path in [&f64_path, &f32_path] {
            let mut z = vec![0.3; grid.pixels.len()];
            apply_start_depth(path.to_str().expect("utf-8"), &grid, &mut z).expect("start depth");
            // Pixels 0, 1, 3, 4, 5: 0.5, NaN (kept), 0 (kept), 0.9, 1.1.
            let want = [0.5, 0.3, 0.3, 0.9, 1.1];
            assert!(z.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-7), "{z:?} from {path:?}");
        }
        let wrong = dir.path().join("wrong.npy");
        ndarray_npy::write_npy(&wrong, &ndarray::Array2::<f64>::zeros((3, 3))).expect("write");
        let err = apply_start_depth(wrong.to_str().expect("utf-8"), &grid, &mut [0.3; 5]).expect_err("wrong size");
        assert!(err.to_string().contains("wrong.npy") && err.to_string().contains("9 values"), "{err}");
    }
}
