"""The monolithic penalized contact of two deformable bodies (P1, one mesh, non-matching contact surfaces).

    a(u, v) + (1/δ) Σ_q w_q (s_q(u))⁺ s_q(v)₀ = (f, v) + Σ_k ∫_ΓN,k t_k·v ds,   u = u_D on the supports,

with s(u) = B u − g the penetration at the points of the contact quadrature (``fem.mortar``: slave points,
their closest points on the master surface, on the reference configuration) and s(v)₀ = B v.  The energy
½ a(u, u) − (f, v)(u) + (1/2δ) Σ_q w_q (s_q⁺)² is convex; its semismooth Newton (``fem.newton``, active
set: the rows with s_q > 0) runs through ``TwoBodySystem``, a ``ContactSystem`` with the exact line search
on that energy (at every step by default: ``solve_two_body``).

The coupling entries Bᵀ W B join DOF blocks of the two bodies that share no cell, outside the pattern of the
finite-element matrix: the system is assembled in SciPy and factorized by ``fem.linalg.SparseFactor``
(sequential MUMPS).  Under MPI ``solve_two_body`` hands over to ``fem.two_body_mpi`` (the contact surfaces gathered
to every rank, the bulk solved in parallel; the same solution).  With the pair's friction law the contact term
is the nodal law on the slave nodes' relative displacements (``fem.two_body_friction``); a load step then takes
the previous one's ``PairState``.
"""

import logging
import time
from dataclasses import dataclass
from typing import NamedTuple

import basix.ufl
import dolfinx.la
import numpy as np
import scipy.sparse as sp
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh

from fenics_contact.errors import InputError
from fenics_contact.fem.contact import ContactProfile, NewtonHistory, NewtonOptions, profile_order
from fenics_contact.fem.friction import FrictionProfile
from fenics_contact.fem.linalg import SparseFactor
from fenics_contact.fem.matrices import assemble_scipy
from fenics_contact.fem.mortar import (
    ContactQuadrature,
    Surface,
    contact_quadrature,
    project,
    surface,
    weight_functions,
)
from fenics_contact.fem.newton import Advance, Check, Direction, StepState, semismooth_newton_loop
from fenics_contact.fem.primal import default_penalty
from fenics_contact.fem.two_body_mpi import solve_two_body_distributed
from fenics_contact.problem.materials import strain, stress
from fenics_contact.problem.pair import TwoBodyProblem

__all__ = [
    "PairState",
    "TwoBodySystem",
    "TwoBodySolution",
    "solve_two_body",
    "two_body_penalty",
    "supported_dofs",
    "stiffness",
    "load_vector",
    "PairTraction",
    "transmitted_pressure",
]

log = logging.getLogger(__name__)

#: iterative-refinement steps with a settled active set (as the one-body primal solve)
MAX_REFINEMENTS = 2


def two_body_penalty(problem: TwoBodyProblem, slave: Surface, master: Surface, delta: float | None) -> float:
    """δ, or when None ``default_penalty(h, E_c)``: h the smaller median facet size of the two surfaces, E_c the
    largest E of the cells touching them."""
    if delta is None:
        h = min(float(np.median(slave.measures)), float(np.median(master.measures)))
        if problem.dim == 3:
            h = float(np.sqrt(h))
        return default_penalty(h, max(problem.contact_moduli()))
    if (
        isinstance(delta, bool)
        or not isinstance(delta, (int, float, np.number))
        or not (np.isfinite(delta) and delta > 0)
    ):
        raise InputError(f"the penalty δ must be a finite number > 0 (or None: the default), got {delta!r}")
    return float(delta)


