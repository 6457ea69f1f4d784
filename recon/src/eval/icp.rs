//! Alignment of a reconstruction to the ground truth by point-to-plane ICP with outlier
//! trimming, rigid or with a uniform scale.
//!
//! The transform maps reconstruction coordinates to ground-truth coordinates,
//! `x_gt = s R x + t` (`R` a rotation, `s > 0` dimensionless, `t` in m). Each iteration
//! pairs every source point `x_i` (current transform applied) with its closest point `q_i` on
//! the ground-truth triangles and that triangle's unit normal `n_i`, keeps the pairs with
//! `|x_i - q_i| ≤` [`IcpOptions::trim_factor`] `×` median distance (outlier trimming:
//! parts of the reconstruction the ground truth lacks), and solves the linearised
//! point-to-plane problem (Chen and Medioni 1992; Low 2004)
//! `min_(ω, τ, σ) Σ_i (n_i · (x_i - q_i) + ω · ((x_i - c) × n_i) +
//!    τ · n_i + σ n_i · (x_i - c))^2`
//! for a small rotation `ω` (rad), translation `τ` (m) and, for a similarity, a
//! relative scale change `σ` about the inliers' centroid `c` (`σ = 0` when rigid).
//! The update `x ↦ (1 + σ) exp([ω]_(×)) (x - c) + c + τ` uses the exact
//! rotation (Rodrigues). A tiny Levenberg damping keeps flat or symmetric surfaces (whose
//! in-plane motions are free) solvable.
//!
//! Starts: the identity (inputs already in one frame, the usual case for reconstructions in
//! the camera frame), the centroid shift, and the four proper rotations taking the source's
//! principal axes onto the target's (sign choices with determinant +1), with the scale ratio
//! of their RMS radii for a similarity (Umeyama 1991's closed form for the scale of two
//! centred point sets, `s = sqrt(tr C_t / tr C_s)`). Each start runs a
//! short ICP on a small subsample; the best by the mean of its nearest 80 % of distances is
//! refined on the full sample. A start other than the identity must beat the identity by 10 %
//! to be chosen, so aligned inputs of symmetric shapes keep the identity; every start is
//! always tried (a trimmed ICP from the identity can slide into a wrong fit that looks good,
//! e.g. a dome rotated about its sphere's centre with its rim trimmed away).
//!
//! Stopping: the update falls below [`IcpOptions::tolerance`], or the inliers' mean distance
//! has not improved for [`STALL_ITERATIONS`] iterations (noisy data, where the trimmed set
//! flickers at the optimum), or [`IcpOptions::max_iterations`].
//!
//! Divergence: where the pairing constrains the motion badly (a nearly flat reconstruction of
//! a dome, a ball reconstructed too large), the linearised step can run away (measured:
//! docs/notes/code-comments.md). A step after which that trimmed mean exceeds
//! [`DIVERGENCE_FACTOR`] times the run's lowest so far is undone and the same equations are solved
//! with a Levenberg damping 100 times larger (relaxed again by 100 after each accepted step),
//! up to a largest damping at which the run stops; the last step is checked the same way.
//! Runs without such a step are unchanged.

// `!(x > 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// The 7 x 7 normal equations' loops read best with indices.
#![allow(clippy::needless_range_loop)]

// 3 x 3 matrices and 3-vectors: glam's `DMat3` and `DVec3` through parry's aliases (the
// linear algebra parry, and so this crate, already depends on).
use parry3d_f64::math::{Matrix, Vector};
use rayon::prelude::*;
use serde::Serialize;

use super::closest::SurfaceIndex;

/// Which alignment `simbench eval` performs before measuring.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum AlignMode {
    /// Measure in the given frames.
    None,
    /// Rotation and translation.
    Rigid,
    /// Rotation, translation and a uniform scale.
    Similarity,
}

impl std::str::FromStr for AlignMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "none" => Ok(AlignMode::None),
            "rigid" => Ok(AlignMode::Rigid),
            "similarity" => Ok(AlignMode::Similarity),
            other => Err(format!("unknown alignment {other:?}; expected none, rigid or similarity")),
        }
    }
}

