//! `simbench reconstruct DIR... --out OUT [--preset NAME] [--config FILE] [--set PATH=VALUE]...`:
//! the reconstruction from thermal videos (`heatrecon::reconstruct`, configured by one
//! `heatrecon::ReconConfig`). The configuration is the preset's (or the file's), then the
//! everyday flags, then each `--set` in order; the resolved configuration is written to
//! `OUT/config.json`, and `--config OUT/config.json` reproduces the run's shape files bit for
//! bit. Timings and paths go to `OUT/run.json`. With `--check`, figures against the ground
//! truth of simulated datasets (`heatrecon::diagnostics`) go to `OUT/check.json`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use heatrecon::config::{LampSide, Stage, Video};
use heatrecon::dataset::{Dataset, LoadOptions};
use heatrecon::diagnostics::TruthCheck;
use heatrecon::method::{ShapeSetup, Stage1Run};
use heatrecon::stage2::Stage2Result;
use heatrecon::{Observer, Preset, ReconConfig};
use heatsim::io::OutputDir;

#[derive(clap::Args)]
pub struct Args {
    /// Dataset directories (same object and camera, one lamp configuration each).
    #[arg(required = true)]
    dirs: Vec<PathBuf>,
    /// Output directory; files appear only once everything succeeded.
    #[arg(long)]
    out: PathBuf,
    /// Named configuration: `paper` (the paper's method, uncalibrated lamps; the default) or
    /// `calibrated-lamps` (plus the shading of the point lamps in lamps.json).
    #[arg(long, conflicts_with = "config")]
    preset: Option<String>,
    /// Configuration file (JSON; `simbench schema recon-config`), e.g. a run's config.json.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Change one configuration value by its dotted path, after the flags: `--set
    /// shape.iterations=300`, `--set stage1.denoise=none` (repeatable).
    #[arg(long, value_name = "PATH=VALUE")]
    set: Vec<String>,
    /// Stage to run up to: 1 (Laplacian, fluxes, lambda, C, h) or 2 (the shape; default).
    #[arg(long)]
    stage: Option<u32>,
    /// Finest pyramid level (0: full resolution; each level halves it by 2 x 2 averaging).
    #[arg(long)]
    level: Option<usize>,
    /// Material diffusivity k/(rho c_p) in m^2/s for a metric shape, or `material` to read it
    /// from the datasets' material.json. Without it the size is fixed by the distance.
    #[arg(long)]
    diffusivity: Option<String>,
    /// Nominal object distance, m (default: the camera's distance to the world origin).
    #[arg(long)]
    distance: Option<f64>,
    /// Emissivity of the object (default: environment.json's).
    #[arg(long)]
    emissivity: Option<f64>,
    /// Temporal noise of the camera (NETD), K (default: measured on the frames at t <= 0).
    #[arg(long)]
    netd: Option<f64>,
    /// Read video_clean.npy (the noise-free video of a simulated dataset).
    #[arg(long)]
    clean: bool,
    /// Side of each video's lamp, e.g. `left,right` (default: from lamps.json).
    #[arg(long, value_delimiter = ',')]
    lamp_sides: Vec<String>,
    /// Compare with the datasets' ground truth (simulated data): stage 1's figures with the
    /// Cramer-Rao bound on lambda, C and h, and the shape's depth error at every level, into
    /// check.json (never used by the reconstruction).
    #[arg(long)]
    check: bool,
    /// With --check and a diffusivity: at every level, the Cramer-Rao bound on the shape at the
    /// true depth (size, relief and image polynomials up to this degree) into check.json.
    #[arg(long, value_name = "DEGREE")]
    shape_bound: Option<usize>,
    /// With --shape-bound: CGLS iterations at most per projection of the fluxes.
    #[arg(long, default_value_t = 400)]
    shape_bound_iterations: usize,
}

