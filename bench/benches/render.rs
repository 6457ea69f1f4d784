//! Criterion benches of the camera on the bunny relief's visible surface at 640 x 512:
//! (a) rasterisation (once per run) and (b) one frame = interpolate the vertex temperatures
//! and expose them (apparent temperature, fixed pattern, temporal noise, quantisation); and
//! (c) with the optics (`camera.supersampling` 4 and the default Gaussian PSF): the
//! supersampled rasterisation (once per run) and one frame's footprint film.
//! Throughput is one element per iteration, so Criterion's "thrpt" reads in frames per second.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use heatsim::camera::{rasterize, Camera, Footprint, PixelKernel, Sensor};
use heatsim::mesh::tetmesh::FaceTag;
use heatsim::scene::camera::{GaussianPsf, PsfSpec};
use heatsim::scene::Scene;
use std::path::Path;

fn bench_render(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/bunny.json");
    let scene = Scene::from_file(&path).expect("loading scenes/bunny.json");
    let mesh = heatsim::meshing::mesh_scene(&scene, None).expect("meshing").mesh;
    let (surface, _) = mesh.tagged_surface(FaceTag::Visible);
    let (verts, tris) = (&surface.verts, &surface.tris);
    let camera = Camera::from_spec(&scene.camera).expect("camera");
    let emissivity = scene.material.resolve().expect("material").emissivity;
    let ambient = scene.environment.ambient_temperature;
    let sensor = Sensor::from_spec(&scene.camera, emissivity, ambient).expect("sensor");
    // A smooth temperature field a few kelvin above ambient (values do not affect the timing).
    let temps: Vec<f64> = verts.iter().map(|p| ambient + 3.0 + 50.0 * p[0] - 30.0 * p[1] + 100.0 * p[2]).collect();

    let render = rasterize(&camera, verts, tris);
    let mask = render.mask();
    eprintln!(
        "bunny visible surface: {} vertices, {} triangles; {} of {} pixels covered",
        verts.len(),
        tris.len(),
        render.covered(),
        render.pixel_count()
    );

    let mut group = c.benchmark_group(format!("render/bunny_{}x{}", camera.width, camera.height));
    group.throughput(Throughput::Elements(1));
    group.bench_function("rasterize", |b| b.iter(|| rasterize(&camera, verts, tris)));
    let mut clean = vec![0.0_f32; render.pixel_count()];
    let mut out = vec![0.0_f32; render.pixel_count()];
    group.bench_function("interpolate", |b| b.iter(|| render.interpolate(tris, &temps, &mut clean)));
    render.interpolate(tris, &temps, &mut clean);
    let mut k = 0u64;
    group.bench_function("expose", |b| {
        b.iter(|| {
            sensor.expose(k, &clean, &mask, &mut out);
            k += 1;
        })
    });
    let mut k = 0u64;
    group.bench_function("frame", |b| {
        b.iter(|| {
            render.interpolate(tris, &temps, &mut clean);
            sensor.expose(k, &clean, &mask, &mut out);
            k += 1;
        })
    });
    group.finish();

    // The optics: 4 x 4 sub-samples per pixel through the Boson's diffraction-limited PSF.
    let mut spec = scene.camera.clone();
    spec.supersampling = 4;
    spec.psf = PsfSpec::Gaussian(GaussianPsf::default());
    let kernel = PixelKernel::from_spec(&spec).expect("kernel");
    let mut group = c.benchmark_group(format!("render/bunny_{}x{}_s4_psf", camera.width, camera.height));
    group.throughput(Throughput::Elements(1));
    group.sample_size(10);
    group.bench_function("footprint", |b| b.iter(|| Footprint::new(&camera, kernel.clone(), verts, tris)));
    let footprint = Footprint::new(&camera, kernel, verts, tris);
    eprintln!("optics: {} sub-samples on the object", footprint.object_sub_samples());
    let mut film = vec![0.0_f64; render.pixel_count()];
    group.bench_function("film", |b| b.iter(|| footprint.film_into(tris, &temps, ambient, &mask, &mut film)));
    group.finish();
}

criterion_group!(benches, bench_render);
criterion_main!(benches);
