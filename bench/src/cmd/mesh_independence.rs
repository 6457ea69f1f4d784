//! `simbench mesh-independence SCENE`: the volumetric solver on two independent meshes of the
//! same solid, ours (TetGen, layered) and fTetWild's (PyPI `pytetwild`, run by
//! `bench/peers/tetwild_mesh.py` in the project's `.venv`).
//!
//! The closed boundary of our mesh is handed to fTetWild; its mesh's boundary faces take the
//! visible/side/back tags of our nearest face ([`TetMesh::transfer_tags`]). Both meshes are
//! simulated with the scene's lamps and filmed by the scene's camera; the noise-free videos are
//! compared over the pixels both see, away from the silhouette (masks eroded by
//! [`SILHOUETTE_MARGIN`] pixels: the two boundaries differ by up to fTetWild's envelope there,
//! which moves the silhouette, not the physics), over the frames after the lamps switch on:
//!
//! - `video_rel_diff` = mean |T_ours - T_tetwild| / mean (T_ours - T_s): must be <= [`VIDEO_AGREEMENT`];
//! - `volume_rel_diff` = |V_tetwild - V_ours| / V_ours: must be <= [`VOLUME_AGREEMENT`].
//!
//! Both are checked, which makes the command an oracle test (exit 1 when either fails).

use anyhow::{bail, Context};
use heatsim::mesh::tetmesh::TetMesh;
use heatsim::scene::Scene;
use heatsim::tetgen::TetgenOutput;
use ndarray::Array2;
use ndarray_npy::ReadNpyExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Largest accepted mean video difference relative to the mean temperature rise.
pub const VIDEO_AGREEMENT: f64 = 0.01;
/// Largest accepted relative volume difference.
pub const VOLUME_AGREEMENT: f64 = 0.005;
/// Pixels within this many pixels of either silhouette are not compared.
pub const SILHOUETTE_MARGIN: usize = 2;

#[derive(clap::Args)]
pub struct Args {
    /// Scene file (JSON); with lamp configurations, the first one is used.
    scene: PathBuf,
    /// Override the object's thickness (m).
    #[arg(long)]
    thickness: Option<f64>,
    /// fTetWild's ideal edge length (m); default: the scene's meshing.surface_element_size.
    #[arg(long)]
    edge: Option<f64>,
    /// fTetWild's envelope, relative to the bounding-box diagonal.
    #[arg(long, default_value_t = 1e-3)]
    epsilon: f64,
    /// Keep the surface handed to fTetWild, its mesh and the report here (default: a temporary
    /// directory removed afterwards).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Use this Stanford bunny OBJ instead of the cached download (also: HEATSIM_BUNNY).
    #[arg(long)]
    bunny: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let root = super::peer::repo_root();
    let python = root.join(".venv/bin/python");
    let script = root.join("bench/peers/tetwild_mesh.py");
    if !python.exists() {
        bail!("the oracle environment {} is missing: run scripts/setup-oracles.sh", python.display());
    }
    let mut scene = super::load_scene(&args.scene, args.thickness)?;
    if let Some((_, lamps)) = scene.lamp_sets().into_iter().next() {
        scene.lamps = lamps;
    }
    scene.lamp_configurations.clear();
    let edge = args.edge.unwrap_or(scene.meshing.surface_element_size);
    if !(edge > 0.0 && edge.is_finite()) {
        bail!("--edge must be a positive length in m, got {edge}");
    }
    if !(args.epsilon > 0.0 && args.epsilon < 0.1) {
        bail!("--epsilon must be in (0, 0.1), got {}", args.epsilon);
    }
    let (_scratch, work) = super::peer::work_dir(args.out.as_deref(), "simbench-tetwild")?;
    let work = std::path::absolute(&work).with_context(|| format!("resolving {}", work.display()))?;

    let t0 = Instant::now();
    let ours = heatsim::meshing::mesh_scene(&scene, args.bunny.as_deref())
        .with_context(|| format!("meshing the object of {}", args.scene.display()))?;
    let tetgen_s = t0.elapsed().as_secs_f64();
    let surface_path = work.join("surface.obj");
    let closed = ours.mesh.boundary_surface().compacted();
    heatsim::mesh::obj::write_obj(&surface_path, &closed, "closed boundary of the TetGen mesh (m)")
        .with_context(|| format!("writing {}", surface_path.display()))?;
    eprintln!(
        "simbench mesh-independence: TetGen {} nodes, {} tetrahedra; running fTetWild (edge {edge} m)",
        ours.mesh.verts.len(),
        ours.mesh.tets.len()
    );
    let tw_dir = work.join("tetwild");
    let tw_info = run_ftetwild(&python, &script, &work, &surface_path, &tw_dir, edge, args.epsilon)?;
    let mut theirs = read_ftetwild_mesh(&tw_dir)?;
    let boundary_gap = theirs.transfer_tags(&ours.mesh)?;

