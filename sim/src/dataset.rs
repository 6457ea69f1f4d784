//! A simulation seen by the thermal camera: the videos, mask and ground truth of a benchmark
//! dataset (SI units: metres, kelvin, W/m^2).
//!
//! The whole boundary of the tetrahedral mesh is rasterised once with a depth buffer (so side
//! walls the camera happens to see are rendered too, and hidden parts are not); every frame is
//! then a gather of node temperatures through the stored barycentric coordinates, turned into
//! what a radiometric camera reports by [`Sensor::expose`] (apparent temperature, fixed
//! pattern, temporal noise, quantisation). `video_clean` is the apparent temperature without
//! any noise, offset or quantisation.
//!
//! # Optics
//! With the scene's default point sampling (`camera.supersampling` 1, no `camera.psf`) each
//! pixel shows the surface at its centre: the film is the true temperature there, NaN off the
//! object. Otherwise the boundary is also rasterised at `s x s` sub-samples per pixel
//! ([`Footprint`]) and the film is each pixel's radiance temperature over its footprint
//! through the PSF, the background counted at the ambient temperature: finite wherever object
//! radiance reaches the pixel, also just outside the mask, and NaN only for pure background
//! ([`crate::camera::optics`] states the model). The optics act before the sensor, so the
//! film is the noise-free optical signal any sensor re-films ([`expose_video`]). The mask,
//! depth, normals and flux stay those of the pixel centres: the ground truth a method is
//! scored against keeps its meaning.

use crate::camera::{rasterize, Camera, CameraError, Footprint, PixelKernel, Render, Sensor};
use crate::scene::{Scene, SceneError};
use crate::simulate::Simulation;
use rayon::prelude::*;
use std::time::Instant;

/// Errors while rendering a dataset.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DatasetError {
    #[error(transparent)]
    Camera(#[from] CameraError),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("camera: the object covers no pixel; point camera.look_at at it (camera.position {position:?} m, camera.look_at {look_at:?} m)")]
    NotInView { position: [f64; 3], look_at: [f64; 3] },
    #[error("camera.supersampling, camera.psf: the camera-grid surface solver (solver.surface_mesh = \"camera_grid\") knows temperatures at pixel centres only, so it films by point sampling; remove the optics or use the visible surface")]
    OpticsOnCameraGrid,
}

/// Images (#H*W, row-major: pixel (u, v) is element v * W + u) and videos (#frames*H*W).
pub struct Dataset {
    pub camera: Camera,
    /// Frame times (s); lamps switch on at 0.
    pub times: Vec<f64>,
    pub mask: Vec<bool>,
    /// Depth z_c along the optical axis (m), NaN off the object.
    pub depth: Vec<f32>,
    /// World-frame unit normals of the surface seen at each pixel, NaN off the object.
    pub normals: Vec<[f32; 3]>,
    /// Absorbed flux with every lamp on (W/m^2), NaN off the object.
    pub flux: Vec<f32>,
    /// Apparent temperature as the camera reports it (K).
    pub video: Vec<f32>,
    /// The film (K, float32 as the sensor takes it): point-sampled, the true surface
    /// temperature at each pixel centre, NaN off the object; with optics, each pixel's
    /// radiance temperature over its footprint, NaN only for pure background (module
    /// documentation, "Optics"). [`expose_video`] turns it into `video` with any sensor, so
    /// one simulation can be filmed at several noise levels and seeds.
    pub film: Vec<f32>,
    /// Apparent temperature without noise, fixed pattern or quantisation (K), in f64: the
    /// departures from separability that carry a row of the Laplacian are below float32's
    /// resolution at 300 K (3e-5 K).
    pub video_clean: Vec<f64>,
    /// Sub-samples on the object of the optics' supersampled rasterisation (0: point sampling).
    pub object_sub_samples: usize,
    /// Seconds to rasterise once (with the optics' supersampled rasterisation, if any), and to
    /// make every frame (gather, optics, sensor) after that.
    pub rasterize_seconds: f64,
    pub frames_seconds: f64,
}

impl Dataset {
    /// Pixels per image.
    pub fn pixels(&self) -> usize {
        (self.camera.width * self.camera.height) as usize
    }
}