/// `x -> scale * rotation * x + translation` (rotation row-major, translation in m).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Similarity {
    /// 3 x 3 rotation, row-major (orthonormal, determinant +1).
    pub rotation: [[f64; 3]; 3],
    /// Translation, m.
    pub translation: [f64; 3],
    /// Uniform scale (dimensionless, > 0; 1 for rigid).
    pub scale: f64,
}

impl Similarity {
    /// The identity.
    pub const IDENTITY: Similarity =
        Similarity { rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], translation: [0.0; 3], scale: 1.0 };

    /// Applies the transform to a point.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        self.apply_v(Vector::from(p)).into()
    }

    /// Applies only the rotation (for normals).
    pub fn rotate(&self, v: [f64; 3]) -> [f64; 3] {
        (self.rotation_matrix() * Vector::from(v)).into()
    }

    /// Rotation angle, degrees.
    pub fn angle_deg(&self) -> f64 {
        let trace = self.rotation_matrix().diagonal().element_sum();
        ((trace - 1.0) / 2.0).clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// The transform of a rotation `rotation`, a translation (m) and a scale.
    fn new(rotation: Matrix, translation: Vector, scale: f64) -> Similarity {
        Similarity { rotation: rotation.transpose().to_cols_array_2d(), translation: translation.into(), scale }
    }

    /// [`Similarity::rotation`] as a matrix (glam stores columns; the field holds rows).
    fn rotation_matrix(&self) -> Matrix {
        Matrix::from_cols_array_2d(&self.rotation).transpose()
    }

    /// [`Similarity::apply`] on a vector.
    fn apply_v(&self, p: Vector) -> Vector {
        self.rotation_matrix() * p * self.scale + Vector::from(self.translation)
    }
}

/// Settings of the ICP.
#[derive(Clone, Debug)]
pub struct IcpOptions {
    /// Source points of the final refinement (area-weighted surface samples).
    pub points: usize,
    /// Source points for comparing starts.
    pub start_points: usize,
    /// Iterations per start.
    pub start_iterations: usize,
    /// Largest number of iterations of the refinement.
    pub max_iterations: usize,
    /// Pairs farther apart than this multiple of the median distance are outliers.
    pub trim_factor: f64,
    /// Convergence: the update's rotation (rad), translation relative to the target size and
    /// relative scale change all below this.
    pub tolerance: f64,
}

impl Default for IcpOptions {
    fn default() -> Self {
        IcpOptions {
            points: 10_000,
            start_points: 600,
            start_iterations: 20,
            max_iterations: 50,
            trim_factor: 3.0,
            tolerance: 1e-9,
        }
    }
}

/// Result of [`align`].
#[derive(Clone, Debug, Serialize)]
pub struct Alignment {
    /// The mode asked for.
    pub mode: AlignMode,
    /// The transform from reconstruction to ground-truth coordinates.
    pub transform: Similarity,
    /// Iterations of the final refinement.
    pub iterations: usize,
    /// Fraction of source points kept as inliers in the last iteration.
    pub inlier_fraction: f64,
    /// Mean distance of the inliers in the last iteration, m.
    pub inlier_mean_m: f64,
    /// Whether the refinement met the tolerance before `max_iterations`.
    pub converged: bool,
    /// Which start won: "identity", "centroid" or "principal axes k".
    pub start: String,
    /// How many starts were tried.
    pub starts_tried: usize,
}

/// Aligns `source` points (reconstruction, m) to the `target` surface. `source_small` is a
/// subsample used to compare starts; `target_points` (samples of the target surface) give its
/// centroid and principal axes; `target_size` (m) scales the translation tolerance.
pub fn align(
    source: &[[f64; 3]],
    source_small: &[[f64; 3]],
    target: &SurfaceIndex,
    target_points: &[[f64; 3]],
    target_size: f64,
    mode: AlignMode,
    opts: &IcpOptions,
) -> Alignment {
    if mode == AlignMode::None {
        return Alignment {
            mode,
            transform: Similarity::IDENTITY,
            iterations: 0,
            inlier_fraction: 1.0,
            inlier_mean_m: f64::NAN,
            converged: true,
            start: "identity".into(),
            starts_tried: 0,
        };
    }
    let with_scale = mode == AlignMode::Similarity;
    let starts = starts(source_small, target_points, with_scale);
    let mut best: Option<(f64, String, Similarity)> = None;
    let mut identity_score = f64::INFINITY;
    let mut n_starts = 0;
    for (name, t0) in starts {
        n_starts += 1;
        let run = icp(source_small, target, target_size, t0, with_scale, opts.start_iterations, opts);
        let score = trimmed_score(source_small, target, &run.transform);
        if name == "identity" {
            identity_score = score;
        }
        let better = match &best {
            None => true,
            Some((s, _, _)) => score < *s && score < 0.9 * identity_score,
        };
        if better && score.is_finite() {
            best = Some((score, name, run.transform));
        }
    }
    let (_, start, t0) = best.unwrap_or((f64::NAN, "identity".into(), Similarity::IDENTITY));
    let run = icp(source, target, target_size, t0, with_scale, opts.max_iterations, opts);
    Alignment {
        mode,
        transform: run.transform,
        iterations: run.iterations,
        inlier_fraction: run.inlier_fraction,
        inlier_mean_m: run.inlier_mean,
        converged: run.converged,
        start,
        starts_tried: n_starts,
    }
}