    eprintln!(
        "simbench mesh-independence: fTetWild {} nodes, {} tetrahedra; simulating both",
        theirs.verts.len(),
        theirs.tets.len()
    );
    let (a, ours_s) = film(&scene, &ours.mesh, "TetGen")?;
    let (b, theirs_s) = film(&scene, &theirs, "fTetWild")?;
    let c = compare_videos(&a, &b, scene.environment.ambient_temperature)?;

    let video_rel_diff = c.sum_diff / c.sum_rise;
    let v_ours = ours.mesh.volume();
    let v_theirs = theirs.volume();
    let volume_rel_diff = (v_theirs - v_ours).abs() / v_ours;
    let report = serde_json::json!({
        "scene": args.scene.display().to_string(),
        "tetgen": { "nodes": ours.mesh.verts.len(), "tets": ours.mesh.tets.len(), "volume_m3": v_ours, "mesh_s": tetgen_s, "simulate_s": ours_s },
        "ftetwild": { "nodes": theirs.verts.len(), "tets": theirs.tets.len(), "volume_m3": v_theirs, "mesh_s": tw_info["seconds"], "simulate_s": theirs_s, "edge_m": edge, "epsilon": args.epsilon, "pytetwild": tw_info["pytetwild"] },
        "boundary_gap_m": boundary_gap,
        "compared_pixels": c.pixels,
        "compared_frames": c.count / c.pixels,
        "mean_rise_k": c.sum_rise / c.count as f64,
        "mean_abs_diff_k": c.sum_diff / c.count as f64,
        "video_rel_diff": video_rel_diff,
        "max_abs_diff_k": c.max_diff,
        "max_rise_k": c.max_rise,
        "volume_rel_diff": volume_rel_diff,
        "targets": { "video_rel_diff": VIDEO_AGREEMENT, "volume_rel_diff": VOLUME_AGREEMENT },
    });
    let text = serde_json::to_string_pretty(&report)? + "\n";
    if args.out.is_some() {
        heatsim::io::write_atomic(&work.join("mesh_independence.json"), text.as_bytes())?;
    }
    print!("{text}");
    check_agreement(video_rel_diff, volume_rel_diff)
}

