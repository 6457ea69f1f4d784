//! The left-out vertices' fluxes, eliminated exactly in the exact flux fit
//! ([`super::shape::fit_flux_exactly`]).
//!
//! A vertex the loss leaves out (weight 0: the rim rings) has a flux that reaches the loss only
//! through conduction into its fitted neighbours. Free, these fluxes absorb the model's error at
//! the rim (a boundary condition the data choose: tied to their neighbours', the noise-free
//! size moves by 23 to 29 %), but they are weakly determined, and CGLS over all fluxes crawls
//! (400 iterations leave the normal equations' residual at 0.1 to 0.4 of the start's on the ball
//! at level 1). Their columns of the whitened flux Jacobian, `B_r`, are local: conduction
//! carries a flux about `sqrt(4 α T)` in the fitted duration `T`. So they are computed a colour
//! at a time: left-out vertices at least `D` rings apart share one tangent run, each keeping the
//! response within `D/2` rings of it, where the response to one of them, measured, has fallen
//! below 1e-6 of its largest value off that vertex. The fit then runs on the fitted
//! vertices' fluxes with the residual projected away from the rim's columns,
//! `min_u ‖P_r (B_f u - r)‖`, `P_r = I - B_r G^+ B_r^T`, `G = B_r^T B_r`
//! (`G^+` its pseudo-inverse with a cut: some left-out vertices' columns are nearly
//! dependent),
//! and the rim's fluxes follow, `d = G^+ B_r^T (r - B_f u)`.

use faer::Mat;

use crate::stage2::energy::RayMesh;

/// Tail at which a column is cut, relative to its largest value off its own vertex.
const TAIL: f64 = 1e-6;

/// Eigenvalues of the unit-diagonal Gram below this fraction of the largest are left out of
/// its pseudo-inverse (directions the data do not determine; their fluxes stay). At 1e-12
/// fitting the noise along them gave fluxes large enough for the loss with radiation to
/// overflow (the ball at 50 mK, seed 3).
const RANK_CUT: f64 = 1e-8;

/// The left-out vertices' whitened flux columns of one video and their Gram's pseudo-inverse.
pub(super) struct RimColumns {
    /// The left-out vertices whose flux reaches the loss, in column order.
    pub(super) rim: Vec<usize>,
    /// Per column, (vertex, its whitened response over the frames).
    cols: Vec<Vec<(usize, Vec<f64>)>>,
    /// The pseudo-inverse of `G = B_r^T B_r` (module doc), as `G^+ = D V Λ^+ V^T D` with
    /// `D` the inverse square roots of G's diagonal and `V Λ V^T` the unit-diagonal Gram's
    /// eigendecomposition: the eigenvectors (columns) and `1/λ` (0 below [`RANK_CUT`] of the
    /// largest).
    eigvecs: Mat<f64>,
    inv_eigs: Vec<f64>,
    inv_sqrt_diag: Vec<f64>,
    frames: usize,
}

/// Per colour, its members and each member's neighbourhood ([`colours`]).
pub(super) type Colours = Vec<Vec<(usize, Vec<usize>)>>;

/// The left-out vertices grouped into colours whose members are at least `sep` rings apart,
/// each with the vertices within `sep / 2` rings of it: per colour, (member, its neighbourhood).
pub(super) fn colours(nbrs: &[Vec<(usize, usize)>], left_out: &[usize], sep: usize) -> Colours {
    let n = nbrs.len();
    let within = |s: usize, radius: usize| -> Vec<(usize, usize)> {
        let mut dist = std::collections::HashMap::from([(s, 0usize)]);
        let mut front = vec![s];
        let mut out = vec![(s, 0)];
        for k in 1..=radius {
            let mut next = Vec::new();
            for &i in &front {
                for &(j, _) in &nbrs[i] {
                    if let std::collections::hash_map::Entry::Vacant(e) = dist.entry(j) {
                        e.insert(k);
                        next.push(j);
                        out.push((j, k));
                    }
                }
            }
            front = next;
        }
        out
    };
    let mut colour_of = vec![usize::MAX; n];
    let mut groups: Colours = Vec::new();
    for &s in left_out {
        let near = within(s, sep.saturating_sub(1));
        let taken: std::collections::BTreeSet<usize> =
            near.iter().filter(|&&(j, _)| colour_of[j] != usize::MAX).map(|&(j, _)| colour_of[j]).collect();
        let c = (0..).find(|c| !taken.contains(c)).expect("a free colour");
        colour_of[s] = c;
        if c == groups.len() {
            groups.push(Vec::new());
        }
        let half: Vec<usize> = near.iter().filter(|&&(_, k)| 2 * k < sep).map(|&(j, _)| j).collect();
        groups[c].push((s, half));
    }
    groups
}

