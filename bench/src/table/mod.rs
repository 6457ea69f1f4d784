//! `simbench table shape-error`: the paper's shape-error results (Table 2, Fig. 4) on simulated
//! objects with a known truth.
//!
//! Each row: generate the object (surfaces of revolution: [`objects`]; the hemisphere and the
//! bunny come from `heatsim`'s scene kinds), write its scene ([`cells`]), simulate two lamp
//! configurations, reconstruct with `simbench reconstruct` as it stands, score the
//! reconstruction against the visible ground truth with `heatrecon::eval` (rigid ICP; also a
//! similarity alignment), render it coloured by signed error beside the truth ([`render`]), and
//! record the result or the failure atomically ([`run`]). [`report`] writes `shape_error.csv`
//! and `shape_error.md`. Units: SI, except the table's distances in mm and NETD in mK.

pub mod cells;
pub mod objects;
pub mod render;
pub mod report;
pub mod run;
