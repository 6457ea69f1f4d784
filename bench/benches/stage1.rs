//! Stage 1 time against pixels and frames (issue 7's performance target: a 160 x 128 mask, two
//! videos of 90 frames, within 5 s on 2 cores, growing linearly).
//!
//! Input: a fully masked W x H pixel grid on a 10 cm dome, two videos (lamp left, right)
//! simulated by `heatrecon::stage1::synthetic` (1 mm PLA-like shell, 0.5 s frames) plus 5 mK
//! of white noise, with 10 frames before the lamps switch on (setup, not timed),
//! timed through the whole of stage 1 as `simbench reconstruct` runs it: low-rank denoising and
//! the estimate (with the options `simbench reconstruct` picks for the estimated noise,
//! `Stage1Options::for_noise`).
//!
//! `cargo bench -p simbench --bench stage1`

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use heatrecon::stage1::synthetic::{simulate, SyntheticModel};
use heatrecon::stage1::{denoise, estimate, Stage1Input, Stage1Options};
use heatsim::camera::PixelGrid;
use rand::{Rng, SeedableRng};

fn input(w: usize, h: usize, frames: usize) -> Stage1Input {
    let grid = PixelGrid::new(&vec![true; w * h], w, h);
    // A 10 cm wide dome z = 0.3 - 0.03 (1 - r^2/r0^2) m under a 1 mm PLA-like shell.
    let pitch = 0.1 / w as f64;
    let verts: Vec<[f64; 3]> = (0..grid.vertex_count())
        .map(|k| {
            let (u, v) = grid.pixel_uv(k);
            let (x, y) = ((u as f64 - w as f64 / 2.0) * pitch, (v as f64 - h as f64 / 2.0) * pitch);
            [x, y, 0.3 - 0.03 * (1.0 - (x * x + y * y) / 0.0025)]
        })
        .collect();
    let model = SyntheticModel {
        heat_capacity: 1950.0,
        conductance: 0.13 * 0.001,
        convection: 5.0,
        emissivity: 0.9,
        ambient: 295.0,
        full_radiation: true,
    };
    let dt = 0.5;
    let pre = 10;
    let times: Vec<f64> = (0..frames + pre).map(|k| (k as f64 - pre as f64) * dt).collect();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let series = [-1.0, 1.0]
        .iter()
        .map(|&side| {
            let flux: Vec<f64> = verts.iter().map(|p| 200.0 * (1.0 + 0.5 * side * p[0] / 0.05).max(0.0)).collect();
            let rise = simulate(&model, &verts, &grid.tris, &flux, frames, dt, 1);
            let mut s = Vec::with_capacity(verts.len() * times.len());
            for i in 0..verts.len() {
                for k in 0..times.len() {
                    let clean = if k < pre { 0.0 } else { rise[i * frames + k - pre] };
                    s.push(clean + 0.005 * (rng.random::<f64>() - 0.5) * 12f64.sqrt());
                }
            }
            s
        })
        .collect();
    Stage1Input { grid, series, times, ambient: 295.0, emissivity: 0.9 }
}

fn stage1(inp: &Stage1Input) {
    let mut inp = inp.clone();
    let sigma = denoise::noise_sigma(&inp).expect("pre-heating frames");
    denoise::low_rank(&mut inp, sigma, "bench");
    let r = estimate(&inp, &Stage1Options::for_noise(Some(sigma), 0)).expect("stage 1");
    std::hint::black_box(r);
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("stage1");
    g.sample_size(10);
    for (w, h) in [(40, 32), (80, 64), (160, 128)] {
        let inp = input(w, h, 90);
        g.bench_with_input(BenchmarkId::new("pixels_90_frames", w * h), &inp, |b, i| b.iter(|| stage1(i)));
    }
    for frames in [30, 60] {
        let inp = input(160, 128, frames);
        g.bench_with_input(BenchmarkId::new("frames_160x128", frames), &inp, |b, i| b.iter(|| stage1(i)));
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
