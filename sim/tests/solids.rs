//! Solids of any thickness and their TetGen meshes: analytic volumes, mesh invariants,
//! grading, and the failures TetGen must not hide.

#[path = "support/shapes.rs"]
mod shapes;

use heatsim::mesh::error::MeshError;
use heatsim::mesh::tetmesh::{tet_signed_volume, FaceTag, TetMesh};
use heatsim::mesh::trimesh::TriMesh;
use heatsim::solid::{self, Facet, Grading, Plc, SolidError};
use heatsim::tetgen::{tetrahedralize, MeshingError, TetgenOptions};

fn grading(h: f64, fine: f64, deep: f64) -> Grading {
    Grading { surface_element_size: h, fine_layer_depth: fine, deep_element_size: deep }
}

fn mesh(s: &solid::Solid) -> TetMesh {
    TetMesh::from_tetgen(tetrahedralize(&s.plc, &TetgenOptions::default()).expect("TetGen succeeds"))
        .expect("valid mesh")
}

/// Positive tetrahedra, closed outward boundary, volume equal to the polyhedral solid's.
fn check(m: &TetMesh, solid_volume: f64) -> f64 {
    assert!(m.tets.iter().all(|t| tet_signed_volume(t.map(|i| m.verts[i])) > 0.0));
    let b = m.boundary_surface();
    b.check_closed_oriented().expect("closed, consistently oriented boundary");
    let v = m.volume();
    assert!((b.signed_volume() - v).abs() < 1e-9 * v, "boundary is not outward or not closed");
    // TetGen treats adjacent facets within its coplanarity tolerance (-T, 1e-8) as one plane
    // and may put Steiner points on it, so the mesh can differ from the curved polyhedron by
    // about 1e-7 of its volume.
    assert!(((v - solid_volume) / solid_volume).abs() < 1e-6, "mesh volume {v} vs solid {solid_volume}");
    v
}

#[test]
fn thin_plate_has_its_analytic_volume_and_tagged_faces() {
    let s = solid::cuboid(0.03, 0.02, 0.001, &grading(2e-3, 4e-3, 4e-3)).unwrap();
    let m = mesh(&s);
    let v = check(&m, s.volume);
    assert!((v - 0.03 * 0.02 * 0.001).abs() < 1e-6 * v);
    let st = m.stats();
    assert!((st.visible_area_m2 - 0.03 * 0.02).abs() < 1e-12, "visible area {}", st.visible_area_m2);
    // The visible face is z = 0 and faces +z; the back z = -d faces -z.
    let (vis, _) = m.tagged_surface(FaceTag::Visible);
    assert!(vis.verts.iter().all(|p| p[2] == 0.0));
    assert!((0..vis.tris.len()).all(|f| vis.face_normal(f)[2] > 0.999));
    let (back, _) = m.tagged_surface(FaceTag::Back);
    assert!(back.verts.iter().all(|p| (p[2] + 0.001).abs() < 1e-15));
    assert!((0..back.tris.len()).all(|f| back.face_normal(f)[2] < -0.999));
}

#[test]
fn hemisphere_shell_and_solid_volumes_within_half_a_percent() {
    for (r, d) in [(0.05_f64, 0.002_f64), (0.05, 0.02), (0.03, 0.03), (0.03, 1.0)] {
        let g = grading(2e-3, 4e-3, Grading::auto_deep_size(2e-3, d.min(r), r));
        let s = solid::hemisphere(r, d, &g).unwrap();
        let m = mesh(&s);
        let v = check(&m, s.volume);
        let a = s.analytic_volume.unwrap();
        assert!(((v - a) / a).abs() < 0.005, "R {r} d {d}: volume {v} vs analytic {a}");
    }
}

#[test]
fn grading_puts_small_tetrahedra_under_the_visible_surface() {
    let s = solid::cuboid(0.04, 0.04, 0.2, &grading(2e-3, 4e-3, 2e-2)).unwrap();
    let m = mesh(&s);
    check(&m, s.volume);
    let mean = |layer| {
        let v: Vec<f64> = m
            .tets
            .iter()
            .zip(&m.tet_region)
            .filter(|(_, &r)| r == layer)
            .map(|(t, _)| tet_signed_volume(t.map(|i| m.verts[i])))
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    assert!(mean(2) > 50.0 * mean(1), "fine {:e} deep {:e}", mean(1), mean(2));
    // Fine layer tetrahedra near the requested size (regular tetrahedron of edge 2 mm).
    assert!(mean(1) < heatsim::solid::plc::regular_tet_volume(2e-3));
}

/// An open spherical cap z = sqrt(R^2 - x^2 - y^2) - R0 over a disk, as a triangle soup.
fn cap(r: f64, rim: f64, n: usize) -> TriMesh {
    let mut verts = Vec::new();
    let mut idx = vec![vec![0usize; n + 1]; n + 1];
    for (i, row) in idx.iter_mut().enumerate() {
        for (j, slot) in row.iter_mut().enumerate() {
            let x = -rim + 2.0 * rim * i as f64 / n as f64;
            let y = -rim + 2.0 * rim * j as f64 / n as f64;
            *slot = verts.len();
            verts.push([x, y, (r * r - x * x - y * y).max(0.0).sqrt()]);
        }
    }
    let mut tris = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (a, b, c, d) = (idx[i][j], idx[i + 1][j], idx[i + 1][j + 1], idx[i][j + 1]);
            let inside = |k: usize| verts[k][0].powi(2) + verts[k][1].powi(2) <= rim * rim;
            if [a, b, c, d].iter().all(|&k| inside(k)) {
                tris.push([a, b, c]);
                tris.push([a, c, d]);
            }
        }
    }
    TriMesh { verts, tris }
}

