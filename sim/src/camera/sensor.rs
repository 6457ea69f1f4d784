//! [`Sensor`]: what the thermal camera reports for a clean image of true surface temperatures.
//!
//! # Radiometry
//! The camera is set to emissivity 1 (a radiometric camera without per-object emissivity
//! correction) and reports the blackbody temperature of the radiance it receives. A grey
//! surface of emissivity `ε` at temperature `T` that reflects surroundings at
//! `T_refl` (the ambient temperature) sends
//! `L = ε B(T) + (1 - ε) B(T_refl)`.
//! With the broadband Stefan–Boltzmann approximation `B(T) ∝ T^4` the apparent
//! temperature is
//! `T_app = (ε T^4 + (1 - ε) T_refl^4)^(1/4).`
//! It is exact for `ε = 1` and for `T = T_refl`, and to first order in
//! `T - T_refl` it is `T_refl + ε (T - T_refl)` whatever the
//! law `B(T)`. A band-limited Planck model (the Boson's 8–14 µm band) would differ slightly:
//! near 300 K in-band radiance grows faster than `T^4` (locally like `T^n` with
//! `n = x e^x / (e^x - 1) ≈ 3.5` at 14 µm to 6 at 8 µm, `x = hc / (λ k T)`, about
//! 4.6 averaged over the band), and with `L ∝ T^n` the second-order term is
//! `(n-1)/2 ε (1 - ε) (T - T_refl)^2 / T_refl`. For
//! `ε = 0.95` (painted objects, paper Sec. 7) going from `n = 4` to 4.6 changes
//! `T_app` by about 1 mK for a 5 K rise and 20 mK for a 20 K rise: below the NETD.
//! `T^4` was chosen because it matches the radiation law of the heat solver and the paper's
//! wavelength-independent emissivity (Sec. 4), and needs no spectral integration or band
//! constants.
//!
//! Background pixels (no object) see surroundings at the ambient temperature, so they report
//! `T_refl` exactly before noise.
//!
//! # Films
//! The sensor takes a *film*: per pixel, the temperature `T` of the grey surface (the object's
//! emissivity) whose radiance the pixel receives, or NaN for a pixel that receives only the
//! background's. Point-sampled (no optics), that is the true surface temperature at the pixel
//! centre under the mask and NaN off it. With optics
//! ([`Footprint`](super::Footprint)), it is the radiance temperature
//! `T_eq = (Σ_i w_i T_i^4)^(1/4)` over the weighted footprint, background sub-samples at
//! `T_refl`; then `T_app^4 = ε T_eq^4 + (1 - ε) T_refl^4 = Σ_i w_i T_(app,i)^4`, the same
//! `T^4` law applied to the mixed radiance, and pixels just outside the mask are finite where
//! blurred or partly covered object radiance reaches them. So: a finite value gives
//! `T_app(T)`, on or off the mask; NaN gives `T_refl` off the mask and stays NaN under it (a
//! film that should cover the pixel but does not).
//!
//! # Noise
//! Per pixel `p` and frame `k` the reported value is
//! `y_(p,k) = Q(T_(app,p,k) + o_p + NETD ξ_(p,k))`
//! - `o_p ~ N(0, σ_FPN^2)`: a fixed per-pixel offset pattern, drawn once per
//!   sensor (per run) and identical in every frame;
//! - `ξ_(p,k) ~ N(0, 1)`: temporal noise, independent across pixels and frames;
//! - `Q(x) = q round(x / q)` if the quantisation step `q > 0`, else `x`.
//!
//! # Random streams
//! All noise comes from ChaCha8 keyed by `ChaCha8Rng::seed_from_u64(seed)`. The image is cut
//! into blocks of [`NOISE_BLOCK`] consecutive pixels (row-major); block `j` of frame `k` draws
//! from stream `k` starting at word `j ·` [`BLOCK_WORD_STRIDE`], and block `j` of the fixed
//! pattern from stream 0 starting at word [`FIXED_PATTERN_WORD_OFFSET`] `+ j ·`
//! [`BLOCK_WORD_STRIDE`]. So the noise of frame `k` depends only on `(seed, k)` and the image
//! size: frames can be produced in any order or in parallel with identical bytes, and blocks
//! run in parallel. Samples are drawn for every pixel in order, so they do not depend on the
//! mask either.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;

use crate::scene::camera::{CameraSpec, MAX_IMAGE_SIDE};

use super::CameraError;

/// Pixels per block of the noise streams (and per parallel task). Part of the definition of the
/// noise: changing it changes every noisy frame.
pub const NOISE_BLOCK: usize = 4096;

