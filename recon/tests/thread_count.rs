//! The same bits at any thread count (issue 28, item 6): the two faer factorisations of the
//! reconstruction (stage 1's low-rank denoising, stage 2's large-steps Cholesky) run inside
//! rayon pools of 1, 2 and 3 threads. End to end (`simbench reconstruct` and `eval` under
//! `RAYON_NUM_THREADS`): bench/tests/cli.rs, `reconstruction_is_the_same_at_any_thread_count`.

use heatrecon::stage1::denoise::low_rank;
use heatrecon::stage1::Stage1Input;
use heatrecon::stage2::optimize::LargeSteps;
use heatsim::camera::PixelGrid;

/// `f()` in a rayon pool of 1, 2 and 3 threads; panics unless the three results have the same bits.
fn same_at_any_thread_count(what: &str, f: impl Fn() -> Vec<f64> + Sync) {
    let run = |n: usize| rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap().install(&f);
    let one = run(1);
    for n in [2, 3] {
        let other = run(n);
        assert_eq!(one.len(), other.len());
        let differ = one.iter().zip(&other).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
        let max = one.iter().zip(&other).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert_eq!(
            differ,
            0,
            "{what}: {differ} of {} values differ between 1 and {n} threads (max {max:e})",
            one.len()
        );
    }
}

/// A deterministic pseudo-random number in [-0.5, 0.5) (SplitMix64 of `i`).
fn noise(i: u64) -> f64 {
    let mut z = i.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    (z ^ (z >> 31)) as f64 / 2f64.powi(64) - 0.5
}

/// Large-steps solve on a 300 x 300 grid: big enough for faer's supernodal Cholesky to run its
/// dense updates through the parallel matrix product (1633 of 90 000 entries differed between
/// 1 and 2 threads with faer's default parallelism).
#[test]
fn large_steps_solve_is_the_same_at_any_thread_count() {
    let side = 300;
    let at = |i: usize, j: usize| i * side + j;
    let mut edges = Vec::new();
    for i in 0..side {
        for j in 0..side {
            if i + 1 < side {
                edges.push([at(i, j), at(i + 1, j)]);
            }
            if j + 1 < side {
                edges.push([at(i, j), at(i, j + 1)]);
            }
            if i + 1 < side && j + 1 < side {
                edges.push([at(i, j), at(i + 1, j + 1)]);
            }
        }
    }
    let n = side * side;
    let b: Vec<f64> = (0..n as u64).map(noise).collect();
    same_at_any_thread_count("large-steps solve", || {
        let steps = LargeSteps::new(n, &edges, 30.0).unwrap();
        let mut x = b.clone();
        steps.solve(&mut x);
        x
    });
}

/// Low-rank denoising of 120 frames (a 120 x 120 Gram matrix; the 45 s, 2 fps datasets have
/// 100): with faer's default parallelism 2837 of the 57 600 denoised values differed between 1
/// and 2 threads.
#[test]
fn low_rank_denoising_is_the_same_at_any_thread_count() {
    let (w, h, frames) = (24, 20, 120);
    let grid = PixelGrid::new(&vec![true; w * h], w, h);
    let nv = grid.vertex_count();
    let times: Vec<f64> = (0..frames).map(|k| k as f64 * 0.5 - 5.0).collect();
    // Rises of a few smooth temporal shapes, varying over the image, plus 50 mK of noise.
    let series: Vec<f64> = (0..nv)
        .flat_map(|i| {
            let (u, v) = (i as f64 / nv as f64, (i % w) as f64 / w as f64);
            times.iter().enumerate().map(move |(k, &t)| {
                let s = t.max(0.0);
                (1.0 + u) * (1.0 - (-s / 20.0).exp()) + v * s / 60.0 + 0.1 * noise((i * frames + k) as u64)
            })
        })
        .collect();
    let input = Stage1Input { grid, series: vec![series], times, ambient: 295.15, emissivity: 0.95 };
    same_at_any_thread_count("low-rank denoising", || {
        let mut x = input.clone();
        low_rank(&mut x, 0.05, "test");
        x.series.concat()
    });
}
