//! What the sweep's tables, plots and summary are made of: the rows that [`super::merge`]
//! collects from the cells and that [`super::plots`] and [`super::summary`] read.

use serde_json::Value;

use super::cells::Shape;

/// A row of `thickness_vs_reference.csv`.
#[derive(Clone, Debug)]
pub struct Part1Row {
    pub material: String,
    pub thickness_m: f64,
    pub mean_abs_err_k: f64,
    pub max_abs_err_k: f64,
    pub mean_rise_k: f64,
}

/// A row of `surface_vs_volumetric.csv`.
#[derive(Clone, Debug)]
pub struct Part2Row {
    pub shape: Shape,
    pub material: String,
    pub thickness_m: f64,
    pub model: String,
    pub pct_err_abs_k: f64,
    pub pct_err_rise: f64,
    pub mean_abs_k: f64,
    pub volumetric_mean_rise_k: f64,
    pub layer_thickness_m: f64,
}

/// A row of `mesh_convergence.csv`.
#[derive(Clone, Debug)]
pub struct ConvRow {
    pub material: String,
    pub thickness_m: f64,
    pub element_factor: f64,
    pub dt_factor: f64,
    pub surface_element_size_m: f64,
    pub time_step_s: f64,
    pub tetrahedra: u64,
    pub mean_rise_k: f64,
    pub seconds: f64,
}

/// Per-cell timing (`cells.csv`).
#[derive(Clone, Debug)]
pub struct CellTiming {
    pub id: String,
    pub nodes: u64,
    pub tetrahedra: u64,
    pub seconds: f64,
}

/// Everything the tables, plots and summary are made of.
pub struct Results {
    pub quick: bool,
    pub part1: Vec<Part1Row>,
    pub part2: Vec<Part2Row>,
    pub conv: Vec<ConvRow>,
    pub timings: Vec<CellTiming>,
    /// The run files (`run_shard_K_of_N.json`): wall time, jobs, cells run.
    pub runs: Vec<Value>,
}
