//! Writing stage 2's results into a staged output directory (`heatsim::io::OutputDir`):
//! - `recon.obj`, `recon.ply`: the finest level's mesh in **camera coordinates** (m; x right,
//!   y down, z forward), triangles facing the camera; the PLY carries `depth` (m) per vertex;
//! - `recon_world.obj`: the same mesh in the dataset's world frame (`x_w = R^T (x_c - t)`), for
//!   `simbench eval` against `gt_mesh.obj`;
//! - `depth.npy` float32 [H, W]: z_c (m), NaN off the mesh; `normals.npy` float32 [H, W, 3]:
//!   unit normals (camera frame, towards the camera), NaN off the mesh;
//! - `residual_stage2.npy` float32 [H, W]: per pixel, the RMS heat residual of the result (K/s) over
//!   frame pairs and videos (the stage-2 residual map);
//! - `convergence.csv`: one row per iteration and level (energy terms, RMS residual in K/s,
//!   diffusivity used).

use heatsim::io::OutputDir;
use heatsim::mesh::trimesh::TriMesh;
use ndarray::{Array2, Array3};
use ndarray_npy::WriteNpyExt;

use super::coarse_to_fine::{LevelResult, LogRow};
use crate::error::ReconError;

/// The level's mesh in camera coordinates (m).
pub fn camera_mesh(res: &LevelResult) -> TriMesh {
    let dirs = super::coarse_to_fine::ray_dirs(&res.camera, &res.grid);
    let verts = dirs.iter().zip(&res.depth).map(|(d, &z)| [d[0] * z, d[1] * z, z]).collect();
    TriMesh { verts, tris: res.grid.tris.clone() }
}

/// The level's mesh in the world frame of its camera (m).
pub fn world_mesh(res: &LevelResult) -> TriMesh {
    let mut m = camera_mesh(res);
    let (r, t) = (res.camera.r, res.camera.t);
    for v in &mut m.verts {
        let c = [v[0] - t[0], v[1] - t[1], v[2] - t[2]];
        *v = std::array::from_fn(|k| r[0][k] * c[0] + r[1][k] * c[1] + r[2][k] * c[2]);
    }
    m
}

/// The convergence log as CSV text.
pub fn log_csv(log: &[LogRow]) -> String {
    let mut s = String::from(
        "level,iteration,evaluations,total,data,normal_consistency,halfspace,lamp_ratio,lamp_shading,symmetry,alpha_m2_per_s,rms_residual_k_per_s\n",
    );
    for r in log {
        s.push_str(&format!(
            "{},{},{},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e},{:.9e},{:.6e},{:.6e}\n",
            r.level,
            r.iteration,
            r.evaluations,
            r.terms.total,
            r.terms.data,
            r.terms.normal,
            r.terms.halfspace,
            r.terms.lamp_ratio,
            r.terms.lamp_shading,
            r.terms.symmetry,
            r.terms.alpha,
            r.terms.rms_residual,
        ));
    }
    s
}

/// Writes the files of the module doc for the finest level `res` and the log.
///
/// # Errors
/// I/O errors, naming `out_path`.
pub fn write_stage2(
    out: &mut OutputDir,
    out_path: &std::path::Path,
    res: &LevelResult,
    log: &[LogRow],
) -> Result<(), ReconError> {
    let io = |e: std::io::Error| ReconError::io(out_path, e);
    let mesh = camera_mesh(res);
    let comment =
        format!("heatrecon stage 2: camera coordinates (m, x right, y down, z forward), pyramid level {}", res.level);
    out.write_with("recon.obj", |w| heatsim::mesh::obj::write_obj_to(w, &mesh, &comment)).map_err(io)?;
    let depth32: Vec<f32> = res.depth.iter().map(|&z| z as f32).collect();
    out.write_with("recon.ply", |w| heatsim::mesh::ply::write_ply_to(w, &mesh, &[("depth", &depth32)], &comment))
        .map_err(io)?;
    let world = world_mesh(res);
    out.write_with("recon_world.obj", |w| {
        heatsim::mesh::obj::write_obj_to(w, &world, "heatrecon stage 2: world frame of camera.json (m)")
    })
    .map_err(io)?;
    let g = &res.grid;
    let mut depth = Array2::<f32>::from_elem((g.height, g.width), f32::NAN);
    let mut normals = Array3::<f32>::from_elem((g.height, g.width, 3), f32::NAN);
    for (k, &p) in g.pixels.iter().enumerate() {
        depth[[p / g.width, p % g.width]] = res.depth[k] as f32;
        for c in 0..3 {
            normals[[p / g.width, p % g.width, c]] = res.normals[k][c] as f32;
        }
    }
    out.write_with("depth.npy", |w| depth.write_npy(w).map_err(std::io::Error::other)).map_err(io)?;
    let image = |v: &[f64]| {
        let mut a = Array2::<f32>::from_elem((g.height, g.width), f32::NAN);
        for (k, &p) in g.pixels.iter().enumerate() {
            a[[p / g.width, p % g.width]] = v[k] as f32;
        }
        a
    };
    let residual = image(&res.residual);
    out.write_with("residual_stage2.npy", |w| residual.write_npy(w).map_err(std::io::Error::other)).map_err(io)?;
    out.write_with("normals.npy", |w| normals.write_npy(w).map_err(std::io::Error::other)).map_err(io)?;
    out.write_bytes("convergence.csv", log_csv(log).as_bytes()).map_err(io)?;
    Ok(())
}
