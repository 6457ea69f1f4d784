//! [`PixelKernel`]: the camera's optics as one separable kernel, from the radiance on a
//! supersampled image to the radiance each pixel integrates.
//!
//! # Model
//! A pixel of the detector (pitch `p`, fill factor 1) integrates the irradiance the lens forms
//! on its square, and the lens spreads each point of the object over the point spread function
//! `h` (m^-2 on the detector, `∫ h = 1`):
//! `E_pix(u, v) = (1 / p^2) ∫_pixel (h ⊛ E_0)(x, y) dx dy`,
//! with `E_0` the pinhole image of the scene's radiance. Both steps are linear in radiance, so
//! they act on radiance, never on temperature.
//!
//! **PSF.** An isotropic Gaussian of standard deviation `σ` (m on the detector),
//! `h(r) = exp(-r^2 / (2 σ^2)) / (2 π σ^2)`, the usual approximation of the Airy pattern of a
//! diffraction-limited circular pupil, `σ ≈ 0.42 λ N` (Airy first-zero radius `1.22 λ N`);
//! Zhang, Zerubia and Olivo-Marin, "Gaussian approximations of fluorescence microscope
//! point-spread function models", Applied Optics 46(10):1819, 2007 (their `0.21 λ / NA` with
//! `NA = 1 / (2 N)`), also Wikipedia, "Airy disk", section "Approximation using a Gaussian
//! profile". The default of [`GaussianPsf`](crate::scene::camera::GaussianPsf) is one wavelength,
//! `λ = 10 µm`, the middle of the Boson's 7.5–13.5 µm band (FLIR Boson datasheet, doc.
//! 102-2013-40: 640 x 512 or 320 x 256 VOx microbolometer, 12 µm pitch, NETD "as low as
//! < 40 mK @ f/1.0"), with `N = 1.0`: `σ = 4.2 µm = 0.35` pixel. Over the band it would range
//! from 3.2 µm (7.5 µm) to 5.7 µm (13.5 µm). A real lens is at best diffraction-limited, so
//! this is the least blur such a camera has; give a larger `sigma` for a measured lens.
//!
//! **Discretisation.** The image is sampled on a regular grid of `s x s` sub-samples per
//! pixel (sub-sample `(i, j)` of pixel `(u, v)` sees pixel coordinates
//! `(u + (i + 1/2)/s - 1/2, v + (j + 1/2)/s - 1/2)`; spacing `h = 1/s` pixel). Each
//! sub-sample's radiance is taken constant over its cell; the Gaussian blur of that
//! piecewise-constant image, evaluated at the sub-sample centres, has the cell-integrated
//! weights `g[k] = Φ((k + 1/2) / σ_s) - Φ((k - 1/2) / σ_s)` per axis (`Φ` the standard
//! normal distribution, `σ_s = s σ / p` in sub-samples), truncated at `|k| ≤ R = ceil(4 σ_s)`
//! (tail mass 6e-5 per axis) and renormalised to sum to 1. The pixel's value is the mean of
//! its `s` blurred sub-samples per axis (the midpoint rule for the pixel integral). Both are
//! convolutions, so one 1D kernel does both: for sub-sample offsets `t = -R, ..., s - 1 + R`
//! from the pixel's first sub-sample,
//! `c[t] = (1/s) Σ_(j=0)^(s-1) g[t - j]`,
//! and the 2D weight of a sub-sample is `c[t_u] c[t_v]` (`Σ c = 1`). Without a PSF, `R = 0`
//! and `c = 1/s` on the pixel's own sub-samples: a box. Radiance outside the image still
//! reaches pixels within `R` sub-samples of the border, so the supersampled image extends
//! [`PixelKernel::margin`] pixels beyond the image on every side.
//!
//! **Radiance mixing.** With the broadband law of [`Sensor`](super::Sensor) (`L ∝ T^4`,
//! module doc there), a pixel whose weighted sub-samples `i` (weights `w_i`, `Σ w_i = 1`)
//! see the object at true temperature `T_i` or the background (surroundings at `T_refl`,
//! radiating as a blackbody) reports `T_app^4 = Σ_i w_i T_(app,i)^4`, and since the object's
//! `T_(app,i)^4 = ε T_i^4 + (1 - ε) T_refl^4` is affine in `T_i^4`,
//! `T_app^4 = ε T_eq^4 + (1 - ε) T_refl^4` with `T_eq^4 = Σ_i w_i T_i^4` (background
//! sub-samples counted at `T_i = T_refl`): the pixel is the grey surface of the object's
//! emissivity at the radiance temperature `T_eq`. That is what the film stores
//! ([`Footprint`](super::Footprint)), whatever the emissivity.

