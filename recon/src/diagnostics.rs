//! Ground-truth diagnostics of a reconstruction of simulated datasets, as an [`Observer`]:
//! stage 1's figures against the truth with the Cramér–Rao bound on lambda, C and h
//! (`validate`), and at every level of the shape stage the depth error per iteration, the energy
//! at the true depth, the energy along the line through the truth ([`truth_scan`]) and,
//! optionally, the Cramér–Rao bound on shape modes (`crate::bound`, taken at the
//! true depth with the true fluxes and globals). The method never reads any of this.

use std::collections::BTreeMap;
use std::path::PathBuf;

use crate::bound::shape::{BoundOptions, ShapeBound};
use crate::dataset::{Dataset, LoadOptions};
use crate::error::ReconError;
use crate::observer::Observer;
use crate::pyramid::Level;
use crate::stage1::{Stage1Input, Stage1Result};
use crate::stage2::coarse_to_fine::{depth_errors, truth_scan, LevelView, ScanPoint};
use crate::stage2::energy::{energy, vertex_rms_residual, Scale, Terms};
use crate::validate::{Stage1Bound, Stage1Check, Truth};

/// The depth error after one iteration of the shape stage.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct IterationCheck {
    /// Pyramid level.
    pub level: usize,
    /// Iteration at the level.
    pub iteration: usize,
    /// Mean |z - z_true| over the vertices, mm.
    pub depth_mae_mm: f64,
    /// The same after the best global scale of z, mm.
    pub depth_mae_scaled_mm: f64,
}

/// The figures of one level of the shape stage against the truth.
#[derive(Clone, Debug, serde::Serialize)]
pub struct LevelCheck {
    /// Pyramid level.
    pub level: usize,
    /// Depth errors of the level's result (mm; raw and after the best scale).
    pub depth_mae_mm: f64,
    /// After the best global scale, mm.
    pub depth_mae_scaled_mm: f64,
    /// The energy at the true depth (`None` where the truth misses a vertex).
    pub truth_terms: Option<Terms>,
    /// The energy along the line from the plane at the truth's mean depth through the truth.
    pub truth_scan: Vec<ScanPoint>,
    /// The Cramér–Rao bound on shape modes at this level, when asked for.
    pub shape_bound: Option<ShapeBound>,
    /// Per vertex, the RMS heat residual at the true depth (K/s), for images.
    #[serde(skip)]
    pub truth_residual: Option<Vec<f64>>,
}

/// An [`Observer`] that compares every level with the datasets' ground truth.
pub struct TruthCheck {
    dirs: Vec<PathBuf>,
    finest: usize,
    load: LoadOptions,
    threshold: f64,
    shape_bound: Option<BoundOptions>,
    truths: BTreeMap<usize, Truth>,
    /// Every dataset's truth at the finest level (loaded once, for stage 1's figures).
    finest_truths: Vec<Truth>,
    grids: BTreeMap<usize, heatsim::camera::PixelGrid>,
    /// Stage 1's figures at the finest level.
    pub stage1: Option<Stage1Check>,
    /// Per level of the shape stage, coarsest first.
    pub levels: Vec<LevelCheck>,
    /// Per iteration of the shape stage.
    pub iterations: Vec<IterationCheck>,
    /// What could not be computed (for example the bound without a noise-free video).
    pub notes: Vec<String>,
}

impl TruthCheck {
    /// Diagnostics of a run at finest pyramid level `finest` on the simulated datasets in
    /// `dirs`, read as `load` says; the half-space `threshold` of Eq. 9; `shape_bound`: the
    /// bound's options, or `None` for no bound.
    ///
    /// # Errors
    /// A dataset without ground truth (`gt_*.npy`, `material.json`, `meta.json`).
    pub fn new(
        dirs: &[PathBuf],
        finest: usize,
        load: LoadOptions,
        threshold: f64,
        shape_bound: Option<BoundOptions>,
    ) -> Result<TruthCheck, ReconError> {
        let finest_truths = dirs.iter().map(|d| Truth::load(d, finest)).collect::<Result<Vec<_>, _>>()?;
        let notes = finest_truths.iter().flat_map(|t| t.warnings.iter().cloned()).collect();
        let mut truths = BTreeMap::new();
        truths.insert(finest, finest_truths[0].clone());
        Ok(TruthCheck {
            dirs: dirs.to_vec(),
            finest,
            load,
            threshold,
            shape_bound,
            truths,
            finest_truths,
            grids: BTreeMap::new(),
            stage1: None,
            levels: Vec::new(),
            iterations: Vec::new(),
            notes,
        })
    }

    /// The first dataset's truth at `level`.
    fn truth(&mut self, level: usize) -> Result<&Truth, ReconError> {
        if !self.truths.contains_key(&level) {
            let t = Truth::load(&self.dirs[0], level)?;
            self.truths.insert(level, t);
        }
        Ok(&self.truths[&level])
    }

