//! Verification of the discrete surface operators (`heatsim::surface::operators`, issue 5) and
//! of their derivatives (`heatsim::surface::derivatives`) against independent oracles:
//! - the cotangent Laplacian L is symmetric with zero row sums on irregular meshes, has linear
//!   precision on flat meshes (L f = 0 at interior vertices for linear f), and -L equals the P1
//!   stiffness matrix assembled from hat-function gradients computed via the metric tensor;
//! - both lumped masses sum to the mesh area, and the mixed Voronoi shares of acute triangles
//!   equal the areas of the corner quadrilaterals cut by the circumcentre;
//! - vertex normals of sphere meshes point outward;
//! - the generalised eigenproblem -L v = lambda M v of icospheres converges to the unit
//!   sphere's Laplace-Beltrami spectrum l(l+1), multiplicity 2l+1;
//! - the mesh-level VJP matches finite differences of a scalar energy on a closed mesh.
//!
//! Run with `cargo test --release -p heatsim --test surface_operators -- --nocapture` to see
//! the measured numbers. Lengths in metres (unit sphere: radius 1 m).

use heatsim::surface::derivatives::LaplacianVjp;
use heatsim::surface::operators::{
    boundary_vertices, corner_areas, lumped_area, triangle_area, vertex_normals, AreaMass, CotanLaplacian,
};
use heatsim::vec3::{add, cross, dot, norm, scale, sub};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

type Mesh = (Vec<[f64; 3]>, Vec<[usize; 3]>);

// ---------------------------------------------------------------------------------------------
// Meshes

/// The icosahedron subdivided `level` times (each triangle into 4 at edge midpoints), vertices
/// projected to the unit sphere; faces oriented outward. 10 * 4^level + 2 vertices.
fn icosphere(level: usize) -> Mesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut verts: Vec<[f64; 3]> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .map(|v| scale(v, 1.0 / norm(v)))
    .to_vec();
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
    for _ in 0..level {
        let mut mid = std::collections::HashMap::new();
        let mut midpoint = |a: usize, b: usize, verts: &mut Vec<[f64; 3]>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let m = add(verts[a], verts[b]);
                verts.push(scale(m, 1.0 / norm(m)));
                verts.len() - 1
            })
        };
        let mut next = Vec::with_capacity(4 * tris.len());
        for [a, b, c] in tris {
            let (ab, bc, ca) = (midpoint(a, b, &mut verts), midpoint(b, c, &mut verts), midpoint(c, a, &mut verts));
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        tris = next;
    }
    (verts, tris)
}

/// Signed volume enclosed by a closed triangle mesh (m^3): positive for outward faces.
fn signed_volume((verts, tris): &Mesh) -> f64 {
    tris.iter().map(|t| dot(verts[t[0]], cross(verts[t[1]], verts[t[2]])) / 6.0).sum()
}

/// An icosphere with each vertex moved randomly along the sphere by up to `amount` times the
/// typical edge length, then re-projected: irregular, with obtuse triangles for large amounts.
fn jittered_icosphere(level: usize, amount: f64, rng: &mut ChaCha8Rng) -> Mesh {
    let (mut verts, tris) = icosphere(level);
    let edge = 1.1 / 2f64.powi(level as i32);
    for v in &mut verts {
        let d: [f64; 3] = std::array::from_fn(|_| rng.random_range(-1.0..1.0) * amount * edge);
        let m = add(*v, d);
        *v = scale(m, 1.0 / norm(m));
    }
    (verts, tris)
}

/// A (nx+1) x (ny+1) grid over [0, 1]^2 with vertices jittered by up to `jitter` cells and
/// heights up to `height` (m), each cell split along a random diagonal.
fn jittered_grid(nx: usize, ny: usize, jitter: f64, height: f64, rng: &mut ChaCha8Rng) -> Mesh {
    let mut verts = Vec::new();
    for j in 0..=ny {
        for i in 0..=nx {
            let x = (i as f64 + rng.random_range(-jitter..=jitter)) / nx as f64;
            let y = (j as f64 + rng.random_range(-jitter..=jitter)) / ny as f64;
            verts.push([x, y, height * rng.random_range(-1.0..=1.0)]);
        }
    }
    let id = |i: usize, j: usize| i + (nx + 1) * j;
    let mut tris = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            if rng.random_bool(0.5) {
                tris.extend([[a, b, c], [a, c, d]]);
            } else {
                tris.extend([[a, b, d], [b, c, d]]);
            }
        }
    }
    (verts, tris)
}

