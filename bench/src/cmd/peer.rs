//! `simbench peer volumetric SCENE`: our volumetric solver side by side with independent peers
//! (scikit-fem assembly with SciPy's SuperLU, MKL PARDISO or SciPy conjugate gradients,
//! `bench/peers/skfem_heat.py`) on the identical problem.
//!
//! The scene is meshed once (per element size with `--element-sizes`), lit by its lamps (the
//! first of its lamp configurations, if it has several) and stepped with backward Euler (the
//! peer's only time discretisation); each of our linear solvers runs on the mesh in a process of
//! its own (`--worker`, which meshes the scene again, checked by its node count; timed:
//! assembly, factorisation and stepping, not meshing); the exact problem is exported with
//! [`heatsim::problem_export::write_problem`]; each peer configuration assembles and steps it in
//! the project's Python environment (`.venv`: scripts/setup-oracles.sh, and
//! scripts/setup-peers.sh for PARDISO). All runs are timed the same way (excluding file reading,
//! meshing and interpreter start-up) and run one after the other, never at the same time. Every
//! run's frames are compared with the first of ours at every node: max |T - T_ref| over the
//! largest temperature rise must be at most [`AGREEMENT`], which makes the run an oracle test as
//! well as a benchmark. The speedups are the peers' stepping times over ours (the same steps),
//! each the fastest of `--repeat` rounds; a round runs every configuration once, so that all
//! of them meet the same states of a shared machine.

use anyhow::{bail, Context};
use heatsim::scene::{LinearSolverKind, TimeIntegration};
use ndarray::Array2;
use ndarray_npy::{ReadNpyExt, WriteNpyExt};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Largest accepted max |T - T_ref| / max temperature rise.
pub const AGREEMENT: f64 = 1e-6;

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum PeerSolver {
    /// The volumetric solver against scikit-fem + SciPy or MKL (bench/peers/skfem_heat.py).
    Volumetric,
}

/// Our linear solvers (`solver.linear_solver` in a scene).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Ours {
    /// Sparse Cholesky factor (faer), chord iteration.
    Direct,
    /// Jacobi-preconditioned conjugate gradients, Newton iteration.
    ConjugateGradients,
}

/// The peer's linear solvers (`skfem_heat.py --linear-solver`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Peer {
    /// SciPy's SuperLU factor, chord iteration.
    Superlu,
    /// MKL PARDISO's Cholesky factor through pypardiso (scripts/setup-peers.sh), chord iteration.
    Pardiso,
    /// SciPy conjugate gradients with the Jacobi preconditioner, Newton iteration.
    Cg,
}

impl Ours {
    fn name(self) -> &'static str {
        match self {
            Ours::Direct => "direct",
            Ours::ConjugateGradients => "conjugate_gradients",
        }
    }
}

impl Peer {
    fn name(self) -> &'static str {
        match self {
            Peer::Superlu => "superlu",
            Peer::Pardiso => "pardiso",
            Peer::Cg => "cg",
        }
    }
}

