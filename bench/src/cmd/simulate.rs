//! `simbench simulate SCENE --out DIR [--solver volumetric|surface]`: temperatures over time
//! and the thermal camera's dataset.

use anyhow::Context;
use heatsim::dataset_format::{CameraFile, DatasetJson, EnvironmentFile, MetaFile, RenderReport};
use heatsim::mesh::obj::write_obj_to;
use heatsim::mesh::vtu::{write_pvd, write_vtu, Cells, DataArray};
use heatsim::scene::{SolverKind, SurfaceFlux, SurfaceMesh};
use ndarray::{Array1, Array2, Array3};
use ndarray_npy::WriteNpyExt;
use std::path::PathBuf;

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum SolverArg {
    /// P1 tetrahedra, backward Euler, exact T^4 radiation (the ground truth).
    Volumetric,
    /// The paper's surface approximation (Eq. 6).
    Surface,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum SurfaceMeshArg {
    Visible,
    CameraGrid,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum SurfaceFluxArg {
    TriangleMean,
    Vertex,
}

#[derive(clap::Args)]
pub struct Args {
    /// Scene file (JSON; see `simbench schema`).
    scene: PathBuf,
    /// Output directory; files appear there only once everything succeeded.
    #[arg(long)]
    out: PathBuf,
    /// Which solver; defaults to the scene's `solver.kind`.
    #[arg(long, value_enum)]
    solver: Option<SolverArg>,
    /// Override the object's thickness (m).
    #[arg(long)]
    thickness: Option<f64>,
    /// Number of frames written as VTU for ParaView (evenly spaced, last frame included; 0: none).
    #[arg(long, default_value_t = 8)]
    vtu_frames: usize,
    /// Surface solver: use the effective thickness min(d, c sqrt(alpha t)) with this c
    /// (overrides solver.effective_thickness_factor; without a value: sqrt(pi)/2).
    #[arg(long, num_args = 0..=1, default_missing_value = "0.886226925452758")]
    effective_thickness_factor: Option<f64>,
    /// Surface solver: run on the visible surface of the tetrahedral mesh or on the camera's
    /// pixel grid (overrides solver.surface_mesh).
    #[arg(long, value_enum)]
    surface_mesh: Option<SurfaceMeshArg>,
    /// Surface solver on the camera grid: each triangle absorbs the mean of its corners'
    /// fluxes, or each vertex its own flux as Eq. 6 (overrides solver.surface_flux).
    #[arg(long, value_enum)]
    surface_flux: Option<SurfaceFluxArg>,
    /// Seed of the camera noise (overrides camera.seed); the same seed gives the same bytes.
    #[arg(long)]
    seed: Option<u64>,
    /// Use this Stanford bunny OBJ instead of the cached download (also: HEATSIM_BUNNY).
    #[arg(long)]
    bunny: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mut scene = super::load_scene(&args.scene, args.thickness)?;
    if let Some(seed) = args.seed {
        scene.camera.seed = seed;
    }
    match args.solver {
        Some(SolverArg::Surface) => scene.solver.kind = SolverKind::Surface,
        Some(SolverArg::Volumetric) => scene.solver.kind = SolverKind::Volumetric,
        None => {}
    }
    if let Some(c) = args.effective_thickness_factor {
        scene.solver.effective_thickness_factor = Some(c);
    }
    match args.surface_mesh {
        Some(SurfaceMeshArg::Visible) => scene.solver.surface_mesh = SurfaceMesh::Visible,
        Some(SurfaceMeshArg::CameraGrid) => scene.solver.surface_mesh = SurfaceMesh::CameraGrid,
        None => {}
    }
    match args.surface_flux {
        Some(SurfaceFluxArg::TriangleMean) => scene.solver.surface_flux = SurfaceFlux::TriangleMean,
        Some(SurfaceFluxArg::Vertex) => scene.solver.surface_flux = SurfaceFlux::Vertex,
        None => {}
    }
    scene.validate().with_context(|| format!("{} with the command-line options", args.scene.display()))?;
    if scene.solver.kind == SolverKind::Surface {
        // Fail before meshing when the object has no thickness.
        heatsim::simulate::surface_layer_thickness(&scene).with_context(|| args.scene.display().to_string())?;
    }
    let meshed = heatsim::meshing::mesh_scene(&scene, args.bunny.as_deref())
        .with_context(|| format!("meshing the object of {}", args.scene.display()))?;
    eprintln!("simbench: {} nodes, {} tetrahedra", meshed.mesh.verts.len(), meshed.mesh.tets.len());
    // One dataset per lamp configuration, all on the same mesh; each dataset directory is
    // complete or absent.
    for (name, lamps) in scene.lamp_sets() {
        let mut lit = scene.clone();
        lit.lamps = lamps;
        lit.lamp_configurations.clear();
        let out_dir = match &name {
            Some(n) => args.out.join(n),
            None => args.out.clone(),
        };
        if let Some(n) = &name {
            eprintln!("simbench: lamp configuration {n}");
        }
        film(&lit, &meshed, &out_dir, &args).with_context(|| match &name {
            Some(n) => format!("lamp configuration {n}"),
            None => "simulating".to_string(),
        })?;
    }
    Ok(())
}

/// Simulates `scene` on the meshed object and writes its dataset to `out_dir`.
fn film(
    scene: &heatsim::scene::Scene,
    meshed: &heatsim::meshing::MeshedObject,
    out_dir: &std::path::Path,
    args: &Args,
) -> anyhow::Result<()> {
    let mesh = &meshed.mesh;
    let surface = scene.solver.kind == SolverKind::Surface;
    let (sim, data) = solve_and_film(scene, meshed, &args.scene)?;
    let mut out = heatsim::io::OutputDir::new(out_dir).with_context(|| format!("preparing {}", out_dir.display()))?;
    write_simulation(&mut out, &sim, mesh, surface, args)?;
    write_dataset(&mut out, scene, meshed, &sim, &data)?;
    out.commit().with_context(|| format!("writing {}", out_dir.display()))?;
    println!("{}", serde_json::to_string_pretty(&sim.report)?);
    for line in signal_lines(sim.report.max_temperature_rise_k, scene.camera.netd) {
        eprintln!("simbench: {line}");
    }
    Ok(())
}

/// Below this many NETDs of peak rise the videos do not determine a shape.
const MIN_RISE_IN_NETD: f64 = 20.0;

/// The peak temperature rise (K) against the camera's temporal noise `netd_k` (K, 1 σ):
/// one line, and a warning when the rise is under [`MIN_RISE_IN_NETD`] NETDs.
pub fn signal_lines(rise_k: f64, netd_k: f64) -> Vec<String> {
    let netd_mk = netd_k * 1e3;
    if netd_k <= 0.0 {
        return vec![format!("peak rise {rise_k:.3} K (the camera has no temporal noise: NETD {netd_mk:.1} mK)")];
    }
    let ratio = rise_k / netd_k;
    let mut lines = vec![format!("peak rise {rise_k:.3} K = {ratio:.1} x the camera's NETD ({netd_mk:.1} mK)")];
    if ratio < MIN_RISE_IN_NETD {
        lines.push(format!(
            "warning: the peak rise is under {MIN_RISE_IN_NETD} x NETD: at this signal the videos will not \
             determine a shape; heat longer, closer or with more power"
        ));
    }
    lines
}

/// Runs the scene's solver on the meshed object and films it with the scene's camera.
/// `scene_path` names the scene in errors.
pub fn solve_and_film(
    scene: &heatsim::scene::Scene,
    meshed: &heatsim::meshing::MeshedObject,
    scene_path: &std::path::Path,
) -> anyhow::Result<(heatsim::simulate::Simulation, heatsim::dataset::Dataset)> {
    let mesh = &meshed.mesh;
    let surface = scene.solver.kind == SolverKind::Surface;
    let sim = solve(scene, mesh, surface, scene_path)?;
    // What the camera sees: the whole boundary of the solid, or the surface model's mesh
    // (on the camera grid, the solid's boundary gives the true depth and normals).
    let (verts, faces) = if surface && sim.camera_grid.is_none() {
        (&sim.visible.verts[..], &sim.visible.tris[..])
    } else {
        (&mesh.verts[..], &mesh.boundary[..])
    };
    let data = heatsim::dataset::render(scene, verts, faces, &sim).context("rendering the thermal video")?;
    eprintln!(
        "simbench: rendered {} frames of {}x{} in {:.2} s after a {:.3} s rasterisation",
        sim.times.len(),
        data.camera.width,
        data.camera.height,
        data.frames_seconds,
        data.rasterize_seconds
    );
    Ok((sim, data))
}

/// Runs the scene's solver on `mesh` with a progress bar.
fn solve(
    scene: &heatsim::scene::Scene,
    mesh: &heatsim::mesh::tetmesh::TetMesh,
    surface: bool,
    scene_path: &std::path::Path,
) -> anyhow::Result<heatsim::simulate::Simulation> {
    let bar = indicatif::ProgressBar::new(0).with_style(
        indicatif::ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} steps ({eta} left)")
            .expect("valid template"),
    );
    bar.set_message("simulating");
    let progress = |done: usize, total: usize| {
        if done == 1 {
            bar.set_length(total as u64);
        }
        bar.set_position(done as u64);
    };
    let sim = if surface {
        heatsim::simulate::simulate_surface(scene, mesh, progress)
    } else {
        heatsim::simulate::simulate_volumetric(scene, mesh, progress)
    }
    .with_context(|| format!("simulating {}", scene_path.display()))?;
    bar.finish_and_clear();
    Ok(sim)
}

/// The simulation's own files: node and visible-surface temperatures, times, the visible
/// surface, the tagged boundary and the ParaView series.
fn write_simulation(
    out: &mut heatsim::io::OutputDir,
    sim: &heatsim::simulate::Simulation,
    mesh: &heatsim::mesh::tetmesh::TetMesh,
    surface: bool,
    args: &Args,
) -> anyhow::Result<()> {
    let frames = sim.times.len();
    let temps = Array2::from_shape_vec((frames, sim.nodes), sim.node_temperatures.clone())?;
    out.write_with("node_temperatures.npy", |w| temps.write_npy(w).map_err(std::io::Error::other))?;
    let visible = Array2::from_shape_vec((frames, sim.visible_nodes.len()), sim.visible_temperatures())?;
    out.write_with("visible_temperatures.npy", |w| visible.write_npy(w).map_err(std::io::Error::other))?;
    let times = Array1::from_vec(sim.times.clone());
    out.write_with("times.npy", |w| times.write_npy(w).map_err(std::io::Error::other))?;
    let vis_nodes = Array1::from_vec(sim.visible_nodes.iter().map(|&n| n as u64).collect());
    out.write_with("visible_nodes.npy", |w| vis_nodes.write_npy(w).map_err(std::io::Error::other))?;
    out.write_with("visible.obj", |w| {
        write_obj_to(w, &sim.visible, "visible surface (metres); vertex k is node visible_nodes[k]")
    })?;
    let tags: Vec<i32> = mesh.boundary_tag.iter().map(|t| t.marker()).collect();
    out.write_with("boundary.vtu", |w| {
        write_vtu(w, &mesh.verts, Cells::Triangle(&mesh.boundary), &[], &[("tag", DataArray::I32(&tags))])
    })?;
    let picks = vtu_frames(frames, args.vtu_frames);
    let mut pvd = Vec::new();
    for &k in &picks {
        let name = format!("temperature_{k:04}.vtu");
        let temperature = [("temperature_K", DataArray::F64(sim.frame(k)))];
        out.write_with(&name, |w| {
            if surface {
                let flux = [("absorbed_flux_W_m2", DataArray::F64(&sim.face_flux))];
                write_vtu(w, &sim.visible.verts, Cells::Triangle(&sim.visible.tris), &temperature, &flux)
            } else {
                let layer = [("layer", DataArray::I32(&mesh.tet_region))];
                write_vtu(w, &mesh.verts, Cells::Tetra(&mesh.tets), &temperature, &layer)
            }
        })?;
        pvd.push((sim.times[k], name));
    }
    if !pvd.is_empty() {
        let entries: Vec<(f64, &str)> = pvd.iter().map(|(t, n)| (*t, n.as_str())).collect();
        out.write_with("temperature.pvd", |w| write_pvd(w, &entries))?;
    }
    Ok(())
}

/// The dataset (issue 4 layout): videos, mask, ground truth, preview and the JSON files.
pub fn write_dataset(
    out: &mut heatsim::io::OutputDir,
    scene: &heatsim::scene::Scene,
    meshed: &heatsim::meshing::MeshedObject,
    sim: &heatsim::simulate::Simulation,
    data: &heatsim::dataset::Dataset,
) -> anyhow::Result<()> {
    let frames = sim.times.len();
    let (h, w) = (data.camera.height as usize, data.camera.width as usize);
    let npy3 = |v: &[f32]| Array3::from_shape_vec((frames, h, w), v.to_vec());
    let video = npy3(&data.video)?;
    out.write_with("video.npy", |f| video.write_npy(f).map_err(std::io::Error::other))?;
    let clean = Array3::from_shape_vec((frames, h, w), data.video_clean.clone())?;
    out.write_with("video_clean.npy", |f| clean.write_npy(f).map_err(std::io::Error::other))?;
    let mask = Array2::from_shape_vec((h, w), data.mask.clone())?;
    out.write_with("mask.npy", |f| mask.write_npy(f).map_err(std::io::Error::other))?;
    out.write_with("mask.png", |f| heatsim::dataset::write_mask_png(f, &data.mask, w as u32, h as u32))?;
    write_ground_truth(out, sim, data)?;
    let last: Vec<f32> = data.video_clean[(frames - 1) * h * w..].iter().map(|&t| t as f32).collect();
    let (lo, hi) = data
        .mask
        .iter()
        .zip(&last)
        .filter(|(m, _)| **m)
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), (_, &t)| (a.min(t), b.max(t)));
    // A picture never costs the data: a preview that cannot be drawn is skipped with a warning.
    let mut png = Vec::new();
    match heatsim::camera::write_preview_png(&mut png, &last, w as u32, h as u32, lo, hi) {
        Ok(()) => out.write_bytes("preview.png", &png)?,
        Err(e) => eprintln!("simbench: warning: preview.png not written ({e}); the data are"),
    }
    dataset_json(scene, meshed, sim, data)?.write_into(out)?;
    Ok(())
}

