//! Tetrahedral meshes cached by content hash: the SHA-256 of the canonical JSON of the scene's
//! `object` and `meshing` sections and the software version names the file, so any change of
//! shape, thickness or meshing option makes a new mesh, and reruns skip TetGen.
//!
//! File format (`<hash>.tetmesh`, little-endian): the 8 bytes `HSTMESH1`, then five u64
//! counts (nodes, tetrahedra, tetrahedron regions = tetrahedra, boundary faces, tags =
//! faces), then nodes as 3 f64 (m), tetrahedra as 4 u64 node indices, regions as i32,
//! boundary faces as 3 u64, tags as i32 TetGen markers (1 visible, 2 side, 3 back).
//! Written atomically; a file that does not parse or whose indices are out of range is
//! ignored and remeshed.

use std::path::Path;

use anyhow::Context;
use heatsim::mesh::tetmesh::{FaceTag, TetMesh};
use heatsim::scene::Scene;
use serde_json::json;

use super::cells::{canonical_json, heatsim_version, sha256_hex};

const MAGIC: &[u8; 8] = b"HSTMESH1";

/// The cache key of the scene's mesh.
pub fn mesh_key(scene: &Scene) -> String {
    let v = json!({ "object": scene.object, "meshing": scene.meshing, "version": heatsim_version() });
    sha256_hex(canonical_json(&v).as_bytes())
}

/// Serialises a mesh in the format above.
pub fn encode(mesh: &TetMesh) -> Vec<u8> {
    let mut b = Vec::with_capacity(48 + mesh.verts.len() * 24 + mesh.tets.len() * 36 + mesh.boundary.len() * 28);
    b.extend_from_slice(MAGIC);
    for n in [mesh.verts.len(), mesh.tets.len(), mesh.tet_region.len(), mesh.boundary.len(), mesh.boundary_tag.len()] {
        b.extend_from_slice(&(n as u64).to_le_bytes());
    }
    mesh.verts.iter().flatten().for_each(|x| b.extend_from_slice(&x.to_le_bytes()));
    mesh.tets.iter().flatten().for_each(|&i| b.extend_from_slice(&(i as u64).to_le_bytes()));
    mesh.tet_region.iter().for_each(|r| b.extend_from_slice(&r.to_le_bytes()));
    mesh.boundary.iter().flatten().for_each(|&i| b.extend_from_slice(&(i as u64).to_le_bytes()));
    mesh.boundary_tag.iter().for_each(|t| b.extend_from_slice(&t.marker().to_le_bytes()));
    b
}

/// Parses the format above; `None` for anything malformed.
pub fn decode(bytes: &[u8]) -> Option<TetMesh> {
    let mut r = Reader { b: bytes, at: 0 };
    if r.take(8)? != MAGIC {
        return None;
    }
    let mut counts = [0usize; 5];
    for c in &mut counts {
        *c = usize::try_from(r.u64()?).ok()?;
    }
    let [nv, nt, nr, nb, ng] = counts;
    if nr != nt || ng != nb || bytes.len() != 48 + nv * 24 + nt * 32 + nr * 4 + nb * 24 + ng * 4 {
        return None;
    }
    let verts = (0..nv).map(|_| Some([r.f64()?, r.f64()?, r.f64()?])).collect::<Option<Vec<_>>>()?;
    let idx = |r: &mut Reader| -> Option<usize> {
        let i = usize::try_from(r.u64()?).ok()?;
        (i < nv).then_some(i)
    };
    let tets =
        (0..nt).map(|_| Some([idx(&mut r)?, idx(&mut r)?, idx(&mut r)?, idx(&mut r)?])).collect::<Option<Vec<_>>>()?;
    let tet_region = (0..nr).map(|_| r.i32()).collect::<Option<Vec<_>>>()?;
    let boundary = (0..nb).map(|_| Some([idx(&mut r)?, idx(&mut r)?, idx(&mut r)?])).collect::<Option<Vec<_>>>()?;
    let boundary_tag = (0..ng).map(|_| FaceTag::from_marker(r.i32()?)).collect::<Option<Vec<_>>>()?;
    Some(TetMesh { verts, tets, tet_region, boundary, boundary_tag })
}

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Option<&[u8]> {
        let s = self.b.get(self.at..self.at.checked_add(n)?)?;
        self.at += n;
        Some(s)
    }
    fn u64(&mut self) -> Option<u64> {
        Some(u64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
    fn f64(&mut self) -> Option<f64> {
        Some(f64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
    fn i32(&mut self) -> Option<i32> {
        Some(i32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }
}

/// The scene's mesh from `cache_dir`, or meshed by TetGen and stored there. Returns the mesh
/// and whether it came from the cache.
pub fn mesh_cached(scene: &Scene, cache_dir: &Path) -> anyhow::Result<(TetMesh, bool)> {
    let path = cache_dir.join("meshes").join(format!("{}.tetmesh", mesh_key(scene)));
    if let Ok(bytes) = std::fs::read(&path) {
        if let Some(mesh) = decode(&bytes) {
            return Ok((mesh, true));
        }
    }
    let meshed = heatsim::meshing::mesh_scene(scene, None).with_context(|| format!("meshing {}", scene.name))?;
    heatsim::io::write_atomic(&path, &encode(&meshed.mesh)).with_context(|| format!("writing {}", path.display()))?;
    Ok((meshed.mesh, false))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_corruption() {
        let mesh = TetMesh {
            verts: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            tets: vec![[0, 1, 2, 3]],
            tet_region: vec![1],
            boundary: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
            boundary_tag: vec![FaceTag::Back, FaceTag::Side, FaceTag::Side, FaceTag::Visible],
        };
        let bytes = encode(&mesh);
        let back = decode(&bytes).unwrap();
        assert_eq!(back.verts, mesh.verts);
        assert_eq!(back.tets, mesh.tets);
        assert_eq!(back.tet_region, mesh.tet_region);
        assert_eq!(back.boundary, mesh.boundary);
        assert_eq!(back.boundary_tag, mesh.boundary_tag);
        assert!(decode(&bytes[..bytes.len() - 1]).is_none(), "truncated");
        let mut bad = bytes.clone();
        bad[48 + 4 * 24] = 9; // first tetrahedron index -> 9 >= 4 nodes
        assert!(decode(&bad).is_none(), "index out of range");
    }
}
