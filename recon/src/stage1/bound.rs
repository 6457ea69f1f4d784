//! Cramér–Rao bound on stage 1's globals: how well any unbiased estimator can determine
//! `λ = (h + R)/C`, `C` and `h` from videos with white temperature noise, given the
//! noise-free rises (simulated data: `video_clean.npy`).
//!
//! **Model.** Per vertex `i` and video `v` the rise `θ` (K) of stage 1's heat equation,
//! `dot(θ) = Σ_g a_g G_g(t) + b_v - λθ - c N(θ), θ(t_0) = 0,`
//! with `c = 1/C` (m^2 K/J), `N` the radiation beyond Eq. 5 (W/m^2, [`super::radiation_remainder`]),
//! `b_v = q_v/C` (K/s) and `G_g = Σ_(j ∈ g) (θ_j - θ_i)` the neighbour differences of
//! the vertex's weight groups ([`super::weight_groups`]), taken from the noise-free video as known
//! inputs. The observations are `θ(t_k)` plus white noise of standard deviation `σ` (K) at
//! the frames from the lamps' switch-on (`t_0`, the first frame at `t ≥ 0`) on.
//!
//! **Sensitivities** `s_p = ∂θ/∂ p` obey
//! `dot(s)_p = -(λ + c N'(θ)) s_p + ∂ f/∂ p`, `s_p(t_0) = 0`, with
//! `∂ f/∂ b_v = 1` (video v only), `∂ f/∂ a_g = G_g`,
//! `∂ f/∂ λ = -θ`, `∂ f/∂ c = -N(θ)`, integrated by the
//! trapezoid rule over the frame intervals along the noise-free `θ` (the exact derivative of
//! the trapezoid model, finite-difference checked in the tests).
//!
//! **Bound.** The Fisher information of vertex i is `S_i^T S_i / σ^2` over the columns
//! above (rows: the frames of all videos). Its per-vertex unknowns (the fluxes, and the row
//! weights unless the rows are known) are removed by projecting the globals' columns on the
//! orthogonal complement of their span (the Schur complement, valid for a rank-deficient
//! nuisance block), the 2 x 2 informations are summed over vertices and inverted:
//! `cov(λ, c) ⪰ J^-1`. Then `C = 1/c` and `h = λ/c - R` by first-order
//! propagation.
//!
//! **What it neglects, and in which direction.** (1) The neighbours' temperatures are known
//! noise-free inputs, so conduction does not carry a change of c from vertex to vertex, and the
//! vertices' informations add: an approximation (neighbours respond alike to c, so the carried
//! part is of second order), which also hands each vertex its neighbours' noise-free rises. (2)
//! The noise is white on the rise; the estimator's rise also carries the pre-heating mean's error
//! in every frame (more noise, a looser bound). (3) Known rows assume the true operator, i.e. the
//! true shape. (2) and (3), and (1)'s noise-free neighbours, make the problem easier than stage
//! 1's, so the bound is optimistic: up to (1)'s second-order coupling, an unbiased estimator
//! cannot beat it, and a target well below it cannot be met on such data.

use rayon::prelude::*;

use super::{radiation_remainder, SIGMA};

/// The standard deviations the bound allows, relative where stated.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct GlobalsBound {
    /// sigma(lambda) / lambda.
    pub lambda_rel_std: f64,
    /// sigma(C) / C, equal to sigma(c) / c to first order.
    pub heat_capacity_rel_std: f64,
    /// sigma(h), W/(m^2 K).
    pub convection_std: f64,
    /// Vertices that contributed information.
    pub vertices: usize,
    /// Frames per video used (from the switch-on).
    pub frames: usize,
}

