#!/usr/bin/env python3
"""Peer solver: the volumetric heat problem of heatsim, assembled with scikit-fem and
stepped with SciPy (SuperLU or conjugate gradients) or MKL PARDISO, as an independent oracle
and a speed reference.

Reads a problem directory written by `heatsim::problem_export::write_problem`
(`simbench peer volumetric SCENE --out DIR` writes one to DIR/problem):
nodes.npy float64 [N, 3] (m), tets.npy int64 [T, 4], boundary.npy int64 [B, 3],
boundary_tag.npy int32 [B] (1 visible, 2 side, 3 back), problem.json and, with point lamps,
lamp_face_flux.npy float64 [P, B] (each point lamp's absorbed flux per boundary face, W/m^2).

Discretisation (the same as sim/src/fem/volumetric.rs, assembled independently):
  P1 tetrahedra; K = k * laplace, M = rho_c * mass (consistent, or its row sums when
  lumped), both from scikit-fem's volume assembly; H = h * boundary mass over the exposed
  facets and a_i = int_Gamma phi_i over the exposed facets, both from a scikit-fem
  FacetBasis restricted to those facets; the load F = absorptivity * flux * int phi_i over
  the visible facets (FacetBasis again) for a uniform lamp, and q_f A_f / 3 per face node for a
  point lamp's face fluxes. Radiation by nodal quadrature:
  R_i(T) = eps sigma a_i (T_i^4 - Ts^4).
  Backward Euler: M (T - T^n)/dt + K T + H (T - Ts) + R(T) = F(t^{n+1}), t^{n+1} = (n+1-zero_step) dt,
  with A = M/dt + K + H and D(T) = diag(4 eps sigma a_i T_i^3), from the polynomial
  extrapolation of the last p + 1 steps (as heatsim's fem::history): p = 2 with a factor; with
  conjugate gradients p in 2..6 chosen per step, the degree whose guess for the last step was
  closest to its solution (History::adaptive); lower in the first steps.

Linear solvers (--linear-solver), each with the iteration heatsim uses with it:
  superlu (default), pardiso: the chord iteration (A + D0) T_{k+1} = b - R(T_k) + D0 T_k with
  D0 = D(T_ref), one factorisation reused across steps (refreshed at T_ref = T after a step
  needing more than 4 iterations). SuperLU: SciPy's splu (MMD on A^T + A, symmetric mode).
  PARDISO: Intel MKL through pypardiso (scripts/setup-peers.sh), matrix type 2 (real symmetric
  positive definite, upper triangle), MKL's default ordering and threads; the solve phase (33)
  is called directly, without pypardiso's per-call matrix comparison and index conversion.
  Stopping (--stopping): `estimate` (default, the same test as ours: Hairer and Wanner,
  Solving ODEs II, Sec. IV.8) stops when eta_k u_k <= tolerance, with u_k the update
  max |T_{k+1} - T_k|, theta_k = u_k / u_{k-1}, eta_k = theta_k / (1 - theta_k) (infinite for
  theta_k >= 0.9) and, in a step's first iteration, eta = max(eta_prev, 1e-10)^0.8 from the
  previous step (1 before the first); `update` stops when u_k <= tolerance.

  cg: Newton's method (A + D(T_k)) T_{k+1} = b - R(T_k) + D(T_k) T_k, each solve by
  Jacobi-preconditioned conjugate gradients warm-started from T_k until the Jacobi-scaled
  residual max_i |r_i| / (A + D)_ii is at most 1 % of the tolerance (heatsim's
  LinearSolver::ConjugateGradients). The CG loop is SciPy's (scipy.sparse.linalg.cg, pure
  Python since SciPy 1.12: a sparse product with SciPy's CSR kernel and NumPy vector
  operations per iteration) with heatsim's stopping test in place of SciPy's 2-norm one, so
  both codes do the same iterations. The first iteration of a step stops when C u_1^2 is
  within the tolerance, C the largest u_(k+1) / u_k^2 seen (both stopping tests as heatsim).

Writes the frame temperatures, float64 [frames, N] (K), to --out and prints JSON timings
{assembly_s, factorisation_s, stepping_s, total_s, solves, ...} on stdout.
"""

