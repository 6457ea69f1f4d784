//! Scene files: what to simulate, as JSON (`scenes/*.json`).
//!
//! A scene names the object, its material, the room, the lamps, the camera, the timing and
//! the solver and meshing options. All quantities are SI (m, s, K, W, kg, J); angles are in
//! degrees where the field name says `_deg`. Only `object` and `material` are required; every
//! other section and field has a default, listed in the docs of each field and in the JSON
//! Schema ([`json_schema`]).
//!
//! ```json
//! {
//!   "name": "cuboid",
//!   "object": { "kind": "cuboid", "width": 0.05, "height": 0.05, "thickness": 0.01 },
//!   "material": { "name": "polystyrene" },
//!   "lamps": [ { "kind": "uniform", "flux": 100.0 } ]
//! }
//! ```
//!
//! # Frame
//! Right-handed, in metres. The camera looks at the object from +z (default position
//! [0, 0, 0.3683], the paper's working distance); the *visible surface* is the part of the
//! boundary facing +z. A cuboid's visible face is z = 0 with the material in z in [-d, 0]; a
//! hemisphere's dome rises to z = R over the base z = 0 (see [`ObjectSpec`]).
//!
//! # Time
//! t = 0 is the start of heating; `timing.pre_heating_frames` frames are recorded before it.
//! Lamp `on`/`off` times are relative to t = 0.
//!
//! # Errors
//! Loading never panics. Unknown fields are rejected everywhere, and every error carries the
//! JSON path of the value at fault: type errors and unknown fields as [`SceneError::Parse`]
//! (`lamps[1].kind: unknown variant "spot", expected one of "uniform", "point"`), values out of
//! range as [`SceneError::Invalid`] (`object.thickness: must be > 0 m, got -0.01`), unknown
//! materials as [`SceneError::UnknownMaterial`].

pub mod camera;
mod error;
pub mod lamp;
pub mod material;
pub mod object;
pub mod options;
pub(crate) mod parse;
pub(crate) mod validate;

use std::path::{Path, PathBuf};

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

pub use camera::{CameraSpec, PsfSpec, MAX_IMAGE_SIDE};
pub use error::SceneError;
pub use lamp::{LampConfiguration, LampSpec, PointLamp, UniformLamp, DEFAULT_RADIANT_FRACTION};
pub use material::{lookup_material, material_library, Material, MaterialSpec, PAINTED_BLACK};
pub use object::{
    BunnySpec, Construction, CuboidSpec, HemisphereSpec, MeshSpec, ObjectSpec, BUNNY_DEFAULT_ROTATION_DEG,
    MAX_OBJECT_SIZE, MAX_THICKNESS, MESH_EXTENSIONS,
};
pub use options::{
    AreaMassKind, BackBoundary, Environment, LinearSolverKind, MassMatrix, MeshingOptions, RadiationModel, SolverKind,
    SolverOptions, SurfaceFlux, SurfaceMesh, TimeIntegration, Timing, FRAME_MULTIPLE_TOLERANCE,
};

fn default_name() -> String {
    "scene".to_owned()
}

/// A complete scene, as read from a scene file.
///
/// Build it with [`Scene::from_file`] or [`Scene::from_json_str`], which parse and
/// [`validate`](Scene::validate); a `Scene` assembled or modified in code should be validated
/// again before use.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// URI of the JSON Schema for editors; ignored by the simulator (optional).
    #[serde(rename = "$schema", default, skip_serializing_if = "Option::is_none")]
    pub schema: Option<String>,
    /// Name of the scene, used to label results (default "scene"; non-empty, no `/`, `\` or
    /// control characters).
    #[serde(default = "default_name")]
    pub name: String,
    /// The heated object (required).
    pub object: ObjectSpec,
    /// Its material: a library name, optionally with overrides, or five explicit numbers
    /// (required).
    pub material: MaterialSpec,
    /// Ambient temperature, convection and back boundary (default: see [`Environment`]).
    #[serde(default)]
    pub environment: Environment,
    /// Heat sources (default: none).
    #[serde(default)]
    pub lamps: Vec<LampSpec>,
    /// Several named lamp configurations of the same object, one dataset each (default: none,
    /// i.e. one dataset lit by `lamps`). When given, `lamps` must be empty.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lamp_configurations: Vec<LampConfiguration>,
    /// The thermal camera (default: FLIR Boson 640 with the paper's lens, see [`CameraSpec`]).
    #[serde(default)]
    pub camera: CameraSpec,
    /// Time step, frame interval, duration (default: see [`Timing`]).
    #[serde(default)]
    pub timing: Timing,
    /// Heat-solver options (default: see [`SolverOptions`]).
    #[serde(default)]
    pub solver: SolverOptions,
    /// Tetrahedral meshing controls (default: see [`MeshingOptions`]).
    #[serde(default)]
    pub meshing: MeshingOptions,
}

