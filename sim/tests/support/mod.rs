//! Shared helpers of the solver tests: a structured box mesh, a tetrahedron quadrature for L2
//! norms, face loads, a time-marching loop and the closed-form solutions the tests compare
//! against. SI units throughout (m, s, K, W).

#![allow(dead_code)] // each test binary uses a different subset

use heatsim::fem::element::{tri_area, tri_flux_load};
use heatsim::fem::volumetric::{HeatSystem, SolverError, StepInfo, Stepper};
use heatsim::mesh::tetmesh::{FaceTag, TetMesh};
use heatsim::mesh::trimesh::TriMesh;
use heatsim::tetgen::TetgenOutput;

// ---------------------------------------------------------------------------------------------
// Structured box mesh

/// Index of grid node (i, j, k), i in 0..=nx, j in 0..=ny, k in 0..=nz, in [`box_mesh`]'s
/// node order (x fastest, then y, then z; k = 0 is the back z = -lz, k = nz the visible z = 0).
pub fn box_node(nx: usize, ny: usize, i: usize, j: usize, k: usize) -> usize {
    i + (nx + 1) * (j + (ny + 1) * k)
}

/// A structured tetrahedral mesh of the box x in [0, lx], y in [0, ly], z in [-lz, 0] (m) with
/// nx x ny x nz hexahedral cells, each split into 6 tetrahedra.
///
/// Split: the Kuhn (Freudenthal) split of each cell along a main diagonal, i.e. one
/// tetrahedron per ordering of the three axes, {u : u_a >= u_b >= u_c} in local cell
/// coordinates u in [0, 1]^3. The local x axis of cell (i, j, k) is reversed when
/// 2 i >= nx, the local y axis when 2 j >= ny (z never): the diagonals point away from the
/// box's vertical mid-planes. Why: a reversal along one axis leaves the face diagonals of the
/// faces normal to that axis unchanged and reverses those of the faces parallel to it, and
/// since the reversal of x depends on i only (and of y on j only), neighbouring cells always
/// agree on their shared face: the mesh is conforming. With even nx and ny it is also
/// mirror-symmetric under x -> lx - x and y -> ly - y (the plain Kuhn split is not), which the
/// symmetry test needs; the 1D and lumped tests do not care which split is used.
///
/// Built through [`TetMesh::from_tetgen`], which orients every tetrahedron positively and
/// extracts the outward boundary. Tags: z = 0 -> Visible, z = -lz -> Back, others Side.
pub fn box_mesh(nx: usize, ny: usize, nz: usize, lx: f64, ly: f64, lz: f64) -> TetMesh {
    box_mesh_split(nx, ny, nz, lx, ly, lz, true)
}

/// [`box_mesh`] with the choice of split: `mirrored` as documented there, or (false) the plain
/// Kuhn split with every cell's diagonal from its (x, y, z)-smallest corner, which is
/// conforming but not mirror-symmetric (the negative control of the symmetry test).
pub fn box_mesh_split(nx: usize, ny: usize, nz: usize, lx: f64, ly: f64, lz: f64, mirrored: bool) -> TetMesh {
    assert!(nx >= 1 && ny >= 1 && nz >= 1, "box_mesh needs at least one cell per axis");
    let mut points = Vec::with_capacity((nx + 1) * (ny + 1) * (nz + 1));
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                // Written so that the faces land exactly on 0, lx, ly, -lz, 0.
                points.push([
                    lx * (i as f64 / nx as f64),
                    ly * (j as f64 / ny as f64),
                    -lz * ((nz - k) as f64 / nz as f64),
                ]);
            }
        }
    }
    const ORDERS: [[usize; 3]; 6] = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];
    let mut tets = Vec::with_capacity(6 * nx * ny * nz);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let flip = [mirrored && 2 * i >= nx, mirrored && 2 * j >= ny, false];
                // Global node of the local corner with bits b (0 or 1 along x, y, z).
                let corner = |b: [usize; 3]| {
                    let l = |axis: usize| if flip[axis] { 1 - b[axis] } else { b[axis] };
                    box_node(nx, ny, i + l(0), j + l(1), k + l(2))
                };
                for order in ORDERS {
                    let mut b = [0usize; 3];
                    let mut tet = [corner(b); 4];
                    for (step, &axis) in order.iter().enumerate() {
                        b[axis] = 1;
                        tet[step + 1] = corner(b);
                    }
                    tets.push(tet);
                }
            }
        }
    }
    // Mark every tetrahedron face lying in the top or the bottom plane (such a face is
    // necessarily a boundary face); from_tetgen tags unmarked boundary faces Side.
    let layer = |n: usize| n / ((nx + 1) * (ny + 1));
    let mut marked_faces = Vec::new();
    for t in &tets {
        for skip in 0..4 {
            let f: Vec<usize> = (0..4).filter(|&a| a != skip).map(|a| t[a]).collect();
            let f = [f[0], f[1], f[2]];
            if f.iter().all(|&n| layer(n) == nz) {
                marked_faces.push((f, FaceTag::Visible.marker()));
            } else if f.iter().all(|&n| layer(n) == 0) {
                marked_faces.push((f, FaceTag::Back.marker()));
            }
        }
    }
    let tet_region = vec![1; tets.len()];
    TetMesh::from_tetgen(TetgenOutput { points, tets, tet_region, marked_faces }).expect("box cells are not degenerate")
}

