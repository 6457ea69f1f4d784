//! `simbench bench-recon`: the whole reconstruction timed per stage and pyramid level, at
//! several camera sizes of one scene in one run, so that the time per vertex and frame can be
//! compared across sizes (stage 1 + 2 should stay linear in pixels x frames).
//!
//! Each size films the scene with the surface solver (`--solver surface`; cached in
//! `--work` under a digest of the scene and size; with at least 10 frames before the lamps
//! switch on, where the noise is measured), then reconstructs both lamp videos with the
//! preset and the material's diffusivity, as `simbench suite run` does. The peak resident
//! memory of each reconstruction is the process's high-water mark, reset before it
//! (`/proc/self/clear_refs`).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use heatrecon::config::{Preset, ReconConfig};
use heatrecon::dataset::{Dataset, LoadOptions};
use heatrecon::observer::Observer;
use heatrecon::pyramid::Level;
use heatsim::scene::SolverKind;
use ndarray_npy::WriteNpyExt;
use serde::Serialize;

#[derive(clap::Args)]
pub struct Args {
    /// Scene file (two lamp configurations).
    #[arg(default_value = "scenes/hemisphere.json")]
    scene: PathBuf,
    /// Camera sizes, WxH, timed in this order.
    #[arg(long, value_delimiter = ',', default_value = "160x128,320x256,640x512")]
    sizes: Vec<String>,
    /// Reconstruction preset.
    #[arg(long, default_value = "paper")]
    preset: String,
    /// Where the filmed datasets are cached.
    #[arg(long, default_value = "target/bench-recon")]
    work: PathBuf,
    /// Also write recon_speed.json and recon_speed.md here.
    #[arg(long)]
    out: Option<PathBuf>,
}

/// The time of one pyramid level.
#[derive(Clone, Debug, Serialize)]
pub struct LevelTime {
    pub level: usize,
    /// Vertices of the level's pixel mesh.
    pub vertices: usize,
    pub frames: usize,
    /// Stage 1 with its denoising, s.
    pub stage1_s: f64,
    /// The shape at this level, s.
    pub stage2_s: f64,
    /// The shape's optimiser iterations and energy evaluations at this level.
    pub iterations: usize,
    pub evaluations: usize,
}

impl LevelTime {
    /// The shape's time per energy evaluation, ms.
    pub fn ms_per_evaluation(&self) -> f64 {
        1e3 * self.stage2_s / self.evaluations.max(1) as f64
    }
}

/// One camera size.
#[derive(Clone, Debug, Serialize)]
pub struct SizeTime {
    pub width: u32,
    pub height: u32,
    /// Reading both datasets, s.
    pub load_s: f64,
    /// `heatrecon::reconstruct` as a whole, s.
    pub reconstruct_s: f64,
    /// Coarsest level first.
    pub levels: Vec<LevelTime>,
    /// Peak resident memory during the reconstruction, bytes (`None` where unreadable).
    pub peak_rss_bytes: Option<u64>,
}

impl SizeTime {
    /// Stage 1 + 2 over all levels per vertex and frame of all levels, microseconds.
    pub fn us_per_vertex_frame(&self) -> f64 {
        let t: f64 = self.levels.iter().map(|l| l.stage1_s + l.stage2_s).sum();
        let n: usize = self.levels.iter().map(|l| l.vertices * l.frames).sum();
        1e6 * t / n.max(1) as f64
    }
}

/// Times each level from the observer's calls: `level_start` .. `stage1` is stage 1, `stage1`
/// .. `level` the shape.
struct Timer {
    mark: Instant,
    current: Option<LevelTime>,
    levels: Vec<LevelTime>,
}

impl Observer for Timer {
    fn level_start(&mut self, _index: usize, _levels: usize, level: &Level) {
        self.mark = Instant::now();
        self.current = Some(LevelTime {
            level: level.level,
            vertices: 0,
            frames: level.times.len(),
            stage1_s: 0.0,
            stage2_s: 0.0,
            iterations: 0,
            evaluations: 0,
        });
    }
    fn stage1(
        &mut self,
        _level: &Level,
        _r: &heatrecon::stage1::Stage1Result,
        _hs: Option<&[i8]>,
        _noise: Option<f64>,
    ) {
        if let Some(c) = &mut self.current {
            c.stage1_s = self.mark.elapsed().as_secs_f64();
        }
        self.mark = Instant::now();
    }
    fn level(&mut self, view: &heatrecon::stage2::coarse_to_fine::LevelView) {
        if let Some(mut c) = self.current.take() {
            c.stage2_s = self.mark.elapsed().as_secs_f64();
            c.vertices = view.result.grid.vertex_count();
            self.levels.push(c);
        }
    }
}