/// Similarity alignment by a search over the scale (module doc): rigid ICP at each scale s
/// (applied about the source's centroid, after the rigid alignment `rigid`), scored by the
/// symmetric trimmed mean distance, the forward part from `source_small` to `target` and the
/// reverse part from `target_points` to the source surface `source_index` (in source
/// coordinates; distances there times s). Golden-section search on ln s in
/// [-ln SCALE_SEARCH, ln SCALE_SEARCH] to 1e-10, then the final rigid refinement of `source`.
#[allow(clippy::too_many_arguments)]
pub fn align_similarity_symmetric(
    source: &[[f64; 3]],
    source_small: &[[f64; 3]],
    source_index: &SurfaceIndex,
    target: &SurfaceIndex,
    target_points: &[[f64; 3]],
    target_size: f64,
    rigid: &Alignment,
    opts: &IcpOptions,
) -> Alignment {
    let (c, _) = centroid_cov(source_small);
    let r = rigid.transform.rotation_matrix();
    let t_rigid = Vector::from(rigid.transform.translation);
    // T_s(p) = R (s (p - c) + c) + t: scale s about the source centroid, then the rigid motion.
    let at_scale = |s: f64| Similarity::new(r, t_rigid + r * (c * (1.0 - s)), s);
    let score = |ln_s: f64| -> f64 {
        let s = ln_s.exp();
        let run = icp(source_small, target, target_size, at_scale(s), false, opts.start_iterations, opts);
        let t = run.transform;
        let forward = trimmed_score(source_small, target, &t);
        // Reverse: target points mapped into source coordinates, p = R^T (q - t) / s.
        let rt = t.rotation_matrix().transpose();
        let tt = Vector::from(t.translation);
        let mut d: Vec<f64> = target_points
            .par_iter()
            .map(|&q| {
                let p = rt * (Vector::from(q) - tt) * (1.0 / t.scale);
                t.scale * source_index.closest(p.into()).distance
            })
            .collect();
        d.sort_by(f64::total_cmp);
        let k = ((d.len() as f64 * 0.8).ceil() as usize).clamp(1, d.len().max(1));
        let reverse = if d.is_empty() { 0.0 } else { d[..k].iter().sum::<f64>() / k as f64 };
        forward + reverse
    };
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (-SCALE_SEARCH.ln(), SCALE_SEARCH.ln());
    let mut x1 = b - g * (b - a);
    let mut x2 = a + g * (b - a);
    let (mut f1, mut f2) = (score(x1), score(x2));
    while b - a > 1e-10 {
        if f1 < f2 {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - g * (b - a);
            f1 = score(x1);
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + g * (b - a);
            f2 = score(x2);
        }
    }
    // The final refinement from the rigid alignment at the best scale (not from the search's
    // short runs).
    // The rigid alignment's own scale (1) competes, so that an exact match stays exact.
    let mid = 0.5 * (a + b);
    let ln_s = if score(0.0) <= score(mid) { 0.0 } else { mid };
    let run = icp(source, target, target_size, at_scale(ln_s.exp()), false, opts.max_iterations, opts);
    Alignment {
        mode: AlignMode::Similarity,
        transform: run.transform,
        iterations: run.iterations,
        inlier_fraction: run.inlier_fraction,
        inlier_mean_m: run.inlier_mean,
        converged: run.converged,
        start: format!("{} (rigid), scale by symmetric search", rigid.start),
        starts_tried: rigid.starts_tried,
    }
}

