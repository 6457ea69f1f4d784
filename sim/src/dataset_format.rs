//! The JSON files of a dataset directory, typed once: `camera.json`, `lamps.json`,
//! `environment.json`, `material.json` and `meta.json` (SI units throughout: m, s, K, W, J).
//!
//! `simbench simulate` builds a [`DatasetJson`] and writes it with [`DatasetJson::write_into`];
//! the reconstruction reads the files with [`read_camera`], [`read_lamps`],
//! [`read_environment`], [`read_material`] and [`read_meta`]. [`json_schema`] is their JSON
//! Schema (`simbench schema dataset`). The arrays beside them (`video.npy`, `mask.npy`, ...)
//! are described in [`DATA_FILES`] and in `meta.json`'s `files`.
//!
//! # Bytes on disk
//! Every file is pretty-printed JSON (two-space indent) with a trailing newline.
//! `camera.json`, `environment.json` and `meta.json` have their keys sorted at every depth;
//! `lamps.json` and `material.json` keep the field order of [`LampSpec`] and [`Material`]
//! ([`DatasetFile::SORTED_KEYS`]). These are the bytes simbench wrote before the files were
//! typed (the first three were built as `serde_json::Value`, whose maps are sorted), kept so
//! that a dataset stays reproducible byte for byte. Numbers are written in the shortest form
//! that reads back exactly; the workspace's `serde_json` (without its `float_roundtrip`
//! feature) may read a 17-digit number 1 ulp off, so a file read and written again has the
//! same keys and values to that precision, not always the same bytes.
//!
//! # Strictness
//! Unknown fields are refused in every file: the writer controls them, and a typo such as
//! `frame_interval` for `frame_interval_s` must not pass unnoticed. The one exception is
//! `meta.json`'s `mesh`, where serde cannot refuse unknown fields beside a flattened struct.
//! Values are range-checked after parsing. A dataset converted from a real camera's
//! recording needs only what was measured: `camera.json`'s `K`, `R`, `t`, `width`, `height`,
//! `frame_interval_s`, and `environment.json`'s `ambient_temperature` (with `emissivity`, or
//! the reconstruction's `--emissivity`); the simulator's sensor settings and ground truth are
//! optional there.
//!
//! # `lamps.json` layouts
//! Written: a bare array of lamps, `[{"kind": "point", ...}, ...]` ([`LampSpec`]), the only
//! layout `simbench simulate` has written since datasets exist. Readers used to accept an
//! object `{"lamps": [...]}` too (the shape of a scene file's section); such a file still
//! loads, with a warning ([`LampsFile::warnings`]). Anything else is refused with
//! [`DatasetFormatError::Layout`]: a lamp object on its own, an object with keys besides
//! `lamps`, an array holding a `{"lamps": ...}` object (the two layouts mixed), a number, a
//! string, `true` or `null`.
//!
//! # Errors
//! Every reader error names the file; parse errors and range errors also give the JSON path
//! of the value at fault (`[0].power`, `K[1][1]`, `scene.object.kind`), parse errors the line
//! and column where known.

use std::collections::BTreeMap;
use std::io;
use std::path::{Path, PathBuf};

use schemars::JsonSchema;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::camera::Camera;
use crate::dataset::Dataset;
use crate::io::OutputDir;
use crate::meshing::MeshReport;
use crate::scene::camera::MAX_SUPERSAMPLING;
use crate::scene::parse::{parse_str_tracked, parse_value_tracked, JsonFailure};
use crate::scene::validate::{int_in, num};
use crate::scene::{
    BackBoundary, CameraSpec, Environment, LampSpec, Material, PsfSpec, Scene, SceneError, MAX_IMAGE_SIDE,
};
use crate::simulate::SimulationReport;

