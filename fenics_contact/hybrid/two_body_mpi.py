"""Algorithm 1 for two bodies on several processes: both subdomains solved in parallel, the pair reduced to the
interface data and the contact rows.

The strips and γ are found collectively (vertex markers summed over the ranks, so that a strip grows across
process boundaries as on one process; γ the facets with a strip cell on one side and a bulk cell on the other,
counted over the ranks).  Ω₁ (the two bulks) and Ω₂ (the two strips) are assembled in parallel on the whole
mesh with the indicator of their cells, the Robin term α_p w_p on their γ rows, identity rows outside them and
on the supports, and factorized once (MUMPS).  Both are linear in their data; Ω₂ is linear but for the contact
forces on its contact rows C (``fem.two_body_mpi``: B, or with friction the slave nodes' relative displacements):

    u₁|γ = r₁ + R₁ g₁₂,      u₂|γ = a₂ + P g₂₁ − Cz λ,      C u₂ = c₀ + Y g₂₁ − S λ,

R₁, P, Y: the responses to unit data at the γ nodes (one back-solve per γ unknown), Cz and S = C K₂⁻¹ Cᵀ the
responses to the contact forces (one back-solve per contact row).  Every rank then holds the same small dense
problem: an evaluation of T solves the reduced contact of the strips (``fem.two_body_mpi.reduced_penalty_newton``,
or ``fem.condensed_friction.solve_condensed``) for the data g₂₁, and the interface Newton method is the serial
one (``hybrid.two_body``) with ∂u₂|γ/∂g₂₁ = P − Cz ∂λ/∂g₂₁ at the converged contact state.  The fixed point is
the serial one.
"""

import logging
import time

import dolfinx.fem.petsc
import dolfinx.la
import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.errors import InputError
from fenics_contact.fem.condensed_friction import CondensedLaw, solve_condensed
from fenics_contact.fem.contact import NewtonHistory, NewtonOptions
from fenics_contact.fem.linalg import DirectSolver
from fenics_contact.fem.mortar import contact_quadrature, surface
from fenics_contact.fem.two_body_mpi import gathered_surface, gathered_u, reduced_penalty_newton
from fenics_contact.hybrid.certificate import Certificate, primal_certificate
from fenics_contact.hybrid.pair_iteration import iterate_pair_interface
from fenics_contact.problem.materials import strain, stress
from fenics_contact.problem.pair import TwoBodyProblem

__all__ = ["distributed_strip", "solve_two_body_hybrid_distributed"]

log = logging.getLogger(__name__)


def _summed(imap, entries: np.ndarray, values, bs: int = 1) -> np.ndarray:
    """Σ over the ranks of ``values`` added at the local ``entries`` of ``imap`` (owned and ghost), on every local
    entry (collective)."""
    vec = dolfinx.la.vector(imap, bs)
    vec.array[:] = 0.0
    np.add.at(vec.array.reshape(-1, bs) if bs > 1 else vec.array, entries, values)
    vec.scatter_reverse(dolfinx.la.InsertMode.add)
    vec.scatter_forward()
    return vec.array.reshape(-1, bs).copy()


def distributed_strip(problem: TwoBodyProblem, V: fem.FunctionSpace, layers: int) -> np.ndarray:
    """Strip marker of the local cells: within ``layers`` vertex-neighbour layers of the two contact surfaces, the
    vertex marks summed over the ranks at every layer (``hybrid.two_body.strip_cells`` on one process)."""
    msh, imap = V.mesh, V.dofmap.index_map
    fdim = msh.topology.dim - 1
    facets = np.concatenate([problem.facet_tags.find(t) for t in (problem.pair.slave, problem.pair.master)])
    blocks = fem.locate_dofs_topological(V, fdim, facets)
    marked = _summed(imap, blocks, 1.0)[:, 0] > 0.0
    cell_blocks = V.dofmap.list
    for _ in range(layers):
        in_strip = marked[cell_blocks].any(axis=1)
        marked = _summed(imap, cell_blocks[in_strip].ravel(), 1.0)[:, 0] > 0.0
    return in_strip


