//! `simbench suite report RUN`: per object and noise level, the median and range over seeds of
//! the rigid MAE, the similarity MAE and the size error, the failures and the method's time;
//! written as `report.md`, `summary.csv`, `cases.csv` and `errors.png`.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context;
use plotters::prelude::*;

use super::bound::BoundEntry;
use super::results::{netd_label, CaseResult, GroupSummary, Spread};
use super::run::RunInfo;
use crate::figure::{ensure_font, png_rgb, FAMILY};

/// Writes the report of the run in `run` into `out` and returns the Markdown.
///
/// # Errors
/// An incomplete run, I/O errors.
pub fn write(run: &Path, out: &Path) -> anyhow::Result<String> {
    let (info, results) = super::results::load(run)?;
    let groups = super::results::summarise(&results);
    let bounds = read_bounds(run)?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let md = markdown(&info, &results, &groups, &bounds);
    let mut files = vec![
        ("report.md", md.clone().into_bytes()),
        ("summary.csv", summary_csv(&groups).into_bytes()),
        ("cases.csv", cases_csv(&results).into_bytes()),
    ];
    if let Some(png) = crate::figure::optional("errors.png", || errors_png(&info.label, &results)) {
        files.push(("errors.png", png));
    }
    for (name, bytes) in files {
        heatsim::io::write_atomic(&out.join(name), &bytes)
            .with_context(|| format!("writing {}", out.join(name).display()))?;
    }
    Ok(md)
}

/// The bounds a run carries (`RUN/bounds.json`), if any.
///
/// # Errors
/// A malformed file.
pub fn read_bounds(run: &Path) -> anyhow::Result<Vec<BoundEntry>> {
    let path = run.join("bounds.json");
    match std::fs::read_to_string(&path) {
        Ok(t) => serde_json::from_str(&t).with_context(|| format!("{}: malformed", path.display())),
        Err(_) => Ok(Vec::new()),
    }
}

/// The bound of a group as `unknown fluxes / known fluxes` (mm), or `-`.
pub fn bound_cell(bounds: &[BoundEntry], object: &str, netd_mk: f64) -> String {
    match bounds.iter().find(|b| b.object == object && b.netd_mk == netd_mk) {
        Some(b) => format!(
            "{} / {}",
            b.row("unknown").map_or("-".into(), |r| f(r.expected_mae_mm, 2)),
            b.row("known").map_or("-".into(), |r| f(r.expected_mae_mm, 2))
        ),
        None => "-".into(),
    }
}

/// The size bound of a group as `unknown fluxes / known fluxes` (standard deviation, % of the
/// size), or `-`.
pub fn size_bound_cell(bounds: &[BoundEntry], object: &str, netd_mk: f64) -> String {
    let pct = |r: Option<&super::bound::BoundRow>| r.and_then(|r| r.size_std_pct).map_or("-".into(), |x| f(x, 1));
    match bounds.iter().find(|b| b.object == object && b.netd_mk == netd_mk) {
        Some(b) => format!("{} / {}", pct(b.row("unknown")), pct(b.row("known"))),
        None => "-".into(),
    }
}

/// Whether the bounds' flux projections converged: how many stopped above the tolerance (their
/// bounds approximate; named when few) and which do not record it.
fn convergence_sentence(bounds: &[BoundEntry]) -> String {
    let name = |b: &BoundEntry| format!("{} at {} mK", b.object, b.netd_mk);
    let recorded: Vec<&BoundEntry> = bounds.iter().filter(|b| b.converged().is_some()).collect();
    let open: Vec<&BoundEntry> = recorded.iter().copied().filter(|b| b.converged() == Some(false)).collect();
    let residuals: Vec<f64> = open.iter().filter_map(|b| b.projection_residual).collect();
    let most = recorded.iter().filter_map(|b| b.projection_iterations).max().unwrap_or(0);
    let tol = super::bound::cgls_tolerance();
    let mut parts = Vec::new();
    if !recorded.is_empty() && open.is_empty() {
        parts.push(format!(
            "The flux projections (CGLS) of every bound that records them converged to a relative residual of {tol:.0e} (at most {most} iterations)."
        ));
    } else if !open.is_empty() {
        let (lo, hi) = residuals.iter().fold((f64::INFINITY, 0.0f64), |(a, b), &r| (a.min(r), b.max(r)));
        let names = if open.len() <= 4 {
            format!(" ({})", open.iter().map(|b| name(b)).collect::<Vec<_>>().join(", "))
        } else {
            String::new()
        };
        parts.push(format!(
            "The flux projections (CGLS) stopped above the tolerance {tol:.0e} on {} of {} bounds{names}, at relative residuals {lo:.1e} to {hi:.1e} after at most {most} iterations: those bounds are approximate.",
            open.len(),
            recorded.len()
        ));
    }
    let unknown: Vec<String> = bounds.iter().filter(|b| b.converged().is_none()).map(name).collect();
    if !unknown.is_empty() {
        parts
            .push(format!("Bounds computed before the projections' convergence was recorded: {}.", unknown.join(", ")));
    }
    parts.join(" ")
}

