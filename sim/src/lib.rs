//! # heatsim: the forward model of shape from heat conduction
//!
//! Everything is in SI units: metres, seconds, kelvin, watts, kilograms, joules.
//!
//! Data flow (see `ARCHITECTURE.md` at the repository root):
//! scene file ([`scene`]) -> closed solid ([`solid`]) -> tetrahedral mesh ([`tetgen`],
//! [`mesh`]) -> heat solvers -> camera -> dataset ([`dataset`], its JSON files typed in
//! [`dataset_format`]).

pub mod assets;
pub mod camera;
pub mod constants;
pub mod dataset;
pub mod dataset_format;
pub mod fem;
pub mod io;
pub mod lamp;
pub mod mesh;
pub mod meshing;
pub mod problem_export;
pub mod scene;
pub mod simulate;
pub mod solid;
pub mod surface;
pub mod tetgen;
pub mod vec3;
