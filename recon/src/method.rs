//! The reconstruction as one call: [`reconstruct`] runs the method a [`ReconConfig`] describes
//! on datasets of one object (one lamp configuration each), [`reconstruct_stage1`] its first
//! stage alone.
//!
//! Stage 1 (paper Sec. 5) at a pyramid level: the series are denoised (truncated SVD at the
//! noise measured on the frames at t <= 0, or `input.netd_k`), then the Laplacian Delta_s, the
//! fluxes q/C per video, lambda = (h + R)/C and 1/C are estimated (`stage1::estimate`) and the
//! half-space image of Eq. 9 is formed. Stage 2 (Sec. 6) runs stage 1 and the shape fit at
//! every level from the coarsest to `level` (`stage2::coarse_to_fine`).

use heatsim::dataset_format as format;

use crate::config::{
    DataLoss, Denoise, EdgeWeights, FluxModel, Globals, LampSide, LampTermConfig, NoiseCorrection, ReconConfig,
    SizeRule, Stage, Video,
};
use crate::dataset::{check_compatible, CameraInfo, Dataset};
use crate::error::ReconError;
use crate::halfspace::halfspace;
use crate::observer::Observer;
use crate::pyramid::Level;
use crate::stage1::denoise::{noise_sigma, DenoiseReport};
use crate::stage1::{estimate, Stage1Input, Stage1Options, Stage1Result};
use crate::stage2::coarse_to_fine::LampTermOptions;
use crate::stage2::lamps::PointLamp;
use crate::stage2::noise::temporal_covariance;
use crate::stage2::{OptimOptions, Scale, Stage1Params, Stage2Options, Stage2Result};

/// Stage 1 at one level, as [`reconstruct_stage1`] returns it.
#[derive(Clone, Debug)]
pub struct Stage1Run {
    /// The level it ran at.
    pub level: Level,
    /// The estimate.
    pub result: Stage1Result,
    /// The half-space image per vertex (Eq. 9), with two videos or more.
    pub halfspace: Option<Vec<i8>>,
    /// The denoising applied, if any.
    pub denoise: Option<DenoiseReport>,
    /// The temporal noise of the raw series, K: `input.netd_k`, else measured on the frames at
    /// t <= 0 (none for clean videos).
    pub noise: Option<f64>,
}

/// How the shape stage was set up from the configuration and the datasets.
#[derive(Clone, Debug)]
pub struct ShapeSetup {
    /// The options the coarse-to-fine fit ran with.
    pub options: Stage2Options,
    /// The nominal distance used, m.
    pub distance: f64,
    /// Whether the half-space term was on (two videos with lamps on opposite sides).
    pub halfspace_term: bool,
}

/// What [`reconstruct`] returns.
#[derive(Clone, Debug)]
pub struct Reconstruction {
    /// Stage 1 at the finest level.
    pub stage1: Option<Stage1Run>,
    /// The shape, per level (`None` when the configuration stops after stage 1).
    pub shape: Option<(ShapeSetup, Stage2Result)>,
}

/// Runs the reconstruction `config` describes on `datasets` (same object and camera, one lamp
/// configuration each, read by `Dataset::load` with `LoadOptions::from(&config.input)`),
/// reporting to `observer`.
///
/// # Errors
/// Incompatible datasets, a configuration the data cannot satisfy (a missing `lamps.json`
/// where lamps are needed, too few frames, ...), numerical failure.
pub fn reconstruct(
    datasets: &[Dataset],
    config: &ReconConfig,
    observer: &mut dyn Observer,
) -> Result<Reconstruction, ReconError> {
    config.validate().map_err(ReconError::Input)?;
    if config.stage == Stage::Laplacian {
        return Ok(Reconstruction { stage1: Some(reconstruct_stage1(datasets, config, observer)?), shape: None });
    }
    check_compatible(datasets)?;
    let finest = Level::build(datasets, config.level);
    let setup = shape_setup(datasets, &finest, config, observer)?;
    let (ambient, emissivity) = (datasets[0].ambient, datasets[0].emissivity);
    let mut last: Option<Stage1Run> = None;
    let result = crate::stage2::reconstruct(
        &finest,
        ambient,
        emissivity,
        &setup.options,
        |level, input, observer| {
            let run = stage1_at(level, input, config, observer)?;
            let params = stage2_params(&run, input, config);
            last = Some(run);
            Ok(params)
        },
        observer,
    )?;
    Ok(Reconstruction { stage1: last, shape: Some((setup, result)) })
}

