//! `simbench suite build`: simulate every object once, store its noise-free film and ground
//! truth, and hash every case's inputs (the noise is drawn from the film when a method runs,
//! [`super::inputs`]).
//!
//! Layout of a suite:
//! - `suite.json`: the manifest ([`super::manifest`]);
//! - `build.json`: timings and sizes of the build (not part of the version);
//! - `objects/<id>/scene.json` (and `object.obj` for generated objects): what was simulated,
//!   with a noise-free camera;
//! - `objects/<id>/<view>/`: `film.npy` (float32 [frames, H, W], the true surface temperature
//!   at each pixel in K, NaN off the object), `times.npy`, `mask.npy`, `camera.json`,
//!   `environment.json`, `material.json`, `lamps.json` and the ground truth (`gt_depth.npy`,
//!   `gt_normals.npy`, `gt_flux.npy`, `gt_mesh.obj`), and `meta.json` (the simulation's
//!   reports, with timings: not hashed, not part of the version);
//! - `bounds/` and `bounds.json`: the Cramér–Rao bounds of the marked objects
//!   ([`super::bound`]).
//!
//! An object is done when `objects/<id>/object.json` (its manifest entry) exists and its files
//! match; an interrupted build resumes from there.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{ensure, Context};
use heatsim::dataset_format::META_FILE;
use ndarray::{Array1, Array2, Array3};
use ndarray_npy::WriteNpyExt;
use serde_json::json;

use super::inputs;
use super::manifest::{file_sha256, CaseEntry, Manifest, ObjectEntry, MANIFEST, SUITE_FORMAT};
use super::spec::{SuiteObject, SuiteSpec};
use crate::table::cells;

/// The stored spec of a suite under construction (refuses mixing two specs in one folder).
const SPEC_FILE: &str = "spec.json";

/// What `simbench suite build` was asked to do.
pub struct Options {
    pub spec: SuiteSpec,
    pub out: PathBuf,
    /// A Stanford bunny OBJ instead of the cached download.
    pub bunny: Option<PathBuf>,
}

/// Builds the suite (module documentation) and returns its manifest.
///
/// # Errors
/// An output folder holding another spec, a failing object (meshing, solver), I/O errors.
pub fn build(opts: &Options) -> anyhow::Result<Manifest> {
    let t0 = Instant::now();
    prepare_out(&opts.out, &opts.spec)?;
    let objects = opts.spec.resolved_objects()?;
    let mut entries = Vec::new();
    let mut timings = serde_json::Map::new();
    for (i, o) in objects.iter().enumerate() {
        eprintln!("suite build: object {}/{}: {}", i + 1, objects.len(), o.id);
        let t = Instant::now();
        let (entry, fresh) = build_object(opts, o).with_context(|| format!("object {}", o.id))?;
        if fresh {
            timings.insert(o.id.clone(), json!({ "simulate_and_store_s": t.elapsed().as_secs_f64() }));
        }
        entries.push(entry);
    }
    let t = Instant::now();
    let mut manifest = Manifest {
        format: SUITE_FORMAT,
        version: String::new(),
        simulator: crate::sweep::cells::heatsim_version(),
        spec: opts.spec.clone(),
        objects: entries,
        cases: Vec::new(),
    };
    manifest.cases = cases(&opts.out, &manifest)?;
    let refilm_s = t.elapsed().as_secs_f64();
    manifest.version = manifest.compute_version();
    let t = Instant::now();
    let bounds = match &opts.spec.bound {
        Some(b) => super::bound::build_bounds(&opts.out, &manifest, b)?,
        None => Vec::new(),
    };
    let bounds_s = t.elapsed().as_secs_f64();
    let text = serde_json::to_string_pretty(&manifest)? + "\n";
    heatsim::io::write_atomic(&opts.out.join(MANIFEST), text.as_bytes()).context("writing suite.json")?;
    let build = json!({
        "version": manifest.version,
        "threads": rayon::current_num_threads(),
        "objects_s": timings,
        "refilm_and_hash_all_cases_s": refilm_s,
        "bounds_s": bounds_s,
        "bounds": bounds.iter().map(|b| json!({ "object": b.object, "netd_mK": b.netd_mk, "seconds": b.seconds })).collect::<Vec<_>>(),
        "cases": manifest.cases.len(),
        "total_s": t0.elapsed().as_secs_f64(),
        "stored_bytes": dir_bytes(&opts.out),
        "note": "objects_s lists only the objects simulated by this invocation (a resumed build skips the others)",
    });
    heatsim::io::write_atomic(&opts.out.join("build.json"), (serde_json::to_string_pretty(&build)? + "\n").as_bytes())?;
    Ok(manifest)
}

/// Creates `out` or checks that it holds a build of the same spec.
fn prepare_out(out: &Path, spec: &SuiteSpec) -> anyhow::Result<()> {
    std::fs::create_dir_all(out.join("objects")).with_context(|| format!("creating {}", out.display()))?;
    let path = out.join(SPEC_FILE);
    let text = serde_json::to_string_pretty(spec)? + "\n";
    if path.exists() {
        let old = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
        ensure!(
            old == text,
            "{} holds a build of another spec ({}); choose another --out or remove it",
            out.display(),
            path.display()
        );
    } else {
        heatsim::io::write_atomic(&path, text.as_bytes())?;
    }
    Ok(())
}

