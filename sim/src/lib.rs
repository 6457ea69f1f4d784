//! # heatsim: the forward model of shape from heat conduction
//!
//! `heatsim` simulates what a thermal camera sees while lamps heat an object: it builds the
//! object's solid from a scene file, meshes it with tetrahedra, solves transient heat
//! conduction with convection, `T^4` radiation and lamp flux (the volumetric ground truth, or
//! the paper's surface approximation), and renders the noisy thermal video with its ground
//! truth. Everything is in SI units: metres, seconds, kelvin, watts, kilograms, joules.
//!
//! Data flow (see `ARCHITECTURE.md` at the repository root):
//! scene file ([`scene`]) -> closed solid ([`solid`]) -> tetrahedral mesh ([`tetgen`],
//! [`mesh`]) -> heat solvers ([`simulate`]) -> camera ([`camera`]) -> dataset ([`dataset`],
//! its JSON files typed in [`dataset_format`]).
//!
//! ```no_run
//! use heatsim::scene::Scene;
//!
//! let scene = Scene::from_file("scenes/hemisphere.json".as_ref())?;
//! let meshed = heatsim::meshing::mesh_scene(&scene, None)?;
//! let sim = heatsim::simulate::simulate_volumetric(&scene, &meshed.mesh, |_done, _total| {})?;
//! println!("peak rise {:.2} K", sim.report.max_temperature_rise_k);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

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
