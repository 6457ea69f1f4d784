//! Stage 1 end to end: datasets simulated by the `simbench` binary (surface solver on the camera
//! grid), reconstructed by `simbench reconstruct --stage 1 --check`, and the figures checked
//! against ground truth; bad inputs give a clear error, a non-zero exit and no output.
//!
//! The scene is `scenes/recon/hemisphere-shell.json` (1 mm PLA shell, R = 5 cm, two 250 W lamps
//! at 28 cm, 45 s at 2 frames/s) with a **160 x 128 camera** (same field of view, so pixels four
//! times larger than the default 640 x 512) to keep the test fast (a few seconds per video).
//! The thresholds are the figures measured with this setup plus a margin; where they fall short
//! of issue 7's targets the README says so ("Reconstruction, stage 1").
//!
//! Needs the release binary next to the test executable: `cargo build --release -p simbench`,
//! then `cargo test --release -p heatrecon --test stage1_e2e -- --nocapture`.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use ndarray::{Array2, Array3};

fn simbench() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let bin = exe.parent().and_then(Path::parent).expect("target dir").join("simbench");
    assert!(bin.exists(), "{} not found: run `cargo build --release -p simbench` first", bin.display());
    bin
}

/// The simulated datasets (left, right), generated once per test run.
fn datasets() -> &'static (PathBuf, PathBuf) {
    static DIR: OnceLock<(tempfile::TempDir, PathBuf, PathBuf)> = OnceLock::new();
    let d = DIR.get_or_init(|| {
        let tmp = tempfile::tempdir().expect("tempdir");
        let scene_src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/recon/hemisphere-shell.json");
        let mut scene: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&scene_src).expect("scene")).expect("scene json");
        scene["camera"]["width"] = 160.into();
        scene["camera"]["height"] = 128.into();
        scene["camera"]["pixel_pitch"] = 48e-6.into();
        let scene_path = tmp.path().join("scene.json");
        std::fs::write(&scene_path, serde_json::to_string_pretty(&scene).unwrap()).unwrap();
        let out = tmp.path().join("data");
        let st = Command::new(simbench())
            .args(["simulate", scene_path.to_str().unwrap(), "--out", out.to_str().unwrap(), "--vtu-frames", "0"])
            .output()
            .expect("run simbench simulate");
        assert!(st.status.success(), "simulate failed: {}", String::from_utf8_lossy(&st.stderr));
        let (l, r) = (out.join("left"), out.join("right"));
        (tmp, l, r)
    });
    (&d.1, &d.2).clone_pair()
}

trait ClonePair {
    fn clone_pair(self) -> &'static (PathBuf, PathBuf);
}
impl ClonePair for (&PathBuf, &PathBuf) {
    fn clone_pair(self) -> &'static (PathBuf, PathBuf) {
        static PAIR: OnceLock<(PathBuf, PathBuf)> = OnceLock::new();
        PAIR.get_or_init(|| (self.0.clone(), self.1.clone()))
    }
}

fn reconstruct(dirs: &[&Path], extra: &[&str]) -> (std::process::Output, tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let mut cmd = Command::new(simbench());
    cmd.arg("reconstruct");
    for d in dirs {
        cmd.arg(d);
    }
    cmd.args(["--out", out.to_str().unwrap(), "--stage", "1"]).args(extra);
    (cmd.output().expect("run simbench reconstruct"), tmp, out)
}

fn check(extra: &[&str]) -> serde_json::Value {
    let (l, r) = datasets();
    let mut args = vec!["--check"];
    args.extend_from_slice(extra);
    let (o, _tmp, out) = reconstruct(&[l, r], &args);
    assert!(o.status.success(), "reconstruct failed: {}", String::from_utf8_lossy(&o.stderr));
    for f in ["flux_0.npy", "flux_1.npy", "laplacian.npz", "params.json", "check.json"] {
        assert!(out.join(f).exists(), "missing output {f}");
    }
    let c: serde_json::Value = serde_json::from_slice(&o.stdout).expect("check json on stdout");
    eprintln!("{extra:?}: {}", serde_json::to_string(&c).unwrap());
    c
}

