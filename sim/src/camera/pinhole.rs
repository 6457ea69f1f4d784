//! [`Camera`]: the pinhole model with OpenCV conventions.
//!
//! Camera frame: x right, y down, z forward (along the optical axis). A world point `x_w` has
//! camera coordinates `x_c = R x_w + t` and, if `z_c > 0`, pixel coordinates
//! `(u, v) = (f_x x_c/z_c + s y_c/z_c + c_x,
//!              f_y y_c/z_c + c_y),
//!    K = [[f_x, s, c_x], [0, f_y, c_y], [0, 0, 1]],`
//! with pixel centres at integer coordinates: the centre of pixel (0, 0) is at `u = v = 0` and
//! the image covers `u ∈ [-1/2, W - 1/2]`, `v ∈ [-1/2, H - 1/2]`.
//!
//! [`Camera::from_spec`] uses square pixels and no skew: `f_x = f_y = (W/2) / tan(HFOV/2)`
//! (so the horizontal field of view spans exactly the outer edges of the outer pixels),
//! `s = 0`, `c_x = (W-1)/2`, `c_y = (H-1)/2`. Lens distortion is not modelled; the reference
//! (physical-parameters section 5) notes it matters only for the widest Boson lenses.

use crate::scene::camera::{CameraSpec, MAX_IMAGE_SIDE};
use crate::vec3::{add, cross, dot, norm, scale, sub, unit};

use super::CameraError;

/// A pinhole camera: image size, intrinsics `k` and extrinsics `(r, t)` (world to camera).
///
/// The fields are public for reading; a hand-built camera must keep `k` upper triangular with
/// `k[2] = [0, 0, 1]` and `fx, fy > 0`, and `r` a rotation (orthonormal, determinant +1).
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// Image width W, in pixels (>= 1).
    pub width: u32,
    /// Image height H, in pixels (>= 1).
    pub height: u32,
    /// Intrinsic matrix K (3 x 3, row-major), in pixels: `[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`.
    pub k: [[f64; 3]; 3],
    /// Rotation world -> camera (3 x 3, row-major); its rows are the camera's x (right),
    /// y (down) and z (forward) axes in world coordinates.
    pub r: [[f64; 3]; 3],
    /// Translation world -> camera, in m: `t = -R c` with `c` the centre of projection.
    pub t: [f64; 3],
}

impl Camera {
    /// The camera of a scene: see [`Camera::look_at`] with the spec's width, height, HFOV,
    /// position, look-at point and up vector. The sensor fields (noise, rate) are not used here.
    ///
    /// # Errors
    /// As [`Camera::look_at`].
    pub fn from_spec(spec: &CameraSpec) -> Result<Camera, CameraError> {
        Camera::look_at(spec.width, spec.height, spec.hfov_deg, spec.position, spec.look_at, spec.up)
    }

    /// A camera at `position` (m) whose optical axis passes through `look_at` (m), with `up`
    /// (any length, not parallel to the axis) pointing up in the picture (towards -y in the
    /// camera frame), a horizontal field of view of `hfov_deg` degrees across the `width`
    /// pixels, square pixels and the principal point at the image centre.
    ///
    /// Axes: `z = (look_at - position) / | · |`, `x = z × up / | · |`
    /// (right), `y = z × x` (down in the picture).
    ///
    /// # Errors
    /// [`CameraError::Invalid`] naming the field (`camera.width`, `camera.height`,
    /// `camera.hfov_deg`, `camera.position`, `camera.look_at`, `camera.up`): a size of 0 or
    /// above [`MAX_IMAGE_SIDE`], an HFOV outside (0, 180) degrees, a non-finite coordinate,
    /// `look_at == position`, or `up` zero or parallel to the optical axis.
    pub fn look_at(
        width: u32,
        height: u32,
        hfov_deg: f64,
        position: [f64; 3],
        look_at: [f64; 3],
        up: [f64; 3],
    ) -> Result<Camera, CameraError> {
        for (field, n) in [("camera.width", width), ("camera.height", height)] {
            if n == 0 || n > MAX_IMAGE_SIDE {
                return Err(CameraError::invalid(
                    field,
                    format!("must be between 1 and {MAX_IMAGE_SIDE} pixels, got {n}"),
                ));
            }
        }
        if !(hfov_deg > 0.0 && hfov_deg < 180.0) {
            return Err(CameraError::invalid(
                "camera.hfov_deg",
                format!("must be in (0, 180) degrees, got {hfov_deg}"),
            ));
        }
        for (field, p) in [("camera.position", position), ("camera.look_at", look_at), ("camera.up", up)] {
            if let Some(i) = p.iter().position(|x| !x.is_finite()) {
                return Err(CameraError::invalid(field, format!("coordinate {i} must be finite, got {p:?}")));
            }
        }
        let axis = sub(look_at, position);
        let Some(z) = unit(axis) else {
            return Err(CameraError::invalid(
                "camera.look_at",
                format!("must differ from camera.position, got {look_at:?}"),
            ));
        };
        let up_len = norm(up);
        let z_cross_up = cross(z, up);
        // Same relative tolerance as CameraSpec::validate: |z x up| <= 1e-9 |up| leaves no
        // usable image x axis.
        if up_len == 0.0 || norm(z_cross_up) <= 1e-9 * up_len {
            return Err(CameraError::invalid(
                "camera.up",
                format!(
                    "must be non-zero and not parallel to the optical axis look_at - position \
                     ({axis:?}), got {up:?}"
                ),
            ));
        }
        let x = scale(z_cross_up, 1.0 / norm(z_cross_up));
        let y = cross(z, x);
        let r = [x, y, z];
        let t = scale([dot(x, position), dot(y, position), dot(z, position)], -1.0);

        let f = 0.5 * f64::from(width) / (0.5 * hfov_deg.to_radians()).tan();
        let cx = 0.5 * (f64::from(width) - 1.0);
        let cy = 0.5 * (f64::from(height) - 1.0);
        let k = [[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]];
        Ok(Camera { width, height, k, r, t })
    }

