"""The monolithic two-body contact on several processes: the contact surfaces gathered, the bulk solved in parallel.

The coupling Bᵀ W B joins DOFs of the two bodies that a distributed mesh spreads over ranks, so the contact is
not assembled into the parallel matrix.  Instead every rank gathers the two (small) contact surfaces with their
global DOF numbers and builds the same contact quadrature (``fem.mortar``: B, weights w, gaps g, one row per
slave node).  The bulk is linear: with K the stiffness whose supported rows and columns are the identity,
factorized once in parallel (MUMPS), every state of the Newton iteration is u = u₀ − Z μ, u₀ = K⁻¹ b (the
supports' values in it), Z = K⁻¹ B_fᵀ (B_f: B without the supported columns; one solve per contact row).  The
penalized contact then reduces to the small problem, the same on every rank,

    μ = W s(μ)⁺,   s(μ) = s₀ − S μ,   S = B Z,   s₀ = B u₀ − g,   W = diag(w/δ),

whose semismooth Newton steps on an active set A, (I + W A S) μ = W A s₀, are those of the serial solve
(``fem.two_body``: the same linearized equations, eliminated exactly), with the exact line search on the same
energy restricted to u₀ − Z μ: ½ μᵀ S μ + ½ Σ W (s⁺)².  It stops when a full step keeps the active set or ‖μ − W s⁺‖
reaches round-off (``RTOL``).  The
solution is the serial one (the unique minimizer of the energy).

With the pair's friction law the contact rows are the slave nodes' relative displacements G (d rows per node,
``fem.two_body_friction``): u = u₀ − Z λ, Z = K⁻¹ G_fᵀ, and the nodal law reduces to U = U₀ − S λ(U), S = G Z,
U₀ = G u₀, solved on every rank by ``fem.condensed_friction.solve_condensed`` (the loop of the frictional Newton);
the state (the anchors) is committed on every rank alike.
"""

import time

import basix.ufl
import dolfinx.fem.petsc
import numpy as np
import scipy.sparse as sp
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.errors import ConvergenceError
from fenics_contact.fem.condensed_friction import CondensedLaw, solve_condensed
from fenics_contact.fem.contact import NewtonHistory, NewtonOptions
from fenics_contact.fem.linalg import DirectSolver
from fenics_contact.fem.mortar import Surface, contact_quadrature, surface
from fenics_contact.problem.materials import strain, stress
from fenics_contact.problem.pair import TwoBodyProblem

__all__ = ["gathered_surface", "gathered_u", "reduced_penalty_newton", "solve_two_body_distributed"]

#: the stopping rule: a full step that keeps the active set (the equations are then linear, solved exactly), or
#: ‖μ − W s(μ)⁺‖ ≤ RTOL ‖μ‖ + 100 ε max W ‖s₀‖ (round-off)
RTOL = 1e-10


def gathered_surface(V: fem.FunctionSpace, problem: TwoBodyProblem, tag: int) -> Surface:
    """The whole surface of facet tag ``tag`` on every rank: each rank's owned facets, DOF blocks numbered
    globally (collective)."""
    msh, comm = V.mesh, V.mesh.comm
    local = surface(V, problem.facet_tags, tag)
    owned = problem.facet_tags.find(tag) < msh.topology.index_map(msh.topology.dim - 1).size_local
    blocks = V.dofmap.index_map.local_to_global(local.blocks[owned].ravel().astype(np.int32))
    parts = comm.allgather(
        (local.coords[owned], blocks.reshape(-1, local.blocks.shape[1]), local.normals[owned], local.measures[owned])
    )
    return Surface(*(np.concatenate([p[i] for p in parts]) for i in range(4)))


def _line_search(S: np.ndarray, W: np.ndarray, s0: np.ndarray, mu: np.ndarray, d: np.ndarray) -> float:
    """The minimizer in (0, 1] of the reduced energy along d (bisection on its monotone slope)."""
    Sd, Smu = S @ d, S @ mu

    def slope(t: float) -> float:
        return float(d @ (Smu + t * Sd) - Sd @ (W * np.maximum(s0 - Smu - t * Sd, 0.0)))

    if slope(1.0) <= 0.0:
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if slope(mid) < 0.0 else (lo, mid)
    return hi