/// File name of the camera ([`CameraFile`]).
pub const CAMERA_FILE: &str = "camera.json";
/// File name of the lamps ([`LampsFile`]).
pub const LAMPS_FILE: &str = "lamps.json";
/// File name of the room and the object's emissivity ([`EnvironmentFile`]).
pub const ENVIRONMENT_FILE: &str = "environment.json";
/// File name of the material ([`Material`]).
pub const MATERIAL_FILE: &str = "material.json";
/// File name of the provenance and reports ([`MetaFile`]).
pub const META_FILE: &str = "meta.json";

/// The camera conventions in words, written as `camera.json`'s `convention`.
pub const CAMERA_CONVENTION: &str = "OpenCV pinhole: x_c = R x_w + t; camera x right, y down, z forward; pixel (u, v) = (fx x_c/z_c + cx, fy y_c/z_c + cy), pixel centres at integers";

/// `meta.json`'s `units`.
pub const UNITS: &str = "SI: metres, seconds, kelvin, watts, joules";

/// The array files of a dataset with their dtype, shape and unit (`meta.json`'s `files`).
pub const DATA_FILES: &[(&str, &str)] = &[
    ("node_temperatures.npy", "float64 [frames, nodes], K (surface solver: its mesh's vertices)"),
    ("visible_temperatures.npy", "float64 [frames, visible vertices], K (vertices of visible.obj)"),
    ("times.npy", "float64 [frames], s; lamps switch on at 0"),
    ("visible_nodes.npy", "uint64 [visible vertices], node index of each visible.obj vertex"),
    ("temperature.pvd", "ParaView time series of a subset of frames"),
    ("video.npy", "float32 [frames, H, W], apparent temperature as the camera reports it, K"),
    ("video_clean.npy", "float64 [frames, H, W], apparent temperature without noise, K"),
    ("mask.npy", "bool [H, W], pixels that see the object"),
    ("gt_depth.npy", "float32 [H, W], depth z_c along the optical axis, m (NaN off the object)"),
    ("gt_normals.npy", "float32 [H, W, 3], world-frame unit normals (NaN off the object)"),
    ("gt_flux.npy", "float32 [H, W], absorbed flux with every lamp on, W/m^2"),
    ("gt_mesh.obj", "visible surface, world frame, m"),
];

/// Errors while reading a dataset's JSON files; each names the file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DatasetFormatError {
    /// The file could not be read (missing, unreadable, not UTF-8).
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error (`ErrorKind::NotFound` for a missing file).
        source: io::Error,
    },
    /// Not JSON, or a value of the wrong type, or an unknown or missing field.
    #[error("{}: {}", path.display(), parse_detail(json_path, message, *line, *column))]
    Parse {
        /// The file.
        path: PathBuf,
        /// JSON path of the value at fault (`K[2]`, `[0].power`); empty for the document.
        json_path: String,
        /// What is wrong, without the location.
        message: String,
        /// 1-based line in the file, 0 if unknown.
        line: usize,
        /// 1-based column in the file, 0 if unknown.
        column: usize,
    },
    /// The document has the wrong overall shape (`lamps.json` in no known layout).
    #[error("{}: {message}", path.display())]
    Layout {
        /// The file.
        path: PathBuf,
        /// What was found and what is expected.
        message: String,
    },
    /// A value parsed but is out of range: `"must be > 0 s, got 0"`.
    #[error("{}: {json_path}: {message}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// JSON path of the value (`frame_interval_s`, `[1].power`).
        json_path: String,
        /// The rule with its unit and the value found.
        message: String,
    },
}

impl DatasetFormatError {
    /// The file the error is about.
    pub fn path(&self) -> &Path {
        match self {
            DatasetFormatError::Io { path, .. }
            | DatasetFormatError::Parse { path, .. }
            | DatasetFormatError::Layout { path, .. }
            | DatasetFormatError::Invalid { path, .. } => path,
        }
    }

    /// The error without the file name in front (the text after `"{file}: "`).
    pub fn detail(&self) -> String {
        match self {
            DatasetFormatError::Io { source, .. } => source.to_string(),
            DatasetFormatError::Parse { json_path, message, line, column, .. } => {
                parse_detail(json_path, message, *line, *column)
            }
            DatasetFormatError::Layout { message, .. } => message.clone(),
            DatasetFormatError::Invalid { json_path, message, .. } => format!("{json_path}: {message}"),
        }
    }

