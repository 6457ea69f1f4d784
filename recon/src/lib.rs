//! heatrecon

pub mod dataset;
pub mod error;
pub mod eval;
pub mod faer_seq;
pub mod halfspace;
pub mod output;
pub mod pyramid;
pub mod stage1;
pub mod stage2;
pub mod validate;
