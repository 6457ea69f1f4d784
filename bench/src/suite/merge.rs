//! `simbench suite merge RUN_1 ... RUN_N --out RUN`: joins the shard runs `--shard 1/N` to
//! `N/N` of one suite and method (a cluster job array) into one complete run.
//!
//! Shard K holds the cases i with i % N == K - 1, in order, so case j of shard K is case
//! j N + K - 1 of the suite: the merged run lists them in the suite's order. The merged folder
//! is written next to `--out` and renamed into place once complete.

use std::path::{Path, PathBuf};

use anyhow::{bail, ensure, Context};

use super::run::{RunInfo, Shard, CASES_DIR, RUN_FILE};

/// Merges `runs` into `out` and returns the merged run's description.
///
/// # Errors
/// Runs of different suites or methods, not a complete set of shards 1/N..N/N, an incomplete
/// shard, an existing `out`.
pub fn merge(runs: &[PathBuf], out: &Path) -> anyhow::Result<RunInfo> {
    ensure!(!runs.is_empty(), "give the shard runs to merge");
    ensure!(!out.exists(), "{} exists; merge into a new folder", out.display());
    let mut shards: Vec<(Shard, RunInfo, &PathBuf)> = Vec::new();
    for r in runs {
        let info = RunInfo::read(r)?;
        let shard = info.shard.with_context(|| format!("{}: not a shard run (no --shard)", r.display()))?;
        info.complete_records(r)?;
        shards.push((shard, info, r));
    }
    let first = shards[0].1.clone();
    for (s, info, path) in &shards {
        ensure!(
            info.suite_version == first.suite_version,
            "{}: suite {} but {} is suite {}",
            path.display(),
            info.suite_version,
            shards[0].2.display(),
            first.suite_version
        );
        ensure!(
            info.method == first.method,
            "{}: method {} but {} ran {}",
            path.display(),
            info.label,
            shards[0].2.display(),
            first.label
        );
        ensure!(
            s.n == shards[0].0.n,
            "{}: shard {}/{} but {} is of {} shards",
            path.display(),
            s.k,
            s.n,
            shards[0].2.display(),
            shards[0].0.n
        );
    }
    let n = shards[0].0.n;
    shards.sort_by_key(|(s, _, _)| s.k);
    let ks: Vec<usize> = shards.iter().map(|(s, _, _)| s.k).collect();
    if ks != (1..=n).collect::<Vec<_>>() {
        bail!(
            "need exactly the shards 1/{n} to {n}/{n} once each, got {}",
            ks.iter().map(|k| format!("{k}/{n}")).collect::<Vec<_>>().join(", ")
        );
    }
    let total: usize = shards.iter().map(|(_, i, _)| i.cases.len()).sum();
    let mut order: Vec<Option<(String, &PathBuf)>> = vec![None; total];
    for (s, info, path) in &shards {
        for (j, c) in info.cases.iter().enumerate() {
            let i = j * n + s.k - 1;
            ensure!(
                i < total && order[i].is_none(),
                "{}: its cases do not interleave with the other shards'",
                path.display()
            );
            order[i] = Some((c.clone(), path));
        }
    }
    let order: Vec<(String, &PathBuf)> =
        order.into_iter().collect::<Option<_>>().context("the shards' cases leave gaps")?;
    let merged = RunInfo { shard: None, cases: order.iter().map(|(c, _)| c.clone()).collect(), ..first.clone() };
    write(out, &merged, &order)?;
    Ok(merged)
}

/// Writes the merged folder beside `out`, then renames it into place.
fn write(out: &Path, merged: &RunInfo, order: &[(String, &PathBuf)]) -> anyhow::Result<()> {
    let tmp = out.with_extension("merging");
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).with_context(|| format!("clearing {}", tmp.display()))?;
    }
    for d in [CASES_DIR, "recon"] {
        std::fs::create_dir_all(tmp.join(d)).with_context(|| format!("creating {}", tmp.join(d).display()))?;
    }
    for (case, run) in order {
        let name = format!("{case}.json");
        std::fs::copy(run.join(CASES_DIR).join(&name), tmp.join(CASES_DIR).join(&name))
            .with_context(|| format!("copying {}", run.join(CASES_DIR).join(&name).display()))?;
        for ext in ["obj", "ply"] {
            let recon = run.join("recon").join(format!("{case}.{ext}"));
            if recon.is_file() {
                std::fs::copy(&recon, tmp.join("recon").join(format!("{case}.{ext}")))
                    .with_context(|| format!("copying {}", recon.display()))?;
            }
        }
    }
    if let Some((_, run)) = order.first() {
        if run.join("bounds.json").is_file() {
            std::fs::copy(run.join("bounds.json"), tmp.join("bounds.json")).context("copying bounds.json")?;
        }
    }
    std::fs::write(tmp.join(RUN_FILE), serde_json::to_string_pretty(merged)? + "\n").context("writing run.json")?;
    std::fs::rename(&tmp, out).with_context(|| format!("moving {} to {}", tmp.display(), out.display()))
}
