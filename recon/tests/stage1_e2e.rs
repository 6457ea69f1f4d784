//! Stage 1 end to end: datasets simulated by the `simbench` binary (surface solver on the camera
//! grid), reconstructed by `simbench reconstruct --stage 1 --check`, and the figures checked
//! against ground truth; bad inputs give a clear error, a non-zero exit and no output.
//!
//! The scenes are `scenes/recon/hemisphere-shell.json` (1 mm PLA shell, R = 5 cm, two 250 W
//! lamps at 28 cm, 45 s at 2 frames/s) and, for the figures, `scenes/recon/bunny-relief.json`
//! (12 cm, 1.5 mm), each with a **160 x 128 camera** (same field of view, so pixels four times
//! larger than the default 640 x 512) to keep the test fast (a few seconds per video).
//! The thresholds are the figures measured with this setup plus a margin; where they fall short
//! of issue 7's targets docs/reconstruction.md and docs/notes/reconstruction-stage1.md say so.
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

/// A validation scene's two videos, simulated once per test run.
struct Datasets {
    _dir: tempfile::TempDir,
    left: PathBuf,
    right: PathBuf,
}

/// `scenes/recon/<name>.json` with a 160 x 128 camera (same field of view), simulated.
fn simulate_small(name: &str) -> Datasets {
    let dir = tempfile::tempdir().expect("tempdir");
    let scene_src = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../scenes/recon/{name}.json"));
    let mut scene: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&scene_src).expect("scene")).expect("scene json");
    scene["camera"]["width"] = 160.into();
    scene["camera"]["height"] = 128.into();
    scene["camera"]["pixel_pitch"] = 48e-6.into();
    let scene_path = dir.path().join("scene.json");
    std::fs::write(&scene_path, serde_json::to_string_pretty(&scene).unwrap()).unwrap();
    let out = dir.path().join("data");
    let st = Command::new(simbench())
        .args(["simulate", scene_path.to_str().unwrap(), "--out", out.to_str().unwrap(), "--vtu-frames", "0"])
        .output()
        .expect("run simbench simulate");
    assert!(st.status.success(), "simulate {name} failed: {}", String::from_utf8_lossy(&st.stderr));
    Datasets { left: out.join("left"), right: out.join("right"), _dir: dir }
}

/// The hemisphere's datasets (left, right).
fn datasets() -> (&'static Path, &'static Path) {
    static D: OnceLock<Datasets> = OnceLock::new();
    let d = D.get_or_init(|| simulate_small("hemisphere-shell"));
    (&d.left, &d.right)
}

/// The bunny relief's datasets (left, right); needs the bunny asset (`scripts/fetch-bunny.sh`).
fn bunny_datasets() -> (&'static Path, &'static Path) {
    static D: OnceLock<Datasets> = OnceLock::new();
    let d = D.get_or_init(|| {
        heatsim::assets::bunny_path(None).expect("the bunny asset is required by this test");
        simulate_small("bunny-relief")
    });
    (&d.left, &d.right)
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
    check_on(datasets(), extra)
}

fn check_on((l, r): (&Path, &Path), extra: &[&str]) -> serde_json::Value {
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
    // Measured: C -0.01 %, h -0.02 % (free rows, float64 clean video, orthogonal solves).
    assert!(num(&c, "heat_capacity_rel_error").abs() < 0.01, "C {c}");
    assert!(num(&c, "convection_rel_error").abs() < 0.01, "h {c}");
    // Measured 0.019 (issue target 0.05; 0.031 with kappa 1e-5 on the backward-Euler video); it
    // was 0.29 with paired rows, kappa 0.1 and a float32 clean video.
    assert!(num(&c, "operator_error_rows") < 0.05, "Delta_s {c}");
    assert!(num(&c, "operator_error_paired_floor") < 0.05, "paired floor {c}");
}

/// On noise-free data most rows are determined by the video alone: per-vertex free rows, no
/// regulariser and no denoising, median row error 0.32 % (with normal equations and a float32
/// video the Frobenius error was 1.37, docs/notes/reconstruction-stage1.md). Not every row: vertices that one lamp
/// does not light have one constraint less, and on the BDF2-simulated video 538 of their rows
/// come out more than 50 % off (Frobenius error 0.75; on the backward-Euler video of the same
/// scene 0.015), which is what the default's weak regulariser is for (Frobenius 0.022).
#[test]
fn unregularised_rows_on_clean_data() {
    let plain = check(&[
        "--clean",
        "--set",
        "stage1.stencil=free",
        "--set",
        "stage1.smoothing=0",
        "--set",
        "stage1.denoise=none",
    ]);
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
    // Measured: lambda +3.4 %, Delta_s 96 %, flux 0.9998, C and h not identifiable (issue: C, h
    // within 10 %: not met).
    assert!(num(&c, "lambda_rel_error").abs() < 0.15, "lambda {c}");
    assert!(num(&c, "operator_error_rows") < 1.5, "Delta_s {c}");
    bound_is_nested(&c);
}