    /// Focal length along u, in pixels.
    pub fn fx(&self) -> f64 {
        self.k[0][0]
    }

    /// Focal length along v, in pixels.
    pub fn fy(&self) -> f64 {
        self.k[1][1]
    }

    /// Principal point u coordinate, in pixels.
    pub fn cx(&self) -> f64 {
        self.k[0][2]
    }

    /// Principal point v coordinate, in pixels.
    pub fn cy(&self) -> f64 {
        self.k[1][2]
    }

    /// Number of pixels W * H.
    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Centre of projection in world coordinates, m: `c = -R^T t`.
    pub fn center(&self) -> [f64; 3] {
        scale(self.rotate_to_world(self.t), -1.0)
    }

    /// The world point (m) seen at pixel coordinates `(u, v)` at depth `z_c` (m along the
    /// optical axis): `R^T (z_c K^-1 (u, v, 1)^T - t)`, the inverse of [`Camera::project`].
    pub fn unproject(&self, u: f64, v: f64, z_c: f64) -> [f64; 3] {
        let x_c = scale(self.pixel_direction(u, v), z_c);
        add(self.center(), self.rotate_to_world(x_c))
    }

    /// Camera coordinates `x_c = R x_w + t` of the world point `p_world`, m.
    #[inline]
    pub fn to_camera(&self, p_world: [f64; 3]) -> [f64; 3] {
        let r = &self.r;
        [dot(r[0], p_world) + self.t[0], dot(r[1], p_world) + self.t[1], dot(r[2], p_world) + self.t[2]]
    }

    /// Pixel coordinates `[u, v]` of the world point `p_world` (m), or `None` if the point is
    /// not strictly in front of the camera (`z_c ≤ 0`, or not finite). Points outside the
    /// image are projected too (u, v outside the image range).
    pub fn project(&self, p_world: [f64; 3]) -> Option<[f64; 2]> {
        self.project_camera(self.to_camera(p_world))
    }

    /// [`Camera::project`] for a point already in camera coordinates.
    #[inline]
    pub fn project_camera(&self, p: [f64; 3]) -> Option<[f64; 2]> {
        if !(p[2] > 0.0 && p[2].is_finite()) {
            return None;
        }
        let (x, y) = (p[0] / p[2], p[1] / p[2]);
        let k = &self.k;
        Some([k[0][0] * x + k[0][1] * y + k[0][2], k[1][1] * y + k[1][2]])
    }

    /// Direction of the ray through pixel coordinates `(u, v)` in the camera frame, scaled to
    /// `z_c = 1`: `K^-1 (u, v, 1)^T`. Every point seen at `(u, v)` is `s * d` for a depth
    /// `s = z_c > 0` in metres.
    #[inline]
    pub fn pixel_direction(&self, u: f64, v: f64) -> [f64; 3] {
        let k = &self.k;
        let y = (v - k[1][2]) / k[1][1];
        let x = (u - k[0][2] - k[0][1] * y) / k[0][0];
        [x, y, 1.0]
    }

    /// The viewing ray through pixel coordinates `(u, v)`: `(origin, direction)` in world
    /// coordinates, with `origin` the centre of projection (m) and `direction` a unit vector
    /// pointing into the scene. [`Camera::project`] maps every point `origin + s direction`,
    /// `s > 0`, back to `(u, v)`.
    pub fn ray(&self, u: f64, v: f64) -> ([f64; 3], [f64; 3]) {
        let d = self.rotate_to_world(self.pixel_direction(u, v));
        // d has z_c = 1, so it is never zero and normalising cannot fail.
        let d = scale(d, 1.0 / norm(d));
        (self.center(), d)
    }

    /// `R^T a`: a camera-frame vector in world coordinates.
    #[inline]
    fn rotate_to_world(&self, a: [f64; 3]) -> [f64; 3] {
        let r = &self.r;
        [
            r[0][0] * a[0] + r[1][0] * a[1] + r[2][0] * a[2],
            r[0][1] * a[0] + r[1][1] * a[1] + r[2][1] * a[2],
            r[0][2] * a[0] + r[1][2] * a[1] + r[2][2] * a[2],
        ]
    }
}
