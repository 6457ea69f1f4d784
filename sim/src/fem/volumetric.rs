//! The volumetric heat solver: P1 tetrahedra, backward Euler, exact T^4 radiation.
//!
//! Model (paper Eq. 1), on the solid Omega with exposed boundary Gamma:
//!
//! rho c_p dT/dt = div(k grad T) in Omega,
//! -k dT/dn = h (T - T_s) + eps sigma (T^4 - T_s^4) - q on Gamma,
//!
//! with q the absorbed flux (W/m^2). P1 elements and backward Euler with step dt give, for the
//! nodal temperatures T = T^{n+1} (K),
//!
//! G(T) = M (T - T^n) / dt + K T + H (T - T_s) + R(T) - F^{n+1} = 0,
//!
//! - M: heat capacity (J/K), consistent rho c_p int phi_i phi_j or lumped (row sums);
//! - K: conduction stiffness (W/K), k int grad phi_i . grad phi_j;
//! - H: convection (W/K), h int_Gamma phi_i phi_j (consistent boundary mass);
//! - R_i(T) = eps sigma a_i (T_i^4 - T_s^4) (W), with a_i = int_Gamma phi_i the lumped exposed
//!   area of node i (nodal quadrature: the radiation term stays diagonal, exactly as in the
//!   energy balance below), evaluated as (T - T_s)(T + T_s)(T^2 + T_s^2) to avoid cancellation;
//! - F_i = int_Gamma q phi_i (W), from per-face fluxes.
//!
//! ## Chord-Newton iteration and its convergence
//! With A = M/dt + K + H (symmetric positive definite) and a fixed diagonal
//! D0 = diag(4 eps sigma a_i T_ref,i^3), each step iterates
//!
//! (A + D0) T_{k+1} = b - R(T_k) + D0 T_k,    b = M T^n / dt + H T_s 1 + F^{n+1},
//!
//! which is Newton's method with the Jacobian frozen at T_ref: one numeric factorisation of
//! A + D0 serves every step. The error obeys e_{k+1} = (A + D0)^{-1} (D0 - D(xi)) e_k with
//! D(xi) = diag(4 eps sigma a_i xi_i^3) between T_k and T, so the iteration contracts with
//! rate rho <= max_i 4 eps sigma a_i |xi_i^3 - T_ref,i^3| / lambda_min(A + D0) < 1 as long as
//! temperatures stay near T_ref; since lambda_min(A) >= the smallest lumped capacity over
//! dt, rho is of order 1e-4 for the scenes here (a few kelvin of heating, dt of 1/60 s), and
//! two solves per step reach 1e-9 K. After every [`REFACTOR_AFTER`] iterations within a step
//! (large steps far from T_ref, where the frozen Jacobian no longer contracts), and after a
//! step that needed more than that, T_ref is moved to the current temperatures and A + D0
//! refactorised.
//!
//! Stopping test (Hairer and Wanner, *Solving ODEs II*, Sec. IV.8, for simplified Newton):
//! with updates u_k = max_i |T_{k+1} - T_k| and the observed contraction
//! theta_k = u_k / u_{k-1}, the remaining error is at most eta_k u_k, eta_k = theta_k / (1 - theta_k);
//! iterations stop when eta_k u_k <= `tolerance` (K). The first iteration of a step uses
//! eta = max(eta_prev, 1e-10)^0.8 from the previous step (the exponent errs on the safe side). A
//! contraction theta >= 0.9 counts as no convergence yet.
//!
//! With [`LinearSolver::ConjugateGradients`] there is no factor to keep, so D0 is the
//! radiation's Jacobian at the current iterate in every iteration (Newton's method), and the
//! first iteration of a step stops on Newton's estimate `C u^2` (the variant's doc).
//!
//! ## Energy balance
//! Summing G(T) = 0 over nodes (1^T K = 0): 1^T M (T^{n+1} - T^n) = dt 1^T (F - H (T - T_s) - R),
//! exactly up to the iteration tolerance, so stored heat = absorbed - convected - radiated
//! holds to roundoff when the sources are integrated with the same backward-Euler rule.
//!
//! ## Second order in time: BDF2
//! [`TimeIntegrator::Bdf2`] replaces M (T - T^n)/dt by M (3/2 T - 2 T^n + 1/2 T^{n-1})/dt:
//! A = 3/2 M/dt + K + H and b = M (2 T^n - 1/2 T^{n-1})/dt + H T_s 1 + F^{n+1}, the same
//! chord-Newton iteration otherwise. Backward Euler's error is first order in dt (enough to
//! bias stage 1's C on the bunny validation scene: docs/notes/code-comments.md); BDF2's is
//! second order. The stepper keeps T^{n-1} itself, so its steps
//! must follow one trajectory. Its first step, and the first after [`Stepper::reset_history`],
//! is a backward-Euler step (a refactorisation each way): the two-step formula needs a smooth
//! solution across its three states, and across a jump of the load (a lamp switching on) a
//! made-up history is off by O(dt): for y' = -lambda y + f switched on at rest it gives
//! y^1 = 2/3 f dt instead of f dt, an error that persists in the slow modes (measured: first
//! order, and twice backward Euler's error). The caller resets the history where the load
//! jumps. Summed over steps, the storage terms telescope to 1^T M (T^N - T^0) plus, per run of
//! BDF2 steps, 1/2 1^T M (last change - change before the run); [`StepInfo::bdf2`] tells which
//! steps carry it.

