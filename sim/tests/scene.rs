//! Integration tests of `heatsim::scene`: the example scenes, round trips, and the error
//! message (with JSON path) of every kind of bad input.

use std::path::{Path, PathBuf};

use heatsim::scene::{json_schema, Construction, LampSpec, ObjectSpec, Scene, SceneError, SolverKind};

fn scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes")
}

fn load_example(name: &str) -> Scene {
    let path = scenes_dir().join(name);
    Scene::from_file(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn parse(text: &str) -> Result<Scene, SceneError> {
    Scene::from_json_str(text, Path::new("/base"))
}

fn parse_err(text: &str) -> SceneError {
    match parse(text) {
        Ok(scene) => panic!("expected an error for\n{text}\ngot {scene:?}"),
        Err(e) => e,
    }
}

/// A minimal valid scene with `extra` spliced in as further top-level fields.
fn minimal_with(object: &str, extra: &str) -> String {
    let sep = if extra.is_empty() { "" } else { "," };
    format!(r#"{{ "object": {object}, "material": {{ "name": "pla" }}{sep} {extra} }}"#)
}

const CUBOID: &str = r#"{ "kind": "cuboid", "width": 0.05, "height": 0.05, "thickness": 0.01 }"#;

#[test]
fn every_example_scene_loads_and_validates() {
    let mut names = Vec::new();
    for entry in std::fs::read_dir(scenes_dir()).expect("scenes/ exists") {
        let path = entry.expect("readable entry").path();
        if path.extension().and_then(|e| e.to_str()) != Some("json") {
            continue;
        }
        let scene = Scene::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
        scene.validate().expect("a loaded scene validates again");
        names.push(scene.name);
    }
    names.sort();
    for expected in ["bunny", "cuboid", "hemisphere"] {
        assert!(names.iter().any(|n| n == expected), "{expected} missing from {names:?}");
    }
}

#[test]
fn cuboid_example_has_the_requested_setup() {
    let scene = load_example("cuboid.json");
    let ObjectSpec::Cuboid(c) = &scene.object else { panic!("not a cuboid: {:?}", scene.object) };
    assert_eq!((c.width, c.height, c.thickness), (0.05, 0.05, 0.01));
    assert_eq!(scene.object.thickness(), Some(0.01));
    let material = scene.material.resolve().unwrap();
    assert_eq!(material.name, "polystyrene");
    assert_eq!((material.density, material.specific_heat, material.conductivity), (1050.0, 1300.0, 0.15));
    assert_eq!(scene.lamps.len(), 1);
    let LampSpec::Uniform(lamp) = &scene.lamps[0] else { panic!("not uniform") };
    assert_eq!(lamp.flux, 100.0);
    assert!(scene.lamps[0].is_on(0.0) && scene.lamps[0].is_on(1e6));
    assert_eq!(scene.camera.position, [0.0, 0.0, 0.3683]);
}

#[test]
fn hemisphere_and_bunny_examples_film_a_left_and_a_right_point_lamp() {
    for (file, kind) in [("hemisphere.json", "hemisphere"), ("bunny.json", "bunny")] {
        let scene = load_example(file);
        assert_eq!(scene.object.kind(), kind);
        assert_eq!(scene.material.resolve().unwrap().name, "pla");
        let sets = scene.lamp_sets();
        let names: Vec<Option<String>> = sets.iter().map(|(n, _)| n.clone()).collect();
        assert_eq!(names, vec![Some("left".to_string()), Some("right".to_string())], "{file}");
        assert!(sets.iter().all(|(_, lamps)| lamps.len() == 1), "{file}: one lamp per configuration");
        let positions: Vec<[f64; 3]> = sets
            .iter()
            .flat_map(|(_, lamps)| lamps.iter())
            .map(|l| match l {
                LampSpec::Point(p) => {
                    assert_eq!(p.power, 100.0);
                    assert_eq!(p.on, 0.0);
                    p.position
                }
                other => panic!("{file}: not a point lamp: {other:?}"),
            })
            .collect();
        assert_eq!(positions, vec![[-0.2, 0.0, 0.35], [0.2, 0.0, 0.35]], "{file}");
    }
    let ObjectSpec::Hemisphere(h) = load_example("hemisphere.json").object else { panic!("not a hemisphere") };
    assert_eq!((h.radius, h.thickness), (0.05, 0.005));
    let ObjectSpec::Bunny(b) = load_example("bunny.json").object else { panic!("not a bunny") };
    assert_eq!((b.size, b.thickness), (0.10, Some(0.01)));
    assert_eq!(b.construction, Construction::Relief);
}

#[test]
fn defaults_fill_every_section() {
    let scene = parse(&minimal_with(CUBOID, "")).unwrap();
    assert_eq!(scene.name, "scene");
    assert_eq!(scene.environment.ambient_temperature, 295.15);
    assert_eq!(scene.environment.convection_coefficient, 5.0);
    assert!(scene.lamps.is_empty());
    assert_eq!((scene.camera.width, scene.camera.height), (640, 512));
    assert_eq!(scene.camera.hfov_deg, 24.3);
    assert_eq!(scene.camera.netd, 0.05);
    assert_eq!(scene.timing.duration, 15.0);
    assert_eq!(scene.timing.steps_per_frame(), 10);
    assert_eq!(scene.timing.pre_heating_frames, 10);
    assert_eq!(scene.solver.kind, SolverKind::Volumetric);
    assert_eq!(scene.solver.max_newton_iterations, 25);
    assert_eq!(scene.meshing.surface_element_size, 2e-3);
    assert_eq!(scene.meshing.relief_resolution_or_default(), 1e-3);
    assert_eq!(scene.meshing.max_tetrahedra, 2_000_000);
}

#[test]
fn examples_round_trip_through_json() {
    for file in ["cuboid.json", "hemisphere.json", "bunny.json"] {
        let scene = load_example(file);
        let text = serde_json::to_string_pretty(&scene).unwrap();
        let back = Scene::from_json_str(&text, Path::new("/elsewhere")).unwrap();
        assert_eq!(back, scene, "{file}:\n{text}");
    }
}

#[test]
fn fully_specified_scene_round_trips() {
    let text = r#"{
      "$schema": "scene.schema.json",
      "name": "everything",
      "object": { "kind": "mesh", "file": "meshes/part.OBJ", "size": 0.08,
                  "rotation_deg": [90, 0, 45], "thickness": 0.004, "construction": "relief" },
      "material": { "name": "steel", "emissivity": 0.07, "absorptivity": 0.4 },
      "environment": { "ambient_temperature": 293.0, "convection_coefficient": 8.0,
                       "back_boundary": "insulated" },
      "lamps": [
        { "kind": "uniform", "flux": 50, "on": 1, "off": 2 },
        { "kind": "point", "power": 60, "position": [0.1, 0.2, 0.3], "radiant_fraction": 0.8,
          "on": 0.5, "off": 10 }
      ],
      "camera": { "width": 320, "height": 256, "pixel_pitch": 1.2e-5, "hfov_deg": 30,
                  "position": [0, -0.1, 0.4], "look_at": [0, 0, 0], "up": [0, 0, 1],
                  "netd": 0.04, "fixed_pattern_sigma": 0.02, "quantization": 0,
                  "native_rate": 30, "seed": 7 },
      "timing": { "duration": 6, "time_step": 0.05, "frame_interval": 0.25,
                  "pre_heating_frames": 3 },
      "solver": { "kind": "surface", "mass": "lumped", "radiation": "linearized",
                  "newton_tolerance": 1e-8, "max_newton_iterations": 10,
                  "effective_thickness_factor": 2.0 },
      "meshing": { "surface_element_size": 0.001, "fine_layer_depth": 0.002,
                   "deep_element_size": 0.005, "radius_edge_ratio": 2.0,
                   "relief_resolution": 0.0005, "max_tetrahedra": 100000,
                   "timeout_seconds": 60 }
    }"#;
    let scene = Scene::from_json_str(text, Path::new("/data/scenes")).unwrap();
    assert_eq!(scene.schema.as_deref(), Some("scene.schema.json"));
    assert_eq!(scene.mesh_file().unwrap(), Path::new("/data/scenes/meshes/part.OBJ"));
    let material = scene.material.resolve().unwrap();
    assert_eq!((material.emissivity, material.absorptivity, material.conductivity), (0.07, 0.4, 51.9));
    assert_eq!(scene.timing.steps_per_frame(), 5);
    assert!(!scene.lamps[0].is_on(0.5) && scene.lamps[0].is_on(1.0) && !scene.lamps[0].is_on(2.0));

    let json = serde_json::to_string(&scene).unwrap();
    let back = Scene::from_json_str(&json, Path::new("/somewhere/else")).unwrap();
    assert_eq!(back, scene);
}

#[test]
fn relative_mesh_path_resolves_against_the_scene_file() {
    let dir = tempfile::tempdir().unwrap();
    let scene_path = dir.path().join("part.json");
    let object = r#"{ "kind": "mesh", "file": "part.glb", "size": 0.1, "construction": "solid" }"#;
    std::fs::write(&scene_path, minimal_with(object, "")).unwrap();
    let scene = Scene::from_file(&scene_path).unwrap();
    assert_eq!(scene.mesh_file().unwrap(), &dir.path().join("part.glb"));
    assert_eq!(scene.object.thickness(), None, "thickness is unused for solid meshes");
}

#[test]
fn explicit_material_is_accepted() {
    let text = r#"{ "object": { "kind": "hemisphere", "radius": 0.05, "thickness": 0.08 },
                    "material": { "density": 1000, "specific_heat": 4000, "conductivity": 0.6,
                                  "emissivity": 0.96, "absorptivity": 0.9 } }"#;
    let m = parse(text).unwrap().material.resolve().unwrap();
    assert_eq!(m.name, "custom");
    assert!((m.diffusivity() - 1.5e-7).abs() < 1e-20);
}

/// Bad inputs and the exact substring each error message must contain.
#[test]
fn bad_inputs_give_precise_messages() {
    let obj = |o: &str| minimal_with(o, "");
    let cuboid_with = |extra: &str| minimal_with(CUBOID, extra);
    let cases: Vec<(&str, String, &str)> = vec![
        (
            "negative thickness",
            obj(r#"{ "kind": "cuboid", "width": 0.05, "height": 0.05, "thickness": -0.01 }"#),
            "object.thickness: must be > 0 m, got -0.01",
        ),
        (
            "thickness above 10 m",
            obj(r#"{ "kind": "hemisphere", "radius": 0.05, "thickness": 12 }"#),
            "object.thickness: must be <= 10 m, got 12",
        ),
        (
            "unknown top-level field",
            cuboid_with(r#""objekt": 1"#),
            "objekt: unknown field `objekt`",
        ),
        (
            "unknown field in a plain section",
            cuboid_with(r#""camera": { "widht": 640 }"#),
            "camera.widht: unknown field `widht`",
        ),
        (
            "unknown field in the tagged object",
            obj(r#"{ "kind": "cuboid", "widht": 0.05, "height": 0.05, "thickness": 0.01 }"#),
            "object.widht: unknown field `widht`",
        ),
        (
            "unknown field in a tagged lamp",
            cuboid_with(r#""lamps": [ { "kind": "point", "powr": 1, "position": [0, 0, 1] } ]"#),
            "lamps[0].powr: unknown field `powr`",
        ),
        (
            "unknown object kind",
            obj(r#"{ "kind": "sphere", "radius": 0.05 }"#),
            r#"object.kind: unknown variant "sphere", expected one of "cuboid", "hemisphere", "mesh", "bunny""#,
        ),
        (
            "unknown lamp kind",
            cuboid_with(
                r#""lamps": [ { "kind": "uniform", "flux": 1 }, { "kind": "spot", "power": 1 } ]"#,
            ),
            r#"lamps[1].kind: unknown variant "spot", expected one of "uniform", "point""#,
        ),
        (
            "missing kind",
            obj(r#"{ "width": 0.05, "height": 0.05, "thickness": 0.01 }"#),
            "object: missing field `kind`",
        ),
        (
            "unknown enum value",
            cuboid_with(r#""solver": { "mass": "diagonal" }"#),
            "solver.mass: unknown variant `diagonal`",
        ),
        (
            "wrong type inside a tagged object",
            obj(r#"{ "kind": "cuboid", "width": "5cm", "height": 0.05, "thickness": 0.01 }"#),
            r#"object.width: invalid type: string "5cm", expected f64"#,
        ),
        (
            "wrong type in an array of a tagged lamp",
            cuboid_with(r#""lamps": [ { "kind": "point", "power": 1, "position": [0, 0, "x"] } ]"#),
            "lamps[0].position[2]: invalid type: string \"x\", expected f64",
        ),
        (
            "missing required section",
            r#"{ "material": { "name": "pla" } }"#.to_owned(),
            "missing field `object`",
        ),
        (
            "unknown material",
            cuboid_with("").replace("\"pla\"", "\"unobtainium\""),
            "material.name: unknown material \"unobtainium\"; known materials: polystyrene, eps, steel",
        ),
        (
            "number too large to be finite",
            obj(r#"{ "kind": "cuboid", "width": 0.05, "height": 0.05, "thickness": 1e999 }"#),
            "object.thickness: number out of range: must be finite",
        ),
        (
            "emissivity above 1",
            minimal_with(CUBOID, "").replace(
                r#"{ "name": "pla" }"#,
                r#"{ "name": "pla", "emissivity": 1.5 }"#,
            ),
            "material.emissivity: must be in [0, 1], got 1.5",
        ),
        (
            "lamp off before on",
            cuboid_with(r#""lamps": [ { "kind": "uniform", "flux": 100, "on": 5, "off": 5 } ]"#),
            "lamps[0].off: must be > lamps[0].on (5 s), got 5",
        ),
        (
            "negative lamp power",
            cuboid_with(r#""lamps": [ { "kind": "point", "power": -1, "position": [0, 0, 1] } ]"#),
            "lamps[0].power: must be >= 0 W, got -1",
        ),
        (
            "radiant fraction zero",
            cuboid_with(
                r#""lamps": [ { "kind": "point", "power": 1, "position": [0, 0, 1], "radiant_fraction": 0 } ]"#,
            ),
            "lamps[0].radiant_fraction: must be in (0, 1], got 0",
        ),
        (
            "frame interval not a multiple of the time step",
            cuboid_with(r#""timing": { "time_step": 0.03, "frame_interval": 0.1 }"#),
            "timing.frame_interval: must be a whole multiple of timing.time_step (0.03 s) within 1e-9 relative, got 0.1",
        ),
        (
            "frame interval below the time step",
            cuboid_with(r#""timing": { "time_step": 0.2, "frame_interval": 0.1 }"#),
            "timing.frame_interval: must be >= timing.time_step (0.2 s), got 0.1",
        ),
        (
            "frame interval above the duration",
            cuboid_with(r#""timing": { "duration": 1, "frame_interval": 2 }"#),
            "timing.frame_interval: must be <= timing.duration (1 s), got 2",
        ),
        (
            "explicit material missing conductivity",
            minimal_with(CUBOID, "").replace(
                r#"{ "name": "pla" }"#,
                r#"{ "density": 1000, "specific_heat": 1000, "emissivity": 0.9, "absorptivity": 0.9 }"#,
            ),
            "material.conductivity: required when material.name is absent",
        ),
        (
            "relief mesh without thickness",
            obj(r#"{ "kind": "mesh", "file": "x.obj", "size": 0.1 }"#),
            "object.thickness: required when object.construction is \"relief\"",
        ),
        (
            "relief bunny without thickness",
            obj(r#"{ "kind": "bunny", "size": 0.1, "construction": "relief" }"#),
            "object.thickness: required when object.construction is \"relief\"",
        ),
        (
            "mesh file of an unsupported format",
            obj(r#"{ "kind": "mesh", "file": "x.stl", "size": 0.1, "thickness": 0.01 }"#),
            "object.file: must be a .obj, .ply, .gltf or .glb file, got \"/base/x.stl\"",
        ),
        (
            "radius-edge ratio below TetGen's bound",
            cuboid_with(r#""meshing": { "radius_edge_ratio": 0.5 }"#),
            "meshing.radius_edge_ratio: must be in [1.1, 10], got 0.5",
        ),
        (
            "deep elements finer than surface elements",
            cuboid_with(r#""meshing": { "deep_element_size": 0.001 }"#),
            "meshing.deep_element_size: must be >= meshing.surface_element_size (0.002 m), got 0.001",
        ),
        (
            "ambient temperature too hot",
            cuboid_with(r#""environment": { "ambient_temperature": 3000 }"#),
            "environment.ambient_temperature: must be < 2000 K, got 3000",
        ),
        (
            "negative convection",
            cuboid_with(r#""environment": { "convection_coefficient": -1 }"#),
            "environment.convection_coefficient: must be >= 0 W/(m^2 K), got -1",
        ),
        (
            "zero image width",
            cuboid_with(r#""camera": { "width": 0 }"#),
            "camera.width: must be >= 1 pixels, got 0",
        ),
        (
            "negative image height",
            cuboid_with(r#""camera": { "height": -5 }"#),
            "camera.height: invalid value: integer `-5`, expected u32",
        ),
        (
            "field of view of 180 degrees",
            cuboid_with(r#""camera": { "hfov_deg": 180 }"#),
            "camera.hfov_deg: must be in (0, 180) deg, got 180",
        ),
        (
            "negative NETD",
            cuboid_with(r#""camera": { "netd": -0.01 }"#),
            "camera.netd: must be >= 0 K, got -0.01",
        ),
        (
            "up parallel to the optical axis",
            cuboid_with(r#""camera": { "up": [0, 0, 2] }"#),
            "camera.up: must be non-zero and not parallel to the optical axis",
        ),
        (
            "zero Newton tolerance",
            cuboid_with(r#""solver": { "newton_tolerance": 0 }"#),
            "solver.newton_tolerance: must be > 0 K, got 0",
        ),
        (
            "empty name",
            cuboid_with(r#""name": """#),
            "name: must be non-empty",
        ),
        ("empty file", String::new(), "the scene is empty"),
        ("whitespace-only file", " \n\t".to_owned(), "the scene is empty"),
        (
            "trailing characters",
            format!("{} x", minimal_with(CUBOID, "")),
            "trailing characters",
        ),
    ];
    for (what, text, expected) in &cases {
        let message = parse_err(text).to_string();
        assert!(message.contains(expected), "{what}:\n  expected substring: {expected}\n  got: {message}");
    }
}

#[test]
fn error_variants_keep_kinds_apart() {
    let invalid =
        parse_err(&minimal_with(r#"{ "kind": "cuboid", "width": 0.05, "height": 0.05, "thickness": -0.01 }"#, ""));
    match &invalid {
        SceneError::Invalid { path, json_path, message } => {
            assert!(path.is_none());
            assert_eq!(json_path, "object.thickness");
            assert_eq!(message, "must be > 0 m, got -0.01");
        }
        other => panic!("expected Invalid, got {other:?}"),
    }
    // Without a file, Invalid displays exactly as "{json_path}: {message}".
    assert_eq!(invalid.to_string(), "object.thickness: must be > 0 m, got -0.01");
    assert_eq!(invalid.json_path(), Some("object.thickness"));

    let unknown = parse_err(&minimal_with(CUBOID, "").replace("\"pla\"", "\"stel\""));
    match &unknown {
        SceneError::UnknownMaterial { name, known, .. } => {
            assert_eq!(name, "stel");
            assert!(known.iter().any(|k| k == "steel"));
            assert!(known.iter().any(|k| k.starts_with("aluminum")));
        }
        other => panic!("expected UnknownMaterial, got {other:?}"),
    }

    let parse_error = parse_err(&minimal_with(CUBOID, r#""camera": { "widht": 1 }"#));
    assert!(
        matches!(&parse_error, SceneError::Parse { json_path, line: 1, .. } if json_path == "camera.widht"),
        "{parse_error:?}"
    );

    let io = Scene::from_file(Path::new("/nonexistent/dir/scene.json")).unwrap_err();
    assert!(matches!(io, SceneError::Io { .. }), "{io:?}");
    assert!(io.to_string().contains("/nonexistent/dir/scene.json"));
}

#[test]
fn malformed_json_reports_line_and_column() {
    let text = "{\n  \"name\": \"x\",\n  \"object\": { \"kind\": \"cuboid\" \"width\": 1 }\n}";
    match parse_err(text) {
        SceneError::Parse { line, column, message, .. } => {
            assert_eq!(line, 3, "{message}");
            assert_eq!(column, 32, "{message}");
            assert!(message.contains("expected `,` or `}`"), "{message}");
        }
        other => panic!("expected Parse, got {other:?}"),
    }
    let shown = parse_err(text).to_string();
    assert!(shown.contains("(line 3, column 32)"), "{shown}");
}

#[test]
fn errors_from_files_name_the_file_and_keep_the_path_message() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("x.json");
    std::fs::write(
        &file,
        minimal_with(r#"{ "kind": "cuboid", "width": 0.05, "height": 0.05, "thickness": -0.01 }"#, ""),
    )
    .unwrap();
    let err = Scene::from_file(&file).unwrap_err();
    assert_eq!(err.to_string(), format!("{}: object.thickness: must be > 0 m, got -0.01", file.display()));

    std::fs::write(&file, "{ \"object\": [").unwrap();
    let err = Scene::from_file(&file).unwrap_err().to_string();
    assert!(err.starts_with(&format!("{}: ", file.display())), "{err}");
    assert!(err.contains("(line 1, column"), "{err}");

    std::fs::write(&file, minimal_with(CUBOID, "").replace("\"pla\"", "\"stel\"")).unwrap();
    let err = Scene::from_file(&file).unwrap_err().to_string();
    assert!(err.starts_with(&format!("{}: material.name: unknown material", file.display())), "{err}");
}

/// JSON cannot carry infinity, but a scene built or modified in code can.
#[test]
fn validate_rejects_non_finite_values_set_in_code() {
    let mut scene = load_example("hemisphere.json");
    if let LampSpec::Point(p) = &mut scene.lamp_configurations[1].lamps[0] {
        p.position[2] = f64::INFINITY;
    }
    assert_eq!(
        scene.validate().unwrap_err().to_string(),
        "lamp_configurations[1].lamps[0].position[2]: must be finite, got inf"
    );
    // Lamps may not be given both ways, and configuration names are unique.
    let mut scene = load_example("hemisphere.json");
    scene.lamps = scene.lamp_configurations[0].lamps.clone();
    assert!(scene
        .validate()
        .unwrap_err()
        .to_string()
        .starts_with("lamps: must be empty when lamp_configurations is given"));
    let mut scene = load_example("hemisphere.json");
    scene.lamp_configurations[1].name = "left".into();
    assert_eq!(
        scene.validate().unwrap_err().to_string(),
        "lamp_configurations[1].name: \"left\" is used by an earlier configuration"
    );

    let mut scene = load_example("cuboid.json");
    scene.environment.ambient_temperature = f64::NAN;
    assert_eq!(scene.validate().unwrap_err().to_string(), "environment.ambient_temperature: must be finite, got NaN");

    let mut scene = load_example("cuboid.json");
    scene.material.conductivity = Some(f64::NEG_INFINITY);
    assert_eq!(scene.validate().unwrap_err().to_string(), "material.conductivity: must be finite, got -inf");
}

#[test]
fn json_schema_describes_every_section() {
    let schema = json_schema();
    let properties = schema["properties"].as_object().expect("schema has properties");
    for key in
        ["$schema", "name", "object", "material", "environment", "lamps", "camera", "timing", "solver", "meshing"]
    {
        assert!(properties.contains_key(key), "{key} missing from the schema");
    }
    let required: Vec<&str> =
        schema["required"].as_array().expect("required list").iter().filter_map(|v| v.as_str()).collect();
    assert_eq!(required, ["object", "material"]);
    let text = serde_json::to_string(&schema).unwrap();
    // Field docs (with units) end up as descriptions, and the object kinds are listed.
    assert!(text.contains("Extent along x, in m"), "missing field docs");
    for kind in ["cuboid", "hemisphere", "mesh", "bunny", "uniform", "point"] {
        assert!(text.contains(&format!("\"{kind}\"")), "kind {kind} missing");
    }
}

/// Loading must never panic: every prefix of the example files, and every number in them
/// replaced by awkward values, gives `Ok` or `Err`.
#[test]
fn loading_never_panics_on_damaged_input() {
    let replacements = [
        "-1",
        "0",
        "-0",
        "1e308",
        "1e-320",
        "1e999",
        "18446744073709551616",
        "-1e308",
        "\"x\"",
        "null",
        "[]",
        "{}",
        "true",
    ];
    for file in ["cuboid.json", "hemisphere.json", "bunny.json"] {
        let text = std::fs::read_to_string(scenes_dir().join(file)).unwrap();
        for (end, _) in text.char_indices() {
            let _ = parse(&text[..end]);
        }
        let numbers = number_spans(&text);
        assert!(numbers.len() > 5, "{file}: too few numbers found");
        for &(start, end) in &numbers {
            for r in replacements {
                let damaged = format!("{}{}{}", &text[..start], r, &text[end..]);
                let _ = parse(&damaged);
            }
        }
    }
}

/// Byte ranges of the JSON numbers in `text` (a simple scan, good enough for our examples).
fn number_spans(text: &str) -> Vec<(usize, usize)> {
    let bytes = text.as_bytes();
    let mut spans = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        let starts_number = bytes[i] == b'-' || bytes[i].is_ascii_digit();
        let after_delim = i == 0 || matches!(bytes[i - 1], b' ' | b'[' | b':' | b',');
        if starts_number && after_delim {
            let start = i;
            while i < bytes.len() && matches!(bytes[i], b'0'..=b'9' | b'.' | b'-' | b'+' | b'e' | b'E') {
                i += 1;
            }
            spans.push((start, i));
        } else {
            i += 1;
        }
    }
    spans
}