    /// The bound on lambda, C and h from the datasets' noise-free videos at `level`.
    fn globals_bound(&self, level: usize, radiation_coefficient: f64, sigma: f64) -> Result<Stage1Bound, ReconError> {
        let lo = LoadOptions { clean: true, ..self.load.clone() };
        let sets = self.dirs.iter().map(|d| Dataset::load(d, &lo)).collect::<Result<Vec<_>, _>>()?;
        let lvl = Level::build(&sets, level);
        let clean = Stage1Input::from_level(&lvl, sets[0].ambient, sets[0].emissivity)?;
        let t0 = Truth::load(&self.dirs[0], level)?;
        Ok(crate::validate::globals_bound(&clean, &t0, radiation_coefficient, sigma))
    }

    /// The shape bound of `view`'s level at the true depth `zt`, with the true fluxes and
    /// globals (`crate::bound::at_truth`); `None` without the raw series or a known diffusivity.
    fn level_bound(&self, view: &LevelView, zt: &[f64], opts: BoundOptions) -> Result<Option<ShapeBound>, ReconError> {
        let (Some(raw), Some(alpha)) = (view.raw_series, view.metric) else {
            return Ok(None);
        };
        let dirs: Vec<&std::path::Path> = self.dirs.iter().map(|d| d.as_path()).collect();
        let rings = view.opts.boundary_rings;
        let (level, threshold) = (view.level.level, self.threshold);
        let bound =
            crate::bound::at_truth(view.mesh, view.input, raw, zt, &dirs, level, alpha, rings, threshold, opts)?;
        Ok(Some(bound))
    }

    fn check_level(&mut self, view: &LevelView) -> Result<LevelCheck, ReconError> {
        let res = view.result;
        let truth = self.truth(res.level)?.depth.clone();
        let (depth_mae_mm, depth_mae_scaled_mm) = depth_errors(&res.depth, &res.grid, &truth);
        let zt: Option<Vec<f64>> = Some(res.grid.pixels.iter().map(|&p| truth[p]).collect::<Vec<f64>>())
            .filter(|z| z.iter().all(|v| v.is_finite()));
        let fixed = view.metric.map_or(view.scale, Scale::Diffusivity);
        let truth_terms = zt.as_ref().map(|zt| energy(view.mesh, view.data, view.reg, fixed, zt, None));
        let truth_residual =
            zt.as_ref().zip(truth_terms).map(|(zt, t)| vertex_rms_residual(view.mesh, view.data, &t, zt));
        let scan = zt
            .as_ref()
            .map(|zt| truth_scan(view.mesh, view.data, view.reg, view.scale, view.metric, zt))
            .unwrap_or_default();
        let shape_bound = match (self.shape_bound, zt.as_ref()) {
            (Some(o), Some(zt)) => self.level_bound(view, zt, o)?,
            _ => None,
        };
        Ok(LevelCheck {
            level: res.level,
            depth_mae_mm,
            depth_mae_scaled_mm,
            truth_terms,
            truth_scan: scan,
            shape_bound,
            truth_residual,
        })
    }
}

impl Observer for TruthCheck {
    fn wants_raw_series(&self) -> bool {
        self.shape_bound.is_some()
    }

    fn stage1(&mut self, level: &Level, result: &Stage1Result, halfspace: Option<&[i8]>, noise: Option<f64>) {
        if level.level != self.finest {
            return;
        }
        let hs = halfspace.map(|h| (h, self.threshold));
        let mut c = crate::validate::check(result, &level.camera, &self.finest_truths, hs);
        if let Some(sigma) = noise {
            // The bound is an addition to the figures: without a noise-free video, say so.
            match self.globals_bound(level.level, result.radiation_coefficient, sigma) {
                Ok(b) => c.bound = Some(b),
                Err(e) => self.notes.push(format!("no Cramer-Rao bound: {e}")),
            }
        }
        self.stage1 = Some(c);
    }

    fn level_start(&mut self, _index: usize, _levels: usize, level: &Level) {
        let grid = heatsim::camera::PixelGrid::new(&level.mask, level.camera.width, level.camera.height);
        self.grids.insert(level.level, grid);
        if let Err(e) = self.truth(level.level) {
            self.notes.push(format!("no truth at level {}: {e}", level.level));
        }
    }

    fn iteration(&mut self, level: usize, iteration: usize, depth: &[f64]) {
        let (Some(grid), Some(truth)) = (self.grids.get(&level), self.truths.get(&level)) else { return };
        let (a, b) = depth_errors(depth, grid, &truth.depth);
        self.iterations.push(IterationCheck { level, iteration, depth_mae_mm: a, depth_mae_scaled_mm: b });
    }

    fn level(&mut self, view: &LevelView) {
        match self.check_level(view) {
            Ok(c) => self.levels.push(c),
            Err(e) => self.notes.push(format!("level {}: {e}", view.result.level)),
        }
    }
}
