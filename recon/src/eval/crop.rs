//! Cropping the ground truth to the part the camera saw.
//!
//! A dataset written by `simbench simulate` holds `camera.json` (OpenCV pinhole:
//! `x_c = R x_w + t`, pixel `(u, v) = (f_x x_c/z_c + s y_c/z_c + c_x, f_y y_c/z_c + c_y)`,
//! pixel centres at integers) and `gt_depth.npy` (float32 [H, W], depth `z_c` along the
//! optical axis in m, NaN where the camera does not see the object). A ground-truth triangle
//! is kept when its centroid has `z_c > 0`, projects into the image, and for at least one
//! pixel of the 3 x 3 block around the pixel it falls in, the depth there is finite (inside
//! the mask) and within the tolerance of the centroid's `z_c` (not occluded):
//! `|z_c - D(u, v)| ≤ abs + px · z_c / f_x,`
//! [`CropTolerance`]: an absolute part (m) and a number of pixel footprints, since a pixel's
//! depth varies across it on surfaces seen at a slant.

// `!(x > 0.0)` is deliberate: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use std::path::{Path, PathBuf};

use heatsim::mesh::TriMesh;
use heatsim::vec3::{add, dot, scale};
use ndarray::Array2;
use serde::{Deserialize, Serialize};

use super::EvalError;

/// File names of a dataset beside the ground truth.
pub const CAMERA_FILE: &str = "camera.json";
/// See [`CAMERA_FILE`].
pub const DEPTH_FILE: &str = "gt_depth.npy";

/// Depth tolerance of the occlusion test.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct CropTolerance {
    /// Absolute part, m.
    pub abs_m: f64,
    /// Pixel footprints (`z_c / f_x` each, m) added to it.
    pub pixels: f64,
}

impl Default for CropTolerance {
    /// 2 mm plus 4 pixel footprints: a 2 mm triangle's centroid is at most half a pixel from
    /// the pixel centre, where a surface tilted by up to about 80 degrees changes depth by up
    /// to ~3 footprints; an occluding surface is a feature of the object, centimetres away.
    fn default() -> Self {
        CropTolerance { abs_m: 2e-3, pixels: 4.0 }
    }
}

/// The camera and depth map of a dataset.
#[derive(Clone, Debug)]
pub struct DepthView {
    /// Intrinsics (pixels), row-major.
    pub k: [[f64; 3]; 3],
    /// Rotation world -> camera, row-major.
    pub r: [[f64; 3]; 3],
    /// Translation world -> camera, m.
    pub t: [f64; 3],
    /// Image size, pixels.
    pub width: usize,
    /// See `width`.
    pub height: usize,
    /// [H, W] depth z_c, m (NaN off the object).
    pub depth: Array2<f32>,
    /// The files it came from.
    pub files: [PathBuf; 2],
}

#[derive(Deserialize)]
struct CameraJson {
    #[serde(rename = "K")]
    k: [[f64; 3]; 3],
    #[serde(rename = "R")]
    r: [[f64; 3]; 3],
    t: [f64; 3],
    width: usize,
    height: usize,
}

impl DepthView {
    /// Loads `camera.json` and `gt_depth.npy` from `dir`; `Ok(None)` when either is absent.
    ///
    /// # Errors
    /// [`EvalError::File`] naming the file: unreadable, malformed JSON or missing fields, not a
    /// 2-D float32 array, a depth map whose shape is not [height, width], or a camera with
    /// non-positive focal lengths.
    pub fn load(dir: &Path) -> Result<Option<DepthView>, EvalError> {
        let cam_path = dir.join(CAMERA_FILE);
        let depth_path = dir.join(DEPTH_FILE);
        if !cam_path.is_file() || !depth_path.is_file() {
            return Ok(None);
        }
        let file_err = |path: &Path, message: String| EvalError::File { path: path.to_path_buf(), message };
        let text = std::fs::read_to_string(&cam_path).map_err(|e| file_err(&cam_path, format!("cannot read: {e}")))?;
        let cam: CameraJson = serde_json::from_str(&text)
            .map_err(|e| file_err(&cam_path, format!("not a camera description (K, R, t, width, height): {e}")))?;
        if !(cam.k[0][0] > 0.0 && cam.k[1][1] > 0.0) || cam.width == 0 || cam.height == 0 {
            return Err(file_err(&cam_path, "K must have positive focal lengths and width, height >= 1".into()));
        }
        let all_finite = cam.k.iter().chain(cam.r.iter()).flatten().chain(cam.t.iter()).all(|v| v.is_finite());
        if !all_finite {
            return Err(file_err(&cam_path, "K, R and t must be finite numbers".into()));
        }
        let f = std::fs::File::open(&depth_path).map_err(|e| file_err(&depth_path, format!("cannot read: {e}")))?;
        let depth: Array2<f32> = ndarray_npy::ReadNpyExt::read_npy(f)
            .map_err(|e| file_err(&depth_path, format!("not a 2-D float32 .npy array: {e}")))?;
        if depth.dim() != (cam.height, cam.width) {
            return Err(file_err(
                &depth_path,
                format!(
                    "shape {:?} does not match the camera's [height, width] = [{}, {}] in {}",
                    depth.dim(),
                    cam.height,
                    cam.width,
                    cam_path.display()
                ),
            ));
        }
        Ok(Some(DepthView {
            k: cam.k,
            r: cam.r,
            t: cam.t,
            width: cam.width,
            height: cam.height,
            depth,
            files: [cam_path, depth_path],
        }))
    }

