"""Algorithm 1 for two deformable bodies: a contact strip on each side of the pair, each bulk coupled to its
strip by its own Robin transmission.

Each body is split into its bulk and a strip of ``layers`` cell layers along its contact surface; Ω₁ (the
two bulks, linear, independent) and Ω₂ (the two strips and the contact between them, nonlinear) exchange
Robin data on γ (the facets between a strip and its bulk, in both bodies):

    Ω₁:  a₁(u₁, v) + Σ_p α_p w_p u₁(p)·v(p) = ℓ₁(v) + Σ_p w_p g₁₂(p)·v(p)
    Ω₂:  a₂(u₂, v) + (penalized contact of the two strips) + Σ_p α_p w_p u₂(p)·v(p) = ℓ₂(v) + Σ_p w_p g₂₁(p)·v(p)
    g₁₂ ← 2α u₂ − g₂₁,   g₂₁ ← 2α u₁ − g₁₂      at every γ node p (vertex weights w_p),

ℓ_i the loads of the cells (and traction facets) of Ω_i.  With the vertex quadrature on γ the fixed point is
the monolithic two-body solution (``fem.two_body``), as Theorem 3.1 states for one body.  The interface
problem F(g) = g − T(g) is solved by Newton's method (``accel="newton"``): Ω₁'s response to g₁₂ is affine,
u₁|γ = R₁ g₁₂ + r₁ (R₁ by back-solves, once), and on a fixed active set so is Ω₂'s, with R₂ from the
factorized Jacobian of its last contact Newton; one step per active set, then exact (after
``pair_iteration.NEWTON_STEPS`` steps without convergence, a cycle of active sets, the iteration goes on with
Anderson acceleration).
``"anderson"`` and ``"none"`` (the paper's update) are the alternatives.  The responses cost one back-solve
per γ unknown and dense matrices of the size of γ: affordable for the strips of a contact zone, not for a γ
of many thousand nodes.  The stopping rule is the transmission residual
(``hybrid.certificate``).  With the pair's friction law Ω₂ is the frictional strips (``fem.two_body_friction``):
R₂ comes from their frictional Jacobian, one interface Newton step per friction state, and the state is
committed once the pair has converged (``state`` carries it to the next load step).  Under MPI
``hybrid.two_body_mpi`` solves both subdomains in parallel and the reduced pair on every rank (the same fixed point).
"""

import logging
import time
from dataclasses import dataclass

import basix.ufl
import numpy as np
import scipy.sparse as sp
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.fem.contact import ContactProfile, NewtonHistory, NewtonOptions
from fenics_contact.fem.friction import FrictionProfile
from fenics_contact.fem.linalg import SparseFactor
from fenics_contact.fem.mortar import ContactQuadrature, contact_quadrature, surface
from fenics_contact.fem.newton import semismooth_newton_loop
from fenics_contact.fem.two_body import (
    MAX_REFINEMENTS,
    PairState,
    TwoBodySystem,
    load_vector,
    stiffness,
    supported_dofs,
    surface_profile,
    two_body_penalty,
)
from fenics_contact.fem.two_body_friction import FrictionalTwoBodySystem, solve_frictional_pair
from fenics_contact.hybrid.certificate import Certificate, primal_certificate, status
from fenics_contact.hybrid.pair_iteration import iterate_pair_interface
from fenics_contact.hybrid.two_body_mpi import solve_two_body_hybrid_distributed
from fenics_contact.problem.pair import TwoBodyProblem

__all__ = ["TwoBodyHybridOptions", "TwoBodyHybridResult", "strip_cells", "solve_two_body_hybrid"]

log = logging.getLogger(__name__)

#: the updates of the interface data
UPDATES = ("newton", "anderson", "none")


