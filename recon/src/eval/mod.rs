//! Scoring a reconstruction against a ground-truth surface (what `simbench eval` prints).
//!
//! All distances are in metres in the API; the JSON of [`Evaluation::to_json`] reports them in
//! millimetres (field names end in `_mm`, as the paper's tables), everything else SI.
//!
//! 1. Alignment ([`icp`]): the reconstruction is moved onto the ground truth by point-to-plane
//!    ICP with outlier trimming (rigid, or with a uniform scale), or left as is. The uniform
//!    scale is not an ICP unknown: the forward distances alone fall as a partial reconstruction
//!    shrinks towards a point (every table row collapsed so), so it is searched for on the
//!    symmetric trimmed distance, forward and reverse, with rigid ICP at each scale
//!    ([`icp::align_similarity_symmetric`]).
//! 2. Forward distances: for every **vertex** of the aligned reconstruction, the distance to
//!    the closest point on the ground-truth **triangles** ([`closest`]). Their mean is `mae_mm`,
//!    the paper's "mean absolute (unsigned) closest-point distance"; `rmse_mm`, `p95_mm` and
//!    `max_mm` are over the same distances. Vertices are what the paper's evaluation most
//!    likely used and make noise of standard deviation sigma on the vertices give
//!    sigma sqrt(2/pi) exactly; on an irregular mesh they over-weight densely meshed parts, so
//!    the same statistics over area-weighted surface samples are reported under
//!    `area_weighted`.
//! 3. Reverse distances: every vertex of the ground truth to the aligned reconstruction's
//!    triangles (`reverse_mae_mm`); `symmetric_mm` is the mean of `mae_mm` and
//!    `reverse_mae_mm`, so a reconstruction covering part of the object scores badly.
//! 4. Normals: `normal_deg` is the mean over area-weighted samples of the reconstruction of the
//!    angle between the (rotated) normal of the sample's triangle and the normal of the nearest
//!    ground-truth triangle; orientation counts (a flipped surface gives 180 degrees).
//!
//! The ground truth may first be cropped to what the camera saw ([`crop`]).

// `!(x > 0.0)` is deliberate: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod closest;
pub mod crop;
pub mod icp;
pub mod metrics;

use std::path::PathBuf;

use heatsim::mesh::TriMesh;
use heatsim::vec3::{cross, dot, norm, sub};
use rayon::prelude::*;
use serde_json::json;

pub use closest::{Closest, SurfaceIndex};
pub use crop::{crop_to_view, Crop, CropTolerance, DepthView};
pub use icp::{AlignMode, Alignment, IcpOptions, Similarity};
pub use metrics::{surface_samples, DistanceStats};

/// After alignment, a mean forward distance above this fraction of the ground truth's
/// bounding-box diagonal means the reconstruction is nowhere near the ground truth (or ICP
/// diverged): [`EvalError::NotNear`]. A quarter of the object's size is far beyond any
/// reconstruction worth scoring, yet small enough to catch meshes in other units or frames.
pub const NOT_NEAR_REL: f64 = 0.25;

/// Similarity alignments whose scale leaves [1/SCALE_LIMIT, SCALE_LIMIT] have collapsed or
/// exploded: [`EvalError::Diverged`].
pub const SCALE_LIMIT: f64 = 10.0;

/// What can go wrong in an evaluation.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EvalError {
    /// A file beside the ground truth (camera, depth) is unusable.
    #[error("{}: {message}", .path.display())]
    File { path: PathBuf, message: String },
    /// The inputs cannot be evaluated.
    #[error("{0}")]
    Invalid(String),
    /// The alignment failed.
    #[error("the alignment diverged: {0}")]
    Diverged(String),
    /// The (aligned) reconstruction is far from the ground truth.
    #[error(
        "the reconstruction is nowhere near the ground truth: after alignment ({align}) its mean distance is {mae_m:.4e} m, more than {rel} of the ground truth's size ({size_m:.4e} m); check the units (metres) and frames{hint}",
        rel = NOT_NEAR_REL
    )]
    NotNear { align: String, mae_m: f64, size_m: f64, hint: String },
}

/// Settings of [`evaluate`].
#[derive(Clone, Debug)]
pub struct EvalOptions {
    /// Alignment before measuring.
    pub align: AlignMode,
    /// ICP settings.
    pub icp: IcpOptions,
    /// Area-weighted samples per surface: as many as the surface has vertices, clamped to
    /// `[min_area_samples, max_area_samples]` (the standard error of a mean over 50,000
    /// samples is 0.5 % of the distances' spread).
    pub min_area_samples: usize,
    /// See `min_area_samples`.
    pub max_area_samples: usize,
}

impl Default for EvalOptions {
    fn default() -> Self {
        EvalOptions {
            align: AlignMode::Rigid,
            icp: IcpOptions::default(),
            min_area_samples: 20_000,
            max_area_samples: 50_000,
        }
    }
}

