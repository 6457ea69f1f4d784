//! `simbench suite converge`: does the filmed video of a suite object converge where methods
//! read it? A refinement study of its meshing and time step.
//!
//! From the spec's settings (level 0), each series refines one parameter by halves, the others
//! held: `surface` halves the element size on the surface (`meshing.surface_element_m` and
//! the generated objects' `object_spacing_m`), `layers` doubles the prism layers through a
//! shell's wall (`meshing.wall_layers`), `time_step` halves the solver's step. Each level is
//! simulated and filmed noise-free with the `left` lamp (the camera's apparent temperature in
//! f64, before any sensor), and consecutive levels of a series are compared frame by frame
//! ([`metrics`]). A pair of levels passes when every frame differs by at most
//! [`Criteria::rms_k`] RMS over the mask and the pixel Laplacian of every heated frame's rise
//! by at most [`Criteria::laplacian_rel`] of its own RMS; a series' verdict is its two finest
//! levels' pair, and its coarsest passing level is the first level whose pair with the next
//! passes. A level whose mesh would exceed `meshing.max_tetrahedra` ends its series there,
//! with the figures reached.
//!
//! Output (`--out`): `levels/<series>-<j>/` (the scene, `film.npy` and `level.json`, reused
//! when a study is resumed), `levels.csv` (one row per level: parameters, nodes, tetrahedra,
//! build and solve seconds), `frames.csv` (one row per pair and frame), `convergence.png`
//! (the worst frame of each pair against the level), `summary.md` and `summary.json`.

pub mod metrics;
pub mod plot;

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use ndarray::Array3;
use ndarray_npy::{ReadNpyExt, WriteNpyExt};
use serde::{Deserialize, Serialize};

use super::spec::{SuiteObject, SuiteSpec};
use crate::table::cells;
use metrics::{Film, FrameDiff};

/// The convergence rule of a pair of levels (issue 52: 2 mK and 10 %).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Criteria {
    /// Largest RMS difference of a frame over the mask, K.
    pub rms_k: f64,
    /// Largest RMS difference of a heated frame's pixel Laplacian of the rise, relative to its
    /// own RMS.
    pub laplacian_rel: f64,
}

impl Default for Criteria {
    fn default() -> Self {
        Criteria { rms_k: 2e-3, laplacian_rel: 0.10 }
    }
}

/// The parameter a series refines.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
#[value(rename_all = "snake_case")]
pub enum Series {
    /// Element size on the surface halved.
    Surface,
    /// Prism layers through the wall doubled.
    Layers,
    /// Solver time step halved.
    TimeStep,
}

impl Series {
    pub fn name(self) -> &'static str {
        match self {
            Series::Surface => "surface",
            Series::Layers => "layers",
            Series::TimeStep => "time_step",
        }
    }
}

/// The settings of one level (m, s).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Params {
    pub surface_element_m: f64,
    pub object_spacing_m: f64,
    pub wall_layers: u32,
    pub time_step_s: f64,
}

impl Params {
    /// Level 0: the spec's settings.
    pub fn of_spec(spec: &SuiteSpec) -> Params {
        Params {
            surface_element_m: spec.meshing.surface_element_m,
            object_spacing_m: spec.meshing.object_spacing_m,
            wall_layers: spec.meshing.wall_layers.unwrap_or(heatsim::scene::options::DEFAULT_WALL_LAYERS),
            time_step_s: spec.timing.time_step_s,
        }
    }

    /// Level `j` of `series` from level 0.
    pub fn refined(self, series: Series, j: u32) -> Params {
        let f = 2f64.powi(j as i32);
        match series {
            Series::Surface => Params {
                surface_element_m: self.surface_element_m / f,
                object_spacing_m: self.object_spacing_m / f,
                ..self
            },
            Series::Layers => Params { wall_layers: self.wall_layers << j, ..self },
            Series::TimeStep => Params { time_step_s: self.time_step_s / f, ..self },
        }
    }
}

/// One level simulated: its settings, mesh and cost.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Level {
    pub series: Series,
    pub level: u32,
    pub params: Params,
    pub nodes: usize,
    pub tetrahedra: usize,
    /// Meshing time, s.
    pub build_seconds: f64,
    /// Solving and filming time, s.
    pub solve_seconds: f64,
    /// Peak temperature rise of the simulation, K.
    pub peak_rise_k: f64,
}

/// Two consecutive levels of a series compared.
#[derive(Clone, Debug, Serialize)]
pub struct Pair {
    pub series: Series,
    /// The coarser level (compared with `level + 1`).
    pub level: u32,
    pub frames: Vec<FrameDiff>,
    pub worst_rms_k: f64,
    pub worst_laplacian_rel: f64,
    pub passes: bool,
}

