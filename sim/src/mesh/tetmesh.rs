//! Linear tetrahedral meshes: positively oriented tetrahedra, tagged outward boundary faces,
//! and the statistics a user checks before trusting a simulation.

use crate::mesh::trimesh::TriMesh;
use crate::tetgen::{MeshingError, TetgenOutput};
use crate::vec3::{cross, dot, norm, sub};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// What a boundary face (or PLC facet) is, as seen by the camera and the boundary conditions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FaceTag {
    /// The surface the camera sees and the lamps heat (faces +z, towards the camera).
    Visible,
    /// Side walls of an extruded object.
    Side,
    /// The far side, away from the camera (bottom of an extrusion, inside of a shell, base).
    Back,
    /// An internal facet separating mesh-grading layers (never on the boundary).
    Interface,
    /// The inner face of a closed hollow shell, facing its enclosed cavity.
    Cavity,
}

impl FaceTag {
    /// All tags, in marker order.
    pub const ALL: [FaceTag; 5] = [FaceTag::Visible, FaceTag::Side, FaceTag::Back, FaceTag::Interface, FaceTag::Cavity];

    /// The TetGen facet marker (non-zero; 0 means "no marker" to TetGen).
    pub fn marker(self) -> i32 {
        match self {
            FaceTag::Visible => 1,
            FaceTag::Side => 2,
            FaceTag::Back => 3,
            FaceTag::Interface => 4,
            FaceTag::Cavity => 5,
        }
    }

    /// Inverse of [`FaceTag::marker`].
    pub fn from_marker(m: i32) -> Option<FaceTag> {
        FaceTag::ALL.into_iter().find(|t| t.marker() == m)
    }
}

/// A P1 tetrahedral mesh.
///
/// - `verts`: #V x 3 node coordinates (m);
/// - `tets`: #T x 4 node indices, every tetrahedron positively oriented:
///   det[v1 - v0, v2 - v0, v3 - v0] > 0;
/// - `tet_region`: #T grading-layer attribute (1 = finest layer under the visible surface);
/// - `boundary`: #B x 3 boundary faces, counter-clockwise seen from outside (outward normal);
/// - `boundary_tag`: #B tags.
#[derive(Clone, Debug, Default)]
pub struct TetMesh {
    pub verts: Vec<[f64; 3]>,
    pub tets: Vec<[usize; 4]>,
    pub tet_region: Vec<i32>,
    pub boundary: Vec<[usize; 3]>,
    pub boundary_tag: Vec<FaceTag>,
}

/// Mesh statistics (SI units); part of `meta.json`'s `mesh` (see `crate::dataset_format`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct MeshStats {
    /// Nodes (#V).
    pub nodes: usize,
    /// Tetrahedra (#T).
    pub tetrahedra: usize,
    /// Boundary faces (#B), all tags.
    pub boundary_faces: usize,
    /// Boundary faces tagged visible (facing the camera).
    pub visible_faces: usize,
    /// Boundary faces tagged side.
    pub side_faces: usize,
    /// Boundary faces tagged back.
    pub back_faces: usize,
    /// Boundary faces tagged cavity (the inside of a closed shell); absent when 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub cavity_faces: usize,
    /// Smallest dihedral angle over all tetrahedra, in degrees.
    pub min_dihedral_deg: f64,
    /// Largest dihedral angle over all tetrahedra, in degrees.
    pub max_dihedral_deg: f64,
    /// Largest radius-edge ratio (circumradius over shortest edge; 0.612 for a regular
    /// tetrahedron), dimensionless.
    pub max_radius_edge_ratio: f64,
    /// Shortest edge, in m.
    pub min_edge_m: f64,
    /// Longest edge, in m.
    pub max_edge_m: f64,
    /// Sum of tetrahedron volumes (m^3).
    pub volume_m3: f64,
    /// Volume enclosed by the boundary surface (divergence theorem, m^3); equals `volume_m3`
    /// for a conforming mesh.
    pub boundary_volume_m3: f64,
    /// Area of the visible surface (m^2).
    pub visible_area_m2: f64,
    /// Tetrahedra per grading layer (index 0 = layer 1, the finest).
    pub tets_per_layer: Vec<usize>,
}

