"""Interface Newton: solve the hybrid fixed point g = T(g) by semismooth Newton (METHOD §9).

Every algorithm exchanges Robin data g = (g₁₂, g₂₁) on γ through traces y_i
(u_i on γ for the primal methods, σ_in_i for the mixed ones):

    T(g) = (a ⊙ y₂(g₂₁) + b g₂₁,  a ⊙ y₁(g₁₂) + b g₁₂)       (primal a = 2α, b = −1; mixed a = −2β, b = 1).

Ω₁ is linear, so y₁ = T₁ g₁₂ + t₁ with a dense n_γ × n_γ matrix T₁ computed once
(offline: fine Ω₁, one factorization and one back-solve per interface unknown;
multiscale Ω₁, its precomputed affine map).  Ω₂ is linear except for the penalty
on Γ_C: with the contact values s = Q x (u_c at the Γ_C nodes, or σ_c at the
Gauss–Lobatto nodes) and the penalty force λ = D s⁺ (D = w/δ or w/ε),

    J₀ x = b₂ + C₂ g₂₁ − Qᵀ λ,   y₂ = N₂ x,

where J₀ is the Ω₂ operator with no contact node active.  Eliminating x and g
(everything but λ enters linearly) leaves an equation on the Γ_C unknowns alone,

    s = s_L − M D s⁺,

with M (n_c × n_c, the contact compliance of the glued problem) and the
load term s_L.  Two strategies solve it (``InterfaceNewtonOptions.strategy``):

* ``"condensed"`` (default): offline, factorize J₀ and back-solve it for the
  n_γ data and n_c contact columns (Yc, Sc, Yq, Sq), form the interface matrix
  K = I − P₁P₂ (P₁ = a⊙T₁ + b, P₂ = a⊙Yc + b) and M.  Online: one J₀ back-solve
  and one Ω₁ load solve for s_L, then a semismooth Newton on the contact forces μ
  (dense, size n_c; with Algorithm 1 the condensation is exact and its active
  sets are those of the monolithic semismooth Newton from its second step on),
  then the data g and one application of T with the real subdomain solvers:
  Ω₁ is solved, Ω₂'s state (one more J₀ back-solve) is checked against its own
  equations with the acceptance test of its Newton solver and solved only if
  that fails.  The transmission residual of that pair certifies the result.
  Should it be above the tolerance (round-off for extreme α, β or contrast),
  Newton steps on F(g) = g − T(g) follow, with Ω₂'s generalized Jacobian from
  the same offline data (Woodbury on J₀, no factorization), or, when such a step
  does not reduce the residual, exactly by back-solves with Ω₂'s own factorization.
* ``"interface"``: Newton on F(g) = g − T(g) from g⁰, each step an application
  of T (the Ω₂ semismooth Newton) and Ω₂'s generalized Jacobian by n_γ
  back-solves with the factorization Ω₂ keeps; a backtracking line search on
  ‖F‖ globalizes it.  It needs no J₀ but n_γ back-solves per step.

Both land on the fixed point of the Robin iteration (the same equations). Where a
near-rigid body rests on Γ_C (a channel 10⁶ times stiffer than its surroundings) the
plain semismooth Newton frees one node per step, and in the mixed method fronts in
the bulk creep one Gauss–Lobatto point per step. By default
(``InterfaceNewtonOptions(front_window=8)``) the contact Newton therefore resolves
every front of its next active set locally (``LocalFronts``, a nonlinear
elimination): the contact equations on the 8 Γ_C unknowns on either side of it, with
the forces elsewhere held, are solved exactly (small dense solves) and the next set
takes their active sets. With ``fronts=True`` it instead extrapolates the fronts along
Γ_C where a front moved the same way twice (``FrontExtrapolation``, an earlier
attempt). Every set solved on all of Γ_C is a step, and a set is
accepted only when the solve on it reproduces it. The contact Newton takes full
steps until an active set recurs and from then on minimizes, along each Newton
direction, ψ = ½ μᵀMμ + ½ Σ D (s⁺)² with s = s_L − Mμ (exact line search on a
piecewise-linear derivative): ψ is the convex energy of the glued problem when M is
symmetric (Algorithms 1, 2), so no cycle can recur. A Newton method that fails (no
convergence in ``max_steps``, a singular condensed system) raises ConvergenceError;
a pair whose transmission residual stays above the tolerance ends with ``converged =
False``.
"""

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
from mpi4py import MPI
from petsc4py import PETSc

import dolfinx.fem.petsc

from fenics_contact.errors import ConvergenceError
from fenics_contact.fem.linalg import DirectSolver, scipy_to_petsc
from fenics_contact.hybrid.iteration import (
    COLLAPSE,
    IterationHistory,
    IterationOptions,
    InterfaceNewtonOptions,
    data_norm,
    evaluate,
    zero_is_the_fixed_point,
)

__all__ = [
    "AffinePart",
    "PrimalPart",
    "MixedPart",
    "FineResponse",
    "ProbedResponse",
    "MatrixResponse",
    "InterfaceProblem",
    "CondensedInterface",
    "ContactNewtonHistory",
    "FrontExtrapolation",
    "LocalFronts",
    "contact_chains",
    "contact_newton",
    "contact_solve",
    "newton_iterate",
]

log = logging.getLogger(__name__)


# ---------------------------------------------------------------------------------------
# multi-right-hand-side solves
# ---------------------------------------------------------------------------------------
def block_solve(ksp: PETSc.KSP, B: np.ndarray, comm: MPI.Comm, *projections) -> list[np.ndarray]:
    """[P(A⁻¹ B) for P in projections] for a dense block B (local rows × columns, Fortran order) with the
    factorization held by ``ksp`` (one multi-RHS solve; the solution block is never copied whole)."""
    nloc, k = B.shape
    size = ((nloc, PETSc.DECIDE), (PETSc.DECIDE, k))
    Bm = PETSc.Mat().createDense(size, array=np.asfortranarray(B), comm=comm)
    Bm.assemble()
    Xm = PETSc.Mat().createDense(size, comm=comm)
    Xm.setUp()
    Xm.assemble()
    try:
        ksp.matSolve(Bm, Xm)
        X = Xm.getDenseArray(readonly=True)
        finite = bool(np.isfinite(X).all())
        out = [P(X) for P in projections] if comm.allreduce(finite, op=MPI.LAND) else None
    finally:
        Bm.destroy()
        Xm.destroy()
    if out is None:
        raise ConvergenceError(f"{ksp.getOptionsPrefix()}: multi-RHS back-solve produced non-finite values")
    return out


