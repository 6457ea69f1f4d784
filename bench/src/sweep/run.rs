//! Running the cells of a sweep: shards, resume, parallel execution, progress.
//!
//! - **Shards**: `--shard K/N` runs the cells whose index i in the full, fixed cell list has
//!   i mod N = K - 1 (a deterministic partition; every shard writes the same `plan.json`).
//! - **Resume**: a cell is done when `cells/<id>.json` parses and holds the cell's current
//!   configuration hash; `--resume` skips those, everything else runs.
//! - **Atomicity**: every file is written to a temporary file in its directory and renamed
//!   ([`heatsim::io::write_atomic`]), so an interrupted run (Ctrl-C, kill) leaves finished
//!   cells complete and no other file under a final name; leftover temporaries (`.tmp*`) of a
//!   killed run are removed when the next run starts.
//! - **References**: a part-1 cell compares its video with the 1 mm cell of its material; the
//!   reference videos are computed first (in parallel) and cached as
//!   `cache/videos/<hash>.npy` (float32 [frames, H, W], K, NaN off the object).
//! - **Parallelism**: cells run on a rayon pool of `--jobs` threads, largest first.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::Mutex;
use std::time::Instant;

use anyhow::{bail, Context};
use heatsim::scene::SolverKind;
use ndarray::Array3;
use ndarray_npy::{ReadNpyExt, WriteNpyExt};
use rayon::prelude::*;
use serde_json::{json, Value};

use super::cells::{effective_factor, Cell, CellSpec, Plan};
use super::mesh_cache::mesh_cached;
use super::metrics::{compare, Video};
use super::CELLS_DIR;

/// `K/N`: run the K-th of N parts of the cell list (1 <= K <= N).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub k: usize,
    pub n: usize,
}

impl Shard {
    /// Whether cell number `index` of the full list belongs to this shard.
    pub fn owns(&self, index: usize) -> bool {
        index % self.n == self.k - 1
    }
}

impl FromStr for Shard {
    type Err = String;
    fn from_str(s: &str) -> Result<Shard, String> {
        let (k, n) = s.split_once('/').ok_or_else(|| format!("expected K/N (e.g. 2/4), got {s:?}"))?;
        let k: usize = k.trim().parse().map_err(|_| format!("K in K/N must be a whole number, got {k:?}"))?;
        let n: usize = n.trim().parse().map_err(|_| format!("N in K/N must be a whole number, got {n:?}"))?;
        if n == 0 || k == 0 || k > n {
            return Err(format!("need 1 <= K <= N, got {k}/{n}"));
        }
        Ok(Shard { k, n })
    }
}

/// What `simbench sweep` was asked to do.
pub struct RunOptions {
    pub plan: Plan,
    pub out: PathBuf,
    pub cache: PathBuf,
    pub resume: bool,
    pub jobs: usize,
    pub shard: Shard,
}

/// What a run did.
#[derive(Debug)]
pub struct RunReport {
    pub ran: usize,
    pub skipped: usize,
    pub wall_seconds: f64,
}

/// The stored result of a cell, if it exists and parses.
pub fn read_cell(path: &Path) -> Option<Value> {
    let text = std::fs::read_to_string(path).ok()?;
    let v: Value = serde_json::from_str(&text).ok()?;
    v.get("hash")?.as_str()?;
    Some(v)
}

