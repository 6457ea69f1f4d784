//! [`SceneError`]: everything that can go wrong while loading a scene file.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Errors from reading, parsing and validating a scene.
///
/// I/O failures, malformed or mistyped JSON, out-of-range values and unknown material names
/// are kept apart. Every variant but [`SceneError::Io`] carries the JSON path of the offending
/// value (`lamps[1].position[2]`); `path` is the scene file when the scene was loaded with
/// [`Scene::from_file`](super::Scene::from_file) and `None` otherwise. With `path == None`,
/// [`SceneError::Invalid`] displays exactly as `"{json_path}: {message}"`; with a file it is
/// prefixed by `"{file}: "`.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SceneError {
    /// The scene file could not be read.
    #[error("cannot read scene file {}: {source}", path.display())]
    Io {
        /// The file that could not be read.
        path: PathBuf,
        /// The underlying I/O error.
        source: std::io::Error,
    },

    /// The text is not valid JSON, or a value has the wrong type, or a field is unknown or
    /// missing.
    #[error("{}{message} (line {line}, column {column})", location(path.as_deref(), json_path))]
    Parse {
        /// The scene file, if the scene was loaded from one.
        path: Option<PathBuf>,
        /// JSON path of the value being parsed (`camera.width`, `lamps[0].kind`); empty for the
        /// document itself.
        json_path: String,
        /// What went wrong, without the location.
        message: String,
        /// 1-based line of the error in the text (0 if unknown). For type errors and unknown
        /// fields inside `object` or a `lamps` entry, this is where that entry ends (the
        /// tagged entries are read whole before their fields are checked); `json_path` is
        /// exact in every case.
        line: usize,
        /// 1-based column of the error in the text (0 at the start of a line or if unknown).
        column: usize,
    },

    /// A value parsed but is out of range or inconsistent with another value.
    ///
    /// `message` has the form `"must be > 0 m, got -0.01"`: the rule with its unit, then the
    /// value found.
    #[error("{}{message}", location(path.as_deref(), json_path))]
    Invalid {
        /// The scene file, if the scene was loaded from one.
        path: Option<PathBuf>,
        /// JSON path of the offending value (`object.thickness`, `lamps[0].position[2]`).
        json_path: String,
        /// The rule that was broken and the value found.
        message: String,
    },

    /// `material.name` names no material of the library
    /// ([`material_library`](super::material_library)).
    #[error(
        "{}unknown material {name:?}; known materials: {}",
        location(path.as_deref(), "material.name"),
        known.join(", ")
    )]
    UnknownMaterial {
        /// The scene file, if the scene was loaded from one.
        path: Option<PathBuf>,
        /// The name as written in the scene.
        name: String,
        /// Canonical names of the library, in library order, followed by the accepted aliases
        /// as `"alias (= name)"`.
        known: Vec<String>,
    },
}

impl SceneError {
    /// An [`SceneError::Invalid`] without a file.
    pub(crate) fn invalid(json_path: impl Into<String>, message: impl Into<String>) -> Self {
        SceneError::Invalid { path: None, json_path: json_path.into(), message: message.into() }
    }

    /// JSON path of the offending value, if the error has one.
    pub fn json_path(&self) -> Option<&str> {
        match self {
            SceneError::Io { .. } => None,
            SceneError::Parse { json_path, .. } | SceneError::Invalid { json_path, .. } => Some(json_path),
            SceneError::UnknownMaterial { .. } => Some("material.name"),
        }
    }

    /// Attaches the scene file to the error (used by [`Scene::from_file`](super::Scene::from_file)).
    pub(crate) fn with_file(mut self, file: &Path) -> Self {
        match &mut self {
            SceneError::Io { .. } => {}
            SceneError::Parse { path, .. }
            | SceneError::Invalid { path, .. }
            | SceneError::UnknownMaterial { path, .. } => *path = Some(file.to_path_buf()),
        }
        self
    }
}

/// `"{file}: {json_path}: "`, leaving out the parts that are absent.
fn location(file: Option<&Path>, json_path: &str) -> String {
    let mut out = String::new();
    if let Some(file) = file {
        let _ = write!(out, "{}: ", file.display());
    }
    if !json_path.is_empty() {
        let _ = write!(out, "{json_path}: ");
    }
    out
}
