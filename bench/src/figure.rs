//! What every figure shares: the embedded font (DejaVu Sans Mono, licence in
//! `sweep/font/`, so no system font is needed), PNG encoding of an RGB buffer, [`optional`]
//! (a figure never stops a run), and the reconstruction's convergence plot.

use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};

static FONT: &[u8] = include_bytes!("sweep/font/DejaVuSansMono.ttf");

/// The font family every figure draws its text in.
pub const FAMILY: &str = "sans-serif";

/// Registers the embedded font under [`FAMILY`] (once per process).
pub fn ensure_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // The embedded font is valid TrueType; registration fails only for unparsable data.
        let _ = register_font(FAMILY, FontStyle::Normal, FONT);
    });
}

/// Makes a figure that must never cost a run its data: if `make` fails, or panics inside the
/// plotting library on input it cannot draw, a warning naming `what` is printed and `None`
/// returned; the caller writes everything else.
pub fn optional<T>(what: &str, make: impl FnOnce() -> anyhow::Result<T>) -> Option<T> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(make)) {
        Ok(Ok(v)) => Some(v),
        Ok(Err(e)) => {
            eprintln!("simbench: warning: {what} not drawn ({e:#}); the data are written");
            None
        }
        Err(_) => {
            eprintln!(
                "simbench: warning: {what} not drawn (the plotting library failed on this data); the data are written"
            );
            None
        }
    }
}

/// PNG bytes of an 8-bit RGB buffer of `w` x `h` pixels (row-major).
pub fn png_rgb(rgb: &[u8], w: u32, h: u32) -> anyhow::Result<Vec<u8>> {
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut writer = enc.write_header()?;
        writer.write_image_data(rgb)?;
        writer.finish()?;
    }
    Ok(out)
}

/// The convergence plot of the shape stage: data energy (log scale) against the iteration
/// counted over all levels, as PNG bytes.
pub fn convergence_png(log: &[heatrecon::stage2::coarse_to_fine::LogRow]) -> anyhow::Result<Vec<u8>> {
    ensure_font();
    let err = |e: &dyn std::fmt::Display| anyhow::anyhow!("{e}");
    let (w, h) = (900u32, 500u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let pts: Vec<(f64, f64)> = log
            .iter()
            .enumerate()
            .filter(|(_, r)| r.terms.data > 0.0 && r.terms.data.is_finite())
            .map(|(k, r)| (k as f64, r.terms.data.log10()))
            .collect();
        let (ymin, ymax) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |a, p| (a.0.min(p.1), a.1.max(p.1)));
        let (ymin, ymax) = match (ymin < ymax, ymin.is_finite()) {
            (true, _) => (ymin - 0.1, ymax + 0.1),
            (false, true) => (ymin - 1.0, ymin + 1.0),
            (false, false) => (0.0, 1.0), // no finite energy: an empty chart
        };
        let mut chart = ChartBuilder::on(&root)
            .caption("stage 2 convergence (levels coarse to fine)", (FAMILY, 18))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(0f64..(log.len().max(2) as f64), ymin..ymax)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("iteration (all levels)")
            .y_desc("log10 data energy")
            .label_style((FAMILY, 12))
            .draw()
            .map_err(|e| err(&e))?;
        chart.draw_series(LineSeries::new(pts, &BLUE)).map_err(|e| err(&e))?;
        root.present().map_err(|e| err(&e))?;
    }
    png_rgb(&buf, w, h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use heatrecon::stage2::coarse_to_fine::LogRow;

    #[test]
    fn convergence_plot_of_degenerate_logs_is_drawn() {
        let row = |data: f64| {
            let mut terms = heatrecon::stage2::energy::Terms::default();
            terms.data = data;
            LogRow { level: 0, iteration: 0, evaluations: 1, terms }
        };
        for log in [vec![], vec![row(1.0)], vec![row(f64::NAN), row(0.0)], vec![row(2.0); 3]] {
            let png = convergence_png(&log).expect("a figure for any log");
            assert!(png.starts_with(b"\x89PNG"));
        }
    }

    #[test]
    fn optional_turns_failures_and_panics_into_none() {
        assert_eq!(optional("a", || Ok(3)), Some(3));
        assert_eq!(optional::<i32>("b", || anyhow::bail!("no data")), None);
        assert_eq!(optional::<i32>("c", || panic!("plotting library")), None);
    }
}