def solve_two_body_distributed(
    problem: TwoBodyProblem, *, delta: float | None, newton: NewtonOptions, line_search: str, state=None
):
    """``fem.two_body.solve_two_body`` on several processes (module docstring); the same ``TwoBodySolution``.
    ``state``: the previous load step's (its friction anchors; its u is not used)."""
    from fenics_contact.fem.two_body import (  # (the serial module calls this one)
        load_vector,
        pair_solution,
        supported_dofs,
        two_body_penalty,
    )

    start = time.perf_counter()
    msh, comm = problem.mesh, problem.comm
    gdim = msh.geometry.dim
    V = fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 1, shape=(gdim,)))
    imap, bs = V.dofmap.index_map, V.dofmap.index_map_bs
    n_owned, N = imap.size_local * bs, imap.size_global * bs
    lo = imap.local_range[0] * bs
    # K with the supports (identity rows and columns), b with their values: K u₀ = b puts u_D on the supports
    u, v, fields = ufl.TrialFunction(V), ufl.TestFunction(V), problem.fields
    K = dolfinx.fem.petsc.assemble_matrix(
        fem.form(ufl.inner(stress(strain(u), fields.lmbda, fields.mu), strain(v)) * ufl.dx)
    )
    K.assemble()
    b = K.createVecLeft()
    b.array[:] = load_vector(problem, V)[:n_owned]
    fixed, values = supported_dofs(problem, V)
    mine = fixed < n_owned
    x_D = b.duplicate()
    x_D.array[fixed[mine]] = values[mine]
    K.zeroRowsColumns((lo + fixed[mine]).astype(PETSc.IntType), 1.0, x_D, b)
    solver = DirectSolver(comm, prefix="two_body_mpi_")
    try:
        solver.set_operator(K)
        u0 = b.duplicate()
        solver.solve(b, u0)
        slave = gathered_surface(V, problem, problem.pair.slave)
        master = gathered_surface(V, problem, problem.pair.master)
        delta = two_body_penalty(problem, slave, master, delta)
        Q = contact_quadrature(
            slave, master, N, bs, problem.pair.quadrature_degree, rule=problem.pair.rule, basis=problem.pair.basis
        )
        free = np.ones(N, dtype=bool)
        free[np.concatenate(comm.allgather(lo + fixed[mine]))] = False
        # the contact rows: B (frictionless), or with friction the relative displacements G (d rows per node)
        rows = Q.B if problem.friction is None else Q.relative
        B_f = (rows @ sp.diags(free.astype(np.float64))).tocsr()
        m = B_f.shape[0]
        B_own = B_f[:, lo : lo + n_owned].tocsc()
        Z = np.zeros((n_owned, m))
        rhs, z = b.duplicate(), b.duplicate()
        for j in range(m):
            rhs.array[:] = B_own[j].toarray().ravel()
            solver.solve(rhs, z)
            Z[:, j] = z.array
        S = comm.allreduce(B_own @ Z, op=MPI.SUM)
        S = 0.5 * (S + S.T)
        s0 = comm.allreduce(rows[:, lo : lo + n_owned] @ u0.array, op=MPI.SUM)
        if problem.friction is not None:  # the stiffness against r_p (as the serial solve: 1 / Σ_j G_pj² / K_jj)
            G0, diagonal = B_own[0::bs], K.getDiagonal()
            stiffness = 1.0 / comm.allreduce(G0.multiply(G0) @ (1.0 / diagonal.array), op=MPI.SUM)
            diagonal.destroy()
        for vec in (rhs, z, x_D, b):
            vec.destroy()
    finally:
        solver.destroy()
        K.destroy()
    if problem.friction is not None:
        parts = (V, Q, (slave, master), u0, Z, S, s0, delta, stiffness)
        return _frictional(problem, parts, newton, state, time.perf_counter() - start)
    s0 -= Q.gap
    W = Q.weights / delta
    mu, s, history = reduced_penalty_newton(S, W, s0, newton, line_search)
    u_h = fem.Function(V, name="u")
    u_h.x.array[:n_owned] = u0.array - Z @ mu
    u_h.x.scatter_forward()
    u0.destroy()
    # the profiles on every rank: u at the contact columns gathered, the contact forces −Bᵀ W s⁺
    u_full = gathered_u(u_h, np.unique(Q.B.indices), N, lo, n_owned, comm)
    force = -(Q.B.T @ (W * np.maximum(s, 0.0)))
    elapsed = time.perf_counter() - start
    return pair_solution(problem, u_h, u_full, force, (slave, master, Q), delta, N, elapsed, history)


