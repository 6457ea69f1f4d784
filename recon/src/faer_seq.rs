//! The faer computations heatrecon uses, run with `Par::Seq`: the same bits at any thread count.
//!
//! faer's high-level `Llt` and `self_adjoint_eigen` take the global parallelism, by default
//! `Par::rayon(0)`: as many threads as the current rayon pool. Their matrix products (the
//! supernodal Cholesky's dense updates, the eigenvectors) then pick a kernel and a split by
//! that thread count, so the last bits of the results changed with `RAYON_NUM_THREADS`, and
//! stages 1 and 2 amplify them (measured between 1 and 2 threads: docs/notes/code-comments.md).
//! Each factorisation here is one call (per video, per
//! level or per step matrix); the per-vertex work around it stays parallel. The sparse
//! Cholesky factor is heatsim's ([`heatsim::fem::cholesky`]), given `Par::Seq` by the callers.

use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::evd::{self, ComputeEigenvectors, EvdError};
use faer::{Mat, MatRef, Par};

pub use heatsim::fem::cholesky::{Llt, SymbolicLlt};

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