/// Total area (m^2) of the boundary faces tagged `tag`.
pub fn tagged_area(mesh: &TetMesh, tag: FaceTag) -> f64 {
    mesh.boundary
        .iter()
        .zip(&mesh.boundary_tag)
        .filter(|(_, &t)| t == tag)
        .map(|(f, _)| tri_area(&f.map(|i| mesh.verts[i])))
        .sum()
}

/// Nodal load (W) of a flux `q` (W/m^2, positive into the body) on the faces tagged `tag`,
/// assembled with [`tri_flux_load`] (independently of `heatsim::simulate::uniform_load`).
pub fn face_load(mesh: &TetMesh, tag: FaceTag, q: f64) -> Vec<f64> {
    let mut load = vec![0.0; mesh.verts.len()];
    for (f, _) in mesh.boundary.iter().zip(&mesh.boundary_tag).filter(|(_, &t)| t == tag) {
        let l = tri_flux_load(tri_area(&f.map(|i| mesh.verts[i])), q);
        for (a, &n) in f.iter().enumerate() {
            load[n] += l[a];
        }
    }
    load
}

/// `exposed` flags: true for the boundary faces whose tag is in `tags`.
pub fn exposed_tags(mesh: &TetMesh, tags: &[FaceTag]) -> Vec<bool> {
    mesh.boundary_tag.iter().map(|t| tags.contains(t)).collect()
}

// ---------------------------------------------------------------------------------------------
// Time marching

/// Newton statistics of a run.
#[derive(Clone, Copy, Debug, Default)]
pub struct MarchStats {
    pub steps: usize,
    pub iterations_total: u64,
    pub iterations_max: u32,
    pub refactorisations: usize,
}

/// Advances `t` (K, per node) by `steps` backward-Euler steps with a constant `load` (W),
/// using linear extrapolation of the last two steps as the initial guess (as
/// `simulate_volumetric` does). `prev` holds the temperatures one step before `t` for the
/// extrapolation (pass `None` at the start of a run). Returns the statistics and the
/// temperatures of the previous step.
pub fn march(
    system: &HeatSystem,
    stepper: &mut Stepper,
    t: &mut Vec<f64>,
    prev: Option<Vec<f64>>,
    load: &[f64],
    steps: usize,
    mut each: impl FnMut(usize, &[f64], &StepInfo),
) -> Result<(MarchStats, Vec<f64>), SolverError> {
    let n = t.len();
    let mut older = prev;
    let mut new = vec![0.0; n];
    let mut stats = MarchStats::default();
    for s in 1..=steps {
        for i in 0..n {
            new[i] = match &older {
                Some(o) => 2.0 * t[i] - o[i],
                None => t[i],
            };
        }
        let info = stepper.step(system, t, load, &mut new)?;
        stats.steps += 1;
        stats.iterations_total += info.iterations as u64;
        stats.iterations_max = stats.iterations_max.max(info.iterations);
        stats.refactorisations += info.refactorised as usize;
        let old = std::mem::replace(t, new.clone());
        older = Some(old);
        each(s, t, &info);
    }
    Ok((stats, older.unwrap_or_else(|| t.clone())))
}

/// Capacity-weighted mean temperature (K): 1^T M T / 1^T M 1.
pub fn mean_temperature(system: &HeatSystem, t: &[f64]) -> f64 {
    let c: f64 = system.capacity.iter().sum();
    system.capacity.iter().zip(t).map(|(a, b)| a * b).sum::<f64>() / c
}

