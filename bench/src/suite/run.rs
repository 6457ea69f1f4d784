//! `simbench suite run`: every case of a suite (or of one shard) through one method, scored.
//!
//! A run folder holds `run.json` (the suite's version, the method's signature, the shard and
//! its cases), `cases/<case>.json` (one record per finished case, written atomically) and
//! `recon/<case>.obj|ply` (each reconstruction). A case's work happens in `work/<case>/` (its
//! inputs, the method's output and log), removed once it is scored unless `--keep-work`.
//! Running again into the same folder resumes: cases with a record are skipped (failed ones
//! too: a failure is a result); a folder of another suite version, method or shard is refused.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, ensure, Context};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use super::manifest::{verify_files, CaseEntry, Manifest};
use super::method::Method;
use super::process::Failure;

/// The run's description file.
pub const RUN_FILE: &str = "run.json";
/// One record per case.
pub const CASES_DIR: &str = "cases";
/// Layout version of a run folder.
pub const RUN_FORMAT: u32 = 1;

/// A shard `K/N`: the cases whose index i (0-based, manifest order) has i % N == K - 1.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    pub k: usize,
    pub n: usize,
}

impl Shard {
    /// Parses `K/N` with 1 <= K <= N.
    ///
    /// # Errors
    /// Anything else, saying what is wrong.
    pub fn parse(s: &str) -> anyhow::Result<Shard> {
        let (k, n) = s.split_once('/').with_context(|| format!("--shard `{s}`: expected K/N, e.g. 1/4"))?;
        let (k, n): (usize, usize) = (
            k.trim().parse().with_context(|| format!("--shard `{s}`: K is not a number"))?,
            n.trim().parse().with_context(|| format!("--shard `{s}`: N is not a number"))?,
        );
        ensure!(n >= 1 && (1..=n).contains(&k), "--shard `{s}`: K must be 1 to N (shards 1/{n} to {n}/{n})");
        Ok(Shard { k, n })
    }

    pub fn contains(&self, index: usize) -> bool {
        index % self.n == self.k - 1
    }
}

/// `run.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunInfo {
    pub format: u32,
    pub suite_version: String,
    pub suite_name: String,
    pub method: Value,
    pub label: String,
    pub shard: Option<Shard>,
    /// The case ids this run covers, in manifest order.
    pub cases: Vec<String>,
}

impl RunInfo {
    /// Reads `RUN/run.json`.
    ///
    /// # Errors
    /// Not a run folder, another format.
    pub fn read(run: &Path) -> anyhow::Result<RunInfo> {
        let path = run.join(RUN_FILE);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("{}: not a suite run (no readable {RUN_FILE})", run.display()))?;
        let info: RunInfo = serde_json::from_str(&text).with_context(|| format!("{}: malformed", path.display()))?;
        ensure!(
            info.format == RUN_FORMAT,
            "{}: run format {} but this simbench reads {RUN_FORMAT}",
            path.display(),
            info.format
        );
        Ok(info)
    }

    /// The records of every case, in order; `None` for cases without one yet.
    ///
    /// # Errors
    /// A record that exists but does not parse, naming it.
    pub fn records(&self, run: &Path) -> anyhow::Result<Vec<Option<Value>>> {
        self.cases
            .iter()
            .map(|id| {
                let p = run.join(CASES_DIR).join(format!("{id}.json"));
                match std::fs::read_to_string(&p) {
                    Ok(t) => Ok(Some(
                        serde_json::from_str(&t).with_context(|| format!("{}: malformed record", p.display()))?,
                    )),
                    Err(_) => Ok(None),
                }
            })
            .collect()
    }

    /// Every record, or an error naming the cases without one.
    ///
    /// # Errors
    /// Missing or malformed records.
    pub fn complete_records(&self, run: &Path) -> anyhow::Result<Vec<Value>> {
        let recs = self.records(run)?;
        let missing: Vec<&str> =
            self.cases.iter().zip(&recs).filter(|(_, r)| r.is_none()).map(|(c, _)| c.as_str()).collect();
        ensure!(
            missing.is_empty(),
            "{}: incomplete run, {} of {} cases have no record (e.g. {}); resume it with `simbench suite run`",
            run.display(),
            missing.len(),
            self.cases.len(),
            missing[0]
        );
        Ok(recs.into_iter().flatten().collect())
    }
}

/// What `simbench suite run` was asked to do.
pub struct Options {
    pub suite: PathBuf,
    pub out: PathBuf,
    pub method: Method,
    /// Wall-clock limit of the method on one case, s.
    pub timeout_s: f64,
    pub shard: Option<Shard>,
    /// The simbench executable (for the built-in method).
    pub exe: PathBuf,
    pub keep_work: bool,
}

