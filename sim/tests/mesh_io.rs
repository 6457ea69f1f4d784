//! Integration tests of the surface-mesh layer: `TriMesh` validation, OBJ / glTF / GLB
//! readers, the OBJ and VTK writers, and the malformed-input corpus in
//! `tests/data/malformed/` (see its README.md).

mod support;

use std::path::{Path, PathBuf};

use heatsim::mesh::error::MeshError;
use heatsim::mesh::trimesh::TriMesh;
use support::icosphere;

// ---------------------------------------------------------------------------------------------
// Shared fixtures.

/// Unit cube [0, 1]^3: 8 vertices, 12 outward triangles (two per side).
fn cube() -> TriMesh {
    let verts = vec![
        [0., 0., 0.],
        [1., 0., 0.],
        [1., 1., 0.],
        [0., 1., 0.],
        [0., 0., 1.],
        [1., 0., 1.],
        [1., 1., 1.],
        [0., 1., 1.],
    ];
    let quads = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [2, 3, 7, 6], [1, 2, 6, 5], [0, 4, 7, 3]];
    let tris = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
    TriMesh::try_new(verts, tris).unwrap()
}

/// Right-corner tetrahedron with unit legs, outward; volume 1/6.
fn tetra() -> TriMesh {
    TriMesh::try_new(
        vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.]],
        vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    )
    .unwrap()
}

/// Concatenate meshes, offsetting indices.
fn merged(meshes: &[TriMesh]) -> TriMesh {
    let mut verts = Vec::new();
    let mut tris = Vec::new();
    for m in meshes {
        let off = verts.len();
        verts.extend_from_slice(&m.verts);
        tris.extend(m.tris.iter().map(|t| t.map(|i| i + off)));
    }
    TriMesh::try_new(verts, tris).unwrap()
}

fn translated(m: &TriMesh, d: [f64; 3]) -> TriMesh {
    m.transformed(|p| [p[0] + d[0], p[1] + d[1], p[2] + d[2]])
}

fn corpus(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/malformed").join(name)
}

// ---------------------------------------------------------------------------------------------

mod solid_validation {
    use super::*;

