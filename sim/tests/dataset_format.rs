//! Integration tests of `heatsim::dataset_format`: every JSON file of a dataset round-trips
//! (value and bytes), `lamps.json` in the legacy object layout loads with a warning, mixed and
//! unknown layouts are refused naming the file, unknown fields and values out of range are
//! refused with their JSON path, a converted recording's minimal files load, and the schema
//! describes every file.

use std::path::{Path, PathBuf};

use heatsim::camera::Camera;
use heatsim::dataset_format::{
    self as format, CameraFile, DatasetFormatError, DatasetJson, EnvironmentFile, LampsLayout, MetaFile, RenderReport,
    DATA_FILES,
};
use heatsim::mesh::tetmesh::MeshStats;
use heatsim::meshing::MeshReport;
use heatsim::scene::{LampSpec, Scene, SolverKind};
use heatsim::simulate::{EnergyBalance, SimulationReport};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// The hemisphere validation scene's left-lamp dataset, with made-up reports.
fn hemisphere_files() -> DatasetJson {
    let mut scene = Scene::from_file(&repo().join("scenes/recon/hemisphere-shell.json")).unwrap();
    scene.lamps = scene.lamp_configurations[0].lamps.clone();
    scene.lamp_configurations.clear();
    let camera = Camera::from_spec(&scene.camera).unwrap();
    let material = scene.material.resolve().unwrap();
    let mesh = MeshReport {
        object: "hemispherical shell, thickness 0.001 m, radius 0.05 m".into(),
        repairs: Vec::new(),
        stats: MeshStats {
            nodes: 34520,
            tetrahedra: 103171,
            boundary_faces: 69024,
            visible_faces: 34602,
            side_faces: 0,
            back_faces: 34422,
            cavity_faces: 0,
            min_dihedral_deg: 7.676234519422678,
            max_dihedral_deg: 164.99535241869933,
            max_radius_edge_ratio: 2.1957844031953893,
            min_edge_m: 0.00033299326761706654,
            max_edge_m: 0.0022452508799462407,
            volume_m3: 1.538485934187583e-5,
            boundary_volume_m3: 1.5384859341873008e-5,
            visible_area_m2: 0.015701908835512524,
            tets_per_layer: vec![103171],
        },
        analytic_volume_m3: Some(1.5395898397692388e-5),
        solid_volume_m3: 1.538486492130875e-5,
        volume_rel_error_vs_analytic: Some(-7.170127738834935e-4),
        volume_rel_error_vs_solid: -3.62657257446989e-7,
        surface_element_size_m: 0.002,
        fine_layer_depth_m: 0.004,
        deep_element_size_m: 0.002,
        radius_edge_ratio_bound: 1.5,
        build_seconds: 0.0015,
        tetgen_seconds: 1.69,
        wall_layers: None,
        first_wall_layer_m: None,
    };
    let simulation = SimulationReport {
        solver: SolverKind::Surface,
        nodes: 2024,
        tetrahedra: 0,
        matrix_nonzeros_lower: 7953,
        time_step_s: 0.05,
        steps: 300,
        frames: 31,
        newton_tolerance_k: 1e-9,
        newton_iterations_total: 318,
        newton_iterations_max: 2,
        newton_iterations_mean: 1.06,
        factorisations: 4,
        cg_iterations_total: None,
        assembly_seconds: 0.001,
        factorisation_seconds: 0.0018,
        stepping_seconds: 0.026,
        energy: EnergyBalance {
            stored_j: 11.389519026150834,
            absorbed_j: 11.691980639392938,
            convected_j: 0.1480317262297789,
            radiated_j: 0.15591891490694154,
            relative_mismatch: 1.4127924736660001e-12,
        },
        max_temperature_rise_k: 1.4782991576956306,
        layer_thickness_m: Some(0.001),
    };
    let render = RenderReport {
        rasterize_s: 0.013,
        frames_s: 0.0012,
        frames_per_second: None,
        covered_pixels: 2024,
        object_sub_samples: None,
    };
    DatasetJson {
        camera: CameraFile::new(&camera, &scene.camera, scene.timing.frame_interval),
        lamps: scene.lamps.clone(),
        environment: EnvironmentFile::new(&scene.environment, material.emissivity),
        material,
        meta: MetaFile::new("simbench test".into(), scene, mesh, simulation, render),
    }
}

