//! The sweep's figures as PNG and SVG (plotters): `thickness_vs_reference` (Fig. 2 left:
//! mean |video_d - video_1mm| in K against thickness, one line per material) and
//! `surface_vs_volumetric` (Fig. 2 right: percentage error of the surface models against the
//! volumetric video, one panel per shape and metric, one line per material; solid lines and
//! circles: `surface`, thin lines and triangles: `surface_effective`). Thickness axes are
//! logarithmic. Text uses the embedded DejaVu Sans Mono (licence in `font/`), so no system
//! font is needed.

use plotters::coord::Shift;
use plotters::prelude::*;

use super::cells::Shape;
use super::results::Results;

use crate::figure::{ensure_font, FAMILY};

const COLOURS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
];

type DrawResult = Result<(), Box<dyn std::error::Error>>;

fn colour(i: usize) -> RGBColor {
    COLOURS[i % COLOURS.len()]
}

/// Distinct values in first-seen order.
fn distinct<T: PartialEq + Clone>(it: impl Iterator<Item = T>) -> Vec<T> {
    let mut v: Vec<T> = Vec::new();
    for x in it {
        if !v.contains(&x) {
            v.push(x);
        }
    }
    v
}

/// The largest finite value, 0 if none (an infinite value would make plotters loop forever).
fn finite_max(values: impl Iterator<Item = f64>) -> f64 {
    values.filter(|v| v.is_finite()).fold(0.0, f64::max)
}

/// The points with finite coordinates and a positive thickness (the x axis is logarithmic).
fn drawable(points: impl Iterator<Item = (f64, f64)>) -> Vec<(f64, f64)> {
    points.filter(|(x, y)| x.is_finite() && *x > 0.0 && y.is_finite()).collect()
}

/// The smallest and largest positive finite thickness; (1e-3, 1e-3) if there is none.
fn thickness_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) =
        values.filter(|d| d.is_finite() && *d > 0.0).fold((f64::INFINITY, 0.0f64), |(a, b), d| (a.min(d), b.max(d)));
    if lo <= hi {
        (lo, hi)
    } else {
        (1e-3, 1e-3)
    }
}

fn thickness_figure<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, res: &Results) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let materials = distinct(res.part1.iter().map(|r| r.material.clone()));
    let (lo, hi) = thickness_range(res.part1.iter().map(|r| r.thickness_m));
    let ymax = finite_max(res.part1.iter().map(|r| r.mean_abs_err_k)).max(1e-6) * 1.1;
    let mut chart = ChartBuilder::on(&root)
        .caption("Volumetric video at thickness d against d = 1 mm (cuboid, 15 s)", (FAMILY, 18))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d((lo.min(hi) * 0.9..hi * 1.1).log_scale(), 0.0..ymax)?;
    chart
        .configure_mesh()
        .x_desc("thickness d (m)")
        .y_desc("mean |T_d - T_1mm| (K)")
        .x_label_formatter(&|x| format!("{x:.0e}"))
        .label_style((FAMILY, 14))
        .draw()?;
    for (i, m) in materials.iter().enumerate() {
        let pts: Vec<(f64, f64)> =
            drawable(res.part1.iter().filter(|r| &r.material == m).map(|r| (r.thickness_m, r.mean_abs_err_k)));
        let c = colour(i);
        chart
            .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))?
            .label(m.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.filled())))?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font((FAMILY, 14))
        .draw()?;
    root.present()?;
    Ok(())
}

