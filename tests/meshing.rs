//! End to end: scene files -> solids -> TetGen meshes, checked against analytic volumes and
//! mesh invariants. These run in release mode in CI (`scripts/test.sh`).

use heat_e2e::{bunny, check_tet_mesh, scene};
use heatsim::meshing::mesh_scene;
use heatsim::scene::{Construction, ObjectSpec};

#[test]
fn shipped_cuboid_meshes_with_its_analytic_volume() {
    let s = scene("cuboid.json");
    let m = mesh_scene(&s, None).expect("cuboid meshes");
    let v = check_tet_mesh(&m.mesh);
    let analytic = m.report.analytic_volume_m3.unwrap();
    assert!(((v - analytic) / analytic).abs() < 0.005, "volume {v} vs {analytic}");
    assert!(m.report.stats.visible_faces > 0 && m.report.stats.back_faces > 0 && m.report.stats.side_faces > 0);
}

#[test]
fn shipped_hemisphere_shell_meshes_within_half_a_percent() {
    let s = scene("hemisphere.json");
    let m = mesh_scene(&s, None).expect("hemisphere meshes");
    let v = check_tet_mesh(&m.mesh);
    let analytic = m.report.analytic_volume_m3.unwrap();
    let err = (v - analytic) / analytic;
    assert!(err.abs() < 0.005, "volume {v} vs {analytic} ({:.3} %)", 100.0 * err);
}

#[test]
fn shipped_bunny_meshes() {
    bunny();
    let s = scene("bunny.json");
    let m = mesh_scene(&s, None).expect("bunny meshes");
    let v = check_tet_mesh(&m.mesh);
    assert!(
        ((v - m.report.solid_volume_m3) / m.report.solid_volume_m3).abs() < 1e-6,
        "TetGen's coplanarity tolerance allows ~1e-7"
    );
}

fn bunny_at(thickness: f64) -> heatsim::meshing::MeshedObject {
    bunny();
    let mut s = scene("bunny.json");
    match &mut s.object {
        ObjectSpec::Bunny(b) => {
            b.thickness = Some(thickness);
            b.construction = Construction::Relief;
        }
        other => panic!("bunny.json holds a {} object", other.kind()),
    }
    mesh_scene(&s, None).unwrap_or_else(|e| panic!("bunny at {thickness} m: {e}"))
}

#[test]
fn bunny_relief_meshes_at_1_cm() {
    let m = bunny_at(0.01);
    let v = check_tet_mesh(&m.mesh);
    // Uniform thickness: volume = silhouette area x thickness, exactly for the polyhedron.
    assert!(
        ((v - m.report.solid_volume_m3) / m.report.solid_volume_m3).abs() < 1e-6,
        "TetGen's coplanarity tolerance allows ~1e-7"
    );
    assert!(m.report.stats.min_dihedral_deg > 0.5);
}

#[test]
fn bunny_relief_meshes_at_20_cm() {
    let m = bunny_at(0.20);
    let v = check_tet_mesh(&m.mesh);
    assert!(
        ((v - m.report.solid_volume_m3) / m.report.solid_volume_m3).abs() < 1e-6,
        "TetGen's coplanarity tolerance allows ~1e-7"
    );
    // The visible surface is the same at 1 cm and 20 cm: only depth is added.
    assert!(m.report.stats.tetrahedra < 400_000, "{} tetrahedra", m.report.stats.tetrahedra);
}

#[test]
fn one_metre_cuboid_stays_graded() {
    let mut s = scene("cuboid.json");
    match &mut s.object {
        ObjectSpec::Cuboid(c) => c.thickness = 1.0,
        other => panic!("cuboid.json holds a {} object", other.kind()),
    }
    let m = mesh_scene(&s, None).expect("1 m cuboid meshes");
    let v = check_tet_mesh(&m.mesh);
    let analytic = m.report.analytic_volume_m3.unwrap();
    assert!(((v - analytic) / analytic).abs() < 0.005);
    let tets = m.report.stats.tetrahedra;
    assert!(tets < 300_000, "a 1 m cuboid took {tets} tetrahedra");
    // Grading: tetrahedra deep inside are far larger than those under the visible surface.
    let mean_volume = |layer: i32| {
        let vols: Vec<f64> = m
            .mesh
            .tets
            .iter()
            .zip(&m.mesh.tet_region)
            .filter(|(_, &r)| r == layer)
            .map(|(t, _)| heatsim::mesh::tetmesh::tet_signed_volume(t.map(|i| m.mesh.verts[i])))
            .collect();
        vols.iter().sum::<f64>() / vols.len() as f64
    };
    let (fine, deep) = (mean_volume(1), mean_volume(2));
    assert!(deep > 100.0 * fine, "mean tetrahedron volume: fine layer {fine:e}, deep {deep:e} m^3");
}
