//! Camera: pinhole projection, rasterisation (coverage, depth, perspective-correct
//! interpolation, fill rule), the radiometric sensor and its noise, preview PNG.

use heatsim::camera::{rasterize, write_preview_png, Camera, CameraError, Render, Sensor, EMPTY};
use heatsim::scene::camera::CameraSpec;
use heatsim::vec3::{add, cross, dot, scale, sub};

/// A plate `corner + s e1 + t e2`, (s, t) in [0, 1]^2, as an n x n grid of squares split into two
/// triangles each, counter-clockwise around `e1 x e2`. Returns (verts, tris).
fn grid_plate(corner: [f64; 3], e1: [f64; 3], e2: [f64; 3], n: usize) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let mut verts = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (s, t) = (i as f64 / n as f64, j as f64 / n as f64);
            verts.push(add(corner, add(scale(e1, s), scale(e2, t))));
        }
    }
    let id = |i: usize, j: usize| j * (n + 1) + i;
    let mut tris = Vec::new();
    for j in 0..n {
        for i in 0..n {
            tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    (verts, tris)
}

/// Intersection of the ray through pixel (u, v) with the plane through `p0` with normal `n`.
fn hit(camera: &Camera, u: f64, v: f64, p0: [f64; 3], n: [f64; 3]) -> [f64; 3] {
    let (o, d) = camera.ray(u, v);
    let s = dot(sub(p0, o), n) / dot(d, n);
    add(o, scale(d, s))
}

/// Plate coordinates (s, t) of a point in the plane of `corner + s e1 + t e2`.
fn plate_coords(p: [f64; 3], corner: [f64; 3], e1: [f64; 3], e2: [f64; 3]) -> (f64, f64) {
    // Solve the 2 x 2 Gram system [e1.e1 e1.e2; e1.e2 e2.e2] (s, t) = (q.e1, q.e2).
    let q = sub(p, corner);
    let (a, b, d) = (dot(e1, e1), dot(e1, e2), dot(e2, e2));
    let (r1, r2) = (dot(q, e1), dot(q, e2));
    let det = a * d - b * b;
    ((d * r1 - b * r2) / det, (a * r2 - b * r1) / det)
}

fn boson() -> Camera {
    Camera::from_spec(&CameraSpec::default()).unwrap()
}

fn pixels(r: &Render) -> impl Iterator<Item = (usize, f64, f64)> + '_ {
    let w = r.width as usize;
    (0..r.pixel_count()).map(move |p| (p, (p % w) as f64, (p / w) as f64))
}

mod projection {
    use super::*;

    #[test]
    fn intrinsics_follow_the_spec() {
        let c = boson();
        let f = 320.0 / (24.3_f64.to_radians() / 2.0).tan();
        assert!((c.fx() - f).abs() < 1e-9 && (c.fy() - f).abs() < 1e-9);
        assert_eq!((c.cx(), c.cy()), (319.5, 255.5));
        assert_eq!((c.width, c.height), (640, 512));
    }