impl RimColumns {
    /// The columns from `response(c)`, the whitened response (`[vertex * frames + frame]`) to a
    /// unit flux at every member of colour `c` of `groups` ([`colours`]); `None` when no
    /// left-out flux reaches the loss.
    pub(super) fn new(
        groups: &[Vec<(usize, Vec<usize>)>],
        frames: usize,
        response: impl Fn(&[usize]) -> Vec<f64>,
    ) -> Option<RimColumns> {
        let mut rim = Vec::new();
        let mut cols = Vec::new();
        for group in groups {
            let members: Vec<usize> = group.iter().map(|g| g.0).collect();
            let resp = response(&members);
            for (s, near) in group {
                let blocks: Vec<(usize, Vec<f64>)> =
                    near.iter().map(|&i| (i, resp[i * frames..(i + 1) * frames].to_vec())).collect();
                // Left-out vertices' rows are zero after whitening.
                let kept: Vec<(usize, Vec<f64>)> =
                    blocks.into_iter().filter(|b| b.1.iter().any(|&v| v != 0.0)).collect();
                if !kept.is_empty() {
                    rim.push(*s);
                    cols.push(kept);
                }
            }
        }
        if rim.is_empty() {
            return None;
        }
        let m = rim.len();
        // Which columns touch each vertex, to form the Gram from shared vertices only.
        let mut at: std::collections::HashMap<usize, Vec<(usize, usize)>> = std::collections::HashMap::new();
        for (c, col) in cols.iter().enumerate() {
            for (k, b) in col.iter().enumerate() {
                at.entry(b.0).or_default().push((c, k));
            }
        }
        let mut g = Mat::<f64>::zeros(m, m);
        let mut keys: Vec<&usize> = at.keys().collect();
        keys.sort_unstable();
        for i in keys {
            let list = &at[i];
            for (x, &(a, ka)) in list.iter().enumerate() {
                for &(c, kc) in &list[x..] {
                    let dot: f64 = cols[a][ka].1.iter().zip(&cols[c][kc].1).map(|(p, q)| p * q).sum();
                    g[(a, c)] += dot;
                    if a != c {
                        g[(c, a)] += dot;
                    }
                }
            }
        }
        // Columns far apart in size (the outer ring's reach the loss only through the inner
        // one) and nearly dependent: a scaled eigendecomposition with a cut, not a Cholesky.
        let inv_sqrt_diag: Vec<f64> = (0..m).map(|a| 1.0 / g[(a, a)].sqrt()).collect();
        let unit = Mat::from_fn(m, m, |a, c| g[(a, c)] * inv_sqrt_diag[a] * inv_sqrt_diag[c]);
        let (eigvecs, eigs) = crate::faer_seq::self_adjoint_eigen(unit.as_ref()).ok()?;
        let top = (0..m).map(|k| eigs[k]).fold(0.0f64, f64::max);
        let inv_eigs = (0..m).map(|k| if eigs[k] > RANK_CUT * top { 1.0 / eigs[k] } else { 0.0 }).collect();
        Some(RimColumns { rim, cols, eigvecs, inv_eigs, inv_sqrt_diag, frames })
    }

    /// `B_r^T x`.
    fn transpose_apply(&self, x: &[f64]) -> Vec<f64> {
        let f = self.frames;
        self.cols
            .iter()
            .map(|col| {
                col.iter().map(|(i, v)| v.iter().zip(&x[i * f..(i + 1) * f]).map(|(p, q)| p * q).sum::<f64>()).sum()
            })
            .collect()
    }

    /// `G^+ B_r^T x`: the left-out fluxes (K/s) that fit `x` best.
    pub(super) fn coefficients(&self, x: &[f64]) -> Vec<f64> {
        let c: Vec<f64> = self.transpose_apply(x).iter().zip(&self.inv_sqrt_diag).map(|(v, s)| v * s).collect();
        let m = c.len();
        let v = &self.eigvecs;
        let w: Vec<f64> = (0..m).map(|k| self.inv_eigs[k] * (0..m).map(|a| v[(a, k)] * c[a]).sum::<f64>()).collect();
        (0..m).map(|a| self.inv_sqrt_diag[a] * (0..m).map(|k| v[(a, k)] * w[k]).sum::<f64>()).collect()
    }

