//! A simulation seen by the thermal camera: the videos, mask and ground truth of a benchmark
//! dataset (SI units: metres, kelvin, W/m^2).
//!
//! The whole boundary of the tetrahedral mesh is rasterised once with a depth buffer (so side
//! walls the camera happens to see are rendered too, and hidden parts are not); every frame is
//! then a gather of node temperatures through the stored barycentric coordinates, turned into
//! what a radiometric camera reports by [`Sensor::expose`] (apparent temperature, fixed
//! pattern, temporal noise, quantisation). `video_clean` is the apparent temperature without
//! any noise, offset or quantisation.

use crate::camera::{rasterize, Camera, CameraError, Render, Sensor};
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
    /// True surface temperature at each pixel (K, float32 as the sensor takes it; NaN off the
    /// object): the film [`expose_video`] turns into `video` with any sensor, so one
    /// simulation can be filmed at several noise levels and seeds.
    pub film: Vec<f32>,
    /// Apparent temperature without noise, fixed pattern or quantisation (K), in f64: the
    /// departures from separability that carry a row of the Laplacian are below float32's
    /// resolution at 300 K (3e-5 K).
    pub video_clean: Vec<f64>,
    /// Seconds to rasterise once, and to make every frame (gather + sensor) after that.
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

    let t0 = Instant::now();
    let render: Render = rasterize(&camera, verts, faces);
    let rasterize_seconds = t0.elapsed().as_secs_f64();
    if render.covered() == 0 {
        return Err(DatasetError::NotInView { position: scene.camera.position, look_at: scene.camera.look_at });
    }
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
        match &sim.camera_grid {
            None => render.interpolate(faces, sim.frame(k), &mut truth),
            Some(grid) => {
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
        rasterize_seconds,
        frames_seconds,
    })
}

/// The video (#frames*H*W, K) `sensor` reports for a `film` of true surface temperatures
/// (#frames*H*W, K, NaN off the object) seen through `mask` (#H*W): frame k is
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
