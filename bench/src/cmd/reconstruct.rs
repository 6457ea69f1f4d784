//! `simbench reconstruct DIR... --out OUT [--stage 1]`: the reconstruction from thermal videos
//! (stage 1: paper Sec. 5, `heatrecon::stage1`; stage 2 is issue 8). With `--check`, also
//! prints and writes (`check.json`) stage 1's figures against the ground truth of simulated
//! datasets (`heatrecon::validate`; the estimate itself never reads ground truth), and the
//! Cramer-Rao bound on the globals at the data's noise (`heatrecon::stage1::bound`).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use heatrecon::dataset::{check_compatible, Dataset, LoadOptions};
use heatrecon::pyramid::Level;
use heatrecon::stage1::{estimate, Known, Radiation, Stage1Input, Stage1Options, Stencil, TimeRule};

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum TimeRuleArg {
    BackwardEuler,
    Trapezoid,
    Central,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum RadiationArg {
    Linearized,
    Full,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum StencilArg {
    Free,
    Paired,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum DenoiseArg {
    None,
    LowRank,
}

#[derive(clap::Args)]
pub struct Args {
    /// Dataset directories (same object and camera, one lamp configuration each).
    #[arg(required = true)]
    dirs: Vec<PathBuf>,
    /// Output directory; files appear only once everything succeeded.
    #[arg(long)]
    out: PathBuf,
    /// Stage to run up to (1: Laplacian, flux, parameters).
    #[arg(long, default_value_t = 1)]
    stage: u32,
    /// Pyramid level (0: full resolution; each level halves it by 2 x 2 block averaging).
    #[arg(long, default_value_t = 0)]
    level: usize,
    /// Read video_clean.npy (noise-free; simulated datasets only).
    #[arg(long)]
    clean: bool,
    /// Emissivity, when environment.json has none (or to override it).
    #[arg(long)]
    emissivity: Option<f64>,
    /// Time rule of stage 1's equations (central: five-point derivative at each frame; stage 2
    /// uses frame pairs, with the trapezoid for central).
    #[arg(long, value_enum, default_value = "central")]
    time_rule: TimeRuleArg,
    /// Radiation model (full: fits 1/C on the T^4 curvature; linearized: Eq. 5, only (h+R)/C).
    #[arg(long, value_enum, default_value = "full")]
    radiation: RadiationArg,
    /// Known convection coefficient h (W/(m^2 K)): C follows from (h + R)/C.
    #[arg(long, conflicts_with = "heat_capacity")]
    convection: Option<f64>,
    /// Known heat capacity per area C (J/(m^2 K)): h follows.
    #[arg(long)]
    heat_capacity: Option<f64>,
    /// Constrain edge weights to be >= 0 (the paper's constraint; cotangent weights can be negative).
    #[arg(long)]
    nonnegative_weights: bool,
    /// First frame time used (s; lamps switch on at 0).
    #[arg(long, default_value_t = 0.0)]
    t_start: f64,
    /// Last frame time used (s).
    #[arg(long)]
    t_end: Option<f64>,
    /// Half-space threshold on the normalised flux difference (Eq. 9).
    #[arg(long, default_value_t = heatrecon::halfspace::DEFAULT_THRESHOLD)]
    threshold: f64,
    /// Parameterisation of the rows of Delta_s (paired: opposite neighbours share a weight).
    #[arg(long, value_enum, default_value = "free")]
    stencil: StencilArg,
    /// Temporal denoising before the estimate (low-rank: truncated SVD at the noise threshold).
    #[arg(long, value_enum, default_value = "low-rank")]
    denoise: DenoiseArg,
    /// Noise (NETD) in K for the denoising threshold and --check's Cramer-Rao bound; default:
    /// estimated from the frames at t <= 0 (with --clean: no bound).
    #[arg(long)]
    netd: Option<f64>,
    /// Graph regularisation strength kappa of the Delta_s rows (0: none; see heatrecon::stage1::smooth);
    /// default 1e-6 x 10^level when the noise is below 1 mK, else 1
    /// (heatrecon::stage1::Stage1Options::for_noise).
    #[arg(long)]
    smoothing: Option<f64>,
    /// Print and write (check.json) figures against the datasets' ground truth, with the
    /// Cramer-Rao bound on lambda, C and h at the data's noise (from video_clean.npy).
    #[arg(long)]
    check: bool,
    #[command(flatten)]
    s2: Stage2Args,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if args.stage == 2 {
        return run_stage2(args);
    }
    if args.stage != 1 {
        anyhow::bail!("--stage {}: only stage 1 exists so far (stage 2 is issue 8)", args.stage);
    }
    let t0 = Instant::now();
    let lo = LoadOptions { emissivity: args.emissivity, clean: args.clean };
    let mut sets = Vec::new();
    for d in &args.dirs {
        eprintln!("[{:6.2} s] reading {}", t0.elapsed().as_secs_f64(), d.display());
        sets.push(Dataset::load(d, &lo)?);
    }
    check_compatible(&sets)?;
    let level = Level::build(&sets, args.level);
    eprintln!(
        "[{:6.2} s] level {}: {} x {}, {} frames, {} videos",
        t0.elapsed().as_secs_f64(),
        level.level,
        level.camera.width,
        level.camera.height,
        level.times.len(),
        level.rises.len()
    );
    let mut input = Stage1Input::from_level(&level, sets[0].ambient, sets[0].emissivity)?;
    // The raw data's noise, for --check's bound (before any denoising; a clean video has none
    // unless --netd says at which noise to evaluate it).
    let measured = if args.clean { None } else { heatrecon::stage1::denoise::noise_sigma(&input) };
    let raw_sigma = args.netd.or(measured).filter(|s| *s > 0.0);
    let denoise = denoise_input(&args, &mut input, t0)?;
    let opts = stage1_options(&args, noise_level(&args, &input, denoise.as_ref()), level.level);
    eprintln!(
        "[{:6.2} s] stage 1 on {} vertices, {} triangles",
        t0.elapsed().as_secs_f64(),
        input.grid.vertex_count(),
        input.grid.tris.len()
    );
    let ts = Instant::now();
    let res = estimate(&input, &opts)?;
    let stage1_s = ts.elapsed().as_secs_f64();
    eprintln!(
        "[{:6.2} s] stage 1 done in {stage1_s:.2} s ({} iterations): lambda = {:.6e} +- {:.1e} 1/s, C = {:?}, h = {:?}",
        t0.elapsed().as_secs_f64(),
        res.iterations,
        res.lambda.value,
        res.lambda.sigma,
        res.heat_capacity.map(|e| (e.value, e.sigma)),
        res.convection.map(|e| (e.value, e.sigma)),
    );
    let hs = (res.flux_over_c.len() >= 2)
        .then(|| heatrecon::halfspace::halfspace(&res.flux_over_c[0], &res.flux_over_c[1], args.threshold));
    let options = serde_json::json!({
        "inputs": args.dirs, "clean": args.clean, "time_rule": format!("{:?}", opts.time_rule),
        "radiation": format!("{:?}", opts.radiation), "known": format!("{:?}", opts.known),
        "nonnegative_weights": opts.nonnegative_weights, "t_start": opts.t_start, "t_end": args.t_end,
        "stage1_seconds": stage1_s, "stencil": format!("{:?}", opts.stencil), "denoise": denoise,
        "level": args.level, "smoothing": res.smoothing,
    });
    let mut out =
        heatsim::io::OutputDir::new(&args.out).with_context(|| format!("preparing {}", args.out.display()))?;
    heatrecon::output::write_stage1(
        &mut out,
        &args.out,
        &res,
        &level,
        hs.as_deref().map(|h| (h, args.threshold)),
        options,
    )?;
    if args.check {
        let truths = args
            .dirs
            .iter()
            .map(|d| heatrecon::validate::Truth::load(d, args.level))
            .collect::<Result<Vec<_>, _>>()
            .context("--check needs the ground truth of simulated datasets")?;
        truths.iter().flat_map(|t| &t.warnings).for_each(|w| eprintln!("warning: {w}"));
        let mut c =
            heatrecon::validate::check(&res, &level.camera, &truths, hs.as_deref().map(|h| (h, args.threshold)));
        if let Some(sigma) = raw_sigma {
            // The bound is an addition to the figures: without a noise-free video, say so.
            match check_bound(&args, &truths[0], res.radiation_coefficient, sigma, t0) {
                Ok(b) => c.bound = Some(b),
                Err(e) => eprintln!("no Cramer-Rao bound: {e:#}"),
            }
        }
        let text = serde_json::to_string_pretty(&c)?;
        println!("{text}");
        out.write_bytes("check.json", text.as_bytes())?;
        let (w, h) = (level.camera.width, level.camera.height);
        let mut img = ndarray::Array2::<f32>::from_elem((h, w), f32::NAN);
        for (k, &p) in res.grid.pixels.iter().enumerate() {
            img[[p / w, p % w]] = c.row_error[k] as f32;
        }
        out.write_with("check_row_error.npy", |wr| {
            ndarray_npy::WriteNpyExt::write_npy(&img, wr).map_err(std::io::Error::other)
        })?;
    }
    out.commit().with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!("[{:6.2} s] wrote {}", t0.elapsed().as_secs_f64(), args.out.display());
    Ok(())
}

/// The Cramér–Rao bound on the globals for `--check`, from the datasets' noise-free videos at
/// the run's level (`heatrecon::validate::globals_bound`); printed as it is computed.
fn check_bound(
    args: &Args,
    t0: &heatrecon::validate::Truth,
    radiation_coefficient: f64,
    sigma: f64,
    start: Instant,
) -> anyhow::Result<heatrecon::validate::Stage1Bound> {
    let lo = LoadOptions { emissivity: args.emissivity, clean: true };
    let sets = args.dirs.iter().map(|d| Dataset::load(d, &lo)).collect::<Result<Vec<_>, _>>()?;
    let level = Level::build(&sets, args.level);
    let clean = Stage1Input::from_level(&level, sets[0].ambient, sets[0].emissivity)?;
    let b = heatrecon::validate::globals_bound(&clean, t0, radiation_coefficient, sigma);
    let show = |g: Option<heatrecon::stage1::bound::GlobalsBound>| match g {
        Some(g) => format!(
            "C +-{:.3} %, h +-{:.3} W/(m^2 K), lambda +-{:.3} %",
            100.0 * g.heat_capacity_rel_std,
            g.convection_std,
            100.0 * g.lambda_rel_std
        ),
        None => "no information".to_string(),
    };
    eprintln!(
        "[{:6.2} s] Cramer-Rao bound at {sigma:.3e} K: rows known: {}; paired: {}; free: {}",
        start.elapsed().as_secs_f64(),
        show(b.rows_known),
        show(b.rows_paired),
        show(b.rows_free)
    );
    Ok(b)
}

// ---------------------------------------------------------------------------------------------
// Stage 2 (issue 8): shape from the Laplacian, coarse to fine. `--stage 2` runs stages 1 and 2.
// ---------------------------------------------------------------------------------------------

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum OptimizerArg {
    /// Large steps + AdamUniform (the paper).
    AdamUniform,
    /// Large steps + L-BFGS.
    Lbfgs,
}

/// Options of stage 2 (`--stage 2`).
#[derive(clap::Args)]
pub struct Stage2Args {
    /// Test-only: take lambda, 1/C and q/C from the simulated datasets' ground truth instead of
    /// stage 1 (measures stage 2 alone). Stage-1 files are then not written.
    #[arg(long)]
    oracle_stage1: bool,
    /// Material diffusivity k/(rho c_p), m^2/s: a metric shape. Without it the diffusivity is
    /// profiled out and the shape's size is fixed by --distance (the authors' nominal distance).
    #[arg(long)]
    diffusivity: Option<f64>,
    /// Test-only: the diffusivity from the datasets' material.json.
    #[arg(long)]
    true_diffusivity: bool,
    /// Nominal object distance, m (start plane; mean depth when the diffusivity is profiled).
    /// Default: the camera's distance to the world origin, |t| of camera.json.
    #[arg(long)]
    distance: Option<f64>,
    /// Coarser pyramid levels above --level to start from.
    #[arg(long, default_value_t = 2)]
    extra_levels: usize,
    /// Start no coarser than the coarsest of those levels whose pixel mesh has at least this
    /// many vertices (drops levels of --extra-levels). Default: 500 with --lamp-shading (whose
    /// fit went wrong from coarsest levels of about 200 vertices), else no limit.
    #[arg(long)]
    min_coarsest_vertices: Option<usize>,
    /// Optimiser.
    #[arg(long, value_enum, default_value = "lbfgs")]
    optimizer: OptimizerArg,
    /// Iterations per level.
    #[arg(long, default_value_t = 200)]
    iterations: usize,
    /// Iterations at the coarsest level (default: --iterations). Its unknowns are few and
    /// cheap, and the slow modes (the distance, the offsets of thin parts) are set there.
    #[arg(long)]
    coarsest_iterations: Option<usize>,
    /// AdamUniform step (m); L-BFGS: first step's largest depth change (m).
    #[arg(long, default_value_t = 2e-4)]
    learning_rate: f64,
    /// Large-steps lambda.
    #[arg(long, default_value_t = 2.0)]
    large_steps: f64,
    /// Normal-consistency weight.
    #[arg(long, default_value_t = 0.1)]
    normal_weight: f64,
    /// Half-space hinge weight at the coarsest level (decayed per level, 0 at the finest).
    #[arg(long, default_value_t = 1e-2)]
    halfspace_weight: f64,
    /// Side of the camera (image x) of each video's lamp, e.g. `left,right`; default: from
    /// lamps.json beside each video when present.
    #[arg(long, value_delimiter = ',')]
    lamp_sides: Vec<String>,
    /// Experimental: weight of the two-light flux ratio term at every level (heatrecon's
    /// stage2::lamp_ratio), from the point lamps in lamps.json beside the first two videos
    /// (positions taken to camera coordinates by camera.json). Default: off.
    #[arg(long)]
    lamp_ratio: Option<f64>,
    /// With --lamp-ratio: a vertex enters the term when both stage-1 fluxes exceed this fraction
    /// of their maximum.
    #[arg(long, default_value_t = 0.2, requires = "lamp_ratio")]
    lamp_ratio_threshold: f64,
    /// Experimental: weight of the lamp-shading term at every level (heatrecon's
    /// stage2::lamp_shading: each video's stage-1 flux against the irradiance of the point
    /// lamps in lamps.json beside it, times one fitted absorptivity / (4 pi C)). Default: off.
    #[arg(long)]
    lamp_shading: Option<f64>,
    /// With --lamp-shading: a vertex enters the term for a video when its stage-1 flux exceeds
    /// this fraction of the image's maximum (leaves cast shadows out).
    #[arg(long, default_value_t = 0.2, requires = "lamp_shading")]
    lamp_shading_threshold: f64,
    /// Weight of the mirror-symmetry term at the coarsest level (heatrecon's stage2::symmetry:
    /// depth mirrored about the mask's centre column, relative to the nominal distance), for
    /// objects symmetric left to right. Default: 0 (off).
    #[arg(long, default_value_t = 0.0)]
    symmetry: f64,
    /// Data loss: L2 (all squared residuals) instead of robust (mean over vertices of their RMS
    /// residual, the default).
    #[arg(long)]
    l2: bool,
    /// Test-only: report depth errors against gt_depth.npy in the log (never used by the fit).
    #[arg(long)]
    depth_truth: bool,
    /// Diagnostic (with --depth-truth and a diffusivity): at every level, the Cramér–Rao bound
    /// on the shape from the videos at the true depth (heatrecon::stage2::output_error::bound):
    /// the size, the relief and the image-coordinate polynomials up to this degree, with the
    /// fluxes and globals unknown or known. With --oracle-stage1 it is taken at the true fluxes
    /// and globals. Printed and written to stage2.json.
    #[arg(long, value_name = "DEGREE")]
    shape_bound: Option<usize>,
    /// With --shape-bound: CGLS iterations at most per projection of the fluxes.
    #[arg(long, default_value_t = 400)]
    shape_bound_iterations: usize,
    /// Data term: use stage 1's flux images as they are, instead of minimising over a constant
    /// flux per vertex and video (the default: only the time-varying part of the heat equation
    /// constrains the shape, and a biased flux image cannot bias it).
    #[arg(long)]
    stage1_flux: bool,
    /// Leave the vertices within this many rings of the mask boundary out of the data term
    /// (partly covered pixels).
    #[arg(long, default_value_t = 2)]
    boundary_rings: usize,
    /// Keep stage 1's lambda = (h+R)/C and 1/C fixed in the shape's data term, instead of
    /// minimising over them from stage 1's values (the default, robust loss only): the shape
    /// then inherits stage 1's error in them.
    #[arg(long)]
    stage1_globals: bool,
    /// Profile lambda and 1/C out at every evaluation (the former default: their minimiser
    /// jumps with the depths at 50 mK, and L-BFGS's line search gives up), instead of
    /// minimising over them jointly with the depths (the default with L-BFGS and the robust
    /// loss; heatrecon::stage2::energy::energy_at_globals).
    #[arg(long, conflicts_with = "stage1_globals")]
    profiled_globals: bool,
    /// Leave the expected contribution of the temperature noise in the shape's data term
    /// (errors in variables; heatrecon::stage2::noise), instead of removing it (the default).
    /// Left in, noise biases the shape away from the camera.
    #[arg(long)]
    no_noise_correction: bool,
    /// With a known diffusivity, keep it fixed in the data term while optimising, instead of
    /// profiling it out at each level (the shape's size then a flat direction) and scaling
    /// the shape to it afterwards (the default). Fixed, the size is a slow mode that stays
    /// near the start distance (README, stage 2). Implied by --lamp-shading, whose lamps fix the
    /// distance.
    #[arg(long)]
    fixed_scale: bool,
    /// Experimental: after the equation-error fit at this pyramid level, refine the shape by
    /// fitting the video as filmed through the surface heat equation (output error,
    /// heatrecon::stage2::output_error; needs the diffusivity). Not the paper's method.
    #[arg(long)]
    output_error_level: Option<usize>,
    /// Rounds (flux fit + shape fit) of the output-error refinement.
    #[arg(long, default_value_t = 10)]
    output_error_rounds: usize,
    /// Large-steps lambda of the output-error shape fits.
    #[arg(long, default_value_t = 1000.0)]
    output_error_large_steps: f64,
    /// Keep the mean depth during the output-error shape fits.
    #[arg(long)]
    output_error_hold_mean_depth: bool,
    /// Every this many output-error rounds, a one-dimensional search of the size with flux
    /// refits (0: none).
    #[arg(long, default_value_t = 0)]
    output_error_size_every: usize,
    /// L-BFGS iterations of each output-error shape fit.
    #[arg(long, default_value_t = 10)]
    output_error_shape_iterations: usize,
    /// L-BFGS iterations of each output-error flux fit (0: the fluxes stay stage 1's).
    #[arg(long, default_value_t = 15)]
    output_error_flux_iterations: usize,
    /// Implicit Euler steps per frame interval in the output-error prediction.
    #[arg(long, default_value_t = 1)]
    output_error_substeps: usize,
    /// Weight of normal consistency in the output-error shape fits, in units of the noise
    /// variance (estimated from the frames at t <= 0; README, "Output-error refinement").
    #[arg(long, default_value_t = 1.3)]
    output_error_normal: f64,
    /// Fit a constant offset per video and pixel in the output-error loss, over every frame
    /// including those before t = 0 (the fixed pattern those frames estimate is noisy).
    #[arg(long)]
    output_error_offsets: bool,
    /// Fit lambda = (h + R)/C and 1/C in the output-error refinement, with the fluxes,
    /// instead of keeping stage 1's.
    #[arg(long)]
    output_error_globals: bool,
    /// Each output-error round one joint L-BFGS of depths, fluxes (and globals) of
    /// --output-error-shape-iterations, instead of a shape fit and a flux fit.
    #[arg(long, conflicts_with = "output_error_hold_mean_depth")]
    output_error_joint: bool,
    /// Fit the output-error refinement to the even frames and keep the round whose prediction
    /// of the odd frames is best (a stopping rule; half the frames are fitted).
    #[arg(long)]
    output_error_holdout: bool,
    /// With --output-error-holdout: rounds without a better held-out loss before stopping.
    #[arg(long, default_value_t = 4)]
    output_error_patience: usize,
    /// Test-only diagnostic (needs the true depth, --depth-truth): fit the output-error model's
    /// own videos at the true shape plus white noise of the measured level, seeded by this.
    #[arg(long)]
    output_error_synthetic: Option<u64>,
    /// With --output-error-synthetic: add the error of a fixed pattern estimated from the
    /// frames up to t = 0 (a constant per pixel).
    #[arg(long, requires = "output_error_synthetic")]
    output_error_synthetic_pattern: bool,
}

/// The options of a calibrated-lamp term (`--lamp-ratio`, `--lamp-shading`: `flag`) of
/// `weight` and `threshold`, with the point lamps of `dirs` (lamps.json beside each video),
/// camera coordinates; `None` without a weight.
fn lamp_term_options(
    flag: &str,
    weight: Option<f64>,
    threshold: f64,
    dirs: &[std::path::PathBuf],
    cam: &heatrecon::dataset::CameraInfo,
) -> anyhow::Result<Option<heatrecon::stage2::coarse_to_fine::LampTermOptions>> {
    use heatrecon::stage2::lamp_ratio::PointLamp;
    use heatsim::scene::LampSpec;
    let Some(weight) = weight else { return Ok(None) };
    anyhow::ensure!(weight >= 0.0 && weight.is_finite(), "--{flag} must be >= 0, got {weight}");
    anyhow::ensure!((0.0..1.0).contains(&threshold), "--{flag}-threshold must be in [0, 1), got {threshold}");
    let mut sets = Vec::new();
    for d in dirs {
        let p = d.join(heatsim::dataset_format::LAMPS_FILE);
        let file = heatsim::dataset_format::read_lamps(d).with_context(|| format!("needed by --{flag}"))?;
        file.warnings.iter().for_each(|w| eprintln!("warning: {w}"));
        let mut v = Vec::new();
        for l in file.lamps {
            let LampSpec::Point(l) = l else {
                anyhow::bail!("{}: --{flag} needs point lamps, found a uniform one", p.display());
            };
            anyhow::ensure!(
                l.on <= 0.0 && l.off.is_none(),
                "{}: --{flag} needs lamps on throughout (on <= 0, no off time)",
                p.display()
            );
            let q = l.position;
            let position: [f64; 3] =
                std::array::from_fn(|r| cam.r[r][0] * q[0] + cam.r[r][1] * q[1] + cam.r[r][2] * q[2] + cam.t[r]);
            v.push(PointLamp { position, radiant_power: l.power * l.radiant_fraction });
        }
        anyhow::ensure!(!v.is_empty(), "{}: no lamp for --{flag}", p.display());
        sets.push(v);
    }
    Ok(Some(heatrecon::stage2::coarse_to_fine::LampTermOptions { lamps: sets, weight, threshold }))
}

fn lamp_axis(args: &Args, cam: &heatrecon::dataset::CameraInfo) -> anyhow::Result<Option<[f64; 3]>> {
    if args.dirs.len() < 2 {
        return Ok(None);
    }
    let side_of = |s: &str| -> anyhow::Result<f64> {
        match s.trim() {
            "left" => Ok(-1.0),
            "right" => Ok(1.0),
            other => anyhow::bail!("--lamp-sides: `{other}` is not left or right"),
        }
    };
    let sides: Vec<f64> = if !args.s2.lamp_sides.is_empty() {
        if args.s2.lamp_sides.len() != args.dirs.len() {
            anyhow::bail!("--lamp-sides has {} entries for {} videos", args.s2.lamp_sides.len(), args.dirs.len());
        }
        args.s2.lamp_sides.iter().map(|s| side_of(s)).collect::<anyhow::Result<_>>()?
    } else {
        let mut v = Vec::new();
        for d in &args.dirs[..2] {
            let p = d.join(heatsim::dataset_format::LAMPS_FILE);
            let file = match heatsim::dataset_format::read_lamps(d) {
                Err(e) if e.is_not_found() => anyhow::bail!(
                    "{}: missing; give the lamp sides with --lamp-sides left,right for the half-space term",
                    p.display()
                ),
                r => r?,
            };
            file.warnings.iter().for_each(|w| eprintln!("warning: {w}"));
            let pos = match file.lamps.first() {
                Some(heatsim::scene::LampSpec::Point(l)) => l.position,
                _ => anyhow::bail!("{}: no lamp position (no lamp, or the first is not a point lamp)", p.display()),
            };
            let xc = cam.r[0][0] * pos[0] + cam.r[0][1] * pos[1] + cam.r[0][2] * pos[2] + cam.t[0];
            v.push(xc.signum());
        }
        v
    };
    if sides[0] == sides[1] {
        eprintln!("warning: both lamps on the same side: no half-space term (degraded mode)");
        return Ok(None);
    }
    // Axis from video 2's lamp towards video 1's: camera x times the side of video 1.
    Ok(Some([sides[0], 0.0, 0.0]))
}

/// Temporal low-rank denoising of `input` as `--denoise` and `--netd` ask (the noise level
/// estimated from the frames at t <= 0 of this level when not given).
fn denoise_input(
    args: &Args,
    input: &mut Stage1Input,
    t0: Instant,
) -> anyhow::Result<Option<heatrecon::stage1::denoise::DenoiseReport>> {
    Ok(match args.denoise {
        DenoiseArg::None => None,
        DenoiseArg::LowRank => {
            let (sigma, source) = match args.netd {
                Some(s) if s.is_finite() && s >= 0.0 => (s, "--netd".to_string()),
                Some(s) => anyhow::bail!("--netd must be a finite number >= 0 K, got {s}"),
                None => match heatrecon::stage1::denoise::noise_sigma(input) {
                    Some(s) => (s, "pooled temporal std of the frames at t <= 0".to_string()),
                    None => anyhow::bail!(
                        "--denoise low-rank needs the noise level: the datasets have fewer than 2 frames at \
                         t <= 0 (before the lamps switch on) to estimate it; pass --netd K or --denoise none"
                    ),
                },
            };
            let rep = heatrecon::stage1::denoise::low_rank(input, sigma, &source);
            eprintln!(
                "[{:6.2} s] denoised: sigma {:.2e} K ({}), ranks {:?}",
                t0.elapsed().as_secs_f64(),
                rep.sigma,
                rep.sigma_source,
                rep.ranks
            );
            Some(rep)
        }
    })
}

/// Per video, the temporal covariance of the noise left in `input`'s series (K^2, frames x
/// frames): the denoiser's sigma projected on its kept basis, else white noise of the level's
/// noise estimated from the frames at t <= 0 (or `--netd`); empty when neither is known.
fn noise_covariances(
    input: &Stage1Input,
    denoise: Option<&heatrecon::stage1::denoise::DenoiseReport>,
    netd: Option<f64>,
) -> Vec<Vec<f64>> {
    use heatrecon::stage2::noise::temporal_covariance;
    match denoise {
        Some(rep) => rep.basis.iter().map(|b| temporal_covariance(&input.times, rep.sigma, Some(b))).collect(),
        None => match heatrecon::stage1::denoise::noise_sigma(input).or(netd) {
            Some(s) => input.series.iter().map(|_| temporal_covariance(&input.times, s, None)).collect(),
            None => Vec::new(),
        },
    }
}

/// The temporal noise of the data (K) that picks stage 1's defaults: the denoiser's sigma, else
/// estimated from the frames at t <= 0, else --netd.
fn noise_level(
    args: &Args,
    input: &Stage1Input,
    denoise: Option<&heatrecon::stage1::denoise::DenoiseReport>,
) -> Option<f64> {
    denoise.map(|r| r.sigma).or_else(|| heatrecon::stage1::denoise::noise_sigma(input)).or(args.netd)
}

/// Stage 1's options from the command line (shared by `--stage 1` and the stage-1 runs of
/// `--stage 2`): [`Stage1Options::for_noise`] for the data's `noise` (K) at pyramid `level`, then
/// the flags.
fn stage1_options(args: &Args, noise: Option<f64>, level: usize) -> Stage1Options {
    let defaults = Stage1Options::for_noise(noise, level);
    Stage1Options {
        time_rule: match args.time_rule {
            TimeRuleArg::BackwardEuler => TimeRule::BackwardEuler,
            TimeRuleArg::Trapezoid => TimeRule::Trapezoid,
            TimeRuleArg::Central => TimeRule::Central,
        },
        radiation: match args.radiation {
            RadiationArg::Linearized => Radiation::Linearized,
            RadiationArg::Full => Radiation::Full,
        },
        known: match (args.convection, args.heat_capacity) {
            (Some(h), _) => Known::Convection(h),
            (_, Some(c)) => Known::HeatCapacity(c),
            _ => Known::None,
        },
        t_start: args.t_start,
        t_end: args.t_end.unwrap_or(f64::INFINITY),
        nonnegative_weights: args.nonnegative_weights,
        stencil: match args.stencil {
            StencilArg::Free => Stencil::Free,
            StencilArg::Paired => Stencil::Paired,
        },
        smoothing: match args.smoothing {
            Some(k) => Some(k).filter(|&k| k > 0.0),
            None => defaults.smoothing,
        },
        ..defaults
    }
}

/// `--min-coarsest-vertices` with lamp shading: from coarsest levels of 206 vertices (the
/// bottle at 160 x 128) its fit moved the shape 10 cm, from 576 and more (every object at
/// 320 x 256) it did not (README, stage 2).
const MIN_COARSEST_VERTICES_SHADING: usize = 500;

fn run_stage2(args: Args) -> anyhow::Result<()> {
    use heatrecon::stage2::{self, OptimOptions, Optimizer, Scale, Stage1Params, Stage2Options};
    let t0 = Instant::now();
    if let Some(l) = args.s2.output_error_level {
        let coarsest = args.level + args.s2.extra_levels;
        anyhow::ensure!(
            (args.level..=coarsest).contains(&l),
            "--output-error-level {l}: not among the reconstructed levels {}..={coarsest} (--level, --extra-levels)",
            args.level
        );
        anyhow::ensure!(
            args.s2.diffusivity.is_some() || args.s2.true_diffusivity,
            "--output-error-level needs the diffusivity (--diffusivity or --true-diffusivity): the refinement is metric"
        );
    }
    if args.s2.shape_bound.is_some() {
        anyhow::ensure!(
            args.s2.depth_truth && (args.s2.diffusivity.is_some() || args.s2.true_diffusivity),
            "--shape-bound needs --depth-truth (the bound is taken at the true depth) and the diffusivity \
             (--diffusivity or --true-diffusivity)"
        );
        anyhow::ensure!(!args.clean, "--shape-bound needs the noisy videos: it cannot run with --clean");
    }
    let lo = LoadOptions { emissivity: args.emissivity, clean: args.clean };
    let mut sets = Vec::new();
    for d in &args.dirs {
        eprintln!("[{:6.2} s] reading {}", t0.elapsed().as_secs_f64(), d.display());
        sets.push(Dataset::load(d, &lo)?);
    }
    check_compatible(&sets)?;
    let finest = Level::build(&sets, args.level);
    let min_vertices = args.s2.min_coarsest_vertices.unwrap_or(if args.s2.lamp_shading.is_some() {
        MIN_COARSEST_VERTICES_SHADING
    } else {
        0
    });
    let extra_levels =
        finest.coarser_vertex_counts(args.s2.extra_levels).iter().take_while(|&&n| n >= min_vertices).count();
    if extra_levels < args.s2.extra_levels {
        eprintln!(
            "note: starting at level {} instead of {}: the coarser levels have fewer than {min_vertices} vertices (--min-coarsest-vertices)",
            args.level + extra_levels,
            args.level + args.s2.extra_levels
        );
    }
    if let Some(l) = args.s2.output_error_level {
        anyhow::ensure!(
            l <= args.level + extra_levels,
            "--output-error-level {l}: level {l} has fewer than {min_vertices} vertices (--min-coarsest-vertices)"
        );
    }
    let cam = &finest.camera;
    let axis = lamp_axis(&args, cam)?;
    anyhow::ensure!(
        args.s2.lamp_ratio.is_none() || args.dirs.len() >= 2,
        "--lamp-ratio needs two videos, got {}",
        args.dirs.len()
    );
    let lamp_ratio = lamp_term_options(
        "lamp-ratio",
        args.s2.lamp_ratio,
        args.s2.lamp_ratio_threshold,
        &args.dirs[..2.min(args.dirs.len())],
        cam,
    )?;
    let lamp_shading =
        lamp_term_options("lamp-shading", args.s2.lamp_shading, args.s2.lamp_shading_threshold, &args.dirs, cam)?;
    let degraded = axis.is_none();
    // Lamp shading fixes the distance itself: the size is not held while the diffusivity is
    // profiled (heatrecon::stage2::lamp_shading).
    let fixed_scale = args.s2.fixed_scale || lamp_shading.is_some();
    if degraded {
        eprintln!("note: fewer than two videos with lamps on opposite sides: stage 2 runs WITHOUT the half-space term (degraded mode: the convex/concave choice is not constrained)");
    }
    let scale = match (args.s2.diffusivity, args.s2.true_diffusivity) {
        (Some(a), _) => {
            anyhow::ensure!(a > 0.0 && a.is_finite(), "--diffusivity must be > 0 m^2/s, got {a}");
            Scale::Diffusivity(a)
        }
        (None, true) => Scale::Diffusivity(heatrecon::stage2::true_physics(&args.dirs[0])?.2),
        (None, false) => Scale::Profiled,
    };
    anyhow::ensure!(
        args.s2.symmetry >= 0.0 && args.s2.symmetry.is_finite(),
        "--symmetry must be a finite weight >= 0, got {}",
        args.s2.symmetry
    );
    let distance = args.s2.distance.unwrap_or_else(|| cam.t.iter().map(|x| x * x).sum::<f64>().sqrt());
    anyhow::ensure!(distance > 0.0 && distance.is_finite(), "--distance must be > 0 m, got {distance}");
    // The frame choice (time rule, window) shared with stage 1.
    let frames = stage1_options(&args, None, args.level);
    let opts = Stage2Options {
        extra_levels,
        finest: args.level,
        scale,
        distance,
        optim: OptimOptions {
            optimizer: match args.s2.optimizer {
                OptimizerArg::AdamUniform => Optimizer::AdamUniform,
                OptimizerArg::Lbfgs => Optimizer::Lbfgs,
            },
            iterations: args.s2.iterations,
            learning_rate: args.s2.learning_rate,
            large_steps_lambda: args.s2.large_steps,
            min_depth: 1e-3 * distance,
            blocks: Vec::new(),
        },
        coarsest_iterations: args.s2.coarsest_iterations,
        normal_consistency: args.s2.normal_weight,
        halfspace_weight: if degraded { 0.0 } else { args.s2.halfspace_weight },
        halfspace_decay: 0.7,
        lamp_axis: axis.unwrap_or([1.0, 0.0, 0.0]),
        time_rule: frames.time_rule,
        t_start: frames.t_start,
        t_end: frames.t_end,
        robust: !args.s2.l2,
        profile_flux: !args.s2.stage1_flux,
        boundary_rings: args.s2.boundary_rings,
        profile_globals: !args.s2.stage1_globals,
        joint_globals: !args.s2.profiled_globals,
        profile_scale: !fixed_scale,
        output_error: args.s2.output_error_level.map(|level| heatrecon::stage2::output_error::OeOptions {
            level,
            rounds: args.s2.output_error_rounds,
            flux_iterations: args.s2.output_error_flux_iterations,
            shape_iterations: args.s2.output_error_shape_iterations,
            boundary_rings: args.s2.boundary_rings,
            substeps: args.s2.output_error_substeps,
            large_steps_lambda: args.s2.output_error_large_steps,
            hold_mean_depth: args.s2.output_error_hold_mean_depth,
            normal_consistency: args.s2.output_error_normal,
            size_every: args.s2.output_error_size_every,
            offsets: args.s2.output_error_offsets,
            globals: args.s2.output_error_globals,
            joint: args.s2.output_error_joint,
            holdout: args.s2.output_error_holdout,
            patience: args.s2.output_error_patience,
            synthetic: args.s2.output_error_synthetic.map(|seed| heatrecon::stage2::output_error::Synthetic {
                seed,
                pattern_error: args.s2.output_error_synthetic_pattern,
            }),
        }),
        lamp_ratio,
        lamp_shading,
        symmetry_weight: args.s2.symmetry,
        shape_bound: args.s2.shape_bound.map(|degree| heatrecon::stage2::output_error::bound::BoundOptions {
            degree,
            max_iterations: args.s2.shape_bound_iterations,
            ..Default::default()
        }),
    };
    let dirs: Vec<&std::path::Path> = args.dirs.iter().map(|d| d.as_path()).collect();
    let mut last_stage1: Option<(heatrecon::stage1::Stage1Result, Level)> = None;
    let total = opts.extra_levels as u64 * opts.optim.iterations as u64
        + opts.coarsest_iterations.unwrap_or(opts.optim.iterations) as u64;
    let bar = indicatif::ProgressBar::new(total);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:40}] {pos}/{len} {msg}")
            .expect("template")
            .progress_chars("=> "),
    );
    let (ambient, emissivity) = (sets[0].ambient, sets[0].emissivity);
    let threshold = args.threshold;
    let oracle = args.s2.oracle_stage1;
    let ts = Instant::now();
    let result = stage2::reconstruct(
        &finest,
        ambient,
        emissivity,
        &opts,
        |level, input| {
            let denoise =
                denoise_input(&args, input, t0).map_err(|e| heatrecon::error::ReconError::Input(format!("{e:#}")))?;
            let s1opts = stage1_options(&args, noise_level(&args, input, denoise.as_ref()), level.level);
            let noise_cov = if args.s2.no_noise_correction {
                Vec::new()
            } else {
                noise_covariances(input, denoise.as_ref(), args.netd)
            };
            if oracle {
                let mut p = stage2::oracle_stage1(&dirs, level.level, &input.grid, ambient, emissivity, threshold)?;
                p.noise_cov = noise_cov;
                return Ok(p);
            }
            let res = estimate(input, &s1opts)?;
            let hs = (res.flux_over_c.len() >= 2)
                .then(|| heatrecon::halfspace::halfspace(&res.flux_over_c[0], &res.flux_over_c[1], threshold));
            let p = Stage1Params {
                lambda: res.lambda.value,
                c_inv: res.c.map(|c| c.value).filter(|c| c.is_finite() && *c > 0.0).unwrap_or(0.0),
                flux_over_c: res.flux_over_c.clone(),
                halfspace: hs,
                noise_cov,
                source: "stage 1 estimate".into(),
            };
            last_stage1 = Some((res, level.clone()));
            Ok(p)
        },
        |level| {
            if !args.s2.depth_truth {
                return None;
            }
            heatrecon::validate::Truth::load(&args.dirs[0], level).ok().map(|t| t.depth)
        },
        |li, n, it| {
            bar.set_message(format!("level {}/{n}", li + 1));
            if it > 0 {
                bar.inc(1);
            }
        },
    )?;
    bar.finish_and_clear();
    for l in &result.levels {
        eprintln!(
            "  level {}: {} vertices, data {:.4e} (rms {:.3e} K/s, alpha {:.3e}), normal {:.3e}, half-space {:.3e}{}{}",
            l.level,
            l.grid.vertex_count(),
            l.terms.data,
            l.terms.rms_residual,
            l.terms.alpha,
            l.terms.normal,
            l.terms.halfspace,
            if opts.lamp_shading.is_some() {
                format!(", lamp shading {:.3e} (beta {:.4e} m^2 K/J)", l.terms.lamp_shading, l.terms.lamp_beta)
            } else {
                String::new()
            },
            l.truth_terms
                .map(|t| format!(
                    "; at the true depth: data {:.4e} (rms {:.3e} K/s), normal {:.3e}, lamp shading {:.3e}",
                    t.data, t.rms_residual, t.normal, t.lamp_shading
                ))
                .unwrap_or_default()
        );
    }
    for l in result.levels.iter().filter(|l| !l.truth_scan.is_empty()) {
        let argmin = |f: &dyn Fn(&heatrecon::stage2::coarse_to_fine::ScanPoint) -> Option<f64>| {
            l.truth_scan
                .iter()
                .filter_map(|p| f(p).map(|v| (p.s, v)))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map_or("n/a".to_string(), |(s, _)| format!("{s:.2}"))
        };
        eprintln!(
            "  level {} truth scan (depths m + s (z_true - m); stage2.json): minimum at s = {} (data), {} (total){}",
            l.level,
            argmin(&|p| Some(p.terms.data)),
            argmin(&|p| Some(p.terms.total)),
            if l.truth_scan[0].output_error.is_some() {
                format!("; output error: {}", argmin(&|p| p.output_error))
            } else {
                String::new()
            } + &if l.truth_scan[0].fixed_diffusivity.is_some() {
                format!(
                    "; diffusivity fixed: {} (data), {} (total)",
                    argmin(&|p| p.fixed_diffusivity.map(|t| t.data)),
                    argmin(&|p| p.fixed_diffusivity.map(|t| t.total))
                )
            } else {
                String::new()
            }
        );
    }
    for l in &result.levels {
        let Some(b) = &l.shape_bound else { continue };
        eprintln!(
            "  level {} shape bound (sigma {:.1} mK; CGLS {} iterations, relative residual {:.1e}): std of {}",
            l.level,
            1e3 * b.sigma,
            b.projection_iterations,
            b.projection_residual,
            b.modes.join(", ")
        );
        for r in &b.rows {
            eprintln!(
                "    fluxes {:7}, globals {:7}: size {:.3e}, relief {:.3e}; expected surface error after alignment {:.3} mm \
                 (size alone {:.3} mm, relief alone {:.3} mm)",
                if r.nuisances.fluxes { "unknown" } else { "known" },
                if r.nuisances.globals { "unknown" } else { "known" },
                r.std[0],
                r.std[1],
                1e3 * r.joint_mae_m,
                1e3 * r.mode_mae_m[0],
                1e3 * r.mode_mae_m[1]
            );
        }
    }
    for l in result.levels.iter().filter(|l| !l.output_error_log.is_empty()) {
        for r in &l.output_error_log {
            let (round, j, mae) = (r.round, r.loss_k2, r.depth_mae_mm);
            eprintln!(
                "  level {} output-error round {round}: loss {j:.6e} K^2 (rms {:.3e} K){}{}{}, lambda {:.5e} 1/s, 1/C {:.4e} m^2 K/J{}",
                l.level,
                j.sqrt(),
                r.heldout_loss_k2.map(|h| format!(", held-out {h:.6e} K^2")).unwrap_or_default(),
                mae.map(|(a, b)| format!(", depth MAE {a:.3} mm ({b:.3} mm after scale)")).unwrap_or_default(),
                r.area_excess.map(|a| format!(", area excess {:.3} %", 100.0 * a)).unwrap_or_default(),
                r.lambda,
                r.c_inv,
                if r.kept && r.heldout_loss_k2.is_some() { " [kept]" } else { "" }
            );
        }
    }
    let stage2_s = ts.elapsed().as_secs_f64();
    let fin = result.levels.last().context("no level reconstructed")?;
    let last_log = result.log.last();
    eprintln!(
        "[{:6.2} s] stage 1+2 done in {stage2_s:.2} s: level {} ({} vertices), data {:.4e}, rms residual {:.3e} K/s, alpha {:.4e} m^2/s{}",
        t0.elapsed().as_secs_f64(),
        fin.level,
        fin.grid.vertex_count(),
        fin.terms.data,
        fin.terms.rms_residual,
        fin.terms.alpha,
        last_log
            .and_then(|r| r.depth_mae_mm.zip(r.depth_mae_scaled_mm))
            .map(|(a, b)| format!(", depth MAE {a:.3} mm ({b:.3} mm after scale)"))
            .unwrap_or_default()
    );
    let mut out =
        heatsim::io::OutputDir::new(&args.out).with_context(|| format!("preparing {}", args.out.display()))?;
    if let Some((res, level)) = &last_stage1 {
        let hs = (res.flux_over_c.len() >= 2)
            .then(|| heatrecon::halfspace::halfspace(&res.flux_over_c[0], &res.flux_over_c[1], threshold));
        heatrecon::output::write_stage1(
            &mut out,
            &args.out,
            res,
            level,
            hs.as_deref().map(|h| (h, threshold)),
            serde_json::json!({"inputs": args.dirs, "clean": args.clean}),
        )?;
    }
    heatrecon::stage2::export::write_stage2(&mut out, &args.out, fin, &result.log)?;
    let summary = serde_json::json!({
        "stage1_source": fin.stage1.source,
        "scale": match opts.scale {
            Scale::Diffusivity(a) => format!("metric: diffusivity {a:e} m^2/s given"),
            Scale::Profiled => format!("diffusivity profiled out; size fixed by the nominal distance {distance} m (mean depth)"),
        },
        "alpha_m2_per_s": fin.terms.alpha,
        "distance_m": distance,
        "halfspace_term": if degraded { "off (degraded mode: needs two videos with lamps on opposite sides)" } else { "on at the coarse levels" },
        "lamp_axis_camera": axis,
        "optimizer": format!("{:?}", opts.optim.optimizer),
        "size": if !fixed_scale && matches!(opts.scale, Scale::Diffusivity(_)) { "diffusivity profiled per level, shape scaled to the given one" } else { "diffusivity fixed in the data term" },
        "data_loss": if opts.robust { "robust: mean over vertices of the per-vertex RMS residual" } else { "L2: mean squared residual" },
        "globals": if !opts.profile_globals || !opts.robust {
            "stage 1's"
        } else if opts.minimises_globals_jointly() {
            "minimised jointly with the depths"
        } else {
            "profiled at every evaluation"
        },
        "min_coarsest_vertices": min_vertices,
        "iterations_per_level": opts.optim.iterations,
        "iterations_coarsest_level": opts.coarsest_iterations.unwrap_or(opts.optim.iterations),
        "learning_rate_m": opts.optim.learning_rate,
        "large_steps_lambda": opts.optim.large_steps_lambda,
        "normal_consistency_weight": opts.normal_consistency,
        "halfspace_weight": opts.halfspace_weight,
        "symmetry_weight_coarsest_level": opts.symmetry_weight,
        "lamp_shading": opts.lamp_shading.as_ref().map(|o| serde_json::json!({
            "weight": o.weight,
            "threshold": o.threshold,
            "beta_m2k_per_j": fin.terms.lamp_beta,
            "note": "calibrated point lamps from lamps.json: not the paper's method (heatrecon::stage2::lamp_shading)",
        })),
        "noise_correction": if args.s2.no_noise_correction { "off" } else { "expected noise outer product removed from the data term (heatrecon::stage2::noise)" },
        "levels": result.levels.iter().map(|l| serde_json::json!({
            "level": l.level, "vertices": l.grid.vertex_count(), "terms": l.terms, "size_factor": l.size_factor,
            "lambda": l.stage1.lambda, "c_inv": l.stage1.c_inv,
            "truth_terms": l.truth_terms, "truth_scan": (!l.truth_scan.is_empty()).then_some(&l.truth_scan),
            "output_error": (!l.output_error_log.is_empty()).then_some(&l.output_error_log),
            "shape_bound": l.shape_bound,
        })).collect::<Vec<_>>(),
        "final_depth_mae_mm": last_log.and_then(|r| r.depth_mae_mm),
        "final_depth_mae_scaled_mm": last_log.and_then(|r| r.depth_mae_scaled_mm),
        "seconds_stage1_and_2": stage2_s,
    });
    out.write_bytes("stage2.json", serde_json::to_string_pretty(&summary)?.as_bytes())?;
    if last_stage1.is_none() {
        out.write_bytes("params.json", serde_json::to_string_pretty(&summary)?.as_bytes())?;
    }
    let png = convergence_png(&result.log)?;
    out.write_bytes("convergence.png", &png)?;
    out.commit().with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!("[{:6.2} s] wrote {}", t0.elapsed().as_secs_f64(), args.out.display());
    Ok(())
}

