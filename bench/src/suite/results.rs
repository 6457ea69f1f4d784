//! A run's case records read back as typed results, grouped per object and noise level.

use std::path::Path;

use anyhow::Context;
use serde::Serialize;
use serde_json::Value;

use super::run::RunInfo;
use super::spec::NoiseLevel;

/// One case's outcome.
#[derive(Clone, Debug, Serialize)]
pub struct CaseResult {
    pub case: String,
    /// The object configuration's id.
    pub object: String,
    pub noise: NoiseLevel,
    pub seed: u32,
    /// `None` when the case succeeded; else the failure's kind.
    pub failure: Option<String>,
    /// Rigid MAE, mm.
    pub mae_mm: f64,
    /// MAE after a similarity alignment, mm.
    pub similarity_mae_mm: f64,
    /// Mean depth over the true mean depth, minus 1.
    pub size_error: f64,
    /// Rotation of the rigid alignment, deg.
    pub rotation_deg: f64,
    /// The method's wall time, s.
    pub method_s: f64,
}

impl CaseResult {
    /// Reads a case record.
    ///
    /// # Errors
    /// A record without its case, object, noise or seed.
    pub fn from_record(r: &Value) -> anyhow::Result<CaseResult> {
        let case = r["case"].as_str().context("record without `case`")?.to_string();
        let num = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
        let s = &r["scores"];
        Ok(CaseResult {
            object: r["object"].as_str().with_context(|| format!("{case}: no object"))?.to_string(),
            noise: serde_json::from_value(r["noise"].clone()).with_context(|| format!("{case}: no noise"))?,
            seed: r["seed"].as_u64().with_context(|| format!("{case}: no seed"))? as u32,
            failure: (r["status"] != "ok").then(|| r["failure"]["kind"].as_str().unwrap_or("unknown").to_string()),
            mae_mm: num(&s["mae_mm"]),
            similarity_mae_mm: num(&s["similarity_mae_mm"]),
            size_error: num(&s["size_error"]),
            rotation_deg: num(&s["rotation_deg"]),
            method_s: num(&r["seconds"]["method"]),
            case,
        })
    }

    pub fn ok(&self) -> bool {
        self.failure.is_none()
    }

    /// The group key: object and NETD.
    pub fn group(&self) -> (String, String) {
        (self.object.clone(), netd_label(&self.noise))
    }
}

/// `NETD 50 mK`.
pub fn netd_label(n: &NoiseLevel) -> String {
    format!("NETD {} mK", n.netd_mk)
}

/// Every result of a complete run, in case order.
///
/// # Errors
/// An incomplete run or a malformed record.
pub fn load(run: &Path) -> anyhow::Result<(RunInfo, Vec<CaseResult>)> {
    let info = RunInfo::read(run)?;
    let recs = info.complete_records(run)?;
    let results = recs.iter().map(CaseResult::from_record).collect::<anyhow::Result<Vec<_>>>()?;
    Ok((info, results))
}

/// Median, smallest and largest of the finite values (NaN for none).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Spread {
    pub median: f64,
    pub min: f64,
    pub max: f64,
}

impl Spread {
    pub fn of(values: impl IntoIterator<Item = f64>) -> Spread {
        let mut v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return Spread { median: f64::NAN, min: f64::NAN, max: f64::NAN };
        }
        v.sort_by(f64::total_cmp);
        let n = v.len();
        let median = if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) };
        Spread { median, min: v[0], max: v[n - 1] }
    }
}

/// The seeds of one object at one noise level.
#[derive(Clone, Debug, Serialize)]
pub struct GroupSummary {
    pub object: String,
    pub noise: NoiseLevel,
    pub cases: usize,
    pub failed: usize,
    pub mae_mm: Spread,
    pub similarity_mae_mm: Spread,
    /// Size error, %.
    pub size_error_pct: Spread,
    pub rotation_deg: Spread,
    pub method_s: Spread,
}

/// One summary per (object, noise level), in order of first appearance.
pub fn summarise(results: &[CaseResult]) -> Vec<GroupSummary> {
    let mut keys: Vec<(String, String)> = Vec::new();
    for r in results {
        if !keys.contains(&r.group()) {
            keys.push(r.group());
        }
    }
    keys.iter()
        .map(|k| {
            let g: Vec<&CaseResult> = results.iter().filter(|r| &r.group() == k).collect();
            let ok: Vec<&&CaseResult> = g.iter().filter(|r| r.ok()).collect();
            GroupSummary {
                object: k.0.clone(),
                noise: g[0].noise,
                cases: g.len(),
                failed: g.len() - ok.len(),
                mae_mm: Spread::of(ok.iter().map(|r| r.mae_mm)),
                similarity_mae_mm: Spread::of(ok.iter().map(|r| r.similarity_mae_mm)),
                size_error_pct: Spread::of(ok.iter().map(|r| 100.0 * r.size_error)),
                rotation_deg: Spread::of(ok.iter().map(|r| r.rotation_deg)),
                method_s: Spread::of(g.iter().map(|r| r.method_s)),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_of_values() {
        let s = Spread::of([3.0, 1.0, f64::NAN, 2.0, 10.0]);
        assert_eq!((s.median, s.min, s.max), (2.5, 1.0, 10.0));
        assert!(Spread::of([]).median.is_nan());
    }
}