/// The resolved configuration: preset or file, then the flags, then `--set`.
fn resolve_config(args: &Args) -> anyhow::Result<ReconConfig> {
    let mut c = match (&args.config, &args.preset) {
        (Some(p), _) => {
            let text = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            ReconConfig::from_json(&text, &p.display().to_string())?
        }
        (None, Some(name)) => Preset::from_name(name)?.config(),
        (None, None) => Preset::Paper.config(),
    };
    if let Some(s) = args.stage {
        c.stage = match s {
            1 => Stage::Laplacian,
            2 => Stage::Shape,
            _ => anyhow::bail!("--stage {s}: the method has stages 1 (Laplacian) and 2 (shape)"),
        };
    }
    c.level = args.level.unwrap_or(c.level);
    if let Some(d) = &args.diffusivity {
        c.input.diffusivity_m2_per_s = Some(match d.as_str() {
            "material" => heatrecon::dataset::read_diffusivity(&args.dirs[0]).context("--diffusivity material")?,
            v => v.parse().map_err(|_| anyhow::anyhow!("--diffusivity: `{v}` is neither a number nor `material`"))?,
        });
    }
    c.input.distance_m = args.distance.or(c.input.distance_m);
    c.input.emissivity = args.emissivity.or(c.input.emissivity);
    c.input.netd_k = args.netd.or(c.input.netd_k);
    if args.clean {
        c.input.video = Video::Clean;
    }
    if !args.lamp_sides.is_empty() {
        let side = |s: &String| match s.trim() {
            "left" => Ok(LampSide::Left),
            "right" => Ok(LampSide::Right),
            other => anyhow::bail!("--lamp-sides: `{other}` is not left or right"),
        };
        c.input.lamp_sides = Some(args.lamp_sides.iter().map(side).collect::<anyhow::Result<_>>()?);
    }
    for s in &args.set {
        let (path, value) = s.split_once('=').with_context(|| format!("--set {s}: expected PATH=VALUE"))?;
        c.set(path.trim(), value.trim())?;
    }
    c.validate().map_err(|e| anyhow::anyhow!("configuration: {e}"))?;
    if args.shape_bound.is_some() {
        anyhow::ensure!(args.check, "--shape-bound needs --check: the bound is taken at the true depth");
        anyhow::ensure!(
            c.input.diffusivity_m2_per_s.is_some() && c.stage == Stage::Shape,
            "--shape-bound needs the shape stage and the diffusivity (--diffusivity): the bound is metric"
        );
        anyhow::ensure!(c.input.video == Video::Measured, "--shape-bound needs the noisy videos: not with --clean");
    }
    Ok(c)
}

/// Progress on standard error, and the ground-truth checks when asked for.
struct Cli {
    start: Instant,
    bar: Option<indicatif::ProgressBar>,
    check: Option<TruthCheck>,
}

impl Cli {
    fn say(&self, text: &str) {
        let line = format!("[{:7.2} s] {text}", self.start.elapsed().as_secs_f64());
        match &self.bar {
            // A hidden bar (standard error not a terminal) prints nothing: write directly.
            Some(b) if !b.is_hidden() => b.println(line),
            _ => eprintln!("{line}"),
        }
    }
}