/// Removes temporaries (`.tmp*`) left in `dir` by a killed run.
fn remove_stale_temporaries(dir: &Path) {
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            if e.file_name().to_string_lossy().starts_with(".tmp") {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// Runs the shard's cells of the plan (see the module doc).
pub fn run_sweep(opts: &RunOptions) -> anyhow::Result<RunReport> {
    let t0 = Instant::now();
    let all = opts.plan.cells()?;
    let cells_dir = opts.out.join(CELLS_DIR);
    std::fs::create_dir_all(&cells_dir).with_context(|| format!("creating {}", cells_dir.display()))?;
    for d in [cells_dir.clone(), opts.cache.join("meshes"), opts.cache.join("videos")] {
        remove_stale_temporaries(&d);
    }
    write_plan(&opts.out, &opts.plan, &all)?;

    let mine: Vec<Cell> = all.into_iter().enumerate().filter(|(i, _)| opts.shard.owns(*i)).map(|(_, c)| c).collect();
    let (mut todo, skipped) = cells_to_run(mine, &cells_dir, opts.resume);
    todo.sort_by(|a, b| b.cost_estimate().total_cmp(&a.cost_estimate()));
    eprintln!(
        "sweep: shard {}/{}: {} cells to run, {} already done (resume), {} jobs",
        opts.shard.k,
        opts.shard.n,
        todo.len(),
        skipped,
        opts.jobs
    );

    let pool = rayon::ThreadPoolBuilder::new().num_threads(opts.jobs).build().context("starting the thread pool")?;
    let bar = indicatif::ProgressBar::new(todo.len() as u64).with_style(
        indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} cells ({eta} left) {msg}")
            .expect("valid template"),
    );
    let finished = std::sync::atomic::AtomicUsize::new(0);
    let total = todo.len();
    let failures: Mutex<Vec<String>> = Mutex::new(Vec::new());
    let report_done = |id: &str, seconds: f64| {
        let n = finished.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1;
        bar.inc(1);
        bar.set_message(id.to_string());
        bar.suspend(|| eprintln!("sweep: [{n}/{total}] {id} done in {seconds:.1} s"));
    };
    let ctx = Ctx { cells_dir: &cells_dir, cache: &opts.cache };

    // References first: one per material of the part-1 cells to run.
    let mut refs: BTreeMap<String, Cell> = BTreeMap::new();
    for cell in &todo {
        if let Some(r) = cell.spec.reference() {
            refs.entry(r.id()).or_insert(Cell::new(r, cell.quick)?);
        }
    }
    let todo_ids: BTreeSet<String> = todo.iter().map(|c| c.id()).collect();
    let written: Mutex<BTreeSet<String>> = Mutex::new(BTreeSet::new());
    pool.install(|| {
        refs.values().collect::<Vec<_>>().par_iter().for_each(|r| {
            let path = ctx.video_path(r);
            if read_video(&path, r).is_some() {
                return;
            }
            match ctx.run_thickness(r, None) {
                Ok((record, seconds)) => {
                    if todo_ids.contains(&r.id()) {
                        match ctx.write_record(r, record) {
                            Ok(()) => {
                                written.lock().expect("lock").insert(r.id());
                                report_done(&r.id(), seconds);
                            }
                            Err(e) => failures.lock().expect("lock").push(format!("{}: {e:#}", r.id())),
                        }
                    }
                }
                Err(e) => failures.lock().expect("lock").push(format!("{}: {e:#}", r.id())),
            }
        });
        let written = written.lock().expect("lock").clone();
        todo.par_iter().filter(|c| !written.contains(&c.id())).for_each(|cell| {
            let t = Instant::now();
            match ctx.run_cell(cell).and_then(|record| ctx.write_record(cell, record)) {
                Ok(()) => report_done(&cell.id(), t.elapsed().as_secs_f64()),
                Err(e) => {
                    bar.suspend(|| eprintln!("sweep: {} failed: {e:#}", cell.id()));
                    failures.lock().expect("lock").push(format!("{}: {e:#}", cell.id()));
                }
            }
        });
    });
    bar.finish_and_clear();
    let failures = failures.into_inner().expect("lock");
    let ran = finished.into_inner();
    let wall_seconds = t0.elapsed().as_secs_f64();
    let report = RunReport { ran, skipped, wall_seconds };
    write_run_file(opts, &report, failures.len())?;
    if !failures.is_empty() {
        bail!("{} cell(s) failed:\n  {}", failures.len(), failures.join("\n  "));
    }
    Ok(report)
}

/// Writes `plan.json` into `out`: the plan's options and the id and configuration hash of
/// every cell of `all` (the full list, whichever shard runs).
fn write_plan(out: &Path, plan: &Plan, all: &[Cell]) -> anyhow::Result<()> {
    let plan_json = json!({
        "quick": plan.quick,
        "materials": plan.materials,
        "shapes": plan.shapes,
        "cells": all.iter().map(|c| json!({ "id": c.id(), "hash": c.hash() })).collect::<Vec<_>>(),
    });
    heatsim::io::write_atomic(&out.join("plan.json"), (serde_json::to_string_pretty(&plan_json)? + "\n").as_bytes())
        .context("writing plan.json")
}

/// The cells of `mine` to run, and how many are skipped: with `resume`, those whose record in
/// `cells_dir` holds their current configuration hash.
fn cells_to_run(mine: Vec<Cell>, cells_dir: &Path, resume: bool) -> (Vec<Cell>, usize) {
    let mut todo = Vec::new();
    let mut skipped = 0;
    for cell in mine {
        let done = resume
            && read_cell(&cells_dir.join(format!("{}.json", cell.id())))
                .is_some_and(|v| v["hash"].as_str() == Some(cell.hash().as_str()));
        if done {
            skipped += 1;
        } else {
            todo.push(cell);
        }
    }
    (todo, skipped)
}

/// Writes the shard's run file `run_shard_K_of_N.json` into the output directory.
fn write_run_file(opts: &RunOptions, report: &RunReport, failed: usize) -> anyhow::Result<()> {
    let run_json = json!({
        "shard": format!("{}/{}", opts.shard.k, opts.shard.n),
        "jobs": opts.jobs,
        "ran": report.ran,
        "skipped": report.skipped,
        "failed": failed,
        "wall_seconds": report.wall_seconds,
        "quick": opts.plan.quick,
    });
    let name = format!("run_shard_{}_of_{}.json", opts.shard.k, opts.shard.n);
    heatsim::io::write_atomic(&opts.out.join(name), (serde_json::to_string_pretty(&run_json)? + "\n").as_bytes())?;
    Ok(())
}

struct Ctx<'a> {
    cells_dir: &'a Path,
    cache: &'a Path,
}

