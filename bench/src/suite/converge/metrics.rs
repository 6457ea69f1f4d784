//! How far two films of one object differ where a method reads them, frame by frame.
//!
//! Both films are on the same pixel grid (the same camera). Over the pixels both masks cover,
//! for frame k with rise `r_k = T_k - T_0` (apparent temperature, K; frame 0 is before the
//! lamps switch on):
//!
//! - `rms_k = sqrt(mean_p (T_k^a(p) - T_k^b(p))^2)` (K);
//! - the 5-point pixel Laplacian `(Λ r)(u, v) = r(u+1, v) + r(u-1, v) + r(u, v+1) + r(u, v-1) - 4 r(u, v)`
//!   (K per pixel^2) at the pixels whose four neighbours are covered too, and
//!   `laplacian_rel_k = ||Λ r^a - Λ r^b|| / ||Λ r^b||` (RMS over those pixels; b is the
//!   reference, the finer film), undefined (NaN) where `Λ r^b` vanishes (frames before heating).

/// One film: `frames` images of `width` x `height` (row-major), apparent temperature in K,
/// and the pixels the object covers.
#[derive(Clone, Debug)]
pub struct Film {
    pub width: usize,
    pub height: usize,
    pub mask: Vec<bool>,
    pub frames: Vec<Vec<f64>>,
}

/// The difference of one frame (module documentation).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct FrameDiff {
    /// RMS difference of the frame over the common mask, K.
    pub rms_k: f64,
    /// RMS of the reference's pixel Laplacian of the rise, K per pixel^2.
    pub laplacian_rms: f64,
    /// RMS difference of the pixel Laplacians of the rise over the reference's RMS.
    pub laplacian_rel: f64,
}

/// Frame-by-frame differences of `a` from the reference `b` (module documentation).
///
/// # Errors
/// Films of different sizes or frame counts, or with no pixel in common.
pub fn compare(a: &Film, b: &Film) -> anyhow::Result<Vec<FrameDiff>> {
    anyhow::ensure!(
        a.width == b.width && a.height == b.height && a.frames.len() == b.frames.len(),
        "films of {}x{}x{} and {}x{}x{} frames cannot be compared",
        a.width,
        a.height,
        a.frames.len(),
        b.width,
        b.height,
        b.frames.len()
    );
    let (w, h) = (a.width, a.height);
    let common: Vec<bool> = a.mask.iter().zip(&b.mask).map(|(&x, &y)| x && y).collect();
    let covered = common.iter().filter(|&&c| c).count();
    anyhow::ensure!(covered > 0, "the two films cover no pixel in common");
    let interior: Vec<usize> = (0..w * h)
        .filter(|&p| {
            let (u, v) = (p % w, p / w);
            u > 0 && v > 0 && u + 1 < w && v + 1 < h && [p, p - 1, p + 1, p - w, p + w].iter().all(|&q| common[q])
        })
        .collect();
    let lap = |f: &[f64], f0: &[f64], p: usize| {
        let r = |q: usize| f[q] - f0[q];
        r(p - 1) + r(p + 1) + r(p - w) + r(p + w) - 4.0 * r(p)
    };
    Ok(a.frames
        .iter()
        .zip(&b.frames)
        .map(|(fa, fb)| {
            let sq: f64 = common.iter().enumerate().filter(|(_, &c)| c).map(|(p, _)| (fa[p] - fb[p]).powi(2)).sum();
            let (mut dd, mut bb) = (0.0, 0.0);
            for &p in &interior {
                let (la, lb) = (lap(fa, &a.frames[0], p), lap(fb, &b.frames[0], p));
                dd += (la - lb).powi(2);
                bb += lb * lb;
            }
            let n = interior.len().max(1) as f64;
            FrameDiff {
                rms_k: (sq / covered as f64).sqrt(),
                laplacian_rms: (bb / n).sqrt(),
                laplacian_rel: if bb > 0.0 { (dd / bb).sqrt() } else { f64::NAN },
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A film of a paraboloid rise c (u^2 + v^2) on a 9 x 7 grid: its pixel Laplacian is 4 c.
    fn paraboloid(c: f64, offset: f64) -> Film {
        let (w, h) = (9, 7);
        let f0 = vec![300.0; w * h];
        let f1 =
            (0..w * h).map(|p| 300.0 + offset + c * (((p % w) as f64).powi(2) + ((p / w) as f64).powi(2))).collect();
        Film { width: w, height: h, mask: vec![true; w * h], frames: vec![f0, f1] }
    }

    #[test]
    fn differences_have_their_closed_forms() {
        let (a, b) = (paraboloid(1.1e-3, 0.002), paraboloid(1e-3, 0.0));
        let d = compare(&a, &b).unwrap();
        assert!(d[0].laplacian_rel.is_nan() && d[0].rms_k == 0.0, "before heating: {:?}", d[0]);
        assert!((d[1].laplacian_rms - 4e-3).abs() < 1e-12, "{:?}", d[1]);
        assert!((d[1].laplacian_rel - 0.1).abs() < 1e-9, "{:?}", d[1]);
        // The RMS of 0.002 + 1e-4 (u^2 + v^2) over the grid.
        let (w, h) = (9, 7);
        let ms: f64 = (0..w * h)
            .map(|p| (0.002 + 1e-4 * (((p % w) as f64).powi(2) + ((p / w) as f64).powi(2))).powi(2))
            .sum::<f64>()
            / (w * h) as f64;
        assert!((d[1].rms_k - ms.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn only_the_common_mask_counts() {
        let (mut a, b) = (paraboloid(1e-3, 0.0), paraboloid(1e-3, 0.0));
        a.frames[1][0] += 5.0;
        a.mask[0] = false;
        let d = compare(&a, &b).unwrap();
        assert_eq!(d[1].rms_k, 0.0);
        assert_eq!(d[1].laplacian_rel, 0.0);
        a.mask = vec![false; 63];
        assert!(compare(&a, &b).is_err());
    }
}
