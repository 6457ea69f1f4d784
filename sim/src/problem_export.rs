//! Export of the exact discrete problem the volumetric solver solves, for independent peers.
//!
//! [`write_problem`] writes the mesh and every number [`crate::simulate::simulate_volumetric`]
//! uses, so that another code (`bench/peers/skfem_heat.py`, scikit-fem + SciPy) can assemble
//! and step the identical problem and its temperatures can be compared node by node:
//!
//! - `nodes.npy`: float64 `[N, 3]`, node positions (m);
//! - `tets.npy`: int64 `[T, 4]`, tetrahedra (node indices);
//! - `boundary.npy`: int64 `[B, 3]`, boundary faces (node indices);
//! - `boundary_tag.npy`: int32 `[B]`, 1 visible, 2 side, 3 back (TetGen markers);
//! - `lamp_face_flux.npy` (only with point lamps): float64 `[P, B]`, each point lamp's absorbed
//!   flux on each boundary face (W/m^2; absorptivity, incidence and shadows included), as
//!   `simulate_volumetric` computes it; the peer assembles its nodal load itself;
//! - `problem.json`: the [`Problem`] (material, environment, lamps, time schedule, tolerance).
//!
//! The time schedule in [`Problem`] is computed exactly as `simulate_volumetric` computes it:
//! step s (1-based) spans ((s - 1 - zero_step) dt, (s - zero_step) dt]; each lamp contributes its
//! load times the fraction of that interval it is on (`simulate::on_fraction`), and
//! a frame is recorded at s = 0 and after every `steps_per_frame` steps.

use crate::mesh::tetmesh::TetMesh;
use crate::scene::{BackBoundary, LampSpec, MassMatrix, Scene, SceneError};
use crate::simulate::Schedule;
use serde::Serialize;
use std::path::Path;

/// One lamp, on for `on <= t < off` (s; `off` absent: stays on): a uniform lamp's irradiance
/// `flux` (W/m^2, before absorptivity) on the visible faces, or a point lamp's absorbed flux on
/// each boundary face, row `face_flux_row` of `lamp_face_flux.npy`.
#[derive(Clone, Debug, Serialize)]
pub struct ProblemLamp {
    pub flux: Option<f64>,
    pub face_flux_row: Option<usize>,
    pub on: f64,
    pub off: Option<f64>,
}

/// Everything but the mesh (SI units), as written to `problem.json`.
#[derive(Clone, Debug, Serialize)]
pub struct Problem {
    /// Thermal conductivity k (W/(m K)).
    pub k: f64,
    /// Volumetric heat capacity rho c_p (J/(m^3 K)).
    pub rho_c: f64,
    pub emissivity: f64,
    pub absorptivity: f64,
    /// Convection coefficient (W/(m^2 K)).
    pub h: f64,
    /// Ambient (and initial) temperature (K).
    #[serde(rename = "Ts")]
    pub ts: f64,
    /// Stefan-Boltzmann constant used (W m^-2 K^-4).
    pub sigma: f64,
    /// Row-sum lumped heat capacity instead of the consistent one.
    pub lumped: bool,
    /// Radiation linearised about Ts (paper Eq. 5) instead of exact T^4.
    pub linearized_radiation: bool,
    /// Time step (s).
    pub dt: f64,
    /// Number of backward-Euler steps.
    pub steps: usize,
    pub steps_per_frame: usize,
    /// Frames recorded, the initial state included: steps / steps_per_frame + 1.
    pub frames: usize,
    /// Start time (s), the time of frame 0.
    pub t0: f64,
    /// The step that ends at t = 0 (lamps on): step s ends at (s - zero_step) dt, computed
    /// from integers so that t = 0 is exact.
    pub zero_step: i64,
    pub lamps: Vec<ProblemLamp>,
    /// Iterations stop when max |T_{k+1} - T_k| <= tolerance (K).
    pub tolerance: f64,
    pub max_iterations: u32,
    /// "exposed" or "insulated" (back faces, tag 3, adiabatic).
    pub back_boundary: &'static str,
    pub nodes: usize,
    pub tetrahedra: usize,
    pub boundary_faces: usize,
}