class TwoBodySystem:
    """The two-body penalized equations as a ``fem.newton.ContactSystem`` on the scalar DOF vector u (SciPy).

    K the stiffness (no boundary conditions), b the load, ``fixed`` the supported DOFs with their values,
    Q the contact quadrature (B, w, g), δ the penalty.  F(u) = K u − b + Bᵀ(w/δ (B u − g)⁺) on the free
    rows, 0 on the fixed ones; J = K + Bᵀ diag(w H(s)/δ) B on the free rows and columns, identity on the fixed.
    """

    def __init__(
        self, K: sp.csr_matrix, b: np.ndarray, fixed: np.ndarray, values: np.ndarray, Q: ContactQuadrature, delta: float
    ) -> None:
        n = K.shape[0]
        self.K, self.b, self.Q, self.delta = K.tocsr(), b, Q, delta
        self.free = np.ones(n, dtype=bool)
        self.free[fixed] = False
        keep = sp.diags(self.free.astype(np.float64))
        self._K_free = (keep @ self.K @ keep + sp.diags((~self.free).astype(np.float64))).tocsr()
        self._B_free = (Q.B @ keep).tocsr()
        self.u = np.zeros(n)
        self.u[fixed] = values
        self.F = np.zeros(n)
        self.d = np.zeros(n)
        self._factor: SparseFactor | None = None
        self._factor_set: np.ndarray | None = None
        self._J: sp.csr_matrix | None = None

    # -- the pieces ------------------------------------------------------------------------------
    def penetration(self, u: np.ndarray | None = None) -> np.ndarray:
        """s = B u − g at the quadrature points."""
        return self.Q.B @ (self.u if u is None else u) - self.Q.gap

    def contact_force(self, u: np.ndarray | None = None) -> np.ndarray:
        """Bᵀ(w/δ (B u − g)⁺) on the free DOFs: the contact term of F."""
        return self._B_free.T @ (self.Q.weights / self.delta * np.maximum(self.penetration(u), 0.0))

    def _assemble_residual(self) -> np.ndarray:
        self.F = (self.K @ self.u - self.b) * self.free + self.contact_force()
        return self.F

    # -- ContactSystem ---------------------------------------------------------------------------
    def residual(self) -> float:
        return float(np.linalg.norm(self._assemble_residual()))

    def jacobian(self, active: np.ndarray) -> bool:
        if self._factor_set is not None and np.array_equal(active, self._factor_set):
            return False
        D = sp.diags(self.Q.weights * active / self.delta)
        self._J = (self._K_free + self._B_free.T @ D @ self._B_free).tocsr()
        if self._factor is not None:
            self._factor.destroy()
        self._factor = SparseFactor.from_csr(self._J, what="the two-body contact Jacobian")
        self._factor_set = active.copy()
        return True

    def solve(self, active: np.ndarray) -> Direction:
        self.d = self._factor.solve(-self.F[:, None])[:, 0]
        return Direction(self.penetration(self.u + self.d) > 0.0)

    def same(self, a: np.ndarray, b: np.ndarray) -> bool:
        return bool(np.array_equal(a, b))

    def line_search(self) -> float:
        """The minimizer of the convex energy along d in (0, 1]: the root of its monotone derivative
        φ'(t) = dᵀ(K(u + t d) − b) + Σ_q (w_q/δ)(B d)_q (s_q + t (B d)_q)⁺ (bisection)."""
        d = self.d * self.free
        Kd, r = self.K @ d, self.K @ self.u - self.b
        Bd, s, w = self.Q.B @ d, self.penetration(), self.Q.weights / self.delta

        def slope(t: float) -> float:
            return float(d @ (r + t * Kd) + np.sum(w * Bd * np.maximum(s + t * Bd, 0.0)))

        if slope(1.0) <= 0.0:
            return 1.0
        lo, hi = 0.0, 1.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if slope(mid) < 0.0 else (lo, mid)
        return hi

    def advance(self, t: float, state: StepState) -> Advance:
        self.u += t * self.d
        active = self.penetration() > 0.0
        return Advance(active, int(np.count_nonzero(active)))

    def check(self) -> Check:
        """‖F‖∞ against ‖ |J||u| + |b| + |Bᵀ W g| ‖∞ (the size of the terms F balances, row by row)."""
        F = self._assemble_residual()
        active = self.penetration() > 0.0
        gap_terms = np.abs(self._B_free.T @ (self.Q.weights / self.delta * active * self.Q.gap))
        J = self._J if self._J is not None else self._K_free
        scale = float(np.max(abs(J) @ np.abs(self.u) + np.abs(self.b) * self.free + gap_terms, initial=0.0))
        return Check(float(np.max(np.abs(F), initial=0.0)), scale, float(np.linalg.norm(F)))

    def contact_force_vector(self) -> np.ndarray:
        """−Bᵀ(w/δ (B u − g)⁺): the contact forces on every DOF (supported ones too)."""
        return -(self.Q.B.T @ (self.Q.weights / self.delta * np.maximum(self.penetration(), 0.0)))

    def solve_block(self, rhs: np.ndarray) -> np.ndarray:
        """J⁻¹ rhs for a block of right-hand sides (zero on the supported rows), with the current factorization."""
        return self._factor.solve(rhs)

    def destroy(self) -> None:
        if self._factor is not None:
            self._factor.destroy()
            self._factor = None