use crate::scene::camera::{CameraSpec, PsfSpec};

use super::CameraError;

/// The PSF is truncated at this many standard deviations (per axis; the Gaussian's mass
/// beyond is 6.3e-5, renormalised away).
pub const PSF_TRUNCATION_SIGMAS: f64 = 4.0;

/// The separable kernel from sub-samples to pixels (module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct PixelKernel {
    /// Sub-samples per pixel along each axis, s >= 1.
    supersampling: usize,
    /// Reach R of the PSF, in sub-samples (0 without one).
    reach: usize,
    /// Weights c[t] for t = -R, ..., s - 1 + R (length s + 2R), summing to 1.
    weights: Vec<f64>,
}

impl PixelKernel {
    /// The kernel of `supersampling` (s >= 1) sub-samples per pixel and axis, with a Gaussian
    /// PSF of standard deviation `sigma_pixels` (in pixel pitches, > 0), or none.
    ///
    /// # Errors
    /// [`CameraError::Invalid`] for `supersampling` 0 (`camera.supersampling`) or a sigma not
    /// finite and > 0 (`camera.psf.sigma`).
    pub fn new(supersampling: usize, sigma_pixels: Option<f64>) -> Result<PixelKernel, CameraError> {
        if supersampling == 0 {
            return Err(CameraError::invalid("camera.supersampling", "must be >= 1, got 0"));
        }
        let s = supersampling;
        let psf = match sigma_pixels {
            None => vec![1.0],
            Some(sigma) => {
                if !(sigma > 0.0 && sigma.is_finite()) {
                    return Err(CameraError::invalid(
                        "camera.psf.sigma",
                        format!("must be finite and > 0 pixels, got {sigma}"),
                    ));
                }
                gaussian_cell_weights(sigma * s as f64)
            }
        };
        let reach = psf.len() / 2;
        let mut weights = vec![0.0; s + 2 * reach];
        // c[t] = (1/s) sum_j g[t - j]: the PSF's weights shifted to each of the pixel's s
        // sub-samples (index t + R into `weights`, k + R into `psf`).
        for j in 0..s {
            for (k, &g) in psf.iter().enumerate() {
                weights[j + k] += g / s as f64;
            }
        }
        Ok(PixelKernel { supersampling: s, reach, weights })
    }

    /// The kernel of a scene's camera (`supersampling`, `psf`, with `pixel_pitch` to express
    /// the PSF in pixels).
    ///
    /// # Errors
    /// As [`PixelKernel::new`], and for a pixel pitch not finite and > 0 (`camera.pixel_pitch`).
    pub fn from_spec(spec: &CameraSpec) -> Result<PixelKernel, CameraError> {
        let sigma = match &spec.psf {
            PsfSpec::None(_) => None,
            PsfSpec::Gaussian(g) => {
                if !(spec.pixel_pitch > 0.0 && spec.pixel_pitch.is_finite()) {
                    return Err(CameraError::invalid(
                        "camera.pixel_pitch",
                        format!("must be finite and > 0 m, got {}", spec.pixel_pitch),
                    ));
                }
                Some(g.sigma / spec.pixel_pitch)
            }
        };
        PixelKernel::new(spec.supersampling as usize, sigma)
    }

    /// Sub-samples per pixel along each axis, s.
    pub fn supersampling(&self) -> usize {
        self.supersampling
    }

    /// Reach R of the PSF beyond a pixel's own sub-samples, in sub-samples.
    pub fn reach(&self) -> usize {
        self.reach
    }

    /// Pixels the supersampled image extends beyond the image on each side: `ceil(R / s)`.
    pub fn margin(&self) -> usize {
        self.reach.div_ceil(self.supersampling)
    }

    /// The weights `c[t]`, `t = -R, ..., s - 1 + R` (element `t + R`), summing to 1.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Index, in the supersampled image (which starts [`PixelKernel::margin`] pixels before
    /// the image), of the sub-sample of weight `weights()[0]` for pixel `u`:
    /// `s (u + margin) - R`.
    #[inline]
    pub fn first_sub_sample(&self, u: usize) -> usize {
        self.supersampling * (u + self.margin()) - self.reach
    }

