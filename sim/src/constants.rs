//! Physical constants (SI).

/// Stefan–Boltzmann constant sigma in W m^-2 K^-4 (exact in the 2019 SI, CODATA 2018).
pub const STEFAN_BOLTZMANN: f64 = 5.670_374_419e-8;
