//! The image pyramid (paper Sec. 6.3): level 0 is the full resolution, level l + 1 halves
//! level l.
//!
//! **Rule.** Coarse pixel `(U, V)` covers the fine pixels `(2U..2U+2, 2V..2V+2)`; it is in the
//! mask only if all four are (`heatsim::camera::grid::downsample_mask`), and its temperature
//! rise is the mean of the four (block averaging; an odd last row or column is dropped). The
//! coarse pixel centre is at fine coordinates `(2U + 1/2, 2V + 1/2)`, so the intrinsics become
//! `fx' = fx/2, fy' = fy/2, s' = s/2, cx' = (cx - 1/2)/2, cy' = (cy - 1/2)/2`. Averaging four
//! independent pixels halves the temporal noise (NETD / 2 per level).

use heatsim::camera::grid::downsample_mask;
use heatsim::camera::PixelGrid;
use ndarray::Array3;

use crate::dataset::{CameraInfo, Dataset};

/// One pyramid level of a set of videos of the same object.
#[derive(Clone, Debug)]
pub struct Level {
    /// Pyramid level (0 = full resolution).
    pub level: usize,
    /// Camera at this resolution (scaled intrinsics, same pose and frame interval).
    pub camera: CameraInfo,
    /// `[H * W]` mask at this resolution.
    pub mask: Vec<bool>,
    /// Times of the frames, s.
    pub times: Vec<f64>,
    /// Per video, temperature rise above ambient, K, `[frames, H, W]`.
    pub rises: Vec<Array3<f64>>,
}

impl Level {
    /// Level 0 of `sets` (already checked to be compatible).
    pub fn from_datasets(sets: &[Dataset]) -> Level {
        Level {
            level: 0,
            camera: sets[0].camera.clone(),
            mask: sets[0].mask.clone(),
            times: sets[0].times.clone(),
            rises: sets.iter().map(|s| s.rise.clone()).collect(),
        }
    }

    /// The next coarser level (see the module doc for the rule).
    pub fn downsample(&self) -> Level {
        let (w, h) = (self.camera.width, self.camera.height);
        let (mask, w2, h2) = downsample_mask(&self.mask, w, h);
        let mut camera = self.camera.clone();
        camera.width = w2;
        camera.height = h2;
        camera.k[0][0] /= 2.0;
        camera.k[0][1] /= 2.0;
        camera.k[1][1] /= 2.0;
        camera.k[0][2] = (camera.k[0][2] - 0.5) / 2.0;
        camera.k[1][2] = (camera.k[1][2] - 0.5) / 2.0;
        let rises = self
            .rises
            .iter()
            .map(|r| {
                let frames = r.dim().0;
                let mut out = Array3::<f64>::zeros((frames, h2, w2));
                for k in 0..frames {
                    for v in 0..h2 {
                        for u in 0..w2 {
                            if mask[v * w2 + u] {
                                let s = r[[k, 2 * v, 2 * u]]
                                    + r[[k, 2 * v, 2 * u + 1]]
                                    + r[[k, 2 * v + 1, 2 * u]]
                                    + r[[k, 2 * v + 1, 2 * u + 1]];
                                out[[k, v, u]] = s / 4.0;
                            }
                        }
                    }
                }
                out
            })
            .collect();
        Level { level: self.level + 1, camera, mask, times: self.times.clone(), rises }
    }

    /// Level `level` of `sets`, built by repeated halving.
    pub fn build(sets: &[Dataset], level: usize) -> Level {
        let mut l = Level::from_datasets(sets);
        for _ in 0..level {
            l = l.downsample();
        }
        l
    }

    /// The vertex counts of the pixel meshes of the `n` levels above this one (the masks only,
    /// no video is averaged), nearest first.
    pub fn coarser_vertex_counts(&self, n: usize) -> Vec<usize> {
        let (mut mask, mut w, mut h) = (self.mask.clone(), self.camera.width, self.camera.height);
        (0..n)
            .map(|_| {
                (mask, w, h) = downsample_mask(&mask, w, h);
                PixelGrid::try_new(&mask, w, h).map_or(0, |g| g.vertex_count())
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 64 x 48 camera with square pixels (fx = fy = 100 px).
    fn camera_64x48() -> CameraInfo {
        CameraInfo {
            k: [[100.0, 0.0, 31.5], [0.0, 100.0, 23.5], [0.0, 0.0, 1.0]],
            r: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            t: [0.0; 3],
            width: 64,
            height: 48,
            frame_interval: 0.1,
        }
    }

    #[test]
    fn intrinsics_follow_pixel_centres() {
        // A point seen at fine pixel centre u = 2U + 1/2 must project to coarse U.
        let cam = camera_64x48();
        let lvl = Level { level: 0, camera: cam, mask: vec![true; 64 * 48], times: vec![0.0], rises: vec![] };
        let c = lvl.downsample();
        let (x, z) = (0.013, 0.7);
        let u_fine = 100.0 * x / z + 31.5;
        let u_coarse = c.camera.k[0][0] * x / z + c.camera.k[0][2];
        assert!((u_coarse - (u_fine - 0.5) / 2.0).abs() < 1e-12);
        assert_eq!((c.camera.width, c.camera.height), (32, 24));
    }

    #[test]
    fn coarser_vertex_counts_match_the_downsampled_levels() {
        let cam = camera_64x48();
        // A disc of radius 20 pixels: every level loses its ragged rim.
        let mask = (0..64 * 48).map(|p| ((p % 64) as f64 - 31.5).hypot((p / 64) as f64 - 23.5) < 20.0).collect();
        let mut lvl = Level { level: 0, camera: cam, mask, times: vec![0.0], rises: vec![] };
        let counts = lvl.coarser_vertex_counts(3);
        for &n in &counts {
            lvl = lvl.downsample();
            let grid = PixelGrid::try_new(&lvl.mask, lvl.camera.width, lvl.camera.height).unwrap();
            assert_eq!(n, grid.vertex_count());
        }
        assert!(counts[0] > 250 && counts[2] > 0 && counts[2] < counts[1] && counts[1] < counts[0], "{counts:?}");
    }
}
