//! The two-light flux ratio (experimental, feature `experimental`; not the paper's method): a
//! stronger form of the half-space constraint (paper Eq. 9, 10) for point lamps at known
//! positions, an opt-in term of the stage-2 energy (`Regularisers::lamp_ratio`).
//!
//! **Model.** With the same absorptivity and heat capacity for both videos, the absorbed
//! fluxes `b_k = q_k / C` of two videos lit by the lamp sets `k = 1, 2` satisfy
//! `(b_1 - b_2)/(b_1 + b_2) = (g_1 - g_2)/(g_1 + g_2),
//!    g_k(x, n) = Σ_(l ∈ k) P_l (n · (p_l - x))/(|p_l - x|^3) (W/m^2),`
//! free of the absorptivity, of C and of `4π` ([`crate::stage2::lamps`]). It constrains each
//! normal's tilt towards the lamps and, because the lamps are at a finite distance, the depth
//! along the ray too.
//!
//! **Term** (dimensionless): `E = 1/(|A|) Σ_(i ∈ A) (d_i(x_i, n_i) - t_i)^2` over the
//! assigned vertices `A` (both measured fluxes above a fraction of their maximum, so that both
//! lamps light them), `t_i` the measured ratio, `d_i` the model's. A vertex whose model
//! irradiance sum `g_1 + g_2` is not positive counts 1 (no gradient).
//!
//! Units: SI (m, W); positions and normals in camera coordinates.

use heatsim::vec3::{add, scale};

use crate::stage2::lamps::{irradiance, LampGrads, PointLamp, WithGrads};

/// The measured ratios and the two videos' lamps (module doc).
#[derive(Clone, Debug)]
pub struct LampRatio {
    /// The lamps of video 1 and of video 2.
    pub lamps: [Vec<PointLamp>; 2],
    /// Per vertex, the measured `(b_1 - b_2)/(b_1 + b_2)`; NaN where not assigned.
    pub target: Vec<f64>,
}

impl LampRatio {
    /// Assigns the vertices whose fluxes `b1`, `b2` (any common unit) both exceed `threshold`
    /// times their image's maximum and that are not `excluded`.
    pub fn new(lamps: [Vec<PointLamp>; 2], b1: &[f64], b2: &[f64], threshold: f64, excluded: &[bool]) -> LampRatio {
        let max = |b: &[f64]| b.iter().copied().filter(|v| v.is_finite()).fold(0.0, f64::max);
        let (m1, m2) = (max(b1), max(b2));
        let target = b1
            .iter()
            .zip(b2)
            .enumerate()
            .map(|(i, (&p, &q))| {
                let lit = p > threshold * m1 && q > threshold * m2 && !excluded.get(i).copied().unwrap_or(false);
                if lit {
                    (p - q) / (p + q)
                } else {
                    f64::NAN
                }
            })
            .collect();
        LampRatio { lamps, target }
    }

    /// The model's ratio `d(x, n)` with `∂ d/∂ n` and `∂ d/∂ x`;
    /// `None` where `g_1 + g_2 ≤ 0`.
    pub fn model(&self, x: [f64; 3], n: [f64; 3]) -> Option<WithGrads> {
        let (g1, n1, x1) = irradiance(&self.lamps[0], x, n, false);
        let (g2, n2, x2) = irradiance(&self.lamps[1], x, n, false);
        let s = g1 + g2;
        if s <= 0.0 {
            return None;
        }
        // d = (g1 - g2)/(g1 + g2): dd/dg1 = 2 g2 / s^2, dd/dg2 = -2 g1 / s^2.
        let (a1, a2) = (2.0 * g2 / (s * s), -2.0 * g1 / (s * s));
        Some(((g1 - g2) / s, add(scale(n1, a1), scale(n2, a2)), add(scale(x1, a1), scale(x2, a2))))
    }

    /// Number of assigned vertices.
    pub fn assigned(&self) -> usize {
        self.target.iter().filter(|t| t.is_finite()).count()
    }