impl TetMesh {
    /// Builds a mesh from TetGen's output: orients every tetrahedron positively, extracts the
    /// boundary (faces of exactly one tetrahedron) with outward orientation and the facet
    /// marker of each face. Deterministic: no hash-map order reaches the result.
    ///
    /// # Errors
    /// [`MeshingError::DegenerateTet`] if a tetrahedron has a volume below 1e-12 of the
    /// cube of its longest edge.
    pub fn from_tetgen(out: TetgenOutput) -> Result<TetMesh, MeshingError> {
        let TetgenOutput { points: verts, mut tets, tet_region, marked_faces } = out;
        for (t, tet) in tets.iter_mut().enumerate() {
            let p = tet.map(|i| verts[i]);
            let v = tet_signed_volume(p);
            let h = max_edge(p);
            if v.abs() <= 1e-12 * h * h * h {
                return Err(MeshingError::DegenerateTet { tet: t, nodes: *tet, volume: v });
            }
            if v < 0.0 {
                tet.swap(2, 3);
            }
        }
        // Every face of every tet, keyed by its sorted nodes.
        let mut faces: Vec<([usize; 3], u32)> = Vec::with_capacity(tets.len() * 4);
        for (t, tet) in tets.iter().enumerate() {
            for local in 0..4 {
                let f = face_opposite(tet, local);
                faces.push((sorted3(f), (t * 4 + local) as u32));
            }
        }
        faces.sort_unstable();
        let mut markers: Vec<([usize; 3], i32)> = marked_faces.into_iter().map(|(f, m)| (sorted3(f), m)).collect();
        markers.sort_unstable();
        let mut boundary = Vec::new();
        let mut boundary_tag = Vec::new();
        let mut i = 0;
        while i < faces.len() {
            let mut j = i + 1;
            while j < faces.len() && faces[j].0 == faces[i].0 {
                j += 1;
            }
            if j - i == 1 {
                let id = faces[i].1 as usize;
                let (t, local) = (id / 4, id % 4);
                // face_opposite returns the face oriented outward for a positive tet.
                boundary.push(face_opposite(&tets[t], local));
                let tag = markers
                    .binary_search_by(|m| m.0.cmp(&faces[i].0))
                    .ok()
                    .and_then(|k| FaceTag::from_marker(markers[k].1))
                    .unwrap_or(FaceTag::Side);
                boundary_tag.push(tag);
            }
            i = j;
        }
        Ok(TetMesh { verts, tets, tet_region, boundary, boundary_tag })
    }

    /// Tags every boundary face like the boundary face of `reference` nearest to its centroid:
    /// for a mesh of the same solid made by another mesher (which knows nothing of visible,
    /// side and back faces). Returns the largest centroid distance found (m), a measure of how
    /// far the two boundaries are apart.
    ///
    /// # Errors
    /// [`MeshingError::NoBoundary`] when `reference` has no boundary face.
    pub fn transfer_tags(&mut self, reference: &TetMesh) -> Result<f64, MeshingError> {
        use parry3d_f64::math::Vector;
        use parry3d_f64::query::PointQuery;
        let v = |p: [f64; 3]| Vector::new(p[0], p[1], p[2]);
        let verts: Vec<Vector> = reference.verts.iter().map(|&p| v(p)).collect();
        let indices: Vec<[u32; 3]> = reference.boundary.iter().map(|f| f.map(|i| i as u32)).collect();
        let surface = parry3d_f64::shape::TriMesh::new(verts, indices).map_err(|_| MeshingError::NoBoundary)?;
        let mut worst = 0.0_f64;
        for (f, tag) in self.boundary.iter().zip(self.boundary_tag.iter_mut()) {
            let p = f.iter().fold([0.0; 3], |a, &i| {
                let q = self.verts[i];
                [a[0] + q[0] / 3.0, a[1] + q[1] / 3.0, a[2] + q[2] / 3.0]
            });
            let (proj, _) = surface.project_local_point_and_get_feature(v(p));
            worst = worst.max((proj.point - v(p)).length());
            *tag = reference.boundary_tag[proj.subshape as usize];
        }
        Ok(worst)
    }

    /// Sum of tetrahedron volumes (m^3).
    pub fn volume(&self) -> f64 {
        self.tets.iter().map(|t| tet_signed_volume(t.map(|i| self.verts[i]))).sum()
    }

