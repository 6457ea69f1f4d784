//! Temporal low-rank denoising of the videos before stage 1 (a direct, non-iterative stand-in
//! for the paper's jointly denoised temperatures of Eq. 8).
//!
//! **Why.** The Laplacian enters Eq. 7 through second differences of the temperature between
//! neighbouring pixels, of order `h^2 ∂^2θ` (`h` the pixel footprint): for a few
//! kelvin varying over centimetres at 0.25 mm pixels, about 1e-3 K, far below a 50 mK NETD.
//! Noise in a regressor also biases least squares towards zero (errors in variables), so the
//! temperatures must be denoised first.
//!
//! **Method.** Per video, the rises form the matrix `X` (vertices x frames). Heat conduction
//! with lamps that switch on once makes every pixel's time series a combination of a few
//! smooth profiles, so the signal is (numerically) of low rank, while white noise of standard
//! deviation `σ` spreads over all singular values, the largest being about
//! `σ(sqrt(n) + sqrt(m))` (`n` vertices, `m` frames; the edge of the Marchenko–Pastur
//! law). The denoised video is the truncated SVD `X V_r V_r^T` keeping the singular values above
//! `τ = σ(sqrt(n) + sqrt(m))` (computed from the `m × m` Gram matrix `X^T X`, whose
//! eigenvectors are `V`). Each kept profile keeps its share of noise: the per-pixel noise drops
//! from `σ` to about `σsqrt(r/m)`.
//!
//! **Noise level.** `σ` is the NETD in kelvin of true temperature: either given, or
//! estimated from the frames before the lamps switch on (`t ≤ 0`, where the rise is zero up
//! to noise) as the pooled standard deviation over time of every vertex ([`noise_sigma`]).

use rayon::prelude::*;

use super::Stage1Input;

/// What the denoiser did.
#[derive(Clone, Debug, serde::Serialize)]
pub struct DenoiseReport {
    /// Noise standard deviation used, K.
    pub sigma: f64,
    /// Where σ came from.
    pub sigma_source: String,
    /// Per video: the rank kept.
    pub ranks: Vec<usize>,
    /// Per video: the threshold τ on singular values (K, Frobenius units).
    pub thresholds: Vec<f64>,
    /// Per video: the leading singular values (up to 12), K.
    pub singular_values: Vec<Vec<f64>>,
    /// Per video: the kept temporal basis (orthonormal frame vectors, `ranks[v]` of them), the
    /// span the series were projected on (for the noise left in them,
    /// `crate::stage2::noise::temporal_covariance`).
    #[serde(skip)]
    pub basis: Vec<Vec<Vec<f64>>>,
}

/// Pooled temporal standard deviation (K) of the rises over the frames at `t <= 0`, or `None`
/// with fewer than two such frames.
pub fn noise_sigma(input: &Stage1Input) -> Option<f64> {
    let pre: Vec<usize> = (0..input.frames()).filter(|&k| input.times[k] <= 1e-12).collect();
    if pre.len() < 2 {
        return None;
    }
    let (nv, frames) = (input.grid.vertex_count(), input.frames());
    let mut ss = 0.0;
    let mut dof = 0usize;
    for s in &input.series {
        ss += (0..nv)
            .into_par_iter()
            .map(|i| {
                let mean = pre.iter().map(|&k| s[i * frames + k]).sum::<f64>() / pre.len() as f64;
                pre.iter().map(|&k| (s[i * frames + k] - mean).powi(2)).sum::<f64>()
            })
            .collect::<Vec<f64>>()
            .iter()
            .sum::<f64>(); // summed in order: the same bits on every run
        dof += nv * (pre.len() - 1);
    }
    Some((ss / dof.max(1) as f64).sqrt())
}

/// Replaces every video of `input` by its truncated SVD at the threshold for noise `sigma`
/// (K; module doc). `sigma_source` is recorded in the report.
pub fn low_rank(input: &mut Stage1Input, sigma: f64, sigma_source: &str) -> DenoiseReport {
    low_rank_at_least(input, sigma, sigma_source, 0)
}