    #[test]
    fn rotation_is_proper_and_center_is_the_position() {
        let spec = CameraSpec {
            position: [0.1, -0.2, 0.3],
            look_at: [0.02, 0.01, -0.05],
            up: [0.3, 1.0, 0.2],
            ..CameraSpec::default()
        };
        let c = Camera::from_spec(&spec).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((dot(c.r[i], c.r[j]) - want).abs() < 1e-14);
            }
        }
        assert!((dot(cross(c.r[0], c.r[1]), c.r[2]) - 1.0).abs() < 1e-14, "det R = +1");
        let centre = c.center();
        for (a, b) in centre.iter().zip(spec.position) {
            assert!((a - b).abs() < 1e-15);
        }
        // `up` points up in the picture: a point above the look-at point has smaller v.
        let above = c.project(add(spec.look_at, scale(spec.up, 0.01))).unwrap();
        assert!(above[1] < c.cy());
    }

    #[test]
    fn optical_axis_maps_to_the_principal_point() {
        let c = boson();
        for p in [[0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, 0.2]] {
            let [u, v] = c.project(p).unwrap();
            assert!((u - c.cx()).abs() < 1e-9 && (v - c.cy()).abs() < 1e-9, "{p:?} -> {u}, {v}");
        }
        // Behind the camera: no projection.
        assert_eq!(c.project([0.0, 0.0, 0.5]), None);
        assert_eq!(c.project(c.center()), None);
    }

    #[test]
    fn edge_of_the_horizontal_field_maps_to_the_outer_pixel_edge() {
        let c = boson();
        let half = (24.3_f64 / 2.0).to_radians();
        let (x, z) = (c.r[0], c.r[2]);
        for (sign, want) in [(1.0, 639.5), (-1.0, -0.5)] {
            let dir = add(scale(z, half.cos()), scale(x, sign * half.sin()));
            let [u, v] = c.project(add(c.center(), scale(dir, 0.4))).unwrap();
            assert!((u - want).abs() < 1e-9, "u = {u}, want {want}");
            assert!((v - c.cy()).abs() < 1e-9);
        }
        // The default camera looks down -z with +y up: world +x is to the right, +y is up.
        let [u, v] = c.project([0.01, 0.02, 0.0]).unwrap();
        assert!(u > c.cx() && v < c.cy());
    }

    #[test]
    fn ray_and_project_round_trip() {
        let oblique = CameraSpec {
            width: 320,
            height: 200,
            hfov_deg: 60.0,
            position: [0.3, 0.2, 0.25],
            look_at: [0.0, 0.01, 0.0],
            up: [0.0, 0.0, 1.0],
            ..CameraSpec::default()
        };
        for c in [boson(), Camera::from_spec(&oblique).unwrap()] {
            for (u, v) in [(0.0, 0.0), (319.5, 255.5), (-0.5, 511.5), (123.25, 77.75), (639.0, 0.0)] {
                let (o, d) = c.ray(u, v);
                assert!((dot(d, d) - 1.0).abs() < 1e-14);
                for s in [0.05, 0.3683, 2.0] {
                    let [pu, pv] = c.project(add(o, scale(d, s))).unwrap();
                    assert!((pu - u).abs() < 1e-9 && (pv - v).abs() < 1e-9, "({u}, {v}) at {s} -> ({pu}, {pv})");
                }
            }
        }
    }

    #[test]
    fn invalid_specs_name_the_field() {
        let field = |spec: CameraSpec| match Camera::from_spec(&spec) {
            Err(CameraError::Invalid { field, .. }) => field,
            Ok(_) => panic!("accepted an invalid camera"),
            Err(e) => panic!("unexpected error {e}"),
        };
        let d = CameraSpec::default();
        assert_eq!(field(CameraSpec { width: 0, ..d.clone() }), "camera.width");
        assert_eq!(field(CameraSpec { height: 0, ..d.clone() }), "camera.height");
        assert_eq!(field(CameraSpec { hfov_deg: 180.0, ..d.clone() }), "camera.hfov_deg");
        assert_eq!(field(CameraSpec { hfov_deg: f64::NAN, ..d.clone() }), "camera.hfov_deg");
        assert_eq!(field(CameraSpec { position: [0.0, f64::INFINITY, 1.0], ..d.clone() }), "camera.position");
        assert_eq!(field(CameraSpec { look_at: [f64::NAN, 0.0, 0.0], ..d.clone() }), "camera.look_at");
        assert_eq!(field(CameraSpec { look_at: d.position, ..d.clone() }), "camera.look_at");
        assert_eq!(field(CameraSpec { up: [0.0, 0.0, 2.0], ..d.clone() }), "camera.up");
        assert_eq!(field(CameraSpec { up: [0.0; 3], ..d.clone() }), "camera.up");
        let msg = Camera::from_spec(&CameraSpec { look_at: d.position, ..d }).unwrap_err().to_string();
        assert!(msg.starts_with("camera.look_at: must differ from camera.position"), "{msg}");
    }
}

mod raster {
    use super::*;

    /// Linear test field on the plate (m): reproduced exactly by perspective-correct
    /// interpolation, not by interpolation that is affine in screen space.
    fn field(p: [f64; 3]) -> f64 {
        p[0] + 2.0 * p[1] + 3.0 * p[2]
    }