impl Scene {
    /// Reads, parses and validates a scene file. A relative `object.file` is resolved against
    /// the directory of `path`.
    ///
    /// # Errors
    /// [`SceneError::Io`] if the file cannot be read (or is not UTF-8); otherwise as
    /// [`Scene::from_json_str`], with the file named in the error.
    pub fn from_file(path: &Path) -> Result<Scene, SceneError> {
        let text =
            std::fs::read_to_string(path).map_err(|source| SceneError::Io { path: path.to_path_buf(), source })?;
        let base_dir = path.parent().unwrap_or(Path::new(""));
        Self::from_json_str(&text, base_dir).map_err(|e| e.with_file(path))
    }

    /// Parses and validates a scene from JSON text. A relative `object.file` is resolved
    /// against `base_dir` and stored resolved.
    ///
    /// # Errors
    /// [`SceneError::Parse`] for malformed JSON, wrong types, unknown or missing fields;
    /// [`SceneError::Invalid`] or [`SceneError::UnknownMaterial`] from
    /// [`validate`](Scene::validate).
    pub fn from_json_str(text: &str, base_dir: &Path) -> Result<Scene, SceneError> {
        let mut scene: Scene = parse::parse_document(text, None)?;
        scene.resolve_paths(base_dir);
        scene.validate()?;
        Ok(scene)
    }

    /// Joins a relative mesh path to `base_dir`.
    fn resolve_paths(&mut self, base_dir: &Path) {
        if let ObjectSpec::Mesh(mesh) = &mut self.object {
            if mesh.file.is_relative() {
                mesh.file = base_dir.join(&mesh.file);
            }
        }
    }

    /// The mesh file of a `mesh` object (resolved when loaded from a file), else `None`.
    pub fn mesh_file(&self) -> Option<&PathBuf> {
        match &self.object {
            ObjectSpec::Mesh(mesh) => Some(&mesh.file),
            _ => None,
        }
    }

    /// Checks every number of every section: finite, in range, and consistent
    /// (`time_step <= frame_interval <= duration`, lamp `off > on`, ...); resolves the
    /// material. Stops at the first problem, in file order.
    ///
    /// # Errors
    /// [`SceneError::Invalid`] with the JSON path and a message of the form
    /// `"must be > 0 m, got -0.01"`, or [`SceneError::UnknownMaterial`].
    pub fn validate(&self) -> Result<(), SceneError> {
        if self.name.is_empty() || self.name.chars().any(|c| c == '/' || c == '\\' || c.is_control()) {
            return Err(SceneError::invalid(
                "name",
                format!("must be non-empty, without '/', '\\' or control characters, got {:?}", self.name),
            ));
        }
        self.object.validate()?;
        self.material.resolve()?;
        self.environment.validate()?;
        for (i, lamp) in self.lamps.iter().enumerate() {
            lamp.validate(i)?;
        }
        if !self.lamp_configurations.is_empty() && !self.lamps.is_empty() {
            return Err(SceneError::invalid(
                "lamps",
                "must be empty when lamp_configurations is given (each configuration lists its own lamps)".to_string(),
            ));
        }
        let mut names = std::collections::BTreeSet::new();
        for (i, config) in self.lamp_configurations.iter().enumerate() {
            let ok = !config.name.is_empty()
                && config.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
            if !ok {
                return Err(SceneError::invalid(
                    &format!("lamp_configurations[{i}].name"),
                    format!("must be non-empty letters, digits, '-' or '_', got {:?}", config.name),
                ));
            }
            if !names.insert(config.name.as_str()) {
                return Err(SceneError::invalid(
                    &format!("lamp_configurations[{i}].name"),
                    format!("{:?} is used by an earlier configuration", config.name),
                ));
            }
            for (j, lamp) in config.lamps.iter().enumerate() {
                lamp.validate_at(&format!("lamp_configurations[{i}].lamps[{j}]"))?;
            }
        }
        self.camera.validate()?;
        self.timing.validate()?;
        self.solver.validate()?;
        let camera_grid =
            self.solver.kind == SolverKind::Surface && self.solver.surface_mesh == SurfaceMesh::CameraGrid;
        if camera_grid && !self.camera.point_sampling() {
            // The camera-grid surface solver knows temperatures at pixel centres only.
            return Err(SceneError::invalid(
                if self.camera.supersampling != 1 { "camera.supersampling" } else { "camera.psf" },
                "must be point sampling (supersampling 1, psf none) with solver.surface_mesh = \"camera_grid\", \
                 which knows temperatures at pixel centres only"
                    .to_string(),
            ));
        }
        self.meshing.validate()
    }
}

impl Scene {
    /// The lamp configurations to film: the named ones, or a single unnamed one lit by
    /// `lamps`.
    pub fn lamp_sets(&self) -> Vec<(Option<String>, Vec<LampSpec>)> {
        if self.lamp_configurations.is_empty() {
            vec![(None, self.lamps.clone())]
        } else {
            self.lamp_configurations.iter().map(|c| (Some(c.name.clone()), c.lamps.clone())).collect()
        }
    }
}

/// The JSON Schema (draft 2020-12, generated by `schemars`) of a scene file, with every
/// field's documentation (unit, default, range) as its `description`.
pub fn json_schema() -> serde_json::Value {
    schemars::schema_for!(Scene).to_value()
}
