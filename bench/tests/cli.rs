//! The `simbench` binary end to end: outputs, exit codes, and bad input.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn simbench(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_simbench")).args(args).output().expect("simbench runs")
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

fn malformed(name: &str) -> String {
    repo().join("sim/tests/data/malformed").join(name).display().to_string()
}

/// Oracle checks need the project's Python environment (scripts/setup-oracles.sh).
fn oracle_python() -> Option<PathBuf> {
    let py = repo().join(".venv/bin/python");
    if py.exists() {
        Some(py)
    } else if std::env::var_os("HEATSIM_REQUIRE_ASSETS").is_some() || std::env::var_os("CI").is_some() {
        panic!("the oracle environment .venv is missing: run scripts/setup-oracles.sh");
    } else {
        None
    }
}

#[test]
fn schema_is_json_with_the_scene_sections() {
    let out = simbench(&["schema"]);
    assert!(out.status.success());
    let schema: serde_json::Value = serde_json::from_slice(&out.stdout).expect("schema is JSON");
    for key in ["object", "material", "environment", "lamps", "camera", "timing", "solver", "meshing"] {
        assert!(schema["properties"].get(key).is_some(), "schema lacks {key}");
    }
}

/// `simbench schema dataset`: one JSON document keyed by the dataset's file names;
/// `simbench schema scene` is the default.
#[test]
fn schema_dataset_describes_every_json_file() {
    let out = simbench(&["schema", "dataset"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let schema: serde_json::Value = serde_json::from_slice(&out.stdout).expect("schema is JSON");
    for file in ["camera.json", "lamps.json", "environment.json", "material.json", "meta.json"] {
        assert!(schema["properties"].get(file).is_some(), "schema lacks {file}");
    }
    assert_eq!(simbench(&["schema", "scene"]).stdout, simbench(&["schema"]).stdout);
    let bad = simbench(&["schema", "datasets"]);
    assert_eq!(bad.status.code(), Some(2), "clap refuses an unknown WHAT");
}

#[test]
fn mesh_writes_vtu_obj_and_stats_that_meshio_reads() {
    let tmp = tempfile::tempdir().unwrap();
    let out_dir = tmp.path().join("cuboid");
    let scene = repo().join("scenes/cuboid.json");
    let out = simbench(&["mesh", scene.to_str().unwrap(), "--out", out_dir.to_str().unwrap()]);
    assert!(out.status.success(), "stderr: {}", String::from_utf8_lossy(&out.stderr));
    let stats: serde_json::Value = serde_json::from_slice(&out.stdout).expect("stdout is the stats JSON");
    let on_disk: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("mesh_stats.json")).unwrap()).unwrap();
    assert_eq!(stats, on_disk);
    for f in ["mesh.vtu", "boundary.vtu", "surface.obj", "visible.obj"] {
        assert!(out_dir.join(f).is_file(), "{f} missing");
    }
    let tets = stats["tetrahedra"].as_u64().unwrap();
    let nodes = stats["nodes"].as_u64().unwrap();
    assert!(tets > 1000 && stats["min_dihedral_deg"].as_f64().unwrap() > 1.0);
    if let Some(py) = oracle_python() {
        let check = Command::new(py)
            .arg(repo().join("scripts/oracle/check_vtu.py"))
            .arg(out_dir.join("mesh.vtu"))
            .output()
            .unwrap();
        assert!(check.status.success(), "meshio: {}", String::from_utf8_lossy(&check.stderr));
        let report: serde_json::Value = serde_json::from_slice(&check.stdout).expect("check_vtu prints JSON");
        assert_eq!(report["points"].as_u64(), Some(nodes));
        assert_eq!(report["cells"]["tetra"].as_u64(), Some(tets));
        assert!(report["tetra_min_signed_volume"].as_f64().unwrap() > 0.0, "a tetrahedron is inverted in the file");
        let v = report["tetra_volume"].as_f64().unwrap();
        let expected = stats["volume_m3"].as_f64().unwrap();
        assert!((v - expected).abs() < 1e-12 * expected.max(1.0), "meshio volume {v} vs {expected}");
    }
}

/// Writes a scene file that meshes `object` (a JSON object) and returns its path.
/// A square in the xz-plane: seen exactly edge-on from +z.
const EDGE_ON: &str = "v 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nf 1 2 3\nf 1 3 4\n";

/// A needle along z, 1000 times longer than wide: scaled to 0.1 m its silhouette is 0.1 mm
/// across, under one raster sample.
const NEEDLE: &str = "v 0 0 0\nv 0.001 0 0\nv 0 0.001 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 3 1 4\n";

/// Writes `text` to `dir/name` and returns the path as a string.
fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.to_string_lossy().into_owned()
}

