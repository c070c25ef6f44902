"""Affine responses of the subdomains on the interface γ and on Γ_C: what the interface Newton needs of Ω₁, Ω₂.

A subdomain problem seen through its interface (``AffinePart``) is

    J x = b + C g − Qᵀ λ,   y = N x + y_off (trace on γ),   s = Q x − gap (contact values on Γ_C),

with J the operator the responses are taken with (Ω₂: J₀, no contact node active; Ω₁: its only operator).
``AffinePart.responses`` back-solves J for the columns of C and Qᵀ (chunked multi-right-hand-side solves
with the factorization it holds, ``block_solve``) and keeps their trace and contact rows: Yc = N J⁻¹C,
Sc = Q J⁻¹C, Yq = N J⁻¹Qᵀ, Sq = Q J⁻¹Qᵀ.  ``PrimalPart`` is a P1 subproblem, ``MixedPart`` an Arnold–Winther one (both
MPI-parallel).  Ω₁'s affine trace response y₁ = T₁ g₁₂ + t₁ is
``FineResponse`` (a fine Ω₁: T₁ by back-solves), ``ProbedResponse`` (a public affine solve, probed column
by column) or ``MatrixResponse`` (given, e.g. by a multiscale Ω₁).
"""

import functools

import dolfinx.fem.petsc
import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.errors import ConvergenceError
from fenics_contact.fem.linalg import DirectSolver
from fenics_contact.fem.mixed_linear import SaddlePointFactorization

__all__ = [
    "ENTRIES_FRACTION",
    "block_solve",
    "AffinePart",
    "PrimalPart",
    "MixedPart",
    "FineResponse",
    "ProbedResponse",
    "MatrixResponse",
]


#: ``MixedPart.responses`` takes the block of J⁻¹ from MUMPS' factors when it spans at most this fraction of the
#: unknowns, else it back-solves: model 3 with the cylinder at h = 1/128 (benchmarks/mixed_interface_response.py),
#: Ω₁'s T₁ on 0.5 % of its unknowns came 6.2× faster than by the back-solves, Ω₂'s J₀ responses on 14.5 % of the
#: strip's 1.9× slower
ENTRIES_FRACTION = 0.05


def block_solve(solver: DirectSolver, B: np.ndarray, comm: MPI.Comm, *projections) -> list[np.ndarray]:
    """[P(A⁻¹ B) for P in projections] for a dense block B (local rows × columns, Fortran order; overwritten when
    the solver is equilibrated) with the factorization ``solver`` holds (one multi-RHS solve,
    ``DirectSolver.mat_solve``; the solution block is never copied whole)."""
    nloc, k = B.shape
    size = ((nloc, PETSc.DECIDE), (PETSc.DECIDE, k))
    Bm = PETSc.Mat().createDense(size, array=np.asfortranarray(B), comm=comm)
    Bm.assemble()
    Xm = PETSc.Mat().createDense(size, comm=comm)
    Xm.setUp()
    Xm.assemble()
    try:
        solver.mat_solve(Bm, Xm)
        X = Xm.getDenseArray(readonly=True)
        finite = bool(np.isfinite(X).all())
        out = [P(X) for P in projections] if comm.allreduce(finite, op=MPI.LAND) else None
    finally:
        Bm.destroy()
        Xm.destroy()
    if out is None:
        raise ConvergenceError(f"{solver.prefix}: multi-RHS back-solve produced non-finite values")
    return out