def reduced_penalty_newton(
    S: np.ndarray,
    W: np.ndarray,
    s0: np.ndarray,
    newton: NewtonOptions,
    line_search: str,
    start: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, NewtonHistory]:
    """μ = W s(μ)⁺, s(μ) = s₀ − S μ by semismooth Newton with the exact line search (module docstring), from
    ``start`` (default 0): (μ, s(μ), the history); the same on every rank."""
    m = s0.size
    mu = np.zeros(m) if start is None else start.copy()
    s = s0 - S @ mu
    active = s >= 0.0  # touching counts: a body held only by contact (as the serial solve)
    history = NewtonHistory(factorizations=1)
    converged = False
    for _ in range(newton.max_iterations):
        history.residuals.append(float(np.linalg.norm(mu - W * np.maximum(s, 0.0))))
        target = np.linalg.solve(np.eye(m) + (W * active)[:, None] * S, W * active * s0)
        d = target - mu
        t = _line_search(S, W, s0, mu, d) if line_search != "never" else 1.0
        mu = mu + t * d
        s = s0 - S @ mu
        kept = np.array_equal(s > 0.0, active)
        active = s > 0.0
        history.active_sizes.append(int(np.count_nonzero(active)))
        floor = 100.0 * np.finfo(float).eps * float(np.max(W, initial=0.0)) * float(np.linalg.norm(s0))
        residual = float(np.linalg.norm(mu - W * np.maximum(s, 0.0)))
        if (kept and t > 1.0 - 1e-9) or residual <= RTOL * float(np.linalg.norm(mu)) + floor:
            converged = True
            break
    if not converged:
        raise ConvergenceError(
            f"two-body contact (distributed): no converged active set in {newton.max_iterations} Newton steps"
        )
    return mu, s, history


def gathered_u(u_h: fem.Function, columns: np.ndarray, N: int, lo: int, n_owned: int, comm: MPI.Comm) -> np.ndarray:
    """A global DOF vector holding u at ``columns`` (the contact columns) on every rank, zero elsewhere."""
    own = columns[(columns >= lo) & (columns < lo + n_owned)]
    u_full = np.zeros(N)
    for idx, val in comm.allgather((own, u_h.x.array[own - lo])):
        u_full[idx] = val
    return u_full


def _frictional(problem: TwoBodyProblem, parts, newton: NewtonOptions, state, elapsed: float):
    """The frictional contact reduced to the slave nodes' relative displacements (module docstring):
    U = U₀ − S λ(U) (``fem.condensed_friction``), the same on every rank, then u = u₀ − Z λ and the state committed."""
    from fenics_contact.fem.two_body import PairState, pair_solution  # (imports this module)
    from fenics_contact.fem.two_body_friction import PairFriction

    start = time.perf_counter()
    V, Q, (slave, master), u0, Z, S, U0, delta, stiffness = parts
    comm, imap, bs = problem.comm, V.dofmap.index_map, V.dofmap.index_map_bs
    n_owned, N, lo = imap.size_local * bs, imap.size_global * bs, imap.local_range[0] * bs
    friction = PairFriction(problem.friction, Q, delta, stiffness, None if state is None else state.anchor)
    law = CondensedLaw(friction, S)
    history = NewtonHistory(factorizations=1)

    def record(trace) -> None:
        history.residuals.extend(trace.residuals)
        history.active_sizes.extend(trace.active_sizes)

    U = solve_condensed(law, U0, U0.copy(), newton.max_iterations, record=record)
    lam = law.forces(U)[0]
    residual = float(np.linalg.norm(U - U0 + S @ lam))
    size = float(np.linalg.norm(U)) + float(np.linalg.norm(S @ lam))
    if not residual <= RTOL * size + 100.0 * np.finfo(float).eps * float(np.linalg.norm(U0)):
        raise ConvergenceError(f"frictional two-body contact (distributed): the reduced residual {residual:.3e}")
    history.residuals.append(residual)
    u_h = fem.Function(V, name="u")
    u_h.x.array[:n_owned] = u0.array - Z @ lam
    u_h.x.scatter_forward()
    u0.destroy()
    u_full = gathered_u(u_h, np.unique(Q.B.indices), N, lo, n_owned, comm)
    force = -(Q.relative.T @ lam)
    friction.nodal = U.reshape(-1, bs)
    tangential = friction.profile()
    dissipation = friction.commit()
    state = PairState(u_h.x.array[:n_owned].copy(), friction.anchor.copy())
    elapsed += time.perf_counter() - start
    return pair_solution(
        problem, u_h, u_full, force, (slave, master, Q), delta, N, elapsed, history, friction=tangential,
        dissipation=dissipation, state=state,
    )  # fmt: skip