// ---------------------------------------------------------------------------------------------
// Quadrature and norms

/// n-point Gauss-Legendre rule on [0, 1]: (nodes, weights), weights summing to 1. Nodes by
/// Newton's method on the Legendre polynomial P_n (three-term recurrence), started from the
/// Chebyshev-like guess cos(pi (i + 3/4) / (n + 1/2)); converges to roundoff in a few steps.
pub fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut x = Vec::with_capacity(n);
    let mut w = Vec::with_capacity(n);
    for i in 0..n {
        let mut z = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 0.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, z);
            for m in 2..=n {
                let p2 = ((2 * m - 1) as f64 * z * p1 - (m - 1) as f64 * p0) / m as f64;
                p0 = p1;
                p1 = p2;
            }
            let p = p1;
            // P_n' = n (z P_n - P_{n-1}) / (z^2 - 1)
            dp = n as f64 * (z * p - p0) / (z * z - 1.0);
            let dz = p / dp;
            z -= dz;
            if dz.abs() < 1e-16 {
                break;
            }
        }
        x.push(0.5 * (1.0 - z));
        w.push(1.0 / ((1.0 - z * z) * dp * dp)); // 2 / ((1 - z^2) P_n'^2), halved for [0, 1]
    }
    (x, w)
}

/// A quadrature rule on the tetrahedron: barycentric coordinates [l0, l1, l2, l3] and
/// weights summing to 1 (multiply by the volume). Collapsed (Duffy) product of n-point
/// Gauss-Legendre rules: l1 = u, l2 = (1 - u) v, l3 = (1 - u)(1 - v) w with Jacobian
/// 6 (1 - u)^2 (1 - v); exact for polynomials of degree <= 2 n - 3 in the coordinates.
pub fn tet_rule(n: usize) -> Vec<([f64; 4], f64)> {
    let (x, w) = gauss_legendre(n);
    let mut rule = Vec::with_capacity(n * n * n);
    for (u, wu) in x.iter().zip(&w) {
        for (v, wv) in x.iter().zip(&w) {
            for (s, ws) in x.iter().zip(&w) {
                let l1 = u;
                let l2 = (1.0 - u) * v;
                let l3 = (1.0 - u) * (1.0 - v) * s;
                let weight = 6.0 * wu * wv * ws * (1.0 - u) * (1.0 - u) * (1.0 - v);
                rule.push(([1.0 - l1 - l2 - l3, *l1, l2, l3], weight));
            }
        }
    }
    rule
}

/// L2 norm (K m^{3/2}) of the difference between the P1 field `t` (per node) and `exact(p)`:
/// sqrt(int_Omega (T_h - T)^2 dV), by the 5-point collapsed product rule per tetrahedron
/// (exact to degree 7; the integrand is smooth inside each element).
pub fn l2_error(mesh: &TetMesh, t: &[f64], exact: impl Fn([f64; 3]) -> f64) -> f64 {
    let rule = tet_rule(5);
    let mut sum = 0.0;
    for tet in &mesh.tets {
        let p = tet.map(|i| mesh.verts[i]);
        let v = heatsim::mesh::tetmesh::tet_signed_volume(p);
        for (l, w) in &rule {
            let mut x = [0.0; 3];
            let mut th = 0.0;
            for a in 0..4 {
                th += l[a] * t[tet[a]];
                for d in 0..3 {
                    x[d] += l[a] * p[a][d];
                }
            }
            let e = th - exact(x);
            sum += v * w * e * e;
        }
    }
    sum.sqrt()
}

/// Observed order of convergence between two errors at a refinement ratio of 2.
pub fn order(coarse: f64, fine: f64) -> f64 {
    (coarse / fine).log2()
}

// ---------------------------------------------------------------------------------------------
// Closed-form solutions

