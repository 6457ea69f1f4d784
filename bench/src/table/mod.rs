//! The benchmark's objects and scenes (paper Table 2 and Fig. 4), and `simbench table
//! shape-error`: the paper's shape-error table as a report of a suite run.
//!
//! [`objects`] generates the surfaces of revolution (the hemisphere and the bunny come from
//! `heatsim`'s scene kinds); [`cells`] writes each object's scene; [`report`] turns a suite run
//! (`crate::suite`) into `shape_error.csv` and `shape_error.md`. Units: SI, except the table's
//! distances in mm and NETD in mK.

pub mod cells;
pub mod objects;
pub mod report;
