//! What a caller of [`crate::reconstruct`] is told while it runs: progress, and each level's
//! whole problem for diagnostics (for example against a simulated dataset's ground truth,
//! [`crate::diagnostics::TruthCheck`]). The method never reads ground truth itself; an
//! observer only looks.

use crate::pyramid::Level;
use crate::stage1::Stage1Result;
use crate::stage2::coarse_to_fine::LevelView;

/// Receives what a reconstruction reports. Every method has a default that ignores it.
pub trait Observer {
    /// A line of progress for a person (reading a file, denoising, a level's size).
    fn message(&mut self, _text: &str) {}

    /// Whether [`LevelView::raw_series`] should carry the series before denoising (a copy of
    /// the level's videos).
    fn wants_raw_series(&self) -> bool {
        false
    }

    /// Stage 1 finished at `level`: its result, the half-space image (Eq. 9) when there are two
    /// videos, and the temporal noise of the raw series (K) when known.
    fn stage1(&mut self, _level: &Level, _result: &Stage1Result, _halfspace: Option<&[i8]>, _noise: Option<f64>) {}

    /// The shape stage starts level `index` of `levels` (0: the coarsest).
    fn level_start(&mut self, _index: usize, _levels: usize, _level: &Level) {}

    /// After each iteration of the shape stage at pyramid level `level`: the depths (m).
    fn iteration(&mut self, _level: usize, _iteration: usize, _depth: &[f64]) {}

    /// A level of the shape stage is done.
    fn level(&mut self, _view: &LevelView) {}
}

/// An observer that ignores everything.
#[derive(Clone, Copy, Debug, Default)]
pub struct Silent;

impl Observer for Silent {}