/// The JSON files of a dataset (`heatsim::dataset_format`): camera, lamps, ground truth and
/// provenance. environment.json is the room as a user would measure it, with the object's
/// emissivity (the reconstruction reads both; its convection_coefficient is ground truth it
/// must not use).
pub fn dataset_json(
    scene: &heatsim::scene::Scene,
    meshed: &heatsim::meshing::MeshedObject,
    sim: &heatsim::simulate::Simulation,
    data: &heatsim::dataset::Dataset,
) -> anyhow::Result<DatasetJson> {
    let material = scene.material.resolve()?;
    Ok(DatasetJson {
        camera: CameraFile::new(&data.camera, &scene.camera, scene.timing.frame_interval),
        lamps: scene.lamps.clone(),
        environment: EnvironmentFile::new(&scene.environment, material.emissivity),
        material,
        meta: MetaFile::new(
            format!("simbench {}", env!("CARGO_PKG_VERSION")),
            scene.clone(),
            meshed.report.clone(),
            sim.report.clone(),
            RenderReport::of(data),
        ),
    })
}

/// The ground truth of a dataset: `gt_depth.npy` (m), `gt_normals.npy`, `gt_flux.npy` (W/m^2)
/// and `gt_mesh.obj` (the visible surface, world frame, m).
pub fn write_ground_truth(
    out: &mut heatsim::io::OutputDir,
    sim: &heatsim::simulate::Simulation,
    data: &heatsim::dataset::Dataset,
) -> anyhow::Result<()> {
    let (h, w) = (data.camera.height as usize, data.camera.width as usize);
    let depth = Array2::from_shape_vec((h, w), data.depth.clone())?;
    out.write_with("gt_depth.npy", |f| depth.write_npy(f).map_err(std::io::Error::other))?;
    let normals = Array3::from_shape_vec((h, w, 3), data.normals.iter().flatten().copied().collect())?;
    out.write_with("gt_normals.npy", |f| normals.write_npy(f).map_err(std::io::Error::other))?;
    let flux = Array2::from_shape_vec((h, w), data.flux.clone())?;
    out.write_with("gt_flux.npy", |f| flux.write_npy(f).map_err(std::io::Error::other))?;
    out.write_with("gt_mesh.obj", |f| {
        write_obj_to(f, &sim.visible, "ground-truth visible surface, world frame (metres)")
    })?;
    Ok(())
}

/// `count` frame indices spread evenly over `0..frames`, the last frame included.
fn vtu_frames(frames: usize, count: usize) -> Vec<usize> {
    if count == 0 || frames == 0 {
        return Vec::new();
    }
    let count = count.min(frames);
    let mut v: Vec<usize> = (1..=count).map(|j| (j * (frames - 1)) / count).collect();
    v.dedup();
    v
}