    /// The pixels `u` (of `n` along this axis) whose kernel covers sub-sample `c` of the
    /// supersampled image, each with its weight: `weights()[c - first_sub_sample(u)]`.
    pub fn pixels_of(&self, c: usize, n: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let s = self.supersampling;
        let len = self.weights.len();
        // first_sub_sample(u) <= c < first_sub_sample(u) + len, i.e.
        // (c + R + 1 - len) / s - margin <= u <= (c + R) / s - margin (integer division).
        let shifted = c + self.reach;
        let margin_sub = s * self.margin();
        let hi = (shifted / s).checked_sub(self.margin());
        let lo = (shifted + 1).saturating_sub(len).div_ceil(s).saturating_sub(self.margin());
        let hi = hi.map(|h| h.min(n.saturating_sub(1)));
        let range = match hi {
            Some(h) if lo <= h && n > 0 => lo..h + 1,
            _ => 0..0,
        };
        range.map(move |u| (u, self.weights[shifted - (s * u + margin_sub)]))
    }

    /// Integrates a supersampled image `fine` (`fine_width x fine_height`, row-major, any
    /// quantity linear in radiance) into `out` (`width x height` pixels): pixel `(u, v)` is
    /// `Σ_(a, b) c[a] c[b] fine[first(v) + b][first(u) + a]`. The fine image must be
    /// `s (width + 2 margin) x s (height + 2 margin)`.
    ///
    /// # Panics
    /// If the sizes do not match.
    pub fn integrate(&self, fine: &[f64], fine_width: usize, width: usize, height: usize, out: &mut [f64]) {
        let s = self.supersampling;
        let m = self.margin();
        assert_eq!(fine_width, s * (width + 2 * m), "supersampled image width");
        assert_eq!(fine.len(), fine_width * s * (height + 2 * m), "supersampled image size");
        assert_eq!(out.len(), width * height, "output image size");
        let len = self.weights.len();
        // Rows: each fine row to `width` values; then columns.
        let rows: Vec<f64> = fine
            .chunks(fine_width)
            .flat_map(|row| {
                (0..width).map(move |u| {
                    let first = self.first_sub_sample(u);
                    row[first..first + len].iter().zip(&self.weights).map(|(x, c)| x * c).sum::<f64>()
                })
            })
            .collect();
        for v in 0..height {
            let first = self.first_sub_sample(v);
            for u in 0..width {
                out[v * width + u] = (0..len).map(|b| self.weights[b] * rows[(first + b) * width + u]).sum();
            }
        }
    }
}

/// The Gaussian's weights per cell of unit width, `Φ((k + 1/2)/σ) - Φ((k - 1/2)/σ)` for
/// `k = -R, ..., R`, `R = ceil(4 σ)`, normalised to sum 1 (`sigma` in cells, > 0).
fn gaussian_cell_weights(sigma: f64) -> Vec<f64> {
    let reach = (PSF_TRUNCATION_SIGMAS * sigma).ceil() as i64;
    // Φ(b) - Φ(a) = (erf(b/√2) - erf(a/√2)) / 2; the common factor goes in the normalisation.
    let scale = 1.0 / (sigma * std::f64::consts::SQRT_2);
    let mut g: Vec<f64> =
        (-reach..=reach).map(|k| libm::erf((k as f64 + 0.5) * scale) - libm::erf((k as f64 - 0.5) * scale)).collect();
    let sum: f64 = g.iter().sum();
    for x in &mut g {
        *x /= sum;
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixels_of_inverts_first_sub_sample() {
        for (s, sigma) in [(1, None), (3, None), (4, Some(0.35)), (1, Some(0.8)), (5, Some(2.0))] {
            let k = PixelKernel::new(s, sigma).unwrap();
            let n = 7;
            let fine = s * (n + 2 * k.margin());
            for c in 0..fine {
                let want: Vec<usize> = (0..n)
                    .filter(|&u| k.first_sub_sample(u) <= c && c < k.first_sub_sample(u) + k.weights().len())
                    .collect();
                let got: Vec<usize> = k.pixels_of(c, n).map(|(u, _)| u).collect();
                assert_eq!(got, want, "s {s}, sigma {sigma:?}, sub-sample {c}");
                for (u, w) in k.pixels_of(c, n) {
                    assert_eq!(w, k.weights()[c - k.first_sub_sample(u)]);
                }
            }
        }
    }

    #[test]
    fn the_margin_holds_the_kernel() {
        let k = PixelKernel::new(4, Some(0.35)).unwrap();
        assert_eq!(k.reach(), 6); // ceil(4 * 1.4)
        assert_eq!(k.margin(), 2);
        assert!(k.first_sub_sample(0) <= 8 - 6);
    }
}
