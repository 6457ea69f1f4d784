//! Sparse assembly of symmetric P1 matrices: the pattern once from topology, values refilled.
//!
//! Storage is the lower triangle in compressed sparse column form (row >= column), which is
//! what the sparse Cholesky factorisation reads. Every element keeps the positions of its
//! ten lower-triangle entries (`tet_slots`, local pairs in the order of [`LOWER_PAIRS`]), and
//! every boundary face its six, so refilling values is a scatter with no searching.
//!
//! Determinism: element matrices are computed in parallel (rayon) but scattered in element
//! order by one thread, so the sums, and hence the bits, are the same for any thread count.

use rayon::prelude::*;

/// Local (row, column) pairs of the lower triangle of a 4 x 4 element matrix, row >= column.
pub const LOWER_PAIRS: [(usize, usize); 10] =
    [(0, 0), (1, 0), (2, 0), (3, 0), (1, 1), (2, 1), (3, 1), (2, 2), (3, 2), (3, 3)];
/// The same for a 3 x 3 face matrix.
pub const LOWER_PAIRS_TRI: [(usize, usize); 6] = [(0, 0), (1, 0), (2, 0), (1, 1), (2, 1), (2, 2)];

/// The lower-triangle CSC pattern of an n x n symmetric matrix with the graph of a mesh.
#[derive(Clone, Debug)]
pub struct Pattern {
    pub n: usize,
    /// Column pointers (#n + 1).
    pub col_ptr: Vec<usize>,
    /// Row index of each stored entry (row >= column), sorted within each column.
    pub row_idx: Vec<usize>,
    /// For each tetrahedron, the entry index of each pair of [`LOWER_PAIRS`] (global row and
    /// column ordered so that row >= column).
    pub tet_slots: Vec<[usize; 10]>,
    /// Index of the diagonal entry of each column.
    pub diag: Vec<usize>,
}

impl Pattern {
    /// Builds the pattern of the node graph of `tets` (#T x 4) over `n` nodes.
    pub fn from_tets(n: usize, tets: &[[usize; 4]]) -> Pattern {
        // Collect (col, row) with row >= col for every tet pair, sort, dedup.
        let mut pairs: Vec<(usize, usize)> = Vec::with_capacity(tets.len() * 10 + n);
        for t in tets {
            for &(a, b) in &LOWER_PAIRS {
                let (r, c) = ordered(t[a], t[b]);
                pairs.push((c, r));
            }
        }
        let mut pattern = Pattern::from_pairs(n, pairs);
        pattern.tet_slots = tets
            .par_iter()
            .map(|t| {
                LOWER_PAIRS.map(|(a, b)| {
                    let (r, c) = ordered(t[a], t[b]);
                    pattern.find(r, c).expect("every tet pair is in the pattern")
                })
            })
            .collect();
        pattern
    }

    /// Builds the pattern of the vertex graph of the triangles `tris` (#F x 3) over `n`
    /// vertices (a surface mesh); `tet_slots` is empty.
    pub fn from_tris(n: usize, tris: &[[usize; 3]]) -> Pattern {
        let mut pairs: Vec<(usize, usize)> = Vec::with_capacity(tris.len() * 6 + n);
        for t in tris {
            for &(a, b) in &LOWER_PAIRS_TRI {
                let (r, c) = ordered(t[a], t[b]);
                pairs.push((c, r));
            }
        }
        Pattern::from_pairs(n, pairs)
    }

    /// The CSC pattern of (col, row) pairs (row >= col), every diagonal added.
    fn from_pairs(n: usize, mut pairs: Vec<(usize, usize)>) -> Pattern {
        pairs.extend((0..n).map(|i| (i, i))); // every diagonal, even for isolated nodes
        pairs.par_sort_unstable();
        pairs.dedup();
        let mut col_ptr = vec![0usize; n + 1];
        for &(c, _) in &pairs {
            col_ptr[c + 1] += 1;
        }
        for c in 0..n {
            col_ptr[c + 1] += col_ptr[c];
        }
        let row_idx: Vec<usize> = pairs.iter().map(|&(_, r)| r).collect();
        let diag: Vec<usize> = (0..n).map(|c| col_ptr[c]).collect(); // row == col sorts first
        Pattern { n, col_ptr, row_idx, tet_slots: Vec::new(), diag }
    }

