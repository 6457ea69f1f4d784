//! Closed triangle meshes of the shapes users bring, for the meshing property tests: boxes,
//! cylinders, cones, tori, smooth random height-field blocks, and several of them side by
//! side. Every mesh is closed, outward (counter-clockwise seen from outside) and centred near
//! the origin with an extent of about 1 (unitless: the tests scale them with `place_mesh`).

#![allow(dead_code)] // each test binary uses a different subset

use heatsim::mesh::trimesh::TriMesh;
use rand::{Rng, SeedableRng};
use std::f64::consts::TAU;

/// A box of sides `a` x `b` x `c` centred at the origin.
pub fn cuboid(a: f64, b: f64, c: f64) -> TriMesh {
    let (x, y, z) = (a / 2.0, b / 2.0, c / 2.0);
    let verts =
        vec![[-x, -y, -z], [x, -y, -z], [x, y, -z], [-x, y, -z], [-x, -y, z], [x, -y, z], [x, y, z], [-x, y, z]];
    let tris = vec![
        [0, 2, 1],
        [0, 3, 2],
        [4, 5, 6],
        [4, 6, 7],
        [0, 1, 5],
        [0, 5, 4],
        [1, 2, 6],
        [1, 6, 5],
        [2, 3, 7],
        [2, 7, 6],
        [3, 0, 4],
        [3, 4, 7],
    ];
    TriMesh { verts, tris }
}

/// The surface of revolution about z of `profile`: (r, z) points from the bottom pole (r = 0)
/// to the top pole (r = 0), with `segments` around.
pub fn revolve(profile: &[(f64, f64)], segments: usize) -> TriMesh {
    let n = profile.len();
    assert!(n >= 3 && profile[0].0 == 0.0 && profile[n - 1].0 == 0.0);
    let mut verts = vec![[0.0, 0.0, profile[0].1]];
    for &(r, z) in &profile[1..n - 1] {
        for s in 0..segments {
            let a = TAU * s as f64 / segments as f64;
            verts.push([r * a.cos(), r * a.sin(), z]);
        }
    }
    verts.push([0.0, 0.0, profile[n - 1].1]);
    let top = verts.len() - 1;
    let ring = |k: usize, s: usize| 1 + k * segments + s % segments;
    let mut tris = Vec::new();
    for s in 0..segments {
        tris.push([0, ring(0, s + 1), ring(0, s)]);
        for k in 0..n - 3 {
            let (a, b, c, d) = (ring(k, s), ring(k, s + 1), ring(k + 1, s + 1), ring(k + 1, s));
            tris.push([a, b, c]);
            tris.push([a, c, d]);
        }
        tris.push([top, ring(n - 3, s), ring(n - 3, s + 1)]);
    }
    TriMesh { verts, tris }
}

/// A closed cylinder of radius `r` and height `h`.
pub fn cylinder(r: f64, h: f64, segments: usize) -> TriMesh {
    revolve(&[(0.0, -h / 2.0), (r, -h / 2.0), (r, h / 2.0), (0.0, h / 2.0)], segments)
}

/// A cone of base radius `r` and height `h`, with its base.
pub fn cone(r: f64, h: f64, segments: usize) -> TriMesh {
    revolve(&[(0.0, -h / 2.0), (r, -h / 2.0), (0.0, h / 2.0)], segments)
}

/// A torus of major radius `big` and tube radius `small` about z.
pub fn torus(big: f64, small: f64, nu: usize, nv: usize) -> TriMesh {
    let mut verts = Vec::new();
    for i in 0..nu {
        let u = TAU * i as f64 / nu as f64;
        for j in 0..nv {
            let v = TAU * j as f64 / nv as f64;
            let r = big + small * v.cos();
            verts.push([r * u.cos(), r * u.sin(), small * v.sin()]);
        }
    }
    let at = |i: usize, j: usize| (i % nu) * nv + j % nv;
    let mut tris = Vec::new();
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            tris.push([a, b, c]);
            tris.push([a, c, d]);
        }
    }
    TriMesh { verts, tris }
}