class _Interface:
    """γ on every rank: its free DOFs (global numbers, sorted), vertex weights w_p and α_p, gathered; and per part
    the owned DOFs that a cell of the part touches."""

    def __init__(self, problem: TwoBodyProblem, V: fem.FunctionSpace, in_strip: np.ndarray, fixed, scale: float):
        msh, comm = V.mesh, V.mesh.comm
        tdim, imap, bs = msh.topology.dim, V.dofmap.index_map, V.dofmap.index_map_bs
        n_cells = msh.topology.index_map(tdim).size_local
        cell_blocks = V.dofmap.list[:n_cells]
        strip = in_strip[:n_cells]
        self.inside = [_summed(imap, cell_blocks[part].ravel(), 1.0)[:, 0] > 0.0 for part in (~strip, strip)]
        # γ: the owned facets with cells of both parts (counted over the ranks)
        msh.topology.create_connectivity(tdim, tdim - 1)
        fmap = msh.topology.index_map(tdim - 1)
        c2f = msh.topology.connectivity(tdim, tdim - 1).array.reshape(n_cells, -1)
        sides = np.zeros((n_cells, c2f.shape[1], 2))
        sides[strip, :, 0], sides[~strip, :, 1] = 1.0, 1.0
        counts = _summed(fmap, c2f.ravel(), sides.reshape(-1, 2), bs=2)[: fmap.size_local]
        gamma = np.flatnonzero((counts > 0.0).all(axis=1)).astype(np.int32)
        if comm.allreduce(gamma.size) == 0:
            raise InputError("the strips have no interface γ with the bulks: fewer layers, or a finer mesh")
        surf = surface(V, dmesh.meshtags(msh, tdim - 1, gamma, np.ones(gamma.size, dtype=np.int32)), 1)
        nodes, weights, _ = surf.lumped()
        weight = _summed(imap, nodes, weights)[:, 0]
        E_cells = problem.fields.E.x.array[problem.fields.E.function_space.dofmap.list[:n_cells, 0]]
        total = _summed(imap, cell_blocks.ravel(), np.repeat(E_cells, cell_blocks.shape[1]))[:, 0]
        count = _summed(imap, cell_blocks.ravel(), 1.0)[:, 0]
        h = float(np.median(np.concatenate(comm.allgather(surf.measures))))
        on = np.flatnonzero(weight[: imap.size_local] > 0.0)
        alpha = scale * total[on] / count[on] / np.sqrt((h if tdim == 2 else np.sqrt(h)) * problem.length)
        dofs = (bs * on[:, None] + np.arange(bs)).ravel()
        keep = ~np.isin(dofs, fixed)
        lo = imap.local_range[0] * bs
        parts = comm.allgather((lo + dofs[keep], np.repeat(weight[on], bs)[keep], np.repeat(alpha, bs)[keep]))
        dofs, w, a = (np.concatenate([p[i] for p in parts]) for i in range(3))
        order = np.argsort(dofs)
        self.dofs, self.weights, self.alpha = dofs[order], w[order], a[order]
        N = imap.size_global * bs
        #: γ rows on the owned columns (m × n_owned)
        m, n_owned = self.dofs.size, imap.size_local * bs
        mine = (self.dofs >= lo) & (self.dofs < lo + n_owned)
        self.rows = sp.csr_matrix(
            (np.ones(mine.sum()), (np.flatnonzero(mine), self.dofs[mine] - lo)), shape=(m, n_owned)
        )
        self.N, self.lo = N, lo