    /// Checks coverage, depth and interpolation of a plate `corner + s e1 + t e2` rendered
    /// with `n` x `n` cells; returns the render.
    fn check_plate(c: &Camera, corner: [f64; 3], e1: [f64; 3], e2: [f64; 3], n: usize) -> Render {
        let (verts, tris) = grid_plate(corner, e1, e2, n);
        let r = rasterize(c, &verts, &tris);
        let normal = cross(e1, e2);
        let values: Vec<f64> = verts.iter().map(|&p| field(p)).collect();
        let mut interp = vec![0.0_f32; r.pixel_count()];
        r.interpolate(&tris, &values, &mut interp);
        let depth = r.depth();
        let mut worst = (0.0_f64, 0.0_f64);
        for (p, u, v) in pixels(&r) {
            let q = hit(c, u, v, corner, normal);
            let (s, t) = plate_coords(q, corner, e1, e2);
            // Pixel centres within 1e-9 (plate units) of the outline may go either way.
            let strictly_in = s > 1e-9 && s < 1.0 - 1e-9 && t > 1e-9 && t < 1.0 - 1e-9;
            let near = -1e-9..=1.0 + 1e-9;
            let strictly_out = !near.contains(&s) || !near.contains(&t);
            if strictly_out {
                assert_eq!(r.face[p], EMPTY, "pixel ({u}, {v}) outside the plate is covered");
                assert!(interp[p].is_nan() && depth[p].is_nan());
            }
            if strictly_in {
                assert_ne!(r.face[p], EMPTY, "pixel ({u}, {v}) inside the plate is empty");
            }
            if r.face[p] != EMPTY {
                let z_want = dot(c.r[2], q) + c.t[2];
                worst.0 = worst.0.max((r.z[p] - z_want).abs() / z_want);
                worst.1 = worst.1.max((f64::from(interp[p]) - field(q)).abs());
                let b = r.bary[p];
                assert!(b.iter().all(|&x| x >= 0.0) && (b.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            }
        }
        // Depth: rounding only. Interpolation: f32 output of values below 0.2 (~1e-8) plus the
        // pixel-to-plane geometry of this test; 1e-7 is far below the ~1e-4 error of
        // screen-space affine interpolation on the tilted plate (see below).
        assert!(worst.0 < 1e-9, "depth relative error {}", worst.0);
        assert!(worst.1 < 1e-7, "interpolation error {}", worst.1);

        // Area: a convex region of area A and perimeter P contains between A - P/2 and
        // A + P/2 + 1 lattice points (Nosarzewska), here pixel centres.
        let corners =
            [corner, add(corner, e1), add(add(corner, e1), e2), add(corner, e2)].map(|q| c.project(q).unwrap());
        let (mut area, mut perimeter) = (0.0, 0.0);
        for i in 0..4 {
            let (a, b) = (corners[i], corners[(i + 1) % 4]);
            area += 0.5 * (a[0] * b[1] - b[0] * a[1]);
            perimeter += ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
        }
        let count = r.covered() as f64;
        assert!(
            count > area.abs() - perimeter / 2.0 && count <= area.abs() + perimeter / 2.0 + 1.0,
            "{count} px for area {area}, perimeter {perimeter}"
        );
        r
    }

    #[test]
    fn fronto_parallel_plate() {
        let c = boson();
        let a = 0.05;
        for n in [1, 7] {
            let r = check_plate(&c, [-0.5 * a, -0.43 * a, 0.0], [a, 0.0, 0.0], [0.0, a, 0.0], n);
            // Depth is the plate's distance everywhere.
            for &z in r.z.iter().filter(|z| !z.is_nan()) {
                assert!((z - 0.3683).abs() < 1e-9 * 0.3683);
            }
        }
    }

    #[test]
    fn tilted_plate_needs_perspective_correct_interpolation() {
        let c = boson();
        let (a, th) = (0.08, 50_f64.to_radians());
        let e1 = [a * th.cos(), 0.0, a * th.sin()];
        let e2 = [0.0, a, 0.0];
        let corner = scale(add(e1, e2), -0.5);
        for n in [1, 5] {
            check_plate(&c, corner, e1, e2, n);
        }
        // The same pixels interpolated affinely in screen space (2D barycentrics of the
        // projected corners) miss the field by far more than the tolerance above.
        let (verts, tris) = grid_plate(corner, e1, e2, 1);
        let r = rasterize(&c, &verts, &tris);
        let mut worst = 0.0_f64;
        for (p, u, v) in pixels(&r).filter(|&(p, _, _)| r.face[p] != EMPTY) {
            let t = tris[r.face[p] as usize];
            let [a, b, d] = t.map(|i| c.project(verts[i]).unwrap());
            let det = (b[0] - a[0]) * (d[1] - a[1]) - (d[0] - a[0]) * (b[1] - a[1]);
            let l1 = ((u - a[0]) * (d[1] - a[1]) - (d[0] - a[0]) * (v - a[1])) / det;
            let l2 = ((b[0] - a[0]) * (v - a[1]) - (u - a[0]) * (b[1] - a[1])) / det;
            let affine = (1.0 - l1 - l2) * field(verts[t[0]]) + l1 * field(verts[t[1]]) + l2 * field(verts[t[2]]);
            let q = hit(&c, u, v, corner, cross(e1, e2));
            worst = worst.max((affine - field(q)).abs());
        }
        assert!(worst > 1e-4, "affine interpolation error only {worst}: the test would not detect it");
    }

    #[test]
    fn nearer_plate_wins() {
        let c = boson();
        let (back_v, back_t) = grid_plate([-0.03, -0.03, 0.0], [0.06, 0.0, 0.0], [0.0, 0.06, 0.0], 4);
        let front_corner = [0.0, -0.01, 0.02];
        let (front_v, front_t) = grid_plate(front_corner, [0.05, 0.0, 0.0], [0.0, 0.04, 0.0], 3);
        // Both orders: the result must not depend on which plate comes first.
        for front_first in [true, false] {
            let (first, second) = if front_first {
                ((&front_v, &front_t), (&back_v, &back_t))
            } else {
                ((&back_v, &back_t), (&front_v, &front_t))
            };
            let mut verts = first.0.clone();
            verts.extend_from_slice(second.0);
            let mut tris = first.1.clone();
            let off = first.0.len();
            tris.extend(second.1.iter().map(|t| t.map(|i| i + off)));
            let is_front = |f: u32| (f < first.1.len() as u32) == front_first;
            let r = rasterize(&c, &verts, &tris);
            let mut overlap = 0;
            for (p, u, v) in pixels(&r) {
                let q = hit(&c, u, v, front_corner, [0.0, 0.0, 1.0]);
                let (s, t) = plate_coords(q, front_corner, [0.05, 0.0, 0.0], [0.0, 0.04, 0.0]);
                if s > 1e-9 && s < 1.0 - 1e-9 && t > 1e-9 && t < 1.0 - 1e-9 {
                    assert!(is_front(r.face[p]), "pixel ({u}, {v}) shows the far plate or nothing");
                    assert!((r.z[p] - (0.3683 - 0.02)).abs() < 1e-12);
                    let back = hit(&c, u, v, [0.0; 3], [0.0, 0.0, 1.0]);
                    if back[0].abs() < 0.03 - 1e-9 && back[1].abs() < 0.03 - 1e-9 {
                        overlap += 1;
                    }
                } else if r.face[p] != EMPTY {
                    assert!(!is_front(r.face[p]) || s.min(t) > -1e-9 && s.max(t) < 1.0 + 1e-9);
                }
            }
            assert!(overlap > 1000, "the plates overlap on only {overlap} pixels");
        }
    }

    /// A camera with dyadic intrinsics at the origin looking along +z: rays through pixel
    /// centres and the edge functions of plates at z = 1 with corners on pixel centres are exact,
    /// so every tie of the fill rule really happens.
    fn dyadic_camera() -> Camera {
        Camera {
            width: 65,
            height: 65,
            k: [[64.0, 0.0, 32.0], [0.0, 64.0, 32.0], [0.0, 0.0, 1.0]],
            r: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            t: [0.0; 3],
        }
    }

    #[test]
    fn shared_edges_and_vertices_cover_each_pixel_exactly_once() {
        let c = dyadic_camera();
        // A 12 x 10 grid of 4-pixel cells with corners on pixel centres u = 8..56, v = 12..52:
        // every grid line, diagonal and vertex passes through pixel centres, and all
        // coordinates are dyadic, so the edge functions are exact there.
        let at =
            |i: usize, j: usize| [(8.0 + 4.0 * i as f64 - 32.0) / 64.0, (12.0 + 4.0 * j as f64 - 32.0) / 64.0, 1.0];
        let mut verts = Vec::new();
        for j in 0..=10 {
            for i in 0..=12 {
                verts.push(at(i, j));
            }
        }
        let id = |i: usize, j: usize| j * 13 + i;
        // Two triangulations: all diagonals one way (6 triangles at each interior vertex), and
        // alternating diagonals (4 or 8 triangles at a vertex).
        for alternate in [false, true] {
            let mut tris = Vec::new();
            for j in 0..10 {
                for i in 0..12 {
                    let [a, b, d, e] = [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)];
                    if alternate && (i + j) % 2 == 1 {
                        tris.extend([[a, b, e], [b, d, e]]);
                    } else {
                        tris.extend([[a, b, d], [a, d, e]]);
                    }
                }
            }
            // Rasterise every triangle alone and count how often each pixel is covered.
            let mut count = vec![0u32; 65 * 65];
            for t in &tris {
                let r = rasterize(&c, &verts, std::slice::from_ref(t));
                for (n, &f) in count.iter_mut().zip(&r.face) {
                    *n += u32::from(f != EMPTY);
                }
            }
            // Top-left rule: the left and top edges are in, the right and bottom edges out.
            let all = rasterize(&c, &verts, &tris);
            for (p, u, v) in pixels(&all) {
                let inside = (8.0..56.0).contains(&u) && (12.0..52.0).contains(&v);
                assert_eq!(count[p], u32::from(inside), "pixel ({u}, {v}) covered {} times", count[p]);
            }
            assert_eq!(all.covered(), 48 * 40);
        }
    }

    #[test]
    fn shared_edges_leave_no_gaps_with_inexact_coordinates() {
        // Plate corners off the pixel grid and a tessellation whose coordinates round: every
        // pixel centre strictly inside is covered exactly once (interior vertices lie within
        // rounding of a pixel centre with negligible probability).
        let c = boson();
        let (verts, tris) = grid_plate([-0.0311, -0.0277, 0.003], [0.061, 0.0, 0.012], [0.0, 0.049, -0.007], 23);
        let mut count = vec![0u32; c.pixel_count()];
        for t in &tris {
            let r = rasterize(&c, &verts, std::slice::from_ref(t));
            for (n, &f) in count.iter_mut().zip(&r.face) {
                *n += u32::from(f != EMPTY);
            }
        }
        let (corner, e1, e2) = ([-0.0311, -0.0277, 0.003], [0.061, 0.0, 0.012], [0.0, 0.049, -0.007]);
        let mut inside = 0;
        for (p, u, v) in pixels(&rasterize(&c, &verts, &tris)) {
            let (s, t) = plate_coords(hit(&c, u, v, corner, cross(e1, e2)), corner, e1, e2);
            if s > 1e-9 && s < 1.0 - 1e-9 && t > 1e-9 && t < 1.0 - 1e-9 {
                assert_eq!(count[p], 1, "pixel ({u}, {v})");
                inside += 1;
            } else {
                assert!(count[p] <= 1);
            }
        }
        assert!(inside > 40_000);
    }

    #[test]
    fn normals_and_face_values() {
        let c = boson();
        let (verts, tris) = grid_plate([-0.02, -0.02, 0.0], [0.04, 0.0, 0.0], [0.0, 0.04, 0.0], 3);
        let r = rasterize(&c, &verts, &tris);
        let normals = r.normals(&verts, &tris);
        let ids: Vec<f64> = (0..tris.len()).map(|f| f as f64).collect();
        let mut out = vec![0.0_f32; r.pixel_count()];
        r.interpolate_face(&ids, &mut out);
        let mask = r.mask();
        assert_eq!(mask.iter().filter(|&&m| m).count(), r.covered());
        assert!(r.covered() > 10_000);
        for p in 0..r.pixel_count() {
            if mask[p] {
                assert_eq!(normals[p], [0.0, 0.0, 1.0]);
                assert_eq!(out[p], r.face[p] as f32);
            } else {
                assert!(normals[p].iter().all(|x| x.is_nan()) && out[p].is_nan());
            }
        }
    }

    #[test]
    fn plate_crossing_the_camera_plane() {
        // A floor under the camera reaching behind it: only the part in front is drawn, and
        // every covered pixel shows the plane at the right depth.
        let c = boson();
        let (verts, tris) = grid_plate([-0.5, -0.5, -0.1], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5], 2);
        let r = rasterize(&c, &verts, &tris);
        let normal = cross([1.0, 0.0, 0.0], [0.0, 1.0, 0.5]);
        assert!(r.covered() > 0);
        for (p, u, v) in pixels(&r).filter(|&(p, _, _)| r.face[p] != EMPTY) {
            let q = hit(&c, u, v, [-0.5, -0.5, -0.1], normal);
            let z = dot(c.r[2], q) + c.t[2];
            assert!((r.z[p] - z).abs() < 1e-9 * z);
        }
    }

