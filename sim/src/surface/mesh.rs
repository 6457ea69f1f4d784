//! The triangle meshes the surface solver runs on, with each lamp's absorbed flux: per face on
//! the visible surface of the tetrahedral mesh, per vertex on the camera's pixel grid.

use crate::camera::grid::PixelGrid;
use crate::camera::{rasterize, Camera};
use crate::mesh::tetmesh::{FaceTag, TetMesh};
use crate::mesh::trimesh::TriMesh;
use crate::scene::Scene;

/// The pixels a camera-grid surface's vertices sit at, and what they absorb.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraGridVertices {
    /// Pixel index v * W + u of each vertex.
    pub pixels: Vec<usize>,
    /// Absorbed flux with every lamp on at each vertex (W/m^2).
    pub vertex_flux: Vec<f64>,
}

/// Why the camera-grid surface cannot be built (the scene's `solver.surface_mesh =
/// "camera_grid"`).
#[derive(Debug, thiserror::Error)]
#[error("solver.surface_mesh = \"camera_grid\": {0}")]
pub struct CameraGridError(pub String);

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

/// The camera's pixel grid on the object: one vertex per pixel whose centre sees the boundary
/// of `mesh`, at the point it sees (back-projected at the rendered depth), triangulated by
/// [`PixelGrid`] (the reconstruction's mesh), and each lamp's flux at each vertex
/// (`lamp_flux[l][i]`, W/m^2): that of the boundary face the vertex's pixel sees. Triangles of
/// the grid that
/// bridge a depth discontinuity (one part of the object in front of another) are kept: the
/// reconstruction's mesh has them too.
///
/// # Errors
/// [`CameraGridError`] when the camera spec is invalid or the camera sees no 2 x 2 block of
/// pixels on the object.
pub fn camera_grid_surface(
    scene: &Scene,
    mesh: &TetMesh,
    lamp_flux: &[Vec<f64>],
) -> Result<(TriMesh, Vec<Vec<f64>>, CameraGridVertices), CameraGridError> {
    let camera = Camera::from_spec(&scene.camera).map_err(|e| CameraGridError(e.to_string()))?;
    let render = rasterize(&camera, &mesh.verts, &mesh.boundary);
    let (w, h) = (camera.width as usize, camera.height as usize);
    let grid = PixelGrid::try_new(&render.mask(), w, h).map_err(|e| CameraGridError(e.to_string()))?;
    if grid.tris.is_empty() {
        return Err(CameraGridError(
            "the camera sees no 2 x 2 block of pixels on the object; move camera.look_at onto it".into(),
        ));
    }
    let verts: Vec<[f64; 3]> =
        grid.pixels.iter().map(|&p| camera.unproject((p % w) as f64, (p / w) as f64, render.z[p])).collect();
    let face_seen: Vec<usize> = grid.pixels.iter().map(|&p| render.face[p] as usize).collect();
    let mut per_lamp = Vec::with_capacity(lamp_flux.len());
    let mut vertex_flux = vec![0.0; verts.len()];
    for flux in lamp_flux {
        let at_vertex: Vec<f64> = face_seen.iter().map(|&f| flux[f]).collect();
        vertex_flux.iter_mut().zip(&at_vertex).for_each(|(a, b)| *a += b);
        per_lamp.push(at_vertex);
    }
    let surface = TriMesh { verts, tris: grid.tris };
    Ok((surface, per_lamp, CameraGridVertices { pixels: grid.pixels, vertex_flux }))
}
