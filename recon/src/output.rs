//! Writing stage 1's results into a staged output directory (`heatsim::io::OutputDir`).
//!
//! Files (images are `[H, W]` of the pyramid level, NaN off the mesh):
//! - `flux_<i>.npy` float32: absorbed flux of video i divided by C, `q/C` in K/s (what the
//!   videos determine; times `heat_capacity` of `params.json` for W/m^2 when that is known);
//! - `flux_wm2_<i>.npy` float32: `q` in W/m^2, only when C was determined;
//! - `laplacian.npz`: `edges` int64 `[E, 2]` (vertex indices, i < j), `weights` float64 `[E]`
//!   (symmetrised `α w_ij` in 1/s for `masses` of mean 1, so
//!   `Δ_s[i,j] = w_ij/m_i`), `masses` float64 `[V]` (relative), `row_weights` float64
//!   `[E, 2]` (the raw per-row estimates `a_ij, a_ji`, 1/s), `pixels` int64 `[V]` (vertex ->
//!   pixel `v * W + u`), `tris` int64 `[F, 3]`;
//! - `residual.npy` float32 `[videos, H, W]`: RMS residual of the equations per vertex, K/s;
//! - `halfspace.npy` int8 `[H, W]` (with two or more videos): Eq. 9 from videos 0 and 1;
//! - `mask.npy` bool `[H, W]` (the mesh's vertices) and `camera.json` (the level's intrinsics);
//! - `params.json`: C, h, λ, c with uncertainties, how C and h were obtained, options, counts.

use std::path::Path;

use heatsim::io::OutputDir;
use ndarray::{Array1, Array2, Array3};
use ndarray_npy::{NpzWriter, WriteNpyExt};
use serde_json::json;

use crate::error::ReconError;
use crate::pyramid::Level;
use crate::stage1::Stage1Result;

fn put<T: WriteNpyExt>(out: &mut OutputDir, name: &str, a: &T) -> std::io::Result<()> {
    out.write_with(name, |w| a.write_npy(w).map_err(std::io::Error::other))
}

fn image(res: &Stage1Result, values: &[f64]) -> Array2<f32> {
    let g = &res.grid;
    let mut img = Array2::<f32>::from_elem((g.height, g.width), f32::NAN);
    for (k, &p) in g.pixels.iter().enumerate() {
        img[[p / g.width, p % g.width]] = values[k] as f32;
    }
    img
}

/// Writes stage 1's files (module doc) into `out`; `halfspace` from [`crate::halfspace`].
///
/// # Errors
/// I/O errors, naming `out_path`.
pub fn write_stage1(
    out: &mut OutputDir,
    out_path: &Path,
    res: &Stage1Result,
    level: &Level,
    halfspace: Option<(&[i8], f64)>,
    options: serde_json::Value,
) -> Result<(), ReconError> {
    let io = |e: std::io::Error| ReconError::io(out_path, e);
    let g = &res.grid;
    for (i, f) in res.flux_over_c.iter().enumerate() {
        let img = image(res, f);
        put(out, &format!("flux_{i}.npy"), &img).map_err(io)?;
        if let Some(c) = res.heat_capacity {
            let q: Vec<f64> = f.iter().map(|x| x * c.value).collect();
            let img = image(res, &q);
            put(out, &format!("flux_wm2_{i}.npy"), &img).map_err(io)?;
        }
    }
    let mut resid = Array3::<f32>::from_elem((res.residual_rms.len(), g.height, g.width), f32::NAN);
    for (v, r) in res.residual_rms.iter().enumerate() {
        resid.index_axis_mut(ndarray::Axis(0), v).assign(&image(res, r));
    }
    put(out, "residual.npy", &resid).map_err(io)?;
    if let Some((hs, _)) = halfspace {
        let mut img = Array2::<i8>::zeros((g.height, g.width));
        for (k, &p) in g.pixels.iter().enumerate() {
            img[[p / g.width, p % g.width]] = hs[k];
        }
        put(out, "halfspace.npy", &img).map_err(io)?;
    }
    let vmask = Array2::from_shape_vec((g.height, g.width), g.vertex_mask()).expect("mask size");
    put(out, "mask.npy", &vmask).map_err(io)?;

    // laplacian.npz
    let edges = Array2::from_shape_fn((res.edges.len(), 2), |(e, c)| res.edges[e][c] as i64);
    let rows = Array2::from_shape_fn((res.edges.len(), 2), |(e, c)| res.row_weights[e][c]);
    let tris = Array2::from_shape_fn((g.tris.len(), 3), |(t, c)| g.tris[t][c] as i64);
    let pixels: Array1<i64> = g.pixels.iter().map(|&p| p as i64).collect();
    let weights = Array1::from(res.weights.clone());
    let masses = Array1::from(res.masses.clone());
    out.write_with("laplacian.npz", |w| {
        let mut z = NpzWriter::new(w);
        let e = |r: Result<(), ndarray_npy::WriteNpzError>| r.map_err(std::io::Error::other);
        e(z.add_array("edges", &edges))?;
        e(z.add_array("weights", &weights))?;
        e(z.add_array("masses", &masses))?;
        e(z.add_array("row_weights", &rows))?;
        e(z.add_array("pixels", &pixels))?;
        e(z.add_array("tris", &tris))?;
        z.finish().map(|_| ()).map_err(std::io::Error::other)
    })
    .map_err(io)?;

    let cam = &level.camera;
    let camera = json!({
        "K": cam.k, "R": cam.r, "t": cam.t, "width": cam.width, "height": cam.height,
        "frame_interval_s": cam.frame_interval, "pyramid_level": level.level,
    });
    out.write_bytes("camera.json", serde_json::to_string_pretty(&camera).expect("json").as_bytes()).map_err(io)?;
    let params = json!({
        "units": "SI: C in J/(m^2 K), h and R in W/(m^2 K), lambda in 1/s, c in m^2 K/J, flux_<i>.npy in K/s (q/C)",
        "heat_capacity": res.heat_capacity,
        "convection": res.convection,
        "lambda": res.lambda,
        "lambda_definition": "(h + R)/C, the combination of C and h the videos determine",
        "c_inverse_heat_capacity": res.c,
        "radiation_coefficient_R": res.radiation_coefficient,
        "split": res.split,
        "uncertainty": "one standard deviation: sigma^2 H^-1 with H the Gauss-Newton Hessian of the profiled cost and sigma^2 = RSS/(rows - unknowns); C and h by first-order propagation; regressor noise not included",
        "halfspace_threshold": halfspace.map(|h| h.1),
        "halfspace_videos": halfspace.map(|_| [0, 1]),
        "vertices": g.vertex_count(),
        "triangles": g.tris.len(),
        "frame_pairs": res.pairs.len(),
        "equations": res.rows,
        "iterations": res.iterations,
        "cost_k2_per_s2": res.cost,
        "rms_residual_k_per_s": (res.cost / res.rows.max(1) as f64).sqrt(),
        "pyramid_level": level.level,
        "options": options,
    });
    out.write_bytes("params.json", serde_json::to_string_pretty(&params).expect("json").as_bytes()).map_err(io)?;
    Ok(())
}
