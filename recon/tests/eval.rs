//! `heatrecon::eval` on known transforms and perturbations of meshes built here: the errors it
//! reports must be the ones put in (closed forms), and the transforms it finds the inverses
//! of those applied.

use heatrecon::eval::{
    crop_to_view, evaluate, AlignMode, CropTolerance, DepthView, EvalError, EvalOptions, Similarity,
};
use heatsim::mesh::TriMesh;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use std::collections::HashMap;

fn opts(align: AlignMode) -> EvalOptions {
    EvalOptions { align, ..EvalOptions::default() }
}

/// Unit icosphere: the icosahedron subdivided `level` times, outward, closed.
fn icosphere(level: usize) -> TriMesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<[f64; 3]> = vec![
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
    ];
    let mut f: Vec<[usize; 3]> = vec![
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
    let normalize = |p: [f64; 3]| {
        let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        [p[0] / n, p[1] / n, p[2] / n]
    };
    for p in v.iter_mut() {
        *p = normalize(*p);
    }
    for _ in 0..level {
        let mut mid: HashMap<(usize, usize), usize> = HashMap::new();
        let mut nf = Vec::with_capacity(f.len() * 4);
        for t in &f {
            let mut m = [0usize; 3];
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let key = (a.min(b), a.max(b));
                m[k] = *mid.entry(key).or_insert_with(|| {
                    let p =
                        normalize([(v[a][0] + v[b][0]) / 2.0, (v[a][1] + v[b][1]) / 2.0, (v[a][2] + v[b][2]) / 2.0]);
                    v.push(p);
                    v.len() - 1
                });
            }
            nf.push([t[0], m[0], m[2]]);
            nf.push([t[1], m[1], m[0]]);
            nf.push([t[2], m[2], m[1]]);
            nf.push([m[0], m[1], m[2]]);
        }
        f = nf;
    }
    TriMesh::try_new(v, f).unwrap()
}

/// A closed, asymmetric "potato" about 10 cm long (m): an icosphere stretched to semi-axes
/// 5 / 3.5 / 2.5 cm with a bump, so that every rotation changes it.
fn potato() -> TriMesh {
    icosphere(4).transformed(|p| {
        let w = 1.0 + 0.15 * (3.0 * p[0] + 1.0).sin() * (2.0 * p[1]).cos() + 0.1 * p[2] * p[0];
        [0.05 * p[0] * w, 0.035 * p[1] * w, 0.025 * p[2] * w]
    })
}

/// A hemispherical dome of radius `r` (m) over z = 0, apex at +z, normals outward; `rings`
/// latitude bands, `segs` longitude segments.
fn hemisphere(r: f64, rings: usize, segs: usize) -> TriMesh {
    let mut v = vec![[0.0, 0.0, r]];
    for i in 1..=rings {
        let th = std::f64::consts::FRAC_PI_2 * i as f64 / rings as f64;
        for j in 0..segs {
            let ph = 2.0 * std::f64::consts::PI * j as f64 / segs as f64;
            v.push([r * th.sin() * ph.cos(), r * th.sin() * ph.sin(), r * th.cos()]);
        }
    }
    let id = |i: usize, j: usize| 1 + (i - 1) * segs + (j % segs);
    let mut f = Vec::new();
    for j in 0..segs {
        f.push([0, id(1, j), id(1, j + 1)]);
    }
    for i in 1..rings {
        for j in 0..segs {
            f.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            f.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    TriMesh::try_new(v, f).unwrap()
}

/// An n x n vertex grid over [-L/2, L/2]^2 in z = 0 (m), normals +z.
fn plane(n: usize, size: f64) -> TriMesh {
    let mut v = Vec::new();
    for i in 0..n {
        for j in 0..n {
            v.push([size * (j as f64 / (n - 1) as f64 - 0.5), size * (i as f64 / (n - 1) as f64 - 0.5), 0.0]);
        }
    }
    let mut f = Vec::new();
    for i in 0..n - 1 {
        for j in 0..n - 1 {
            let a = i * n + j;
            f.push([a, a + 1, a + n + 1]);
            f.push([a, a + n + 1, a + n]);
        }
    }
    TriMesh::try_new(v, f).unwrap()
}

fn rotation(axis: [f64; 3], deg: f64) -> [[f64; 3]; 3] {
    let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
    heatrecon::eval::icp::rodrigues(axis.map(|a| a / n * deg.to_radians()))
}

/// The composition `a` after `b`.
#[allow(clippy::needless_range_loop)]
fn compose(a: &Similarity, b: &Similarity) -> Similarity {
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = (0..3).map(|k| a.rotation[i][k] * b.rotation[k][j]).sum();
        }
    }
    let tb = a.apply(b.translation);
    Similarity { rotation: r, translation: tb, scale: a.scale * b.scale }
}

