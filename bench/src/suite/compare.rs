//! `simbench suite compare BASE NEW`: two runs of the same suite paired case by case and seed
//! by seed on the log rigid MAE, with a verdict per noise level (`super::stats`).
//!
//! Groups: one per noise level, pooling the objects (the noise-free level has one seed per
//! object). A group is judged with at least [`stats::MIN_PAIRS`] pairs where both runs
//! succeeded; a pair where one run failed is counted apart and enters the test on the failure
//! counts. Per object and noise level the median change over seeds and its range are shown,
//! without a verdict. `compare` fails (exit 1) when a group is significantly worse in error or
//! in failures, at a family-wise false-alarm rate of [`stats::ALPHA`] over all groups.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{ensure, Context};
use serde::Serialize;

use super::results::{netd_label, CaseResult};
use super::run::RunInfo;
use super::stats::{self, GroupJudgement, Pair, Verdict};

/// One noise level's judgement.
#[derive(Clone, Debug, Serialize)]
pub struct GroupRow {
    pub noise: String,
    pub judgement: GroupJudgement,
}

/// One object at one noise level, over seeds.
#[derive(Clone, Debug, Serialize)]
pub struct CaseRow {
    pub object: String,
    pub noise: String,
    pub seeds: usize,
    pub base_failed: usize,
    pub new_failed: usize,
    pub change: Option<stats::CaseSummary>,
}

/// The comparison.
#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    pub suite_version: String,
    pub base: String,
    pub new: String,
    pub alpha: f64,
    pub groups: Vec<GroupRow>,
    pub cases: Vec<CaseRow>,
    pub worse: bool,
}

/// Pairs the two runs and judges them (module documentation).
///
/// # Errors
/// Incomplete runs, runs of different suites or versions, different cases or seeds.
pub fn compare(base: &Path, new: &Path) -> anyhow::Result<Comparison> {
    let (bi, br) = super::results::load(base)?;
    let (ni, nr) = super::results::load(new)?;
    check_comparable(&bi, &ni, base, new)?;
    let pair = |b: &CaseResult, n: &CaseResult| Pair {
        base_mae: b.ok().then_some(b.mae_mm),
        new_mae: n.ok().then_some(n.mae_mm),
    };
    let mut levels: Vec<String> = Vec::new();
    let mut keys: Vec<(String, String)> = Vec::new();
    for r in &br {
        let l = netd_label(&r.noise);
        if !levels.contains(&l) {
            levels.push(l);
        }
        if !keys.contains(&r.group()) {
            keys.push(r.group());
        }
    }
    let matched: Vec<(&CaseResult, &CaseResult)> = br.iter().zip(&nr).collect();
    let groups: Vec<Vec<Pair>> = levels
        .iter()
        .map(|l| matched.iter().filter(|(b, _)| &netd_label(&b.noise) == l).map(|(b, n)| pair(b, n)).collect())
        .collect();
    let judgements = stats::judge(&groups, stats::ALPHA);
    let worse = stats::any_worse(&judgements);
    let groups = levels.into_iter().zip(judgements).map(|(noise, judgement)| GroupRow { noise, judgement }).collect();
    let cases = keys
        .into_iter()
        .map(|k| {
            let g: Vec<&(&CaseResult, &CaseResult)> = matched.iter().filter(|(b, _)| b.group() == k).collect();
            let d = stats::log_ratios(&g.iter().map(|(b, n)| pair(b, n)).collect::<Vec<_>>());
            CaseRow {
                object: k.0,
                noise: k.1,
                seeds: g.len(),
                base_failed: g.iter().filter(|(b, _)| !b.ok()).count(),
                new_failed: g.iter().filter(|(_, n)| !n.ok()).count(),
                change: stats::summarize_case(&d),
            }
        })
        .collect();
    Ok(Comparison {
        suite_version: bi.suite_version,
        base: bi.label,
        new: ni.label,
        alpha: stats::ALPHA,
        groups,
        cases,
        worse,
    })
}