    #[test]
    fn same_result_on_one_thread() {
        let c = boson();
        let (verts, tris) = grid_plate([-0.05, -0.04, -0.02], [0.1, 0.0, 0.03], [0.0, 0.08, 0.01], 40);
        let many = rasterize(&c, &verts, &tris);
        let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        let one = pool.install(|| rasterize(&c, &verts, &tris));
        assert_eq!(many.face, one.face);
        assert_eq!(many.bary, one.bary);
        assert!(many.z.iter().zip(&one.z).all(|(a, b)| a.to_bits() == b.to_bits()));
    }
}

mod sensor {
    use super::*;

    const W: u32 = 640;
    const H: u32 = 512;
    const N: usize = (W * H) as usize;

    fn spec(netd: f64, fpn: f64, q: f64, seed: u64) -> CameraSpec {
        CameraSpec { netd, fixed_pattern_sigma: fpn, quantization: q, seed, ..CameraSpec::default() }
    }

    fn mean_std(x: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
        let n = x.clone().count() as f64;
        let mean = x.clone().sum::<f64>() / n;
        let var = x.map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
        (mean, var.sqrt())
    }

    fn expose(s: &Sensor, k: u64, t: f32) -> Vec<f32> {
        let mut out = vec![0.0; N];
        s.expose(k, &vec![t; N], &vec![true; N], &mut out);
        out
    }

