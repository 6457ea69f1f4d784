//! Running the rows: generate the object, `simbench simulate`, `simbench reconstruct`, score
//! with [`heatrecon::eval::evaluate`], render, and write one JSON record per row atomically.
//!
//! Simulation and reconstruction run as child processes of this same executable (the command
//! line is the contract, so the table always measures what `simbench reconstruct` does at the
//! time; a crash, a missing feature or a time-out of the child becomes the row's recorded
//! failure instead of ending the run). Each row works in `OUT/work/<id>/` (the generated OBJ,
//! the scene, the datasets, the reconstruction, logs); its record `OUT/cells/<id>.json` holds
//! the SHA-256 of its configuration, and `--resume` skips rows whose record has `status: "ok"`
//! and the same hash (failed rows always run again).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use anyhow::Context;
use heatrecon::eval::{crop_to_view, evaluate, AlignMode, CropTolerance, DepthView, EvalOptions, Evaluation};
use heatsim::mesh::{read_surface, TriMesh};
use rayon::prelude::*;
use serde_json::{json, Value};

use super::cells::{self, RowSpec, Setup};
use super::render;

/// Sub-directory of the output directory with one JSON record per row.
pub const CELLS_DIR: &str = "cells";
/// Sub-directory with the per-row work directories (large; not committed).
pub const WORK_DIR: &str = "work";
/// Sub-directory with the PNG renders.
pub const RENDERS_DIR: &str = "renders";

/// What `simbench table shape-error` was asked to do.
pub struct Options {
    pub rows: Vec<RowSpec>,
    pub setup: Setup,
    pub out: PathBuf,
    pub resume: bool,
    pub jobs: usize,
    /// Wall-clock limit of each child process, s.
    pub timeout_s: f64,
    /// Keep the videos in the work directories.
    pub keep_work: bool,
    /// The executable to run `simulate` and `reconstruct` with.
    pub exe: PathBuf,
    /// Run nothing: rebuild the tables from the stored records (all rows must have one with
    /// the current hash).
    pub report_only: bool,
}

/// A prepared row: its scene, configuration and hash.
struct Prepared {
    row: RowSpec,
    scene: Value,
    obj: Option<(Vec<u8>, f64)>,
    config: Value,
    hash: String,
}

fn prepare(row: &RowSpec, setup: &Setup) -> anyhow::Result<Prepared> {
    let obj = match row.object.revolved() {
        Some(r) => Some(r.obj_file(setup.object_spacing_m)?),
        None => None,
    };
    let scene = cells::scene_json(row, setup, obj.as_ref().map(|(_, s)| ("object.obj", *s)))?;
    let sha = obj.as_ref().map(|(b, _)| crate::sweep::cells::sha256_hex(b));
    let config = cells::config(row, setup, &scene, sha.as_deref());
    let hash = cells::hash(&config);
    Ok(Prepared { row: row.clone(), scene, obj, config, hash })
}

/// What a run did.
#[derive(Debug)]
pub struct Report {
    pub ran: usize,
    pub skipped: usize,
    pub failed: usize,
    pub wall_seconds: f64,
}

/// The stored record of a row, if it exists and parses.
pub fn read_record(path: &Path) -> Option<Value> {
    let v: Value = serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()?;
    v.get("hash")?.as_str()?;
    Some(v)
}

