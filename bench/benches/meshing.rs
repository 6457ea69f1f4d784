//! Criterion benches of the meshing pipeline, by phase and size:
//! solid construction (Triangle + PLC), TetGen (in its child process), and mesh assembly
//! (orientation, boundary extraction, statistics).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use heatsim::mesh::tetmesh::TetMesh;
use heatsim::solid::{cuboid, Grading};
use heatsim::tetgen::{tetrahedralize, TetgenOptions};

fn grading(h: f64) -> Grading {
    Grading { surface_element_size: h, fine_layer_depth: 4e-3, deep_element_size: 1e-2 }
}

fn bench_cuboid(c: &mut Criterion) {
    let mut group = c.benchmark_group("cuboid_5cm_x_5cm_x_2cm");
    group.sample_size(10);
    for h in [4e-3, 2e-3] {
        let g = grading(h);
        group
            .bench_with_input(BenchmarkId::new("solid", h), &g, |b, g| b.iter(|| cuboid(0.05, 0.05, 0.02, g).unwrap()));
        let solid = cuboid(0.05, 0.05, 0.02, &g).unwrap();
        let opts = TetgenOptions::default();
        group.bench_with_input(BenchmarkId::new("tetgen", h), &solid, |b, s| {
            b.iter(|| tetrahedralize(&s.plc, &opts).unwrap())
        });
        let out = tetrahedralize(&solid.plc, &opts).unwrap();
        group.bench_with_input(BenchmarkId::new("assemble_and_stats", h), &out, |b, o| {
            b.iter(|| TetMesh::from_tetgen(o.clone()).unwrap().stats())
        });
    }
    group.finish();
}

criterion_group!(benches, bench_cuboid);
criterion_main!(benches);
