//! `simbench suite build|verify|run|merge|report|compare`: the frozen benchmark suite
//! (`crate::suite`).

use std::path::PathBuf;

use anyhow::{ensure, Context};

use crate::suite::{build, inputs, manifest, method::Method, run};

#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Subcommand)]
enum Command {
    /// Simulate every object of a spec once and store the suite: datasets, ground truth and
    /// suite.json with the SHA-256 of every file (resumable).
    Build(BuildArgs),
    /// Compute the Cramér–Rao bound of more objects of a built suite, in the family of its
    /// spec's `bound` (level, degree), into SUITE/bounds/ and SUITE/bounds.json (not part of
    /// the suite's version); a run resumed afterwards carries them to its report.
    Bound(BoundArgs),
    /// Check every stored file of a suite against suite.json (`--deep`: also re-film every
    /// case's inputs and check their hashes).
    Verify(VerifyArgs),
    /// Run a method on every case of a suite and score it (resumable, shardable).
    Run(Box<RunArgs>),
    /// Join the shard runs 1/N..N/N of one suite and method into one run.
    Merge(MergeArgs),
    /// Per object and noise level: median and range over seeds of the errors, failures and
    /// time (report.md, summary.csv, cases.csv, errors.png).
    Report(ReportArgs),
    /// Pair two runs of the same suite case by case and seed by seed: a verdict per noise
    /// level (sign-flip permutation test, Holm-corrected); exit 1 when NEW is significantly
    /// worse in a group (errors or failures).
    Compare(CompareArgs),
    /// What `compare` can detect on a suite: its power against a method CHANGE times worse and
    /// its false-alarm rate, by simulation from a run's spread over seeds.
    Power(PowerArgs),
    /// Refinement study of an object's film: element size on the surface, layers through a
    /// shell's wall and time step, each refined by halves from the spec's settings; frame-by-
    /// frame differences against the criteria (levels.csv, frames.csv, convergence.png,
    /// summary.md, summary.json). Exit 1 when a series does not converge.
    Converge(ConvergeArgs),
    /// Where heat-only recovery works: runs of suites differing in noise and heating gathered
    /// per object, NETD and heating (map.csv, map.md, map.png).
    Map(MapArgs),
}

#[derive(clap::Args)]
struct MapArgs {
    /// A suite (its folder or its suite.json) and a run of it; repeat for each suite.
    #[arg(long = "run", num_args = 2, value_names = ["SUITE", "RUN"], required = true)]
    runs: Vec<PathBuf>,
    /// The NETD of the figure's heating column, mK.
    #[arg(long, default_value_t = 50.0)]
    netd: f64,
    /// The output folder.
    #[arg(long)]
    out: PathBuf,
}