/// A random rotation (from a random unit quaternion) followed by a translation.
fn random_rigid_motion(rng: &mut ChaCha8Rng) -> impl Fn([f64; 3]) -> [f64; 3] {
    let q: [f64; 4] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
    let l = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    let [w, x, y, z] = q.map(|c| c / l);
    let r = [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
        [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
        [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
    ];
    let shift: [f64; 3] = std::array::from_fn(|_| rng.random_range(-3.0..3.0));
    move |p| add(std::array::from_fn(|i| dot(r[i], p)), shift)
}

fn count_obtuse((verts, tris): &Mesh) -> usize {
    tris.iter()
        .filter(|t| {
            (0..3).any(|c| dot(sub(verts[t[(c + 1) % 3]], verts[t[c]]), sub(verts[t[(c + 2) % 3]], verts[t[c]])) < 0.0)
        })
        .count()
}

/// The irregular meshes of the structural tests: a non-planar jittered grid and a jittered
/// icosphere, both with obtuse triangles.
fn irregular_meshes() -> Vec<(&'static str, Mesh)> {
    let mut rng = ChaCha8Rng::seed_from_u64(51);
    let meshes = vec![
        ("jittered grid 12x9 with heights", jittered_grid(12, 9, 0.35, 0.05, &mut rng)),
        ("jittered icosphere level 3", jittered_icosphere(3, 0.3, &mut rng)),
    ];
    for (name, m) in &meshes {
        assert!(count_obtuse(m) > 0, "{name} has no obtuse triangle");
    }
    meshes
}

// ---------------------------------------------------------------------------------------------
// Laplacian structure

#[test]
fn laplacian_is_symmetric_with_zero_row_sums() {
    for (name, (verts, tris)) in irregular_meshes() {
        let lap = CotanLaplacian::new(&verts, &tris);
        let n = verts.len();
        let a = lap.to_dense();
        let wmax = lap.weights.iter().fold(0.0f64, |m, w| m.max(w.abs()));
        let (mut asym, mut rowsum) = (0.0f64, 0.0f64);
        for i in 0..n {
            rowsum = rowsum.max(a[i * n..(i + 1) * n].iter().sum::<f64>().abs());
            for j in 0..n {
                asym = asym.max((a[i * n + j] - a[j * n + i]).abs());
            }
        }
        // apply() and diagonal() agree with the dense matrix.
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let x: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
        let mut y = vec![0.0; n];
        lap.apply(&x, &mut y);
        let diag = lap.diagonal();
        let (mut dapply, mut ddiag) = (0.0f64, 0.0f64);
        for i in 0..n {
            let yd: f64 = (0..n).map(|j| a[i * n + j] * x[j]).sum();
            dapply = dapply.max((yd - y[i]).abs());
            ddiag = ddiag.max((diag[i] - a[i * n + i]).abs());
        }
        println!(
            "{name}: n = {n}, max |w| = {wmax:.3}, max |L - L^T| = {asym:.1e}, max |row sum| = {rowsum:.1e}, \
             max |apply - dense| = {dapply:.1e}, max |diagonal - dense| = {ddiag:.1e}"
        );
        assert_eq!(asym, 0.0);
        assert!(rowsum <= 1e-14 * wmax, "{name}: row sum {rowsum}");
        assert!(dapply <= 1e-13 * wmax && ddiag <= 1e-13 * wmax, "{name}: {dapply} {ddiag}");
        // Every edge of the mesh is in the list exactly once.
        let mut all: Vec<[usize; 2]> = tris
            .iter()
            .flat_map(|t| (0..3).map(move |c| [t[c].min(t[(c + 1) % 3]), t[c].max(t[(c + 1) % 3])]))
            .collect();
        all.sort_unstable();
        all.dedup();
        assert_eq!(all, lap.edges);
    }
}

#[test]
fn laplacian_has_linear_precision_on_flat_meshes() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for trial in 0..4 {
        let (flat, tris) = jittered_grid(10 + trial, 8, 0.4, 0.0, &mut rng);
        let motion = random_rigid_motion(&mut rng);
        let verts: Vec<[f64; 3]> = flat.iter().map(|&p| motion(p)).collect();
        let obtuse = count_obtuse(&(verts.clone(), tris.clone()));
        assert!(obtuse > 0, "the test mesh should contain obtuse triangles");
        let lap = CotanLaplacian::new(&verts, &tris);
        let on_boundary = boundary_vertices(verts.len(), &tris);
        let c: [f64; 3] = std::array::from_fn(|_| rng.random_range(-2.0..2.0));
        let f: Vec<f64> = verts.iter().map(|&p| dot(c, p) + 0.7).collect();
        let mut lf = vec![0.0; verts.len()];
        lap.apply(&f, &mut lf);
        // Scale of the cancelling terms at each vertex: sum_j |w_ij| |f_j - f_i|.
        let mut scale_ = vec![0.0; verts.len()];
        for (&[i, j], &w) in lap.edges.iter().zip(&lap.weights) {
            scale_[i] += (w * (f[j] - f[i])).abs();
            scale_[j] += (w * (f[j] - f[i])).abs();
        }
        let (mut worst, mut interior, mut worst_boundary) = (0.0f64, 0, 0.0f64);
        for i in 0..verts.len() {
            let rel = lf[i].abs() / scale_[i];
            if on_boundary[i] {
                worst_boundary = worst_boundary.max(rel);
            } else {
                interior += 1;
                worst = worst.max(rel);
            }
        }
        println!(
            "flat mesh {trial}: {interior} interior vertices, {obtuse} obtuse triangles, \
             max |(L f)_i| / sum_j |w_ij (f_j - f_i)| = {worst:.1e} (boundary: {worst_boundary:.2})"
        );
        assert!(worst < 1e-12, "linear precision violated: {worst}");
        // The boundary rows are not zero (the boundary term of Green's formula): the test sees them.
        assert!(worst_boundary > 1e-3);
    }
}

/// Hat-function gradients of a triangle from the metric tensor G = E^T E of its edge basis
/// E = [p1 - p0, p2 - p0]: grad phi_1 = (G^-1)_{00} e1 + (G^-1)_{01} e2, likewise phi_2, and
/// grad phi_0 = -grad phi_1 - grad phi_2; area sqrt(det G)/2. Independent of cotangents.
fn p1_gradients(p: &[[f64; 3]; 3]) -> ([[f64; 3]; 3], f64) {
    let (e1, e2) = (sub(p[1], p[0]), sub(p[2], p[0]));
    let (g11, g12, g22) = (dot(e1, e1), dot(e1, e2), dot(e2, e2));
    let det = g11 * g22 - g12 * g12;
    let (i11, i12, i22) = (g22 / det, -g12 / det, g11 / det);
    let d1 = add(scale(e1, i11), scale(e2, i12));
    let d2 = add(scale(e1, i12), scale(e2, i22));
    ([scale(add(d1, d2), -1.0), d1, d2], 0.5 * det.sqrt())
}

#[test]
fn minus_laplacian_is_the_p1_stiffness_matrix() {
    for (name, (verts, tris)) in irregular_meshes() {
        let n = verts.len();
        let mut k = vec![0.0; n * n];
        for t in &tris {
            let (g, area) = p1_gradients(&t.map(|i| verts[i]));
            for a in 0..3 {
                for b in 0..3 {
                    k[t[a] * n + t[b]] += area * dot(g[a], g[b]);
                }
            }
        }
        let l = CotanLaplacian::new(&verts, &tris).to_dense();
        let kmax = k.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let diff = k.iter().zip(&l).fold(0.0f64, |m, (k, l)| m.max((k + l).abs()));
        println!("{name}: max |K_P1 + L| / max |K_P1| = {:.1e}", diff / kmax);
        assert!(diff <= 1e-12 * kmax, "{name}: {}", diff / kmax);
    }
}

// ---------------------------------------------------------------------------------------------
// Masses and normals

#[test]
fn lumped_masses_sum_to_the_area() {
    for (name, (verts, tris)) in irregular_meshes() {
        let total: f64 = tris.iter().map(|t| triangle_area(&t.map(|i| verts[i]))).sum();
        for kind in [AreaMass::Barycentric, AreaMass::MixedVoronoi] {
            let a = lumped_area(&verts, &tris, kind);
            let s: f64 = a.iter().sum();
            println!("{name}, {kind:?}: |sum a_i - area| / area = {:.1e}", (s - total).abs() / total);
            assert!((s - total).abs() <= 1e-13 * total);
            assert!(a.iter().all(|&x| x > 0.0), "{name} {kind:?}: a non-positive mass");
        }
    }
}

/// The mixed Voronoi share of corner c of an acute triangle is the area of the quadrilateral
/// p_c, midpoint(c, c+1), circumcentre, midpoint(c, c+2); circumcentre from the closed form
/// o = p0 + (|v|^2 (u x v) x u + |u|^2 v x (u x v)) / (2 |u x v|^2), u, v the edges at p0.
#[test]
fn mixed_voronoi_shares_are_circumcentre_quadrilaterals() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut checked = 0;
    let mut worst = 0.0f64;
    while checked < 200 {
        let p: [[f64; 3]; 3] = std::array::from_fn(|_| std::array::from_fn(|_| rng.random_range(-1.0..1.0)));
        let acute = (0..3).all(|c| dot(sub(p[(c + 1) % 3], p[c]), sub(p[(c + 2) % 3], p[c])) > 0.0);
        if !acute || triangle_area(&p) < 0.05 {
            continue;
        }
        checked += 1;
        let (u, v) = (sub(p[1], p[0]), sub(p[2], p[0]));
        let n = cross(u, v);
        let o = add(p[0], scale(add(scale(cross(n, u), dot(v, v)), scale(cross(v, n), dot(u, u))), 0.5 / dot(n, n)));
        let r: Vec<f64> = p.iter().map(|&q| norm(sub(q, o))).collect();
        assert!((r[0] - r[1]).abs() < 1e-12 && (r[0] - r[2]).abs() < 1e-12, "circumcentre {r:?}");
        let shares = corner_areas(&p, AreaMass::MixedVoronoi);
        for c in 0..3 {
            let ma = scale(add(p[c], p[(c + 1) % 3]), 0.5);
            let mb = scale(add(p[c], p[(c + 2) % 3]), 0.5);
            let quad = triangle_area(&[p[c], ma, o]) + triangle_area(&[p[c], o, mb]);
            worst = worst.max((quad - shares[c]).abs() / triangle_area(&p));
        }
    }
    println!("mixed Voronoi vs circumcentre quadrilaterals, 200 acute triangles: max error / area = {worst:.1e}");
    assert!(worst < 1e-13);
}

