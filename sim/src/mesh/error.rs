//! [`MeshError`]: everything that can go wrong when reading or validating a surface mesh.
//!
//! The variants keep three kinds of problem apart:
//! - I/O: the file could not be read ([`MeshError::Io`]);
//! - format: the bytes are not a valid OBJ / glTF / GLB file, or use a feature we do not
//!   support ([`MeshError::Parse`]);
//! - geometry and topology: the file parsed, but the triangles do not describe a valid
//!   surface or solid (every other variant).
//!
//! Geometric errors found while loading a file are wrapped in [`MeshError::InFile`] so that
//! the message names the file. Indices in messages are 0-based positions in the loaded
//! [`TriMesh`](super::trimesh::TriMesh) (`verts`, `tris`), not the 1-based indices of an OBJ
//! file.

use std::path::PathBuf;

/// An error reading, building or validating a triangle surface mesh.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MeshError {
    /// The file at `path` (or a file it references, such as a glTF `.bin` buffer) could not be
    /// read.
    #[error("cannot read {}: {source}", .path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// The file is not valid in its format: truncated, bad syntax, not text, or a feature we do
    /// not support. `message` says where (line number, glTF object) and what.
    #[error("{}: {message}", .path.display())]
    Parse { path: PathBuf, message: String },

    /// The mesh has no `what` ("vertices", "triangles").
    #[error("the mesh has no {what}")]
    Empty { what: String },

    /// Coordinate `coord` (0 = x, 1 = y, 2 = z) of vertex `vertex` is NaN or infinite.
    #[error(
        "vertex {vertex} has a non-finite {} coordinate ({value}); every coordinate must be a finite number of metres",
        axis_name(*.coord)
    )]
    NonFinite { vertex: usize, coord: usize, value: f64 },

    /// Triangle `face` references vertex `index`, but only `vertex_count` vertices exist.
    #[error(
        "face {face} references vertex {index} but the mesh has {vertex_count} vertices ({})",
        valid_range(*.vertex_count)
    )]
    IndexOutOfRange { face: usize, index: usize, vertex_count: usize },

    /// Triangle `face` has (nearly) zero area `area` (m^2): it repeats a vertex index or its
    /// corners are (nearly) collinear.
    #[error("face {face} is degenerate: its area is {area:e} m^2 (it repeats a vertex or its corners are collinear)")]
    DegenerateFace { face: usize, area: f64 },

    /// The surface is not closed and manifold: edge `edge` (vertex indices, sorted) is used by
    /// `face_count` triangles instead of exactly two. `boundary_edges` counts all such edges.
    #[error(
        "the surface is not closed: edge ({}, {}) is used by {face_count} face(s), but every edge of a closed surface is shared by exactly 2 faces; {boundary_edges} edge(s) in total are not shared by exactly 2 faces",
        .edge[0], .edge[1]
    )]
    Open { edge: [usize; 2], face_count: usize, boundary_edges: usize },

    /// The two triangles sharing edge `edge` (vertex indices, sorted) traverse it in the same
    /// direction, so one of them has the opposite winding of its neighbour.
    #[error(
        "the faces are not consistently oriented: both faces sharing edge ({}, {}) traverse it in the same direction, so one of them is flipped",
        .edge[0], .edge[1]
    )]
    InconsistentOrientation { edge: [usize; 2] },

    /// The closed surface encloses a negative signed volume (m^3): its normals point inwards.
    #[error(
        "the surface is inside out: its signed volume is {signed_volume:e} m^3, so the faces are wound clockwise seen from outside (normals point inwards); flip the winding of every face"
    )]
    InsideOut { signed_volume: f64 },

    /// Triangles `faces[0]` and `faces[1]` intersect other than along a shared vertex or edge;
    /// `pairs_found` intersecting pairs were found in total.
    #[error(
        "the surface intersects itself: faces {} and {} intersect ({pairs_found} intersecting face pair(s) found in total)",
        .faces[0], .faces[1]
    )]
    SelfIntersecting { faces: [usize; 2], pairs_found: usize },

    /// An error (geometric, or I/O on a file it references) found while loading `path`.
    #[error("{}: {source}", .path.display())]
    InFile {
        path: PathBuf,
        #[source]
        source: Box<MeshError>,
    },
}

impl MeshError {
    /// Wrap `self` with the file it came from (see [`MeshError::InFile`]).
    pub fn in_file(self, path: impl Into<PathBuf>) -> MeshError {
        MeshError::InFile { path: path.into(), source: Box::new(self) }
    }

    /// The innermost error, looking through [`MeshError::InFile`] wrappers.
    pub fn root(&self) -> &MeshError {
        match self {
            MeshError::InFile { source, .. } => source.root(),
            other => other,
        }
    }
}

fn axis_name(coord: usize) -> &'static str {
    match coord {
        0 => "x",
        1 => "y",
        2 => "z",
        _ => "(invalid axis)",
    }
}

fn valid_range(vertex_count: usize) -> String {
    match vertex_count {
        0 => "there are no valid indices".to_string(),
        n => format!("0-based; valid indices are 0 to {}", n - 1),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_name_indices_and_values() {
        let e = MeshError::IndexOutOfRange { face: 12, index: 99, vertex_count: 8 }.in_file("models/x.obj");
        assert_eq!(
            e.to_string(),
            "models/x.obj: face 12 references vertex 99 but the mesh has 8 vertices \
             (0-based; valid indices are 0 to 7)"
        );
        assert!(matches!(e.root(), MeshError::IndexOutOfRange { face: 12, .. }));

        let e = MeshError::NonFinite { vertex: 3, coord: 1, value: f64::NAN };
        assert!(e.to_string().contains("vertex 3 has a non-finite y coordinate (NaN)"));

        let e = MeshError::Open { edge: [2, 5], face_count: 1, boundary_edges: 4 };
        let s = e.to_string();
        assert!(s.contains("edge (2, 5) is used by 1 face(s)"), "{s}");
        assert!(s.contains("4 edge(s) in total"), "{s}");
    }

    #[test]
    fn io_error_keeps_its_source() {
        use std::error::Error as _;
        let e =
            MeshError::Io { path: "a/b.obj".into(), source: std::io::Error::new(std::io::ErrorKind::NotFound, "gone") };
        assert_eq!(e.to_string(), "cannot read a/b.obj: gone");
        assert!(e.source().is_some());
    }
}
