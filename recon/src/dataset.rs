//! Reading one thermal video dataset (the layout `simbench simulate` writes, or a user's
//! conversion of a real camera's recording) and turning what the camera reports into the true
//! temperature rise above ambient.
//!
//! Files read (nothing else: never `gt_*.npy`, `material.json` or `meta.json`, which are
//! ground truth; `environment.json`'s ground-truth `convection_coefficient` is parsed with the
//! file but never used). The JSON files are read through `heatsim::dataset_format`, which
//! refuses unknown fields and values out of range, naming the file and the field:
//! - `video.npy` (or `video_clean.npy` with [`LoadOptions::clean`]): float32 or float64 `[frames, H, W]`,
//!   apparent temperature in K as a camera set to emissivity 1 reports it;
//! - `mask.npy`: bool `[H, W]`, pixels that see the object;
//! - `camera.json`: `K`, `R`, `t`, `width`, `height`, `frame_interval_s`;
//! - `times.npy` (optional): float64 `[frames]`, s, lamps switch on at t = 0; without it frame 0
//!   is taken at t = 0 and frames follow every `frame_interval_s`;
//! - `environment.json`: `ambient_temperature` (K) and `emissivity` (or
//!   [`LoadOptions::emissivity`]).
//!
//! **Preprocessing** (paper Sec. 5, "subtracting the first frame"). The sensor adds a fixed
//! per-pixel offset `o_p` to the apparent temperature. Before the lamps switch on (t <= 0) the
//! object is at ambient `T_s`, whose apparent temperature is `T_s` whatever the emissivity, so
//! `o_p` is estimated as the mean over those frames of `T_app - T_s` (with no such frame:
//! frame 0 alone, as the paper). Then, with the known emissivity `ε` and the
//! surroundings reflected at `T_s`,
//! `T = (((T_app - o_p)^4 - (1-ε) T_s^4)/ε)^(1/4),`
//! inverting the sensor model of `heatsim::camera::sensor`. Stored is the rise
//! `θ = T - T_s` (K), computed without cancellation.

use std::path::{Path, PathBuf};

use heatsim::dataset_format::{read_environment, CameraFile, CAMERA_FILE, ENVIRONMENT_FILE};
use ndarray::{Array1, Array2, Array3};

use crate::error::ReconError;

/// The pinhole camera of a dataset (OpenCV conventions, see `heatsim::camera::pinhole`).
#[derive(Clone, Debug, PartialEq)]
pub struct CameraInfo {
    /// Intrinsics, pixels.
    pub k: [[f64; 3]; 3],
    /// Rotation world -> camera.
    pub r: [[f64; 3]; 3],
    /// Translation world -> camera, m.
    pub t: [f64; 3],
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// Time between frames, s.
    pub frame_interval: f64,
}

/// How to read a dataset.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// Emissivity to use when `environment.json` has none (or to override it).
    pub emissivity: Option<f64>,
    /// Read `video_clean.npy` (noise-free, simulated datasets only) instead of `video.npy`.
    pub clean: bool,
}

impl From<&crate::config::InputConfig> for LoadOptions {
    /// The reading a configuration asks for (its emissivity, its video).
    fn from(c: &crate::config::InputConfig) -> LoadOptions {
        LoadOptions { emissivity: c.emissivity, clean: c.video == crate::config::Video::Clean }
    }
}

/// One preprocessed video.
#[derive(Clone, Debug)]
pub struct Dataset {
    /// The directory it came from.
    pub dir: PathBuf,
    /// Its camera.
    pub camera: CameraInfo,
    /// `[H * W]`, row-major.
    pub mask: Vec<bool>,
    /// Time of each frame, s (lamps on from t = 0).
    pub times: Vec<f64>,
    /// Ambient (surroundings) temperature T_s, K.
    pub ambient: f64,
    /// Emissivity used for the conversion.
    pub emissivity: f64,
    /// Number of frames used to estimate the fixed pattern.
    pub fixed_pattern_frames: usize,
    /// True temperature rise above ambient, K, `[frames, H, W]` (0 outside the mask).
    pub rise: Array3<f64>,
}

/// Reads `camera.json` at `path` (`heatsim::dataset_format::CameraFile`).
///
/// # Errors
/// [`ReconError`] naming the file and the JSON path of the field.
pub fn read_camera(path: &Path) -> Result<CameraInfo, ReconError> {
    let c: CameraFile = heatsim::dataset_format::read_file(path)?;
    Ok(CameraInfo {
        k: c.k,
        r: c.r,
        t: c.t,
        width: c.width as usize,
        height: c.height as usize,
        frame_interval: c.frame_interval_s,
    })
}