/// Refuses runs of different suites, versions, cases or seeds.
fn check_comparable(b: &RunInfo, n: &RunInfo, base: &Path, new: &Path) -> anyhow::Result<()> {
    ensure!(
        b.suite_version == n.suite_version,
        "{} is a run of suite {} but {} of suite {}: runs of different suites or suite versions cannot be paired",
        base.display(),
        b.suite_version,
        new.display(),
        n.suite_version
    );
    ensure!(
        b.shard.is_none() && n.shard.is_none(),
        "compare whole runs, not shards: merge the shards first (simbench suite merge)"
    );
    if b.cases != n.cases {
        let only_b: Vec<&String> = b.cases.iter().filter(|c| !n.cases.contains(c)).collect();
        let only_n: Vec<&String> = n.cases.iter().filter(|c| !b.cases.contains(c)).collect();
        anyhow::bail!(
            "the runs hold different cases or seeds: {} only in {} (e.g. {:?}), {} only in {} (e.g. {:?})",
            only_b.len(),
            base.display(),
            only_b.first(),
            only_n.len(),
            new.display(),
            only_n.first()
        );
    }
    Ok(())
}

fn pct(x: f64) -> String {
    format!("{:+.1} %", 100.0 * (x.exp() - 1.0))
}

/// The Markdown of a comparison.
pub fn markdown(c: &Comparison) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Compare: {} against {}\n", c.new, c.base);
    let _ = writeln!(
        s,
        "Suite `{}`. Pairs: the same case and seed in both runs; change = MAE_new / MAE_base of the rigid MAE. Verdicts per noise level (objects pooled) by the sign-flip permutation test of the mean log-ratio (exact up to {} pairs) and an exact one-sided McNemar test of the failures, Holm-corrected over every group's \"worse\" tests, family-wise level {}.\n",
        c.suite_version,
        stats::EXACT_MAX_N,
        c.alpha
    );
    let _ = writeln!(s, "| noise | pairs | both ok | geometric mean change | p worse (Holm) | p better (Holm) | failures base-only / new-only | p more failures (Holm) | verdict |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|");
    for g in &c.groups {
        let j = &g.judgement;
        let p = |x: Option<f64>| x.map_or("-".into(), |v| format!("{v:.3}"));
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} / {} | {} | {} |",
            g.noise,
            j.pairs,
            j.error.n,
            j.error.mean_diff.map_or("-".into(), pct),
            p(j.p_worse_adjusted),
            p(j.p_better_adjusted),
            j.failures.c,
            j.failures.b,
            p(j.p_more_failures_adjusted),
            verdict_word(j.verdict)
        );
    }
    let _ = writeln!(
        s,
        "\nPer object and noise level (no verdict: too few seeds): the median change over seeds [smallest, largest].\n"
    );
    let _ = writeln!(s, "| object | noise | seeds | failed base / new | median change [range] |");
    let _ = writeln!(s, "|---|---|---|---|---|");
    for r in &c.cases {
        let change = r
            .change
            .map_or("-".into(), |x| format!("{} [{}, {}]", pct(x.median_diff), pct(x.min_diff), pct(x.max_diff)));
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} / {} | {} |",
            r.object, r.noise, r.seeds, r.base_failed, r.new_failed, change
        );
    }
    let _ = writeln!(
        s,
        "\n{}",
        if c.worse { "**NEW is worse** in at least one group." } else { "No group is significantly worse." }
    );
    s
}

fn verdict_word(v: Verdict) -> &'static str {
    match v {
        Verdict::Worse => "**worse**",
        Verdict::Better => "better",
        Verdict::NoDifference => "no difference",
        Verdict::TooFewPairs => "too few pairs",
    }
}

/// The per-case CSV.
pub fn csv(c: &Comparison) -> String {
    let mut s = String::from(
        "object,noise,seeds,base_failed,new_failed,both_ok,median_log_ratio,min_log_ratio,max_log_ratio,median_ratio\n",
    );
    for r in &c.cases {
        let (n, med, lo, hi, ratio) = match r.change {
            Some(x) => (
                x.n.to_string(),
                format!("{:.6}", x.median_diff),
                format!("{:.6}", x.min_diff),
                format!("{:.6}", x.max_diff),
                format!("{:.6}", x.ratio_median),
            ),
            None => ("0".into(), String::new(), String::new(), String::new(), String::new()),
        };
        let _ = writeln!(
            s,
            "{},{},{},{},{},{n},{med},{lo},{hi},{ratio}",
            r.object, r.noise, r.seeds, r.base_failed, r.new_failed
        );
    }
    s
}