fn scene_with(dir: &Path, name: &str, object: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, format!(r#"{{"object": {object}, "material": {{"name": "pla"}}}}"#)).unwrap();
    p
}

#[test]
fn bad_input_fails_cleanly_and_writes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let mesh = |file: &str, construction: &str| {
        format!(
            r#"{{"kind": "mesh", "file": "{file}", "size": 0.1, "thickness": 0.01, "construction": "{construction}"}}"#
        )
    };
    let cases: Vec<(PathBuf, &str)> = vec![
        (
            scene_with(d, "neg.json", r#"{"kind": "cuboid", "width": 0.05, "height": 0.05, "thickness": -0.01}"#),
            "object.thickness: must be > 0 m, got -0.01",
        ),
        (
            scene_with(d, "zero.json", r#"{"kind": "hemisphere", "radius": 0, "thickness": 0.01}"#),
            "object.radius: must be > 0 m, got 0",
        ),
        (
            scene_with(
                d,
                "unknown.json",
                r#"{"kind": "cuboid", "width": 0.05, "height": 0.05, "thickness": 0.01, "colour": "red"}"#,
            ),
            "object.colour",
        ),
        (scene_with(d, "kind.json", r#"{"kind": "torus", "radius": 0.05}"#), "unknown variant"),
        (scene_with(d, "missing.json", &mesh("nowhere.obj", "relief")), "nowhere.obj"),
        (scene_with(d, "truncated.json", &mesh(&malformed("truncated.obj"), "relief")), "truncated.obj"),
        (scene_with(d, "bad_index.json", &mesh(&malformed("bad_index.obj"), "relief")), "bad_index.obj"),
        (scene_with(d, "nan.json", &mesh(&malformed("nan.obj"), "relief")), "nan.obj"),
        (scene_with(d, "inf.json", &mesh(&malformed("inf.obj"), "relief")), "inf.obj"),
        (scene_with(d, "empty.json", &mesh(&malformed("empty.obj"), "relief")), "empty.obj"),
        (scene_with(d, "garbage.json", &mesh(&malformed("garbage.obj"), "relief")), "garbage.obj"),
        (scene_with(d, "glb.json", &mesh(&malformed("truncated.glb"), "relief")), "truncated.glb"),
        (scene_with(d, "gltf.json", &mesh(&malformed("bad_index.gltf"), "relief")), "bad_index.gltf"),
        (scene_with(d, "open.json", &mesh(&malformed("open.obj"), "solid")), "open.obj: the surface is not closed"),
        (
            scene_with(d, "selfx.json", &mesh(&malformed("self_intersecting.obj"), "solid")),
            "self_intersecting.obj: the surface intersects",
        ),
        (
            scene_with(d, "inside_out.json", &mesh(&malformed("inside_out.obj"), "solid")),
            "inside_out.obj: the surface is inside out",
        ),
        (
            scene_with(d, "edge_on.json", &mesh(&write(d, "edge_on.obj", EDGE_ON), "relief")),
            "edge_on.obj: could not build the solid: the surface covers 0 samples",
        ),
        (
            scene_with(d, "needle.json", &mesh(&write(d, "needle.obj", NEEDLE), "relief")),
            "needle.obj: could not build the solid",
        ),
    ];
    for (scene, expected) in &cases {
        let out_dir = d.join("out");
        let out = simbench(&["mesh", scene.to_str().unwrap(), "--out", out_dir.to_str().unwrap()]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        let name = scene.file_name().unwrap().to_string_lossy();
        assert_eq!(out.status.code(), Some(1), "{name}: exit code; stderr: {stderr}");
        assert!(stderr.to_lowercase().contains(&expected.to_lowercase()), "{name}: expected `{expected}` in: {stderr}");
        assert!(!stderr.contains("panicked"), "{name} panicked: {stderr}");
        assert!(out.stdout.is_empty(), "{name}: printed to stdout on failure");
        assert!(!out_dir.exists(), "{name}: left {} behind", out_dir.display());
        let leftovers: Vec<_> = std::fs::read_dir(d)
            .unwrap()
            .filter_map(Result::ok)
            .filter(|e| e.file_name().to_string_lossy().contains("partial"))
            .collect();
        assert!(leftovers.is_empty(), "{name}: left a staging directory");
    }
}

#[test]
fn closed_bunny_as_a_solid_is_refused_as_self_intersecting() {
    // The known trap: the closed bunny self-intersects; it must be refused before TetGen.
    heatsim::assets::bunny_path(None).expect("the bunny asset is required by this test");
    let tmp = tempfile::tempdir().unwrap();
    let scene = tmp.path().join("bunny_solid.json");
    std::fs::write(
        &scene,
        r#"{"object": {"kind": "bunny", "size": 0.1, "construction": "solid"}, "material": {"name": "pla"}}"#,
    )
    .unwrap();
    let out_dir = tmp.path().join("out");
    let out = simbench(&["mesh", scene.to_str().unwrap(), "--out", out_dir.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "stderr: {stderr}");
    assert!(stderr.contains("intersect"), "{stderr}");
    assert!(!out_dir.exists());
}

#[test]
fn missing_bunny_override_names_the_flag() {
    let tmp = tempfile::tempdir().unwrap();
    let out = simbench(&[
        "mesh",
        repo().join("scenes/bunny.json").to_str().unwrap(),
        "--out",
        tmp.path().join("o").to_str().unwrap(),
        "--bunny",
        "/no/such/bunny.obj",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr.contains("/no/such/bunny.obj") && stderr.contains("--bunny"), "{stderr}");
}

/// A small, quick scene: a 2 cm PLA plate, one uniform lamp, 1 s of video at 6 fps.
fn small_scene(dir: &Path, name: &str, extra: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(
        &p,
        format!(
            r#"{{"object": {{"kind": "cuboid", "width": 0.02, "height": 0.02, "thickness": 0.004}},
 "material": {{"name": "pla"}},
 "meshing": {{"surface_element_size": 0.003}},
 "timing": {{"duration": 1.0, "pre_heating_frames": 2}}{extra}}}"#
        ),
    )
    .unwrap();
    p
}

#[test]
fn dataset_is_complete_and_the_same_seed_gives_the_same_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = small_scene(
        tmp.path(),
        "plate.json",
        r#", "lamps": [{"kind": "uniform", "flux": 200.0}, {"kind": "point", "power": 60.0, "position": [0.1, 0.0, 0.3]}]"#,
    );
    let run = |dir: &str, seed: &str| {
        let out = tmp.path().join(dir);
        let o = simbench(&[
            "simulate",
            scene.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--seed",
            seed,
            "--vtu-frames",
            "0",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        out
    };
    let a = run("a", "7");
    let b = run("b", "7");
    let c = run("c", "8");
    for f in [
        "video.npy",
        "video_clean.npy",
        "mask.npy",
        "mask.png",
        "camera.json",
        "lamps.json",
        "material.json",
        "environment.json",
        "gt_mesh.obj",
        "gt_depth.npy",
        "gt_normals.npy",
        "gt_flux.npy",
        "preview.png",
        "meta.json",
    ] {
        assert!(a.join(f).is_file(), "{f} missing");
    }
    let bytes = |d: &Path, f: &str| std::fs::read(d.join(f)).unwrap();
    assert_eq!(bytes(&a, "video.npy"), bytes(&b, "video.npy"), "same seed, different video");
    assert_ne!(bytes(&a, "video.npy"), bytes(&c, "video.npy"), "different seeds gave the same noise");
    assert_eq!(
        bytes(&a, "video_clean.npy"),
        bytes(&c, "video_clean.npy"),
        "the clean video must not depend on the seed"
    );
    // The JSON files read back through their types and written again: the same keys and
    // values. (Not always the same bytes: without serde_json's `float_roundtrip` feature a
    // 17-digit number such as 1.6000000000000001e-6 may be read 1 ulp off, as it always was.)
    let (files, warnings) = heatsim::dataset_format::DatasetJson::read(&a).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    for (name, text) in files.texts() {
        let written: serde_json::Value = serde_json::from_slice(&bytes(&a, name)).unwrap();
        assert_eq!(written, serde_json::from_str::<serde_json::Value>(&text).unwrap(), "{name}");
    }
    let meta: serde_json::Value = serde_json::from_slice(&bytes(&a, "meta.json")).unwrap();
    assert!(meta["simulation"]["energy"]["relative_mismatch"].as_f64().unwrap() < 1e-6);
    assert!(meta["render"]["covered_pixels"].as_u64().unwrap() > 1000);
}

#[test]
fn dataset_bad_input_fails_cleanly() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let cases = [
        (
            small_scene(
                d,
                "away.json",
                r#", "lamps": [{"kind": "uniform", "flux": 100.0}], "camera": {"position": [0.0, 0.0, 0.4], "look_at": [0.0, 0.0, 1.0], "up": [0.0, 1.0, 0.0]}"#,
            ),
            "camera",
        ),
        (
            small_scene(
                d,
                "inside.json",
                r#", "lamps": [{"kind": "point", "power": 60.0, "position": [0.0, 0.0, -0.002]}]"#,
            ),
            "lamps[0].position",
        ),
        (
            small_scene(
                d,
                "close.json",
                r#", "lamps": [{"kind": "point", "power": 60.0, "position": [0.0, 0.0, 0.0003]}]"#,
            ),
            "lamps[0].position",
        ),
        (
            small_scene(d, "zero.json", r#", "lamps": [{"kind": "uniform", "flux": 100.0}], "camera": {"width": 0}"#),
            "camera.width",
        ),
    ];
    let dt = d.join("dt.json");
    std::fs::write(&dt, r#"{"object": {"kind": "cuboid", "width": 0.02, "height": 0.02, "thickness": 0.004}, "material": {"name": "pla"},
 "timing": {"duration": 1.0, "time_step": 0.5, "frame_interval": 0.25}}"#).unwrap();
    let cases: Vec<(PathBuf, &str)> = cases.into_iter().chain([(dt, "time_step")]).collect();
    for (scene, expected) in &cases {
        let out_dir = d.join("out");
        let o = simbench(&["simulate", scene.to_str().unwrap(), "--out", out_dir.to_str().unwrap()]);
        let stderr = String::from_utf8_lossy(&o.stderr);
        let name = scene.file_name().unwrap().to_string_lossy();
        assert_eq!(o.status.code(), Some(1), "{name}: {stderr}");
        assert!(stderr.contains(expected), "{name}: expected `{expected}` in: {stderr}");
        assert!(!stderr.contains("panicked"), "{name}: {stderr}");
        assert!(!out_dir.exists(), "{name}: left output behind");
    }
}

#[test]
fn surface_solver_writes_the_same_dataset_layout() {
    // --solver surface on the visible surface and on the camera grid: the dataset files of
    // the volumetric solver, a surface of the right kind, and the camera-grid video showing
    // each vertex's temperature at its own pixel.
    let tmp = tempfile::tempdir().unwrap();
    let scene = small_scene(
        tmp.path(),
        "plate.json",
        r#", "lamps": [{"kind": "point", "power": 60.0, "position": [0.05, 0.0, 0.2]}]"#,
    );
    for (mesh, flux, dir) in [
        ("visible", "triangle-mean", "vis"),
        ("camera-grid", "triangle-mean", "grid"),
        ("camera-grid", "vertex", "gridv"),
    ] {
        let out = tmp.path().join(dir);
        let o = simbench(&[
            "simulate",
            scene.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--solver",
            "surface",
            "--surface-mesh",
            mesh,
            "--surface-flux",
            flux,
            "--vtu-frames",
            "2",
        ]);
        assert!(o.status.success(), "{mesh}: {}", String::from_utf8_lossy(&o.stderr));
        for f in ["video.npy", "video_clean.npy", "mask.npy", "gt_depth.npy", "gt_flux.npy", "gt_mesh.obj", "meta.json"]
        {
            assert!(out.join(f).is_file(), "{mesh}: {f} missing");
        }
        assert!(out.join("temperature.pvd").is_file());
        let meta: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("meta.json")).unwrap()).unwrap();
        let sim = &meta["simulation"];
        assert_eq!(sim["solver"], "surface");
        // The scene as run, with the flux option only when it is not the default.
        let recorded = meta["scene"]["solver"].get("surface_flux").and_then(|v| v.as_str());
        assert_eq!(recorded, (flux == "vertex").then_some("vertex"), "{mesh} {flux}");
        assert_eq!(sim["layer_thickness_m"].as_f64(), Some(0.004));
        assert!(sim["energy"]["relative_mismatch"].as_f64().unwrap() < 1e-9);
        let env: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("environment.json")).unwrap()).unwrap();
        assert!(env["emissivity"].as_f64().unwrap() > 0.5, "environment.json carries the emissivity");
        if mesh == "camera-grid" {
            // One vertex per covered pixel.
            let covered = meta["render"]["covered_pixels"].as_u64().unwrap();
            assert_eq!(sim["nodes"].as_u64().unwrap(), covered, "camera grid: a vertex per masked pixel");
        }
    }
    // A closed mesh has no thickness for the surface model: refused before meshing.
    let solid = tmp.path().join("solid.json");
    std::fs::write(
        &solid,
        r#"{"object": {"kind": "bunny", "size": 0.1, "construction": "solid"}, "material": {"name": "pla"}, "lamps": []}"#,
    )
    .unwrap();
    let out = tmp.path().join("solid_out");
    let o = simbench(&["simulate", solid.to_str().unwrap(), "--out", out.to_str().unwrap(), "--solver", "surface"]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("object.thickness"), "{stderr}");
    assert!(!out.exists());
}

/// Bad configurations are refused before any dataset is read, with exit code 1, a message
/// naming the key (or file) and nothing written: an unknown preset, an unknown or mistyped key
/// in a configuration file (its JSON path), `--set` on a missing key, an experiment's level
/// that is not reconstructed.
#[test]
fn reconstruct_refuses_bad_configuration() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().join("out");
    let o = out.to_str().expect("utf-8");
    let cfg = dir.path().join("cfg.json");
    let c = cfg.to_str().expect("utf-8");
    // The experiments' section exists in builds with the feature `experimental` only.
    let experiment_refusal: &[&str] = if cfg!(feature = "experimental") {
        &["experimental.output_error.level", "not among the reconstructed levels"]
    } else {
        &["unknown field `experimental`"]
    };
    let cases: [(&str, &[&str], &[&str]); 6] = [
        ("", &["--preset", "fastest"], &["unknown preset `fastest`", "paper, calibrated-lamps"]),
        (r#"{"shape": {"iteratons": 3}}"#, &["--config", c], &["cfg.json", "shape", "iteratons"]),
        (r#"{"stage1": {"denoise": "median"}}"#, &["--config", c], &["cfg.json", "stage1.denoise"]),
        ("", &["--set", "shape.iteration=3"], &["--set shape.iteration=3", "no key `shape.iteration`"]),
        ("", &["--set", "shape.iterations=-3"], &["shape.iterations"]),
        (
            r#"{"experimental": {"output_error": {"level": 5}}}"#,
            &["--diffusivity", "1e-7", "--config", c],
            experiment_refusal,
        ),
    ];
    for (file, extra, expected) in cases {
        std::fs::write(&cfg, file).expect("write config");
        let mut args = vec!["reconstruct", "no/such/left", "no/such/right", "--out", o];
        args.extend(extra);
        let r = simbench(&args);
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(1), "{extra:?}: {err}");
        for e in expected {
            assert!(err.contains(e), "{extra:?}: {e:?} missing from {err}");
        }
        assert!(!out.exists(), "{extra:?}: nothing may be written");
    }
}

/// `simbench schema recon-config` prints the configuration's JSON Schema, documented with units.
#[test]
fn schema_prints_the_reconstruction_configuration() {
    let o = simbench(&["schema", "recon-config"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let schema: serde_json::Value = serde_json::from_slice(&o.stdout).expect("JSON");
    for key in ["stage", "level", "input", "stage1", "shape", "experimental"] {
        assert!(schema["properties"].get(key).is_some(), "schema lacks {key}: {schema}");
    }
    assert!(o.stdout.windows(4).any(|w| w == b"m^2/"), "units are documented");
}

/// The hemisphere validation scene at 80 x 64 pixels and `duration` s, simulated into `dir`:
/// (left, right).
fn small_hemisphere(dir: &Path, duration: f64) -> (PathBuf, PathBuf) {
    let mut scene: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(repo().join("scenes/recon/hemisphere-shell.json")).unwrap())
            .unwrap();
    scene["camera"]["width"] = 80.into();
    scene["camera"]["height"] = 64.into();
    scene["camera"]["pixel_pitch"] = 96e-6.into();
    scene["timing"]["duration"] = duration.into();
    let scene_path = dir.join("scene.json");
    std::fs::write(&scene_path, scene.to_string()).unwrap();
    let data = dir.join("data");
    let sim =
        simbench(&["simulate", scene_path.to_str().unwrap(), "--out", data.to_str().unwrap(), "--vtu-frames", "0"]);
    assert!(sim.status.success(), "{}", String::from_utf8_lossy(&sim.stderr));
    (data.join("left"), data.join("right"))
}

/// Without `--stage` the whole method runs and writes the shape; the resolved configuration
/// is written to config.json, and `--config OUT/config.json` gives the same shape files byte
/// for byte (timings and paths are only in run.json).
#[test]
fn reconstruct_writes_its_configuration_and_reruns_from_it() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (l, r) = small_hemisphere(dir.path(), 10.0);
    let (l, r) = (l.to_str().unwrap(), r.to_str().unwrap());
    let first = dir.path().join("first");
    let f = first.to_str().unwrap();
    let o = simbench(&[
        "reconstruct",
        l,
        r,
        "--out",
        f,
        "--diffusivity",
        "material",
        "--set",
        "shape.iterations=3",
        "--set",
        "shape.extra_levels=1",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cfg: serde_json::Value = serde_json::from_slice(&std::fs::read(first.join("config.json")).unwrap()).unwrap();
    assert_eq!(cfg["stage"], "shape");
    assert_eq!(cfg["shape"]["iterations"], 3);
    assert!(cfg["input"]["diffusivity_m2_per_s"].as_f64().unwrap() > 0.0, "the everyday flag is recorded: {cfg}");
    let second = dir.path().join("second");
    let config = first.join("config.json");
    let o = simbench(&["reconstruct", l, r, "--out", second.to_str().unwrap(), "--config", config.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in [
        "depth.npy",
        "normals.npy",
        "recon.obj",
        "recon.ply",
        "recon_world.obj",
        "convergence.csv",
        "stage2.json",
        "params.json",
        "laplacian.npz",
        "flux_0.npy",
        "config.json",
    ] {
        let (a, b) = (std::fs::read(first.join(f)).unwrap(), std::fs::read(second.join(f)).unwrap());
        assert!(a == b, "{f} differs between the run and its rerun from config.json");
    }
    assert!(first.join("run.json").exists());
}

/// `shape.globals`: minimised jointly with the depths by default, `profiled` or held at
/// `stage1`; `stage2.json` says which.
#[test]
fn stage2_records_how_the_globals_were_fitted() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (l, r) = small_hemisphere(dir.path(), 10.0);
    let run = |name: &str, extra: &[&str]| -> Output {
        let out = dir.path().join(name);
        let mut args = vec!["reconstruct", l.to_str().unwrap(), r.to_str().unwrap(), "--out", out.to_str().unwrap()];
        args.extend(["--diffusivity", "material", "--set", "shape.iterations=3", "--set", "shape.extra_levels=1"]);
        args.extend(extra);
        simbench(&args)
    };
    for (name, extra, expected) in [
        ("joint", &[][..], "minimised jointly with the depths"),
        ("profiled", &["--set", "shape.globals=profiled"][..], "profiled at every evaluation"),
        ("held", &["--set", "shape.globals=stage1"][..], "stage 1's"),
    ] {
        let o = run(name, extra);
        assert!(o.status.success(), "{name}: {}", String::from_utf8_lossy(&o.stderr));
        let p: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.path().join(name).join("stage2.json")).unwrap()).unwrap();
        assert_eq!(p["globals"], expected, "{name}");
    }
}

/// `shape.min_coarsest_vertices`: stage 2 starts at the coarsest requested level whose pixel
/// mesh has that many vertices, says so, and records the rule in stage2.json's configuration;
/// the calibrated-lamps preset sets it to 500. A small hemisphere (80 x 64 camera, 10 s) and a few iterations keep it
/// fast; only the choice of levels is checked here.
#[test]
fn coarsest_level_respects_the_minimum_vertex_count() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (l, r) = small_hemisphere(dir.path(), 10.0);
    // The levels a run reconstructed (coarsest first) with their vertex counts, and its stderr.
    let run = |name: &str, extra: &[&str]| -> (Vec<(u64, u64)>, serde_json::Value, String) {
        let out = dir.path().join(name);
        let mut args = vec!["reconstruct", l.to_str().unwrap(), r.to_str().unwrap(), "--out", out.to_str().unwrap()];
        args.extend(["--diffusivity", "material", "--set", "shape.iterations=2", "--set", "shape.extra_levels=2"]);
        args.extend(extra);
        let o = simbench(&args);
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert!(o.status.success(), "{err}");
        let p: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("stage2.json")).unwrap()).unwrap();
        let levels = p["levels"]
            .as_array()
            .unwrap()
            .iter()
            .map(|l| (l["level"].as_u64().unwrap(), l["vertices"].as_u64().unwrap()))
            .collect();
        (levels, p, err)
    };
    let (all, p, err) = run("all", &[]);
    eprintln!("levels and vertices: {all:?}");
    assert_eq!(all.iter().map(|l| l.0).collect::<Vec<_>>(), [2, 1, 0], "{all:?}");
    assert_eq!(p["config"]["shape"]["min_coarsest_vertices"], 0);
    assert!(!err.contains("starting at level"), "{err}");
    // Just above level 2's count: start at level 1.
    let min = (all[0].1 + 1).to_string();
    let (some, p, err) = run("some", &["--set", &format!("shape.min_coarsest_vertices={min}")]);
    assert_eq!(some, all[1..], "{some:?} against {all:?}");
    assert_eq!(p["config"]["shape"]["min_coarsest_vertices"].to_string(), min);
    assert!(err.contains("starting at level 1 instead of 2"), "{err}");
    // The calibrated-lamps preset's 500 against the counts of the first run.
    let (shaded, p, _) = run("shaded", &["--preset", "calibrated-lamps", "--set", "shape.coarsest_iterations=2"]);
    assert_eq!(p["config"]["shape"]["min_coarsest_vertices"], 500);
    let expected: Vec<(u64, u64)> = match all.iter().position(|l| l.1 >= 500) {
        Some(k) => all[k..].to_vec(),
        None => all[2..].to_vec(),
    };
    assert_eq!(shaded, expected, "{all:?}");
}

