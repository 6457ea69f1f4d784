//! Integration tests of `heatsim::lamp`: the point-lamp irradiance against its closed form
//! (cosine law, inverse square, the reference table of section 4), shadows against their
//! geometric projection, energy balances (intercepted power = irradiance x projected area)
//! on a cube and a meshed hemispherical shell, lamp placement checks, uniform lamps, and the
//! time of the shadow pass on the bunny relief.
//!
//! Run with `cargo test --release -p heatsim --test lamps -- --nocapture` to see the numbers.

mod support;

use heatsim::lamp::{absorbed_face_flux, check_lamps, point_irradiance, LampError, Occluder};
use heatsim::mesh::tetmesh::{FaceTag, TetMesh};
use heatsim::scene::{LampSpec, PointLamp, UniformLamp};
use heatsim::solid::{self, Grading};
use heatsim::tetgen::{tetrahedralize, TetgenOptions};
use heatsim::vec3::{add, cross, dot, norm, scale, sub};
use std::f64::consts::PI;
use std::time::Instant;
use support::box_mesh;

const ETA: f64 = 0.85;

fn lamp(power: f64, position: [f64; 3]) -> PointLamp {
    PointLamp { power, position, radiant_fraction: ETA, on: 0.0, off: None }
}

fn centroid(verts: &[[f64; 3]], f: &[usize; 3]) -> [f64; 3] {
    scale(add(add(verts[f[0]], verts[f[1]]), verts[f[2]]), 1.0 / 3.0)
}

/// Area-weighted normal (length = 2 x area).
fn area_normal(verts: &[[f64; 3]], f: &[usize; 3]) -> [f64; 3] {
    cross(sub(verts[f[1]], verts[f[0]]), sub(verts[f[2]], verts[f[0]]))
}

fn area(verts: &[[f64; 3]], f: &[usize; 3]) -> f64 {
    0.5 * norm(area_normal(verts, f))
}

/// A structured box mesh (support::box_mesh, Kuhn split) moved by `shift` (m).
fn shifted_box(n: [usize; 3], size: [f64; 3], shift: [f64; 3]) -> TetMesh {
    let mut m = box_mesh(n[0], n[1], n[2], size[0], size[1], size[2]);
    for v in &mut m.verts {
        *v = add(*v, shift);
    }
    m
}

