//! The outputs of `simbench peer` (its module doc): a one-mesh summary table, and with several
//! element sizes the scaling against nodes as `peer_scaling.{json,csv,png}`.
//!
//! Time per step is the run's stepping time over its steps (s), time per solve over its solves;
//! a speedup is a peer's stepping time over ours on the same mesh and steps; the bytes read per
//! step are `peer::bytes_read`'s estimate.

use anyhow::Context;
use plotters::prelude::*;
use serde_json::Value;
use std::fmt::Write as _;
use std::path::Path;

/// A run's label: `ours direct`, `peer superlu`, ...
fn label(run: &Value) -> String {
    format!("{} {}", run["code"].as_str().unwrap_or("?"), run["linear_solver"].as_str().unwrap_or("?"))
}

/// A human-readable table of one mesh's runs and the speedups of ours over each peer.
pub fn summary(report: &Value) -> String {
    let mut s = format!(
        "simbench peer: {} nodes, {} steps; agreement with {}: max {:.1e} of the rise (bound {:.0e})\n",
        report["nodes"],
        report["steps"],
        report["reference"].as_str().unwrap_or("?"),
        report["max_rel_diff"].as_f64().unwrap_or(f64::NAN),
        report["agreement_bound"].as_f64().unwrap_or(f64::NAN)
    );
    let _ =
        writeln!(s, "  {:<26} {:>10} {:>10} {:>8} {:>11}", "run", "step (ms)", "total (s)", "solves", "max |dT| (K)");
    for run in report["runs"].as_array().into_iter().flatten() {
        let _ = writeln!(
            s,
            "  {:<26} {:>10.3} {:>10.2} {:>8} {:>11.1e}",
            label(run),
            run["step_s"].as_f64().unwrap_or(f64::NAN) * 1e3,
            run["total_s"].as_f64().unwrap_or(f64::NAN),
            run["solves"],
            run["max_abs_diff_k"].as_f64().unwrap_or(f64::NAN)
        );
    }
    for sp in report["speedups"].as_array().into_iter().flatten() {
        let _ = writeln!(
            s,
            "  ours {} over peer {}: {:.2}x stepping, {:.2}x total",
            sp["ours"].as_str().unwrap_or("?"),
            sp["peer"].as_str().unwrap_or("?"),
            sp["stepping"].as_f64().unwrap_or(f64::NAN),
            sp["total"].as_f64().unwrap_or(f64::NAN)
        );
    }
    s
}

/// `peer_scaling.json`, `.csv` (one row per mesh and run) and `.png` in `out`.
pub fn write(out: &Path, reports: &[Value]) -> anyhow::Result<()> {
    let mut csv = String::from(
        "nodes,tetrahedra,element_size_m,steps,code,linear_solver,step_s,solve_s,total_s,solves,cg_iterations,bytes_read_per_step,max_abs_diff_k\n",
    );
    for r in reports {
        for run in r["runs"].as_array().into_iter().flatten() {
            let _ = writeln!(
                csv,
                "{},{},{},{},{},{},{},{},{},{},{},{},{}",
                r["nodes"],
                r["tets"],
                r["element_size_m"],
                r["steps"],
                run["code"].as_str().unwrap_or(""),
                run["linear_solver"].as_str().unwrap_or(""),
                run["step_s"],
                run["solve_s"],
                run["total_s"],
                run["solves"],
                run["cg_iterations"],
                run["bytes_read_per_step"],
                run["max_abs_diff_k"]
            );
        }
    }
    let mut files = vec![
        ("peer_scaling.json", (serde_json::to_string_pretty(reports)? + "\n").into_bytes()),
        ("peer_scaling.csv", csv.into_bytes()),
    ];
    let labels: Vec<String> = reports.iter().flat_map(|r| r["runs"].as_array().into_iter().flatten().map(label)).fold(
        Vec::new(),
        |mut v, l| {
            if !v.contains(&l) {
                v.push(l);
            }
            v
        },
    );
    let lines: Vec<(String, Vec<(f64, f64)>)> = labels
        .iter()
        .map(|l| {
            let pts = reports
                .iter()
                .filter_map(|r| {
                    let run = r["runs"].as_array()?.iter().find(|run| label(run) == *l)?;
                    Some((r["nodes"].as_f64()?, run["step_s"].as_f64()? * 1e3))
                })
                .collect();
            (l.clone(), pts)
        })
        .collect();
    if let Some(png) = crate::figure::optional("peer_scaling.png", || {
        loglog_png("volumetric step against mesh size: ours and the peers", "time per step (ms)", &lines)
    }) {
        files.push(("peer_scaling.png", png));
    }
    for (name, bytes) in files {
        heatsim::io::write_atomic(&out.join(name), &bytes)
            .with_context(|| format!("writing {}", out.join(name).display()))?;
    }
    Ok(())
}

/// A log-log plot of `lines` (label, points (nodes, y)) against nodes, one colour each.
pub fn loglog_png(caption: &str, y_desc: &str, lines: &[(String, Vec<(f64, f64)>)]) -> anyhow::Result<Vec<u8>> {
    crate::figure::ensure_font();
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("{e}");
    let logged: Vec<(&str, Vec<(f64, f64)>)> = lines
        .iter()
        .map(|(l, pts)| {
            (l.as_str(), pts.iter().filter(|p| p.0 > 0.0 && p.1 > 0.0).map(|p| (p.0.log10(), p.1.log10())).collect())
        })
        .collect();
    let all: Vec<(f64, f64)> = logged.iter().flat_map(|(_, p)| p.iter().copied()).collect();
    anyhow::ensure!(!all.is_empty(), "no timings");
    let range = |f: fn(&(f64, f64)) -> f64| {
        let (lo, hi) = all.iter().map(f).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(v), b.max(v)));
        (lo - 0.1)..(hi + 0.1)
    };
    let (w, h) = (720u32, 480u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(caption, (crate::figure::FAMILY, 15))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(range(|p| p.0), range(|p| p.1))
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("log10 nodes")
            .y_desc(format!("log10 {y_desc}"))
            .label_style((crate::figure::FAMILY, 11))
            .draw()
            .map_err(|e| err(&e))?;
        for (k, (label, pts)) in logged.iter().enumerate() {
            let colour = Palette99::pick(k).to_rgba();
            chart
                .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                .map_err(|e| err(&e))?
                .label(*label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(2)));
            chart.draw_series(pts.iter().map(|p| Circle::new(*p, 3, colour.filled()))).map_err(|e| err(&e))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font((crate::figure::FAMILY, 11))
            .draw()
            .map_err(|e| err(&e))?;
        root.present().map_err(|e| err(&e))?;
    }
    crate::figure::png_rgb(&buf, w, h)
}
