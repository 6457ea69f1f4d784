//! `simbench peer volumetric SCENE`: our volumetric solver side by side with an independent
//! peer (scikit-fem + SciPy, `bench/peers/skfem_heat.py`) on the identical problem.
//!
//! The scene is meshed once; our solver runs on the mesh (timed: assembly, factorisation and
//! stepping, not meshing); the exact problem is exported with
//! [`heatsim::problem_export::write_problem`]; the peer assembles and steps it in the
//! project's Python environment (`.venv`, made by scripts/setup-oracles.sh). Both are timed
//! the same way (assembly + factorisation + stepping, excluding file reading and interpreter
//! start-up) and run one after the other, never at the same time. All frames of both are
//! compared: max |T_ours - T_peer| over the largest temperature rise must be <= 1e-6, which
//! makes the run an oracle test as well as a benchmark.

use anyhow::{bail, Context};
use ndarray::Array2;
use ndarray_npy::{ReadNpyExt, WriteNpyExt};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Largest accepted max |T_ours - T_peer| / max temperature rise.
pub const AGREEMENT: f64 = 1e-6;

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum PeerSolver {
    /// The volumetric solver against scikit-fem + SciPy (bench/peers/skfem_heat.py).
    Volumetric,
}

#[derive(clap::Args)]
pub struct Args {
    /// Which of our solvers to compare.
    #[arg(value_enum)]
    solver: PeerSolver,
    /// Scene file (JSON; see `simbench schema`).
    scene: PathBuf,
    /// Override the object's thickness (m).
    #[arg(long)]
    thickness: Option<f64>,
    /// Override the scene's iteration tolerance (K) for both solvers.
    #[arg(long)]
    tolerance: Option<f64>,
    /// Keep the exported problem (DIR/problem), both temperature series (DIR/ours.npy,
    /// DIR/peer.npy, float64 [frames, nodes]) and the report (DIR/peer_report.json) here;
    /// default: a temporary directory removed afterwards.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Use this Stanford bunny OBJ instead of the cached download (also: HEATSIM_BUNNY).
    #[arg(long)]
    bunny: Option<PathBuf>,
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
    let root = repo_root();
    let python = root.join(".venv/bin/python");
    let script = root.join("bench/peers/skfem_heat.py");
    check_peer_environment(&python)?;

    let mut scene = super::load_scene(&args.scene, args.thickness)?;
    if let Some(tol) = args.tolerance {
        scene.solver.newton_tolerance = tol;
    }
    scene.validate().context("the command-line overrides")?;

    let (_scratch, work) = work_dir(args.out.as_deref(), "simbench-peer")?;

    let t_mesh = Instant::now();
    let meshed = heatsim::meshing::mesh_scene(&scene, args.bunny.as_deref())
        .with_context(|| format!("meshing the object of {}", args.scene.display()))?;
    let mesh_seconds = t_mesh.elapsed().as_secs_f64();
    let mesh = &meshed.mesh;
    eprintln!("simbench peer: {} nodes, {} tetrahedra; running ours", mesh.verts.len(), mesh.tets.len());

    // Ours: everything simulate_volumetric does (loads, assembly, factorisation, stepping).
    let t_ours = Instant::now();
    let sim = heatsim::simulate::simulate_volumetric(&scene, mesh, |_, _| {})
        .with_context(|| format!("simulating {}", args.scene.display()))?;
    let ours_s = t_ours.elapsed().as_secs_f64();

    let problem_dir = work.join("problem");
    let problem =
        heatsim::problem_export::write_problem(&problem_dir, &scene, mesh).context("exporting the problem")?;
    if problem.steps != sim.report.steps || problem.frames != sim.times.len() {
        bail!(
            "the exported schedule ({} steps, {} frames) differs from the run ({} steps, {} frames)",
            problem.steps,
            problem.frames,
            sim.report.steps,
            sim.times.len()
        );
    }
    let frames = sim.times.len();
    let ours = Array2::from_shape_vec((frames, sim.nodes), sim.node_temperatures.clone())?;
    let ours_path = work.join("ours.npy");
    ours.write_npy(std::io::BufWriter::new(std::fs::File::create(&ours_path)?))
        .with_context(|| format!("writing {}", ours_path.display()))?;

    let peer_path = work.join("peer.npy");
    let (timings, peer_process_s) = run_peer(&python, &script, &problem_dir, &peer_path)?;
    let peer_s = timings["total_s"].as_f64().context("the peer's timings lack total_s")?;
    let peer = read_peer_temperatures(&peer_path, ours.dim())?;

