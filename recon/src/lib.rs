//! heatrecon

pub mod eval;
pub mod dataset;
pub mod error;
pub mod halfspace;
pub mod pyramid;
pub mod stage1;
pub mod stage2;
pub mod validate;
pub mod output;