impl Observer for Cli {
    fn message(&mut self, text: &str) {
        self.say(text);
    }
    fn wants_raw_series(&self) -> bool {
        self.check.as_ref().is_some_and(|c| c.wants_raw_series())
    }
    fn stage1(
        &mut self,
        level: &heatrecon::pyramid::Level,
        r: &heatrecon::stage1::Stage1Result,
        hs: Option<&[i8]>,
        n: Option<f64>,
    ) {
        if let Some(c) = &mut self.check {
            c.stage1(level, r, hs, n);
        }
    }
    fn level_start(&mut self, index: usize, levels: usize, level: &heatrecon::pyramid::Level) {
        if let Some(b) = &self.bar {
            b.set_message(format!("level {} ({}/{levels})", level.level, index + 1));
        }
        if let Some(c) = &mut self.check {
            c.level_start(index, levels, level);
        }
    }
    fn iteration(&mut self, level: usize, iteration: usize, depth: &[f64]) {
        if let (Some(b), true) = (&self.bar, iteration > 0) {
            b.inc(1);
        }
        if let Some(c) = &mut self.check {
            c.iteration(level, iteration, depth);
        }
    }
    fn level(&mut self, view: &heatrecon::stage2::coarse_to_fine::LevelView) {
        let l = view.result;
        self.say(&format!(
            "level {}: {} vertices, data {:.4e} (rms {:.3e} K/s, alpha {:.3e} m^2/s), normal {:.3e}, half-space {:.3e}",
            l.level,
            l.grid.vertex_count(),
            l.terms.data,
            l.terms.rms_residual,
            l.terms.alpha,
            l.terms.normal,
            l.terms.halfspace
        ));
        let Some(c) = &mut self.check else { return };
        c.level(view);
        let line = c.levels.last().filter(|lc| lc.level == l.level).map(|lc| {
            format!(
                "  against the truth: depth MAE {:.3} mm ({:.3} mm after scale)",
                lc.depth_mae_mm, lc.depth_mae_scaled_mm
            )
        });
        if let Some(line) = line {
            self.say(&line);
        }
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let start = Instant::now();
    let config = resolve_config(&args)?;
    let check = match args.check {
        false => None,
        true => Some(
            TruthCheck::new(
                &args.dirs,
                config.level,
                LoadOptions::from(&config.input),
                config.stage1.halfspace_threshold,
                args.shape_bound.map(|degree| heatrecon::bound::shape::BoundOptions {
                    degree,
                    max_iterations: args.shape_bound_iterations,
                    ..Default::default()
                }),
            )
            .context("--check needs the ground truth of simulated datasets")?,
        ),
    };
    let mut cli = Cli { start, bar: None, check };
    let load = LoadOptions::from(&config.input);
    let mut sets = Vec::new();
    for d in &args.dirs {
        cli.say(&format!("reading {}", d.display()));
        sets.push(Dataset::load(d, &load)?);
    }
    if config.stage == Stage::Shape {
        let s = &config.shape;
        let total = s.extra_levels as u64 * s.iterations as u64 + s.coarsest_iterations.unwrap_or(s.iterations) as u64;
        let bar = indicatif::ProgressBar::new(total);
        bar.set_style(
            indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:40}] {pos}/{len} {msg}")
                .expect("template")
                .progress_chars("=> "),
        );
        cli.bar = Some(bar);
    }
    let t = Instant::now();
    let rec = heatrecon::reconstruct(&sets, &config, &mut cli)?;
    let seconds = t.elapsed().as_secs_f64();
    if let Some(b) = cli.bar.take() {
        b.finish_and_clear();
    }
    let mut out = OutputDir::new(&args.out).with_context(|| format!("preparing {}", args.out.display()))?;
    out.write_bytes("config.json", config.to_json().as_bytes())?;
    if let Some(run) = &rec.stage1 {
        write_stage1(&mut out, &args.out, run, &config)?;
    }
    if let Some((setup, result)) = &rec.shape {
        write_shape(&mut out, &args.out, &config, setup, result)?;
    }
    if let Some(check) = &cli.check {
        write_check(&mut out, check, rec.stage1.as_ref(), rec.shape.as_ref().map(|s| &s.1))?;
    }
    let run_record = serde_json::json!({
        "command": std::env::args().collect::<Vec<_>>(),
        "inputs": args.dirs,
        "out": args.out,
        "simbench_version": env!("CARGO_PKG_VERSION"),
        "threads": rayon::current_num_threads(),
        "seconds": {"reconstruct": seconds, "total": start.elapsed().as_secs_f64()},
    });
    out.write_bytes("run.json", (serde_json::to_string_pretty(&run_record)? + "\n").as_bytes())?;
    out.commit().with_context(|| format!("writing {}", args.out.display()))?;
    cli.say(&format!("wrote {}", args.out.display()));
    Ok(())
}

/// Stage 1's files at the finest level (`heatrecon::output`).
fn write_stage1(out: &mut OutputDir, path: &Path, run: &Stage1Run, config: &ReconConfig) -> anyhow::Result<()> {
    let threshold = config.stage1.halfspace_threshold;
    let options = serde_json::json!({
        "level": run.level.level,
        "denoise": run.denoise,
        "smoothing": run.result.smoothing,
    });
    heatrecon::output::write_stage1(
        out,
        path,
        &run.result,
        &run.level,
        run.halfspace.as_deref().map(|h| (h, threshold)),
        options,
    )?;
    Ok(())
}