/// Distance in 32-bit words between the starts of consecutive blocks within one stream: 2^40
/// words, whereas a block draws about 2 words per pixel (one u64 per Gaussian sample, more on
/// the rare ziggurat rejections), 2^13 words in all; blocks can never overlap.
pub const BLOCK_WORD_STRIDE: u128 = 1 << 40;

/// Start (32-bit words) of the fixed pattern in stream 0. Frames use words below
/// 2^28 / NOISE_BLOCK * 2^40 < 2^56 of their stream (at most 16384^2 pixels), so the fixed
/// pattern never shares words with frame 0. ChaCha words are addressed with 68 bits.
pub const FIXED_PATTERN_WORD_OFFSET: u128 = 1 << 64;

/// The radiometric sensor and its noise (see the module documentation).
#[derive(Clone, Debug)]
pub struct Sensor {
    width: u32,
    height: u32,
    emissivity: f64,
    reflected_temperature: f64,
    /// T_refl^4, K^4.
    reflected_t4: f64,
    netd: f64,
    quantization: f64,
    seed: u64,
    /// #H*W fixed offsets o_p, K.
    fixed_pattern: Vec<f64>,
}

impl Sensor {
    /// The sensor of a scene's camera (`width`, `height`, `netd`, `fixed_pattern_sigma`,
    /// `quantization`, `seed`) viewing a surface of `emissivity` (dimensionless, in [0, 1])
    /// that reflects surroundings at `reflected_temperature` (K, > 0; the ambient
    /// temperature). Draws the fixed pattern.
    ///
    /// # Errors
    /// [`CameraError::Invalid`] naming the field (`camera.width`, `camera.height`,
    /// `camera.netd`, `camera.fixed_pattern_sigma`, `camera.quantization`, `emissivity`,
    /// `reflected_temperature`) for a value out of range or not finite.
    pub fn from_spec(spec: &CameraSpec, emissivity: f64, reflected_temperature: f64) -> Result<Sensor, CameraError> {
        for (field, n) in [("camera.width", spec.width), ("camera.height", spec.height)] {
            if n == 0 || n > MAX_IMAGE_SIDE {
                return Err(CameraError::invalid(
                    field,
                    format!("must be between 1 and {MAX_IMAGE_SIDE} pixels, got {n}"),
                ));
            }
        }
        for (field, x) in [
            ("camera.netd", spec.netd),
            ("camera.fixed_pattern_sigma", spec.fixed_pattern_sigma),
            ("camera.quantization", spec.quantization),
        ] {
            if !(x >= 0.0 && x.is_finite()) {
                return Err(CameraError::invalid(field, format!("must be finite and >= 0 K, got {x}")));
            }
        }
        if !(0.0..=1.0).contains(&emissivity) {
            return Err(CameraError::invalid("emissivity", format!("must be in [0, 1], got {emissivity}")));
        }
        if !(reflected_temperature > 0.0 && reflected_temperature.is_finite()) {
            return Err(CameraError::invalid(
                "reflected_temperature",
                format!("must be finite and > 0 K, got {reflected_temperature}"),
            ));
        }
        let n = spec.width as usize * spec.height as usize;
        let mut fixed_pattern = vec![0.0; n];
        if spec.fixed_pattern_sigma > 0.0 {
            let sigma = spec.fixed_pattern_sigma;
            fixed_pattern.par_chunks_mut(NOISE_BLOCK).enumerate().for_each(|(j, block)| {
                let mut rng = block_rng(spec.seed, 0, FIXED_PATTERN_WORD_OFFSET, j);
                for o in block {
                    *o = sigma * rng.sample::<f64, _>(StandardNormal);
                }
            });
        }
        let t2 = reflected_temperature * reflected_temperature;
        Ok(Sensor {
            width: spec.width,
            height: spec.height,
            emissivity,
            reflected_temperature,
            reflected_t4: t2 * t2,
            netd: spec.netd,
            quantization: spec.quantization,
            seed: spec.seed,
            fixed_pattern,
        })
    }

    /// Image width W, in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height H, in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Emissivity of the viewed surface, dimensionless.
    pub fn emissivity(&self) -> f64 {
        self.emissivity
    }

    /// Temperature of the reflected surroundings (and of the background), K.
    pub fn reflected_temperature(&self) -> f64 {
        self.reflected_temperature
    }

    /// Temporal noise, 1 sigma per pixel and frame, K.
    pub fn netd(&self) -> f64 {
        self.netd
    }

