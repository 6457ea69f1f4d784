//! `simbench sweep thickness`: the paper's Fig. 2 (Sec. 4), reproduced from first principles.
//!
//! **Part 1, saturation with thickness** (Fig. 2 left): a cuboid heated uniformly over its
//! visible face, simulated by the volumetric solver for thicknesses d log-spaced from 1 mm to
//! 1 m; the metric is the mean over heating frames and object pixels of
//! |video_d - video_1mm| (apparent temperature without noise, K), and its maximum.
//!
//! **Part 2, the surface approximation** (Fig. 2 right): cuboid, hemisphere and bunny relief,
//! one volumetric run per cell and, on the visible surface of the same tetrahedral mesh, the
//! paper's surface model (Eq. 6) with thickness d and with the effective thickness
//! min(d, c sqrt(alpha t)). With e = mean |video_surface - video_volumetric| over heating
//! frames and pixels seen by both:
//! `pct_err_abs_K = 100 e / mean(video_volumetric)` (relative to the absolute temperature in
//! kelvin, how the paper's figure reads) and `pct_err_rise = 100 e / mean(video_volumetric -
//! T_amb)` (relative to the temperature rise, the honest measure).
//!
//! Every cell (one configuration) writes one JSON file atomically, named by its id and holding
//! the SHA-256 of its configuration ([`cells::Cell::hash`]); `--resume` skips cells whose file
//! holds the same hash. Units are SI throughout.
//!
//! Files: [`cells`] (the cell list, scenes, hashes), [`mesh_cache`] (tetrahedral meshes cached
//! by content hash), [`metrics`] (video comparisons), [`run`] (parallel execution, shards,
//! resume, progress), [`merge`] (joining shard outputs, the CSVs) into [`results`], [`plots`], [`summary`].

pub mod cells;
pub mod merge;
pub mod mesh_cache;
pub mod metrics;
pub mod plots;
pub mod results;
pub mod run;
pub mod summary;

/// Irradiance of the uniform lamp on the visible surface, in W/m^2 (absorbed: absorptivity
/// 0.95 times this). The paper's "5 mW per vertex" depends on the mesh: on a regular
/// triangulation of edge h each vertex carries the area (sqrt(3)/2) h^2, so 5 mW per vertex
/// is 1000 W/m^2 at h = 2.4 mm (and 5770 W/m^2 at 1 mm).
pub const FLUX_W_M2: f64 = 1000.0;

/// Version of the cell format and of the metric definitions; part of every cell hash.
pub const SWEEP_FORMAT: u32 = 1;

/// Sub-directory of the output directory holding one JSON file per cell.
pub const CELLS_DIR: &str = "cells";

/// Default cache directory (meshes, reference videos) inside the output directory.
pub const CACHE_DIR: &str = "cache";