    #[test]
    fn unit_cube_is_a_closed_outward_solid() {
        let m = cube();
        m.check_closed_oriented().unwrap();
        assert!(m.boundary_edges().is_empty());
        assert!((m.signed_volume() - 1.0).abs() < 1e-12);
        assert!((m.area() - 6.0).abs() < 1e-12);
        assert_eq!(m.bounding_box(), ([0.; 3], [1.; 3]));
        for f in 0..12 {
            let n = m.face_normal(f);
            assert!(((n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt() - 1.0).abs() < 1e-15);
            assert!((m.face_area(f) - 0.5).abs() < 1e-15);
        }
        m.validate_solid().unwrap();
    }

    #[test]
    fn flipped_cube_is_inside_out() {
        let e = cube().flipped().validate_solid().unwrap_err();
        match e {
            MeshError::InsideOut { signed_volume } => assert!((signed_volume + 1.0).abs() < 1e-12),
            other => panic!("expected InsideOut, got {other:?}"),
        }
        assert!(e_string(&cube().flipped()).contains("inside out"));
    }

    fn e_string(m: &TriMesh) -> String {
        m.validate_solid().unwrap_err().to_string()
    }

    #[test]
    fn cube_missing_a_face_is_open_and_names_the_edge() {
        let mut m = cube();
        let removed = m.tris.pop().unwrap();
        assert_eq!(removed, [0, 7, 3]);
        assert_eq!(m.boundary_edges(), vec![[0, 3], [0, 7], [3, 7]]);
        let e = m.validate_solid().unwrap_err();
        assert!(matches!(e, MeshError::Open { edge: [0, 3], face_count: 1, boundary_edges: 3 }));
        assert!(e.to_string().contains("edge (0, 3) is used by 1 face(s)"), "{e}");
    }

    #[test]
    fn edge_shared_by_four_faces_is_open() {
        let mut m = cube();
        // A two-sided fin hanging off edge (0, 1): the edge is now used by four faces.
        m.verts.push([0.5, -1.0, 0.0]);
        m.tris.push([0, 1, 8]);
        m.tris.push([1, 0, 8]);
        match m.check_closed_oriented().unwrap_err() {
            MeshError::Open { edge, face_count, .. } => assert_eq!((edge, face_count), ([0, 1], 4)),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn one_reversed_face_is_inconsistent_orientation() {
        let mut m = cube();
        let [a, b, c] = m.tris[0];
        m.tris[0] = [a, c, b];
        let e = m.validate_solid().unwrap_err();
        assert!(matches!(e, MeshError::InconsistentOrientation { edge: [0, 2] }), "{e:?}");
        assert!(e.to_string().contains("edge (0, 2)"));
    }

    #[test]
    fn overlapping_cubes_self_intersect_and_disjoint_cubes_do_not() {
        let overlapping = merged(&[cube(), translated(&cube(), [0.5, 0.5, 0.5])]);
        match overlapping.validate_solid().unwrap_err() {
            MeshError::SelfIntersecting { faces, pairs_found } => {
                assert!(faces[0] < 12 && faces[1] >= 12, "{faces:?}");
                assert!(pairs_found >= 4, "{pairs_found}");
                assert_eq!(pairs_found, overlapping.self_intersections(usize::MAX).len());
            }
            other => panic!("expected SelfIntersecting, got {other:?}"),
        }

        let disjoint = merged(&[cube(), translated(&cube(), [2.0, 0.0, 0.0])]);
        disjoint.validate_solid().unwrap();
        assert!((disjoint.signed_volume() - 2.0).abs() < 1e-12);

        // Touching along a whole side is not a valid solid either (a mesher would need the
        // shared side to be one set of faces).
        let touching = merged(&[cube(), translated(&cube(), [1.0, 0.0, 0.0])]);
        assert!(matches!(touching.validate_solid(), Err(MeshError::SelfIntersecting { .. })));

        // A gap of 1e-6 of the size is clean.
        let near = merged(&[cube(), translated(&cube(), [1.0 + 1e-6, 0.0, 0.0])]);
        near.validate_solid().unwrap();
    }

    #[test]
    fn cube_with_a_vertex_pushed_through_the_opposite_face_self_intersects() {
        let mut m = cube();
        m.verts[6] = [0.3, 0.4, -0.5]; // (1, 1, 1) pushed down through the bottom z = 0
        m.check_closed_oriented().unwrap();
        let pairs = m.self_intersections(usize::MAX);
        assert!(!pairs.is_empty());
        // Every reported pair really involves a face incident to the moved vertex.
        for [i, j] in &pairs {
            assert!(m.tris[*i].contains(&6) || m.tris[*j].contains(&6), "{i} {j}");
        }
        let e = m.validate_solid().unwrap_err();
        assert!(matches!(e, MeshError::SelfIntersecting { faces, .. } if faces == pairs[0]), "{e:?}");
    }

    #[test]
    fn folded_adjacent_faces_intersect() {
        // Two faces sharing edge (0, 1), coplanar, on the same side: a fold.
        let m = TriMesh::try_new(
            vec![[0., 0., 0.], [1., 0., 0.], [0.5, 1., 0.], [0.3, 2., 0.]],
            vec![[0, 1, 2], [1, 0, 3]],
        )
        .unwrap();
        assert_eq!(m.self_intersections(10), vec![[0, 1]]);
        // Unfolded (opposite sides) and bent out of plane: only the edge is shared.
        let flat = TriMesh::try_new(
            vec![[0., 0., 0.], [1., 0., 0.], [0.5, 1., 0.], [0.3, -2., 0.]],
            vec![[0, 1, 2], [1, 0, 3]],
        )
        .unwrap();
        assert!(flat.self_intersections(10).is_empty());
        let bent = TriMesh::try_new(
            vec![[0., 0., 0.], [1., 0., 0.], [0.5, 1., 0.], [0.3, 1., 0.5]],
            vec![[0, 1, 2], [1, 0, 3]],
        )
        .unwrap();
        assert!(bent.self_intersections(10).is_empty());
    }

    #[test]
    fn degenerate_face_is_reported() {
        // A cube whose top is split with a needle triangle of zero area: vertex 8 lies on
        // edge (4, 6)'s midpoint, so face [4, 8, 6] is collinear.
        let mut m = cube();
        m.verts.push([0.5, 0.5, 1.0]);
        // Replace top triangle [4, 5, 6] by [4, 5, 8], [5, 6, 8] and add the sliver [4, 8, 6]
        // paired with [4, 6, 7] -> [4, 6, 7] keeps edge (4, 6); sliver needs edge (6, 4).
        let top = m.tris.iter().position(|t| *t == [4, 5, 6]).unwrap();
        m.tris[top] = [4, 5, 8];
        m.tris.push([5, 6, 8]);
        m.tris.push([8, 6, 4]);
        // Edges: (4,8),(8,6) used twice now; (6,4) by [8,6,4] and [4,6,7]; (4,5),(5,6) once each
        // in the top plus once in the sides.
        m.check_closed_oriented().unwrap();
        match m.validate_solid().unwrap_err() {
            MeshError::DegenerateFace { face, area } => {
                assert_eq!(m.tris[face], [8, 6, 4]);
                assert!(area < 1e-15);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn tetrahedron_and_icospheres_validate() {
        let t = tetra();
        t.validate_solid().unwrap();
        assert!((t.signed_volume() - 1.0 / 6.0).abs() < 1e-15);

        for level in 0..=3 {
            let r = 0.02; // 2 cm
            let s = icosphere(level, r);
            assert_eq!(s.tris.len(), 20 * 4usize.pow(level));
            s.validate_solid().unwrap();
            let sphere = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
            let v = s.signed_volume();
            // Inscribed polyhedron: below the sphere, converging to it.
            assert!(v < sphere && v > 0.6 * sphere, "level {level}: {v} vs {sphere}");
            assert!(matches!(s.flipped().validate_solid(), Err(MeshError::InsideOut { .. })));
            // Far from the origin and at micrometre scale it is just as valid.
            translated(&s, [10.0, -3.0, 7.0]).validate_solid().unwrap();
            s.transformed(|p| p.map(|x| 1e-4 * x)).validate_solid().unwrap();
        }
    }

    #[test]
    fn weld_closes_a_uv_seam() {
        let s = icosphere(2, 1.0);
        // Cut along the half-plane y = 0, x > 0 like a UV seam: faces on the y < 0 side get
        // their own copies of the seam vertices.
        let on_seam = |p: [f64; 3]| p[1].abs() < 1e-12 && p[0] > 0.0;
        let mut verts = s.verts.clone();
        let mut copy = std::collections::BTreeMap::new();
        let mut tris = s.tris.clone();
        for t in tris.iter_mut() {
            let centroid_y: f64 = t.iter().map(|&v| s.verts[v][1]).sum::<f64>() / 3.0;
            if centroid_y < 0.0 {
                for v in t.iter_mut() {
                    if on_seam(s.verts[*v]) {
                        *v = *copy.entry(*v).or_insert_with(|| {
                            verts.push(s.verts[*v]);
                            verts.len() - 1
                        });
                    }
                }
            }
        }
        assert!(!copy.is_empty());
        let seamed = TriMesh::try_new(verts, tris).unwrap();
        assert!(!seamed.boundary_edges().is_empty());
        assert!(matches!(seamed.validate_solid(), Err(MeshError::Open { .. })));
        let welded = seamed.weld(1e-9);
        assert_eq!(welded.verts.len(), s.verts.len());
        assert_eq!(welded, s, "welding restores the original (first occurrences keep order)");
        welded.validate_solid().unwrap();
    }

    #[test]
    fn self_intersections_are_sorted_deterministic_and_limited() {
        // Three mutually overlapping cubes: many intersecting pairs.
        let m = merged(&[cube(), translated(&cube(), [0.5, 0.3, 0.2]), translated(&cube(), [0.2, 0.5, 0.4])]);
        let all = m.self_intersections(usize::MAX);
        assert!(all.len() > 10);
        assert!(all.windows(2).all(|w| w[0] < w[1]), "sorted, no duplicates");
        assert!(all.iter().all(|[i, j]| i < j));
        assert_eq!(all, m.self_intersections(usize::MAX));
        assert_eq!(m.self_intersections(3), all[..3].to_vec());
        assert!(m.self_intersections(0).is_empty());
    }

    #[test]
    fn large_mesh_validates_in_sub_quadratic_time() {
        // 81920 faces, like the Stanford bunny's 70k. An O(F^2) search would take minutes
        // here; the BVH takes well under a second even in this unoptimised test profile.
        let s = icosphere(6, 0.05);
        assert_eq!(s.tris.len(), 81920);
        let t = std::time::Instant::now();
        s.validate_solid().unwrap();
        let dt = t.elapsed();
        eprintln!("validate_solid on {} faces: {dt:?}", s.tris.len());
        assert!(dt.as_secs_f64() < 20.0, "{dt:?}");
    }

    /// The real bunny when it is on disk (scripts/fetch-bunny.sh puts it in the cache).
    #[test]
    fn stanford_bunny_if_available() {
        let cache = std::env::var_os("HEATSIM_CACHE_DIR")
            .map(PathBuf::from)
            .or_else(|| std::env::var_os("XDG_CACHE_HOME").map(|d| PathBuf::from(d).join("heatsim")))
            .or_else(|| std::env::var_os("HOME").map(|d| PathBuf::from(d).join(".cache/heatsim")));
        let Some(path) = cache.map(|c| c.join("bunny.obj")).filter(|p| p.exists()) else {
            eprintln!("stanford_bunny_if_available: bunny.obj not cached; skipped");
            return;
        };
        let m = heatsim::mesh::obj::read_obj(&path).unwrap();
        assert_eq!((m.verts.len(), m.tris.len()), (34835, 69666));
        let t = std::time::Instant::now();
        let result = m.validate_solid();
        let dt = t.elapsed();
        eprintln!("bunny: {} faces, validate_solid {dt:?}: {result:?}", m.tris.len());
        assert!(dt.as_secs_f64() < 20.0, "{dt:?}");
        m.check_closed_oriented().unwrap();
        assert!(m.signed_volume() > 0.0);
        // The glmark2 bunny (sha256 bff773d2...) really intersects itself, confirmed with exact
        // rational arithmetic: edge (16322, 16323) crosses the interior of face 69661, which
        // shares vertex 16321 with face 22949 and vertex 34834 with face 69659.
        assert_eq!(m.self_intersections(usize::MAX), vec![[22949, 69661], [69659, 69661]]);
        assert!(matches!(result, Err(MeshError::SelfIntersecting { faces: [22949, 69661], pairs_found: 2 })));
    }
}

// ---------------------------------------------------------------------------------------------

mod obj_io {
    use super::*;
    use heatsim::mesh::obj::{read_obj, write_obj, write_obj_to};
    use heatsim::mesh::trimesh::read_surface;

    #[test]
    fn write_then_read_is_bit_exact() {
        let mut m = icosphere(2, 1.0 / 3.0);
        m = translated(&m, [0.1, 0.2, 1e-7]);
        // Awkward values: subnormal-ish, huge, negative zero, many digits.
        m.verts[0] = [1e-300, -0.0, 123456789.12345679];
        m.verts[1] = [5e-324, f64::MAX / 4.0, -2.5e-5];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sphere.obj");
        write_obj(&path, &m, "icosphere\nsecond comment line").unwrap();
        let back = read_obj(&path).unwrap();
        assert_eq!(back.tris, m.tris);
        assert_eq!(back.verts.len(), m.verts.len());
        for (a, b) in back.verts.iter().zip(&m.verts) {
            for k in 0..3 {
                assert_eq!(a[k].to_bits(), b[k].to_bits(), "{} vs {}", a[k], b[k]);
            }
        }
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.starts_with("# icosphere\n# second comment line\n"));
    }

    #[test]
    fn write_obj_to_uses_one_based_faces() {
        let mut out = Vec::new();
        write_obj_to(&mut out, &tetra(), "").unwrap();
        let text = String::from_utf8(out).unwrap();
        let faces: Vec<&str> = text.lines().filter(|l| l.starts_with("f ")).collect();
        assert_eq!(faces, ["f 1 3 2", "f 1 2 4", "f 1 4 3", "f 2 3 4"]);
        assert!(text.contains("v 1 0 0\n"));
    }

    #[test]
    fn matches_tobj_on_polygons_negative_indices_and_attributes() {
        // tobj (with f32 coordinates) is the oracle: same triangles, same corner positions.
        let text = "\
# a unit cube written with quads, texture/normal refs and relative indices
o cube
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
vt 0 0
vn 0 0 1
f 1/1/1 4/1/1 3/1/1 2/1/1
f 5//1 6//1 7//1 8//1
f -8 -7 -3 -4
f 3/1 4/1 8/1 7/1
f 2 3 7 6
f 1 5 8 4
";
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("quads.obj");
        std::fs::write(&path, text).unwrap();
        let ours = read_obj(&path).unwrap();
        assert_eq!(ours.tris.len(), 12);
        ours.validate_solid().unwrap();
        assert!((ours.signed_volume() - 1.0).abs() < 1e-12);

        let opts = tobj::LoadOptions { triangulate: true, single_index: false, ..Default::default() };
        let (models, _) = tobj::load_obj(&path, &opts).unwrap();
        let mut theirs: Vec<[[f64; 3]; 3]> = Vec::new();
        for model in &models {
            let p = &model.mesh.positions;
            for t in model.mesh.indices.chunks(3) {
                theirs.push([0, 1, 2].map(|k| {
                    let i = t[k] as usize;
                    [0, 1, 2].map(|c| f64::from(p[3 * i + c]))
                }));
            }
        }
        assert_eq!(theirs.len(), ours.tris.len());
        for (f, t) in ours.tris.iter().enumerate() {
            for k in 0..3 {
                let a = ours.verts[t[k]];
                let b = theirs[f][k];
                assert!((0..3).all(|c| (a[c] - b[c]).abs() <= 1e-7), "face {f} corner {k}: {a:?} vs {b:?}");
            }
        }
    }

    #[test]
    fn groups_share_vertices() {
        // tobj would duplicate the vertices shared by the two groups; we keep one list, so
        // the cube stays closed.
        let mut text = String::new();
        for p in &cube().verts {
            text += &format!("v {} {} {}\n", p[0], p[1], p[2]);
        }
        for (f, t) in cube().tris.iter().enumerate() {
            if f % 6 == 0 {
                text += &format!("g part{f}\nusemtl m{f}\n");
            }
            text += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
        }
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("groups.obj");
        std::fs::write(&path, text).unwrap();
        let m = read_obj(&path).unwrap();
        assert_eq!(m, cube());
        m.validate_solid().unwrap();
    }

    #[test]
    fn read_surface_dispatches_on_extension() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("CUBE.OBJ");
        write_obj(&path, &cube(), "").unwrap();
        assert_eq!(read_surface(&path).unwrap(), cube());
        let e = read_surface(&corpus("unsupported.stl")).unwrap_err();
        assert!(matches!(e, MeshError::Parse { .. }));
        let s = e.to_string();
        assert!(s.contains("unsupported.stl") && s.contains(".obj, .ply, .gltf and .glb"), "{s}");
        let e = read_surface(Path::new("no_extension")).unwrap_err();
        assert!(e.to_string().contains("(no extension)"), "{e}");
    }

    #[test]
    fn missing_file_is_an_io_error_naming_it() {
        let e = read_obj(Path::new("/nonexistent/dir/x.obj")).unwrap_err();
        match &e {
            MeshError::Io { path, source } => {
                assert_eq!(path, Path::new("/nonexistent/dir/x.obj"));
                assert_eq!(source.kind(), std::io::ErrorKind::NotFound);
            }
            other => panic!("{other:?}"),
        }
        assert!(e.to_string().starts_with("cannot read /nonexistent/dir/x.obj: "));
    }
}

// ---------------------------------------------------------------------------------------------

/// Minimal glTF 2.0 writer for tests: one buffer, positions (f32) and u32 indices per mesh.
mod gltf_builder {
    use base64::Engine as _;
    use serde_json::{json, Value};

    pub struct Builder {
        pub bin: Vec<u8>,
        pub views: Vec<Value>,
        pub accessors: Vec<Value>,
        pub meshes: Vec<Value>,
        pub nodes: Vec<Value>,
    }

    impl Builder {
        pub fn new() -> Self {
            Builder { bin: Vec::new(), views: Vec::new(), accessors: Vec::new(), meshes: Vec::new(), nodes: Vec::new() }
        }

        fn push_view(&mut self, bytes: &[u8], target: u32) -> usize {
            while self.bin.len() % 4 != 0 {
                self.bin.push(0);
            }
            self.views.push(json!({"buffer": 0, "byteOffset": self.bin.len(),
                                   "byteLength": bytes.len(), "target": target}));
            self.bin.extend_from_slice(bytes);
            self.views.len() - 1
        }

        /// Add a mesh with one triangle primitive; `tris = None` makes it non-indexed.
        pub fn mesh(&mut self, verts: &[[f64; 3]], tris: Option<&[[usize; 3]]>) -> usize {
            let pos: Vec<u8> = verts.iter().flat_map(|p| p.map(|x| x as f32)).flat_map(f32::to_le_bytes).collect();
            let view = self.push_view(&pos, 34962);
            let lo = [0, 1, 2].map(|k| verts.iter().map(|p| p[k] as f32).fold(f32::MAX, f32::min));
            let hi = [0, 1, 2].map(|k| verts.iter().map(|p| p[k] as f32).fold(f32::MIN, f32::max));
            self.accessors.push(json!({"bufferView": view, "componentType": 5126,
                "count": verts.len(), "type": "VEC3", "min": lo, "max": hi}));
            let pos_acc = self.accessors.len() - 1;
            let mut prim = json!({"attributes": {"POSITION": pos_acc}, "mode": 4});
            if let Some(tris) = tris {
                let idx: Vec<u8> = tris.iter().flatten().flat_map(|&i| (i as u32).to_le_bytes()).collect();
                let view = self.push_view(&idx, 34963);
                self.accessors.push(json!({"bufferView": view, "componentType": 5125,
                    "count": 3 * tris.len(), "type": "SCALAR"}));
                prim["indices"] = json!(self.accessors.len() - 1);
            }
            self.meshes.push(json!({"primitives": [prim]}));
            self.meshes.len() - 1
        }

        pub fn node(&mut self, node: Value) -> usize {
            self.nodes.push(node);
            self.nodes.len() - 1
        }

        /// The JSON document; `uri` is the buffer's URI (None for a GLB's BIN chunk).
        pub fn document(&self, roots: Option<&[usize]>, uri: Option<String>) -> Value {
            let mut buffer = json!({"byteLength": self.bin.len()});
            if let Some(uri) = uri {
                buffer["uri"] = json!(uri);
            }
            let mut doc = json!({
                "asset": {"version": "2.0"},
                "buffers": [buffer],
                "bufferViews": self.views,
                "accessors": self.accessors,
                "meshes": self.meshes,
            });
            if !self.nodes.is_empty() {
                doc["nodes"] = json!(self.nodes);
            }
            if let Some(roots) = roots {
                doc["scene"] = json!(0);
                doc["scenes"] = json!([{"nodes": roots}]);
            }
            doc
        }

        pub fn data_uri(&self) -> String {
            format!(
                "data:application/octet-stream;base64,{}",
                base64::engine::general_purpose::STANDARD.encode(&self.bin)
            )
        }

        pub fn glb(&self, roots: Option<&[usize]>) -> Vec<u8> {
            let mut js = serde_json::to_vec(&self.document(roots, None)).unwrap();
            while js.len() % 4 != 0 {
                js.push(b' ');
            }
            let mut bin = self.bin.clone();
            while bin.len() % 4 != 0 {
                bin.push(0);
            }
            let total = 12 + 8 + js.len() + 8 + bin.len();
            let mut out = Vec::new();
            out.extend_from_slice(b"glTF");
            out.extend(2u32.to_le_bytes());
            out.extend((total as u32).to_le_bytes());
            out.extend((js.len() as u32).to_le_bytes());
            out.extend_from_slice(b"JSON");
            out.extend(js);
            out.extend((bin.len() as u32).to_le_bytes());
            out.extend_from_slice(b"BIN\0");
            out.extend(bin);
            out
        }
    }
}

mod gltf_io {
    use super::gltf_builder::Builder;
    use super::*;
    use heatsim::mesh::gltf::read_gltf;
    use heatsim::mesh::trimesh::read_surface;
    use serde_json::json;

    fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    #[test]
    fn data_uri_gltf_round_trips_a_tetrahedron() {
        let t = tetra();
        let mut b = Builder::new();
        let mesh = b.mesh(&t.verts, Some(&t.tris));
        let node = b.node(json!({"mesh": mesh}));
        let doc = b.document(Some(&[node]), Some(b.data_uri()));
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "tet.gltf", doc.to_string().as_bytes());
        let m = read_gltf(&path).unwrap();
        assert_eq!(m, t);
        m.validate_solid().unwrap();
        assert_eq!(read_surface(&path).unwrap(), t);
    }

    #[test]
    fn glb_and_external_bin_buffers() {
        let t = tetra();
        let mut b = Builder::new();
        let mesh = b.mesh(&t.verts, Some(&t.tris));
        let node = b.node(json!({"mesh": mesh}));
        let dir = tempfile::tempdir().unwrap();
        let glb = write(dir.path(), "tet.GLB", &b.glb(Some(&[node])));
        assert_eq!(read_surface(&glb).unwrap(), t);

        write(dir.path(), "tet data.bin", &b.bin);
        let doc = b.document(Some(&[node]), Some("tet%20data.bin".into()));
        let gltf = write(dir.path(), "tet.gltf", doc.to_string().as_bytes());
        assert_eq!(read_gltf(&gltf).unwrap(), t);
    }

    #[test]
    fn node_transforms_are_applied() {
        let t = tetra();
        let mut b = Builder::new();
        let mesh = b.mesh(&t.verts, Some(&t.tris));
        // Root translated by (1, 2, 3) holding the mesh; a child scaled by 2 (world: translate
        // then scale) holding it again; a third, mirrored instance (scale -1 along x) that must
        // stay outward.
        let child = b.node(json!({"mesh": mesh, "scale": [2.0, 2.0, 2.0]}));
        let root = b.node(json!({"mesh": mesh, "translation": [1.0, 2.0, 3.0], "children": [child]}));
        let mirrored = b.node(json!({"mesh": mesh, "matrix": [
            -1.0, 0.0, 0.0, 0.0,  0.0, 1.0, 0.0, 0.0,  0.0, 0.0, 1.0, 0.0,  -5.0, 0.0, 0.0, 1.0]}));
        let doc = b.document(Some(&[root, mirrored]), Some(b.data_uri()));
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "scene.gltf", doc.to_string().as_bytes());
        let m = read_gltf(&path).unwrap();
        assert_eq!(m.verts.len(), 12);
        assert_eq!(m.tris.len(), 12);
        // Instance 1: translated.
        assert_eq!(&m.verts[0..4], &translated(&t, [1.0, 2.0, 3.0]).verts[..]);
        // Instance 2: scaled by 2, then translated by the parent.
        let want: Vec<[f64; 3]> =
            t.verts.iter().map(|p| [2.0 * p[0] + 1.0, 2.0 * p[1] + 2.0, 2.0 * p[2] + 3.0]).collect();
        assert_eq!(&m.verts[4..8], &want[..]);
        assert_eq!(m.tris[4], [4, 6, 5]);
        // Instance 3: mirrored in x and moved to x = -5 .. -6; winding reversed to stay outward.
        assert_eq!(m.verts[9], [-6.0, 0.0, 0.0]);
        assert_eq!(m.tris[8], [8, 9, 10]);
        // Volumes: 1/6 + 8/6 + 1/6, all positive; instances 1 and 2 overlap, so it is no solid.
        assert!((m.signed_volume() - 10.0 / 6.0).abs() < 1e-12);
        let third = TriMesh::try_new(m.verts[8..12].to_vec(), m.tris[8..12].iter().map(|t| t.map(|i| i - 8)).collect())
            .unwrap();
        third.validate_solid().unwrap();
        assert!(matches!(m.validate_solid(), Err(MeshError::SelfIntersecting { .. })));
    }

    #[test]
    fn rotation_quaternion_is_applied() {
        let t = tetra();
        let mut b = Builder::new();
        let mesh = b.mesh(&t.verts, Some(&t.tris));
        let h = std::f64::consts::FRAC_1_SQRT_2;
        // 90 degrees about +z: (1, 0, 0) -> (0, 1, 0).
        let node = b.node(json!({"mesh": mesh, "rotation": [0.0, 0.0, h, h]}));
        let doc = b.document(Some(&[node]), Some(b.data_uri()));
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "rot.gltf", doc.to_string().as_bytes());
        let m = read_gltf(&path).unwrap();
        let p = m.verts[1];
        assert!(p[0].abs() < 1e-7 && (p[1] - 1.0).abs() < 1e-7 && p[2].abs() < 1e-7, "{p:?}");
        m.validate_solid().unwrap();
    }

    #[test]
    fn non_indexed_primitives_and_scene_less_files() {
        // Triangle soup (every corner its own vertex), no scene: identity, sequential indices.
        let t = tetra();
        let soup: Vec<[f64; 3]> = t.tris.iter().flatten().map(|&i| t.verts[i]).collect();
        let mut b = Builder::new();
        b.mesh(&soup, None);
        let cube_mesh = translated(&cube(), [2.0, 0.0, 0.0]);
        b.mesh(&cube_mesh.verts, Some(&cube_mesh.tris));
        let doc = b.document(None, Some(b.data_uri()));
        let dir = tempfile::tempdir().unwrap();
        let path = write(dir.path(), "soup.gltf", doc.to_string().as_bytes());
        let m = read_gltf(&path).unwrap();
        assert_eq!(m.verts.len(), 12 + 8);
        assert_eq!(&m.tris[..4], &[[0, 1, 2], [3, 4, 5], [6, 7, 8], [9, 10, 11]]);
        assert_eq!(m.tris[4], cube_mesh.tris[0].map(|i| i + 12));
        assert!(matches!(m.validate_solid(), Err(MeshError::Open { .. })));
        let welded = m.weld(0.0);
        assert_eq!(welded.verts.len(), 4 + 8);
        welded.validate_solid().unwrap();
        assert!((welded.signed_volume() - (1.0 / 6.0 + 1.0)).abs() < 1e-12);
    }

    /// Every prefix and many single-byte corruptions of valid files must give Ok or Err,
    /// never a panic.
    #[test]
    fn truncations_and_corruptions_never_panic() {
        let t = tetra();
        let mut b = Builder::new();
        let mesh = b.mesh(&t.verts, Some(&t.tris));
        let node = b.node(json!({"mesh": mesh, "translation": [0.0, 0.0, 1.0]}));
        let glb = b.glb(Some(&[node]));
        let gltf = b.document(Some(&[node]), Some(b.data_uri())).to_string().into_bytes();
        let mut obj = Vec::new();
        heatsim::mesh::obj::write_obj_to(&mut obj, &cube(), "cube").unwrap();
        let dir = tempfile::tempdir().unwrap();
        let mut outcomes = [0usize; 2];
        for (name, bytes) in [("x.glb", &glb), ("x.gltf", &gltf), ("x.obj", &obj)] {
            let path = dir.path().join(name);
            let mut check = |data: &[u8]| {
                std::fs::write(&path, data).unwrap();
                outcomes[read_surface(&path).is_ok() as usize] += 1;
            };
            for n in 0..bytes.len() {
                check(&bytes[..n]);
            }
            for k in 0..bytes.len() {
                for flip in [0x01u8, 0x80, 0xff] {
                    let mut c = bytes.clone();
                    c[k] ^= flip;
                    check(&c);
                }
            }
        }
        assert!(outcomes[0] > 0 && outcomes[1] > 0, "{outcomes:?}");
    }

    /// Structured corruption of the glTF JSON: every number replaced by awkward values, every
    /// object member and array element removed in turn. Must never panic.
    #[test]
    fn json_field_mutations_never_panic() {
        use serde_json::Value;
        let t = tetra();
        let mut b = Builder::new();
        let mesh = b.mesh(&t.verts, Some(&t.tris));
        let child = b.node(json!({"mesh": mesh, "scale": [1.0, 2.0, 1.0]}));
        let node = b.node(json!({"mesh": mesh, "children": [child], "rotation": [0.0, 0.0, 0.0, 1.0]}));
        let doc = b.document(Some(&[node]), Some(b.data_uri()));

        // Paths (as JSON pointers) to every number, object member and array element.
        fn walk(v: &Value, at: String, out: &mut Vec<(String, bool)>) {
            match v {
                Value::Number(_) => out.push((at, true)),
                Value::Object(m) => {
                    for (k, x) in m {
                        let p = format!("{at}/{k}");
                        out.push((p.clone(), false));
                        walk(x, p, out);
                    }
                }
                Value::Array(a) => {
                    for (i, x) in a.iter().enumerate() {
                        let p = format!("{at}/{i}");
                        out.push((p.clone(), false));
                        walk(x, p, out);
                    }
                }
                _ => {}
            }
        }
        let mut paths = Vec::new();
        walk(&doc, String::new(), &mut paths);
        let awkward = [
            json!(0),
            json!(1),
            json!(2),
            json!(3),
            json!(5),
            json!(255),
            json!(65535),
            json!(4294967295u64),
            json!(4294967301u64),
            json!(-1),
            json!(0.5),
            json!(1e30),
        ];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.gltf");
        let mut tried = 0;
        for (pointer, is_number) in &paths {
            let mut variants = Vec::new();
            if *is_number {
                for a in &awkward {
                    let mut d = doc.clone();
                    *d.pointer_mut(pointer).unwrap() = a.clone();
                    variants.push(d);
                }
            }
            // Remove the member or element.
            let (parent, key) = pointer.rsplit_once('/').unwrap();
            let mut d = doc.clone();
            match d.pointer_mut(parent).unwrap() {
                Value::Object(m) => {
                    m.remove(key);
                }
                Value::Array(a) => {
                    a.remove(key.parse::<usize>().unwrap());
                }
                _ => unreachable!(),
            }
            variants.push(d);
            for d in variants {
                std::fs::write(&path, d.to_string()).unwrap();
                let _ = read_gltf(&path);
                tried += 1;
            }
        }
        assert!(tried > 300, "{tried}");
    }
}

// ---------------------------------------------------------------------------------------------

mod malformed_corpus {
    use super::*;
    use heatsim::mesh::trimesh::read_surface;