/// Runs the rows (see the module documentation) and returns the records of all of them, in
/// plan order.
pub fn run(opts: &Options) -> anyhow::Result<(Vec<Value>, Report)> {
    let t0 = Instant::now();
    let cells_dir = opts.out.join(CELLS_DIR);
    let prepared: Vec<Prepared> =
        opts.rows.iter().map(|r| prepare(r, &opts.setup).with_context(|| r.id())).collect::<anyhow::Result<_>>()?;
    let record_path = |p: &Prepared| cells_dir.join(format!("{}.json", p.row.id()));
    let mut todo = Vec::new();
    let mut skipped = 0;
    for p in &prepared {
        let done = opts.resume
            && read_record(&record_path(p))
                .is_some_and(|v| v["hash"].as_str() == Some(&p.hash) && v["status"].as_str() == Some("ok"));
        if opts.report_only {
            let current = read_record(&record_path(p)).is_some_and(|v| v["hash"].as_str() == Some(&p.hash));
            anyhow::ensure!(
                current,
                "--report-only: {} has no record with the current configuration hash; run without --report-only",
                p.row.id()
            );
            skipped += 1;
        } else if done {
            skipped += 1;
        } else {
            todo.push(p);
        }
    }
    for d in [&cells_dir, &opts.out.join(WORK_DIR), &opts.out.join(RENDERS_DIR)] {
        std::fs::create_dir_all(d).with_context(|| format!("creating {}", d.display()))?;
    }
    let plan = json!({
        "setup": opts.setup,
        "rows": prepared.iter().map(|p| json!({ "id": p.row.id(), "hash": p.hash })).collect::<Vec<_>>(),
    });
    heatsim::io::write_atomic(&opts.out.join("plan.json"), (serde_json::to_string_pretty(&plan)? + "\n").as_bytes())
        .context("writing plan.json")?;
    eprintln!("table: {} rows to run, {} already done (resume), {} jobs", todo.len(), skipped, opts.jobs);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(opts.jobs).build().context("starting the thread pool")?;
    let failed = Mutex::new(0usize);
    let write_errors = Mutex::new(Vec::<String>::new());
    pool.install(|| {
        todo.par_iter().for_each(|p| {
            let t = Instant::now();
            eprintln!("table: {} ...", p.row.id());
            let rec = run_row(p, opts);
            let ok = rec["status"] == "ok";
            if !ok {
                *failed.lock().expect("lock") += 1;
            }
            eprintln!(
                "table: {} {} in {:.1} s{}",
                p.row.id(),
                if ok { "done" } else { "FAILED" },
                t.elapsed().as_secs_f64(),
                if ok {
                    format!(": mae {:.3} mm", rec["mae_mm"].as_f64().unwrap_or(f64::NAN))
                } else {
                    format!(" ({}): {}", rec["failed_stage"].as_str().unwrap_or("?"), first_line(&rec["error"]))
                }
            );
            let path = record_path(p);
            let text = serde_json::to_string_pretty(&rec).unwrap_or_default() + "\n";
            if let Err(e) = heatsim::io::write_atomic(&path, text.as_bytes()) {
                write_errors.lock().expect("lock").push(format!("writing {}: {e}", path.display()));
            }
        });
    });
    let write_errors = write_errors.into_inner().expect("lock");
    if !write_errors.is_empty() {
        anyhow::bail!("{}", write_errors.join("\n"));
    }
    let records: Vec<Value> = prepared
        .iter()
        .map(|p| {
            read_record(&record_path(p))
                .with_context(|| format!("the record {} is missing or unreadable", record_path(p).display()))
        })
        .collect::<anyhow::Result<_>>()?;
    let report = Report {
        ran: todo.len(),
        skipped,
        failed: failed.into_inner().expect("lock"),
        wall_seconds: t0.elapsed().as_secs_f64(),
    };
    Ok((records, report))
}

fn first_line(v: &Value) -> String {
    v.as_str().unwrap_or("").lines().next().unwrap_or("").chars().take(200).collect()
}

/// Why and where a row failed.
struct Failure {
    stage: &'static str,
    error: anyhow::Error,
}

fn at<T>(stage: &'static str, r: anyhow::Result<T>) -> Result<T, Failure> {
    r.map_err(|error| Failure { stage, error })
}

/// Runs one row; never fails: a failure is recorded in the returned record.
fn run_row(p: &Prepared, opts: &Options) -> Value {
    let t0 = Instant::now();
    let mut seconds = serde_json::Map::new();
    let mut extra = serde_json::Map::new();
    let result = run_row_inner(p, opts, &mut seconds, &mut extra);
    seconds.insert("total".into(), json!(t0.elapsed().as_secs_f64()));
    let row = &p.row;
    let mut rec = json!({
        "id": row.id(),
        "hash": p.hash,
        "object": row.object.name(),
        "solver": row.solver.name(),
        "thickness_m": row.thickness_m,
        "netd_mK": row.netd_mk,
        "seconds": seconds,
        "config": p.config,
    });
    for (k, v) in extra {
        rec[k] = v;
    }
    match result {
        Ok(()) => rec["status"] = json!("ok"),
        Err(f) => {
            rec["status"] = json!("failed");
            rec["failed_stage"] = json!(f.stage);
            rec["error"] = json!(format!("{:#}", f.error));
        }
    }
    if !opts.keep_work {
        clean_work(&opts.out.join(WORK_DIR).join(row.id()));
    }
    rec
}