# ---------------------------------------------------------------------------------------
# the affine pieces of one subdomain
# ---------------------------------------------------------------------------------------
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
    def responses(self, *, contact: bool, chunk: int, solver: DirectSolver | None = None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(Yc, Sc, Yq, Sq): trace and contact rows of J⁻¹C and J⁻¹Qᵀ (chunked multi-RHS back-solves)."""
        ksp = (solver or self.solver).ksp
        rows = (self.trace_rows, self.contact_rows) if self.n_c else (self.trace_rows,)
        Yc = np.zeros((self.n_g, self.n_g))
        Sc = np.zeros((self.n_c, self.n_g))
        for j0 in range(0, self.n_g, chunk):
            j1 = min(j0 + chunk, self.n_g)
            out = block_solve(ksp, self.data_block(j0, j1), self.comm, *rows)
            Yc[:, j0:j1] = out[0]
            if self.n_c:
                Sc[:, j0:j1] = out[1]
        Yq = np.zeros((self.n_g, self.n_c))
        Sq = np.zeros((self.n_c, self.n_c))
        if contact:
            for k0 in range(0, self.n_c, chunk):
                k1 = min(k0 + chunk, self.n_c)
                Yq[:, k0:k1], Sq[:, k0:k1] = block_solve(ksp, self.contact_block(k0, k1), self.comm, *rows)
        return Yc, Sc, Yq, Sq

    def load_response(self) -> tuple[np.ndarray, np.ndarray]:
        """(y₀, s₀): trace and contact values of J⁻¹ b (zero data, no contact force)."""
        x0 = self.solve(self.body_load())[:, None]
        y0 = self.trace_rows(x0)[:, 0] + self.trace_offset
        return y0, (self.contact_rows(x0)[:, 0] - self.gap if self.n_c else np.zeros(0))

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
        """Coordinates of the contact unknowns (n_c × gdim, global order): the front extrapolation orders them
        along Γ_C (``contact_chains``)."""
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
                self.solver = DirectSolver(comm, prefix=f"{sub.prefix}j0_")
                self._J0 = sub.contact_free_matrix()
                self.solver.set_operator(self._J0)
        else:
            sub.factorize()
            self.solver = sub.solver
        self._b = sub.b.duplicate()
        self._x = sub.b.duplicate()

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
        return self.sub.body_load(self._b).getArray(readonly=True).copy()

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

    def destroy(self) -> None:
        for obj in (self._b, self._x):
            obj.destroy()
        if self.n_c and self._J0 is not None:
            self._J0.destroy()
            self.solver.destroy()


class MixedPart(AffinePart):
    """A ``fem.mixed.MixedSubproblem`` (serial); ``perm``: its interface value k is canonical value perm[k]."""

    def __init__(self, sub, *, perm: np.ndarray | None, contact: bool, factorize: bool = True) -> None:
        import scipy.sparse as sp

        from fenics_contact.fem.mixed_linear import MIXED_SOLVER_OPTIONS

        self.sub, self.comm = sub, sub.mesh.comm
        inv = np.arange(sub.C.shape[1]) if perm is None else np.argsort(perm)
        self.C = sub.C[:, inv].tocsc()  # data (canonical order) → stress rows
        self.N = sub.N[inv].tocsr()  # stress → trace (canonical order)
        self.n_g = self.C.shape[1]
        self.ns, self.nown = sub.n_sigma, sub.n_sigma + sub.n_u
        self.n_c = sub.Q.shape[0] if contact else 0
        self.D = sub.q_weights / sub.epsilon if contact else np.zeros(0)
        self.gap = -sub.q0 if contact else np.zeros(0)  # σ_c = Q c + q0 (q0: the traction lifting's)
        self.trace_offset = sub.n0[inv] if sub.beta is not None else 0.0  # σn = N c + n0
        self._J0 = None
        if contact:
            self.QT = sub.Q.T.tocsc()
        if contact and factorize:
            saddle = sp.bmat([[sub.Kt, sub.B.T], [sub.B, None]], format="csr")
            self._J0 = scipy_to_petsc(saddle, self.comm)
            self.solver = DirectSolver(self.comm, prefix=f"{sub.prefix}j0_", options=MIXED_SOLVER_OPTIONS)
            self.solver.set_operator(self._J0)
        elif not contact:
            sub._factorize_for(None)
            self.solver = sub.solver
        self._b = PETSc.Vec().createSeq(self.nown, comm=self.comm)
        self._x = self._b.duplicate()

    def data_free(self) -> np.ndarray:
        return np.diff(self.C.indptr) > 0

    def contact_points(self) -> np.ndarray:
        return np.asarray(self.sub.q_points)[:, : self.sub.mesh.geometry.dim]

    def data_block(self, j0: int, j1: int) -> np.ndarray:
        B = np.zeros((self.nown, j1 - j0), order="F")
        B[: self.ns] = self.C[:, j0:j1].toarray()
        return B

    def contact_block(self, k0: int, k1: int) -> np.ndarray:
        B = np.zeros((self.nown, k1 - k0), order="F")
        B[: self.ns] = self.QT[:, k0:k1].toarray()
        return B

    def trace_rows(self, X: np.ndarray) -> np.ndarray:
        return self.N @ X[: self.ns]

    def contact_rows(self, X: np.ndarray) -> np.ndarray:
        return self.sub.Q @ X[: self.ns]

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
            r[: self.ns] -= self.QT @ lam
        return r

    def destroy(self) -> None:
        for obj in (self._b, self._x):
            obj.destroy()
        if self._J0 is not None:
            self._J0.destroy()
            self.solver.destroy()


# ---------------------------------------------------------------------------------------
# the affine Ω₁ response y₁ = T₁ g₁₂ + t₁
# ---------------------------------------------------------------------------------------
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


@dataclass(slots=True)
class InterfaceProblem:
    """What the Newton method needs from a step: Ω₁ response, Ω₂ pieces, the update y ↦ a⊙y + b g.

    ``gather``/``local`` map one half of the step's data (g₁₂ or g₂₁, local owned values) to the
    global numbering and back; ``condensed`` caches the offline condensation.
    """

    omega1: object
    omega2: AffinePart
    a: np.ndarray
    b: float
    gather: object
    local: object
    options: InterfaceNewtonOptions
    condensed: "CondensedInterface | None" = None
    free: np.ndarray = None  #: interface values whose data act on a subdomain (others stay 0: γ ∩ Γ_D)

    def __post_init__(self) -> None:
        if self.free is None:
            self.free = self.omega2.data_free() | (np.abs(self.omega1.T).sum(axis=0) > 0.0)

    def halves(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Global (g₁₂, g₂₁) from the step's local data."""
        n = g.size // 2
        return self.gather(g[:n]), self.gather(g[n:])

    def data(self, g12: np.ndarray, g21: np.ndarray) -> np.ndarray:
        """The step's local data from global halves."""
        return np.concatenate([self.local(g12), self.local(g21)])

    def step_direction(self, F12: np.ndarray, F21: np.ndarray, D2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Newton direction of F(g) = g − T(g) with ∂y₂/∂g₂₁ = D2: (I − P₁P₂) d₂₁ = −F₂₁ − P₁F₁₂, d₁₂ = P₂d₂₁ − F₁₂."""
        f = np.flatnonzero(self.free)
        a, eye = self.a[f], np.eye(f.size)
        P1 = a[:, None] * self.omega1.T[np.ix_(f, f)] + self.b * eye
        P2 = a[:, None] * D2[np.ix_(f, f)] + self.b * eye
        d12, d21 = np.zeros(self.a.size), np.zeros(self.a.size)
        d21[f] = sla.solve(eye - P1 @ P2, -F21[f] - P1 @ F12[f])
        d12[f] = P2 @ d21[f] - F12[f]
        return d12, d21


# ---------------------------------------------------------------------------------------
# the condensed problem on Γ_C and its semismooth Newton
# ---------------------------------------------------------------------------------------
class CondensedInterface:
    """Offline condensation of the glued linear problem onto the Γ_C unknowns: s = s_L − M λ."""

    def __init__(self, problem: InterfaceProblem) -> None:
        om2 = problem.omega2
        self.problem = problem
        self.Yc, self.Sc, self.Yq, self.Sq = om2.responses(contact=True, chunk=problem.options.chunk)
        f = self.f = np.flatnonzero(problem.free)  # the data at the other values stay zero
        a, b, eye = problem.a[f], problem.b, np.eye(f.size)
        self.P1 = a[:, None] * problem.omega1.T[np.ix_(f, f)] + b * eye
        P2 = a[:, None] * self.Yc[np.ix_(f, f)] + b * eye
        self.lu = sla.lu_factor(eye - self.P1 @ P2)
        self.Gq = np.zeros((problem.a.size, self.Sq.shape[0]))  # ∂g₂₁/∂λ = −Gq
        self.Gq[f] = sla.lu_solve(self.lu, self.P1 @ (a[:, None] * self.Yq[f]))
        self.M = self.Sq + self.Sc @ self.Gq
        self._chains = None
        if problem.options.fronts or problem.options.front_window:
            self.chains  # noqa: B018 -- formed offline (collective: all ranks' points), not in the timed solve

    def load_terms(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Online: (s_L, g₂₁ at λ = 0, y₂₀) from one Ω₂ back-solve and the Ω₁ load response."""
        p, f = self.problem, self.f
        t1 = p.omega1.load()
        y20, s00 = p.omega2.load_response()
        g21 = np.zeros(p.a.size)
        g21[f] = sla.lu_solve(self.lu, self.P1 @ (p.a[f] * y20[f]) + p.a[f] * t1[f])
        return s00 + self.Sc @ g21, g21, y20

    def jacobian(self, active: np.ndarray) -> np.ndarray:
        """∂y₂/∂g₂₁ for the Ω₂ active set (Woodbury on J₀: no factorization)."""
        A = np.flatnonzero(active)
        if A.size == 0:
            return self.Yc
        DA = self.D[A]
        S = np.eye(A.size) + self.Sq[np.ix_(A, A)] * DA[None, :]
        return self.Yc - (self.Yq[:, A] * DA[None, :]) @ np.linalg.solve(S, self.Sc[A])

    @property
    def D(self) -> np.ndarray:
        return self.problem.omega2.D

    @property
    def chains(self) -> list:
        """The Γ_C unknowns ordered along the boundary (``contact_chains``; the front extrapolation's), built on
        first use (collective: the contact points are gathered from all ranks)."""
        if self._chains is None:
            self._chains = contact_chains(self.problem.omega2.contact_points()) if self.M.size else []
        return self._chains

    def lowest_eigenvalue(self) -> float:
        """Smallest eigenvalue of ½(M + Mᵀ): > 0 when the glued problem is an elastic (positive definite) one.

        Always so with a fine Ω₁ (M is then the symmetric compliance of the monolithic problem on Γ_C); a
        multiscale Ω₁ whose interface response is not a Robin map of an elastic body can make it negative.
        """
        if not self.M.size:
            return np.inf
        return float(np.linalg.eigvalsh(0.5 * (self.M + self.M.T))[0])

    def solve(self, options: InterfaceNewtonOptions, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, "ContactNewtonHistory"]:
        """Contact Newton, then (g₁₂, g₂₁, λ) global."""
        p = self.problem
        s_load, g21_0, y20 = self.load_terms()
        try:
            chains = self.chains if options.fronts or options.front_window else None
            _, lam, hist = contact_solve(s_load, self.M, self.D, options, name, chains)
        except ConvergenceError as err:
            lowest = self.lowest_eigenvalue()
            if lowest < 0.0:
                raise ConvergenceError(
                    f"{name}: the glued problem is not positive definite (the symmetric part of its condensed "
                    f"contact compliance has the eigenvalue {lowest:.2e} < 0), so its contact problem need not "
                    "have a solution: Ω₁'s interface response is not that of an elastic body at this transmission "
                    "coefficient (a multiscale Ω₁ whose approximation error the Robin coefficient amplifies). Use a "
                    "smaller α or β (Algorithm 3's default alpha='Emin*h^-1/2'), or more oversampling layers") from err
            raise
        g21 = g21_0 - self.Gq @ lam
        y2 = y20 + self.Yc @ g21 - self.Yq @ lam
        g12 = np.where(p.free, p.a * y2 + p.b * g21, 0.0)
        return g12, g21, lam, hist


def contact_solve(s_load: np.ndarray, M: np.ndarray, D: np.ndarray, options: InterfaceNewtonOptions, name: str,
                  chains) -> tuple[np.ndarray, np.ndarray, "ContactNewtonHistory"]:
    """``contact_newton`` with the options' front handling (``chains`` given: the front extrapolation with
    ``options.fronts``, else the local front resolution), and the plain contact Newton afresh should that not
    converge: with a non-symmetric M (a multiscale Ω₁) the energy line search that stops cycles is no merit
    function, and a predicted set can lead into a cycle the plain Newton avoids.  The failed attempt's steps
    stay counted (``ContactNewtonHistory.discarded``)."""
    try:
        return contact_newton(s_load, M, D, max_steps=options.max_steps, name=name, chains=chains,
                              window=0 if options.fronts else options.front_window)
    except ConvergenceError as first:
        if not chains:
            raise
        log.warning("%s: the contact Newton with %s did not converge (%s); the plain contact Newton instead", name,
                    "the front extrapolation" if options.fronts else "the local front resolution", first)
        s, mu, hist = contact_newton(s_load, M, D, max_steps=options.max_steps, name=name)
        hist.discarded = first.steps
        return s, mu, hist


@dataclass(slots=True)
class ContactNewtonHistory:
    """Active-set sizes, step lengths and contact-law violations ‖μ − D s⁺‖ of the contact Newton.

    ``added`` / ``removed``: the contact rows each step brought into / took out of the active set it
    solves next (indices into the Γ_C unknowns; the step that confirms the set adds and removes none).
    """

    active_sizes: list[int] = field(default_factory=list)
    step_lengths: list[float] = field(default_factory=list)
    residuals: list[float] = field(default_factory=list)
    added: list[np.ndarray] = field(default_factory=list)
    removed: list[np.ndarray] = field(default_factory=list)
    #: rows where the next set differs from the semismooth step's own set {s > 0} because the front
    #: extrapolation or the local front resolution set them, per step (empty: none); the next step solves
    #: that trial set.  A row may be one the step would have flipped and the local problem kept as it was
    #: (then it is in neither ``added`` nor ``removed``)
    extrapolated: list[np.ndarray] = field(default_factory=list)
    #: per step: (local problems, their semismooth iterations, largest window) of the local front resolution
    #: (``LocalFronts``; (0, 0, 0) when none was solved)
    local: list[tuple[int, int, int]] = field(default_factory=list)
    #: steps of a first attempt that did not converge (``CondensedInterface.solve`` then starts the plain
    #: contact Newton afresh; the records above are the second attempt's), counted in ``steps``
    discarded: int = 0

    @property
    def steps(self) -> int:
        return len(self.step_lengths) + self.discarded

    @property
    def local_iterations(self) -> int:
        """Semismooth iterations of all the local front problems (each a solve of at most 2w unknowns for an
        isolated front)."""
        return sum(it for _, it, _ in self.local)


# ---------------------------------------------------------------------------------------
# front extrapolation: Γ_C ordered along the boundary, secant on the fronts of the active set
# ---------------------------------------------------------------------------------------
def contact_chains(points: np.ndarray, *, cut: float = 4.0) -> list[tuple[np.ndarray, np.ndarray]]:
    """The contact unknowns ordered along Γ_C: one (indices, arc-length positions) pair per piece of Γ_C.

    The pieces are the paths of the Euclidean minimum spanning tree of ``points`` once its edges longer than
    ``cut`` × the median edge are removed (separate components of Γ_C); a piece that is not a path (a
    node with three tree neighbours: points too far from a curve) is left out, and its fronts are then
    simply not extrapolated.  Coincident points (a vertex copied at a corner) follow each other.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components, minimum_spanning_tree
    from scipy.spatial.distance import cdist

    if points.shape[0] < 3:
        return []
    dist = cdist(points, points)
    if dist.max() == 0.0:
        return []
    # coincident points (copies of a vertex) are one node of the tree, expanded again in the chain
    _, group = connected_components(dist <= 1e-12 * dist.max(), directed=False)
    first = np.unique(group, return_index=True)[1]
    members = [np.flatnonzero(group == g) for g in range(first.size)]
    points = points[first]
    n = points.shape[0]
    dist = dist[np.ix_(first, first)]
    if n < 3:
        return []
    tree = minimum_spanning_tree(dist).tocoo()
    keep = tree.data <= cut * np.median(tree.data)
    adj = coo_matrix((tree.data[keep], (tree.row[keep], tree.col[keep])), shape=(n, n)).tocsr()
    adj = (adj + adj.T).tocsr()
    count, label = connected_components(adj, directed=False)
    degree = np.diff(adj.indptr)
    chains = []
    for c in range(count):
        nodes = np.flatnonzero(label == c)
        if nodes.size < 3 or degree[nodes].max() > 2:
            continue
        order, prev = [int(nodes[degree[nodes] == 1][0])], -1
        while True:
            nbrs = [k for k in adj.indices[adj.indptr[order[-1]] : adj.indptr[order[-1] + 1]] if k != prev]
            if not nbrs:
                break
            prev = order[-1]
            order.append(int(nbrs[0]))
        order = np.array(order)
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points[order], axis=0), axis=1))])
        chains.append((np.concatenate([members[k] for k in order]),
                       np.concatenate([np.full(members[k].size, a) for k, a in zip(order, arc)])))
    return chains


class FrontExtrapolation:
    """Secant prediction of the fronts of the contact Newton's active set along Γ_C (``contact_chains``).

    A front is the end e of a contiguous active segment of a chain.  A semismooth step solved on the set
    moves it to the zero crossing z of the new s along the chain (its last node on the active side of z).
    Where a stiff body rests on Γ_C (a near-rigid punch on the penalty), the front moves one node per step:
    z(e) − e shrinks slowly.  When a front has moved the same way in two consecutive steps and z(e) − e
    contracts, the secant through (e₀, z₀), (e₁, z₁) predicts the fixed point e* = z(e*); the trial set
    moves the front to the last node before e* + ``margin`` node spacing in the direction it came from
    (a conservative rounding: one node too far can make a near-rigid body pivot).  Only fronts of a
    stretch of Γ_C made of another material than most of it are extrapolated (local compliance M_ii·D_i
    more than ``inclusion`` times off its median: a stiff or soft inclusion on Γ_C, where the slow fronts
    are; elsewhere the plain steps converge fast and a prediction that is one node off costs a step), and
    the prediction stays inside the stretch of one local compliance (M_ii·D_i within a factor ``clamp`` of
    its neighbour's: a material boundary of Γ_C is where such a front stops, and the secant's smooth model
    does not hold across it).  Every trial set is then solved (a counted step) and must confirm itself;
    after ``max_misses`` predictions that the next step undid (a row the prediction changed is changed
    back) no more are made.  The fixed point is that of the semismooth Newton: the trial set is only a
    start for its next step.
    """

    def __init__(self, chains, M: np.ndarray, D: np.ndarray, *, margin: float = 0.5, clamp: float = 2.0,
                 inclusion: float = 4.0, max_misses: int = 2) -> None:
        self.chains = [(np.asarray(idx), np.asarray(pos, dtype=float)) for idx, pos in chains]
        self.compliance = np.abs(np.diag(M)) * D
        self.margin, self.clamp, self.max_misses = margin, clamp, max_misses
        typical = np.median(self.compliance) if self.compliance.size else 0.0
        #: rows whose fronts may be extrapolated: local compliance more than ``inclusion`` times off the median
        self.eligible = np.maximum(self.compliance, typical) > inclusion * np.minimum(self.compliance, typical)
        self.records: dict = {}
        self.misses = 0
        self.changed = np.zeros(0, dtype=np.int64)  # rows the last prediction changed
        self.target = np.zeros(0, dtype=bool)  # and their predicted state

    def _same_material(self, i: int, k: int) -> bool:
        a, b = self.compliance[i], self.compliance[k]
        return max(a, b) <= self.clamp * min(a, b)

    @staticmethod
    def _crossing(s: np.ndarray, idx: np.ndarray, pos: np.ndarray, e: int, o: int):
        """Zero crossing z of s near the front (end e, active side −o) and the node before it, or None."""
        n = idx.size
        j = e
        if s[idx[e]] > 0.0:
            while 0 <= j + o < n and s[idx[j + o]] > 0.0:
                j += o
            if not 0 <= j + o < n:
                return None
        else:
            while 0 <= j - o < n and s[idx[j]] <= 0.0:
                j -= o
            if s[idx[j]] <= 0.0:
                return None
        a, b = s[idx[j]], s[idx[j + o]]
        return pos[j] + (pos[j + o] - pos[j]) * a / (a - b), j

    def missed(self, predicted: np.ndarray) -> bool:
        """Whether the step that solved the last prediction undid it (changed back a row it had changed);
        if so the prediction is dropped, its records with it, and one miss counted."""
        miss = bool(self.changed.size) and bool(np.any(predicted[self.changed] != self.target))
        if miss:
            self.misses += 1
            self.records = {}
        self.changed = np.zeros(0, dtype=np.int64)
        return miss

    def trial(self, active: np.ndarray, s_new: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        """The next set: ``predicted`` (the semismooth step's {s_new > 0} after solving on ``active``), with
        the fronts that qualify moved to their secant prediction."""
        trial = predicted.copy()
        records = {}
        for c, (idx, pos) in enumerate(self.chains):
            act = active[idx]
            ends = [(i, 1) for i in np.flatnonzero(act[:-1] & ~act[1:])]  # o = +1: active below the end
            ends += [(i + 1, -1) for i in np.flatnonzero(~act[:-1] & act[1:])]
            for e, o in ends:
                found = self._crossing(s_new, idx, pos, e, o)
                if found is None:
                    continue
                z, j = found
                last = self.records.get((c, o, e))
                k = j
                if last is not None and j != e and self.misses < self.max_misses and self.eligible[idx[e]]:
                    e0, z0 = last
                    f0, f1 = z0 - e0, z - pos[e]
                    if np.sign(f0) == np.sign(f1) != 0.0 and abs(f1) < abs(f0):
                        star = pos[e] - f1 * (pos[e] - e0) / (f1 - f0)
                        spacing = 0.5 * abs(pos[min(j + 1, idx.size - 1)] - pos[max(j - 1, 0)])
                        star -= np.sign(f1) * self.margin * spacing  # back towards where the front came from
                        if f1 * o < 0.0:  # the segment shrinks: free its nodes beyond e*
                            while (0 <= k - o < idx.size and trial[idx[k - o]] and o * pos[k] > o * star
                                   and self._same_material(idx[k], idx[k - o])):
                                trial[idx[k]] = False
                                k -= o
                        else:  # it grows: activate the nodes up to e*
                            while (0 <= k + o < idx.size and not trial[idx[k + o]] and o * pos[k + o] <= o * star
                                   and self._same_material(idx[k], idx[k + o])):
                                k += o
                                trial[idx[k]] = True
                records[(c, o, k)] = (pos[e], z)
        self.records = records
        self.changed = np.flatnonzero(trial != predicted)
        self.target = trial[self.changed]
        return trial


class LocalFronts:
    """Local resolution of the fronts of the contact Newton's active set (a nonlinear elimination).

    After a step has solved the set 𝒜 for (s, μ), the semismooth step's next set is {s > 0}.  Where a stiff
    body rests on Γ_C (a channel 10⁶ times stiffer than its surroundings on the penalty) that set frees or
    takes one node per step, and in the mixed method fronts in the bulk creep one Gauss–Lobatto point per
    step.  Here every front of the next set (the end of a contiguous active segment of a ``contact_chains``
    chain) gets a window of the ``width`` unknowns on either side of it (overlapping windows merged), and on
    each window R the penalized contact equations are solved exactly with the forces elsewhere held at the
    step's μ:

        s_R = r_R − M_RR μ_R,  μ_R = D_R s_R⁺,  r_R = s_L,R − M_R,R̄ μ_R̄,

    by the same semismooth Newton (full steps from the next set's rows; at most 2|R| + 10 iterations, and a
    window whose iteration does not settle keeps the plain set).  The next set takes the windows' active
    sets.  Each local iteration is one dense solve of at most |R| unknowns (2w for an isolated front),
    against the n_c of a step.  The trial set is only the start of the next step: a set is accepted only when
    the step solved on it reproduces it, so the fixed point is the plain Newton's.  (Nonlinear elimination,
    Lanzkron, Rose & Wilkes 1996; Cai & Keyes 2002: the unknowns that hold a Newton method back are
    eliminated by local nonlinear solves.)
    """

    def __init__(self, chains, M: np.ndarray, D: np.ndarray, width: int) -> None:
        self.chains = [np.asarray(idx) for idx, _ in chains]
        self.M, self.D, self.width = M, D, int(width)

    def windows(self, active: np.ndarray) -> list[np.ndarray]:
        """The merged windows (rows of the contact unknowns) around the fronts of ``active``."""
        out, w = [], self.width
        for idx in self.chains:
            a = active[idx]
            mark = np.zeros(idx.size, dtype=bool)
            for e in np.flatnonzero(a[:-1] != a[1:]):  # a front between positions e and e + 1
                mark[max(0, e - w + 1) : e + w + 1] = True
            edges = np.flatnonzero(np.diff(np.concatenate([[0], mark.astype(np.int8), [0]])))
            out += [idx[a0:a1] for a0, a1 in zip(edges[::2], edges[1::2])]
        return out

    def _solve(self, R: np.ndarray, r: np.ndarray, start: np.ndarray) -> tuple[np.ndarray | None, int]:
        """The active set of the window's equations (None: no settled set), and the iterations taken."""
        MRR, DR = self.M[np.ix_(R, R)], self.D[R]
        act, seen = start.copy(), set()
        for it in range(2 * R.size + 10):
            seen.add(np.packbits(act).tobytes())
            new = _solve_on(r, MRR, DR, np.flatnonzero(act))[0] > 0.0
            if np.array_equal(new, act):
                return new, it + 1
            if np.packbits(new).tobytes() in seen:  # a cycle (possible for a non-symmetric M)
                return None, it + 1
            act = new
        return None, 2 * R.size + 10

    def trial(self, predicted: np.ndarray, s_load: np.ndarray, mu: np.ndarray) -> tuple[np.ndarray, tuple]:
        """The next set: ``predicted`` with every front window's own solution; and (windows, iterations,
        largest window)."""
        trial = predicted.copy()
        iterations, largest = 0, 0
        wins = self.windows(predicted)
        for R in wins:
            r = s_load[R] - self.M[R] @ mu + self.M[np.ix_(R, R)] @ mu[R]
            found, it = self._solve(R, r, predicted[R])
            iterations += it
            largest = max(largest, R.size)
            if found is not None:
                trial[R] = found
        return trial, (len(wins), iterations, largest)


def _solve_on(s_load: np.ndarray, M: np.ndarray, D: np.ndarray, A: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The contact equations s = s_L − M μ, μ = D s⁺ linearized on the set A (indices): (s, μ, the relative residual
    of the solve).  (D_A⁻¹ + M_AA) μ_A = s_L,A, μ = 0 off A, s = s_L − M_:A μ_A and on A s = μ_A / D_A (no
    cancellation with a stiff penalty); the residual is 0 for an empty A and infinite when not finite."""
    s, mu = s_load.copy(), np.zeros(s_load.size)
    if not A.size:
        return s, mu, 0.0
    K = M[np.ix_(A, A)] + np.diag(1.0 / D[A])
    mu[A] = np.linalg.solve(K, s_load[A])
    r = K @ mu[A] - s_load[A]
    s = s_load - M[:, A] @ mu[A]
    s[A] = mu[A] / D[A]
    size = np.linalg.norm(s_load[A]) + np.linalg.norm(M[np.ix_(A, A)] @ mu[A]) + 1e-300
    return s, mu, float(np.linalg.norm(r) / size) if np.isfinite(r).all() else np.inf


def _line_search(mu: np.ndarray, dmu: np.ndarray, s: np.ndarray, ds: np.ndarray, s_load: np.ndarray,
                 D: np.ndarray) -> float:
    """argmin over t ∈ (0, 1] of ψ(s + t ds): root of the increasing piecewise-linear φ'(t).

    φ'(t) = dμᵀ(s_L − s − t ds) + Σ D (s + t ds)⁺ ds  (ψ = ½μᵀMμ + ½ΣD(s⁺)², s = s_L − Mμ).
    """
    c0, c1 = dmu @ (s_load - s), -(dmu @ ds)

    def dphi(t: np.ndarray) -> np.ndarray:
        return c0 + c1 * t + (D * ds * np.maximum(s[None, :] + t[:, None] * ds[None, :], 0.0)).sum(axis=1)

    ends = dphi(np.array([0.0, 1.0]))
    if ends[0] >= 0.0 or ends[1] <= 0.0:
        return 1.0
    nz = ds != 0.0
    bp = -s[nz] / ds[nz]
    bp = np.unique(np.concatenate([[0.0, 1.0], bp[(bp > 0.0) & (bp < 1.0)]]))
    vals = dphi(bp)
    k = int(np.argmax(vals > 0.0))
    t0, t1, v0, v1 = bp[k - 1], bp[k], vals[k - 1], vals[k]
    return float(t0 - v0 * (t1 - t0) / (v1 - v0))


def contact_newton(s_load: np.ndarray, M: np.ndarray, D: np.ndarray, *, max_steps: int = 50,
                   name: str = "contact Newton", rtol: float = 1e-10, active: np.ndarray | None = None,
                   line_search: bool = False, chains=None,
                   window: int = 0) -> tuple[np.ndarray, np.ndarray, ContactNewtonHistory]:
    """Solve s = s_L − M μ, μ = D s⁺ by semismooth Newton (finite termination, globalized): (s, μ).

    Starts from μ = 0 (no contact force) with the active set 𝒜 = {s_L > 0} (the contact-free
    solution's penetration pattern), or from the set ``active`` (a guess, e.g. a coarser solve's);
    ``line_search``: the exact line search at every step (by default only once an active set
    recurs).  A full step solves the problem linearized at the
    current active set 𝒜 = {s > 0} for the forces: (D_𝒜⁻¹ + M_𝒜𝒜) μ_𝒜 = s_L,𝒜, s = s_L − M_:𝒜 μ_𝒜
    (on 𝒜, s = μ/D: no cancellation with a stiff penalty).  It stops at the first step whose result
    has the set it was computed for (then both equations hold exactly) and checks that solve.
    ``chains`` (``contact_chains`` of the Γ_C unknowns' coordinates): the next set is the front
    extrapolation's trial set (``FrontExtrapolation``) until the line search starts; every set
    solved, predicted or not, is one step.  ``window`` > 0 (with ``chains``, instead of the
    extrapolation): the next set is that of the local front resolution (``LocalFronts``, ``window``
    unknowns on either side of every front), also until the line search starts.
    """
    hist = ContactNewtonHistory()
    n = s_load.size
    s, mu = s_load.copy(), np.zeros(n)
    active = s > 0.0 if active is None else np.asarray(active, dtype=bool).copy()
    visited: set[bytes] = set()
    if window < 0:
        raise ValueError(f"contact_newton: window must be >= 0, got {window}")
    fronts = local = None
    if chains and window > 0:
        local = LocalFronts(chains, M, D, window)
    elif chains:
        fronts = FrontExtrapolation(chains, M, D)
    for _ in range(max_steps):
        visited.add(np.packbits(active).tobytes())
        s_new, mu_new, residual = _solve_on(s_load, M, D, np.flatnonzero(active))
        if residual > rtol:
            error = ConvergenceError(f"{name}: the condensed contact system is singular or ill-conditioned "
                                     f"(relative residual {residual:.1e})")
            error.steps = hist.steps + 1
            raise error
        predicted = s_new > 0.0
        settled = np.array_equal(predicted, active)
        if fronts is not None and not settled:
            fronts.missed(predicted)
        if not settled and not line_search:
            line_search = np.packbits(predicted).tobytes() in visited
        t = 1.0
        if line_search and not settled:
            t = _line_search(mu, mu_new - mu, s, s_new - s, s_load, D)
        s, mu = s + t * (s_new - s), mu + t * (mu_new - mu)
        following = s > 0.0
        extrapolated = np.zeros(0, dtype=np.int64)
        local_work = (0, 0, 0)
        if fronts is not None and not line_search and not settled:
            trial = fronts.trial(active, s_new, following)
            if np.packbits(trial).tobytes() in visited:
                fronts.changed = extrapolated  # already solved: no prediction this step
            else:
                extrapolated, following = np.flatnonzero(trial != following), trial
        if local is not None and not line_search and not settled:
            trial, local_work = local.trial(following, s_load, mu_new)
            if np.packbits(trial).tobytes() not in visited:  # (a set already solved: the plain one instead)
                extrapolated, following = np.flatnonzero(trial != following), trial
        hist.local.append(local_work)
        hist.step_lengths.append(t)
        hist.active_sizes.append(int(np.count_nonzero(following)))
        hist.added.append(np.flatnonzero(following & ~active))
        hist.removed.append(np.flatnonzero(active & ~following))
        hist.extrapolated.append(extrapolated)
        hist.residuals.append(float(np.linalg.norm(mu - D * np.maximum(s, 0.0))))  # contact-law violation
        if settled:
            return s, mu, hist
        active = following
    error = ConvergenceError(
        f"{name}: contact Newton did not converge in {max_steps} steps (active-set sizes "
        f"{hist.active_sizes[-5:]}, step lengths {hist.step_lengths[-5:]}, residuals {hist.residuals[-3:]})"
    )
    error.steps = hist.steps
    raise error


# ---------------------------------------------------------------------------------------
# the driver
# ---------------------------------------------------------------------------------------
def _norm(v: np.ndarray) -> float:
    return float(np.linalg.norm(v))


def newton_iterate(step, options: IterationOptions, *, name: str, monitor=None,
                   initial: np.ndarray | None = None) -> IterationHistory:
    """Interface Newton on g = T(g) (``accel="newton"``); each record is one application of T.

    The step provides ``interface_problem(options.newton)`` (an ``InterfaceProblem``, built once
    and cached by the step: its time is the offline ``history.time_offline_s``).
    """
    nopt = options.newton
    history = IterationHistory()
    t_off = time.perf_counter()
    problem = step.interface_problem(nopt)
    if problem.omega2.refresh():
        problem.condensed = None
    if nopt.strategy == "condensed" and problem.condensed is None:
        problem.condensed = CondensedInterface(problem)
    history.time_offline_s = time.perf_counter() - t_off
    start = time.perf_counter()
    comm = step.comm
    om2 = problem.omega2
    if nopt.strategy == "condensed":
        g12, g21, lam, ch = problem.condensed.solve(nopt, name)
        # broadcast: every rank continues from rank 0's (identical) dense result
        g12, g21, lam = comm.bcast((g12, g21, lam), root=0)
        om2.set_state(om2.solve(om2.rhs(g21, lam)))  # warm start of Ω₂: one J₀ back-solve
        history.newton_steps = ch.steps
        predicted = [e.size for e in ch.extrapolated]
        by = "the front extrapolation" if nopt.fronts else "the local front resolution"
        log.info("%s: contact Newton %d steps, active-set sizes %s, step lengths %s, rows added/removed per "
                 "step %s%s%s", name, ch.steps, ch.active_sizes, [round(t, 3) for t in ch.step_lengths],
                 [f"+{a.size}/-{r.size}" for a, r in zip(ch.added, ch.removed)],
                 f" (rows {by} set otherwise than the plain step: {predicted})" if any(predicted) else "",
                 f"; local front problems {sum(w for w, _, _ in ch.local)}, {ch.local_iterations} iterations, "
                 f"largest window {max(m for _, _, m in ch.local)}" if any(w for w, _, _ in ch.local) else "")
        history.contact_newton = ch
        g = problem.data(g12, g21)
    else:
        g = step.initial_data() if initial is None else initial
    steps_left = nopt.max_corrections if nopt.strategy == "condensed" else nopt.max_steps
    # Jacobian of Ω₂: from the offline condensation (Woodbury, no factorization), or exact by n_γ back-solves
    # with Ω₂'s own factorization (the "interface" strategy, and the fallback when a condensed step fails:
    # with a stiff penalty the Woodbury update loses digits)
    exact = nopt.strategy == "interface"
    # certify: Ω₁ is solved, Ω₂'s warm state is checked against its own equations (solved only if that fails)
    Tg, rec = evaluate(step, g, history, name=name, monitor=monitor, omega2_warm=nopt.strategy == "condensed")
    rec.info["newton_steps"] = history.newton_steps
    # iterates that collapse towards a vanishing solution never certify (a relative residual): try g = 0 once,
    # before corrections would iterate on noise (on two ranks an Ω₂ solve there failed its own residual check),
    # else after them
    initial_size = data_norm(np.asarray(initial, dtype=float), comm) if initial is not None else 0.0
    first_size = data_norm(g, comm)

    def zero_or_back(g: np.ndarray):
        """The pair at g = 0 if it glues, else the pair at g again: (T(g) or None, the last record)."""
        if zero_is_the_fixed_point(step, history, options, name=name, monitor=monitor):
            return None, history.records[-1]
        return evaluate(step, g, history, name=name, monitor=monitor)

    zero_tried = rec.residual >= options.tol and first_size <= COLLAPSE * initial_size \
        and history.iterations < options.max_iterations
    if zero_tried:
        Tg, rec = zero_or_back(g)  # (glued: rec.residual < tol ends the corrections before they start)

    def residual_norm(g: np.ndarray, Tg: np.ndarray) -> float:
        return _norm(np.concatenate([a - b for a, b in zip(problem.halves(g), problem.halves(Tg))]))

    while rec.residual >= options.tol and steps_left > 0 and history.iterations < options.max_iterations:
        F12, F21 = (a - b for a, b in zip(problem.halves(g), problem.halves(Tg)))
        fnorm = _norm(np.concatenate([F12, F21]))
        if exact:
            D2 = om2.responses(contact=False, chunk=nopt.chunk, solver=om2.sub.solver)[0]
        else:
            D2 = problem.condensed.jacobian(om2.contact_values() > 0.0)
        d12, d21 = problem.step_direction(F12, F21, D2)
        d12, d21 = comm.bcast((d12, d21), root=0)
        steps_left -= 1
        history.newton_steps += 1
        g0, rec0, t = g, rec, 1.0
        for _ in range(6 if exact else 1):  # backtracking (each trial is one application of T)
            g = g0 + t * problem.data(d12, d21)
            Tg, rec = evaluate(step, g, history, name=name, monitor=monitor)
            accepted = (rec.residual < options.tol or residual_norm(g, Tg) <= (1.0 - 1e-4 * t) * fnorm
                        or rec.residual < 0.5 * rec0.residual)
            rec.info["newton_steps"] = history.newton_steps
            rec.info["step_length"] = t
            if accepted or history.iterations >= options.max_iterations:
                break
            t *= 0.5
        log.info("%s: Newton step %d (%s Jacobian), step length %g, residual %.3e", name, history.newton_steps,
                 "exact" if exact else "condensed", t, rec.residual)
        if not accepted and not exact and history.iterations < options.max_iterations:
            exact = True  # back to g0 and retry with the exact Jacobian of Ω₂
            g = g0
            Tg, rec = evaluate(step, g, history, name=name, monitor=monitor)
    history.converged = bool(rec.residual < options.tol)
    if not history.converged and not zero_tried and history.iterations < options.max_iterations \
            and data_norm(g, comm) <= COLLAPSE * max(initial_size, first_size):
        Tg, rec = zero_or_back(g)
    history.time_s = time.perf_counter() - start - history.time_monitor_s
    log.info("%s: %s, %d Newton steps, %d applications of T, transmission residual %.3e, online %.3f s "
             "(interface response offline %.3f s)", name, "converged" if history.converged else "NOT converged",
             history.newton_steps, history.iterations, rec.residual, history.time_s, history.time_offline_s)
    return history
