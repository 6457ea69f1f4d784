//! Finite elements for heat conduction: element kernels, sparse assembly, and the volumetric
//! backward-Euler solver with exact T^4 radiation.

pub mod assembly;
pub mod cholesky;
pub mod element;
pub mod history;
pub mod pcg;
pub mod volumetric;
