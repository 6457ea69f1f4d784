#!/usr/bin/env python3
"""Peer solver: the volumetric heat problem of heatsim, assembled with scikit-fem and
stepped with SciPy, as an independent oracle and a speed reference.

Reads a problem directory written by `heatsim::problem_export::write_problem`
(`simbench peer volumetric SCENE --out DIR` writes one to DIR/problem):
nodes.npy float64 [N, 3] (m), tets.npy int64 [T, 4], boundary.npy int64 [B, 3],
boundary_tag.npy int32 [B] (1 visible, 2 side, 3 back) and problem.json.

Discretisation (the same as sim/src/fem/volumetric.rs, assembled independently):
  P1 tetrahedra; K = k * laplace, M = rho_c * mass (consistent, or its row sums when
  lumped), both from scikit-fem's volume assembly; H = h * boundary mass over the exposed
  facets and a_i = int_Gamma phi_i over the exposed facets, both from a scikit-fem
  FacetBasis restricted to those facets; the load F = absorptivity * flux * int phi_i over
  the visible facets (FacetBasis again). Radiation by nodal quadrature:
  R_i(T) = eps sigma a_i (T_i^4 - Ts^4).
  Backward Euler: M (T - T^n)/dt + K T + H (T - Ts) + R(T) = F(t^{n+1}), t^{n+1} = (n+1-zero_step) dt,
  solved by the chord iteration (A + D0) T_{k+1} = b - R(T_k) + D0 T_k with
  A = M/dt + K + H and D0 = diag(4 eps sigma a_i T_ref^3), one SuperLU factorisation reused
  across steps (refreshed at T_ref = T after a step needing more than 4 iterations), starting
  from the quadratic extrapolation of the last three steps (as heatsim).
  Stopping (--stopping): `estimate` (default, the same test as ours: Hairer and Wanner,
  Solving ODEs II, Sec. IV.8) stops when eta_k u_k <= tolerance, with u_k the update
  max |T_{k+1} - T_k|, theta_k = u_k / u_{k-1}, eta_k = theta_k / (1 - theta_k) (infinite for
  theta_k >= 0.9) and, in a step's first iteration, eta = max(eta_prev, 1e-10)^0.8 from the
  previous step (1 before the first); `update` stops when u_k <= tolerance (never earlier than
  `estimate` once theta < 1/2; at least two solves per changing step).

Writes the frame temperatures, float64 [frames, N] (K), to --out and prints JSON timings
{assembly_s, factorisation_s, stepping_s, total_s, ...} on stdout.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from skfem import Basis, BilinearForm, ElementTetP1, FacetBasis, LinearForm, MeshTet, asm
from skfem.models.poisson import laplace, mass

REFACTOR_AFTER = 4


@LinearForm
def unit_load(v, w):
    return v


def facet_keys(tri, n):
    """One int64 key per triangle, independent of the order of its nodes."""
    s = np.sort(np.asarray(tri, dtype=np.int64), axis=-1)
    return (s[..., 0] * n + s[..., 1]) * n + s[..., 2]


def factorise(a, d0):
    m = (a + sp.diags(d0)).tocsc()
    return spla.splu(m, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("problem", type=Path, help="problem directory (problem_export::write_problem)")
    ap.add_argument("--out", type=Path, required=True, help="frame temperatures, float64 [frames, N] (.npy)")
    ap.add_argument(
        "--stopping",
        choices=["estimate", "update"],
        default="estimate",
        help="iteration stopping test: error estimate (as ours, default) or plain update",
    )
    args = ap.parse_args()
    d = args.problem
    prob = json.loads((d / "problem.json").read_text())
    nodes = np.load(d / "nodes.npy")
    tets = np.load(d / "tets.npy")
    boundary = np.load(d / "boundary.npy")
    tags = np.load(d / "boundary_tag.npy")
    n = nodes.shape[0]

    t_start = time.perf_counter()
    # --- assembly (scikit-fem) ---
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
    lamp_loads = [prob["absorptivity"] * lamp["flux"] * phi_visible for lamp in prob["lamps"]]

    dt = prob["dt"]
    ts = prob["Ts"]
    A = (M / dt + K + H).tocsc()
    Mdt = (M / dt).tocsr()
    h_ts = H @ np.full(n, ts)
    c = prob["emissivity"] * prob["sigma"] * area  # eps sigma a_i (W/K^4)
    rad = np.flatnonzero(c > 0.0)
    c_rad = c[rad]
    linear = bool(prob.get("linearized_radiation", False))  # paper Eq. 5
    t_assembly = time.perf_counter()

    # --- factorisation at T_ref = Ts ---
    temp = np.full(n, ts)
    d0 = np.zeros(n)
    d0[rad] = 4.0 * c_rad * (ts if linear else temp[rad]) ** 3
    lu = factorise(A, d0)
    d0_rad = d0[rad]
    t_fact = time.perf_counter()

    # --- backward-Euler steps ---
    steps = prob["steps"]
    per_frame = prob["steps_per_frame"]
    zero_step = prob["zero_step"]
    tol = prob["tolerance"]
    max_iter = prob["max_iterations"]
    frames = np.empty((steps // per_frame + 1, n))
    frames[0] = temp
    old = temp.copy()
    older = temp.copy()
    oldest = temp.copy()
    iterations = 0
    factorisations = 1
    plain = args.stopping == "update"
    eta_prev = 1.0
    load = np.zeros(n)
    for s in range(1, steps + 1):
        time_s = (s - zero_step) * dt  # integer step count: t = 0 exactly, as in heatsim
        load[:] = 0.0
        for lamp, f in zip(prob["lamps"], lamp_loads):
            # The fraction of the step (time_s - dt, time_s] the lamp is on, as heatsim.
            end = time_s if lamp["off"] is None else min(lamp["off"], time_s)
            w = min(max((end - max(lamp["on"], time_s - dt)) / dt, 0.0), 1.0)
            if w > 0.0:
                load += w * f
        b = Mdt @ old + h_ts + load
        t = old.copy() if s == 1 else (2.0 * old - older if s == 2 else 3.0 * (old - older) + oldest)
        it = 0
        eta = max(eta_prev, 1e-10) ** 0.8
        previous_update = np.inf
        while True:
            it += 1
            x = b.copy()
            tr = t[rad]
            if linear:
                x[rad] += d0_rad * tr - 4.0 * c_rad * ts**3 * (tr - ts)
            else:
                x[rad] += d0_rad * tr - c_rad * ((tr - ts) * (tr + ts) * (tr * tr + ts * ts))
            x = lu.solve(x)
            update = np.max(np.abs(x - t))
            t = x
            if linear:
                break  # a linear problem solved with its exact matrix
            if not np.isfinite(update):
                sys.exit(f"skfem_heat: non-finite temperature in step {s}")
            if it > 1:
                theta = update / previous_update
                eta = theta / (1.0 - theta) if theta < 0.9 else np.inf
            previous_update = update
            if update == 0.0 or (update if plain else eta * update) <= tol:
                break
            if it >= max_iter:
                sys.exit(f"skfem_heat: no convergence in step {s}: update {update:e} K after {it} iterations")
        if np.isfinite(eta):
            eta_prev = eta
        iterations += it
        if it > REFACTOR_AFTER:
            d0 = np.zeros(n)
            d0[rad] = 4.0 * c_rad * t[rad] ** 3
            lu = factorise(A, d0)
            d0_rad = d0[rad]
            factorisations += 1
        oldest = older
        older = old
        old = t
        if s % per_frame == 0:
            frames[s // per_frame] = t
    t_end = time.perf_counter()

    np.save(args.out, frames)
    print(
        json.dumps(
            {
                "assembly_s": t_assembly - t_start,
                "factorisation_s": t_fact - t_assembly,
                "stepping_s": t_end - t_fact,
                "total_s": t_end - t_start,
                "nodes": n,
                "tetrahedra": int(tets.shape[0]),
                "steps": steps,
                "frames": int(frames.shape[0]),
                "iterations_total": iterations,
                "factorisations": factorisations,
                "factor_nnz": int(lu.L.nnz + lu.U.nnz),
                "stopping": args.stopping,
            }
        )
    )


if __name__ == "__main__":
    main()