    /// Whether the file is missing.
    pub fn is_not_found(&self) -> bool {
        matches!(self, DatasetFormatError::Io { source, .. } if source.kind() == io::ErrorKind::NotFound)
    }

    fn parse(path: &Path, f: JsonFailure) -> DatasetFormatError {
        DatasetFormatError::Parse {
            path: path.to_path_buf(),
            // In text that is not JSON, the line and column say where; a path would be a guess.
            json_path: if f.syntax { String::new() } else { f.json_path },
            message: f.message,
            line: f.line,
            column: f.column,
        }
    }

    fn layout(path: &Path, message: impl Into<String>) -> DatasetFormatError {
        DatasetFormatError::Layout { path: path.to_path_buf(), message: message.into() }
    }

    /// A range error of [`DatasetFile::check`] (a [`SceneError::Invalid`]) for `path`.
    fn invalid(path: &Path, e: SceneError) -> DatasetFormatError {
        let (json_path, message) = match e {
            SceneError::Invalid { json_path, message, .. } => (json_path, message),
            other => (other.json_path().unwrap_or_default().to_owned(), other.to_string()),
        };
        DatasetFormatError::Invalid { path: path.to_path_buf(), json_path, message }
    }
}

/// `"{json_path}: {message} (line {line}, column {column})"`, leaving out what is unknown.
fn parse_detail(json_path: &str, message: &str, line: usize, column: usize) -> String {
    let mut out = String::new();
    if !json_path.is_empty() {
        out.push_str(json_path);
        out.push_str(": ");
    }
    out.push_str(message);
    if line > 0 {
        out.push_str(&format!(" (line {line}, column {column})"));
    }
    out
}

/// One JSON file of a dataset directory, read with [`read_file`] and written with
/// [`to_json_text`]. `lamps.json` is not one: it has two layouts ([`read_lamps`]).
pub trait DatasetFile: Serialize + DeserializeOwned {
    /// Its name in the dataset directory.
    const NAME: &'static str;
    /// Keys sorted at every depth (`true`) or in field order (module doc, "Bytes on disk").
    const SORTED_KEYS: bool;
    /// Range checks after parsing; JSON paths relative to the file.
    ///
    /// # Errors
    /// [`SceneError::Invalid`] for the first value out of range.
    fn check(&self) -> Result<(), SceneError> {
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// camera.json

/// `camera.json`: the pinhole camera (OpenCV conventions, see [`Camera`]) and, for a
/// simulated dataset, the sensor settings it was rendered with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CameraFile {
    /// Intrinsic matrix K (3 x 3, row-major), in pixels: `[[fx, s, cx], [0, fy, cy], [0, 0,
    /// 1]]`, fx and fy > 0; pixel centres at integer (u, v).
    #[serde(rename = "K")]
    pub k: [[f64; 3]; 3],
    /// Rotation world -> camera (3 x 3, row-major, dimensionless); its rows are the camera's
    /// x (right), y (down) and z (forward) axes in world coordinates.
    #[serde(rename = "R")]
    pub r: [[f64; 3]; 3],
    /// Translation world -> camera, in m: x_c = R x_w + t.
    pub t: [f64; 3],
    /// Image width W, in pixels (1 to 16384).
    pub width: u32,
    /// Image height H, in pixels (1 to 16384).
    pub height: u32,
    /// Time between frames, in s (> 0).
    pub frame_interval_s: f64,
    /// The conventions in words ([`CAMERA_CONVENTION`]); optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub convention: Option<String>,
    /// Pixel pitch on the detector, in m (> 0); simulated datasets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixel_pitch_m: Option<f64>,
    /// Horizontal field of view, in degrees (in (0, 180)); simulated datasets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hfov_deg: Option<f64>,
    /// Temporal noise, 1 sigma per pixel and frame, in K (>= 0); simulated datasets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub netd_k: Option<f64>,
    /// Fixed-pattern (per-pixel offset) noise, 1 sigma, in K (>= 0); simulated datasets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fixed_pattern_sigma_k: Option<f64>,
    /// Quantisation step of the reported temperatures, in K (>= 0; 0: none); simulated
    /// datasets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quantization_k: Option<f64>,
    /// Seed of the noise generator; simulated datasets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Sub-samples per pixel and axis the video integrates (1 to 16); written only for a
    /// simulated dataset with optics (absent: point sampling at pixel centres).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supersampling: Option<u32>,
    /// The lens's point spread function the video was blurred with (`{"kind": "gaussian",
    /// "sigma": m on the detector}`); written only for a simulated dataset with optics
    /// (absent: none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub psf: Option<PsfSpec>,
}

impl CameraFile {
    /// The file of a simulated dataset: `camera` as rendered, the sensor settings of `spec`
    /// (the scene's camera) and the frame interval `frame_interval_s` (s).
    pub fn new(camera: &Camera, spec: &CameraSpec, frame_interval_s: f64) -> CameraFile {
        CameraFile {
            k: camera.k,
            r: camera.r,
            t: camera.t,
            width: camera.width,
            height: camera.height,
            frame_interval_s,
            convention: Some(CAMERA_CONVENTION.to_owned()),
            pixel_pitch_m: Some(spec.pixel_pitch),
            hfov_deg: Some(spec.hfov_deg),
            netd_k: Some(spec.netd),
            fixed_pattern_sigma_k: Some(spec.fixed_pattern_sigma),
            quantization_k: Some(spec.quantization),
            seed: Some(spec.seed),
            // Point sampling writes neither, so such files keep the bytes they had before the
            // optics existed.
            supersampling: (!spec.point_sampling()).then_some(spec.supersampling),
            psf: (!spec.point_sampling()).then(|| spec.psf.clone()),
        }
    }
}

impl DatasetFile for CameraFile {
    const NAME: &'static str = CAMERA_FILE;
    const SORTED_KEYS: bool = true;

