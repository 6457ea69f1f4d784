//! Running the volumetric solver from a scene: boundary exposure, lamp loads, the frame
//! schedule and the energy balance.
//!
//! Time: lamps switch on at t = 0 (their `on`/`off` times are relative to it); the simulation
//! starts `timing.pre_heating_frames` frame intervals earlier at the ambient temperature, so
//! the first frames show the object before heating, as the paper's captures do. Frames are
//! taken every `timing.frame_interval` until `timing.duration`, each after a whole number of
//! backward-Euler steps of `timing.time_step`. A lamp's load over a step is its full load
//! times the fraction of the step it is on ([`on_fraction`]).

use crate::fem::element::tri_area;
use crate::fem::volumetric::{HeatSystem, LinearSolver, Physics, SolverError, Stepper, TimeIntegrator};
use crate::lamp::{absorbed_face_flux, check_lamps, LampError, Occluder};
use crate::mesh::tetmesh::{FaceTag, TetMesh};
use crate::mesh::trimesh::TriMesh;
use crate::scene::{
    AreaMassKind, BackBoundary, LampSpec, LinearSolverKind, MassMatrix, RadiationModel, Scene, SceneError, SolverKind,
    SurfaceFlux, SurfaceMesh, TimeIntegration, Timing,
};
use crate::surface::effective_thickness;
pub use crate::surface::mesh::CameraGridVertices;
use crate::surface::mesh::{camera_grid_surface, visible_surface};
use crate::surface::operators::{lumped_area, AreaMass};
use crate::surface::system::{assemble as surface_system, SurfacePhysics};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Errors of a simulation run.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SimulationError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Solver(#[from] SolverError),
    #[error(transparent)]
    Lamp(#[from] LampError),
    #[error("solver.surface_mesh = \"camera_grid\": {0}")]
    CameraGrid(String),
    /// The solver's error in the message, not as its source, so that a printed chain names it
    /// once.
    #[error("time step {step} (t = {time} s): {error}")]
    Step { step: usize, time: f64, error: SolverError },
}

/// Heat bookkeeping over the whole run (J), integrated with the backward-Euler rule.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EnergyBalance {
    /// Heat stored, 1^T M (T_end - T_start), in J.
    pub stored_j: f64,
    /// Heat absorbed from the lamps, sum over steps of dt 1^T F, in J.
    pub absorbed_j: f64,
    /// Heat convected away, sum over steps of dt 1^T H (T - T_s), in J.
    pub convected_j: f64,
    /// Heat radiated away, sum over steps of dt sum_i eps sigma a_i (T_i^4 - T_s^4), in J.
    pub radiated_j: f64,
    /// |stored - (absorbed - convected - radiated)| / max(|absorbed|, |stored|),
    /// dimensionless.
    pub relative_mismatch: f64,
}

/// Timings, iterations and energy of a run; `meta.json`'s `simulation` (see
/// `crate::dataset_format`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SimulationReport {
    /// The solver that ran.
    pub solver: SolverKind,
    /// Unknowns: tetrahedral mesh nodes (volumetric) or surface vertices (surface).
    pub nodes: usize,
    /// Tetrahedra of the mesh solved on; 0 for the surface solver.
    pub tetrahedra: usize,
    /// Nonzeros of the lower triangle of the system matrix.
    pub matrix_nonzeros_lower: usize,
    /// Time step, in s.
    pub time_step_s: f64,
    /// Time steps taken.
    pub steps: usize,
    /// Frames recorded.
    pub frames: usize,
    /// Newton's stopping tolerance on the temperature update, in K.
    pub newton_tolerance_k: f64,
    /// Newton iterations over all steps.
    pub newton_iterations_total: u64,
    /// Most Newton iterations in one step.
    pub newton_iterations_max: u32,
    /// Newton iterations per step, on average.
    pub newton_iterations_mean: f64,
    /// Numeric factorisations of the system matrix.
    pub factorisations: usize,
    /// Conjugate-gradient iterations over all solves (`solver.linear_solver:
    /// "conjugate_gradients"`); absent with the direct solver.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cg_iterations_total: Option<u64>,
    /// Time to assemble the system, in s.
    pub assembly_seconds: f64,
    /// Time spent factorising, in s.
    pub factorisation_seconds: f64,
    /// Time spent stepping (solves and Newton), in s.
    pub stepping_seconds: f64,
    /// Heat bookkeeping over the run.
    pub energy: EnergyBalance,
    /// Largest temperature rise above ambient over all nodes and frames, in K.
    pub max_temperature_rise_k: f64,
    /// Surface solver: the layer thickness d of Eq. 6 (m), effective or the object's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub layer_thickness_m: Option<f64>,
}