    /// How a corpus file must fail.
    enum Expect {
        /// Reading fails with this variant (of the innermost error for `InFile`).
        Read(fn(&MeshError) -> bool, &'static str, bool),
        /// Reading succeeds; `validate_solid` fails with this variant.
        Validate(fn(&MeshError) -> bool, &'static str),
    }
    use Expect::*;

    fn parse(e: &MeshError) -> bool {
        matches!(e, MeshError::Parse { .. })
    }
    fn in_file(inner: fn(&MeshError) -> bool) -> impl Fn(&MeshError) -> bool {
        move |e| matches!(e, MeshError::InFile { source, .. } if inner(source))
    }

    #[test]
    fn every_malformed_file_gives_the_documented_error() {
        // (file, expectation). For `Read`, the bool says the error is wrapped in InFile
        // (geometric / referenced-file problems) rather than being a Parse error.
        let table: Vec<(&str, Expect)> = vec![
            ("truncated.obj", Read(parse, "line 8: a vertex (\"v\") needs 3 coordinates but has 2", false)),
            (
                "bad_index.obj",
                Read(
                    |e| matches!(e, MeshError::IndexOutOfRange { face: 3, index: 8, vertex_count: 4 }),
                    "face 3 references vertex 8 but the mesh has 4 vertices",
                    true,
                ),
            ),
            (
                "nan.obj",
                Read(
                    |e| matches!(e, MeshError::NonFinite { vertex: 1, coord: 0, value } if value.is_nan()),
                    "vertex 1 has a non-finite x coordinate (NaN)",
                    true,
                ),
            ),
            (
                "inf.obj",
                Read(
                    |e| matches!(e, MeshError::NonFinite { vertex: 2, coord: 1, value } if *value == f64::INFINITY),
                    "vertex 2 has a non-finite y coordinate (inf)",
                    true,
                ),
            ),
            ("empty.obj", Read(|e| matches!(e, MeshError::Empty { .. }), "the mesh has no vertices", true)),
            ("garbage.obj", Read(parse, "is not valid UTF-8 text", false)),
            ("two_vertex_face.obj", Read(parse, "line 10: a face (\"f\") needs at least 3 vertices but has 2", false)),
            ("zero_index.obj", Read(parse, "line 6: face corner \"0\" uses vertex index 0", false)),
            ("unsupported.stl", Read(parse, "supported extensions are .obj, .ply, .gltf and .glb", false)),
            (
                "open.obj",
                Validate(
                    |e| matches!(e, MeshError::Open { edge: [0, 3], face_count: 1, boundary_edges: 4 }),
                    "edge (0, 3) is used by 1 face(s)",
                ),
            ),
            (
                "inside_out.obj",
                Validate(
                    |e| matches!(e, MeshError::InsideOut { signed_volume } if (signed_volume + 1.0).abs() < 1e-12),
                    "the surface is inside out",
                ),
            ),
            (
                "self_intersecting.obj",
                Validate(
                    |e| matches!(e, MeshError::SelfIntersecting { faces, .. } if faces[0] < 4 && faces[1] >= 4),
                    "the surface intersects itself",
                ),
            ),
            ("truncated.glb", Read(parse, "truncated GLB: the header declares", false)),
            ("bad_length.glb", Read(parse, "less than the 20-byte minimum", false)),
            (
                "bad_index.gltf",
                Read(
                    |e| matches!(e, MeshError::IndexOutOfRange { face: 3, index: 7, vertex_count: 4 }),
                    "face 3 references vertex 7 but the mesh has 4 vertices",
                    true,
                ),
            ),
            (
                "missing_buffer.gltf",
                Read(
                    |e| {
                        matches!(e, MeshError::Io { path, source }
                    if path.ends_with("missing_buffer.bin") && source.kind() == std::io::ErrorKind::NotFound)
                    },
                    "cannot read",
                    true,
                ),
            ),
            ("lines_mode.gltf", Read(parse, "mesh 0 primitive 0 uses primitive mode Lines", false)),
            ("accessor_overrun.gltf", Read(parse, "accessor 1 (30 elements of 2 bytes", false)),
            ("node_cycle.gltf", Read(parse, "node 0 is reached twice", false)),
            ("not_json.gltf", Read(parse, "not a valid glTF 2.0 file", false)),
        ];
        let mut failures = Vec::new();
        for (name, expect) in &table {
            let path = corpus(name);
            assert!(path.exists(), "missing corpus file {name}");
            let result = read_surface(&path);
            let problem = match (expect, result) {
                (Read(variant, text, wrapped), Err(e)) => {
                    let msg = e.to_string();
                    let shape_ok = if *wrapped { in_file(*variant)(&e) } else { variant(&e) };
                    if !shape_ok {
                        Some(format!("wrong variant: {e:?}"))
                    } else if !msg.contains(text) {
                        Some(format!("message {msg:?} lacks {text:?}"))
                    } else if !msg.contains(name) {
                        Some(format!("message {msg:?} does not name the file"))
                    } else {
                        None
                    }
                }
                (Validate(variant, text), Ok(m)) => match m.validate_solid() {
                    Err(e) if variant(&e) && e.to_string().contains(text) => None,
                    other => Some(format!("validate_solid gave {other:?}")),
                },
                (Read(..), Ok(m)) => Some(format!("read succeeded: {} faces", m.tris.len())),
                (Validate(..), Err(e)) => Some(format!("read failed: {e}")),
            };
            if let Some(p) = problem {
                failures.push(format!("{name}: {p}"));
            }
        }
        assert!(failures.is_empty(), "\n{}", failures.join("\n"));
    }

    #[test]
    fn missing_buffer_message_names_both_files() {
        let e = read_surface(&corpus("missing_buffer.gltf")).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("missing_buffer.gltf: cannot read "), "{msg}");
        assert!(msg.contains("missing_buffer.bin"), "{msg}");
    }
}

// ---------------------------------------------------------------------------------------------

mod vtu_io {
    use super::*;
    use base64::Engine as _;
    use heatsim::mesh::vtu::{write_pvd, write_vtu, Cells, DataArray};