import argparse
import ctypes
import json
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from skfem import Basis, ElementTetP1, FacetBasis, LinearForm, MeshTet, asm
from skfem.models.poisson import laplace, mass

REFACTOR_AFTER = 4
# heatsim's CG: scaled-residual target as a fraction of the tolerance, and its iteration cap.
CG_TARGET = 1e-2
CG_MAX_ITERATIONS = 2000


@LinearForm
def unit_load(v, w):
    return v


def facet_keys(tri, n):
    """One int64 key per triangle, independent of the order of its nodes."""
    s = np.sort(np.asarray(tri, dtype=np.int64), axis=-1)
    return (s[..., 0] * n + s[..., 1]) * n + s[..., 2]


def face_load(nodes, faces, q):
    """Nodal load (W) of a flux q (W/m^2) constant on each face: int_face q phi_i = q A / 3."""
    p = nodes[faces]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    load = np.zeros(nodes.shape[0])
    for k in range(3):
        np.add.at(load, faces[:, k], q * area / 3.0)
    return load


class SuperLU:
    """SciPy's SuperLU factor of a symmetric positive definite matrix."""

    name = "SuperLU (SciPy splu)"

    def __init__(self, m):
        self.lu = spla.splu(
            m.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
        )
        self.nnz = int(self.lu.L.nnz + self.lu.U.nnz)

    def solve(self, b):
        return self.lu.solve(b)


class Pardiso:
    """MKL PARDISO's Cholesky factor (matrix type 2) through pypardiso's ctypes binding."""

    name = "PARDISO (MKL, pypardiso)"

    def __init__(self, m):
        import pypardiso

        self.ps = pypardiso.PyPardisoSolver(mtype=2)
        upper = sp.triu(m, format="csr")
        upper.sort_indices()
        self.a = np.ascontiguousarray(upper.data)
        self.ia = (upper.indptr + 1).astype(np.int32)  # one-based
        self.ja = (upper.indices + 1).astype(np.int32)
        self.n = m.shape[0]
        self.call(12, np.zeros(self.n))  # analysis and numerical factorisation
        self.nnz = int(self.ps.iparm[17])  # iparm(18): non-zeros in the factor

    def call(self, phase, b):
        x = np.zeros_like(b)
        error = ctypes.c_int32(0)
        i32 = ctypes.POINTER(ctypes.c_int32)
        f64 = ctypes.POINTER(ctypes.c_double)
        self.ps._mkl_pardiso(
            self.ps.pt.ctypes.data_as(ctypes.POINTER(self.ps._pt_type[0])),
            ctypes.byref(ctypes.c_int32(1)),
            ctypes.byref(ctypes.c_int32(1)),
            ctypes.byref(ctypes.c_int32(2)),
            ctypes.byref(ctypes.c_int32(phase)),
            ctypes.byref(ctypes.c_int32(self.n)),
            self.a.ctypes.data_as(f64),
            self.ia.ctypes.data_as(i32),
            self.ja.ctypes.data_as(i32),
            self.ps.perm.ctypes.data_as(i32),
            ctypes.byref(ctypes.c_int32(1)),
            self.ps.iparm.ctypes.data_as(i32),
            ctypes.byref(ctypes.c_int32(0)),
            b.ctypes.data_as(f64),
            x.ctypes.data_as(f64),
            ctypes.byref(error),
        )
        if error.value != 0:
            sys.exit(f"skfem_heat: PARDISO phase {phase} failed with error {error.value}")
        return x

    def solve(self, b):
        return self.call(33, np.ascontiguousarray(b))