/// Runs `bench/peers/tetwild_mesh.py` (`script`, with the environment's `python`) in `work` on
/// the closed surface `surface` with fTetWild's ideal edge length `edge` (m) and envelope
/// `epsilon` (relative); it writes `nodes.npy` and `tets.npy` into `tw_dir`. Returns the JSON
/// line the script prints last (its seconds and pytetwild's version).
fn run_ftetwild(
    python: &Path,
    script: &Path,
    work: &Path,
    surface: &Path,
    tw_dir: &Path,
    edge: f64,
    epsilon: f64,
) -> anyhow::Result<serde_json::Value> {
    // fTetWild leaves scratch files in its working directory: keep them in ours.
    let out = Command::new(python)
        .current_dir(work)
        .arg(script)
        .arg(surface)
        .arg(tw_dir)
        .arg("--edge")
        .arg(edge.to_string())
        .arg("--epsilon")
        .arg(epsilon.to_string())
        .output()
        .with_context(|| format!("running {}", script.display()))?;
    if !out.status.success() {
        bail!(
            "fTetWild failed ({}); is pytetwild installed (scripts/setup-oracles.sh)? {}",
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let stdout = String::from_utf8_lossy(&out.stdout);
    stdout
        .lines()
        .rev()
        .find_map(|l| serde_json::from_str(l).ok())
        .with_context(|| format!("fTetWild's script printed no JSON: {stdout}"))
}

/// fTetWild's mesh from `tw_dir/nodes.npy` (#V x 3, m) and `tw_dir/tets.npy` (#T x 4), checked;
/// its boundary faces are all tagged side until [`TetMesh::transfer_tags`].
fn read_ftetwild_mesh(tw_dir: &Path) -> anyhow::Result<TetMesh> {
    let nodes: Array2<f64> = Array2::read_npy(std::fs::File::open(tw_dir.join("nodes.npy"))?)?;
    let tets: Array2<i64> = Array2::read_npy(std::fs::File::open(tw_dir.join("tets.npy"))?)?;
    if nodes.ncols() != 3 || tets.ncols() != 4 || tets.nrows() == 0 {
        bail!("fTetWild wrote nodes {:?} and tets {:?}", nodes.dim(), tets.dim());
    }
    let n = nodes.nrows() as i64;
    if tets.iter().any(|&i| i < 0 || i >= n) {
        bail!("fTetWild's tetrahedra index nodes out of range");
    }
    let output = TetgenOutput {
        points: nodes.rows().into_iter().map(|r| [r[0], r[1], r[2]]).collect(),
        tets: tets.rows().into_iter().map(|r| [r[0] as usize, r[1] as usize, r[2] as usize, r[3] as usize]).collect(),
        tet_region: vec![0; tets.nrows()],
        marked_faces: Vec::new(),
    };
    TetMesh::from_tetgen(output).context("fTetWild's mesh")
}

/// Simulates the scene on `mesh` and films it; returns the dataset and the simulation's
/// seconds. `name` names the mesh in errors.
fn film(scene: &Scene, mesh: &TetMesh, name: &str) -> anyhow::Result<(heatsim::dataset::Dataset, f64)> {
    let t = Instant::now();
    let sim = heatsim::simulate::simulate_volumetric(scene, mesh, |_, _| {})
        .with_context(|| format!("simulating on the {name} mesh"))?;
    let seconds = t.elapsed().as_secs_f64();
    let data = heatsim::dataset::render(scene, &mesh.verts, &mesh.boundary, &sim)
        .with_context(|| format!("rendering the {name} run"))?;
    Ok((data, seconds))
}

/// Sums over the compared pixels and heating frames (module doc) of two videos.
struct VideoComparison {
    /// Pixels both masks keep after erosion.
    pixels: usize,
    /// Sum of |T_a - T_b| (K).
    sum_diff: f64,
    /// Sum of T_a - T_s (K).
    sum_rise: f64,
    /// Largest |T_a - T_b| (K).
    max_diff: f64,
    /// Largest T_a - T_s (K).
    max_rise: f64,
    /// Pixel-frames compared.
    count: usize,
}

/// Compares the noise-free videos of `a` and `b` (same camera) over the pixels both see away
/// from the silhouettes and the frames after the lamps switch on; `ambient` is T_s (K).
fn compare_videos(
    a: &heatsim::dataset::Dataset,
    b: &heatsim::dataset::Dataset,
    ambient: f64,
) -> anyhow::Result<VideoComparison> {
    let (w, h) = (a.camera.width as usize, a.camera.height as usize);
    let keep = eroded(&a.mask, w, h, SILHOUETTE_MARGIN)
        .iter()
        .zip(eroded(&b.mask, w, h, SILHOUETTE_MARGIN))
        .map(|(x, y)| *x && y)
        .collect::<Vec<bool>>();
    let pixels: Vec<usize> = (0..w * h).filter(|&p| keep[p]).collect();
    if pixels.is_empty() {
        bail!("the two meshes share no pixel away from the silhouettes");
    }
    let (mut sum_diff, mut sum_rise, mut max_diff, mut max_rise, mut count) = (0.0, 0.0, 0.0_f64, 0.0_f64, 0usize);
    for (k, &t) in a.times.iter().enumerate() {
        if t <= 0.0 {
            continue;
        }
        let (fa, fb) = (&a.video_clean[k * w * h..(k + 1) * w * h], &b.video_clean[k * w * h..(k + 1) * w * h]);
        for &p in &pixels {
            let d = (fa[p] - fb[p]).abs();
            let rise = fa[p] - ambient;
            sum_diff += d;
            sum_rise += rise;
            max_diff = max_diff.max(d);
            max_rise = max_rise.max(rise);
            count += 1;
        }
    }
    Ok(VideoComparison { pixels: pixels.len(), sum_diff, sum_rise, max_diff, max_rise, count })
}

/// The oracle's verdict: both relative differences within their targets (NaN fails).
// `!(x <= target)` is deliberate: it also rejects NaN.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
fn check_agreement(video_rel_diff: f64, volume_rel_diff: f64) -> anyhow::Result<()> {
    if !(video_rel_diff <= VIDEO_AGREEMENT) {
        bail!(
            "the videos on the two meshes differ by {:.3} % of the mean rise (target {} %)",
            100.0 * video_rel_diff,
            100.0 * VIDEO_AGREEMENT
        );
    }
    if !(volume_rel_diff <= VOLUME_AGREEMENT) {
        bail!("the mesh volumes differ by {:.3} % (target {} %)", 100.0 * volume_rel_diff, 100.0 * VOLUME_AGREEMENT);
    }
    Ok(())
}

/// `mask` (W x H, row-major) eroded by `r` pixels (square structuring element).
fn eroded(mask: &[bool], w: usize, h: usize, r: usize) -> Vec<bool> {
    (0..w * h)
        .map(|p| {
            let (u, v) = (p % w, p / w);
            if u < r || v < r || u + r >= w || v + r >= h {
                return false;
            }
            (v - r..=v + r).all(|y| (u - r..=u + r).all(|x| mask[y * w + x]))
        })
        .collect()
}