/// Stage 1 alone at `config.level` on `datasets`.
///
/// # Errors
/// As [`reconstruct`].
pub fn reconstruct_stage1(
    datasets: &[Dataset],
    config: &ReconConfig,
    observer: &mut dyn Observer,
) -> Result<Stage1Run, ReconError> {
    config.validate().map_err(ReconError::Input)?;
    check_compatible(datasets)?;
    let level = Level::build(datasets, config.level);
    observer.message(&format!(
        "level {}: {} x {}, {} frames, {} videos",
        level.level,
        level.camera.width,
        level.camera.height,
        level.times.len(),
        level.rises.len()
    ));
    let mut input = Stage1Input::from_level(&level, datasets[0].ambient, datasets[0].emissivity)?;
    stage1_at(&level, &mut input, config, observer)
}

/// Stage 1 at `level`: denoises `input` in place (the shape's data term then uses it) and
/// estimates.
fn stage1_at(
    level: &Level,
    input: &mut Stage1Input,
    config: &ReconConfig,
    observer: &mut dyn Observer,
) -> Result<Stage1Run, ReconError> {
    // The raw data's noise, before any denoising (a clean video has none unless netd_k says at
    // which noise to evaluate it).
    let measured = if config.input.video == Video::Clean { None } else { noise_sigma(input) };
    let noise = config.input.netd_k.or(measured).filter(|s| *s > 0.0);
    let denoise = denoise(input, config, observer)?;
    let opts = stage1_options(config, noise_level(config, input, denoise.as_ref()), level.level);
    observer.message(&format!(
        "stage 1 at level {} on {} vertices, {} triangles",
        level.level,
        input.grid.vertex_count(),
        input.grid.tris.len()
    ));
    let result = estimate(input, &opts)?;
    observer.message(&format!(
        "stage 1 done ({} iterations): lambda = {:.6e} +- {:.1e} 1/s, C = {:?}, h = {:?}",
        result.iterations,
        result.lambda.value,
        result.lambda.sigma,
        result.heat_capacity.map(|e| (e.value, e.sigma)),
        result.convection.map(|e| (e.value, e.sigma)),
    ));
    let halfspace = (result.flux_over_c.len() >= 2)
        .then(|| halfspace(&result.flux_over_c[0], &result.flux_over_c[1], config.stage1.halfspace_threshold));
    observer.stage1(level, &result, halfspace.as_deref(), noise);
    Ok(Stage1Run { level: level.clone(), result, halfspace, denoise, noise })
}

/// What the shape stage takes from stage 1 at a level; `input` is the (denoised) stage-1 input.
fn stage2_params(run: &Stage1Run, input: &Stage1Input, config: &ReconConfig) -> Stage1Params {
    let res = &run.result;
    let noise_cov = match config.shape.noise_correction {
        NoiseCorrection::None => Vec::new(),
        NoiseCorrection::Removed => noise_covariances(input, run.denoise.as_ref(), config.input.netd_k),
    };
    Stage1Params {
        lambda: res.lambda.value,
        c_inv: res.c.map(|c| c.value).filter(|c| c.is_finite() && *c > 0.0).unwrap_or(0.0),
        flux_over_c: res.flux_over_c.clone(),
        halfspace: run.halfspace.clone(),
        noise_cov,
        source: "stage 1 estimate".into(),
    }
}