class PairState(NamedTuple):
    """What a converged load step hands the next one: the displacement DOFs ``u`` (the warm start), the friction
    anchors it committed (``fem.friction``: None when frictionless), and Algorithm 1's interface data g."""

    u: np.ndarray
    anchor: np.ndarray | None = None
    interface: np.ndarray | None = None


@dataclass(slots=True)
class TwoBodySolution:
    """The two-body penalized solution: u, the Newton history, the contact profiles of both surfaces (nodal
    normal stress σ_c < 0 in compression, along each surface's outward normal) and the contact quadrature."""

    u: fem.Function
    newton: NewtonHistory
    slave: ContactProfile
    master: ContactProfile
    delta: float
    dofs: int
    time_s: float
    quadrature: ContactQuadrature
    problem: TwoBodyProblem
    #: the resultant contact force on the slave and on the master body (Σ of the nodal contact forces)
    forces: tuple[np.ndarray, np.ndarray]
    #: with friction: the tangential traction, pressure and stick/slip state at the slave nodes
    friction: FrictionProfile | None = None
    #: with friction: the energy the step's slip dissipated (≥ 0)
    dissipation: float = 0.0
    #: the state the next load step starts from (``solve_two_body(..., state=)``)
    state: PairState | None = None

    @property
    def profile(self) -> ContactProfile:
        """The slave side's profile (the surface the contact integral lives on)."""
        return self.slave

    def force_balance(self) -> float:
        """|F_slave + F_master| / max |F|: the relative imbalance of the resultant contact forces (round-off)."""
        fs, fm = self.forces
        return float(np.linalg.norm(fs + fm) / max(np.linalg.norm(fs), np.linalg.norm(fm), np.finfo(float).tiny))


def pair_solution(
    problem: TwoBodyProblem, u: fem.Function, u_contact: np.ndarray, force: np.ndarray, surfaces, delta: float,
    dofs: int, elapsed: float, history: NewtonHistory, **extra,
) -> TwoBodySolution:  # fmt: skip
    """The ``TwoBodySolution`` of u, ``u_contact`` (a DOF vector holding u at least at the contact columns), the
    nodal contact forces ``force`` and ``surfaces`` = (slave, master, Q): both profiles and both resultants;
    ``extra``: the friction fields and the state."""
    slave, master, Q = surfaces
    bs = u.function_space.dofmap.index_map_bs
    return TwoBodySolution(
        u,
        history,
        surface_profile(u_contact, force, slave, Q, slave=True),
        surface_profile(u_contact, force, master, Q, slave=False),
        delta,
        dofs,
        elapsed,
        Q,
        problem,
        tuple(force.reshape(-1, bs)[surf.nodes].sum(axis=0) for surf in (slave, master)),
        **extra,
    )