fn write(dir: &Path, files: &DatasetJson) {
    let mut out = heatsim::io::OutputDir::new(dir).unwrap();
    files.write_into(&mut out).unwrap();
    out.commit().unwrap();
}

#[test]
fn every_file_round_trips_in_value_and_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("data");
    let files = hemisphere_files();
    write(&dir, &files);
    let (read, warnings) = DatasetJson::read(&dir).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(read, files);
    // Each reader on its own, and the bytes written again from what was read.
    assert_eq!(format::read_camera(&dir).unwrap(), files.camera);
    assert_eq!(format::read_environment(&dir).unwrap(), files.environment);
    assert_eq!(format::read_material(&dir).unwrap(), files.material);
    assert_eq!(format::read_meta(&dir).unwrap(), files.meta);
    let lamps = format::read_lamps(&dir).unwrap();
    assert_eq!((lamps.lamps, lamps.layout), (files.lamps.clone(), LampsLayout::Array));
    // These numbers read back exactly; serde_json without `float_roundtrip` may read some
    // 17-digit numbers 1 ulp off (module doc of heatsim::dataset_format).
    for (name, text) in read.texts() {
        assert_eq!(std::fs::read_to_string(dir.join(name)).unwrap(), text, "{name}");
        assert!(text.ends_with("}\n") || text.ends_with("]\n"), "{name}: pretty JSON and a newline");
    }
}

#[test]
fn files_keep_the_layout_simbench_has_always_written() {
    let files = hemisphere_files();
    let texts = files.texts();
    let text = |name: &str| texts.iter().find(|(n, _)| *n == name).unwrap().1.clone();
    // camera.json, environment.json, meta.json: keys sorted (upper case first); lamps.json and
    // material.json: field order.
    let camera = text("camera.json");
    let order =
        ["\"K\"", "\"R\"", "\"convention\"", "\"fixed_pattern_sigma_k\"", "\"frame_interval_s\"", "\"t\"", "\"width\""];
    let at: Vec<usize> = order.iter().map(|k| camera.find(k).unwrap_or_else(|| panic!("{k}"))).collect();
    assert!(at.windows(2).all(|w| w[0] < w[1]), "camera.json keys not sorted:\n{camera}");
    assert!(text("environment.json").starts_with("{\n  \"ambient_temperature\": 295.15,\n  \"back_boundary\": \"exposed\",\n  \"convection_coefficient\": 5.0,\n  \"emissivity\": 0.9\n}\n"));
    let meta = text("meta.json");
    let keys = ["\"files\"", "\"mesh\"", "\"render\"", "\"scene\"", "\"simulation\"", "\"software\"", "\"units\""];
    let at: Vec<usize> = keys.iter().map(|k| meta.find(&format!("\n  {k}")).unwrap()).collect();
    assert!(at.windows(2).all(|w| w[0] < w[1]), "meta.json keys not sorted");
    assert!(meta.contains("\"frames_per_second\": null"), "an unmeasurable rate is null");
    assert!(text("material.json").starts_with("{\n  \"name\": \"pla\",\n  \"density\": 1300.0,"));
    assert!(text("lamps.json").starts_with("[\n  {\n    \"kind\": \"point\",\n    \"power\": 250.0,"));
    assert_eq!(files.meta.files.len(), DATA_FILES.len());
}

/// The reference datasets committed under results/simulate were written before the files
/// were typed; they still load.
#[test]
fn committed_reference_datasets_load() {
    let mut seen = 0;
    for dir in ["results/simulate/bunny/left", "results/simulate/bunny/right", "results/simulate/bunny-uniform"] {
        let dir = repo().join(dir);
        if !dir.join("camera.json").exists() {
            continue;
        }
        let (files, warnings) = DatasetJson::read(&dir).unwrap_or_else(|e| panic!("{e}"));
        assert!(warnings.is_empty());
        assert!(!files.lamps.is_empty());
        seen += 1;
    }
    assert!(seen > 0, "no reference dataset found");
}

fn lamps_file(text: &str) -> (tempfile::TempDir, Result<format::LampsFile, DatasetFormatError>) {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("lamps.json"), text).unwrap();
    let r = format::read_lamps(tmp.path());
    (tmp, r)
}