/// Temporal low-rank denoising of `input` as `config.stage1.denoise` asks, at `input.netd_k` or
/// the noise measured on the frames at t <= 0 of this level.
fn denoise(
    input: &mut Stage1Input,
    config: &ReconConfig,
    observer: &mut dyn Observer,
) -> Result<Option<DenoiseReport>, ReconError> {
    if config.stage1.denoise == Denoise::None {
        return Ok(None);
    }
    let (sigma, source) =
        match config.input.netd_k {
            Some(s) => (s, "input.netd_k".to_string()),
            None => match noise_sigma(input) {
                Some(s) => (s, "pooled temporal std of the frames at t <= 0".to_string()),
                None => return Err(ReconError::Input(
                    "stage1.denoise low_rank needs the noise level: the datasets have fewer than 2 frames at t <= 0 \
                     (before the lamps switch on) to estimate it; give input.netd_k (--netd K) or set \
                     stage1.denoise=none"
                        .into(),
                )),
            },
        };
    #[cfg(not(feature = "experimental"))]
    let rep = crate::stage1::denoise::low_rank(input, sigma, &source);
    #[cfg(feature = "experimental")]
    let rep = crate::stage1::denoise::low_rank_at_least(input, sigma, &source, config.experimental.min_rank);
    observer.message(&format!("denoised: sigma {:.2e} K ({}), ranks {:?}", rep.sigma, rep.sigma_source, rep.ranks));
    Ok(Some(rep))
}

/// Per video, the temporal covariance of the noise left in `input`'s series (K^2, frames x
/// frames): the denoiser's sigma projected on its kept basis, else white noise of the level's
/// noise estimated from the frames at t <= 0 (or `netd`); empty when neither is known.
fn noise_covariances(input: &Stage1Input, denoise: Option<&DenoiseReport>, netd: Option<f64>) -> Vec<Vec<f64>> {
    match denoise {
        Some(rep) => rep.basis.iter().map(|b| temporal_covariance(&input.times, rep.sigma, Some(b))).collect(),
        None => match noise_sigma(input).or(netd) {
            Some(s) => input.series.iter().map(|_| temporal_covariance(&input.times, s, None)).collect(),
            None => Vec::new(),
        },
    }
}

/// The temporal noise of the data (K) that picks stage 1's defaults: the denoiser's sigma, else
/// estimated from the frames at t <= 0, else `input.netd_k`.
fn noise_level(config: &ReconConfig, input: &Stage1Input, denoise: Option<&DenoiseReport>) -> Option<f64> {
    denoise.map(|r| r.sigma).or_else(|| noise_sigma(input)).or(config.input.netd_k)
}

/// Stage 1's options: [`Stage1Options::for_noise`] for the data's `noise` (K) at pyramid
/// `level`, then the configuration.
fn stage1_options(config: &ReconConfig, noise: Option<f64>, level: usize) -> Stage1Options {
    let defaults = Stage1Options::for_noise(noise, level);
    let c = &config.stage1;
    Stage1Options {
        time_rule: c.time_rule,
        radiation: c.radiation,
        known: c.known,
        t_start: c.t_start_s,
        t_end: c.t_end_s.unwrap_or(f64::INFINITY),
        nonnegative_weights: c.edge_weights == EdgeWeights::Nonnegative,
        stencil: c.stencil,
        smoothing: match c.smoothing {
            Some(k) => Some(k).filter(|&k| k > 0.0),
            None => defaults.smoothing,
        },
        ..defaults
    }
}