/// The scale range of [`align_similarity_symmetric`]: [1/SCALE_SEARCH, SCALE_SEARCH].
pub const SCALE_SEARCH: f64 = 3.0;

/// Iterations without improvement after which ICP counts as converged (see `icp`).
pub const STALL_ITERATIONS: usize = 4;

/// An ICP step after which the mean of the nearest 80 % of distances exceeds this factor times
/// the lowest value of the run so far has run away: it is undone and retried with more damping
/// (module doc).
/// Well-behaved runs never come near it (the trimmed set's flicker at the optimum changes the
/// score by parts per thousand).
pub const DIVERGENCE_FACTOR: f64 = 1.5;

/// Levenberg damping of the point-to-plane normal equations, relative to their trace: the
/// default (keeps flat and symmetric surfaces solvable) and the largest tried after undone
/// steps (factors of 100) before the run stops.
const MIN_DAMPING: f64 = 1e-12;
const MAX_DAMPING: f64 = 1e2;

/// A source point (transformed), its closest target point (both m), that triangle's unit
/// normal, their distance (m).
type Pair = (Vector, Vector, Vector, f64);

struct Run {
    transform: Similarity,
    iterations: usize,
    inlier_fraction: f64,
    inlier_mean: f64,
    converged: bool,
}

/// Mean of the nearest 80 % of source-to-target distances under `t` (m).
fn trimmed_score(source: &[[f64; 3]], target: &SurfaceIndex, t: &Similarity) -> f64 {
    let mut d: Vec<f64> = source.par_iter().map(|&p| target.closest(t.apply(p)).distance).collect();
    d.sort_by(f64::total_cmp);
    trimmed_mean(&d)
}

fn icp(
    source: &[[f64; 3]],
    target: &SurfaceIndex,
    target_size: f64,
    mut t: Similarity,
    with_scale: bool,
    max_iterations: usize,
    opts: &IcpOptions,
) -> Run {
    let nvar = if with_scale { 7 } else { 6 };
    let mut iterations = 0;
    let mut converged = false;
    let mut inlier_fraction = 0.0;
    let mut inlier_mean = f64::NAN;
    let mut best_mean = f64::INFINITY;
    let mut since_best = 0;
    // Relative Levenberg damping of the normal equations (module doc, "Divergence").
    let mut damping = MIN_DAMPING;
    // The last accepted iterate: its transform and normal equations.
    let mut accepted: Option<(Similarity, NormalEquations)> = None;
    // The lowest trimmed score of an accepted iterate.
    let mut best_score = f64::INFINITY;
    while iterations < max_iterations {
        iterations += 1;
        let pairs: Vec<Pair> = source
            .par_iter()
            .map(|&p| {
                let x = t.apply(p);
                let c = target.closest(x);
                (Vector::from(x), Vector::from(c.point), Vector::from(target.face_normal(c.face)), c.distance)
            })
            .collect();
        let mut d: Vec<f64> = pairs.iter().map(|p| p.3).collect();
        d.sort_by(f64::total_cmp);
        let score = trimmed_mean(&d);
        // Whether this iteration's pairs were accepted (not a rejected step's).
        let mut fresh = false;
        let eqs = match accepted.take() {
            Some((prev, eqs)) if !(score <= DIVERGENCE_FACTOR * best_score) => {
                // The step ran away: undo it and solve the same equations more damped.
                t = prev;
                damping *= 100.0;
                if damping > MAX_DAMPING {
                    break;
                }
                accepted = Some((prev, eqs));
                eqs
            }
            _ => {
                let median = d[d.len() / 2];
                let threshold = (opts.trim_factor * median).max(1e-12 * target_size);
                let inliers: Vec<&Pair> = pairs.iter().filter(|p| p.3 <= threshold).collect();
                inlier_fraction = inliers.len() as f64 / pairs.len() as f64;
                if inliers.len() < nvar {
                    break;
                }
                inlier_mean = inliers.iter().map(|p| p.3).sum::<f64>() / inliers.len() as f64;
                damping = (damping / 100.0).max(MIN_DAMPING);
                fresh = true;
                best_score = best_score.min(score);
                let eqs = normal_equations(&inliers, target_size, nvar);
                accepted = Some((t, eqs));
                eqs
            }
        };
        let NormalEquations { mut a, b, c } = eqs;
        let trace: f64 = (0..nvar).map(|i| a[i][i]).sum();
        for (i, row) in a.iter_mut().enumerate().take(nvar) {
            row[i] += damping * trace + 1e-300;
        }
        let Some(delta) = solve_spd(&a, &b, nvar) else { break };
        let omega = Vector::new(delta[0], delta[1], delta[2]);
        let tau = Vector::new(delta[3], delta[4], delta[5]) * target_size;
        let sigma = if with_scale { delta[6] } else { 0.0 };
        let dr = exp_rotation(omega);
        let ds = 1.0 + sigma;
        // x' = ds dR (s R p + t - c) + c + tau.
        let next = Similarity::new(
            orthonormalize(dr * t.rotation_matrix()),
            dr * (Vector::from(t.translation) - c) * ds + c + tau,
            t.scale * ds,
        );
        let step = omega.length().max(tau.length() / target_size).max(sigma.abs());
        if !step.is_finite() || !(next.scale > 0.0) {
            break;
        }
        t = next;
        if step < opts.tolerance {
            converged = true;
            break;
        }
        // Noisy data: the trimmed set flickers at the optimum and the steps stall above the
        // tolerance (around 1e-6 on a noisy bunny); stop once the inliers' mean distance has
        // not improved by a relative 1e-6 for STALL_ITERATIONS iterations.
        if fresh {
            if inlier_mean < best_mean * (1.0 - 1e-6) {
                best_mean = inlier_mean;
                since_best = 0;
            } else {
                since_best += 1;
                if since_best >= STALL_ITERATIONS {
                    converged = true;
                    break;
                }
            }
        }
    }
    // The last step was never scored (it may be the one a stall stopped after): it may have
    // run away too.
    if let Some((prev, _)) = accepted {
        if t != prev && !(trimmed_score(source, target, &t) <= DIVERGENCE_FACTOR * best_score) {
            t = prev;
        }
    }
    Run { transform: t, iterations, inlier_fraction, inlier_mean, converged }
}