class _Part:
    """One subdomain in parallel: a(u, v) on its cells, the Robin term on γ, identity outside it and on the
    supports; factorized once; ``responses`` its owned solutions to unit γ data and to contact rows."""

    def __init__(self, problem, V, cells, inside, iface: _Interface, fixed, values, prefix: str) -> None:
        from fenics_contact.fem.two_body import load_vector  # (the serial module imports this package)

        msh, comm = V.mesh, V.mesh.comm
        imap, bs = V.dofmap.index_map, V.dofmap.index_map_bs
        n_owned, lo = imap.size_local * bs, iface.lo
        chi = fem.Function(fem.functionspace(msh, ("DG", 0)))
        chi.x.array[cells] = 1.0
        chi.x.scatter_forward()
        u, v, fields = ufl.TrialFunction(V), ufl.TestFunction(V), problem.fields
        self.K = dolfinx.fem.petsc.assemble_matrix(
            fem.form(chi * ufl.inner(stress(strain(u), fields.lmbda, fields.mu), strain(v)) * ufl.dx)
        )
        self.K.assemble()
        self.b = self.K.createVecLeft()
        self.b.array[:] = load_vector(problem, V, cells)[:n_owned]
        robin = self.b.duplicate()
        robin.array[:] = iface.rows.T @ (iface.alpha * iface.weights)
        self.K.setDiagonal(robin, addv=PETSc.InsertMode.ADD_VALUES)
        outside = np.flatnonzero(~np.repeat(inside[: imap.size_local], bs))
        mine = fixed < n_owned
        x_D = self.b.duplicate()
        x_D.array[fixed[mine]] = values[mine]
        rows = np.union1d(outside, fixed[mine])
        self.K.zeroRowsColumns((lo + rows).astype(PETSc.IntType), 1.0, x_D, self.b)
        for vec in (robin, x_D):
            vec.destroy()
        self.solver = DirectSolver(comm, prefix=prefix)
        self.solver.set_operator(self.K)
        self.x = self.b.duplicate()
        self.solver.solve(self.b, self.x)
        #: the owned solution to the loads and supports
        self.u0 = self.x.array.copy()

    def solve_columns(self, columns: np.ndarray) -> np.ndarray:
        """K⁻¹ for each column (owned entries) of ``columns`` (n_owned × k)."""
        out = np.zeros(columns.shape)
        rhs = self.b.duplicate()
        for j in range(columns.shape[1]):
            rhs.array[:] = columns[:, j]
            self.solver.solve(rhs, self.x)
            out[:, j] = self.x.array
        rhs.destroy()
        return out

    def destroy(self) -> None:
        self.solver.destroy()
        for obj in (self.K, self.b, self.x):
            obj.destroy()


def _replicated(comm: MPI.Comm, part: np.ndarray) -> np.ndarray:
    """Σ over the ranks of ``part``, bitwise the same on every rank (summed on rank 0, broadcast): the reduced
    problem each rank solves alone then takes the same steps everywhere."""
    return comm.bcast(comm.reduce(part, op=MPI.SUM, root=0), root=0)