/// How far `t` is from the identity: (rotation angle in degrees, |translation| in m, |scale - 1|).
fn distance_from_identity(t: &Similarity) -> (f64, f64, f64) {
    let tr = t.translation;
    (t.angle_deg(), (tr[0] * tr[0] + tr[1] * tr[1] + tr[2] * tr[2]).sqrt(), (t.scale - 1.0).abs())
}

#[test]
fn identical_meshes_score_zero() {
    for (name, mesh) in [("potato", potato()), ("hemisphere", hemisphere(0.05, 24, 64))] {
        for align in [AlignMode::None, AlignMode::Rigid, AlignMode::Similarity] {
            let e = evaluate(&mesh, &mesh, &opts(align)).unwrap();
            let j = e.to_json();
            for key in ["mae_mm", "reverse_mae_mm", "symmetric_mm", "rmse_mm", "p95_mm"] {
                let v = j[key].as_f64().unwrap();
                assert!(v.abs() < 1e-9, "{name} {align:?}: {key} = {v} mm");
            }
            assert!(j["area_weighted"]["mae_mm"].as_f64().unwrap() < 1e-9, "{name} {align:?}");
            assert!(e.normal_deg < 1e-5, "{name} {align:?}: normal error {} deg", e.normal_deg);
            let (ang, tr, sc) = distance_from_identity(&e.alignment.transform);
            assert!(ang < 1e-6 && tr < 1e-12 && sc < 1e-12, "{name} {align:?}: {:?}", e.alignment.transform);
        }
    }
}

#[test]
fn rigid_transform_is_recovered() {
    let gt = potato();
    // Move the ground truth by 10 degrees about a skew axis and 1 cm: that is the "reconstruction".
    let moved =
        Similarity { rotation: rotation([1.0, 2.0, 0.5], 10.0), translation: [0.01, -0.004, 0.003], scale: 1.0 };
    let recon = gt.transformed(|p| moved.apply(p));
    // Without alignment the error is large ...
    let none = evaluate(&recon, &gt, &opts(AlignMode::None)).unwrap();
    assert!(none.mae_mm() > 3.0, "unaligned {} mm", none.mae_mm());
    // ... and rigid ICP removes it and finds the inverse transform.
    let e = evaluate(&recon, &gt, &opts(AlignMode::Rigid)).unwrap();
    assert!(e.mae_mm() < 1e-6, "mae {} mm", e.mae_mm());
    assert!(e.symmetric_mm() < 1e-6, "symmetric {} mm", e.symmetric_mm());
    assert!(e.normal_deg < 1e-4, "normals {} deg", e.normal_deg);
    let back = compose(&e.alignment.transform, &moved);
    let (ang, tr, sc) = distance_from_identity(&back);
    assert!(ang < 1e-6 && tr < 1e-9 && sc == 0.0, "found {:?}, residual {ang} deg, {tr} m", e.alignment.transform);
    assert!((e.alignment.transform.angle_deg() - 10.0).abs() < 1e-6);
    assert!(e.alignment.converged && e.alignment.inlier_fraction > 0.9);
}

#[test]
fn rotation_from_principal_axes_start_is_recovered() {
    // 120 degrees: beyond the reach of ICP from the identity; the principal-axes starts find it.
    let gt = potato();
    let moved = Similarity { rotation: rotation([0.3, -1.0, 0.4], 120.0), translation: [0.2, 0.1, -0.05], scale: 1.0 };
    let recon = gt.transformed(|p| moved.apply(p));
    let e = evaluate(&recon, &gt, &opts(AlignMode::Rigid)).unwrap();
    assert!(e.mae_mm() < 1e-6, "mae {} mm (start {})", e.mae_mm(), e.alignment.start);
    let (ang, tr, _) = distance_from_identity(&compose(&e.alignment.transform, &moved));
    assert!(ang < 1e-6 && tr < 1e-9, "residual {ang} deg {tr} m");
}

#[test]
fn scale_is_recovered_by_similarity() {
    let gt = potato();
    let moved =
        Similarity { rotation: rotation([0.0, 1.0, 1.0], 5.0), translation: [0.003, 0.002, -0.001], scale: 1.25 };
    let recon = gt.transformed(|p| moved.apply(p));
    // Rigid alignment cannot undo a 25 % scale.
    let rigid = evaluate(&recon, &gt, &opts(AlignMode::Rigid)).unwrap();
    assert!(rigid.mae_mm() > 1.0, "rigid {} mm", rigid.mae_mm());
    let e = evaluate(&recon, &gt, &opts(AlignMode::Similarity)).unwrap();
    assert!(e.mae_mm() < 1e-6, "mae {} mm", e.mae_mm());
    assert!((e.alignment.transform.scale - 1.0 / 1.25).abs() < 1e-9, "scale {}", e.alignment.transform.scale);
    let (ang, tr, sc) = distance_from_identity(&compose(&e.alignment.transform, &moved));
    assert!(ang < 1e-6 && tr < 1e-9 && sc < 1e-9, "residual {ang} deg {tr} m {sc}");
}

