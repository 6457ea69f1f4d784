//! `simbench bench-solver SCENE`: timings of the volumetric solver's phases with each linear
//! solver (the sparse Cholesky factor and Jacobi-preconditioned conjugate gradients), measured
//! in one run so their ratios are meaningful on a noisy shared machine, and the largest
//! difference between the two solvers' temperatures after the same steps.

use super::median_time as time;
use anyhow::Context;
use heatsim::fem::volumetric::{extrapolate, HeatSystem, LinearSolver, Stepper, TimeIntegrator};
use heatsim::mesh::tetmesh::FaceTag;
use heatsim::simulate::{exposed_faces, physics_from_scene, uniform_load};
use std::path::PathBuf;

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
    /// Repetitions of each timed phase (the median is reported).
    #[arg(long, default_value_t = 30)]
    repeat: usize,
    /// Use this Stanford bunny OBJ instead of the cached download.
    #[arg(long)]
    bunny: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut scene = super::load_scene(&args.scene, args.thickness)?;
    if let Some(h) = args.element_size {
        scene.meshing.surface_element_size = h;
    }
    scene.validate().context("overrides")?;
    let meshed = heatsim::meshing::mesh_scene(&scene, args.bunny.as_deref())?;
    let mesh = &meshed.mesh;
    let material = scene.material.resolve()?;
    let env = &scene.environment;
    let physics = physics_from_scene(&scene)?;
    let exposed = exposed_faces(mesh, env.back_boundary);
    if std::env::var_os("FAER_SEQ").is_some() {
        faer::set_global_parallelism(faer::Par::Seq);
    }
    let r = args.repeat;
    let assembly_s = time(r.min(5), || HeatSystem::assemble(mesh, physics.clone(), &exposed).unwrap());
    let system = HeatSystem::assemble(mesh, physics, &exposed)?;
    let n = system.len();
    let t_ref = vec![env.ambient_temperature; n];
    let dt = scene.timing.time_step;
    let tol = scene.solver.newton_tolerance;
    let its = scene.solver.max_newton_iterations;
    let be = TimeIntegrator::BackwardEuler;
    // Steps of a heating run: uniform flux on the visible face, extrapolated initial guess.
    let load = uniform_load(mesh, FaceTag::Visible, 100.0 * material.absorptivity);
    let mut phases = Vec::new();
    let mut finals: Vec<Vec<f64>> = Vec::new();
    for solver in [LinearSolver::Direct, LinearSolver::ConjugateGradients] {
        let new_stepper = || Stepper::with_solver(&system, dt, be, solver, tol, its, &t_ref);
        let setup_s = time(r.min(5), || new_stepper().unwrap());
        let mut stepper = new_stepper()?;
        let mut rhs: Vec<f64> = (0..n).map(|i| (i % 7) as f64).collect();
        let (mut oldest, mut older, mut old, mut new) = (t_ref.clone(), t_ref.clone(), t_ref.clone(), t_ref.clone());
        let mut iterations = Vec::new();
        let mut s = 0;
        let mut advance = |iterations: &mut Vec<u32>, stepper: &mut Stepper| {
            s += 1;
            extrapolate(s, &old, &older, &oldest, &mut new);
            let info = stepper.step(&system, &old, &load, &mut new).unwrap();
            iterations.push(info.iterations);
            oldest.copy_from_slice(&older);
            older.copy_from_slice(&old);
            old.copy_from_slice(&new);
        };
        // Warm up past the lamp switching on, as in a run, so the predictor has history.
        let mut warmup = Vec::new();
        for _ in 0..10 {
            advance(&mut warmup, &mut stepper);
        }
        let cg_before = stepper.cg_iterations;
        let step_s = time(r, || advance(&mut iterations, &mut stepper));
        let solves: u32 = iterations.iter().sum();
        let cg_per_solve = (stepper.cg_iterations - cg_before) as f64 / f64::from(solves.max(1));
        let substitution_s = time(r, || stepper.substitute(&mut rhs));
        // The same number of steps from rest for the agreement check.
        let mut fresh = new_stepper()?;
        let (mut o3, mut o2, mut o1, mut t) = (t_ref.clone(), t_ref.clone(), t_ref.clone(), t_ref.clone());
        for k in 1..=AGREEMENT_STEPS {
            extrapolate(k, &o1, &o2, &o3, &mut t);
            fresh.step(&system, &o1, &load, &mut t)?;
            o3.copy_from_slice(&o2);
            o2.copy_from_slice(&o1);
            o1.copy_from_slice(&t);
        }
        finals.push(t);
        phases.push(serde_json::json!({
            "solver": format!("{solver:?}"),
            "setup_s": setup_s,
            "substitution_s": substitution_s,
            "step_s": step_s,
            "step_over_substitution": step_s / substitution_s,
            "iterations_per_step_mean": iterations.iter().map(|&i| f64::from(i)).sum::<f64>() / iterations.len() as f64,
            "cg_iterations_per_solve_mean": cg_per_solve,
            "factorisations": stepper.factorisations,
        }));
    }
    let step = |i: usize| phases[i]["step_s"].as_f64().unwrap_or(f64::NAN);
    let agreement = finals[0].iter().zip(&finals[1]).fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
    let report = serde_json::json!({
        "scene": args.scene,
        "nodes": n,
        "tetrahedra": mesh.tets.len(),
        "matrix_nonzeros_lower": system.pattern.nnz(),
        "threads": rayon_threads(),
        "assembly_s": assembly_s,
        "solvers": phases,
        "direct_step_over_cg_step": step(0) / step(1),
        "max_difference_after_steps_k": agreement,
        "agreement_steps": AGREEMENT_STEPS,
        "newton_tolerance_k": tol,
        "target": "direct step_over_substitution <= 3",
    });
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}

/// Steps from rest after which the two solvers' temperatures are compared.
const AGREEMENT_STEPS: usize = 100;

fn rayon_threads() -> usize {
    std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)
}