    /// The whole boundary as a triangle mesh over all nodes (unused nodes stay unreferenced).
    pub fn boundary_surface(&self) -> TriMesh {
        TriMesh { verts: self.verts.clone(), tris: self.boundary.clone() }
    }

    /// The boundary faces with `tag`, compacted: returns the surface and, for each of its
    /// vertices, the index of the node it came from.
    pub fn tagged_surface(&self, tag: FaceTag) -> (TriMesh, Vec<usize>) {
        let mut map = vec![usize::MAX; self.verts.len()];
        let mut nodes = Vec::new();
        let mut tris = Vec::new();
        for (f, t) in self.boundary.iter().zip(&self.boundary_tag) {
            if *t != tag {
                continue;
            }
            tris.push(f.map(|n| {
                if map[n] == usize::MAX {
                    map[n] = nodes.len();
                    nodes.push(n);
                }
                map[n]
            }));
        }
        let verts = nodes.iter().map(|&n| self.verts[n]).collect();
        (TriMesh { verts, tris }, nodes)
    }

    /// Computes [`MeshStats`].
    pub fn stats(&self) -> MeshStats {
        let mut min_dih = f64::INFINITY;
        let mut max_dih = 0.0_f64;
        let mut max_rer = 0.0_f64;
        let mut min_edge = f64::INFINITY;
        let mut max_edge_len = 0.0_f64;
        let mut volume = 0.0;
        for t in &self.tets {
            let p = t.map(|i| self.verts[i]);
            volume += tet_signed_volume(p);
            let (lo, hi) = dihedral_range_deg(p);
            min_dih = min_dih.min(lo);
            max_dih = max_dih.max(hi);
            let (emin, emax) = edge_range(p);
            min_edge = min_edge.min(emin);
            max_edge_len = max_edge_len.max(emax);
            max_rer = max_rer.max(circumradius(p) / emin);
        }
        let count = |tag| self.boundary_tag.iter().filter(|&&t| t == tag).count();
        let surface = self.boundary_surface();
        let visible_area = self
            .boundary
            .iter()
            .zip(&self.boundary_tag)
            .filter(|(_, &t)| t == FaceTag::Visible)
            .map(|(f, _)| tri_area(f.map(|i| self.verts[i])))
            .sum();
        let layers = self.tet_region.iter().copied().max().unwrap_or(0).max(0) as usize;
        let mut tets_per_layer = vec![0; layers];
        for &r in &self.tet_region {
            if r >= 1 {
                tets_per_layer[r as usize - 1] += 1;
            }
        }
        MeshStats {
            nodes: self.verts.len(),
            tetrahedra: self.tets.len(),
            boundary_faces: self.boundary.len(),
            visible_faces: count(FaceTag::Visible),
            side_faces: count(FaceTag::Side),
            back_faces: count(FaceTag::Back),
            cavity_faces: count(FaceTag::Cavity),
            min_dihedral_deg: min_dih,
            max_dihedral_deg: max_dih,
            max_radius_edge_ratio: max_rer,
            min_edge_m: min_edge,
            max_edge_m: max_edge_len,
            volume_m3: volume,
            boundary_volume_m3: surface.signed_volume(),
            visible_area_m2: visible_area,
            tets_per_layer,
        }
    }
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// The face opposite local vertex `local`, ordered so that its normal points away from that
/// vertex when the tetrahedron is positively oriented.
fn face_opposite(t: &[usize; 4], local: usize) -> [usize; 3] {
    match local {
        0 => [t[1], t[2], t[3]],
        1 => [t[0], t[3], t[2]],
        2 => [t[0], t[1], t[3]],
        _ => [t[0], t[2], t[1]],
    }
}

fn sorted3(mut f: [usize; 3]) -> [usize; 3] {
    f.sort_unstable();
    f
}

/// Signed volume det[p1 - p0, p2 - p0, p3 - p0] / 6 (m^3).
pub fn tet_signed_volume(p: [[f64; 3]; 4]) -> f64 {
    dot(sub(p[1], p[0]), cross(sub(p[2], p[0]), sub(p[3], p[0]))) / 6.0
}

fn tri_area(p: [[f64; 3]; 3]) -> f64 {
    0.5 * norm(cross(sub(p[1], p[0]), sub(p[2], p[0])))
}

const EDGES: [(usize, usize); 6] = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)];