use super::assembly::{add_tet_matrices, sym_matvec, Pattern};
use super::cholesky::{Llt, SymbolicLlt};
use super::element::{tet_gradients, tet_mass_consistent, tet_mass_lumped, tet_stiffness, tri_area, tri_mass};
use super::pcg::{CgWorkspace, Csr};
use crate::constants::STEFAN_BOLTZMANN;
use crate::mesh::tetmesh::TetMesh;
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Par, Side};

/// The time discretisation of [`Stepper`] (module doc).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TimeIntegrator {
    /// Backward Euler, first order (the default).
    #[default]
    BackwardEuler,
    /// Two-step backward differentiation formula, second order.
    Bdf2,
}

impl TimeIntegrator {
    /// The coefficient of M T^{n+1}/dt in the step's matrix (1 or 3/2).
    pub fn mass_coefficient(self) -> f64 {
        match self {
            TimeIntegrator::BackwardEuler => 1.0,
            TimeIntegrator::Bdf2 => 1.5,
        }
    }
}

/// A step that needs more iterations than this moves T_ref to the current temperatures and
/// refactorises for the following steps.
pub const REFACTOR_AFTER: u32 = 4;

/// Material and environment of the volumetric problem (SI).
#[derive(Clone, Debug, PartialEq)]
pub struct Physics {
    /// Thermal conductivity k (W/(m K)).
    pub conductivity: f64,
    /// Volumetric heat capacity rho c_p (J/(m^3 K)).
    pub volumetric_heat_capacity: f64,
    /// Emissivity eps of exposed faces (0..1).
    pub emissivity: f64,
    /// Convection coefficient h (W/(m^2 K)).
    pub convection_coefficient: f64,
    /// Surrounding temperature T_s (K).
    pub ambient_temperature: f64,
    /// Consistent or lumped heat capacity.
    pub lumped_mass: bool,
    /// Radiation linearised about T_s (paper Eq. 5): R_i = 4 eps sigma a_i T_s^3 (T_i - T_s),
    /// instead of the exact eps sigma a_i (T_i^4 - T_s^4). The problem is then linear and each
    /// step is one substitution.
    pub linearized_radiation: bool,
}

/// Errors of the volumetric solver.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SolverError {
    #[error("tetrahedron {tet} is degenerate (zero volume)")]
    DegenerateTet { tet: usize },
    #[error("triangle {triangle} is degenerate (zero area)")]
    DegenerateTriangle { triangle: usize },
    #[error("vertex {vertex} belongs to no triangle of non-zero area")]
    IsolatedVertex { vertex: usize },
    #[error("the system matrix is not positive definite ({0}); check the material (k, rho c_p > 0) and the time step")]
    Factorisation(String),
    #[error(
        "the radiation iteration did not converge in step {step}: update {update:e} K after {iterations} iterations"
    )]
    NotConverged { step: usize, iterations: u32, update: f64 },
    #[error("non-finite temperature at node {node} in step {step}")]
    NonFinite { step: usize, node: usize },
    #[error("input length mismatch: {what} has {got} entries, expected {expected}")]
    Length { what: &'static str, got: usize, expected: usize },
}

/// The operators of one mesh and physics, independent of the time step: any P1 heat problem
/// of the form M dT/dt + K T + H (T - T_s) + R(T) = F, the volumetric one
/// ([`HeatSystem::assemble`]) or the surface model (`crate::surface::system`).
pub struct HeatSystem {
    pub physics: Physics,
    pub pattern: Pattern,
    /// Lower triangles (pattern order) of K and H, and of M when consistent.
    stiffness: Vec<f64>,
    convection: Vec<f64>,
    mass: Vec<f64>,
    /// Row sums of M (J/K): the lumped capacities, also 1^T M.
    pub capacity: Vec<f64>,
    /// Row sums of H (W/K): h times the exposed lumped area of each node.
    pub convection_rowsum: Vec<f64>,
    /// Nodes with exposed area and eps sigma a_i (W/K^4) for each.
    radiating: Vec<(usize, f64)>,
}

impl HeatSystem {
    /// A system from its parts: lower triangles (in `pattern` order) of the stiffness K (W/K),
    /// the convection matrix H (W/K) and the capacity M (J/K; only its diagonal is read when
    /// `physics.lumped_mass`), the lumped capacities (row sums of M), the row sums of H, and
    /// the exposed (radiating) lumped area a_i of every node (m^2).
    ///
    /// # Errors
    /// [`SolverError::Length`] when a part does not match the pattern.
    pub fn from_parts(physics: Physics, pattern: Pattern, parts: SystemParts) -> Result<HeatSystem, SolverError> {
        let SystemParts { stiffness, convection, mass, capacity, convection_rowsum, radiating_area } = parts;
        let (nnz, n) = (pattern.nnz(), pattern.n);
        for (what, got, expected) in [
            ("stiffness", stiffness.len(), nnz),
            ("convection", convection.len(), nnz),
            ("mass", mass.len(), nnz),
            ("capacity", capacity.len(), n),
            ("convection_rowsum", convection_rowsum.len(), n),
            ("radiating_area", radiating_area.len(), n),
        ] {
            if got != expected {
                return Err(SolverError::Length { what, got, expected });
            }
        }
        let es = physics.emissivity * STEFAN_BOLTZMANN;
        let radiating = radiating_area
            .iter()
            .enumerate()
            .filter(|(_, &a)| a > 0.0 && es > 0.0)
            .map(|(i, &a)| (i, es * a))
            .collect();
        Ok(HeatSystem { physics, pattern, stiffness, convection, mass, capacity, convection_rowsum, radiating })
    }