fn surface_figure<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, res: &Results) -> DrawResult
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let shapes: Vec<Shape> = distinct(res.part2.iter().map(|r| r.shape));
    let materials = distinct(res.part2.iter().map(|r| r.material.clone()));
    let (root_title, body) = root.split_vertically(36);
    root_title.titled(
        "Surface models against the volumetric video (15 s; solid: surface, thin: surface_effective)",
        (FAMILY, 18),
    )?;
    let panels = body.split_evenly((2, shapes.len().max(1)));
    let (lo, hi) = thickness_range(res.part2.iter().map(|r| r.thickness_m));
    for (row, metric) in ["pct_err_rise", "pct_err_abs_K"].iter().enumerate() {
        let value = |r: &super::results::Part2Row| if row == 0 { r.pct_err_rise } else { r.pct_err_abs_k };
        let ymax = finite_max(res.part2.iter().map(value)).max(1e-3) * 1.1;
        for (col, shape) in shapes.iter().enumerate() {
            let area = &panels[row * shapes.len() + col];
            let mut chart = ChartBuilder::on(area)
                .caption(format!("{}: {metric}", shape.name()), (FAMILY, 15))
                .margin(8)
                .x_label_area_size(35)
                .y_label_area_size(50)
                .build_cartesian_2d((lo.min(hi) * 0.9..hi * 1.1).log_scale(), 0.0..ymax)?;
            chart
                .configure_mesh()
                .x_desc("thickness d (m)")
                .y_desc("error (%)")
                .x_label_formatter(&|x| format!("{x:.0e}"))
                .label_style((FAMILY, 12))
                .draw()?;
            for (i, m) in materials.iter().enumerate() {
                let c = colour(i);
                for model in ["surface", "surface_effective"] {
                    let pts = drawable(
                        res.part2
                            .iter()
                            .filter(|r| r.shape == *shape && &r.material == m && r.model == model)
                            .map(|r| (r.thickness_m, value(r))),
                    );
                    if pts.is_empty() {
                        continue;
                    }
                    if model == "surface" {
                        let s = chart.draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))?;
                        if row == 0 && col == 0 {
                            s.label(m.as_str())
                                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
                        }
                        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.filled())))?;
                    } else {
                        chart.draw_series(LineSeries::new(pts.clone(), c.stroke_width(1)))?;
                        chart.draw_series(pts.iter().map(|&p| TriangleMarker::new(p, 4, c.stroke_width(1))))?;
                    }
                }
            }
            if row == 0 && col == 0 {
                chart
                    .configure_series_labels()
                    .position(SeriesLabelPosition::UpperLeft)
                    .background_style(WHITE.mix(0.8))
                    .border_style(BLACK)
                    .label_font((FAMILY, 12))
                    .draw()?;
            }
        }
    }
    root.present()?;
    Ok(())
}

fn png_bytes(rgb: &[u8], (w, h): (u32, u32)) -> anyhow::Result<Vec<u8>> {
    crate::figure::png_rgb(rgb, w, h)
}

/// Every figure as (file name, bytes).
pub fn all(res: &Results) -> anyhow::Result<Vec<(String, Vec<u8>)>> {
    ensure_font();
    let mut files = Vec::new();
    let err = |e: Box<dyn std::error::Error>| anyhow::anyhow!("{e}");
    if !res.part1.is_empty() {
        let size = (900, 600);
        let mut rgb = vec![0u8; (size.0 * size.1 * 3) as usize];
        thickness_figure(BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area(), res).map_err(err)?;
        files.push(("thickness_vs_reference.png".to_string(), png_bytes(&rgb, size)?));
        let mut svg = String::new();
        thickness_figure(SVGBackend::with_string(&mut svg, size).into_drawing_area(), res).map_err(err)?;
        files.push(("thickness_vs_reference.svg".to_string(), svg.into_bytes()));
    }
    if !res.part2.is_empty() {
        let shapes = distinct(res.part2.iter().map(|r| r.shape)).len().max(1) as u32;
        let size = (420 * shapes, 760);
        let mut rgb = vec![0u8; (size.0 * size.1 * 3) as usize];
        surface_figure(BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area(), res).map_err(err)?;
        files.push(("surface_vs_volumetric.png".to_string(), png_bytes(&rgb, size)?));
        let mut svg = String::new();
        surface_figure(SVGBackend::with_string(&mut svg, size).into_drawing_area(), res).map_err(err)?;
        files.push(("surface_vs_volumetric.svg".to_string(), svg.into_bytes()));
    }
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sweep::results::{Part1Row, Part2Row};

    #[test]
    fn sweep_figures_of_degenerate_results_are_drawn() {
        let p1 = |d: f64, err: f64| Part1Row {
            material: "pla".into(),
            thickness_m: d,
            mean_abs_err_k: err,
            max_abs_err_k: err,
            mean_rise_k: 1.0,
        };
        let p2 = |d: f64, err: f64| Part2Row {
            shape: Shape::Cuboid,
            material: "pla".into(),
            thickness_m: d,
            model: "surface".into(),
            pct_err_abs_k: err,
            pct_err_rise: err,
            mean_abs_k: err,
            volumetric_mean_rise_k: 1.0,
            layer_thickness_m: d,
        };
        let results = |part1, part2| Results {
            quick: true,
            part1,
            part2,
            conv: Vec::new(),
            timings: Vec::new(),
            runs: Vec::new(),
        };
        for res in [
            results(vec![], vec![]),
            results(vec![p1(0.01, 0.0)], vec![p2(0.01, 0.0)]),
            results(vec![p1(0.01, f64::NAN), p1(0.02, f64::INFINITY)], vec![p2(0.01, f64::NAN)]),
        ] {
            let files = all(&res).expect("figures for any results");
            assert!(files.iter().all(|(_, bytes)| !bytes.is_empty()));
        }
    }
}
