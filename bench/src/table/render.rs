//! Error renders: the ground truth (grey, Lambert-shaded) beside the aligned reconstruction
//! coloured by its signed closest-point error, both seen orthographically from +z (the camera's
//! side; world x to the right, y up) on the same scale.
//!
//! Rasterisation is a plain z-buffer: each triangle's pixels (centres inside by barycentric
//! coordinates) keep the largest interpolated z (nearest to a camera at +z); the error colour is
//! interpolated from the vertices. Colour map: blue (-E) - white (0) - red (+E), linear, with
//! E = max(1 mm, 95th percentile of |error|) rounded up to 0.5 mm; positive = outside the
//! ground truth (the side its normal points to). Shading: 0.35 + 0.65 |n . l| with
//! l = (0.3, 0.4, 1)/|.| .

use heatrecon::eval::Evaluation;
use heatsim::mesh::TriMesh;
use plotters::prelude::*;

use crate::figure::{ensure_font, FAMILY};

/// Panel size in pixels (the longer side of the object's box fits into it).
pub const PANEL: u32 = 360;
const MARGIN: u32 = 30;
const BAR_W: u32 = 18;
const BAR_LABELS: u32 = 80;
const BACKGROUND: [u8; 3] = [255, 255, 255];

/// Blue-white-red for t in [-1, 1] (clamped).
pub fn diverging(t: f64) -> [u8; 3] {
    let t = t.clamp(-1.0, 1.0);
    let (blue, red) = ([33.0, 102.0, 172.0], [178.0, 24.0, 43.0]);
    let end = if t < 0.0 { blue } else { red };
    let s = t.abs();
    [0, 1, 2].map(|c| (255.0 + s * (end[c] - 255.0)).round() as u8)
}

/// A z-buffered orthographic rendering from +z: per pixel, the face index and the barycentric
/// coordinates of the nearest surface point, `None` where nothing is seen.
pub struct Raster {
    pub hits: Vec<Option<(usize, [f64; 3])>>,
}

/// Rasterises `mesh` into `width` x `height` pixels covering the world box `lo`..`hi` (x, y in
/// m; image row 0 at y = hi).
pub fn rasterize(mesh: &TriMesh, lo: [f64; 2], hi: [f64; 2], width: usize, height: usize) -> Raster {
    let mut zbuf = vec![f64::NEG_INFINITY; width * height];
    let mut hits = vec![None; width * height];
    let sx = width as f64 / (hi[0] - lo[0]);
    let sy = height as f64 / (hi[1] - lo[1]);
    let to_px = |p: [f64; 3]| [(p[0] - lo[0]) * sx, (hi[1] - p[1]) * sy];
    for (f, t) in mesh.tris.iter().enumerate() {
        let p = t.map(|i| mesh.verts[i]);
        let q = p.map(to_px);
        let area = (q[1][0] - q[0][0]) * (q[2][1] - q[0][1]) - (q[2][0] - q[0][0]) * (q[1][1] - q[0][1]);
        if area.abs() < 1e-12 {
            continue;
        }
        let xmin = q.iter().map(|v| v[0]).fold(f64::INFINITY, f64::min).floor().max(0.0) as usize;
        let xmax = (q.iter().map(|v| v[0]).fold(f64::NEG_INFINITY, f64::max).ceil() as usize).min(width);
        let ymin = q.iter().map(|v| v[1]).fold(f64::INFINITY, f64::min).floor().max(0.0) as usize;
        let ymax = (q.iter().map(|v| v[1]).fold(f64::NEG_INFINITY, f64::max).ceil() as usize).min(height);
        for y in ymin..ymax {
            for x in xmin..xmax {
                let c = [x as f64 + 0.5, y as f64 + 0.5];
                let w0 = ((q[1][0] - c[0]) * (q[2][1] - c[1]) - (q[2][0] - c[0]) * (q[1][1] - c[1])) / area;
                let w1 = ((q[2][0] - c[0]) * (q[0][1] - c[1]) - (q[0][0] - c[0]) * (q[2][1] - c[1])) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 < -1e-9 || w1 < -1e-9 || w2 < -1e-9 {
                    continue;
                }
                let z = w0 * p[0][2] + w1 * p[1][2] + w2 * p[2][2];
                let k = y * width + x;
                if z > zbuf[k] {
                    zbuf[k] = z;
                    hits[k] = Some((f, [w0, w1, w2]));
                }
            }
        }
    }
    Raster { hits }
}

fn shade(mesh: &TriMesh, f: usize) -> f64 {
    let n = mesh.face_normal(f);
    let l = [0.3_f64, 0.4, 1.0];
    let ln = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
    0.35 + 0.65 * ((n[0] * l[0] + n[1] * l[1] + n[2] * l[2]) / ln).abs()
}

/// The colour scale E (m) of a set of signed errors (see the module documentation).
pub fn error_scale(signed: &[f64]) -> f64 {
    let mut a: Vec<f64> = signed.iter().map(|v| v.abs()).filter(|v| v.is_finite()).collect();
    a.sort_by(f64::total_cmp);
    let p95 = a.get(((0.95 * a.len() as f64).ceil() as usize).saturating_sub(1)).copied().unwrap_or(0.0);
    (p95.max(1e-3) / 0.5e-3).ceil() * 0.5e-3
}