#[derive(clap::Args)]
pub struct Args {
    /// Which of our solvers to compare.
    #[arg(value_enum)]
    solver: PeerSolver,
    /// Scene file (JSON; see `simbench schema`).
    scene: PathBuf,
    /// Our linear solvers to run (comma-separated); the first is the reference every run is
    /// compared with.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [Ours::Direct, Ours::ConjugateGradients])]
    ours: Vec<Ours>,
    /// The peer's linear solvers to run (comma-separated).
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [Peer::Superlu, Peer::Pardiso, Peer::Cg])]
    peers: Vec<Peer>,
    /// Override the object's thickness (m).
    #[arg(long)]
    thickness: Option<f64>,
    /// Override the scene's iteration tolerance (K) for every run.
    #[arg(long)]
    tolerance: Option<f64>,
    /// Rounds, each running every configuration once; per configuration the fastest round
    /// (stepping time) is reported, all in `stepping_s_runs` (timings on a shared machine vary
    /// between runs, and a run on two threads more than one on one).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    repeat: u32,
    /// Override the scene's timing.duration (s), to time fewer steps on large meshes.
    #[arg(long)]
    duration: Option<f64>,
    /// Several meshing.surface_element_size values (m, comma-separated): one mesh and one
    /// comparison each, for the scaling against nodes (`--out` then also gets
    /// peer_scaling.{json,csv,png}).
    #[arg(long, value_delimiter = ',')]
    element_sizes: Vec<f64>,
    /// Keep the exported problem (`DIR/problem`), every temperature series
    /// (`DIR/<code>-<solver>.npy`, float64 [frames, nodes]) and the report
    /// (`DIR/peer_report.json`) here (per mesh size in `DIR/h<size>/` with `--element-sizes`);
    /// default: a temporary directory removed afterwards.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Use this Stanford bunny OBJ instead of the cached download (also: HEATSIM_BUNNY).
    #[arg(long)]
    bunny: Option<PathBuf>,
    /// Internal: run `--ours`'s first solver once on the mesh of `--element-sizes` (or the
    /// scene's) in this process and print its timings as JSON; the comparison starts one such
    /// process per run of ours.
    #[arg(long, hide = true, requires = "out")]
    worker: bool,
    /// Internal, with `--worker`: also write the temperatures to `--out`'s `ours-<solver>.npy`.
    #[arg(long, hide = true, requires = "worker")]
    worker_temperatures: bool,
}

/// The repository root (this crate lives in `bench/`).
pub(crate) fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("bench/ has a parent").to_path_buf()
}

/// A directory removed when dropped (the default work directory).
pub(crate) struct ScratchDir(PathBuf);

/// The work directory of a peer run: `out` (created, kept), or a fresh temporary directory
/// named after `prefix` and the process, removed when the returned guard is dropped.
pub(crate) fn work_dir(out: Option<&Path>, prefix: &str) -> anyhow::Result<(Option<ScratchDir>, PathBuf)> {
    match out {
        Some(dir) => {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            Ok((None, dir.to_path_buf()))
        }
        None => {
            let dir = std::env::temp_dir().join(format!("{prefix}-{}", std::process::id()));
            std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
            Ok((Some(ScratchDir(dir.clone())), dir))
        }
    }
}

impl Drop for ScratchDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let PeerSolver::Volumetric = args.solver;
    if args.ours.is_empty() {
        bail!("--ours names no solver");
    }
    if args.worker {
        return worker(&args);
    }
    let root = repo_root();
    let python = root.join(".venv/bin/python");
    check_peer_environment(&python, &args.peers)?;
    let (_scratch, work) = work_dir(args.out.as_deref(), "simbench-peer")?;
    let sizes: Vec<Option<f64>> =
        if args.element_sizes.is_empty() { vec![None] } else { args.element_sizes.iter().map(|&h| Some(h)).collect() };
    let mut reports = Vec::new();
    for (k, h) in sizes.iter().enumerate() {
        let dir = match h {
            Some(h) => work.join(format!("h{h}")),
            None => work.clone(),
        };
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        if let Some(h) = h {
            eprintln!("simbench peer: [{}/{}] element size {h} m", k + 1, sizes.len());
        }
        let report = compare(&args, *h, &dir, &python, &root.join("bench/peers/skfem_heat.py"))?;
        if args.out.is_some() {
            let text = serde_json::to_string_pretty(&report)? + "\n";
            heatsim::io::write_atomic(&dir.join("peer_report.json"), text.as_bytes())?;
        }
        eprint!("{}", super::peer_scaling::summary(&report));
        reports.push(report);
    }
    if let (Some(out), true) = (&args.out, sizes.len() > 1) {
        super::peer_scaling::write(out, &reports)?;
    }
    let printed = if reports.len() == 1 { reports[0].clone() } else { Value::Array(reports.clone()) };
    println!("{}", serde_json::to_string_pretty(&printed)?);
    for r in &reports {
        let rel = r["max_rel_diff"].as_f64().unwrap_or(f64::NAN);
        if rel.is_nan() || rel > AGREEMENT {
            bail!(
                "at {} nodes, a run's temperatures differ from the reference by {rel:e} of the temperature rise \
                 (> {AGREEMENT:e}); see each run's max_rel_diff",
                r["nodes"]
            );
        }
    }
    Ok(())
}

