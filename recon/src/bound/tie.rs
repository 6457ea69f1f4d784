//! The fluxes of the vertices the loss leaves out (weight 0: the rim rings of partly covered
//! pixels), tied to those of the fitted vertices for the exact flux fit
//! ([`super::shape::fit_flux_exactly`]).
//!
//! A left-out vertex's flux reaches the loss only through conduction into its fitted
//! neighbours, a lagged copy of what their own fluxes do: a few hundred such weakly determined
//! unknowns per video make CGLS crawl and fit the noise's time course. Tied, each left-out
//! vertex takes the mean of its neighbours one ring nearer the fitted vertices (breadth first
//! from them), `b = E b_f`: `(E b_f)_i = b_i` for a fitted vertex and
//! `Σ_s e_is b_s` (weights summing to 1 over fitted vertices `s`) for a left-out one. A left-out
//! vertex that no fitted vertex reaches keeps a zero row (its flux does not move).
//!
//! A different model from the free fluxes that [`super::rim`] eliminates: the rim's free fluxes
//! absorb the model's error there, and tied, the noise-free size of the ball and the hemisphere
//! moves by 23 and 29 % (docs/notes/reconstruction-stage2.md, "The rim's fluxes carry the
//! size"). Kept as an option (`tie_left_out` of the experimental output-error settings).

use std::collections::BTreeMap;

/// The extension `E` from the fitted vertices' fluxes to every vertex's (module doc).
pub(crate) struct Tie {
    /// Per vertex: `None` when fitted; the fitted vertices and weights of its mean when tied.
    rows: Vec<Option<Vec<(usize, f64)>>>,
}

impl Tie {
    /// The tie of the vertices not `fitted`, on the mesh with neighbours `nbrs` (per vertex,
    /// (neighbour, edge)).
    pub(crate) fn new(nbrs: &[Vec<(usize, usize)>], fitted: &[bool]) -> Tie {
        let n = fitted.len();
        let mut rows: Vec<Option<Vec<(usize, f64)>>> =
            (0..n).map(|i| if fitted[i] { None } else { Some(Vec::new()) }).collect();
        let mut reached = fitted.to_vec();
        loop {
            let layer: Vec<usize> =
                (0..n).filter(|&i| !reached[i] && nbrs[i].iter().any(|&(j, _)| reached[j])).collect();
            if layer.is_empty() {
                break;
            }
            let layer_rows: Vec<Vec<(usize, f64)>> = layer
                .iter()
                .map(|&i| {
                    let sources: Vec<usize> = nbrs[i].iter().map(|&(j, _)| j).filter(|&j| reached[j]).collect();
                    let w = 1.0 / sources.len() as f64;
                    let mut acc = BTreeMap::<usize, f64>::new();
                    for j in sources {
                        match &rows[j] {
                            None => *acc.entry(j).or_default() += w,
                            Some(row) => row.iter().for_each(|&(s, ws)| *acc.entry(s).or_default() += w * ws),
                        }
                    }
                    acc.into_iter().collect()
                })
                .collect();
            for (&i, row) in layer.iter().zip(layer_rows) {
                rows[i] = Some(row);
                reached[i] = true;
            }
        }
        Tie { rows }
    }

    /// The tie of the vertices of zero weight; `None` when every vertex is fitted.
    pub(crate) fn of_weights(nbrs: &[Vec<(usize, usize)>], weight: &[f64]) -> Option<Tie> {
        let fitted: Vec<bool> = (0..nbrs.len()).map(|i| weight.get(i).is_none_or(|&w| w > 0.0)).collect();
        fitted.iter().any(|f| !f).then(|| Tie::new(nbrs, &fitted))
    }

    /// `E u`: the fitted entries of `u` kept, the tied ones set from them (`u`'s tied entries
    /// are not read).
    pub(crate) fn extend(&self, u: &[f64]) -> Vec<f64> {
        self.rows
            .iter()
            .enumerate()
            .map(|(i, row)| match row {
                None => u[i],
                Some(row) => row.iter().map(|&(s, w)| w * u[s]).sum(),
            })
            .collect()
    }

    /// `E^T g`, as a vector over all vertices that is zero at the tied ones.
    pub(crate) fn extend_t(&self, g: &[f64]) -> Vec<f64> {
        let mut out: Vec<f64> =
            self.rows.iter().enumerate().map(|(i, row)| if row.is_none() { g[i] } else { 0.0 }).collect();
        for (i, row) in self.rows.iter().enumerate() {
            for &(s, w) in row.iter().flatten() {
                out[s] += w * g[i];
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A path 0 - 1 - 2 - 3 - 4 with 0 and 1 left out, and 2 - 5 - 6 with 6 left out; 7 left out
    /// and unreached.
    fn path() -> (Vec<Vec<(usize, usize)>>, Vec<bool>) {
        let edges = [(0, 1), (1, 2), (2, 3), (3, 4), (2, 5), (5, 6), (1, 5)];
        let mut nbrs = vec![Vec::new(); 8];
        for (e, &(i, j)) in edges.iter().enumerate() {
            nbrs[i].push((j, e));
            nbrs[j].push((i, e));
        }
        let fitted = vec![false, false, true, true, true, true, false, false];
        (nbrs, fitted)
    }

    /// Ring by ring: 1 is the mean of 2 and 5, 0 copies 1, 6 copies 5, 7 stays 0; `extend_t`
    /// is `extend`'s transpose.
    #[test]
    fn ties_ring_by_ring_and_transposes() {
        let (nbrs, fitted) = path();
        let tie = Tie::new(&nbrs, &fitted);
        let u = [9.0, 9.0, 2.0, 3.0, 4.0, 6.0, 9.0, 9.0];
        assert_eq!(tie.extend(&u), vec![4.0, 4.0, 2.0, 3.0, 4.0, 6.0, 6.0, 0.0]);
        let g = [1.0, -2.0, 0.5, 3.0, -1.0, 2.0, 4.0, 7.0];
        let lhs: f64 = tie.extend(&u).iter().zip(&g).map(|(a, b)| a * b).sum();
        let et = tie.extend_t(&g);
        let rhs: f64 = et.iter().zip(&u).map(|(a, b)| a * b).sum();
        assert!((lhs - rhs).abs() <= 1e-12 * lhs.abs(), "{lhs} vs {rhs}");
        assert_eq!([et[0], et[1], et[6], et[7]], [0.0; 4], "tied entries of E^T g are zero");
        assert!(Tie::of_weights(&nbrs, &[1.0; 8]).is_none());
    }
}