    /// Assembles K, M, H and the radiation areas. `exposed[f]` says whether boundary face f
    /// of `mesh.boundary` exchanges heat with the surroundings.
    pub fn assemble(mesh: &TetMesh, physics: Physics, exposed: &[bool]) -> Result<HeatSystem, SolverError> {
        let n = mesh.verts.len();
        if exposed.len() != mesh.boundary.len() {
            return Err(SolverError::Length { what: "exposed", got: exposed.len(), expected: mesh.boundary.len() });
        }
        let pattern = Pattern::from_tets(n, &mesh.tets);
        let geometry: Vec<Option<([[f64; 3]; 4], f64)>> = {
            use rayon::prelude::*;
            mesh.tets.par_iter().map(|t| tet_gradients(&t.map(|i| mesh.verts[i]))).collect()
        };
        if let Some(t) = geometry.iter().position(Option::is_none) {
            return Err(SolverError::DegenerateTet { tet: t });
        }
        let geom = |t: usize| geometry[t].expect("checked above");
        let k = physics.conductivity;
        let rc = physics.volumetric_heat_capacity;
        let mut stiffness = vec![0.0; pattern.nnz()];
        add_tet_matrices(&mut stiffness, &pattern, |t| {
            let (g, v) = geom(t);
            tet_stiffness(&g, v, k)
        });
        let mut mass = vec![0.0; pattern.nnz()];
        let mut capacity = vec![0.0; n];
        if physics.lumped_mass {
            for (t, tet) in mesh.tets.iter().enumerate() {
                let m = tet_mass_lumped(geom(t).1, rc);
                for (a, &node) in tet.iter().enumerate() {
                    capacity[node] += m[a];
                }
            }
            for (i, c) in capacity.iter().enumerate() {
                mass[pattern.diag[i]] = *c;
            }
        } else {
            add_tet_matrices(&mut mass, &pattern, |t| tet_mass_consistent(geom(t).1, rc));
            for (t, tet) in mesh.tets.iter().enumerate() {
                // Row sums of the element matrix: rho c V / 4 per node.
                let m = tet_mass_lumped(geom(t).1, rc);
                for (a, &node) in tet.iter().enumerate() {
                    capacity[node] += m[a];
                }
            }
        }
        let h = physics.convection_coefficient;
        let mut convection = vec![0.0; pattern.nnz()];
        let mut convection_rowsum = vec![0.0; n];
        let mut area = vec![0.0; n];
        for (f, face) in mesh.boundary.iter().enumerate() {
            if !exposed[f] {
                continue;
            }
            let a = tri_area(&face.map(|i| mesh.verts[i]));
            let b = tri_mass(a, h);
            let slots = pattern.tri_slots(face);
            for (s, &(p, q)) in slots.iter().zip(&super::assembly::LOWER_PAIRS_TRI) {
                convection[*s] += b[p][q];
            }
            for &node in face {
                area[node] += a / 3.0;
                convection_rowsum[node] += h * a / 3.0;
            }
        }
        let es = physics.emissivity * STEFAN_BOLTZMANN;
        let radiating =
            area.iter().enumerate().filter(|(_, &a)| a > 0.0 && es > 0.0).map(|(i, &a)| (i, es * a)).collect();
        Ok(HeatSystem { physics, pattern, stiffness, convection, mass, capacity, convection_rowsum, radiating })
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.pattern.n
    }

    /// Whether the mesh has no nodes.
    pub fn is_empty(&self) -> bool {
        self.pattern.n == 0
    }

    /// Radiated power (W), summed over nodes: sum_i R_i(T).
    pub fn radiated_power(&self, t: &[f64]) -> f64 {
        self.radiating.iter().map(|&(i, c)| self.radiation(t[i], c)).sum()
    }

    /// R_i at temperature `t` (K) for a node with coefficient `c` = eps sigma a_i (W/K^4).
    fn radiation(&self, t: f64, c: f64) -> f64 {
        let ts = self.physics.ambient_temperature;
        if self.physics.linearized_radiation {
            4.0 * c * ts.powi(3) * (t - ts)
        } else {
            c * quartic_excess(t, ts)
        }
    }

    /// dR_i/dT at `t` (W/K).
    fn radiation_slope(&self, t: f64, c: f64) -> f64 {
        let tt = if self.physics.linearized_radiation { self.physics.ambient_temperature } else { t };
        4.0 * c * tt.powi(3)
    }

    /// The diagonal D0 of the chord matrix at temperatures `t_ref`, one entry per radiating node.
    fn radiation_jacobian(&self, t_ref: &[f64]) -> Vec<f64> {
        self.radiating.iter().map(|&(i, c)| self.radiation_slope(t_ref[i], c)).collect()
    }

    /// Convected power (W): 1^T H (T - T_s).
    pub fn convected_power(&self, t: &[f64]) -> f64 {
        let ts = self.physics.ambient_temperature;
        self.convection_rowsum.iter().zip(t).map(|(c, x)| c * (x - ts)).sum()
    }

    /// Heat content relative to `reference` (J): 1^T M (T - T_ref).
    pub fn heat_content(&self, t: &[f64], reference: &[f64]) -> f64 {
        self.capacity.iter().zip(t.iter().zip(reference)).map(|(c, (a, b))| c * (a - b)).sum()
    }
}

/// The matrices of a [`HeatSystem`] assembled elsewhere (see [`HeatSystem::from_parts`]).
pub struct SystemParts {
    pub stiffness: Vec<f64>,
    pub convection: Vec<f64>,
    pub mass: Vec<f64>,
    pub capacity: Vec<f64>,
    pub convection_rowsum: Vec<f64>,
    pub radiating_area: Vec<f64>,
}