    /// Entry index of (row, col), row >= col, if stored.
    pub fn find(&self, row: usize, col: usize) -> Option<usize> {
        let (lo, hi) = (self.col_ptr[col], self.col_ptr[col + 1]);
        self.row_idx[lo..hi].binary_search(&row).ok().map(|k| lo + k)
    }

    /// Entry indices of a triangle's six lower pairs ([`LOWER_PAIRS_TRI`]).
    ///
    /// # Panics
    /// If the triangle's edges are not in the pattern (a bug: boundary faces are tet faces).
    pub fn tri_slots(&self, f: &[usize; 3]) -> [usize; 6] {
        LOWER_PAIRS_TRI.map(|(a, b)| {
            let (r, c) = ordered(f[a], f[b]);
            self.find(r, c).expect("boundary face edges are tetrahedron edges")
        })
    }

    /// Number of stored entries.
    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }
}

fn ordered(a: usize, b: usize) -> (usize, usize) {
    if a >= b {
        (a, b)
    } else {
        (b, a)
    }
}

/// Adds the lower triangles of per-element 4 x 4 matrices into `values` (len nnz).
/// `element` computes one element's matrix; it runs in parallel, the scatter does not.
pub fn add_tet_matrices(values: &mut [f64], pattern: &Pattern, element: impl Fn(usize) -> [[f64; 4]; 4] + Sync) {
    let local: Vec<[f64; 10]> = (0..pattern.tet_slots.len())
        .into_par_iter()
        .map(|t| {
            let m = element(t);
            LOWER_PAIRS.map(|(a, b)| m[a][b])
        })
        .collect();
    for (slots, vals) in pattern.tet_slots.iter().zip(&local) {
        for (s, v) in slots.iter().zip(vals) {
            values[*s] += v;
        }
    }
}

/// y = A x for the symmetric matrix whose lower triangle is (`pattern`, `values`).
pub fn sym_matvec(pattern: &Pattern, values: &[f64], x: &[f64], y: &mut [f64]) {
    y.iter_mut().for_each(|v| *v = 0.0);
    for c in 0..pattern.n {
        let xc = x[c];
        let mut acc = 0.0;
        let range = pattern.col_ptr[c]..pattern.col_ptr[c + 1];
        for (&r, &a) in pattern.row_idx[range.clone()].iter().zip(&values[range]) {
            if r == c {
                acc += a * xc;
            } else {
                y[r] += a * xc;
                acc += a * x[r];
            }
        }
        y[c] += acc;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pattern_of_two_tets_sharing_a_face() {
        let tets = [[0, 1, 2, 3], [1, 2, 3, 4]];
        let p = Pattern::from_tets(5, &tets);
        // Lower triangle: 5 diagonals + 9 distinct edges.
        assert_eq!(p.nnz(), 14);
        assert!(p.find(4, 0).is_none());
        assert_eq!(p.row_idx[p.diag[3]], 3);
        let s = p.tri_slots(&[3, 1, 2]);
        assert!(s.iter().all(|&k| k < p.nnz()));
    }

    #[test]
    #[allow(clippy::needless_range_loop)] // dense reference loops read clearest with indices
    fn symmetric_matvec_matches_dense() {
        let tets = [[0, 1, 2, 3], [1, 2, 3, 4]];
        let p = Pattern::from_tets(5, &tets);
        let mut values = vec![0.0; p.nnz()];
        add_tet_matrices(&mut values, &p, |t| {
            let mut m = [[0.0; 4]; 4];
            for i in 0..4 {
                for j in 0..4 {
                    m[i][j] = 1.0 + (i + j + t) as f64 * 0.5 + if i == j { 3.0 } else { 0.0 };
                }
            }
            m
        });
        let mut dense = [[0.0; 5]; 5];
        for (t, tet) in tets.iter().enumerate() {
            for i in 0..4 {
                for j in 0..4 {
                    dense[tet[i]][tet[j]] += 1.0 + (i + j + t) as f64 * 0.5 + if i == j { 3.0 } else { 0.0 };
                }
            }
        }
        let x = [1.0, -2.0, 0.5, 3.0, -1.0];
        let mut y = [0.0; 5];
        sym_matvec(&p, &values, &x, &mut y);
        for i in 0..5 {
            let expected: f64 = (0..5).map(|j| dense[i][j] * x[j]).sum();
            assert!((y[i] - expected).abs() < 1e-12);
        }
    }
}