/// The damped point-to-plane system of one ICP iteration (module doc), before damping:
/// `a` (nvar x nvar used), `b`, and the inliers' centroid `c` (m) its rotation is about.
#[derive(Clone, Copy)]
struct NormalEquations {
    a: [[f64; 7]; 7],
    b: [f64; 7],
    c: Vector,
}

/// The point-to-plane normal equations of the inlier pairs, scaled: translation in units of
/// `target_size`.
fn normal_equations(inliers: &[&Pair], target_size: f64, nvar: usize) -> NormalEquations {
    let c = inliers.iter().fold(Vector::ZERO, |c, p| c + p.0) * (1.0 / inliers.len() as f64);
    let mut a = [[0.0f64; 7]; 7];
    let mut b = [0.0f64; 7];
    for &&(x, q, n, _) in inliers {
        let xc = x - c;
        let rot = xc.cross(n);
        let j = [rot.x / target_size, rot.y / target_size, rot.z / target_size, n.x, n.y, n.z, n.dot(xc) / target_size];
        let r = n.dot(x - q) / target_size;
        for i in 0..nvar {
            for k in 0..nvar {
                a[i][k] += j[i] * j[k];
            }
            b[i] -= j[i] * r;
        }
    }
    NormalEquations { a, b, c }
}

/// Mean of the nearest 80 % of sorted distances `d` (m): the score starts are compared by.
fn trimmed_mean(d: &[f64]) -> f64 {
    let k = ((d.len() as f64 * 0.8).ceil() as usize).clamp(1, d.len());
    d[..k].iter().sum::<f64>() / k as f64
}