/// Bounds on the normal deviation of the level-5 icosphere (10242 vertices), regular and
/// jittered by 0.3 edge lengths (degrees), set just above the measured 0.169 and 1.41 deg.
/// The deviation halves with each level (first order in h, as expected of area weighting).
const NORMAL_BOUND_DEG: [f64; 2] = [0.2, 1.5];

/// Largest angle (degrees) between a vertex normal and the radius through the vertex.
fn worst_normal_angle((verts, tris): &Mesh) -> f64 {
    let normals = vertex_normals(verts, tris);
    assert!(normals.iter().all(|nrm| (norm(*nrm) - 1.0).abs() < 1e-14));
    verts
        .iter()
        .zip(&normals)
        .map(|(p, nrm)| (dot(*p, *nrm) / norm(*p)).clamp(-1.0, 1.0).acos().to_degrees())
        .fold(0.0f64, f64::max)
}

#[test]
fn sphere_vertex_normals_point_outward() {
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let mut rows = Vec::new();
    for level in 1..=5 {
        let (exact, jittered) = (icosphere(level), jittered_icosphere(level, 0.3, &mut rng));
        let (a, b) = (worst_normal_angle(&exact), worst_normal_angle(&jittered));
        println!("icosphere level {level}: max angle normal/radius = {a:.4} deg; jittered by 0.3 edge: {b:.3} deg");
        rows.push((a, b));
    }
    // Level 1 is exact by symmetry (every vertex star is mirror-symmetric about its radius);
    // from level 2 on the deviation shrinks with refinement.
    assert!(rows[0].0 < 1e-5, "{}", rows[0].0); // acos near 1 resolves ~1e-6 deg
    for w in rows[1..].windows(2) {
        assert!(w[1].0 < w[0].0 && w[1].1 < w[0].1, "{w:?}");
    }
    let (a, b) = *rows.last().expect("levels");
    assert!(a < NORMAL_BOUND_DEG[0] && b < NORMAL_BOUND_DEG[1], "level 5: {a} deg, jittered {b} deg");
}