#[derive(clap::Args)]
struct CompareArgs {
    base: PathBuf,
    new: PathBuf,
    /// Where to write compare.md, compare.csv, compare.json and compare.png (default:
    /// NEW/compare).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(clap::Args)]
struct PowerArgs {
    run: PathBuf,
    /// The factor on the MAE of the worse method.
    #[arg(long, default_value_t = 1.2)]
    change: f64,
    /// Simulated pairs of runs, for each of the power and the false-alarm rate.
    #[arg(long, default_value_t = 1000)]
    draws: usize,
    /// Seed of the simulation.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Simulate this many seeds per noisy object instead of the run's.
    #[arg(long)]
    seeds: Option<usize>,
}

#[derive(clap::Args)]
struct MergeArgs {
    /// The shard runs.
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    /// The merged run folder (must not exist).
    #[arg(long)]
    out: PathBuf,
}

#[derive(clap::Args)]
struct ReportArgs {
    run: PathBuf,
    /// Where to write the report (default: RUN/report).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(clap::Args)]
struct BuildArgs {
    /// A shipped tier: `quick` (160 x 128) or `full` (320 x 256); `tiny` is a smoke test.
    #[arg(long, conflicts_with = "spec")]
    tier: Option<String>,
    /// A spec file (JSON; see suites/*.json) instead of a tier.
    #[arg(long)]
    spec: Option<PathBuf>,
    /// The suite folder.
    #[arg(long)]
    out: PathBuf,
    /// Use this Stanford bunny OBJ instead of the cached download (also: HEATSIM_BUNNY).
    #[arg(long)]
    bunny: Option<PathBuf>,
}

#[derive(clap::Args)]
struct ConvergeArgs {
    /// A shipped tier (quick, full, tiny).
    #[arg(long, conflicts_with = "spec")]
    tier: Option<String>,
    /// A suite spec file.
    #[arg(long)]
    spec: Option<PathBuf>,
    /// The object: an id of the spec (ball-volumetric-shell-d0.002) or its name (ball).
    #[arg(long)]
    object: String,
    /// The series to run, comma-separated.
    #[arg(long, value_delimiter = ',', default_values = ["surface", "layers", "time_step"])]
    series: Vec<crate::suite::converge::Series>,
    /// Levels per series, the spec's settings (level 0) included.
    #[arg(long, default_value_t = 3)]
    levels: u32,
    /// Largest RMS difference of a frame between the two finest levels, mK.
    #[arg(long, default_value_t = 2.0)]
    max_rms_mk: f64,
    /// Largest relative difference of the pixel Laplacian of a frame's rise, %.
    #[arg(long, default_value_t = 10.0)]
    max_laplacian_percent: f64,
    /// The output folder (resumed: levels already there are reused).
    #[arg(long)]
    out: PathBuf,
    /// Use this Stanford bunny OBJ instead of the cached download.
    #[arg(long)]
    bunny: Option<PathBuf>,
}

#[derive(clap::Args)]
struct BoundArgs {
    suite: PathBuf,
    /// Object ids or names, comma-separated; `all`: every object of the suite.
    #[arg(long, value_delimiter = ',', required = true)]
    objects: Vec<String>,
}

#[derive(clap::Args)]
struct VerifyArgs {
    suite: PathBuf,
    /// Also re-film every case's inputs and check their SHA-256.
    #[arg(long)]
    deep: bool,
}

#[derive(clap::Args)]
struct RunArgs {
    suite: PathBuf,
    /// The run folder (resumed when it holds this run).
    #[arg(long)]
    out: PathBuf,
    /// `builtin` (the paper preset), `builtin:PRESET` (`paper`, `calibrated-lamps`) or `plane`
    /// (a plane at the true mean depth: what no shape information scores).
    #[arg(long)]
    method: Option<String>,
    /// The built-in method with this configuration file (replaces the preset).
    #[arg(long)]
    config: Option<PathBuf>,
    /// An external method: `sh -c` runs it with {left}, {right}, {out} and {case} replaced;
    /// it writes {out}/recon_world.obj or .ply in the world frame, in metres.
    #[arg(long)]
    method_cmd: Option<String>,
    /// Hand lamps.json to the external method (it uses calibrated lamps).
    #[arg(long)]
    lamps: bool,
    /// Wall-clock limit of the method on one case, s.
    #[arg(long, default_value_t = 1800.0)]
    timeout: f64,
    /// Only the cases of shard K of N (K/N, 1 <= K <= N): case i with i % N == K - 1.
    #[arg(long)]
    shard: Option<String>,
    /// Keep each case's inputs, output and log in OUT/work/.
    #[arg(long)]
    keep_work: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    match args.command {
        Command::Build(a) => build_cmd(a),
        Command::Bound(a) => bound_cmd(a),
        Command::Converge(a) => converge_cmd(a),
        Command::Verify(a) => verify_cmd(a),
        Command::Run(a) => run_cmd(*a),
        Command::Merge(a) => {
            let info = crate::suite::merge::merge(&a.runs, &a.out)?;
            println!(
                "{}: {} cases of suite {} ({})",
                a.out.display(),
                info.cases.len(),
                info.suite_version,
                info.label
            );
            Ok(())
        }
        Command::Compare(a) => compare_cmd(a),
        Command::Power(a) => {
            let p = crate::suite::power::study(&a.run, a.change, a.draws, a.seed, a.seeds)?;
            println!("{}", crate::suite::power::markdown(&p, &a.run));
            Ok(())
        }
        Command::Map(a) => {
            let pairs: Vec<(PathBuf, PathBuf)> = a.runs.chunks(2).map(|p| (p[0].clone(), p[1].clone())).collect();
            let md = crate::suite::map::write(&pairs, a.netd, &a.out)?;
            println!("{md}");
            eprintln!("suite map: written to {}", a.out.display());
            Ok(())
        }
        Command::Report(a) => {
            let out = a.out.unwrap_or_else(|| a.run.join("report"));
            let md = crate::suite::report::write(&a.run, &out)?;
            println!("{md}");
            eprintln!("suite report: written to {}", out.display());
            Ok(())
        }
    }
}

fn converge_cmd(a: ConvergeArgs) -> anyhow::Result<()> {
    use crate::suite::converge;
    let spec = crate::suite::spec::SuiteSpec::load(a.tier.as_deref(), a.spec.as_deref())?;
    ensure!(
        a.max_rms_mk > 0.0 && a.max_laplacian_percent > 0.0,
        "--max-rms-mk and --max-laplacian-percent must be > 0"
    );
    let opts = converge::Options {
        spec,
        object: a.object,
        series: a.series,
        levels: a.levels,
        criteria: converge::Criteria { rms_k: a.max_rms_mk * 1e-3, laplacian_rel: a.max_laplacian_percent * 1e-2 },
        out: a.out.clone(),
        bunny: a.bunny,
    };
    let study = converge::study(&opts)?;
    let md = converge::write(&study, &a.out)?;
    println!("{md}");
    eprintln!("suite converge: written to {}", a.out.display());
    let failed: Vec<&str> = study.series.iter().filter(|s| !s.converged).map(|s| s.series.name()).collect();
    ensure!(failed.is_empty(), "{}: not converged in {}", study.object, failed.join(", "));
    Ok(())
}

fn bound_cmd(a: BoundArgs) -> anyhow::Result<()> {
    let m = manifest::Manifest::read(&a.suite)?;
    manifest::verify_files(&a.suite, &m)?;
    let spec = m.spec.bound.clone().with_context(|| {
        format!("{}: the suite's spec has no `bound` (the level and degree of its bounds)", a.suite.display())
    })?;
    let bounds = crate::suite::bound::compute_bounds(&a.suite, &m, &spec, &a.objects)?;
    println!("{}: {} bounds in bounds.json", a.suite.display(), bounds.len());
    Ok(())
}

fn build_cmd(a: BuildArgs) -> anyhow::Result<()> {
    let spec = crate::suite::spec::SuiteSpec::load(a.tier.as_deref(), a.spec.as_deref())?;
    let m = build::build(&build::Options { spec, out: a.out.clone(), bunny: a.bunny })?;
    println!("{}: suite {} with {} objects and {} cases", a.out.display(), m.version, m.objects.len(), m.cases.len());
    Ok(())
}

fn verify_cmd(a: VerifyArgs) -> anyhow::Result<()> {
    let m = manifest::Manifest::read(&a.suite)?;
    let n = manifest::verify_files(&a.suite, &m)?;
    let mut checked = 0;
    if a.deep {
        for case in &m.cases {
            for (rel, bytes) in inputs::case_inputs(&a.suite, case, true)? {
                let want =
                    case.inputs.get(&rel).with_context(|| format!("case {}: {rel} not in suite.json", case.id))?;
                let got = crate::sweep::cells::sha256_hex(&bytes);
                ensure!(&got == want, "case {}: {rel} re-films with SHA-256 {got}, suite.json records {want}", case.id);
                checked += 1;
            }
        }
    }
    println!(
        "{}: suite {} intact ({n} stored files{})",
        a.suite.display(),
        m.version,
        if a.deep { format!(", {checked} case inputs re-filmed") } else { String::new() }
    );
    Ok(())
}

fn run_cmd(a: RunArgs) -> anyhow::Result<()> {
    let method = Method::parse(a.method.as_deref(), a.method_cmd.as_deref(), a.config.as_deref(), a.lamps)?;
    let shard = a.shard.as_deref().map(run::Shard::parse).transpose()?;
    ensure!(a.timeout.is_finite() && a.timeout > 0.0, "--timeout: must be a positive number of seconds");
    let exe = std::env::current_exe().context("locating the simbench executable")?;
    let opts = run::Options {
        suite: a.suite,
        out: a.out.clone(),
        method,
        timeout_s: a.timeout,
        shard,
        exe,
        keep_work: a.keep_work,
    };
    let (ran, skipped, failed) = run::run(&opts)?;
    println!("{}: {ran} cases run ({failed} failed), {skipped} already done", a.out.display());
    Ok(())
}

fn compare_cmd(a: CompareArgs) -> anyhow::Result<()> {
    let c = crate::suite::compare::compare(&a.base, &a.new)?;
    let out = a.out.unwrap_or_else(|| a.new.join("compare"));
    crate::suite::compare::write(&c, &out)?;
    println!("{}", crate::suite::compare::markdown(&c));
    eprintln!("suite compare: written to {}", out.display());
    anyhow::ensure!(
        !c.worse,
        "{} is significantly worse than {} in at least one group (see {})",
        a.new.display(),
        a.base.display(),
        out.join("compare.md").display()
    );
    Ok(())
}
