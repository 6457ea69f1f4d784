//! Criterion bench of `heatrecon::eval::evaluate` (issue 9 target: a 10^5-vertex
//! reconstruction against the bunny within 2 s).
//!
//! Ground truth: the Stanford bunny (34,835 vertices) scaled to 10 cm. Reconstruction: the same
//! surface subdivided once at edge midpoints (139,473 vertices, more than the target's 10^5),
//! each vertex moved along the z axis by a deterministic pseudo-random amount in [-0.5, 0.5] mm,
//! then rotated by 5 degrees and shifted by 3 mm. Timed: the whole rigid evaluation (ICP from
//! all starts, forward/reverse distances over vertices and area samples, normals). The inputs
//! are also written to `target/eval-bench/` for timing the command end to end:
//! `simbench eval --recon target/eval-bench/recon.ply --gt target/eval-bench/bunny.obj`.

use criterion::{criterion_group, criterion_main, Criterion};
use heatrecon::eval::{evaluate, AlignMode, EvalOptions};
use heatsim::mesh::TriMesh;
use std::collections::HashMap;
use std::path::Path;

fn subdivide(m: &TriMesh) -> TriMesh {
    let mut verts = m.verts.clone();
    let mut mid: HashMap<(usize, usize), usize> = HashMap::new();
    let mut tris = Vec::with_capacity(m.tris.len() * 4);
    for t in &m.tris {
        let mut e = [0usize; 3];
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            e[k] = *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let p = [0, 1, 2].map(|d| 0.5 * (m.verts[a][d] + m.verts[b][d]));
                verts.push(p);
                verts.len() - 1
            });
        }
        tris.extend([[t[0], e[0], e[2]], [t[1], e[1], e[0]], [t[2], e[2], e[1]], [e[0], e[1], e[2]]]);
    }
    TriMesh::try_new(verts, tris).expect("subdivided mesh")
}

fn bench_eval(c: &mut Criterion) {
    let path = heatsim::assets::bunny_path(None).expect("the Stanford bunny (scripts/fetch-bunny.sh)");
    let raw = heatsim::mesh::read_surface(&path).expect("reading the bunny");
    let (lo, hi) = raw.bounding_box();
    let extent = (0..3).map(|d| hi[d] - lo[d]).fold(0.0, f64::max);
    let s = 0.1 / extent;
    let gt = raw.transformed(|p| p.map(|x| x * s));
    let (c5, s5) = (5f64.to_radians().cos(), 5f64.to_radians().sin());
    let recon = {
        let sub = subdivide(&gt);
        let verts = sub
            .verts
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let h = ((i as f64 * 12.9898).sin() * 43758.5453).fract().abs() - 0.5; // [-0.5, 0.5)
                let z = p[2] + 1e-3 * h;
                [c5 * p[0] - s5 * p[1] + 0.003, s5 * p[0] + c5 * p[1], z]
            })
            .collect();
        TriMesh::try_new(verts, sub.tris).expect("recon")
    };
    eprintln!(
        "ground truth {} vertices / {} triangles; reconstruction {} vertices / {} triangles",
        gt.verts.len(),
        gt.tris.len(),
        recon.verts.len(),
        recon.tris.len()
    );
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/eval-bench");
    if std::fs::create_dir_all(&out).is_ok() {
        let _ = heatsim::mesh::write_ply(&out.join("recon.ply"), &recon, &[], "eval bench reconstruction");
        let _ = heatsim::mesh::write_obj(&out.join("bunny.obj"), &gt, "bunny scaled to 10 cm");
    }
    let opts = EvalOptions { align: AlignMode::Rigid, ..EvalOptions::default() };
    let e = evaluate(&recon, &gt, &opts).expect("evaluate");
    eprintln!(
        "mae {:.4} mm, symmetric {:.4} mm, rotation found {:.4} deg",
        e.mae_mm(),
        e.symmetric_mm(),
        e.alignment.transform.angle_deg()
    );
    let mut group = c.benchmark_group("eval");
    group.sample_size(10);
    group.bench_function("bunny_139k_vertex_recon_rigid", |b| b.iter(|| evaluate(&recon, &gt, &opts).unwrap()));
    group.finish();
}

criterion_group!(benches, bench_eval);
criterion_main!(benches);