/// T^4 - T_s^4 as (T - T_s)(T + T_s)(T^2 + T_s^2), accurate when T is close to T_s.
pub fn quartic_excess(t: f64, ts: f64) -> f64 {
    (t - ts) * (t + ts) * (t * t + ts * ts)
}

/// Per-step diagnostics.
#[derive(Clone, Copy, Debug, Default)]
pub struct StepInfo {
    /// Chord-Newton iterations (linear solves) this step.
    pub iterations: u32,
    /// The last update max_i |T_{k+1} - T_k| (K).
    pub last_update: f64,
    /// The estimated remaining error eta u (K) when the iteration stopped.
    pub error_estimate: f64,
    /// Whether the factor was refreshed after this step.
    pub refactorised: bool,
    /// Whether this step used the BDF2 formula (else backward Euler).
    pub bdf2: bool,
}

/// How the stepper solves its linear systems `(A + D0) x = rhs`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LinearSolver {
    /// Sparse Cholesky factor of `A + D0` (faer), a forward and a backward substitution per
    /// solve.
    #[default]
    Direct,
    /// Jacobi-preconditioned conjugate gradients warm-started from the current iterate
    /// (`super::pcg`), to a scaled residual of 1 % of the stepper's tolerance. With no factor
    /// to keep, `D0` is the radiation's Jacobian at the current iterate in every iteration
    /// (Newton's method). Newton's next update is about `C u^2` (`u` the current one), so the
    /// first iteration of a step stops when `C u^2` is within the tolerance, `C` the largest
    /// ratio `u_(k+1) / u_k^2` seen so far (unknown at first: two iterations).
    ConjugateGradients,
}

/// The factor's parallelism, fixed so that its bits do not depend on the thread pool
/// (`super::cholesky`): two parts, the machines' cores the committed results were computed on.
const FACTOR_PARALLELISM: Par = Par::Rayon(std::num::NonZeroUsize::new(2).unwrap());

/// CG iterations at most per solve (a mass-dominated step needs tens).
const CG_MAX_ITERATIONS: u32 = 2000;

/// The stepper's form of `A + D0`: a factor with its symbolic analysis, or the matrix itself.
enum Linear {
    Direct { symbolic: SymbolicLlt, factor: Llt },
    ConjugateGradients(Box<CgState>),
}

impl Linear {
    fn as_cg(&self) -> Option<&CgState> {
        match self {
            Linear::ConjugateGradients(cg) => Some(cg),
            Linear::Direct { .. } => None,
        }
    }
}

/// Conjugate gradients' matrix A + D with its work vectors, kept across solves.
struct CgState {
    matrix: Csr,
    /// The consistent mass matrix over the time step, M/dt (W/K), both triangles; `None` when
    /// the mass is lumped.
    mass_dt: Option<Csr>,
    work: CgWorkspace,
    /// The right-hand side and the iterate of the current solve.
    rhs: Vec<f64>,
    x: Vec<f64>,
    /// eps sigma a_i of every node, 0 where it does not radiate (W/K^4).
    emission: Vec<f64>,
    /// D: 4 eps sigma a_i T_i^3 of every node at the current iterate (W/K).
    slope: Vec<f64>,
}

impl CgState {
    fn new(system: &HeatSystem, dt: f64, a: &[f64], d0: &[f64]) -> Result<CgState, SolverError> {
        let n = system.len();
        Ok(CgState {
            matrix: cg_matrix(system, a, d0)?,
            mass_dt: match system.physics.lumped_mass {
                true => None,
                false => Some(
                    Csr::from_lower(&system.pattern, &system.mass, &[])
                        .ok_or_else(|| SolverError::Factorisation("a non-positive mass diagonal".into()))?
                        .scaled(1.0 / dt),
                ),
            },
            work: CgWorkspace::default(),
            rhs: vec![0.0; n],
            x: vec![0.0; n],
            emission: {
                let mut e = vec![0.0; n];
                system.radiating.iter().for_each(|&(i, c)| e[i] = c);
                e
            },
            slope: vec![0.0; n],
        })
    }

    /// Newton's system at the iterate `t`, over blocks of nodes in parallel: the radiation's
    /// slope D(t) on the matrix's diagonal, `rhs = b + D(t) t - R(t)`, and `x = t`, the
    /// starting guess.
    fn prepare(&mut self, system: &HeatSystem, b: &[f64], t: &[f64]) -> Result<(), SolverError> {
        use rayon::prelude::*;
        const BLOCK: usize = 4096;
        let emission = &self.emission;
        (self.rhs.par_chunks_mut(BLOCK), self.x.par_chunks_mut(BLOCK), self.slope.par_chunks_mut(BLOCK))
            .into_par_iter()
            .enumerate()
            .for_each(|(k, (rhs, x, slope))| {
                for j in 0..rhs.len() {
                    let i = k * BLOCK + j;
                    let (c, ti) = (emission[i], t[i]);
                    x[j] = ti;
                    if c == 0.0 {
                        (slope[j], rhs[j]) = (0.0, b[i]);
                    } else {
                        slope[j] = system.radiation_slope(ti, c);
                        rhs[j] = b[i] + (slope[j] * ti - system.radiation(ti, c));
                    }
                }
            });
        if self.matrix.set_diagonal_additions(&self.slope) {
            Ok(())
        } else {
            Err(SolverError::Factorisation("a non-positive diagonal entry".into()))
        }
    }
}