/// `--check`'s Cramér–Rao bound on noisy data: present, at the measured noise, and ordered as
/// its models are nested (the paired rows' columns are sums of the free rows' columns, the known
/// rows have none), so more unknowns can only loosen it. The clean run has none (no noise).
fn bound_is_nested(c: &serde_json::Value) {
    let b = &c["bound"];
    assert!(num(b, "sigma") > 0.02 && num(b, "sigma") < 0.1, "noise level of a 50 mK video: {b}");
    for k in ["heat_capacity_rel_std", "lambda_rel_std", "convection_std"] {
        let v: Vec<f64> = ["rows_known", "rows_paired", "rows_free"].iter().map(|m| num(&b[*m], k)).collect();
        assert!(v[0] > 0.0 && v[0] <= v[1] * (1.0 + 1e-9) && v[1] <= v[2] * (1.0 + 1e-9), "{k}: {v:?} in {b}");
    }
}

/// Issue 7's noise-free figures on the bunny relief. The scene applies each vertex's `gt_flux`
/// as Eq. 6 (`solver.surface_flux: "vertex"`), so the flux estimate can match it exactly; with
/// the camera grid's default triangle means of the corner fluxes the correlation was limited to
/// 0.9969 (640 x 512) by the jumps at shadow and facet edges. Measured: C -0.02 %, h -0.04 %, flux 0.99999999,
/// Delta_s 1.6 %, half-space 94.99 %, which is Eq. 9's own agreement on `gt_flux` (the rule's
/// ceiling on this object, under the 95 %: docs/notes/reconstruction-stage1.md).
#[test]
fn noise_free_bunny_figures() {
    let c = check_on(bunny_datasets(), &["--clean"]);
    for r in c["flux_correlation"].as_array().unwrap() {
        assert!(r.as_f64().unwrap() >= 0.999, "flux correlation {r} < 0.999");
    }
    assert!(num(&c, "heat_capacity_rel_error").abs() < 0.01, "C {c}");
    assert!(num(&c, "convection_rel_error").abs() < 0.01, "h {c}");
    assert!(num(&c, "operator_error_rows") < 0.05, "Delta_s {c}");
    let ceiling = num(&c, "halfspace_agreement_true_flux");
    assert!(num(&c, "halfspace_agreement") >= ceiling - 0.002, "half-space below Eq. 9's ceiling {ceiling}: {c}");
    assert!(c["bound"].is_null(), "no noise, no bound: {c}");
}

/// The bunny at NETD 50 mK. Measured: flux 0.992 / 0.993, lambda +11 %, half-space 93.8 %
/// (ceiling 95.0 %).
#[test]
fn netd_50mk_bunny_figures() {
    let c = check_on(bunny_datasets(), &[]);
    for r in c["flux_correlation"].as_array().unwrap() {
        assert!(r.as_f64().unwrap() >= 0.95, "flux correlation {r} < 0.95");
    }
    assert!(num(&c, "halfspace_agreement") >= 0.92, "half-space {c}");
    bound_is_nested(&c);
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
    expect_error(&[l, r], &["--set", "stage1.t_end_s=1.0"], &["too few frames", "Sec. 5"]);
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
/// free rows fit the noise (measured Delta_s 7.2, flux correlation 0.9996); the default
/// regulariser does not (0.96, 0.9998). How far the noise fit goes depends on the data: on
/// the same scene with triangle-mean fluxes (before the scenes applied Eq. 6's per-vertex flux)
/// it was 15.8 against 0.95, when this test asked for a factor 10; the factor is now 5, and
/// the default must in addition stay below the zero operator's error (1).
#[test]
fn free_rows_on_noisy_data() {
    let free = check(&["--set", "stage1.smoothing=0"]);
    let ours = check(&[]);
    let corr = |c: &serde_json::Value| c["flux_correlation"][0].as_f64().unwrap();
    assert!(corr(&ours) >= corr(&free), "free {free} vs default {ours}");
    assert!(num(&ours, "operator_error_rows") < 1.0, "default rows fit the noise: {ours}");
    assert!(num(&ours, "operator_error_rows") < 0.2 * num(&free, "operator_error_rows"), "free {free} vs {ours}");
}