    /// The decoded payload of the DataArray named `name` (after checking its 8-byte header),
    /// and its opening tag.
    fn array(xml: &str, name: &str) -> (String, Vec<u8>) {
        let key = format!("Name=\"{name}\"");
        let start = xml.find(&key).unwrap_or_else(|| panic!("no array {name}"));
        let tag_start = xml[..start].rfind('<').unwrap();
        let tag_end = start + xml[start..].find('>').unwrap();
        let body_end = tag_end + xml[tag_end..].find("</DataArray>").unwrap();
        let tag = xml[tag_start..=tag_end].to_string();
        let raw = base64::engine::general_purpose::STANDARD.decode(xml[tag_end + 1..body_end].trim()).unwrap();
        let n = u64::from_le_bytes(raw[..8].try_into().unwrap()) as usize;
        assert_eq!(n, raw.len() - 8, "header of {name} counts the payload bytes");
        (tag, raw[8..].to_vec())
    }

    fn f64s(b: &[u8]) -> Vec<f64> {
        b.chunks(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect()
    }
    fn i64s(b: &[u8]) -> Vec<i64> {
        b.chunks(8).map(|c| i64::from_le_bytes(c.try_into().unwrap())).collect()
    }

    fn two_tets() -> (Vec<[f64; 3]>, Vec<[usize; 4]>) {
        let pts = vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.], [0., 0., 1.], [1., 1., 1.]];
        (pts, vec![[0, 1, 2, 3], [1, 2, 3, 4]])
    }