/// Candidate starting transforms, named.
fn starts(source: &[[f64; 3]], target: &[[f64; 3]], with_scale: bool) -> Vec<(String, Similarity)> {
    let mut out = vec![("identity".to_string(), Similarity::IDENTITY)];
    let (cs, covs) = centroid_cov(source);
    let (ct, covt) = centroid_cov(target);
    let tr_s = covs.diagonal().element_sum();
    let tr_t = covt.diagonal().element_sum();
    let s = if with_scale && tr_s > 0.0 && tr_t > 0.0 { (tr_t / tr_s).sqrt() } else { 1.0 };
    out.push(("centroid".to_string(), Similarity::new(Matrix::IDENTITY, ct - cs * s, s)));
    let (Some(es), Some(et)) = (principal_axes(covs), principal_axes(covt)) else { return out };
    // R = Et D Es^T with D = diag(d0, d1, d0 d1 det(Et) det(Es)), so det R = +1.
    // (Determinants by rows, as the row-major arrays this replaced: the same bits.)
    let det_s = es.transpose().determinant();
    let det_t = et.transpose().determinant();
    for (k, (d0, d1)) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)].into_iter().enumerate() {
        let d2 = d0 * d1 * det_s * det_t;
        let r = Matrix::from_cols(et.x_axis * d0, et.y_axis * d1, et.z_axis * d2) * es.transpose();
        out.push((format!("principal axes {k}"), Similarity::new(r, ct - r * cs * s, s)));
    }
    out
}

/// Centroid (m) and covariance (#points-normalised, m^2) of the points `p` (#P x 3).
fn centroid_cov(p: &[[f64; 3]]) -> (Vector, Matrix) {
    let n = p.len().max(1) as f64;
    let c = p.iter().fold(Vector::ZERO, |c, &q| c + Vector::from(q)) * (1.0 / n);
    let cov = p.iter().fold(Matrix::ZERO, |cov, &q| {
        let d = Vector::from(q) - c;
        cov + Matrix::from_cols(d * d.x, d * d.y, d * d.z) / n
    });
    (c, cov)
}

/// Eigenvectors of a symmetric 3 x 3 matrix as columns, eigenvalues descending (faer).
fn principal_axes(m: Matrix) -> Option<Matrix> {
    let a = faer::Mat::<f64>::from_fn(3, 3, |i, j| m.col(j)[i]);
    let eig = a.self_adjoint_eigen(faer::Side::Lower).ok()?;
    let s = eig.S().column_vector();
    let u = eig.U();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| s[j].total_cmp(&s[i]));
    let axis = |k: usize| Vector::new(u[(0, k)], u[(1, k)], u[(2, k)]);
    Some(Matrix::from_cols(axis(order[0]), axis(order[1]), axis(order[2])))
}

