//! The frozen benchmark suite: objects simulated once and filmed at several noise levels and
//! seeds (`build`, `inputs`, `manifest`), any method run on every case and scored (`run`,
//! `method`, `score`), and runs reported (`report`), compared seed by seed (`compare`,
//! `stats`, `power`) and gathered across noise and heating (`map`); `converge` shows that an
//! object's film converges under its meshing.

pub mod bound;
pub mod build;
pub mod compare;
pub mod converge;
pub mod inputs;
pub mod manifest;
pub mod map;
pub mod merge;
pub mod method;
pub mod power;
pub mod process;
pub mod report;
pub mod results;
pub mod run;
pub mod score;
pub mod spec;
pub mod stats;
