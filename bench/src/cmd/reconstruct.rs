//! `simbench reconstruct DIR... --out OUT [--stage 1]`: the reconstruction from thermal videos
//! (stage 1: paper Sec. 5, `heatrecon::stage1`; stage 2 is issue 8). With `--check`, also
//! prints and writes (`check.json`) stage 1's figures against the ground truth of simulated
//! datasets (`heatrecon::validate`; the estimate itself never reads ground truth).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use heatrecon::dataset::{check_compatible, Dataset, LoadOptions};
use heatrecon::pyramid::Level;
use heatrecon::stage1::{estimate, Known, Radiation, Stage1Input, Stage1Options, TimeRule};

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum TimeRuleArg {
    BackwardEuler,
    Trapezoid,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum RadiationArg {
    Linearized,
    Full,
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
    /// Time rule of the frame-pair equations.
    #[arg(long, value_enum, default_value = "trapezoid")]
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
    /// Print and write (check.json) figures against the datasets' ground truth.
    #[arg(long)]
    check: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
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
    let input = Stage1Input::from_level(&level, sets[0].ambient, sets[0].emissivity)?;
    let opts = Stage1Options {
        time_rule: match args.time_rule {
            TimeRuleArg::BackwardEuler => TimeRule::BackwardEuler,
            TimeRuleArg::Trapezoid => TimeRule::Trapezoid,
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
        ..Default::default()
    };
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
        "stage1_seconds": stage1_s,
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
        let c = heatrecon::validate::check(&res, &level.camera, &truths, hs.as_deref());
        let text = serde_json::to_string_pretty(&c)?;
        println!("{text}");
        out.write_bytes("check.json", text.as_bytes())?;
    }
    out.commit().with_context(|| format!("writing {}", args.out.display()))?;
    eprintln!("[{:6.2} s] wrote {}", t0.elapsed().as_secs_f64(), args.out.display());
    Ok(())
}
