//! heatrecon

pub mod eval;