class JacobiCg:
    """A + D as a full CSR matrix whose diagonal is updated in place, and Jacobi PCG on it."""

    name = "conjugate gradients (SciPy, Jacobi)"

    def __init__(self, a):
        self.m = sp.csr_matrix(a)
        self.m.sort_indices()
        self.base = self.m.diagonal().copy()
        rows = np.repeat(np.arange(a.shape[0]), np.diff(self.m.indptr))
        self.diag_pos = np.flatnonzero(rows == self.m.indices)
        if len(self.diag_pos) != a.shape[0]:
            sys.exit("skfem_heat: the step matrix lacks a diagonal entry")
        self.inv_diag = 1.0 / self.base
        self.iterations = 0

    def set_diagonal(self, nodes, add):
        d = self.base.copy()
        d[nodes] += add
        self.m.data[self.diag_pos] = d
        self.inv_diag = 1.0 / d

    def solve(self, b, x, tol):
        """scipy.sparse.linalg.cg's loop from the start x, stopping on max |r_i| / A_ii <= tol."""
        r = b - self.m @ x
        if np.max(np.abs(r * self.inv_diag)) <= tol:
            return x, 0
        rho_prev, p = None, None
        for it in range(1, CG_MAX_ITERATIONS + 1):
            z = r * self.inv_diag
            rho = np.dot(r, z)
            p = z.copy() if p is None else z + (rho / rho_prev) * p
            q = self.m @ p
            alpha = rho / np.dot(p, q)
            x = x + alpha * p
            r = r - alpha * q
            rho_prev = rho
            if np.max(np.abs(r * self.inv_diag)) <= tol:
                self.iterations += it
                return x, it
        sys.exit(f"skfem_heat: conjugate gradients did not reach {tol:e} K in {CG_MAX_ITERATIONS} iterations")


def assemble(d, prob):
    """The problem's matrices and loads assembled with scikit-fem (module doc)."""
    nodes = np.load(d / "nodes.npy")
    tets = np.load(d / "tets.npy")
    boundary = np.load(d / "boundary.npy")
    tags = np.load(d / "boundary_tag.npy")
    n = nodes.shape[0]
    mesh = MeshTet(np.ascontiguousarray(nodes.T), np.ascontiguousarray(tets.T))
    elem = ElementTetP1()
    basis = Basis(mesh, elem)
    # P1: the degree of freedom of node i is i.
    if not np.array_equal(basis.nodal_dofs[0], np.arange(n)):
        sys.exit("skfem_heat: unexpected P1 degree-of-freedom numbering")
    K = prob["k"] * asm(laplace, basis)
    M = prob["rho_c"] * asm(mass, basis)
    if prob["lumped"]:
        M = sp.diags(np.asarray(M.sum(axis=1)).ravel())

    # Match our boundary faces to scikit-fem's facets by sorted node triples.
    bfac = mesh.boundary_facets()
    skeys = facet_keys(mesh.facets[:, bfac].T, n)
    order = np.argsort(skeys)
    ours = facet_keys(boundary, n)
    pos = np.searchsorted(skeys, ours, sorter=order)
    pos = np.minimum(pos, len(order) - 1)
    found = skeys[order[pos]] == ours
    if not found.all() or len(bfac) != len(boundary):
        sys.exit(
            f"skfem_heat: boundary mismatch: {int((~found).sum())} of {len(boundary)} faces are not "
            f"boundary facets of the mesh ({len(bfac)} boundary facets)"
        )
    facet_of = bfac[order[pos]]
    exposed = np.ones(len(boundary), dtype=bool)
    if prob["back_boundary"] == "insulated":
        exposed = tags != 3
    visible = tags == 1

    zero_n = np.zeros(n)
    if exposed.any():
        fb = FacetBasis(mesh, elem, facets=facet_of[exposed])
        H = prob["h"] * asm(mass, fb)
        area = asm(unit_load, fb)  # a_i = int over exposed faces of phi_i
    else:
        H = sp.csr_matrix((n, n))
        area = zero_n.copy()
    phi_visible = asm(unit_load, FacetBasis(mesh, elem, facets=facet_of[visible])) if visible.any() else zero_n.copy()
    face_flux_path = d / "lamp_face_flux.npy"
    face_flux = np.load(face_flux_path) if face_flux_path.exists() else None
    lamp_loads = []
    for lamp in prob["lamps"]:
        if lamp["flux"] is not None:
            lamp_loads.append(prob["absorptivity"] * lamp["flux"] * phi_visible)
        else:
            lamp_loads.append(face_load(nodes, boundary, face_flux[lamp["face_flux_row"]]))
    dt = prob["dt"]
    c = prob["emissivity"] * prob["sigma"] * area  # eps sigma a_i (W/K^4)
    return {
        "n": n,
        "tets": int(tets.shape[0]),
        "A": (M / dt + K + H).tocsr(),
        "Mdt": (M / dt).tocsr(),
        "h_ts": H @ np.full(n, prob["Ts"]),
        "lamp_loads": lamp_loads,
        "rad": np.flatnonzero(c > 0.0),
        "c_rad": c[c > 0.0],
    }


