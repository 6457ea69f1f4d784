//! A case's inputs: what a method may read, as a real capture would have them.
//!
//! For each view (`left`, `right`): `video.npy` (float32 [frames, H, W], apparent temperature
//! in K as a camera set to emissivity 1 reports it), `times.npy`, `mask.npy`, `camera.json`
//! (the pinhole camera and the sensor's datasheet noise: NETD, fixed pattern, quantisation; no
//! seed), `environment.json` (ambient temperature and the object's emissivity only: the
//! convection coefficient is ground truth), `material.json` (the material as a table gives
//! it), and `lamps.json` only for methods that declare calibrated lamps. Never the film, the
//! ground truth or node temperatures.
//!
//! The video is the stored noise-free film exposed by the case's sensor
//! ([`heatsim::dataset::expose_video`], the same code `simbench simulate` films with): the
//! noise of a frame depends only on the sensor seed and the frame index, so the bytes are
//! fixed by the manifest, which holds their SHA-256; [`write_case_inputs`] checks them.

use std::path::Path;

use anyhow::{ensure, Context};
use heatsim::camera::Sensor;
use heatsim::dataset_format::{read_camera, read_environment, to_json_text, EnvironmentFile};
use ndarray::{Array2, Array3};

use super::build::npy;
use super::manifest::{CaseEntry, VIEWS};
use crate::sweep::cells::sha256_hex;

/// The store directory of a view of a case's object.
pub fn store_dir(suite: &Path, case: &CaseEntry, view: &str) -> std::path::PathBuf {
    suite.join("objects").join(&case.object).join(view)
}

/// (path relative to the case's input directory, bytes) of every input file of `case`,
/// `lamps.json` included when `lamps` is set.
///
/// # Errors
/// Missing or unreadable stored files, naming them.
pub fn case_inputs(suite: &Path, case: &CaseEntry, lamps: bool) -> anyhow::Result<Vec<(String, Vec<u8>)>> {
    let mut out = Vec::new();
    for view in VIEWS {
        let dir = store_dir(suite, case, view);
        let read = |name: &str| {
            let p = dir.join(name);
            std::fs::read(&p)
                .with_context(|| format!("{}: missing or unreadable (the suite is incomplete)", p.display()))
        };
        let seed =
            *case.sensor_seeds.get(view).with_context(|| format!("case {}: no sensor seed for {view}", case.id))?;
        out.push((format!("{view}/video.npy"), video(&dir, case, seed)?));
        for name in ["times.npy", "mask.npy", "material.json"] {
            out.push((format!("{view}/{name}"), read(name)?));
        }
        let mut camera = read_camera(&dir)?;
        camera.netd_k = Some(case.noise.netd_mk * 1e-3);
        camera.fixed_pattern_sigma_k = Some(case.noise.fixed_pattern_mk * 1e-3);
        camera.quantization_k = Some(case.noise.quantization_mk * 1e-3);
        camera.seed = None;
        out.push((format!("{view}/camera.json"), to_json_text(&camera).into_bytes()));
        let env = read_environment(&dir)?;
        let env = EnvironmentFile {
            ambient_temperature: env.ambient_temperature,
            convection_coefficient: None,
            back_boundary: None,
            emissivity: env.emissivity,
        };
        out.push((format!("{view}/environment.json"), to_json_text(&env).into_bytes()));
        if lamps {
            out.push((format!("{view}/lamps.json"), read("lamps.json")?));
        }
    }
    Ok(out)
}

/// The noisy video of one view: the stored film exposed by the case's sensor with `seed`.
fn video(dir: &Path, case: &CaseEntry, seed: u64) -> anyhow::Result<Vec<u8>> {
    let film_path = dir.join("film.npy");
    let film: Array3<f32> =
        ndarray_npy::read_npy(&film_path).with_context(|| format!("reading {}", film_path.display()))?;
    let mask_path = dir.join("mask.npy");
    let mask: Array2<bool> =
        ndarray_npy::read_npy(&mask_path).with_context(|| format!("reading {}", mask_path.display()))?;
    let (h, w) = mask.dim();
    ensure!(film.dim().1 == h && film.dim().2 == w, "{}: frames are not the mask's size", film_path.display());
    let env = read_environment(dir)?;
    let emissivity =
        env.emissivity.with_context(|| format!("{}: no emissivity", dir.join("environment.json").display()))?;
    let camera = read_camera(dir)?;
    let spec = heatsim::scene::camera::CameraSpec {
        width: camera.width,
        height: camera.height,
        netd: case.noise.netd_mk * 1e-3,
        fixed_pattern_sigma: case.noise.fixed_pattern_mk * 1e-3,
        quantization: case.noise.quantization_mk * 1e-3,
        seed,
        ..heatsim::scene::camera::CameraSpec::default()
    };
    let sensor = Sensor::from_spec(&spec, emissivity, env.ambient_temperature)?;
    let mask: Vec<bool> = mask.iter().copied().collect();
    let frames = film.dim().0;
    let flat: Vec<f32> = film.iter().copied().collect();
    let video = heatsim::dataset::expose_video(&sensor, &flat, &mask);
    npy(&Array3::from_shape_vec((frames, h, w), video)?)
}

/// Writes the inputs of `case` into `dir/left` and `dir/right` and checks each file against the
/// manifest.
///
/// # Errors
/// A file whose bytes differ from the manifest (a suite built by another version, or altered),
/// I/O errors.
pub fn write_case_inputs(suite: &Path, case: &CaseEntry, dir: &Path, lamps: bool) -> anyhow::Result<()> {
    for (rel, bytes) in case_inputs(suite, case, lamps)? {
        let expected =
            case.inputs.get(&rel).with_context(|| format!("case {}: {rel} is not in suite.json", case.id))?;
        let got = sha256_hex(&bytes);
        ensure!(
            &got == expected,
            "case {}: {rel} comes out with SHA-256 {got} but suite.json records {expected} (the stored film was altered, or this simbench films differently: rebuild the suite)",
            case.id
        );
        let path = dir.join(&rel);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).with_context(|| format!("creating {}", parent.display()))?;
        }
        heatsim::io::write_atomic(&path, &bytes).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
