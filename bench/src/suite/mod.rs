//! The frozen benchmark suite: objects simulated once and filmed at several noise levels and
//! seeds (`build`, `inputs`, `manifest`), any method run on every case and scored (`run`,
//! `method`, `score`), and runs reported and compared seed by seed.

pub mod bound;
pub mod build;
pub mod inputs;
pub mod manifest;
pub mod merge;
pub mod method;
pub mod process;
pub mod report;
pub mod results;
pub mod run;
pub mod score;
pub mod spec;