    /// Quantisation step, K (0: none).
    pub fn quantization(&self) -> f64 {
        self.quantization
    }

    /// Seed of the noise streams.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// #H*W fixed per-pixel offsets `o_p`, K (all 0 if `fixed_pattern_sigma` is 0).
    pub fn fixed_pattern(&self) -> &[f64] {
        &self.fixed_pattern
    }

    /// Apparent temperature (K) of a surface at true temperature `t_true` (K):
    /// `(ε T^4 + (1 - ε) T_refl^4)^(1/4)`, noise-free.
    #[inline]
    pub fn apparent(&self, t_true: f64) -> f64 {
        let t2 = t_true * t_true;
        let radiance = self.emissivity * (t2 * t2) + (1.0 - self.emissivity) * self.reflected_t4;
        radiance.sqrt().sqrt()
    }

    /// Applies quantisation to `x` (K): the nearest multiple of the step, or `x` if it is 0.
    #[inline]
    pub fn quantize(&self, x: f64) -> f64 {
        if self.quantization > 0.0 {
            (x / self.quantization).round() * self.quantization
        } else {
            x
        }
    }

    /// Frame `frame_index` as the camera reports it, into `out` (#H*W, K): the apparent
    /// temperature of every finite value of the film `clean` (#H*W, K; module documentation,
    /// "Films"), on or off `mask`; the background, `T_refl`, where `clean` is NaN off the
    /// mask; then fixed pattern, temporal noise and quantisation (module documentation).
    /// Deterministic: depends only on the sensor (seed, parameters), `frame_index` and the
    /// inputs. A NaN in `clean` under the mask stays NaN.
    ///
    /// # Panics
    /// If `clean`, `mask` or `out` does not have W * H elements.
    pub fn expose(&self, frame_index: u64, clean: &[f32], mask: &[bool], out: &mut [f32]) {
        let n = self.fixed_pattern.len();
        assert_eq!(clean.len(), n, "clean image has the wrong number of pixels");
        assert_eq!(mask.len(), n, "mask has the wrong number of pixels");
        assert_eq!(out.len(), n, "output image has the wrong number of pixels");
        out.par_chunks_mut(NOISE_BLOCK)
            .zip(clean.par_chunks(NOISE_BLOCK))
            .zip(mask.par_chunks(NOISE_BLOCK))
            .zip(self.fixed_pattern.par_chunks(NOISE_BLOCK))
            .enumerate()
            .for_each(|(j, (((out, clean), mask), offsets))| {
                let mut rng = (self.netd > 0.0).then(|| block_rng(self.seed, frame_index, 0, j));
                for (((o, &t), &m), &offset) in out.iter_mut().zip(clean).zip(mask).zip(offsets) {
                    let signal = self.signal(f64::from(t), m);
                    let noise = match &mut rng {
                        Some(rng) => self.netd * rng.sample::<f64, _>(StandardNormal),
                        None => 0.0,
                    };
                    *o = self.quantize(signal + offset + noise) as f32;
                }
            });
    }

    /// The noise-free apparent temperature of a film value `t` (K, NaN: no object radiance) at
    /// a pixel whose centre sees the object (`on_mask`) or not (module documentation, "Films").
    #[inline]
    fn signal(&self, t: f64, on_mask: bool) -> f64 {
        if on_mask || !t.is_nan() {
            self.apparent(t)
        } else {
            self.reflected_temperature
        }
    }

    /// The noise-free apparent temperature of the film `clean` (K; #H*W) into `out`
    /// (K, f64): what [`Sensor::expose`] reports without fixed pattern, temporal noise and
    /// quantisation, and without rounding to f32 (ground truth for `video_clean`).
    ///
    /// # Panics
    /// If `clean`, `mask` or `out` does not have W * H elements.
    pub fn expose_clean(&self, clean: &[f64], mask: &[bool], out: &mut [f64]) {
        let n = self.fixed_pattern.len();
        assert_eq!(clean.len(), n, "clean image has the wrong number of pixels");
        assert_eq!(mask.len(), n, "mask has the wrong number of pixels");
        assert_eq!(out.len(), n, "output image has the wrong number of pixels");
        for ((o, &t), &m) in out.iter_mut().zip(clean).zip(mask) {
            *o = self.signal(t, m);
        }
    }
}

/// The generator of block `block` in stream `stream`, starting at word
/// `base + block * BLOCK_WORD_STRIDE`.
fn block_rng(seed: u64, stream: u64, base: u128, block: usize) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    rng.set_word_pos(base + block as u128 * BLOCK_WORD_STRIDE);
    rng
}