/// A flat square plate z = 0, [-half, half]^2, n x n cells of two triangles each, facing +z
/// (an open surface).
fn plate(n: usize, half: f64) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let h = 2.0 * half / n as f64;
    let mut verts = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            verts.push([-half + i as f64 * h, -half + j as f64 * h, 0.0]);
        }
    }
    let id = |i: usize, j: usize| i + (n + 1) * j;
    let mut tris = Vec::new();
    for j in 0..n {
        for i in 0..n {
            tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    (verts, tris)
}

fn relative(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

// =============================================================================================
// Closed form on a plate

/// Every visible face of a plate (a closed 20 cm x 20 cm x 1 cm box) gets
/// eta P H / (4 pi r^3) at its centroid, to rounding: the code evaluates the same expression
/// with a different association, so 1e-12 leaves ~4 orders of magnitude for rounding. Side
/// and back faces face away from a lamp above the plate and get exactly 0.
#[test]
fn plate_irradiance_matches_cosine_inverse_square_law() {
    let m = shifted_box([16, 16, 1], [0.2, 0.2, 0.01], [-0.1, -0.1, 0.0]);
    let occ = Occluder::new(&m.verts, &m.boundary).unwrap();
    for position in [[0.0, 0.0, 0.3], [0.05, -0.03, 0.25], [0.4, 0.0, 0.02]] {
        let l = lamp(100.0, position);
        let e = point_irradiance(&l, &m.verts, &m.boundary, &occ);
        let mut worst = 0.0_f64;
        for (k, f) in m.boundary.iter().enumerate() {
            let c = centroid(&m.verts, f);
            match m.boundary_tag[k] {
                FaceTag::Visible => {
                    let h = position[2] - c[2];
                    let r = norm(sub(position, c));
                    let expected = ETA * 100.0 * h / (4.0 * PI * r.powi(3));
                    worst = worst.max(relative(e[k], expected));
                }
                FaceTag::Back => assert_eq!(e[k], 0.0, "back face {k}"),
                _ => {
                    // A side face is lit only if the lamp is in front of its plane.
                    let n = area_normal(&m.verts, f);
                    if dot(n, sub(position, c)) <= 0.0 {
                        assert_eq!(e[k], 0.0, "side face {k} faces away");
                    } else {
                        let r = norm(sub(position, c));
                        let cos = dot(n, sub(position, c)) / (norm(n) * r);
                        let expected = ETA * 100.0 * cos / (4.0 * PI * r * r);
                        worst = worst.max(relative(e[k], expected));
                    }
                }
            }
        }
        println!("lamp at {position:?}: max relative error vs closed form {worst:.2e}");
        assert!(worst < 1e-12);
    }
}

/// The on-axis irradiance (a face whose centroid is on the lamp's axis) is eta P / (4 pi H^2):
/// it drops by exactly 4 when H doubles (to rounding), and matches the table of the reference
/// (section 4, eta = 0.85) to its rounding to whole W/m^2.
#[test]
fn on_axis_irradiance_is_inverse_square_and_matches_the_reference_table() {
    // One triangle centred on the origin, facing +z.
    let verts = vec![[-1e-3, -1e-3, 0.0], [2e-3, -1e-3, 0.0], [-1e-3, 2e-3, 0.0]];
    let tris = vec![[0, 1, 2]];
    let occ = Occluder::new(&verts, &tris).unwrap();
    let e = |p: f64, h: f64| point_irradiance(&lamp(p, [0.0, 0.0, h]), &verts, &tris, &occ)[0];
    for h in [0.1, 0.3, 0.4, 1.7] {
        let ratio = e(100.0, h) / e(100.0, 2.0 * h);
        assert!((ratio - 4.0).abs() < 1e-13, "H {h}: ratio {ratio}");
        assert!(relative(e(100.0, h), ETA * 100.0 / (4.0 * PI * h * h)) < 1e-14);
    }
    let table = [
        (60.0, 0.3, 45.0),
        (60.0, 0.4, 25.0),
        (60.0, 0.5, 16.0),
        (100.0, 0.3, 75.0),
        (100.0, 0.4, 42.0),
        (100.0, 0.5, 27.0),
    ];
    for (p, d, expected) in table {
        let got = e(p, d);
        println!("{p} W at {d} m: {got:.2} W/m^2 (reference table {expected})");
        assert!((got - expected).abs() <= 0.5, "{p} W at {d} m: {got} vs {expected}");
    }
    // "At 40 cm, moving 5 cm closer raises E by about 30 %, moving 5 cm away lowers it by about
    // 20 %."
    let closer = e(100.0, 0.35) / e(100.0, 0.4) - 1.0;
    let farther = 1.0 - e(100.0, 0.45) / e(100.0, 0.4);
    assert!((closer - 0.306).abs() < 0.01 && (farther - 0.210).abs() < 0.01, "{closer} {farther}");
}

// =============================================================================================
// Shadows

/// A 6 cm x 4 cm square floating at z = h between a lamp at z = H and a plate (z = 0) casts
/// the shadow of its central projection from the lamp, scaled by H / (H - h) = 2. Shadow rays
/// start at the face centroids, so a face is shadowed exactly when its centroid projects into
/// the square, up to the rays' lift off the plate (~1e-7 m, x2 in the projection) and
/// rounding: faces whose centroid is within 1 µm of the shadow's outline are not checked (a
/// far thinner band than one face, 5 mm; no centroid of this grid falls in it).
#[test]
fn floating_square_casts_its_geometric_shadow() {
    let (mut verts, mut tris) = plate(60, 0.15);
    let plate_faces = tris.len();
    let (lamp_h, sq_h) = (0.4, 0.2);
    let (x0, x1, y0, y1) = (-0.02, 0.04, -0.03, 0.01);
    let base = verts.len();
    verts.extend([[x0, y0, sq_h], [x1, y0, sq_h], [x1, y1, sq_h], [x0, y1, sq_h]]);
    tris.extend([[base, base + 1, base + 2], [base, base + 2, base + 3]]);
    let occ = Occluder::new(&verts, &tris).unwrap();
    let l = lamp(100.0, [0.0, 0.0, lamp_h]);
    let e = point_irradiance(&l, &verts, &tris, &occ);
    let k = lamp_h / (lamp_h - sq_h);
    let (sx0, sx1, sy0, sy1) = (k * x0, k * x1, k * y0, k * y1);
    let band = 1e-6;
    let (mut shadowed, mut lit, mut skipped) = (0, 0, 0);
    let mut shadow_area = 0.0;
    for (f, t) in tris.iter().enumerate().take(plate_faces) {
        let c = centroid(&verts, t);
        let dx = (c[0] - sx0).min(sx1 - c[0]);
        let dy = (c[1] - sy0).min(sy1 - c[1]);
        let inside = dx.min(dy);
        if inside.abs() < band {
            skipped += 1;
            continue;
        }
        if inside > 0.0 {
            assert_eq!(e[f], 0.0, "face {f} at {c:?} is in the shadow");
            shadowed += 1;
            shadow_area += area(&verts, t);
        } else {
            let r = norm(sub(l.position, c));
            let expected = ETA * 100.0 * lamp_h / (4.0 * PI * r.powi(3));
            assert!(relative(e[f], expected) < 1e-12, "face {f} at {c:?}: {} vs {expected}", e[f]);
            lit += 1;
        }
    }
    // The shadow polygon covers (k^2 x 6 cm x 4 cm) = 96 cm^2; faces whose centroids are
    // inside cover it up to a band of one face (5 mm) along its 40 cm outline.
    let polygon = (sx1 - sx0) * (sy1 - sy0);
    println!("shadow: {shadowed} faces shadowed ({shadow_area:.6} m^2 vs polygon {polygon:.6} m^2), {lit} lit, {skipped} skipped");
    assert_eq!(skipped, 0);
    assert!((shadow_area - polygon).abs() < 0.4 * 0.005 / 2.0, "{shadow_area} vs {polygon}");
    // The square's underside faces away from the lamp; its top is lit at normal incidence.
    assert!(e[plate_faces] > 0.0 && e[plate_faces + 1] > 0.0);
}

/// Far faces of a cube lit from one side get 0 by the cosine law, and their shadow rays (if
/// one were cast) would be blocked by the cube itself; the near faces' rays are clear. The
/// power intercepted by the cube, sum of E_f A_f, equals the flux E0 = eta P / (4 pi D^2) at
/// the centre times the projected area s^2 (|u_x| + |u_y| + |u_z|) when D >> s: with D = 1000
/// s the 1/r^2 variation across the cube is ~ s / D = 0.1 %, well inside 1 %.
#[test]
fn cube_self_shadowing_and_intercepted_power() {
    let s = 0.02;
    let m = shifted_box([6, 6, 6], [s, s, s], [-s / 2.0, -s / 2.0, s / 2.0]);
    let occ = Occluder::new(&m.verts, &m.boundary).unwrap();
    let u = {
        let d = [0.8, -0.35, 0.45];
        scale(d, 1.0 / norm(d))
    };
    let dist = 1000.0 * s;
    let l = lamp(100.0, scale(u, dist));
    let e = point_irradiance(&l, &m.verts, &m.boundary, &occ);
    let mut power = 0.0;
    let (mut far, mut near) = (0, 0);
    for (k, f) in m.boundary.iter().enumerate() {
        let n = area_normal(&m.verts, f);
        let c = centroid(&m.verts, f);
        let lifted = add(c, scale(n, 1e-7 / norm(n)));
        if dot(n, u) < 0.0 {
            far += 1;
            assert_eq!(e[k], 0.0);
            assert!(!occ.segment_is_clear(lifted, l.position), "face {k}: the cube must shadow its far side");
        } else {
            near += 1;
            assert!(e[k] > 0.0);
            assert!(occ.segment_is_clear(lifted, l.position), "face {k}: near faces see the lamp");
        }
        power += e[k] * area(&m.verts, f);
    }
    let e0 = ETA * 100.0 / (4.0 * PI * dist * dist);
    let projected = s * s * (u[0].abs() + u[1].abs() + u[2].abs());
    let rel = relative(power, e0 * projected);
    println!(
        "cube: {near} lit faces, {far} far faces; intercepted {power:.6e} W vs E0 A_proj {:.6e} W (rel {rel:.2e})",
        e0 * projected
    );
    assert!(rel < 0.01);
}

/// A hemispherical shell (R = 5 cm, 5 mm thick, meshed by TetGen like a scene object) under a
/// far lamp (D = 1000 R: 1/r^2 varies by ~2 R / D = 0.2 % over it) intercepts E0 times its
/// silhouette area, which for a hemisphere seen at angle alpha from its axis is
/// pi R^2 (1 + |cos alpha|) / 2: pi R^2 on the axis, from above and from below (through the
/// opening onto the base ring and the inside of the dome). Lit from below at 60 degrees, the
/// inside of the dome is partly in the shadow of the shell itself: without shadow rays the sum
/// would count the inner faces behind the near wall too. The inscribed polygonal dome (edges
/// of R / 10) loses ~0.2 % of the area; 2 % is the brief's tolerance.
#[test]
fn hemisphere_shell_intercepts_flux_times_silhouette() {
    let r = 0.05;
    let g = Grading { surface_element_size: r / 10.0, fine_layer_depth: 0.002, deep_element_size: 0.005 };
    let sol = solid::hemisphere(r, 0.005, &g).unwrap();
    let m = TetMesh::from_tetgen(tetrahedralize(&sol.plc, &TetgenOptions::default()).unwrap()).unwrap();
    let occ = Occluder::new(&m.verts, &m.boundary).unwrap();
    let dist = 1000.0 * r;
    for (name, alpha_deg) in [
        ("above, on the axis", 0.0_f64),
        ("below, on the axis", 180.0),
        ("below at 60 degrees", 120.0),
        ("above at 45 degrees", 45.0),
    ] {
        let a = alpha_deg.to_radians();
        let u = [a.sin(), 0.0, a.cos()];
        let l = lamp(100.0, scale(u, dist));
        let e = point_irradiance(&l, &m.verts, &m.boundary, &occ);
        let power: f64 = m.boundary.iter().zip(&e).map(|(f, e)| e * area(&m.verts, f)).sum();
        // The same sum with the cosine law only (no shadow rays).
        let unshadowed: f64 = m
            .boundary
            .iter()
            .map(|f| {
                let n = area_normal(&m.verts, f);
                let d = sub(l.position, centroid(&m.verts, f));
                let rr = norm(d);
                (ETA * 100.0 / (4.0 * PI * rr * rr)) * (dot(n, d) / (norm(n) * rr)).max(0.0) * 0.5 * norm(n)
            })
            .sum();
        let e0 = ETA * 100.0 / (4.0 * PI * dist * dist);
        let expected = e0 * PI * r * r * (1.0 + a.cos().abs()) / 2.0;
        let rel = (power - expected) / expected;
        println!(
            "hemisphere lit from {name}: intercepted {power:.5e} W vs E0 x silhouette {expected:.5e} W (rel {rel:+.2e}); without shadows {:+.2e}",
            (unshadowed - expected) / expected
        );
        assert!(rel.abs() < 0.02);
        if alpha_deg == 120.0 {
            assert!((unshadowed - expected) / expected > 0.05, "the shell must shadow part of its inside");
        }
    }
}

// =============================================================================================
// Lamp placement and inside tests

fn point(position: [f64; 3]) -> LampSpec {
    LampSpec::Point(lamp(100.0, position))
}

#[test]
fn check_lamps_rejects_lamps_inside_or_too_close() {
    // A 4 cm x 4 cm x 1 cm plate, visible face z = 0.
    let m = shifted_box([4, 4, 2], [0.04, 0.04, 0.01], [-0.02, -0.02, 0.0]);
    let occ = Occluder::new(&m.verts, &m.boundary).unwrap();
    let uniform = LampSpec::Uniform(UniformLamp { flux: 500.0, on: 0.0, off: None });

    let inside = [uniform.clone(), point([0.001, 0.002, -0.004])];
    let err = check_lamps(&inside, &occ, 1e-3).unwrap_err();
    println!("{err}");
    assert!(matches!(err, LampError::LampInside { index: 1, .. }));
    assert!(err.to_string().starts_with("lamps[1].position: the lamp"));
    assert!(err.to_string().contains("inside the object"));

    let close = [point([0.0, 0.0, 0.35]), point([0.005, -0.003, 0.0005])];
    let err = check_lamps(&close, &occ, 1e-3).unwrap_err();
    println!("{err}");
    match err {
        LampError::LampTooClose { index, distance, min_distance } => {
            assert_eq!(index, 1);
            assert!((distance - 0.0005).abs() < 1e-15, "{distance}");
            assert_eq!(min_distance, 1e-3);
        }
        other => panic!("expected LampTooClose, got {other}"),
    }
    let msg = check_lamps(&close, &occ, 1e-3).unwrap_err().to_string();
    assert_eq!(
        msg,
        "lamps[1].position: the lamp is 0.0005 m from the object's surface; it must be at least 0.001 m away"
    );
    // Next to a corner: the distance is to the corner, sqrt(3) x 0.4 mm = 0.69 mm.
    let corner = [point([0.0204, 0.0204, 0.0004])];
    assert!(matches!(check_lamps(&corner, &occ, 1e-3), Err(LampError::LampTooClose { index: 0, .. })));
    assert!(check_lamps(&corner, &occ, 6e-4).is_ok());

    // The bunny scene's lamps, a lamp beside and one below the plate; uniform lamps pass.
    let ok = [
        uniform,
        point([-0.2, 0.0, 0.35]),
        point([0.2, 0.0, 0.35]),
        point([0.1, 0.0, -0.005]),
        point([0.0, 0.0, -0.5]),
    ];
    check_lamps(&ok, &occ, 1e-3).unwrap();
    assert!(matches!(check_lamps(&ok, &occ, -1.0), Err(LampError::InvalidMinDistance { .. })));
    let nan = [point([f64::NAN, 0.0, 0.3])];
    assert!(matches!(check_lamps(&nan, &occ, 1e-3), Err(LampError::NonFinitePosition { index: 0, .. })));
}

/// `contains` and `distance` on a cube [-1, 1]^3 cm (a 5 x 5 x 5 Kuhn-split grid, so its
/// faces are cut by diagonals and grid lines): points well inside and outside, 1 nm inside and
/// outside every face, edge and corner, on the grid's lines and diagonals (where rays through
/// vertices and edges are likely), and points on the surface.
#[test]
fn contains_and_distance_on_a_cube() {
    let a = 0.01;
    let m = shifted_box([5, 5, 5], [2.0 * a, 2.0 * a, 2.0 * a], [-a, -a, a]);
    let occ = Occluder::new(&m.verts, &m.boundary).unwrap();
    let mut checked = 0;
    // Every combination of coordinates from {-a, -0.6a, 0, 0.6a, a} (grid lines and corners)
    // pushed 1 nm in or out along each axis that sits on the boundary.
    let coords = [-a, -0.6 * a, 0.0, 0.6 * a, a];
    let eps = 1e-9;
    for &x in &coords {
        for &y in &coords {
            for &z in &coords {
                let p = [x, y, z];
                let on_boundary: Vec<usize> = (0..3).filter(|&d| p[d].abs() == a).collect();
                if on_boundary.is_empty() {
                    assert!(occ.contains(p), "{p:?} is inside");
                    let expected = (0..3).map(|d| a - p[d].abs()).fold(f64::INFINITY, f64::min);
                    assert!((occ.distance(p) - expected).abs() < 1e-15);
                    checked += 1;
                    continue;
                }
                // On the surface: counts as inside, distance 0.
                assert!(occ.contains(p), "{p:?} is on the surface");
                assert!(occ.distance(p) < 1e-15);
                let mut inner = p;
                let mut outer = p;
                for &d in &on_boundary {
                    inner[d] -= eps * p[d].signum();
                    outer[d] += eps * p[d].signum();
                }
                assert!(occ.contains(inner), "{inner:?} is 1 nm inside");
                assert!(!occ.contains(outer), "{outer:?} is 1 nm outside");
                // Outside a face, an edge or a corner: eps, sqrt(2) eps, sqrt(3) eps.
                let expected = eps * (on_boundary.len() as f64).sqrt();
                assert!(relative(occ.distance(outer), expected) < 1e-6, "{outer:?}: {}", occ.distance(outer));
                checked += 3;
            }
        }
    }
    // Far away, on the axes and diagonals.
    for p in
        [[0.0, 0.0, 1.0], [2.0 * a, 0.0, 0.0], [2.0 * a, 2.0 * a, 2.0 * a], [-0.011, 0.0, 0.0], [0.0, 0.0, -0.0100001]]
    {
        assert!(!occ.contains(p), "{p:?} is outside");
    }
    assert!(relative(occ.distance([2.0 * a, 2.0 * a, 2.0 * a]), 3f64.sqrt() * a) < 1e-12);
    println!("contains: {checked} points near faces, edges and corners classified correctly");
}

// =============================================================================================
// absorbed_face_flux

#[test]
fn absorbed_flux_of_uniform_and_point_lamps() {
    let m = shifted_box([4, 3, 2], [0.04, 0.03, 0.01], [-0.02, -0.015, 0.0]);
    let occ = Occluder::new(&m.verts, &m.boundary).unwrap();
    let beta = 0.9;
    let uniform = LampSpec::Uniform(UniformLamp { flux: 500.0, on: 0.0, off: None });
    let q = absorbed_face_flux(&uniform, beta, &m.verts, &m.boundary, &m.boundary_tag, &occ);
    assert_eq!(q.len(), m.boundary.len());
    for (k, t) in m.boundary_tag.iter().enumerate() {
        assert_eq!(q[k], if *t == FaceTag::Visible { 450.0 } else { 0.0 }, "face {k} ({t:?})");
    }
    let visible_power: f64 = m.boundary.iter().zip(&q).map(|(f, q)| q * area(&m.verts, f)).sum();
    assert!(relative(visible_power, 450.0 * 0.04 * 0.03) < 1e-12);

    // A point lamp beside the plate lights one side face as well as the top.
    let l = lamp(60.0, [0.3, 0.0, 0.2]);
    let e = point_irradiance(&l, &m.verts, &m.boundary, &occ);
    let q = absorbed_face_flux(&LampSpec::Point(l), beta, &m.verts, &m.boundary, &m.boundary_tag, &occ);
    assert!(q.iter().zip(&e).all(|(q, e)| *q == beta * e));
    let lit_sides = m.boundary_tag.iter().zip(&q).filter(|(t, q)| **t == FaceTag::Side && **q > 0.0).count();
    assert!(lit_sides > 0);
}

#[test]
fn occluder_rejects_bad_surfaces() {
    let verts = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    assert!(matches!(Occluder::new(&verts, &[]), Err(LampError::EmptyMesh)));
    let e = Occluder::new(&verts, &[[0, 1, 3]]).unwrap_err();
    assert!(matches!(e, LampError::IndexOutOfRange { face: 0, index: 3, vertex_count: 3 }), "{e}");
    let bad = vec![[0.0, 0.0, 0.0], [1.0, f64::NAN, 0.0], [0.0, 1.0, 0.0]];
    assert!(matches!(Occluder::new(&bad, &[[0, 1, 2]]), Err(LampError::NonFiniteVertex { vertex: 1, .. })));
}

// =============================================================================================
// The bunny relief: speed and determinism

/// The shadow pass for the bunny scene's two lamps over the relief's whole boundary (~60k
/// faces), as a run does it once: build the hierarchy, then one point_irradiance per lamp.
/// It must take well under a second in release. Also: the same result on 1 thread as on all
/// (faces are independent), and the scene's lamps pass `check_lamps`.
#[test]
fn bunny_relief_shadow_pass_is_fast_and_deterministic() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/bunny.json");
    let mut scene = heatsim::scene::Scene::from_file(&path).unwrap();
    // Every lamp of every configuration (the scene films a left and a right lamp).
    scene.lamps = scene.lamp_sets().into_iter().flat_map(|(_, lamps)| lamps).collect();
    assert_eq!(scene.lamps.len(), 2);
    let t = Instant::now();
    let meshed = heatsim::meshing::mesh_scene(&scene, None).unwrap();
    let mesh_s = t.elapsed().as_secs_f64();
    let m = &meshed.mesh;

    let t = Instant::now();
    let occ = Occluder::new(&m.verts, &m.boundary).unwrap();
    let build_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let fluxes: Vec<Vec<f64>> = scene
        .lamps
        .iter()
        .map(|l| match l {
            LampSpec::Point(p) => point_irradiance(p, &m.verts, &m.boundary, &occ),
            LampSpec::Uniform(_) => unreachable!("the bunny scene has point lamps"),
        })
        .collect();
    let trace_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    check_lamps(&scene.lamps, &occ, 1e-3).unwrap();
    let check_s = t.elapsed().as_secs_f64();

    let faces = m.boundary.len();
    for (i, (l, e)) in scene.lamps.iter().zip(&fluxes).enumerate() {
        let LampSpec::Point(p) = l else { unreachable!() };
        let facing = m
            .boundary
            .iter()
            .filter(|f| dot(area_normal(&m.verts, f), sub(p.position, centroid(&m.verts, f))) > 0.0)
            .count();
        let lit = e.iter().filter(|&&x| x > 0.0).count();
        let visible_lit = e.iter().zip(&m.boundary_tag).filter(|(x, t)| **x > 0.0 && **t == FaceTag::Visible).count();
        let max = e.iter().copied().fold(0.0, f64::max);
        println!(
            "bunny lamp {i} at {:?}: {facing} faces face it, {lit} lit ({} in shadow), {visible_lit} of them visible; max {max:.2} W/m^2",
            p.position,
            facing - lit
        );
        assert!(lit > faces / 10 && lit <= facing);
        // Nothing beats normal incidence at the distance of the nearest face.
        assert!(max < ETA * p.power / (4.0 * PI * 0.3f64.powi(2)));
    }
    println!(
        "bunny relief: {faces} boundary faces; TetGen meshing {mesh_s:.2} s; hierarchy {:.1} ms; shadow pass for {} lamps {:.1} ms; check_lamps {:.2} ms",
        build_s * 1e3,
        scene.lamps.len(),
        trace_s * 1e3,
        check_s * 1e3
    );
    assert!(faces > 20_000);
    assert!(build_s + trace_s < 0.5, "the shadow pass took {:.3} s", build_s + trace_s);

    // Determinism: one thread gives the same bits.
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let LampSpec::Point(p0) = &scene.lamps[0] else { unreachable!() };
    let serial = pool.install(|| point_irradiance(p0, &m.verts, &m.boundary, &occ));
    assert!(serial.iter().zip(&fluxes[0]).all(|(a, b)| a.to_bits() == b.to_bits()));
}
