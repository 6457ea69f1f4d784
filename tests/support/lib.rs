//! Shared helpers for the workspace end-to-end tests in `tests/`.

use std::path::{Path, PathBuf};

/// The repository root.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_path_buf()
}

/// A scene shipped in `scenes/`.
pub fn scene(name: &str) -> heatsim::scene::Scene {
    let path = root().join("scenes").join(name);
    heatsim::scene::Scene::from_file(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The Stanford bunny. Tests that need it fail (never skip) when it cannot be had; the
/// message says how to provide it.
pub fn bunny() -> PathBuf {
    heatsim::assets::bunny_path(None).unwrap_or_else(|e| panic!("the bunny asset is required by this test: {e}"))
}

/// Checks a tetrahedral mesh the way a user should before trusting it: every tetrahedron
/// positively oriented, the boundary closed and consistently outward, and the volume enclosed
/// by the boundary equal to the sum of the tetrahedra. Returns the mesh volume (m^3).
pub fn check_tet_mesh(mesh: &heatsim::mesh::tetmesh::TetMesh) -> f64 {
    use heatsim::mesh::tetmesh::tet_signed_volume;
    assert!(!mesh.tets.is_empty(), "empty mesh");
    for (t, tet) in mesh.tets.iter().enumerate() {
        let v = tet_signed_volume(tet.map(|i| mesh.verts[i]));
        assert!(v > 0.0, "tetrahedron {t} has volume {v:e}");
    }
    let surface = mesh.boundary_surface();
    surface.check_closed_oriented().expect("boundary is closed and consistently oriented");
    let enclosed = surface.signed_volume();
    let volume = mesh.volume();
    assert!(enclosed > 0.0, "boundary is inside out (enclosed volume {enclosed:e})");
    assert!(
        (enclosed - volume).abs() <= 1e-9 * volume,
        "boundary encloses {enclosed:e} m^3 but the tetrahedra sum to {volume:e}"
    );
    volume
}