/// One mesh: every configuration of ours and of the peer, their timings and agreement.
fn compare(args: &Args, element_size: Option<f64>, work: &Path, python: &Path, script: &Path) -> anyhow::Result<Value> {
    let scene = scene_of(args, element_size)?;
    let t_mesh = Instant::now();
    let meshed = heatsim::meshing::mesh_scene(&scene, args.bunny.as_deref())
        .with_context(|| format!("meshing the object of {}", args.scene.display()))?;
    let mesh_seconds = t_mesh.elapsed().as_secs_f64();
    let mesh = &meshed.mesh;
    eprintln!("simbench peer: {} nodes, {} tetrahedra", mesh.verts.len(), mesh.tets.len());

    // Rounds of every configuration once, ours first, so that all of them meet the same states
    // of a shared machine; per configuration the fastest round is kept. Every run is a process
    // of its own, ours as the peer's: a run leaves state behind that slows the next one in the
    // same process (rayon's workers after faer's parallel factor slowed our conjugate gradients
    // by up to 60 %; docs/notes/forward-model.md).
    let problem_dir = work.join("problem");
    let problem =
        heatsim::problem_export::write_problem(&problem_dir, &scene, mesh).context("exporting the problem")?;
    let schedule = (problem.steps, problem.frames);
    let mut best: Vec<Option<Value>> = vec![None; args.ours.len() + args.peers.len()];
    for round in 0..args.repeat {
        for (k, &ours) in args.ours.iter().enumerate() {
            let (run, s) = run_ours_process(args, element_size, ours, mesh.verts.len(), work, round == 0)
                .with_context(|| format!("simulating {} with ours ({})", args.scene.display(), ours.name()))?;
            if s != schedule {
                bail!(
                    "ours ({}) ran {} steps and {} frames, the exported problem has {} and {}",
                    ours.name(),
                    s.0,
                    s.1,
                    schedule.0,
                    schedule.1
                );
            }
            keep_fastest(&mut best[k], run);
        }
        for (k, &peer) in args.peers.iter().enumerate() {
            let run = run_peer_once(python, script, &problem_dir, peer, work)?;
            keep_fastest(&mut best[args.ours.len() + k], run);
        }
    }
    let reference = read_temperatures(&work.join(format!("ours-{}.npy", args.ours[0].name())), None)?;
    let mut runs: Vec<Value> = best.into_iter().map(|b| b.expect("every configuration ran")).collect();
    let max_rise = reference.iter().map(|t| t - scene.environment.ambient_temperature).fold(0.0_f64, f64::max);
    let max_rel_diff = add_agreement(&mut runs, &reference, max_rise, schedule.0, work)?;
    Ok(json!({
        "scene": args.scene.display().to_string(),
        "peer": "scikit-fem + SciPy / MKL (bench/peers/skfem_heat.py)",
        "element_size_m": scene.meshing.surface_element_size,
        "nodes": mesh.verts.len(),
        "tets": mesh.tets.len(),
        "steps": schedule.0,
        "frames": schedule.1,
        "tolerance_k": scene.solver.newton_tolerance,
        "lumped": problem.lumped,
        "back_boundary": problem.back_boundary,
        "max_rise_k": max_rise,
        "reference": format!("ours {}", args.ours[0].name()),
        "max_rel_diff": max_rel_diff,
        "agreement_bound": AGREEMENT,
        "threads_available": std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        "mesh_s": mesh_seconds,
        "speedups": speedups(&runs),
        "runs": runs,
    }))
}

