//! `simbench eval` end to end: JSON output, alignment modes, cropping beside a dataset,
//! the PLY output, and bad input (clear message naming the file, exit code 1, no panic).

use heatsim::mesh::{write_obj, write_ply, TriMesh};
use std::path::Path;
use std::process::{Command, Output};

fn simbench(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_simbench")).args(args).output().expect("simbench runs")
}

fn json_of(out: &Output) -> serde_json::Value {
    assert!(out.status.success(), "simbench failed: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("stdout is JSON")
}

fn fails_with(out: &Output, needles: &[&str]) {
    assert_eq!(out.status.code(), Some(1), "stderr: {}", String::from_utf8_lossy(&out.stderr));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    for n in needles {
        assert!(err.contains(n), "stderr lacks {n:?}: {err}");
    }
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

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn offset_plane_scores_its_offset_and_rigid_alignment_removes_it() {
    let dir = tempfile::tempdir().unwrap();
    let gt_path = dir.path().join("gt.obj");
    let recon_path = dir.path().join("recon.ply");
    let gt = plane(31, 0.1);
    write_obj(&gt_path, &gt, "plane").unwrap();
    write_ply(&recon_path, &gt.transformed(|p| [p[0], p[1], p[2] + 0.002]), &[], "plane + 2 mm").unwrap();

    let j = json_of(&simbench(&["eval", "--recon", s(&recon_path), "--gt", s(&gt_path), "--align", "none"]));
    for key in ["mae_mm", "reverse_mae_mm", "symmetric_mm", "rmse_mm", "p95_mm"] {
        let v = j[key].as_f64().unwrap();
        assert!((v - 2.0).abs() < 1e-9, "{key} = {v}");
    }
    assert!(j["normal_deg"].as_f64().unwrap() < 1e-9);
    assert_eq!(j["alignment"]["mode"], "none");
    assert_eq!(j["crop"]["applied"], false);
    assert_eq!(j["counts"]["recon_vertices"], 961);
    assert_eq!(j["counts"]["gt_triangles"], 1800);
    assert!(j["seconds"].as_f64().unwrap() > 0.0);

    let j = json_of(&simbench(&["eval", "--recon", s(&recon_path), "--gt", s(&gt_path)]));
    assert_eq!(j["alignment"]["mode"], "rigid", "rigid is the default");
    assert!(j["mae_mm"].as_f64().unwrap() < 1e-6, "{}", j["mae_mm"]);
    let tz = j["alignment"]["translation_m"][2].as_f64().unwrap();
    assert!((tz + 0.002).abs() < 1e-9, "translation z {tz}");
    assert_eq!(j["alignment"]["scale"], 1.0);
}

#[test]
fn scaled_mesh_with_similarity_and_the_ply_output() {
    let dir = tempfile::tempdir().unwrap();
    let gt_path = dir.path().join("gt.obj");
    let recon_path = dir.path().join("recon.obj");
    // A bumpy height field, so that the scale is determined.
    let gt = plane(41, 0.1).transformed(|p| [p[0], p[1], 0.01 * (40.0 * p[0]).sin() * (30.0 * p[1]).cos()]);
    write_obj(&gt_path, &gt, "bumps").unwrap();
    write_obj(&recon_path, &gt.transformed(|p| [1.1 * p[0], 1.1 * p[1], 1.1 * p[2] + 0.001]), "scaled").unwrap();
    let out_ply = dir.path().join("aligned.ply");
    let j = json_of(&simbench(&[
        "eval",
        "--recon",
        s(&recon_path),
        "--gt",
        s(&gt_path),
        "--align",
        "similarity",
        "--out-ply",
        s(&out_ply),
    ]));
    let scale = j["alignment"]["scale"].as_f64().unwrap();
    assert!((scale - 1.0 / 1.1).abs() < 1e-6, "scale {scale}");
    assert!(j["mae_mm"].as_f64().unwrap() < 1e-4, "{}", j["mae_mm"]);
    let aligned = heatsim::mesh::read_surface(&out_ply).unwrap();
    assert_eq!(aligned.tris, gt.tris);
    let header = std::fs::read(&out_ply).unwrap();
    assert!(String::from_utf8_lossy(&header[..400]).contains("property float signed_error_m"));
}

/// A dataset directory: the ground truth beside camera.json and gt_depth.npy (as
/// `simbench simulate` writes them) is cropped to the pixels the camera saw, and the size is
/// measured in its depth image.
#[test]
fn ground_truth_beside_a_dataset_is_cropped() {
    let dir = tempfile::tempdir().unwrap();
    let gt_path = dir.path().join("gt_mesh.obj");
    let gt = plane(81, 0.4);
    write_obj(&gt_path, &gt, "plane").unwrap();
    let (w, h, f) = (64usize, 48usize, 100.0);
    let cam = serde_json::json!({
        "K": [[f, 0.0, (w as f64 - 1.0) / 2.0], [0.0, f, (h as f64 - 1.0) / 2.0], [0.0, 0.0, 1.0]],
        "R": [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]],
        "t": [0.0, 0.0, 0.5], "width": w, "height": h,
    });
    std::fs::write(dir.path().join("camera.json"), cam.to_string()).unwrap();
    let depth = ndarray::Array2::<f32>::from_elem((h, w), 0.5);
    ndarray_npy::write_npy(dir.path().join("gt_depth.npy"), &depth).unwrap();
    // The reconstruction: only the part in view (32 x 24 cm), 1 mm above.
    let recon_path = dir.path().join("recon.obj");
    write_obj(&recon_path, &plane(33, 0.24).transformed(|p| [p[0], p[1], 0.001]), "").unwrap();

    let j = json_of(&simbench(&["eval", "--recon", s(&recon_path), "--gt", s(&gt_path), "--align", "none"]));
    assert_eq!(j["crop"]["applied"], true);
    let kept = j["crop"]["kept_triangles"].as_u64().unwrap();
    assert_eq!(j["crop"]["total_triangles"], 12800);
    assert!(kept > 3000 && kept < 12800, "kept {kept}");
    assert!((j["mae_mm"].as_f64().unwrap() - 1.0).abs() < 1e-9);
    // The cropped truth extends a little past the reconstruction only: the reverse error is small.
    let rev = j["reverse_mae_mm"].as_f64().unwrap();
    assert!(rev < 30.0, "reverse {rev}");
    // Its size: 1 mm nearer the camera at 0.5 m, so a depth ratio of 0.499 / 0.5.
    let ratio = j["size"]["depth_ratio"].as_f64().unwrap();
    assert!((ratio - 0.998).abs() < 1e-5, "depth ratio {ratio}");
    assert!((j["size"]["size_error"].as_f64().unwrap() - (ratio - 1.0)).abs() < 1e-12);

    let k =
        json_of(&simbench(&["eval", "--recon", s(&recon_path), "--gt", s(&gt_path), "--align", "none", "--no-crop"]));
    assert_eq!(k["crop"]["applied"], false);
    assert!(k["reverse_mae_mm"].as_f64().unwrap() > 2.0 * rev, "the whole plane is penalised more");

    // A malformed camera.json is an error naming it.
    std::fs::write(dir.path().join("camera.json"), "{\"K\": 1}").unwrap();
    fails_with(&simbench(&["eval", "--recon", s(&recon_path), "--gt", s(&gt_path)]), &["camera.json"]);
}

#[test]
fn bad_input_gives_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let gt_path = dir.path().join("gt.obj");
    write_obj(&gt_path, &plane(11, 0.1), "").unwrap();
    let missing = dir.path().join("nope.obj");
    fails_with(&simbench(&["eval", "--recon", s(&missing), "--gt", s(&gt_path)]), &["nope.obj", "--recon"]);
    fails_with(&simbench(&["eval", "--recon", s(&gt_path), "--gt", s(&missing)]), &["nope.obj", "--gt"]);

    let nan = dir.path().join("nan.obj");
    std::fs::write(&nan, "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n").unwrap();
    fails_with(&simbench(&["eval", "--recon", s(&nan), "--gt", s(&gt_path)]), &["nan.obj", "non-finite"]);

    let empty = dir.path().join("empty.ply");
    std::fs::write(
        &empty,
        "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n",
    )
    .unwrap();
    fails_with(&simbench(&["eval", "--recon", s(&empty), "--gt", s(&gt_path)]), &["empty.ply", "no vertices"]);

    let bad_ply = dir.path().join("bad.ply");
    std::fs::write(&bad_ply, "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0\n").unwrap();
    fails_with(
        &simbench(&["eval", "--recon", s(&bad_ply), "--gt", s(&gt_path)]),
        &["bad.ply", "line 3", "no property y"],
    );

    let far = dir.path().join("far.obj");
    write_obj(&far, &plane(11, 0.1).transformed(|p| [p[0] + 5.0, p[1], p[2]]), "").unwrap();
    fails_with(
        &simbench(&["eval", "--recon", s(&far), "--gt", s(&gt_path), "--align", "none"]),
        &["nowhere near", "far.obj"],
    );

    let out = simbench(&["eval", "--recon", s(&gt_path), "--gt", s(&gt_path), "--align", "affine"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("affine") && err.contains("rigid") && err.contains("similarity"), "{err}");
}
