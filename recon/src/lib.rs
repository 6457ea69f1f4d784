//! Shape from heat conduction: the reconstruction of paper Sec. 5 and 6 and the scorer.
//!
//! The method recovers an object's shape from thermal videos of it heated by lamps, in two
//! stages. Stage 1 ([`stage1`], paper Sec. 5) estimates, from the videos alone, the scaled
//! surface Laplacian between neighbouring pixels, the absorbed flux of each video and the
//! global heat-exchange parameters (`C` and `h`) by structured least squares. Stage 2
//! ([`stage2`], paper Sec. 6) finds one depth per pixel whose cotangent Laplacian and area
//! masses reproduce stage 1's operator, coarse to fine over an image pyramid. Every setting
//! of both stages lives in [`config`] (presets, JSON, a JSON Schema).
//!
//! [`reconstruct`] runs the whole method on thermal videos of one object (one dataset per
//! lamp configuration, the layout `simbench simulate` writes), configured by one
//! [`ReconConfig`] whose default is the paper's method; an [`Observer`] is told of progress
//! and may look at every level (ground-truth checks live in [`diagnostics`], never in the
//! method). [`eval`] scores a reconstructed mesh against a ground-truth mesh.
//!
//! ```no_run
//! use heatrecon::{dataset::Dataset, reconstruct, ReconConfig, Silent};
//!
//! let mut config = ReconConfig::default(); // the paper's method
//! config.input.diffusivity_m2_per_s = Some(1.2e-7); // PLA: a metric shape
//! let load = heatrecon::dataset::LoadOptions::from(&config.input);
//! let left = Dataset::load("data/left".as_ref(), &load)?;
//! let right = Dataset::load("data/right".as_ref(), &load)?;
//! let rec = reconstruct(&[left, right], &config, &mut Silent)?;
//! let (_, shape) = rec.shape.expect("the default runs the shape stage");
//! let finest = shape.levels.last().expect("one level at least");
//! println!("{} vertices, mean depth {:.4} m", finest.depth.len(), finest.depth.iter().sum::<f64>() / finest.depth.len() as f64);
//! # Ok::<(), heatrecon::error::ReconError>(())
//! ```

pub mod bound;
pub mod config;
pub mod dataset;
pub mod diagnostics;
pub mod error;
pub mod eval;
#[cfg(feature = "experimental")]
pub mod experimental;
pub mod faer_seq;
pub mod halfspace;
pub mod method;
pub mod observer;
pub mod output;
pub mod pyramid;
pub mod stage1;
pub mod stage2;
pub mod validate;

pub use config::{Preset, ReconConfig};
pub use method::{reconstruct, reconstruct_stage1, Reconstruction, Stage1Run};
pub use observer::{Observer, Silent};
