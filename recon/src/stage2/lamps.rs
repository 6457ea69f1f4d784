//! Isotropic point lamps at known positions (camera coordinates) and the irradiance they put
//! on a surface point, with its gradients: what the calibrated-lamp terms of the stage-2 energy
//! share ([`super::lamp_shading`]; the experimental two-light ratio).
//!
//! An isotropic point lamp of radiant power `P` (W) at `p` puts the irradiance
//! `P n · (p - x) / (4π |p - x|^3)` (W/m²) on a surface point `x` (m) of unit normal `n`
//! that it lights. Units: SI (m, W).

use heatsim::vec3::{add, dot, norm, scale, sub};

/// An isotropic point lamp, camera coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointLamp {
    /// Position, m.
    pub position: [f64; 3],
    /// Radiated power (electrical power times radiant fraction), W.
    pub radiant_power: f64,
}

/// A value with its gradients with respect to the unit normal and the position.
pub(crate) type WithGrads = (f64, [f64; 3], [f64; 3]);

/// Where a lamp term adds its weighted gradients: per vertex, d/dn and d/dx.
pub type LampGrads<'a> = Option<(&'a mut [[f64; 3]], &'a mut [[f64; 3]])>;

/// `g = Σ_l P_l n · (p_l - x)/|p_l - x|^3` (W/m², without the 4 pi; module doc) with its gradients with
/// respect to n and x. With `lit_only`, a lamp behind the surface (`n · (p_l - x) ≤ 0`)
/// adds nothing (the attached shadow, `max(0, cosθ)` of `heatsim::lamp`).
pub(crate) fn irradiance(lamps: &[PointLamp], x: [f64; 3], n: [f64; 3], lit_only: bool) -> WithGrads {
    let (mut g, mut gn, mut gx) = (0.0, [0.0; 3], [0.0; 3]);
    for l in lamps {
        let r = sub(l.position, x);
        let d = norm(r);
        let d3 = d * d * d;
        let c = dot(n, r);
        if lit_only && c <= 0.0 {
            continue;
        }
        g += l.radiant_power * c / d3;
        gn = add(gn, scale(r, l.radiant_power / d3));
        // d/dx [n.r / |r|^3] = -n / |r|^3 + 3 (n.r) r / |r|^5
        gx = add(gx, scale(add(scale(n, -1.0 / d3), scale(r, 3.0 * c / (d3 * d * d))), l.radiant_power));
    }
    (g, gn, gx)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Points of a sphere cap in front of the camera with their normals (towards the camera),
    /// and lamps to its left and right between it and the camera (the scenes' layout).
    pub(crate) fn cap() -> (Vec<[f64; 3]>, Vec<[f64; 3]>, [Vec<PointLamp>; 2]) {
        let (c, r) = ([0.0, 0.0, 0.4], 0.05);
        let mut x = Vec::new();
        let mut n = Vec::new();
        for a in 0..6 {
            for b in 0..6 {
                let (u, v) = (-0.6 + 0.24 * a as f64, -0.6 + 0.24 * b as f64);
                let w = -(1.0 - u * u - v * v).sqrt();
                n.push([u, v, w]);
                x.push([c[0] + r * u, c[1] + r * v, c[2] + r * w]);
            }
        }
        let lamp = |px: f64| vec![PointLamp { position: [px, 0.0, 0.17], radiant_power: 212.5 }];
        (x, n, [lamp(-0.2), lamp(0.2)])
    }

    /// The irradiance `P max(0, cosθ)/(4π r^2)` of `heatsim::lamp` at each point, W/m².
    pub(crate) fn model_flux(x: &[[f64; 3]], n: &[[f64; 3]], lamps: &[PointLamp]) -> Vec<f64> {
        x.iter()
            .zip(n)
            .map(|(x, n)| {
                lamps
                    .iter()
                    .map(|l| {
                        let r = sub(l.position, *x);
                        l.radiant_power * dot(*n, r).max(0.0) / (4.0 * std::f64::consts::PI * norm(r).powi(3))
                    })
                    .sum()
            })
            .collect()
    }
}