    #[test]
    fn apparent_temperature() {
        for eps in [0.0, 0.3, 0.95, 1.0] {
            let s = Sensor::from_spec(&spec(0.0, 0.0, 0.0, 0), eps, 295.15).unwrap();
            assert!((s.apparent(295.15) - 295.15).abs() < 1e-12 * 295.15, "eps {eps}");
            let t = 310.0_f64;
            let want = (eps * t.powi(4) + (1.0 - eps) * 295.15_f64.powi(4)).powf(0.25);
            assert!((s.apparent(t) - want).abs() < 1e-12 * t);
            if eps == 1.0 {
                for t in [250.0, 295.15, 300.0, 373.15] {
                    assert!((s.apparent(t) - t).abs() < 1e-12 * t);
                }
            }
        }
        // Grey surface above ambient: between ambient and its true temperature, close to the
        // linearisation T_refl + eps (T - T_refl).
        let s = Sensor::from_spec(&spec(0.0, 0.0, 0.0, 0), 0.95, 295.0).unwrap();
        // Second-order term (n - 1)/2 eps (1 - eps) dT^2 / T_refl with n = 4: 6.0 mK.
        let app = s.apparent(300.0);
        let second = 1.5 * 0.95 * 0.05 * 25.0 / 295.0;
        assert!(app > 295.0 && app < 300.0 && (app - (295.0 + 0.95 * 5.0) - second).abs() < 1e-3, "{app}");
    }