/// `--shape-bound`: refused without `--check` or the diffusivity (exit code 1, nothing
/// written); with them, `check.json` holds the bound at every level, four rows whose standard
/// deviations grow as nuisances become unknown.
#[test]
fn shape_bound_is_checked_and_nested() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (l, r) = small_hemisphere(dir.path(), 10.0);
    let run = |name: &str, extra: &[&str]| -> Output {
        let out = dir.path().join(name);
        let mut args = vec!["reconstruct", l.to_str().unwrap(), r.to_str().unwrap(), "--out", out.to_str().unwrap()];
        args.extend([
            "--set",
            "shape.iterations=1",
            "--level",
            "1",
            "--set",
            "shape.extra_levels=0",
            "--shape-bound",
            "1",
        ]);
        args.extend(extra);
        simbench(&args)
    };
    for (name, extra, expected) in [
        ("no_truth", &["--diffusivity", "material"][..], "--shape-bound needs --check"),
        ("no_alpha", &["--check"][..], "needs the shape stage and the diffusivity"),
    ] {
        let o = run(name, extra);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.code() == Some(1) && err.contains(expected), "{name}: {err}");
        assert!(!dir.path().join(name).exists(), "{name}: nothing may be written");
    }
    let o = run("bound", &["--check", "--diffusivity", "material"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let p: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("bound").join("check.json")).unwrap()).unwrap();
    let b = &p["levels"][0]["shape_bound"];
    assert_eq!(b["modes"].as_array().unwrap().len(), 4, "size, relief, u, v: {b}");
    let rows = b["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 4, "{b}");
    let std = |fluxes: bool, globals: bool| -> Vec<f64> {
        let row = rows
            .iter()
            .find(|r| r["nuisances"]["fluxes"] == fluxes && r["nuisances"]["globals"] == globals)
            .expect("row");
        assert!(row["joint_mae_m"].as_f64().unwrap() > 0.0, "{row}");
        row["std"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect()
    };
    let (known, free) = (std(false, false), std(true, true));
    for (tighter, looser) in [(&known, &std(true, false)), (&known, &std(false, true)), (&std(true, false), &free)] {
        for (a, c) in tighter.iter().zip(looser.iter()) {
            assert!(a.is_finite() && *a > 0.0 && *c >= a * (1.0 - 1e-9), "{tighter:?} vs {looser:?}");
        }
    }
}

/// `reconstruct` (stages 1 and 2) and `eval` write the same bytes at 1, 2 and 3 threads (issue
/// 28, item 6; heatrecon::faer_seq), the run record (run.json) and eval's timings aside. The scene's full 45 s at 2 fps: 100 frames,
/// where faer's parallel eigenvectors in stage 1's denoising depended on the thread count.
#[test]
fn reconstruction_is_the_same_at_any_thread_count() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (l, r) = small_hemisphere(dir.path(), 45.0);
    let with_threads = |n: usize, args: &[&str]| -> Output {
        let o = Command::new(env!("CARGO_BIN_EXE_simbench"))
            .args(args)
            .env("RAYON_NUM_THREADS", n.to_string())
            .output()
            .expect("simbench runs");
        assert!(o.status.success(), "{n} threads: {}", String::from_utf8_lossy(&o.stderr));
        o
    };
    // Timings removed: the "*seconds*" keys of eval's JSON.
    fn without_seconds(v: &mut serde_json::Value) {
        match v {
            serde_json::Value::Object(m) => {
                m.retain(|k, _| !k.contains("seconds"));
                m.values_mut().for_each(without_seconds);
            }
            serde_json::Value::Array(a) => a.iter_mut().for_each(without_seconds),
            _ => {}
        }
    }
    // Every file of an output directory, sorted by name, but the run record (timings, paths,
    // the thread count).
    let contents = |out: &Path| -> Vec<(String, Vec<u8>)> {
        let mut files: Vec<_> = std::fs::read_dir(out).unwrap().map(|e| e.unwrap().path()).collect();
        files.sort();
        files
            .iter()
            .map(|p| (p.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read(p).unwrap()))
            .filter(|(name, _)| name != "run.json")
            .collect()
    };
    let runs: Vec<(PathBuf, Vec<(String, Vec<u8>)>)> = [1, 2, 3]
        .iter()
        .map(|&n| {
            let out = dir.path().join(format!("threads{n}"));
            let o = out.to_str().unwrap();
            let args = ["reconstruct", l.to_str().unwrap(), r.to_str().unwrap(), "--out", o];
            with_threads(n, &[&args[..], &["--diffusivity", "material", "--set", "shape.iterations=30"]].concat());
            (out.clone(), contents(&out))
        })
        .collect();
    let names: Vec<&str> = runs[0].1.iter().map(|f| f.0.as_str()).collect();
    for f in ["depth.npy", "normals.npy", "recon.obj", "recon.ply", "laplacian.npz", "flux_0.npy", "params.json"] {
        assert!(names.contains(&f), "{f} missing: {names:?}");
    }
    for (n, (_, files)) in [2, 3].iter().zip(&runs[1..]) {
        assert_eq!(files.iter().map(|f| f.0.as_str()).collect::<Vec<_>>(), names, "{n} threads");
        for (a, b) in runs[0].1.iter().zip(files) {
            assert!(a.1 == b.1, "{} differs between 1 and {n} threads", a.0);
        }
    }
    // eval of the reconstruction against the truth (ICP with scale, metrics, PLY of the errors).
    let gt = l.join("gt_mesh.obj");
    let evals: Vec<(serde_json::Value, Vec<u8>)> = [1, 2]
        .iter()
        .map(|&n| {
            let ply = dir.path().join(format!("eval{n}.ply"));
            let recon = runs[0].0.join("recon_world.obj");
            let args = ["eval", "--recon", recon.to_str().unwrap(), "--gt", gt.to_str().unwrap()];
            let o =
                with_threads(n, &[&args[..], &["--align", "similarity", "--out-ply", ply.to_str().unwrap()]].concat());
            let mut j: serde_json::Value = serde_json::from_slice(&o.stdout).expect("stdout is JSON");
            without_seconds(&mut j);
            (j, std::fs::read(&ply).unwrap())
        })
        .collect();
    assert_eq!(evals[0].0, evals[1].0, "eval's figures differ between 1 and 2 threads");
    assert!(evals[0].1 == evals[1].1, "eval's PLY differs between 1 and 2 threads");
}

