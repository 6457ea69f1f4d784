//! The expected contribution of temperature noise to the data term's Gram matrices (errors in
//! variables), removed so that the data energy estimates the noise-free one.
//!
//! **Model.** The rises of every vertex carry noise `n_i ∈ R^F` (F frames) with the
//! same temporal covariance `Σ` (K^2) for every vertex and independent between vertices
//! (pixels, or disjoint block averages at coarser levels). One row of vertex i at frame pair k
//! is `[g_1 … g_p, y]` with `g_j = e_k^T(θ_j - θ_i)` and
//! `y = f_k^Tθ_i + …`, where `e_k` is the time rule's mix of frames k and k+1
//! (`w δ_(k+1) + (1-w) δ_k`) and `f_k = (δ_(k+1) - δ_k)/Δ t_k +
//! λ e_k`; with the profiled flux both are centred over the pairs. Summed over the pairs,
//! `E δ g_j δ g_l = S_ee(1 + δ_jl),
//!    E δ g_j δ y = -S_ef, E δ y^2 = S_ff,`
//! with `S_ab = Σ_k a_k^T Σ b_k`; the profiled-globals column `bar(θ)_i` adds
//! `E δ bar(θ) δ g_j = -S_ee`, `E δ bar(θ) δ y =
//! S_ef`, `E δ bar(θ)^2 = S_ee`. The radiation remainder's noise (its
//! derivative is below 1 % of lambda for rises of a few K) is neglected.
//!
//! **Covariance.** For white noise of std sigma, with the fixed pattern removed as the mean of
//! the P frames at ambient and the video then projected on a temporal basis `V_r` (low-rank
//! denoising), `Σ = σ^2 V_r V_r^T (I - A)(I - A)^T V_r V_r^T`, `A` the averaging
//! over the ambient frames ([`temporal_covariance`]). The basis is estimated from the data,
//! mostly the signal; its dependence on the noise is neglected.

use crate::error::ReconError;

/// The three sums of the module doc for one video (K^2, K^2/s, K^2/s^2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RowNoise {
    /// `S_ee`, K^2.
    pub s_ee: f64,
    /// `S_ef`, K^2/s.
    pub s_ef: f64,
    /// `S_ff`, K^2/s^2.
    pub s_ff: f64,
}

impl RowNoise {
    /// From the noise covariance `cov` (K^2, row-major F x F), the frame `times` (s), the
    /// frame `pairs` used (by first frame), the time weight `w` of frame k+1, `lambda` (1/s),
    /// and whether the rows are centred over the pairs (profiled flux).
    ///
    /// # Errors
    /// A covariance whose size is not F x F.
    pub fn new(
        cov: &[f64],
        times: &[f64],
        pairs: &[usize],
        w: f64,
        lambda: f64,
        centred: bool,
    ) -> Result<RowNoise, ReconError> {
        let nf = times.len();
        if cov.len() != nf * nf {
            return Err(ReconError::Input(format!(
                "stage 2: noise covariance of {} values for {nf} frames ({} expected)",
                cov.len(),
                nf * nf
            )));
        }
        // The functionals e_k and f_k as dense frame vectors.
        let functionals: Vec<(Vec<f64>, Vec<f64>)> = pairs
            .iter()
            .map(|&k| {
                let dt = times[k + 1] - times[k];
                let (mut e, mut f) = (vec![0.0; nf], vec![0.0; nf]);
                e[k + 1] = w;
                e[k] = 1.0 - w;
                f[k + 1] = 1.0 / dt + lambda * w;
                f[k] = -1.0 / dt + lambda * (1.0 - w);
                (e, f)
            })
            .collect();
        let n = functionals.len().max(1) as f64;
        let (mut e_mean, mut f_mean) = (vec![0.0; nf], vec![0.0; nf]);
        if centred {
            for (e, f) in &functionals {
                e_mean.iter_mut().zip(e).for_each(|(m, x)| *m += x / n);
                f_mean.iter_mut().zip(f).for_each(|(m, x)| *m += x / n);
            }
        }
        let quad = |a: &[f64], b: &[f64]| -> f64 {
            let mut s = 0.0;
            for (r, &ar) in a.iter().enumerate() {
                if ar != 0.0 {
                    s += ar * cov[r * nf..(r + 1) * nf].iter().zip(b).map(|(c, x)| c * x).sum::<f64>();
                }
            }
            s
        };
        let (mut s_ee, mut s_ef, mut s_ff) = (0.0, 0.0, 0.0);
        for (e, f) in &functionals {
            let e: Vec<f64> = e.iter().zip(&e_mean).map(|(x, m)| x - m).collect();
            let f: Vec<f64> = f.iter().zip(&f_mean).map(|(x, m)| x - m).collect();
            s_ee += quad(&e, &e);
            s_ef += quad(&e, &f);
            s_ff += quad(&f, &f);
        }
        Ok(RowNoise { s_ee, s_ef, s_ff })
    }