/// The shape stage's options from `config` and the datasets (levels, lamps, scale).
fn shape_setup(
    datasets: &[Dataset],
    finest: &Level,
    config: &ReconConfig,
    observer: &mut dyn Observer,
) -> Result<ShapeSetup, ReconError> {
    let s = &config.shape;
    let min_vertices = s.min_coarsest_vertices;
    let extra_levels = finest.coarser_vertex_counts(s.extra_levels).iter().take_while(|&&n| n >= min_vertices).count();
    if extra_levels < s.extra_levels {
        observer.message(&format!(
            "note: starting at level {} instead of {}: the coarser levels have fewer than {min_vertices} vertices \
             (shape.min_coarsest_vertices)",
            config.level + extra_levels,
            config.level + s.extra_levels
        ));
    }
    #[cfg(feature = "experimental")]
    if let Some(oe) = &config.experimental.output_error {
        if oe.level > config.level + extra_levels {
            return Err(ReconError::Input(format!(
                "experimental.output_error.level {}: level {} has fewer than {min_vertices} vertices \
                 (shape.min_coarsest_vertices)",
                oe.level, oe.level
            )));
        }
    }
    let cam = &finest.camera;
    let axis = lamp_axis(datasets, config.input.lamp_sides.as_deref(), cam, observer)?;
    #[cfg(feature = "experimental")]
    let lamp_ratio = match &config.experimental.lamp_ratio {
        Some(_) if datasets.len() < 2 => {
            return Err(ReconError::Input(format!("experimental.lamp_ratio needs two videos, got {}", datasets.len())))
        }
        term => lamp_term("experimental.lamp_ratio", term.as_ref(), &datasets[..2.min(datasets.len())], cam, observer)?,
    };
    let lamp_shading = lamp_term("shape.lamp_shading", s.lamp_shading.as_ref(), datasets, cam, observer)?;
    let halfspace_term = axis.is_some();
    if !halfspace_term {
        observer.message(
            "note: fewer than two videos with lamps on opposite sides: stage 2 runs WITHOUT the half-space term \
             (degraded mode: the convex/concave choice is not constrained)",
        );
    }
    // Lamp shading fixes the distance itself: the size is not held while the diffusivity is
    // profiled (stage2::lamp_shading).
    let fixed_scale = s.size == SizeRule::Fixed || lamp_shading.is_some();
    let scale = config.input.diffusivity_m2_per_s.map_or(Scale::Profiled, Scale::Diffusivity);
    let distance = config.input.distance_m.unwrap_or_else(|| cam.t.iter().map(|x| x * x).sum::<f64>().sqrt());
    if !(distance > 0.0 && distance.is_finite()) {
        return Err(ReconError::Input(format!("the nominal distance must be > 0 m, got {distance}")));
    }
    // The frame choice (time rule, window) shared with stage 1.
    let frames = stage1_options(config, None, config.level);
    let options = Stage2Options {
        extra_levels,
        finest: config.level,
        scale,
        distance,
        optim: OptimOptions {
            optimizer: s.optimizer,
            iterations: s.iterations,
            learning_rate: s.learning_rate_m,
            large_steps_lambda: s.large_steps_lambda,
            min_depth: 1e-3 * distance,
            blocks: Vec::new(),
        },
        coarsest_iterations: s.coarsest_iterations,
        normal_consistency: s.normal_weight,
        halfspace_weight: if halfspace_term { s.halfspace_weight } else { 0.0 },
        halfspace_decay: s.halfspace_decay,
        lamp_axis: axis.unwrap_or([1.0, 0.0, 0.0]),
        time_rule: frames.time_rule,
        t_start: frames.t_start,
        t_end: frames.t_end,
        robust: s.data_loss == DataLoss::Robust,
        profile_flux: s.flux == FluxModel::Profiled,
        boundary_rings: s.boundary_rings,
        profile_globals: s.globals != Globals::Stage1,
        joint_globals: s.globals == Globals::Joint,
        profile_scale: !fixed_scale,
        #[cfg(feature = "experimental")]
        output_error: config.experimental.output_error.clone(),
        #[cfg(feature = "experimental")]
        initial_depth: config.experimental.initial_depth.clone(),
        #[cfg(feature = "experimental")]
        lamp_ratio,
        lamp_shading,
        symmetry_weight: s.symmetry_weight,
    };
    Ok(ShapeSetup { options, distance, halfspace_term })
}

