//! The triangle meshes the surface solver runs on, with each lamp's absorbed flux per face:
//! the visible surface of the tetrahedral mesh, or the camera's pixel grid on it.

use crate::mesh::tetmesh::{FaceTag, TetMesh};
use crate::mesh::trimesh::TriMesh;
use crate::scene::Scene;
use crate::simulate::SimulationError;

/// The faces of `mesh` tagged visible, as their own mesh, and each lamp's flux on them
/// (`lamp_flux[l][f]` is lamp l's flux on boundary face f, W/m^2).
pub fn visible_surface(mesh: &TetMesh, lamp_flux: &[Vec<f64>]) -> (TriMesh, Vec<Vec<f64>>) {
    let (surface, _) = mesh.tagged_surface(FaceTag::Visible);
    // tagged_surface keeps the boundary order of the faces it selects.
    let pick = |flux: &Vec<f64>| -> Vec<f64> {
        flux.iter().zip(&mesh.boundary_tag).filter(|(_, &t)| t == FaceTag::Visible).map(|(q, _)| *q).collect()
    };
    (surface, lamp_flux.iter().map(pick).collect())
}

/// One vertex per pixel the camera sees the object at, placed at the pixel centre's point on
/// the boundary of `mesh`, triangulated on the pixel grid; see [`crate::camera::grid`].
pub fn camera_grid_surface(
    scene: &Scene,
    mesh: &TetMesh,
    lamp_flux: &[Vec<f64>],
) -> Result<(TriMesh, Vec<Vec<f64>>), SimulationError> {
    let _ = (scene, mesh, lamp_flux);
    Err(SimulationError::Unsupported("solver.surface_mesh = \"camera_grid\" is not available yet"))
}
