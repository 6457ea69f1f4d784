//! `simbench table objects` and `simbench table shape-error`: the generated objects are closed
//! valid solids of the expected size and volume; `--quick` runs end to end and records either
//! numbers or failures; resume; bad arguments.

use std::f64::consts::PI;
use std::path::Path;
use std::process::{Command, Output};

use heatsim::mesh::read_surface;
use serde_json::Value;

fn simbench(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_simbench")).args(args).output().expect("simbench runs")
}

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "simbench failed:\nstdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn fails_with(args: &[&str], needles: &[&str]) {
    let out = simbench(args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{args:?} should fail; stderr: {err}");
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: stderr should mention `{n}`: {err}");
    }
}

/// CSV with double-quoted fields.
fn parse_csv(text: &str) -> Vec<Vec<String>> {
    text.lines()
        .map(|line| {
            let mut fields = Vec::new();
            let mut cur = String::new();
            let mut quoted = false;
            let mut chars = line.chars().peekable();
            while let Some(c) = chars.next() {
                match (c, quoted) {
                    ('"', true) if chars.peek() == Some(&'"') => {
                        cur.push('"');
                        chars.next();
                    }
                    ('"', _) => quoted = !quoted,
                    (',', false) => fields.push(std::mem::take(&mut cur)),
                    _ => cur.push(c),
                }
            }
            fields.push(cur);
            fields
        })
        .collect()
}

/// Volume of a can with filleted ends: pi [R^2 (H - fb - ft) + F(fb) + F(ft)] with
/// F(rho) = integral_0^rho (c + sqrt(rho^2 - u^2))^2 du = c^2 rho + c pi rho^2 / 2 + 2 rho^3 / 3,
/// c = R - rho (derived here independently of the generator's arc formula).
fn can_volume(r: f64, h: f64, fb: f64, ft: f64) -> f64 {
    let f = |rho: f64| {
        let c = r - rho;
        c * c * rho + c * PI * rho * rho / 2.0 + 2.0 * rho.powi(3) / 3.0
    };
    PI * (r * r * (h - fb - ft) + f(fb) + f(ft))
}

