//! [`CameraSpec`]: the thermal camera (`"camera"` in a scene file).
//!
//! Defaults model a FLIR Boson 640 with the paper's ≈18 mm lens (reference section 5):
//! 640 × 512 pixels of 12 µm, HFOV 24.3°, 368.3 mm above the object looking down -z, 60 Hz,
//! NETD 50 mK.

use crate::vec3::{cross, norm, sub};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::validate::{finite3, int_in, num, Check};
use super::SceneError;

/// Largest accepted image width or height, in pixels.
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// A pinhole thermal camera with noise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct CameraSpec {
    /// Image width, in pixels (default 640; 1 to 16384).
    pub width: u32,
    /// Image height, in pixels (default 512; 1 to 16384).
    pub height: u32,
    /// Pixel pitch on the detector, in m (default 12e-6; > 0, <= 1e-3).
    pub pixel_pitch: f64,
    /// Horizontal field of view, in degrees (default 24.3; in (0, 180)).
    pub hfov_deg: f64,
    /// Centre of projection, in m (default [0, 0, 0.3683]: the paper's working distance).
    pub position: [f64; 3],
    /// Point the optical axis passes through, in m (default [0, 0, 0]).
    pub look_at: [f64; 3],
    /// Up direction of the image (need not be unit or orthogonal to the axis), dimensionless
    /// (default [0, 1, 0]).
    pub up: [f64; 3],
    /// Temporal noise, 1 σ per pixel and frame, in K (default 0.05; >= 0).
    pub netd: f64,
    /// Fixed-pattern (per-pixel offset) noise, 1 σ, in K (default 0.025 = 0.5 NETD right after
    /// a flat-field correction; >= 0).
    pub fixed_pattern_sigma: f64,
    /// Quantisation step of the output temperatures, in K (default 0.01; 0 disables; >= 0).
    pub quantization: f64,
    /// Native frame rate of the sensor, in Hz (default 60; > 0).
    pub native_rate: f64,
    /// Seed of the noise generator (default 0).
    pub seed: u64,
}

impl Default for CameraSpec {
    fn default() -> Self {
        CameraSpec {
            width: 640,
            height: 512,
            pixel_pitch: 12e-6,
            hfov_deg: 24.3,
            position: [0.0, 0.0, 0.3683],
            look_at: [0.0, 0.0, 0.0],
            up: [0.0, 1.0, 0.0],
            netd: 0.05,
            fixed_pattern_sigma: 0.025,
            quantization: 0.01,
            native_rate: 60.0,
            seed: 0,
        }
    }
}

impl CameraSpec {
    /// Checks every number and the viewing geometry (JSON paths `camera.*`).
    ///
    /// # Errors
    /// [`SceneError::Invalid`] for the first value out of range, for `look_at == position`,
    /// or for `up` zero or parallel to the optical axis.
    pub fn validate(&self) -> Check {
        let max = u64::from(MAX_IMAGE_SIDE);
        int_in("camera.width", self.width.into(), 1, max, "pixels")?;
        int_in("camera.height", self.height.into(), 1, max, "pixels")?;
        num("camera.pixel_pitch", self.pixel_pitch, "m")?.gt(0.0)?.le(1e-3)?;
        num("camera.hfov_deg", self.hfov_deg, "deg")?.within(0.0, false, 180.0, false)?;
        finite3("camera.position", self.position)?;
        finite3("camera.look_at", self.look_at)?;
        for (i, &x) in self.up.iter().enumerate() {
            num(&format!("camera.up[{i}]"), x, "")?;
        }
        num("camera.netd", self.netd, "K")?.ge(0.0)?;
        num("camera.fixed_pattern_sigma", self.fixed_pattern_sigma, "K")?.ge(0.0)?;
        num("camera.quantization", self.quantization, "K")?.ge(0.0)?;
        num("camera.native_rate", self.native_rate, "Hz")?.gt(0.0)?;

        let axis = sub(self.look_at, self.position);
        let axis_len = norm(axis);
        if axis_len == 0.0 {
            return Err(SceneError::invalid(
                "camera.look_at",
                format!("must differ from camera.position, got {:?}", self.look_at),
            ));
        }
        let up_len = norm(self.up);
        // Relative tolerance: |axis x up| below 1e-9 |axis| |up| leaves no usable image x axis.
        if up_len == 0.0 || norm(cross(axis, self.up)) <= 1e-9 * axis_len * up_len {
            return Err(SceneError::invalid(
                "camera.up",
                format!(
                    "must be non-zero and not parallel to the optical axis look_at - position \
                     ({axis:?}), got {:?}",
                    self.up
                ),
            ));
        }
        Ok(())
    }
}
