//! The faer factorisations heatrecon uses, run with `Par::Seq`: the same bits at any thread count.
//!
//! faer's high-level `Llt` and `self_adjoint_eigen` take the global parallelism, by default
//! `Par::rayon(0)`: as many threads as the current rayon pool. Their matrix products (the
//! supernodal Cholesky's dense updates, the eigenvectors) then pick a kernel and a split by
//! that thread count, so the last bits of the results changed with `RAYON_NUM_THREADS`, and
//! stages 1 and 2 amplify them (measured between 1 and 2 threads: docs/notes/code-comments.md).
//! Each factorisation here is one call (per video, per
//! level or per step matrix); the per-vertex work around it stays parallel.

use std::sync::Arc;

use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::evd::{self, ComputeEigenvectors, EvdError};
use faer::sparse::linalg::cholesky::{self, LltRef, SymbolicCholesky};
use faer::sparse::linalg::LltError;
use faer::sparse::{FaerError, SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, Mat, MatMut, MatRef, Par, Side};

/// Symbolic sparse Cholesky factorisation (fill-reducing ordering), shared between numeric ones.
#[derive(Clone, Debug)]
pub struct SymbolicLlt(Arc<SymbolicCholesky<usize>>);

impl SymbolicLlt {
    /// Analyses the pattern `mat` (only its `side` triangle is read).
    ///
    /// # Errors
    /// As `faer::sparse::linalg::cholesky::factorize_symbolic_cholesky`.
    pub fn try_new(mat: SymbolicSparseColMatRef<'_, usize>, side: Side) -> Result<SymbolicLlt, FaerError> {
        Ok(SymbolicLlt(Arc::new(cholesky::factorize_symbolic_cholesky(
            mat,
            side,
            Default::default(),
            Default::default(),
        )?)))
    }
}

/// Numeric sparse Cholesky factorisation L L^T, computed and applied sequentially.
#[derive(Clone, Debug)]
pub struct Llt {
    symbolic: SymbolicLlt,
    values: Vec<f64>,
}

impl Llt {
    /// Factorises `mat` (the pattern `symbolic` was built from; only its `side` triangle is read).
    ///
    /// # Errors
    /// `mat` is not (numerically) positive definite.
    pub fn try_new_with_symbolic(
        symbolic: SymbolicLlt,
        mat: SparseColMatRef<'_, usize, f64>,
        side: Side,
    ) -> Result<Llt, LltError> {
        let s = &symbolic.0;
        let mut values = vec![0.0; s.len_val()];
        let mut buf = MemBuffer::try_new(s.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()))
            .map_err(|_| FaerError::OutOfMemory)?;
        s.factorize_numeric_llt(
            &mut values,
            mat,
            side,
            Default::default(),
            Par::Seq,
            MemStack::new(&mut buf),
            Default::default(),
        )?;
        Ok(Llt { symbolic, values })
    }

    /// Solves A x = `b` in place.
    pub fn solve_in_place(&self, b: &mut [f64]) {
        let s = &self.symbolic.0;
        let mut buf = MemBuffer::new(s.solve_in_place_scratch::<f64>(1, Par::Seq));
        let rhs = MatMut::from_column_major_slice_mut(b, s.nrows(), 1);
        LltRef::new(s, &self.values).solve_in_place_with_conj(Conj::No, rhs, Par::Seq, MemStack::new(&mut buf));
    }
}

/// Eigendecomposition of the self-adjoint `a` (its lower triangle is read): (eigenvectors as
/// columns, eigenvalues), as `Mat::self_adjoint_eigen(Side::Lower)` but sequential.
///
/// # Errors
/// The eigenvalue iteration did not converge.
pub fn self_adjoint_eigen(a: MatRef<'_, f64>) -> Result<(Mat<f64>, Diag<f64>), EvdError> {
    let n = a.nrows();
    let (mut u, mut s) = (Mat::zeros(n, n), Diag::zeros(n));
    let req = evd::self_adjoint_evd_scratch::<f64>(n, ComputeEigenvectors::Yes, Par::Seq, Default::default());
    let mut buf = MemBuffer::new(req);
    evd::self_adjoint_evd(a, s.as_mut(), Some(u.as_mut()), Par::Seq, MemStack::new(&mut buf), Default::default())?;
    Ok((u, s))
}