/// A series' outcome.
#[derive(Clone, Debug, Serialize)]
pub struct SeriesResult {
    pub series: Series,
    pub levels: Vec<Level>,
    pub pairs: Vec<Pair>,
    /// Why the series stopped before the levels asked for, if it did.
    pub stopped: Option<String>,
    /// The finest pair passes.
    pub converged: bool,
    /// The first level whose pair with the next passes.
    pub coarsest_passing: Option<u32>,
}

/// A study of one object.
#[derive(Clone, Debug, Serialize)]
pub struct Study {
    pub object: String,
    pub criteria: Criteria,
    pub times_s: Vec<f64>,
    pub series: Vec<SeriesResult>,
}

/// What to study.
pub struct Options {
    pub spec: SuiteSpec,
    /// An object id of the spec (`ball-volumetric-shell-d0.002`) or its name (`ball`).
    pub object: String,
    pub series: Vec<Series>,
    /// Levels per series, level 0 included (>= 2).
    pub levels: u32,
    pub criteria: Criteria,
    pub out: PathBuf,
    pub bunny: Option<PathBuf>,
}

/// Runs the study (module documentation), resuming the levels already in `opts.out`.
///
/// # Errors
/// An unknown object, fewer than 2 levels, a failing level 0 or 1 (meshing, solver), I/O.
pub fn study(opts: &Options) -> anyhow::Result<Study> {
    anyhow::ensure!(opts.levels >= 2, "--levels: at least 2 levels are needed to compare, got {}", opts.levels);
    let objects = opts.spec.resolved_objects()?;
    let object = objects.iter().find(|o| o.id == opts.object || o.object.name() == opts.object).with_context(|| {
        format!(
            "--object {}: not in the spec; its objects: {}",
            opts.object,
            objects.iter().map(|o| o.id.as_str()).collect::<Vec<_>>().join(", ")
        )
    })?;
    let base = Params::of_spec(&opts.spec);
    let (base_level, base_film, times) = film_level(opts, object, Series::Surface, 0, base)?;
    let mut series = Vec::new();
    for &s in &opts.series {
        let mut levels = vec![Level { series: s, ..base_level.clone() }];
        let mut films = vec![base_film.clone()];
        let mut stopped = None;
        for j in 1..opts.levels {
            let p = base.refined(s, j);
            match film_level(opts, object, s, j, p) {
                Ok((level, film, _)) => {
                    levels.push(level);
                    films.push(film);
                }
                Err(e) => {
                    eprintln!("suite converge: {} level {j} of {}: {e:#}", s.name(), object.id);
                    stopped = Some(format!("level {j}: {e:#}"));
                    break;
                }
            }
        }
        let pairs = films
            .windows(2)
            .enumerate()
            .map(|(j, w)| pair(s, j as u32, &w[0], &w[1], &times, &opts.criteria))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let converged = pairs.last().is_some_and(|p| p.passes);
        let coarsest_passing = pairs.iter().find(|p| p.passes).map(|p| p.level);
        series.push(SeriesResult { series: s, levels, pairs, stopped, converged, coarsest_passing });
    }
    Ok(Study { object: object.id.clone(), criteria: opts.criteria, times_s: times, series })
}

/// Compares two levels; the Laplacian counts on the frames after the lamps switch on (t > 0)
/// only: before, the rise is zero but for rounding, and so would be its Laplacian's RMS.
fn pair(series: Series, level: u32, coarse: &Film, fine: &Film, times: &[f64], c: &Criteria) -> anyhow::Result<Pair> {
    let mut frames = metrics::compare(coarse, fine)?;
    for (f, &t) in frames.iter_mut().zip(times) {
        if t <= 0.0 {
            f.laplacian_rel = f64::NAN;
        }
    }
    let worst_rms_k = frames.iter().map(|f| f.rms_k).fold(0.0, f64::max);
    let worst_laplacian_rel =
        frames.iter().filter(|f| !f.laplacian_rel.is_nan()).map(|f| f.laplacian_rel).fold(0.0, f64::max);
    let passes = worst_rms_k <= c.rms_k && worst_laplacian_rel <= c.laplacian_rel;
    Ok(Pair { series, level, frames, worst_rms_k, worst_laplacian_rel, passes })
}

/// The folder of a level: level 0 is shared by every series.
fn level_dir(out: &Path, series: Series, j: u32) -> PathBuf {
    if j == 0 {
        out.join("levels").join("base")
    } else {
        out.join("levels").join(format!("{}-{j}", series.name()))
    }
}