class _Reduced:
    """The pair on every rank (module docstring): Ω₁'s r₁, R₁; Ω₂'s a₂, P, Cz, and its contact rows c₀, Y, S; the
    contact of the strips solved for given data g₂₁, with ∂λ/∂g₂₁ at the solution."""

    def __init__(self, problem, iface: _Interface, parts, contact, newton: NewtonOptions, friction) -> None:
        comm = problem.comm
        bulk, strips = parts
        rows, free_rows, gap, self.W = contact
        G = iface.rows
        data = G.T.toarray() * iface.weights  # unit data w_j at the γ DOF j (owned rows)
        self.X1 = bulk.solve_columns(data)
        self.r1 = _replicated(comm, G @ bulk.u0)
        self.R1 = _replicated(comm, G @ self.X1)
        self.X2 = strips.solve_columns(data)
        self.Z = strips.solve_columns(free_rows.T.toarray())
        self.a2 = _replicated(comm, G @ strips.u0)
        self.P = _replicated(comm, G @ self.X2)
        self.Cz = _replicated(comm, G @ self.Z)
        self.c0 = _replicated(comm, rows @ strips.u0) - gap
        self.Y = _replicated(comm, free_rows @ self.X2)
        S = _replicated(comm, free_rows @ self.Z)
        self.S = 0.5 * (S + S.T)
        self.newton, self.friction = newton, friction
        self.law = None if friction is None else CondensedLaw(friction, self.S)
        self.lam = np.zeros(self.c0.size)
        self.U = self.c0.copy()
        self.histories: list[NewtonHistory] = []

    def contact(self, g21: np.ndarray) -> np.ndarray:
        """λ for the data g₂₁ (warm-started from the last one); the history appended."""
        c0 = self.c0 + self.Y @ g21
        if self.law is None:
            self.lam, self.s, history = reduced_penalty_newton(self.S, self.W, c0, self.newton, "always", self.lam)
            self.histories.append(history)
            return self.lam
        history = NewtonHistory(factorizations=1)

        def record(trace) -> None:
            history.residuals.extend(trace.residuals)
            history.active_sizes.extend(trace.active_sizes)

        self.U = solve_condensed(self.law, c0, self.U, self.newton.max_iterations, record=record)
        self.lam = self.law.forces(self.U)[0]
        self.histories.append(history)
        return self.lam

    def dlam(self) -> np.ndarray:
        """∂λ/∂g₂₁ at the last contact state: (I + W_A S)⁻¹ W_A Y, or with friction Λ'(I + S Λ')⁻¹ Y."""
        n = self.c0.size
        if self.law is None:
            WA = self.W * (self.s > 0.0)
            return np.linalg.solve(np.eye(n) + WA[:, None] * self.S, WA[:, None] * self.Y)
        blocks = sla.block_diag(*self.law.forces(self.U)[1])
        return blocks @ np.linalg.solve(np.eye(n) + self.S @ blocks, self.Y)