def supported_dofs(problem: TwoBodyProblem, V: fem.FunctionSpace) -> tuple[np.ndarray, np.ndarray]:
    """The supported scalar DOFs and their values u_D."""
    msh = V.mesh
    bs, fdim = V.dofmap.index_map_bs, msh.topology.dim - 1
    x = V.tabulate_dof_coordinates()
    dofs, values = [], []
    for s in problem.supports:
        blocks = fem.locate_dofs_topological(V, fdim, problem.facet_tags.find(s.facets))
        comps = range(bs) if s.components is None else s.components
        if max(comps) >= bs:
            raise InputError(f"Support on tag {s.facets}: component {max(comps)} of a {bs}D displacement")
        u_D = np.zeros((bs, blocks.size)) if s.displacement is None else np.asarray(s.displacement(x[blocks].T))
        if u_D.shape != (bs, blocks.size):
            raise InputError(f"the displacement on tag {s.facets} must give {bs} components, got shape {u_D.shape}")
        for c in comps:
            dofs.append(bs * blocks + c)
            values.append(u_D[c])
    dofs, values = np.concatenate(dofs), np.concatenate(values)
    dofs, first = np.unique(dofs, return_index=True)
    return dofs, values[first]


def _cell_measure(problem: TwoBodyProblem, cells: np.ndarray | None):
    """dx over the mesh, or over ``cells`` only (marked 1)."""
    msh = problem.mesh
    if cells is None:
        return ufl.dx(domain=msh)
    tags = dmesh.meshtags(msh, msh.topology.dim, np.sort(cells).astype(np.int32), np.ones(cells.size, np.int32))
    return ufl.Measure("dx", domain=msh, subdomain_data=tags)(1)


def stiffness(problem: TwoBodyProblem, V: fem.FunctionSpace, cells: np.ndarray | None = None) -> sp.csr_matrix:
    """K: a(u, v) over the mesh, or over ``cells`` only (no boundary conditions; SciPy CSR)."""
    u, v, fields = ufl.TrialFunction(V), ufl.TestFunction(V), problem.fields
    dx = _cell_measure(problem, cells)
    return assemble_scipy(ufl.inner(stress(strain(u), fields.lmbda, fields.mu), strain(v)) * dx)


def load_vector(problem: TwoBodyProblem, V: fem.FunctionSpace, cells: np.ndarray | None = None) -> np.ndarray:
    """b: (f, v) + Σ_k ∫_ΓN,k t_k·v ds over the mesh, or over ``cells`` and the traction facets of those cells."""
    msh, v = V.mesh, ufl.TestFunction(V)
    L = ufl.inner(problem.fields.f, v) * _cell_measure(problem, cells)
    if problem.tractions:
        tdim = msh.topology.dim
        f2c = msh.topology.connectivity(tdim - 1, tdim)
        entities, values = [], []
        for k, tag in enumerate(problem.tractions):
            facets = problem.facet_tags.find(tag)
            if cells is not None:
                facets = facets[np.isin([f2c.links(f)[0] for f in facets], cells)]
            entities.append(facets)
            values.append(np.full(facets.size, k + 1, dtype=np.int32))
        entities, values = np.concatenate(entities), np.concatenate(values)
        order = np.argsort(entities)
        tags = dmesh.meshtags(msh, tdim - 1, entities[order].astype(np.int32), values[order])
        ds = ufl.Measure("ds", domain=msh, subdomain_data=tags)
        for k, traction in enumerate(problem.tractions.values()):
            t = fem.Function(V)
            t.interpolate(traction)
            L += ufl.inner(t, v) * ds(k + 1)
    b = fem.assemble_vector(fem.form(L))
    b.scatter_reverse(dolfinx.la.InsertMode.add)
    return b.array.copy()