/// The scene with the command line's overrides, lit by its lamps or its first lamp
/// configuration (as `simbench mesh-independence`), stepped with backward Euler (the peer's
/// time discretisation).
fn scene_of(args: &Args, element_size: Option<f64>) -> anyhow::Result<heatsim::scene::Scene> {
    let mut scene = super::load_scene(&args.scene, args.thickness)?;
    if let Some(tol) = args.tolerance {
        scene.solver.newton_tolerance = tol;
    }
    if let Some(d) = args.duration {
        scene.timing.duration = d;
    }
    if let Some(h) = element_size {
        scene.meshing.surface_element_size = h;
    }
    if let Some((_, lamps)) = scene.lamp_sets().into_iter().next() {
        scene.lamps = lamps;
    }
    scene.lamp_configurations.clear();
    if scene.solver.time_integration != TimeIntegration::BackwardEuler {
        eprintln!("simbench peer: the peer steps with backward Euler; so does ours here (the scene asks for BDF2)");
        scene.solver.time_integration = TimeIntegration::BackwardEuler;
    }
    scene.validate().context("the command-line overrides")?;
    Ok(scene)
}

/// `simbench peer --worker`: one run of `--ours`'s first solver on the scene's mesh (with the
/// command line's overrides), its timings and schedule printed as one JSON line.
fn worker(args: &Args) -> anyhow::Result<()> {
    let element_size = match args.element_sizes.as_slice() {
        [] => None,
        [h] => Some(*h),
        _ => bail!("--worker takes at most one element size"),
    };
    let out = args.out.as_deref().context("--worker needs --out")?;
    let ours = *args.ours.first().context("--ours names no solver")?;
    let mut scene = scene_of(args, element_size)?;
    let meshed = heatsim::meshing::mesh_scene(&scene, args.bunny.as_deref())
        .with_context(|| format!("meshing the object of {}", args.scene.display()))?;
    let temperatures = args.worker_temperatures.then(|| out.join(format!("ours-{}.npy", ours.name())));
    let (run, (steps, frames)) = run_ours(&mut scene, &meshed.mesh, ours, temperatures.as_deref())
        .with_context(|| format!("simulating {}", args.scene.display()))?;
    println!("{}", json!({ "run": run, "nodes": meshed.mesh.verts.len(), "steps": steps, "frames": frames }));
    Ok(())
}

/// One run of our linear solver `ours` in a process of its own (`simbench peer --worker`),
/// which meshes the scene again (TetGen is deterministic; the node count is checked against
/// `nodes`). With `temperatures`, it writes them to `work/ours-<solver>.npy`. Returns the run
/// and its schedule (steps, frames).
fn run_ours_process(
    args: &Args,
    element_size: Option<f64>,
    ours: Ours,
    nodes: usize,
    work: &Path,
    temperatures: bool,
) -> anyhow::Result<(Value, (usize, usize))> {
    eprintln!("simbench peer: running ours ({})", ours.name());
    let exe = std::env::current_exe().context("locating the simbench executable")?;
    let solver = clap::ValueEnum::to_possible_value(&ours).context("a named solver")?;
    let mut cmd = Command::new(exe);
    cmd.args(["peer", "volumetric"])
        .arg(&args.scene)
        .args(["--worker", "--ours", solver.get_name(), "--out"])
        .arg(work);
    let options = [
        ("--thickness", args.thickness),
        ("--tolerance", args.tolerance),
        ("--duration", args.duration),
        ("--element-sizes", element_size),
    ];
    for (flag, value) in options {
        if let Some(v) = value {
            // `{:e}` prints the shortest string that parses back to the same f64.
            cmd.arg(flag).arg(format!("{v:e}"));
        }
    }
    if let Some(bunny) = &args.bunny {
        cmd.arg("--bunny").arg(bunny);
    }
    if temperatures {
        cmd.arg("--worker-temperatures");
    }
    let line = last_json_line(&cmd.output().context("running simbench peer --worker")?, "the run")?;
    let count = |k: &str| line[k].as_u64().map(|n| n as usize).with_context(|| format!("the run's JSON lacks {k}"));
    if count("nodes")? != nodes {
        bail!("the run meshed the scene into {} nodes, this process into {nodes}", count("nodes")?);
    }
    Ok((line["run"].clone(), (count("steps")?, count("frames")?)))
}