    #[test]
    fn temporal_noise_statistics() {
        let s = Sensor::from_spec(&spec(0.05, 0.0, 0.0, 7), 1.0, 295.15).unwrap();
        let a = expose(&s, 0, 300.0);
        let b = expose(&s, 1, 300.0);
        // Sampling errors: sigma / sqrt(N) for the mean, sigma / sqrt(2 N) for the std; the f32
        // output adds rounding of at most 1.6e-5 K (half an ulp at 300 K).
        let (m, sd) = mean_std(a.iter().map(|&x| f64::from(x) - 300.0));
        assert!(m.abs() < 3.0 * 0.05 / (N as f64).sqrt() + 1.6e-5, "mean {m}");
        assert!((sd - 0.05).abs() < 3.0 * 0.05 / (2.0 * N as f64).sqrt() + 1.6e-5, "std {sd}");
        // Independent across frames: correlation within 3 / sqrt(N) of 0.
        let corr = a.iter().zip(&b).map(|(&x, &y)| (f64::from(x) - 300.0) * (f64::from(y) - 300.0)).sum::<f64>()
            / (N as f64 * 0.05 * 0.05);
        assert!(corr.abs() < 3.0 / (N as f64).sqrt(), "correlation {corr}");
        // ... and across neighbouring pixels.
        let corr = a.windows(2).map(|x| (f64::from(x[0]) - 300.0) * (f64::from(x[1]) - 300.0)).sum::<f64>()
            / (N as f64 * 0.05 * 0.05);
        assert!(corr.abs() < 3.0 / (N as f64).sqrt(), "neighbour correlation {corr}");
    }

    #[test]
    fn fixed_pattern_is_the_same_in_every_frame() {
        let s = Sensor::from_spec(&spec(0.0, 0.025, 0.0, 3), 1.0, 295.15).unwrap();
        let (m, sd) = mean_std(s.fixed_pattern().iter().copied());
        assert!(m.abs() < 3.0 * 0.025 / (N as f64).sqrt(), "mean {m}");
        assert!((sd - 0.025).abs() < 3.0 * 0.025 / (2.0 * N as f64).sqrt(), "std {sd}");
        let f0 = expose(&s, 0, 300.0);
        assert_eq!(f0, expose(&s, 9, 300.0));
        for (&y, &o) in f0.iter().zip(s.fixed_pattern()) {
            assert_eq!(y, (300.0 + o) as f32);
        }
        // With temporal noise too, the frame average converges to the fixed pattern: the
        // difference of two frames has no fixed part and std sqrt(2) NETD.
        let s = Sensor::from_spec(&spec(0.05, 0.025, 0.0, 3), 1.0, 295.15).unwrap();
        let (a, b) = (expose(&s, 4, 300.0), expose(&s, 5, 300.0));
        let (_, sd) = mean_std(a.iter().zip(&b).map(|(&x, &y)| f64::from(x) - f64::from(y)));
        let want = 0.05 * 2f64.sqrt();
        assert!((sd - want).abs() < 3.0 * want / (2.0 * N as f64).sqrt() + 3.2e-5, "std {sd}");
        // The frame of the other spec has the same fixed pattern (same seed).
        let corr = a.iter().zip(s.fixed_pattern()).map(|(&x, &o)| (f64::from(x) - 300.0) * o).sum::<f64>()
            / (N as f64 * 0.025 * 0.025);
        assert!((corr - 1.0).abs() < 0.02, "fixed-pattern correlation {corr}");
    }