class Radiation:
    """R(T) and its Jacobian on the radiating nodes (nodal quadrature; Eq. 5's linear form
    when the problem says so)."""

    def __init__(self, prob, sys_):
        self.rad, self.c, self.ts = sys_["rad"], sys_["c_rad"], prob["Ts"]
        self.linear = bool(prob.get("linearized_radiation", False))

    def value(self, t):
        tr, ts = t[self.rad], self.ts
        if self.linear:
            return 4.0 * self.c * ts**3 * (tr - ts)
        return self.c * ((tr - ts) * (tr + ts) * (tr * tr + ts * ts))

    def slope(self, t):
        return 4.0 * self.c * (np.full(len(self.rad), self.ts) if self.linear else t[self.rad]) ** 3


def lamp_load(prob, sys_, time_s, out):
    """The nodal load of the step ending at time_s: each lamp's share of (time_s - dt, time_s]."""
    dt = prob["dt"]
    out[:] = 0.0
    for lamp, f in zip(prob["lamps"], sys_["lamp_loads"]):
        end = time_s if lamp["off"] is None else min(lamp["off"], time_s)
        w = min(max((end - max(lamp["on"], time_s - dt)) / dt, 0.0), 1.0)
        if w > 0.0:
            out += w * f
    return out


class Chord:
    """The chord iteration with a reused factor (module doc)."""

    def __init__(self, factor_type, a, rad, t, plain):
        self.factor_type, self.a, self.rad, self.plain = factor_type, a, rad, plain
        self.eta_prev = 1.0
        self.factorisations = 0
        self.refactor(t)

    def refactor(self, t):
        d0 = np.zeros(self.a.shape[0])
        d0[self.rad.rad] = self.rad.slope(t)
        self.factor = self.factor_type(self.a + sp.diags(d0))
        self.d0_rad = d0[self.rad.rad]
        self.factorisations += 1

    def step(self, b, t, tol, max_iter, s):
        it, eta, previous_update = 0, max(self.eta_prev, 1e-10) ** 0.8, np.inf
        rad = self.rad.rad
        while True:
            it += 1
            x = b.copy()
            x[rad] += self.d0_rad * t[rad] - self.rad.value(t)
            x = self.factor.solve(x)
            update = np.max(np.abs(x - t))
            t = x
            if self.rad.linear:
                break  # a linear problem solved with its exact matrix
            if not np.isfinite(update):
                sys.exit(f"skfem_heat: non-finite temperature in step {s}")
            if it > 1:
                theta = update / previous_update
                eta = theta / (1.0 - theta) if theta < 0.9 else np.inf
            previous_update = update
            if update == 0.0 or (update if self.plain else eta * update) <= tol:
                break
            if it >= max_iter:
                sys.exit(f"skfem_heat: no convergence in step {s}: update {update:e} K after {it} iterations")
        if np.isfinite(eta):
            self.eta_prev = eta
        if it > REFACTOR_AFTER:
            self.refactor(t)
        return t, it