@dataclass(frozen=True, slots=True)
class TwoBodyHybridOptions:
    """``layers``: cell layers of each strip from its contact surface (vertex neighbours); α_p = ``alpha_scale``
    · E_p / √(h_γ L_ref) (E_p the mean E of the cells at the γ node p, h_γ the median γ facet size, L_ref the pair's
    size ``TwoBodyProblem.length``: a stiffness per length, the same relative α in any unit); stop when the
    transmission residual is below ``tol``, at most ``max_iterations`` evaluations of T; ``accel`` the update."""

    layers: int = 2
    alpha_scale: float = 1.0
    tol: float = 1e-8
    max_iterations: int = 500
    accel: str = "newton"
    depth: int = 10

    def __post_init__(self) -> None:
        for name in ("layers", "max_iterations", "depth"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise InputError(f"two-body Algorithm 1: {name} must be an integer >= 1, got {value!r}")
        if not (np.isfinite(self.alpha_scale) and self.alpha_scale > 0 and np.isfinite(self.tol) and self.tol > 0):
            raise InputError(f"alpha_scale and tol must be finite and > 0, got {self.alpha_scale!r}, {self.tol!r}")
        if self.accel not in UPDATES:
            raise InputError(f"unknown update {self.accel!r}; choose one of {', '.join(UPDATES)}")


@dataclass(slots=True)
class TwoBodyHybridResult:
    """The converged (or last) pair: u (Ω₁ values in the bulks, Ω₂'s in the strips, their mean on γ), the
    transmission residual per evaluation of T, the contact Newton histories, the strip cells (local; under MPI the
    owned ones)."""

    u: fem.Function
    converged: bool
    residuals: list[float]
    newton: list[NewtonHistory]
    strip: np.ndarray
    delta: float
    time_s: float
    #: the contact profiles of the slave and the master surface (``fem.two_body.TwoBodySolution``)
    slave: ContactProfile
    master: ContactProfile
    #: the resultant contact force on the slave and on the master body (from Ω₂'s contact forces)
    forces: tuple[np.ndarray, np.ndarray]
    #: with friction: the tangential traction, pressure and stick/slip state at the slave nodes (Ω₂'s)
    friction: FrictionProfile | None = None
    #: with friction: the energy the step's slip dissipated (≥ 0)
    dissipation: float = 0.0
    #: the state the next load step starts from (``solve_two_body_hybrid(..., state=)``)
    state: PairState | None = None
    #: the evaluations of T the interface Newton made (0 with another update)
    interface_newton_steps: int = 0
    #: the round-off floor of the last pair's transmission residual (``hybrid.certificate``)
    floor: float = 0.0
    #: the last pair's residual is above tol but at its round-off floor (``certificate.at_floor``; converged)
    at_floor: bool = False

    @property
    def iterations(self) -> int:
        """Evaluations of T (pairs of subdomain solves)."""
        return len(self.residuals)

    @property
    def transmission_residual(self) -> float:
        """The transmission residual of the last pair (the stopping rule)."""
        return self.residuals[-1]

    @property
    def status(self) -> str:
        """``certificate.status``: ``"converged"``, ``"floor"`` (at the round-off floor ``floor``) or
        ``"not converged"``."""
        return status(self.converged, self.at_floor)

    def force_balance(self) -> float:
        """|F_slave + F_master| / max |F| (round-off)."""
        fs, fm = self.forces
        return float(np.linalg.norm(fs + fm) / max(np.linalg.norm(fs), np.linalg.norm(fm), np.finfo(float).tiny))


def strip_cells(problem: TwoBodyProblem, layers: int) -> np.ndarray:
    """The local cells within ``layers`` vertex-neighbour layers of the two contact surfaces (sorted)."""
    msh = problem.mesh
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim, 0)
    msh.topology.create_connectivity(0, tdim)
    c2v, v2c = msh.topology.connectivity(tdim, 0), msh.topology.connectivity(0, tdim)
    msh.topology.create_connectivity(tdim - 1, 0)
    f2v = msh.topology.connectivity(tdim - 1, 0)
    facets = np.concatenate([problem.facet_tags.find(t) for t in (problem.pair.slave, problem.pair.master)])
    vertices = np.unique(np.concatenate([f2v.links(f) for f in facets]))
    cells = np.zeros(0, dtype=np.int32)
    for _ in range(layers):
        cells = np.unique(np.concatenate([cells, *[v2c.links(v) for v in vertices]]))
        vertices = np.unique(np.concatenate([c2v.links(c) for c in cells]))
    return cells.astype(np.int32)