/// Moves `solution` into `t` and returns the update max_i |solution_i - t_i| (K); an error
/// names the first node whose new temperature is not finite.
fn take_update(solution: impl Iterator<Item = f64>, t: &mut [f64], step: usize) -> Result<f64, SolverError> {
    let mut update = 0.0_f64;
    for (i, (v, ti)) in solution.zip(t.iter_mut()).enumerate() {
        if !v.is_finite() {
            return Err(SolverError::NonFinite { step, node: i });
        }
        update = update.max((v - *ti).abs());
        *ti = v;
    }
    Ok(update)
}

/// [`take_update`] in parallel over blocks of nodes (the same result: a maximum does not depend
/// on the order, and the first non-finite node is the lowest of the blocks' first).
fn take_update_parallel(solution: &[f64], t: &mut [f64], step: usize) -> Result<f64, SolverError> {
    use rayon::prelude::*;
    const BLOCK: usize = 4096;
    let (update, first_bad) = t
        .par_chunks_mut(BLOCK)
        .zip(solution.par_chunks(BLOCK))
        .enumerate()
        .map(|(k, (tb, sb))| match take_update(sb.iter().copied(), tb, step) {
            Ok(u) => (u, None),
            Err(SolverError::NonFinite { node, .. }) => (0.0, Some(k * BLOCK + node)),
            Err(_) => unreachable!("take_update fails only on a non-finite value"),
        })
        .reduce(|| (0.0, None), |a, b| (a.0.max(b.0), a.1.into_iter().chain(b.1).min()));
    match first_bad {
        Some(node) => Err(SolverError::NonFinite { step, node }),
        None => Ok(update),
    }
}

/// Backward-Euler (or BDF2) stepper for a fixed time step; owns the factorisation (or the
/// matrix, for conjugate gradients), scratch memory and, for BDF2, the previous state.
pub struct Stepper {
    dt: f64,
    integrator: TimeIntegrator,
    /// BDF2: T^{n-1} of the next step (the `t_old` of the last one); `None` before the first
    /// and after a reset, when the next step is backward Euler.
    history: Option<Vec<f64>>,
    /// The coefficient c of M/dt in the current factor (1 backward Euler, 3/2 BDF2).
    coefficient: f64,
    /// Scratch: the combination of old states that multiplies M/dt in b.
    combined: Vec<f64>,
    tolerance: f64,
    max_iterations: u32,
    /// Lower triangle of A = c M/dt + K + H (pattern order; c = 1, or 3/2 for BDF2).
    a_values: Vec<f64>,
    linear: Linear,
    /// D0: 4 eps sigma a_i T_ref,i^3 for each radiating node (same order as `radiating`).
    d0: Vec<f64>,
    rhs: Vec<f64>,
    /// eta of the last iteration of the previous step (see the stopping test).
    eta: f64,
    /// Conjugate gradients (Newton): the largest u_(k+1) / u_k^2 seen (1/K; infinite before
    /// the first pair; [`LinearSolver::ConjugateGradients`]).
    newton_c: f64,
    /// Number of numeric factorisations (or matrix refreshes, for conjugate gradients) so far.
    pub factorisations: usize,
    /// Conjugate-gradient iterations so far (0 with the direct solver).
    pub cg_iterations: u64,
    steps: usize,
}

impl Stepper {
    /// Backward Euler: analyses the sparsity once and factorises A + D0 with T_ref = `t_ref`
    /// (K, per node).
    pub fn new(
        system: &HeatSystem,
        dt: f64,
        tolerance: f64,
        max_iterations: u32,
        t_ref: &[f64],
    ) -> Result<Stepper, SolverError> {
        Stepper::with_integrator(system, dt, TimeIntegrator::BackwardEuler, tolerance, max_iterations, t_ref)
    }

    /// As [`Stepper::new`] with the time discretisation `integrator` (module doc).
    pub fn with_integrator(
        system: &HeatSystem,
        dt: f64,
        integrator: TimeIntegrator,
        tolerance: f64,
        max_iterations: u32,
        t_ref: &[f64],
    ) -> Result<Stepper, SolverError> {
        Stepper::with_solver(system, dt, integrator, LinearSolver::Direct, tolerance, max_iterations, t_ref)
    }

    /// As [`Stepper::with_integrator`] with the linear solver `solver`.
    pub fn with_solver(
        system: &HeatSystem,
        dt: f64,
        integrator: TimeIntegrator,
        solver: LinearSolver,
        tolerance: f64,
        max_iterations: u32,
        t_ref: &[f64],
    ) -> Result<Stepper, SolverError> {
        let n = system.len();
        if t_ref.len() != n {
            return Err(SolverError::Length { what: "t_ref", got: t_ref.len(), expected: n });
        }
        // Every integrator's first step is backward Euler (module doc).
        let coefficient = TimeIntegrator::BackwardEuler.mass_coefficient();
        let a_values = step_matrix(system, dt, coefficient);
        let d0 = system.radiation_jacobian(t_ref);
        let linear = match solver {
            LinearSolver::Direct => {
                let p = &system.pattern;
                let sym = SymbolicSparseColMatRef::new_checked(n, n, &p.col_ptr, None, &p.row_idx);
                let symbolic =
                    SymbolicLlt::try_new(sym, Side::Lower).map_err(|e| SolverError::Factorisation(format!("{e:?}")))?;
                let factor = factorise(system, &symbolic, &a_values, &d0)?;
                Linear::Direct { symbolic, factor }
            }
            LinearSolver::ConjugateGradients => {
                Linear::ConjugateGradients(Box::new(CgState::new(system, dt, &a_values, &d0)?))
            }
        };
        Ok(Stepper {
            dt,
            integrator,
            history: None,
            coefficient,
            combined: vec![0.0; n],
            tolerance,
            max_iterations,
            a_values,
            linear,
            d0,
            rhs: vec![0.0; n],
            eta: 1.0,
            newton_c: f64::INFINITY,
            factorisations: 1,
            cg_iterations: 0,
            steps: 0,
        })
    }