class NewtonCg:
    """Newton's method with Jacobi PCG solves (module doc; heatsim's ConjugateGradients)."""

    def __init__(self, a, rad):
        self.cg, self.rad = JacobiCg(a), rad
        self.eta_prev, self.newton_c = 1.0, np.inf
        self.factorisations = 0

    def step(self, b, t, tol, max_iter, s):
        it, eta, previous_update = 0, max(self.eta_prev, 1e-10) ** 0.8, np.inf
        rad = self.rad.rad
        while True:
            it += 1
            d = self.rad.slope(t)
            self.cg.set_diagonal(rad, d)
            x = b.copy()
            x[rad] += d * t[rad] - self.rad.value(t)
            x, _ = self.cg.solve(x, t.copy(), CG_TARGET * tol)
            update = np.max(np.abs(x - t))
            t = x
            if self.rad.linear:
                break
            if not np.isfinite(update):
                sys.exit(f"skfem_heat: non-finite temperature in step {s}")
            if it > 1:
                theta = update / previous_update
                eta = theta / (1.0 - theta) if theta < 0.9 else np.inf
                if np.isfinite(previous_update) and previous_update > 1e3 * tol:
                    c = update / previous_update**2
                    self.newton_c = max(self.newton_c, c) if np.isfinite(self.newton_c) else c
            else:
                eta = self.newton_c * update if update > 0.0 else 0.0
            previous_update = update
            if update == 0.0 or eta * update <= tol:
                break
            if it >= max_iter:
                sys.exit(f"skfem_heat: no convergence in step {s}: update {update:e} K after {it} iterations")
            if it % REFACTOR_AFTER == 0 and len(rad):
                previous_update, eta = np.nan, np.inf  # as heatsim: no estimate across a refresh
        if np.isfinite(eta):
            self.eta_prev = eta
        return t, it


def predict(history, degree):
    """The next step's starting guess: the polynomial through the last min(degree, known - 1) + 1
    states (most recent first) one step ahead, in heatsim's arithmetic (fem::history)."""
    s = history
    p = min(degree, len(s) - 1)
    if p == 0:
        return s[0].copy()
    if p == 1:
        return 2.0 * s[0] - s[1]
    if p == 2:
        return 3.0 * (s[0] - s[1]) + s[2]
    d1, d2, d3 = s[0] - s[1], s[1] - s[2], s[2] - s[3]
    if p == 3:
        return s[0] + 3.0 * (d1 - d2) + d3
    d4 = s[3] - s[4]
    if p == 4:
        return s[0] + 4.0 * (d1 + d3) - 6.0 * d2 - d4
    d5 = s[4] - s[5]
    if p == 5:
        return s[0] + 5.0 * (d1 - d4) + 10.0 * (d3 - d2) + d5
    d6 = s[5] - s[6]
    return s[0] + 6.0 * (d1 + d5) + 20.0 * d3 - 15.0 * (d2 + d4) - d6


def guesses(history, top):
    """The guesses of degrees 0..top from the states (most recent first), in Newton's form: the
    latest state plus its backward differences up to order p (heatsim's fem::history)."""
    d = [h.copy() for h in history[: top + 1]]
    g = [d[0].copy()]
    for p in range(1, top + 1):
        d = [d[q] - d[q + 1] for q in range(len(d) - 1)]
        g.append(g[-1] + d[0])
    return g


# Every how many nodes best_degree compares the guesses (heatsim's fem::history::SAMPLE).
SAMPLE = 8


