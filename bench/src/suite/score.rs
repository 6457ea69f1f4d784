//! Scoring a case's reconstruction against the ground truth the camera saw, and the `plane`
//! baseline.
//!
//! The ground truth is the object's `gt_mesh.obj` cropped to the pixels the left camera saw
//! ([`load_gt`]). The scores:
//! - rigid: [`heatrecon::eval::evaluate`] after rigid ICP: `mae_mm` (the paper's metric: mean
//!   distance from the reconstruction's vertices to the truth), the symmetric mean, RMSE, the
//!   normal error and the ICP rotation (deg);
//! - similarity: the same after ICP with a scale, `similarity_mae_mm` and the scale; shape and
//!   size are judged apart;
//! - size: `depth_ratio`, the mean depth z_c of the reconstruction over the pixels where both
//!   it and the truth are seen, divided by the truth's mean over the same pixels (1 = right
//!   distance; on camera rays, too far also means too large). `size_error` = depth_ratio - 1.

use std::path::Path;

use anyhow::Context;
use heatrecon::eval::{crop_to_view, evaluate, AlignMode, CropTolerance, DepthView, EvalOptions};
use heatsim::camera::Camera;
use heatsim::mesh::TriMesh;
use serde_json::{json, Value};

/// The scores of one reconstruction (module documentation) as JSON fields.
///
/// # Errors
/// Unreadable ground truth, or a reconstruction that cannot be aligned.
pub fn score(recon: &TriMesh, truth_dir: &Path) -> anyhow::Result<Value> {
    let gt = load_gt(truth_dir)?;
    let rigid = evaluate(recon, &gt, &EvalOptions::default()).context("rigid alignment")?;
    let mut v = json!({
        "mae_mm": rigid.mae_mm(),
        "symmetric_mm": rigid.symmetric_mm(),
        "rmse_mm": rigid.forward.rmse * 1e3,
        "normal_deg": rigid.normal_deg,
        "rotation_deg": rigid.alignment.transform.angle_deg(),
    });
    match evaluate(recon, &gt, &EvalOptions { align: AlignMode::Similarity, ..EvalOptions::default() }) {
        Ok(s) => {
            v["similarity_mae_mm"] = json!(s.mae_mm());
            v["similarity_scale"] = json!(s.alignment.transform.scale);
        }
        Err(e) => v["similarity_error"] = json!(e.to_string()),
    }
    let view = DepthView::load(truth_dir)?
        .with_context(|| format!("{}: no camera.json and gt_depth.npy", truth_dir.display()))?;
    if let Some(ratio) = depth_ratio(recon, &view) {
        v["depth_ratio"] = json!(ratio);
        v["size_error"] = json!(ratio - 1.0);
    }
    Ok(v)
}

/// The ground truth of a dataset: `gt_mesh.obj` cropped to the pixels the camera saw.
///
/// # Errors
/// A missing or unreadable mesh, camera or depth.
pub fn load_gt(dataset: &Path) -> anyhow::Result<TriMesh> {
    let path = dataset.join("gt_mesh.obj");
    let full = heatsim::mesh::read_surface(&path).with_context(|| format!("reading {}", path.display()))?;
    let view =
        DepthView::load(dataset)?.with_context(|| format!("{}: no camera.json and gt_depth.npy", dataset.display()))?;
    Ok(crop_to_view(&full, &view, &CropTolerance::default())
        .with_context(|| format!("cropping {}", path.display()))?
        .mesh)
}

/// The camera of a depth view.
fn camera(view: &DepthView) -> Camera {
    Camera { width: view.width as u32, height: view.height as u32, k: view.k, r: view.r, t: view.t }
}

/// Mean reconstruction depth over mean true depth on the pixels both cover (module
/// documentation); `None` when they share no pixel.
pub fn depth_ratio(recon: &TriMesh, view: &DepthView) -> Option<f64> {
    let render = heatsim::camera::rasterize(&camera(view), &recon.verts, &recon.tris);
    let depth = render.depth();
    let (mut sr, mut st, mut n) = (0.0, 0.0, 0usize);
    for (r, t) in depth.iter().zip(view.depth.iter()) {
        if r.is_finite() && t.is_finite() {
            sr += f64::from(*r);
            st += f64::from(*t);
            n += 1;
        }
    }
    (n > 0).then(|| sr / st)
}

/// The `plane` baseline: a fronto-parallel plane over the object's pixels at the true mean
/// depth, in the world frame (m). It knows the mean depth and nothing else, so its score is
/// what no shape information gets.
///
/// # Errors
/// Unreadable ground truth, an empty view.
pub fn plane(truth_dir: &Path) -> anyhow::Result<TriMesh> {
    let view = DepthView::load(truth_dir)?
        .with_context(|| format!("{}: no camera.json and gt_depth.npy", truth_dir.display()))?;
    let seen: Vec<f64> = view.depth.iter().filter(|d| d.is_finite()).map(|&d| f64::from(d)).collect();
    anyhow::ensure!(!seen.is_empty(), "{}: the object covers no pixel", truth_dir.display());
    let z = seen.iter().sum::<f64>() / seen.len() as f64;
    let cam = camera(&view);
    let (w, h) = (view.width, view.height);
    let inside = |u: usize, v: usize| view.depth[[v, u]].is_finite();
    let mut index = vec![usize::MAX; w * h];
    let mut verts = Vec::new();
    for v in 0..h {
        for u in 0..w {
            if inside(u, v) {
                index[v * w + u] = verts.len();
                verts.push(cam.unproject(u as f64, v as f64, z));
            }
        }
    }
    let mut tris = Vec::new();
    for v in 0..h.saturating_sub(1) {
        for u in 0..w.saturating_sub(1) {
            let [a, b, c, d] =
                [index[v * w + u], index[v * w + u + 1], index[(v + 1) * w + u], index[(v + 1) * w + u + 1]];
            if a != usize::MAX && b != usize::MAX && c != usize::MAX && d != usize::MAX {
                tris.push([a, c, b]);
                tris.push([b, c, d]);
            }
        }
    }
    anyhow::ensure!(!tris.is_empty(), "{}: the object's pixels hold no 2 x 2 block", truth_dir.display());
    Ok(TriMesh::try_new(verts, tris)?)
}