    #[test]
    fn tetra_vtu_decodes_back_to_the_input() {
        let (pts, tets) = two_tets();
        let temperature = [300.0, 301.5, 302.25, 299.0, 1.0 / 3.0];
        let flux = [[1.0, 2.0, 3.0]; 5];
        let region = [7i32, -2];
        let mut out = Vec::new();
        write_vtu(
            &mut out,
            &pts,
            Cells::Tetra(&tets),
            &[("temperature_K", DataArray::F64(&temperature)), ("flux_W_m2", DataArray::Vec3(&flux))],
            &[("region", DataArray::I32(&region))],
        )
        .unwrap();
        let xml = String::from_utf8(out).unwrap();
        assert!(xml.contains(
            "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">"
        ));
        assert!(xml.contains("<Piece NumberOfPoints=\"5\" NumberOfCells=\"2\">"));

        let (tag, b) = array(&xml, "Points");
        assert!(tag.contains("type=\"Float64\"") && tag.contains("NumberOfComponents=\"3\""));
        assert!(tag.contains("format=\"binary\""));
        assert_eq!(f64s(&b), pts.iter().flatten().copied().collect::<Vec<_>>());

        let (tag, b) = array(&xml, "connectivity");
        assert!(tag.contains("type=\"Int64\""));
        assert_eq!(i64s(&b), vec![0, 1, 2, 3, 1, 2, 3, 4]);
        let (tag, b) = array(&xml, "offsets");
        assert!(tag.contains("type=\"Int64\""));
        assert_eq!(i64s(&b), vec![4, 8]);
        let (tag, b) = array(&xml, "types");
        assert!(tag.contains("type=\"UInt8\""));
        assert_eq!(b, vec![10, 10]);

        let (tag, b) = array(&xml, "temperature_K");
        assert!(tag.contains("type=\"Float64\"") && !tag.contains("NumberOfComponents"));
        assert_eq!(
            f64s(&b).iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
            temperature.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
        );
        let (tag, b) = array(&xml, "flux_W_m2");
        assert!(tag.contains("NumberOfComponents=\"3\""));
        assert_eq!(f64s(&b), [1.0, 2.0, 3.0].repeat(5));
        let (tag, b) = array(&xml, "region");
        assert!(tag.contains("type=\"Int32\""));
        let got: Vec<i32> = b.chunks(4).map(|c| i32::from_le_bytes(c.try_into().unwrap())).collect();
        assert_eq!(got, region);
        // Point data precedes Points, cell data is inside CellData.
        let pd = xml.find("<PointData>").unwrap();
        let cd = xml.find("<CellData>").unwrap();
        assert!(pd < xml.find("temperature_K").unwrap() && cd < xml.find("region").unwrap());
    }