/// `x` with `digits` decimals; "-" when not finite (Markdown).
pub(super) fn f(x: f64, digits: usize) -> String {
    if x.is_finite() {
        format!("{x:.digits$}")
    } else {
        "-".into()
    }
}

/// `x` with `digits` decimals; an empty field when not finite (CSV).
pub fn csv_num(x: f64, digits: usize) -> String {
    if x.is_finite() {
        format!("{x:.digits$}")
    } else {
        String::new()
    }
}

/// `median [smallest, largest]` with `digits` decimals; "-" when there is none (Markdown).
pub(super) fn spread(s: &Spread, digits: usize) -> String {
    if s.median.is_finite() {
        format!("{} [{}, {}]", f(s.median, digits), f(s.min, digits), f(s.max, digits))
    } else {
        "-".into()
    }
}

/// The Markdown report.
pub fn markdown(info: &RunInfo, results: &[CaseResult], groups: &[GroupSummary], bounds: &[BoundEntry]) -> String {
    let mut s = String::new();
    let failed = results.iter().filter(|r| !r.ok()).count();
    let _ = writeln!(s, "# Suite run: {}\n", info.label);
    let _ = writeln!(s, "Suite `{}`, {} cases, {} failed.\n", info.suite_version, results.len(), failed);
    let _ = writeln!(
        s,
        "Per object and noise level over the seeds: median [smallest, largest]. Rigid MAE: mean distance from the reconstruction's vertices to the visible truth after rigid ICP (mm, the paper's metric); similarity MAE: the same after ICP with a scale (shape without size); size: mean depth over the true mean depth on the pixels both cover, minus 1 (%); rotation: the rigid ICP's rotation (deg; large means the shape had to be turned to fit).\n"
    );
    let _ = writeln!(s, "| object | noise | seeds | failed | rigid MAE (mm) | similarity MAE (mm) | size (%) | rotation (deg) | method (s) | bound (mm) | size bound (%) |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|");
    for g in groups {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            g.object,
            netd_label(&g.noise),
            g.cases,
            g.failed,
            spread(&g.mae_mm, 2),
            spread(&g.similarity_mae_mm, 2),
            spread(&g.size_error_pct, 1),
            f(g.rotation_deg.median, 1),
            f(g.method_s.median, 1),
            bound_cell(bounds, &g.object, g.noise.netd_mk),
            size_bound_cell(bounds, &g.object, g.noise.netd_mk)
        );
    }
    if let Some(b) = bounds.first() {
        let _ = writeln!(
            s,
            "\nBound: {}; fluxes unknown (the paper's setting) / known (calibrated lamps), lambda and C unknown in both, on seed 1's videos; the size bound: the standard deviation of the size mode's coefficient (the relative error of the mean depth along the camera rays), %. It holds for unbiased estimators of those modes only. Modes: {}.",
            b.label,
            b.modes.join(", ")
        );
        let converged = convergence_sentence(bounds);
        if !converged.is_empty() {
            let _ = writeln!(s, "{converged}");
        }
    }
    let fails: Vec<&CaseResult> = results.iter().filter(|r| !r.ok()).collect();
    if !fails.is_empty() {
        let _ = writeln!(s, "\nFailed cases:\n");
        for r in fails {
            let _ = writeln!(s, "- {}: {}", r.case, r.failure.as_deref().unwrap_or(""));
        }
    }
    let _ = writeln!(s, "\nCamera model at each level: temporal noise NETD per pixel and frame, a fixed per-pixel offset pattern and a quantisation step:\n");
    let mut levels: Vec<String> =
        groups.iter().map(|g| format!("- {}: {}", netd_label(&g.noise), g.noise.describe())).collect();
    levels.dedup();
    levels.sort();
    levels.dedup();
    let _ = writeln!(s, "{}", levels.join("\n"));
    let _ = writeln!(s, "\n![errors](errors.png)");
    s
}