/// Runs the cases (module documentation); returns (ran, skipped, failed).
///
/// # Errors
/// An unreadable or altered suite, a run folder of another suite, method or shard. A failing
/// case is recorded, not an error.
pub fn run(opts: &Options) -> anyhow::Result<(usize, usize, usize)> {
    let manifest = Manifest::read(&opts.suite)?;
    let checked = verify_files(&opts.suite, &manifest)?;
    eprintln!("suite run: {} ({checked} stored files verified), method {}", manifest.version, opts.method.label());
    let cases: Vec<&CaseEntry> = manifest
        .cases
        .iter()
        .enumerate()
        .filter(|(i, _)| opts.shard.is_none_or(|s| s.contains(*i)))
        .map(|(_, c)| c)
        .collect();
    let info = RunInfo {
        format: RUN_FORMAT,
        suite_version: manifest.version.clone(),
        suite_name: manifest.spec.name.clone(),
        method: opts.method.signature(),
        label: opts.method.label(),
        shard: opts.shard,
        cases: cases.iter().map(|c| c.id.clone()).collect(),
    };
    open_run(&opts.out, &info)?;
    // The bounds travel with the run, so that its report can print them.
    if let Ok(bytes) = std::fs::read(opts.suite.join("bounds.json")) {
        heatsim::io::write_atomic(&opts.out.join("bounds.json"), &bytes).context("writing bounds.json")?;
    }
    let (mut ran, mut skipped, mut failed) = (0, 0, 0);
    for (i, case) in cases.iter().enumerate() {
        let record_path = opts.out.join(CASES_DIR).join(format!("{}.json", case.id));
        if record_path.is_file() {
            skipped += 1;
            continue;
        }
        let t = Instant::now();
        let rec = run_case(opts, &manifest, case);
        let ok = rec["status"] == "ok";
        failed += usize::from(!ok);
        ran += 1;
        let what = if ok {
            format!("mae {:.3} mm", rec["scores"]["mae_mm"].as_f64().unwrap_or(f64::NAN))
        } else {
            format!(
                "FAILED ({}): {}",
                rec["failure"]["kind"].as_str().unwrap_or("?"),
                rec["failure"]["message"].as_str().unwrap_or("")
            )
        };
        eprintln!("suite run: [{}/{}] {} {what} ({:.1} s)", i + 1, cases.len(), case.id, t.elapsed().as_secs_f64());
        heatsim::io::write_atomic(&record_path, (serde_json::to_string_pretty(&rec)? + "\n").as_bytes())
            .with_context(|| format!("writing {}", record_path.display()))?;
    }
    Ok((ran, skipped, failed))
}

/// Creates the run folder, or checks that an existing one is this run (resume).
fn open_run(out: &Path, info: &RunInfo) -> anyhow::Result<()> {
    let path = out.join(RUN_FILE);
    if path.exists() {
        let old = RunInfo::read(out)?;
        if old.suite_version != info.suite_version {
            bail!(
                "{} is a run of suite {}, not {}; choose another --out",
                out.display(),
                old.suite_version,
                info.suite_version
            );
        }
        if old.method != info.method || old.shard != info.shard {
            bail!(
                "{} is a run of {} (shard {:?}); this is {} (shard {:?}): choose another --out",
                out.display(),
                old.label,
                old.shard,
                info.label,
                info.shard
            );
        }
        eprintln!("suite run: resuming {}", out.display());
    }
    for d in [CASES_DIR, "recon", "work"] {
        std::fs::create_dir_all(out.join(d)).with_context(|| format!("creating {}", out.join(d).display()))?;
    }
    heatsim::io::write_atomic(&path, (serde_json::to_string_pretty(info)? + "\n").as_bytes())
        .context("writing run.json")
}

/// Runs and scores one case; never fails: a failure is in the record.
fn run_case(opts: &Options, manifest: &Manifest, case: &CaseEntry) -> Value {
    let work = opts.out.join("work").join(&case.id);
    let mut seconds = serde_json::Map::new();
    let result = run_case_inner(opts, case, &work, &mut seconds);
    let mut rec = json!({
        "case": case.id, "object": case.object, "noise": case.noise, "seed": case.seed,
        "seconds": seconds,
    });
    if let Ok(o) = manifest.object_of(case) {
        rec["solver"] = json!(o.solver);
        rec["shape"] = json!(o.object);
    }
    match result {
        Ok((scores, recon)) => {
            rec["status"] = json!("ok");
            rec["scores"] = scores;
            rec["recon"] = json!(recon);
        }
        Err(f) => {
            rec["status"] = json!("failed");
            rec["failure"] = json!(f);
        }
    }
    if !opts.keep_work {
        let _ = std::fs::remove_dir_all(&work);
    }
    rec
}

fn run_case_inner(
    opts: &Options,
    case: &CaseEntry,
    work: &Path,
    seconds: &mut serde_json::Map<String, Value>,
) -> Result<(Value, String), Failure> {
    let t = Instant::now();
    if work.exists() {
        std::fs::remove_dir_all(work)
            .map_err(|e| Failure::new("inputs", format!("clearing {}: {e}", work.display())))?;
    }
    super::inputs::write_case_inputs(&opts.suite, case, work, opts.method.wants_lamps())
        .map_err(|e| Failure::new("inputs", format!("{e:#}")))?;
    seconds.insert("inputs".into(), json!(t.elapsed().as_secs_f64()));
    let truth = super::inputs::store_dir(&opts.suite, case, "left");
    let t = Instant::now();
    let result = opts.method.run(&case.id, work, &truth, &opts.exe, opts.timeout_s);
    seconds.insert("method".into(), json!(t.elapsed().as_secs_f64()));
    let file = result?;
    let mesh = heatsim::mesh::read_surface(&file)
        .map_err(|e| Failure::new("malformed_output", format!("{}: {e}", file.display())))?;
    let t = Instant::now();
    let scores = super::score::score(&mesh, &truth).map_err(|e| Failure::new("scoring", format!("{e:#}")))?;
    seconds.insert("score".into(), json!(t.elapsed().as_secs_f64()));
    let ext = file.extension().and_then(|e| e.to_str()).unwrap_or("obj");
    let kept = format!("recon/{}.{ext}", case.id);
    std::fs::copy(&file, opts.out.join(&kept))
        .map_err(|e| Failure::new("scoring", format!("keeping {}: {e}", file.display())))?;
    Ok((scores, kept))
}