class _Split:
    """The DOF sets of Ω₁ and Ω₂, the γ DOFs (shared, not supported) with their vertex weights and α."""

    def __init__(self, problem: TwoBodyProblem, V: fem.FunctionSpace, strip: np.ndarray, fixed: np.ndarray, scale):
        msh = V.mesh
        tdim, bs = msh.topology.dim, V.dofmap.index_map_bs
        imap = msh.topology.index_map(tdim)
        num_cells = imap.size_local + imap.num_ghosts
        in_strip = np.zeros(num_cells, dtype=bool)
        in_strip[strip] = True
        cell_dofs = V.dofmap.list
        blocks = [np.unique(cell_dofs[~in_strip]), np.unique(cell_dofs[in_strip])]
        self.dofs = [(bs * b[:, None] + np.arange(bs)).ravel() for b in blocks]
        # γ: the facets between a strip cell and a bulk cell; vertex weights |f|/k
        msh.topology.create_connectivity(tdim - 1, tdim)
        f2c = msh.topology.connectivity(tdim - 1, tdim)
        fmap = msh.topology.index_map(tdim - 1)
        gamma = [f for f in range(fmap.size_local + fmap.num_ghosts) if len(set(in_strip[f2c.links(f)])) == 2]
        if not gamma:
            raise InputError("the strips have no interface γ with the bulks: fewer layers, or a finer mesh")
        gamma = np.asarray(gamma, dtype=np.int32)
        surf = surface(V, dmesh.meshtags(msh, tdim - 1, gamma, np.ones(gamma.size, dtype=np.int32)), 1)
        nodes, weights, _ = surf.lumped()
        # E_p: the mean E of the cells at the node (DG0 E: one value per cell)
        E_cells = problem.fields.E.x.array[problem.fields.E.function_space.dofmap.list[:, 0]]
        flat = cell_dofs.ravel()
        total = np.bincount(flat, np.repeat(E_cells, cell_dofs.shape[1]), minlength=flat.max() + 1)
        count = np.bincount(flat, minlength=flat.max() + 1)
        mean_E = total[nodes] / count[nodes]
        h = float(np.median(surf.measures))
        alpha = scale * mean_E / np.sqrt((h if tdim == 2 else np.sqrt(h)) * problem.length)
        dofs = (bs * nodes[:, None] + np.arange(bs)).ravel()
        keep = ~np.isin(dofs, fixed)
        self.gamma = dofs[keep]
        self.weights = np.repeat(weights, bs)[keep]
        self.alpha = np.repeat(alpha, bs)[keep]


#: right-hand sides per multi-RHS back-solve of the interface responses
CHUNK = 128