def surface_profile(
    u: np.ndarray, force: np.ndarray, own: Surface, Q: ContactQuadrature, *, slave: bool
) -> ContactProfile:
    """Nodal profile of one surface: σ_c = (f_p·n_p)/w_p with f the contact force on the node (−Bᵀ(w/δ s⁺), not
    polluted by support reactions), n_p its outward normal and w_p = ∫ N_p ds; u_c the penetration the penalty
    acts on: the slave nodes' weighted gaps s̃_p (``mortar.nodal_gaps``), on a master node the largest s̃_p of
    the slave nodes coupled with it (∫ N_p M_j ds > 0), so that ``active`` marks the master nodes that carry
    contact forces; −∞ on a node that faces no part of the other surface.  Needs Q with nodal rows."""
    if Q.nodes is None:
        raise InputError("surface_profile needs the nodal gaps of mortar.nodal_gaps")
    nodes, weights, normals = own.lumped()
    points = own.node_coordinates()
    bs = Q.nu.shape[1]
    sigma = np.sum(force.reshape(-1, bs)[nodes] * normals, axis=1) / weights
    s = Q.B @ u - Q.gap
    u_c, gap = np.full(nodes.size, -np.inf), np.full(nodes.size, np.nan)
    if slave:
        at = np.searchsorted(nodes, Q.nodes)
        u_c[at], gap[at] = s, Q.gap
    else:  # master node j: the largest s̃_p of the slave rows p coupled with it (∫ N_p M_j ds > 0)
        cols = (bs * nodes[:, None] + np.arange(bs)).ravel()
        Bm = Q.B[:, cols].tocoo()
        coupled = Bm.data != 0.0
        rows, js = Bm.row[coupled], Bm.col[coupled] // bs
        np.maximum.at(u_c, js, s[rows])
        gap_min = np.full(nodes.size, np.inf)
        np.minimum.at(gap_min, js, Q.gap[rows])
        gap = np.where(np.isfinite(gap_min), gap_min, np.nan)
    order = profile_order(points)
    return ContactProfile(
        points[order, 1], u_c[order], sigma[order], points[order], weights[order], normals[order], gap[order]
    )


class PairTraction(NamedTuple):
    """The normal contact pressure the pair transmits, at the points of a segment-to-segment quadrature of the
    slave surface: the slave points x_q, their closest points π(x_q) on the master surface, the weights w_q, the
    directions ν_q (the master's inward unit normal at π(x_q)) and the pressure p_q, which pushes the slave
    body along −ν_q and the master along +ν_q: the resultants ∓Σ_q w_q p_q ν_q, equal and opposite.  ``nodal``:
    the P1 interpolant Σ_p λ_p N_p of the nodal pressures at the same points (with the standard basis, the
    pressure itself; with the dual basis, the profile its nodal values describe)."""

    points: np.ndarray
    master_points: np.ndarray
    weights: np.ndarray
    nu: np.ndarray
    pressure: np.ndarray
    nodal: np.ndarray