    #[test]
    fn seeded_and_order_independent() {
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let s1 = Sensor::from_spec(&spec(0.05, 0.025, 0.01, 11), 0.95, 295.15).unwrap();
        let s2 = Sensor::from_spec(&spec(0.05, 0.025, 0.01, 11), 0.95, 295.15).unwrap();
        let other = Sensor::from_spec(&spec(0.05, 0.025, 0.01, 12), 0.95, 295.15).unwrap();
        // Frames 0..4 in order on s1; frame 3 first, then the others, on s2; in parallel.
        let in_order: Vec<Vec<f32>> = (0..4).map(|k| expose(&s1, k, 301.0)).collect();
        let f3_first = expose(&s2, 3, 301.0);
        assert_eq!(bits(&f3_first), bits(&in_order[3]));
        use rayon::prelude::*;
        let parallel: Vec<Vec<f32>> = (0..4usize)
            .into_par_iter()
            .rev()
            .map(|k| expose(&s2, k as u64, 301.0))
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .collect();
        for k in 0..4 {
            assert_eq!(bits(&parallel[k]), bits(&in_order[k]), "frame {k}");
        }
        let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
        assert_eq!(bits(&pool.install(|| expose(&s1, 2, 301.0))), bits(&in_order[2]));
        assert_ne!(in_order[0], in_order[1]);
        let differ = expose(&other, 0, 301.0).iter().zip(&in_order[0]).filter(|(a, b)| a != b).count();
        assert!(differ > N * 9 / 10, "only {differ} pixels differ for another seed");
        // Huge frame indices are fine (each is its own stream).
        assert_ne!(expose(&s1, u64::MAX, 301.0), expose(&s1, u64::MAX - 1, 301.0));
    }

    #[test]
    fn quantisation_puts_values_on_the_grid() {
        let q = 0.01;
        let s = Sensor::from_spec(&spec(0.05, 0.025, q, 5), 0.9, 295.15).unwrap();
        let out = expose(&s, 0, 303.3);
        let mut distinct = std::collections::BTreeSet::new();
        for &y in &out {
            // Every value is the f32 nearest to a multiple of q.
            assert_eq!(y, ((f64::from(y) / q).round() * q) as f32);
            distinct.insert(y.to_bits());
        }
        // NETD and FPN span many steps.
        assert!(distinct.len() > 20);
    }

    #[test]
    fn background_reports_the_ambient_temperature() {
        let s = Sensor::from_spec(&spec(0.0, 0.0, 0.0, 0), 0.9, 294.0).unwrap();
        let mut clean = vec![f32::NAN; N];
        let mut mask = vec![false; N];
        for p in (0..N).step_by(3) {
            clean[p] = 310.0;
            mask[p] = true;
        }
        let mut out = vec![0.0; N];
        s.expose(0, &clean, &mask, &mut out);
        for p in 0..N {
            let want = if mask[p] { s.apparent(310.0) as f32 } else { 294.0 };
            assert_eq!(out[p], want);
        }
        assert!(out[0] < 310.0 && out[0] > 294.0 + 0.9 * 16.0 - 0.1);
    }

    /// Films with optics are finite off the mask where blurred or partly covered object
    /// radiance arrives: the sensor reports those values as it reports the object's, and the
    /// background only where the film is NaN.
    #[test]
    fn finite_film_values_off_the_mask_are_exposed() {
        let s = Sensor::from_spec(&spec(0.0, 0.0, 0.0, 0), 0.9, 294.0).unwrap();
        // Even pixels carry radiance (every fourth one under the mask), odd ones none.
        let clean: Vec<f32> = (0..N).map(|p| if p % 2 == 0 { 300.0 } else { f32::NAN }).collect();
        let mask: Vec<bool> = (0..N).map(|p| p % 4 == 0).collect();
        let mut out = vec![0.0; N];
        s.expose(0, &clean, &mask, &mut out);
        let mut clean64 = vec![0.0; N];
        s.expose_clean(&clean.iter().map(|&t| f64::from(t)).collect::<Vec<_>>(), &mask, &mut clean64);
        for p in 0..N {
            let want = if p % 2 == 0 { s.apparent(300.0) } else { 294.0 };
            assert_eq!(out[p], want as f32, "pixel {p}");
            assert_eq!(clean64[p], want, "pixel {p}");
        }
        // Under the mask a NaN stays NaN: a film that should cover the pixel but does not.
        let mut out = vec![0.0; N];
        s.expose(0, &vec![f32::NAN; N], &vec![true; N], &mut out);
        assert!(out.iter().all(|x| x.is_nan()));
    }

    #[test]
    fn invalid_parameters_name_the_field() {
        let field = |r: Result<Sensor, CameraError>| match r {
            Err(CameraError::Invalid { field, .. }) => field,
            Ok(_) => panic!("accepted an invalid sensor"),
            Err(e) => panic!("unexpected error {e}"),
        };
        let d = CameraSpec::default();
        assert_eq!(field(Sensor::from_spec(&d, 1.5, 295.0)), "emissivity");
        assert_eq!(field(Sensor::from_spec(&d, f64::NAN, 295.0)), "emissivity");
        assert_eq!(field(Sensor::from_spec(&d, 0.9, 0.0)), "reflected_temperature");
        assert_eq!(field(Sensor::from_spec(&CameraSpec { netd: -0.1, ..d.clone() }, 0.9, 295.0)), "camera.netd");
        assert_eq!(
            field(Sensor::from_spec(&CameraSpec { fixed_pattern_sigma: f64::NAN, ..d.clone() }, 0.9, 295.0)),
            "camera.fixed_pattern_sigma"
        );
        assert_eq!(
            field(Sensor::from_spec(&CameraSpec { quantization: f64::INFINITY, ..d.clone() }, 0.9, 295.0)),
            "camera.quantization"
        );
        assert_eq!(field(Sensor::from_spec(&CameraSpec { height: 0, ..d }, 0.9, 295.0)), "camera.height");
    }
}