// ---------------------------------------------------------------------------------------------
// Spectrum of the unit sphere

/// Bounds on the relative eigenvalue errors of bands l = 1, 2, 3 at the finest icosphere
/// (level 4, 2562 vertices, mean edge 0.076 m), set just above the measured errors (both
/// masses: l = 1: 3.2e-7 / 2.8e-8, l = 2: 1.42e-3, l = 3: 3.6e-3 / 4.1e-3).
const SPECTRUM_BOUND: [f64; 4] = [0.0, 1e-6, 2e-3, 5e-3];

/// Least observed convergence order in h of bands l = 2, 3 between levels 3 and 4 (measured
/// 2.00 for both masses: the O(h^2) of the literature).
const MIN_ORDER: f64 = 1.9;

/// Eigenvalues (ascending) of -L v = lambda M v with diagonal M, via the symmetric matrix
/// M^{-1/2} (-L) M^{-1/2}.
fn sphere_spectrum((verts, tris): &Mesh, kind: AreaMass) -> Vec<f64> {
    let n = verts.len();
    let l = CotanLaplacian::new(verts, tris).to_dense();
    let m = lumped_area(verts, tris, kind);
    let s: Vec<f64> = m.iter().map(|x| 1.0 / x.sqrt()).collect();
    let a = faer::Mat::<f64>::from_fn(n, n, |i, j| -l[i * n + j] * s[i] * s[j]);
    a.self_adjoint_eigenvalues(faer::Side::Lower).expect("symmetric eigenvalues converge")
}