/// The true parameters the bound linearises about.
#[derive(Clone, Copy, Debug)]
pub struct BoundModel {
    /// lambda = (h + R)/C, 1/s.
    pub lambda: f64,
    /// c = 1/C, m^2 K/J.
    pub c: f64,
    /// Ambient temperature T_s, K.
    pub ambient: f64,
    /// Emissivity.
    pub emissivity: f64,
    /// Temperature noise per frame and vertex, K.
    pub sigma: f64,
}

/// dN/dtheta of [`radiation_remainder`], W/(m^2 K).
fn radiation_remainder_slope(theta: f64, ts: f64, eps: f64) -> f64 {
    eps * SIGMA * theta * (12.0 * ts * ts + 12.0 * ts * theta + 4.0 * theta * theta)
}

/// Sensitivities of one vertex's rise in one video to each forcing column (module doc):
/// `theta[k]` the rise at `times[k]` (k = 0 the switch-on, theta 0), `forcing[p][k]` the partial
/// derivative of the right-hand side with respect to unknown p at frame k. Returns s_p(t_k).
pub(crate) fn sensitivities(theta: &[f64], times: &[f64], forcing: &[Vec<f64>], m: &BoundModel) -> Vec<Vec<f64>> {
    let a: Vec<f64> =
        theta.iter().map(|&th| m.lambda + m.c * radiation_remainder_slope(th, m.ambient, m.emissivity)).collect();
    forcing
        .iter()
        .map(|f| {
            let mut s = vec![0.0; theta.len()];
            for k in 1..theta.len() {
                let dt = times[k] - times[k - 1];
                s[k] =
                    (s[k - 1] * (1.0 - 0.5 * dt * a[k - 1]) + 0.5 * dt * (f[k - 1] + f[k])) / (1.0 + 0.5 * dt * a[k]);
            }
            s
        })
        .collect()
}

/// Removes from `targets` their projection on the span of `basis` (modified Gram–Schmidt,
/// twice; basis columns whose remainder is below 1e-12 of their norm are dependent and skipped).
fn project_out(basis: &[Vec<f64>], targets: &mut [Vec<f64>]) {
    let dot = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(a, b)| a * b).sum::<f64>();
    let mut q: Vec<Vec<f64>> = Vec::new();
    for col in basis {
        let n0 = dot(col, col).sqrt();
        let mut v = col.clone();
        for _ in 0..2 {
            for e in &q {
                let p = dot(&v, e);
                v.iter_mut().zip(e).for_each(|(x, y)| *x -= p * y);
            }
        }
        let n = dot(&v, &v).sqrt();
        if n > 1e-12 * n0 && n > 0.0 {
            v.iter_mut().for_each(|x| *x /= n);
            q.push(v);
        }
    }
    for t in targets.iter_mut() {
        for _ in 0..2 {
            for e in &q {
                let p = dot(t, e);
                t.iter_mut().zip(e).for_each(|(x, y)| *x -= p * y);
            }
        }
    }
}