/// One run of our linear solver `ours` on `mesh`, timed (assembly, factorisation, stepping).
/// Writes its temperatures (K, float64 [frames, nodes]) to `temperatures` if given. Returns the
/// run and its schedule (steps, frames).
fn run_ours(
    scene: &mut heatsim::scene::Scene,
    mesh: &heatsim::mesh::tetmesh::TetMesh,
    ours: Ours,
    temperatures: Option<&Path>,
) -> anyhow::Result<(Value, (usize, usize))> {
    scene.solver.linear_solver = match ours {
        Ours::Direct => LinearSolverKind::Direct,
        Ours::ConjugateGradients => LinearSolverKind::ConjugateGradients,
    };
    let t_ours = Instant::now();
    let sim = heatsim::simulate::simulate_volumetric(scene, mesh, |_, _| {})?;
    let total_s = t_ours.elapsed().as_secs_f64();
    let r = &sim.report;
    let run = json!({
        "code": "ours",
        "linear_solver": ours.name(),
        "total_s": total_s,
        "assembly_s": r.assembly_seconds,
        "factorisation_s": r.factorisation_seconds,
        "stepping_s": r.stepping_seconds,
        "solves": r.newton_iterations_total,
        "cg_iterations": r.cg_iterations_total,
        "factorisations": r.factorisations,
        "matrix_nnz": 2 * r.matrix_nonzeros_lower - r.nodes,
    });
    let schedule = (r.steps, sim.times.len());
    if let Some(path) = temperatures {
        let temps = Array2::from_shape_vec((sim.times.len(), sim.nodes), sim.node_temperatures)?;
        let file = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
        temps.write_npy(std::io::BufWriter::new(file)).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok((run, schedule))
}

/// One run of the peer with the linear solver `peer` on the problem in `problem_dir`; its
/// temperatures go to `work/peer-<solver>.npy`.
fn run_peer_once(python: &Path, script: &Path, problem_dir: &Path, peer: Peer, work: &Path) -> anyhow::Result<Value> {
    let path = work.join(format!("peer-{}.npy", peer.name()));
    let (timings, process_s) = run_peer(python, script, problem_dir, peer, &path)?;
    let number = |k: &str| timings[k].as_f64().with_context(|| format!("the peer's timings lack {k}"));
    Ok(json!({
        "code": "peer",
        "linear_solver": peer.name(),
        "total_s": number("total_s")?,
        "assembly_s": number("assembly_s")?,
        "factorisation_s": number("factorisation_s")?,
        "stepping_s": number("stepping_s")?,
        "solves": timings["solves"],
        "cg_iterations": timings.get("cg_iterations"),
        "factorisations": timings["factorisations"],
        "factor_nonzeros": timings.get("factor_nnz"),
        "matrix_nnz": timings.get("matrix_nnz"),
        "process_s": process_s,
    }))
}

/// Adds to each run its time per step, solves per step and its largest difference from
/// `reference` (K, and over the largest rise `max_rise`), reading its temperatures from
/// `work/<code>-<solver>.npy`. Returns the largest relative difference (NaN if any is not a
/// number).
fn add_agreement(
    runs: &mut [Value],
    reference: &Array2<f64>,
    max_rise: f64,
    steps: usize,
    work: &Path,
) -> anyhow::Result<f64> {
    let mut max_rel_diff = 0.0_f64;
    for run in runs.iter_mut() {
        let code = run["code"].as_str().unwrap_or("").to_string();
        let path = work.join(format!("{code}-{}.npy", run["linear_solver"].as_str().unwrap_or("")));
        let temps = read_temperatures(&path, Some(reference.dim()))?;
        let (max_abs, worst) = largest_difference(reference, &temps);
        let rel = if max_rise > 0.0 { max_abs / max_rise } else { max_abs };
        max_rel_diff = if rel.is_nan() || max_rel_diff.is_nan() { f64::NAN } else { max_rel_diff.max(rel) };
        let steps = steps.max(1) as f64;
        let stepping = run["stepping_s"].as_f64().unwrap_or(f64::NAN);
        let solves = run["solves"].as_f64().unwrap_or(f64::NAN);
        let extra = json!({
            "step_s": stepping / steps,
            "solve_s": stepping / solves,
            "solves_per_step": solves / steps,
            "bytes_read_per_step": bytes_read(run).map(|b| b / steps),
            "max_abs_diff_k": max_abs,
            "max_rel_diff": rel,
            "worst_frame": worst.0,
            "worst_node": worst.1,
        });
        run.as_object_mut().expect("an object").extend(extra.as_object().expect("an object").clone());
    }
    Ok(max_rel_diff)
}

/// An estimate of the bytes a run read from its step matrix or factor over all its solves,
/// the memory traffic that bounds every configuration (vectors left out; as `simbench
/// bench-solver`): conjugate gradients read the full matrix (8-byte values, 4-byte columns)
/// once per iteration and once per solve for the starting residual; SuperLU reads L and U once
/// per solve, PARDISO its Cholesky factor twice (8 bytes per supernodal value). `None` for our
/// factor, whose size the run does not report (`simbench bench-solver` counts it).
fn bytes_read(run: &Value) -> Option<f64> {
    let num = |k: &str| run[k].as_f64();
    match run["linear_solver"].as_str()? {
        "conjugate_gradients" | "cg" => Some((num("cg_iterations")? + num("solves")?) * num("matrix_nnz")? * 12.0),
        "superlu" => Some(num("solves")? * num("factor_nonzeros")? * 8.0),
        "pardiso" => Some(num("solves")? * num("factor_nonzeros")? * 16.0),
        _ => None,
    }
}

/// Each peer run's stepping and total time over each of ours.
fn speedups(runs: &[Value]) -> Vec<Value> {
    runs.iter()
        .filter(|r| r["code"] == "ours")
        .flat_map(|o| {
            runs.iter().filter(|r| r["code"] == "peer").map(move |p| {
                let ratio = |k: &str| p[k].as_f64().unwrap_or(f64::NAN) / o[k].as_f64().unwrap_or(f64::NAN);
                json!({
                    "ours": o["linear_solver"],
                    "peer": p["linear_solver"],
                    "stepping": ratio("stepping_s"),
                    "total": ratio("total_s"),
                })
            })
        })
        .collect()
}

/// Keeps in `best` whichever of it and `run` stepped faster, with every stepping time seen in
/// `stepping_s_runs` (in the order run).
fn keep_fastest(best: &mut Option<Value>, mut run: Value) {
    let stepping = |v: &Value| v["stepping_s"].as_f64().unwrap_or(f64::INFINITY);
    let mut seen: Vec<Value> = best.as_ref().and_then(|b| b["stepping_s_runs"].as_array().cloned()).unwrap_or_default();
    seen.push(run["stepping_s"].clone());
    if let Some(b) = best.as_ref().filter(|b| stepping(b) <= stepping(&run)) {
        run = b.clone();
    }
    run["stepping_s_runs"] = Value::Array(seen);
    *best = Some(run);
}

/// Checks that the project's Python environment `python` exists and imports scikit-fem and
/// SciPy, and pypardiso when `peers` asks for PARDISO.
fn check_peer_environment(python: &Path, peers: &[Peer]) -> anyhow::Result<()> {
    if peers.is_empty() {
        return Ok(());
    }
    if !python.exists() {
        bail!("the oracle environment {} is missing: run scripts/setup-oracles.sh", python.display());
    }
    let mut probes = vec![("import skfem, scipy", "scikit-fem or SciPy", "scripts/setup-oracles.sh")];
    if peers.contains(&Peer::Pardiso) {
        probes.push(("import pypardiso", "pypardiso (MKL PARDISO)", "scripts/setup-peers.sh"));
    }
    for (code, what, fix) in probes {
        let probe = Command::new(python)
            .args(["-c", code])
            .output()
            .with_context(|| format!("running {}", python.display()))?;
        if !probe.status.success() {
            bail!(
                "{what} is missing from {} (run {fix}): {}",
                python.display(),
                String::from_utf8_lossy(&probe.stderr).trim()
            );
        }
    }
    Ok(())
}

/// Runs the peer `script` with `python` and the linear solver `peer` on the exported problem
/// in `problem_dir`; it writes its temperatures to `peer_path`. Returns the timings it prints
/// (the last JSON line of its output) and the seconds the process took.
fn run_peer(
    python: &Path,
    script: &Path,
    problem_dir: &Path,
    peer: Peer,
    peer_path: &Path,
) -> anyhow::Result<(Value, f64)> {
    eprintln!("simbench peer: running {} --linear-solver {}", script.display(), peer.name());
    let t_peer = Instant::now();
    let out = Command::new(python)
        .arg(script)
        .arg(problem_dir)
        .arg("--out")
        .arg(peer_path)
        .args(["--linear-solver", peer.name()])
        .output()
        .with_context(|| format!("running {}", script.display()))?;
    let process_s = t_peer.elapsed().as_secs_f64();
    Ok((last_json_line(&out, &format!("the peer ({})", peer.name()))?, process_s))
}

/// The last line of a finished process's output that parses as JSON; an error with its
/// standard error if it failed, `what` naming it.
fn last_json_line(out: &std::process::Output, what: &str) -> anyhow::Result<Value> {
    if !out.status.success() {
        bail!("{what} failed ({}): {}", out.status, String::from_utf8_lossy(&out.stderr).trim());
    }
    let stdout = String::from_utf8_lossy(&out.stdout);
    stdout
        .lines()
        .rev()
        .find_map(|l| serde_json::from_str(l).ok())
        .with_context(|| format!("{what} printed no JSON: {stdout}"))
}

/// A run's temperatures (K, [frames, nodes]) from `path`; with `dim`, they must have that shape
/// (the reference's).
fn read_temperatures(path: &Path, dim: Option<(usize, usize)>) -> anyhow::Result<Array2<f64>> {
    let temps: Array2<f64> =
        Array2::read_npy(std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?)
            .with_context(|| format!("reading {}", path.display()))?;
    if let Some(dim) = dim.filter(|&d| d != temps.dim()) {
        bail!("{} holds {:?} temperatures, the reference {:?}", path.display(), temps.dim(), dim);
    }
    Ok(temps)
}

/// max |a - b| (K; infinite when a difference is not finite) and where it is (frame, node).
fn largest_difference(a: &Array2<f64>, b: &Array2<f64>) -> (f64, (usize, usize)) {
    let (mut max_abs, mut worst) = (0.0_f64, (0usize, 0usize));
    for ((idx, x), y) in a.indexed_iter().zip(b.iter()) {
        let d = (x - y).abs();
        // NaN compares false: caught below through the finiteness check.
        if d > max_abs || !d.is_finite() {
            max_abs = if d.is_finite() { d } else { f64::INFINITY };
            worst = idx;
        }
    }
    (max_abs, worst)
}
