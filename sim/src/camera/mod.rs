//! The thermal camera: pinhole geometry, rasterisation of the visible surface, the radiometric
//! sensor with its noise, and preview images.
//!
//! Pipeline (geometry is static over a run, so the expensive part happens once):
//! 1. [`Camera::from_spec`] builds the pinhole model from a scene's
//!    [`CameraSpec`](crate::scene::camera::CameraSpec) ([`pinhole`]).
//! 2. [`rasterize`] renders the visible surface `(verts, tris)` once into a [`Render`]: for each
//!    pixel the nearest triangle, the perspective-correct barycentric coordinates of the point
//!    seen at the pixel centre, and its depth ([`raster`]).
//! 3. Every frame, [`Render::interpolate`] gathers the per-vertex temperatures into a clean
//!    image of true surface temperatures, and [`Sensor::expose`] turns it into what the camera
//!    reports: apparent (emissivity-weighted) temperature plus fixed-pattern noise, temporal
//!    noise and quantisation ([`sensor`]).
//!    With optics (a [`supersampling`](crate::scene::camera::CameraSpec::supersampling)
//!    above 1 or a [`psf`](crate::scene::camera::CameraSpec::psf)), the image of true
//!    temperatures is replaced by the film of a [`Footprint`] (rasterised once at `s x s`
//!    sub-samples per pixel): each pixel's radiance temperature over its footprint through
//!    the lens's PSF ([`optics`], [`footprint`]), finite wherever object radiance reaches
//!    the pixel, also just outside the mask. Mask, depth and normals stay those of the pixel
//!    centres.
//! 4. [`write_preview_png`] writes a false-colour PNG for a quick look ([`preview`]).
//!
//! Conventions (OpenCV): camera frame x right, y down, z forward;
//! `x_c = R x_w + t`; pixel `(u, v) = (f_x x_c / z_c + c_x, f_y y_c / z_c + c_y)` with pixel
//! centres at integer coordinates (the centre of pixel (0, 0) is `u = v = 0`, so the image
//! spans `u ∈ [-1/2, W - 1/2]`). Images are `H * W`, row-major: pixel `(u, v)` (column,
//! row) is element `v * W + u`. SI units: metres, kelvin.

pub mod error;
pub mod footprint;
pub mod grid;
pub mod optics;
pub mod pinhole;
pub mod preview;
pub mod raster;
pub mod sensor;

pub use error::CameraError;
pub use footprint::{supersampled_camera, Footprint};
pub use grid::PixelGrid;
pub use optics::PixelKernel;
pub use pinhole::Camera;
pub use preview::write_preview_png;
pub use raster::{rasterize, Render, Sample, EMPTY, NEAR_PLANE};
pub use sensor::Sensor;