fn run_row_inner(
    p: &Prepared,
    opts: &Options,
    seconds: &mut serde_json::Map<String, Value>,
    extra: &mut serde_json::Map<String, Value>,
) -> Result<(), Failure> {
    let id = p.row.id();
    let work = opts.out.join(WORK_DIR).join(&id);
    let clock = Instant::now();
    at("prepare", prepare_work(&work, p))?;
    // 1. Simulate both lamp configurations.
    let dataset = work.join("dataset");
    let mut args: Vec<String> = vec!["simulate".into(), work.join("scene.json").display().to_string()];
    args.extend(["--out".into(), dataset.display().to_string(), "--vtu-frames".into(), "0".into()]);
    let t = Instant::now();
    at("simulate", run_child(&opts.exe, &args, &work.join("simulate.log"), opts.timeout_s))?;
    seconds.insert("simulate".into(), json!(t.elapsed().as_secs_f64()));
    // 2. Reconstruct.
    let recon = work.join("recon");
    let mut args: Vec<String> = vec![
        "reconstruct".into(),
        dataset.join("left").display().to_string(),
        dataset.join("right").display().to_string(),
        "--out".into(),
        recon.display().to_string(),
    ];
    args.extend(opts.setup.reconstruct_args.iter().cloned());
    // A metric reconstruction from the material's diffusivity, as the paper (which takes it
    // from its material table), unless the arguments fix the scale otherwise.
    if !opts.setup.reconstruct_args.iter().any(|a| a.contains("diffusivity") || a == "--distance") {
        let (name, _) = p.row.object.material_and_wall();
        let material =
            at("reconstruct", heatsim::scene::lookup_material(name).context(format!("unknown material {name}")))?;
        args.extend(["--diffusivity".into(), format!("{:e}", material.diffusivity())]);
    }
    let t = Instant::now();
    let r = run_child(&opts.exe, &args, &work.join("reconstruct.log"), opts.timeout_s);
    seconds.insert("reconstruct".into(), json!(t.elapsed().as_secs_f64()));
    at("reconstruct", r)?;
    if let Ok(text) = std::fs::read_to_string(recon.join("stage2.json")) {
        if let Ok(v) = serde_json::from_str::<Value>(&text) {
            extra.insert("reconstruction".into(), v);
        }
    }
    let recon_file = recon.join("recon_world.obj");
    let recon_mesh = at(
        "reconstruct",
        if recon_file.is_file() {
            read_surface(&recon_file).with_context(|| format!("reading {}", recon_file.display()))
        } else {
            Err(anyhow::anyhow!(
                "`simbench reconstruct {}` wrote no recon_world.obj (the shape stage did not run; its log: {})",
                opts.setup.reconstruct_args.join(" "),
                work.join("reconstruct.log").display()
            ))
        },
    )?;
    // 3. Evaluate against the visible ground truth, cropped to what the camera saw.
    let t = Instant::now();
    let left = dataset.join("left");
    let gt = at("evaluate", load_gt(&left))?;
    let e = at("evaluate", evaluate(&recon_mesh, &gt, &EvalOptions::default()).map_err(anyhow::Error::from))?;
    extra.insert("mae_mm".into(), json!(e.mae_mm()));
    extra.insert("symmetric_mm".into(), json!(e.symmetric_mm()));
    extra.insert("rmse_mm".into(), json!(e.forward.rmse * 1e3));
    extra.insert("normal_deg".into(), json!(e.normal_deg));
    let mut rigid = e.to_json();
    rigid.as_object_mut().map(|m| m.remove("definitions"));
    extra.insert("eval_rigid".into(), rigid);
    let sim = evaluate(&recon_mesh, &gt, &EvalOptions { align: AlignMode::Similarity, ..EvalOptions::default() });
    match sim {
        Ok(s) => {
            extra.insert("similarity_mae_mm".into(), json!(s.mae_mm()));
            extra.insert("similarity_scale".into(), json!(s.alignment.transform.scale));
        }
        Err(err) => {
            extra.insert("similarity_error".into(), json!(err.to_string()));
        }
    }
    seconds.insert("evaluate".into(), json!(t.elapsed().as_secs_f64()));
    // 4. Render and keep the aligned reconstruction with its signed errors.
    let t = Instant::now();
    at("render", write_aligned_ply(&work.join("aligned.ply"), &e))?;
    let png = at("render", render::error_figure(&gt, &e, &id))?;
    let path = opts.out.join(RENDERS_DIR).join(format!("{id}.png"));
    at("render", heatsim::io::write_atomic(&path, &png).with_context(|| format!("writing {}", path.display())))?;
    seconds.insert("render".into(), json!(t.elapsed().as_secs_f64()));
    extra.insert("render".into(), json!(format!("{RENDERS_DIR}/{id}.png")));
    // The row's seconds column: simulation + reconstruction + evaluation.
    seconds.insert("pipeline".into(), json!(clock.elapsed().as_secs_f64()));
    Ok(())
}

