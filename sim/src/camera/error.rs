//! [`CameraError`]: invalid camera or sensor parameters.

/// An invalid camera or sensor parameter. Only bad input is reported here; the rasteriser and
/// the sensor cannot fail numerically once their inputs are valid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CameraError {
    /// Parameter `field` (a JSON path such as `camera.look_at`, or the name of a function
    /// argument such as `emissivity`) is out of range; `message` says why and gives the value.
    #[error("{field}: {message}")]
    Invalid { field: String, message: String },
}

impl CameraError {
    pub(crate) fn invalid(field: &str, message: impl Into<String>) -> CameraError {
        CameraError::Invalid { field: field.to_owned(), message: message.into() }
    }
}