    /// `x - B_r G^+ B_r^T x` in place.
    pub(super) fn project(&self, x: &mut [f64]) {
        let f = self.frames;
        let y = self.coefficients(x);
        for (col, yc) in self.cols.iter().zip(y) {
            for (i, v) in col {
                x[i * f..(i + 1) * f].iter_mut().zip(v).for_each(|(o, p)| *o -= yc * p);
            }
        }
    }
}

/// The left-out vertex whose incident edges are shortest on average (at positions `x`, m):
/// where conduction crosses the most rings, the probe of [`separation`].
pub(super) fn probe(mesh: &RayMesh, x: &[[f64; 3]], left_out: &[usize]) -> usize {
    let len = |i: usize, j: usize| (0..3).map(|k| (x[i][k] - x[j][k]).powi(2)).sum::<f64>().sqrt();
    let mean_edge =
        |i: usize| mesh.nbrs[i].iter().map(|&(j, _)| len(i, j)).sum::<f64>() / mesh.nbrs[i].len().max(1) as f64;
    *left_out
        .iter()
        .min_by(|&&a, &&b| mean_edge(a).total_cmp(&mean_edge(b)).then(a.cmp(&b)))
        .expect("a left-out vertex")
}

/// Rings `D` between members of a colour, from `response`, the rise (`[vertex * frames +
/// frame]`) to a unit flux at `probe`: beyond `D/2 - 2` rings it stays below [`TAIL`] of its
/// largest value off the probe. Measured rather than taken from the Gaussian kernel, whose
/// tail implicit Euler's fattens where `α Δt / h^2` is small.
pub(super) fn separation(nbrs: &[Vec<(usize, usize)>], probe: usize, response: &[f64], frames: usize) -> usize {
    let mut ring_max: Vec<f64> = Vec::new();
    let mut seen = vec![false; nbrs.len()];
    seen[probe] = true;
    let mut front = vec![probe];
    while !front.is_empty() {
        ring_max.push(
            front.iter().flat_map(|&i| &response[i * frames..(i + 1) * frames]).fold(0.0f64, |m, v| m.max(v.abs())),
        );
        let mut next = Vec::new();
        for &i in &front {
            for &(j, _) in &nbrs[i] {
                if !seen[j] {
                    seen[j] = true;
                    next.push(j);
                }
            }
        }
        front = next;
    }
    let off_probe = ring_max.iter().skip(1).fold(0.0f64, |m, &v| m.max(v));
    let last = (1..ring_max.len()).rev().find(|&k| ring_max[k] >= TAIL * off_probe).unwrap_or(1);
    2 * (last + 2)
}

/// [`colours`] of the `left_out` vertices of `mesh`, `sep` rings apart ([`separation`]), taken
/// in their order around the image centroid (greedy colouring along the rim: 94 colours on the
/// ball at level 1 where the raster order took 104 at the same separation).
pub(super) fn colour_left_out(mesh: &RayMesh, left_out: &[usize], sep: usize) -> Colours {
    let dirs = &mesh.dirs;
    let c: [f64; 2] =
        std::array::from_fn(|k| left_out.iter().map(|&i| dirs[i][k]).sum::<f64>() / left_out.len().max(1) as f64);
    let angle = |i: usize| (dirs[i][1] - c[1]).atan2(dirs[i][0] - c[0]);
    let mut around = left_out.to_vec();
    around.sort_by(|&a, &b| angle(a).total_cmp(&angle(b)).then(a.cmp(&b)));
    colours(&mesh.nbrs, &around, sep)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Members of a colour are `sep` rings apart, every left-out vertex is coloured once, and
    /// each keeps its neighbourhood within `sep / 2` rings (a path graph).
    #[test]
    fn colours_keep_members_apart() {
        let n = 30;
        let nbrs: Vec<Vec<(usize, usize)>> = (0..n)
            .map(|i| {
                let mut v = Vec::new();
                if i > 0 {
                    v.push((i - 1, i - 1));
                }
                if i + 1 < n {
                    v.push((i + 1, i));
                }
                v
            })
            .collect();
        let left_out: Vec<usize> = (0..n).step_by(2).collect();
        let groups = colours(&nbrs, &left_out, 6);
        let mut seen: Vec<usize> = groups.iter().flatten().map(|g| g.0).collect();
        seen.sort_unstable();
        assert_eq!(seen, left_out);
        for g in &groups {
            for (a, (s, near)) in g.iter().enumerate() {
                assert!(near.iter().all(|&j| j.abs_diff(*s) * 2 < 6), "neighbourhood of {s}: {near:?}");
                assert!(g[a + 1..].iter().all(|(t, _)| t.abs_diff(*s) >= 6), "{s} and a member too near");
            }
        }
        assert_eq!(groups.len(), 3);
    }
}
