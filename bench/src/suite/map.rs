//! `simbench suite map`: where heat-only shape recovery works. Several runs of suites that
//! differ in the camera's noise and in the heating are gathered into one table: per object,
//! NETD and heating, the median rigid and similarity MAE, the median size error, the failure
//! rate and the case's bounds (of the aligned error and of the size); written as `map.csv`,
//! `map.md` and `map.png`.
//!
//! The heating of a suite is the energy each lamp delivers, `E = P t_heat` (J: lamp power,
//! W, times the heating's duration, s), so that power and duration studies share one axis.
//! The figure's NETD column holds the rows at the reference heating (that of the run with
//! the most noise levels); its heating column the rows at the reference NETD (`--netd`).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{ensure, Context};
use plotters::prelude::*;

use super::bound::BoundEntry;
use super::manifest::Manifest;
use super::report::{csv_num, f as cell, read_bounds, spread};
use super::results::{self, CaseResult, Spread};
use crate::figure::{ensure_font, png_rgb, FAMILY};

/// One object at one NETD and heating, over its seeds.
#[derive(Clone, Debug)]
pub struct MapRow {
    /// The object configuration's id.
    pub object: String,
    pub netd_mk: f64,
    /// Lamp power, W.
    pub lamp_power_w: f64,
    /// Heating duration, s.
    pub duration_s: f64,
    pub cases: usize,
    pub failed: usize,
    pub mae_mm: Spread,
    pub similarity_mae_mm: Spread,
    /// Size error, %.
    pub size_error_pct: Spread,
    /// The bound (fluxes unknown, known), mm; NaN without one.
    pub bound_mm: (f64, f64),
    /// The bound on the size (fluxes unknown, known): standard deviation, % of the size; NaN
    /// without one.
    pub size_bound_pct: (f64, f64),
}

impl MapRow {
    /// Energy per lamp, J.
    pub fn heating_j(&self) -> f64 {
        self.lamp_power_w * self.duration_s
    }

    /// Failed cases over cases, %.
    pub fn failure_pct(&self) -> f64 {
        100.0 * self.failed as f64 / self.cases.max(1) as f64
    }
}

/// The rows of one run of `suite` (a suite folder or its manifest file).
///
/// # Errors
/// An unreadable suite or run, or a run of another suite version.
pub fn rows_of(suite: &Path, run: &Path) -> anyhow::Result<Vec<MapRow>> {
    let m = Manifest::read_dir_or_file(suite)?;
    let (info, cases) = results::load(run)?;
    ensure!(
        info.suite_version == m.version,
        "{}: a run of suite {} but {} is suite {}",
        run.display(),
        info.suite_version,
        suite.display(),
        m.version
    );
    let bounds = read_bounds(run)?;
    Ok(group(&cases, &bounds, m.spec.lamp_power_w, m.spec.timing.duration_s))
}

fn group(cases: &[CaseResult], bounds: &[BoundEntry], power: f64, duration: f64) -> Vec<MapRow> {
    results::summarise(cases)
        .into_iter()
        .map(|g| {
            let b = bounds.iter().find(|b| b.object == g.object && b.netd_mk == g.noise.netd_mk);
            let bound = |fluxes: &str| b.and_then(|b| b.row(fluxes)).map_or(f64::NAN, |r| r.expected_mae_mm);
            let size = |fluxes: &str| b.and_then(|b| b.row(fluxes)).and_then(|r| r.size_std_pct).unwrap_or(f64::NAN);
            MapRow {
                netd_mk: g.noise.netd_mk,
                lamp_power_w: power,
                duration_s: duration,
                cases: g.cases,
                failed: g.failed,
                mae_mm: g.mae_mm,
                similarity_mae_mm: g.similarity_mae_mm,
                size_error_pct: g.size_error_pct,
                bound_mm: (bound("unknown"), bound("known")),
                size_bound_pct: (size("unknown"), size("known")),
                object: g.object,
            }
        })
        .collect()
}

