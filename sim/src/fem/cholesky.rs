//! Sparse Cholesky factorisation L L^T through faer's explicit-parallelism interface: the
//! caller fixes the parallelism, so the bits do not depend on the thread pool a factor is made
//! or applied in.
//!
//! faer's high-level `Llt` takes the global parallelism, by default `Par::rayon(0)`: as many
//! threads as the current rayon pool. Its supernodal factor's dense updates then pick a kernel
//! and a split by that thread count, so the last bits of a factor (and of every solve with it)
//! changed with `RAYON_NUM_THREADS` on meshes large enough for parallel supernodes (5,733 nodes
//! in `tests/volumetric.rs`'s determinism test; not at 1,859). With a fixed `Par::rayon(k)` the
//! split is the same in a pool of any size (a pool of one thread runs the k parts in turn).

use std::sync::Arc;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{self, LltRef, SymbolicCholesky};
use faer::sparse::linalg::LltError;
use faer::sparse::{FaerError, SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};

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

/// Numeric sparse Cholesky factorisation L L^T, computed and applied with the parallelism given
/// at its construction.
#[derive(Clone, Debug)]
pub struct Llt {
    symbolic: SymbolicLlt,
    values: Vec<f64>,
    par: Par,
}

impl Llt {
    /// Factorises `mat` (the pattern `symbolic` was built from; only its `side` triangle is
    /// read) with parallelism `par`, which its solves use too.
    ///
    /// # Errors
    /// `mat` is not (numerically) positive definite.
    pub fn try_new_with_symbolic(
        symbolic: SymbolicLlt,
        mat: SparseColMatRef<'_, usize, f64>,
        side: Side,
        par: Par,
    ) -> Result<Llt, LltError> {
        let s = &symbolic.0;
        let mut values = vec![0.0; s.len_val()];
        let mut buf = MemBuffer::try_new(s.factorize_numeric_llt_scratch::<f64>(par, Default::default()))
            .map_err(|_| FaerError::OutOfMemory)?;
        s.factorize_numeric_llt(
            &mut values,
            mat,
            side,
            Default::default(),
            par,
            MemStack::new(&mut buf),
            Default::default(),
        )?;
        Ok(Llt { symbolic, values, par })
    }

    /// Solves A x = `b` in place.
    pub fn solve_in_place(&self, b: &mut [f64]) {
        let s = &self.symbolic.0;
        let mut buf = MemBuffer::new(s.solve_in_place_scratch::<f64>(1, self.par));
        let rhs = MatMut::from_column_major_slice_mut(b, s.nrows(), 1);
        LltRef::new(s, &self.values).solve_in_place_with_conj(Conj::No, rhs, self.par, MemStack::new(&mut buf));
    }
}