def _responses(solve, size: int, positions: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """X[positions] for A X = E, E[positions[j], j] = weights[j], by blocks of ``CHUNK`` columns (``solve``: A⁻¹
    of a dense block)."""
    out = np.zeros((positions.size, positions.size))
    for first in range(0, positions.size, CHUNK):
        cols = np.arange(first, min(first + CHUNK, positions.size))
        rhs = np.zeros((size, cols.size))
        rhs[positions[cols], np.arange(cols.size)] = weights[cols]
        out[:, cols] = solve(rhs)[positions]
    return out


def _local(dofs: np.ndarray, n: int) -> np.ndarray:
    """Global DOF -> position in ``dofs`` (−1 outside)."""
    out = np.full(n, -1, dtype=np.int64)
    out[dofs] = np.arange(dofs.size)
    return out


class _Bulk:
    """Ω₁: the linear Robin problem on the bulk DOFs, factorized once."""

    def __init__(self, K: sp.csr_matrix, b: np.ndarray, dofs, fixed, values, robin: sp.dia_matrix) -> None:
        n = K.shape[0]
        self.dofs = dofs
        loc = _local(dofs, n)
        fixed_here = fixed[loc[fixed] >= 0]
        values_here = values[loc[fixed] >= 0]
        A = (K + robin)[dofs][:, dofs].tocsr()
        self.free = np.ones(dofs.size, dtype=bool)
        self.free[loc[fixed_here]] = False
        self.u_fixed = np.zeros(dofs.size)
        self.u_fixed[loc[fixed_here]] = values_here
        self.A_ff = A[self.free][:, self.free].tocsr()
        self.rhs0 = b[dofs][self.free] - A[self.free] @ self.u_fixed
        self.factor = SparseFactor.from_csr(self.A_ff, what="the two-body bulk (Omega_1) matrix")

    def response(self, positions: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """R₁[i, j] = ∂u₁(positions[i])/∂g_j for data weights[j] at positions[j] (multi-RHS solves)."""
        rows = np.cumsum(self.free) - 1  # bulk position -> position among the free DOFs
        return _responses(self.factor.solve, int(self.free.sum()), rows[positions], weights)

    def solve(self, data: np.ndarray) -> np.ndarray:
        """u₁ on the bulk DOFs for the data vector ``data`` (on the bulk DOFs)."""
        u = self.u_fixed.copy()
        u[self.free] = self.factor.solve((self.rhs0 + data[self.free])[:, None])[:, 0]
        return u

    def error(self, u: np.ndarray, data: np.ndarray) -> np.ndarray:
        """An estimate of the error of ``solve``'s u (bulk DOFs): one step of iterative refinement,
        A⁻¹(rhs − A u) (one back-solve)."""
        out = np.zeros(self.dofs.size)
        residual = self.rhs0 + data[self.free] - self.A_ff @ u[self.free]
        out[self.free] = self.factor.solve(residual[:, None])[:, 0]
        return out

    def destroy(self) -> None:
        self.factor.destroy()


def solve_two_body_hybrid(
    problem: TwoBodyProblem,
    *,
    delta: float | None = None,
    options: TwoBodyHybridOptions = TwoBodyHybridOptions(),
    newton: NewtonOptions = NewtonOptions(),
    state: PairState | None = None,
    omega1=None,
) -> TwoBodyHybridResult:
    """Algorithm 1 for two bodies (module docstring); the same δ default as the monolithic solve.  ``state``: the
    previous load step's ``.state`` (either solve's): Ω₂ starts from its u, the interface data from its g (when
    Algorithm 1 made it), and with friction the slip is measured from its anchors.  ``omega1``: None (the fine
    bulks), or ``omega1(problem, V, split, strip)`` building another Ω₁ with ``response``, ``solve`` and
    ``destroy`` (``multiscale.pair``: a CEM-GMsFEM space in each bulk; serial)."""
    if state is not None and not isinstance(state, PairState):
        raise InputError(f"two-body Algorithm 1: state must be a PairState (a solution's .state), got {state!r}")
    if omega1 is not None and problem.comm.size > 1:
        raise InputError("two-body Algorithm 1 with another Omega_1 runs on one process (run it without mpiexec)")
    if problem.comm.size > 1:  # both subdomains in parallel, the pair reduced to γ and the contact rows
        return solve_two_body_hybrid_distributed(problem, delta=delta, options=options, newton=newton, state=state)
    start = time.perf_counter()
    msh = problem.mesh
    gdim = msh.geometry.dim
    V = fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 1, shape=(gdim,)))
    bs = V.dofmap.index_map_bs
    n = V.dofmap.index_map.size_local * bs
    fixed, values = supported_dofs(problem, V)
    strip = strip_cells(problem, options.layers)
    bulk_cells = np.setdiff1d(np.arange(msh.topology.index_map(msh.topology.dim).size_local), strip)
    split = _Split(problem, V, strip, fixed, options.alpha_scale)
    robin = sp.csr_matrix((split.alpha * split.weights, (split.gamma, split.gamma)), shape=(n, n))
    if omega1 is None:
        K1, b1 = stiffness(problem, V, bulk_cells), load_vector(problem, V, bulk_cells)
        bulk = _Bulk(K1, b1, split.dofs[0], fixed, values, robin)
    else:
        bulk = omega1(problem, V, split, strip)
    slave = surface(V, problem.facet_tags, problem.pair.slave)
    master = surface(V, problem.facet_tags, problem.pair.master)
    delta = two_body_penalty(problem, slave, master, delta)
    Q = contact_quadrature(
        slave, master, n, bs, problem.pair.quadrature_degree, rule=problem.pair.rule, basis=problem.pair.basis
    )
    d2 = split.dofs[1]
    loc2 = _local(d2, n)
    Q2 = ContactQuadrature(Q.points, Q.weights, Q.gap, Q.nu, Q.B[:, d2].tocsr(), Q.nodes, Q.relative[:, d2].tocsr())
    K2 = (stiffness(problem, V, strip) + robin)[d2][:, d2].tocsr()
    b2 = load_vector(problem, V, strip)[d2]
    mine = loc2[fixed] >= 0
    frictional = problem.friction is not None
    if frictional:
        anchor = None if state is None else state.anchor
        system = FrictionalTwoBodySystem(
            K2, b2.copy(), loc2[fixed[mine]], values[mine], Q2, delta, problem.friction, anchor
        )
    else:
        system = TwoBodySystem(K2, b2.copy(), loc2[fixed[mine]], values[mine], Q2, delta)
    if state is not None:
        system.u[system.free] = np.asarray(state.u, dtype=np.float64)[d2][system.free]
    g1_pos, g2_pos = _local(split.dofs[0], n)[split.gamma], loc2[split.gamma]
    m = split.gamma.size
    w, alpha = split.weights, split.alpha
    histories: list[NewtonHistory] = []
    residuals: list[float] = []

    def errors(u1: np.ndarray, data1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Estimates of the errors of u₁ and u₂ on γ (one refinement step each: the bulk's back-solve, and the
        strips' with the Jacobian of their last Newton step for their residual there)."""
        e1 = bulk.error(u1, data1)[g1_pos] if hasattr(bulk, "error") else np.zeros(m)
        e2 = system.solve_block(-(system.F * system.free)[:, None])[g2_pos, 0]
        return e1, e2

    def solve_pair(g: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        data1 = np.zeros(split.dofs[0].size)
        data1[g1_pos] = w * g[:m]
        u1 = bulk.solve(data1)
        system.b = b2.copy()
        system.b[g2_pos] += w * g[m:]
        if frictional:
            histories.append(solve_frictional_pair(system, newton, MAX_REFINEMENTS))
            return u1, system.u.copy(), data1
        trace = semismooth_newton_loop(
            system,
            system.penetration() >= 0.0,
            name="two-body strips",
            max_steps=newton.max_iterations,
            line_search="always",
            rtol=newton.rtol,
            atol=newton.atol,
            refinements=MAX_REFINEMENTS,
            sizes="active contact nodes",
        )
        histories.append(NewtonHistory(trace.residuals, trace.active_sizes, trace.factorizations))
        return u1, system.u.copy(), data1

    last: list[np.ndarray] = []

    def T(g: np.ndarray) -> tuple[np.ndarray, Certificate]:
        u1, u2, data1 = solve_pair(g)
        last[:] = [u1, u2]
        u1g, u2g = u1[g1_pos], u2[g2_pos]
        cert = primal_certificate(u1g, u2g, g[:m], g[m:], alpha, w, MPI.COMM_SELF, errors(u1, data1))
        residuals.append(cert.value)
        return np.concatenate([2 * alpha * u2g - g[m:], 2 * alpha * u1g - g[:m]]), cert

    g = np.zeros(2 * m)
    if state is not None and state.interface is not None and state.interface.size == 2 * m:
        g = state.interface.copy()
    try:
        # R₁ = ∂u₁|γ/∂g₁₂ (once); R₂ = ∂u₂|γ/∂g₂₁ from Ω₂'s factorized Jacobian at the current active set
        outcome = iterate_pair_interface(
            T,
            g,
            alpha,
            lambda: bulk.response(g1_pos, w),
            lambda: _responses(system.solve_block, d2.size, g2_pos, w),
            options,
            name="two bodies, Algorithm 1",
        )
        g, converged, newton_steps = outcome.g, outcome.converged, outcome.steps
        force = np.zeros(n)
        force[d2] = system.contact_force_vector()
        tangential = system.profile() if frictional else None
        dissipation = system.commit() if frictional else 0.0
    finally:
        system.destroy()
        bulk.destroy()
    u1, u2 = last
    merged, count = np.zeros(n), np.zeros(n)
    for dofs, values_ in ((split.dofs[0], u1), (d2, u2)):
        merged[dofs] += values_
        count[dofs] += 1.0
    u = fem.Function(V, name="u")
    u.x.array[:n] = merged / np.maximum(count, 1.0)
    forces = tuple(force.reshape(-1, bs)[surf.nodes].sum(axis=0) for surf in (slave, master))
    elapsed = time.perf_counter() - start
    log.info(
        "two bodies, Algorithm 1 (%s): %d evaluations of T, transmission residual %.3e, %.2f s",
        options.accel,
        len(residuals),
        residuals[-1],
        elapsed,
    )
    if not converged:
        log.warning("two bodies, Algorithm 1: NOT converged (transmission residual %.3e)", residuals[-1])
    profiles = (
        surface_profile(u.x.array[:n], force, slave, Q, slave=True),
        surface_profile(u.x.array[:n], force, master, Q, slave=False),
    )
    next_state = PairState(u.x.array[:n].copy(), system.friction.anchor.copy() if frictional else None, g.copy())
    return TwoBodyHybridResult(
        u, converged, residuals, histories, strip, delta, elapsed, *profiles, forces, tangential, dissipation,
        next_state, newton_steps, outcome.floor, outcome.status == "floor",
    )  # fmt: skip