/// Gathers the runs (suite, run), drops rows repeated across runs (the first kept), and writes
/// `map.csv`, `map.md` and `map.png` into `out`; returns the Markdown.
///
/// # Errors
/// As [`rows_of`]; no rows; I/O errors.
pub fn write(pairs: &[(PathBuf, PathBuf)], netd_ref_mk: f64, out: &Path) -> anyhow::Result<String> {
    let mut rows: Vec<MapRow> = Vec::new();
    let mut ref_heating = (0usize, f64::NAN);
    for (suite, run) in pairs {
        let r = rows_of(suite, run)?;
        let levels = {
            let mut l: Vec<u64> = r.iter().map(|x| x.netd_mk.to_bits()).collect();
            l.sort_unstable();
            l.dedup();
            l.len()
        };
        if levels > ref_heating.0 {
            ref_heating = (levels, r.first().map_or(f64::NAN, MapRow::heating_j));
        }
        for row in r {
            let same =
                |x: &MapRow| x.object == row.object && x.netd_mk == row.netd_mk && x.heating_j() == row.heating_j();
            if !rows.iter().any(same) {
                rows.push(row);
            }
        }
    }
    ensure!(!rows.is_empty(), "suite map: the runs hold no cases");
    rows.sort_by(|a, b| {
        (a.object.as_str(), a.heating_j(), a.netd_mk)
            .partial_cmp(&(b.object.as_str(), b.heating_j(), b.netd_mk))
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let md = markdown(&rows);
    let mut files = vec![("map.csv", csv(&rows).into_bytes()), ("map.md", md.clone().into_bytes())];
    if let Some(png) = crate::figure::optional("map.png", || png(&rows, ref_heating.1, netd_ref_mk)) {
        files.push(("map.png", png));
    }
    for (name, bytes) in files {
        heatsim::io::write_atomic(&out.join(name), &bytes)
            .with_context(|| format!("writing {}", out.join(name).display()))?;
    }
    Ok(md)
}

/// One line per row.
pub fn csv(rows: &[MapRow]) -> String {
    let mut s = String::from(
        "object,netd_mK,lamp_power_W,heating_s,heating_J,cases,failed,failure_pct,mae_mm_median,mae_mm_min,mae_mm_max,similarity_mae_mm_median,size_error_pct_median,size_error_pct_min,size_error_pct_max,bound_fluxes_unknown_mm,bound_fluxes_known_mm,size_bound_fluxes_unknown_pct,size_bound_fluxes_known_pct\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            r.object,
            r.netd_mk,
            r.lamp_power_w,
            r.duration_s,
            r.heating_j(),
            r.cases,
            r.failed,
            csv_num(r.failure_pct(), 1),
            csv_num(r.mae_mm.median, 4),
            csv_num(r.mae_mm.min, 4),
            csv_num(r.mae_mm.max, 4),
            csv_num(r.similarity_mae_mm.median, 4),
            csv_num(r.size_error_pct.median, 2),
            csv_num(r.size_error_pct.min, 2),
            csv_num(r.size_error_pct.max, 2),
            csv_num(r.bound_mm.0, 4),
            csv_num(r.bound_mm.1, 4),
            csv_num(r.size_bound_pct.0, 2),
            csv_num(r.size_bound_pct.1, 2),
        );
    }
    s
}

/// The table as Markdown.
pub fn markdown(rows: &[MapRow]) -> String {
    let mut s = String::from("| object | NETD (mK) | heating (W x s) | failed | rigid MAE (mm) | similarity MAE (mm) | size (%) | bound, fluxes unknown / known (mm) | size bound, unknown / known (%) |\n|---|---|---|---|---|---|---|---|---|\n");
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} x {} | {}/{} | {} | {} | {} | {} / {} | {} / {} |",
            r.object,
            r.netd_mk,
            r.lamp_power_w,
            r.duration_s,
            r.failed,
            r.cases,
            spread(&r.mae_mm, 2),
            cell(r.similarity_mae_mm.median, 2),
            spread(&r.size_error_pct, 1),
            cell(r.bound_mm.0, 2),
            cell(r.bound_mm.1, 2),
            cell(r.size_bound_pct.0, 1),
            cell(r.size_bound_pct.1, 1),
        );
    }
    s
}

/// A quantity of the figure's rows: its axis label, whether its axis is logarithmic, and its
/// value of a row (with the bound's, where it has one).
struct Quantity {
    label: &'static str,
    log: bool,
    value: fn(&MapRow) -> f64,
    bound: Option<fn(&MapRow) -> f64>,
}