    #[test]
    fn triangle_vtu_has_type_5_and_offsets_by_3() {
        let c = cube();
        let mut out = Vec::new();
        write_vtu(&mut out, &c.verts, Cells::Triangle(&c.tris), &[], &[]).unwrap();
        let xml = String::from_utf8(out).unwrap();
        assert!(!xml.contains("<PointData>") && !xml.contains("<CellData>"));
        assert_eq!(array(&xml, "types").1, vec![5u8; 12]);
        assert_eq!(i64s(&array(&xml, "offsets").1), (1..=12).map(|k| 3 * k).collect::<Vec<_>>());
        let conn: Vec<i64> = c.tris.iter().flatten().map(|&i| i as i64).collect();
        assert_eq!(i64s(&array(&xml, "connectivity").1), conn);
    }

    #[test]
    fn pvd_lists_time_steps() {
        let mut out = Vec::new();
        write_pvd(&mut out, &[(0.0, "frame_0000.vtu"), (0.25, "frame_0001.vtu")]).unwrap();
        let xml = String::from_utf8(out).unwrap();
        assert!(xml.contains("<VTKFile type=\"Collection\""));
        assert!(xml.contains("<DataSet timestep=\"0\" group=\"\" part=\"0\" file=\"frame_0000.vtu\"/>"));
        assert!(xml.contains("<DataSet timestep=\"0.25\" group=\"\" part=\"0\" file=\"frame_0001.vtu\"/>"));
    }