/// The bound of the module doc. `series[v]` is video v's noise-free rise, layout
/// `[vertex * frames + frame]` (as [`super::Stage1Input::series`]) at `times` (s); `groups` the
/// weight groups per vertex (unknown rows) or `None` (rows known). Frames before the first at
/// `t >= 0` are left out. `None` without two frames from the switch-on or without information
/// on both globals.
pub fn globals_bound(
    series: &[Vec<f64>],
    times: &[f64],
    groups: Option<&[Vec<Vec<usize>>]>,
    m: &BoundModel,
) -> Option<GlobalsBound> {
    let frames = times.len();
    let k0 = times.iter().position(|&t| t >= -1e-12)?;
    let used = &times[k0..];
    if used.len() < 2 || series.is_empty() || frames == 0 {
        return None;
    }
    let nv = series[0].len() / frames;
    let nvid = series.len();
    let per_vertex: Vec<[f64; 3]> = (0..nv)
        .into_par_iter()
        .with_min_len(256)
        .map(|i| {
            let own = |v: usize| &series[v][i * frames + k0..(i + 1) * frames];
            let my_groups: &[Vec<usize>] = groups.map_or(&[], |g| &g[i]);
            // Columns over the stacked frames of all videos: fluxes, row weights, lambda, c.
            let rows = used.len() * nvid;
            let mut nuisance = vec![vec![0.0; rows]; nvid + my_groups.len()];
            let mut globals = vec![vec![0.0; rows]; 2];
            for v in 0..nvid {
                let th = own(v);
                let mut forcing = vec![vec![1.0; used.len()]];
                for g in my_groups {
                    forcing.push(
                        (0..used.len())
                            .map(|k| g.iter().map(|&j| series[v][j * frames + k0 + k] - th[k]).sum::<f64>())
                            .collect(),
                    );
                }
                forcing.push(th.iter().map(|&t| -t).collect());
                forcing.push(th.iter().map(|&t| -radiation_remainder(t, m.ambient, m.emissivity)).collect());
                let s = sensitivities(th, used, &forcing, m);
                let r = v * used.len()..(v + 1) * used.len();
                nuisance[v][r.clone()].copy_from_slice(&s[0]);
                for (g, sg) in s[1..=my_groups.len()].iter().enumerate() {
                    nuisance[nvid + g][r.clone()].copy_from_slice(sg);
                }
                globals[0][r.clone()].copy_from_slice(&s[my_groups.len() + 1]);
                globals[1][r].copy_from_slice(&s[my_groups.len() + 2]);
            }
            project_out(&nuisance, &mut globals);
            let dot = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(a, b)| a * b).sum::<f64>();
            [dot(&globals[0], &globals[0]), dot(&globals[0], &globals[1]), dot(&globals[1], &globals[1])]
        })
        .collect();
    // Summed in order: the same bits on every run.
    let s2 = m.sigma * m.sigma;
    let j = per_vertex.iter().fold([0.0; 3], |a, b| [a[0] + b[0], a[1] + b[1], a[2] + b[2]]).map(|x| x / s2);
    let det = j[0] * j[2] - j[1] * j[1];
    if det.is_nan() || det <= 0.0 {
        return None;
    }
    // Inverse of [[j0, j1], [j1, j2]].
    let (vl, vlc, vc) = (j[2] / det, -j[1] / det, j[0] / det);
    // h = lambda/c - R: dh/dlambda = 1/c, dh/dc = -lambda/c^2.
    let (gl, gc) = (1.0 / m.c, -m.lambda / (m.c * m.c));
    let vh = gl * gl * vl + 2.0 * gl * gc * vlc + gc * gc * vc;
    Some(GlobalsBound {
        lambda_rel_std: vl.sqrt() / m.lambda,
        heat_capacity_rel_std: vc.sqrt() / m.c,
        convection_std: vh.max(0.0).sqrt(),
        vertices: per_vertex.iter().filter(|p| p[0] > 0.0).count(),
        frames: used.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    const TS: f64 = 295.15;
    const EPS: f64 = 0.9;

    /// The trapezoid model of one vertex without neighbours: rise under flux `b` (K/s) and
    /// neighbour forcing `g` scaled by `a`, Newton on every step.
    fn simulate(times: &[f64], b: f64, a: f64, g: &[f64], lambda: f64, c: f64) -> Vec<f64> {
        let f = |th: f64, k: usize| a * g[k] + b - lambda * th - c * radiation_remainder(th, TS, EPS);
        let mut th = vec![0.0; times.len()];
        for k in 1..times.len() {
            let dt = times[k] - times[k - 1];
            let rhs = th[k - 1] + 0.5 * dt * f(th[k - 1], k - 1);
            let mut x = th[k - 1];
            for _ in 0..30 {
                let r = x - 0.5 * dt * f(x, k) - rhs;
                let dr = 1.0 + 0.5 * dt * (lambda + c * radiation_remainder_slope(x, TS, EPS));
                x -= r / dr;
            }
            th[k] = x;
        }
        th
    }

    fn frame_times(n: usize, dt: f64) -> Vec<f64> {
        (0..n).map(|k| k as f64 * dt).collect()
    }

    /// Sensitivities against central finite differences of the trapezoid model, for a flux, a
    /// neighbour weight, lambda and c (a 30 K rise, so the radiation term is far from linear).
    #[test]
    fn sensitivities_match_finite_differences() {
        let times = frame_times(91, 0.5);
        let g: Vec<f64> = times.iter().map(|t| 0.05 * (0.1 * t).sin()).collect();
        let (b, a, lambda, c) = (1.2, 0.3, 4e-3, 3e-4);
        let th = simulate(&times, b, a, &g, lambda, c);
        let m = BoundModel { lambda, c, ambient: TS, emissivity: EPS, sigma: 0.05 };
        let forcing = vec![
            vec![1.0; times.len()],
            g.clone(),
            th.iter().map(|t| -t).collect(),
            th.iter().map(|&t| -radiation_remainder(t, TS, EPS)).collect(),
        ];
        let s = sensitivities(&th, &times, &forcing, &m);
        let fd = |p: usize| -> Vec<f64> {
            let h = [1e-6 * b, 1e-6, 1e-6 * lambda, 1e-6 * c][p];
            let mut up = [b, a, lambda, c];
            let mut dn = up;
            up[p] += h;
            dn[p] -= h;
            let (tu, td) =
                (simulate(&times, up[0], up[1], &g, up[2], up[3]), simulate(&times, dn[0], dn[1], &g, dn[2], dn[3]));
            tu.iter().zip(&td).map(|(x, y)| (x - y) / (2.0 * h)).collect()
        };
        for (p, sp) in s.iter().enumerate() {
            let reference = fd(p);
            let scale = reference.iter().fold(0.0f64, |x, y| x.max(y.abs()));
            let err = sp.iter().zip(&reference).fold(0.0f64, |x, (a, b)| x.max((a - b).abs())) / scale;
            assert!(err < 1e-6, "unknown {p}: relative error {err:e}");
        }
    }

    /// Monte Carlo: three vertices, two videos, known rows; the least-squares fit of the fluxes,
    /// lambda and c to noisy trapezoid-model data (Gauss–Newton from the truth) has the spread
    /// the bound gives (efficient in this small-noise regime), to within sampling error.
    #[test]
    fn bound_matches_the_spread_of_a_least_squares_fit() {
        let times = frame_times(61, 0.5);
        let (lambda, c) = (4e-3, 3e-4);
        let fluxes = [[1.0, 0.4], [0.7, 1.1], [0.2, 0.9]];
        let zero = vec![0.0; times.len()];
        let clean: Vec<Vec<Vec<f64>>> =
            (0..2).map(|v| fluxes.iter().map(|f| simulate(&times, f[v], 0.0, &zero, lambda, c)).collect()).collect();
        let series: Vec<Vec<f64>> = clean.iter().map(|vid| vid.concat()).collect();
        let sigma = 2e-4;
        let m = BoundModel { lambda, c, ambient: TS, emissivity: EPS, sigma };
        let bound = globals_bound(&series, &times, None, &m).expect("informative");
        // Parameters: 6 fluxes, lambda, c; residuals over 2 x 3 trajectories.
        let predict = |p: &[f64]| -> Vec<f64> {
            let mut out = Vec::new();
            for v in 0..2 {
                for i in 0..3 {
                    out.extend(simulate(&times, p[2 * i + v], 0.0, &zero, p[6], p[7]));
                }
            }
            out
        };
        let truth: Vec<f64> = fluxes.iter().flatten().copied().chain([lambda, c]).collect();
        let y0 = predict(&truth);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let noise = Normal::new(0.0, sigma).expect("positive sigma");
        let runs = 600;
        let (mut lams, mut cs) = (Vec::new(), Vec::new());
        for _ in 0..runs {
            let y: Vec<f64> = y0.iter().map(|v| v + noise.sample(&mut rng)).collect();
            let mut p = truth.clone();
            for _ in 0..4 {
                let r0: Vec<f64> = predict(&p).iter().zip(&y).map(|(a, b)| a - b).collect();
                // Columns per relative change of each parameter (comparable scales).
                let cols: Vec<Vec<f64>> = (0..8)
                    .map(|q| {
                        let h = 1e-6 * truth[q];
                        let mut pq = p.clone();
                        pq[q] += h;
                        predict(&pq).iter().zip(&y).zip(&r0).map(|((a, b), r)| (a - b - r) / 1e-6).collect()
                    })
                    .collect();
                let mut jtj = vec![0.0; 64];
                let mut jtr = vec![0.0; 8];
                for a in 0..8 {
                    for b in 0..8 {
                        jtj[a * 8 + b] = cols[a].iter().zip(&cols[b]).map(|(x, z)| x * z).sum();
                    }
                    jtr[a] = cols[a].iter().zip(&r0).map(|(x, z)| x * z).sum();
                }
                assert!(crate::stage1::lsq::chol_solve(&jtj, 8, &mut jtr), "positive definite");
                p.iter_mut().zip(&jtr).zip(&truth).for_each(|((x, d), t)| *x -= d * t);
            }
            lams.push(p[6]);
            cs.push(p[7]);
        }
        let spread = |x: &[f64], truth: f64| {
            let mean = x.iter().sum::<f64>() / x.len() as f64;
            let sd = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (x.len() - 1) as f64).sqrt();
            (sd / truth, (mean - truth) / truth)
        };
        let (sl, bl) = spread(&lams, lambda);
        let (sc, bc) = spread(&cs, c);
        eprintln!(
            "lambda: std {sl:.4e} (bound {:.4e}), bias {bl:.1e}; c: std {sc:.4e} (bound {:.4e}), bias {bc:.1e}",
            bound.lambda_rel_std, bound.heat_capacity_rel_std
        );
        // Sampling error of a standard deviation from 600 runs: about 3 %.
        for (name, emp, crb, bias) in
            [("lambda", sl, bound.lambda_rel_std, bl), ("c", sc, bound.heat_capacity_rel_std, bc)]
        {
            assert!(
                (emp / crb - 1.0).abs() < 0.15 && bias.abs() < 0.3 * crb,
                "{name}: empirical relative std {emp:.4e}, bound {crb:.4e}, bias {bias:.2e}"
            );
        }
    }

    /// Unknown rows cost information: the bound with free neighbour weights is looser than with
    /// the rows known, and a vertex whose neighbours are cold (no conduction signal) adds none
    /// for its weights.
    #[test]
    fn unknown_rows_loosen_the_bound() {
        let times = frame_times(61, 0.5);
        let (lambda, c) = (4e-3, 3e-4);
        let zero = vec![0.0; times.len()];
        let fl = [1.0, 0.8, 0.5];
        let series: Vec<Vec<f64>> = (0..2)
            .map(|v| {
                fl.iter().flat_map(|f| simulate(&times, f * (1.0 + 0.3 * v as f64), 0.0, &zero, lambda, c)).collect()
            })
            .collect();
        let m = BoundModel { lambda, c, ambient: TS, emissivity: EPS, sigma: 1e-3 };
        let known = globals_bound(&series, &times, None, &m).expect("informative");
        let groups = vec![vec![vec![1]], vec![vec![0], vec![2]], vec![vec![1]]];
        let free = globals_bound(&series, &times, Some(&groups), &m).expect("informative");
        assert!(free.heat_capacity_rel_std > known.heat_capacity_rel_std, "{known:?} {free:?}");
        assert!(free.lambda_rel_std > known.lambda_rel_std, "{known:?} {free:?}");
    }
}