    /// Camera coordinates of a world point, m.
    pub fn to_camera(&self, p: [f64; 3]) -> [f64; 3] {
        add([dot(self.r[0], p), dot(self.r[1], p), dot(self.r[2], p)], self.t)
    }

    /// Whether the camera sees the world point `p` (m) unoccluded (see the module docs).
    pub fn sees(&self, p: [f64; 3], tol: &CropTolerance) -> bool {
        let c = self.to_camera(p);
        if !(c[2] > 0.0) {
            return false;
        }
        let (x, y) = (c[0] / c[2], c[1] / c[2]);
        let u = self.k[0][0] * x + self.k[0][1] * y + self.k[0][2];
        let v = self.k[1][1] * y + self.k[1][2];
        let (iu, iv) = (u.round(), v.round());
        if !(iu >= 0.0 && iv >= 0.0 && iu < self.width as f64 && iv < self.height as f64) {
            return false;
        }
        let tolerance = tol.abs_m + tol.pixels * c[2] / self.k[0][0];
        let (iu, iv) = (iu as i64, iv as i64);
        for dv in -1..=1 {
            for du in -1..=1 {
                let (uu, vv) = (iu + du, iv + dv);
                if uu < 0 || vv < 0 || uu >= self.width as i64 || vv >= self.height as i64 {
                    continue;
                }
                let d = self.depth[(vv as usize, uu as usize)] as f64;
                if d.is_finite() && (c[2] - d).abs() <= tolerance {
                    return true;
                }
            }
        }
        false
    }
}

/// A cropped ground truth.
#[derive(Clone, Debug)]
pub struct Crop {
    /// The kept triangles, with the vertices they use (renumbered in order of first use).
    pub mesh: TriMesh,
    /// Triangles kept.
    pub kept: usize,
    /// Triangles before cropping.
    pub total: usize,
}

/// Keeps the triangles of `gt` whose centroid the camera of `view` sees (module docs).
///
/// # Errors
/// [`EvalError::Invalid`] if no triangle is kept (the mesh and the camera disagree).
pub fn crop_to_view(gt: &TriMesh, view: &DepthView, tol: &CropTolerance) -> Result<Crop, EvalError> {
    let mut map = vec![usize::MAX; gt.verts.len()];
    let mut verts = Vec::new();
    let mut tris = Vec::new();
    for t in &gt.tris {
        let [a, b, c] = t.map(|i| gt.verts[i]);
        let centroid = scale(add(add(a, b), c), 1.0 / 3.0);
        if !view.sees(centroid, tol) {
            continue;
        }
        tris.push(t.map(|i| {
            if map[i] == usize::MAX {
                map[i] = verts.len();
                verts.push(gt.verts[i]);
            }
            map[i]
        }));
    }
    let kept = tris.len();
    if kept == 0 {
        return Err(EvalError::Invalid(format!(
            "cropping the ground truth to the camera's view ({} and {}) kept none of its {} triangles: the mesh and the camera do not match (pass --no-crop to evaluate against the whole mesh)",
            view.files[0].display(),
            view.files[1].display(),
            gt.tris.len()
        )));
    }
    let mesh = TriMesh::try_new(verts, tris).map_err(|e| EvalError::Invalid(format!("cropped ground truth: {e}")))?;
    Ok(Crop { mesh, kept, total: gt.tris.len() })
}
