//! Stage 2 (paper Sec. 6): shape from the Laplacian. One depth per pixel-vertex along its
//! camera ray; the heat residual re-evaluated with the cotangent Laplacian and area mass of the
//! current vertices ([`energy`]), normal consistency, the half-space hinge of Eq. 10 and an
//! optional mirror symmetry ([`symmetry`]); with calibrated lamps, the opt-in two-light ratio
//! (`experimental::lamp_ratio`, feature `experimental`) and lamp shading ([`lamp_shading`]);
//! large-steps AdamUniform or L-BFGS ([`optimize`]); coarse to fine over the image pyramid ([`coarse_to_fine`]); files
//! ([`export`]).

pub mod coarse_to_fine;
pub mod energy;
pub mod export;
pub mod lamp_shading;
pub mod lamps;
pub mod noise;
pub mod optimize;
mod profile;
pub mod symmetry;

pub use coarse_to_fine::{reconstruct, Stage1Params, Stage2Options, Stage2Result};
pub use energy::Scale;
pub use optimize::{OptimOptions, Optimizer};