/// A `lamps.json` in no known layout (or with a bad lamp) stops `reconstruct` with exit code 1
/// and a message naming the file, before anything is written; the legacy object layout
/// `{"lamps": [...]}` still loads, with a warning naming the file.
#[test]
fn reconstruct_refuses_a_corrupt_lamps_json() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (l, r) = small_hemisphere(dir.path(), 10.0);
    let lamps = l.join("lamps.json");
    let run = |name: &str, extra: &[&str]| -> (Output, PathBuf) {
        let out = dir.path().join(name);
        let mut args = vec!["reconstruct", l.to_str().unwrap(), r.to_str().unwrap(), "--out", out.to_str().unwrap()];
        args.extend(["--level", "1"]);
        args.extend(extra);
        (simbench(&args), out)
    };
    let stage2: &[&str] = &["--set", "shape.iterations=1", "--set", "shape.extra_levels=0"];
    for (text, expected, extra) in [
        ("3", "unknown layout: a number", stage2),
        ("\"left\"", "unknown layout: a string", stage2),
        (r#"[{"kind": "point", "power": 250.0, "position": [-0.2, 0.0, 0.2]}, {"lamps": []}]"#, "mixed layout", stage2),
        (r#"{"lamps": [], "name": "left"}"#, "other keys (`name`)", stage2),
        (r#"[{"kind": "point", "power": "250 W", "position": [-0.2, 0.0, 0.2]}]"#, "[0].power: invalid type", stage2),
        // Stage 1's --check reads lamps.json with the rest of the ground truth.
        ("3", "unknown layout: a number", &["--stage", "1", "--check"][..]),
    ] {
        std::fs::write(&lamps, text).unwrap();
        let (o, out) = run("out", extra);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{text}: {err}");
        assert!(err.contains(&format!("{}: ", lamps.display())) && err.contains(expected), "{text}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!out.exists(), "{text}: wrote {}", out.display());
    }
    std::fs::write(&lamps, r#"{"lamps": [{"kind": "point", "power": 250.0, "position": [-0.2, 0.0, 0.2]}]}"#).unwrap();
    let (o, out) = run("legacy", stage2);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains(&format!("warning: {}: legacy layout", lamps.display())), "{err}");
    assert!(out.join("stage2.json").is_file());
}

#[test]
fn a_uniformly_heated_thin_plate_keeps_its_data_and_preview() {
    // scenes/cuboid.json at 1 mm on the surface solver: uniform heating gives a uniform last
    // frame, whose preview once stopped the run after the simulation (lo == hi).
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("plate");
    let scene = repo().join("scenes/cuboid.json");
    let o = simbench(&[
        "simulate",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--solver",
        "surface",
        "--thickness",
        "0.001",
    ]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    for f in ["video.npy", "mask.npy", "gt_depth.npy", "meta.json", "preview.png"] {
        assert!(out.join(f).is_file(), "{f} missing; stderr: {stderr}");
    }
}

#[test]
fn the_users_box_scene_simulates_end_to_end() {
    // scenes/box.json: an OBJ box with quads, rotated, as a relief (TetGen aborted on boxes).
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("box");
    let scene = repo().join("scenes/box.json");
    let o = simbench(&["simulate", scene.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    for view in ["left", "right"] {
        for f in ["video.npy", "mask.npy", "gt_depth.npy", "meta.json", "preview.png"] {
            assert!(out.join(view).join(f).is_file(), "{view}/{f} missing; stderr: {stderr}");
        }
    }
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("left/meta.json")).unwrap()).unwrap();
    let mesh = &meta["mesh"];
    assert!(mesh["object"].as_str().unwrap().contains("1 part(s)"), "{mesh}");
    assert!(mesh["volume_rel_error_vs_solid"].as_f64().unwrap().abs() < 1e-6, "{mesh}");
}

/// `simulate` compares the peak rise with the camera's NETD on stderr, and warns when the
/// signal is too weak to determine a shape.
#[test]
fn simulate_prints_the_peak_rise_against_the_netd() {
    let tmp = tempfile::tempdir().unwrap();
    let run = |name: &str, netd: f64| {
        let camera = format!(r#", "camera": {{"width": 64, "height": 48, "netd": {netd}}}"#);
        let lamps = r#", "lamps": [{"kind": "uniform", "flux": 200.0}]"#;
        let scene = small_scene(tmp.path(), &format!("{name}.json"), &format!("{camera}{lamps}"));
        let out = tmp.path().join(name);
        let o = simbench(&["simulate", scene.to_str().unwrap(), "--out", out.to_str().unwrap(), "--vtu-frames", "0"]);
        let stderr = String::from_utf8_lossy(&o.stderr).to_string();
        assert!(o.status.success(), "{stderr}");
        let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        (summary["max_temperature_rise_k"].as_f64().unwrap(), stderr)
    };
    // A quiet camera: hundreds of NETDs, no warning.
    let (rise, stderr) = run("quiet", 0.0005);
    let line = format!("peak rise {rise:.3} K = {:.1} x the camera's NETD (0.5 mK)", rise / 0.0005);
    assert!(rise / 0.0005 >= 20.0, "the quiet case is meant to be above 20 NETD: {rise} K");
    assert!(stderr.contains(&line), "no `{line}` in:\n{stderr}");
    assert!(!stderr.contains("warning: the peak rise"), "{stderr}");
    // A noisy camera: the same rise under 20 NETDs warns.
    let (rise, stderr) = run("noisy", 1.0);
    assert!(rise < 20.0, "the noisy case is meant to be under 20 NETD: {rise} K");
    assert!(stderr.contains("x the camera's NETD (1000.0 mK)"), "{stderr}");
    assert!(stderr.contains("warning: the peak rise is under 20 x NETD"), "{stderr}");
}

/// `simbench bench-solver --element-sizes`: one row per mesh and linear solver, the two solvers'
/// temperatures within the Newton tolerance, and the scaling files.
#[test]
fn bench_solver_sweeps_mesh_sizes_with_both_linear_solvers() {
    let dir = tempfile::tempdir().unwrap();
    let scene = repo().join("scenes/cuboid.json");
    let out = simbench(&[
        "bench-solver",
        scene.to_str().unwrap(),
        "--element-sizes",
        "0.005,0.004",
        "--repeat",
        "2",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let rows = rows.as_array().expect("one row per element size");
    assert_eq!(rows.len(), 2);
    assert!(rows[0]["nodes"].as_u64() < rows[1]["nodes"].as_u64(), "the finer mesh has more nodes");
    for r in rows {
        let diff = r["max_difference_after_steps_k"].as_f64().unwrap();
        assert!(diff <= 1e-9, "the solvers differ by {diff:e} K");
        let solvers: Vec<&str> =
            r["solvers"].as_array().unwrap().iter().map(|p| p["solver"].as_str().unwrap()).collect();
        assert_eq!(solvers, ["Direct", "ConjugateGradients"]);
        assert!(r["solvers"][1]["cg_iterations_per_solve_mean"].as_f64().unwrap() > 0.0);
    }
    let csv = std::fs::read_to_string(dir.path().join("solver_scaling.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 4, "{csv}");
    assert!(std::fs::read(dir.path().join("solver_scaling.png")).unwrap().starts_with(b"\x89PNG"));
}