fn lamps_error(text: &str) -> String {
    let (tmp, r) = lamps_file(text);
    let e = r.expect_err(text);
    let message = e.to_string();
    assert_eq!(e.path(), tmp.path().join("lamps.json"), "{message}");
    assert!(message.starts_with(&format!("{}: ", tmp.path().join("lamps.json").display())), "{message}");
    message
}

const POINT: &str = r#"{"kind": "point", "power": 250.0, "position": [-0.2, 0.0, 0.2]}"#;

#[test]
fn legacy_lamps_layout_loads_with_a_warning() {
    let (tmp, r) = lamps_file(&format!(r#"{{"lamps": [{POINT}, {{"kind": "uniform", "flux": 100.0}}]}}"#));
    let f = r.unwrap();
    assert_eq!(f.layout, LampsLayout::LegacyObject);
    assert_eq!(f.lamps.len(), 2);
    assert!(matches!(&f.lamps[0], LampSpec::Point(l) if l.position == [-0.2, 0.0, 0.2] && l.radiant_fraction == 0.85));
    assert_eq!(f.warnings.len(), 1);
    let w = &f.warnings[0];
    assert!(w.starts_with(&tmp.path().join("lamps.json").display().to_string()) && w.contains("legacy"), "{w}");
    // The same lamps as a bare array: no warning.
    let (_t, r) = lamps_file(&format!(r#"[{POINT}, {{"kind": "uniform", "flux": 100.0}}]"#));
    let g = r.unwrap();
    assert_eq!((g.layout, g.warnings.len()), (LampsLayout::Array, 0));
    assert_eq!(g.lamps, f.lamps);
    // An empty legacy file is still the legacy layout.
    let (_t, r) = lamps_file(r#"{"lamps": []}"#);
    assert_eq!(r.unwrap().layout, LampsLayout::LegacyObject);
}

#[test]
fn mixed_lamps_layouts_are_refused() {
    let m = lamps_error(&format!(r#"[{POINT}, {{"lamps": [{POINT}]}}]"#));
    assert!(m.contains("mixed layout") && m.contains("[1]"), "{m}");
    let m = lamps_error(&format!(r#"{{"lamps": [{{"lamps": [{POINT}]}}]}}"#));
    assert!(m.contains("mixed layout") && m.contains("lamps[0]"), "{m}");
    let m = lamps_error(&format!(r#"{{"lamps": [{POINT}], "camera": {{}}}}"#));
    assert!(m.contains("other keys") && m.contains("`camera`"), "{m}");
}

#[test]
fn unknown_lamps_layouts_are_refused() {
    for (text, expected) in [
        ("3", "unknown layout: a number"),
        (r#""lamps""#, "unknown layout: a string"),
        ("null", "unknown layout: null"),
        (POINT, "unknown layout: a single lamp object"),
        (r#"{"lights": []}"#, "unknown layout: an object with keys `lights`"),
        (r#"{"lamps": 3}"#, "unknown layout: `lamps` is a number"),
    ] {
        let m = lamps_error(text);
        assert!(m.contains(expected), "{text}: {m}");
    }
}

#[test]
fn bad_lamps_name_the_json_path() {
    let m = lamps_error(&format!(r#"[{POINT}, {{"kind": "point", "powr": 1.0, "position": [0, 0, 1]}}]"#));
    assert!(m.contains("[1].powr: unknown field"), "{m}");
    let m = lamps_error(r#"{"lamps": [{"kind": "spot"}]}"#);
    assert!(m.contains("lamps[0].kind: unknown variant"), "{m}");
    let m = lamps_error(r#"[{"kind": "uniform", "flux": -1.0}]"#);
    assert!(m.contains("[0].flux: must be >= 0"), "{m}");
    let m = lamps_error("[{");
    assert!(m.contains("line 1"), "{m}");
    let empty = tempfile::tempdir().unwrap();
    let e = format::read_lamps(empty.path()).unwrap_err();
    assert!(e.is_not_found() && e.to_string().contains("lamps.json"), "{e}");
}

fn write_file(name: &str, text: &str) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join(name), text).unwrap();
    let dir = tmp.path().to_path_buf();
    (tmp, dir)
}

#[test]
fn camera_fields_are_typed_and_checked() {
    let minimal = r#"{"K": [[100, 0, 31.5], [0, 100, 23.5], [0, 0, 1]], "R": [[1, 0, 0], [0, -1, 0], [0, 0, -1]],
        "t": [0, 0, 0.5], "width": 64, "height": 48, "frame_interval_s": 0.5}"#;
    let (_t, dir) = write_file("camera.json", minimal);
    let c = format::read_camera(&dir).unwrap();
    assert_eq!((c.width, c.height, c.frame_interval_s, c.netd_k), (64, 48, 0.5, None));
    for (text, expected) in [
        (minimal.replace("frame_interval_s", "frame_interval"), "unknown field `frame_interval`"),
        (minimal.replace("\"width\": 64", "\"width\": 0"), "width: must be >= 1 pixels, got 0"),
        (minimal.replace("\"width\": 64", "\"width\": 6.5"), "width: invalid type"),
        (minimal.replace("0.5}", "0.0}"), "frame_interval_s: must be > 0 s, got 0"),
        (minimal.replace("[[100, 0, 31.5]", "[[-100, 0, 31.5]"), "K[0][0]: must be > 0 pixels"),
        (minimal.replace("[0, 0, 1]], \"R\"", "[0, 0]], \"R\""), "K[2]: invalid length 2"),
        (minimal.replace("\"t\": [0, 0, 0.5], ", ""), "missing field `t`"),
    ] {
        let (_t, dir) = write_file("camera.json", &text);
        let m = format::read_camera(&dir).unwrap_err().to_string();
        assert!(m.contains("camera.json: ") && m.contains(expected), "expected `{expected}` in {m}");
    }
}

#[test]
fn environment_and_material_are_checked() {
    let (_t, dir) = write_file("environment.json", r#"{"ambient_temperature": 293.0}"#);
    let e = format::read_environment(&dir).unwrap();
    assert_eq!((e.ambient_temperature, e.emissivity, e.convection_coefficient), (293.0, None, None));
    for (text, expected) in [
        (r#"{"ambient_temperature": -1}"#, "ambient_temperature: must be > 0 K"),
        (r#"{"ambient_temperature": 293, "emissivity": 1.5}"#, "emissivity: must be in [0, 1], got 1.5"),
        (r#"{"ambient_temperature": 293, "emisivity": 0.9}"#, "unknown field `emisivity`"),
        (r#"{"ambient_temperature": 293, "back_boundary": "open"}"#, "back_boundary: unknown variant"),
    ] {
        let (_t, dir) = write_file("environment.json", text);
        let m = format::read_environment(&dir).unwrap_err().to_string();
        assert!(m.contains("environment.json: ") && m.contains(expected), "expected `{expected}` in {m}");
    }
    let pla = serde_json::to_value(heatsim::scene::lookup_material("pla").unwrap()).unwrap();
    let mut extra = pla.clone();
    extra["diffusivity"] = 1e-7.into();
    let mut negative = pla.clone();
    negative["density"] = (-1.0).into();
    for (value, expected) in [(extra, "unknown field `diffusivity`"), (negative, "density: must be > 0")] {
        let (_t, dir) = write_file("material.json", &value.to_string());
        let m = format::read_material(&dir).unwrap_err().to_string();
        assert!(m.contains("material.json: ") && m.contains(expected), "expected `{expected}` in {m}");
    }
}

#[test]
fn meta_refuses_unknown_fields_with_their_path() {
    let files = hemisphere_files();
    let mut meta = serde_json::to_value(&files.meta).unwrap();
    meta["scene"]["object"]["radius_m"] = 0.05.into();
    let (_t, dir) = write_file("meta.json", &meta.to_string());
    let m = format::read_meta(&dir).unwrap_err().to_string();
    assert!(m.contains("meta.json: scene.object.radius_m: unknown field"), "{m}");
}

#[test]
fn schema_describes_every_file() {
    let schema = format::json_schema();
    let props = schema["properties"].as_object().expect("properties");
    for file in ["camera.json", "lamps.json", "environment.json", "material.json", "meta.json"] {
        assert!(props.contains_key(file), "schema lacks {file}");
    }
    let text = schema.to_string();
    for word in ["frame_interval_s", "ambient_temperature", "layer_thickness_m", "in W/(m² K)", "legacy"] {
        assert!(text.contains(word), "schema lacks {word}");
    }
}