/// Renders the frames of `sim` with the scene's camera: the triangles `faces` over `verts`
/// (m) are rasterised, `sim.frame(k)` gives the temperature of every vertex of `verts` (K)
/// and `sim.face_flux` the absorbed flux of every face (W/m^2). For the volumetric solver
/// these are the mesh's nodes and boundary faces; for the surface solver, the visible
/// surface's vertices and triangles.
///
/// A surface simulation on the camera grid (`sim.camera_grid`) has one vertex per pixel: pass
/// the tetrahedral mesh's nodes and boundary faces, whose rendering gives the true depth and
/// normals; the mask is the grid's pixels, each showing its vertex's temperature and flux.
pub fn render(
    scene: &Scene,
    verts: &[[f64; 3]],
    faces: &[[usize; 3]],
    sim: &Simulation,
) -> Result<Dataset, DatasetError> {
    let camera = Camera::from_spec(&scene.camera)?;
    let material = scene.material.resolve()?;
    let ambient = scene.environment.ambient_temperature;
    let sensor = Sensor::from_spec(&scene.camera, material.emissivity, ambient)?;
    let mut quiet = scene.camera.clone();
    quiet.netd = 0.0;
    quiet.fixed_pattern_sigma = 0.0;
    quiet.quantization = 0.0;
    let clean_sensor = Sensor::from_spec(&quiet, material.emissivity, ambient)?;

    if sim.camera_grid.is_some() && !scene.camera.point_sampling() {
        return Err(DatasetError::OpticsOnCameraGrid);
    }
    let kernel = PixelKernel::from_spec(&scene.camera)?;

    let t0 = Instant::now();
    let render: Render = rasterize(&camera, verts, faces);
    if render.covered() == 0 {
        return Err(DatasetError::NotInView { position: scene.camera.position, look_at: scene.camera.look_at });
    }
    // Point sampling keeps the pixel-centre gather: the bytes of every film made before the
    // optics existed.
    let footprint = (!scene.camera.point_sampling()).then(|| Footprint::new(&camera, kernel, verts, faces));
    let rasterize_seconds = t0.elapsed().as_secs_f64();
    let n = render.pixel_count();
    let mut mask = render.mask();
    let mut flux = vec![f32::NAN; n];
    let mut depth = render.depth();
    let mut normals = render.normals(verts, faces);
    match &sim.camera_grid {
        None => render.interpolate_face(&sim.face_flux, &mut flux),
        Some(grid) => {
            let mut on_grid = vec![false; n];
            for (&p, &q) in grid.pixels.iter().zip(&grid.vertex_flux) {
                on_grid[p] = true;
                flux[p] = q as f32;
            }
            for p in 0..n {
                if !on_grid[p] {
                    mask[p] = false;
                    depth[p] = f32::NAN;
                    normals[p] = [f32::NAN; 3];
                }
            }
        }
    }

    let t1 = Instant::now();
    let frames = sim.times.len();
    let mut film = vec![0.0_f32; frames * n];
    let mut video_clean = vec![0.0_f64; frames * n];
    film.par_chunks_mut(n).zip(video_clean.par_chunks_mut(n)).enumerate().for_each(|(k, (truth32, clean_out))| {
        let mut truth = vec![f64::NAN; n];
        match (&sim.camera_grid, &footprint) {
            (None, None) => render.interpolate(faces, sim.frame(k), &mut truth),
            (None, Some(footprint)) => footprint.film_into(faces, sim.frame(k), ambient, &mask, &mut truth),
            (Some(grid), _) => {
                for (&p, &t) in grid.pixels.iter().zip(sim.frame(k)) {
                    truth[p] = t;
                }
            }
        }
        for (o, &t) in truth32.iter_mut().zip(&truth) {
            *o = t as f32;
        }
        clean_sensor.expose_clean(&truth, &mask, clean_out);
    });
    let video = expose_video(&sensor, &film, &mask);
    let frames_seconds = t1.elapsed().as_secs_f64();
    Ok(Dataset {
        depth,
        normals,
        camera,
        times: sim.times.clone(),
        mask,
        flux,
        video,
        video_clean,
        film,
        object_sub_samples: footprint.as_ref().map_or(0, Footprint::object_sub_samples),
        rasterize_seconds,
        frames_seconds,
    })
}

/// The video (#frames*H*W, K) `sensor` reports for a `film` (#frames*H*W, K, NaN where only
/// background radiance arrives; [`Dataset::film`]) seen through `mask` (#H*W): frame k is
/// [`Sensor::expose`] of frame k, so its noise depends only on the sensor's seed and k, and the
/// same film and sensor give the same bytes on any thread count.
///
/// # Panics
/// If `film` is not a whole number of `mask`-sized frames.
pub fn expose_video(sensor: &Sensor, film: &[f32], mask: &[bool]) -> Vec<f32> {
    let n = mask.len();
    assert!(n > 0 && film.len() % n == 0, "the film is not a whole number of frames");
    let mut video = vec![0.0_f32; film.len()];
    video.par_chunks_mut(n).zip(film.par_chunks(n)).enumerate().for_each(|(k, (out, frame))| {
        sensor.expose(k as u64, frame, mask, out);
    });
    video
}

/// Writes a boolean mask (#H*W, row-major) as an 8-bit greyscale PNG (255 = object).
pub fn write_mask_png(w: &mut impl std::io::Write, mask: &[bool], width: u32, height: u32) -> std::io::Result<()> {
    let mut enc = png::Encoder::new(w, width, height);
    enc.set_color(png::ColorType::Grayscale);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header().map_err(std::io::Error::other)?;
    let data: Vec<u8> = mask.iter().map(|&m| if m { 255 } else { 0 }).collect();
    writer.write_image_data(&data).map_err(std::io::Error::other)?;
    writer.finish().map_err(std::io::Error::other)
}
