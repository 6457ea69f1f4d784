//! Lamp shading: the absorbed flux of calibrated point lamps as a function of the shape, an
//! opt-in term of the stage-2 energy ([`super::energy::Regularisers::lamp_shading`]). Not the
//! paper's method: the paper uses the lamps only through the sign of Eq. 9.
//!
//! **Model.** With the lamps of `heatsim::lamp` (isotropic points of radiant power `P_l` at
//! `p_l`, attached shadows, no cast shadows) and one absorptivity `a` and heat capacity `C`
//! for the whole object, stage 1's flux of video k at a vertex `x` of unit normal `n` is
//! `b_k = β g_k(x, n),
//!    g_k = Σ_(l ∈ k) P_l (max(0, n · (p_l - x)))/(|p_l - x|^3) (W/m^2),
//!        β = a/(4π C) (m^2 K/J).`
//! Unlike the two-light ratio (`crate::experimental::lamp_ratio`), which keeps only each normal's tilt
//! towards the lamps, the absolute flux with one `β` for every vertex and video ties both
//! components of every normal and, through `|p_l - x|^-2`, the distance: shading with two
//! calibrated lights.
//!
//! **Term** (dimensionless):
//! `E = min_β (Σ_(k,i ∈ A_k) (b_(k,i) - β g_(k,i))^2)/(Σ_(k,i ∈ A_k) b_(k,i)^2),
//!        β^* = (Σ b g)/(Σ g^2),`
//! over the assigned vertices `A_k` of each video (measured flux above a fraction of the
//! image's maximum, which leaves out cast shadows, and outside the boundary rings). With
//! `β` at its optimum, `∂ E/∂ g_(k,i) = -2β^*(b_(k,i) - β^* g_(k,i))
//! / Σ b^2` (the envelope theorem). If every `g` is 0, `E = 1` with no gradient.
//!
//! Units: SI (m, W); positions and normals in camera coordinates; `b` in stage 1's K/s.

use super::lamps::{irradiance, LampGrads, PointLamp, WithGrads};
use heatsim::vec3::{add, scale};

/// The measured fluxes and the lamps of each video (module doc).
#[derive(Clone, Debug)]
pub struct LampShading {
    /// The lamps of each video.
    pub lamps: Vec<Vec<PointLamp>>,
    /// Per video and vertex, the measured flux b (K/s); NaN where not assigned.
    pub target: Vec<Vec<f64>>,
}

impl LampShading {
    /// Assigns, per video, the vertices whose flux exceeds `threshold` times the image's
    /// maximum and that are not `excluded`.
    ///
    /// # Panics
    /// If `lamps` and `fluxes` differ in length.
    pub fn new(lamps: Vec<Vec<PointLamp>>, fluxes: &[Vec<f64>], threshold: f64, excluded: &[bool]) -> LampShading {
        assert_eq!(lamps.len(), fluxes.len(), "one lamp set per flux image");
        let target = fluxes
            .iter()
            .map(|b| {
                let max = b.iter().copied().filter(|v| v.is_finite()).fold(0.0, f64::max);
                b.iter()
                    .enumerate()
                    .map(|(i, &v)| {
                        let keep = v > threshold * max && !excluded.get(i).copied().unwrap_or(false);
                        if keep {
                            v
                        } else {
                            f64::NAN
                        }
                    })
                    .collect()
            })
            .collect();
        LampShading { lamps, target }
    }

    /// Number of assigned (video, vertex) pairs.
    pub fn assigned(&self) -> usize {
        self.target.iter().flatten().filter(|t| t.is_finite()).count()
    }