impl Dataset {
    /// Reads and preprocesses the dataset in `dir` (module doc).
    ///
    /// # Errors
    /// Missing or malformed files, sizes that disagree between files, NaN or infinite
    /// temperatures inside the mask, an empty mask, non-increasing times, no emissivity.
    pub fn load(dir: &Path, opts: &LoadOptions) -> Result<Dataset, ReconError> {
        let camera = read_camera(&dir.join(CAMERA_FILE))?;
        let env_path = dir.join(ENVIRONMENT_FILE);
        let env = read_environment(dir)?;
        let ambient = env.ambient_temperature; // > 0 K, checked by the reader
        let emissivity = match opts.emissivity {
            Some(e) => e,
            None => env.emissivity.ok_or_else(|| {
                ReconError::format(
                    &env_path,
                    "no `emissivity` field: add it or pass the emissivity explicitly (--emissivity)",
                )
            })?,
        };
        if !(emissivity > 0.0 && emissivity <= 1.0) {
            return Err(ReconError::format(&env_path, format!("emissivity must be in (0, 1], got {emissivity}")));
        }

        let mask_path = dir.join("mask.npy");
        let mask: Array2<bool> = ndarray_npy::read_npy(&mask_path)
            .map_err(|e| ReconError::format(&mask_path, format!("expected a bool [H, W] array: {e}")))?;
        let (h, w) = mask.dim();
        if (w, h) != (camera.width, camera.height) {
            return Err(ReconError::format(
                &mask_path,
                format!("mask is {w} x {h} (W x H) but camera.json says {} x {}", camera.width, camera.height),
            ));
        }
        let mask: Vec<bool> = mask.iter().copied().collect();
        if !mask.iter().any(|&b| b) {
            return Err(ReconError::format(&mask_path, "the mask is empty: no pixel sees the object"));
        }

        let video_name = if opts.clean { "video_clean.npy" } else { "video.npy" };
        let video_path = dir.join(video_name);
        // float32 as cameras store it, or float64 (the simulator's noise-free video).
        let video: Array3<f64> = match ndarray_npy::read_npy::<_, Array3<f64>>(&video_path) {
            Ok(v) => v,
            Err(_) => ndarray_npy::read_npy::<_, Array3<f32>>(&video_path).map(|v| v.mapv(f64::from)).map_err(|e| {
                ReconError::format(&video_path, format!("expected a float32 or float64 [frames, H, W] array: {e}"))
            })?,
        };
        let (frames, vh, vw) = video.dim();
        if (vw, vh) != (w, h) {
            return Err(ReconError::format(
                &video_path,
                format!("frames are {vw} x {vh} (W x H) but mask.npy is {w} x {h}"),
            ));
        }
        if frames < 2 {
            return Err(ReconError::format(&video_path, format!("needs at least 2 frames, has {frames}")));
        }

        let times = read_times(dir, frames, video_name, camera.frame_interval)?;

        // NaN / infinite values inside the mask.
        for f in 0..frames {
            for (p, &m) in mask.iter().enumerate() {
                let x = video[[f, p / w, p % w]];
                if m && !x.is_finite() {
                    return Err(ReconError::format(
                        &video_path,
                        format!("frame {f}, pixel (u {}, v {}) inside the mask is {x}", p % w, p / w),
                    ));
                }
            }
        }

        let (rise, fixed_pattern_frames) =
            true_rise(&video, &mask, &times, camera.frame_interval, ambient, emissivity, &video_path)?;
        Ok(Dataset { dir: dir.to_path_buf(), camera, mask, times, ambient, emissivity, fixed_pattern_frames, rise })
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.times.len()
    }
}

/// The frame times (s) of the dataset in `dir`: `times.npy` when present (`frames` finite,
/// increasing values), else every `frame_interval` (s) from 0; `video_name` for messages.
fn read_times(dir: &Path, frames: usize, video_name: &str, frame_interval: f64) -> Result<Vec<f64>, ReconError> {
    let times_path = dir.join("times.npy");
    if !times_path.exists() {
        return Ok((0..frames).map(|k| k as f64 * frame_interval).collect());
    }
    let t: Array1<f64> = ndarray_npy::read_npy(&times_path)
        .map_err(|e| ReconError::format(&times_path, format!("expected a float64 [frames] array: {e}")))?;
    if t.len() != frames {
        return Err(ReconError::format(
            &times_path,
            format!("has {} times but {video_name} has {frames} frames", t.len()),
        ));
    }
    let t = t.to_vec();
    if t.iter().any(|x| !x.is_finite()) || t.windows(2).any(|p| p[1] <= p[0]) {
        return Err(ReconError::format(&times_path, "times must be finite and increasing"));
    }
    Ok(t)
}