/// Point lamps closer than this to the object's surface are refused (m).
pub const MIN_LAMP_DISTANCE: f64 = 1e-3;

/// Node temperatures at every frame and the visible surface the camera will render.
pub struct Simulation {
    /// Absorbed flux (W/m^2) on each boundary face with every lamp on (`mesh.boundary` order).
    pub face_flux: Vec<f64>,
    /// Frame times (s); lamps switch on at 0.
    pub times: Vec<f64>,
    /// #frames x #nodes temperatures (K), row-major.
    pub node_temperatures: Vec<f64>,
    pub nodes: usize,
    /// The visible surface (faces tagged visible) and the node of each of its vertices.
    pub visible: TriMesh,
    pub visible_nodes: Vec<usize>,
    /// Surface solver on the camera grid: the pixel of each vertex.
    pub camera_grid: Option<CameraGridVertices>,
    pub report: SimulationReport,
}

impl Simulation {
    /// Temperatures (K) of frame `k`.
    pub fn frame(&self, k: usize) -> &[f64] {
        &self.node_temperatures[k * self.nodes..(k + 1) * self.nodes]
    }

    /// #frames x #visible-vertices temperatures (K) of the visible surface, row-major.
    pub fn visible_temperatures(&self) -> Vec<f64> {
        (0..self.times.len()).flat_map(|k| self.visible_nodes.iter().map(move |&n| self.frame(k)[n])).collect()
    }
}

/// The time grid of a run: `frames` frames (the initial state included), `per_frame`
/// backward-Euler steps between frames, `steps` steps in all. Times come from integer counts
/// so that t = 0 (lamps on) is exact: step s (1-based) ends at (s - zero_step) dt and frame k
/// is at (k - pre_heating_frames) frame_interval.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Schedule {
    pub dt: f64,
    pub frame_interval: f64,
    pub pre_heating_frames: usize,
    pub per_frame: usize,
    pub frames: usize,
    pub steps: usize,
    /// The step that ends at t = 0.
    pub zero_step: usize,
}

impl Schedule {
    /// The schedule of a scene's timing.
    pub fn new(timing: &Timing) -> Schedule {
        let per_frame = timing.steps_per_frame() as usize;
        let heating_frames = (timing.duration / timing.frame_interval).round() as usize;
        let pre = timing.pre_heating_frames as usize;
        let frames = pre + heating_frames + 1;
        Schedule {
            dt: timing.time_step,
            frame_interval: timing.frame_interval,
            pre_heating_frames: pre,
            per_frame,
            frames,
            steps: (frames - 1) * per_frame,
            zero_step: pre * per_frame,
        }
    }

    /// The time (s) at the end of step `s` (1-based).
    pub fn step_time(&self, s: usize) -> f64 {
        (s as i64 - self.zero_step as i64) as f64 * self.dt
    }

    /// The time (s) of frame `k`.
    pub fn frame_time(&self, k: usize) -> f64 {
        (k as i64 - self.pre_heating_frames as i64) as f64 * self.frame_interval
    }
}

/// The fraction of the step (t0, t1] during which a lamp on over [on, off) shines: its load
/// over the step is this fraction of its full load, so switching times need not fall on the
/// step grid and the step before t = on stays dark.
pub fn on_fraction(on: f64, off: Option<f64>, t0: f64, t1: f64) -> f64 {
    let end = off.map_or(t1, |off| off.min(t1));
    ((end - on.max(t0)) / (t1 - t0)).clamp(0.0, 1.0)
}