def best_degree(history, t, max_degree):
    """The degree in 2..max_degree (at most the known states allow) whose guess from `history`
    is closest to `t` in the largest difference over every SAMPLE-th node, the lowest on ties
    (heatsim's History::adaptive)."""
    top = min(len(history) - 1, max_degree)
    if top <= 2:
        return 2
    g = guesses([h[::SAMPLE] for h in history], top)
    errors = [np.max(np.abs(t[::SAMPLE] - g[p])) for p in range(top + 1)]
    best = 2
    for p in range(3, top + 1):
        if errors[p] < errors[best]:
            best = p
    return best


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("problem", type=Path, help="problem directory (problem_export::write_problem)")
    ap.add_argument("--out", type=Path, required=True, help="frame temperatures, float64 [frames, N] (.npy)")
    ap.add_argument(
        "--linear-solver",
        choices=["superlu", "pardiso", "cg"],
        default="superlu",
        help="SuperLU or PARDISO factor (chord iteration), or Jacobi CG (Newton); see the module doc",
    )
    ap.add_argument(
        "--stopping",
        choices=["estimate", "update"],
        default="estimate",
        help="factor's iteration stopping test: error estimate (as ours, default) or plain update",
    )
    args = ap.parse_args()
    d = args.problem
    prob = json.loads((d / "problem.json").read_text())

    t_start = time.perf_counter()
    sys_ = assemble(d, prob)
    n, ts, dt = sys_["n"], prob["Ts"], prob["dt"]
    rad = Radiation(prob, sys_)
    t_assembly = time.perf_counter()

    temp = np.full(n, ts)
    if args.linear_solver == "cg":
        it_rule = NewtonCg(sys_["A"], rad)
    else:
        factor_type = Pardiso if args.linear_solver == "pardiso" else SuperLU
        it_rule = Chord(factor_type, sys_["A"], rad, temp, args.stopping == "update")
    t_fact = time.perf_counter()

    steps, per_frame, zero_step = prob["steps"], prob["steps_per_frame"], prob["zero_step"]
    frames = np.empty((steps // per_frame + 1, n))
    frames[0] = temp
    history = [temp.copy()]  # the last states, most recent first
    # CG: the degree chosen per step up to 6 (heatsim's History::adaptive); a factor: 2.
    max_degree, degree = (6, 6) if args.linear_solver == "cg" else (2, 2)
    solves = 0
    load = np.zeros(n)
    for s in range(1, steps + 1):
        time_s = (s - zero_step) * dt  # integer step count: t = 0 exactly, as in heatsim
        old = history[0]
        b = sys_["Mdt"] @ old + sys_["h_ts"] + lamp_load(prob, sys_, time_s, load)
        t, it = it_rule.step(b, predict(history, degree), prob["tolerance"], prob["max_iterations"], s)
        solves += it
        if args.linear_solver == "cg":
            degree = best_degree(history, t, max_degree)
        history = [t] + history[:max_degree]
        if s % per_frame == 0:
            frames[s // per_frame] = t
    t_end = time.perf_counter()

    np.save(args.out, frames)
    timings = {
        "linear_solver": args.linear_solver,
        "assembly_s": t_assembly - t_start,
        "factorisation_s": t_fact - t_assembly,
        "stepping_s": t_end - t_fact,
        "total_s": t_end - t_start,
        "nodes": n,
        "tetrahedra": sys_["tets"],
        "steps": steps,
        "frames": int(frames.shape[0]),
        "iterations_total": solves,
        "solves": solves,
        "factorisations": it_rule.factorisations,
        "matrix_nnz": int(sys_["A"].nnz),
    }
    if args.linear_solver == "cg":
        timings["cg_iterations"] = it_rule.cg.iterations
    else:
        timings["factor_nnz"] = it_rule.factor.nnz
        timings["stopping"] = args.stopping
    print(json.dumps(timings))


if __name__ == "__main__":
    main()