class AffinePart:
    """A subdomain problem seen through its interface: J x = b + C g − Qᵀλ, trace y = N x, contact s = Q x.

    Subclasses provide the local blocks of C and Qᵀ, the global rows of N X and Q X, the
    body load b, and get/set of the subproblem state.  ``solver`` holds the factorization of
    the operator the responses are taken with (J₀ for Ω₂, the only operator for Ω₁).
    """

    comm: MPI.Comm
    n_g: int  #: global number of interface values
    n_c: int  #: global number of contact rows (0 without contact)
    D: np.ndarray  #: penalty weights (n_c,): λ = D s⁺
    gap: np.ndarray  #: contact offsets (n_c,): s = Q x − gap (the obstacle's gap; 0 for a flush wall)
    trace_offset: np.ndarray | float = 0.0  #: y = N x + trace_offset (mixed: the traction lifting's σ_t n)
    solver: DirectSolver

    # -- provided by subclasses ----------------------------------------------------------
    def data_block(self, j0: int, j1: int) -> np.ndarray: ...
    def contact_block(self, k0: int, k1: int) -> np.ndarray: ...
    def trace_rows(self, X: np.ndarray) -> np.ndarray: ...
    def contact_rows(self, X: np.ndarray) -> np.ndarray: ...
    def body_load(self) -> np.ndarray: ...
    def state(self) -> np.ndarray: ...
    def set_state(self, x: np.ndarray) -> None: ...
    def solve(self, b: np.ndarray, solver: DirectSolver | None = None) -> np.ndarray: ...

    # -- generic -------------------------------------------------------------------------
    def responses(
        self, *, contact: bool, chunk: int, solver: DirectSolver | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(Yc, Sc, Yq, Sq): trace and contact rows of J⁻¹C and J⁻¹Qᵀ (chunked multi-RHS back-solves)."""
        solver = solver or self.solver
        rows = (self.trace_rows, self.contact_rows) if self.n_c else (self.trace_rows,)
        Yc = np.zeros((self.n_g, self.n_g))
        Sc = np.zeros((self.n_c, self.n_g))
        for j0 in range(0, self.n_g, chunk):
            j1 = min(j0 + chunk, self.n_g)
            out = block_solve(solver, self.data_block(j0, j1), self.comm, *rows)
            Yc[:, j0:j1] = out[0]
            if self.n_c:
                Sc[:, j0:j1] = out[1]
        Yq = np.zeros((self.n_g, self.n_c))
        Sq = np.zeros((self.n_c, self.n_c))
        if contact:
            for k0 in range(0, self.n_c, chunk):
                k1 = min(k0 + chunk, self.n_c)
                Yq[:, k0:k1], Sq[:, k0:k1] = block_solve(solver, self.contact_block(k0, k1), self.comm, *rows)
        return Yc, Sc, Yq, Sq

    def load_response(self) -> tuple[np.ndarray, np.ndarray]:
        """(y₀, s₀): trace and contact values of J⁻¹ b (zero data, no contact force); J⁻¹ b is kept while b and
        J's factorization stay (a load path moves the obstacle only: s₀ takes the new normals and gap)."""
        x0 = self.load_solution()[:, None]
        y0 = self.trace_rows(x0)[:, 0] + self.trace_offset
        return y0, (self.contact_rows(x0)[:, 0] - self.gap if self.n_c else np.zeros(0))

    def load_solution(self) -> np.ndarray:
        """J⁻¹ b (local; the kept array, read only), solved again only when b or J's factorization changed; a
        vanishing b (no body force, traction or u_D reaching the subproblem) gives zeros without a solve."""
        b = self._current_body_load()
        kept = getattr(self, "_kept_load", None)
        key = (id(self.solver), getattr(self.solver, "factorizations", None))
        changed = kept is None or kept[0] != key or not (kept[1] is b or np.array_equal(kept[1], b))
        if self.comm.allreduce(changed, op=MPI.LOR):  # (collective: the solve is)
            loaded = self.comm.allreduce(bool(np.any(b)), op=MPI.LOR)
            kept = self._kept_load = (key, b, self._solve_load(b) if loaded else np.zeros_like(b))
        return kept[2]

    def _current_body_load(self) -> np.ndarray:
        """b as ``load_solution`` compares it with the b of its kept solve (a subclass that keeps b returns the kept
        array itself: the same object for the same b)."""
        return self.body_load()

    def _solve_load(self, b: np.ndarray) -> np.ndarray:
        """J⁻¹ b for ``load_solution``."""
        return self.solve(b)

    def refresh(self) -> bool:
        """Re-read the contact geometry (an obstacle may have moved): True when the condensation is stale."""
        return False

    def contact_values(self) -> np.ndarray:
        """s = Q x − gap of the current subproblem state (global)."""
        return self.contact_rows(self.state()[:, None])[:, 0] - self.gap

    def data_free(self) -> np.ndarray:
        """Interface values whose data act on this subproblem (False e.g. at γ nodes on Γ_D)."""
        raise NotImplementedError

    def contact_points(self) -> np.ndarray:
        """Coordinates of the contact unknowns (n_c × gdim, global order): the contact Newton's front handling
        orders them along Γ_C (``fronts.contact_chains``)."""
        raise NotImplementedError


class PrimalPart(AffinePart):
    """A ``fem.primal.PrimalSubproblem`` on part ``part`` of an ``InterfaceSpace`` (MPI-parallel)."""

    def __init__(self, sub, iface, part: int, *, contact: bool, factorize: bool = True) -> None:
        self.sub, self.comm = sub, iface.comm
        comm = self.comm
        V = sub.V
        self.bs = V.dofmap.index_map_bs
        self.nown = V.dofmap.index_map.size_local * self.bs
        offset = comm.exscan(iface.size) or 0
        self.n_g = comm.allreduce(iface.size, op=MPI.SUM)
        probe = dolfinx.fem.Function(V)
        iface.to_part(offset + np.arange(iface.size) + 1.0, part, probe)
        vals = probe.x.array[: self.nown]
        rows = np.flatnonzero(vals > 0.5)
        cols = np.rint(vals[rows]).astype(np.int64) - 1
        iface.to_part(iface.weights, part, probe)
        w = probe.x.array[rows].copy()
        mask = dolfinx.fem.petsc.create_vector(V)
        mask.set(1.0)
        dolfinx.fem.petsc.set_bc(mask, sub.bcs)
        free = mask.getArray(readonly=True)[rows] != 0.0
        mask.destroy()
        self.trace_at, self.trace_index = rows, cols  # owned γ DOFs and their interface value
        self.data_at, self.data_index, self.data_w = rows[free], cols[free], w[free]
        self.n_c = 0
        self.D = self.gap = np.zeros(0)
        if contact:
            nodes, normals, weights, gap = sub.contact_nodes()
            self.c_nodes, self.c_normals = nodes, normals
            self.c_offset = comm.exscan(nodes.size) or 0
            self.n_c = comm.allreduce(nodes.size, op=MPI.SUM)
            self.D = np.concatenate(comm.allgather(weights / sub.delta))
            self.gap = np.concatenate(comm.allgather(gap))
            self._J0 = None
            if factorize:  # J₀ (only the condensed strategy needs it)
                self.solver = DirectSolver(comm, prefix=f"{sub.prefix}j0_", spd=sub.friction is None)
                self._J0 = sub.contact_free_matrix()
                self.solver.set_operator(self._J0)
        else:
            sub.factorize()
            self.solver = sub.solver
        self._b = sub.b.duplicate()
        self._x = sub.b.duplicate()
        self._kept_inverse = None  # (J₀'s factorization count, rows, the block of J₀⁻¹ there, transposed)
        self._kept_body = None  # (the values ``body_load`` was assembled from, b)
        self._kept_components = None  # (J₀'s factorization count, ``component_responses``)
        self._solved = None  # (b or b + C g, g or None) of the last ``solve_for``
        #: condense per displacement component (``component_responses``) where the entries of J₀⁻¹ are taken
        self.by_components = True

    def refresh(self) -> bool:
        if not self.n_c:
            return False
        _, normals, _, gap = self.sub.contact_nodes()
        self.gap = np.concatenate(self.comm.allgather(gap))  # enters online only (s_L)
        moved = self.comm.allreduce(not np.array_equal(normals, self.c_normals), op=MPI.LOR)
        self.c_normals = normals  # ν enters the contact columns: condense again
        return bool(moved)

    def contact_points(self) -> np.ndarray:
        gdim = self.sub.mesh.geometry.dim
        x = self.sub.V.tabulate_dof_coordinates()[self.c_nodes][:, :gdim]
        return np.concatenate(self.comm.allgather(x)).reshape(-1, gdim)

    def data_free(self) -> np.ndarray:
        free = np.zeros(self.n_g, dtype=bool)
        free[np.concatenate(self.comm.allgather(self.data_index))] = True
        return free

    def responses(
        self, *, contact: bool, chunk: int, solver: DirectSolver | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(Yc, Sc, Yq, Sq) as ``AffinePart.responses``; on one process from the block of J⁻¹ on the γ and Γ_C
        unknowns that MUMPS computes from its factors (``DirectSolver.inverse_block``: the values of the
        back-solves without them; benchmarks/results/interface_response.md)."""
        solver = solver or self.solver
        if not solver.has_inverse_entries() or not self.sub.symmetric:  # (MUMPS gives entries of A⁻ᵀ)
            return super().responses(contact=contact, chunk=chunk, solver=solver)
        contact_at = (self.bs * self.c_nodes[:, None] + np.arange(self.bs)).ravel() if self.n_c else self.trace_at[:0]
        rows = np.unique(np.concatenate([self.trace_at, self.data_at, contact_at]))
        at = functools.partial(np.searchsorted, rows)  # position among ``rows`` of a DOF
        r_idx, c_idx, v = [at(self.data_at)], [self.data_index], [self.data_w]  # C
        if contact:
            for c in range(self.bs):  # Qᵀ
                r_idx.append(at(self.bs * self.c_nodes + c))
                c_idx.append(self.n_g + np.arange(self.n_c))
                v.append(self.c_normals[:, c])
        shape = (rows.size, self.n_g + (self.n_c if contact else 0))
        B = sp.csr_matrix((np.concatenate(v), (np.concatenate(r_idx), np.concatenate(c_idx))), shape=shape)
        # the rows ``rows`` of J⁻¹ [C Qᵀ] = ((J⁻¹)ᵀ[rows, rows]ᵀ B)ᵀ; B has one or ``bs`` entries per column
        X = np.asarray((B.T @ self._inverse_block_transposed(solver, rows)).T)
        Y = np.zeros((self.n_g, B.shape[1]))
        Y[self.trace_index] = X[at(self.trace_at)]
        S = (
            sum(self.c_normals[:, c, None] * X[at(self.bs * self.c_nodes + c)] for c in range(self.bs))
            if self.n_c
            else np.zeros((0, B.shape[1]))
        )
        if not contact:
            return Y, S, np.zeros((self.n_g, self.n_c)), np.zeros((self.n_c, self.n_c))
        return Y[:, : self.n_g], S[:, : self.n_g], Y[:, self.n_g :], S[:, self.n_g :]

    def contact_normals(self) -> np.ndarray:
        """The outward normals ν of the Γ_C unknowns (n_c × bs, global order): Q = Σ_k diag(ν_k) E_kᵀ."""
        return np.concatenate(self.comm.allgather(self.c_normals)).reshape(-1, self.bs)

    def component_responses(self) -> tuple | None:
        """J₀'s responses with the contact columns and rows taken per displacement component (E_k: the unit vectors
        of component k at the Γ_C nodes, Q = Σ_k diag(ν_k) E_kᵀ): (Yc, [E_kᵀ J₀⁻¹C]_k, [N J₀⁻¹E_k]_k,
        [[E_kᵀ J₀⁻¹E_l]_l]_k), independent of the normals ν: a moving obstacle recombines them without solves
        (``CondensedInterface``).  From the block of J₀⁻¹ that ``responses`` takes (one process, MUMPS' entries,
        J₀ symmetric), kept while J₀'s factorization is; None otherwise (the condensation then takes
        ``responses`` whenever ν moves) or when ``by_components`` is off."""
        solver = self.solver if self.n_c else None
        if solver is None or not (self.by_components and solver.has_inverse_entries() and self.sub.symmetric):
            return None
        kept = self._kept_components
        if kept is not None and kept[0] == solver.factorizations:
            return kept[1]
        contact_at = [self.bs * self.c_nodes + k for k in range(self.bs)]
        rows = np.unique(np.concatenate([self.trace_at, self.data_at, *contact_at]))
        at = functools.partial(np.searchsorted, rows)
        inv_t = self._inverse_block_transposed(solver, rows)  # (J₀⁻¹[rows, rows])ᵀ
        C = sp.csr_matrix((self.data_w, (at(self.data_at), self.data_index)), shape=(rows.size, self.n_g))
        X = np.asarray((C.T @ inv_t).T)  # the rows ``rows`` of J₀⁻¹ C
        Yc = np.zeros((self.n_g, self.n_g))
        Yc[self.trace_index] = X[at(self.trace_at)]
        Sc = [X[at(c)] for c in contact_at]
        cols = [inv_t[at(c)].T for c in contact_at]  # J₀⁻¹[rows, c] = J₀⁻¹ E_k on ``rows``
        Yq = []
        for col in cols:
            y = np.zeros((self.n_g, self.n_c))
            y[self.trace_index] = col[at(self.trace_at)]
            Yq.append(y)
        Sq = [[cols[l][at(contact_at[k])] for l in range(self.bs)] for k in range(self.bs)]
        out = (Yc, Sc, Yq, Sq)
        self._kept_components = (solver.factorizations, out)
        return out

    def _inverse_block_transposed(self, solver: DirectSolver, rows: np.ndarray) -> np.ndarray:
        """((J⁻¹)[rows][:, rows])ᵀ, C-contiguous; J₀'s is kept (it is factorized once, and the rows stay when the
        obstacle moves: only the normals in Qᵀ change, so a refreshed condensation costs products, no MUMPS
        call).  J is symmetric here: MUMPS computes one triangle, swept along the rows' nodes (``_sweep``), and the
        block, exactly symmetric, is its own transpose."""
        if solver is not getattr(self, "solver", None):  # (no J₀ without ``factorize``)
            return solver.inverse_block(rows, sweep=self._sweep(rows))
        kept = self._kept_inverse
        if kept is None or kept[0] != solver.factorizations or not np.array_equal(kept[1], rows):
            block = solver.inverse_block(rows, sweep=self._sweep(rows))
            self._kept_inverse = kept = (solver.factorizations, rows, block)
        return kept[2]

    def _sweep(self, rows: np.ndarray) -> np.ndarray:
        """The coordinate of the rows' nodes in which they spread most: the order in which ``inverse_block`` takes
        one triangle of a symmetric block (γ and Γ_C are lines in 2D: the position along them; the entries of a
        column from the rows ahead of it, about half the pruned substitutions)."""
        x = self.sub.V.tabulate_dof_coordinates()[np.asarray(rows) // self.bs]
        return x[:, int(np.argmax(np.ptp(x, axis=0)))]

    def data_block(self, j0: int, j1: int) -> np.ndarray:
        B = np.zeros((self.nown, j1 - j0), order="F")
        sel = (self.data_index >= j0) & (self.data_index < j1)
        B[self.data_at[sel], self.data_index[sel] - j0] = self.data_w[sel]
        return B

    def contact_block(self, k0: int, k1: int) -> np.ndarray:
        B = np.zeros((self.nown, k1 - k0), order="F")
        k = self.c_offset + np.arange(self.c_nodes.size)
        sel = (k >= k0) & (k < k1)
        for c in range(self.bs):
            B[self.bs * self.c_nodes[sel] + c, k[sel] - k0] = self.c_normals[sel, c]
        return B

    def trace_rows(self, X: np.ndarray) -> np.ndarray:
        parts = self.comm.allgather((self.trace_index, X[self.trace_at]))
        Y = np.zeros((self.n_g, X.shape[1]))
        for idx, vals in parts:
            Y[idx] = vals
        return Y

    def contact_rows(self, X: np.ndarray) -> np.ndarray:
        s = sum(self.c_normals[:, c, None] * X[self.bs * self.c_nodes + c] for c in range(self.bs))
        return np.concatenate(self.comm.allgather(np.asarray(s).reshape(-1, X.shape[1])), axis=0)

    def body_load(self) -> np.ndarray:
        """b (local), assembled again only when the values it depends on changed (``body_load_inputs``: a load
        path moves the obstacle, which b does not see)."""
        return self._current_body_load().copy()

    def _current_body_load(self) -> np.ndarray:
        """The kept b (read only: the same array while its inputs stay), assembled again when they changed."""
        inputs = self.sub.body_load_inputs()
        kept = self._kept_body
        same = kept is not None and len(kept[0]) == len(inputs) and all(map(np.array_equal, kept[0], inputs))
        if self.comm.allreduce(not same, op=MPI.LOR):  # (collective: the assembly is)
            b = self.sub.body_load(self._b).getArray(readonly=True).copy()
            b.flags.writeable = False
            self._kept_body = kept = ([np.array(a, copy=True) for a in inputs], b)
        return kept[1]

    def _solve_load(self, b: np.ndarray) -> np.ndarray:
        """J⁻¹ b; on one process with MUMPS' sparse right-hand side (``DirectSolver.solve_sparse``): the forward
        elimination skips the fronts off b's support (a body force on part of the body, u_D on Γ_D)."""
        if isinstance(self.solver, DirectSolver) and self.solver.sequential_mumps():
            rows = np.flatnonzero(b)
            return self.solver.solve_sparse(rows, b[rows])
        return self.solve(b)

    def state(self) -> np.ndarray:
        return self.sub.u.x.petsc_vec.getArray(readonly=True).copy()

    def set_state(self, x: np.ndarray) -> None:
        self.sub.u.x.petsc_vec.getArray()[:] = x
        self.sub.u.x.scatter_forward()

    def solve(self, b: np.ndarray, solver: DirectSolver | None = None) -> np.ndarray:
        self._b.getArray()[:] = b
        (solver or self.solver).solve(self._b, self._x)
        return self._x.getArray(readonly=True).copy()

    def rhs(self, g: np.ndarray, lam: np.ndarray) -> np.ndarray:
        """b + C g − Qᵀ λ (local) for global data g and contact forces λ."""
        r = self.body_load()
        r[self.data_at] += self.data_w * g[self.data_index]
        if self.n_c:
            mine = lam[self.c_offset : self.c_offset + self.c_nodes.size]
            for c in range(self.bs):
                r[self.bs * self.c_nodes + c] -= self.c_normals[:, c] * mine
        return r

    def solve_for(self, g: np.ndarray) -> None:
        """Set the subproblem's state to its solution for global data g without contact forces, x = J⁻¹(b + C g):
        no assembly, one back-solve.  For the linear Ω₁, whose J is its only operator (``FineResponse``).  On one
        process x = J⁻¹b + J⁻¹(C g), the first kept (``load_solution``), the second a back-solve whose right-hand
        side vanishes but on the γ unknowns (``DirectSolver.solve_sparse``: MUMPS skips the forward elimination
        elsewhere, benchmarks/results/load_step_cost.md); otherwise one back-solve of the kept body load plus the
        data."""
        if self.n_c:
            raise ValueError("solve_for solves the subproblem without contact (its linear operator J)")
        if isinstance(self.solver, DirectSolver) and self.solver.sequential_mumps():
            x = self.solver.solve_sparse(self.data_at, self.data_w * g[self.data_index])
            x += self.load_solution()
            self._solved = (self._kept_load[1], g)
            self.set_state(x)
            return
        rhs = self.rhs(g, np.zeros(0))
        self._solved = (rhs, None)
        self.set_state(self.solve(rhs))

    def solved_rhs(self) -> np.ndarray:
        """b + C g (local, a new array) of the last ``solve_for``: the right-hand side its state solves."""
        b, g = self._solved
        r = b.copy()
        if g is not None:
            r[self.data_at] += self.data_w * g[self.data_index]
        return r

    def destroy(self) -> None:
        for obj in (self._b, self._x):
            obj.destroy()
        if self.n_c and self._J0 is not None:
            self._J0.destroy()
            self.solver.destroy()