/// One row per object and noise level.
pub fn summary_csv(groups: &[GroupSummary]) -> String {
    let mut s = String::from("object,netd_mK,fixed_pattern_mK,quantization_mK,cases,failed,mae_mm_median,mae_mm_min,mae_mm_max,similarity_mae_mm_median,size_error_pct_median,size_error_pct_min,size_error_pct_max,rotation_deg_median,method_s_median\n");
    for g in groups {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            g.object,
            g.noise.netd_mk,
            g.noise.fixed_pattern_mk,
            g.noise.quantization_mk,
            g.cases,
            g.failed,
            csv_num(g.mae_mm.median, 6),
            csv_num(g.mae_mm.min, 6),
            csv_num(g.mae_mm.max, 6),
            csv_num(g.similarity_mae_mm.median, 6),
            csv_num(g.size_error_pct.median, 4),
            csv_num(g.size_error_pct.min, 4),
            csv_num(g.size_error_pct.max, 4),
            csv_num(g.rotation_deg.median, 3),
            csv_num(g.method_s.median, 3)
        );
    }
    s
}

/// One row per case.
pub fn cases_csv(results: &[CaseResult]) -> String {
    let mut s = String::from(
        "case,object,netd_mK,seed,status,failure,mae_mm,similarity_mae_mm,size_error,rotation_deg,method_s\n",
    );
    for r in results {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{}",
            r.case,
            r.object,
            r.noise.netd_mk,
            r.seed,
            if r.ok() { "ok" } else { "failed" },
            r.failure.as_deref().unwrap_or(""),
            csv_num(r.mae_mm, 6),
            csv_num(r.similarity_mae_mm, 6),
            csv_num(r.size_error, 6),
            csv_num(r.rotation_deg, 3),
            csv_num(r.method_s, 3)
        );
    }
    s
}