    /// The (highest) degree of the starting guess that suits the linear solver
    /// (`super::history`): 6 for conjugate gradients, whose iterations grow with the logarithm
    /// of the guess's error, the degree chosen per step up to it ([`Stepper::history`]; higher
    /// degrees amplify the previous solves' errors; measurements in
    /// docs/notes/forward-model.md); 2 for the factor, whose chord iteration needs one
    /// substitution however good the guess.
    pub fn predictor_degree(&self) -> usize {
        match self.linear {
            Linear::ConjugateGradients(_) => 6,
            Linear::Direct { .. } => 2,
        }
    }

    /// The history of states and starting guesses for this stepper from `initial` (K): with
    /// conjugate gradients of a degree chosen per step up to [`Stepper::predictor_degree`], with
    /// the factor of degree 2 (`super::history`).
    pub fn history(&self, initial: &[f64]) -> super::history::History {
        match self.linear {
            Linear::ConjugateGradients(_) => super::history::History::adaptive(initial, self.predictor_degree()),
            Linear::Direct { .. } => super::history::History::new(initial, self.predictor_degree()),
        }
    }

    /// The time step (s).
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// The time discretisation.
    pub fn integrator(&self) -> TimeIntegrator {
        self.integrator
    }

    /// BDF2: forgets the previous state, so that the next step is backward Euler: call it
    /// where the load jumps, or to start another trajectory (module doc).
    pub fn reset_history(&mut self) {
        self.history = None;
    }

    /// One step from `t_old` with nodal load `load` (W, at the new time). `t` holds the
    /// initial guess on entry (for example an extrapolation) and the new temperatures on
    /// return. BDF2 also uses the state before `t_old`, kept from the previous step (module
    /// doc).
    pub fn step(
        &mut self,
        system: &HeatSystem,
        t_old: &[f64],
        load: &[f64],
        t: &mut [f64],
    ) -> Result<StepInfo, SolverError> {
        match self.linear {
            // On one of rayon's workers, so that the step's parallel passes start without a
            // hand-over from the calling thread (`super::pcg::Csr::solve`).
            Linear::ConjugateGradients(_) => rayon::scope(|_| self.step_here(system, t_old, load, t)),
            Linear::Direct { .. } => self.step_here(system, t_old, load, t),
        }
    }

    /// [`Stepper::step`] on the calling thread.
    fn step_here(
        &mut self,
        system: &HeatSystem,
        t_old: &[f64],
        load: &[f64],
        t: &mut [f64],
    ) -> Result<StepInfo, SolverError> {
        let n = system.len();
        for (what, len) in [("t_old", t_old.len()), ("load", load.len()), ("t", t.len())] {
            if len != n {
                return Err(SolverError::Length { what, got: len, expected: n });
            }
        }
        let ts = system.physics.ambient_temperature;
        let bdf2 = self.integrator == TimeIntegrator::Bdf2 && self.history.is_some();
        let coefficient = if bdf2 { TimeIntegrator::Bdf2 } else { TimeIntegrator::BackwardEuler }.mass_coefficient();
        if coefficient != self.coefficient {
            self.a_values = step_matrix(system, self.dt, coefficient);
            refresh(&mut self.linear, system, &self.a_values, &self.d0)?;
            self.factorisations += 1;
            self.coefficient = coefficient;
        }
        // b = M y / dt + H T_s 1 + F, without radiation: y = T^n (backward Euler) or
        // 2 T^n - T^{n-1}/2 (BDF2).
        let y: &[f64] = match self.history.as_deref().filter(|_| bdf2) {
            None => t_old,
            Some(older) => {
                for ((c, &a), &o) in self.combined.iter_mut().zip(t_old).zip(older) {
                    *c = 2.0 * a - 0.5 * o;
                }
                &self.combined
            }
        };
        let b = &mut self.rhs;
        if let Some(mass_dt) = self.linear.as_cg().and_then(|cg| cg.mass_dt.as_ref()) {
            // The full product with M/dt in one parallel pass (the lower triangle's is serial).
            mass_dt.matvec_plus(y, |i| system.convection_rowsum[i] * ts + load[i], b);
        } else {
            if system.physics.lumped_mass {
                for i in 0..n {
                    b[i] = system.capacity[i] * y[i] / self.dt;
                }
            } else {
                sym_matvec(&system.pattern, &system.mass, y, b);
                b.iter_mut().for_each(|v| *v /= self.dt);
            }
            for i in 0..n {
                b[i] += system.convection_rowsum[i] * ts + load[i];
            }
        }
        let mut info = StepInfo { bdf2, ..StepInfo::default() };
        let mut x = vec![0.0; n];
        let mut eta = self.eta.max(1e-10).powf(0.8);
        let mut previous_update = f64::INFINITY;
        loop {
            info.iterations += 1;
            // Counted from 1, as the steps of a run (`crate::simulate`).
            let step = self.steps + 1;
            let update = match &mut self.linear {
                Linear::Direct { factor, .. } => {
                    for i in 0..n {
                        x[i] = b[i];
                    }
                    for (&(i, c), d) in system.radiating.iter().zip(&self.d0) {
                        x[i] += d * t[i] - system.radiation(t[i], c);
                    }
                    factor.solve_in_place(&mut x);
                    take_update(x.iter().copied(), t, step)?
                }
                Linear::ConjugateGradients(cg) => {
                    // Newton: the Jacobian at the current iterate (the variant's doc).
                    cg.prepare(system, b, t)?;
                    let target = self.tolerance * 1e-2;
                    let rep = cg.matrix.solve(&cg.rhs, &mut cg.x, target, CG_MAX_ITERATIONS, &mut cg.work);
                    self.cg_iterations += u64::from(rep.iterations);
                    // Short of its target but within the step's tolerance: rounding's floor.
                    if rep.scaled_residual > target.max(self.tolerance) {
                        return Err(SolverError::NotConverged {
                            step,
                            iterations: info.iterations,
                            update: rep.scaled_residual,
                        });
                    }
                    take_update_parallel(&cg.x, t, step)?
                }
            };
            let newton = matches!(self.linear, Linear::ConjugateGradients(_));
            if info.iterations > 1 {
                let theta = update / previous_update;
                eta = if theta < 0.9 { theta / (1.0 - theta) } else { f64::INFINITY };
                // Above rounding's floor, the pair measures Newton's constant.
                if newton && previous_update.is_finite() && previous_update > 1e3 * self.tolerance {
                    let c = update / (previous_update * previous_update);
                    self.newton_c = if self.newton_c.is_finite() { self.newton_c.max(c) } else { c };
                }
            } else if newton {
                eta = self.newton_c * update;
            }
            previous_update = update;
            info.last_update = update;
            info.error_estimate = eta * update;
            if system.physics.linearized_radiation {
                // A linear problem solved with its exact matrix: one substitution is the answer.
                info.error_estimate = 0.0;
                break;
            }
            if update == 0.0 || info.error_estimate <= self.tolerance {
                break;
            }
            if info.iterations >= self.max_iterations {
                return Err(SolverError::NotConverged { step, iterations: info.iterations, update });
            }
            if info.iterations % REFACTOR_AFTER == 0 && !system.radiating.is_empty() {
                // Slow or no contraction (a large step far from T_ref): refactorise with the
                // Jacobian at the current iterate, which makes the next iterations Newton's.
                self.d0 = system.radiation_jacobian(t);
                refresh(&mut self.linear, system, &self.a_values, &self.d0)?;
                self.factorisations += 1;
                info.refactorised = true;
                // No contraction estimate across a change of matrix.
                previous_update = f64::NAN;
                eta = f64::INFINITY;
            }
        }
        if eta.is_finite() {
            self.eta = eta;
        }
        if info.iterations > REFACTOR_AFTER && !info.refactorised {
            self.d0 = system.radiation_jacobian(t);
            refresh(&mut self.linear, system, &self.a_values, &self.d0)?;
            self.factorisations += 1;
            info.refactorised = true;
        }
        if self.integrator == TimeIntegrator::Bdf2 {
            match &mut self.history {
                Some(h) => h.copy_from_slice(t_old),
                None => self.history = Some(t_old.to_vec()),
            }
        }
        self.steps += 1;
        Ok(info)
    }