/// Reads a cached reference video; `None` when absent or not of the cell's shape.
fn read_video(path: &Path, cell: &Cell) -> Option<Video> {
    let file = std::fs::File::open(path).ok()?;
    let a = Array3::<f32>::read_npy(std::io::BufReader::new(file)).ok()?;
    let (frames, height, width) = a.dim();
    let schedule = heatsim::simulate::Schedule::new(&cell.scene.timing);
    if frames != schedule.frames
        || width != cell.scene.camera.width as usize
        || height != cell.scene.camera.height as usize
    {
        return None;
    }
    Some(Video {
        frames,
        pixels: width * height,
        width,
        height,
        times: (0..frames).map(|k| schedule.frame_time(k)).collect(),
        data: a.into_raw_vec_and_offset().0,
    })
}

impl Ctx<'_> {
    fn video_path(&self, cell: &Cell) -> PathBuf {
        self.cache.join("videos").join(format!("{}.npy", cell.hash()))
    }

    fn write_record(&self, cell: &Cell, record: Value) -> anyhow::Result<()> {
        let path = self.cells_dir.join(format!("{}.json", cell.id()));
        heatsim::io::write_atomic(&path, (serde_json::to_string_pretty(&record)? + "\n").as_bytes())
            .with_context(|| format!("writing {}", path.display()))
    }

    fn run_cell(&self, cell: &Cell) -> anyhow::Result<Value> {
        match &cell.spec {
            CellSpec::Thickness { .. } => {
                let reference = Cell::new(cell.spec.reference().expect("part-1 cells have one"), cell.quick)?;
                let ref_video = read_video(&self.video_path(&reference), &reference)
                    .with_context(|| format!("the reference video of {} is missing", reference.id()))?;
                Ok(self.run_thickness(cell, Some(&ref_video))?.0)
            }
            CellSpec::Convergence { .. } => Ok(self.run_thickness(cell, None)?.0),
            CellSpec::Surface { .. } => self.run_surface(cell),
        }
    }

    /// Part 1 and convergence: one volumetric run. A reference cell (1 mm) stores its video;
    /// other part-1 cells compare with `reference`.
    fn run_thickness(&self, cell: &Cell, reference: Option<&Video>) -> anyhow::Result<(Value, f64)> {
        let t = Instant::now();
        let (mesh, cached) = mesh_cached(&cell.scene, self.cache)?;
        let mesh_s = t.elapsed().as_secs_f64();
        let sim = heatsim::simulate::simulate_volumetric(&cell.scene, &mesh, |_, _| {})
            .with_context(|| format!("simulating {}", cell.id()))?;
        let data = heatsim::dataset::render(&cell.scene, &mesh.verts, &mesh.boundary, &sim)?;
        let video = Video::from_dataset(&data);
        let ambient = cell.scene.environment.ambient_temperature;
        let is_reference = cell.spec.is_reference();
        let result = match (&cell.spec, reference) {
            (CellSpec::Thickness { .. }, _) if is_reference => {
                let path = self.video_path(cell);
                let a = Array3::from_shape_vec((video.frames, video.height, video.width), video.data.clone())?;
                let mut bytes = Vec::new();
                a.write_npy(&mut bytes)?;
                heatsim::io::write_atomic(&path, &bytes).with_context(|| format!("writing {}", path.display()))?;
                let d = compare(&video, &video, ambient)?;
                json!({ "vs_reference": d, "mean_rise_k": video.mean_heating() - ambient })
            }
            (CellSpec::Thickness { .. }, Some(r)) => {
                let d = compare(&video, r, ambient)?;
                json!({ "vs_reference": d, "mean_rise_k": video.mean_heating() - ambient })
            }
            (CellSpec::Thickness { .. }, None) => bail!("{}: no reference video", cell.id()),
            _ => json!({ "mean_rise_k": video.mean_heating() - ambient }),
        };
        let seconds = t.elapsed().as_secs_f64();
        let record = record(
            cell,
            result,
            &mesh,
            cached,
            json!({ "mesh": mesh_s, "volumetric": sim.report.stepping_seconds + sim.report.assembly_seconds + sim.report.factorisation_seconds, "total": seconds }),
        );
        Ok((record, seconds))
    }

    /// Part 2: volumetric, surface and surface_effective on one mesh.
    fn run_surface(&self, cell: &Cell) -> anyhow::Result<Value> {
        let t = Instant::now();
        let (mesh, cached) = mesh_cached(&cell.scene, self.cache)?;
        let mesh_s = t.elapsed().as_secs_f64();
        let tv = Instant::now();
        let sim = heatsim::simulate::simulate_volumetric(&cell.scene, &mesh, |_, _| {})
            .with_context(|| format!("simulating {} (volumetric)", cell.id()))?;
        let data = heatsim::dataset::render(&cell.scene, &mesh.verts, &mesh.boundary, &sim)?;
        let truth = Video::from_dataset(&data);
        drop(data);
        let vol_s = tv.elapsed().as_secs_f64();
        let ambient = cell.scene.environment.ambient_temperature;
        let mut models = serde_json::Map::new();
        let ts = Instant::now();
        for (model, factor) in [("surface", None), ("surface_effective", Some(effective_factor()))] {
            let mut scene = cell.scene.clone();
            scene.solver.kind = SolverKind::Surface;
            scene.solver.effective_thickness_factor = factor;
            let layer = heatsim::simulate::surface_layer_thickness(&scene)?;
            let s = heatsim::simulate::simulate_surface(&scene, &mesh, |_, _| {})
                .with_context(|| format!("simulating {} ({model})", cell.id()))?;
            let data = heatsim::dataset::render(&scene, &s.visible.verts, &s.visible.tris, &s)?;
            let d = compare(&Video::from_dataset(&data), &truth, ambient)?;
            models.insert(model.to_string(), json!({ "diff": d, "layer_thickness_m": layer }));
        }
        let surf_s = ts.elapsed().as_secs_f64();
        let result = json!({
            "volumetric_mean_rise_k": truth.mean_heating() - ambient,
            "models": models,
        });
        Ok(record(
            cell,
            result,
            &mesh,
            cached,
            json!({ "mesh": mesh_s, "volumetric": vol_s, "surface": surf_s, "total": t.elapsed().as_secs_f64() }),
        ))
    }
}

