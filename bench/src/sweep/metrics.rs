//! Video comparisons of the sweep (temperatures in K).
//!
//! A [`Video`] is the apparent temperature without noise (`video_clean`), frames x pixels,
//! with NaN where the camera does not see the object. A comparison of `test` against `truth`
//! runs over the heating frames (t > 0; the frame at t = 0 is the ambient start) and the
//! pixels both see (P pixels, F frames):
//! - `mean_abs_k` = (1 / F P) sum |test - truth|, `max_abs_k` its maximum;
//! - `mean_truth_k` = (1 / F P) sum truth (absolute temperature);
//! - `mean_rise_k` = `mean_truth_k` - T_amb (the apparent temperature of an object at ambient
//!   is T_amb exactly, whatever its emissivity);
//! - `pct_err_abs_k` = 100 `mean_abs_k` / `mean_truth_k`, `pct_err_rise` = 100 `mean_abs_k` /
//!   `mean_rise_k`.

use anyhow::{bail, ensure};
use serde::{Deserialize, Serialize};

/// A noiseless video: `data[k * pixels + p]`, NaN off the object.
#[derive(Clone, Debug)]
pub struct Video {
    pub frames: usize,
    pub pixels: usize,
    pub width: usize,
    pub height: usize,
    /// Frame times, s (heating starts at 0).
    pub times: Vec<f64>,
    pub data: Vec<f32>,
}

impl Video {
    /// The clean video of a dataset, NaN outside its mask.
    pub fn from_dataset(d: &heatsim::dataset::Dataset) -> Video {
        let pixels = d.pixels();
        // f32 as the sweep has always compared (its figures are mK, far above f32's 3e-5 K).
        let mut data: Vec<f32> = d.video_clean.iter().map(|&t| t as f32).collect();
        for frame in data.chunks_mut(pixels) {
            frame.iter_mut().zip(&d.mask).for_each(|(v, &m)| {
                if !m {
                    *v = f32::NAN;
                }
            });
        }
        Video {
            frames: d.times.len(),
            pixels,
            width: d.camera.width as usize,
            height: d.camera.height as usize,
            times: d.times.clone(),
            data,
        }
    }

    /// Mean over heating frames and seen pixels (K).
    pub fn mean_heating(&self) -> f64 {
        let (mut s, mut n) = (0.0, 0usize);
        for k in (0..self.frames).filter(|&k| self.times[k] > 0.0) {
            for &v in self.data[k * self.pixels..(k + 1) * self.pixels].iter().filter(|v| v.is_finite()) {
                s += v as f64;
                n += 1;
            }
        }
        s / n.max(1) as f64
    }
}

/// The figures of one comparison (see the module doc).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Diff {
    pub mean_abs_k: f64,
    pub max_abs_k: f64,
    pub mean_truth_k: f64,
    pub mean_rise_k: f64,
    pub pct_err_abs_k: f64,
    pub pct_err_rise: f64,
    pub pixels: usize,
    pub frames: usize,
}

/// Compares `test` with `truth` (see the module doc); `ambient` in K.
///
/// # Errors
/// Videos of different sizes or frame times, or no pixel seen by both.
pub fn compare(test: &Video, truth: &Video, ambient: f64) -> anyhow::Result<Diff> {
    ensure!(
        test.frames == truth.frames && test.width == truth.width && test.height == truth.height,
        "videos differ in size: {}x{}x{} against {}x{}x{}",
        test.frames,
        test.height,
        test.width,
        truth.frames,
        truth.height,
        truth.width
    );
    for (a, b) in test.times.iter().zip(&truth.times) {
        ensure!((a - b).abs() <= 1e-9 * (1.0 + b.abs()), "videos differ in frame times: {a} s against {b} s");
    }
    let both: Vec<usize> = (0..truth.pixels)
        .filter(|&p| {
            (0..truth.frames)
                .all(|k| truth.data[k * truth.pixels + p].is_finite() && test.data[k * test.pixels + p].is_finite())
        })
        .collect();
    if both.is_empty() {
        bail!("the two videos share no pixel of the object");
    }
    let heating: Vec<usize> = (0..truth.frames).filter(|&k| truth.times[k] > 0.0).collect();
    if heating.is_empty() {
        bail!("the videos have no frame after heating starts");
    }
    let (mut sum_abs, mut max_abs, mut sum_truth) = (0.0f64, 0.0f64, 0.0f64);
    for &k in &heating {
        let (t, r) = (&test.data[k * test.pixels..], &truth.data[k * truth.pixels..]);
        for &p in &both {
            let e = (t[p] as f64 - r[p] as f64).abs();
            sum_abs += e;
            max_abs = max_abs.max(e);
            sum_truth += r[p] as f64;
        }
    }
    let n = (heating.len() * both.len()) as f64;
    let mean_abs_k = sum_abs / n;
    let mean_truth_k = sum_truth / n;
    let mean_rise_k = mean_truth_k - ambient;
    Ok(Diff {
        mean_abs_k,
        max_abs_k: max_abs,
        mean_truth_k,
        mean_rise_k,
        pct_err_abs_k: 100.0 * mean_abs_k / mean_truth_k,
        pct_err_rise: 100.0 * mean_abs_k / mean_rise_k,
        pixels: both.len(),
        frames: heating.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn video(values: &[[f32; 4]]) -> Video {
        Video {
            frames: values.len(),
            pixels: 4,
            width: 2,
            height: 2,
            times: (0..values.len()).map(|k| k as f64).collect(),
            data: values.iter().flatten().copied().collect(),
        }
    }

    #[test]
    fn hand_computed_comparison() {
        let nan = f32::NAN;
        // Frame 0 is t = 0 and is ignored; pixel 3 is off the object in the truth.
        let truth = video(&[[300.0, 300.0, 300.0, nan], [302.0, 304.0, 306.0, nan], [304.0, 306.0, 308.0, nan]]);
        let test = video(&[[900.0, 0.0, 0.0, 1.0], [303.0, 304.0, 305.0, 1.0], [304.0, 310.0, 308.0, 1.0]]);
        let d = compare(&test, &truth, 300.0).unwrap();
        // |diffs| over frames 1, 2 and pixels 0..3: 1, 0, 1, 0, 4, 0 -> mean 1, max 4.
        assert_eq!(d.pixels, 3);
        assert_eq!(d.frames, 2);
        assert!((d.mean_abs_k - 1.0).abs() < 1e-12);
        assert_eq!(d.max_abs_k, 4.0);
        assert!((d.mean_truth_k - 305.0).abs() < 1e-12);
        assert!((d.mean_rise_k - 5.0).abs() < 1e-12);
        assert!((d.pct_err_rise - 20.0).abs() < 1e-9);
        assert!((d.pct_err_abs_k - 100.0 / 305.0).abs() < 1e-9);
        assert!((truth.mean_heating() - 305.0).abs() < 1e-12);
    }

    #[test]
    fn mismatched_videos_are_errors() {
        let a = video(&[[1.0; 4], [2.0; 4]]);
        let b = video(&[[1.0; 4]]);
        assert!(compare(&a, &b, 0.0).is_err());
        let c = video(&[[f32::NAN; 4], [f32::NAN; 4]]);
        assert!(compare(&a, &c, 0.0).unwrap_err().to_string().contains("no pixel"));
    }
}