fn parse_size(s: &str) -> anyhow::Result<(u32, u32)> {
    let (w, h) = s.split_once('x').with_context(|| format!("--sizes: `{s}` is not WxH"))?;
    let p = |v: &str| v.trim().parse::<u32>().ok().filter(|&n| n >= 8);
    match (p(w), p(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => anyhow::bail!("--sizes: `{s}` is not WxH with both sides at least 8 pixels"),
    }
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let sizes: Vec<(u32, u32)> = args.sizes.iter().map(|s| parse_size(s)).collect::<anyhow::Result<_>>()?;
    let base: ReconConfig = Preset::from_name(&args.preset)?.config();
    let mut rows = Vec::new();
    for &(w, h) in &sizes {
        let dirs = film(&args.scene, w, h, &args.work)?;
        let t = Instant::now();
        let sets =
            dirs.iter().map(|d| Dataset::load(d, &LoadOptions::from(&base.input))).collect::<Result<Vec<_>, _>>()?;
        let load_s = t.elapsed().as_secs_f64();
        let mut config = base.clone();
        config.input.diffusivity_m2_per_s = Some(heatrecon::dataset::read_diffusivity(&dirs[0])?);
        reset_peak_rss();
        let mut timer = Timer { mark: Instant::now(), current: None, levels: Vec::new() };
        let t = Instant::now();
        let rec =
            heatrecon::reconstruct(&sets, &config, &mut timer).with_context(|| format!("reconstructing at {w}x{h}"))?;
        let reconstruct_s = t.elapsed().as_secs_f64();
        if let Some((_, shape)) = &rec.shape {
            for l in &mut timer.levels {
                let last = shape.log.iter().filter(|r| r.level == l.level).last();
                (l.iterations, l.evaluations) = last.map_or((0, 0), |r| (r.iteration, r.evaluations));
            }
        }
        let row =
            SizeTime { width: w, height: h, load_s, reconstruct_s, levels: timer.levels, peak_rss_bytes: peak_rss() };
        eprintln!("bench-recon: {w}x{h}: {:.1} s", row.reconstruct_s);
        rows.push(row);
    }
    let md = markdown(&args.scene, &args.preset, &rows);
    println!("{md}");
    if let Some(out) = &args.out {
        std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
        let json = serde_json::to_string_pretty(&rows)? + "\n";
        heatsim::io::write_atomic(&out.join("recon_speed.json"), json.as_bytes())?;
        heatsim::io::write_atomic(&out.join("recon_speed.md"), md.as_bytes())?;
    }
    Ok(())
}

/// Frames before the lamps switch on, at least (the suite's full tier films 10).
const PRE_HEATING_FRAMES: u32 = 10;

/// Films `scene` at `w` x `h` with the surface solver into the cache; returns
/// the dataset folder of each lamp configuration.
fn film(scene_path: &Path, w: u32, h: u32, work: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let mut scene = super::load_scene(scene_path, None)?;
    scene.camera.width = w;
    scene.camera.height = h;
    scene.solver.kind = SolverKind::Surface;
    // The paper preset measures the noise on the frames before the lamps switch on.
    scene.timing.pre_heating_frames = scene.timing.pre_heating_frames.max(PRE_HEATING_FRAMES);
    scene.validate().with_context(|| format!("{} at {w}x{h}", scene_path.display()))?;
    let key = crate::sweep::cells::sha256_hex(serde_json::to_string(&scene)?.as_bytes());
    let stem = scene_path.file_stem().and_then(|s| s.to_str()).unwrap_or("scene");
    let root = work.join(format!("{stem}-{w}x{h}-{}", &key[..12]));
    let sets = scene.lamp_sets();
    anyhow::ensure!(sets.len() >= 2, "{}: the reconstruction needs two lamp configurations", scene_path.display());
    let dirs: Vec<PathBuf> = sets.iter().map(|(n, _)| root.join(n.as_deref().unwrap_or("video"))).collect();
    if dirs.iter().all(|d| d.join("times.npy").is_file()) {
        return Ok(dirs);
    }
    let meshed = heatsim::meshing::mesh_scene(&scene, None)
        .with_context(|| format!("meshing the object of {}", scene_path.display()))?;
    for ((_, lamps), dir) in sets.into_iter().zip(&dirs) {
        let mut lit = scene.clone();
        lit.lamps = lamps;
        lit.lamp_configurations.clear();
        let (sim, data) = super::simulate::solve_and_film(&lit, &meshed, scene_path)?;
        let mut out = heatsim::io::OutputDir::new(dir).with_context(|| format!("preparing {}", dir.display()))?;
        super::simulate::write_dataset(&mut out, &lit, &meshed, &sim, &data)?;
        let times = ndarray::Array1::from_vec(sim.times.clone());
        out.write_with("times.npy", |f| times.write_npy(f).map_err(std::io::Error::other))?;
        out.commit().with_context(|| format!("writing {}", dir.display()))?;
    }
    Ok(dirs)
}

/// Resets the process's peak resident memory (Linux; ignored elsewhere).
fn reset_peak_rss() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

/// The process's peak resident memory since the last reset, bytes (Linux `VmHWM`).
fn peak_rss() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The timings as Markdown: one table of levels per size, then the sizes side by side.
pub fn markdown(scene: &Path, preset: &str, rows: &[SizeTime]) -> String {
    let mut s = format!(
        "# Reconstruction speed: {} (filmed with the surface solver), preset `{preset}`, {} threads\n\n",
        scene.display(),
        rayon::current_num_threads()
    );
    let _ = writeln!(
        s,
        "| camera | level | vertices | frames | stage 1 (s) | shape (s) | iterations | evaluations | per evaluation (ms) |\n|---|---|---|---|---|---|---|---|---|"
    );
    for r in rows {
        for l in &r.levels {
            let _ = writeln!(
                s,
                "| {}x{} | {} | {} | {} | {:.2} | {:.2} | {} | {} | {:.1} |",
                r.width,
                r.height,
                l.level,
                l.vertices,
                l.frames,
                l.stage1_s,
                l.stage2_s,
                l.iterations,
                l.evaluations,
                l.ms_per_evaluation()
            );
        }
    }
    let _ = writeln!(
        s,
        "\n| camera | reading (s) | reconstruction (s) | stage 1 + 2 per vertex and frame (us) | peak memory (GB) |\n|---|---|---|---|---|"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "| {}x{} | {:.2} | {:.1} | {:.3} | {} |",
            r.width,
            r.height,
            r.load_s,
            r.reconstruct_s,
            r.us_per_vertex_frame(),
            r.peak_rss_bytes.map_or("-".into(), |b| format!("{:.2}", b as f64 / 1e9))
        );
    }
    if let (Some(a), Some(b)) = (rows.first(), rows.last()) {
        let _ = writeln!(
            s,
            "\nTime per vertex and frame at {}x{} over {}x{}: {:.2} (1 for linear).",
            b.width,
            b.height,
            a.width,
            a.height,
            b.us_per_vertex_frame() / a.us_per_vertex_frame()
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_and_bad_ones_are_named() {
        assert_eq!(parse_size("640x512").unwrap(), (640, 512));
        for bad in ["640", "4x4", "ax512", "640x"] {
            assert!(parse_size(bad).unwrap_err().to_string().contains(bad), "{bad}");
        }
    }

    #[test]
    fn time_per_vertex_frame_sums_every_level() {
        let lv = |v, s1, s2| LevelTime {
            level: 0,
            vertices: v,
            frames: 10,
            stage1_s: s1,
            stage2_s: s2,
            iterations: 3,
            evaluations: 4,
        };
        let r = SizeTime {
            width: 8,
            height: 8,
            load_s: 0.0,
            reconstruct_s: 0.0,
            levels: vec![lv(100, 1e-3, 1e-3), lv(400, 4e-3, 4e-3)],
            peak_rss_bytes: None,
        };
        assert!((r.us_per_vertex_frame() - 2.0).abs() < 1e-12);
        let md = markdown(Path::new("s.json"), "paper", &[r.clone(), r]);
        assert!(
            md.contains("| 8x8 | 0 | 400 | 10 | 0.00 | 0.00 | 3 | 4 | 1.0 |") && md.contains("(1 for linear)"),
            "{md}"
        );
    }
}