/// The PNG figure of one row: ground truth | reconstruction by signed error | colour bar.
///
/// # Errors
/// Plotting or encoding failures.
pub fn error_figure(gt: &TriMesh, e: &Evaluation, title: &str) -> anyhow::Result<Vec<u8>> {
    ensure_font();
    let rec = &e.aligned;
    let (glo, ghi) = gt.bounding_box();
    let (rlo, rhi) = rec.bounding_box();
    let lo = [glo[0].min(rlo[0]), glo[1].min(rlo[1])];
    let hi = [ghi[0].max(rhi[0]), ghi[1].max(rhi[1])];
    let pad = 0.03 * (hi[0] - lo[0]).max(hi[1] - lo[1]);
    let (lo, hi) = ([lo[0] - pad, lo[1] - pad], [hi[0] + pad, hi[1] + pad]);
    let aspect = (hi[1] - lo[1]) / (hi[0] - lo[0]);
    let (pw, ph) = if aspect <= 1.0 {
        (PANEL as usize, ((PANEL as f64 * aspect).round() as usize).max(1))
    } else {
        (((PANEL as f64 / aspect).round() as usize).max(1), PANEL as usize)
    };
    let scale = error_scale(&e.vertex_signed_m);
    let g = rasterize(gt, lo, hi, pw, ph);
    let r = rasterize(rec, lo, hi, pw, ph);
    let gt_px: Vec<[u8; 3]> = g
        .hits
        .iter()
        .map(|h| match h {
            Some((f, _)) => [(200.0 * shade(gt, *f)) as u8; 3],
            None => BACKGROUND,
        })
        .collect();
    let rec_px: Vec<[u8; 3]> = r
        .hits
        .iter()
        .map(|h| match h {
            Some((f, w)) => {
                let t = rec.tris[*f];
                let err: f64 = (0..3).map(|k| w[k] * e.vertex_signed_m[t[k]]).sum();
                let c = diverging(err / scale);
                let s = 0.55 + 0.45 * shade(rec, *f);
                c.map(|v| (f64::from(v) * s).round() as u8)
            }
            None => BACKGROUND,
        })
        .collect();

    let width = 3 * MARGIN + 2 * pw as u32 + MARGIN + BAR_W + BAR_LABELS;
    let height = ph as u32 + 2 * MARGIN + 40;
    let mut buf = vec![255u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (width, height)).into_drawing_area();
        let err = |e: DrawingAreaErrorKind<_>| anyhow::anyhow!("drawing the render: {e:?}");
        let top = (MARGIN + 30) as i32;
        let x0 = MARGIN as i32;
        let x1 = (2 * MARGIN + pw as u32) as i32;
        for (img, x) in [(&gt_px, x0), (&rec_px, x1)] {
            for (k, c) in img.iter().enumerate() {
                if *c != BACKGROUND {
                    let (px, py) = ((k % pw) as i32, (k / pw) as i32);
                    root.draw_pixel((x + px, top + py), &RGBColor(c[0], c[1], c[2])).map_err(err)?;
                }
            }
            root.draw(&Rectangle::new([(x - 1, top - 1), (x + pw as i32, top + ph as i32)], BLACK.stroke_width(1)))
                .map_err(err)?;
        }
        let style = (FAMILY, 14).into_font().color(&BLACK);
        root.draw(&Text::new(title.to_string(), (x0, 6), style.clone())).map_err(err)?;
        root.draw(&Text::new("ground truth (cropped to the view)".to_string(), (x0, top - 20), style.clone()))
            .map_err(err)?;
        root.draw(&Text::new(
            format!("reconstruction: MAE {:.2} mm, RMSE {:.2} mm", e.mae_mm(), e.forward.rmse * 1e3),
            (x1, top - 20),
            style.clone(),
        ))
        .map_err(err)?;
        // Colour bar.
        let bx = (3 * MARGIN + 2 * pw as u32) as i32;
        for y in 0..ph as i32 {
            let t = 1.0 - 2.0 * (f64::from(y) + 0.5) / ph as f64;
            let c = diverging(t);
            root.draw(&Rectangle::new(
                [(bx, top + y), (bx + BAR_W as i32, top + y + 1)],
                RGBColor(c[0], c[1], c[2]).filled(),
            ))
            .map_err(err)?;
        }
        let small = (FAMILY, 12).into_font().color(&BLACK);
        let lx = bx + BAR_W as i32 + 4;
        for (frac, v) in [(0.0, scale), (0.5, 0.0), (1.0, -scale)] {
            let y = top + (frac * (ph as f64 - 1.0)) as i32 - 6;
            root.draw(&Text::new(format!("{:+.1} mm", v * 1e3), (lx, y), small.clone())).map_err(err)?;
        }
        root.draw(&Text::new(
            "signed error, + outside; orthographic from +z (x right, y up), same scale".to_string(),
            (x0, top + ph as i32 + 10),
            small,
        ))
        .map_err(err)?;
        root.present().map_err(err)?;
    }
    crate::figure::png_rgb(&buf, width, height)
}
