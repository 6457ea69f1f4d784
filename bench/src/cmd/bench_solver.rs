//! `simbench bench-solver SCENE [--element-sizes H1,H2,...] [--out DIR]`: timings of the
//! volumetric solver's phases with each linear solver (the sparse Cholesky factor and
//! Jacobi-preconditioned conjugate gradients), measured in one run so their ratios are
//! meaningful on a noisy shared machine, and the largest difference between the two solvers'
//! temperatures after the same steps. With several element sizes, one mesh per size (the
//! scaling against nodes); `--out` writes `solver_scaling.{json,csv,png}`.
//!
//! Bytes read per step (an estimate of the memory traffic that bounds both solvers): the
//! factor's values twice per solve (forward and backward substitution, 8 bytes each), or the
//! full matrix once per CG iteration (8-byte values and 4-byte columns); vectors are left out.

use super::median_time as time;
use anyhow::Context;
use heatsim::fem::volumetric::{HeatSystem, LinearSolver, Stepper, TimeIntegrator};
use heatsim::mesh::tetmesh::FaceTag;
use heatsim::scene::Scene;
use heatsim::simulate::{exposed_faces, physics_from_scene, uniform_load};
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct Args {
    /// Scene file (JSON).
    scene: PathBuf,
    /// Override the object's thickness (m).
    #[arg(long)]
    thickness: Option<f64>,
    /// Override meshing.surface_element_size (m) to change the mesh size.
    #[arg(long)]
    element_size: Option<f64>,
    /// Several meshing.surface_element_size values (m, comma-separated): one mesh and one
    /// measurement each, for the scaling against nodes.
    #[arg(long, value_delimiter = ',', conflicts_with = "element_size")]
    element_sizes: Vec<f64>,
    /// Repetitions of each timed phase (the median is reported).
    #[arg(long, default_value_t = 30)]
    repeat: usize,
    /// Use this Stanford bunny OBJ instead of the cached download.
    #[arg(long)]
    bunny: Option<PathBuf>,
    /// Also write solver_scaling.json, .csv and .png here.
    #[arg(long)]
    out: Option<PathBuf>,
}

/// Steps from rest after which the two solvers' temperatures are compared.
const AGREEMENT_STEPS: usize = 100;

pub fn run(args: Args) -> anyhow::Result<()> {
    let sizes: Vec<Option<f64>> = if args.element_sizes.is_empty() {
        vec![args.element_size]
    } else {
        args.element_sizes.iter().map(|&h| Some(h)).collect()
    };
    let mut rows = Vec::new();
    for (k, h) in sizes.iter().enumerate() {
        let mut scene = super::load_scene(&args.scene, args.thickness)?;
        if let Some(h) = h {
            scene.meshing.surface_element_size = *h;
        }
        scene.validate().with_context(|| format!("overrides (element size {h:?})"))?;
        let row = measure(&scene, &args)?;
        if sizes.len() > 1 {
            eprintln!("bench-solver: [{}/{}] element size {:?} m: {} nodes", k + 1, sizes.len(), h, row["nodes"]);
        }
        rows.push(row);
    }
    let report = if rows.len() == 1 { rows[0].clone() } else { Value::Array(rows.clone()) };
    println!("{}", serde_json::to_string_pretty(&report)?);
    if let Some(out) = &args.out {
        write_outputs(out, &rows)?;
    }
    Ok(())
}