/// The shape's files (`heatrecon::stage2::export`), `stage2.json` and the convergence plot.
fn write_shape(
    out: &mut OutputDir,
    path: &Path,
    config: &ReconConfig,
    setup: &ShapeSetup,
    result: &Stage2Result,
) -> anyhow::Result<()> {
    use heatrecon::stage2::Scale;
    let fin = result.levels.last().context("no level reconstructed")?;
    heatrecon::stage2::export::write_stage2(out, path, fin, &result.log)?;
    let o = &setup.options;
    let summary = serde_json::json!({
        "stage1_source": fin.stage1.source,
        "scale": match o.scale {
            Scale::Diffusivity(a) => format!("metric: diffusivity {a:e} m^2/s given"),
            Scale::Profiled => format!("diffusivity profiled out; size fixed by the nominal distance {} m (mean depth)", setup.distance),
        },
        "alpha_m2_per_s": fin.terms.alpha,
        "distance_m": setup.distance,
        "halfspace_term": if setup.halfspace_term { "on at the coarse levels" } else { "off (degraded mode: needs two videos with lamps on opposite sides)" },
        "lamp_axis_camera": setup.halfspace_term.then_some(o.lamp_axis),
        "size": if o.profile_scale && matches!(o.scale, Scale::Diffusivity(_)) { "diffusivity profiled per level, shape scaled to the given one" } else { "diffusivity fixed in the data term" },
        "globals": if !o.profile_globals || !o.robust {
            "stage 1's"
        } else if o.minimises_globals_jointly() {
            "minimised jointly with the depths"
        } else {
            "profiled at every evaluation"
        },
        "coarsest_level": fin.level + o.extra_levels,
        "lamp_shading_beta_m2k_per_j": o.lamp_shading.as_ref().map(|_| fin.terms.lamp_beta),
        "levels": result.levels.iter().map(|l| serde_json::json!({
            "level": l.level, "vertices": l.grid.vertex_count(), "terms": l.terms, "size_factor": l.size_factor,
            "profiled_size_factor": l.profiled_size_factor,
            "lambda": l.stage1.lambda, "c_inv": l.stage1.c_inv,
            "experiments": l.experiments,
        })).collect::<Vec<_>>(),
        "config": config,
    });
    out.write_bytes("stage2.json", (serde_json::to_string_pretty(&summary)? + "\n").as_bytes())?;
    if let Some(png) = crate::figure::optional("convergence.png", || crate::figure::convergence_png(&result.log)) {
        out.write_bytes("convergence.png", &png)?;
    }
    Ok(())
}

/// `check.json` (and the images of the errors) from the ground-truth diagnostics.
fn write_check(
    out: &mut OutputDir,
    check: &TruthCheck,
    stage1: Option<&Stage1Run>,
    shape: Option<&Stage2Result>,
) -> anyhow::Result<()> {
    for n in &check.notes {
        eprintln!("note: {n}");
    }
    let final_level = check.levels.last();
    let doc = serde_json::json!({
        "stage1": check.stage1,
        "levels": check.levels,
        "iterations": check.iterations,
        "final_depth_mae_mm": final_level.map(|l| l.depth_mae_mm),
        "final_depth_mae_scaled_mm": final_level.map(|l| l.depth_mae_scaled_mm),
        "notes": check.notes,
    });
    let text = serde_json::to_string_pretty(&doc)? + "\n";
    if let Some(c) = &check.stage1 {
        println!("{}", serde_json::to_string_pretty(c)?);
    }
    out.write_bytes("check.json", text.as_bytes())?;
    let image = |grid: &heatsim::camera::PixelGrid, v: &[f64]| {
        let mut img = ndarray::Array2::<f32>::from_elem((grid.height, grid.width), f32::NAN);
        for (k, &p) in grid.pixels.iter().enumerate() {
            img[[p / grid.width, p % grid.width]] = v[k] as f32;
        }
        img
    };
    let npy = |out: &mut OutputDir, name: &str, a: ndarray::Array2<f32>| {
        out.write_with(name, |w| ndarray_npy::WriteNpyExt::write_npy(&a, w).map_err(std::io::Error::other))
    };
    if let (Some(c), Some(run)) = (&check.stage1, stage1) {
        npy(out, "check_row_error.npy", image(&run.result.grid, &c.row_error))?;
    }
    if let (Some(lc), Some(fin)) = (final_level, shape.and_then(|s| s.levels.last())) {
        if let Some(r) = lc.truth_residual.as_ref().filter(|_| lc.level == fin.level) {
            npy(out, "residual_stage2_truth.npy", image(&fin.grid, r))?;
        }
    }
    Ok(())
}
