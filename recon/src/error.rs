//! [`ReconError`]: every way reconstruction input can be wrong, each naming the file or field.

use std::path::PathBuf;

/// An error of the reconstruction: bad or inconsistent input, or an I/O failure.
#[derive(Debug, thiserror::Error)]
pub enum ReconError {
    /// A file could not be read or written.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
    /// A file was read but its content is wrong (shape, type, field, value).
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// Datasets or options that do not fit together, or too little data.
    #[error("{0}")]
    Input(String),
}

impl ReconError {
    /// A [`ReconError::Format`] for `path`.
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> ReconError {
        ReconError::Format { path: path.into(), message: message.into() }
    }
    /// A [`ReconError::Io`] for `path`.
    pub fn io(path: impl Into<PathBuf>, e: impl std::fmt::Display) -> ReconError {
        ReconError::Io { path: path.into(), message: e.to_string() }
    }
}

impl From<heatsim::dataset_format::DatasetFormatError> for ReconError {
    /// A missing or unreadable file is [`ReconError::Io`], anything else
    /// [`ReconError::Format`]; both name the file.
    fn from(e: heatsim::dataset_format::DatasetFormatError) -> ReconError {
        use heatsim::dataset_format::DatasetFormatError as E;
        match &e {
            E::Io { path, source } => ReconError::io(path, source),
            _ => ReconError::format(e.path(), e.detail()),
        }
    }
}