fn solve_spd(a: &[[f64; 7]; 7], b: &[f64; 7], n: usize) -> Option<Vec<f64>> {
    // Cholesky, n <= 7.
    let mut l = [[0.0f64; 7]; 7];
    for i in 0..n {
        for j in 0..=i {
            let mut s = a[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            if i == j {
                if !(s > 0.0) {
                    return None;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    let mut y = vec![0.0; n];
    for i in 0..n {
        let s: f64 = (0..i).map(|k| l[i][k] * y[k]).sum();
        y[i] = (b[i] - s) / l[i][i];
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        let s: f64 = (i + 1..n).map(|k| l[k][i] * x[k]).sum();
        x[i] = (y[i] - s) / l[i][i];
    }
    Some(x)
}

/// Rotation matrix `exp([w]x)` (Rodrigues; a rotation by |w| about w), `w` in rad;
/// row-major.
pub fn rodrigues(w: [f64; 3]) -> [[f64; 3]; 3] {
    exp_rotation(Vector::from(w)).transpose().to_cols_array_2d()
}

/// [`rodrigues`] on glam types.
fn exp_rotation(w: Vector) -> Matrix {
    let th = w.length();
    let axis = if th > 0.0 { w * (1.0 / th) } else { Vector::Z };
    Matrix::from_axis_angle(axis, th)
}

/// Re-orthonormalises a rotation (Gram–Schmidt on the rows) against drift over iterations.
fn orthonormalize(m: Matrix) -> Matrix {
    let r0 = m.row(0).normalize();
    let r1 = (m.row(1) - r0 * r0.dot(m.row(1))).normalize();
    Matrix::from_rows(r0, r1, r0.cross(r1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rodrigues_is_a_rotation_by_the_angle() {
        let r = rodrigues([0.0, 0.0, 0.3]);
        let t = Similarity { rotation: r, translation: [0.0; 3], scale: 1.0 };
        assert!((t.angle_deg() - 0.3f64.to_degrees()).abs() < 1e-12);
        let p = t.apply([1.0, 0.0, 0.0]);
        assert!((p[0] - 0.3f64.cos()).abs() < 1e-15 && (p[1] - 0.3f64.sin()).abs() < 1e-15);
        assert!((t.rotation_matrix().determinant() - 1.0).abs() < 1e-15);
    }

    /// glam's axis-angle matrix is the Rodrigues formula this module wrote out before, to
    /// the bit (same products, same order of additions).
    #[test]
    fn rodrigues_matches_the_written_out_formula_bitwise() {
        for w in [[0.0, 0.0, 0.0], [0.0, 0.0, 0.3], [1e-9, -2e-9, 3e-10], [0.4, -1.3, 2.2], [-3.0, 0.1, 0.05]] {
            let th = Vector::from(w).length();
            let k: [f64; 3] = if th > 0.0 { (Vector::from(w) * (1.0 / th)).into() } else { [0.0, 0.0, 1.0] };
            let (s, c) = th.sin_cos();
            let v = 1.0 - c;
            let written = [
                [c + k[0] * k[0] * v, k[0] * k[1] * v - k[2] * s, k[0] * k[2] * v + k[1] * s],
                [k[1] * k[0] * v + k[2] * s, c + k[1] * k[1] * v, k[1] * k[2] * v - k[0] * s],
                [k[2] * k[0] * v - k[1] * s, k[2] * k[1] * v + k[0] * s, c + k[2] * k[2] * v],
            ];
            assert_eq!(rodrigues(w), written, "w = {w:?}");
        }
    }

    #[test]
    fn principal_axes_starts_are_proper_rotations() {
        let pts: Vec<[f64; 3]> =
            (0..100).map(|i| [i as f64 * 0.01, (i % 7) as f64 * 0.003, (i % 3) as f64 * 0.001]).collect();
        for (_, s) in starts(&pts, &pts, false) {
            assert!((s.rotation_matrix().determinant() - 1.0).abs() < 1e-9);
        }
    }

    /// A dome of radius 5 cm (apex at +z; `heatsim`'s hemisphere triangulation, 2.5 mm edges)
    /// and, 3 mm above its base, a nearly flat disc of the same radius: what stage 2 returned on
    /// the 50 mK hemisphere.
    fn dome_and_disc() -> (SurfaceIndex, Vec<[f64; 3]>, Vec<[f64; 3]>) {
        let r = 0.05;
        let dome = heatsim::solid::hemisphere::unit_dome(0.05);
        let v: Vec<[f64; 3]> = dome.points.iter().map(|&p| (Vector::from(p) * r).into()).collect();
        let samples = v.clone();
        let index = SurfaceIndex::new(&heatsim::mesh::TriMesh::try_new(v, dome.tris).unwrap()).unwrap();
        let n = 41;
        let disc: Vec<[f64; 3]> = (0..n * n)
            .map(|k| [0.1 * ((k % n) as f64 / (n - 1) as f64 - 0.5), 0.1 * ((k / n) as f64 / (n - 1) as f64 - 0.5)])
            .filter(|p| p[0] * p[0] + p[1] * p[1] <= r * r)
            .map(|p| [p[0], p[1], 0.003 + 0.001 * (1.0 - (p[0] * p[0] + p[1] * p[1]) / (r * r))])
            .collect();
        (index, samples, disc)
    }

    /// Rigid ICP of the disc onto the dome from every start ends within 1.5 times its start's
    /// trimmed mean distance (without the divergence guard, the second flipped principal-axes
    /// start went 6.5 -> 10.4 mm).
    #[test]
    fn icp_never_ends_far_worse_than_its_start() {
        let (index, samples, disc) = dome_and_disc();
        let opts = IcpOptions::default();
        for (name, t0) in starts(&disc, &samples, false) {
            let start = trimmed_score(&disc, &index, &t0);
            let run = icp(&disc, &index, 0.1, t0, false, opts.max_iterations, &opts);
            let end = trimmed_score(&disc, &index, &run.transform);
            println!("{name}: trimmed mean {start:.4e} -> {end:.4e} m in {} iterations", run.iterations);
            assert!(end <= 1.5 * start, "{name}: {start} -> {end} m");
        }
    }
}
