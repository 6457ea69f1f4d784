//! Half-space images (paper Eq. 9): from two flux images, which side each normal leans to.
//!
//! Each flux image is min–max normalised over the mesh vertices,
//! `hat(f) = (f - min f) / (max f - min f)` (as the authors' code); with `d = hat(f)^1 - hat(f)^2`,
//! `N = +1` where `d ≥ ε_hs`, `-1` where `d ≤ -ε_hs`, 0 elsewhere
//! (`ε_hs = 0.10` by default, as the authors). `N = +1` means the surface normal leans
//! towards the lamp of video 1 (it absorbs relatively more of its light, Lambert's law).

/// The authors' threshold on the normalised flux difference.
pub const DEFAULT_THRESHOLD: f64 = 0.10;

/// Min–max normalisation (all zeros if the image is constant).
pub fn normalise(f: &[f64]) -> Vec<f64> {
    let lo = f.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = f.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if hi > lo {
        f.iter().map(|x| (x - lo) / (hi - lo)).collect()
    } else {
        vec![0.0; f.len()]
    }
}

/// Eq. 9 per vertex: +1, -1 or 0.
pub fn halfspace(f1: &[f64], f2: &[f64], threshold: f64) -> Vec<i8> {
    let (a, b) = (normalise(f1), normalise(f2));
    a.iter()
        .zip(&b)
        .map(|(x, y)| {
            let d = x - y;
            if d >= threshold {
                1
            } else if d <= -threshold {
                -1
            } else {
                0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eq9() {
        let f1 = [0.0, 1.0, 2.0, 3.0];
        let f2 = [3.0, 2.0, 1.0, 0.0];
        assert_eq!(halfspace(&f1, &f2, 0.1), vec![-1, -1, 1, 1]);
        assert_eq!(halfspace(&f1, &f1, 0.1), vec![0; 4]);
    }
}
