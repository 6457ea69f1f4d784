//! `simbench suite power RUN`: what `compare` can tell apart on this suite, measured by
//! simulation from a real run's spread.
//!
//! From the run (typically the built-in method's): per object and noise level the median
//! log MAE m_g over its seeds, and per noise level the pooled spread
//! s = sqrt(mean over its objects of the sample variance of ln MAE over seeds). A scripted
//! method draws ln MAE = m_g + ln(change) + s xi (xi ~ N(0, 1), fresh for every case, seed and
//! draw); a base run draws the same with change 1. Each draw pairs a base and a new run on the
//! suite's cases and applies `compare`'s verdicts ([`super::stats::judge`]) to the levels whose
//! spread is known (an object with two or more successful seeds; the noise-free level, one
//! seed per object, is left out: with no spread any shift would be a certain verdict); the false-alarm
//! rate is the fraction of draws with change 1 that `compare` fails, the power the fraction
//! with the given change.

use std::fmt::Write as _;
use std::path::Path;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Serialize;

use super::results::{netd_label, CaseResult};
use super::stats::{self, Pair};

/// The outcome of the study.
#[derive(Clone, Debug, Serialize)]
pub struct Power {
    /// Per noise level: its label, pooled spread s and pairs.
    pub levels: Vec<(String, f64, usize)>,
    pub change: f64,
    pub draws: usize,
    /// Fraction of draws where `compare` fails for a method `change` times worse.
    pub power: f64,
    /// Fraction of draws where `compare` fails for a method no different.
    pub false_alarm: f64,
    /// Levels left out: no object has two successful seeds there, so their spread over seeds
    /// is unknown (a zero spread would make any shift a certain verdict).
    pub skipped: Vec<String>,
}

/// `compare`'s sign-flip test, with 4000 Monte Carlo patterns beyond `EXACT_MAX_N` pairs
/// instead of `MC_DRAWS` (a valid p-value for any number; thousands of simulated comparisons
/// would take hours otherwise).
fn fast_test(d: &[f64]) -> stats::TestResult {
    if d.len() <= stats::EXACT_MAX_N {
        stats::sign_flip_test(d)
    } else {
        stats::sign_flip_test_with(d, stats::PValueMethod::MonteCarlo { draws: 4000, seed: stats::MC_SEED })
    }
}

/// The case structure of a run: per noise level, each case's group median log MAE; with
/// `seeds`, every object of a level with more than one seed gets that many cases instead.
fn structure(results: &[CaseResult], seeds: Option<usize>) -> Vec<(String, Option<f64>, Vec<f64>)> {
    let mut levels: Vec<String> = Vec::new();
    for r in results {
        if !levels.contains(&netd_label(&r.noise)) {
            levels.push(netd_label(&r.noise));
        }
    }
    levels
        .into_iter()
        .map(|l| {
            let cases: Vec<&CaseResult> = results.iter().filter(|r| netd_label(&r.noise) == l).collect();
            let mut groups: Vec<String> = cases.iter().map(|r| r.object.clone()).collect();
            groups.dedup();
            let (mut var_sum, mut var_n) = (0.0, 0usize);
            let mut medians = Vec::new();
            for g in &groups {
                let logs: Vec<f64> = cases
                    .iter()
                    .filter(|r| &r.object == g && r.ok() && r.mae_mm > 0.0)
                    .map(|r| r.mae_mm.ln())
                    .collect();
                let n = cases.iter().filter(|r| &r.object == g).count();
                let n = match seeds {
                    Some(k) if n > 1 => k,
                    _ => n,
                };
                let median = super::results::Spread::of(logs.iter().copied()).median;
                medians.extend(std::iter::repeat_n(if median.is_finite() { median } else { 0.0 }, n));
                if logs.len() >= 2 {
                    let mean = logs.iter().sum::<f64>() / logs.len() as f64;
                    var_sum += logs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (logs.len() - 1) as f64;
                    var_n += 1;
                }
            }
            let s = (var_n > 0).then(|| (var_sum / var_n as f64).sqrt());
            (l, s, medians)
        })
        .collect()
}

/// Runs the study (module documentation) on the run in `run`.
///
/// # Errors
/// An incomplete run, a change that is not positive.
pub fn study(run: &Path, change: f64, draws: usize, seed: u64, seeds: Option<usize>) -> anyhow::Result<Power> {
    anyhow::ensure!(change.is_finite() && change > 0.0, "--change must be a positive factor, got {change}");
    anyhow::ensure!(draws >= 10, "--draws must be at least 10");
    let (_, results) = super::results::load(run)?;
    let (levels, skipped): (Vec<_>, Vec<_>) = structure(&results, seeds).into_iter().partition(|l| l.1.is_some());
    let levels: Vec<(String, f64, Vec<f64>)> = levels.into_iter().map(|(l, s, m)| (l, s.unwrap_or(0.0), m)).collect();
    anyhow::ensure!(
        !levels.is_empty(),
        "{}: no noise level has two or more seeds of an object: no spread to simulate",
        run.display()
    );
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let draw = |factor: f64, rng: &mut ChaCha8Rng| {
        let groups: Vec<Vec<Pair>> = levels
            .iter()
            .map(|(_, s, medians)| {
                medians
                    .iter()
                    .map(|m| {
                        let xb: f64 = StandardNormal.sample(rng);
                        let xn: f64 = StandardNormal.sample(rng);
                        Pair { base_mae: Some((m + s * xb).exp()), new_mae: Some((m + factor.ln() + s * xn).exp()) }
                    })
                    .collect()
            })
            .collect();
        stats::any_worse(&stats::judge_with(&groups, stats::ALPHA, &fast_test))
    };
    let power = (0..draws).filter(|_| draw(change, &mut rng)).count() as f64 / draws as f64;
    let false_alarm = (0..draws).filter(|_| draw(1.0, &mut rng)).count() as f64 / draws as f64;
    Ok(Power {
        levels: levels.iter().map(|(l, s, m)| (l.clone(), *s, m.len())).collect(),
        change,
        draws,
        power,
        false_alarm,
        skipped: skipped.into_iter().map(|(l, _, _)| l).collect(),
    })
}

/// The study in words.
pub fn markdown(p: &Power, run: &Path) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Power of `simbench suite compare` on the suite of {}, by simulation ({} draws):\n",
        run.display(),
        p.draws
    );
    let _ = writeln!(s, "| noise | pairs | pooled spread of ln MAE over seeds |");
    let _ = writeln!(s, "|---|---|---|");
    for (l, sd, n) in &p.levels {
        let _ = writeln!(s, "| {l} | {n} | {sd:.3} |");
    }
    for l in &p.skipped {
        let _ = writeln!(s, "| {l} | left out: one seed per object, no spread over seeds to simulate | |");
    }
    let _ = writeln!(
        s,
        "\nA method {:.0} % worse is called worse in {:.1} % of draws (power); a method no different in {:.1} % (false alarms, level {}).",
        100.0 * (p.change - 1.0),
        100.0 * p.power,
        100.0 * p.false_alarm,
        stats::ALPHA
    );
    s
}