#[test]
fn generated_objects_are_closed_valid_and_of_the_expected_size_and_volume() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("objects");
    let stdout = ok(&simbench(&["table", "objects", "--out", out.to_str().unwrap(), "--spacing", "0.0005"]));
    let report: Value = serde_json::from_str(&stdout).unwrap();
    let objects = report["objects"].as_array().unwrap();
    let names: Vec<&str> = objects.iter().map(|o| o["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["ball", "soda_can", "bottle_1", "bottle_2", "vase", "twisted_spindle"]);
    // name, length along the axis (m), largest diameter (m), independent analytic volume (m^3)
    // where a closed form is at hand (the twisted spindle, whose section is an oval, is checked
    // by the generator's unit tests).
    let expected: [(&str, f64, f64, Option<f64>); 5] = [
        ("ball", 0.06, 0.06, Some(4.0 / 3.0 * PI * 0.03f64.powi(3))),
        ("soda_can", 0.122, 0.066, Some(can_volume(0.033, 0.122, 0.005, 0.009))),
        ("bottle_1", 0.105, 0.048, None),
        ("bottle_2", 0.105, 0.056, None),
        ("vase", 0.110, 0.068, None),
    ];
    for (name, length, diameter, closed_form) in expected {
        let o = objects.iter().find(|o| o["name"] == name).unwrap_or_else(|| panic!("{name} missing"));
        let mesh = read_surface(&out.join(format!("{name}.obj"))).unwrap();
        mesh.validate_solid().unwrap_or_else(|e| panic!("{name}: {e}"));
        let (lo, hi) = mesh.bounding_box();
        let ext = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
        eprintln!("{name}: extent {ext:?} m, {} triangles", mesh.tris.len());
        assert!((ext[0] - length).abs() < 1e-9, "{name}: length {} m, expected {length}", ext[0]);
        // Sectors include phi = 0 (y) and pi/2 (z); the outline samples may miss the largest
        // radius of a curved profile by its sagitta, spacing^2 / (8 R) < 2 um here.
        assert!((ext[1] - diameter).abs() < 1e-5, "{name}: diameter {} m, expected {diameter}", ext[1]);
        assert!((ext[2] - diameter).abs() < 1e-5, "{name}: diameter {} m, expected {diameter}", ext[2]);
        // Centred on the origin, axis along x.
        for k in 0..3 {
            assert!((lo[k] + hi[k]).abs() < 1e-6, "{name}: not centred on axis {k}: {lo:?} {hi:?}");
        }
        let v = mesh.signed_volume();
        let analytic = o["analytic_volume_m3"].as_f64().unwrap();
        let rel = v / analytic - 1.0;
        eprintln!("{name}: mesh volume {v:.6e} m^3, analytic {analytic:.6e} m^3 ({:+.4} %)", 100.0 * rel);
        assert!(rel.abs() < 0.01, "{name}: mesh volume {v} differs from the analytic {analytic} by {rel}");
        // The inscribed polyhedron lies inside the smooth surface.
        assert!(rel < 0.0, "{name}: the inscribed mesh should be slightly smaller, got {rel}");
        if let Some(cf) = closed_form {
            assert!((analytic / cf - 1.0).abs() < 1e-9, "{name}: generator's analytic {analytic} vs closed form {cf}");
        }
        // A surface of revolution lies between the cylinders of its smallest and largest radius.
        assert!(v < PI * (diameter / 2.0).powi(2) * length, "{name}: larger than its bounding cylinder");
    }
    // The bottles have grooves: along the body the radius is not monotone (surface normals
    // turn back and forth). Count sign changes of dr/da along a top line of the mesh.
    for (name, min_changes) in [("bottle_1", 8), ("bottle_2", 14)] {
        let mesh = read_surface(&out.join(format!("{name}.obj"))).unwrap();
        let mut top: Vec<[f64; 2]> =
            mesh.verts.iter().filter(|p| p[2].abs() < 1e-12 && p[1] > 0.0).map(|p| [p[0], p[1]]).collect();
        top.sort_by(|a, b| a[0].total_cmp(&b[0]));
        let slopes: Vec<f64> = top.windows(2).map(|w| w[1][1] - w[0][1]).filter(|d| d.abs() > 1e-7).collect();
        let changes = slopes.windows(2).filter(|s| s[0].signum() != s[1].signum()).count();
        assert!(changes >= min_changes, "{name}: only {changes} slope sign changes along the profile");
    }
}

/// A one-object spec at the quick tier's settings: the noise-free ball and the ball at 50 mK
/// with 2 seeds.
fn ball_spec(dir: &Path) -> std::path::PathBuf {
    let mut spec: Value = serde_json::from_str(
        &std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../suites/quick.json")).unwrap(),
    )
    .unwrap();
    spec["name"] = "ball".into();
    spec["seeds"] = 2.into();
    spec["objects"] = serde_json::json!([{ "object": "ball", "solver": "surface" }]);
    spec["noise"] = serde_json::json!([spec["noise"][0], spec["noise"][2]]);
    spec.as_object_mut().unwrap().remove("bound");
    let path = dir.join("ball.json");
    std::fs::write(&path, spec.to_string()).unwrap();
    path
}

#[test]
fn the_table_is_a_report_of_a_suite_run() {
    let dir = tempfile::tempdir().unwrap();
    let (suite, run, out) = (dir.path().join("suite"), dir.path().join("run"), dir.path().join("table"));
    let spec = ball_spec(dir.path());
    ok(&simbench(&["suite", "build", "--spec", spec.to_str().unwrap(), "--out", suite.to_str().unwrap()]));
    ok(&simbench(&[
        "suite",
        "run",
        suite.to_str().unwrap(),
        "--out",
        run.to_str().unwrap(),
        "--method",
        "builtin:paper",
    ]));
    let stdout = ok(&simbench(&["table", "shape-error", run.to_str().unwrap(), "--out", out.to_str().unwrap()]));
    let text = std::fs::read_to_string(out.join("shape_error.csv")).unwrap();
    assert_eq!(text, stdout, "stdout is the CSV");
    let rows = parse_csv(&text);
    let header = &rows[0];
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    assert_eq!(rows.len(), 1 + 2, "one row per noise level: {text}");
    for r in &rows[1..] {
        assert_eq!(r.len(), header.len(), "{r:?}");
        assert_eq!(
            (r[col("object")].as_str(), r[col("solver")].as_str(), r[col("thickness_m")].as_str()),
            ("ball", "surface", "0.002")
        );
    }
    assert_eq!(rows[2][col("seeds")], "2");
    let md = std::fs::read_to_string(out.join("shape_error.md")).unwrap();
    assert!(md.contains("1.2 (SFM) / 0.7 (Kinect)"), "the paper's ball value is beside the table");
    // Stage 2's accuracy on the noise-free ball (160 x 128): within the paper's ball figure
    // (1.2 mm against SFM, Table 2). Measured 0.88 mm with the old table pipeline (the same
    // scene and reconstruction).
    assert_eq!(rows[1][col("netd_mK")], "0");
    assert_eq!(rows[1][col("failed")], "0");
    let mae: f64 = rows[1][col("mae_mm")].parse().unwrap();
    assert!(mae < 1.2, "NETD 0 ball: {mae} mm, above the paper's 1.2 mm");
}

#[test]
fn bad_arguments_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("t");
    let o = o.to_str().unwrap();
    fails_with(&["table", "shape-error", dir.path().to_str().unwrap(), "--out", o], &["not a suite run"]);
    fails_with(&["table", "objects", "--out", o, "--spacing=-1"], &["--spacing"]);
    fails_with(&["table", "nonsense"], &["nonsense"]);
    assert!(!Path::new(o).exists(), "nothing written by failed commands");
}
