//! [`write_preview_png`]: a false-colour 8-bit RGB PNG of a scalar image with a colour bar.
//!
//! Layout: the W x H image, a [`BAR_GAP`]-pixel grey gap, then a [`BAR_WIDTH`]-pixel vertical
//! colour bar running from `hi` at the top to `lo` at the bottom. Colour map: matplotlib's
//! *inferno* (perceptually uniform, dark = cold), sampled at 17 evenly spaced stops and
//! interpolated linearly in sRGB. Values are clamped to `[lo, hi]`; NaN pixels (no data, e.g.
//! background) are mid grey. Tick labels would need a font, so the range is written instead as
//! PNG `tEXt` chunks: `Minimum` and `Maximum` (the values of `lo` and `hi`, in the image's unit),
//! `Colormap`, and a `Description` of the layout.

use std::io::{self, Write};

/// Width of the colour bar, in pixels.
pub const BAR_WIDTH: u32 = 16;

/// Gap between the image and the colour bar, in pixels.
pub const BAR_GAP: u32 = 8;

/// Colour of NaN pixels and of the gap (sRGB).
pub const NO_DATA: [u8; 3] = [128, 128, 128];

/// Matplotlib's inferno at t = i / 16, i = 0..=16 (entries round(255 i / 16) of its 256-entry
/// table, by van der Walt and Smith, CC0), as 8-bit sRGB.
const INFERNO: [[u8; 3]; 17] = [
    [0, 0, 4],
    [11, 7, 36],
    [33, 12, 74],
    [61, 9, 101],
    [87, 16, 110],
    [113, 25, 110],
    [138, 34, 106],
    [163, 44, 97],
    [188, 55, 84],
    [208, 69, 69],
    [227, 89, 51],
    [241, 113, 31],
    [249, 140, 10],
    [252, 170, 15],
    [249, 201, 50],
    [242, 232, 101],
    [252, 255, 164],
];

/// The inferno colour of `t` in [0, 1] (clamped; NaN gives [`NO_DATA`]).
pub fn inferno(t: f64) -> [u8; 3] {
    if t.is_nan() {
        return NO_DATA;
    }
    let x = t.clamp(0.0, 1.0) * (INFERNO.len() - 1) as f64;
    let i = (x.floor() as usize).min(INFERNO.len() - 2);
    let f = x - i as f64;
    let (a, b) = (INFERNO[i], INFERNO[i + 1]);
    [0, 1, 2].map(|c| (f64::from(a[c]) + f * (f64::from(b[c]) - f64::from(a[c]))).round() as u8)
}

/// A colour range that can be drawn: `(lo, hi)` itself when both are finite and `lo < hi`; a
/// single finite value (a uniform image: lo == hi, or only one of them finite) widened to
/// +-max(1e-3, 1e-5 |value|) around it, so it shows in the middle of the colour map; (0, 1)
/// when neither is finite (no data: the image is all grey).
pub fn display_range(lo: f32, hi: f32) -> (f32, f32) {
    if lo.is_finite() && hi.is_finite() && lo < hi {
        return (lo, hi);
    }
    let centre = match (lo.is_finite(), hi.is_finite()) {
        (true, true) => 0.5 * (lo + hi),
        (true, false) => lo,
        (false, true) => hi,
        (false, false) => return (0.0, 1.0),
    };
    let half = (1e-5 * centre.abs()).max(1e-3);
    (centre - half, centre + half)
}

/// Writes `image` (#H*W values, row-major, any unit; NaN = no data) as a PNG preview with a
/// colour bar mapping `lo` (bottom, black) to `hi` (top, pale yellow); see the module
/// documentation for the layout and the metadata. The PNG is `W + BAR_GAP + BAR_WIDTH` pixels
/// wide and `H` high.
///
/// A range that cannot be drawn (a uniform image, no data) is widened by [`display_range`],
/// and the range drawn is the one written to the metadata.
///
/// # Errors
/// [`io::ErrorKind::InvalidInput`] if `width` or `height` is 0 or `image.len() != W * H`;
/// otherwise the errors of `w` and of the encoder.
pub fn write_preview_png(
    w: &mut impl Write,
    image: &[f32],
    width: u32,
    height: u32,
    lo: f32,
    hi: f32,
) -> io::Result<()> {
    let invalid = |msg: String| io::Error::new(io::ErrorKind::InvalidInput, msg);
    if width == 0 || height == 0 {
        return Err(invalid(format!("preview: empty image {width} x {height}")));
    }
    if image.len() != width as usize * height as usize {
        return Err(invalid(format!("preview: {} values for a {width} x {height} image", image.len())));
    }
    let (lo, hi) = display_range(lo, hi);
    let out_w = width + BAR_GAP + BAR_WIDTH;
    let (lo64, span) = (f64::from(lo), f64::from(hi) - f64::from(lo));
    let mut data = Vec::with_capacity(out_w as usize * height as usize * 3);
    for (row, line) in image.chunks(width as usize).enumerate() {
        for &x in line {
            data.extend_from_slice(&inferno((f64::from(x) - lo64) / span));
        }
        for _ in 0..BAR_GAP {
            data.extend_from_slice(&NO_DATA);
        }
        // Row centres split [lo, hi] into H equal parts, hi at the top.
        let t = (f64::from(height) - row as f64 - 0.5) / f64::from(height);
        let colour = inferno(t);
        for _ in 0..BAR_WIDTH {
            data.extend_from_slice(&colour);
        }
    }

    let mut encoder = png::Encoder::new(w, out_w, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let text = [
        ("Minimum", format!("{lo}")),
        ("Maximum", format!("{hi}")),
        ("Colormap", "inferno (17 stops, linear interpolation); NaN = grey (128, 128, 128)".to_owned()),
        (
            "Description",
            format!(
                "left {width} x {height}: image; right {BAR_WIDTH} px after a {BAR_GAP} px gap: \
                 colour bar from Minimum (bottom) to Maximum (top)"
            ),
        ),
    ];
    for (key, value) in text {
        encoder.add_text_chunk(key.to_owned(), value)?;
    }
    let mut writer = encoder.write_header()?;
    writer.write_image_data(&data)?;
    writer.finish()?;
    Ok(())
}
