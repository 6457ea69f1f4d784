//! The paper's surface approximation (Sec. 4, Eq. 6): heat conduction on the visible surface
//! of an object treated as a layer of thickness d, and the discrete operators it is built of.

pub mod derivatives;
pub mod operators;