/// The material, environment and solver choices of a scene as solver [`Physics`].
pub fn physics_from_scene(scene: &Scene) -> Result<Physics, SceneError> {
    let material = scene.material.resolve()?;
    let env = &scene.environment;
    Ok(Physics {
        conductivity: material.conductivity,
        volumetric_heat_capacity: material.density * material.specific_heat,
        emissivity: material.emissivity,
        convection_coefficient: env.convection_coefficient,
        ambient_temperature: env.ambient_temperature,
        lumped_mass: scene.solver.mass == MassMatrix::Lumped,
        linearized_radiation: scene.solver.radiation == RadiationModel::Linearized,
    })
}

/// Which boundary faces exchange heat with the surroundings.
pub fn exposed_faces(mesh: &TetMesh, back: BackBoundary) -> Vec<bool> {
    mesh.boundary_tag.iter().map(|&t| t != FaceTag::Back || back == BackBoundary::Exposed).collect()
}

/// Nodal load (W) of an absorbed flux constant on each boundary face: `face_flux[f]`
/// (W/m^2) on `mesh.boundary[f]`; F_i = sum over faces at i of q_f A_f / 3.
pub fn face_flux_load(mesh: &TetMesh, face_flux: &[f64]) -> Vec<f64> {
    face_load(&mesh.verts, &mesh.boundary, face_flux)
}

/// Nodal load (W) over `verts` of a flux `face_flux[f]` (W/m^2) constant on each of `faces`:
/// F_i = sum over faces at i of q_f A_f / 3.
pub fn face_load(verts: &[[f64; 3]], faces: &[[usize; 3]], face_flux: &[f64]) -> Vec<f64> {
    let mut load = vec![0.0; verts.len()];
    for (face, &q) in faces.iter().zip(face_flux) {
        if q != 0.0 {
            let share = q * tri_area(&face.map(|i| verts[i])) / 3.0;
            for &n in face {
                load[n] += share;
            }
        }
    }
    load
}

/// Nodal load (W) of a flux `q` (W/m^2) absorbed uniformly on the faces tagged `tag`.
pub fn uniform_load(mesh: &TetMesh, tag: FaceTag, q: f64) -> Vec<f64> {
    let flux: Vec<f64> = mesh.boundary_tag.iter().map(|&t| if t == tag { q } else { 0.0 }).collect();
    face_flux_load(mesh, &flux)
}

/// Runs the volumetric solver on `mesh` for the scene's material, environment, lamps and
/// timing. `progress(done, total)` is called after every step. It lights the object with
/// `scene.lamps`; for a scene with `lamp_configurations`, run it once per entry of
/// [`Scene::lamp_sets`] (as `simbench simulate` does).
pub fn simulate_volumetric(
    scene: &Scene,
    mesh: &TetMesh,
    progress: impl FnMut(usize, usize) + Send,
) -> Result<Simulation, SimulationError> {
    let env = &scene.environment;
    let physics = physics_from_scene(scene)?;
    // Absorbed flux of every lamp on every boundary face (shadows computed once per run),
    // and the nodal load it makes; lamps switch on and off over time.
    let lamp_flux = boundary_lamp_flux(scene, mesh)?;
    let face_flux = total_flux(mesh.boundary.len(), &lamp_flux);
    let lamps: Vec<(&LampSpec, Vec<f64>)> =
        scene.lamps.iter().zip(&lamp_flux).map(|(lamp, flux)| (lamp, face_flux_load(mesh, flux))).collect();
    let t_assembly = Instant::now();
    let system = HeatSystem::assemble(mesh, physics, &exposed_faces(mesh, env.back_boundary))?;
    let assembly_seconds = t_assembly.elapsed().as_secs_f64();
    let run = integrate(scene, &system, &lamps, progress)?;
    let (visible, visible_nodes) = mesh.tagged_surface(FaceTag::Visible);
    let report = run.report(scene, &system, SolverKind::Volumetric, mesh.tets.len(), assembly_seconds, None);
    Ok(Simulation {
        face_flux,
        times: run.times,
        node_temperatures: run.temperatures,
        nodes: system.len(),
        visible,
        visible_nodes,
        camera_grid: None,
        report,
    })
}