    /// meshio oracle (scripts/oracle/check_vtu.py) when the oracle venv exists: set
    /// HEATSIM_ORACLE_PYTHON, or create <workspace>/.venv with scripts/setup-oracles.sh.
    #[test]
    fn meshio_reads_what_we_write() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
        let python = std::env::var_os("HEATSIM_ORACLE_PYTHON")
            .map(PathBuf::from)
            .unwrap_or_else(|| root.join(".venv/bin/python"));
        if !python.exists() {
            eprintln!("meshio_reads_what_we_write: no oracle python at {python:?}; skipped");
            return;
        }
        let (pts, tets) = two_tets();
        let temperature = [1.0, 2.0, 3.0, 4.0, 5.5];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("two_tets.vtu");
        let mut f = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        write_vtu(
            &mut f,
            &pts,
            Cells::Tetra(&tets),
            &[("T", DataArray::F64(&temperature))],
            &[("region", DataArray::I32(&[1, 2]))],
        )
        .unwrap();
        drop(f);
        let out = std::process::Command::new(&python)
            .arg(root.join("scripts/oracle/check_vtu.py"))
            .arg(&path)
            .args(["--expect-points", "5", "--expect-cells", "tetra=2"])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "check_vtu.py failed: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(summary["points"], 5);
        assert_eq!(summary["cells"]["tetra"], 2);
        assert_eq!(summary["connectivity"]["tetra"], 16);
        assert_eq!(summary["sums"]["point:T"], 15.5);
        assert_eq!(summary["sums"]["cell:region"], 3.0);
        assert_eq!(summary["bounds"], serde_json::json!([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]));
    }
}