const QUANTITIES: [Quantity; 3] = [
    Quantity { label: "median rigid MAE (mm)", log: true, value: |r| r.mae_mm.median, bound: Some(|r| r.bound_mm.0) },
    Quantity {
        label: "median |size error| (%)",
        log: true,
        value: |r| r.size_error_pct.median.abs(),
        bound: Some(|r| r.size_bound_pct.0),
    },
    Quantity { label: "failed cases (%)", log: false, value: MapRow::failure_pct, bound: None },
];

/// Three rows of panels (MAE and |size error| with their bounds dashed, failures) against NETD at the
/// reference heating (left) and against the heating at `netd_ref` (right); one colour per object.
fn png(rows: &[MapRow], heating_ref: f64, netd_ref: f64) -> anyhow::Result<Vec<u8>> {
    ensure_font();
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("{e}");
    let mut objects: Vec<&str> = Vec::new();
    for r in rows {
        if !objects.contains(&r.object.as_str()) {
            objects.push(&r.object);
        }
    }
    let columns: [(&str, Vec<&MapRow>, fn(&MapRow) -> f64); 2] = [
        ("NETD (mK)", rows.iter().filter(|r| r.heating_j() == heating_ref).collect(), |r| r.netd_mk),
        ("heating per lamp (kJ)", rows.iter().filter(|r| r.netd_mk == netd_ref).collect(), |r| r.heating_j() / 1e3),
    ];
    let (w, h) = (1100u32, 1050u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let panels = root.split_evenly((QUANTITIES.len(), columns.len()));
        for (qi, q) in QUANTITIES.iter().enumerate() {
            for (ci, (xlabel, sel, xof)) in columns.iter().enumerate() {
                let area = &panels[qi * columns.len() + ci];
                let title = if ci == 0 {
                    format!("at {} kJ per lamp", cell(heating_ref / 1e3, 1))
                } else {
                    format!("at NETD {netd_ref} mK")
                };
                panel(area, q, &title, xlabel, sel, *xof, &objects).map_err(|e| err(&e))?;
            }
        }
        root.present().map_err(|e| err(&e))?;
    }
    png_rgb(&buf, w, h)
}