/// A block over [-1/2, 1/2]^2 whose top is a smooth random height field (a few low Fourier
/// modes, |z| at most `amplitude`) above a flat bottom at z = -(`amplitude` + `depth`).
pub fn height_field(rng: &mut impl Rng, amplitude: f64, depth: f64, n: usize) -> TriMesh {
    let modes: Vec<[f64; 4]> = (0..4)
        .map(|_| {
            [
                rng.random_range(0.5..3.0),
                rng.random_range(0.5..3.0),
                rng.random_range(0.0..TAU),
                rng.random_range(-1.0..1.0),
            ]
        })
        .collect();
    let f = |x: f64, y: f64| {
        amplitude * modes.iter().map(|m| m[3] * (TAU * (m[0] * x + m[1] * y) / 2.0 + m[2]).sin()).sum::<f64>() / 4.0
    };
    let idx = |i: usize, j: usize, top: bool| 2 * (j * (n + 1) + i) + usize::from(top);
    let mut verts = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f64 / n as f64 - 0.5, j as f64 / n as f64 - 0.5);
            verts.push([x, y, -(amplitude + depth)]);
            verts.push([x, y, f(x, y)]);
        }
    }
    let mut tris = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let q = |top| [idx(i, j, top), idx(i + 1, j, top), idx(i + 1, j + 1, top), idx(i, j + 1, top)];
            let [a, b, c, d] = q(true);
            tris.extend([[a, b, c], [a, c, d]]);
            let [a, b, c, d] = q(false);
            tris.extend([[a, c, b], [a, d, c]]);
        }
    }
    // Side walls: walk the boundary counter-clockwise seen from +z.
    let mut boundary: Vec<(usize, usize)> = (0..n).map(|i| (i, 0)).collect();
    boundary.extend((0..n).map(|j| (n, j)));
    boundary.extend((0..n).map(|i| (n - i, n)));
    boundary.extend((0..n).map(|j| (0, n - j)));
    for k in 0..boundary.len() {
        let (p, q) = (boundary[k], boundary[(k + 1) % boundary.len()]);
        let (a, b) = (idx(p.0, p.1, false), idx(q.0, q.1, false));
        let (c, d) = (idx(q.0, q.1, true), idx(p.0, p.1, true));
        tris.extend([[a, b, c], [a, c, d]]);
    }
    TriMesh { verts, tris }
}

/// `meshes` side by side along x with gaps of `gap` between their bounding boxes.
pub fn side_by_side(meshes: &[TriMesh], gap: f64) -> TriMesh {
    let mut out = TriMesh { verts: Vec::new(), tris: Vec::new() };
    let mut x = 0.0;
    for m in meshes {
        let (lo, hi) = m.bounding_box();
        let base = out.verts.len();
        out.verts.extend(m.verts.iter().map(|p| [p[0] - lo[0] + x, p[1], p[2]]));
        out.tris.extend(m.tris.iter().map(|t| t.map(|i| i + base)));
        x += hi[0] - lo[0] + gap;
    }
    out
}

/// One random shape of the family and its name.
pub fn random_shape(rng: &mut impl Rng) -> (String, TriMesh) {
    let kind = rng.random_range(0..6);
    let single = |rng: &mut dyn rand::RngCore, kind: usize| -> (String, TriMesh) {
        let mut u = |lo: f64, hi: f64| lo + (hi - lo) * (rng.next_u32() as f64 / u32::MAX as f64);
        match kind {
            0 => {
                let (a, b, c) = (u(0.2, 1.0), u(0.2, 1.0), u(0.05, 1.0));
                (format!("box {a:.3} x {b:.3} x {c:.3}"), cuboid(a, b, c))
            }
            1 => {
                let (r, h, s) = (u(0.1, 0.5), u(0.05, 1.0), u(6.0, 64.0) as usize);
                (format!("cylinder r {r:.3} h {h:.3}, {s} segments"), cylinder(r, h, s))
            }
            2 => {
                let (r, h, s) = (u(0.1, 0.5), u(0.1, 1.0), u(6.0, 64.0) as usize);
                (format!("cone r {r:.3} h {h:.3}, {s} segments"), cone(r, h, s))
            }
            3 => {
                let (big, small) = (u(0.25, 0.5), u(0.06, 0.2));
                let (nu, nv) = (u(12.0, 48.0) as usize, u(6.0, 24.0) as usize);
                (format!("torus {big:.3} / {small:.3}, {nu} x {nv}"), torus(big, small, nu, nv))
            }
            _ => {
                let (amp, depth) = (u(0.02, 0.3), u(0.05, 0.5));
                let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(rng.next_u64());
                (format!("height field amplitude {amp:.3} depth {depth:.3}"), height_field(&mut r, amp, depth, 16))
            }
        }
    };
    if kind < 5 {
        single(rng, kind)
    } else {
        let n = rng.random_range(2..=3);
        let gap = rng.random_range(0.05..0.3);
        let parts: Vec<(String, TriMesh)> = (0..n)
            .map(|_| {
                let kind = rng.random_range(0..5);
                single(rng, kind)
            })
            .collect();
        let names: Vec<&str> = parts.iter().map(|p| p.0.as_str()).collect();
        let meshes: Vec<TriMesh> = parts.iter().map(|p| p.1.clone()).collect();
        (format!("{n} parts {gap:.3} apart: {}", names.join("; ")), side_by_side(&meshes, gap))
    }
}
