//! `simbench bench-surface`: timings of the surface solver (paper Eq. 6) on a camera-sized
//! pixel-grid surface, measured in one run so their ratios are meaningful on a noisy machine.
//!
//! The surface: one vertex per pixel of a W x H grid with 0.25 mm pitch, lifted to a smooth
//! bump z = A cos(2 pi x / P) cos(2 pi y / P) so that the cotangent weights are not those of a
//! flat grid; triangulated by `heatsim::camera::grid::PixelGrid` with a full mask.

use super::median_time as time;
use anyhow::Context;
use heatsim::camera::grid::PixelGrid;
use heatsim::fem::volumetric::Stepper;
use heatsim::scene::Scene;
use heatsim::simulate::{face_load, physics_from_scene};
use heatsim::surface::operators::AreaMass;
use heatsim::surface::system::{assemble, SurfacePhysics};
use std::time::Instant;

#[derive(clap::Args)]
pub struct Args {
    /// Grid width in pixels.
    #[arg(long, default_value_t = 640)]
    width: usize,
    /// Grid height in pixels.
    #[arg(long, default_value_t = 512)]
    height: usize,
    /// Material name from the library (`simbench schema` lists them).
    #[arg(long, default_value = "pla")]
    material: String,
    /// Layer thickness d (m).
    #[arg(long, default_value_t = 0.005)]
    thickness: f64,
    /// Radiation: exact T^4 (chord Newton) or linearised (one substitution per step).
    #[arg(long)]
    linearized: bool,
    /// Repetitions of each timed phase (the median is reported).
    #[arg(long, default_value_t = 20)]
    repeat: usize,
}

const PITCH: f64 = 2.5e-4;

pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(args.width >= 2 && args.height >= 2, "--width and --height must be at least 2 pixels");
    anyhow::ensure!(args.thickness > 0.0 && args.thickness.is_finite(), "--thickness must be > 0 m");
    let radiation = if args.linearized { "linearized" } else { "full" };
    // 15 s at 6 frames per second: the solver steps once per frame.
    let json = format!(
        r#"{{ "object": {{ "kind": "cuboid", "width": 0.1, "height": 0.1, "thickness": {} }},
             "material": {{ "name": "{}" }}, "lamps": [],
             "timing": {{ "duration": 15.0, "time_step": {dt}, "frame_interval": {dt}, "pre_heating_frames": 0 }},
             "solver": {{ "kind": "surface", "radiation": "{radiation}" }} }}"#,
        args.thickness,
        args.material,
        dt = 1.0 / 6.0
    );
    let scene = Scene::from_json_str(&json, std::path::Path::new(".")).context("--material")?;
    let (w, h) = (args.width, args.height);
    let grid = PixelGrid::try_new(&vec![true; w * h], w, h)?;
    let (period, amplitude) = (0.04, 0.005);
    let tau = std::f64::consts::TAU;
    let verts: Vec<[f64; 3]> = grid
        .pixels
        .iter()
        .map(|&p| {
            let (x, y) = ((p % w) as f64 * PITCH, (p / w) as f64 * PITCH);
            [x, y, amplitude * (tau * x / period).cos() * (tau * y / period).cos()]
        })
        .collect();
    let surface = SurfacePhysics {
        physics: physics_from_scene(&scene)?,
        thickness: args.thickness,
        area_mass: AreaMass::Barycentric,
    };
    let r = args.repeat;
    let assembly_s = time(r.min(5), || assemble(&verts, &grid.tris, &surface).unwrap());
    let system = assemble(&verts, &grid.tris, &surface)?;
    let n = system.len();
    let ts = scene.environment.ambient_temperature;
    let t_ref = vec![ts; n];
    let dt = scene.timing.time_step;
    let (tol, its) = (scene.solver.newton_tolerance, scene.solver.max_newton_iterations);
    let setup_s = time(r.min(5), || Stepper::new(&system, dt, tol, its, &t_ref).unwrap());
    // 100 W/m^2 absorbed on a disc of a third of the grid's width: a non-uniform heating.
    let centre = [w as f64 * PITCH / 2.0, h as f64 * PITCH / 2.0];
    let radius = w as f64 * PITCH / 6.0;
    let flux: Vec<f64> = grid
        .tris
        .iter()
        .map(|t| {
            let c = t.iter().fold([0.0; 2], |a, &i| [a[0] + verts[i][0] / 3.0, a[1] + verts[i][1] / 3.0]);
            if (c[0] - centre[0]).hypot(c[1] - centre[1]) < radius {
                100.0
            } else {
                0.0
            }
        })
        .collect();
    let load = face_load(&verts, &grid.tris, &flux);
    let steps = (scene.timing.duration / dt).round() as usize;
    // A whole run: 90 steps of 1/6 s.
    let run_s = {
        let mut stepper = Stepper::new(&system, dt, tol, its, &t_ref)?;
        let (mut history, mut new) = (stepper.history(&t_ref), t_ref.clone());
        let t0 = Instant::now();
        let mut iterations = 0u64;
        for _ in 0..steps {
            history.predict(&mut new);
            iterations += stepper.step(&system, history.latest(), &load, &mut new)?.iterations as u64;
            history.push(&new);
        }
        (t0.elapsed().as_secs_f64(), iterations as f64 / steps as f64, new.iter().map(|t| t - ts).fold(0.0, f64::max))
    };
    // One step and one substitution, timed in the same state (mid-run).
    let mut stepper = Stepper::new(&system, dt, tol, its, &t_ref)?;
    let (mut history, mut new) = (stepper.history(&t_ref), t_ref.clone());
    let mut advance = || {
        history.predict(&mut new);
        stepper.step(&system, history.latest(), &load, &mut new).unwrap();
        history.push(&new);
    };
    for _ in 0..10 {
        advance();
    }
    let step_s = time(r, &mut advance);
    let stepper = Stepper::new(&system, dt, tol, its, &t_ref)?;
    let mut rhs: Vec<f64> = (0..n).map(|i| (i % 7) as f64).collect();
    let substitution_s = time(r, || stepper.substitute(&mut rhs));
    let report = serde_json::json!({
        "grid": format!("{w}x{h}"),
        "vertices": n,
        "triangles": grid.tris.len(),
        "material": args.material,
        "thickness_m": args.thickness,
        "radiation": radiation,
        "time_step_s": dt,
        "threads": std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        "assembly_s": assembly_s,
        "symbolic_plus_numeric_factorisation_s": setup_s,
        "substitution_s": substitution_s,
        "step_s": step_s,
        "step_over_substitution": step_s / substitution_s,
        "run_15s_at_6fps_s": run_s.0,
        "run_iterations_per_step_mean": run_s.1,
        "run_max_rise_k": run_s.2,
        "target": "step_over_substitution <= 2",
    });
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}