/// The smallest and largest finite value; `None` if there is none.
fn finite_range(v: &[f64]) -> Option<(f64, f64)> {
    let (lo, hi) =
        v.iter().filter(|x| x.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
    (lo <= hi).then_some((lo, hi))
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

fn panel(
    area: &Area,
    q: &Quantity,
    title: &str,
    xlabel: &str,
    rows: &[&MapRow],
    xof: fn(&MapRow) -> f64,
    objects: &[&str],
) -> anyhow::Result<()> {
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("{e}");
    let tr = |v: f64| if q.log { v.max(1e-3).log10() } else { v };
    let mut ys: Vec<f64> = rows.iter().map(|r| (q.value)(r)).filter(|v| v.is_finite()).map(tr).collect();
    if let Some(b) = q.bound {
        ys.extend(rows.iter().map(|r| b(r)).filter(|v| v.is_finite() && *v > 0.0).map(tr));
    }
    let xs: Vec<f64> = rows.iter().map(|r| xof(r)).collect();
    let (x0, x1) = finite_range(&xs).unwrap_or((0.0, 1.0));
    let (y0, y1) = finite_range(&ys).unwrap_or((0.0, 1.0));
    let pad = |a: f64, b: f64| if b > a { 0.08 * (b - a) } else { 0.5 };
    let (px, py) = (pad(x0, x1), pad(y0, y1));
    let ylabel = if q.log { format!("log10 {}", q.label) } else { q.label.to_string() };
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FAMILY, 13))
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(56)
        .build_cartesian_2d((x0 - px)..(x1 + px), (y0 - py)..(y1 + py))
        .map_err(|e| err(&e))?;
    chart.configure_mesh().x_desc(xlabel).y_desc(ylabel).label_style((FAMILY, 10)).draw().map_err(|e| err(&e))?;
    for (oi, obj) in objects.iter().enumerate() {
        let colour = Palette99::pick(oi).to_rgba();
        let mut pts: Vec<(f64, &MapRow)> = rows.iter().filter(|r| r.object == *obj).map(|r| (xof(r), *r)).collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        let line: Vec<(f64, f64)> =
            pts.iter().map(|(x, r)| (*x, (q.value)(r))).filter(|p| p.1.is_finite()).map(|(x, v)| (x, tr(v))).collect();
        chart
            .draw_series(LineSeries::new(line.clone(), colour.stroke_width(2)))
            .map_err(|e| err(&e))?
            .label(obj.to_string())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(2)));
        chart.draw_series(line.iter().map(|p| Circle::new(*p, 3, colour.filled()))).map_err(|e| err(&e))?;
        if let Some(b) = q.bound {
            let bl: Vec<(f64, f64)> = pts
                .iter()
                .map(|(x, r)| (*x, b(r)))
                .filter(|p| p.1.is_finite() && p.1 > 0.0)
                .map(|(x, v)| (x, tr(v)))
                .collect();
            chart.draw_series(DashedLineSeries::new(bl, 4, 3, colour.stroke_width(1))).map_err(|e| err(&e))?;
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font((FAMILY, 10))
        .draw()
        .map_err(|e| err(&e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::suite::bound::BoundRow;
    use crate::suite::spec::NoiseLevel;

    fn case(object: &str, netd: f64, seed: u32, mae: Option<f64>) -> CaseResult {
        CaseResult {
            case: format!("{object}-netd{netd}-s{seed}"),
            object: object.into(),
            noise: NoiseLevel { netd_mk: netd, fixed_pattern_mk: 25.0, quantization_mk: 10.0 },
            seed,
            failure: mae.is_none().then(|| "scoring".to_string()),
            mae_mm: mae.unwrap_or(f64::NAN),
            similarity_mae_mm: mae.unwrap_or(f64::NAN),
            size_error: 0.1 * seed as f64,
            rotation_deg: 1.0,
            method_s: 1.0,
        }
    }

    #[test]
    fn rows_carry_medians_failures_heating_and_the_bound() {
        let cases = [
            case("ball", 50.0, 1, Some(2.0)),
            case("ball", 50.0, 2, None),
            case("ball", 50.0, 3, Some(4.0)),
            case("ball", 20.0, 1, Some(1.0)),
        ];
        let bound = BoundEntry {
            object: "ball".into(),
            netd_mk: 50.0,
            level: 1,
            degree: 2,
            modes: vec![],
            sigma_k: 0.05,
            rows: vec![
                BoundRow {
                    fluxes: "unknown".into(),
                    globals: "unknown".into(),
                    expected_mae_mm: 0.7,
                    size_std_pct: Some(12.5),
                },
                BoundRow {
                    fluxes: "known".into(),
                    globals: "unknown".into(),
                    expected_mae_mm: 0.2,
                    size_std_pct: None,
                },
            ],
            label: String::new(),
            seconds: 0.0,
            projection_residual: None,
            projection_iterations: None,
        };
        let rows = group(&cases, &[bound], 250.0, 20.0);
        let r50 = rows.iter().find(|r| r.netd_mk == 50.0).expect("50 mK row");
        assert_eq!((r50.cases, r50.failed), (3, 1));
        assert!((r50.failure_pct() - 100.0 / 3.0).abs() < 1e-9);
        assert_eq!(r50.mae_mm.median, 3.0);
        assert!((r50.size_error_pct.median - 20.0).abs() < 1e-9, "median of 10 % and 30 %");
        assert_eq!(r50.bound_mm, (0.7, 0.2));
        assert_eq!(r50.size_bound_pct.0, 12.5);
        assert!(r50.size_bound_pct.1.is_nan(), "a row without the size bound");
        assert_eq!(r50.heating_j(), 5000.0);
        let r20 = rows.iter().find(|r| r.netd_mk == 20.0).expect("20 mK row");
        assert!(r20.bound_mm.0.is_nan(), "no bound at 20 mK");
        let text = csv(&rows);
        assert_eq!(text.lines().count(), 3);
        assert!(text.contains("ball,50,250,20,5000,3,1,33.3,3.0000,2.0000,4.0000"), "{text}");
        let md = markdown(&rows);
        assert!(md.contains("| 1/3 |") && md.contains("0.70 / 0.20 | 12.5 / - |"), "{md}");
        let png = png(&rows, 5000.0, 50.0).expect("figure");
        assert!(png.starts_with(b"\x89PNG"));
    }
}