/// Meshes and assembles `scene`, then times both linear solvers on it (module doc).
fn measure(scene: &Scene, args: &Args) -> anyhow::Result<Value> {
    let meshed = heatsim::meshing::mesh_scene(scene, args.bunny.as_deref())?;
    let mesh = &meshed.mesh;
    let material = scene.material.resolve()?;
    let env = &scene.environment;
    let physics = physics_from_scene(scene)?;
    let exposed = exposed_faces(mesh, env.back_boundary);
    let r = args.repeat;
    let assembly_s = time(r.min(5), || HeatSystem::assemble(mesh, physics.clone(), &exposed).unwrap());
    let system = HeatSystem::assemble(mesh, physics, &exposed)?;
    let n = system.len();
    // Steps of a heating run: uniform flux on the visible face, extrapolated initial guess.
    let load = uniform_load(mesh, FaceTag::Visible, 100.0 * material.absorptivity);
    let bench = SolverBench { system: &system, load: &load, scene, repeat: r };
    let mut phases = Vec::new();
    let mut finals: Vec<Vec<f64>> = Vec::new();
    for solver in [LinearSolver::Direct, LinearSolver::ConjugateGradients] {
        let (phase, last) = bench.time(solver)?;
        phases.push(phase);
        finals.push(last);
    }
    let agreement = finals[0].iter().zip(&finals[1]).fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
    let nnz_full = 2 * system.pattern.nnz() - n;
    let factor_values = factor_len(&system)?;
    for p in &mut phases {
        let solves = p["iterations_per_step_mean"].as_f64().unwrap_or(f64::NAN);
        let bytes = if p["solver"] == "Direct" {
            solves * 2.0 * 8.0 * factor_values as f64
        } else {
            solves * p["cg_iterations_per_solve_mean"].as_f64().unwrap_or(f64::NAN) * 12.0 * nnz_full as f64
        };
        p["bytes_read_per_step"] = json!(bytes);
    }
    let step = |i: usize| phases[i]["step_s"].as_f64().unwrap_or(f64::NAN);
    Ok(json!({
        "scene": args.scene,
        "element_size_m": scene.meshing.surface_element_size,
        "nodes": n,
        "tetrahedra": mesh.tets.len(),
        "matrix_nonzeros_lower": system.pattern.nnz(),
        "matrix_nonzeros_full": nnz_full,
        "factor_values": factor_values,
        "threads": rayon_threads(),
        "assembly_s": assembly_s,
        "solvers": phases,
        "direct_step_over_cg_step": step(0) / step(1),
        "max_difference_after_steps_k": agreement,
        "agreement_steps": AGREEMENT_STEPS,
        "newton_tolerance_k": scene.solver.newton_tolerance,
        "target": "direct step_over_substitution <= 3",
    }))
}

/// One mesh's system and load, timed with a given linear solver.
struct SolverBench<'a> {
    system: &'a HeatSystem,
    load: &'a [f64],
    scene: &'a Scene,
    repeat: usize,
}

impl SolverBench<'_> {
    fn stepper(&self, solver: LinearSolver) -> anyhow::Result<Stepper> {
        let s = &self.scene.solver;
        let t_ref = vec![self.scene.environment.ambient_temperature; self.system.len()];
        let dt = self.scene.timing.time_step;
        let be = TimeIntegrator::BackwardEuler;
        Ok(Stepper::with_solver(self.system, dt, be, solver, s.newton_tolerance, s.max_newton_iterations, &t_ref)?)
    }

    /// The phases' timings with `solver`, and the temperatures after `AGREEMENT_STEPS` steps
    /// from rest.
    fn time(&self, solver: LinearSolver) -> anyhow::Result<(Value, Vec<f64>)> {
        let (system, load, r) = (self.system, self.load, self.repeat);
        let n = system.len();
        let setup_s = time(r.min(5), || self.stepper(solver).unwrap());
        let mut stepper = self.stepper(solver)?;
        let t_ref = vec![self.scene.environment.ambient_temperature; n];
        let (mut history, mut new) = (stepper.history(&t_ref), t_ref.clone());
        let mut advance = |stepper: &mut Stepper| {
            history.predict(&mut new);
            let info = stepper.step(system, history.latest(), load, &mut new).unwrap();
            history.push(&new);
            info.iterations
        };
        // Warm up past the lamp switching on, as in a run, so the predictor has history.
        for _ in 0..10 {
            advance(&mut stepper);
        }
        let cg_before = stepper.cg_iterations;
        let mut iterations = Vec::new();
        let step_s = time(r, || iterations.push(advance(&mut stepper)));
        let solves: u32 = iterations.iter().sum();
        let cg_per_solve = (stepper.cg_iterations - cg_before) as f64 / f64::from(solves.max(1));
        let mut rhs: Vec<f64> = (0..n).map(|i| (i % 7) as f64).collect();
        let substitution_s = time(r, || stepper.substitute(&mut rhs));
        // The same number of steps from rest, for the agreement check.
        let mut fresh = self.stepper(solver)?;
        let (mut history, mut t) = (fresh.history(&t_ref), t_ref.clone());
        for _ in 0..AGREEMENT_STEPS {
            history.predict(&mut t);
            fresh.step(system, history.latest(), load, &mut t)?;
            history.push(&t);
        }
        let phase = json!({
            "solver": format!("{solver:?}"),
            "setup_s": setup_s,
            "substitution_s": substitution_s,
            "step_s": step_s,
            "step_over_substitution": step_s / substitution_s,
            "iterations_per_step_mean": f64::from(solves) / iterations.len().max(1) as f64,
            "cg_iterations_per_solve_mean": cg_per_solve,
            "factorisations": stepper.factorisations,
        });
        Ok((phase, t))
    }
}