/// Runs the paper's surface model (Eq. 6, [`crate::surface::system`]) for the scene's
/// material, environment, lamps and timing, on the surface `scene.solver.surface_mesh`
/// names: the visible surface of `mesh` (the volumetric solver's own vertices) or the camera's
/// pixel grid on it. The layer thickness is [`surface_layer_thickness`]. Lamps are shadowed by
/// the whole object (`mesh`'s boundary), as for the volumetric solver. The returned
/// simulation's nodes are the surface's vertices: `sim.frame(k)` indexes `sim.visible.verts`
/// and `sim.face_flux` indexes `sim.visible.tris`. On the visible surface the lamps' flux is
/// applied per face; on the camera grid, where it is known per vertex, as triangle means of
/// the corners' or per vertex as Eq. 6 (`solver.surface_flux`; `sim.face_flux` holds the
/// triangles' corner means either way).
pub fn simulate_surface(
    scene: &Scene,
    mesh: &TetMesh,
    progress: impl FnMut(usize, usize) + Send,
) -> Result<Simulation, SimulationError> {
    let thickness = surface_layer_thickness(scene)?;
    let lamp_flux = boundary_lamp_flux(scene, mesh)?;
    let area_mass = match scene.solver.surface_area_mass {
        AreaMassKind::Barycentric => AreaMass::Barycentric,
        AreaMassKind::MixedVoronoi => AreaMass::MixedVoronoi,
    };
    // Each lamp's nodal load (W) and the flux per face with every lamp on (W/m^2, for output).
    let (surface, loads, face_flux, camera_grid) = match scene.solver.surface_mesh {
        SurfaceMesh::Visible => {
            let (surface, flux) = visible_surface(mesh, &lamp_flux);
            let loads: Vec<Vec<f64>> = flux.iter().map(|q| face_load(&surface.verts, &surface.tris, q)).collect();
            let face_flux = total_flux(surface.tris.len(), &flux);
            (surface, loads, face_flux, None)
        }
        SurfaceMesh::CameraGrid => {
            let (surface, flux, grid) =
                camera_grid_surface(scene, mesh, &lamp_flux).map_err(|e| SimulationError::CameraGrid(e.0))?;
            let corner_mean =
                |q: &[f64]| -> Vec<f64> { surface.tris.iter().map(|t| (q[t[0]] + q[t[1]] + q[t[2]]) / 3.0).collect() };
            let loads = match scene.solver.surface_flux {
                SurfaceFlux::TriangleMean => {
                    flux.iter().map(|q| face_load(&surface.verts, &surface.tris, &corner_mean(q))).collect()
                }
                // Eq. 6's load: each vertex's flux times its area (the system's lumped M_a), so
                // M_a^-1 F is exactly the flux of the face the vertex's pixel sees (`gt_flux`).
                SurfaceFlux::Vertex => {
                    let area = lumped_area(&surface.verts, &surface.tris, area_mass);
                    flux.iter().map(|q| q.iter().zip(&area).map(|(q, a)| q * a).collect()).collect()
                }
            };
            let face_flux = corner_mean(&grid.vertex_flux);
            (surface, loads, face_flux, Some(grid))
        }
    };
    let lamps: Vec<(&LampSpec, Vec<f64>)> = scene.lamps.iter().zip(loads).collect();
    let surface_physics = SurfacePhysics { physics: physics_from_scene(scene)?, thickness, area_mass };
    let t_assembly = Instant::now();
    let system = surface_system(&surface.verts, &surface.tris, &surface_physics)?;
    let assembly_seconds = t_assembly.elapsed().as_secs_f64();
    let run = integrate(scene, &system, &lamps, progress)?;
    let report = run.report(scene, &system, SolverKind::Surface, 0, assembly_seconds, Some(thickness));
    let n = system.len();
    Ok(Simulation {
        face_flux,
        times: run.times,
        node_temperatures: run.temperatures,
        nodes: n,
        visible: surface,
        visible_nodes: (0..n).collect(),
        camera_grid,
        report,
    })
}

/// The layer thickness d (m) of the surface model for a scene: the object's thickness, or
/// with `solver.effective_thickness_factor` = c the effective thickness
/// [`effective_thickness`]`(d, alpha, timing.duration, c)`.
///
/// # Errors
/// [`SceneError::Invalid`] at `object.thickness` when the object has none (a closed mesh).
pub fn surface_layer_thickness(scene: &Scene) -> Result<f64, SceneError> {
    let d = scene.object.thickness().ok_or_else(|| {
        SceneError::invalid(
            "object.thickness",
            "the surface solver needs the object's thickness (a relief, cuboid or hemisphere; \
             a closed mesh has none)",
        )
    })?;
    let material = scene.material.resolve()?;
    Ok(match scene.solver.effective_thickness_factor {
        Some(c) => effective_thickness(d, material.diffusivity(), scene.timing.duration, c),
        None => d,
    })
}