fn num(c: &serde_json::Value, k: &str) -> f64 {
    c[k].as_f64().unwrap_or_else(|| panic!("{k} missing in {c}"))
}

#[test]
fn noise_free_figures() {
    let c = check(&["--clean"]);
    for r in c["flux_correlation"].as_array().unwrap() {
        assert!(r.as_f64().unwrap() >= 0.999, "flux correlation {r} < 0.999");
    }
    assert!(num(&c, "halfspace_agreement") >= 0.95, "half-space {c}");
    assert!(num(&c, "lambda_rel_error").abs() < 0.02, "lambda {c}");
    // Measured: C -0.02 %, h -0.05 % (free rows, float64 clean video, orthogonal solves).
    assert!(num(&c, "heat_capacity_rel_error").abs() < 0.01, "C {c}");
    assert!(num(&c, "convection_rel_error").abs() < 0.01, "h {c}");
    // Measured 0.022 (issue target 0.05; 0.031 with kappa 1e-5 on the backward-Euler video); it
    // was 0.29 with paired rows, kappa 0.1 and a float32 clean video.
    assert!(num(&c, "operator_error_rows") < 0.05, "Delta_s {c}");
    assert!(num(&c, "operator_error_paired_floor") < 0.05, "paired floor {c}");
}

/// On noise-free data most rows are determined by the video alone: per-vertex free rows, no
/// regulariser and no denoising, median row error 0.32 % (with normal equations and a float32
/// video the Frobenius error was 1.37, README, stage 1). Not every row: vertices that one lamp
/// does not light have one constraint less, and on the BDF2-simulated video 538 of their rows
/// come out more than 50 % off (Frobenius error 0.75; on the backward-Euler video of the same
/// scene 0.015), which is what the default's weak regulariser is for (Frobenius 0.022).
#[test]
fn unregularised_rows_on_clean_data() {
    let plain = check(&["--clean", "--stencil", "free", "--smoothing", "0", "--denoise", "none"]);
    assert!(num(&plain, "operator_row_error_median") < 0.01, "per-vertex free rows {plain}");
    let regularised = check(&["--clean"]);
    assert!(
        num(&regularised, "operator_error_rows") < num(&plain, "operator_error_rows"),
        "the regulariser must help: {regularised} against {plain}"
    );
}

#[test]
fn netd_50mk_figures() {
    let c = check(&[]);
    for r in c["flux_correlation"].as_array().unwrap() {
        assert!(r.as_f64().unwrap() >= 0.95, "flux correlation {r} < 0.95");
    }
    assert!(num(&c, "halfspace_agreement") >= 0.95, "half-space {c}");
    // Measured: lambda +5.0 %, Delta_s 95 %, flux 0.9997, C and h not identifiable (issue: C, h
    // within 10 %: not met).
    assert!(num(&c, "lambda_rel_error").abs() < 0.15, "lambda {c}");
    assert!(num(&c, "operator_error_rows") < 1.5, "Delta_s {c}");
}

// ---- bad input ----

fn copy_dir(src: &Path, dst: &Path) {
    std::fs::create_dir_all(dst).unwrap();
    for e in std::fs::read_dir(src).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_file() {
            std::fs::copy(e.path(), dst.join(e.file_name())).unwrap();
        }
    }
}

fn expect_error(dirs: &[&Path], extra: &[&str], needles: &[&str]) {
    let (o, _tmp, out) = reconstruct(dirs, extra);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "expected failure, got success; stderr {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    for n in needles {
        assert!(err.contains(n), "stderr lacks {n:?}: {err}");
    }
    assert!(!out.exists(), "output written despite the error");
}

fn edited(name: &str, edit: impl FnOnce(&Path)) -> (tempfile::TempDir, PathBuf) {
    let (_, r) = datasets();
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path().join(name);
    copy_dir(r, &d);
    edit(&d);
    (tmp, d)
}