/// Values stored in the Cholesky factor of the system's pattern (its symbolic analysis).
fn factor_len(system: &HeatSystem) -> anyhow::Result<usize> {
    use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, CholeskySymbolicParams};
    use faer::sparse::SymbolicSparseColMatRef;
    let p = &system.pattern;
    let sym = SymbolicSparseColMatRef::new_checked(p.n, p.n, &p.col_ptr, None, &p.row_idx);
    let s = factorize_symbolic_cholesky(sym, faer::Side::Lower, Default::default(), CholeskySymbolicParams::default())
        .map_err(|e| anyhow::anyhow!("symbolic Cholesky: {e:?}"))?;
    Ok(s.len_val())
}

/// `solver_scaling.json`, `.csv` and `.png` in `out`.
fn write_outputs(out: &Path, rows: &[Value]) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let mut csv = String::from(
        "nodes,tetrahedra,element_size_m,solver,step_s,solve_s,solves_per_step,cg_iterations_per_solve,bytes_read_per_step,max_difference_k\n",
    );
    for r in rows {
        for p in r["solvers"].as_array().into_iter().flatten() {
            let _ = writeln!(
                csv,
                "{},{},{},{},{},{},{},{},{},{}",
                r["nodes"],
                r["tetrahedra"],
                r["element_size_m"],
                p["solver"].as_str().unwrap_or(""),
                p["step_s"],
                p["substitution_s"],
                p["iterations_per_step_mean"],
                p["cg_iterations_per_solve_mean"],
                p["bytes_read_per_step"],
                r["max_difference_after_steps_k"]
            );
        }
    }
    let mut files = vec![
        ("solver_scaling.json", (serde_json::to_string_pretty(rows)? + "\n").into_bytes()),
        ("solver_scaling.csv", csv.into_bytes()),
    ];
    if let Some(png) = crate::figure::optional("solver_scaling.png", || scaling_png(rows)) {
        files.push(("solver_scaling.png", png));
    }
    for (name, bytes) in files {
        heatsim::io::write_atomic(&out.join(name), &bytes)
            .with_context(|| format!("writing {}", out.join(name).display()))?;
    }
    Ok(())
}

/// Time per step against nodes, log-log, one line per linear solver.
fn scaling_png(rows: &[Value]) -> anyhow::Result<Vec<u8>> {
    let series = |name: &str| -> Vec<(f64, f64)> {
        rows.iter()
            .filter_map(|r| {
                let p = r["solvers"].as_array()?.iter().find(|p| p["solver"] == name)?;
                Some((r["nodes"].as_f64()?, p["step_s"].as_f64()? * 1e3))
            })
            .collect()
    };
    let lines: Vec<(String, Vec<(f64, f64)>)> =
        [("Direct", "sparse Cholesky factor"), ("ConjugateGradients", "conjugate gradients")]
            .iter()
            .map(|(name, label)| (label.to_string(), series(name)))
            .collect();
    super::peer_scaling::loglog_png("volumetric step against mesh size", "time per step (ms)", &lines)
}

fn rayon_threads() -> usize {
    std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)
}
