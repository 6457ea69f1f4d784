//! `convergence.png`: for each series, the worst frame of each pair of consecutive levels
//! against the pair's coarser level: RMS difference (mK, log scale) on the left, the pixel
//! Laplacian's relative difference (%, log scale) on the right, the criteria dashed.

use plotters::prelude::*;

use super::Study;
use crate::figure::{ensure_font, png_rgb, FAMILY};

const COLOURS: [RGBColor; 3] = [BLUE, RED, RGBColor(0, 140, 0)];

/// The figure as PNG bytes.
///
/// # Errors
/// A drawing failure of the plotting library.
pub fn png(study: &Study) -> anyhow::Result<Vec<u8>> {
    ensure_font();
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("{e}");
    let (w, h) = (1100u32, 480u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let panels = root.split_evenly((1, 2));
        let max_level = study.series.iter().map(|s| s.pairs.len()).max().unwrap_or(1).max(1) as f64;
        let criteria = [study.criteria.rms_k * 1e3, study.criteria.laplacian_rel * 100.0];
        let titles = ["worst frame RMS difference (mK)", "worst pixel-Laplacian difference (%)"];
        for (panel, ((title, limit), which)) in panels.iter().zip(titles.iter().zip(criteria).zip(0..)) {
            let value = |p: &super::Pair| if which == 0 { p.worst_rms_k * 1e3 } else { p.worst_laplacian_rel * 100.0 };
            let values: Vec<f64> = study
                .series
                .iter()
                .flat_map(|s| s.pairs.iter().map(value))
                .filter(|v| *v > 0.0)
                .chain([limit])
                .collect();
            let lo = values.iter().copied().fold(f64::INFINITY, f64::min).log10().floor();
            let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max).log10().ceil().max(lo + 1.0);
            let mut chart = ChartBuilder::on(panel)
                .caption(format!("{}: {title}", study.object), (FAMILY, 15))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(60)
                .build_cartesian_2d(-0.2..max_level - 0.8, lo..hi)
                .map_err(|e| err(&e))?;
            chart
                .configure_mesh()
                .x_desc("coarser level of the pair")
                .y_desc(format!("log10 {title}"))
                .label_style((FAMILY, 11))
                .draw()
                .map_err(|e| err(&e))?;
            chart
                .draw_series(DashedLineSeries::new(
                    [(-0.2, limit.log10()), (max_level - 0.8, limit.log10())],
                    6,
                    4,
                    BLACK.into(),
                ))
                .map_err(|e| err(&e))?;
            for (s, colour) in study.series.iter().zip(COLOURS.iter().cycle()) {
                let pts: Vec<(f64, f64)> =
                    s.pairs.iter().filter(|p| value(p) > 0.0).map(|p| (f64::from(p.level), value(p).log10())).collect();
                chart
                    .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                    .map_err(|e| err(&e))?
                    .label(s.series.name())
                    .legend(move |(x, y)| PathElement::new([(x, y), (x + 16, y)], colour.stroke_width(2)));
                chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, colour.filled()))).map_err(|e| err(&e))?;
            }
            chart
                .configure_series_labels()
                .label_font((FAMILY, 12))
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(|e| err(&e))?;
        }
        root.present().map_err(|e| err(&e))?;
    }
    png_rgb(&buf, w, h)
}
