//! Oracle test: the absorbed flux (`gt_flux.npy`) and the shadows of a dataset written by
//! `simbench simulate` against Mitsuba 3 (scripts/oracle/mitsuba_flux.py), which renders the
//! same boundary surface with a diffuse BSDF of albedo = absorptivity under point emitters of
//! the lamps' radiant intensity, through the same camera: pi times its radiance is the absorbed
//! flux. Over lit pixels away from silhouettes and shadow edges the mean relative error must be
//! at most 2 %, and the shadows must agree on at least 99 % of the pixels.

use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// The oracle environment's Python with Mitsuba, or None (with a note) when it is missing;
/// panics when it is required (scripts/test.sh and CI set HEATSIM_REQUIRE_ASSETS or CI).
fn mitsuba_python() -> Option<PathBuf> {
    let py = repo().join(".venv/bin/python");
    let ok = py.exists()
        && Command::new(&py)
            .args(["-c", "import mitsuba as mi, meshio, scipy; mi.set_variant('scalar_rgb')"])
            .status()
            .is_ok_and(|s| s.success());
    if ok {
        return Some(py);
    }
    if std::env::var_os("HEATSIM_REQUIRE_ASSETS").is_some() || std::env::var_os("CI").is_some() {
        panic!(
            "the oracle environment .venv (with mitsuba, meshio and SciPy) is missing: run scripts/setup-oracles.sh"
        );
    }
    eprintln!("note: skipping the Mitsuba oracle test; run scripts/setup-oracles.sh to enable it");
    None
}

/// Writes a scene of the bunny relief (size 0.1 m, 1 cm thick, coarse 4 mm mesh, 0.5 s) with
/// the given lamps and camera members, simulates it and returns the dataset directory.
fn simulate(dir: &Path, name: &str, lamps: &str, camera: &str) -> PathBuf {
    let scene = dir.join(format!("{name}.json"));
    let json = format!(
        r#"{{
  "name": "{name}",
  "object": {{ "kind": "bunny", "size": 0.1, "thickness": 0.01 }},
  "material": {{ "name": "pla" }},
  "lamps": {lamps},
  "camera": {camera},
  "timing": {{ "duration": 0.5, "pre_heating_frames": 1 }},
  "meshing": {{ "surface_element_size": 0.004 }}
}}"#
    );
    std::fs::write(&scene, json).unwrap();
    let out_dir = dir.join(name);
    let out = Command::new(env!("CARGO_BIN_EXE_simbench"))
        .args(["simulate", scene.to_str().unwrap(), "--out", out_dir.to_str().unwrap(), "--vtu-frames", "0"])
        .output()
        .expect("simbench runs");
    assert!(
        out.status.success(),
        "simbench simulate failed ({}): {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    out_dir
}

/// Runs the oracle on `dataset` with `extra` arguments: (exit code, JSON report).
fn oracle(py: &Path, dataset: &Path, extra: &[&str]) -> (i32, serde_json::Value) {
    let out = Command::new(py)
        .arg(repo().join("scripts/oracle/mitsuba_flux.py"))
        .arg(dataset)
        .arg("--json")
        .args(extra)
        .output()
        .expect("the oracle runs");
    let code = out.status.code().unwrap_or(-1);
    let report = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "mitsuba_flux.py ({code}) printed no JSON report ({e}): {}\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )
    });
    (code, report)
}

fn num(report: &serde_json::Value, key: &str) -> f64 {
    report[key].as_f64().unwrap_or_else(|| panic!("{key} missing from the report: {report:#}"))
}

