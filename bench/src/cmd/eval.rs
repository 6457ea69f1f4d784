//! `simbench eval --recon R --gt G [--align rigid|similarity|none] [--no-crop] [--out-ply F]`:
//! scores a reconstruction against a ground-truth surface (`heatrecon::eval`) and prints JSON.
//!
//! Distances in the JSON are millimetres (`*_mm`, as in the paper's tables); everything else is
//! SI. `mae_mm` is the mean over the aligned reconstruction's vertices of the distance to the
//! closest point on the ground-truth triangles; see `definitions` in the output. Beside a
//! dataset's camera and depth, `size` gives the depth ratio of the suite's scores
//! (`crate::suite::score`): the reconstruction's distance and size over the truth's.

use anyhow::Context;
use heatrecon::eval::{crop_to_view, evaluate, AlignMode, CropTolerance, DepthView, EvalOptions};
use heatsim::mesh::read_surface;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum AlignArg {
    /// Point-to-plane ICP: rotation and translation.
    Rigid,
    /// Point-to-plane ICP with a uniform scale.
    Similarity,
    /// Measure in the given frames.
    None,
}

#[derive(clap::Args)]
pub struct Args {
    /// Reconstruction surface (OBJ, PLY, glTF or GLB; metres).
    #[arg(long)]
    recon: PathBuf,
    /// Ground-truth surface (OBJ, PLY, glTF or GLB; metres). When `camera.json` and
    /// `gt_depth.npy` lie beside it (a dataset of `simbench simulate`), it is cropped to what
    /// the camera saw and the output gains `size` (the depth ratio).
    #[arg(long)]
    gt: PathBuf,
    /// Alignment of the reconstruction onto the ground truth before measuring.
    #[arg(long, value_enum, default_value = "rigid")]
    align: AlignArg,
    /// Do not crop the ground truth to the camera's view.
    #[arg(long)]
    no_crop: bool,
    /// Also write the aligned reconstruction as PLY with a per-vertex float `signed_error_m`
    /// (m; positive outside the ground truth).
    #[arg(long)]
    out_ply: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let start = Instant::now();
    let recon = read_surface(&args.recon).context("reading the reconstruction (--recon)")?;
    let gt_full = read_surface(&args.gt).context("reading the ground truth (--gt)")?;
    let dir = args.gt.parent().map(|p| if p.as_os_str().is_empty() { std::path::Path::new(".") } else { p });
    let tol = CropTolerance::default();
    let mut size_json = serde_json::Value::Null;
    let (gt, crop_json) = match (args.no_crop, dir) {
        (true, _) => (gt_full, serde_json::json!({ "applied": false, "reason": "--no-crop" })),
        (false, None) => (gt_full, serde_json::json!({ "applied": false, "reason": "no directory" })),
        (false, Some(dir)) => match DepthView::load(dir)? {
            None => (
                gt_full,
                serde_json::json!({
                    "applied": false,
                    "reason": format!("no {} and {} beside the ground truth", heatrecon::eval::crop::CAMERA_FILE, heatrecon::eval::crop::DEPTH_FILE),
                }),
            ),
            Some(view) => {
                if let Some(ratio) = crate::suite::score::depth_ratio(&recon, &view) {
                    size_json = serde_json::json!({
                        "depth_ratio": ratio,
                        "size_error": ratio - 1.0,
                        "rule": "the reconstruction's mean camera depth over the truth's, on the pixels both cover (1: right distance and size)",
                    });
                }
                let crop =
                    crop_to_view(&gt_full, &view, &tol).with_context(|| format!("cropping {}", args.gt.display()))?;
                let json = serde_json::json!({
                    "applied": true,
                    "kept_triangles": crop.kept,
                    "total_triangles": crop.total,
                    "camera": view.files[0],
                    "depth": view.files[1],
                    "rule": "keep a triangle when its centroid projects into the mask and its camera depth is within the tolerance of gt_depth in the 3 x 3 pixels around it",
                    "tolerance": { "abs_m": tol.abs_m, "pixel_footprints": tol.pixels },
                });
                (crop.mesh, json)
            }
        },
    };
    let align = match args.align {
        AlignArg::Rigid => AlignMode::Rigid,
        AlignArg::Similarity => AlignMode::Similarity,
        AlignArg::None => AlignMode::None,
    };
    let e = evaluate(&recon, &gt, &EvalOptions { align, ..EvalOptions::default() })
        .with_context(|| format!("evaluating {} against {}", args.recon.display(), args.gt.display()))?;
    if let Some(path) = &args.out_ply {
        let signed: Vec<f32> = e.vertex_signed_m.iter().map(|&v| v as f32).collect();
        let mut bytes = Vec::new();
        heatsim::mesh::write_ply_to(
            &mut bytes,
            &e.aligned,
            &[("signed_error_m", &signed)],
            &format!("reconstruction {} aligned to {}", args.recon.display(), args.gt.display()),
        )?;
        heatsim::io::write_atomic(path, &bytes).with_context(|| format!("writing {}", path.display()))?;
    }
    let mut json = e.to_json();
    json["recon"] = serde_json::json!(args.recon);
    json["gt"] = serde_json::json!(args.gt);
    json["crop"] = crop_json;
    if !size_json.is_null() {
        json["size"] = size_json;
    }
    json["units"] =
        serde_json::json!("distances *_mm in millimetres; translation_m in metres; angles in degrees; seconds in s");
    json["seconds"] = serde_json::json!(start.elapsed().as_secs_f64());
    println!("{}", serde_json::to_string_pretty(&json)?);
    Ok(())
}