    /// Subtracts the expected noise outer product from the Gram matrix `g` (row-major, m x m
    /// with m = p + 1 + extra) of a vertex with `p` neighbours; `extra` is 0 or 2 (the
    /// profiled-globals columns theta and N(theta), in that order).
    pub fn subtract_from(&self, g: &mut [f64], p: usize, extra: usize) {
        let m = p + 1 + extra;
        debug_assert_eq!(g.len(), m * m, "Gram size (a bug)");
        for r in 0..p {
            for c in 0..p {
                g[r * m + c] -= self.s_ee * if r == c { 2.0 } else { 1.0 };
            }
            g[r * m + p] += self.s_ef;
            g[p * m + r] += self.s_ef;
        }
        g[p * m + p] -= self.s_ff;
        if extra == 2 {
            let t = p + 1;
            for r in 0..p {
                g[r * m + t] += self.s_ee;
                g[t * m + r] += self.s_ee;
            }
            g[t * m + t] -= self.s_ee;
            g[t * m + p] -= self.s_ef;
            g[p * m + t] -= self.s_ef;
        }
    }
}

/// The temporal noise covariance (K^2, row-major F x F) of rises with white noise of std `sigma`
/// (K) per frame, the fixed pattern removed as the mean of the frames at `times <= 0`, and,
/// when `basis` is given (orthonormal frame vectors of the low-rank denoiser), projected on its
/// span (module doc).
pub fn temporal_covariance(times: &[f64], sigma: f64, basis: Option<&[Vec<f64>]>) -> Vec<f64> {
    let nf = times.len();
    let pre: Vec<bool> = times.iter().map(|&t| t <= 1e-9).collect();
    let np = pre.iter().filter(|&&b| b).count();
    let s2 = sigma * sigma;
    // Cov(n_k - a, n_l - a), a the mean over the ambient frames (none: no offset removed).
    let mut cov = vec![0.0; nf * nf];
    for k in 0..nf {
        for l in 0..nf {
            let mut c = if k == l { 1.0 } else { 0.0 };
            if np > 0 {
                let q = 1.0 / np as f64;
                c += q - if pre[k] { q } else { 0.0 } - if pre[l] { q } else { 0.0 };
            }
            cov[k * nf + l] = s2 * c;
        }
    }
    let Some(basis) = basis else {
        return cov;
    };
    // P cov P with P = V V^T: B = V^T cov V (r x r), then V B V^T.
    let r = basis.len();
    let mut cv = vec![0.0; nf * r]; // cov V
    for k in 0..nf {
        for (b, v) in basis.iter().enumerate() {
            cv[k * r + b] = (0..nf).map(|l| cov[k * nf + l] * v[l]).sum();
        }
    }
    let mut small = vec![0.0; r * r];
    for (a, va) in basis.iter().enumerate() {
        for b in 0..r {
            small[a * r + b] = (0..nf).map(|k| va[k] * cv[k * r + b]).sum();
        }
    }
    let mut out = vec![0.0; nf * nf];
    for k in 0..nf {
        for l in 0..nf {
            let mut s = 0.0;
            for a in 0..r {
                for b in 0..r {
                    s += basis[a][k] * small[a * r + b] * basis[b][l];
                }
            }
            out[k * nf + l] = s;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sums against the exact second moments of the rows as they are built (fixed pattern
    /// removed from each vertex's raw white noise, time mix, centring over the pairs): the rows
    /// are linear in the raw noise, so probing them with unit vectors gives their coefficients
    /// c, and E[r_a r_b] = sigma^2 sum_k c_a,k . c_b,k.
    #[test]
    fn row_noise_matches_the_rows_second_moments() {
        let times: Vec<f64> = (0..14).map(|k| (k as f64 - 3.0) * 0.5).collect();
        let pairs: Vec<usize> = (3..13).collect();
        let (sigma, w, lambda) = (0.05, 0.5, 0.01);
        let nf = times.len();
        let cov = temporal_covariance(&times, sigma, None);
        let rn = RowNoise::new(&cov, &times, &pairs, w, lambda, true).unwrap();
        // Rows [g_1, g_2, y, theta_i] per pair from the raw noise of vertex i and two neighbours.
        let rows = |raw: &[f64]| -> Vec<[f64; 4]> {
            let rise = |v: usize| -> Vec<f64> {
                let n = &raw[v * nf..(v + 1) * nf];
                let a = n[..3].iter().sum::<f64>() / 3.0; // the three frames at t <= 0
                n.iter().map(|x| x - a).collect()
            };
            let (ni, n1, n2) = (rise(0), rise(1), rise(2));
            let mix = |n: &[f64], k: usize| w * n[k + 1] + (1.0 - w) * n[k];
            let r: Vec<[f64; 4]> = pairs
                .iter()
                .map(|&k| {
                    let dt = times[k + 1] - times[k];
                    [
                        mix(&n1, k) - mix(&ni, k),
                        mix(&n2, k) - mix(&ni, k),
                        (ni[k + 1] - ni[k]) / dt + lambda * mix(&ni, k),
                        mix(&ni, k),
                    ]
                })
                .collect();
            let mean: Vec<f64> = (0..4).map(|c| r.iter().map(|x| x[c]).sum::<f64>() / r.len() as f64).collect();
            r.iter().map(|x| [x[0] - mean[0], x[1] - mean[1], x[2] - mean[2], x[3] - mean[3]]).collect()
        };
        let probes: Vec<Vec<[f64; 4]>> = (0..3 * nf)
            .map(|c| {
                let mut raw = vec![0.0; 3 * nf];
                raw[c] = 1.0;
                rows(&raw)
            })
            .collect();
        let moment = |a: usize, b: usize| -> f64 {
            sigma * sigma * probes.iter().map(|p| p.iter().map(|r| r[a] * r[b]).sum::<f64>()).sum::<f64>()
        };
        let close = |x: f64, exact: f64| (x - exact).abs() <= 1e-12 * exact.abs().max(1e-30);
        assert!(close(moment(0, 0), 2.0 * rn.s_ee), "g_j^2: {} vs {}", moment(0, 0), 2.0 * rn.s_ee);
        assert!(close(moment(0, 1), rn.s_ee), "g_1 g_2: {} vs {}", moment(0, 1), rn.s_ee);
        assert!(close(moment(0, 2), -rn.s_ef), "g y: {} vs {}", moment(0, 2), -rn.s_ef);
        assert!(close(moment(2, 2), rn.s_ff), "y^2: {} vs {}", moment(2, 2), rn.s_ff);
        assert!(close(moment(3, 0), -rn.s_ee), "theta g: {} vs {}", moment(3, 0), -rn.s_ee);
        assert!(close(moment(3, 2), rn.s_ef), "theta y: {} vs {}", moment(3, 2), rn.s_ef);
        assert!(close(moment(3, 3), rn.s_ee), "theta^2: {} vs {}", moment(3, 3), rn.s_ee);
        // And subtract_from removes exactly these from a Gram matrix [g_1 g_2 y theta N].
        let mut g = vec![0.0; 25];
        for a in 0..4 {
            for b in 0..4 {
                let (ra, rb) = ([0, 1, 2, 3][a], [0, 1, 2, 3][b]);
                g[ra * 5 + rb] = moment(a, b);
            }
        }
        rn.subtract_from(&mut g, 2, 2);
        assert!(g.iter().all(|x| x.abs() < 1e-12 * rn.s_ff), "left over: {g:?}");
    }

    /// Projection on the full frame space leaves the covariance unchanged; on a subspace it
    /// is idempotent and its trace is sigma^2 times the rank (no fixed pattern removed).
    #[test]
    fn projected_covariance() {
        let times: Vec<f64> = (1..9).map(|k| k as f64).collect();
        let nf = times.len();
        let id: Vec<Vec<f64>> = (0..nf).map(|k| (0..nf).map(|l| if k == l { 1.0 } else { 0.0 }).collect()).collect();
        let full = temporal_covariance(&times, 0.1, None);
        let proj = temporal_covariance(&times, 0.1, Some(&id));
        assert!(full.iter().zip(&proj).all(|(a, b)| (a - b).abs() < 1e-15));
        let s = 1.0 / 2f64.sqrt();
        let mut v1 = vec![0.0; nf];
        v1[0] = s;
        v1[1] = s;
        let mut v2 = vec![0.0; nf];
        v2[5] = 1.0;
        let p = temporal_covariance(&times, 0.1, Some(&[v1, v2]));
        let trace: f64 = (0..nf).map(|k| p[k * nf + k]).sum();
        assert!((trace - 2.0 * 0.01).abs() < 1e-15, "trace {trace}");
    }
}