/// Writes `compare.md`, `compare.csv`, `compare.json` and `compare.png` into `out`.
///
/// # Errors
/// I/O errors.
pub fn write(c: &Comparison, out: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    for (name, text) in [
        ("compare.md", markdown(c)),
        ("compare.csv", csv(c)),
        ("compare.json", serde_json::to_string_pretty(c)? + "\n"),
    ] {
        heatsim::io::write_atomic(&out.join(name), text.as_bytes())
            .with_context(|| format!("writing {}", out.join(name).display()))?;
    }
    if let Some(png) = crate::figure::optional("compare.png", || plot(c)) {
        heatsim::io::write_atomic(&out.join("compare.png"), &png).context("writing compare.png")?;
    }
    Ok(())
}

/// Per object and noise level, the median change MAE_new / MAE_base over seeds (dot, log
/// scale) and its range (bar); 1 = no change.
fn plot(c: &Comparison) -> anyhow::Result<Vec<u8>> {
    use crate::figure::{ensure_font, png_rgb, FAMILY};
    use plotters::prelude::*;
    ensure_font();
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("{e}");
    let rows: Vec<(usize, stats::CaseSummary)> =
        c.cases.iter().enumerate().filter_map(|(i, r)| Some((i, r.change?))).collect();
    // Finite values only: an infinite axis would make plotters loop forever.
    let lim = rows
        .iter()
        .flat_map(|(_, x)| [x.min_diff.abs(), x.max_diff.abs()])
        .filter(|v| v.is_finite())
        .fold(0.1f64, f64::max)
        * 1.1;
    let (w, h) = (900u32, 160 + 18 * c.cases.len().max(1) as u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let labels: Vec<String> = c.cases.iter().map(|r| format!("{} {}", r.object, r.noise)).collect();
        let mut chart = ChartBuilder::on(&root)
            .caption(format!("{} against {}: change of the rigid MAE", c.new, c.base), (FAMILY, 14))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(330)
            .build_cartesian_2d(-lim..lim, -0.5f64..(c.cases.len() as f64 - 0.5))
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("ln(MAE_new / MAE_base): median over seeds and range")
            .y_labels(c.cases.len().max(1))
            .y_label_formatter(&|y| {
                let i = y.round();
                if (y - i).abs() < 1e-6 && i >= 0.0 {
                    labels.get(i as usize).cloned().unwrap_or_default()
                } else {
                    String::new()
                }
            })
            .label_style((FAMILY, 10))
            .draw()
            .map_err(|e| err(&e))?;
        chart
            .draw_series(std::iter::once(PathElement::new(vec![(0.0, -0.5), (0.0, c.cases.len() as f64 - 0.5)], BLACK)))
            .map_err(|e| err(&e))?;
        for (i, x) in &rows {
            let y = *i as f64;
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(x.min_diff, y), (x.max_diff, y)],
                    BLUE.stroke_width(2),
                )))
                .map_err(|e| err(&e))?;
            chart
                .draw_series(std::iter::once(Circle::new((x.median_diff, y), 4, RED.filled())))
                .map_err(|e| err(&e))?;
        }
        root.present().map_err(|e| err(&e))?;
    }
    png_rgb(&buf, w, h)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compare_plot_of_degenerate_comparisons_is_drawn() {
        let summary = |d: f64| stats::CaseSummary {
            n: 1,
            median_diff: d,
            min_diff: d,
            max_diff: d,
            q1_diff: d,
            q3_diff: d,
            ratio_median: d.exp(),
        };
        let row = |change| CaseRow {
            object: "ball".into(),
            noise: "20 mK".into(),
            seeds: 1,
            base_failed: 0,
            new_failed: 0,
            change,
        };
        for cases in [
            vec![],
            vec![row(None)],
            vec![row(Some(summary(0.0)))],
            vec![row(Some(summary(f64::NAN)))],
            vec![row(Some(summary(f64::NEG_INFINITY)))],
        ] {
            let c = Comparison {
                suite_version: "v".into(),
                base: "a".into(),
                new: "b".into(),
                alpha: 0.05,
                groups: Vec::new(),
                cases,
                worse: false,
            };
            // A NaN change cannot be drawn by plotters; `write` keeps the data either way.
            if let Some(png) = crate::figure::optional("compare.png", || plot(&c)) {
                assert!(png.starts_with(b"\x89PNG"));
            }
        }
    }
}
