//! Walls meshed in prism layers (`heatsim::mesh::layered`) against closed forms: a plate under
//! a constant flux reproduces the 1D slab (Carslaw & Jaeger) at its face and converges with
//! second order in the layers, equal or graded; hollow shells built from scenes have the
//! volume of the analytic shell and their cavity tagged; a wall too thick for its object is
//! refused naming the field.
//!
//! `cargo test --release -p heatsim --test layered_wall -- --nocapture` prints the errors.

mod support;

use heatsim::fem::volumetric::{HeatSystem, Physics, Stepper};
use heatsim::mesh::layered::{layered_wall, Layering};
use heatsim::mesh::tetmesh::FaceTag;
use heatsim::mesh::TriMesh;
use heatsim::meshing::{mesh_scene, BuildError};
use heatsim::scene::Scene;
use support::*;

/// PLA (k 0.13 W/(m K), rho c_p 1240 x 1800 J/(m^3 K)): a 2 mm wall has l^2 / alpha = 69 s,
/// so 0.5 to 20 s spans the early, semi-infinite regime to the heat reaching the back.
const K: f64 = 0.13;
const RC: f64 = 1240.0 * 1800.0;
const WALL: f64 = 2e-3;
const Q: f64 = 400.0;

/// A flat 6 x 6 mm square in z = 0 facing +z, `n` x `n` cells of two triangles.
fn plate(n: usize) -> TriMesh {
    let h = 6e-3 / n as f64;
    let verts = (0..=n).flat_map(|j| (0..=n).map(move |i| [i as f64 * h - 3e-3, j as f64 * h - 3e-3, 0.0])).collect();
    let v = |i: usize, j: usize| j * (n + 1) + i;
    let tris = (0..n)
        .flat_map(|j| {
            (0..n).flat_map(move |i| [[v(i, j), v(i + 1, j), v(i + 1, j + 1)], [v(i, j), v(i + 1, j + 1), v(i, j + 1)]])
        })
        .collect();
    TriMesh { verts, tris }
}

/// Largest error of the front-face temperature (K) at t = 0.5, 2, 5, 20 s of an insulated plate
/// of `layers` layers (innermost `ratio` times the outermost) under the flux Q, BDF2 at 20 ms.
fn front_face_error(layers: usize, ratio: f64) -> f64 {
    let surface = plate(3);
    let normals = vec![[0.0, 0.0, 1.0]; surface.verts.len()];
    let layering = Layering { thickness: WALL, layers, ratio, inner_tag: FaceTag::Back, rim_tag: FaceTag::Side };
    let mesh = layered_wall(&surface, &normals, &layering).unwrap();
    let t0 = 300.0;
    let physics = Physics {
        conductivity: K,
        volumetric_heat_capacity: RC,
        emissivity: 0.0,
        convection_coefficient: 0.0,
        ambient_temperature: t0,
        lumped_mass: false,
        linearized_radiation: false,
    };
    let system = HeatSystem::assemble(&mesh, physics, &vec![false; mesh.boundary.len()]).unwrap();
    let load = face_load(&mesh, FaceTag::Visible, Q);
    let dt = 0.02;
    let mut t = vec![t0; mesh.verts.len()];
    let integrator = heatsim::fem::volumetric::TimeIntegrator::Bdf2;
    let mut stepper = Stepper::with_integrator(&system, dt, integrator, 1e-10, 25, &t).unwrap();
    let front: Vec<usize> = (0..surface.verts.len()).collect();
    let (mut done, mut prev, mut worst) = (0, None, 0.0_f64);
    for time in [0.5, 2.0, 5.0, 20.0] {
        let target = (time / dt).round() as usize;
        let (_, p) = march(&system, &mut stepper, &mut t, prev.take(), &load, target - done, |_, _, _| {}).unwrap();
        prev = Some(p);
        done = target;
        let exact = t0 + slab_rise(Q, K, K / RC, WALL, 0.0, time);
        for &i in &front {
            worst = worst.max((t[i] - exact).abs());
        }
    }
    worst
}

#[test]
fn a_layered_plate_is_the_slab_and_converges_with_second_order() {
    for ratio in [1.0, 4.0] {
        let errors: Vec<f64> = [4, 8, 16].iter().map(|&n| front_face_error(n, ratio)).collect();
        let orders: Vec<f64> = errors.windows(2).map(|w| (w[0] / w[1]).log2()).collect();
        eprintln!(
            "layered plate, ratio {ratio}: front-face errors {errors:.3?} K at 4, 8, 16 layers; orders {orders:.2?}"
        );
        // Measured: 1.3 mK (equal layers) and 0.4 mK (ratio 4) at 16 layers, a 3.8 K rise.
        assert!(errors[2] < 2e-3, "16 layers: {} K", errors[2]);
        assert!(orders[1] > 1.7, "order {orders:?}");
    }
    // Graded layers resolve the early front better than equal ones at the same count.
    assert!(front_face_error(8, 4.0) < front_face_error(8, 1.0));
}