/// Errors of [`problem`] and [`write_problem`].
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ExportError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Lamps(#[from] crate::simulate::SimulationError),
    #[error("solver.time_integration: the exported problem is stepped with backward Euler; \"bdf2\" is not supported")]
    Bdf2,
    #[error("writing the problem: {0}")]
    Io(#[from] std::io::Error),
}

/// The numbers of the discrete problem `simulate_volumetric(scene, mesh)` solves.
pub fn problem(scene: &Scene, mesh: &TetMesh) -> Result<Problem, ExportError> {
    if scene.solver.time_integration != crate::scene::TimeIntegration::BackwardEuler {
        return Err(ExportError::Bdf2);
    }
    let material = scene.material.resolve()?;
    let env = &scene.environment;
    let timing = &scene.timing;
    let mut point_lamps = 0;
    let lamps = scene
        .lamps
        .iter()
        .map(|lamp| match lamp {
            LampSpec::Uniform(u) => ProblemLamp { flux: Some(u.flux), face_flux_row: None, on: u.on, off: u.off },
            LampSpec::Point(_) => {
                point_lamps += 1;
                ProblemLamp { flux: None, face_flux_row: Some(point_lamps - 1), on: lamp.on(), off: lamp.off() }
            }
        })
        .collect();
    let schedule = Schedule::new(timing);
    Ok(Problem {
        k: material.conductivity,
        rho_c: material.density * material.specific_heat,
        emissivity: material.emissivity,
        absorptivity: material.absorptivity,
        h: env.convection_coefficient,
        ts: env.ambient_temperature,
        sigma: crate::constants::STEFAN_BOLTZMANN,
        lumped: scene.solver.mass == MassMatrix::Lumped,
        linearized_radiation: scene.solver.radiation == crate::scene::RadiationModel::Linearized,
        dt: timing.time_step,
        steps: schedule.steps,
        steps_per_frame: schedule.per_frame,
        frames: schedule.frames,
        t0: schedule.frame_time(0),
        zero_step: schedule.zero_step as i64,
        lamps,
        tolerance: scene.solver.newton_tolerance,
        max_iterations: scene.solver.max_newton_iterations,
        back_boundary: match env.back_boundary {
            BackBoundary::Exposed => "exposed",
            BackBoundary::Insulated => "insulated",
        },
        nodes: mesh.verts.len(),
        tetrahedra: mesh.tets.len(),
        boundary_faces: mesh.boundary.len(),
    })
}

/// Writes the problem of `simulate_volumetric(scene, mesh)` into `dir` (created if missing;
/// files appear only once all are written). Returns what went into `problem.json`.
pub fn write_problem(dir: &Path, scene: &Scene, mesh: &TetMesh) -> Result<Problem, ExportError> {
    use ndarray::{Array1, Array2};
    use ndarray_npy::WriteNpyExt;
    let p = problem(scene, mesh)?;
    let npy = |e: ndarray_npy::WriteNpyError| std::io::Error::other(e);
    let shape = |e: ndarray::ShapeError| std::io::Error::other(e);
    let mut out = crate::io::OutputDir::new(dir)?;
    let nodes =
        Array2::from_shape_vec((mesh.verts.len(), 3), mesh.verts.iter().flatten().copied().collect()).map_err(shape)?;
    out.write_with("nodes.npy", |w| nodes.write_npy(w).map_err(npy))?;
    let tets = Array2::from_shape_vec((mesh.tets.len(), 4), mesh.tets.iter().flatten().map(|&i| i as i64).collect())
        .map_err(shape)?;
    out.write_with("tets.npy", |w| tets.write_npy(w).map_err(npy))?;
    let faces =
        Array2::from_shape_vec((mesh.boundary.len(), 3), mesh.boundary.iter().flatten().map(|&i| i as i64).collect())
            .map_err(shape)?;
    out.write_with("boundary.npy", |w| faces.write_npy(w).map_err(npy))?;
    let tags = Array1::from_vec(mesh.boundary_tag.iter().map(|t| t.marker()).collect::<Vec<i32>>());
    out.write_with("boundary_tag.npy", |w| tags.write_npy(w).map_err(npy))?;
    let point: Vec<usize> =
        p.lamps.iter().enumerate().filter(|(_, l)| l.face_flux_row.is_some()).map(|(i, _)| i).collect();
    if !point.is_empty() {
        let flux = crate::simulate::boundary_lamp_flux(scene, mesh)?;
        let rows: Vec<f64> = point.iter().flat_map(|&i| flux[i].iter().copied()).collect();
        let rows = Array2::from_shape_vec((point.len(), mesh.boundary.len()), rows).map_err(shape)?;
        out.write_with("lamp_face_flux.npy", |w| rows.write_npy(w).map_err(npy))?;
    }
    let json = serde_json::to_string_pretty(&p).map_err(std::io::Error::other)? + "\n";
    out.write_bytes("problem.json", json.as_bytes())?;
    out.commit()?;
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(solver: &str) -> Scene {
        let json = format!(
            r#"{{ "name": "plate", "object": {{ "kind": "cuboid", "width": 0.02, "height": 0.02, "thickness": 0.005 }},
                 "material": {{ "name": "pla" }}, "lamps": [ {{ "kind": "uniform", "flux": 100.0 }} ],
                 "timing": {{ "duration": 1.0 }}{solver} }}"#
        );
        Scene::from_json_str(&json, Path::new(".")).unwrap()
    }

    /// The peer steps with backward Euler only: a BDF2 scene is refused, naming the field.
    #[test]
    fn a_bdf2_scene_is_refused() {
        let mesh = TetMesh::default();
        assert!(problem(&scene(""), &mesh).is_ok());
        let err = problem(&scene(r#", "solver": { "time_integration": "bdf2" }"#), &mesh).unwrap_err();
        assert!(matches!(err, ExportError::Bdf2), "{err}");
        assert!(err.to_string().starts_with("solver.time_integration"), "{err}");
    }
}