#[test]
fn different_frame_counts() {
    let (l, _) = datasets();
    let (_t, d) = edited("short", |d| {
        let v: Array3<f32> = ndarray_npy::read_npy(d.join("video.npy")).unwrap();
        let v = v.slice(ndarray::s![..50, .., ..]).to_owned();
        ndarray_npy::write_npy(d.join("video.npy"), &v).unwrap();
        std::fs::remove_file(d.join("times.npy")).ok();
    });
    expect_error(&[l, &d], &[], &["do not match", "frames"]);
}

#[test]
fn different_sizes() {
    let (l, _) = datasets();
    let (_t, d) = edited("small", |d| {
        let v: Array3<f32> = ndarray_npy::read_npy(d.join("video.npy")).unwrap();
        ndarray_npy::write_npy(d.join("video.npy"), &v.slice(ndarray::s![.., ..64, ..80]).to_owned()).unwrap();
        let m: Array2<bool> = ndarray_npy::read_npy(d.join("mask.npy")).unwrap();
        ndarray_npy::write_npy(d.join("mask.npy"), &m.slice(ndarray::s![..64, ..80]).to_owned()).unwrap();
        let mut cam: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join("camera.json")).unwrap()).unwrap();
        cam["width"] = 80.into();
        cam["height"] = 64.into();
        std::fs::write(d.join("camera.json"), cam.to_string()).unwrap();
    });
    expect_error(&[l, &d], &[], &["do not match", "image size"]);
}

#[test]
fn mismatched_mask() {
    let (l, _) = datasets();
    let (_t, d) = edited("mask", |d| {
        let mut m: Array2<bool> = ndarray_npy::read_npy(d.join("mask.npy")).unwrap();
        let p = m.indexed_iter().find(|(_, &b)| b).map(|(i, _)| i).unwrap();
        m[p] = false;
        ndarray_npy::write_npy(d.join("mask.npy"), &m).unwrap();
    });
    expect_error(&[l, &d], &[], &["mask.npy differs"]);
}

#[test]
fn mask_of_wrong_size() {
    let (_t, d) = edited("masksize", |d| {
        ndarray_npy::write_npy(d.join("mask.npy"), &Array2::<bool>::from_elem((10, 10), true)).unwrap();
    });
    expect_error(&[&d], &[], &["mask.npy", "camera.json says"]);
}

#[test]
fn nan_pixel() {
    let (l, _) = datasets();
    let (_t, d) = edited("nan", |d| {
        let mut v: Array3<f32> = ndarray_npy::read_npy(d.join("video.npy")).unwrap();
        let m: Array2<bool> = ndarray_npy::read_npy(d.join("mask.npy")).unwrap();
        let (r, c) = m.indexed_iter().find(|(_, &b)| b).map(|(i, _)| i).unwrap();
        v[[30, r, c]] = f32::NAN;
        ndarray_npy::write_npy(d.join("video.npy"), &v).unwrap();
    });
    expect_error(&[l, &d], &[], &["video.npy", "frame 30", "NaN"]);
}

#[test]
fn too_few_frames() {
    let (l, r) = datasets();
    expect_error(&[l, r], &["--t-end", "1.0"], &["too few frames", "Sec. 5"]);
}

#[test]
fn empty_mask() {
    let (_t, d) = edited("empty", |d| {
        let m: Array2<bool> = ndarray_npy::read_npy(d.join("mask.npy")).unwrap();
        ndarray_npy::write_npy(d.join("mask.npy"), &Array2::<bool>::from_elem(m.dim(), false)).unwrap();
    });
    expect_error(&[&d], &[], &["mask.npy", "empty"]);
}

/// Noisy data: the globals come from paired rows (noise rule), the rows are then re-estimated
/// free (shapes differ between the two fits: a regression test for that path). Unregularised
/// free rows fit the noise (measured Delta_s 37, flux correlation 0.9993); the default
/// regulariser does not (0.95, 0.9997).
#[test]
fn free_rows_on_noisy_data() {
    let free = check(&["--smoothing", "0"]);
    let ours = check(&[]);
    let corr = |c: &serde_json::Value| c["flux_correlation"][0].as_f64().unwrap();
    assert!(corr(&ours) >= corr(&free), "free {free} vs default {ours}");
    assert!(num(&ours, "operator_error_rows") < 0.1 * num(&free, "operator_error_rows"), "free {free} vs {ours}");
}