    /// One solve with the current matrix in place of `rhs` (for benchmarks: the unit the
    /// cost of a step is compared against): a forward and backward substitution, or conjugate
    /// gradients from zero.
    pub fn substitute(&self, rhs: &mut [f64]) {
        match &self.linear {
            Linear::Direct { factor, .. } => {
                factor.solve_in_place(rhs);
            }
            Linear::ConjugateGradients(cg) => {
                let b = rhs.to_vec();
                rhs.iter_mut().for_each(|v| *v = 0.0);
                cg.matrix.solve(&b, rhs, self.tolerance * 1e-2, CG_MAX_ITERATIONS, &mut CgWorkspace::default());
            }
        }
    }
}

/// Rebuilds the factor (or the matrix) of A + D0 from the lower triangle `a` of A and `d0`.
fn refresh(linear: &mut Linear, system: &HeatSystem, a: &[f64], d0: &[f64]) -> Result<(), SolverError> {
    match linear {
        Linear::Direct { symbolic, factor } => *factor = factorise(system, symbolic, a, d0)?,
        Linear::ConjugateGradients(cg) => cg.matrix = cg_matrix(system, a, d0)?,
    }
    Ok(())
}

/// A + D0 as a full matrix for conjugate gradients.
fn cg_matrix(system: &HeatSystem, a: &[f64], d0: &[f64]) -> Result<Csr, SolverError> {
    let diag: Vec<(usize, f64)> = system.radiating.iter().zip(d0).map(|(&(i, _), &d)| (i, d)).collect();
    Csr::from_lower(&system.pattern, a, &diag)
        .ok_or_else(|| SolverError::Factorisation("a non-positive diagonal entry".into()))
}

/// Lower triangle of A = c M/dt + K + H in pattern order.
fn step_matrix(system: &HeatSystem, dt: f64, c: f64) -> Vec<f64> {
    (0..system.pattern.nnz()).map(|k| c * system.mass[k] / dt + system.stiffness[k] + system.convection[k]).collect()
}