/// Simulates and films one level (or reads it back from an earlier run of the study).
fn film_level(
    opts: &Options,
    object: &SuiteObject,
    series: Series,
    j: u32,
    p: Params,
) -> anyhow::Result<(Level, Film, Vec<f64>)> {
    let dir = level_dir(&opts.out, series, j);
    if let Some(done) = read_level(&dir)? {
        eprintln!("suite converge: {} level {j}: reusing {}", series.name(), dir.display());
        return Ok(done);
    }
    eprintln!("suite converge: {} {} level {j}: {p:?}", object.id, series.name());
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut setup = opts.spec.setup();
    setup.surface_element_m = p.surface_element_m;
    setup.object_spacing_m = p.object_spacing_m;
    setup.wall_layers = Some(p.wall_layers);
    setup.time_step_s = p.time_step_s;
    let generated = object.object.revolved().map(|r| r.obj_file(p.object_spacing_m)).transpose()?;
    if let Some((bytes, _)) = &generated {
        heatsim::io::write_atomic(&dir.join("object.obj"), bytes)?;
    }
    let json = cells::scene_json(&object.row(), &setup, generated.as_ref().map(|(_, s)| ("object.obj", *s)))?;
    let scene_path = dir.join("scene.json");
    heatsim::io::write_atomic(&scene_path, (serde_json::to_string_pretty(&json)? + "\n").as_bytes())?;
    let scene = crate::cmd::load_scene(&scene_path, None)?;
    let t0 = Instant::now();
    let meshed = heatsim::meshing::mesh_scene(&scene, opts.bunny.as_deref())
        .with_context(|| format!("meshing {}", scene_path.display()))?;
    let build_seconds = t0.elapsed().as_secs_f64();
    let (_, lamps) = scene.lamp_sets().into_iter().next().context("the suite's scenes have lamp configurations")?;
    let mut lit = scene.clone();
    lit.lamps = lamps;
    lit.lamp_configurations.clear();
    let t1 = Instant::now();
    let (sim, data) = crate::cmd::simulate::solve_and_film(&lit, &meshed, &scene_path)?;
    let solve_seconds = t1.elapsed().as_secs_f64();
    let (w, h) = (data.camera.width as usize, data.camera.height as usize);
    let frames: Vec<Vec<f64>> = data.video_clean.chunks(w * h).map(<[f64]>::to_vec).collect();
    let film = Film { width: w, height: h, mask: data.mask.clone(), frames };
    let level = Level {
        series,
        level: j,
        params: p,
        nodes: meshed.mesh.verts.len(),
        tetrahedra: meshed.mesh.tets.len(),
        build_seconds,
        solve_seconds,
        peak_rise_k: sim.report.max_temperature_rise_k,
    };
    write_level(&dir, &level, &film, &sim.times)?;
    Ok((level, film, sim.times))
}

/// `level.json` with the frame times beside the film.
#[derive(Serialize, Deserialize)]
struct LevelFile {
    level: Level,
    times_s: Vec<f64>,
    mask: Vec<bool>,
}

fn write_level(dir: &Path, level: &Level, film: &Film, times: &[f64]) -> anyhow::Result<()> {
    let flat: Vec<f64> = film.frames.concat();
    let a = Array3::from_shape_vec((film.frames.len(), film.height, film.width), flat)?;
    let mut bytes = Vec::new();
    a.write_npy(&mut bytes)?;
    heatsim::io::write_atomic(&dir.join("film.npy"), &bytes)?;
    let file = LevelFile { level: level.clone(), times_s: times.to_vec(), mask: film.mask.clone() };
    // level.json last: its presence marks the level done.
    heatsim::io::write_atomic(&dir.join("level.json"), serde_json::to_string_pretty(&file)?.as_bytes())?;
    Ok(())
}

fn read_level(dir: &Path) -> anyhow::Result<Option<(Level, Film, Vec<f64>)>> {
    let marker = dir.join("level.json");
    if !marker.exists() {
        return Ok(None);
    }
    let file: LevelFile = serde_json::from_str(&std::fs::read_to_string(&marker)?)
        .with_context(|| format!("reading {}", marker.display()))?;
    let path = dir.join("film.npy");
    let a = Array3::<f64>::read_npy(std::fs::File::open(&path).with_context(|| format!("opening {}", path.display()))?)
        .with_context(|| format!("reading {}", path.display()))?;
    let (n, h, w) = a.dim();
    let flat = a.into_raw_vec_and_offset().0;
    let frames = flat.chunks(w * h).map(<[f64]>::to_vec).collect::<Vec<_>>();
    anyhow::ensure!(frames.len() == n && file.mask.len() == w * h, "{}: film and mask sizes differ", dir.display());
    Ok(Some((file.level, Film { width: w, height: h, mask: file.mask, frames }, file.times_s)))
}