/// Rigid MAE of every successful case (log scale) per object, one colour per noise level.
fn errors_png(label: &str, results: &[CaseResult]) -> anyhow::Result<Vec<u8>> {
    ensure_font();
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("{e}");
    let mut objects: Vec<&str> = Vec::new();
    let mut levels: Vec<f64> = Vec::new();
    for r in results {
        if !objects.contains(&r.object.as_str()) {
            objects.push(&r.object);
        }
        if !levels.contains(&r.noise.netd_mk) {
            levels.push(r.noise.netd_mk);
        }
    }
    let ok: Vec<&CaseResult> = results.iter().filter(|r| r.ok() && r.mae_mm > 0.0 && r.mae_mm.is_finite()).collect();
    let (lo, hi) = ok
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, r| (a.0.min(r.mae_mm.log10()), a.1.max(r.mae_mm.log10())));
    let (lo, hi) = if lo < hi { (lo - 0.1, hi + 0.1) } else { (-1.0, 2.0) };
    let (w, h) = (140 * objects.len().max(4) as u32 + 120, 520u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let names = objects.clone();
        let mut chart = ChartBuilder::on(&root)
            .caption(format!("rigid MAE per case: {label}"), (FAMILY, 16))
            .margin(12)
            .x_label_area_size(70)
            .y_label_area_size(60)
            .build_cartesian_2d(-0.5f64..(objects.len() as f64 - 0.5), lo..hi)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .y_desc("log10 rigid MAE (mm)")
            .x_labels(objects.len().max(1))
            .x_label_formatter(&|x| {
                let i = x.round();
                if (x - i).abs() < 1e-6 && i >= 0.0 {
                    names.get(i as usize).map(|s| s.to_string()).unwrap_or_default()
                } else {
                    String::new()
                }
            })
            .label_style((FAMILY, 10))
            .disable_x_mesh()
            .draw()
            .map_err(|e| err(&e))?;
        for (li, &netd) in levels.iter().enumerate() {
            let colour = Palette99::pick(li).to_rgba();
            let dx = (li as f64 - (levels.len() as f64 - 1.0) / 2.0) * 0.18;
            let pts: Vec<(f64, f64)> = ok
                .iter()
                .filter(|r| r.noise.netd_mk == netd)
                .map(|r| (objects.iter().position(|o| *o == r.object).unwrap_or(0) as f64 + dx, r.mae_mm.log10()))
                .collect();
            chart
                .draw_series(pts.into_iter().map(|p| Circle::new(p, 4, colour.filled())))
                .map_err(|e| err(&e))?
                .label(format!("NETD {netd} mK"))
                .legend(move |(x, y)| Circle::new((x, y), 4, colour.filled()));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE)
            .border_style(BLACK)
            .label_font((FAMILY, 12))
            .draw()
            .map_err(|e| err(&e))?;
        root.present().map_err(|e| err(&e))?;
    }
    png_rgb(&buf, w, h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::suite::spec::NoiseLevel;

    fn case(object: &str, failure: Option<&str>, mae_mm: f64) -> CaseResult {
        CaseResult {
            case: format!("{object}-case"),
            object: object.into(),
            noise: NoiseLevel { netd_mk: 20.0, fixed_pattern_mk: 25.0, quantization_mk: 10.0 },
            seed: 1,
            failure: failure.map(str::to_string),
            mae_mm,
            similarity_mae_mm: mae_mm,
            size_error: 0.0,
            rotation_deg: 0.0,
            method_s: 1.0,
        }
    }

    fn bound(object: &str, residual: Option<f64>) -> BoundEntry {
        BoundEntry {
            object: object.into(),
            netd_mk: 50.0,
            level: 2,
            degree: 2,
            modes: vec![],
            sigma_k: 0.05,
            rows: vec![],
            label: String::new(),
            seconds: 0.0,
            projection_residual: residual,
            projection_iterations: residual.map(|r| if r > 1e-5 { 400 } else { 37 }),
        }
    }

    /// The report says which bounds' projections stopped short and which do not record it.
    #[test]
    fn convergence_sentence_names_the_bounds_that_stopped_short() {
        let done = convergence_sentence(&[bound("ball", Some(3e-6)), bound("vase", Some(1e-5))]);
        assert!(done.starts_with("The flux projections (CGLS) of every bound"), "{done}");
        assert!(done.contains("at most 37 iterations"), "{done}");
        let short = convergence_sentence(&[bound("ball", Some(3e-6)), bound("hemisphere", Some(2.5e-3))]);
        assert!(
            short.contains(
                "on 1 of 2 bounds (hemisphere at 50 mK), at relative residuals 2.5e-3 to 2.5e-3 after at most 400"
            ),
            "{short}"
        );
        let many: Vec<BoundEntry> = (0..6).map(|k| bound(&format!("o{k}"), Some(1e-3 * (k + 1) as f64))).collect();
        let many = convergence_sentence(&many);
        assert!(many.contains("on 6 of 6 bounds, at relative residuals 1.0e-3 to 6.0e-3"), "{many}");
        let old = convergence_sentence(&[bound("ball", Some(3e-6)), bound("bunny", None)]);
        assert!(old.contains("every bound that records them") && old.ends_with("recorded: bunny at 50 mK."), "{old}");
        assert_eq!(
            convergence_sentence(&[bound("bunny", None)]),
            "Bounds computed before the projections' convergence was recorded: bunny at 50 mK."
        );
    }

    #[test]
    fn errors_plot_of_degenerate_runs_is_drawn() {
        let runs = [
            vec![],
            vec![case("ball", Some("timeout"), f64::NAN)],
            vec![case("ball", None, 1.0)],
            vec![case("ball", None, 1.0), case("vase", None, 1.0), case("can", None, f64::INFINITY)],
        ];
        for results in &runs {
            assert!(errors_png("run", results).expect("a figure for any run").starts_with(b"\x89PNG"));
        }
    }

    #[test]
    fn csv_keeps_minus_signs_and_leaves_missing_values_empty() {
        let r = CaseResult { similarity_mae_mm: f64::NAN, size_error: -0.25, ..case("ball", None, 1.5) };
        let csv = cases_csv(&[r]);
        let row: Vec<&str> = csv.lines().nth(1).unwrap().split(',').collect();
        assert_eq!(row[6..9], ["1.500000", "", "-0.250000"], "{csv}");
    }
}