def solve_two_body_hybrid_distributed(problem: TwoBodyProblem, *, delta, options, newton: NewtonOptions, state):
    """``hybrid.two_body.solve_two_body_hybrid`` on several processes (module docstring); the same result type,
    its fields on the owned DOFs, the profiles and forces on every rank."""
    from fenics_contact.fem.two_body import PairState, supported_dofs, surface_profile, two_body_penalty
    from fenics_contact.fem.two_body_friction import PairFriction
    from fenics_contact.hybrid.two_body import TwoBodyHybridResult  # (imports this module)

    start = time.perf_counter()
    msh, comm = problem.mesh, problem.comm
    V = fem.functionspace(msh, ("Lagrange", 1, (msh.geometry.dim,)))
    imap, bs = V.dofmap.index_map, V.dofmap.index_map_bs
    n_owned = imap.size_local * bs
    fixed, values = supported_dofs(problem, V)
    in_strip = distributed_strip(problem, V, options.layers)
    iface = _Interface(problem, V, in_strip, fixed, options.alpha_scale)
    N, lo = iface.N, iface.lo
    n_cells = msh.topology.index_map(msh.topology.dim).size_local
    strip = np.flatnonzero(in_strip[:n_cells]).astype(np.int32)
    bulk_cells = np.flatnonzero(~in_strip[:n_cells]).astype(np.int32)
    slave = gathered_surface(V, problem, problem.pair.slave)
    master = gathered_surface(V, problem, problem.pair.master)
    delta = two_body_penalty(problem, slave, master, delta)
    Q = contact_quadrature(
        slave, master, N, bs, problem.pair.quadrature_degree, rule=problem.pair.rule, basis=problem.pair.basis
    )
    free = np.ones(N, dtype=bool)
    free[np.concatenate(comm.allgather(lo + fixed[fixed < n_owned]))] = False
    frictional = problem.friction is not None
    rows = (Q.relative if frictional else Q.B)[:, lo : lo + n_owned].tocsr()
    free_rows = (rows @ sp.diags(free[lo : lo + n_owned].astype(np.float64))).tocsr()
    gap = np.zeros(rows.shape[0]) if frictional else Q.gap
    bulk = strips = None
    try:
        bulk = _Part(problem, V, bulk_cells, iface.inside[0], iface, fixed, values, "two_body_hybrid_bulk_")
        strips = _Part(problem, V, strip, iface.inside[1], iface, fixed, values, "two_body_hybrid_strips_")
        friction = None
        if frictional:  # the stiffness against r_p (as the serial strips: 1 / Σ_j G_pj² / K_jj)
            diagonal = strips.K.getDiagonal()
            G0 = free_rows[0::bs]
            stiffness = 1.0 / _replicated(comm, G0.multiply(G0) @ (1.0 / diagonal.array))
            diagonal.destroy()
            friction = PairFriction(problem.friction, Q, delta, stiffness, None if state is None else state.anchor)
        red = _Reduced(problem, iface, (bulk, strips), (rows, free_rows, gap, Q.weights / delta), newton, friction)
        u10, u20 = bulk.u0, strips.u0
    finally:
        for part in (bulk, strips):
            if part is not None:
                part.destroy()
    m, w, alpha = iface.dofs.size, iface.weights, iface.alpha
    residuals: list[float] = []

    def T(g: np.ndarray) -> tuple[np.ndarray, Certificate]:
        u1g = red.r1 + red.R1 @ g[:m]
        u2g = red.a2 + red.P @ g[m:] - red.Cz @ red.contact(g[m:])
        cert = primal_certificate(u1g, u2g, g[:m], g[m:], alpha, w, MPI.COMM_SELF)
        residuals.append(cert.value)
        return np.concatenate([2 * alpha * u2g - g[m:], 2 * alpha * u1g - g[:m]]), cert

    g = np.zeros(2 * m)
    if state is not None and state.interface is not None and state.interface.size == 2 * m:
        g = state.interface.copy()
    outcome = iterate_pair_interface(
        T,
        g,
        alpha,
        lambda: red.R1,
        lambda: red.P - red.Cz @ red.dlam(),
        options,
        name="two bodies, Algorithm 1 (MPI)",
        warn=comm.rank == 0,
    )
    g, converged, newton_steps = outcome.g, outcome.converged, outcome.steps
    lam = red.lam
    u1 = u10 + red.X1 @ g[:m]
    u2 = u20 + red.X2 @ g[m:] - red.Z @ lam
    inside = [np.repeat(part[: imap.size_local], bs).astype(np.float64) for part in iface.inside]
    u = fem.Function(V, name="u")
    u.x.array[:n_owned] = (inside[0] * u1 + inside[1] * u2) / np.maximum(inside[0] + inside[1], 1.0)
    u.x.scatter_forward()
    force = -((Q.relative.T @ lam) if frictional else (Q.B.T @ lam))
    tangential, dissipation = None, 0.0
    if frictional:
        friction.nodal = red.U.reshape(-1, bs)
        tangential = friction.profile()
        dissipation = friction.commit()
    u_full = gathered_u(u, np.unique(Q.B.indices), N, lo, n_owned, comm)
    profiles = (
        surface_profile(u_full, force, slave, Q, slave=True),
        surface_profile(u_full, force, master, Q, slave=False),
    )
    forces = tuple(force.reshape(-1, bs)[surf.nodes].sum(axis=0) for surf in (slave, master))
    next_state = PairState(u.x.array[:n_owned].copy(), friction.anchor.copy() if frictional else None, g.copy())
    elapsed = time.perf_counter() - start
    if comm.rank == 0:
        log.info(
            "two bodies, Algorithm 1 on %d ranks (%s): %d evaluations of T, transmission residual %.3e, %.2f s",
            comm.size,
            options.accel,
            len(residuals),
            residuals[-1],
            elapsed,
        )
        if not converged:
            log.warning("two bodies, Algorithm 1 (MPI): NOT converged (transmission residual %.3e)", residuals[-1])
    return TwoBodyHybridResult(
        u, converged, residuals, red.histories, strip, delta, elapsed, *profiles, forces, tangential, dissipation,
        next_state, newton_steps, outcome.floor, outcome.status == "floor",
    )  # fmt: skip