/// The lamp axis of the half-space term (camera frame, from video 2's lamp towards video 1's):
/// from `sides` or the first lamp of each of the first two videos' `lamps.json`; `None` with
/// fewer than two videos or both lamps on one side.
fn lamp_axis(
    datasets: &[Dataset],
    sides: Option<&[LampSide]>,
    cam: &CameraInfo,
    observer: &mut dyn Observer,
) -> Result<Option<[f64; 3]>, ReconError> {
    if datasets.len() < 2 {
        return Ok(None);
    }
    let sides: Vec<f64> = match sides {
        Some(sides) => {
            if sides.len() != datasets.len() {
                return Err(ReconError::Input(format!(
                    "input.lamp_sides has {} entries for {} videos",
                    sides.len(),
                    datasets.len()
                )));
            }
            sides.iter().map(|s| if *s == LampSide::Left { -1.0 } else { 1.0 }).collect()
        }
        None => {
            let mut sides = Vec::new();
            for d in &datasets[..2] {
                let p = d.dir.join(format::LAMPS_FILE);
                let file = match format::read_lamps(&d.dir) {
                    Err(e) if e.is_not_found() => {
                        return Err(ReconError::Input(format!(
                            "{}: missing; give the lamp sides (--lamp-sides left,right) for the half-space term",
                            p.display()
                        )))
                    }
                    r => r?,
                };
                file.warnings.iter().for_each(|w| observer.message(&format!("warning: {w}")));
                let pos = match file.lamps.first() {
                    Some(heatsim::scene::LampSpec::Point(l)) => l.position,
                    _ => {
                        return Err(ReconError::format(
                            &p,
                            "no lamp position (no lamp, or the first is not a point lamp)",
                        ))
                    }
                };
                sides.push(cam_x(cam, pos).signum());
            }
            sides
        }
    };
    if sides[0] == sides[1] {
        observer.message("warning: both lamps on the same side: no half-space term (degraded mode)");
        return Ok(None);
    }
    // Axis from video 2's lamp towards video 1's: camera x times the side of video 1.
    Ok(Some([sides[0], 0.0, 0.0]))
}

/// Camera-frame x of world point `p`.
fn cam_x(cam: &CameraInfo, p: [f64; 3]) -> f64 {
    cam.r[0][0] * p[0] + cam.r[0][1] * p[1] + cam.r[0][2] * p[2] + cam.t[0]
}

/// The options of a calibrated-lamp term (`name`, for errors) with the point lamps of each of
/// `datasets` (its `lamps.json`), in camera coordinates; `None` without the term.
fn lamp_term(
    name: &str,
    term: Option<&LampTermConfig>,
    datasets: &[Dataset],
    cam: &CameraInfo,
    observer: &mut dyn Observer,
) -> Result<Option<LampTermOptions>, ReconError> {
    use heatsim::scene::LampSpec;
    let Some(term) = term else { return Ok(None) };
    let mut sets = Vec::new();
    for d in datasets {
        let p = d.dir.join(format::LAMPS_FILE);
        let file = format::read_lamps(&d.dir)?;
        file.warnings.iter().for_each(|w| observer.message(&format!("warning: {w}")));
        let mut v = Vec::new();
        for l in file.lamps {
            let LampSpec::Point(l) = l else {
                return Err(ReconError::format(&p, format!("{name} needs point lamps, found a uniform one")));
            };
            if !(l.on <= 0.0 && l.off.is_none()) {
                return Err(ReconError::format(&p, format!("{name} needs lamps on throughout (on <= 0, no off time)")));
            }
            let q = l.position;
            let position: [f64; 3] =
                std::array::from_fn(|r| cam.r[r][0] * q[0] + cam.r[r][1] * q[1] + cam.r[r][2] * q[2] + cam.t[r]);
            v.push(PointLamp { position, radiant_power: l.power * l.radiant_fraction });
        }
        if v.is_empty() {
            return Err(ReconError::format(&p, format!("no lamp for {name}")));
        }
        sets.push(v);
    }
    Ok(Some(LampTermOptions { lamps: sets, weight: term.weight, threshold: term.threshold }))
}