#[test]
#[allow(clippy::needless_range_loop)] // bands are indexed by l
fn icosphere_spectrum_converges_to_l_l_plus_1() {
    const LEVELS: std::ops::RangeInclusive<usize> = 1..=4;
    for kind in [AreaMass::Barycentric, AreaMass::MixedVoronoi] {
        let mut table =
            format!("unit icosphere, -L v = lambda M v, {kind:?} mass: max_m |lambda_lm - l(l+1)| / l(l+1)\n");
        table += "  level      n    h (m)  |lambda_0|       l=1       l=2       l=3  lambda_16   observed order\n";
        // Per level: mean edge length h (m), errors of bands 0..=3, and lambda_16 (band l = 4).
        let mut rows: Vec<(usize, f64, [f64; 4], f64)> = Vec::new();
        for level in LEVELS {
            let mesh = icosphere(level);
            assert!(signed_volume(&mesh) > 0.0);
            let h = {
                let (v, t) = &mesh;
                t.iter().map(|t| norm(sub(v[t[0]], v[t[1]]))).sum::<f64>() / t.len() as f64
            };
            let ev = sphere_spectrum(&mesh, kind);
            let mut err = [ev[0].abs(), 0.0, 0.0, 0.0];
            for l in 1..=3 {
                let exact = (l * (l + 1)) as f64;
                err[l] = ev[l * l..(l + 1) * (l + 1)].iter().map(|x| (x - exact).abs() / exact).fold(0.0, f64::max);
            }
            let order = rows.last().map(|&(_, hp, ep, _)| {
                (1..=3).map(|l| format!("{:.2}", (ep[l] / err[l]).ln() / (hp / h).ln())).collect::<Vec<_>>().join(" ")
            });
            table += &format!(
                "  {level:>5} {:>6} {h:>8.4} {:>10.1e} {:>9.2e} {:>9.2e} {:>9.2e} {:>10.3}   {}\n",
                mesh.0.len(),
                err[0],
                err[1],
                err[2],
                err[3],
                ev[16],
                order.unwrap_or_default()
            );
            rows.push((mesh.0.len(), h, err, ev[16]));
        }
        print!("{table}");
        // Level 1 is special: by the icosahedral symmetry every vertex star is mirror-symmetric
        // about its radius, and with the mixed Voronoi mass the coordinate functions are then
        // exact eigenvectors (band l = 1 exact to roundoff). The errors decrease from there on.
        for (i, &(n, _, err, ev16)) in rows.iter().enumerate() {
            assert!(err[0] < 1e-10, "{kind:?} n = {n}: lambda_0 = {}", err[0]);
            if i > 0 {
                let first_band = if i == 1 && kind == AreaMass::MixedVoronoi { 2 } else { 1 };
                for l in first_band..=3 {
                    assert!(err[l] < rows[i - 1].2[l], "{kind:?} band {l}: error did not decrease at n = {n}");
                }
                // From level 2 on, band 4 (l(l+1) = 20) lies clearly above band 3 (12).
                assert!(ev16 > 16.0, "{kind:?} n = {n}: lambda_16 = {ev16}");
            }
        }
        let [.., (_, h3, e3, _), (_, h4, e4, _)] = rows[..] else { unreachable!("four levels") };
        for l in 1..=3 {
            assert!(e4[l] < SPECTRUM_BOUND[l], "{kind:?} band {l}: {} >= bound {}", e4[l], SPECTRUM_BOUND[l]);
        }
        for l in 2..=3 {
            let order = (e3[l] / e4[l]).ln() / (h3 / h4).ln();
            assert!(order > MIN_ORDER, "{kind:?} band {l}: order {order}");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Derivatives on a closed mesh

/// The mesh VJP against central differences of E = sum_e g_e w_e + sum_i m_i a_i on a jittered
/// level-1 icosphere (closed, irregular), both mass kinds.
#[test]
fn mesh_vjp_matches_finite_differences_on_a_closed_mesh() {
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let (verts, tris) = jittered_icosphere(1, 0.25, &mut rng);
    // Stay clear of right angles, where the mixed Voronoi shares have a kink.
    let min_cos = tris
        .iter()
        .flat_map(|t| {
            let verts = &verts;
            (0..3).map(move |c| {
                let (u, v) = (sub(verts[t[(c + 1) % 3]], verts[t[c]]), sub(verts[t[(c + 2) % 3]], verts[t[c]]));
                (dot(u, v) / (norm(u) * norm(v))).abs()
            })
        })
        .fold(f64::INFINITY, f64::min);
    assert!(min_cos > 1e-3, "{min_cos}");
    let lap = CotanLaplacian::new(&verts, &tris);
    let g: Vec<f64> = lap.edges.iter().map(|_| rng.random_range(-1.0..1.0)).collect();
    let m: Vec<f64> = verts.iter().map(|_| rng.random_range(-1.0..1.0)).collect();
    let vjp = LaplacianVjp::new(verts.len(), &tris).unwrap();
    assert_eq!(vjp.edges(), &lap.edges[..]);
    let h = 1e-6; // m, on edges of ~0.6 m
    for kind in [AreaMass::Barycentric, AreaMass::MixedVoronoi] {
        for (label, ge, gm) in [
            ("edges only", Some(&g[..]), None),
            ("masses only", None, Some(&m[..])),
            ("both", Some(&g[..]), Some(&m[..])),
        ] {
            let e = |x: &[[f64; 3]]| -> f64 {
                let w = CotanLaplacian::new(x, &tris).weights;
                let a = lumped_area(x, &tris, kind);
                let ew = if ge.is_some() { w.iter().zip(&g).map(|(w, g)| w * g).sum::<f64>() } else { 0.0 };
                let ea = if gm.is_some() { a.iter().zip(&m).map(|(a, m)| a * m).sum::<f64>() } else { 0.0 };
                ew + ea
            };
            let mut grad = vec![[0.0; 3]; verts.len()];
            vjp.accumulate(&verts, ge, gm, kind, &mut grad).unwrap();
            let (mut err, mut sc) = (0.0f64, 0.0f64);
            for v in 0..verts.len() {
                for k in 0..3 {
                    let (mut xp, mut xm) = (verts.clone(), verts.clone());
                    xp[v][k] += h;
                    xm[v][k] -= h;
                    let fd = (e(&xp) - e(&xm)) / (2.0 * h);
                    err = err.max((fd - grad[v][k]).abs());
                    sc = sc.max(grad[v][k].abs());
                }
            }
            println!("closed-mesh VJP ({kind:?}, {label}): max |FD - VJP| / max |VJP| = {:.1e}", err / sc);
            assert!(err / sc < 1e-6, "{kind:?} {label}: {}", err / sc);
        }
        // Translation invariance: the gradient of an intrinsic energy sums to zero.
        let mut grad = vec![[0.0; 3]; verts.len()];
        vjp.accumulate(&verts, Some(&g), Some(&m), kind, &mut grad).unwrap();
        let total = grad.iter().fold([0.0; 3], |s, x| add(s, *x));
        let sc = grad.iter().map(|x| norm(*x)).fold(0.0, f64::max);
        assert!(norm(total) < 1e-12 * sc * verts.len() as f64, "{total:?}");
    }
}

/// The mesh VJP on a 640 x 512 pixel-grid surface (the benchmark size, 3.3e5 vertices)
/// gives the same bits on 1 and 2 threads and matches a serial per-triangle scatter of the
/// public triangle Jacobians to roundoff; the timings of the three are printed.
#[test]
fn mesh_vjp_is_deterministic_and_matches_a_serial_scatter_on_a_large_grid() {
    use heatsim::surface::derivatives::{corner_areas_grad, half_cotangents_grad};
    let mut rng = ChaCha8Rng::seed_from_u64(23);
    let (verts, tris) = jittered_grid(639, 511, 0.3, 1e-3, &mut rng);
    let t0 = std::time::Instant::now();
    let vjp = LaplacianVjp::new(verts.len(), &tris).unwrap();
    let t_new = t0.elapsed();
    let g: Vec<f64> = vjp.edges().iter().map(|_| rng.random_range(-1.0..1.0)).collect();
    let m: Vec<f64> = verts.iter().map(|_| rng.random_range(-1.0..1.0)).collect();
    let kind = AreaMass::MixedVoronoi;
    // Best of 3 runs each (the machine is shared, so the timings are indicative).
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let mut best = (Vec::new(), std::time::Duration::MAX);
        for _ in 0..3 {
            let mut grad = vec![[0.0; 3]; verts.len()];
            let t = std::time::Instant::now();
            pool.install(|| vjp.accumulate(&verts, Some(&g), Some(&m), kind, &mut grad)).unwrap();
            let dt = t.elapsed();
            if dt < best.1 {
                best = (grad, dt);
            }
        }
        best
    };
    let (g1, t1) = run(1);
    let (g2, t2) = run(2);
    assert!(g1 == g2, "the VJP depends on the number of threads");
    // Serial scatter: the same sum in a different order, from the public triangle Jacobians.
    let t = std::time::Instant::now();
    let mut gs = vec![[0.0; 3]; verts.len()];
    let edge_of = |a: usize, b: usize| vjp.edges().binary_search(&[a.min(b), a.max(b)]).unwrap();
    for tri in &tris {
        let p = tri.map(|i| verts[i]);
        let (_, jw) = half_cotangents_grad(&p);
        let (_, ja) = corner_areas_grad(&p, kind);
        for c in 0..3 {
            let ge = g[edge_of(tri[(c + 1) % 3], tri[(c + 2) % 3])];
            let gm = m[tri[c]];
            for v in 0..3 {
                gs[tri[v]] = add(gs[tri[v]], add(scale(jw[c][v], ge), scale(ja[c][v], gm)));
            }
        }
    }
    let ts = t.elapsed();
    let sc = gs.iter().map(|x| norm(*x)).fold(0.0, f64::max);
    let diff = gs.iter().zip(&g1).map(|(a, b)| norm(sub(*a, *b))).fold(0.0, f64::max);
    println!(
        "VJP on {} vertices / {} triangles ({kind:?}): connectivity {:.1} ms; accumulate 1 thread {:.1} ms, \
         2 threads {:.1} ms; serial scatter with edge binary search {:.1} ms; max |diff| / max |grad| = {:.1e}",
        verts.len(),
        tris.len(),
        t_new.as_secs_f64() * 1e3,
        t1.as_secs_f64() * 1e3,
        t2.as_secs_f64() * 1e3,
        ts.as_secs_f64() * 1e3,
        diff / sc
    );
    assert!(diff <= 1e-12 * sc, "{}", diff / sc);
}