/// The outcome of [`evaluate`]; distances in m.
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// Reconstruction vertices -> ground-truth triangles.
    pub forward: DistanceStats,
    /// Ground-truth vertices -> reconstruction triangles.
    pub reverse: DistanceStats,
    /// Area-weighted samples of the reconstruction -> ground truth.
    pub forward_area: DistanceStats,
    /// Area-weighted samples of the ground truth -> reconstruction.
    pub reverse_area: DistanceStats,
    /// Mean normal angle error, degrees.
    pub normal_deg: f64,
    /// The alignment.
    pub alignment: Alignment,
    /// Signed distance of every reconstruction vertex (aligned) to the ground truth, m:
    /// positive on the side the nearest ground-truth triangle's normal points to.
    pub vertex_signed_m: Vec<f64>,
    /// The aligned reconstruction.
    pub aligned: TriMesh,
    /// Sizes: reconstruction and ground-truth vertices and triangles.
    pub counts: [usize; 4],
    /// Wall-clock seconds of the phases: alignment, forward distances and normals, reverse
    /// distances.
    pub seconds: [f64; 3],
}

impl Evaluation {
    /// `mae_mm`: mean forward distance over reconstruction vertices, mm.
    pub fn mae_mm(&self) -> f64 {
        self.forward.mean * 1e3
    }

    /// `symmetric_mm`: mean of the forward and reverse vertex means, mm.
    pub fn symmetric_mm(&self) -> f64 {
        0.5 * (self.forward.mean + self.reverse.mean) * 1e3
    }

    /// The JSON report (distances in mm, the rest SI).
    pub fn to_json(&self) -> serde_json::Value {
        let t = &self.alignment.transform;
        let a = &self.alignment;
        json!({
            "mae_mm": self.mae_mm(),
            "reverse_mae_mm": self.reverse.mean * 1e3,
            "symmetric_mm": self.symmetric_mm(),
            "rmse_mm": self.forward.rmse * 1e3,
            "p95_mm": self.forward.p95 * 1e3,
            "max_mm": self.forward.max * 1e3,
            "normal_deg": self.normal_deg,
            "area_weighted": {
                "mae_mm": self.forward_area.mean * 1e3,
                "reverse_mae_mm": self.reverse_area.mean * 1e3,
                "symmetric_mm": 0.5 * (self.forward_area.mean + self.reverse_area.mean) * 1e3,
                "rmse_mm": self.forward_area.rmse * 1e3,
                "p95_mm": self.forward_area.p95 * 1e3,
                "samples": [self.forward_area.count, self.reverse_area.count],
            },
            "alignment": {
                "mode": a.mode,
                "rotation": t.rotation,
                "translation_m": t.translation,
                "scale": t.scale,
                "rotation_deg": t.angle_deg(),
                "iterations": a.iterations,
                "inlier_fraction": a.inlier_fraction,
                "converged": a.converged,
                "start": a.start,
                "starts_tried": a.starts_tried,
                "maps": "x_gt = scale * rotation * x_recon + translation_m",
            },
            "phase_seconds": { "alignment": self.seconds[0], "forward": self.seconds[1], "reverse": self.seconds[2] },
            "counts": {
                "recon_vertices": self.counts[0],
                "recon_triangles": self.counts[1],
                "gt_vertices": self.counts[2],
                "gt_triangles": self.counts[3],
            },
            "definitions": {
                "mae_mm": "mean over reconstruction vertices (after alignment) of the distance to the closest point on the ground-truth triangles, mm",
                "reverse_mae_mm": "mean over ground-truth vertices of the distance to the closest point on the aligned reconstruction's triangles, mm",
                "symmetric_mm": "(mae_mm + reverse_mae_mm) / 2",
                "rmse_mm, p95_mm, max_mm": "root mean square, 95th percentile (nearest rank), maximum of the same forward distances, mm",
                "normal_deg": "mean over area-weighted samples of the reconstruction of the angle between its triangle's normal and the nearest ground-truth triangle's normal, degrees",
                "area_weighted": "the same statistics over area-weighted surface samples instead of vertices",
            },
        })
    }
}

