//! The paper's surface approximation (Sec. 4, Eq. 6): heat conduction on the visible surface
//! of an object treated as a layer of thickness d, and the discrete operators it is built of.
//!
//! ## Effective thickness (beyond the paper)
//! Within a video of length t, heat diffuses only about sqrt(alpha t) into the object
//! (alpha = k / (rho c_p), m^2/s). A thick object's surface therefore heats like a layer far
//! thinner than d, and the surface model with the true d underestimates the rise. The
//! effective thickness is
//!
//! d_eff = min(d, c sqrt(alpha t)),
//!
//! with t the heating duration (`timing.duration`) and c = `solver.effective_thickness_factor`.
//! [`DEFAULT_EFFECTIVE_THICKNESS_FACTOR`] = sqrt(pi) / 2 ~ 0.886 matches the surface
//! temperature of a semi-infinite solid under a constant absorbed flux q at time t,
//! 2 q sqrt(t / pi) / sqrt(k rho c_p), with that of a lumped layer, q t / (rho c_p d_eff)
//! (losses neglected). Matching the mean over [0, t] instead gives c = 3 sqrt(pi) / 8 ~ 0.665.

pub mod derivatives;
pub mod mesh;
pub mod operators;
pub mod system;

/// The c of [`effective_thickness`] that matches the surface temperature rise of a
/// semi-infinite solid under constant flux at the end of the heating: sqrt(pi) / 2.
pub const DEFAULT_EFFECTIVE_THICKNESS_FACTOR: f64 = 0.886_226_925_452_758; // sqrt(pi) / 2

/// min(d, c sqrt(alpha t)) (m) for thickness `d` (m), diffusivity `alpha` (m^2/s), heating
/// time `t` (s) and factor `c` (dimensionless).
pub fn effective_thickness(d: f64, alpha: f64, t: f64, c: f64) -> f64 {
    d.min(c * (alpha * t).sqrt())
}

#[cfg(test)]
mod tests {
    #[test]
    fn default_factor_is_half_root_pi() {
        assert!((super::DEFAULT_EFFECTIVE_THICKNESS_FACTOR - std::f64::consts::PI.sqrt() / 2.0).abs() < 1e-15);
        // Polystyrene-like alpha = 1e-7 m^2/s over 15 s: sqrt(1.5e-6) = 1.22 mm.
        let d = super::effective_thickness(0.1, 1e-7, 15.0, 1.0);
        assert!((d - 1.5e-6_f64.sqrt()).abs() < 1e-15);
        assert_eq!(super::effective_thickness(1e-4, 1e-7, 15.0, 1.0), 1e-4);
    }
}
