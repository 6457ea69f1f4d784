//! The paper's surface model (Eq. 6) as a [`HeatSystem`] on a triangle mesh.
//!
//! The visible surface carries a layer of thickness d. Per unit area, with C = d rho c_p
//! (J/(m^2 K)) and the cotangent Laplacian L and lumped area mass M_a (m^2) of
//! [`super::operators`],
//!
//! C M_a dT/dt = k d L T + M_a (q - h (T - T_s) - eps sigma (T^4 - T_s^4)),
//!
//! which is paper Eq. 6 (there with the radiation linearised, Eq. 5) multiplied by M_a:
//! alpha C M_a^{-1} L = (k d) M_a^{-1} L since alpha rho c_p = k. In the form of
//! [`HeatSystem`]: capacity M = C M_a (diagonal), stiffness K = -k d L (W/K), convection
//! H = h M_a (diagonal, as the paper's M_a), radiating area a_i = (M_a)_ii, load
//! F_i = sum over faces at i of q_f A_f / 3 (W) for a flux given per face, or
//! (M_a)_ii q_i for one given per vertex, as Eq. 6 writes it (the camera grid with
//! `solver.surface_flux: "vertex"`). Convection, radiation and absorption act once
//! per unit area (the layer's front), as in the paper; its back and edges are adiabatic.
//!
//! Backward Euler then gives the same step as the volumetric solver's, and its chord-Newton
//! iteration handles the exact T^4 law (or one substitution per step when linearised).

use super::operators::{corner_areas, half_cotangents, AreaMass};
use crate::fem::assembly::{Pattern, LOWER_PAIRS_TRI};
use crate::fem::volumetric::{HeatSystem, Physics, SolverError, SystemParts};

/// Material, layer and environment of the surface model (SI).
#[derive(Clone, Debug, PartialEq)]
pub struct SurfacePhysics {
    /// Thermal conductivity k (W/(m K)), volumetric heat capacity rho c_p (J/(m^3 K)),
    /// emissivity, convection h (W/(m^2 K)), ambient T_s (K) and the radiation model;
    /// `lumped_mass` is ignored (the surface model's capacity is always lumped, Eq. 6).
    pub physics: Physics,
    /// Layer thickness d (m).
    pub thickness: f64,
    /// How the area is shared among vertices.
    pub area_mass: AreaMass,
}

/// Assembles the surface model on the triangles `tris` over `verts` (m).
///
/// # Errors
/// [`SolverError::DegenerateTriangle`] for a triangle of zero area (its cotangents are
/// infinite), [`SolverError::IsolatedVertex`] for a vertex in no triangle (no capacity).
pub fn assemble(verts: &[[f64; 3]], tris: &[[usize; 3]], surface: &SurfacePhysics) -> Result<HeatSystem, SolverError> {
    let n = verts.len();
    let pattern = Pattern::from_tris(n, tris);
    let kd = surface.physics.conductivity * surface.thickness;
    let c = surface.physics.volumetric_heat_capacity * surface.thickness;
    let h = surface.physics.convection_coefficient;
    let mut stiffness = vec![0.0; pattern.nnz()];
    let mut area = vec![0.0; n];
    for (f, t) in tris.iter().enumerate() {
        let p = t.map(|i| verts[i]);
        let w = half_cotangents(&p);
        let shares = corner_areas(&p, surface.area_mass);
        if !w.iter().all(|x| x.is_finite()) || shares.iter().sum::<f64>() <= 0.0 {
            return Err(SolverError::DegenerateTriangle { triangle: f });
        }
        // Element stiffness -k d L_t: off-diagonal -k d w_c for the edge opposite corner c,
        // diagonal k d times the sum of the weights of the two edges at the corner.
        let opposite = |a: usize, b: usize| 3 - a - b;
        let slots = pattern.tri_slots(t);
        for (s, &(a, b)) in slots.iter().zip(&LOWER_PAIRS_TRI) {
            stiffness[*s] += if a == b { kd * (w[(a + 1) % 3] + w[(a + 2) % 3]) } else { -kd * w[opposite(a, b)] };
        }
        for (corner, share) in shares.into_iter().enumerate() {
            area[t[corner]] += share;
        }
    }
    if let Some(i) = area.iter().position(|&a| a <= 0.0) {
        return Err(SolverError::IsolatedVertex { vertex: i });
    }
    let mut mass = vec![0.0; pattern.nnz()];
    let mut convection = vec![0.0; pattern.nnz()];
    for i in 0..n {
        mass[pattern.diag[i]] = c * area[i];
        convection[pattern.diag[i]] = h * area[i];
    }
    let mut physics = surface.physics.clone();
    physics.lumped_mass = true;
    let parts = SystemParts {
        stiffness,
        convection,
        mass,
        capacity: area.iter().map(|a| c * a).collect(),
        convection_rowsum: area.iter().map(|a| h * a).collect(),
        radiating_area: area,
    };
    HeatSystem::from_parts(physics, pattern, parts)
}