fn factorise(system: &HeatSystem, symbolic: &SymbolicLlt, a: &[f64], d0: &[f64]) -> Result<Llt, SolverError> {
    let p = &system.pattern;
    let mut values = a.to_vec();
    for (&(i, _), d) in system.radiating.iter().zip(d0) {
        values[p.diag[i]] += d;
    }
    let sym = SymbolicSparseColMatRef::new_checked(p.n, p.n, &p.col_ptr, None, &p.row_idx);
    let mat = SparseColMatRef::new(sym, &values);
    Llt::try_new_with_symbolic(symbolic.clone(), mat, Side::Lower, FACTOR_PARALLELISM)
        .map_err(|e| SolverError::Factorisation(format!("{e:?}")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::uniform_load;
    use crate::solid::{cuboid, Grading};
    use crate::tetgen::{tetrahedralize, TetgenOptions};

    /// The parallel update is the serial one: the same largest change and state, and the first
    /// non-finite node over several blocks.
    #[test]
    fn parallel_update_matches_the_serial_one() {
        let n = 10_000;
        let t0: Vec<f64> = (0..n).map(|i| 300.0 + (i as f64 * 0.37).sin()).collect();
        let x: Vec<f64> = (0..n).map(|i| 300.0 + (i as f64 * 0.41).cos()).collect();
        let (mut a, mut b) = (t0.clone(), t0.clone());
        let serial = take_update(x.iter().copied(), &mut a, 3).unwrap();
        assert_eq!(take_update_parallel(&x, &mut b, 3).unwrap(), serial);
        assert_eq!(a, b);
        let mut bad = x.clone();
        bad[9_000] = f64::NAN;
        bad[5_000] = f64::INFINITY;
        match take_update_parallel(&bad, &mut t0.clone(), 7) {
            Err(SolverError::NonFinite { step: 7, node: 5_000 }) => {}
            other => panic!("expected the non-finite node 5000, got {other:?}"),
        }
    }

    fn plate() -> TetMesh {
        let g = Grading { surface_element_size: 4e-3, fine_layer_depth: 4e-3, deep_element_size: 4e-3 };
        let s = cuboid(0.02, 0.02, 0.005, &g).unwrap();
        TetMesh::from_tetgen(tetrahedralize(&s.plc, &TetgenOptions::default()).unwrap()).unwrap()
    }

    fn physics() -> Physics {
        Physics {
            conductivity: 0.19,
            volumetric_heat_capacity: 1190.0 * 1450.0,
            emissivity: 0.9,
            convection_coefficient: 5.0,
            ambient_temperature: 295.0,
            lumped_mass: false,
            linearized_radiation: false,
        }
    }

    /// Conjugate gradients (with Newton's iteration) are no further from the converged
    /// solution than the Cholesky factor's chord iteration is, up to the tolerance, over a
    /// heating run with radiation for both integrators, in no more linear solves.
    #[test]
    fn conjugate_gradients_agree_with_the_direct_solver() {
        let mesh = plate();
        let exposed = vec![true; mesh.boundary.len()];
        let system = HeatSystem::assemble(&mesh, physics(), &exposed).unwrap();
        let n = system.len();
        let t0 = vec![295.0; n];
        let load = uniform_load(&mesh, crate::mesh::tetmesh::FaceTag::Visible, 2000.0);
        for integrator in [TimeIntegrator::BackwardEuler, TimeIntegrator::Bdf2] {
            let run = |solver, tolerance| {
                let mut s = Stepper::with_solver(&system, 0.5, integrator, solver, tolerance, 200, &t0).unwrap();
                let (mut old, mut t) = (t0.clone(), t0.clone());
                let mut solves = 0;
                for _ in 0..40 {
                    solves += s.step(&system, &old, &load, &mut t).unwrap().iterations;
                    old.copy_from_slice(&t);
                }
                (t, solves, s.cg_iterations)
            };
            let (exact, _, _) = run(LinearSolver::Direct, 1e-13);
            let (direct, solves_d, cg_d) = run(LinearSolver::Direct, 1e-9);
            let (cg, solves_c, cg_c) = run(LinearSolver::ConjugateGradients, 1e-9);
            let err = |x: &[f64]| x.iter().zip(&exact).fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()));
            let (err_d, err_c) = (err(&direct), err(&cg));
            let rise = exact.iter().fold(0.0_f64, |m, t| m.max(t - 295.0));
            assert!(rise > 1.0, "the plate should heat: {rise} K");
            assert!(
                err_c <= err_d + 1e-9,
                "{integrator:?}: after 40 steps CG is {err_c:e} K from the converged run, the factor {err_d:e} K"
            );
            assert!(solves_c <= solves_d, "{integrator:?}: {solves_c} solves against {solves_d}");
            assert_eq!(cg_d, 0);
            assert!(cg_c > 0);
        }
    }

    /// The stopping test bounds the error of the returned temperatures, not just the last
    /// update: compare with the same step iterated to roundoff.
    #[test]
    fn stopping_test_bounds_the_true_error() {
        let mesh = plate();
        let exposed = vec![true; mesh.boundary.len()];
        let system = HeatSystem::assemble(&mesh, physics(), &exposed).unwrap();
        let n = system.len();
        // Far from T_ref (295 K) so the chord iteration contracts visibly: start at 340 K.
        let t_ref = vec![295.0; n];
        let t_old = vec![340.0; n];
        let load = uniform_load(&mesh, crate::mesh::tetmesh::FaceTag::Visible, 500.0);
        let tol = 1e-9;
        let mut loose = Stepper::new(&system, 0.5, tol, 50, &t_ref).unwrap();
        let mut t = t_old.clone();
        let info = loose.step(&system, &t_old, &load, &mut t).unwrap();
        let mut tight = Stepper::new(&system, 0.5, 0.0, 200, &t_ref).unwrap();
        let mut exact = t_old.clone();
        // Tolerance 0 stops only on an exactly zero update or at max iterations.
        let _ = tight.step(&system, &t_old, &load, &mut exact);
        let err = t.iter().zip(&exact).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(info.iterations >= 2, "this case should need several iterations, took {}", info.iterations);
        assert!(
            err <= tol,
            "true error {err:e} exceeds the tolerance after {} iterations (estimate {:e})",
            info.iterations,
            info.error_estimate
        );
    }
}