    let ts = scene.environment.ambient_temperature;
    let max_rise = ours.iter().map(|t| t - ts).fold(0.0_f64, f64::max);
    let (max_abs, worst) = largest_difference(&ours, &peer);
    let max_rel_diff = if max_rise > 0.0 { max_abs / max_rise } else { max_abs };
    let threads = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    let report = serde_json::json!({
        "scene": args.scene.display().to_string(),
        "peer": "scikit-fem + SciPy (bench/peers/skfem_heat.py)",
        "nodes": sim.nodes,
        "tets": mesh.tets.len(),
        "steps": sim.report.steps,
        "frames": frames,
        "tolerance_k": scene.solver.newton_tolerance,
        "lumped": problem.lumped,
        "back_boundary": problem.back_boundary,
        "ours_s": ours_s,
        "peer_s": peer_s,
        "speedup": peer_s / ours_s,
        "max_rel_diff": max_rel_diff,
        "max_abs_diff_k": max_abs,
        "max_rise_k": max_rise,
        "worst_frame": worst.0,
        "worst_node": worst.1,
        "threads_available": threads,
        "mesh_s": mesh_seconds,
        "ours": {
            "assembly_s": sim.report.assembly_seconds,
            "factorisation_s": sim.report.factorisation_seconds,
            "stepping_s": sim.report.stepping_seconds,
            "iterations_total": sim.report.newton_iterations_total,
            "factorisations": sim.report.factorisations,
        },
        "peer_timings": timings,
        "peer_process_s": peer_process_s,
        "agreement_bound": AGREEMENT,
    });
    let text = serde_json::to_string_pretty(&report)? + "\n";
    if args.out.is_some() {
        heatsim::io::write_atomic(&work.join("peer_report.json"), text.as_bytes())?;
    }
    print!("{text}");
    if max_rel_diff.is_nan() || max_rel_diff > AGREEMENT {
        bail!(
            "our temperatures differ from the peer's by {max_rel_diff:e} of the temperature rise (> {AGREEMENT:e}): \
             {max_abs:e} K at frame {}, node {}",
            worst.0,
            worst.1
        );
    }
    Ok(())
}

/// Checks that the project's Python environment `python` exists and imports scikit-fem and
/// SciPy.
fn check_peer_environment(python: &Path) -> anyhow::Result<()> {
    if !python.exists() {
        bail!("the oracle environment {} is missing: run scripts/setup-oracles.sh", python.display());
    }
    let probe = Command::new(python)
        .args(["-c", "import skfem, scipy"])
        .output()
        .with_context(|| format!("running {}", python.display()))?;
    if !probe.status.success() {
        bail!(
            "scikit-fem or SciPy is missing from {} (run scripts/setup-oracles.sh): {}",
            python.display(),
            String::from_utf8_lossy(&probe.stderr).trim()
        );
    }
    Ok(())
}

/// Runs the peer `script` with `python` on the exported problem in `problem_dir`; it writes its
/// temperatures to `peer_path`. Returns the timings it prints (the last JSON line of its
/// output) and the seconds the process took.
fn run_peer(
    python: &Path,
    script: &Path,
    problem_dir: &Path,
    peer_path: &Path,
) -> anyhow::Result<(serde_json::Value, f64)> {
    eprintln!("simbench peer: running {}", script.display());
    let t_peer = Instant::now();
    let out = Command::new(python)
        .arg(script)
        .arg(problem_dir)
        .arg("--out")
        .arg(peer_path)
        .output()
        .with_context(|| format!("running {}", script.display()))?;
    let peer_process_s = t_peer.elapsed().as_secs_f64();
    if !out.status.success() {
        bail!("the peer failed ({}): {}", out.status, String::from_utf8_lossy(&out.stderr).trim());
    }
    let stdout = String::from_utf8_lossy(&out.stdout);
    let timings: serde_json::Value = stdout
        .lines()
        .rev()
        .find_map(|l| serde_json::from_str(l).ok())
        .with_context(|| format!("the peer printed no JSON timings: {stdout}"))?;
    Ok((timings, peer_process_s))
}

/// The peer's temperatures (K, [frames, nodes]) from `peer_path`; they must have the shape
/// `dim` of ours.
fn read_peer_temperatures(peer_path: &Path, dim: (usize, usize)) -> anyhow::Result<Array2<f64>> {
    let peer: Array2<f64> =
        Array2::read_npy(std::fs::File::open(peer_path).with_context(|| format!("opening {}", peer_path.display()))?)
            .with_context(|| format!("reading {}", peer_path.display()))?;
    if peer.dim() != dim {
        bail!("the peer wrote {:?} temperatures, ours are {:?}", peer.dim(), dim);
    }
    Ok(peer)
}

/// max |ours - peer| (K; infinite when a difference is not finite) and where it is (frame,
/// node).
fn largest_difference(ours: &Array2<f64>, peer: &Array2<f64>) -> (f64, (usize, usize)) {
    let (mut max_abs, mut worst) = (0.0_f64, (0usize, 0usize));
    for ((idx, a), b) in ours.indexed_iter().zip(peer.iter()) {
        let d = (a - b).abs();
        // NaN compares false: caught below through the finiteness check.
        if d > max_abs || !d.is_finite() {
            max_abs = if d.is_finite() { d } else { f64::INFINITY };
            worst = idx;
        }
    }
    (max_abs, worst)
}