/// Simulates and stores one object, or reuses a finished earlier build of it (then `false`).
fn build_object(opts: &Options, o: &SuiteObject) -> anyhow::Result<(ObjectEntry, bool)> {
    let rel = format!("objects/{}", o.id);
    let dir = opts.out.join(&rel);
    let marker = dir.join("object.json");
    if let Ok(text) = std::fs::read_to_string(&marker) {
        if let Ok(entry) = serde_json::from_str::<ObjectEntry>(&text) {
            let intact = entry.files.iter().all(|(f, sha)| file_sha256(&opts.out.join(f)).is_ok_and(|s| &s == sha));
            if intact {
                eprintln!("suite build: {} already built, kept", o.id);
                return Ok((entry, false));
            }
        }
    }
    if dir.exists() {
        std::fs::remove_dir_all(&dir).with_context(|| format!("clearing {}", dir.display()))?;
    }
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let setup = opts.spec.setup();
    let generated = match o.object.revolved() {
        Some(r) => Some(r.obj_file(setup.object_spacing_m)?),
        None => None,
    };
    if let Some((bytes, _)) = &generated {
        heatsim::io::write_atomic(&dir.join("object.obj"), bytes)?;
    }
    let scene_json = cells::scene_json(&o.row(), &setup, generated.as_ref().map(|(_, s)| ("object.obj", *s)))?;
    let scene_path = dir.join("scene.json");
    heatsim::io::write_atomic(&scene_path, (serde_json::to_string_pretty(&scene_json)? + "\n").as_bytes())?;
    let scene = crate::cmd::load_scene(&scene_path, None)?;
    let meshed = heatsim::meshing::mesh_scene(&scene, opts.bunny.as_deref())
        .with_context(|| format!("meshing the object of {}", scene_path.display()))?;
    for (name, lamps) in scene.lamp_sets() {
        let name = name.context("the suite's scenes have named lamp configurations")?;
        let mut lit = scene.clone();
        lit.lamps = lamps;
        lit.lamp_configurations.clear();
        let (sim, data) = crate::cmd::simulate::solve_and_film(&lit, &meshed, &scene_path)?;
        store_view(&dir.join(&name), &lit, &meshed, &sim, &data).with_context(|| format!("storing view {name}"))?;
    }
    let mut files = BTreeMap::new();
    for path in walk(&dir)?.into_iter().filter(|p| !p.ends_with(META_FILE)) {
        let rel_path = path.strip_prefix(&opts.out).expect("inside the suite").to_string_lossy().replace('\\', "/");
        files.insert(rel_path, file_sha256(&path)?);
    }
    let entry = ObjectEntry {
        id: o.id.clone(),
        object: o.object.name().into(),
        solver: o.solver.name().into(),
        thickness_m: o.thickness_m,
        material: o.object.material_and_wall().0.into(),
        files,
    };
    heatsim::io::write_atomic(&marker, (serde_json::to_string_pretty(&entry)? + "\n").as_bytes())?;
    Ok((entry, true))
}

/// Writes one view's film, inputs and ground truth (module documentation), all at once.
fn store_view(
    dir: &Path,
    scene: &heatsim::scene::Scene,
    meshed: &heatsim::meshing::MeshedObject,
    sim: &heatsim::simulate::Simulation,
    data: &heatsim::dataset::Dataset,
) -> anyhow::Result<()> {
    let frames = sim.times.len();
    let (h, w) = (data.camera.height as usize, data.camera.width as usize);
    let mut out = heatsim::io::OutputDir::new(dir).with_context(|| format!("preparing {}", dir.display()))?;
    let film = Array3::from_shape_vec((frames, h, w), data.film.clone())?;
    out.write_bytes("film.npy", &npy(&film)?)?;
    out.write_bytes("times.npy", &npy(&Array1::from_vec(sim.times.clone()))?)?;
    out.write_bytes("mask.npy", &npy(&Array2::from_shape_vec((h, w), data.mask.clone())?)?)?;
    crate::cmd::simulate::write_ground_truth(&mut out, sim, data)?;
    crate::cmd::simulate::dataset_json(scene, meshed, sim, data)?.write_into(&mut out)?;
    out.commit().with_context(|| format!("writing {}", dir.display()))?;
    Ok(())
}

/// The bytes of an array in `.npy` format.
pub fn npy<A: WriteNpyExt>(a: &A) -> anyhow::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    a.write_npy(&mut bytes)?;
    Ok(bytes)
}

/// Every case of the spec with the hashes of its inputs (re-filmed in memory).
fn cases(suite: &Path, manifest: &Manifest) -> anyhow::Result<Vec<CaseEntry>> {
    let mut out = Vec::new();
    for object in &manifest.objects {
        for noise in &manifest.spec.noise {
            for seed in noise.seeds(manifest.spec.seeds) {
                let id = CaseEntry::make_id(&object.id, noise, seed);
                let sensor_seeds =
                    super::manifest::VIEWS.iter().map(|v| (v.to_string(), CaseEntry::sensor_seed(&id, v))).collect();
                let mut case = CaseEntry {
                    id,
                    object: object.id.clone(),
                    noise: *noise,
                    seed,
                    sensor_seeds,
                    inputs: BTreeMap::new(),
                };
                let files = inputs::case_inputs(suite, &case, true)?;
                case.inputs = files.iter().map(|(p, b)| (p.clone(), crate::sweep::cells::sha256_hex(b))).collect();
                out.push(case);
            }
        }
    }
    Ok(out)
}

/// Every file under `dir`, sorted.
fn walk(dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).with_context(|| format!("listing {}", d.display()))? {
            let p = e?.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p);
            }
        }
    }
    out.sort();
    Ok(out)
}

/// Bytes of every file under `dir`.
fn dir_bytes(dir: &Path) -> u64 {
    walk(dir).map(|v| v.iter().filter_map(|p| p.metadata().ok()).map(|m| m.len()).sum()).unwrap_or(0)
}