/// Scores `recon` against `gt` (both in metres; build them with [`TriMesh::try_new`] or a
/// reader, which rejects empty meshes and non-finite coordinates).
///
/// # Errors
/// [`EvalError::Diverged`] if a similarity alignment's scale leaves
/// [1/[`SCALE_LIMIT`], [`SCALE_LIMIT`]] or the transform is not finite; [`EvalError::NotNear`]
/// if the aligned reconstruction's mean distance exceeds [`NOT_NEAR_REL`] of the ground truth's
/// bounding-box diagonal; [`EvalError::Invalid`] for a mesh without area.
pub fn evaluate(recon: &TriMesh, gt: &TriMesh, opts: &EvalOptions) -> Result<Evaluation, EvalError> {
    let size = gt.bounding_box_diagonal();
    for (name, m) in [("reconstruction", recon), ("ground truth", gt)] {
        if !(m.area() > 0.0) {
            return Err(EvalError::Invalid(format!("the {name} has no area (all triangles degenerate)")));
        }
    }
    let gt_index = SurfaceIndex::new(gt)?;
    let n_area =
        |m: &TriMesh| m.verts.len().clamp(opts.min_area_samples, opts.max_area_samples.max(opts.min_area_samples));
    let recon_samples = surface_samples(recon, n_area(recon));
    let gt_samples = surface_samples(gt, n_area(gt));

    // 1. Alignment.
    let clock = std::time::Instant::now();
    let icp_src: Vec<[f64; 3]> = surface_samples(recon, opts.icp.points).into_iter().map(|s| s.0).collect();
    let icp_small: Vec<[f64; 3]> = surface_samples(recon, opts.icp.start_points).into_iter().map(|s| s.0).collect();
    let gt_pts: Vec<[f64; 3]> = gt_samples.iter().step_by((gt_samples.len() / 20_000).max(1)).map(|s| s.0).collect();
    let alignment = match opts.align {
        // The scale by a search on the symmetric distance from the rigid alignment (module doc):
        // a forward-only similarity ICP shrinks a partial reconstruction towards a point.
        AlignMode::Similarity => {
            let rigid = icp::align(&icp_src, &icp_small, &gt_index, &gt_pts, size, AlignMode::Rigid, &opts.icp);
            let recon_raw_index = SurfaceIndex::new(recon)?;
            icp::align_similarity_symmetric(
                &icp_src,
                &icp_small,
                &recon_raw_index,
                &gt_index,
                &gt_pts,
                size,
                &rigid,
                &opts.icp,
            )
        }
        mode => icp::align(&icp_src, &icp_small, &gt_index, &gt_pts, size, mode, &opts.icp),
    };
    let t = alignment.transform;
    let finite = t.rotation.iter().flatten().chain(t.translation.iter()).all(|v| v.is_finite()) && t.scale.is_finite();
    if !finite {
        return Err(EvalError::Diverged("the transform is not finite".into()));
    }
    if !(t.scale > 1.0 / SCALE_LIMIT && t.scale < SCALE_LIMIT) {
        return Err(EvalError::Diverged(format!(
            "the scale went to {:.4e}, outside [{}, {}]: the surfaces overlap too little for a similarity alignment",
            t.scale,
            1.0 / SCALE_LIMIT,
            SCALE_LIMIT
        )));
    }
    let aligned = recon.transformed(|p| t.apply(p));
    let t_align = clock.elapsed().as_secs_f64();

    // 2. Forward: vertices, with signs.
    let fwd: Vec<(f64, f64)> = aligned
        .verts
        .par_iter()
        .map(|&p| {
            let c = gt_index.closest(p);
            let sign = if dot(sub(p, c.point), gt_index.face_normal(c.face)) < 0.0 { -1.0 } else { 1.0 };
            (c.distance, sign * c.distance)
        })
        .collect();
    let forward_d: Vec<f64> = fwd.iter().map(|x| x.0).collect();
    let vertex_signed_m: Vec<f64> = fwd.iter().map(|x| x.1).collect();
    let forward = DistanceStats::of(&forward_d);
    if !(forward.mean <= NOT_NEAR_REL * size) {
        let hint = match opts.align {
            AlignMode::None => "; with --align none nothing was aligned: try --align rigid".to_string(),
            _ => format!(
                "; ICP ended after {} iterations from the {} start with {:.0} % inliers",
                alignment.iterations,
                alignment.start,
                alignment.inlier_fraction * 100.0
            ),
        };
        return Err(EvalError::NotNear {
            align: format!("{:?}", opts.align).to_lowercase(),
            mae_m: forward.mean,
            size_m: size,
            hint,
        });
    }

    // Area-weighted forward samples and normals (samples move with the transform).
    let fwd_area: Vec<(f64, f64)> = recon_samples
        .par_iter()
        .map(|&(p, f)| {
            let c = gt_index.closest(t.apply(p));
            let n = t.rotate(recon.face_normal(f));
            let m = gt_index.face_normal(c.face);
            // atan2(|n x m|, n . m): accurate near 0 and 180 degrees, unlike acos.
            (c.distance, norm(cross(n, m)).atan2(dot(n, m)).to_degrees())
        })
        .collect();
    let forward_area = DistanceStats::of(&fwd_area.iter().map(|x| x.0).collect::<Vec<_>>());
    let normal_deg = fwd_area.iter().map(|x| x.1).sum::<f64>() / fwd_area.len().max(1) as f64;

    let t_forward = clock.elapsed().as_secs_f64() - t_align;

    // 3. Reverse.
    let recon_index = SurfaceIndex::new(&aligned)?;
    let reverse_d: Vec<f64> = gt.verts.par_iter().map(|&p| recon_index.closest(p).distance).collect();
    let reverse = DistanceStats::of(&reverse_d);
    let reverse_area_d: Vec<f64> = gt_samples.par_iter().map(|&(p, _)| recon_index.closest(p).distance).collect();
    let reverse_area = DistanceStats::of(&reverse_area_d);

    Ok(Evaluation {
        forward,
        reverse,
        forward_area,
        reverse_area,
        normal_deg,
        alignment,
        vertex_signed_m,
        counts: [recon.verts.len(), recon.tris.len(), gt.verts.len(), gt.tris.len()],
        aligned,
        seconds: [t_align, t_forward, clock.elapsed().as_secs_f64() - t_align - t_forward],
    })
}