/// Temperature rise T - T0 (K) of a slab of thickness `l` (m), conductivity `k` (W/(m K)) and
/// diffusivity `alpha` (m^2/s), initially at T0, with a constant flux `q` (W/m^2) into the
/// face x = 0 from t = 0 and the face x = l insulated, at depth `x` (m) below the heated face
/// and time `t` (s) (Carslaw & Jaeger, Sec. 3.3; derived in the test module):
///
/// T - T0 = (q l / k) [ alpha t / l^2 + (3 (l - x)^2 - l^2) / (6 l^2)
///          - (2 / pi^2) sum_{n >= 1} ((-1)^n / n^2) exp(-n^2 pi^2 alpha t / l^2) cos(n pi (l - x) / l) ].
///
/// The series is summed until the terms fall below 1e-18 of the leading ones (at most 10^6
/// terms, enough down to alpha t / l^2 ~ 1e-10).
pub fn slab_rise(q: f64, k: f64, alpha: f64, l: f64, x: f64, t: f64) -> f64 {
    use std::f64::consts::PI;
    let fo = alpha * t / (l * l);
    let s = (l - x) / l;
    let mut series = 0.0;
    for n in 1..=1_000_000u64 {
        let nf = n as f64;
        let decay = (-nf * nf * PI * PI * fo).exp() / (nf * nf);
        if decay < 1e-18 {
            break;
        }
        let sign = if n % 2 == 0 { 1.0 } else { -1.0 };
        series += sign * decay * (nf * PI * s).cos();
    }
    q * l / k * (fo + (3.0 * s * s - 1.0) / 6.0 - 2.0 / (PI * PI) * series)
}

/// Time (s) for a lumped body cooling only by radiation, dT/dt = -a (T^4 - Ts^4), to go from
/// `t1` to `t` (Ts < t <= t1, K), with a = eps sigma A / C (1/(K^3 s)):
///
/// time = (1 / (4 a Ts^3)) [ ln((T + Ts)/(T - Ts)) - ln((T1 + Ts)/(T1 - Ts))
///        + 2 (atan(T/Ts) - atan(T1/Ts)) ],
///
/// from 1/(T^4 - Ts^4) = (1/(2 Ts^2)) [1/(T^2 - Ts^2) - 1/(T^2 + Ts^2)].
pub fn radiative_cooling_time(a: f64, ts: f64, t1: f64, t: f64) -> f64 {
    let g = |x: f64| ((x + ts) / (x - ts)).ln() + 2.0 * (x / ts).atan();
    (g(t) - g(t1)) / (4.0 * a * ts.powi(3))
}

/// Inverse of [`radiative_cooling_time`] by bisection on (Ts, T1]: the temperature (K) at
/// `time` (s). The time is decreasing in T, so 200 halvings reach the last bit.
pub fn radiative_cooling_temperature(a: f64, ts: f64, t1: f64, time: f64) -> f64 {
    let (mut lo, mut hi) = (ts, t1);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid == lo || mid == hi {
            break;
        }
        if mid == ts || radiative_cooling_time(a, ts, t1, mid) > time {
            lo = mid; // too cold: cooling to mid takes longer than `time`
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

// ---------------------------------------------------------------------------------------------
// Surfaces

/// Icosphere of radius `r` (metres): the icosahedron with each triangle split in four
/// `level` times, midpoints pushed to the sphere. 20 * 4^level faces.
pub fn icosphere(level: u32, r: f64) -> TriMesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut verts: Vec<[f64; 3]> = vec![
        [-1., t, 0.],
        [1., t, 0.],
        [-1., -t, 0.],
        [1., -t, 0.],
        [0., -1., t],
        [0., 1., t],
        [0., -1., -t],
        [0., 1., -t],
        [t, 0., -1.],
        [t, 0., 1.],
        [-t, 0., -1.],
        [-t, 0., 1.],
    ];
    let mut tris: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let project = |p: [f64; 3]| {
        let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        p.map(|x| x / n)
    };
    for v in verts.iter_mut() {
        *v = project(*v);
    }
    for _ in 0..level {
        let mut mid = std::collections::HashMap::new();
        let mut next = Vec::with_capacity(4 * tris.len());
        for &[a, b, c] in &tris {
            let mut m = |i: usize, j: usize| {
                *mid.entry((i.min(j), i.max(j))).or_insert_with(|| {
                    let (p, q) = (verts[i], verts[j]);
                    verts.push(project([0, 1, 2].map(|k| 0.5 * (p[k] + q[k]))));
                    verts.len() - 1
                })
            };
            let (ab, bc, ca) = (m(a, b), m(b, c), m(c, a));
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        tris = next;
    }
    TriMesh::try_new(verts.into_iter().map(|p| p.map(|x| r * x)).collect(), tris).unwrap()
}