#[test]
fn unaligned_offset_along_the_normal_is_reported_exactly() {
    let gt = plane(41, 0.1);
    let recon = gt.transformed(|p| [p[0], p[1], p[2] + 0.002]);
    let e = evaluate(&recon, &gt, &opts(AlignMode::None)).unwrap();
    for (what, v) in [
        ("mae", e.mae_mm()),
        ("reverse", e.reverse.mean * 1e3),
        ("p95", e.forward.p95 * 1e3),
        ("rmse", e.forward.rmse * 1e3),
        ("area", e.forward_area.mean * 1e3),
    ] {
        assert!((v - 2.0).abs() < 1e-9, "{what}: {v} mm");
    }
    assert!(e.normal_deg < 1e-9);
    assert!(e.vertex_signed_m.iter().all(|s| (s - 0.002).abs() < 1e-12), "above the plane: positive");
    // A rigid alignment removes the offset.
    let e = evaluate(&recon, &gt, &opts(AlignMode::Rigid)).unwrap();
    assert!(e.mae_mm() < 1e-6, "aligned {} mm", e.mae_mm());
    assert!((e.alignment.transform.translation[2] + 0.002).abs() < 1e-9);
}

#[test]
fn normal_noise_gives_sigma_sqrt_two_over_pi() {
    let sigma = 5e-4; // m
    let n = 201; // 40,401 vertices
    let gt = plane(n, 0.1);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let normal = Normal::new(0.0, sigma).unwrap();
    let verts = gt.verts.iter().map(|p| [p[0], p[1], normal.sample(&mut rng)]).collect();
    let recon = TriMesh::try_new(verts, gt.tris.clone()).unwrap();
    let expected = sigma * (2.0 / std::f64::consts::PI).sqrt();
    // Standard error of the mean of |X|: sigma sqrt(1 - 2/pi) / sqrt(N).
    let se = sigma * (1.0 - 2.0 / std::f64::consts::PI).sqrt() / ((n * n) as f64).sqrt();
    let e = evaluate(&recon, &gt, &opts(AlignMode::None)).unwrap();
    assert!((e.forward.mean - expected).abs() < 4.0 * se, "mae {} vs {expected} (se {se})", e.forward.mean);
    // RMSE ~ sigma, and the 95th percentile of |X| is 1.96 sigma.
    assert!((e.forward.rmse - sigma).abs() < 0.01 * sigma, "rmse {}", e.forward.rmse);
    assert!((e.forward.p95 - 1.96 * sigma).abs() < 0.03 * sigma, "p95 {}", e.forward.p95);
    // Rigid ICP on pure noise barely moves (the least-squares plane of the noise is the plane).
    let r = evaluate(&recon, &gt, &opts(AlignMode::Rigid)).unwrap();
    assert!((r.forward.mean - expected).abs() < 6.0 * se, "aligned mae {} vs {expected}", r.forward.mean);
}

#[test]
fn partial_reconstruction_is_penalised_by_the_symmetric_measure() {
    let gt = hemisphere(0.05, 24, 64);
    // Keep the faces with centroid x > 0: half of the dome.
    let tris: Vec<[usize; 3]> =
        gt.tris.iter().copied().filter(|t| t.iter().map(|&i| gt.verts[i][0]).sum::<f64>() > 0.0).collect();
    let half = TriMesh::try_new(gt.verts.clone(), tris).unwrap();
    for align in [AlignMode::None, AlignMode::Rigid] {
        let e = evaluate(&half, &gt, &opts(align)).unwrap();
        assert!(e.mae_mm() < 1e-6, "{align:?}: forward {} mm", e.mae_mm());
        // Unused vertices of `half` count in the forward direction; they lie on gt, distance 0.
        assert!(e.reverse.mean * 1e3 > 5.0, "{align:?}: reverse {} mm", e.reverse.mean * 1e3);
        assert!(e.symmetric_mm() > 2.5, "{align:?}: symmetric {} mm", e.symmetric_mm());
    }
}

#[test]
fn a_reconstruction_far_away_is_an_error() {
    let gt = hemisphere(0.05, 12, 32);
    let recon = gt.transformed(|p| [p[0] + 1.0, p[1], p[2]]);
    let err = evaluate(&recon, &gt, &opts(AlignMode::None)).unwrap_err();
    assert!(matches!(err, EvalError::NotNear { .. }), "{err}");
    let msg = err.to_string();
    assert!(msg.contains("nowhere near") && msg.contains("--align rigid"), "{msg}");
    // Rigid alignment from the centroid start finds it.
    let e = evaluate(&recon, &gt, &opts(AlignMode::Rigid)).unwrap();
    assert!(e.mae_mm() < 1e-6, "{} mm: {:?}", e.mae_mm(), e.alignment);
}

