//! Criterion benches of the volumetric solver by phase, on (a) a cuboid of about 1e5
//! tetrahedra and (b) the bunny relief at 1 cm thickness: assembly, symbolic plus numeric
//! factorisation, one forward and backward substitution, one time step; and, with
//! HEATSIM_BENCH_LONG=1, a whole 15 s run (1000 steps). `simbench bench-solver` prints the same
//! phases and their ratios from one run.

use criterion::{criterion_group, criterion_main, Criterion};
use heatsim::fem::history::History;
use heatsim::fem::volumetric::{HeatSystem, Stepper};
use heatsim::mesh::tetmesh::{FaceTag, TetMesh};
use heatsim::scene::Scene;
use heatsim::simulate::{exposed_faces, physics_from_scene, simulate_volumetric, uniform_load};
use std::path::Path;

fn scene(name: &str) -> Scene {
    Scene::from_file(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(name)).unwrap()
}

fn cases() -> Vec<(&'static str, Scene, TetMesh)> {
    let mut cuboid = scene("cuboid.json");
    cuboid.meshing.surface_element_size = 1.4e-3; // about 1.07e5 tetrahedra
    let mut bunny = scene("bunny.json");
    bunny.object.set_thickness(0.01);
    // The benches time heating by a uniform flux, so replace the point lamps.
    for s in [&mut cuboid, &mut bunny] {
        s.lamps = scene("cuboid.json").lamps;
    }
    [("cuboid_1e5_tets", cuboid), ("bunny_1cm", bunny)]
        .into_iter()
        .map(|(name, s)| {
            let mesh = heatsim::meshing::mesh_scene(&s, None).expect("meshing").mesh;
            (name, s, mesh)
        })
        .collect()
}

fn bench_solver(c: &mut Criterion) {
    for (name, scene, mesh) in cases() {
        let mut group = c.benchmark_group(format!("volumetric/{name}"));
        group.sample_size(10);
        let exposed = exposed_faces(&mesh, scene.environment.back_boundary);
        let phys = physics_from_scene(&scene).unwrap();
        group.bench_function("assembly", |b| b.iter(|| HeatSystem::assemble(&mesh, phys.clone(), &exposed).unwrap()));
        let system = HeatSystem::assemble(&mesh, phys.clone(), &exposed).unwrap();
        let n = system.len();
        let t_ref = vec![phys.ambient_temperature; n];
        let dt = scene.timing.time_step;
        group.bench_function("factorisation", |b| b.iter(|| Stepper::new(&system, dt, 1e-9, 25, &t_ref).unwrap()));
        let mut stepper = Stepper::new(&system, dt, 1e-9, 25, &t_ref).unwrap();
        let mut rhs = vec![1.0; n];
        group.bench_function("substitution", |b| b.iter(|| stepper.substitute(&mut rhs)));
        let load = uniform_load(&mesh, FaceTag::Visible, 95.0);
        let (mut history, mut new) = (stepper.history(&t_ref), t_ref.clone());
        group.bench_function("step", |b| {
            b.iter(|| {
                history.predict(&mut new);
                stepper.step(&system, history.latest(), &load, &mut new).unwrap();
                history.push(&new);
            })
        });
        if std::env::var_os("HEATSIM_BENCH_LONG").is_some() {
            group.bench_function("run_15s", |b| b.iter(|| simulate_volumetric(&scene, &mesh, |_, _| {}).unwrap()));
        }
        group.finish();
    }
}

criterion_group!(benches, bench_solver);
criterion_main!(benches);