/// The checks every passing comparison must meet, with at least `lit` lit and `shadow`
/// shadowed pixels compared.
fn assert_agrees(code: i32, report: &serde_json::Value, lit: f64, shadow: f64) {
    assert_eq!(code, 0, "the Mitsuba oracle failed: {report:#}");
    assert!(num(report, "mean_rel_err") <= 0.02, "flux differs from Mitsuba's: {report:#}");
    assert!(num(report, "shadow_agreement") >= 0.99, "shadows differ from Mitsuba's: {report:#}");
    assert!(num(report, "lit_pixels") >= lit, "too few lit pixels compared: {report:#}");
    assert!(num(report, "shadow_pixels") >= shadow, "too few shadowed pixels compared: {report:#}");
    // The camera and the silhouette: the same pixels see the object, at the same depth.
    assert!(num(report, "mask_iou") >= 0.999, "the masks differ: {report:#}");
    // (A pixel or two may differ where a Mitsuba ray slips through an edge between triangles.)
    assert!(num(report, "depth_p99_rel_err") <= 1e-5, "the depths differ: {report:#}");
    assert!(
        num(report, "depth_mismatched_pixels") <= 1e-3 * num(report, "compared_pixels"),
        "the depths differ: {report:#}"
    );
    // No bias: a systematic error (a wrong intensity or absorptivity) shows here first.
    assert!((num(report, "mean_ratio_ours_over_mitsuba") - 1.0).abs() <= 2e-3, "biased flux: {report:#}");
}

#[test]
fn bunny_flux_and_self_shadows_match_mitsuba() {
    let Some(py) = mitsuba_python() else { return };
    let tmp = tempfile::tempdir().unwrap();
    // A lamp low on the left: the ear and the head shadow the body.
    let ds = simulate(
        tmp.path(),
        "bunny",
        r#"[ { "kind": "point", "power": 100.0, "position": [-0.3, 0.0, 0.15] } ]"#,
        "{}",
    );
    let (code, report) = oracle(&py, &ds, &[]);
    eprintln!("mitsuba oracle, bunny: {report}");
    assert_agrees(code, &report, 20_000.0, 5_000.0);

    // The check can fail: 5 % too much light in Mitsuba ...
    let (code, wrong) = oracle(&py, &ds, &["--scale", "1.05"]);
    assert_eq!(code, 1, "a 5 % intensity error must fail the oracle: {wrong:#}");
    let err = num(&wrong, "mean_rel_err");
    assert!((0.04..0.06).contains(&err), "a 5 % intensity error should show as ~4.8 %: {wrong:#}");

    // ... or shadows where Mitsuba sees light: zero our brightest quarter of lit pixels.
    let bad = tmp.path().join("bunny-bad-shadows");
    std::fs::create_dir(&bad).unwrap();
    for entry in std::fs::read_dir(&ds).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), bad.join(entry.file_name())).unwrap();
    }
    let mut flux: ndarray::Array2<f32> = ndarray_npy::read_npy(bad.join("gt_flux.npy")).unwrap();
    let mut lit: Vec<f32> = flux.iter().copied().filter(|v| *v > 0.0).collect();
    lit.sort_by(f32::total_cmp);
    let cut = lit[lit.len() * 3 / 4];
    flux.mapv_inplace(|v| if v > cut { 0.0 } else { v });
    ndarray_npy::write_npy(bad.join("gt_flux.npy"), &flux).unwrap();
    let (code, wrong) = oracle(&py, &bad, &[]);
    assert_eq!(code, 1, "false shadows must fail the oracle: {wrong:#}");
    assert!(num(&wrong, "shadow_agreement") < 0.99, "{wrong:#}");
}

#[test]
fn oblique_camera_and_two_lamps_match_mitsuba() {
    let Some(py) = mitsuba_python() else { return };
    let tmp = tempfile::tempdir().unwrap();
    // A rolled, off-axis camera of a non-default size and field of view, and two lamps of
    // different powers and radiant fractions whose contributions add up.
    let ds = simulate(
        tmp.path(),
        "oblique",
        r#"[ { "kind": "point", "power": 100.0, "position": [-0.3, 0.0, 0.15] },
             { "kind": "point", "power": 60.0, "position": [0.2, 0.25, 0.3], "radiant_fraction": 0.7, "on": 0.2, "off": 0.4 } ]"#,
        r#"{ "position": [0.12, -0.08, 0.33], "look_at": [0.0, 0.01, -0.02], "up": [0.2, 1.0, 0.0], "width": 400, "height": 300, "hfov_deg": 30.0 }"#,
    );
    let (code, report) = oracle(&py, &ds, &[]);
    eprintln!("mitsuba oracle, oblique camera and two lamps: {report}");
    assert_agrees(code, &report, 10_000.0, 0.0);
}