/// A camera 0.5 m above the plane looking down -z at a 64 x 48 image whose field of view
/// covers only part of the plane, the depth map of the plane written as a dataset would.
#[test]
fn cropping_keeps_what_the_camera_saw() {
    let gt = plane(81, 0.4); // 40 cm square, 5 mm grid
    let (w, h) = (64usize, 48usize);
    let f = 100.0; // pixels: at 0.5 m a pixel covers 5 mm; the image 32 x 24 cm
    let (cx, cy) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
    let k = [[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]];
    // Looking down: camera x = world x, camera y = -world y, camera z = -world z; centre at z = 0.5.
    let r = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]];
    let t = [0.0, 0.0, 0.5];
    // Depth of the plane is 0.5 everywhere, except a hole (NaN: "not the object") on the left.
    let depth = ndarray::Array2::from_shape_fn((h, w), |(_, u)| if u < 16 { f32::NAN } else { 0.5f32 });
    let dir = tempfile::tempdir().unwrap();
    let cam = serde_json::json!({"K": k, "R": r, "t": t, "width": w, "height": h, "other": 1});
    std::fs::write(dir.path().join("camera.json"), cam.to_string()).unwrap();
    ndarray_npy::write_npy(dir.path().join("gt_depth.npy"), &depth).unwrap();
    let view = DepthView::load(dir.path()).unwrap().expect("both files present");
    let crop = crop_to_view(&gt, &view, &CropTolerance::default()).unwrap();
    assert_eq!(crop.total, gt.tris.len());
    // Every kept centroid projects into the image right of column 16 (up to the 3 x 3 block).
    for tri in &crop.mesh.tris {
        let c = tri.iter().fold([0.0; 3], |a, &i| {
            let p = crop.mesh.verts[i];
            [a[0] + p[0] / 3.0, a[1] + p[1] / 3.0, a[2] + p[2] / 3.0]
        });
        let u = f * c[0] / 0.5 + cx;
        let v = f * (-c[1]) / 0.5 + cy;
        assert!(u >= 14.5 && u < w as f64 - 0.5 && (-0.5..h as f64 - 0.5).contains(&v), "({u}, {v})");
    }
    // Area: the visible region is (64 - 16 + 1 neighbour column) x 48 pixels of 5 mm, about.
    let area = crop.mesh.area();
    let expected = (49.0 * 0.005) * (48.0 * 0.005);
    assert!((area - expected).abs() < 0.1 * expected, "area {area} vs {expected}");
    // A plane behind the visible one (10 cm deeper) is occluded: nothing kept.
    let behind = gt.transformed(|p| [p[0], p[1], p[2] - 0.1]);
    assert!(crop_to_view(&behind, &view, &CropTolerance::default()).is_err());
    // Missing camera.json: no view.
    std::fs::remove_file(dir.path().join("camera.json")).unwrap();
    assert!(DepthView::load(dir.path()).unwrap().is_none());
    // A depth map of the wrong shape is an error naming the file.
    std::fs::write(
        dir.path().join("camera.json"),
        serde_json::json!({"K": k, "R": r, "t": t, "width": 10, "height": 10}).to_string(),
    )
    .unwrap();
    let err = DepthView::load(dir.path()).unwrap_err().to_string();
    assert!(err.contains("gt_depth.npy") && err.contains("does not match"), "{err}");
}

/// An open surface (a dome, as the reconstructions of the shape-error table), tessellated
/// differently from the truth, shrunk by 1/1.1 and moved: the similarity alignment finds the
/// scale (the forward-only similarity ICP shrank such surfaces towards a point).
#[test]
fn scale_of_an_open_surface_is_recovered_by_similarity() {
    let gt = hemisphere(0.05, 24, 64);
    let moved =
        Similarity { rotation: rotation([1.0, 0.0, 0.3], 4.0), translation: [0.002, -0.001, 0.004], scale: 1.0 / 1.1 };
    let recon = hemisphere(0.05, 18, 48).transformed(|p| moved.apply(p));
    let e = evaluate(&recon, &gt, &opts(AlignMode::Similarity)).unwrap();
    let s = e.alignment.transform.scale;
    assert!((s - 1.1).abs() < 0.005 * 1.1, "scale {s}, expected 1.1: {:?}", e.alignment);
    // The two tessellations' chords differ by up to 0.1 mm (sagitta of 48 segments on 5 cm), and
    // the symmetric criterion's reverse half prefers a slightly larger recon to cover the
    // truth's vertices: 0.19 mm measured.
    assert!(e.mae_mm() < 0.3, "mae {} mm after similarity", e.mae_mm());
}