/// Absorbed flux (W/m^2) of each lamp of the scene on each boundary face of `mesh`, shadows
/// by the whole boundary.
pub(crate) fn boundary_lamp_flux(scene: &Scene, mesh: &TetMesh) -> Result<Vec<Vec<f64>>, SimulationError> {
    let material = scene.material.resolve()?;
    let occluder = Occluder::new(&mesh.verts, &mesh.boundary)?;
    check_lamps(&scene.lamps, &occluder, MIN_LAMP_DISTANCE)?;
    Ok(scene
        .lamps
        .iter()
        .map(|lamp| {
            absorbed_face_flux(lamp, material.absorptivity, &mesh.verts, &mesh.boundary, &mesh.boundary_tag, &occluder)
        })
        .collect())
}

/// The sum over lamps of per-face fluxes: the flux with every lamp on.
fn total_flux(faces: usize, lamp_flux: &[Vec<f64>]) -> Vec<f64> {
    let mut total = vec![0.0; faces];
    for flux in lamp_flux {
        total.iter_mut().zip(flux).for_each(|(a, b)| *a += b);
    }
    total
}

/// Temperatures of a run of a [`HeatSystem`] and its statistics.
struct Integration {
    times: Vec<f64>,
    /// #frames x #nodes (K).
    temperatures: Vec<f64>,
    energy: EnergyBalance,
    iterations_total: u64,
    iterations_max: u32,
    factorisations: usize,
    cg_iterations_total: Option<u64>,
    factorisation_seconds: f64,
    stepping_seconds: f64,
}

impl Integration {
    fn report(
        &self,
        scene: &Scene,
        system: &HeatSystem,
        solver: SolverKind,
        tetrahedra: usize,
        assembly_seconds: f64,
        layer_thickness_m: Option<f64>,
    ) -> SimulationReport {
        let schedule = Schedule::new(&scene.timing);
        let ambient = scene.environment.ambient_temperature;
        SimulationReport {
            solver,
            nodes: system.len(),
            tetrahedra,
            matrix_nonzeros_lower: system.pattern.nnz(),
            time_step_s: schedule.dt,
            steps: schedule.steps,
            frames: schedule.frames,
            newton_tolerance_k: scene.solver.newton_tolerance,
            newton_iterations_total: self.iterations_total,
            newton_iterations_max: self.iterations_max,
            newton_iterations_mean: self.iterations_total as f64 / schedule.steps.max(1) as f64,
            factorisations: self.factorisations,
            cg_iterations_total: self.cg_iterations_total,
            assembly_seconds,
            factorisation_seconds: self.factorisation_seconds,
            stepping_seconds: self.stepping_seconds,
            energy: self.energy.clone(),
            max_temperature_rise_k: self.temperatures.iter().map(|t| t - ambient).fold(0.0, f64::max),
            layer_thickness_m,
        }
    }
}