class MixedPart(AffinePart):
    """A ``fem.mixed.MixedSubproblem`` (serial or distributed); ``perm``: its interface value k is canonical value
    perm[k] (serial only).

    Under MPI the state, the data and contact blocks and the solves are this rank's owned entries (the layout
    of the subproblem's saddle-point factorization: owned stresses, then owned displacements), the trace and
    contact rows global (gathered from the blocks of N and Q, ``fem.distributed.DistributedMatrix``).
    J₀ is factorized equilibrated like the subproblem's own Jacobians (D J₀ D, D = diag(s I_σ, I_u/s) with the
    subproblem's ``stress_scale`` s), so every solver here returns solutions of the unscaled systems."""

    def __init__(self, sub, *, perm: np.ndarray | None, contact: bool, factorize: bool = True) -> None:
        self.sub, self.comm = sub, sub.mesh.comm
        self.serial = self.comm.size == 1
        if not (self.serial or perm is None or np.array_equal(perm, np.arange(perm.size))):
            raise ValueError("a distributed MixedPart takes its data in the canonical order (perm=None)")
        self.inv = np.arange(sub.C.shape[1]) if perm is None else np.argsort(perm)
        self.C = sub.C[:, self.inv].tocsc()  # data (canonical order) → stress rows (owned rows)
        self.n_g = self.C.shape[1]
        self.ns, self.nown = sub.n_sigma, sub.n_sigma + sub.n_u
        self.n_c = sub.q_points.shape[0] if contact else 0
        self.D = sub.q_weights / sub.epsilon if contact else np.zeros(0)
        self.gap = -sub.q0 if contact else np.zeros(0)  # σ_c = Q c + q0 (q0: the traction lifting's)
        self.trace_offset = self._gathered(sub.n0)[self.inv] if sub.beta is not None else 0.0  # σn = N c + n0
        self._J0 = None
        if self.serial:
            self.N = sub.N[self.inv].tocsr()  # stress → trace (canonical order)
            if contact:
                self.QT = sub.Q.T.tocsc()
        if contact and factorize:
            self._J0 = SaddlePointFactorization(
                self.comm,
                f"{sub.prefix}j0_",
                self.ns,
                sub.assembly,
                None,
                contact=False,
                has_operators=True,
                scale=sub.stress_scale,
            )
            self._J0.factorize_for(None)
            self.solver = self._J0.solver
        elif not contact:
            sub._factorize_for(None)
            self.solver = sub.solver
        self._b = PETSc.Vec().createMPI((self.nown, PETSc.DECIDE), comm=self.comm)
        self._x = self._b.duplicate()

    def responses(
        self, *, contact: bool, chunk: int, solver: DirectSolver | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(Yc, Sc, Yq, Sq) as ``AffinePart.responses``; on one process, when the stress unknowns that C, Qᵀ, N
        and Q touch are few (``ENTRIES_FRACTION``), from the block of J⁻¹ on them that MUMPS computes from its
        factors (``DirectSolver.inverse_block``, J symmetric: the values of the back-solves without them)."""
        solver = solver or self.solver
        if not (self.serial and solver.has_inverse_entries()):
            return super().responses(contact=contact, chunk=chunk, solver=solver)
        Q = self.sub.Q.tocsc() if self.n_c else sp.csc_matrix((0, self.ns))
        N = self.N.tocsc()
        B = sp.hstack([self.C, self.QT]).tocsr() if contact and self.n_c else self.C.tocsr()
        touched = np.diff(B.indptr) > 0
        touched |= np.diff(N.indptr) > 0
        touched |= np.diff(Q.indptr) > 0
        rows = np.flatnonzero(touched)
        if rows.size > ENTRIES_FRACTION * self.nown:
            return super().responses(contact=contact, chunk=chunk, solver=solver)
        X = solver.inverse_block(rows) @ B[rows].toarray()  # the rows ``rows`` of J⁻¹ [C Qᵀ]
        Y, S = N[:, rows] @ X, Q[:, rows] @ X
        if not (contact and self.n_c):
            return Y, S, np.zeros((self.n_g, self.n_c)), np.zeros((self.n_c, self.n_c))
        return Y[:, : self.n_g], S[:, : self.n_g], Y[:, self.n_g :], S[:, self.n_g :]

    def _gathered(self, block: np.ndarray) -> np.ndarray:
        """The global array from every rank's block (rank order)."""
        return block if self.serial else np.concatenate(self.comm.allgather(np.asarray(block)))

    def data_free(self) -> np.ndarray:
        free = np.diff(self.C.indptr) > 0
        return free if self.serial else np.any(self.comm.allgather(free), axis=0)

    def contact_points(self) -> np.ndarray:
        return np.asarray(self.sub.q_points)[:, : self.sub.mesh.geometry.dim]

    def data_block(self, j0: int, j1: int) -> np.ndarray:
        B = np.zeros((self.nown, j1 - j0), order="F")
        B[: self.ns] = self.C[:, j0:j1].toarray()
        return B

    def contact_block(self, k0: int, k1: int) -> np.ndarray:
        B = np.zeros((self.nown, k1 - k0), order="F")
        if self.serial:
            B[: self.ns] = self.QT[:, k0:k1].toarray()
            return B
        nodes, e = self.sub.contact_nodes, np.zeros(self.n_c)
        for j, k in enumerate(range(k0, k1)):  # Qᵀ e_k, column by column (collective)
            e[k] = 1.0
            B[: self.ns, j] = nodes.Q.T @ nodes.block(e)
            e[k] = 0.0
        return B

    def trace_rows(self, X: np.ndarray) -> np.ndarray:
        if self.serial:
            return self.N @ X[: self.ns]
        return self._gathered_rows(self.sub.interface.N, X)[self.inv]

    def contact_rows(self, X: np.ndarray) -> np.ndarray:
        if self.serial:
            return self.sub.Q @ X[: self.ns]
        return self._gathered_rows(self.sub.contact_nodes.Q, X)

    def _gathered_rows(self, op, X: np.ndarray) -> np.ndarray:
        """op X[:ns] with all ranks' row blocks of the distributed ``op``, column by column (collective)."""
        k = X.shape[1]
        block = np.zeros((op.local_shape[0], k))
        for j in range(k):
            block[:, j] = op @ X[: self.ns, j]
        return np.concatenate(self.comm.allgather(block), axis=0)

    def body_load(self) -> np.ndarray:
        b = np.zeros(self.nown)
        b[: self.ns] = self.sub._stress_load(None)  # traction lifting, ∫_ΓD u_D·τn, gap term ∫_ΓC g τ_c
        b[self.ns :] = self.sub.G
        return b

    def state(self) -> np.ndarray:
        return np.concatenate([self.sub.c, self.sub.u])

    def set_state(self, x: np.ndarray) -> None:
        self.sub.set_state(x[: self.ns], x[self.ns :])

    def solve(self, b: np.ndarray, solver: DirectSolver | None = None) -> np.ndarray:
        self._b.array[:] = b
        (solver or self.solver).solve(self._b, self._x)
        return self._x.array.copy()

    def rhs(self, g: np.ndarray, lam: np.ndarray) -> np.ndarray:
        r = self.body_load()
        r[: self.ns] += self.C @ g
        if self.n_c:
            if self.serial:
                r[: self.ns] -= self.QT @ lam
            else:
                nodes = self.sub.contact_nodes
                r[: self.ns] -= nodes.Q.T @ nodes.block(lam)
        return r

    def destroy(self) -> None:
        for obj in (self._b, self._x):
            obj.destroy()
        if self._J0 is not None:
            self._J0.destroy()


class FineResponse:
    """Fine Ω₁: T₁ = N₁ J₁⁻¹ C₁ by one multi-RHS back-solve of its factorization; t₁ by one solve."""

    def __init__(self, part: AffinePart, *, chunk: int) -> None:
        self.part = part
        self.T = part.responses(contact=False, chunk=chunk)[0]

    def load(self) -> np.ndarray:
        return self.part.load_response()[0]


class ProbedResponse:
    """Ω₁ through a public affine solve y₁(g) (e.g. ``cem.Omega1Multiscale``): T₁ e_j = y₁(e_j) − y₁(0)."""

    def __init__(self, trace_of, n_g: int) -> None:
        self.trace_of = trace_of
        y0 = trace_of(np.zeros(n_g))
        self.T = np.column_stack([trace_of(e) - y0 for e in np.eye(n_g)]) if n_g else np.zeros((0, 0))

    def load(self) -> np.ndarray:
        return self.trace_of(np.zeros(self.T.shape[0]))


class MatrixResponse:
    """Ω₁ given as y₁ = T g + t₀ (``multiscale.mixed_cem.InterfaceResponse``)."""

    def __init__(self, T: np.ndarray, t0: np.ndarray) -> None:
        self.T, self.t0 = T, t0

    def load(self) -> np.ndarray:
        return self.t0