fn shell_scene(dir: &std::path::Path, thickness: f64) -> Scene {
    shell_scene_with(dir, thickness, 0.004)
}

fn shell_scene_with(dir: &std::path::Path, thickness: f64, element: f64) -> Scene {
    let obj = dir.join("sphere.obj");
    heatsim::mesh::write_obj(&obj, &icosphere(4, 1.0), "unit icosphere").unwrap();
    let json = serde_json::json!({
        "object": { "kind": "mesh", "file": obj, "size": 0.06, "thickness": thickness, "construction": "shell" },
        "material": { "name": "pmma" },
        "meshing": { "surface_element_size": element, "wall_layers": 4 },
        "lamps": [{ "kind": "point", "power": 100.0, "position": [0.0, 0.0, 0.3] }],
    });
    Scene::from_json_str(&json.to_string(), dir).unwrap()
}

#[test]
fn a_hollow_sphere_has_the_shell_volume_and_a_cavity() {
    let dir = tempfile::tempdir().unwrap();
    let d = 2e-3;
    let m = mesh_scene(&shell_scene(dir.path(), d), None).unwrap();
    let (r, s) = (0.03_f64, m.mesh.stats());
    let analytic = 4.0 / 3.0 * std::f64::consts::PI * (r.powi(3) - (r - d).powi(3));
    // The polyhedron inscribed in the sphere: its area and enclosed volume are below the
    // sphere's by about the squared edge over the squared radius.
    let rel = (s.volume_m3 - analytic) / analytic;
    eprintln!(
        "hollow sphere: {} tetrahedra, volume {:.6e} m^3, {rel:.2e} from the analytic shell",
        s.tetrahedra, s.volume_m3
    );
    assert!(rel < 0.0 && rel > -0.02, "{rel}");
    assert!((s.boundary_volume_m3 - s.volume_m3).abs() < 1e-12 * s.volume_m3, "the mesh does not conform");
    assert_eq!(s.cavity_faces, s.visible_faces + s.back_faces, "every outer face has its cavity face");
    assert_eq!(s.side_faces, 0);
    assert_eq!(m.report.wall_layers, Some(4));
    assert!(m.solid.is_none());
}

#[test]
fn a_wall_thicker_than_the_object_is_refused_naming_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let e = mesh_scene(&shell_scene(dir.path(), 0.035), None).err().expect("a 35 mm wall in a 30 mm sphere");
    assert!(matches!(&e, BuildError::MeshFile { .. }), "{e}");
    let msg = format!("{e}");
    assert!(msg.contains("sphere.obj") && msg.contains("object.thickness"), "{msg}");
}

#[test]
fn a_surface_split_past_the_tetrahedra_limit_is_refused_before_it_is_made() {
    let dir = tempfile::tempdir().unwrap();
    let e = mesh_scene(&shell_scene_with(dir.path(), 2e-3, 1e-6), None).err().expect("1 um elements on a 6 cm sphere");
    assert!(format!("{e}").contains("meshing.max_tetrahedra"), "{e}");
}

#[test]
fn a_layered_hemisphere_has_the_analytic_volume() {
    let json = serde_json::json!({
        "object": { "kind": "hemisphere", "radius": 0.05, "thickness": 1e-3 },
        "material": { "name": "pla" },
        "meshing": { "surface_element_size": 0.002, "wall_layers": 3 },
        "lamps": [{ "kind": "point", "power": 100.0, "position": [0.0, 0.0, 0.3] }],
    });
    let scene = Scene::from_json_str(&json.to_string(), std::path::Path::new(".")).unwrap();
    let m = mesh_scene(&scene, None).unwrap();
    let rel = m.report.volume_rel_error_vs_analytic.unwrap();
    eprintln!("layered hemisphere: {} tetrahedra, {rel:.2e} from the analytic volume", m.mesh.tets.len());
    assert!(rel < 0.0 && rel > -2e-3, "{rel}");
    assert_eq!(m.report.stats.tets_per_layer.len(), 3);
    // The dome and the inside face the camera and away from it; the base ring is back.
    assert!(m.report.stats.visible_faces > 0 && m.report.stats.cavity_faces == 0 && m.report.stats.side_faces == 0);
}
