//! [`CameraSpec`]: the thermal camera (`"camera"` in a scene file).
//!
//! Defaults model a FLIR Boson 640 with the paper's ≈18 mm lens (reference section 5):
//! 640 × 512 pixels of 12 µm, HFOV 24.3°, 368.3 mm above the object looking down -z, 60 Hz,
//! NETD 50 mK.
//!
//! The optics ([`CameraSpec::supersampling`], [`CameraSpec::psf`]) default to point sampling:
//! each pixel shows the surface at its centre, with no pixel area and no lens blur, as before
//! they existed. [`PsfSpec::Gaussian`]'s default width is the diffraction limit of the Boson's
//! f/1.0 lens at 10 µm (see [`BOSON_PSF_SIGMA`] and `camera::optics`).

use crate::vec3::{cross, norm, sub};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::parse::tagged_enum;
use super::validate::{finite3, int_in, num, Check};
use super::SceneError;

/// Largest accepted image width or height, in pixels.
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// Largest accepted supersampling factor s (s x s sub-samples per pixel). Memory grows as s^2:
/// the footprint stores 32 bytes per sub-sample that sees the object.
pub const MAX_SUPERSAMPLING: u32 = 16;

/// Default standard deviation of the Gaussian PSF on the detector, in m: 0.42 λ N for a
/// diffraction-limited lens of f-number N = 1.0 at λ = 10 µm, i.e. 4.2 µm = 0.35 of the
/// Boson's 12 µm pixel (Airy first-zero radius 1.22 λ N = 12.2 µm). Sources in
/// `camera::optics`.
pub const BOSON_PSF_SIGMA: f64 = 4.2e-6;

/// Largest accepted Gaussian PSF standard deviation, in pixel pitches: 8 (the kernel then
/// reaches 32 pixels, far beyond any focused thermal lens).
pub const MAX_PSF_SIGMA_PIXELS: f64 = 8.0;

/// The lens's point spread function on the detector; tagged by `"kind"`: `none` or
/// `gaussian`.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum PsfSpec {
    /// No blur: a point on the object lights one point of the detector (default).
    None(NoPsf),
    /// An isotropic Gaussian, the usual approximation of the Airy pattern of a
    /// diffraction-limited lens (sigma ≈ 0.42 λ N).
    Gaussian(GaussianPsf),
}

tagged_enum!(PsfSpec {
    "none" => None,
    "gaussian" => Gaussian,
});

/// No blur (`{"kind": "none"}`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NoPsf {}

/// An isotropic Gaussian PSF (`{"kind": "gaussian", "sigma": 4.2e-6}`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GaussianPsf {
    /// Standard deviation on the detector, in m (default 4.2e-6 = 0.42 λ N for N = 1.0,
    /// λ = 10 µm; > 0, <= 8 pixel pitches).
    #[serde(default = "default_psf_sigma")]
    pub sigma: f64,
}

fn default_psf_sigma() -> f64 {
    BOSON_PSF_SIGMA
}

impl Default for GaussianPsf {
    fn default() -> Self {
        GaussianPsf { sigma: BOSON_PSF_SIGMA }
    }
}

impl Default for PsfSpec {
    fn default() -> Self {
        PsfSpec::None(NoPsf {})
    }
}

impl PsfSpec {
    /// Whether this is `{"kind": "none"}` (also: whether a scene file omits it).
    pub fn is_none(&self) -> bool {
        matches!(self, PsfSpec::None(_))
    }

    /// Checks the parameters (JSON paths below `path`, e.g. `camera.psf.sigma`) for a
    /// detector of pixel pitch `pixel_pitch` (m).
    ///
    /// # Errors
    /// [`SceneError::Invalid`] for a sigma not finite, <= 0 or above
    /// [`MAX_PSF_SIGMA_PIXELS`] pitches.
    pub fn validate_at(&self, path: &str, pixel_pitch: f64) -> Check {
        match self {
            PsfSpec::None(_) => Ok(()),
            PsfSpec::Gaussian(g) => {
                num(&format!("{path}.sigma"), g.sigma, "m")?.gt(0.0)?.le(MAX_PSF_SIGMA_PIXELS * pixel_pitch)?;
                Ok(())
            }
        }
    }
}

fn is_one(s: &u32) -> bool {
    *s == 1
}

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
    /// Supersampling factor s, dimensionless: each pixel integrates its whole footprint (fill
    /// factor 1) from s x s sub-samples on a regular grid, and silhouette pixels mix object
    /// and background radiance (default 1: point sampling at the pixel centre; 1 to 16).
    // Not serialised at its default (so scenes written before the optics keep their bytes),
    // hence the schema's default given by hand.
    #[serde(skip_serializing_if = "is_one")]
    #[schemars(extend("default" = 1))]
    pub supersampling: u32,
    /// The lens's point spread function, applied to the radiance on the supersampled image
    /// before it is integrated into pixels (default `{"kind": "none"}`; the Gaussian's
    /// default sigma is 4.2e-6 m, the diffraction limit of an f/1.0 lens at 10 µm).
    #[serde(skip_serializing_if = "PsfSpec::is_none")]
    #[schemars(extend("default" = {"kind": "none"}))]
    pub psf: PsfSpec,
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
            supersampling: 1,
            psf: PsfSpec::default(),
        }
    }
}

impl CameraSpec {
    /// Whether the optics are point sampling (supersampling 1, no PSF): each pixel shows the
    /// surface at its centre, bit for bit as before the optics existed.
    pub fn point_sampling(&self) -> bool {
        self.supersampling == 1 && self.psf.is_none()
    }

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
        int_in("camera.supersampling", self.supersampling.into(), 1, MAX_SUPERSAMPLING.into(), "")?;
        self.psf.validate_at("camera.psf", self.pixel_pitch)?;

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