/// `levels.csv`, `frames.csv`, `summary.json`, `summary.md` and `convergence.png` into `out`.
pub fn write(study: &Study, out: &Path) -> anyhow::Result<String> {
    let mut levels = String::from(
        "series,level,surface_element_m,object_spacing_m,wall_layers,time_step_s,nodes,tetrahedra,build_s,solve_s,peak_rise_k\n",
    );
    let mut frames =
        String::from("series,coarse_level,frame,time_s,rms_diff_k,laplacian_rms_k_per_px2,laplacian_rel_diff\n");
    for s in &study.series {
        for l in &s.levels {
            let p = &l.params;
            levels.push_str(&format!(
                "{},{},{},{},{},{},{},{},{:.3},{:.3},{:.6}\n",
                s.series.name(),
                l.level,
                p.surface_element_m,
                p.object_spacing_m,
                p.wall_layers,
                p.time_step_s,
                l.nodes,
                l.tetrahedra,
                l.build_seconds,
                l.solve_seconds,
                l.peak_rise_k
            ));
        }
        for pr in &s.pairs {
            for (k, f) in pr.frames.iter().enumerate() {
                frames.push_str(&format!(
                    "{},{},{k},{},{:.6e},{:.6e},{:.6e}\n",
                    s.series.name(),
                    pr.level,
                    study.times_s.get(k).copied().unwrap_or(f64::NAN),
                    f.rms_k,
                    f.laplacian_rms,
                    f.laplacian_rel
                ));
            }
        }
    }
    let md = markdown(study);
    heatsim::io::write_atomic(&out.join("levels.csv"), levels.as_bytes())?;
    heatsim::io::write_atomic(&out.join("frames.csv"), frames.as_bytes())?;
    heatsim::io::write_atomic(&out.join("summary.json"), serde_json::to_string_pretty(study)?.as_bytes())?;
    heatsim::io::write_atomic(&out.join("summary.md"), md.as_bytes())?;
    if let Some(png) = crate::figure::optional("convergence.png", || plot::png(study)) {
        heatsim::io::write_atomic(&out.join("convergence.png"), &png)?;
    }
    Ok(md)
}

/// The study in Markdown: one table row per pair, and each series' verdict.
pub fn markdown(study: &Study) -> String {
    let c = &study.criteria;
    let mut md = format!(
        "# Convergence of {}\n\nA pair of levels passes when every frame differs by at most {} mK RMS over the mask and the pixel Laplacian of every heated frame's rise by at most {} % of its RMS (the left lamp, noise-free, apparent temperature).\n\n",
        study.object,
        c.rms_k * 1e3,
        c.laplacian_rel * 100.0
    );
    md.push_str("| series | levels | parameters (coarse -> fine) | nodes (fine) | worst frame RMS, mK | worst Laplacian, % | passes |\n|---|---|---|---|---|---|---|\n");
    for s in &study.series {
        for pr in &s.pairs {
            let (a, b) = (&s.levels[pr.level as usize], &s.levels[pr.level as usize + 1]);
            md.push_str(&format!(
                "| {} | {} -> {} | {} -> {} | {} | {:.2} | {:.1} | {} |\n",
                s.series.name(),
                pr.level,
                pr.level + 1,
                describe(s.series, &a.params),
                describe(s.series, &b.params),
                b.nodes,
                pr.worst_rms_k * 1e3,
                pr.worst_laplacian_rel * 100.0,
                if pr.passes { "yes" } else { "no" }
            ));
        }
    }
    md.push('\n');
    for s in &study.series {
        let verdict = match (s.converged, s.coarsest_passing) {
            (true, Some(j)) => {
                format!("converged; coarsest passing level {j} ({})", describe(s.series, &s.levels[j as usize].params))
            }
            (false, Some(j)) => format!("finest pair fails; level {j} passed with the next"),
            (_, None) => "no pair passes".to_string(),
        };
        md.push_str(&format!("- {}: {verdict}", s.series.name()));
        if let Some(why) = &s.stopped {
            md.push_str(&format!(" (stopped at {why})"));
        }
        md.push('\n');
    }
    md
}

fn describe(series: Series, p: &Params) -> String {
    match series {
        Series::Surface => format!("{} m / {} m", p.surface_element_m, p.object_spacing_m),
        Series::Layers => format!("{} layers", p.wall_layers),
        Series::TimeStep => format!("{} s", p.time_step_s),
    }
}