/// [`low_rank`] keeping at least `min_rank` profiles per video (those above float round-off).
pub fn low_rank_at_least(input: &mut Stage1Input, sigma: f64, sigma_source: &str, min_rank: usize) -> DenoiseReport {
    let (nv, m) = (input.grid.vertex_count(), input.frames());
    let tau = sigma * ((nv as f64).sqrt() + (m as f64).sqrt());
    let mut ranks = Vec::new();
    let mut thresholds = Vec::new();
    let mut singular_values = Vec::new();
    let mut bases = Vec::new();
    for s in &mut input.series {
        // Gram X^T X (m x m), accumulated over chunks of vertices.
        let gram = s
            .par_chunks(m * 256)
            .map(|chunk| {
                let mut g = vec![0.0; m * m];
                for row in chunk.chunks(m) {
                    for a in 0..m {
                        let ra = row[a];
                        if ra != 0.0 {
                            for b in a..m {
                                g[a * m + b] += ra * row[b];
                            }
                        }
                    }
                }
                g
            })
            .collect::<Vec<Vec<f64>>>()
            .into_iter()
            // Chunks summed in order (rayon's reduce tree depends on scheduling): the same bits
            // on every run.
            .fold(vec![0.0; m * m], |mut x, y| {
                x.iter_mut().zip(&y).for_each(|(a, b)| *a += b);
                x
            });
        let a = faer::Mat::<f64>::from_fn(m, m, |i, j| if i <= j { gram[i * m + j] } else { gram[j * m + i] });
        // Sequential: faer's parallel eigenvectors change their bits with the thread count.
        let Ok((u, ev)) = crate::faer_seq::self_adjoint_eigen(a.as_ref()) else {
            ranks.push(m);
            thresholds.push(tau);
            singular_values.push(vec![]);
            bases.push((0..m).map(|k| (0..m).map(|f| if f == k { 1.0 } else { 0.0 }).collect()).collect());
            continue;
        };
        let ev = ev.column_vector();
        let mut order: Vec<usize> = (0..m).collect();
        order.sort_by(|&i, &j| ev[j].total_cmp(&ev[i]));
        let sv: Vec<f64> = order.iter().map(|&k| ev[k].max(0.0).sqrt()).collect();
        // Keep singular values above tau; never below float round-off of the largest.
        let floor = sv.first().copied().unwrap_or(0.0) * 1e-7;
        let kept: Vec<usize> = order
            .iter()
            .zip(&sv)
            .enumerate()
            .filter(|(i, (_, &x))| x > floor && (x > tau || *i < min_rank))
            .map(|(_, (&k, _))| k)
            .collect();
        let r = kept.len();
        let basis: Vec<Vec<f64>> = kept.iter().map(|&k| (0..m).map(|f| u[(f, k)]).collect()).collect();
        s.par_chunks_mut(m).for_each(|row| {
            let coef: Vec<f64> = basis.iter().map(|v| v.iter().zip(row.iter()).map(|(a, b)| a * b).sum()).collect();
            for (f, x) in row.iter_mut().enumerate() {
                *x = basis.iter().zip(&coef).map(|(v, c)| v[f] * c).sum();
            }
        });
        ranks.push(r);
        thresholds.push(tau);
        singular_values.push(sv.iter().take(12).copied().collect());
        bases.push(basis);
    }
    DenoiseReport { sigma, sigma_source: sigma_source.to_string(), ranks, thresholds, singular_values, basis: bases }
}

#[cfg(test)]
mod tests {
    use super::*;
    use heatsim::camera::PixelGrid;

    /// Rises of two smooth temporal shapes varying over a 12 x 10 image, plus white noise of
    /// `sigma` (a hash of the index, uniform with that standard deviation).
    fn two_profiles(sigma: f64) -> Stage1Input {
        let (w, h, frames) = (12, 10, 60);
        let grid = PixelGrid::new(&vec![true; w * h], w, h);
        let nv = grid.vertex_count();
        let times: Vec<f64> = (0..frames).map(|k| k as f64 * 0.5 - 5.0).collect();
        // splitmix64 of the index.
        let noise = |j: u64| {
            let mut x = j.wrapping_add(0x9e37_79b9_7f4a_7c15);
            x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            x ^= x >> 31;
            ((x >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * sigma * 12f64.sqrt()
        };
        let series = (0..nv)
            .flat_map(|i| {
                let (a, b) = (1.0 + i as f64 / nv as f64, (i % w) as f64 / w as f64);
                let times = times.clone();
                (0..frames).map(move |k| {
                    let s = times[k].max(0.0);
                    a * (1.0 - (-s / 20.0).exp()) + b * s / 60.0 + noise((i * frames + k) as u64)
                })
            })
            .collect();
        Stage1Input { grid, series: vec![series], times, ambient: 295.15, emissivity: 0.95 }
    }

    /// The threshold keeps the two profiles above the noise; a floor keeps more, and a floor at
    /// or below the threshold's rank changes nothing (the same bits as `low_rank`).
    #[test]
    fn min_rank_is_a_floor_on_the_threshold_rank() {
        let input = two_profiles(0.01);
        let mut plain = input.clone();
        assert_eq!(low_rank(&mut plain, 0.01, "test").ranks, [2]);
        for floor in [0, 1, 2] {
            let mut x = input.clone();
            assert_eq!(low_rank_at_least(&mut x, 0.01, "test", floor).ranks, [2], "floor {floor}");
            assert_eq!(x.series, plain.series, "floor {floor}");
        }
        let mut x = input.clone();
        let rep = low_rank_at_least(&mut x, 0.01, "test", 4);
        assert_eq!((rep.ranks[0], rep.basis[0].len()), (4, 4));
        // Two profiles more of the noise: closer to the raw series than the threshold's rank.
        let dist = |a: &[f64]| a.iter().zip(&input.series[0]).map(|(p, q)| (p - q).powi(2)).sum::<f64>();
        assert!(dist(&x.series[0]) < dist(&plain.series[0]));
    }
}