def transmitted_pressure(solution: TwoBodySolution, degree: int | None = None) -> PairTraction:
    """The pressure field the penalized pair transmits (``PairTraction``), at the segment-to-segment quadrature
    of ``degree`` (None: the pair's ``quadrature_degree``).

    The contact term Σ_p (w_p/δ) (s̃_p)⁺ s̃_p(v) of the nodal gaps (``mortar.nodal_gaps``) is
    Σ_q w_q p(x_q) s_q(v) with p = Σ_p λ_p φ_p, λ_p = (s̃_p)⁺/δ and φ_p the weight functions of the pair's
    ``basis`` (``mortar.weight_functions``): a pressure on the slave facets, which the quadrature integrates
    against both bodies' test functions.  It is that field, read at the points.  With the standard basis it is
    the P1 field Σ_p λ_p N_p (the nodal profiles σ_c are its consistent nodal forces over the lumped weights).
    With the dual basis ψ_p it has, on every slave facet, the resultant of the P1 interpolant Σ_p λ_p N_p of the
    same nodal values (``PairTraction.nodal``) and gives the slave nodes the forces λ_p ∫ N_p ds; as a field it
    reproduces constants only (its L² error is O(h) where the pressure varies), so the pressure profile is read
    from the nodal values.  The penetration s_q at a point itself carries no pressure: the penalty constrains
    only its weighted nodal means."""
    Q = solution.quadrature
    if solution.problem.comm.size > 1:
        raise InputError("transmitted_pressure runs on one process (the solution's quadrature is the gathered one)")
    if Q.nodes is None:
        raise InputError("transmitted_pressure needs a solution with the nodal gaps of mortar.nodal_gaps")
    problem = solution.problem
    V = solution.u.function_space
    bs = V.dofmap.index_map_bs
    n = V.dofmap.index_map.size_local * bs
    u = solution.u.x.array[:n]
    nodal = np.zeros(V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts)
    nodal[Q.nodes] = np.maximum(Q.B @ u - Q.gap, 0.0) / solution.delta
    slave = surface(V, problem.facet_tags, problem.pair.slave)
    master = surface(V, problem.facet_tags, problem.pair.master)
    degree = problem.pair.quadrature_degree if degree is None else degree
    points = contact_quadrature(slave, master, n, bs, degree, nodal=False, rule=problem.pair.rule)
    on = project(points.points, slave)  # each point on its slave facet: the values from its vertices
    values = nodal[slave.blocks[on.facet]]
    pressure = np.sum(weight_functions(on.bary, points.partial, problem.pair.basis) * values, axis=1)
    foot = project(points.points, master)
    closest = np.einsum("nk,nkd->nd", foot.bary, master.coords[foot.facet])
    return PairTraction(points.points, closest, points.weights, points.nu, pressure, np.sum(on.bary * values, axis=1))


def solve_two_body(
    problem: TwoBodyProblem,
    *,
    delta: float | None = None,
    newton: NewtonOptions = NewtonOptions(),
    line_search: str = "always",
    initial: np.ndarray | None = None,
    state: PairState | None = None,
) -> TwoBodySolution:
    """Penalized contact of the two bodies of ``problem`` by semismooth Newton (under MPI:
    ``fem.two_body_mpi.solve_two_body_distributed``); with the pair's friction law, ``fem.two_body_friction``.

    ``initial``: the displacement DOF vector to start from (a warm start, e.g. the previous load step's
    ``u.x.array``); its supported DOFs take the problem's values.  Serial only.  ``state``: the previous load
    step's ``TwoBodySolution.state`` (its u the warm start unless ``initial`` is given; with friction its anchors,
    from which this step's slip is measured; without one, the step starts from the unstretched state).

    ``delta`` defaults to ``two_body_penalty``; ``line_search`` as in ``fem.newton`` (exact, on the energy):
    ``"always"`` by default, as a full first step from no contact drives the bodies through each other and the
    active set then shrinks back a few nodes per step (Hertz at contact cells a/20: 5 steps searching at every
    step, 18 with full steps until a cycle).  The first step is linearized at the touching nodes (s̃ ≥ 0): a body
    held only by the contact (pushed by a traction) is not free to move in it.
    """
    if not isinstance(problem, TwoBodyProblem):
        raise InputError(f"solve_two_body takes a TwoBodyProblem, got {type(problem).__name__}")
    if state is not None and not isinstance(state, PairState):
        raise InputError(f"solve_two_body: state must be a PairState (a solution's .state), got {type(state).__name__}")
    if problem.comm.size > 1:  # the contact surfaces gathered, the bulk solved in parallel
        if initial is not None:
            raise InputError("solve_two_body: a warm start (initial) is serial only")
        return solve_two_body_distributed(problem, delta=delta, newton=newton, line_search=line_search, state=state)
    start = time.perf_counter()
    msh = problem.mesh
    gdim = msh.geometry.dim
    V = fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 1, shape=(gdim,)))
    bs = V.dofmap.index_map_bs
    n = V.dofmap.index_map.size_local * bs
    K = stiffness(problem, V)
    b = load_vector(problem, V)
    fixed, values = supported_dofs(problem, V)
    slave = surface(V, problem.facet_tags, problem.pair.slave)
    master = surface(V, problem.facet_tags, problem.pair.master)
    delta = two_body_penalty(problem, slave, master, delta)
    Q = contact_quadrature(
        slave, master, n, bs, problem.pair.quadrature_degree, rule=problem.pair.rule, basis=problem.pair.basis
    )
    if initial is None and state is not None:
        initial = state.u
    if problem.friction is not None:
        return _solve_frictional(problem, V, (K, b, fixed, values), (slave, master, Q), delta, newton, initial, state)
    system = TwoBodySystem(K, b, fixed, values, Q, delta)
    _warm_start(system, initial, n)
    try:
        trace = semismooth_newton_loop(
            system,
            system.penetration() >= 0.0,  # touching counts: a body held only by contact
            name="two-body contact",
            max_steps=newton.max_iterations,
            line_search=line_search,
            rtol=newton.rtol,
            atol=newton.atol,
            refinements=MAX_REFINEMENTS,
            sizes="active quadrature points",
        )
    finally:
        system.destroy()
    u = fem.Function(V, name="u")
    u.x.array[:n] = system.u
    history = NewtonHistory(trace.residuals, trace.active_sizes, trace.factorizations)
    log.debug("two bodies: step lengths %s", trace.step_lengths)
    elapsed = time.perf_counter() - start
    solution = pair_solution(
        problem, u, system.u, system.contact_force_vector(), (slave, master, Q), delta, n, elapsed, history,
        state=PairState(system.u.copy()),
    )  # fmt: skip
    log.info(
        "two bodies: %d Newton steps, active quadrature points %s, force balance %.1e, %.2f s",
        history.steps,
        history.active_sizes,
        solution.force_balance(),
        elapsed,
    )
    return solution


