//! Oracle test: `simbench peer volumetric` runs our volumetric solver and the independent
//! scikit-fem + SciPy peer (bench/peers/skfem_heat.py, SuperLU and conjugate gradients) on the
//! identical mesh and problem; their temperatures must agree to 1e-6 of the temperature rise at
//! every node and frame.

use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// Whether the peer's Python environment is usable; panics when it is required (the test
/// scripts and CI set HEATSIM_REQUIRE_ASSETS or CI) but missing.
fn peer_available() -> bool {
    let py = repo().join(".venv/bin/python");
    let ok = py.exists() && Command::new(&py).args(["-c", "import skfem, scipy"]).status().is_ok_and(|s| s.success());
    if !ok {
        if std::env::var_os("HEATSIM_REQUIRE_ASSETS").is_some() || std::env::var_os("CI").is_some() {
            panic!("the oracle environment .venv (with scikit-fem and SciPy) is missing: run scripts/setup-oracles.sh");
        }
        eprintln!("note: skipping the peer oracle test; run scripts/setup-oracles.sh to enable it");
    }
    ok
}

/// A 20 x 20 x 5 mm polystyrene plate, 0.2 s before and 1.8 s of heating at 60 steps/s
/// (120 steps), with `extra` JSON members appended to the scene.
fn plate_scene(dir: &Path, name: &str, lamps: &str, extra: &str) -> PathBuf {
    let path = dir.join(format!("{name}.json"));
    let json = format!(
        r#"{{
  "name": "{name}",
  "object": {{ "kind": "cuboid", "width": 0.02, "height": 0.02, "thickness": 0.005 }},
  "material": {{ "name": "polystyrene" }},
  "lamps": {lamps},
  "timing": {{ "duration": 1.8, "pre_heating_frames": 2, "frame_interval": 0.1 }}{extra}
}}"#
    );
    std::fs::write(&path, json).unwrap();
    path
}

fn run_peer(scene: &Path) -> serde_json::Value {
    let out = Command::new(env!("CARGO_BIN_EXE_simbench"))
        .args(["peer", "volumetric", scene.to_str().unwrap(), "--peers", "superlu,cg"])
        .output()
        .expect("simbench runs");
    let report: Option<serde_json::Value> = serde_json::from_slice(&out.stdout).ok();
    assert!(
        out.status.success(),
        "simbench peer failed ({}): {}\nreport: {report:#?}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    report.expect("simbench peer prints a JSON report")
}

fn check(report: &serde_json::Value, steps: u64) {
    let rel = report["max_rel_diff"].as_f64().unwrap();
    assert!(rel <= 1e-6, "ours and the scikit-fem peer differ by {rel:e} of the temperature rise: {report:#}");
    assert_eq!(report["steps"].as_u64(), Some(steps));
    assert!(report["max_rise_k"].as_f64().unwrap() > 0.05, "the plate should heat: {report:#}");
    assert!(report["nodes"].as_u64().unwrap() > 100);
    // Both of our linear solvers, the SuperLU and CG peers, each compared with our direct solver.
    let runs = report["runs"].as_array().expect("runs");
    let names: Vec<String> = runs
        .iter()
        .map(|r| format!("{} {}", r["code"].as_str().unwrap(), r["linear_solver"].as_str().unwrap()))
        .collect();
    assert_eq!(names, ["ours direct", "ours conjugate_gradients", "peer superlu", "peer cg"], "{report:#}");
    for run in runs {
        assert!(run["max_rel_diff"].as_f64().is_some_and(|v| v <= 1e-6), "{run:#}");
        assert!(run["stepping_s"].as_f64().is_some_and(|v| v > 0.0), "{run:#}");
    }
    let speedups = report["speedups"].as_array().expect("speedups");
    assert_eq!(speedups.len(), 4, "{report:#}");
    assert!(speedups.iter().all(|s| s["stepping"].as_f64().is_some_and(|v| v > 0.0)), "{report:#}");
}

#[test]
fn peer_agrees_consistent_mass_exposed_lamp_switching_off() {
    if !peer_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene = plate_scene(
        tmp.path(),
        "plate_consistent",
        r#"[ { "kind": "uniform", "flux": 500.0, "on": 0.0, "off": 1.0 } ]"#,
        "",
    );
    check(&run_peer(&scene), 120);
}

#[test]
fn peer_agrees_lumped_mass_insulated_back_two_lamps() {
    if !peer_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene = plate_scene(
        tmp.path(),
        "plate_lumped",
        r#"[ { "kind": "uniform", "flux": 300.0, "on": 0.25, "off": 1.2 }, { "kind": "uniform", "flux": 200.0 } ]"#,
        r#",
  "environment": { "ambient_temperature": 300.0, "convection_coefficient": 12.0, "back_boundary": "insulated" },
  "solver": { "mass": "lumped" }"#,
    );
    check(&run_peer(&scene), 120);
}

#[test]
fn peer_agrees_linearized_radiation_and_off_grid_switching() {
    if !peer_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    // Switching times off the 1/60 s step grid exercise the partial-step lamp weights.
    let scene = plate_scene(
        tmp.path(),
        "plate_linearized",
        r#"[ { "kind": "uniform", "flux": 400.0, "on": 0.013, "off": 0.9071 } ]"#,
        r#",
  "solver": { "radiation": "linearized" }"#,
    );
    check(&run_peer(&scene), 120);
}

#[test]
fn peer_agrees_point_lamp_and_uniform_lamp() {
    if !peer_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    // The point lamp's face fluxes (incidence and distance vary over the plate) are exported;
    // the peer assembles their nodal load itself.
    let scene = plate_scene(
        tmp.path(),
        "plate_point_lamp",
        r#"[ { "kind": "point", "power": 60.0, "position": [-0.03, 0.01, 0.08], "on": 0.0, "off": 1.4 },
      { "kind": "uniform", "flux": 150.0, "on": 0.5 } ]"#,
        "",
    );
    let report = run_peer(&scene);
    check(&report, 120);
}