    fn check(&self) -> Result<(), SceneError> {
        let max = u64::from(MAX_IMAGE_SIDE);
        int_in("width", self.width.into(), 1, max, "pixels")?;
        int_in("height", self.height.into(), 1, max, "pixels")?;
        num("frame_interval_s", self.frame_interval_s, "s")?.gt(0.0)?;
        num("K[0][0]", self.k[0][0], "pixels")?.gt(0.0)?;
        num("K[1][1]", self.k[1][1], "pixels")?.gt(0.0)?;
        if let Some(p) = self.pixel_pitch_m {
            num("pixel_pitch_m", p, "m")?.gt(0.0)?;
        }
        if let Some(h) = self.hfov_deg {
            num("hfov_deg", h, "deg")?.within(0.0, false, 180.0, false)?;
        }
        for (field, value) in [
            ("netd_k", self.netd_k),
            ("fixed_pattern_sigma_k", self.fixed_pattern_sigma_k),
            ("quantization_k", self.quantization_k),
        ] {
            if let Some(v) = value {
                num(field, v, "K")?.ge(0.0)?;
            }
        }
        if let Some(s) = self.supersampling {
            int_in("supersampling", s.into(), 1, MAX_SUPERSAMPLING.into(), "")?;
        }
        if let Some(psf) = &self.psf {
            psf.validate_at("psf", self.pixel_pitch_m.unwrap_or(f64::INFINITY))?;
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// environment.json

/// `environment.json`: the room as a user would measure it, with the object's emissivity
/// (the reconstruction reads both, and must not read `convection_coefficient`, which is ground
/// truth).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct EnvironmentFile {
    /// Air and surroundings temperature T_s, also the object's initial temperature, in K
    /// (> 0).
    pub ambient_temperature: f64,
    /// Free-convection coefficient h, in W/(m² K) (>= 0); ground truth of simulated datasets,
    /// optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub convection_coefficient: Option<f64>,
    /// The simulation's back boundary, `"exposed"` or `"insulated"`; simulated datasets,
    /// optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub back_boundary: Option<BackBoundary>,
    /// Long-wave (8–14 µm) emissivity of the object's surface, dimensionless in [0, 1] (a
    /// copy of `material.json`'s); optional: the reconstruction can be given it instead.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub emissivity: Option<f64>,
}

impl EnvironmentFile {
    /// The file of a simulated dataset: the scene's `environment` and the material's
    /// `emissivity`.
    pub fn new(environment: &Environment, emissivity: f64) -> EnvironmentFile {
        EnvironmentFile {
            ambient_temperature: environment.ambient_temperature,
            convection_coefficient: Some(environment.convection_coefficient),
            back_boundary: Some(environment.back_boundary),
            emissivity: Some(emissivity),
        }
    }
}

impl DatasetFile for EnvironmentFile {
    const NAME: &'static str = ENVIRONMENT_FILE;
    const SORTED_KEYS: bool = true;

    fn check(&self) -> Result<(), SceneError> {
        num("ambient_temperature", self.ambient_temperature, "K")?.gt(0.0)?;
        if let Some(h) = self.convection_coefficient {
            num("convection_coefficient", h, "W/(m^2 K)")?.ge(0.0)?;
        }
        if let Some(e) = self.emissivity {
            num("emissivity", e, "")?.within(0.0, true, 1.0, true)?;
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// material.json

/// `material.json` is the resolved [`Material`] of the scene (ground truth: density,
/// specific heat, conductivity, emissivity, absorptivity, name and source).
impl DatasetFile for Material {
    const NAME: &'static str = MATERIAL_FILE;
    const SORTED_KEYS: bool = false;

    fn check(&self) -> Result<(), SceneError> {
        // Material::validate names the fields `material.<field>`; in this file they are
        // top-level.
        self.validate("material").map_err(|e| match e {
            SceneError::Invalid { path, json_path, message } => SceneError::Invalid {
                path,
                json_path: json_path.strip_prefix("material.").map(str::to_owned).unwrap_or(json_path),
                message,
            },
            other => other,
        })
    }
}

// ---------------------------------------------------------------------------------------------
// meta.json

/// `meta.json`'s `render`: the camera rendering's timings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RenderReport {
    /// Time to rasterise the surface once, in s.
    pub rasterize_s: f64,
    /// Time to make every frame after that (gather and sensor), in s.
    pub frames_s: f64,
    /// Frames made per second, in 1/s; `null` when `frames_s` was too short to measure.
    pub frames_per_second: Option<f64>,
    /// Pixels that see the object.
    pub covered_pixels: usize,
    /// Sub-samples on the object of the optics' supersampled rasterisation (`camera.json`'s
    /// `supersampling`, `psf`); absent for point sampling.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub object_sub_samples: Option<usize>,
}

impl RenderReport {
    /// The report of a rendered dataset.
    pub fn of(data: &Dataset) -> RenderReport {
        let per_second = data.times.len() as f64 / data.frames_seconds;
        RenderReport {
            rasterize_s: data.rasterize_seconds,
            frames_s: data.frames_seconds,
            // JSON has no infinity: a zero time was written as null before this was typed.
            frames_per_second: per_second.is_finite().then_some(per_second),
            covered_pixels: data.mask.iter().filter(|m| **m).count(),
            object_sub_samples: (data.object_sub_samples > 0).then_some(data.object_sub_samples),
        }
    }
}

/// `meta.json`: where the dataset comes from and how it was made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MetaFile {
    /// The program that wrote the dataset and its version, e.g. `"simbench 0.1.0"`.
    pub software: String,
    /// The scene as simulated, after the command line's overrides; of a scene with
    /// `lamp_configurations`, this dataset's lamps in `lamps` and no configurations.
    pub scene: Scene,
    /// Meshing statistics and timings.
    pub mesh: MeshReport,
    /// Solver statistics, timings and energy balance.
    pub simulation: SimulationReport,
    /// Rendering timings.
    pub render: RenderReport,
    /// The units of every file ([`UNITS`]).
    pub units: String,
    /// Each array file of the dataset: dtype, shape and unit ([`DATA_FILES`]).
    pub files: BTreeMap<String, String>,
}

impl MetaFile {
    /// The file of a simulated dataset, with [`UNITS`] and [`DATA_FILES`].
    pub fn new(
        software: String,
        scene: Scene,
        mesh: MeshReport,
        simulation: SimulationReport,
        render: RenderReport,
    ) -> MetaFile {
        let files = DATA_FILES.iter().map(|(name, what)| (name.to_string(), what.to_string())).collect();
        MetaFile { software, scene, mesh, simulation, render, units: UNITS.to_owned(), files }
    }
}

impl DatasetFile for MetaFile {
    const NAME: &'static str = META_FILE;
    const SORTED_KEYS: bool = true;
}

// ---------------------------------------------------------------------------------------------
// lamps.json

/// The layout a `lamps.json` was read in (module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LampsLayout {
    /// A bare array of lamps: the layout written.
    Array,
    /// The legacy object `{"lamps": [...]}`: still read, with a warning.
    LegacyObject,
}

/// `lamps.json` as read: the lamps, and what the caller should tell the user.
#[derive(Debug, Clone, PartialEq)]
pub struct LampsFile {
    /// The lamps in file order (world frame, SI units; see [`LampSpec`]).
    pub lamps: Vec<LampSpec>,
    /// The layout the file was in.
    pub layout: LampsLayout,
    /// Warnings for the user, each starting with the file's path; show them as
    /// `eprintln!("warning: {w}")`.
    pub warnings: Vec<String>,
}

/// `"a number"`, `"a string"`, ... for layout errors.
fn json_kind(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

/// Whether `v` looks like the legacy `{"lamps": ...}` wrapper rather than a lamp.
fn is_lamps_wrapper(v: &Value) -> bool {
    matches!(v, Value::Object(m) if m.contains_key("lamps") && !m.contains_key("kind"))
}

/// Parses the text of a `lamps.json` (`path` names it in errors and warnings).
///
/// # Errors
/// [`DatasetFormatError::Parse`] for bad JSON or a bad lamp (JSON path `[i].field`, or
/// `lamps[i].field` in the legacy layout), [`DatasetFormatError::Layout`] for a layout other
/// than the two known, [`DatasetFormatError::Invalid`] for a value out of range.
pub fn parse_lamps(text: &str, path: &Path) -> Result<LampsFile, DatasetFormatError> {
    let value: Value = parse_str_tracked(text).map_err(|f| DatasetFormatError::parse(path, f))?;
    let (items, prefix, layout) = match value {
        Value::Array(items) => (items, "", LampsLayout::Array),
        Value::Object(mut map) => match map.remove("lamps") {
            None => {
                let what = if map.contains_key("kind") {
                    "a single lamp object".to_owned()
                } else if map.is_empty() {
                    "an empty object".to_owned()
                } else {
                    let keys: Vec<String> = map.keys().map(|k| format!("`{k}`")).collect();
                    format!("an object with keys {}", keys.join(", "))
                };
                return Err(DatasetFormatError::layout(
                    path,
                    format!("unknown layout: {what}; expected an array of lamps [{{\"kind\": ...}}, ...]"),
                ));
            }
            Some(_) if !map.is_empty() => {
                let extra: Vec<String> = map.keys().map(|k| format!("`{k}`")).collect();
                return Err(DatasetFormatError::layout(
                    path,
                    format!(
                        "unknown layout: the legacy object {{\"lamps\": [...]}} with other keys ({}); \
                         expected an array of lamps",
                        extra.join(", ")
                    ),
                ));
            }
            Some(Value::Array(items)) => (items, "lamps", LampsLayout::LegacyObject),
            Some(other) => {
                return Err(DatasetFormatError::layout(
                    path,
                    format!("unknown layout: `lamps` is {}; expected an array of lamps", json_kind(&other)),
                ))
            }
        },
        other => {
            return Err(DatasetFormatError::layout(
                path,
                format!("unknown layout: {}; expected an array of lamps [{{\"kind\": ...}}, ...]", json_kind(&other)),
            ))
        }
    };
    if let Some(i) = items.iter().position(is_lamps_wrapper) {
        return Err(DatasetFormatError::layout(
            path,
            format!(
                "mixed layout: {prefix}[{i}] is a {{\"lamps\": ...}} object inside the array of lamps; \
                 expected an array of lamps only"
            ),
        ));
    }
    let lamps: Vec<LampSpec> =
        parse_value_tracked(Value::Array(items), prefix).map_err(|f| DatasetFormatError::parse(path, f))?;
    for (i, lamp) in lamps.iter().enumerate() {
        lamp.validate_at(&format!("{prefix}[{i}]")).map_err(|e| DatasetFormatError::invalid(path, e))?;
    }
    let warnings = match layout {
        LampsLayout::Array => Vec::new(),
        LampsLayout::LegacyObject => vec![format!(
            "{}: legacy layout {{\"lamps\": [...]}} read; datasets now hold a bare array of lamps [...] \
             (rewrite the file as the value of its `lamps`)",
            path.display()
        )],
    };
    Ok(LampsFile { lamps, layout, warnings })
}

// ---------------------------------------------------------------------------------------------
// Reading and writing

fn read_text(path: &Path) -> Result<String, DatasetFormatError> {
    std::fs::read_to_string(path).map_err(|source| DatasetFormatError::Io { path: path.to_path_buf(), source })
}

/// Reads and checks one JSON file of a dataset from `path` (any file name).
///
/// # Errors
/// [`DatasetFormatError::Io`] (missing or unreadable), [`DatasetFormatError::Parse`] (bad JSON,
/// wrong type, unknown or missing field) or [`DatasetFormatError::Invalid`] (out of range).
pub fn read_file<F: DatasetFile>(path: &Path) -> Result<F, DatasetFormatError> {
    let text = read_text(path)?;
    let file: F = parse_str_tracked(&text).map_err(|f| DatasetFormatError::parse(path, f))?;
    file.check().map_err(|e| DatasetFormatError::invalid(path, e))?;
    Ok(file)
}

/// Reads `camera.json` of the dataset in `dir`.
///
/// # Errors
/// As [`read_file`].
pub fn read_camera(dir: &Path) -> Result<CameraFile, DatasetFormatError> {
    read_file(&dir.join(CAMERA_FILE))
}

/// Reads `environment.json` of the dataset in `dir`.
///
/// # Errors
/// As [`read_file`].
pub fn read_environment(dir: &Path) -> Result<EnvironmentFile, DatasetFormatError> {
    read_file(&dir.join(ENVIRONMENT_FILE))
}

/// Reads `material.json` of the dataset in `dir`.
///
/// # Errors
/// As [`read_file`].
pub fn read_material(dir: &Path) -> Result<Material, DatasetFormatError> {
    read_file(&dir.join(MATERIAL_FILE))
}

/// Reads `meta.json` of the dataset in `dir`.
///
/// # Errors
/// As [`read_file`].
pub fn read_meta(dir: &Path) -> Result<MetaFile, DatasetFormatError> {
    read_file(&dir.join(META_FILE))
}

/// Reads `lamps.json` of the dataset in `dir`, in either layout (module doc); a legacy layout
/// comes back with a warning in [`LampsFile::warnings`].
///
/// # Errors
/// [`DatasetFormatError::Io`] for a missing or unreadable file, otherwise as [`parse_lamps`].
pub fn read_lamps(dir: &Path) -> Result<LampsFile, DatasetFormatError> {
    let path = dir.join(LAMPS_FILE);
    parse_lamps(&read_text(&path)?, &path)
}

/// Pretty-printed JSON with a trailing newline, keys sorted at every depth when `sorted`.
fn pretty<T: Serialize>(value: &T, sorted: bool) -> String {
    let text = if sorted {
        // serde_json's maps are BTreeMaps (no `preserve_order` feature): a `Value` sorts keys.
        serde_json::to_value(value).and_then(|v| serde_json::to_string_pretty(&v))
    } else {
        serde_json::to_string_pretty(value)
    };
    // Only maps with non-string keys fail to serialise; the dataset files have none.
    text.expect("dataset files serialise to JSON (a failure is a bug)") + "\n"
}

/// The text of a dataset file as written (module doc, "Bytes on disk").
pub fn to_json_text<F: DatasetFile>(file: &F) -> String {
    pretty(file, F::SORTED_KEYS)
}

/// The text of `lamps.json` as written: a bare array.
pub fn lamps_json_text(lamps: &[LampSpec]) -> String {
    pretty(&lamps, false)
}

/// The five JSON files of a dataset. Its JSON Schema ([`json_schema`]) is an object keyed by
/// file name; no such object is ever written.
#[derive(Debug, Clone, PartialEq, JsonSchema)]
#[schemars(
    title = "simbench dataset",
    description = "The JSON files of a dataset directory written by `simbench simulate`, keyed by file name \
                   (SI units: m, s, K, W, J). Each is pretty-printed JSON; the arrays beside them are described \
                   in meta.json's `files`."
)]
pub struct DatasetJson {
    /// `camera.json`: the pinhole camera and the sensor settings.
    #[schemars(rename = "camera.json")]
    pub camera: CameraFile,
    /// `lamps.json`: a bare array of the lamps that lit the video (world frame). Readers also
    /// accept the legacy object `{"lamps": [...]}`, with a warning.
    #[schemars(rename = "lamps.json")]
    pub lamps: Vec<LampSpec>,
    /// `environment.json`: ambient temperature, convection (ground truth), back boundary and
    /// the object's emissivity.
    #[schemars(rename = "environment.json")]
    pub environment: EnvironmentFile,
    /// `material.json`: the resolved material (ground truth).
    #[schemars(rename = "material.json")]
    pub material: Material,
    /// `meta.json`: software, the scene as simulated, mesh, simulation and render reports.
    #[schemars(rename = "meta.json")]
    pub meta: MetaFile,
}

impl DatasetJson {
    /// (file name, text) of each file, in the order [`write_into`](Self::write_into) writes
    /// them.
    pub fn texts(&self) -> [(&'static str, String); 5] {
        [
            (CAMERA_FILE, to_json_text(&self.camera)),
            (LAMPS_FILE, lamps_json_text(&self.lamps)),
            (MATERIAL_FILE, to_json_text(&self.material)),
            (ENVIRONMENT_FILE, to_json_text(&self.environment)),
            (META_FILE, to_json_text(&self.meta)),
        ]
    }

    /// Writes the five files into `out`.
    ///
    /// # Errors
    /// I/O errors of `out`.
    pub fn write_into(&self, out: &mut OutputDir) -> io::Result<()> {
        for (name, text) in self.texts() {
            out.write_bytes(name, text.as_bytes())?;
        }
        Ok(())
    }

    /// Reads the five files of the dataset in `dir`, with the warnings of `lamps.json`.
    ///
    /// # Errors
    /// The first file that fails to read ([`read_file`], [`read_lamps`]).
    pub fn read(dir: &Path) -> Result<(DatasetJson, Vec<String>), DatasetFormatError> {
        let lamps = read_lamps(dir)?;
        let files = DatasetJson {
            camera: read_camera(dir)?,
            lamps: lamps.lamps,
            environment: read_environment(dir)?,
            material: read_material(dir)?,
            meta: read_meta(dir)?,
        };
        Ok((files, lamps.warnings))
    }
}

/// The JSON Schema (draft 2020-12, generated by `schemars`) of a dataset's JSON files: an
/// object keyed by file name, every field documented with its unit.
pub fn json_schema() -> Value {
    schemars::schema_for!(DatasetJson).to_value()
}