def _warm_start(system: TwoBodySystem, initial: np.ndarray | None, n: int) -> None:
    """u ← ``initial`` on the free DOFs (the supported ones keep the problem's values)."""
    if initial is None:
        return
    start_u = np.asarray(initial, dtype=np.float64).ravel()
    if start_u.size < n or not np.all(np.isfinite(start_u[:n])):
        raise InputError(f"solve_two_body: initial must hold {n} finite displacement DOFs, got {start_u.size}")
    system.u[system.free] = start_u[:n][system.free]


def _solve_frictional(problem, V, operators, surfaces, delta, newton, initial, state) -> TwoBodySolution:
    """The frictional solve of ``solve_two_body`` (``fem.two_body_friction``), the friction state committed."""
    from fenics_contact.fem.two_body_friction import FrictionalTwoBodySystem, solve_frictional_pair  # (imports this)

    start = time.perf_counter()
    n = V.dofmap.index_map.size_local * V.dofmap.index_map_bs
    anchor = None if state is None else state.anchor
    system = FrictionalTwoBodySystem(*operators, surfaces[2], delta, problem.friction, anchor)
    _warm_start(system, initial, n)
    try:
        history = solve_frictional_pair(system, newton, MAX_REFINEMENTS)
    finally:
        system.destroy()
    u = fem.Function(V, name="u")
    u.x.array[:n] = system.u
    force = system.contact_force_vector()
    tangential = system.profile()
    dissipation = system.commit()
    elapsed = time.perf_counter() - start
    solution = pair_solution(
        problem, u, system.u, force, surfaces, delta, n, elapsed, history, friction=tangential,
        dissipation=dissipation, state=PairState(system.u.copy(), system.friction.anchor.copy()),
    )  # fmt: skip
    log.info(
        "two bodies, %s: %d Newton steps, stick %d, slip %d nodes, dissipation %.3e, force balance %.1e, %.2f s",
        problem.friction.describe(),
        history.steps,
        int(np.count_nonzero(tangential.stick)),
        int(np.count_nonzero(tangential.slip)),
        dissipation,
        solution.force_balance(),
        elapsed,
    )
    return solution