fn prepare_work(work: &Path, p: &Prepared) -> anyhow::Result<()> {
    if work.exists() {
        std::fs::remove_dir_all(work).with_context(|| format!("clearing {}", work.display()))?;
    }
    std::fs::create_dir_all(work).with_context(|| format!("creating {}", work.display()))?;
    if let Some((bytes, _)) = &p.obj {
        heatsim::io::write_atomic(&work.join("object.obj"), bytes)?;
    }
    heatsim::io::write_atomic(&work.join("scene.json"), (serde_json::to_string_pretty(&p.scene)? + "\n").as_bytes())?;
    Ok(())
}

/// The ground truth of a dataset: `gt_mesh.obj` cropped to the pixels the camera saw.
pub fn load_gt(dataset: &Path) -> anyhow::Result<TriMesh> {
    let path = dataset.join("gt_mesh.obj");
    let full = read_surface(&path).with_context(|| format!("reading {}", path.display()))?;
    let view =
        DepthView::load(dataset)?.with_context(|| format!("{}: no camera.json and gt_depth.npy", dataset.display()))?;
    Ok(crop_to_view(&full, &view, &CropTolerance::default())
        .with_context(|| format!("cropping {}", path.display()))?
        .mesh)
}

fn write_aligned_ply(path: &Path, e: &Evaluation) -> anyhow::Result<()> {
    let signed: Vec<f32> = e.vertex_signed_m.iter().map(|&v| v as f32).collect();
    let mut bytes = Vec::new();
    heatsim::mesh::write_ply_to(
        &mut bytes,
        &e.aligned,
        &[("signed_error_m", &signed)],
        "reconstruction aligned (rigid ICP) to the ground truth; signed_error_m: m, positive outside",
    )?;
    heatsim::io::write_atomic(path, &bytes).with_context(|| format!("writing {}", path.display()))
}

/// Runs `exe args`, stdout and stderr into `log`; fails with the log's tail on a non-zero exit,
/// a signal or after `timeout_s`.
fn run_child(exe: &Path, args: &[String], log: &Path, timeout_s: f64) -> anyhow::Result<()> {
    let file = std::fs::File::create(log).with_context(|| format!("creating {}", log.display()))?;
    let err = file.try_clone()?;
    let mut child = Command::new(exe)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::from(file))
        .stderr(Stdio::from(err))
        .spawn()
        .with_context(|| format!("starting {}", exe.display()))?;
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait()? {
            break s;
        }
        if start.elapsed().as_secs_f64() > timeout_s {
            let _ = child.kill();
            let _ = child.wait();
            anyhow::bail!(
                "`simbench {}` did not finish within {timeout_s} s (--timeout); log {}",
                args.join(" "),
                log.display()
            );
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    if status.success() {
        return Ok(());
    }
    let text = std::fs::read_to_string(log).unwrap_or_default();
    let error_lines: Vec<&str> = text.lines().filter(|l| l.starts_with("error")).collect();
    let tail: Vec<&str> = if error_lines.is_empty() {
        let all: Vec<&str> = text.lines().collect();
        all[all.len().saturating_sub(5)..].to_vec()
    } else {
        error_lines
    };
    anyhow::bail!(
        "`simbench {}` exited with {status}: {}",
        args.first().map(String::as_str).unwrap_or(""),
        tail.join(" | ")
    )
}

/// Removes the large files of a work directory (videos, temperatures, VTU), keeping the scene,
/// logs, ground truth, reconstruction and the aligned PLY.
fn clean_work(work: &Path) {
    let big = ["video.npy", "video_clean.npy", "node_temperatures.npy", "visible_temperatures.npy", "boundary.vtu"];
    for cfg in ["left", "right"] {
        for f in big {
            let _ = std::fs::remove_file(work.join("dataset").join(cfg).join(f));
        }
    }
}