fn record(cell: &Cell, result: Value, mesh: &heatsim::mesh::tetmesh::TetMesh, cached: bool, seconds: Value) -> Value {
    json!({
        "id": cell.id(),
        "hash": cell.hash(),
        "spec": cell.spec,
        "result": result,
        "mesh": {
            "nodes": mesh.verts.len(),
            "tetrahedra": mesh.tets.len(),
            "surface_element_size_m": cell.scene.meshing.surface_element_size,
            "fine_layer_depth_m": cell.scene.meshing.fine_layer_depth,
            "from_cache": cached,
        },
        "seconds": seconds,
        "config": cell.config(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_parsing() {
        assert_eq!("2/4".parse::<Shard>().unwrap(), Shard { k: 2, n: 4 });
        assert!("3/2".parse::<Shard>().unwrap_err().contains("1 <= K <= N"));
        assert!("0/2".parse::<Shard>().is_err());
        assert!("2".parse::<Shard>().unwrap_err().contains("K/N"));
        assert!("a/2".parse::<Shard>().is_err());
    }

    #[test]
    fn shards_partition_the_cells() {
        let plan =
            Plan::new(true, vec!["steel".into(), "glass".into()], vec![super::super::cells::Shape::Cuboid]).unwrap();
        let ids: Vec<String> = plan.cells().unwrap().iter().map(|c| c.id()).collect();
        let mut seen = Vec::new();
        for k in 1..=3 {
            let shard = Shard { k, n: 3 };
            let part: Vec<String> =
                ids.iter().enumerate().filter(|(i, _)| shard.owns(*i)).map(|(_, id)| id.clone()).collect();
            assert!(!part.is_empty());
            seen.extend(part);
        }
        seen.sort();
        let mut all = ids.clone();
        all.sort();
        assert_eq!(seen, all);
    }
}