/// The convergence plot: data energy (log scale) against the iteration counted over all levels.
fn convergence_png(log: &[heatrecon::stage2::coarse_to_fine::LogRow]) -> anyhow::Result<Vec<u8>> {
    use plotters::prelude::*;
    static FONT: &[u8] = include_bytes!("../sweep/font/DejaVuSansMono.ttf");
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let _ = plotters::style::register_font("sans-serif", plotters::style::FontStyle::Normal, FONT);
    });
    let (w, h) = (900u32, 500u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e}"))?;
        let pts: Vec<(f64, f64)> = log
            .iter()
            .enumerate()
            .filter(|(_, r)| r.terms.data > 0.0 && r.terms.data.is_finite())
            .map(|(k, r)| (k as f64, r.terms.data.log10()))
            .collect();
        let (ymin, ymax) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, p| (a.0.min(p.1), a.1.max(p.1)));
        let (ymin, ymax) = if ymin < ymax { (ymin - 0.1, ymax + 0.1) } else { (ymin - 1.0, ymin + 1.0) };
        let mut chart = ChartBuilder::on(&root)
            .caption("stage 2 convergence (levels coarse to fine)", ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(0f64..(log.len().max(2) as f64), ymin..ymax)
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        chart
            .configure_mesh()
            .x_desc("iteration (all levels)")
            .y_desc("log10 data energy")
            .label_style(("sans-serif", 12))
            .draw()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        chart.draw_series(LineSeries::new(pts, &BLUE)).map_err(|e| anyhow::anyhow!("{e}"))?;
        root.present().map_err(|e| anyhow::anyhow!("{e}"))?;
    }
    let img = image_png(&buf, w, h)?;
    Ok(img)
}

fn image_png(rgb: &[u8], w: u32, h: u32) -> anyhow::Result<Vec<u8>> {
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut wr = enc.write_header()?;
        wr.write_image_data(rgb)?;
    }
    Ok(out)
}