/// Backward Euler (or BDF2, `solver.time_integration`) over the scene's schedule from the
/// ambient temperature, with each lamp's nodal load (W) weighted by the fraction of each step
/// it is on; frames recorded on the schedule; the energy balance integrated with the same rule
/// (BDF2's storage terms beyond M (T^{n+1} - T^n) included, `fem::volumetric` module doc); with
/// BDF2 the stepper restarts with a backward-Euler step wherever a lamp's on-fraction changes.
fn integrate(
    scene: &Scene,
    system: &HeatSystem,
    lamps: &[(&LampSpec, Vec<f64>)],
    mut progress: impl FnMut(usize, usize) + Send,
) -> Result<Integration, SimulationError> {
    let n = system.len();
    let dt = scene.timing.time_step;
    let schedule = Schedule::new(&scene.timing);
    let Schedule { per_frame, frames, steps, .. } = schedule;

    let initial = vec![scene.environment.ambient_temperature; n];
    let t_fact = Instant::now();
    let integrator = match scene.solver.time_integration {
        TimeIntegration::BackwardEuler => TimeIntegrator::BackwardEuler,
        TimeIntegration::Bdf2 => TimeIntegrator::Bdf2,
    };
    let linear = match scene.solver.linear_solver {
        LinearSolverKind::Direct => LinearSolver::Direct,
        LinearSolverKind::ConjugateGradients => LinearSolver::ConjugateGradients,
    };
    let mut stepper = Stepper::with_solver(
        system,
        dt,
        integrator,
        linear,
        scene.solver.newton_tolerance,
        scene.solver.max_newton_iterations,
        &initial,
    )?;
    let factorisation_seconds = t_fact.elapsed().as_secs_f64();

    let mut times = Vec::with_capacity(frames);
    let mut out = Vec::with_capacity(frames * n);
    times.push(schedule.frame_time(0));
    out.extend_from_slice(&initial);
    let mut history = stepper.history(&initial);
    let mut new = initial.clone();
    let mut load = vec![0.0; n];
    let mut energy = EnergyBalance::default();
    // BDF2's storage terms beyond M (T^{n+1} - T^n), summed (J; fem::volumetric module doc).
    let mut bdf2_storage = 0.0;
    let mut fractions: Vec<f64> = Vec::new();
    let mut absorbed = 0.0;
    let (mut iterations_total, mut iterations_max) = (0u64, 0u32);
    let t_step = Instant::now();
    // The steps on one of rayon's workers, so that their parallel passes start without a
    // hand-over from this thread (`fem::pcg::Csr::solve`).
    rayon::scope(|_| -> Result<(), SimulationError> {
        for s in 1..=steps {
            let time = schedule.step_time(s);
            let now: Vec<f64> =
                lamps.iter().map(|(lamp, _)| on_fraction(lamp.on(), lamp.off(), time - dt, time)).collect();
            if now != fractions {
                load.iter_mut().for_each(|v| *v = 0.0);
                for ((_, l), &w) in lamps.iter().zip(&now) {
                    if w > 0.0 {
                        load.iter_mut().zip(l).for_each(|(a, b)| *a += w * b);
                    }
                }
                absorbed = load.iter().sum::<f64>();
                // The load jumps (a lamp switches): BDF2 restarts with a backward-Euler step.
                stepper.reset_history();
                fractions = now;
            }
            history.predict(&mut new);
            let info = stepper
                .step(system, history.latest(), &load, &mut new)
                .map_err(|error| SimulationError::Step { step: s, time, error })?;
            if info.bdf2 {
                // M (3/2 T^{n+1} - 2 T^n + 1/2 T^{n-1}) = M (T^{n+1} - T^n) + 1/2 M (change - previous change).
                let (old, older) = (history.latest(), history.previous());
                bdf2_storage += 0.5 * (system.heat_content(&new, old) - system.heat_content(old, older));
            }
            iterations_total += info.iterations as u64;
            iterations_max = iterations_max.max(info.iterations);
            energy.absorbed_j += dt * absorbed;
            energy.convected_j += dt * system.convected_power(&new);
            energy.radiated_j += dt * system.radiated_power(&new);
            history.push(&new);
            if s % per_frame == 0 {
                times.push(schedule.frame_time(s / per_frame));
                out.extend_from_slice(&new);
            }
            progress(s, steps);
        }
        Ok(())
    })?;
    let stepping_seconds = t_step.elapsed().as_secs_f64();
    energy.stored_j = system.heat_content(history.latest(), &initial);
    let balance = energy.absorbed_j - energy.convected_j - energy.radiated_j;
    let scale = energy.absorbed_j.abs().max(energy.stored_j.abs()).max(f64::MIN_POSITIVE);
    energy.relative_mismatch = (energy.stored_j + bdf2_storage - balance).abs() / scale;
    Ok(Integration {
        times,
        temperatures: out,
        energy,
        iterations_total,
        iterations_max,
        factorisations: stepper.factorisations,
        cg_iterations_total: (linear == LinearSolver::ConjugateGradients).then_some(stepper.cg_iterations),
        factorisation_seconds,
        stepping_seconds,
    })
}
