//! Triangle and tetrahedral meshes: types, validation, file I/O.

pub mod error;
pub mod gltf;
pub mod layered;
pub mod obj;
pub mod ply;
pub mod tetmesh;
pub mod trimesh;
pub mod vtu;

pub use self::gltf::read_gltf;
pub use error::MeshError;
pub use obj::{read_obj, write_obj, write_obj_to};
pub use ply::{read_ply, write_ply, write_ply_to};
pub use trimesh::{read_surface, TriMesh};
pub use vtu::{write_pvd, write_vtu, Cells, DataArray};