    /// The term `E` and `β^*` (module doc) at positions `x` and unit normals `n` (per
    /// vertex); with `grads = (dn, dx)`, adds `weight` dE/dn and `weight` dE/dx per vertex.
    pub fn term(&self, x: &[[f64; 3]], n: &[[f64; 3]], weight: f64, grads: LampGrads) -> (f64, f64) {
        // Model irradiance and its gradients for every assigned pair.
        let model: Vec<Vec<Option<WithGrads>>> = self
            .target
            .iter()
            .zip(&self.lamps)
            .map(|(t, lamps)| {
                t.iter().enumerate().map(|(i, b)| b.is_finite().then(|| irradiance(lamps, x[i], n[i], true))).collect()
            })
            .collect();
        let (mut bb, mut bg, mut gg) = (0.0, 0.0, 0.0);
        for (t, m) in self.target.iter().zip(&model) {
            for (b, m) in t.iter().zip(m) {
                if let Some((g, _, _)) = m {
                    bb += b * b;
                    bg += b * g;
                    gg += g * g;
                }
            }
        }
        if bb == 0.0 {
            return (0.0, 0.0);
        }
        if gg == 0.0 {
            return (1.0, 0.0);
        }
        let beta = bg / gg;
        let mut e = 0.0;
        for (t, m) in self.target.iter().zip(&model) {
            for (b, m) in t.iter().zip(m) {
                if let Some((g, _, _)) = m {
                    e += (b - beta * g).powi(2);
                }
            }
        }
        if let Some((gn, gx)) = grads {
            for (t, m) in self.target.iter().zip(&model) {
                for (i, (b, m)) in t.iter().zip(m).enumerate() {
                    if let Some((g, dn, dx)) = m {
                        let w = -2.0 * weight * beta * (b - beta * g) / bb;
                        gn[i] = add(gn[i], scale(*dn, w));
                        gx[i] = add(gx[i], scale(*dx, w));
                    }
                }
            }
        }
        (e / bb, beta)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stage2::lamps::tests::{cap, model_flux};
    use heatsim::vec3::{dot, norm, sub};

    /// Fluxes made by the model give a zero term and recover beta; the gradients match
    /// central differences.
    #[test]
    fn model_fluxes_are_matched_and_gradients_match_differences() {
        let (x, n, lamps) = cap();
        let beta = 3.7e-4;
        let fluxes: Vec<Vec<f64>> = lamps
            .iter()
            .map(|ls| model_flux(&x, &n, ls).iter().map(|g| beta * g * 4.0 * std::f64::consts::PI).collect())
            .collect();
        let exact = LampShading::new(lamps.to_vec(), &fluxes, 0.1, &[]);
        assert!(exact.assigned() > 40, "{} assigned", exact.assigned());
        let (e, b) = exact.term(&x, &n, 1.0, None);
        assert!(e < 1e-24, "{e}");
        assert!((b / beta - 1.0).abs() < 1e-12, "beta {b} vs {beta}");

        let mut ls = exact.clone();
        ls.target.iter_mut().flatten().enumerate().for_each(|(i, t)| *t *= 1.0 + 0.02 * ((i % 5) as f64 - 2.0));
        let nv = x.len();
        let (mut gn, mut gx) = (vec![[0.0; 3]; nv], vec![[0.0; 3]; nv]);
        let (e0, _) = ls.term(&x, &n, 2.0, Some((&mut gn, &mut gx)));
        assert!(e0 > 1e-5, "{e0}");
        let h = 1e-7;
        for i in [0, 7, 14, 21, 28, 35] {
            for c in 0..3 {
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[i][c] += h;
                xm[i][c] -= h;
                let fd = 2.0 * (ls.term(&xp, &n, 1.0, None).0 - ls.term(&xm, &n, 1.0, None).0) / (2.0 * h);
                assert!((fd - gx[i][c]).abs() <= 1e-6 * (1.0 + fd.abs()), "dx[{i}][{c}]: {fd} vs {}", gx[i][c]);
                let (mut np, mut nm) = (n.clone(), n.clone());
                np[i][c] += h;
                nm[i][c] -= h;
                let fd = 2.0 * (ls.term(&x, &np, 1.0, None).0 - ls.term(&x, &nm, 1.0, None).0) / (2.0 * h);
                assert!((fd - gn[i][c]).abs() <= 1e-6 * (1.0 + fd.abs()), "dn[{i}][{c}]: {fd} vs {}", gn[i][c]);
            }
        }
    }

    /// The term carries the distance even at fixed normals, where the ratio of two lamps
    /// hardly does: a cap moved 10 % further along the rays scores clearly worse.
    #[test]
    fn moving_the_shape_along_the_rays_is_penalised() {
        let (x, n, lamps) = cap();
        let fluxes: Vec<Vec<f64>> = lamps.iter().map(|ls| model_flux(&x, &n, ls)).collect();
        let ls = LampShading::new(lamps.to_vec(), &fluxes, 0.1, &[]);
        let far: Vec<[f64; 3]> = x.iter().map(|p| scale(*p, 1.1)).collect();
        let (e, _) = ls.term(&far, &n, 1.0, None);
        assert!(e > 1e-4, "term {e} after moving 10 % further");
        // A lamp behind a vertex lights nothing there (attached shadow).
        let back = PointLamp { position: [0.0, 0.0, 1.0], radiant_power: 1.0 };
        let (g, dn, dx) = irradiance(&[back], x[0], n[0], true);
        assert!(dot(n[0], sub(back.position, x[0])) < 0.0 && g == 0.0 && norm(dn) == 0.0 && norm(dx) == 0.0);
    }
}
