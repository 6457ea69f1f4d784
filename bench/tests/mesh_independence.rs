//! Issue 6, mesh independence: the volumetric solver on our TetGen mesh and on fTetWild's
//! mesh of the same closed surface (`simbench mesh-independence`, fTetWild from PyPI
//! `pytetwild` in the project's .venv) gives the same visible-surface video within 1 % of the
//! mean temperature rise, and the same volume within 0.5 %. The command checks both targets
//! itself (exit 1 when either fails); the test re-reads its report.
//!
//! Scenes (scenes/oracle/): a steel hemisphere shell (R = 2 cm, 4 mm, 1 mm elements) and a
//! PLA cuboid (12 x 12 x 4 mm, 0.4 mm elements), each under an oblique point lamp. Elements
//! must resolve the heated depth sqrt(alpha t) (1.4 mm for PLA in 15 s): the PLA hemisphere at
//! 1 mm disagrees by 2.5 % (measured), which is mesh error in both meshes, not a solver fault.

use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

fn check(scene: &str) {
    let tmp = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_simbench"))
        .args(["mesh-independence", repo().join("scenes/oracle").join(scene).to_str().unwrap(), "--out"])
        .arg(tmp.path())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    eprintln!("{}", String::from_utf8_lossy(&out.stdout));
    assert!(out.status.success(), "{scene}: {stderr}");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("mesh_independence.json")).unwrap()).unwrap();
    let video = report["video_rel_diff"].as_f64().unwrap();
    let volume = report["volume_rel_diff"].as_f64().unwrap();
    eprintln!("{scene}: video {:.3} % of the mean rise, volume {:.4} %", 100.0 * video, 100.0 * volume);
    assert!(video <= 0.01 && volume <= 0.005);
    // The comparison must see the object and the heating.
    assert!(report["compared_pixels"].as_u64().unwrap() > 10_000, "{report}");
    assert!(report["mean_rise_k"].as_f64().unwrap() > 0.01, "{report}");
    assert!(report["ftetwild"]["tets"].as_u64().unwrap() > 10_000, "{report}");
}

#[test]
fn steel_hemisphere_is_mesh_independent() {
    check("tetwild-hemisphere-steel.json");
}

#[test]
fn pla_cuboid_is_mesh_independent() {
    check("tetwild-cuboid-pla.json");
}