/// The true temperature rise above `ambient` (K) inside `mask` of the apparent `video` (module
/// doc, "Preprocessing"), and the number of frames the fixed pattern was estimated from.
fn true_rise(
    video: &Array3<f64>,
    mask: &[bool],
    times: &[f64],
    frame_interval: f64,
    ambient: f64,
    emissivity: f64,
    video_path: &Path,
) -> Result<(Array3<f64>, usize), ReconError> {
    let (frames, h, w) = video.dim();
    // Fixed pattern from the frames at ambient (t <= 0), else frame 0.
    let tol = 1e-9 * frame_interval;
    let mut pre: Vec<usize> = (0..frames).filter(|&k| times[k] <= tol).collect();
    if pre.is_empty() {
        pre.push(0);
    }
    let mut offset = vec![0.0f64; w * h];
    for &k in &pre {
        for (p, o) in offset.iter_mut().enumerate() {
            *o += video[[k, p / w, p % w]] - ambient;
        }
    }
    offset.iter_mut().for_each(|o| *o /= pre.len() as f64);

    let ts4 = ambient.powi(4);
    let mut rise = Array3::<f64>::zeros((frames, h, w));
    for k in 0..frames {
        for (p, &m) in mask.iter().enumerate() {
            if !m {
                continue;
            }
            let (v, u) = (p / w, p % w);
            let d = video[[k, v, u]] - offset[p] - ambient; // apparent rise
            let a = ambient + d;
            let a4_minus = d * (a + ambient) * (a * a + ambient * ambient); // a^4 - Ts^4
            let t4_minus = a4_minus / emissivity; // T^4 - Ts^4
            let t4 = ts4 + t4_minus;
            if t4 <= 0.0 {
                return Err(ReconError::format(
                    video_path,
                    format!(
                        "frame {k}, pixel (u {u}, v {v}): apparent temperature too low for emissivity {emissivity}"
                    ),
                ));
            }
            let t = t4.sqrt().sqrt();
            rise[[k, v, u]] = t4_minus / ((t + ambient) * (t * t + ambient * ambient));
        }
    }
    Ok((rise, pre.len()))
}

/// Checks that several datasets film the same object with the same camera (same image size,
/// intrinsics, pose, mask, frame interval, ambient temperature and emissivity).
///
/// # Errors
/// [`ReconError::Input`] naming the two directories and what differs.
pub fn check_compatible(sets: &[Dataset]) -> Result<(), ReconError> {
    let Some(first) = sets.first() else {
        return Err(ReconError::Input("no dataset given".into()));
    };
    for s in &sets[1..] {
        let what = if (s.camera.width, s.camera.height) != (first.camera.width, first.camera.height) {
            Some(format!(
                "image size {} x {} vs {} x {}",
                s.camera.width, s.camera.height, first.camera.width, first.camera.height
            ))
        } else if s.camera.k != first.camera.k || s.camera.r != first.camera.r || s.camera.t != first.camera.t {
            Some("camera intrinsics or pose (K, R, t) differ".to_string())
        } else if s.frames() != first.frames() {
            Some(format!("{} frames vs {} frames", s.frames(), first.frames()))
        } else if s.mask != first.mask {
            Some("mask.npy differs (not the same object and view)".to_string())
        } else if (s.camera.frame_interval - first.camera.frame_interval).abs() > 1e-12 * first.camera.frame_interval {
            Some(format!("frame interval {} s vs {} s", s.camera.frame_interval, first.camera.frame_interval))
        } else if s.ambient != first.ambient {
            Some(format!("ambient temperature {} K vs {} K", s.ambient, first.ambient))
        } else if s.emissivity != first.emissivity {
            Some(format!("emissivity {} vs {}", s.emissivity, first.emissivity))
        } else {
            None
        };
        if let Some(what) = what {
            return Err(ReconError::Input(format!(
                "datasets {} and {} do not match: {what}",
                first.dir.display(),
                s.dir.display()
            )));
        }
    }
    Ok(())
}

/// The thermal diffusivity k/(rho c_p) of the material in `dir`'s `material.json` (m^2/s): the
/// one input of the material the paper takes from a table.
///
/// # Errors
/// A missing or malformed `material.json`.
pub fn read_diffusivity(dir: &Path) -> Result<f64, ReconError> {
    let m = heatsim::dataset_format::read_material(dir)?;
    Ok(m.conductivity / (m.density * m.specific_heat))
}