fn edge_range(p: [[f64; 3]; 4]) -> (f64, f64) {
    EDGES.iter().map(|&(a, b)| norm(sub(p[a], p[b]))).fold((f64::INFINITY, 0.0), |(lo, hi), e| (lo.min(e), hi.max(e)))
}

fn max_edge(p: [[f64; 3]; 4]) -> f64 {
    edge_range(p).1
}

/// Smallest and largest of the six dihedral angles (degrees). The dihedral angle at edge
/// (a, b) is pi minus the angle between the outward normals of the two faces sharing it.
pub fn dihedral_range_deg(p: [[f64; 3]; 4]) -> (f64, f64) {
    let t = [0, 1, 2, 3];
    let normals: Vec<[f64; 3]> = (0..4)
        .map(|l| {
            let f = face_opposite(&t, l).map(|i| p[i]);
            let n = cross(sub(f[1], f[0]), sub(f[2], f[0]));
            let len = norm(n);
            [n[0] / len, n[1] / len, n[2] / len]
        })
        .collect();
    let mut lo = f64::INFINITY;
    let mut hi = 0.0_f64;
    // The edge (a, b) is shared by the faces opposite the other two vertices.
    for &(a, b) in &EDGES {
        let others: Vec<usize> = (0..4).filter(|&k| k != a && k != b).collect();
        let c = dot(normals[others[0]], normals[others[1]]).clamp(-1.0, 1.0);
        let angle = 180.0 - c.acos().to_degrees();
        lo = lo.min(angle);
        hi = hi.max(angle);
    }
    (lo, hi)
}

/// Circumradius of a tetrahedron (m).
fn circumradius(p: [[f64; 3]; 4]) -> f64 {
    let a = sub(p[1], p[0]);
    let b = sub(p[2], p[0]);
    let c = sub(p[3], p[0]);
    let num = [
        dot(a, a) * cross(b, c)[0] + dot(b, b) * cross(c, a)[0] + dot(c, c) * cross(a, b)[0],
        dot(a, a) * cross(b, c)[1] + dot(b, b) * cross(c, a)[1] + dot(c, c) * cross(a, b)[1],
        dot(a, a) * cross(b, c)[2] + dot(b, b) * cross(c, a)[2] + dot(c, c) * cross(a, b)[2],
    ];
    norm(num) / (2.0 * dot(a, cross(b, c))).abs()
}

#[cfg(test)]
mod tests {
    use super::*;

    const REGULAR: [[f64; 3]; 4] = [[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]];

    #[test]
    fn regular_tetrahedron_measures() {
        let (lo, hi) = dihedral_range_deg(REGULAR);
        let expected = (1.0_f64 / 3.0).acos().to_degrees(); // 70.53 deg
        assert!((lo - expected).abs() < 1e-9 && (hi - expected).abs() < 1e-9);
        let edge = 8.0_f64.sqrt();
        assert!((circumradius(REGULAR) / edge - (6.0_f64).sqrt() / 4.0).abs() < 1e-12);
        assert!((tet_signed_volume(REGULAR).abs() - edge.powi(3) / (6.0 * 2f64.sqrt())).abs() < 1e-12);
    }

    #[test]
    fn single_tet_boundary_is_outward_and_closed() {
        let out = TetgenOutput {
            points: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            tets: vec![[0, 2, 1, 3]], // negatively oriented on purpose
            tet_region: vec![1],
            marked_faces: vec![([0, 1, 2], FaceTag::Back.marker())],
        };
        let m = TetMesh::from_tetgen(out).unwrap();
        assert!(tet_signed_volume(m.tets[0].map(|i| m.verts[i])) > 0.0);
        assert_eq!(m.boundary.len(), 4);
        let s = m.stats();
        assert!((s.boundary_volume_m3 - 1.0 / 6.0).abs() < 1e-15);
        assert!((s.volume_m3 - 1.0 / 6.0).abs() < 1e-15);
        assert_eq!(s.back_faces, 1);
        assert_eq!(s.side_faces, 3);
    }

    #[test]
    fn flat_tet_is_rejected() {
        let out = TetgenOutput {
            points: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]],
            tets: vec![[0, 1, 2, 3]],
            tet_region: vec![1],
            marked_faces: vec![],
        };
        assert!(matches!(TetMesh::from_tetgen(out), Err(MeshingError::DegenerateTet { tet: 0, .. })));
    }
}