mod preview {
    use super::*;
    use std::io::Cursor;

    #[test]
    fn png_decodes_with_the_right_size_colours_and_range() {
        let (w, h) = (64u32, 48u32);
        let mut image: Vec<f32> = (0..w * h).map(|p| 295.0 + 10.0 * (p % w) as f32 / (w - 1) as f32).collect();
        image[5 * w as usize + 3] = f32::NAN;
        let mut bytes = Vec::new();
        write_preview_png(&mut bytes, &image, w, h, 295.0, 305.0).unwrap();

        let mut reader = png::Decoder::new(Cursor::new(bytes)).read_info().unwrap();
        let info = reader.info();
        let out_w = w + heatsim::camera::preview::BAR_GAP + heatsim::camera::preview::BAR_WIDTH;
        assert_eq!((info.width, info.height), (out_w, h));
        assert_eq!(info.color_type, png::ColorType::Rgb);
        let text: Vec<(String, String)> =
            info.uncompressed_latin1_text.iter().map(|c| (c.keyword.clone(), c.text.clone())).collect();
        assert!(text.contains(&("Minimum".to_owned(), "295".to_owned())), "{text:?}");
        assert!(text.contains(&("Maximum".to_owned(), "305".to_owned())), "{text:?}");
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        reader.next_frame(&mut buf).unwrap();
        let px = |x: u32, y: u32| {
            let i = 3 * (y * out_w + x) as usize;
            [buf[i], buf[i + 1], buf[i + 2]]
        };
        assert_eq!(px(0, 0), [0, 0, 4], "lo is inferno's black");
        assert_eq!(px(w - 1, 0), [252, 255, 164], "hi is inferno's pale yellow");
        assert_eq!(px(3, 5), heatsim::camera::preview::NO_DATA);
        // Colour bar: bright at the top, dark at the bottom.
        let (top, bottom) = (px(out_w - 1, 0), px(out_w - 1, h - 1));
        assert!(
            top.iter().map(|&c| u32::from(c)).sum::<u32>() > 500
                && bottom.iter().map(|&c| u32::from(c)).sum::<u32>() < 60
        );
    }

    /// Decodes a preview: its pixels and its metadata range.
    fn decode(bytes: Vec<u8>) -> (Vec<u8>, f32, f32) {
        let mut reader = png::Decoder::new(Cursor::new(bytes)).read_info().unwrap();
        let text = |key: &str| -> f32 {
            let chunk = reader.info().uncompressed_latin1_text.iter().find(|c| c.keyword == key).unwrap();
            chunk.text.parse().unwrap()
        };
        let (lo, hi) = (text("Minimum"), text("Maximum"));
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        reader.next_frame(&mut buf).unwrap();
        (buf, lo, hi)
    }

    #[test]
    fn degenerate_images_still_give_a_picture() {
        // A uniform frame (the thin plate under uniform heating): mid colour, range around it.
        let mut bytes = Vec::new();
        write_preview_png(&mut bytes, &[296.05798; 6], 3, 2, 296.05798, 296.05798).unwrap();
        let (px, lo, hi) = decode(bytes);
        assert!(lo < 296.05798 && hi > 296.05798 && hi - lo < 0.01, "{lo} {hi}");
        assert_eq!(px[..3], heatsim::camera::preview::inferno(0.5));
        // A single pixel; an image that is all NaN (no finite range: grey, range 0..1).
        let mut bytes = Vec::new();
        write_preview_png(&mut bytes, &[1.0], 1, 1, 1.0, 1.0).unwrap();
        assert_eq!(
            decode(bytes).0.len(),
            3 * (1 + heatsim::camera::preview::BAR_GAP + heatsim::camera::preview::BAR_WIDTH) as usize
        );
        let mut bytes = Vec::new();
        write_preview_png(&mut bytes, &[f32::NAN; 4], 2, 2, f32::INFINITY, f32::NEG_INFINITY).unwrap();
        let (px, lo, hi) = decode(bytes);
        assert_eq!((lo, hi), (0.0, 1.0));
        assert_eq!(px[..3], heatsim::camera::preview::NO_DATA);
    }

    #[test]
    fn invalid_input_is_an_error() {
        let mut sink = Vec::new();
        let e = write_preview_png(&mut sink, &[1.0; 5], 3, 2, 0.0, 1.0).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
        let e = write_preview_png(&mut sink, &[], 0, 0, 0.0, 1.0).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
    }
}