#[test]
fn relief_of_an_open_cap_has_uniform_thickness() {
    let surface = solid::place_mesh(&cap(0.05, 0.03, 120), [0.0; 3], 0.06).unwrap();
    let d = 0.01;
    let s = solid::relief(&surface, d, 5e-4, 85.0, &grading(2e-3, 4e-3, 4e-3)).unwrap();
    let m = mesh(&s);
    check(&m, s.volume);
    // Every back node lies exactly d below the visible surface at the same (x, y).
    let (vis, _) = m.tagged_surface(FaceTag::Visible);
    let (back, _) = m.tagged_surface(FaceTag::Back);
    let top_at = |x: f64, y: f64| vis.verts.iter().find(|p| p[0] == x && p[1] == y).map(|p| p[2]);
    let mut matched = 0;
    for p in &back.verts {
        if let Some(z) = top_at(p[0], p[1]) {
            assert!((z - p[2] - d).abs() < 1e-12);
            matched += 1;
        }
    }
    assert!(matched > back.verts.len() / 2, "only {matched} of {} back nodes match", back.verts.len());
    // The visible surface follows the sphere (placed with its top at z = 0) within a raster step.
    let r = 0.05 * 0.06 / 0.06;
    for p in vis.verts.iter().filter(|p| p[0].hypot(p[1]) < 0.025) {
        let exact = (r * r - p[0] * p[0] - p[1] * p[1]).sqrt() - r;
        assert!((p[2] - exact).abs() < 1e-4, "height {} vs {exact} at {:?}", p[2], p);
    }
}

/// Two cubes that interpenetrate: the PLC is self-intersecting.
fn overlapping_cubes() -> Plc {
    let mut plc = Plc::default();
    for offset in [0.0, 0.5] {
        let base = plc.points.len();
        for z in [0.0, 1.0] {
            for (x, y) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
                plc.push_point([x + offset, y + offset, z + offset]);
            }
        }
        for f in [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]] {
            plc.facets.push(Facet { points: f.iter().map(|i| base + i).collect(), tag: FaceTag::Side });
        }
    }
    plc
}

#[test]
fn tetgen_self_intersection_is_an_error_not_an_empty_mesh() {
    // The known trap: TetGen throws status 3, tritet prints it and reports success with zero
    // points. We must surface the status.
    match tetrahedralize(&overlapping_cubes(), &TetgenOptions::default()) {
        Err(MeshingError::TetgenStatus { status: 3, meaning, .. }) => assert!(meaning.contains("self-intersecting")),
        other => panic!("expected TetGen status 3, got {other:?}"),
    }
}

#[test]
fn malformed_plc_is_caught_before_tetgen() {
    let mut plc = overlapping_cubes();
    plc.facets[0].points[0] = 1000;
    assert!(
        matches!(tetrahedralize(&plc, &TetgenOptions::default()), Err(MeshingError::InvalidPlc(m)) if m.contains("facet 0 references point 1000"))
    );
}

#[test]
fn closed_mesh_solid_meshes_and_bad_surfaces_are_refused() {
    let cube = shapes::cuboid(0.02, 0.02, 0.02);
    let s = solid::closed_mesh(&cube).unwrap();
    let opts = TetgenOptions { max_volume: Some(1e-8), ..TetgenOptions::default() };
    let m = TetMesh::from_tetgen(tetrahedralize(&s.plc, &opts).unwrap()).unwrap();
    check(&m, 8e-6);
    let mut open = cube.clone();
    open.tris.pop();
    assert!(
        matches!(solid::closed_mesh(&open), Err(SolidError::Mesh(e)) if matches!(e.root(), MeshError::Open { .. }))
    );
    let flipped = cube.flipped();
    assert!(
        matches!(solid::closed_mesh(&flipped), Err(SolidError::Mesh(e)) if matches!(e.root(), MeshError::InsideOut { .. }))
    );
}

#[test]
fn nonpositive_sizes_are_refused_with_the_field_name() {
    let g = grading(2e-3, 4e-3, 4e-3);
    let e = solid::cuboid(0.05, 0.05, -0.01, &g).unwrap_err().to_string();
    assert_eq!(e, "object.thickness: must be > 0 m, got -0.01");
    let e = solid::hemisphere(0.0, 0.01, &g).unwrap_err().to_string();
    assert_eq!(e, "object.radius: must be > 0 m, got 0");
}