    /// The term `E` (module doc) at positions `x` and unit normals `n` (per vertex); with
    /// `grads = (dn, dx)`, adds `weight` dE/dn and `weight` dE/dx per vertex.
    pub fn term(&self, x: &[[f64; 3]], n: &[[f64; 3]], weight: f64, mut grads: LampGrads) -> f64 {
        let k = 1.0 / self.assigned().max(1) as f64;
        let mut e = 0.0;
        for (i, &t) in self.target.iter().enumerate() {
            if !t.is_finite() {
                continue;
            }
            let Some((d, dn, dx)) = self.model(x[i], n[i]) else {
                e += 1.0;
                continue;
            };
            e += (d - t) * (d - t);
            if let Some((gn, gx)) = grads.as_mut() {
                let w = weight * k * 2.0 * (d - t);
                gn[i] = add(gn[i], scale(dn, w));
                gx[i] = add(gx[i], scale(dx, w));
            }
        }
        e * k
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stage2::lamps::tests::{cap, model_flux};

    /// Fluxes made by the model itself give a zero term; the model is the ratio of the two
    /// inverse-square cosine laws; the gradients match central differences.
    #[test]
    fn ratio_of_model_fluxes_is_matched_and_gradients_match_differences() {
        let (x, n, lamps) = cap();
        let (b1, b2) = (model_flux(&x, &n, &lamps[0]), model_flux(&x, &n, &lamps[1]));
        let exact = LampRatio::new(lamps.clone(), &b1, &b2, 0.1, &[]);
        assert!(exact.assigned() > 20, "{} assigned", exact.assigned());
        assert!(exact.term(&x, &n, 1.0, None) < 1e-24);

        // A perturbed target: a non-zero term whose gradients are checked.
        let mut lr = exact.clone();
        lr.target.iter_mut().enumerate().for_each(|(i, t)| *t += 0.01 * ((i % 5) as f64 - 2.0));
        let nv = x.len();
        let (mut gn, mut gx) = (vec![[0.0; 3]; nv], vec![[0.0; 3]; nv]);
        let e0 = lr.term(&x, &n, 2.0, Some((&mut gn, &mut gx)));
        assert!(e0 > 1e-5);
        let h = 1e-7;
        for i in [0, 7, 14, 21, 28] {
            for c in 0..3 {
                let (mut xp, mut xm) = (x.clone(), x.clone());
                xp[i][c] += h;
                xm[i][c] -= h;
                let fd = 2.0 * (lr.term(&xp, &n, 1.0, None) - lr.term(&xm, &n, 1.0, None)) / (2.0 * h);
                assert!((fd - gx[i][c]).abs() <= 1e-6 * (1.0 + fd.abs()), "dx[{i}][{c}]: {fd} vs {}", gx[i][c]);
                let (mut np, mut nm) = (n.clone(), n.clone());
                np[i][c] += h;
                nm[i][c] -= h;
                let fd = 2.0 * (lr.term(&x, &np, 1.0, None) - lr.term(&x, &nm, 1.0, None)) / (2.0 * h);
                assert!((fd - gn[i][c]).abs() <= 1e-6 * (1.0 + fd.abs()), "dn[{i}][{c}]: {fd} vs {}", gn[i][c]);
            }
        }
    }

    /// The ratio depends on the depth along the ray at fixed normals (the lamps are at a finite
    /// distance), so it carries the size: moving the cap 10 % further changes it.
    #[test]
    fn ratio_changes_with_distance_at_fixed_normals() {
        let (x, n, lamps) = cap();
        let lr = LampRatio { lamps, target: vec![0.0; x.len()] };
        let far: Vec<[f64; 3]> = x.iter().map(|p| scale(*p, 1.1)).collect();
        let rms = (x.iter().zip(&far).zip(&n).map(|((a, b), n)| {
            let (da, _, _) = lr.model(*a, *n).expect("lit");
            let (db, _, _) = lr.model(*b, *n).expect("lit");
            (da - db).powi(2)
        }))
        .sum::<f64>()
            / x.len() as f64;
        assert!(rms.sqrt() > 0.01, "rms change {}", rms.sqrt());
    }
}
